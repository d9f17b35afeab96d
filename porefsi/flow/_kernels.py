"""Numba kernels of the drainage model (private; each has a pure-Python twin in tests/reference).

Edge-state conventions shared with :mod:`porefsi.flow._drainage_graph`: nodes ``0..n-1`` are pores,
``n`` is the virtual inlet (always non-wetting) and ``n + 1`` the virtual outlet; edge ``e`` joins
``a[e]`` and ``b[e]``.
"""

from __future__ import annotations

import heapq

import numpy as np

from porefsi._numba import jit

_INF = np.inf


@jit
def _filling_step(vol_nw, vol, q, filling):
    """Smallest filling time over pores ``filling`` (indices) with inflow ``q > 0``.

    Returns ``(dt, k)`` with ``k`` the pore index that fills first, or ``(inf, -1)``.
    """
    dt = _INF
    k = -1
    for i in filling:
        if q[i] > 0.0:
            t = (vol[i] - vol_nw[i]) / q[i]
            if t < dt:
                dt = t
                k = i
    if dt < 0.0:
        dt = 0.0
    return dt, k


@jit
def _apply_filling(vol_nw, vol, q, filling, dt, k):
    """Advance the non-wetting volumes of ``filling`` pores by ``q * dt`` in place, capped at ``vol``.

    Pore ``k`` (the one that set dt) is set exactly full. Returns the volume actually added, m³.
    """
    added = 0.0
    for i in filling:
        if q[i] > 0.0:
            old = vol_nw[i]
            if i == k:
                new = vol[i]
            else:
                new = old + q[i] * dt
                if new > vol[i]:
                    new = vol[i]
            vol_nw[i] = new
            added += new - old
    return added


@jit
def _most_violated(edges, state, P, thresholds):
    """Most violated constraint of the active set, for every edge in one pass.

    ``edges = (a, b, n)`` (edge ends, the inlet node's index), ``state = (full, trapped, inv,
    closed, blocked)``, ``P`` the node pressures and ``thresholds = (thr, pcb)``.

    An edge with exactly one non-wetting end ``u`` (a full pore or the inlet node ``n``) and a
    non-full, non-trapped pore ``x`` at the other end is

    - *pinned* (not ``inv``, or ``closed``): violated by ``P[u] - P[x] - T``, where ``T`` is the
      entry threshold ``thr[e]`` (or ``pcb[x]`` for a stalled meniscus already in the body of x);
      edges with ``blocked[e]`` are skipped;
    - *active* (``inv`` and not ``closed``): violated by ``-(P[u] - P[x] - pcb[x])`` (backflow).

    Returns ``(edge, excess, kind)`` with kind 1 = open, -1 = close, or ``(-1, -inf, 0)``.
    """
    a, b, n = edges
    full, trapped, inv, closed, blocked = state
    thr, pcb = thresholds
    best = -1
    best_ex = -_INF
    kind = 0
    for e in range(a.shape[0]):
        i = a[e]
        j = b[e]
        if j > n:  # outlet edge: never a meniscus constraint
            continue
        fi = True if i == n else full[i]
        fj = full[j]
        if fi == fj:
            continue
        if fi:
            u = i
            x = j
        else:
            u = j
            x = i
        if trapped[x]:
            continue
        d = P[u] - P[x]
        if inv[e] and not closed[e]:
            ex = -(d - pcb[x])
            k = -1
        else:
            if blocked[e]:
                continue
            if inv[e]:
                ex = d - pcb[x]
            else:
                ex = d - thr[e]
            k = 1
        if ex > best_ex:
            best_ex = ex
            best = e
            kind = k
    return best, best_ex, kind


