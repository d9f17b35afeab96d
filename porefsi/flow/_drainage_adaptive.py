r"""Adaptive drainage scheme (private; ``scheme="adaptive"`` of :mod:`porefsi.flow.drainage`).

The exact event scheme (:class:`~porefsi.flow._drainage_engine.Engine`) solves the pressure field
after every event. At low capillary number most events are quasi-static: every meniscus is
pinned, the cheapest threshold opens (invasion percolation) and the one invaded pore takes all of
the injected rate ``Q`` until it is full. The adaptive engine runs such fills in **certified
batches** without a pressure solve, and falls back to dynamic events with solves where the
certificate fails.

Certificate (rigorous). While pore ``x`` fills through edge ``e = (u, x)`` and nothing else moves,
the inlet pressure is ``P_in = Pc_b,x + Q (R_N(in, u) + 1/g_e + R_W(x, out))`` with ``R_N`` and
``R_W`` the effective resistances of the non-wetting cluster and of the wetting region. By the
maximum principle every pinned meniscus sees at most ``P_in`` across it, so if an upper bound of
``P_in`` stays below the cheapest other threshold, the exact scheme fills ``x`` alone, with the
same time ``(V_x - V_n,x) / Q``. The bounds come from Rayleigh's monotonicity law:

* ``R_N(in, u) <= d_N(u)``, the shortest non-wetting path resistance from the inlet through full
  pores, kept up to date incrementally (the cluster only grows, so distances only shrink);
* ``R_W(x, out) <= min_y (1/g_w,xy + d_W(y))`` over x's wetting neighbours ``y``, with ``d_W``
  the shortest wetting path to the outlet in the wetting region left *at the end of the batch*:
  the batch's fills are predicted by invasion percolation with trapping, and every intermediate
  wetting region contains the final one, so one Dijkstra serves the whole batch.

Fills are applied in order while the certificate holds; the first fill that fails it is a
dynamic event (the exact scheme's jump and pressure solve). Certified fills are the exact
scheme's events: same pores, same order, same times (their inlet pressure is recorded as NaN,
like the exact scheme's skipped solves).
"""

from __future__ import annotations

import dataclasses
import heapq
import weakref

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from porefsi.flow import _drainage_pivots as pivots
from porefsi.flow import _drainage_predictor as pred
from porefsi.flow import _kernels as kern
from porefsi.flow._drainage_engine import Engine
from porefsi.flow._drainage_graph import DrainageGraph
from porefsi.flow._drainage_options import (
    DEFAULT_BACKOFF,
    DEFAULT_FLUX_TOLERANCE,
    DEFAULT_HOPS,
    DEFAULT_LOCAL_MENISCI,
    DEFAULT_LOCAL_SOLVES,
    DEFAULT_PREDICT_FILLS,
    DEFAULT_TIE_TOLERANCE,
)

__all__ = ["AdaptiveEngine", "AdaptiveTuning", "DEFAULT_LOCAL_SOLVES", "DEFAULT_HOPS", "DEFAULT_LOCAL_MENISCI"]

#: Relative safety of the certificate against round-off in the bound (as the exact scheme's skip).
_SAFETY = 1e-9


_RES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _resistances(g: DrainageGraph):
    """(non-wetting resistance per adjacency entry, inlet-conduit resistance per pore), cached per graph."""
    r = _RES.get(g)
    if r is None:
        in_res = np.full(g.n, np.inf)
        ie = np.flatnonzero(g.is_in_edge)
        in_res[g.b[ie]] = 1.0 / g.gn[ie]
        r = (1.0 / g.gn[g.nbr_edge], in_res)
        _RES[g] = r
    return r


