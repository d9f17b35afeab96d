"""Naive pure-Python twins of porefsi.flow._kernels (clarity over speed)."""

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra


def filling_step(vol_nw, vol, q, filling):
    times = [(vol[i] - vol_nw[i]) / q[i] for i in filling if q[i] > 0]
    if not times:
        return np.inf, -1
    k = [i for i in filling if q[i] > 0][int(np.argmin(times))]
    return max(min(times), 0.0), k


def apply_filling(vol_nw, vol, q, filling, dt, k):
    out = vol_nw.copy()
    for i in filling:
        if q[i] > 0:
            out[i] = vol[i] if i == k else min(vol_nw[i] + q[i] * dt, vol[i])
    return out


def most_violated(a, b, n, full, trapped, inv, closed, blocked, P, thr, pcb):
    cands = []
    for e in range(len(a)):
        i, j = a[e], b[e]
        if j > n:
            continue
        fi = True if i == n else bool(full[i])
        fj = bool(full[j])
        if fi == fj:
            continue
        u, x = (i, j) if fi else (j, i)
        if trapped[x]:
            continue
        d = P[u] - P[x]
        if inv[e] and not closed[e]:
            cands.append((-(d - pcb[x]), e, -1))
        elif not blocked[e]:
            cands.append(((d - pcb[x]) if inv[e] else (d - thr[e]), e, 1))
    if not cands:
        return -1, -np.inf, 0
    ex = max(c[0] for c in cands)
    first = next(c for c in cands if c[0] == ex)
    return first[1], ex, first[2]


def trapped_after(indptr, nbr, full, trapped, is_outlet):
    """Pores of wetting clusters (non-full, non-trapped) with no outlet pore: connected components."""
    n = len(full)
    usable = ~full & ~trapped
    rows = np.repeat(np.arange(n), np.diff(indptr))
    m = usable[rows] & usable[nbr]
    A = sp.coo_array((np.ones(m.sum()), (rows[m], nbr[m])), shape=(n, n))
    _, lab = connected_components(A, directed=False)
    good = np.unique(lab[usable & is_outlet])
    return trapped | (usable & ~np.isin(lab, good))


def dijkstra_to_outlet(indptr, nbr, nbr_res, usable, out_res):
    n = len(indptr) - 1
    rows = np.repeat(np.arange(n), np.diff(indptr))
    m = usable[rows] & usable[nbr]
    src = np.concatenate([rows[m], np.full(n, n)])
    dst = np.concatenate([nbr[m], np.arange(n)])
    w = np.concatenate([nbr_res[m], np.where(usable, out_res, np.inf)])
    ok = np.isfinite(w)
    A = sp.coo_array((w[ok], (src[ok], dst[ok])), shape=(n + 1, n + 1)).tocsr()
    d = dijkstra(A, directed=False, indices=n)
    return d[:n]


def n_distance(indptr, nbr, nbr_res, full, in_res):
    """Shortest path from a virtual inlet node over full pores (scipy Dijkstra on an explicit graph)."""
    n = len(indptr) - 1
    edges = {}
    for v in range(n):
        for p in range(indptr[v], indptr[v + 1]):
            w = int(nbr[p])
            if full[v] and full[w]:
                key = (min(v, w), max(v, w))
                edges[key] = min(edges.get(key, np.inf), float(nbr_res[p]))
    for v in range(n):
        if full[v] and np.isfinite(in_res[v]):
            edges[(v, n)] = float(in_res[v])
    if not edges:
        return np.full(n, np.inf)
    a = [k[0] for k in edges]
    b = [k[1] for k in edges]
    A = sp.coo_array((list(edges.values()), (a, b)), shape=(n + 1, n + 1)).tocsr()
    d = dijkstra(A, directed=False, indices=n)[:n]
    return np.where(full, d, np.inf)


def ball(seeds, indptr, nbr, allowed, hops):
    """Allowed pores within ``hops`` steps of an allowed seed through allowed pores (plain BFS, lists)."""
    n = len(indptr) - 1
    frontier = {int(s) for s in seeds if s < n and allowed[s]}
    seen = set(frontier)
    for _ in range(hops):
        nxt = set()
        for v in frontier:
            for p in range(indptr[v], indptr[v + 1]):
                w = int(nbr[p])
                if allowed[w] and w not in seen:
                    nxt.add(w)
        seen |= nxt
        frontier = nxt
    out = np.zeros(n, dtype=bool)
    out[list(seen)] = True
    return out


def edge_states(g, full, trapped, inv, closed):
    """Twin of ``_kernels._edge_states`` (vectorised NumPy on the graph ``g``): (cond, men, fa)."""
    fx = np.concatenate([full, [True, False]])
    tx = np.concatenate([trapped, [False, False]])
    fa, fb = fx[g.a], fx[g.b]
    out_e = ~g.inner
    nw = (fa & fb) | (out_e & fa)
    men = (fa ^ fb) & inv & ~closed & ~out_e
    w = ~fa & ~fb
    tr = tx[g.a] | tx[g.b]
    men &= ~tr
    cond = np.where(nw | men, g.gn, np.where(w, g.gw, 0.0))
    cond[tr] = 0.0
    return cond, men, fa


def assemble(g, cond, men, fa, rate, p_fixed, diag_ref):
    """Twin of ``_kernels._assemble`` (bincount / ``add.at``): (matrix values, rhs, filling pores)."""
    n = g.n
    diag = (np.bincount(g.a, cond, minlength=n + 2) + np.bincount(g.b, cond, minlength=n + 2))[:n + 1]
    rhs = np.zeros(n + 1)
    off = np.where(g.inner, -cond, 0.0)
    if rate is not None:
        rhs[n] = rate
    else:
        ie = g.is_in_edge
        np.add.at(rhs, g.b[ie], cond[ie] * p_fixed)
        off[ie] = 0.0
        diag[n] = 1.0
        rhs[n] = p_fixed
    em = np.flatnonzero(men)
    u = np.where(fa[em], g.a[em], g.b[em])
    x = np.where(fa[em], g.b[em], g.a[em])
    src = cond[em] * g.pcb[x]
    np.add.at(rhs, u, src)
    np.add.at(rhs, x, -src)
    zero = diag <= 0
    diag[zero] = diag_ref[zero]
    rhs[zero] = 0.0
    data = np.zeros(g.indices.size)
    data[g.pos_diag] = diag
    data[g.pos_ab[g.inner]] = off[g.inner]
    data[g.pos_ba[g.inner]] = off[g.inner]
    return data, rhs, x