@jit
def _trapped_from(seeds, graph, state, work):
    """Find wetting clusters cut off from the outlet after some pores became full.

    ``graph = (indptr, nbr, is_outlet, key)``, ``state = (full, trapped)``, ``work = (stamp,
    mark)``. Best-first search (priority ``-key``, i.e. towards the outlet face) from every seed
    over non-full, non-trapped pores; a search that reaches an outlet pore proves its cluster is
    connected; a search that exhausts its cluster marks it trapped. ``stamp``/``mark`` are work
    arrays (int64, length 1 and n) reused between calls; ``mark`` values below ``stamp`` are stale.

    Returns the number of pores newly marked trapped (``trapped`` is updated in place).
    """
    indptr, nbr, is_outlet, key = graph
    full, trapped = state
    stamp, mark = work
    n_new = 0
    base = stamp[0]
    # mark[v] == base + 1: reached-outlet set of this call; == base + 2 + s: visited by search s
    ok = base + 1
    for s in range(seeds.shape[0]):
        v0 = seeds[s]
        if full[v0] or trapped[v0] or mark[v0] == ok:
            continue
        tag = base + 2 + s
        heap = [(-key[v0], v0)]
        mark[v0] = tag
        visited = [v0]
        found = False
        while len(heap) > 0:
            item = heapq.heappop(heap)
            v = item[1]
            if is_outlet[v] or mark[v] == ok:
                found = True
                break
            for p in range(indptr[v], indptr[v + 1]):
                w = nbr[p]
                if full[w] or trapped[w]:
                    continue
                if mark[w] == ok:
                    found = True
                    break
                if mark[w] != tag:
                    mark[w] = tag
                    visited.append(w)
                    heapq.heappush(heap, (-key[w], w))
            if found:
                break
        if found:
            for v in visited:
                mark[v] = ok
        else:
            for v in visited:
                trapped[v] = True
            n_new += len(visited)
    stamp[0] = base + 2 + seeds.shape[0]
    return n_new


@jit
def _dijkstra_to_outlet(indptr, nbr, nbr_res, usable, out_res):
    """Shortest-path resistance from every usable pore to the outlet node over usable pores.

    ``nbr_res[p]`` is the wetting resistance of adjacency entry ``p``; ``out_res[v]`` is the
    resistance from pore v to the outlet node (``inf`` when v is not an outlet pore). Returns
    ``(dist, pred)`` where ``pred[v]`` is the next pore towards the outlet (``-1`` = outlet node).
    """
    n = indptr.shape[0] - 1
    dist = np.full(n, _INF)
    pred = np.full(n, -2, dtype=np.int64)
    heap = [(0.0, np.int64(0))]
    heap.pop()
    for v in range(n):
        if usable[v] and out_res[v] < _INF:
            dist[v] = out_res[v]
            pred[v] = -1
            heapq.heappush(heap, (dist[v], np.int64(v)))
    while len(heap) > 0:
        dv, v = heapq.heappop(heap)
        if dv > dist[v]:
            continue
        for p in range(indptr[v], indptr[v + 1]):
            w = nbr[p]
            if not usable[w]:
                continue
            nd = dv + nbr_res[p]
            if nd < dist[w]:
                dist[w] = nd
                pred[w] = v
                heapq.heappush(heap, (nd, np.int64(w)))
    return dist, pred


@jit
def _path_usable(x, pred, usable, max_len):
    """Whether the predecessor chain from pore ``x`` to the outlet still runs over usable pores."""
    v = x
    for _ in range(max_len + 1):
        if v == -1:
            return True
        if v < 0 or not usable[v]:
            return False
        v = pred[v]
    return False


@jit
def _wetting_bound(x, adjacency, search, usable, out_res_x):
    """Shortest wetting path resistance from pore ``x`` to the outlet, from a cached search.

    ``adjacency = (indptr, nbr, nbr_res)``; ``search = (dist, pred)`` is a
    :func:`_dijkstra_to_outlet` result over a wetting region that contains ``usable`` (the region
    only shrinks). Returns ``(r, exact)``: ``r = min(out_res_x, min_y nbr_res[x, y] + d(y))`` over
    usable neighbours ``y`` whose cached path is still usable (there ``d(y) = dist[y]``, the
    shortest distance in ``usable`` too), and whether ``r`` is the value a fresh search over
    ``usable`` would give: false when a neighbour whose cached path is broken has a cached
    distance (a lower bound of its fresh one) below ``r``.
    """
    indptr, nbr, nbr_res = adjacency
    dist, pred = search
    n = indptr.shape[0] - 1
    best = out_res_x
    low_broken = _INF
    for p in range(indptr[x], indptr[x + 1]):
        y = nbr[p]
        if not usable[y]:
            continue
        v = nbr_res[p] + dist[y]
        if v >= best:
            continue
        if _path_usable(y, pred, usable, n):
            best = v
        elif v < low_broken:
            low_broken = v
    return best, low_broken >= best


