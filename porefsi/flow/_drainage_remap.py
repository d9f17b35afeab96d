"""Build a drainage engine state from per-pore saturations on any network (private).

Used by :meth:`porefsi.flow.drainage.DrainageSimulator.remap` when the coupling re-extracts the
network from the deformed image and pores and throats change. The caller supplies each new pore's
non-wetting saturation (volume-weighted voxel overlap of the old and new label images); this module
turns it into the discrete state the event engine needs:

1. saturations within ``full_tol`` of 1 are full;
2. the non-wetting cluster ``N`` is the set of full pores connected to the virtual inlet through
   full pores; full pores outside it are *stranded*;
3. pores with ``0 < s < 1`` next to ``N`` are filling: their meniscus entered through the throat
   of lowest entry threshold from ``N`` (the one invasion percolation opens first), which is marked
   invaded and made the pore's parent; other throats from ``N`` stay pinned until exceeded;
4. non-wetting fluid in pores that are neither in ``N`` nor filling next to it (stranded) cannot be
   carried by a model without disconnected non-wetting ganglia: it is removed and reported;
5. throats between two pores of ``N`` (and inlet edges into ``N``) are invaded; the invasion tree
   is the least-resistance tree of ``N`` from the inlet (Dijkstra over ``1/g_n``), so the skip bound
   ``R_tree`` is the resistance of an actual path, as the bound requires;
6. wetting clusters (non-full pores) with no outlet pore are trapped.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra

from porefsi.flow._drainage_graph import DrainageGraph

__all__ = ["engine_arrays_from_saturation"]


def engine_arrays_from_saturation(g: DrainageGraph, sat: np.ndarray, full_tol: float = 1e-9) -> dict:
    """Discrete engine state on graph ``g`` from kept-pore saturations ``sat`` (n,), in [0, 1].

    Returns
    -------
    dict
        ``vn (n,)`` non-wetting volumes m³, ``full, trapped (n,)`` bool, ``inv (E,)`` bool,
        ``parent (n,)`` int edge, ``tree_res (n + 1,)`` path resistance Pa s/m³ from the inlet,
        ``n_stranded`` int, ``stranded_volume`` m³ (non-wetting volume dropped, step 4),
        ``n_full``, ``n_filling`` int.
    """
    n, E = g.n, g.n_edges
    a, b = g.a, g.b
    cand = sat >= 1.0 - full_tol
    # N: full pores connected to the inlet node through full pores (node n = inlet)
    ok = np.concatenate([cand, [True, False]])
    both = ok[a] & ok[b]
    A = sp.coo_array((np.ones(int(both.sum())), (a[both], b[both])), shape=(n + 2, n + 2)).tocsr()
    _, lab = connected_components(A, directed=False)
    in_n = (lab == lab[n]) & ok
    full = in_n[:n].copy()
    # filling pores: 0 < s < 1 (or stranded-full) next to N; meniscus through the cheapest throat
    nx = np.concatenate([full, [True, False]])
    fa, fb = nx[a], nx[b]
    front = (fa ^ fb) & (b <= n)
    x_of = np.where(fa, b, a)
    filling_cand = np.zeros(n + 2, dtype=bool)
    filling_cand[:n] = (sat > 0) & ~full
    fe = np.flatnonzero(front & filling_cand[x_of])
    order = np.lexsort((fe, g.thr[fe]))  # cheapest threshold first, ties by edge index
    fe = fe[order]
    xs, first = np.unique(x_of[fe], return_index=True)
    menisci = fe[first]
    filling = np.zeros(n, dtype=bool)
    filling[xs] = True
    vn = np.where(full, g.vol, np.where(filling, np.clip(sat, 0.0, 1.0) * g.vol, 0.0))
    # a filling pore that was (nearly) full but hangs off N by a meniscus keeps s < 1 exactly
    vn = np.where(filling, np.minimum(vn, np.nextafter(g.vol, 0.0)), vn)
    strand = (sat > 0) & ~full & ~filling
    stranded_volume = float(np.sum(np.clip(sat[strand], 0.0, 1.0) * g.vol[strand]))
    inv = np.zeros(E, dtype=bool)
    inv[fa & fb & (b <= n)] = True
    inv[menisci] = True
    # least-resistance tree of N from the inlet
    nw = fa & fb & (b <= n)
    ea = np.flatnonzero(nw)
    R = sp.coo_array((1.0 / g.gn[ea], (a[ea], b[ea])), shape=(n + 1, n + 1)).tocsr()
    dist, pred = dijkstra(R, directed=False, indices=n, return_predecessors=True)
    parent = np.full(n, -1, dtype=np.int64)
    tree_res = np.zeros(n + 1)
    fidx = np.flatnonzero(full)
    tree_res[fidx] = dist[fidx]
    eid = sp.coo_array((np.concatenate([ea, ea]) + 1.0, (np.concatenate([a[ea], b[ea]]),
                                                        np.concatenate([b[ea], a[ea]]))),
                       shape=(n + 1, n + 1)).tocsr()
    if fidx.size:
        parent[fidx] = np.asarray(eid[pred[fidx], fidx]).ravel().astype(np.int64) - 1
    parent[xs] = menisci
    # trapped wetting clusters: non-full pores whose component has no outlet pore
    wet = ~full
    ww = np.concatenate([wet, [False, False]])
    m = ww[a] & ww[b]
    Aw = sp.coo_array((np.ones(int(m.sum())), (a[m], b[m])), shape=(n, n)).tocsr()
    _, wl = connected_components(Aw, directed=False)
    has_out = np.zeros(wl.max() + 1 if n else 0, dtype=bool)
    has_out[wl[g.is_outlet & wet]] = True
    trapped = wet & ~has_out[wl]
    return dict(vn=vn, full=full, trapped=trapped, inv=inv, parent=parent, tree_res=tree_res,
                n_stranded=int(strand.sum()), stranded_volume=stranded_volume,
                n_full=int(full.sum()), n_filling=int(filling.sum()))
