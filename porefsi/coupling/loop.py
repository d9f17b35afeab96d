"""The staggered two-way coupled loop (the seed paper's algorithm 1), composed of named parts.

One exchange step from ``t`` to ``t + Δt`` (:meth:`CoupledRun.advance`):

1. **fluid advance** (:func:`~porefsi.coupling.fluid_step.advance_fluid`): the drainage is
   advanced through the times the solid needs loads at;
2. **load transfer** (:func:`~porefsi.coupling.fluid_step.transfer_loads`): those pore pressures
   become nodal forces through the interface;
3. **solid step** (:mod:`porefsi.coupling.solid_step`): one TDG step, or a quasi-static solve at
   ``t + Δt``;
4. **network update** (:mod:`porefsi.coupling.network_step`): the network follows the displacement
   (geometric update, re-extraction, or none) and the drainage state is carried onto it;
5. **relaxation** (:class:`~porefsi.coupling.relaxation.Relaxation`): optionally 1-4 are repeated
   from the same start (sub-iterations), the displacement relaxed (Aitken) until it stops changing
   (strong coupling), and with re-extraction until the pore sizes stop changing (pre-coupling).

The total-Lagrangian solid takes its loads on the reference configuration, so the interface is
built once on the reference mesh (re-built only when re-extraction changes the pores), and the
geometric update always maps the *reference* network with the *total* displacement (no drift).
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from collections.abc import Callable, Iterator

import numpy as np

from porefsi.coupling import checkpoint as _ckpt
from porefsi.coupling._loop_support import invaded_outside
from porefsi.coupling.fluid_step import advance_fluid, carry_state, fluid_times, pore_pressure, transfer_loads
from porefsi.coupling.interface import Interface
from porefsi.coupling.linear_step import with_response
from porefsi.coupling.network_step import ExtractionCache, NetworkState, make_updater
from porefsi.coupling.problem import CoarseLoadWarning, CoupledProblem
from porefsi.coupling.records import TIMESERIES_COLUMNS, TIMESERIES_DOCS, ExchangeRecord, Iterate, IterationStats
from porefsi.coupling.relaxation import Relaxation
from porefsi.coupling.solid_step import make_solid_stepper
from porefsi.coupling.timing import StageClock
from porefsi.coupling.update import mean_size_change
from porefsi.errors import ConvergenceError
from porefsi.flow.drainage import OUTLET_PRESSURE, DrainageSimulator
from porefsi.flow.permeability import absolute_permeability
from porefsi.flow.state import FlowState
from porefsi.network.network import Network
from porefsi.solid.stress import element_cauchy, nodal_average, von_mises

__all__ = ["CoupledRun", "ExchangeRecord", "TIMESERIES_COLUMNS", "TIMESERIES_DOCS", "OUTLET_PRESSURE"]

#: Stages of an exchange step, timed in :attr:`ExchangeRecord.seconds` (with stress, permeability).
STEP_STAGES = ("fluid", "interface", "solid", "update")


class _StopRule:
    """When the fixed-point iteration of a step ends: displacement and pore sizes settled, or fail."""

    def __init__(self, coupling, network, precoupling: bool):
        self.sub, self.tol = coupling.subiterations, coupling.subiteration_tol
        self.precoupling, self.ea_tol = precoupling, network.precoupling_tol
        self.n_max = max(self.sub, network.precoupling_max_iter if precoupling else 1)
        self.ea: list[float] = []
        self.n_iter = 0

    def done(self, residuals: list, t1: float) -> bool:
        """After an iteration: True when converged; raise when out of iterations."""
        self.n_iter += 1
        disp_ok = self.sub == 1 or residuals[-1] < self.tol
        ea_ok = not self.precoupling or self.ea[-1] <= self.ea_tol
        if disp_ok and ea_ok:
            return True
        if self.n_iter >= self.n_max:
            what = "fluid-solid sub-iterations" if not disp_ok else "pre-coupling re-extractions"
            hist = residuals if not disp_ok else self.ea
            raise ConvergenceError(
                f"{what} did not converge in {self.n_iter} iterations at t = {t1:g} s (last change "
                f"{hist[-1]:.3g}); raise coupling.subiterations / network.precoupling_max_iter, use "
                "relaxation = 'aitken', or a smaller exchange_dt", hist)
        return False


@dataclasses.dataclass(frozen=True, eq=False)
class _Outcome:
    """The converged iterate of an exchange step."""

    sim: DrainageSimulator  # advanced to the end of the step, on ``sim_labels``' network
    sim_labels: np.ndarray
    network: NetworkState  # the network the displacement made
    u: np.ndarray
    v: np.ndarray
    displacement: np.ndarray  # (Nn, 3) at the end of the step
    output_forces: np.ndarray  # (Nv, 3)
    stats: IterationStats


class CoupledRun:
    """A coupled simulation in progress: advance it with :meth:`steps`, save it with :meth:`checkpoint`.

    Parameters
    ----------
    problem : CoupledProblem
        Built by :func:`porefsi.coupling.problem.build_problem` (or :func:`porefsi.case.problem_from_case`).
    reuse_extractions : bool, default True
        Re-extraction mode: serve the extraction of a voxel image seen before (by digest; the
        extraction is deterministic, so the result is the same bit for bit) instead of computing
        it again. False computes every re-extraction, as the paper does (benchmarks of its cost).
    load_map : callable, optional
        ``P -> P'`` applied to the pore pressures (Np,) before they load the solid (studies of the
        fixed point, e.g. an amplified loop gain; default: the pressures themselves).
    on_iteration : callable, optional
        Called with an :class:`~porefsi.coupling.records.Iterate` after every fluid-solid iteration
        (before its network update).

    Attributes
    ----------
    current : NetworkState
        Network, interface and voxel labels at time :attr:`t`.
    sim : DrainageSimulator
        The drainage at :attr:`t`.
    u, v : ndarray, shape (n_dofs,)
        Free displacement (m) and velocity (m/s) of the solid at :attr:`t`.
    solid : StaticStepper, TDGStepper or LinearStepper
        The solid stepper (owns its factorisations; ``solid.response`` = linear/auto: a
        :class:`~porefsi.coupling.linear_step.LinearStepper` around one of the others).
    extractions : ExtractionCache
    seconds, cpu_seconds : dict
        Wall time (``time.perf_counter``) and CPU time (``time.process_time``: this process, all
        threads) of the steps so far by stage (fluid, interface, solid, update, stress,
        permeability), s; checkpointed, so cumulative over a resumed run's processes.
    update_seconds, update_cpu_seconds : dict
        The re-extraction part of the ``update`` stage, wall and CPU: ``voxelise`` (the deformed
        solid on the voxel grid), ``extract`` (computed extractions), ``interface_rebuild`` (after
        a topology change), s.
    coarse_load : dict or None
        Graded mesh refined at the predicted invasion (``problem.refined``): the first step end at
        which fluid held pores outside the refined region, ``{"t_s", "n_pores"}`` (their
        walls are meshed by coarse leaves there); a :class:`CoarseLoadWarning` is issued then,
        once per run. None while it has not happened (or without such a mesh).
    """

    def __init__(self, problem: CoupledProblem, *, reuse_extractions: bool = True,
                 load_map: Callable[[np.ndarray], np.ndarray] | None = None,
                 on_iteration: Callable[[Iterate], None] | None = None):
        self.problem = problem
        self.load_map, self.on_iteration = load_map, on_iteration
        opts = problem.options
        self.dt = opts.coupling.exchange_dt
        self.t_end = opts.drainage.t_end
        self.n_steps = opts.n_exchange_steps
        self.step_index = 0
        self.t = 0.0
        self.current = NetworkState(problem.network, problem.interface, problem.extraction.labels)
        self.sim = DrainageSimulator(problem.network, problem.fluids, opts.drainage, axis=opts.axis)
        self.model = problem.model
        self.model.horizon_steps = self.n_steps  # the frozen-tangent hint of "auto" (porefsi.solid.linsolve)
        self.u = np.zeros(self.model.n_dofs)
        self.v = np.zeros(self.model.n_dofs)
        cc = opts.coupling
        inner = make_solid_stepper(self.model, cc.integrator, cc.tdg_iterations, cc.tdg_load_rule,
                                   opts.solid.newton_rtol)
        self.solid = with_response(inner, opts.solid.response, opts.solid.response_tol, problem.interface,
                                   self.n_steps)
        self.extractions = ExtractionCache(reuse_extractions)
        self.extractions.seed(problem.image.phases, problem.extraction)
        self.seconds = dict.fromkeys((*STEP_STAGES, "stress", "permeability"), 0.0)
        self.cpu_seconds = dict.fromkeys(self.seconds, 0.0)
        self.update_seconds = dict.fromkeys(("voxelise", "extract", "interface_rebuild"), 0.0)
        self.update_cpu_seconds = dict.fromkeys(self.update_seconds, 0.0)
        self.updater = make_updater(problem, self.extractions, StageClock(self.update_seconds, self.update_cpu_seconds))
        self.coarse_load: dict | None = None

    # ---- the state at t, by part -----------------------------------------------------------
    @property
    def network(self) -> Network:
        """The (deformed) network at :attr:`t`."""
        return self.current.network

    @network.setter
    def network(self, net: Network) -> None:
        self.current = dataclasses.replace(self.current, network=net)

    @property
    def interface(self) -> Interface:
        """The interface at :attr:`t` (rebuilt when a re-extraction changed the pores)."""
        return self.current.interface

    @interface.setter
    def interface(self, itf: Interface) -> None:
        self.current = dataclasses.replace(self.current, interface=itf)

    @property
    def labels(self) -> np.ndarray:
        """Voxel labels of the network at :attr:`t`."""
        return self.current.labels

    @property
    def reuse_extractions(self) -> bool:
        """Whether re-extractions are served from :attr:`extractions`."""
        return self.extractions.enabled

    @property
    def n_extractions(self) -> int:
        """Re-extractions computed."""
        return self.extractions.n_computed

    @property
    def n_extractions_reused(self) -> int:
        """Re-extractions served from the digest cache."""
        return self.extractions.n_reused

    def load_times(self, t0: float, dt: float) -> tuple[float, ...]:
        """Times within the step at which the solid needs the fluid load (the last is always t0 + dt)."""
        return self.solid.load_times(t0, dt)

    # ---- the loop -----------------------------------------------------------------------
    def initial_record(self) -> ExchangeRecord:
        """The state at t = 0 (before injection), as a record."""
        U = self.model.expand(self.u, 0.0)
        return self._record(self.sim.state, U, np.zeros_like(U), StageClock(), 0.0, IterationStats())

    def steps(self) -> Iterator[ExchangeRecord]:
        """Advance exchange step by exchange step to ``t_end``, yielding a record after each."""
        while self.step_index < self.n_steps:
            yield self.advance()

    def advance(self) -> ExchangeRecord:
        """One exchange step (module docstring); the record of its end."""
        t_wall = time.perf_counter()
        t0, t1 = self.t, min(self.t_end, (self.step_index + 1) * self.dt)
        clock = StageClock(dict.fromkeys(STEP_STAGES, 0.0), dict.fromkeys(STEP_STAGES, 0.0))
        out = self._iterate(t0, t1, clock)
        self.u, self.v, self.t = out.u, out.v, t1
        with clock("update"):
            self.sim = carry_state(out.sim, out.network.network, out.sim_labels, out.network.labels)
            self.current = out.network
        self.step_index += 1
        if self.coarse_load is None and self.problem.refined is not None:
            self._check_coarse_load()
        rec = self._record(self.sim.state, out.displacement, out.output_forces, clock, time.perf_counter() - t_wall,
                           out.stats)
        for total, part in ((self.seconds, rec.seconds), (self.cpu_seconds, rec.cpu_seconds)):
            for key, val in part.items():
                total[key] = total.get(key, 0.0) + val
        return rec

    def _iterate(self, t0: float, t1: float, clock: StageClock) -> _Outcome:
        """Fluid advance, load transfer, solid step and network update from the state at ``t0``.

        Repeated (relaxed) until the stop rule holds.
        """
        opts = self.problem.options
        # the start-of-step load is the one the solid carried at t0: the pressures of the
        # network and interface of t0, even when a re-extraction below changes the topology
        F0 = self.current.interface.nodal_forces(pore_pressure(self.sim.state))
        times = fluid_times(self.solid.load_times(t0, t1 - t0), t0, t1)
        relax = Relaxation(self.model.expand(self.u, t0), aitken=opts.coupling.relaxation == "aitken")
        stop = _StopRule(opts.coupling, opts.network, self.updater.precoupling)
        net_k = self.current
        while True:
            with clock("fluid"):  # a repeated iteration starts again from the state at t0
                sim = self.sim if stop.n_max == 1 else self.sim.with_network(self.current.network)
                sim = carry_state(sim, net_k.network, self.current.labels, net_k.labels)
                sim_labels = net_k.labels
                pressures = advance_fluid(sim, times, t0)
            with clock("interface"):
                loaded = pressures if self.load_map is None else {s: self.load_map(P) for s, P in pressures.items()}
                loads = transfer_loads(net_k.interface, loaded, F0, t0, t1)
            with clock("solid"):
                u1, v1 = self.solid.step(self.u, self.v, t0, t1 - t0, loads.forces, loaded, net_k.interface)
                U1 = self.model.expand(u1, t1)
            U_use = relax(U1) if opts.coupling.subiterations > 1 else U1
            if self.on_iteration is not None:
                sub = opts.coupling.subiterations > 1
                self.on_iteration(Iterate(stop.n_iter + 1, net_k, sim.state, pressures, U1, U_use,
                                          relax.residuals[-1] if sub else None, relax.omegas[-1] if sub else None))
            with clock("update"):
                net_prev, net_k = net_k, self.updater.update(U_use, self.current)
                if stop.precoupling:  # the paper's pre-coupling measure between successive re-extractions (eq. 3.3)
                    stop.ea.append(mean_size_change(net_prev.network, net_k.network))
            if stop.done(relax.residuals, t1):
                break
        stats = IterationStats(stop.n_iter, tuple(relax.residuals), tuple(relax.omegas), tuple(stop.ea))
        return _Outcome(sim, sim_labels, net_k, u1, v1, U1, loads.output, stats)

    def _check_coarse_load(self) -> None:
        """Warn (once) when fluid holds pores outside the graded mesh's refined region."""
        out = invaded_outside(self.problem.refined, self.labels, self.sim.state.nw_saturation)
        if len(out) == 0:
            return
        self.coarse_load = {"t_s": self.t, "n_pores": int(len(out))}
        s = self.problem.options.solid
        warnings.warn(f"at t = {self.t:g} s fluid holds {len(out)} pore(s) outside the graded mesh's refined region "
                      f"(solid.refine = 'invaded' predicted the load elsewhere): their walls may lie on leaves of up "
                      f"to {s.coarsen_max} voxels instead of {s.coarsen}-voxel blocks; at this rate use "
                      "solid.refine = 'walls' or a uniform mesh", CoarseLoadWarning, stacklevel=3)

    def _record(self, state: FlowState, U: np.ndarray, F: np.ndarray, clock: StageClock, wall: float,
                stats: IterationStats) -> ExchangeRecord:
        """The record of the state at :attr:`t` (stress and permeability computed here)."""
        with clock("stress"):
            vm = nodal_average(self.model.mesh, von_mises(element_cauchy(self.model, self.u, self.t)))
        with clock("permeability"):
            k = absolute_permeability(self.network, self.problem.options.axis).k_m2
        P = pore_pressure(state)
        c = self.sim.counters
        row = {
            "step": self.step_index, "time_s": self.t, "sw": state.sw,
            "inlet_pressure_Pa": state.inlet_pressure,
            "capillary_pressure_Pa": state.inlet_pressure - OUTLET_PRESSURE,
            "max_pore_pressure_Pa": float(P.max(initial=0.0)),
            "total_pore_force_N": float(np.linalg.norm(F, axis=1).sum()),
            "max_displacement_m": float(np.linalg.norm(U, axis=1).max(initial=0.0)),
            "max_von_mises_Pa": float(vm.max(initial=0.0)), "permeability_m2": k,
            "mean_pore_radius_m": float(np.mean(self.network.pore_radius)),
            "n_events": c["n_events"], "n_solves": c["n_solves"], "mass_balance_error": state.mass_balance_error,
            "load_balance_error": self.interface.load_balance_error(P), "subiterations": stats.iterations,
            "coupling_residual": stats.residual, "precoupling_iterations": len(stats.precoupling_history),
            "precoupling_Ea": stats.precoupling_ea, "wall_s": wall,
        }
        return ExchangeRecord(self.step_index, self.t, state, self.network, U, vm, F, row, dict(clock.wall),
                              stats.residual_history, stats.relaxation_history, stats.precoupling_history,
                              dict(clock.cpu))

    # ---- checkpoints --------------------------------------------------------------------
    def checkpoint(self) -> tuple[dict, dict]:
        """(arrays, metadata) that :meth:`restore` turns back into this run, exactly (plain arrays + JSON)."""
        return _ckpt.run_state(self)

    @classmethod
    def restore(cls, problem: CoupledProblem, arrays: dict, meta: dict, *, reuse_extractions: bool = True
                ) -> CoupledRun:
        """Rebuild a run from :meth:`checkpoint` output (on the same problem).

        Raises
        ------
        ValueError
            A checkpoint of another format version (e.g. the pickles of earlier porefsi versions).
        KeyError, ValueError, TypeError
            Missing or inconsistent entries (:func:`porefsi.case.run.run_case` reports them as a
            damaged checkpoint).
        """
        run = cls(problem, reuse_extractions=reuse_extractions)
        _ckpt.restore_run_state(run, arrays, meta)
        return run