@jit
def _n_distance(indptr, nbr, nbr_res, full, in_res):
    """Shortest non-wetting path resistance from the virtual inlet node to every full pore.

    Dijkstra over full pores only; ``nbr_res[p]`` is the non-wetting resistance of adjacency
    entry ``p`` and ``in_res[v]`` that of the inlet conduit into pore ``v`` (``inf`` when v is
    not an inlet pore). Returns ``dist`` (n,), ``inf`` for pores that are not full or not joined
    to the inlet through full pores. By Rayleigh's monotonicity law each value bounds the
    effective resistance of the full cluster between the inlet and the pore from above.
    """
    return _dijkstra_to_outlet(indptr, nbr, nbr_res, full, in_res)[0]  # the same search from the inlet side


@jit
def _n_distance_add(x, dist, indptr, nbr, nbr_res, full, in_res):
    """Update :func:`_n_distance`'s ``dist`` in place after pore ``x`` became full (``full[x]`` set).

    Adding a pore to the full cluster only shortens paths, so the update is a Dijkstra from
    ``x`` over the distances that decrease. Returns the number of pores whose distance changed.
    """
    d = in_res[x]
    for p in range(indptr[x], indptr[x + 1]):
        w = nbr[p]
        if full[w] and w != x:
            c = dist[w] + nbr_res[p]
            if c < d:
                d = c
    if not d < dist[x]:
        return 0
    dist[x] = d
    n_changed = 1
    heap = [(d, np.int64(x))]
    while len(heap) > 0:
        dv, v = heapq.heappop(heap)
        if dv > dist[v]:
            continue
        for p in range(indptr[v], indptr[v + 1]):
            w = nbr[p]
            if not full[w]:
                continue
            nd = dv + nbr_res[p]
            if nd < dist[w]:
                dist[w] = nd
                n_changed += 1
                heapq.heappush(heap, (nd, np.int64(w)))
    return n_changed


@jit
def _ball(seeds, indptr, nbr, allowed, hops):
    """Mask (n,) of the ``allowed`` pores within ``hops`` adjacency steps of an allowed seed.

    Breadth-first search from the allowed ``seeds`` that only walks through allowed pores.
    """
    n = indptr.shape[0] - 1
    depth = np.full(n, -1, dtype=np.int64)
    queue = np.empty(n, dtype=np.int64)
    head = 0
    tail = 0
    for s in seeds:
        if s < n and allowed[s] and depth[s] < 0:
            depth[s] = 0
            queue[tail] = s
            tail += 1
    while head < tail:
        v = queue[head]
        head += 1
        if depth[v] >= hops:
            continue
        for p in range(indptr[v], indptr[v + 1]):
            w = nbr[p]
            if allowed[w] and depth[w] < 0:
                depth[w] = depth[v] + 1
                queue[tail] = w
                tail += 1
    return depth >= 0


@jit
def _edge_states(ends, inner, cond_n, cond_w, state):
    """Edge conductances, active-meniscus mask and non-wetting-end mask of a configuration.

    ``ends = (a, b, n)``; ``state = (full, trapped, inv, closed)`` (pores: full, trapped; edges:
    invaded, closed). Node ``n`` (inlet) counts as full, ``n + 1`` (outlet) as not. Returns
    ``(cond, men, fa)``, shapes (E,): non-wetting conduits and active menisci carry ``cond_n``,
    wetting conduits ``cond_w``, pinned menisci and edges touching a trapped pore 0.
    """
    a, b, n = ends
    full, trapped, inv, closed = state
    m = a.shape[0]
    cond = np.zeros(m)
    men = np.zeros(m, dtype=np.bool_)
    fa = np.zeros(m, dtype=np.bool_)
    for e in range(m):
        ae, be = a[e], b[e]
        fae = ae == n or (ae < n and full[ae])
        fbe = be == n or (be < n and full[be])
        fa[e] = fae
        if (ae < n and trapped[ae]) or (be < n and trapped[be]):
            continue
        if inner[e]:
            if fae != fbe:
                if inv[e] and not closed[e]:
                    men[e] = True
                    cond[e] = cond_n[e]
            elif fae:
                cond[e] = cond_n[e]
            else:
                cond[e] = cond_w[e]
        elif fae:
            cond[e] = cond_n[e]
        else:
            cond[e] = cond_w[e]
    return cond, men, fa


