"""Event engine of the dynamic drainage model (private; the public API is :mod:`porefsi.flow.drainage`).

State: non-wetting volume per pore ``vn`` (full when ``vn == vol``), ``trapped`` pores, and per
edge ``inv`` (non-wetting fluid has passed the constriction) and ``closed`` (a meniscus in the
body of a filling pore held still because the field would push it back). Edge kinds follow from
these (see :meth:`Engine.conductances`): non-wetting conduit, active meniscus, pinned meniscus,
wetting conduit. Between two events every flux is constant, so volumes are integrated exactly.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from porefsi.errors import ConvergenceError, NetworkError
from porefsi.flow import _kernels as kern
from porefsi.flow._drainage_graph import DrainageGraph
from porefsi.flow._drainage_solver import PressureSolver

__all__ = ["Engine"]


class Engine:
    """Mutable event engine on a :class:`DrainageGraph` (owned by one simulator; never shared)."""

    def __init__(self, graph: DrainageGraph, rate: float | None, inlet_pressure: float | None,
                 solver: str = "auto", skip_solves: bool = False, max_active_set_iter: int | None = None):
        g = graph
        self.g = g
        self.rate = rate
        self.p_fixed = inlet_pressure
        n, E = g.n, g.n_edges
        self.solver = PressureSolver(n + 1, method=solver)
        self.skip_solves = bool(skip_solves) and rate is not None
        self.max_iter = int(max_active_set_iter) if max_active_set_iter else 4 * E + 10
        self.vn = np.zeros(n)
        self.full = np.zeros(n, dtype=bool)
        self.trapped = np.zeros(n, dtype=bool)
        self.inv = np.zeros(E, dtype=bool)
        self.closed = np.zeros(E, dtype=bool)
        self.parent = np.full(n, -1, dtype=np.int64)
        self.tree_res = np.zeros(n + 1)
        self.P = np.zeros(n + 1)
        self.p_valid = True  # P matches the configuration (all zero at rest)
        self.q = np.zeros(n)
        self.q_out_n = 0.0
        self.q_out_w = 0.0
        self.flux_valid = False
        self.t = 0.0
        self.injected = 0.0
        self.out_n = 0.0
        self.out_w = 0.0
        self.deformation = 0.0
        self.fill_time = np.full(n, np.nan)
        self.edge_time = np.full(E, np.nan)
        self.t_breakthrough = np.nan
        self.sw_breakthrough = np.nan
        self.n_events = self.n_fills = self.n_jumps = self.n_skipped = self.n_changes = 0
        self.max_iter_seen = 0
        self._stamp = np.zeros(1, dtype=np.int64)
        self._mark = np.zeros(n, dtype=np.int64)
        self._dist = None
        self._pred = None
        self._nbr_res = 1.0 / g.gw[g.nbr_edge]
        self._diag_ref = self._wetting_diagonal()
        self._indptr = g.pattern_indptr.astype(g.indices.dtype)  # the pattern with one index dtype (no copies)
        self._ptol = 1e-10 * float(np.max(g.pcb))
        self.rows: list[tuple] = []

    # -- derived edge kinds ----------------------------------------------------------------
    def _node_full(self):
        return np.concatenate([self.full, [True, False]])

    def conductances(self):
        """Edge conductances for the current configuration and the active-meniscus mask.

        Returns ``(cond, men, fa)``, shapes (E,): conductances (m³/(Pa s)), active menisci, and
        whether the edge's ``a`` end is non-wetting (numba kernel ``_edge_states``; its NumPy twin
        is ``tests/reference/drainage_ref.edge_states``).
        """
        g = self.g
        return kern._edge_states((g.a, g.b, g.n), g.inner, g.gn, g.gw, (self.full, self.trapped, self.inv, self.closed))

    def has_open_path(self) -> bool:
        """Whether injected fluid can move: an active meniscus or a non-wetting conduit to the outlet."""
        g = self.g
        return bool(kern._open_path((g.a, g.b, g.n), g.inner, (self.full, self.trapped, self.inv, self.closed)))

    # -- pressure solve --------------------------------------------------------------------
    def _wetting_diagonal(self):
        """Diagonal of the all-wetting pressure matrix (sum of incident wetting conductances), (n + 1,)."""
        g = self.g
        n = g.n
        return (np.bincount(g.a, g.gw, minlength=n + 2) + np.bincount(g.b, g.gw, minlength=n + 2))[:n + 1]

    def solve(self):
        """Solve the pressure field of the current configuration; return (cond, men, fa)."""
        cond, men, fa = self.conductances()
        A, rhs, x = self.assemble(cond, men, fa)
        old = self.P
        nmask = np.concatenate([self.full, [True]]) if self.solver.method in ("split", "hybrid") else None
        P = self.solver.solve(A, rhs, x0=old, hint=lambda: self._hint(x), nmask=nmask)
        P[:self.g.n][self.trapped] = old[:self.g.n][self.trapped]
        self.P = P
        self.p_valid = True
        return cond, men, fa

    def assemble(self, cond, men, fa):
        """Pressure matrix (CSR, the graph's fixed pattern), right-hand side and the active menisci's pores.

        Rows of nodes without a conducting edge are ``d x = 0`` with ``d`` the node's all-wetting
        diagonal (see :meth:`solve`): a node without conducting edges (trapped, or the inlet before
        any meniscus) is decoupled on the scale of the other rows, so the low-rank solver sees no
        large diagonal jump when a node decouples or couples again. Numba kernel ``_assemble``
        (same sums in the same order as its NumPy twin ``tests/reference/drainage_ref.assemble``,
        so the same values to the bit).
        """
        g = self.g
        n = g.n
        if getattr(self, "_diag_ref", None) is None:  # engines pickled before this attribute existed
            self._diag_ref = self._wetting_diagonal()
        const_rate = self.rate is not None
        bc = (float(self.rate) if const_rate else 0.0, 0.0 if const_rate else float(self.p_fixed), const_rate)
        data, rhs, x = kern._assemble((g.a, g.b, n), (g.inner, g.is_in_edge, men, fa), cond, g.pcb,
                                      (g.pos_diag, g.pos_ab, g.pos_ba, g.indices.size), self._diag_ref, bc)
        if getattr(self, "_indptr", None) is None or self._indptr.dtype != g.indices.dtype:
            self._indptr = g.pattern_indptr.astype(g.indices.dtype)  # one index dtype: no copies per call
        A = sp.csr_array((data, g.indices, self._indptr), shape=(n + 1, n + 1))
        return A, rhs, x

    def _hint(self, targets, n_pinned: int = 2):
        """Rows likely to change soon, for the solver to prefetch (cost only, never the answer).

        The pores being filled (``targets``) and the ``n_pinned`` pores behind the pinned menisci
        of lowest threshold (the next invasions at low capillary number), with their neighbours:
        their rows change when those pores become full.
        """
        g = self.g
        fx = self._node_full()
        fa, fb = fx[g.a], fx[g.b]
        pin = np.flatnonzero((fa ^ fb) & g.inner & ~self.inv)
        if pin.size:
            xp = np.where(fa[pin], g.b[pin], g.a[pin])
            ok = ~self.trapped[xp]
            pin, xp = pin[ok], xp[ok]
            if pin.size > n_pinned:
                xp = xp[np.argpartition(g.thr[pin], n_pinned)[:n_pinned]]
        t = np.unique(np.concatenate([targets, xp])) if pin.size else np.unique(targets)
        if t.size == 0:
            return t
        nb = np.concatenate([g.nbr[g.indptr[v]:g.indptr[v + 1]] for v in t])
        h = np.concatenate([t, nb])
        return h[~self.trapped[h]]

    # -- events ----------------------------------------------------------------------------
    def open_edge(self, e: int):
        """Let the meniscus of edge ``e`` advance (first invasion or resumption of a stalled one)."""
        g = self.g
        if not self.inv[e]:
            self.inv[e] = True
            self.edge_time[e] = self.t
            x = g.b[e] if (g.a[e] == g.n or self.full[g.a[e]]) else g.a[e]
            if self.parent[x] < 0:
                self.parent[x] = e
        self.closed[e] = False
        self.n_changes += 1

    def _resolve(self):
        """Establish the fluxes of the current configuration. Returns True for a quasi-static jump."""
        g = self.g
        n = g.n
        if self.rate is not None and not self.has_open_path():
            e, thr = self._cheapest()
            self.open_edge(e)
            self.n_jumps += 1
            # static field: non-wetting at rest at the threshold, wetting at rest at the outlet pressure
            P = np.where(self.trapped, self.P[:n], 0.0)
            P[self.full] = thr
            self.P = np.concatenate([P, [thr]])
            self.p_valid = True
            self.flux_valid = False
            if self.skip_solves:
                self._try_skip(e)
            return True
        blocked = np.zeros(g.n_edges, dtype=bool)
        hist = []
        for it in range(self.max_iter):
            cond, men, fa = self.solve()
            e, ex, kind = kern._most_violated((g.a, g.b, n), (self.full, self.trapped, self.inv, self.closed,
                                                                     blocked), self.P, (g.thr, g.pcb))
            if e < 0 or ex <= self._ptol:
                self.max_iter_seen = max(self.max_iter_seen, it)
                break
            hist.append(float(ex))
            if kind == 1:
                self.open_edge(e)
            else:
                self.closed[e] = True
                blocked[e] = True
                self.n_changes += 1
        else:
            raise ConvergenceError(
                f"active-set resolution did not settle in {self.max_iter} iterations at t = {self.t:.6g} s; "
                "pass a larger max_active_set_iter or report this network", history=hist)
        self._settled_fluxes(cond, men, fa, hist)
        return False

    def _settled_fluxes(self, cond, men, fa, hist) -> None:
        """Meniscus inflows ``q`` and outlet flows of the settled active set, from the solved ``P``."""
        g, n = self.g, self.g.n
        em = np.flatnonzero(men)
        u = np.where(fa[em], g.a[em], g.b[em])
        x = np.where(fa[em], g.b[em], g.a[em])
        f = np.maximum(cond[em] * (self.P[u] - self.P[x] - g.pcb[x]), 0.0)
        self.q = np.bincount(x, f, minlength=n)[:n].astype(float)
        oe = np.flatnonzero(~g.inner)
        fo = cond[oe] * self.P[g.a[oe]]
        self.q_out_n = float(np.sum(np.where(fa[oe], fo, 0.0)))
        self.q_out_w = float(np.sum(np.where(fa[oe], 0.0, fo)))
        if self.rate is not None:
            tot = float(self.q.sum()) + self.q_out_n
            if not tot > 0:
                raise ConvergenceError(f"no non-wetting flux at t = {self.t:.6g} s although fluid is injected",
                                       history=hist)
            s = self.rate / tot  # exact volume bookkeeping (round-off of the solve removed)
            self.q *= s
            self.q_out_n *= s
            self.q_out_w = self.rate - self.q_out_n
        self.flux_valid = True

    def _cheapest(self):
        g = self.g
        zero = np.zeros(g.n + 1)
        nob = np.zeros(g.n_edges, dtype=bool)
        e, ex, kind = kern._most_violated((g.a, g.b, g.n), (self.full, self.trapped, self.inv, self.closed, nob),
                                       zero, (g.thr, g.pcb))
        if e < 0 or kind != 1:
            raise NetworkError(
                f"at t = {self.t:.6g} s the injected fluid can neither advance nor leave the network "
                "(no invadable throat and no path to the outlet)")
        return int(e), float(-ex)

    def _try_skip(self, e: int):
        """Skip the solve after a jump when a bound proves no other meniscus can move (constant rate).

        With one active meniscus (into pore x through e) and no breakthrough, all of Q fills x.
        Non-wetting pressures are at most P_in and wetting pressures at least 0 (maximum principle),
        so a pinned edge can open only if ``P_in >= threshold``. Rayleigh's monotonicity bounds
        ``P_in <= Pc_b(x) + Q (R_tree + R_e + R_w_path)`` by the resistance of one path.
        """
        g = self.g
        a, b = int(g.a[e]), int(g.b[e])
        u, x = (a, b) if (a == g.n or self.full[a]) else (b, a)
        usable = ~self.full & ~self.trapped
        if self._pred is None or not kern._path_usable(x, self._pred, usable, g.n):
            self._dist, self._pred = kern._dijkstra_to_outlet(g.indptr, g.nbr, self._nbr_res, usable, g.out_res_w)
        dw = self._dist[x]
        if not np.isfinite(dw):
            return
        p_up = g.pcb[x] + self.rate * (self.tree_res[u] + 1.0 / g.gn[e] + dw)
        zero = np.zeros(g.n + 1)
        skip_e = np.zeros(g.n_edges, dtype=bool)
        skip_e[e] = True  # the one active meniscus: exclude it from the pinned candidates
        closed = self.closed.copy()
        closed[e] = True
        e2, ex, _ = kern._most_violated((g.a, g.b, g.n), (self.full, self.trapped, self.inv, closed, skip_e),
                                        zero, (g.thr, g.pcb))
        thr_min = -ex if e2 >= 0 else np.inf
        if p_up < thr_min * (1.0 - 1e-9):
            self._skip_solve_single_inflow(x)

    def _skip_solve_single_inflow(self, x: int) -> None:
        """A jump whose solve is provably unneeded: all of the rate enters pore ``x``, no pressure solve."""
        self.q = np.zeros(self.g.n)
        self.q[x] = self.rate
        self.q_out_n = 0.0
        self.q_out_w = self.rate
        self.flux_valid = True
        self.p_valid = False
        self.n_skipped += 1

    def step(self, t_target: float):
        """Advance by one event (a pore becomes full, a jump, or reaching ``t_target``)."""
        g = self.g
        self.n_events += 1
        if not self.flux_valid:
            if self._resolve():
                self._record(self.inlet_pressure())
                return
        filling = np.flatnonzero(self.q > 0)
        dt, k = kern._filling_step(self.vn, g.vol, self.q, filling)
        remaining = t_target - self.t
        if dt >= remaining:
            dt, k = remaining, -1
        kern._apply_filling(self.vn, g.vol, self.q, filling, dt, k)
        self.out_n += self.q_out_n * dt
        self.out_w += self.q_out_w * dt
        self.t = t_target if k < 0 else self.t + dt
        if self.rate is not None:
            self.injected = self.rate * self.t  # prescribed: the balance checks the fluxes against it
        else:  # constant pressure: nothing is prescribed, the inflow is what the solve gives
            self.injected += (float(self.q.sum()) + self.q_out_n) * dt
        p_in = self.inlet_pressure()  # the inlet pressure during this interval
        newly = filling[self.vn[filling] >= g.vol[filling]]
        if newly.size:
            self._on_full(newly)
        self._record(p_in)

    def _on_full(self, pores):
        g = self.g
        self.full[pores] = True
        self.vn[pores] = g.vol[pores]
        self.fill_time[pores] = self.t
        self.n_fills += pores.size
        for x in pores:
            e = self.parent[x]
            if e >= 0:
                u = g.a[e] if g.b[e] == x else g.b[e]
                self.tree_res[x] = self.tree_res[u] + 1.0 / g.gn[e]
        if np.isnan(self.t_breakthrough) and g.is_outlet[pores].any():
            self.t_breakthrough = self.t
            self.sw_breakthrough = self.sw()
        seeds = np.unique(np.concatenate([g.nbr[g.indptr[p]:g.indptr[p + 1]] for p in pores]))
        seeds = seeds[~self.full[seeds] & ~self.trapped[seeds]]
        if seeds.size:
            kern._trapped_from(seeds, (g.indptr, g.nbr, g.is_outlet, g.key), (self.full, self.trapped),
                               (self._stamp, self._mark))
        self.flux_valid = False
        self.p_valid = False

    # -- bookkeeping -----------------------------------------------------------------------
    def sw(self) -> float:
        """Wetting saturation of the kept pore space."""
        return 1.0 - float(self.vn.sum()) / float(self.g.vol.sum())

    def mass_error(self) -> float:
        """Relative non-wetting volume balance error, ``|V_in + V_def - V_stored - V_out,n| / (V_in + |V_def|)``.

        At constant rate ``V_in = Q t`` is the *prescribed* volume, so the balance tests the
        fluxes the solve produced (and their rescaling to sum to Q) against it. At constant inlet
        pressure nothing is prescribed: ``V_in`` is the time integral of the computed inflow (into
        filling pores plus non-wetting outflow), so the balance checks the volume bookkeeping
        (exact integration, capping of full pores, deformation booking) only.
        """
        den = self.injected + abs(self.deformation)
        if den <= 0:
            return 0.0
        return abs(self.injected + self.deformation - float(self.vn.sum()) - self.out_n) / den

    def inlet_pressure(self) -> float:
        """Inlet node pressure if current, else NaN."""
        return float(self.P[self.g.n]) if self.p_valid else np.nan

    def _record(self, p_in):
        self.rows.append((self.t, self.injected, self.sw(), p_in, self.q_out_w, self.q_out_n,
                          self.n_events, self.solver.n_solves, self.mass_error(), self.n_fills))

    def ensure_pressure(self):
        """Solve for the pressure if a skipped solve left it stale (no configuration change)."""
        if self.p_valid:
            return
        if self.rate is not None and not self.has_open_path():
            # every meniscus pinned: fluids at rest, non-wetting at the next jump's threshold
            _, thr = self._cheapest()
            n = self.g.n
            P = np.where(self.trapped, self.P[:n], 0.0)
            P[self.full] = thr
            self.P = np.concatenate([P, [thr]])
            self.p_valid = True
            return
        self.solve()
