"""Maximal balls and their master/slave hierarchy (private kernels of the extraction).

Integer voxel coordinates: voxel ``(i, j, k)`` has centre ``(i, j, k)`` here. Twins:
``tests/reference/extract_ref.py::maximal_balls``, ``::ball_reach`` and ``::families``.
"""

from __future__ import annotations

import math

import numpy as np

from porefsi._numba import jit, prange
from porefsi.network._mb_prefetch import _prefetch


# --------------------------------------------------------------------------------------------
# Maximal balls
# --------------------------------------------------------------------------------------------
@jit
def _maximal_balls(dt2, min_dt2, offsets, off_class, reach2, scratch, like):
    """Centres of the maximal balls, sorted by radius descending then linear index ascending.

    A candidate ball sits at every voxel ``p`` with ``dt2[p] >= min_dt2``; it is the digital ball
    ``B(p) = {x : |x - p|^2 < dt2[p]}`` (lattice points). It is removed when it lies inside the
    ball of a voxel ``q = p + o`` for one of the ``offsets``: ``B(p)`` is inside ``B(q)`` exactly
    when ``dt2[q] > reach2[c, dt2[p]]``, the largest squared distance from ``q`` to a point of
    ``B(p)`` (``c = off_class[o]``, see :func:`ball_reach_table`).

    Parameters
    ----------
    dt2 : ndarray of uint16 or int32, shape (nx, ny, nz)
    min_dt2 : int
    offsets : ndarray of int64, shape (n_off, 3)
        Neighbour offsets tested (the zero offset excluded).
    off_class : ndarray of int64, shape (n_off,)
        Row of ``reach2`` for each offset.
    reach2 : ndarray of int64, shape (n_class, >= max(dt2) + 1)
    scratch : ndarray of int32, shape (nx, ny, nz)
        All -1 on entry and on exit (used to flag the maximal balls, so no list grows).
    like : ndarray of int32 or int64
        Its dtype is the returned indices' (int32 halves their memory when they fit).

    Returns
    -------
    order : ndarray of ``like.dtype``, shape (M,)
        Linear (C-order) indices of the maximal-ball centres.
    n_candidates : int
    """
    slab_top, slab_cand = _mark_maximal(dt2, min_dt2, offsets, off_class, reach2, scratch)
    top, ncand = slab_top.max(), slab_cand.sum()
    return _flagged_by_level(dt2, scratch, top, like), ncand