@jit
def _open_path(ends, inner, state):
    """Whether ``_edge_states`` would report an active meniscus or a non-wetting outlet conduit.

    Same arguments and the same edge kinds as :func:`_edge_states` (without its arrays): an
    inner edge between a non-wetting and a wetting end that is invaded and not closed, neither
    end trapped; or an outlet conduit with a non-wetting end (trapped or not, as there).
    """
    a, b, n = ends
    full, trapped, inv, closed = state
    for e in range(a.shape[0]):
        ae, be = a[e], b[e]
        fae = ae == n or (ae < n and full[ae])
        if not inner[e]:
            if fae:
                return True
            continue
        fbe = be == n or (be < n and full[be])
        if fae != fbe and inv[e] and not closed[e]:
            if not ((ae < n and trapped[ae]) or (be < n and trapped[be])):
                return True
    return False


@jit
def _assemble(ends, edge, cond, pcb, pos, diag_ref, bc):
    """Values of the pressure matrix (fixed CSR pattern) and the right-hand side of a configuration.

    ``ends = (a, b, n)``, ``edge = (inner, is_in_edge, men, fa)``, ``pos = (pos_diag, pos_ab,
    pos_ba, nnz)``, ``bc = (rate, p_fixed, constant_rate)``. The sums run in the order of
    :meth:`porefsi.flow._drainage_engine.Engine.assemble`'s NumPy twin (bincount, ``add.at``),
    so the values are the same to the bit. Returns ``(data (nnz,), rhs (n + 1,), x)`` with ``x``
    the filling pore of each active meniscus in edge order.
    """
    a, b, n = ends
    inner, is_in, men, fa = edge
    pos_diag, pos_ab, pos_ba, nnz = pos
    rate, p_fixed, const_rate = bc
    m = a.shape[0]
    da = np.zeros(n + 2)
    db = np.zeros(n + 2)
    for e in range(m):
        da[a[e]] += cond[e]
    for e in range(m):
        db[b[e]] += cond[e]
    diag = da[:n + 1] + db[:n + 1]
    rhs = np.zeros(n + 1)
    data = np.zeros(nnz)
    if const_rate:
        rhs[n] = rate
    else:
        for e in range(m):
            if is_in[e]:
                rhs[b[e]] += cond[e] * p_fixed
        diag[n] = 1.0
        rhs[n] = p_fixed
    k = 0
    for e in range(m):
        if men[e]:
            k += 1
    us = np.empty(k, dtype=np.int64)
    xs = np.empty(k, dtype=np.int64)
    src = np.empty(k)
    k = 0
    for e in range(m):
        if men[e]:
            us[k] = a[e] if fa[e] else b[e]
            xs[k] = b[e] if fa[e] else a[e]
            src[k] = cond[e] * pcb[xs[k]]
            k += 1
    for i in range(k):
        rhs[us[i]] += src[i]
    for i in range(k):
        rhs[xs[i]] += -src[i]
    for i in range(n + 1):
        if diag[i] <= 0.0:
            diag[i] = diag_ref[i]
            rhs[i] = 0.0
        data[pos_diag[i]] = diag[i]
    for e in range(m):
        if inner[e]:
            off = 0.0 if (is_in[e] and not const_rate) else -cond[e]
            data[pos_ab[e]] = off
            data[pos_ba[e]] = off
    return data, rhs, xs
