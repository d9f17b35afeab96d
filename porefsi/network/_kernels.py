"""Numba kernels of the maximal-ball extraction (private; called by :mod:`porefsi.network.extract`).

Every kernel takes arrays and scalars only and has a slow pure-Python twin in
``tests/reference/extract_ref.py``. Integer voxel coordinates: voxel ``(i, j, k)`` has centre
``(i, j, k)`` here; the public wrapper adds the half voxel and the origin.
"""

from __future__ import annotations

import math

import numpy as np
from numba import types
from numba.typed import Dict

from porefsi._numba import jit

#: "No solid anywhere on this line" in an int32 squared distance map.
INF = np.int32(np.iinfo(np.int32).max)
#: Cap of a uint16 squared distance map (radii up to 255 voxels are exact below it).
CAP16 = np.uint16(np.iinfo(np.uint16).max)


# --------------------------------------------------------------------------------------------
# Squared Euclidean distance transform (Felzenszwalb & Huttenlocher 2012, separable)
# --------------------------------------------------------------------------------------------
@jit
def _envelope_line(f, n, d, v, z, inf):
    """Lower envelope of parabolas ``f[p] + (q - p)^2`` on one line; ``d[q]`` its minimum over p.

    ``f`` entries ``>= inf`` are skipped (no solid voxel within reach on that line); results are
    capped at ``inf``.
    """
    k = -1
    for q in range(n):
        fq = f[q]
        if fq >= inf:
            continue
        s = 0.0
        while k >= 0:
            p = v[k]
            s = ((fq + q * q) - (f[p] + p * p)) / (2.0 * (q - p))
            if s <= z[k]:
                k -= 1
            else:
                break
        if k < 0:
            k = 0
            v[0] = q
            z[0] = -np.inf
            z[1] = np.inf
        else:
            k += 1
            v[k] = q
            z[k] = s
            z[k + 1] = np.inf
    if k < 0:
        for q in range(n):
            d[q] = inf
        return
    k = 0
    for q in range(n):
        while z[k + 1] < q:
            k += 1
        p = v[k]
        val = (q - p) * (q - p) + f[p]
        d[q] = val if val < inf else inf


@jit
def _sq_edt(pore, out, cap):
    """Squared distance (voxel units) from each pore voxel to the nearest solid voxel centre.

    Solid voxels get 0. Outside the image is *not* solid. Values are ``min(d^2, cap)``: exact
    wherever the true value is below ``cap`` (a capped intermediate only ever feeds candidates
    that are themselves ``>= cap``), ``cap`` where no solid voxel is nearer.

    Parameters
    ----------
    pore : ndarray of uint8, shape (nx, ny, nz)
        1 = pore.
    out : ndarray of int32 or uint16, shape (nx, ny, nz)
        Written in place.
    cap : int
        The largest value ``out`` can hold (:data:`INF` for int32, :data:`CAP16` for uint16).
    """
    nx, ny, nz = pore.shape
    m = max(nx, ny, nz)
    f = np.empty(m, np.int64)
    d = np.empty(m, np.int64)
    v = np.empty(m, np.int64)
    z = np.empty(m + 1, np.float64)
    inf = np.int64(cap)
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                f[k] = inf if pore[i, j, k] else 0
            _envelope_line(f, nz, d, v, z, inf)
            for k in range(nz):
                out[i, j, k] = d[k]
    for i in range(nx):
        for k in range(nz):
            for j in range(ny):
                f[j] = out[i, j, k]
            _envelope_line(f, ny, d, v, z, inf)
            for j in range(ny):
                out[i, j, k] = d[j]
    # last axis: gather a slab of lines at a time would be more cache friendly; the strided
    # gather costs ~20 % of the EDT on 400^3 and keeps the memory at one line.
    for j in range(ny):
        for k in range(nz):
            for i in range(nx):
                f[i] = out[i, j, k]
            _envelope_line(f, nx, d, v, z, inf)
            for i in range(nx):
                out[i, j, k] = d[i]


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


