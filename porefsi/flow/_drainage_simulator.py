"""The drainage simulator: a network advanced event by event (private; public via :mod:`porefsi.flow.drainage`).

See :mod:`porefsi.flow.drainage` for the model and :class:`DrainageSimulator` for the API.
"""

from __future__ import annotations

import math

import numpy as np

from porefsi.errors import InputError
from porefsi.flow._drainage_engine import Engine
from porefsi.flow._drainage_graph import build_graph
from porefsi.flow._drainage_options import DrainageOptions, options_from
from porefsi.flow._drainage_state import make_state
from porefsi.flow.fluids import PAPER_FLUIDS, Fluids
from porefsi.flow.state import FlowState
from porefsi.image.voxel_image import axis_index
from porefsi.network.network import Network

__all__ = ["DrainageSimulator", "HISTORY_COLUMNS", "OUTLET_PRESSURE", "ROW_COLUMNS"]

#: Pressure of the virtual outlet node, Pa (gauge): 0 by construction (the node is eliminated from
#: the pressure system), so the capillary pressure inlet minus outlet equals the inlet pressure.
OUTLET_PRESSURE = 0.0

# what the engine stores per event (checkpoints pickle these rows: keep their layout)
ROW_COLUMNS = ("time_s", "injected_m3", "sw", "inlet_pressure_pa", "w_outflow_m3_s", "nw_outflow_m3_s",
                "n_events", "n_solves", "mass_balance_error", "n_full")

#: Columns of :attr:`DrainageResult.history` (one row per event): the stored ones plus
#: ``capillary_pressure_pa`` = inlet minus outlet node pressure (:data:`OUTLET_PRESSURE`).
HISTORY_COLUMNS = ("time_s", "injected_m3", "sw", "inlet_pressure_pa", "capillary_pressure_pa", "w_outflow_m3_s",
                   "nw_outflow_m3_s", "n_events", "n_solves", "mass_balance_error", "n_full")


def _make_engine(graph, rate, inlet_pressure, opts: dict) -> Engine:
    """The event engine of the scheme named in ``opts`` (:meth:`DrainageOptions.engine_options`)."""
    o = dict(opts)
    if o.pop("scheme", "exact") == "adaptive":
        from porefsi.flow._drainage_adaptive import AdaptiveEngine, AdaptiveTuning

        tuning = AdaptiveTuning(
            local_solves=o.pop("local_solves"), hops=o.pop("hops"), local_menisci=o.pop("local_menisci"),
            tie_tolerance=o.pop("tie_tolerance", 0.0), predict_fills=o.pop("predict_fills", 0),
            flux_tolerance=o.pop("flux_tolerance", 0.0), backoff=o.pop("backoff", 32),
            block_pivots=o.pop("block_pivots", "off") == "on")
        return AdaptiveEngine(graph, rate, inlet_pressure, **o, tuning=tuning)
    return Engine(graph, rate, inlet_pressure, **o)


