r"""Flux-split predictor-corrector of the adaptive drainage scheme (private; option ``predict_fills``).

Regime: several menisci active at once (Ca >~ 1e-6 on rock networks), where no quasi-static
batch of :mod:`porefsi.flow._drainage_adaptive` applies and the exact scheme pays one or more
pressure solves per fill. Here the menisci share the injected rate ``Q``; between two fills the
split changes only through the pore that became full, whose inflow the others take over.

Predictor. From a resolved state (the exact scheme's event: solve, active set, fluxes ``q``, the
first fill made with them), up to ``m - 1`` further fills are made without a solve: after a pore
``k`` fills, its new menisci are taken as pinned and its inflow is handed to the other active
menisci in proportion to their fluxes (``q_i <- q_i Q / (Q - q_k)``), so volume is conserved
exactly; each fill time is remaining volume over that flux, as in the exact scheme. The batch
stops early at a fill where the last solve's field says a new meniscus of the filled pore is
within 10 % of its entry threshold (``P_w,k + Pc_b,k - P_w,y >= 0.9 T``): that is a likely
opening, and the corrector's solve comes right after it, as in the exact scheme.

Corrector (a posteriori, one solve, :func:`verdict`). The pressure field of the state the batch
reached, with every predicted meniscus pinned, is solved and the batch accepted when

* no meniscus is violated except the new ones of the batch's last fill (an opening there is what
  the exact scheme does right after that fill); a violated one of an earlier fill, or an older
  pinned one whose excess (interpolated linearly in the fill index from the field before the
  batch) crossed zero earlier, names the fill the batch must end at;
* no active meniscus is pushed back, and the flux split agrees with the predicted one:
  ``sum_i |q_i - q_i^pred| <= flux_tolerance Q`` (else half the batch).

Accepted: the solve is the first one of the next event's active-set resolution (not repeated).
Rejected: the state rolls back to the end of the batch's first fill (the exact scheme's event;
arrays, history rows and counters restored) and the batch is retried with the size named, down
to none, after which the next event is the exact one (and, after repeated rejections, the next
few events are exact without an attempt). ``m`` doubles after an accepted batch, up to
``predict_fills``. Not a certificate: the check sees the end of the batch, not the states in
between. Measured (docs/drainage.md, "Several active menisci"): almost every batch is rejected,
because a meniscus opens right after nearly every fill, so the option is off by default.
"""

from __future__ import annotations

import numpy as np

#: A new meniscus of a filled pore within this fraction of its threshold ends the batch (cost only).
_NEAR_OPENING = 0.1

#: Engine attributes a rollback restores (arrays copied; scalars as they are).
_STATE_ARRAYS = ("vn", "full", "trapped", "inv", "closed", "parent", "tree_res", "P", "q", "fill_time", "edge_time")
_STATE_SCALARS = (
    "q_out_n",
    "q_out_w",
    "flux_valid",
    "p_valid",
    "t",
    "injected",
    "out_n",
    "out_w",
    "t_breakthrough",
    "sw_breakthrough",
    "n_events",
    "n_fills",
    "n_jumps",
    "n_skipped",
    "n_changes",
    "max_iter_seen",
)


def snapshot(e) -> dict:
    """The engine state a rollback restores (plus the length of its event rows)."""
    s = {k: getattr(e, k).copy() for k in _STATE_ARRAYS}
    s.update({k: getattr(e, k) for k in _STATE_SCALARS})
    s["n_rows"] = len(e.rows)
    return s


def restore(e, s: dict) -> None:
    """Put the engine back into the state ``s`` of :func:`snapshot` (searches and caches reset)."""
    for k in _STATE_ARRAYS:
        setattr(e, k, s[k].copy())
    for k in _STATE_SCALARS:
        setattr(e, k, s[k])
    del e.rows[s["n_rows"] :]
    e.dn_full = -1  # non-wetting distances: recomputed before the next quasi-static batch
    e.dw_dist = e.dw_pred = None  # wetting-path searches were over a smaller wetting region
    e._dist = e._pred = None
    e.p_current = False


def redistribute(q: np.ndarray, k: np.ndarray, rate: float) -> bool:
    """Hand the inflow of pores ``k`` (just full) to the other filling pores in proportion (in place).

    Returns False (and ``q`` all zero) when no filling pore is left.
    """
    q[k] = 0.0
    tot = float(q.sum())
    if not tot > 0:
        return False
    q *= rate / tot
    return True