@jit
def _relabel(labels, table):
    """``labels[v] = table[labels[v]]`` where ``labels[v] >= 0``, in place."""
    flat = labels.reshape(-1)
    for n in range(flat.size):
        o = flat[n]
        if o >= 0:
            flat[n] = table[o]


# --------------------------------------------------------------------------------------------
# Voxel labels: seeded priority flood on the distance map (marker watershed)
# --------------------------------------------------------------------------------------------
@jit
def _flood(dt2, labels, buf, queue):
    """Grow the seed labels over the pore space, highest distance-map values first.

    Level by level from the largest ``dt2`` down: the unlabelled voxels of the level that touch
    a labelled face neighbour (C order; label of the first labelled neighbour in the order -x,
    +x, -y, +y, -z, +z) start a first-in first-out growth into every unlabelled pore voxel
    with ``dt2 >=`` the level. So a region only ever grows through voxels at least as wide as
    the level being flooded, two floods meet at the narrowest section between them (the
    saddle of the distance map; on a plateau, half-way), and every region stays 6-connected.
    Pore voxels not connected to a seed stay -1.

    Parameters
    ----------
    dt2 : ndarray of uint16 or int32, shape (nx, ny, nz)
        0 on solid.
    labels : ndarray of int32, shape (nx, ny, nz)
        Seeds ``>= 0``, -1 elsewhere; grown in place.
    buf, queue : ndarray of int32 or int64, shape (>= number of unlabelled pore voxels,)
        Work space (voxel indices sorted by level; the growth queue).

    Returns
    -------
    int
        Voxels labelled.
    """
    nx, ny, nz = dt2.shape
    nyz = ny * nz
    df = dt2.reshape(-1)
    lf = labels.reshape(-1)
    top = 0
    for n in range(df.size):
        if lf[n] < 0 and df[n] > top:
            top = df[n]
    count = np.zeros(top + 2, np.int64)
    for n in range(df.size):
        if lf[n] < 0 and df[n] > 0:
            count[top - df[n]] += 1
    start = np.zeros(top + 2, np.int64)
    for t in range(1, top + 2):
        start[t] = start[t - 1] + count[t - 1]
    fill = start.copy()
    for n in range(df.size):
        if lf[n] < 0 and df[n] > 0:
            key = top - df[n]
            buf[fill[key]] = n
            fill[key] += 1
    offs = np.array([-nyz, nyz, -nz, nz, -1, 1], np.int64)
    done = 0
    for key in range(top):
        level = top - key
        tail = 0
        for s in range(start[key], start[key + 1]):
            n = np.int64(buf[s])
            if lf[n] != -1:
                continue
            i = n // nyz
            j = (n // nz) % ny
            k = n % nz
            for t in range(6):
                if (t == 0 and i == 0) or (t == 1 and i == nx - 1) or (t == 2 and j == 0):
                    continue
                if (t == 3 and j == ny - 1) or (t == 4 and k == 0) or (t == 5 and k == nz - 1):
                    continue
                lab = lf[n + offs[t]]
                if lab >= 0:
                    lf[n] = -2 - lab  # pending: invisible to the rest of this scan
                    queue[tail] = n
                    tail += 1
                    break
        for h in range(tail):
            n = np.int64(queue[h])
            lf[n] = -2 - lf[n]
        head = 0
        while head < tail:
            n = np.int64(queue[head])
            head += 1
            i = n // nyz
            j = (n // nz) % ny
            k = n % nz
            lab = lf[n]
            for t in range(6):
                if (t == 0 and i == 0) or (t == 1 and i == nx - 1) or (t == 2 and j == 0):
                    continue
                if (t == 3 and j == ny - 1) or (t == 4 and k == 0) or (t == 5 and k == nz - 1):
                    continue
                m = n + offs[t]
                if lf[m] == -1 and df[m] >= level:
                    lf[m] = lab
                    queue[tail] = m
                    tail += 1
        done += tail
    return done


# --------------------------------------------------------------------------------------------
# Throats: interfaces between pore labels
# --------------------------------------------------------------------------------------------
@jit
def _interfaces(labels, dt2, n_pores):
    """Aggregate the voxel faces shared by two different pore labels into throats.

    For each pair ``(a < b)`` of touching labels: the number of shared faces, the largest
    ``w = min(dt2[u], dt2[v])`` over its faces ``(u, v)`` (squared inscribed radius on the
    interface) and the centre of the first face that attains it (voxel-index coordinates, a
    face between voxels ``i`` and ``i + 1`` sits at ``i + 0.5``). Throats are numbered in the
    order their first face is met in a C-order scan (x, then y, then z faces per voxel).

    Returns
    -------
    conns : ndarray of int64, shape (Nt, 2)
    w : ndarray of int64, shape (Nt,)
    point : ndarray of float64, shape (Nt, 3)
    n_faces : ndarray of int64, shape (Nt,)
    """
    nx, ny, nz = labels.shape
    table = Dict.empty(key_type=types.int64, value_type=types.int64)
    cap = 256
    conns = np.empty((cap, 2), np.int64)
    w = np.empty(cap, np.int64)
    point = np.empty((cap, 3), np.float64)
    nf = np.empty(cap, np.int64)
    nt = 0
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                la = labels[i, j, k]
                if la < 0:
                    continue
                for ax in range(3):
                    a, b, c = i, j, k
                    if ax == 0:
                        a += 1
                        if a >= nx:
                            continue
                    elif ax == 1:
                        b += 1
                        if b >= ny:
                            continue
                    else:
                        c += 1
                        if c >= nz:
                            continue
                    lb = labels[a, b, c]
                    if lb < 0 or lb == la:
                        continue
                    lo = min(la, lb)
                    hi = max(la, lb)
                    key = np.int64(lo) * n_pores + hi
                    val = min(dt2[i, j, k], dt2[a, b, c])
                    if key in table:
                        t = table[key]
                    else:
                        if nt == cap:
                            cap *= 2
                            c2 = np.empty((cap, 2), np.int64)
                            c2[:nt] = conns[:nt]
                            conns = c2
                            w2 = np.empty(cap, np.int64)
                            w2[:nt] = w[:nt]
                            w = w2
                            p2 = np.empty((cap, 3), np.float64)
                            p2[:nt] = point[:nt]
                            point = p2
                            n2 = np.empty(cap, np.int64)
                            n2[:nt] = nf[:nt]
                            nf = n2
                        t = np.int64(nt)
                        nt += 1
                        table[key] = t
                        conns[t, 0] = lo
                        conns[t, 1] = hi
                        w[t] = -1
                        nf[t] = 0
                    nf[t] += 1
                    if val > w[t]:
                        w[t] = val
                        point[t, 0] = i + 0.5 * (a - i)
                        point[t, 1] = j + 0.5 * (b - j)
                        point[t, 2] = k + 0.5 * (c - k)
    return conns[:nt].copy(), w[:nt].copy(), point[:nt].copy(), nf[:nt].copy()


@jit
def _pore_stats(labels, n_pores):
    """Voxel count of each pore region and whether it touches each box face.

    Returns
    -------
    count : ndarray of int64, shape (Np,)
    faces : ndarray of bool, shape (Np, 6)
        Columns xmin, xmax, ymin, ymax, zmin, zmax.
    """
    nx, ny, nz = labels.shape
    count = np.zeros(n_pores, np.int64)
    faces = np.zeros((n_pores, 6), np.bool_)
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                p = labels[i, j, k]
                if p < 0:
                    continue
                count[p] += 1
                if i == 0:
                    faces[p, 0] = True
                if i == nx - 1:
                    faces[p, 1] = True
                if j == 0:
                    faces[p, 2] = True
                if j == ny - 1:
                    faces[p, 3] = True
                if k == 0:
                    faces[p, 4] = True
                if k == nz - 1:
                    faces[p, 5] = True
    return count, faces