class DrainageSimulator:
    """Time-resolved drainage of a network, advanced on demand (for coupling to a solid).

    Parameters
    ----------
    net : Network
        The pore network. Pores not in a group joining the two faces of ``axis`` are dropped
        (``n_dropped`` says how many).
    fluids : Fluids
        Viscosities, interfacial tension and contact angle (default: the paper's).
    options : DrainageOptions, optional
        Boundary condition (``rate`` m³/s, or ``inlet_pressure`` Pa, gauge, outlet at 0), scheme
        and pressure solver (``t_end`` is not used here). 'lowrank' (the 'auto' choice above 400
        unknowns) reuses one sparse LU across events through low-rank (Sherman–Morrison–Woodbury)
        updates of the rows that changed, checked by its residual: a direct solve to round-off.
        ``skip_solves`` skips the solve after a quasi-static jump when a resistance bound proves
        that no other meniscus can move while the invaded pore fills (identical outcome, the
        inlet pressure of such events is recorded as NaN). ``max_active_set_iter`` caps the
        active-set iterations of an event (exceeding it raises
        :class:`~porefsi.errors.ConvergenceError` with the violation history).
    axis : {'x', 'y', 'z'}
        Flow direction: inlet on its low face, outlet on its high face.
    **overrides
        Fields of :class:`DrainageOptions` by name, replacing those of ``options`` (the keyword
        form, e.g. ``DrainageSimulator(net, rate=1e-12, scheme="adaptive")``).

    Raises
    ------
    InputError
        Non-positive rate, non-finite inlet pressure, an unknown ``solver`` or option name.
    NetworkError
        No inlet or outlet pores on the axis, or no connected path between them.

    Examples
    --------
    >>> import numpy as np
    >>> from porefsi.network.lattice import lattice_network
    >>> net = lattice_network((6, 6, 1), 1e-4, np.random.default_rng(0))
    >>> sim = DrainageSimulator(net, rate=1e-12)
    >>> state = sim.advance_to(0.5)
    >>> bool(0.0 <= state.nw_saturation.min() <= state.nw_saturation.max() <= 1.0)
    True
    """

    def __init__(self, net: Network, fluids: Fluids = PAPER_FLUIDS, options: DrainageOptions | None = None, *,
                 axis="x", _keep=None, **overrides):
        if not isinstance(net, Network):
            raise InputError(f"net must be a porefsi Network, got {type(net).__name__}")
        if not isinstance(fluids, Fluids):
            raise InputError(f"fluids must be a porefsi Fluids, got {type(fluids).__name__}")
        options, _ = options_from(options, overrides)
        self.net = net
        self.fluids = fluids
        self.axis = axis_index(axis)
        self.options = options
        self.rate = options.rate if options.inlet_pressure is None else None
        self.inlet_pressure_bc = options.inlet_pressure
        self.graph = build_graph(net, fluids, self.axis, keep=_keep)
        self._opts = options.engine_options(self.graph.n, self.capillary_number)
        self._engine = _make_engine(self.graph, self.rate, self.inlet_pressure_bc, self._opts)

    # -- sizes and counters ----------------------------------------------------------------
    @property
    def capillary_number(self) -> float:
        """Ca = mu_n Q / (sigma A), A the network's extent across ``axis`` (NaN at constant pressure)."""
        if self.rate is None:
            return math.nan
        area = float(np.prod(np.delete(np.asarray(self.net.extent, dtype=float), self.axis)))
        return self.fluids.capillary_number(self.rate, area) if area > 0 else math.inf

    @property
    def n_dropped(self) -> int:
        """Number of pores dropped because they do not connect the inlet face to the outlet face."""
        return self.net.n_pores - self.graph.n

    @property
    def t(self) -> float:
        """Current time, s."""
        return self._engine.t

    @property
    def counters(self) -> dict:
        """Event and solve counts: events, fills, jumps, solves, skipped solves, AMG setups, ...

        The adaptive scheme adds ``n_certified_fills`` (quasi-static fills certified without a
        solve), ``n_local_solves``, ``n_global_solves``, and for the flux-split predictor
        ``n_predicted_fills`` (accepted), ``n_predict_batches`` and ``n_predict_rollbacks``.
        """
        e = self._engine
        out = dict(n_events=e.n_events, n_fills=e.n_fills, n_jumps=e.n_jumps, n_solves=e.solver.n_solves,
                   n_skipped_solves=e.n_skipped, n_active_set_changes=e.n_changes,
                   max_active_set_iterations=e.max_iter_seen, n_solver_setups=e.solver.n_setups,
                   cg_iterations=e.solver.iterations)
        if hasattr(e, "n_certified"):
            out.update(n_certified_fills=e.n_certified, n_local_solves=e.n_local, n_global_solves=e.n_global,
                       n_predicted_fills=getattr(e, "n_predicted", 0),
                       n_predict_batches=getattr(e, "n_predict_batches", 0),
                       n_predict_rollbacks=getattr(e, "n_rollbacks", 0),
                       n_block_pivots=getattr(e, "n_block_pivots", 0), n_block_undos=getattr(e, "n_block_undos", 0))
        return out

    @property
    def breakthrough_time(self) -> float:
        """Time the first outlet pore became full, s (NaN before)."""
        return self._engine.t_breakthrough

    # -- stepping --------------------------------------------------------------------------
    def advance_to(self, t: float, stop_at_breakthrough: bool = False) -> FlowState:
        """Advance to time ``t`` (s) and return the state there (pressures solved if stale).

        Raises
        ------
        InputError
            ``t`` earlier than the current time or not finite.
        """
        t = float(t)
        e = self._engine
        if not math.isfinite(t) or t < e.t:
            raise InputError(f"cannot advance to t = {t!r} s: the simulation is at t = {e.t:.6g} s; "
                             "times must be finite and non-decreasing")
        while e.t < t:
            e.step(t)
            if stop_at_breakthrough and not np.isnan(e.t_breakthrough):
                break
        return self.state

    def events(self, t_end: float):
        """Generator over events up to ``t_end``: yields ``t`` after each event (state via :attr:`state`)."""
        t_end = float(t_end)
        e = self._engine
        while e.t < t_end:
            e.step(t_end)
            yield e.t

    @property
    def state(self) -> FlowState:
        """The current :class:`FlowState` (solves for the pressure if a skipped solve left it stale)."""
        e = self._engine
        e.ensure_pressure()
        return make_state(self.net, self.graph, e)

    def with_network(self, net: Network) -> DrainageSimulator:
        """Carry the state onto ``net``: same pores and throats, new radii, lengths and volumes.

        Saturations are kept, so each pore's non-wetting volume scales with its volume; the
        non-wetting volume this creates (or removes, if pores shrink) is booked as
        ``deformation_volume`` so the mass balance stays exact. Nothing can overflow: a full pore
        stays full. Entry pressures and conductances follow the new radii; the field is re-solved
        at the next event.

        Raises
        ------
        InputError
            ``net`` has different pores or throats.
        """
        old = self.net
        if net.n_pores != old.n_pores or not np.array_equal(net.throat_conns, old.throat_conns) or \
                not np.array_equal(net.pore_faces, old.pore_faces):
            raise InputError("with_network needs the same pores, throats and face labels (only sizes may "
                             "change); build a new DrainageSimulator for a different network")
        new = DrainageSimulator.__new__(DrainageSimulator)
        new.net, new.fluids, new.axis = net, self.fluids, self.axis
        new.rate, new.inlet_pressure_bc, new._opts = self.rate, self.inlet_pressure_bc, self._opts
        new.options = self.options
        new.graph = build_graph(net, self.fluids, self.axis, keep=self.graph.keep)
        e0 = self._engine
        e = _make_engine(new.graph, self.rate, self.inlet_pressure_bc, self._opts)
        for name in ("full", "trapped", "inv", "closed", "parent", "P", "fill_time", "edge_time"):
            setattr(e, name, getattr(e0, name).copy())
        for name in ("t", "injected", "out_n", "out_w", "t_breakthrough", "sw_breakthrough", "n_events",
                     "n_fills", "n_jumps", "n_skipped", "n_changes", "max_iter_seen", "rows"):
            v = getattr(e0, name)
            setattr(e, name, list(v) if isinstance(v, list) else v)
        e._stamp, e._mark = e0._stamp.copy(), e0._mark.copy()
        e.solver.n_solves = e0.solver.n_solves
        sat = e0.vn / e0.g.vol
        e.vn = np.where(e0.full, new.graph.vol, sat * new.graph.vol)
        e.deformation = e0.deformation + float(e.vn.sum() - e0.vn.sum())
        e.p_valid = False
        e.flux_valid = False
        # non-wetting path resistances along the invasion tree, in fill order
        for x in np.argsort(np.where(e.full, e.fill_time, np.inf), kind="stable")[:int(e.full.sum())]:
            pe = e.parent[x]
            g = new.graph
            u = g.a[pe] if g.b[pe] == x else g.b[pe]
            e.tree_res[x] = e.tree_res[u] + 1.0 / g.gn[pe]
        if hasattr(e, "dn_full"):  # adaptive: non-wetting distances from the new conductances
            e.dn_full = -1
        new._engine = e
        return new

    def remap(self, net: Network, nw_saturation, invasion_time=None, full_tol: float = 1e-9) -> DrainageSimulator:
        """Carry the state onto a network of a *different* topology, given its pore saturations.

        The coupling re-extracts the network from the deformed image; the caller computes each new
        pore's non-wetting saturation by volume-weighted voxel overlap of the old and new label
        images. This builds a consistent engine state from those saturations (full pores, the
        non-wetting cluster connected to the inlet, filling pores attached to it, invaded throats,
        trapped wetting clusters, the invasion tree) and keeps time, injected and outflow volumes,
        breakthrough and counters. The change of stored non-wetting volume is booked as
        ``deformation_volume``, so the mass balance stays exact. See ``docs/drainage.md`` ("Remap")
        for the construction and what is approximate.

        Parameters
        ----------
        net : Network
            The new network (any topology; pores not spanning the axis are dropped).
        nw_saturation : array_like of float, shape (net.n_pores,)
            Non-wetting saturation of each new pore, in [0, 1] (values within 1e-9 outside are clipped).
        invasion_time : array_like of float, shape (net.n_pores,), optional
            Time each new pore became full, s (e.g. the earliest overlapping old pore's); full pores
            without one get the current time.
        full_tol : float
            Saturations ``>= 1 - full_tol`` count as full.

        Returns
        -------
        DrainageSimulator
            A new simulator (this one is unchanged); ``last_remap`` holds the counts of full,
            filling and stranded pores and the stranded non-wetting volume (m³) that was removed.

        Raises
        ------
        InputError
            Wrong shape, non-finite or out-of-range saturations.
        NetworkError
            ``net`` has no spanning path along the axis.
        """
        from porefsi.flow._drainage_remap import engine_arrays_from_saturation

        if not isinstance(net, Network):
            raise InputError(f"net must be a porefsi Network, got {type(net).__name__}")
        sat = np.asarray(nw_saturation, dtype=float)
        if sat.shape != (net.n_pores,):
            raise InputError(f"nw_saturation needs shape ({net.n_pores},) (one value per pore of the new "
                             f"network), got {sat.shape}")
        if not np.all(np.isfinite(sat)) or sat.min(initial=0.0) < -1e-9 or sat.max(initial=0.0) > 1 + 1e-9:
            raise InputError("nw_saturation must be finite and within [0, 1], got range "
                             f"[{np.min(sat):.6g}, {np.max(sat):.6g}]; compute it as overlap volume / pore volume")
        sat = np.clip(sat, 0.0, 1.0)
        e0 = self._engine
        new = DrainageSimulator.__new__(DrainageSimulator)
        new.net, new.fluids, new.axis = net, self.fluids, self.axis
        new.rate, new.inlet_pressure_bc, new._opts = self.rate, self.inlet_pressure_bc, self._opts
        new.options = self.options
        new.graph = g = build_graph(net, self.fluids, self.axis)
        e = _make_engine(g, self.rate, self.inlet_pressure_bc, self._opts)
        arr = engine_arrays_from_saturation(g, sat[g.keep], full_tol=full_tol)
        for name in ("vn", "full", "trapped", "inv", "parent", "tree_res"):
            setattr(e, name, arr[name])
        for name in ("t", "injected", "out_n", "out_w", "t_breakthrough", "sw_breakthrough", "n_events",
                     "n_fills", "n_jumps", "n_skipped", "n_changes", "max_iter_seen", "rows"):
            v = getattr(e0, name)
            setattr(e, name, list(v) if isinstance(v, list) else v)
        e.solver.n_solves = e0.solver.n_solves
        ft = np.full(net.n_pores, e.t) if invasion_time is None else np.asarray(invasion_time, dtype=float)
        if ft.shape != (net.n_pores,):
            raise InputError(f"invasion_time needs shape ({net.n_pores},), got {ft.shape}")
        ft = ft[g.keep]
        e.fill_time = np.where(e.full, np.where(np.isfinite(ft), np.minimum(ft, e.t), e.t), np.nan)
        e.edge_time = np.where(e.inv, e.t, np.nan)
        if np.isnan(e.t_breakthrough) and (e.full & g.is_outlet).any():
            e.t_breakthrough, e.sw_breakthrough = e.t, e.sw()
        e.deformation = e0.deformation + float(e.vn.sum() - e0.vn.sum())
        e.P = np.zeros(g.n + 1)
        e.p_valid = False
        e.flux_valid = False
        new._engine = e
        new.last_remap = {k: arr[k] for k in ("n_full", "n_filling", "n_stranded", "stranded_volume")}
        return new

    def history(self) -> dict:
        """Time series so far, one row per event: dict of arrays keyed by :data:`HISTORY_COLUMNS`.

        ``capillary_pressure_pa`` is the inlet minus the outlet node pressure; the outlet is at
        :data:`OUTLET_PRESSURE` = 0 by construction, so it equals ``inlet_pressure_pa`` (NaN where
        a skipped solve left the pressure undetermined).
        """
        rows = np.asarray(self._engine.rows, dtype=float).reshape(-1, len(ROW_COLUMNS))
        h = {k: rows[:, i].copy() for i, k in enumerate(ROW_COLUMNS)}
        h["capillary_pressure_pa"] = h["inlet_pressure_pa"] - OUTLET_PRESSURE
        return {k: h[k] for k in HISTORY_COLUMNS}

    def invasion_time(self) -> np.ndarray:
        """Time each pore became full of non-wetting fluid, s, shape (Np,) (NaN if never)."""
        out = np.full(self.net.n_pores, np.nan)
        out[self.graph.keep] = self._engine.fill_time
        return out

    def throat_invasion_time(self) -> np.ndarray:
        """Time the non-wetting fluid first passed each throat, s, shape (Nt,) (NaN if never)."""
        g = self.graph
        out = np.full(self.net.n_throats, np.nan)
        m = g.throat >= 0
        out[g.throat[m]] = self._engine.edge_time[m]
        return out
