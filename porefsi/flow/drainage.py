r"""Dynamic two-phase drainage on a pore network (DPN): single-pressure, pore-filling events.

A non-wetting fluid is injected at a constant rate (or constant pressure) through a virtual inlet
node joined to the pores on the low face of ``axis``; the wetting fluid leaves through a virtual
outlet node at P = 0 joined to the pores on the high face. Spherical pore bodies hold the
saturation; throat conduits (pore part - cylinder - pore part, in series, each segment with the
viscosity of the fluid in it) give the conductances. See ``docs/drainage.md`` for the model, its
deviations from the seed paper and its validity limits.

.. math::

    Q_{ij} = g_{ij}\,(P_i - P_j - P_{c,b,j}), \qquad
    g_{ij} = \Big(\sum_k \mu_k h_k\Big)^{-1}, \qquad
    V_j \frac{dS_j}{dt} = \sum_i Q_{ij}

for a meniscus advancing into pore ``j``; a pinned meniscus from a non-wetting pore ``i`` enters
``j`` once ``P_i - P_j >= max(P_e,ij, P_c,b,j)``. The time step is the smallest pore filling time.

References
----------
.. [1] Aker, E., Måløy, K. J., Hansen, A., Batrouni, G. G. (1998). A two-dimensional network
   simulator for two-phase flow in porous media. Transp. Porous Media 32, 163-186.
.. [2] Joekar-Niasar, V., Hassanizadeh, S. M. (2012). Analysis of fundamentals of two-phase flow
   in porous media using dynamic pore-network models: a review. Crit. Rev. Environ. Sci.
   Technol. 42, 1895-1976.
"""

from __future__ import annotations

import dataclasses
import time as _time

import numpy as np

from porefsi.errors import InputError
from porefsi.flow import _drainage_checkpoint as _ckpt
from porefsi.flow._drainage_options import (
    DEFAULT_BACKOFF,
    DEFAULT_BLOCK_PIVOTS,
    DEFAULT_FLUX_TOLERANCE,
    DEFAULT_PREDICT_FILLS,
    SCHEMES,
    DrainageOptions,
    RunControl,
    options_from,
)
from porefsi.flow._drainage_simulator import HISTORY_COLUMNS, OUTLET_PRESSURE, DrainageSimulator
from porefsi.flow.fluids import PAPER_FLUIDS, Fluids
from porefsi.flow.state import DrainageResult
from porefsi.image.voxel_image import axis_index
from porefsi.network.network import Network

#: Options added after checkpoints with the options object existed: left out of a run's
#: fingerprint at these (their defaults, the earlier behaviour), so those checkpoints still resume.
_LATER_KNOBS = {"predict_fills": DEFAULT_PREDICT_FILLS, "flux_tolerance": DEFAULT_FLUX_TOLERANCE,
                "backoff": DEFAULT_BACKOFF, "block_pivots": DEFAULT_BLOCK_PIVOTS}

__all__ = ["DrainageSimulator", "DrainageResult", "DrainageOptions", "RunControl", "simulate_drainage", "PAPER_RATE",
           "PAPER_T_END", "HISTORY_COLUMNS", "OUTLET_PRESSURE", "SCHEMES", "DEFAULT_SCHEME"]

#: The paper's injection rate, m³/s, and injection time, s (the defaults of :class:`DrainageOptions`).
PAPER_RATE = DrainageOptions.rate
PAPER_T_END = DrainageOptions.t_end

#: The scheme the command line and the case file use unless told otherwise.
DEFAULT_SCHEME = DrainageOptions.scheme