@dataclasses.dataclass(frozen=True)
class AdaptiveTuning:
    """Knobs of the adaptive scheme (:class:`AdaptiveEngine`), from :class:`DrainageOptions`.

    Attributes
    ----------
    local_solves, hops, local_menisci : int
        Local solves allowed between two global ones (0: every solve is global), radius in
        throats of the wetting patches of a local solve, most active menisci for a local solve.
    tie_tolerance : float
        Relative band by which the certificate's bound may exceed the next threshold (0: the
        rigorous certificate; > 0: near-ties are filled in invasion-percolation order, an
        approximation measured in docs/drainage.md).
    batch : int
        Most fills predicted (and certified) per batch; cost only, never the outcome.
    predict_fills, flux_tolerance : int, float
        The flux-split predictor-corrector (:mod:`porefsi.flow._drainage_predictor`) where menisci
        are active: most fills per predicted batch (0 or 1: off, the exact scheme's events) and
        the corrector's tolerance on the flux split (L1, relative to the rate).
    backoff : int
        Most steps without a quasi-static batch attempt after attempts that certified nothing
        (doubling from 1; 0: attempt at every step). Cost only with ``tie_tolerance = 0``.
    block_pivots : bool
        Settle the menisci of an event in checked blocks (:mod:`porefsi.flow._drainage_pivots`)
        instead of one per solve.
    """

    local_solves: int = DEFAULT_LOCAL_SOLVES
    hops: int = DEFAULT_HOPS
    local_menisci: int = DEFAULT_LOCAL_MENISCI
    tie_tolerance: float = DEFAULT_TIE_TOLERANCE
    batch: int = 64
    predict_fills: int = DEFAULT_PREDICT_FILLS
    flux_tolerance: float = DEFAULT_FLUX_TOLERANCE
    backoff: int = DEFAULT_BACKOFF
    block_pivots: bool = False