def near_opening(e, pores: np.ndarray) -> bool:
    """Whether a new meniscus of ``pores`` (just full) is within :data:`_NEAR_OPENING` of its threshold."""
    return any(_near_opening(e, int(k)) for k in pores)


def _near_opening(e, k: int) -> bool:
    """:func:`near_opening` of one pore, from the last solve's field.

    The non-wetting pressure in ``k`` is taken as its wetting pressure plus its body threshold
    ``P_k + Pc_b,k`` (the meniscus that was filling it).
    """
    g = e.g
    lo, hi = g.indptr[k], g.indptr[k + 1]
    nb, ed = g.nbr[lo:hi], g.nbr_edge[lo:hi]
    ok = (nb < g.n) & ~e.inv[ed]
    ok[ok] &= ~e.full[nb[ok]] & ~e.trapped[nb[ok]]
    if not ok.any():
        return False
    p_nw = e.P[k] + g.pcb[k]
    return bool(np.any(p_nw - e.P[nb[ok]] >= (1.0 - _NEAR_OPENING) * g.thr[ed[ok]]))


def verdict(e, fills: list, q_pred: np.ndarray, tol: float, p0: np.ndarray) -> int:
    """Corrector: solve the current configuration; 0 if the batch is accepted, else the fills to retry with.

    ``fills`` lists the pores that became full at each fill of the batch (the first is the exact
    event's), ``q_pred`` the predicted inflow per pore now, ``p0`` the field of the solve before
    the batch. A meniscus violated now opens in the exact scheme at the first state where it is
    violated: for a new meniscus of the ``j``-th fill that is state ``j``; for one pinned before
    the batch it is located by interpolating its excess linearly in the fill index between ``p0``
    and now. The batch is accepted when every such state is the last one, no active meniscus is
    pushed back and the flux split agrees (see the module docstring); otherwise the answer is
    the earliest such state (at least 1), or half the batch for a backflow or flux mismatch.
    The solve is kept as the current field (``e.p_current``) for the next resolution to reuse.
    """
    g = e.g
    n = g.n
    m = len(fills)
    if not e.has_open_path():  # every meniscus pinned: the fluids are at rest, no solve (the exact
        return max(m - 1, 1)  # scheme's quasi-static jump); end the batch one fill earlier
    cond, men, fa = e.solve()
    e.p_current = True
    P = e.P
    fb = e._node_full()[g.b]
    u = np.minimum(np.where(fa, g.a, g.b), n)
    x = np.minimum(np.where(fa, g.b, g.a), n)
    xp = np.minimum(x, n - 1)
    one = (fa ^ fb) & g.inner & ~e.trapped[xp]
    d = P[u] - P[x]
    active = one & e.inv & ~e.closed
    thr = np.where(e.inv, g.pcb[xp], g.thr)
    ex = d - thr
    opened = np.flatnonzero(one & ~active & (ex > e._ptol))
    when = np.full(n + 1, 0, dtype=np.int64)  # fill index (1..m) at which each pore became full; 0: before
    for j, pores in enumerate(fills, start=1):
        when[pores] = j
    first = m
    for k in opened:
        j = int(when[u[k]])
        if j == 0:  # pinned before the batch: linear in the fill index from the field before it
            ex0 = p0[u[k]] - p0[x[k]] - thr[k]
            j = int(np.ceil(m * (-ex0) / (ex[k] - ex0))) if ex0 < 0 else 1
        first = min(first, max(j, 1))
    if first < m:
        return first
    if np.any(active & (d - g.pcb[xp] < -e._ptol)):
        return max(m // 2, 1)
    em = np.flatnonzero(men)
    q = np.bincount(x[em], np.maximum(cond[em] * (d[em] - g.pcb[xp[em]]), 0.0), minlength=n + 1)[:n]
    tot = float(q.sum())
    if not tot > 0:  # every meniscus pinned: right if the prediction ran out of filling pores too
        return 0 if not q_pred.any() else max(m // 2, 1)
    q *= e.rate / tot
    return 0 if float(np.abs(q - q_pred).sum()) <= tol * e.rate else max(m // 2, 1)
