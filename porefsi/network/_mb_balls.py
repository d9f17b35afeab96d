"""Maximal balls and their master/slave hierarchy (private kernels of the extraction).

Integer voxel coordinates: voxel ``(i, j, k)`` has centre ``(i, j, k)`` here. Twins:
``tests/reference/extract_ref.py::maximal_balls`` and ``::families``.
"""

from __future__ import annotations

import math

import numpy as np

from porefsi._numba import jit


# --------------------------------------------------------------------------------------------
# Maximal balls
# --------------------------------------------------------------------------------------------
@jit
def _maximal_balls(dt2, min_dt2, sqrt_tab, offsets, scratch):
    """Centres of the maximal balls, sorted by radius descending then linear index ascending.

    A candidate ball sits at every voxel with ``dt2 >= min_dt2`` (radius ``sqrt(dt2)``); it is
    removed when the ball of a voxel ``q = p + o`` for one of the ``offsets`` contains it,
    ``sqrt(dt2[q]) >= sqrt(dt2[p]) + |o|``.

    Parameters
    ----------
    dt2 : ndarray of uint16 or int32, shape (nx, ny, nz)
    min_dt2 : int
    sqrt_tab : ndarray of float64
        ``sqrt(n)`` for ``n = 0 .. max(dt2)``.
    offsets : ndarray of int64, shape (n_off, 3)
        Neighbour offsets tested (the zero offset excluded).
    scratch : ndarray of int32, shape (nx, ny, nz)
        All -1 on entry and on exit (used to flag the maximal balls, so no list grows).

    Returns
    -------
    order : ndarray of int64, shape (M,)
        Linear (C-order) indices of the maximal-ball centres.
    n_candidates : int
    """
    nx, ny, nz = dt2.shape
    eps = 1e-9
    ncand = 0
    n_off = offsets.shape[0]
    olen = np.empty(n_off, np.float64)
    for t in range(n_off):
        olen[t] = math.sqrt(offsets[t, 0] ** 2 + offsets[t, 1] ** 2 + offsets[t, 2] ** 2)
    top = 0
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                if dt2[i, j, k] > top:
                    top = dt2[i, j, k]
    count = np.zeros(top + 2, np.int64)
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                dp = dt2[i, j, k]
                if dp < min_dt2:
                    continue
                ncand += 1
                rp = sqrt_tab[dp]
                maximal = True
                for t in range(n_off):
                    a = i + offsets[t, 0]
                    b = j + offsets[t, 1]
                    c = k + offsets[t, 2]
                    if a < 0 or a >= nx or b < 0 or b >= ny or c < 0 or c >= nz:
                        continue
                    dq = dt2[a, b, c]
                    if dq > dp and sqrt_tab[dq] >= rp + olen[t] - eps:
                        maximal = False
                        break
                if maximal:
                    scratch[i, j, k] = -2
                    count[top - dp] += 1
    start = np.zeros(top + 2, np.int64)
    for t in range(1, top + 2):
        start[t] = start[t - 1] + count[t - 1]
    order = np.empty(start[top + 1], np.int64)
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                if scratch[i, j, k] == -2:
                    scratch[i, j, k] = -1
                    key = top - dt2[i, j, k]
                    order[start[key]] = (i * ny + j) * nz + k
                    start[key] += 1
    return order, ncand


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
def _families(dt2, balls, sqrt_tab, extent, ratio, labels):
    """Build the master/slave hierarchy of the maximal balls and paint the voxels they cover.

    Balls are visited in the order given (radius descending). Ball ``k`` scans the voxels it
    covers (squared distance to its centre ``< dt2``); voxels nobody covers yet are painted
    ``k``; among the balls that already cover some of its voxels (all at least as large as
    ``k``) it adopts the first-visited, i.e. largest, one whose family master either lies within
    ``extent`` master radii of ``k``'s centre or is clearly larger than ``k``
    (``R_k < ratio * R_master``). With no such ball ``k`` becomes a master (a pore) and claims
    every voxel of its ball. So a channel narrower than its master stays in the family however
    long it is, while a uniform channel (no larger master) is cut every ``extent`` radii.

    Parameters
    ----------
    dt2 : ndarray of uint16 or int32, shape (nx, ny, nz)
    balls : ndarray of int64, shape (M,)
        Linear indices of maximal-ball centres, radius descending.
    sqrt_tab : ndarray of float64
        ``sqrt(n)`` for ``n = 0 .. max(dt2)``.
    extent : float
        Family reach, in master radii, for balls of comparable size.
    ratio : float
        Balls smaller than ``ratio`` times the master radius join regardless of distance.
    labels : ndarray of int32, shape (nx, ny, nz)
        All -1 on entry; on exit the index of the ball owning each covered voxel, -1 elsewhere.

    Returns
    -------
    master : ndarray of int32, shape (M,)
        Index (into ``balls``) of each ball's family master; ``master[k] == k`` for masters.
    """
    nx, ny, nz = dt2.shape
    nb = balls.size
    master = np.empty(nb, np.int32)
    stamp = np.full(nb, -1, np.int32)
    for k in range(nb):
        p = balls[k]
        i = p // (ny * nz)
        j = (p // nz) % ny
        l = p % nz
        d2 = dt2[i, j, l]
        rk = sqrt_tab[d2]
        lim = d2 - 1
        h = _isqrt(lim)
        best = nb
        for a in range(max(i - h, 0), min(i + h, nx - 1) + 1):
            da = (a - i) * (a - i)
            hb = _isqrt(lim - da)
            for b in range(max(j - hb, 0), min(j + hb, ny - 1) + 1):
                dab = da + (b - j) * (b - j)
                w = _isqrt(lim - dab)
                for c in range(max(l - w, 0), min(l + w, nz - 1) + 1):
                    o = labels[a, b, c]
                    if o < 0:
                        labels[a, b, c] = k
                    elif o < best:
                        r = master[o]
                        if stamp[r] == k:
                            continue
                        q = balls[r]
                        qi = q // (ny * nz)
                        qj = (q // nz) % ny
                        ql = q % nz
                        s = (qi - i) * (qi - i) + (qj - j) * (qj - j) + (ql - l) * (ql - l)
                        rm = sqrt_tab[dt2[qi, qj, ql]]
                        reach = extent * rm
                        if s < reach * reach or rk < ratio * rm:
                            best = o
                        else:
                            stamp[r] = k
        if best < nb:
            master[k] = master[best]
        else:
            master[k] = k
            for a in range(max(i - h, 0), min(i + h, nx - 1) + 1):
                da = (a - i) * (a - i)
                hb = _isqrt(lim - da)
                for b in range(max(j - hb, 0), min(j + hb, ny - 1) + 1):
                    dab = da + (b - j) * (b - j)
                    w = _isqrt(lim - dab)
                    for c in range(max(l - w, 0), min(l + w, nz - 1) + 1):
                        labels[a, b, c] = k
    return master