class AdaptiveEngine(Engine):
    """Event engine with certified quasi-static batches (see module docstring).

    Parameters
    ----------
    graph, rate, inlet_pressure, solver, max_active_set_iter
        As for :class:`~porefsi.flow._drainage_engine.Engine`.
    skip_solves
        As for the exact engine: a jump that no batch certified still skips its solve when the
        exact scheme's one-path bound allows (measured: that bound, with the current wetting
        region, certifies more jumps than the batch bound, which must hold for the batch's end).
    tuning : AdaptiveTuning
        The scheme's knobs.
    """

    def __init__(self, graph: DrainageGraph, rate: float | None, inlet_pressure: float | None,
                 solver: str = "auto", skip_solves: bool = False, max_active_set_iter: int | None = None, *,
                 tuning: AdaptiveTuning = AdaptiveTuning()):
        super().__init__(graph, rate, inlet_pressure, solver=solver, skip_solves=skip_solves,
                         max_active_set_iter=max_active_set_iter)
        t = tuning
        self.margin = 1.0 - _SAFETY + float(t.tie_tolerance)  # certified: bound < margin x the next threshold
        self.max_menisci = int(t.local_menisci)
        self.batch = int(t.batch)
        self.hops = int(t.hops)
        self.max_local = int(t.local_solves)
        self.local_left = 0  # local solves left before the next global one
        self.has_ref = False  # whether a global solve has set the reference below
        self.ref_data = np.zeros(graph.indices.size)  # matrix values, right-hand side and field of the
        self.ref_rhs = np.zeros(graph.n + 1)  # last global solve: the far field of local solves
        self.ref_P = np.zeros(graph.n + 1)
        self.n_local = 0
        self.n_global = 0
        self.last_global = -2  # event of the last global solve
        self.dn = np.full(graph.n, np.inf)  # d_N: shortest non-wetting path resistance from the inlet
        self.dn_full = 0  # full pores d_N accounts for (-1: stale, recomputed before the next batch)
        self.n_certified = 0
        self.n_batches = 0
        self.dw_dist = self.dw_pred = None  # the last wetting-path search (d_W), over a region that only shrinks
        self.n_dw_searches = 0
        self.backoff = 0  # after a batch that certified nothing, this many quiet steps skip the attempt
        self.backoff_left = 0  # (doubling up to max_backoff; a certified batch resets it)
        self.max_backoff = int(t.backoff)
        self.predict_fills = int(t.predict_fills)
        self.flux_tol = float(t.flux_tolerance)
        self.predict_m = 2  # fills of the next predicted batch (doubles on success, halves on failure, >= 2)
        self.predict_wait = self.predict_left = 0  # exact events without a prediction after rejections at 2
        self.p_current = False  # P solves the current configuration (a corrector's solve, reused once)
        self.n_predicted = 0  # fills made with a predicted flux split and accepted by the corrector
        self.n_predict_batches = 0
        self.n_rollbacks = 0
        self.block_pivots = bool(t.block_pivots)
        self.n_block_pivots = 0  # block pivots made, and members undone by their check
        self.n_block_undos = 0

    # -- non-wetting distances ---------------------------------------------------------------
    def _sync_dn(self):
        nf = int(np.count_nonzero(self.full))
        if self.dn_full != nf:
            nres, in_res = _resistances(self.g)
            self.dn = kern._n_distance(self.g.indptr, self.g.nbr, nres, self.full, in_res)
            self.dn_full = nf

    def _resolve(self):
        """The exact engine's resolution, with block pivots when switched on (constant rate, fluid moving)."""
        if getattr(self, "block_pivots", False) and self.rate is not None and self.has_open_path():
            pivots.resolve(self)
            return False
        return Engine._resolve(self)

    def open_edge(self, e: int):
        """As the exact engine's; a kept corrector solve no longer matches the configuration."""
        self.p_current = False
        super().open_edge(e)

    def _on_full(self, pores):
        self.p_current = False
        synced = self.dn_full == int(np.count_nonzero(self.full))
        super()._on_full(pores)
        if synced:
            nres, in_res = _resistances(self.g)
            for x in pores:
                kern._n_distance_add(int(x), self.dn, self.g.indptr, self.g.nbr, nres, self.full, in_res)
            self.dn_full += int(pores.size)
        else:
            self.dn_full = -1

    # -- pressure solves ---------------------------------------------------------------------
    def solve(self, force_global: bool = False):
        """Solve the field of the current configuration, locally when allowed; return (cond, men, fa).

        A local solve recomputes the field on the non-wetting cluster, the inlet node and the
        wetting pores within ``hops`` throats of every row that changed since the last global
        solve (and of the active menisci); the rest of the wetting region keeps the last global
        field, which enters as a Dirichlet condition. ``force_global`` (outputs) solves globally
        without making the result the reference of later local solves.
        """
        if getattr(self, "p_current", False):  # the corrector's solve of this very configuration
            self.p_current = False
            return self.conductances()
        cond, men, fa = self.conductances()
        A, rhs, x = self.assemble(cond, men, fa)
        old = self.P
        P = None
        if not force_global and self.local_left > 0 and self.has_ref and x.size <= self.max_menisci:
            P = self._local(A, rhs, x)
        glob = P is None
        if glob:
            nmask = np.concatenate([self.full, [True]])
            frequent = self.n_events - self.last_global <= 1
            P = self.solver.solve(A, rhs, x0=old, hint=lambda: self._hint(x), nmask=nmask, frequent=frequent)
            self.last_global = self.n_events
        else:
            self.local_left -= 1
            self.n_local += 1
        P[:self.g.n][self.trapped] = old[:self.g.n][self.trapped]
        if glob and not force_global:
            if self.max_local > 0:  # the far field of later local solves (none allowed: no copies)
                self.ref_data, self.ref_rhs, self.ref_P = A.data.copy(), rhs.copy(), P.copy()
            self.has_ref = True
            self.local_left = self.max_local
            self.n_global += 1
        self.P = P
        self.p_valid = True
        return cond, men, fa

    def _local(self, A, rhs, x):
        g = self.g
        n = g.n
        ch = np.flatnonzero(A.data != self.ref_data)
        rows = np.concatenate([g.row_of[ch], np.flatnonzero(rhs != self.ref_rhs), x])
        seeds = np.unique(rows[rows < n])
        lam = np.zeros(n + 1, dtype=bool)
        lam[:n] = kern._ball(seeds, g.indptr, g.nbr, ~self.full & ~self.trapped, self.hops) | self.full
        lam[n] = True
        idx = np.flatnonzero(lam)
        Ar = A[idx]
        Pr = self.ref_P.copy()
        Pr[idx] = 0.0
        bl = rhs[idx] - Ar @ Pr
        Al = Ar[:, idx]
        d = Al.diagonal()
        sc = 1.0 / np.sqrt(d)
        As = sp.csc_array(sp.diags_array(sc) @ Al @ sp.diags_array(sc))
        lu = spla.splu(As, permc_spec="MMD_AT_PLUS_A", options=dict(SymmetricMode=True))
        P = self.ref_P.copy()
        P[idx] = lu.solve(bl * sc) * sc
        return P

    def ensure_pressure(self):
        """Solve for the pressure if stale: a global solve that does not become a local reference."""
        if self.p_valid:
            return
        if self.rate is not None and not self.has_open_path():
            return Engine.ensure_pressure(self)
        self.solve(force_global=True)

    # -- stepping ----------------------------------------------------------------------------
    def step(self, t_target: float):
        """Advance by one event, or by a certified batch of quasi-static fills (two events each)."""
        if self.flux_valid or self.rate is None or not np.isnan(self.t_breakthrough):
            return Engine.step(self, t_target)
        if self.has_open_path():
            if getattr(self, "predict_fills", 0) > 1:
                return self._predicted(t_target)
            return Engine.step(self, t_target)
        if self.backoff_left > 0:  # recent batches certified nothing: do not pay for predicting one
            self.backoff_left -= 1
            return Engine.step(self, t_target)
        if self._batch(t_target) == 0:
            self.backoff = min(2 * self.backoff + 1, getattr(self, "max_backoff", DEFAULT_BACKOFF))
            self.backoff_left = self.backoff
            Engine.step(self, t_target)  # not certified: the exact jump; the next event solves
        else:
            self.backoff = 0

    def _predicted(self, t_target):
        """The exact event, then up to ``predict_m - 1`` fills with a predicted flux split, checked by one solve.

        See :mod:`porefsi.flow._drainage_predictor`. A rejected batch is retried from the end of
        the exact event with the size the corrector names, down to none (the next step then
        resolves the exact event's state exactly).
        """
        before = self.full.copy()
        Engine.step(self, t_target)
        if self.flux_valid or not np.isnan(self.t_breakthrough):
            return  # no fill (the target time), or breakthrough: the exact scheme's events from here
        if self.predict_left > 0:  # recent batches were rejected down to none
            self.predict_left -= 1
            return
        first = np.flatnonzero(self.full & ~before)
        q0 = self.q.copy()
        if not pred.redistribute(q0, first, self.rate) or pred.near_opening(self, first):
            return
        saved = pred.snapshot(self)
        m = self.predict_m
        while m > 1:
            fills, q = self._predict_fills(m, q0.copy(), first, t_target)
            self.n_predict_batches += 1
            retry = pred.verdict(self, fills, q, self.flux_tol, saved["P"])
            if retry == 0:
                self.flux_valid = False  # the next event resolves, starting from the corrector's solve
                self.n_predicted += len(fills) - 1
                self.predict_m = min(2 * len(fills), self.predict_fills)
                self.predict_wait = 0
                return
            pred.restore(self, saved)
            self.n_rollbacks += 1
            m = min(retry, len(fills) - 1)
        self.predict_m = 2
        self.predict_wait = min(2 * self.predict_wait + 1, 32)
        self.predict_left = self.predict_wait

    def _predict_fills(self, m, q, first, t_target):
        """Fills with the predicted split after the exact one, up to ``m`` in all; return (pores per fill, q)."""
        fills = [first]
        while len(fills) < m:
            self.q, self.flux_valid, self.p_valid = q, True, False
            before = self.full.copy()
            Engine.step(self, t_target)
            if self.flux_valid:  # the target time, no fill
                break
            last = np.flatnonzero(self.full & ~before)
            fills.append(last)
            q = q.copy()
            if (not np.isnan(self.t_breakthrough) or not pred.redistribute(q, last, self.rate)
                    or pred.near_opening(self, last)):
                break
        return fills, q

    def _front(self):
        """Pinned menisci as a heap of (threshold, edge) (no meniscus is active when this is called)."""
        g = self.g
        fx = self._node_full()
        fa, fb = fx[g.a], fx[g.b]
        idx = np.flatnonzero((fa ^ fb) & g.inner & ~(self.inv & ~self.closed))
        x = np.where(fa[idx], g.b[idx], g.a[idx])
        ok = ~self.trapped[x]
        idx, x = idx[ok], x[ok]
        th = np.where(self.inv[idx], g.pcb[x], g.thr[idx])
        heap = list(zip(th.tolist(), idx.tolist(), strict=True))
        heapq.heapify(heap)
        return heap

    def _valid(self, th, e, full, trapped):
        """Pore entered through front edge ``e`` if it is still pinned there at threshold ``th``, else -1."""
        g = self.g
        a, b = int(g.a[e]), int(g.b[e])
        fa = a == g.n or full[a]
        fb = full[b]
        if fa == fb:
            return -1
        x = b if fa else a
        if trapped[x] or (self.inv[e] and not self.closed[e]):
            return -1
        return x if th == (g.pcb[x] if self.inv[e] else g.thr[e]) else -1

    def _predict(self, t_target):
        """Invasion percolation with trapping from the current state for up to ``batch`` fills.

        Returns the fills ``[(edge, pore, next_threshold)]`` and the wetting-region mask at their
        end; stops after an outlet pore or the fill that reaches ``t_target``.
        """
        g = self.g
        heap = self._front()
        full = self.full.copy()
        trapped = self.trapped.copy()
        stamp, mark = np.zeros(1, dtype=np.int64), np.zeros(g.n, dtype=np.int64)
        seq = []
        t = self.t
        while len(seq) < self.batch:
            x = -1
            while heap and x < 0:
                th, e = heapq.heappop(heap)
                x = self._valid(th, e, full, trapped)
            if x < 0:
                break
            nxt = np.inf
            while heap:
                if self._valid(heap[0][0], heap[0][1], full, trapped) >= 0:
                    nxt = heap[0][0]
                    break
                heapq.heappop(heap)
            seq.append((e, x, nxt))
            t += (g.vol[x] - self.vn[x]) / self.rate
            if g.is_outlet[x] or t >= t_target:
                break
            full[x] = True
            nb = g.nbr[g.indptr[x]:g.indptr[x + 1]]
            ed = g.nbr_edge[g.indptr[x]:g.indptr[x + 1]]
            for y, ee in zip(nb.tolist(), ed.tolist(), strict=True):
                if not full[y] and not trapped[y]:
                    heapq.heappush(heap, (float(g.pcb[y] if self.inv[ee] else g.thr[ee]), ee))
            seeds = nb[~full[nb] & ~trapped[nb]]
            if seeds.size:
                kern._trapped_from(seeds, (g.indptr, g.nbr, g.is_outlet, g.key), (full, trapped), (stamp, mark))
        if seq:
            full[seq[-1][1]] = True
        return seq, ~full & ~trapped

    def _batch(self, t_target) -> int:
        """Apply the certified prefix of a predicted batch; return the number of fills applied."""
        seq, usable = self._predict(t_target)
        if not seq:
            return 0
        self._sync_dn()
        e, x, nxt = seq[0]
        if not self._bound(e, x, 0.0) < nxt * self.margin:  # fails without its wetting part
            return 0
        self.n_batches += 1
        done = 0
        for e, x, nxt in seq:
            rw = self._wetting_bound(x, usable)
            if not self._bound(e, x, rw) < nxt * self.margin:
                break
            self._certified_jump(e, x)
            Engine.step(self, t_target)  # the fill, all of Q into x (or up to t_target)
            done += 1
            if self.t >= t_target or not np.isnan(self.t_breakthrough):
                break
        return done

    def _wetting_bound(self, x, usable) -> float:
        """``min_y (1/g_w,xy + d_W(y))`` over x's neighbours in ``usable`` (and x's own outlet conduit).

        ``d_W`` is the shortest wetting path to the outlet in ``usable``: read from the last
        search where its path is still usable (the wetting region only shrinks, so it is still
        the shortest), searched afresh only where a broken path could give a smaller value.
        """
        g = self.g
        adj = (g.indptr, g.nbr, self._nbr_res)
        if self.dw_pred is not None:
            rw, exact = kern._wetting_bound(x, adj, (self.dw_dist, self.dw_pred), usable, g.out_res_w[x])
            if exact:
                return rw
        self.dw_dist, self.dw_pred = kern._dijkstra_to_outlet(g.indptr, g.nbr, self._nbr_res, usable, g.out_res_w)
        self.n_dw_searches += 1
        return kern._wetting_bound(x, adj, (self.dw_dist, self.dw_pred), usable, g.out_res_w[x])[0]

    def _bound(self, e, x, rw):
        """Upper bound of the inlet pressure while ``x`` fills alone through ``e``, given ``R_W <= rw``."""
        g = self.g
        u = g.a[e] if g.b[e] == x else g.b[e]
        rn = 0.0 if u == g.n else self.dn[u]
        return g.pcb[x] + self.rate * (rn + 1.0 / g.gn[e] + rw)

    def _certified_jump(self, e, x):
        """The exact scheme's jump into ``x`` through ``e`` followed by its skipped solve."""
        g = self.g
        n = g.n
        self.n_events += 1
        thr = float(g.pcb[x] if self.inv[e] else g.thr[e])
        self.open_edge(e)
        self.n_jumps += 1
        P = np.where(self.trapped, self.P[:n], 0.0)
        P[self.full] = thr
        self.P = np.concatenate([P, [thr]])
        self._skip_solve_single_inflow(x)
        self.n_certified += 1
        self._record(self.inlet_pressure())
