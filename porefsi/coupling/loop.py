"""The staggered two-way coupled loop (the seed paper's algorithm 1), as a generator.

One exchange step from ``t`` to ``t + Δt``:

1. the DPN is advanced to ``t + 2Δt/3`` and to ``t + Δt``; the fluid pressures at ``t`` and
   ``t + 2Δt/3`` become nodal forces through the interface (the TDG's left-Radau load samples);
2. the solid takes one TDG step (or a quasi-static Newton solve at ``t + Δt``);
3. the network follows the displacement (geometric update, re-extraction, or none) and the DPN
   state is carried onto it;
4. optionally 1-3 are repeated from the same start (sub-iterations) with Aitken relaxation of the
   displacement until it stops changing (strong coupling).

The total-Lagrangian solid takes its loads on the reference configuration, so the interface is
built once on the reference mesh (re-built only when re-extraction changes the pores), and the
geometric update always maps the *reference* network with the *total* displacement (no drift).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Iterator

import numpy as np

from porefsi.coupling._loop_support import (
    _SOLVER_FAILURES,
    StageClock,
    _digest,
    _same_topology,
    _solver_failure,
    _TangentLog,
)
from porefsi.coupling.interface import Interface
from porefsi.coupling.problem import CoupledProblem, build_interface
from porefsi.coupling.relaxation import aitken_omega
from porefsi.coupling.update import deformed_image, geometric_update, mean_size_change, update_nodes
from porefsi.errors import ConvergenceError, NetworkError
from porefsi.flow._drainage_checkpoint import simulator_from_state, simulator_state
from porefsi.flow.drainage import OUTLET_PRESSURE, DrainageSimulator
from porefsi.flow.permeability import absolute_permeability
from porefsi.flow.state import FlowState
from porefsi.image.ops import percolating_cluster
from porefsi.integrators.tdg import TDGStepper
from porefsi.io import plain
from porefsi.network.extract import extract_network
from porefsi.network.network import Network
from porefsi.solid.static import solve_static
from porefsi.solid.stress import element_cauchy, nodal_average, von_mises

__all__ = ["ExchangeRecord", "CoupledRun", "TIMESERIES_COLUMNS", "TIMESERIES_DOCS", "OUTLET_PRESSURE"]

#: Layout version of :meth:`CoupledRun.checkpoint` (1: pickled objects, no longer read; 2: plain arrays).
CHECKPOINT_FORMAT = 2

#: Columns of the per-exchange-step time series (``timeseries.csv``).
TIMESERIES_COLUMNS = (
    "step", "time_s", "sw", "inlet_pressure_Pa", "capillary_pressure_Pa", "max_pore_pressure_Pa",
    "total_pore_force_N", "max_displacement_m", "max_von_mises_Pa", "permeability_m2", "mean_pore_radius_m",
    "n_events", "n_solves", "mass_balance_error", "load_balance_error", "subiterations", "coupling_residual",
    "precoupling_iterations", "precoupling_Ea", "wall_s",
)

#: What each column of :data:`TIMESERIES_COLUMNS` holds (SI units, as in the names).
TIMESERIES_DOCS = {
    "step": "exchange step (0 = the initial state)",
    "time_s": "time at the end of the step, s",
    "sw": "wetting saturation of the spanning pore space",
    "inlet_pressure_Pa": "pressure of the virtual inlet node (gauge: outlet at 0), Pa",
    "capillary_pressure_Pa": "P_in - P_out, inlet minus outlet node pressure (the drainage's definition); "
                             "equal to inlet_pressure_Pa because the outlet is held at P_out = 0, Pa",
    "max_pore_pressure_Pa": "largest pore-wall (volume-averaged fluid) pressure, Pa",
    "total_pore_force_N": "sum over nodes of the magnitude of the pore-pressure nodal force, N",
    "max_displacement_m": "largest nodal displacement magnitude, m",
    "max_von_mises_Pa": "largest nodal (volume-averaged) von Mises stress, Pa",
    "permeability_m2": "absolute permeability of the current (deformed) network along the flow axis, m^2",
    "mean_pore_radius_m": "mean pore radius of the current network, m",
    "n_events": "cumulative drainage filling events",
    "n_solves": "cumulative drainage pressure solves",
    "mass_balance_error": "relative non-wetting volume balance of the drainage against the prescribed Q t (round-off)",
    "load_balance_error": "relative mismatch between the load the interface hands over and the pores carry",
    "subiterations": "fluid-solid sub-iterations of the step (0 at step 0)",
    "coupling_residual": "last relative displacement change of the sub-iterations (0 without)",
    "precoupling_iterations": "re-extractions of the step (re-extraction mode)",
    "precoupling_Ea": "last mean-pore-size change E_a (paper eq. 3.3; empty without re-extraction)",
    "wall_s": "wall time of the step, s",
}


@dataclasses.dataclass(frozen=True, eq=False)
class ExchangeRecord:
    """What one exchange step produced.

    Attributes
    ----------
    step : int
        Exchange step index (0 = the initial state at t = 0).
    t : float
        Time at the end of the step, s.
    flow : FlowState
        Drainage state at ``t``.
    network : Network
        Network at ``t`` (deformed).
    displacement : ndarray, shape (Nn, 3)
        Nodal displacement, m.
    von_mises : ndarray, shape (Nn,)
        Nodal (volume-averaged) von Mises stress, Pa.
    nodal_force : ndarray, shape (Nn, 3)
        Pore-pressure forces on the nodes at ``t``, N.
    row : dict
        The time-series row (:data:`TIMESERIES_COLUMNS`).
    seconds : dict
        Wall time of the step by stage: fluid, interface, solid, update, stress, permeability, s.
    residual_history : tuple of float
        Fluid-solid sub-iterations: relative displacement change ``|r_k| / |U|`` of each (empty
        without sub-iterations).
    relaxation_history : tuple of float
        The relaxation factor ``omega_k`` used after each sub-iteration (Aitken or 1).
    precoupling_history : tuple of float
        Pre-coupling re-extractions: ``E_a`` (paper eq. 3.3) after each (empty unless re-extracting).
    cpu_seconds : dict
        CPU time (``time.process_time``: this process, all threads) of the step by the stages of
        ``seconds``, s.
    """

    step: int
    t: float
    flow: FlowState
    network: Network
    displacement: np.ndarray
    von_mises: np.ndarray
    nodal_force: np.ndarray
    row: dict
    seconds: dict
    residual_history: tuple = ()
    relaxation_history: tuple = ()
    precoupling_history: tuple = ()
    cpu_seconds: dict = dataclasses.field(default_factory=dict)


def _pressure(state: FlowState) -> np.ndarray:
    """Pore-wall loading pressure (volume-averaged fluid pressure; 0 where a pore is not simulated)."""
    return np.nan_to_num(np.asarray(state.fluid_pressure, float), nan=0.0)


class CoupledRun:
    """A coupled simulation in progress: advance it with :meth:`steps`, save it with :meth:`checkpoint`.

    Parameters
    ----------
    problem : CoupledProblem
        Built by :func:`porefsi.coupling.problem.build_problem`.
    reuse_extractions : bool, default True
        Re-extraction mode: serve the extraction of a voxel image seen before (by digest; the
        extraction is deterministic, so the result is the same bit for bit) instead of computing
        it again. False computes every re-extraction, as the paper does (benchmarks of its cost).

    Attributes
    ----------
    seconds, cpu_seconds : dict
        Wall time (``time.perf_counter``) and CPU time (``time.process_time``: this process, all
        threads) of the steps so far by stage (fluid, interface, solid, update, stress,
        permeability), s; checkpointed, so cumulative over a resumed run's processes.
    n_extractions, n_extractions_reused : int
        Re-extractions computed, and served from the digest cache.
    update_seconds, update_cpu_seconds : dict
        The re-extraction part of the ``update`` stage, wall and CPU: ``voxelise`` (the deformed
        solid on the voxel grid), ``extract`` (computed extractions), ``interface_rebuild`` (after
        a topology change), s.
    """

    def __init__(self, problem: CoupledProblem, *, reuse_extractions: bool = True):
        self.problem = problem
        self.reuse_extractions = bool(reuse_extractions)
        case = problem.case
        self.dt = case.coupling.exchange_dt
        self.t_end = case.drainage.t_end
        self.n_steps = max(1, int(math.ceil(self.t_end / self.dt - 1e-9)))
        self.step_index = 0
        self.t = 0.0
        self.network = problem.network
        self.interface: Interface = problem.interface
        self.labels = problem.extraction.labels
        self.sim = DrainageSimulator(problem.network, problem.fluids, rate=case.drainage.rate, axis=case.image.axis,
                                     scheme=case.drainage.scheme)
        self.model = problem.model
        self.u = np.zeros(self.model.n_dofs)
        self.v = np.zeros(self.model.n_dofs)
        self._stepper = None
        self._static_lu = None
        # Where the reused solid factorisations were built: (u, t) of the static tangent, and of
        # the TDG stepper's tangent (plus whether the stepper will refresh it at the next step).
        # Checkpointed, so a resumed run rebuilds the very same matrices and repeats the
        # uninterrupted run bit for bit instead of agreeing only to the Newton tolerance.
        self._static_lu_at: tuple[np.ndarray, float] | None = None
        self._tdg_system = _TangentLog(self.model)
        self._tdg_stale = True
        self._tdg_pin_dt: float | None = None  # dt of the restored stepper whose tangent is pinned
        self._update_nodes = None  # per-pore nodes of the geometric update (built on first use)
        # extractions by voxel-image digest (re-extraction mode), seeded with the reference image's
        self._extractions = {_digest(problem.image.phases): problem.extraction}
        self.n_extractions = 0  # re-extractions actually computed (not served from the above)
        self.n_extractions_reused = 0  # re-extractions served from the digest cache
        self.seconds = dict.fromkeys(("fluid", "interface", "solid", "update", "stress", "permeability"), 0.0)
        self.cpu_seconds = dict.fromkeys(self.seconds, 0.0)
        self.update_seconds = dict.fromkeys(("voxelise", "extract", "interface_rebuild"), 0.0)
        self.update_cpu_seconds = dict.fromkeys(self.update_seconds, 0.0)
        self._update_clock = StageClock(self.update_seconds, self.update_cpu_seconds)
        self.precoupling_history: list[float] = []

    # ---- solid --------------------------------------------------------------------------
    def _stepper_for(self, dt: float):
        if self._stepper is None or self._stepper.dt != dt:
            if self._tdg_pin_dt is not None and dt != self._tdg_pin_dt:
                self._tdg_system.pin = None  # the checkpointed stepper had another dt: a fresh start
            self._tdg_pin_dt = None
            cc = self.problem.case.coupling
            self._stepper = TDGStepper(self._tdg_system, dt, n_iter=cc.tdg_iterations, make_solver=self._make_solver,
                                       tangent="auto", load_rule=cc.tdg_load_rule)
        return self._stepper

    def _make_solver(self, A):
        """The model's linear solver for A; a solver-library failure becomes a ConvergenceError."""
        try:
            return self.model.make_solver(A)
        except _SOLVER_FAILURES as exc:
            raise _solver_failure(exc, self.t) from exc

    def load_times(self, t0: float, dt: float) -> tuple[float, float]:
        """Times within the step at which the solid needs the fluid load (the last is always t0 + dt)."""
        if self.problem.case.coupling.integrator == "static":
            return (t0 + dt,)
        return self._stepper_for(dt).load_times(t0)

    def _solid_step(self, u, v, t0, dt, forces):
        """One solid step; ``forces`` maps each of :meth:`load_times` to nodal forces (Nn, 3)."""
        cc = self.problem.case.coupling
        if cc.integrator == "static":
            u1 = self._static_solve(self.model.with_nodal_forces(forces[t0 + dt]), t0 + dt, u, t_prev=t0)
            return u1, (u1 - u) / dt
        st = self._stepper_for(dt)
        loads = tuple(self.model.with_nodal_forces(forces[s]).external_force(s) for s in st.load_times(t0))
        u1, v1, info = st.step(u, v, t0, loads=loads)
        # the "auto" tangent policy refreshes at the next step after a failed secant check
        self._tdg_stale = info.extra.get("tangent_defect", 0.0) > st.tangent_rtol
        return u1, v1

    def _static_solve(self, model, t: float, u0: np.ndarray, t_prev: float | None = None, rtol: float = 1e-8,
                      max_iter: int = 30) -> np.ndarray:
        """Quasi-static equilibrium at ``t`` by modified Newton.

        The tangent is factorised once and reused across exchange steps (pore-pressure strains are
        ~1e-7, so it barely changes); it is refreshed when the iteration stops contracting, and a
        full Newton solve from ``(u0, t_prev)`` is the fallback.
        """
        u = np.array(u0, dtype=float)
        fext = model.external_force(t)
        scale = max(float(np.linalg.norm(fext)), float(np.linalg.norm(model.internal_force(np.zeros_like(u), t))),
                    1e-300)
        for refresh in (False, True):
            if refresh or (self._static_lu is None and self._static_lu_at is None):
                self._static_lu, self._static_lu_at = None, (u.copy(), t)
            if self._static_lu is None:  # built here, or rebuilt from a checkpoint's (u, t)
                self._static_lu = self._make_solver(model.tangent(*self._static_lu_at))
            x = u.copy()
            prev = np.inf
            for _ in range(max_iter):
                r = model.internal_force(x, t) - fext
                nr = float(np.linalg.norm(r))
                if nr <= rtol * scale:
                    return x
                if nr > 0.5 * prev:  # not contracting: the stored tangent is stale
                    break
                prev = nr
                x = x - self._static_lu(r)
        try:
            u1, _ = solve_static(model, t, u0=u, t_prev=t_prev, rtol=rtol)
        except _SOLVER_FAILURES as exc:
            raise _solver_failure(exc, t) from exc
        self._static_lu = self._static_lu_at = None
        return u1

    # ---- network ------------------------------------------------------------------------
    def _update_network(self, U: np.ndarray):
        """Network for displacement U (Nn, 3), and the interface/labels that go with it."""
        mode = self.problem.case.network.update
        p = self.problem
        if mode == "none":
            return self.network, self.interface, self.labels, None
        if mode == "geometric":
            if self._update_nodes is None:
                self._update_nodes = update_nodes(p.network.pore_coords, p.network.pore_radius,
                                                  self.interface.pore_nodes, p.mesh.points, p.node_spacing)
            return geometric_update(p.network, self._update_nodes, p.mesh.points, U), self.interface, \
                self.labels, None
        with self._update_clock("voxelise"):
            img = deformed_image(p.image, p.mesh.points, U, p.node_spacing)
        # The extraction is deterministic: the same voxel image gives the same network bit for bit,
        # so an image seen before (at the paper's loads: always the reference image, displacements
        # being ~1e-6 voxel) reuses its extraction instead of repeating it.
        key = _digest(img.phases)
        ex = self._extractions.get(key) if self.reuse_extractions else None
        if ex is not None:
            self.n_extractions_reused += 1
        else:
            with self._update_clock("extract"):
                ex = extract_network(percolating_cluster(img, p.case.image.axis).image,
                                     conductance=p.case.network.conductance)
            self.n_extractions += 1
            if self.reuse_extractions:
                if len(self._extractions) >= 4:
                    self._extractions.pop(next(iter(self._extractions)))
                self._extractions[key] = ex
        new = ex.network
        if _same_topology(new, self.network):
            return new, self.interface, self.labels, None
        with self._update_clock("interface_rebuild"):
            itf = build_interface(p.case, new, ex.labels, p.mesh, p.image.voxel_size, p.image.origin, p.model)
        return new, itf, ex.labels, None

    @staticmethod
    def _carry(sim: DrainageSimulator, net: Network, labels_old=None, labels_new=None) -> DrainageSimulator:
        """Carry the drainage state onto ``net``.

        Same topology: sizes only. Otherwise a remap in which each new pore's non-wetting
        saturation is the voxel-weighted mean over the old pores its voxels belonged to (labels of
        ``sim.net`` and of ``net``), so the stored volume is kept.
        """
        if net is sim.net:
            return sim
        if _same_topology(net, sim.net):
            return sim.with_network(net)
        if labels_new is None or labels_old is None:
            raise NetworkError("the network topology changed but no voxel labels were given to remap the state")
        st = sim.state
        sat_old = np.concatenate([np.asarray(st.nw_saturation, float), [0.0]])  # index -1 -> solid: 0
        fill_old = np.concatenate([np.nan_to_num(sim.invasion_time(), nan=np.inf), [np.inf]])
        old = np.asarray(labels_old).ravel()
        new = np.asarray(labels_new).ravel()
        m = new >= 0
        n_new = net.n_pores
        count = np.bincount(new[m], minlength=n_new).astype(float)
        sat = np.bincount(new[m], weights=sat_old[old[m]], minlength=n_new) / np.maximum(count, 1.0)
        first = np.full(n_new, np.inf)
        np.minimum.at(first, new[m], fill_old[old[m]])
        return sim.remap(net, np.clip(sat, 0.0, 1.0), invasion_time=np.where(np.isfinite(first), first, np.nan))

    # ---- the loop -----------------------------------------------------------------------
    def initial_record(self) -> ExchangeRecord:
        """The state at t = 0 (before injection), as a record."""
        U = self.model.expand(self.u, 0.0)
        return self._record(self.sim.state, U, np.zeros_like(U), StageClock(), 0, 0.0, None)

    def steps(self) -> Iterator[ExchangeRecord]:
        """Advance exchange step by exchange step to ``t_end``, yielding a record after each."""
        cc = self.problem.case.coupling
        while self.step_index < self.n_steps:
            t_wall = time.perf_counter()
            t0 = self.t
            t1 = min(self.t_end, (self.step_index + 1) * self.dt)
            dt = t1 - t0
            stages = ("fluid", "interface", "solid", "update")
            clock = StageClock(dict.fromkeys(stages, 0.0), dict.fromkeys(stages, 0.0))
            # the start-of-step load is the one the solid carried at t0: the pressures of the
            # network and interface of t0, even when a re-extraction below changes the topology
            F0 = self.interface.nodal_forces(_pressure(self.sim.state))
            sim_start = self.sim
            U_start = self.model.expand(self.u, t0)
            U_iter = None
            omega, r_prev = 1.0, None
            res_hist: list[float] = []
            omega_hist: list[float] = []
            net_k, itf_k, lab_k, ea = self.network, self.interface, self.labels, None
            reextract = self.problem.case.network.update == "reextract"
            nc = self.problem.case.network
            n_max = max(cc.subiterations, nc.precoupling_max_iter if reextract else 1)
            ea_hist: list[float] = []
            n_iter = 0
            while True:
                n_iter += 1
                with clock("fluid"):
                    sim = sim_start if n_max == 1 else sim_start.with_network(self.network)
                    sim = self._carry(sim, net_k, self.labels, lab_k)
                    lab_sim = lab_k
                    later = sorted((set(self.load_times(t0, dt)) | {t1}) - {t0})
                    try:
                        pressures = {s: _pressure(sim.advance_to(s)) for s in later}
                    except _SOLVER_FAILURES as exc:
                        raise _solver_failure(exc, t0, "fluid") from exc
                with clock("interface"):
                    forces = {t0: F0} | {s: itf_k.nodal_forces(P) for s, P in pressures.items()}
                    # outputs are drawn on the vertices: the P1 split of a P2 operator's load
                    F1 = forces[t1] if itf_k.vertex_operator is None else itf_k.vertex_forces(pressures[t1])
                with clock("solid"):
                    u1, v1 = self._solid_step(self.u, self.v, t0, dt, forces)
                    U1 = self.model.expand(u1, t1)
                if cc.subiterations > 1:
                    base = U_start if U_iter is None else U_iter
                    r = U1 - base
                    if cc.relaxation == "aitken":
                        omega = aitken_omega(omega, r, r_prev)
                    res_hist.append(float(np.linalg.norm(r)) / max(float(np.linalg.norm(U1)), 1e-300))
                    U_iter, r_prev = base + omega * r, r
                    omega_hist.append(float(omega))
                    U_use = U_iter
                else:
                    U_use = U1
                with clock("update"):
                    net_prev = net_k
                    net_k, itf_k, lab_k, _ = self._update_network(U_use)
                    if reextract:  # the paper's pre-coupling measure between successive re-extractions (eq. 3.3)
                        ea_hist.append(mean_size_change(net_prev, net_k))
                disp_ok = cc.subiterations == 1 or res_hist[-1] < cc.subiteration_tol
                ea_ok = not reextract or ea_hist[-1] <= nc.precoupling_tol
                if disp_ok and ea_ok:
                    break
                if n_iter >= n_max:
                    what = "fluid-solid sub-iterations" if not disp_ok else "pre-coupling re-extractions"
                    hist = res_hist if not disp_ok else ea_hist
                    raise ConvergenceError(
                        f"{what} did not converge in {n_iter} iterations at t = {t1:g} s (last change "
                        f"{hist[-1]:.3g}); raise coupling.subiterations / network.precoupling_max_iter, use "
                        "relaxation = 'aitken', or a smaller exchange_dt", hist)
            ea = ea_hist[-1] if ea_hist else None
            self.u, self.v, self.t = u1, v1, t1
            with clock("update"):
                self.sim = self._carry(sim, net_k, lab_sim, lab_k)
                self.network, self.interface, self.labels = net_k, itf_k, lab_k
            self.step_index += 1
            rec = self._record(self.sim.state, U1, F1, clock, self.step_index, time.perf_counter() - t_wall,
                               (n_iter, res_hist[-1] if res_hist else 0.0, ea, len(ea_hist)))
            rec = dataclasses.replace(rec, residual_history=tuple(res_hist), relaxation_history=tuple(omega_hist),
                                      precoupling_history=tuple(ea_hist))
            for total, part in ((self.seconds, rec.seconds), (self.cpu_seconds, rec.cpu_seconds)):
                for key, val in part.items():
                    total[key] = total.get(key, 0.0) + val
            yield rec

    def _record(self, state: FlowState, U, F, clock: StageClock, step, wall, sub) -> ExchangeRecord:
        with clock("stress"):
            sigma = element_cauchy(self.model, self.u, self.t)
            vm = nodal_average(self.model.mesh, von_mises(sigma))
        with clock("permeability"):
            k = absolute_permeability(self.network, self.problem.case.image.axis).k_m2
        P = _pressure(state)
        n_sub, res, ea, n_pre = sub if sub else (0, 0.0, None, 0)
        c = self.sim.counters
        row = {
            "step": step, "time_s": self.t, "sw": state.sw,
            "inlet_pressure_Pa": state.inlet_pressure,
            "capillary_pressure_Pa": state.inlet_pressure - OUTLET_PRESSURE,
            "max_pore_pressure_Pa": float(P.max(initial=0.0)),
            "total_pore_force_N": float(np.linalg.norm(F, axis=1).sum()),
            "max_displacement_m": float(np.linalg.norm(U, axis=1).max(initial=0.0)),
            "max_von_mises_Pa": float(vm.max(initial=0.0)), "permeability_m2": k,
            "mean_pore_radius_m": float(np.mean(self.network.pore_radius)),
            "n_events": c["n_events"], "n_solves": c["n_solves"], "mass_balance_error": state.mass_balance_error,
            "load_balance_error": self.interface.load_balance_error(P), "subiterations": n_sub,
            "coupling_residual": res, "precoupling_iterations": n_pre,
            "precoupling_Ea": float("nan") if ea is None else ea, "wall_s": wall,
        }
        return ExchangeRecord(step, self.t, state, self.network, U, vm, F, row, dict(clock.wall),
                              cpu_seconds=dict(clock.cpu))

    # ---- checkpoints --------------------------------------------------------------------
    def checkpoint(self) -> tuple[dict, dict]:
        """(arrays, metadata) that :meth:`restore` turns back into this run, exactly."""
        arrays = {"u": self.u, "v": self.v, "labels": self.labels}
        meta = {"format": CHECKPOINT_FORMAT, "step_index": self.step_index, "t": self.t, "seconds": self.seconds,
                "cpu_seconds": self.cpu_seconds, "n_extractions": self.n_extractions,
                "n_extractions_reused": self.n_extractions_reused, "update_seconds": self.update_seconds,
                "update_cpu_seconds": self.update_cpu_seconds}
        # plain arrays only (no pickles: a checkpoint from someone else must not run code)
        simulator_state(self.sim, "sim", arrays, meta)
        meta["network_is_sim_network"] = self.network is self.sim.net
        if not meta["network_is_sim_network"]:
            plain.put_dataclass("network", self.network, arrays, meta)
        plain.put_dataclass("interface", self.interface, arrays, meta)
        # where the reused factorisations were built (restore rebuilds the same matrices)
        if self._static_lu_at is not None:
            arrays["static_lu_u"] = self._static_lu_at[0]
            meta["static_lu_t"] = self._static_lu_at[1]
        if self._tdg_system.pin is not None:  # restored, not stepped yet: still the same tangent
            at, dt = self._tdg_system.pin, self._tdg_pin_dt
        elif self._stepper is not None and self._tdg_system.last is not None and not self._tdg_stale:
            at, dt = self._tdg_system.last, self._stepper.dt
        else:
            at = dt = None
        if at is not None:
            arrays["tdg_tangent_u"] = at[0]
            meta["tdg_tangent_t"], meta["tdg_tangent_dt"] = at[1], dt
        return arrays, meta

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
        if meta.get("format") != CHECKPOINT_FORMAT:
            raise ValueError(f"checkpoint format {meta.get('format')!r}, this porefsi reads {CHECKPOINT_FORMAT}")
        run = cls(problem, reuse_extractions=reuse_extractions)
        run.u = np.array(arrays["u"], dtype=float)
        run.v = np.array(arrays["v"], dtype=float)
        if run.u.shape != (run.model.n_dofs,) or run.v.shape != run.u.shape:
            raise ValueError(f"displacements of {run.u.size} dofs, the solid model has {run.model.n_dofs}")
        run.labels = np.array(arrays["labels"])
        run.sim = simulator_from_state("sim", arrays, meta)
        run.network = run.sim.net if meta["network_is_sim_network"] else \
            Network(**plain.get_fields("network", arrays, meta))
        run.interface = Interface(**plain.get_fields("interface", arrays, meta))
        run.step_index = int(meta["step_index"])
        run.t = float(meta["t"])
        run.seconds = dict(meta["seconds"])
        run.cpu_seconds.update(meta.get("cpu_seconds", {}))
        run.n_extractions = int(meta.get("n_extractions", 0))
        run.n_extractions_reused = int(meta.get("n_extractions_reused", 0))
        run.update_seconds.update(meta.get("update_seconds", {}))
        run.update_cpu_seconds.update(meta.get("update_cpu_seconds", {}))
        if "static_lu_u" in arrays:
            run._static_lu_at = (np.array(arrays["static_lu_u"], dtype=float), float(meta["static_lu_t"]))
        if "tdg_tangent_u" in arrays:  # the stepper's first tangent is the checkpointed run's
            run._tdg_system.pin = (np.array(arrays["tdg_tangent_u"], dtype=float), float(meta["tdg_tangent_t"]))
            run._tdg_pin_dt = float(meta["tdg_tangent_dt"])
        return run