@jit(parallel=True)
def _flagged_by_level(dt2, scratch, top, like):
    """Flat indices of the voxels with ``scratch == -2`` (reset to -1), by ``dt2`` descending then C order.

    A counting sort over blocks of slabs on numba's threads: each block counts its voxels per
    level, the blocks' offsets per level follow in block order, then each block writes its voxels
    in C order, so the list does not depend on the number of threads.
    """
    nx, ny, nz = dt2.shape
    nb = min(nx, 64)
    count = np.zeros((nb, top + 2), np.int64)
    for blk in prange(nb):
        for i in range(blk * nx // nb, (blk + 1) * nx // nb):
            for j in range(ny):
                for k in range(nz):
                    if scratch[i, j, k] == -2:
                        count[blk, top - dt2[i, j, k]] += 1
    run = 0
    for key in range(top + 2):
        for blk in range(nb):
            c = count[blk, key]
            count[blk, key] = run
            run += c
    order = np.empty(run, like.dtype)
    for blk in prange(nb):
        for i in range(blk * nx // nb, (blk + 1) * nx // nb):
            for j in range(ny):
                for k in range(nz):
                    if scratch[i, j, k] == -2:
                        scratch[i, j, k] = -1
                        key = top - dt2[i, j, k]
                        order[count[blk, key]] = (i * ny + j) * nz + k
                        count[blk, key] += 1
    return order


@jit(parallel=True)
def _mark_maximal(dt2, min_dt2, offsets, off_class, reach2, scratch):
    """:func:`_maximal_balls`' test: ``scratch[p] = -2`` at every maximal-ball centre p.

    Slabs along the first axis run on numba's threads; each voxel is tested alone (reads ``dt2``,
    writes only its own ``scratch`` entry), so the result does not depend on their number.
    Returns the largest ``dt2`` and the number of candidates of each slab, (nx,) int64 each.
    """
    nx, ny, nz = dt2.shape
    n_off = offsets.shape[0]
    slab_top = np.zeros(nx, np.int64)
    slab_cand = np.zeros(nx, np.int64)
    for i in prange(nx):
        top, ncand = 0, 0
        for j in range(ny):
            for k in range(nz):
                dp = dt2[i, j, k]
                top = max(top, np.int64(dp))
                if dp < min_dt2:
                    continue
                ncand += 1
                maximal = True
                for t in range(n_off):
                    a = i + offsets[t, 0]
                    b = j + offsets[t, 1]
                    c = k + offsets[t, 2]
                    if a < 0 or a >= nx or b < 0 or b >= ny or c < 0 or c >= nz:
                        continue
                    dq = dt2[a, b, c]
                    if dq > dp and dq > reach2[off_class[t], dp]:
                        maximal = False
                        break
                if maximal:
                    scratch[i, j, k] = -2
        slab_top[i], slab_cand[i] = top, ncand
    return slab_top, slab_cand


@jit
def _reach_table(classes, top):
    """``reach2[c, d]``: see :func:`ball_reach_table` (``classes`` sorted, non-negative)."""
    n_cls = classes.shape[0]
    best = np.full((n_cls, top + 1), -1, np.int64)  # max over |y|^2 = n of y . o (sorted)
    a = 0
    while a * a <= top:
        for b in range(a + 1):
            if a * a + b * b > top:
                break
            for c in range(b + 1):
                n = a * a + b * b + c * c
                if n > top:
                    break
                for t in range(n_cls):
                    v = a * classes[t, 0] + b * classes[t, 1] + c * classes[t, 2]
                    if v > best[t, n]:
                        best[t, n] = v
        a += 1
    reach2 = np.zeros((n_cls, top + 1), np.int64)
    for t in range(n_cls):
        o2 = classes[t, 0] ** 2 + classes[t, 1] ** 2 + classes[t, 2] ** 2
        run = -1
        for d in range(1, top + 1):
            n = d - 1
            if best[t, n] >= 0 and n + 2 * best[t, n] > run:
                run = n + 2 * best[t, n]
            reach2[t, d] = run + o2
    return reach2


def ball_reach_table(offsets, top):
    """Largest squared distance from a neighbour to the digital ball of each size.

    For an offset ``o`` and ``d >= 1``: ``max {|y - o|^2 : y integer, |y|^2 < d}``, i.e. how far
    the voxel ``p + o`` is from the farthest voxel of the ball ``B(p)`` of ``dt2[p] = d``. By the
    symmetry of the lattice ball it depends only on the sorted absolute components of ``o`` (its
    class): with ``y`` aligned against ``o``, it is ``max_{n < d} (n + 2 max_{|y|^2 = n} y . o) +
    |o|^2``, where ``y`` and ``o`` both run over sorted non-negative components.

    Parameters
    ----------
    offsets : ndarray of int64, shape (n_off, 3)
    top : int
        Largest ``d`` needed (the maximum of the distance map).

    Returns
    -------
    off_class : ndarray of int64, shape (n_off,)
    reach2 : ndarray of int64, shape (n_class, top + 1)
        ``reach2[:, 0]`` is unused (0).
    """
    key = -np.sort(-np.abs(np.asarray(offsets, np.int64)), axis=1)
    classes, off_class = np.unique(key, axis=0, return_inverse=True)
    reach2 = _reach_table(np.ascontiguousarray(classes, np.int64), int(top))
    return np.ascontiguousarray(off_class.reshape(-1), np.int64), reach2


def ball_offsets(half_width):
    """Neighbour offsets of the maximal-ball test: the cube of ``half_width``, zero excluded.

    Returns
    -------
    ndarray of int64, shape ((2 h + 1)^3 - 1, 3)
        Sorted by length, so the nearest neighbours (most likely to contain the ball) come first.
    """
    r = np.arange(-half_width, half_width + 1)
    o = np.stack(np.meshgrid(r, r, r, indexing="ij"), axis=-1).reshape(-1, 3)
    o = o[np.any(o != 0, axis=1)]
    return np.ascontiguousarray(o[np.argsort((o * o).sum(axis=1), kind="stable")], dtype=np.int64)


# --------------------------------------------------------------------------------------------
# Ball hierarchy (master/slave families) and voxel painting
# --------------------------------------------------------------------------------------------
@jit
def _isqrt(x):
    r = int(math.sqrt(x))
    while r * r > x:
        r -= 1
    while (r + 1) * (r + 1) <= x:
        r += 1
    return r


@jit
def _owner(v):
    """Ball index stored in a painted label (cores are flagged as ``-2 - owner``), -1 if unpainted."""
    if v >= 0:
        return v
    if v <= -2:
        return -2 - v
    return -1


@jit
def _joins(dt2, balls, sqrt_tab, r, centre, rk, rules):
    """Whether a ball of radius ``rk`` centred at ``centre`` may join the family of master ball ``r``.

    ``rules = (extent, ratio)``: its centre lies within ``extent`` master radii of the master's
    centre, or it is clearly smaller (``rk < ratio * R_master``).
    """
    ny, nz = dt2.shape[1], dt2.shape[2]
    q = np.int64(balls[r])
    qi, qj, ql = q // (ny * nz), (q // nz) % ny, q % nz
    s = (qi - centre[0]) ** 2 + (qj - centre[1]) ** 2 + (ql - centre[2]) ** 2
    rm = sqrt_tab[dt2[qi, qj, ql]]
    reach = rules[0] * rm
    return s < reach * reach or rk < rules[1] * rm


@jit
def _prefetch_plane(lf, dims, a, ijl, lim):
    """Prefetch the rows of plane ``a`` of the ball ``|x - ijl|^2 <= lim`` (around its centre column).

    The hierarchy's scans are bound by the latency of these rows (each in its own cache line,
    planes megabytes apart); fetched one plane ahead, they arrive while the current plane is
    scanned. A hint: nothing is read into the kernel.
    """
    ny, nz = dims[1], dims[2]
    i, j, l = ijl
    hn = _isqrt(lim - (a - i) * (a - i))
    for b in range(max(j - hn, 0), min(j + hn, ny - 1) + 1):
        row = (np.int64(a) * ny + b) * nz + l
        _prefetch(lf, row - 8)
        _prefetch(lf, row + 8)


@jit
def _scan_ball(dt2, balls, sqrt_tab, labels, fam, k, rules):
    """Scan the voxels of ball ``k``: paint the unpainted ones, flag its core, find the ball to adopt.

    ``fam = (master, stamp)`` (``stamp[r] == k``: master ``r`` already refused ``k``); ``rules =
    (extent, ratio, core^2)``. Returns the first-visited (largest) covering ball whose family
    ``k`` may join (:func:`_joins`), or ``balls.size`` if none.
    """
    nx, ny, nz = dt2.shape
    master, stamp = fam
    p = np.int64(balls[k])
    i, j, l = p // (ny * nz), (p // nz) % ny, p % nz
    d2 = dt2[i, j, l]
    rk, lim, cl = sqrt_tab[d2], d2 - 1, rules[2] * d2
    h = _isqrt(lim)
    best = balls.size
    lf = labels.reshape(-1)
    _prefetch_plane(lf, labels.shape, max(i - h, 0), (i, j, l), lim)
    for a in range(max(i - h, 0), min(i + h, nx - 1) + 1):
        da = (a - i) * (a - i)
        hb = _isqrt(lim - da)
        if a < min(i + h, nx - 1):
            _prefetch_plane(lf, labels.shape, a + 1, (i, j, l), lim)
        for b in range(max(j - hb, 0), min(j + hb, ny - 1) + 1):
            dab = da + (b - j) * (b - j)
            w = _isqrt(lim - dab)
            for c in range(max(l - w, 0), min(l + w, nz - 1) + 1):
                v = labels[a, b, c]
                if v == -1:  # paint (flagged if in k's core)
                    labels[a, b, c] = -2 - k if dab + (c - l) * (c - l) < cl else k
                    continue
                o = _owner(v)
                if o < best and stamp[master[o]] != k:
                    if _joins(dt2, balls, sqrt_tab, master[o], (i, j, l), rk, rules):
                        best = o
                    else:
                        stamp[master[o]] = k
                if v >= 0 and dab + (c - l) * (c - l) < cl:  # flag a painted voxel of k's core
                    labels[a, b, c] = -2 - v
    return best


@jit
def _claim_ball(dt2, labels, p, k):
    """Label every voxel of the ball centred at flat index ``p`` with ``k`` (core flags kept)."""
    nx, ny, nz = dt2.shape
    i, j, l = p // (ny * nz), (p // nz) % ny, p % nz
    lim = dt2[i, j, l] - 1
    h = _isqrt(lim)
    for a in range(max(i - h, 0), min(i + h, nx - 1) + 1):
        da = (a - i) * (a - i)
        hb = _isqrt(lim - da)
        for b in range(max(j - hb, 0), min(j + hb, ny - 1) + 1):
            dab = da + (b - j) * (b - j)
            w = _isqrt(lim - dab)
            for c in range(max(l - w, 0), min(l + w, nz - 1) + 1):
                labels[a, b, c] = -2 - k if labels[a, b, c] <= -2 else k


@jit
def _families(dt2, balls, sqrt_tab, extent, ratio, labels, core):
    """Build the master/slave hierarchy of the maximal balls and paint the voxels they cover.

    Balls are visited in the order given (radius descending). A ball whose centre voxel lies in
    the *core* of a ball visited before it (the voxels within ``core`` times that ball's radius
    of its centre) is skipped: it joins the family of the ball owning its centre voxel and paints
    nothing (with ``core > 0`` the balls kept are spaced about ``core`` radii apart along the
    medial axis, so the work per voxel does not grow with the pore radius in voxels; ``core = 0``
    skips nothing). Every other ball ``k`` scans the voxels it covers (:func:`_scan_ball`): voxels
    nobody covers yet are painted ``k``; among the balls that already cover some of its voxels
    (all at least as large as ``k``) it adopts the first-visited, i.e. largest, one whose family
    master either lies within ``extent`` master radii of ``k``'s centre or is clearly larger than
    ``k`` (``R_k < ratio * R_master``). With no such ball ``k`` becomes a master (a pore) and
    claims every voxel of its ball. So a channel narrower than its master stays in the family
    however long it is, while a uniform channel (no larger master) is cut every ``extent`` radii.

    Parameters
    ----------
    dt2 : ndarray of uint16 or int32, shape (nx, ny, nz)
    balls : ndarray of int32 or int64, shape (M,)
        Linear indices of maximal-ball centres, radius descending.
    sqrt_tab : ndarray of float64
        ``sqrt(n)`` for ``n = 0 .. max(dt2)``.
    extent, ratio : float
        Family reach in master radii; balls smaller than ``ratio`` master radii join at any distance.
    labels : ndarray of int32, shape (nx, ny, nz)
        All -1 on entry; on exit the index of the ball owning each covered voxel, -1 elsewhere.
    core : float
        Core radius in ball radii, in [0, 1).

    Returns
    -------
    master : ndarray of int32, shape (M,)
        Index (into ``balls``) of each ball's family master; ``master[k] == k`` for masters.
    n_kept : int
        Balls scanned (not skipped).
    """
    nb = balls.size
    master = np.empty(nb, np.int32)
    stamp = np.full(nb, -1, np.int32)
    lf = labels.reshape(-1)
    rules = (extent, ratio, core * core)
    n_kept = 0
    for k in range(nb):
        p = np.int64(balls[k])
        if lf[p] <= -2:  # centred in a scanned ball's core: join its family unscanned
            master[k] = master[-2 - lf[p]]
            continue
        n_kept += 1
        best = _scan_ball(dt2, balls, sqrt_tab, labels, (master, stamp), k, rules)
        if best < nb:
            master[k] = master[best]
        else:
            master[k] = k
            _claim_ball(dt2, labels, p, k)
    _unflag(labels)
    return master, n_kept


@jit(parallel=True)
def _unflag(labels):
    """Core flags ``-2 - owner`` back to ``owner``, slabs on numba's threads."""
    nx, ny, nz = labels.shape
    for i in prange(nx):
        for j in range(ny):
            for k in range(nz):
                if labels[i, j, k] <= -2:
                    labels[i, j, k] = -2 - labels[i, j, k]


@jit(parallel=True)
def _fill(a, value):
    """``a[...] = value`` by slabs on numba's threads (the pages are first touched in parallel)."""
    for i in prange(a.shape[0]):
        a[i] = value