def simulate_drainage(net: Network, fluids: Fluids = PAPER_FLUIDS, options: DrainageOptions | None = None, *,
                      axis="x", times=None, stop_at_breakthrough: bool = False, run: RunControl | None = None,
                      **overrides) -> DrainageResult:
    """Run a drainage from t = 0 to ``options.t_end`` and collect the time series and snapshots.

    Parameters
    ----------
    net, fluids, axis
        As for :class:`DrainageSimulator`.
    options : DrainageOptions, optional
        Rate or inlet pressure, end time ``t_end`` (s, default the paper's 20 s), scheme and
        pressure solver (default: the paper's set-up, exact scheme).
    times : array_like of float, optional
        Snapshot times, s, within (0, t_end]; the final state is always included.
    stop_at_breakthrough : bool
        Stop at the first breakthrough instead of ``t_end``.
    run : RunControl, optional
        Checkpoints, resume and progress callbacks (they never change the result).
    **overrides
        Fields of :class:`DrainageOptions` or of :class:`RunControl` by name (the keyword form,
        e.g. ``simulate_drainage(net, rate=1e-13, t_end=0.5)``), replacing those given.

    Returns
    -------
    DrainageResult

    Raises
    ------
    InputError
        Bad times or rates; ``resume`` without a checkpoint or with one of another run.

    Examples
    --------
    >>> import numpy as np
    >>> from porefsi.network.lattice import lattice_network
    >>> net = lattice_network((6, 6, 1), 1e-4, np.random.default_rng(0))
    >>> res = simulate_drainage(net, options=DrainageOptions(rate=1e-12, t_end=0.5), times=[0.25])
    >>> [round(s.t, 6) for s in res.snapshots], bool(res.final.mass_balance_error < 1e-12)
    ([0.25, 0.5], True)
    >>> rigorous = DrainageOptions(rate=1e-12, t_end=0.5, scheme="adaptive", tie_tolerance=0.0)
    >>> fast = simulate_drainage(net, options=rigorous)  # certified batches only: the exact events
    >>> bool(np.array_equal(fast.invasion_time, res.invasion_time, equal_nan=True))
    True
    """
    options, run_kw = options_from(options, overrides, run_ok=True)
    run = dataclasses.replace(run or RunControl(), **run_kw)
    t_end = options.t_end
    ts = np.unique(np.asarray([] if times is None else times, dtype=float).ravel())
    if ts.size and (not np.all(np.isfinite(ts)) or ts[0] <= 0 or ts[-1] > t_end):
        raise InputError(f"snapshot times must lie in (0, t_end={t_end:g}] s, got {ts.min():g}..{ts.max():g}")
    if not isinstance(net, Network) or not isinstance(fluids, Fluids):
        raise InputError(f"simulate_drainage needs a porefsi Network and Fluids, got {type(net).__name__} and "
                         f"{type(fluids).__name__}")
    key = None
    if run.checkpoint is not None:
        settings = dict(times=tuple(ts.tolist()), axis=axis_index(axis),
                        stop_at_breakthrough=bool(stop_at_breakthrough),
                        options=tuple(sorted((k, v) for k, v in dataclasses.asdict(options).items()
                                             if not (k in _LATER_KNOBS and v == _LATER_KNOBS[k]))))
        key = _ckpt.fingerprint(net, fluids, settings)
    driver = _Driver(run, key)
    if run.resume:
        d = _ckpt.load(run.checkpoint, key)
        sim, snaps, k, driver.before = d["sim"], d["snaps"], d["k"], d["seconds"]
    else:
        sim = DrainageSimulator(net, fluids, options, axis=axis)
        snaps, k = [], 0
    driver.advance(sim, [*ts.tolist(), t_end], snaps, k, stop_at_breakthrough)
    final = sim.state
    if not snaps or snaps[-1].t != final.t:
        snaps.append(final)
    if run.checkpoint is not None:
        driver.save(sim, snaps, len(ts) + 1)
    return DrainageResult(
        history=sim.history(), snapshots=snaps, invasion_time=sim.invasion_time(),
        breakthrough_time=sim.breakthrough_time, breakthrough_sw=sim._engine.sw_breakthrough, final=final,
        counters=sim.counters, n_dropped=sim.n_dropped, seconds=driver.seconds(),
    )


class _Driver:
    """Advances a simulator through its target times with checkpoints, reports and deferred Ctrl-C."""

    def __init__(self, run: RunControl, key: str | None):
        self.run, self.key = run, key
        self.before = 0.0  # seconds of the processes before a resume
        self.t0 = self.last = self.last_report = _time.perf_counter()

    def seconds(self) -> float:
        return self.before + _time.perf_counter() - self.t0

    def save(self, sim, snaps, k):
        secs = self.seconds()
        _ckpt.save(self.run.checkpoint, self.key, dict(sim=sim, snaps=snaps, k=k, seconds=secs))
        self.last = _time.perf_counter()
        if self.run.progress is not None:
            self.run.progress(sim, secs)

    def _between_events(self, sim, snaps, k, interrupted):
        run = self.run
        if run.report is not None and _time.perf_counter() - self.last_report >= run.report_every:
            self.last_report = _time.perf_counter()
            run.report(sim, self.seconds())
        if run.checkpoint is not None and (interrupted() or _time.perf_counter() - self.last >= run.checkpoint_every):
            self.save(sim, snaps, k)
            if interrupted():
                raise KeyboardInterrupt(f"drainage interrupted at t = {sim.t:.6g} s; saved to {run.checkpoint}: "
                                        "continue with resume=True (command line: --resume)")

    def advance(self, sim, targets, snaps, k, stop_at_breakthrough) -> None:
        """Step ``sim`` through ``targets[k:]`` (snapshot times, then the end), appending snapshots."""
        e = sim._engine
        n_snap = len(targets) - 1
        self.last = self.last_report = _time.perf_counter()
        if self.run.report is not None:  # the run has started (inputs and checkpoint checked)
            self.run.report(sim, self.seconds())
        stopped = False
        with _ckpt.deferred_interrupt(self.run.checkpoint is not None) as interrupted:  # Ctrl-C: save, then stop
            while k < len(targets):
                t = targets[k]
                while e.t < t and not stopped:
                    e.step(t)
                    stopped = stop_at_breakthrough and not np.isnan(e.t_breakthrough)
                    self._between_events(sim, snaps, k, interrupted)
                if k < n_snap:  # a snapshot time (at breakthrough, when stopping there, the final state only)
                    if stopped:
                        k = n_snap
                        continue
                    snaps.append(sim.state)
                k += 1
