"""Voxel regions of the pores and their interfaces (private kernels of the extraction).

Twins: ``tests/reference/extract_ref.py::flood``, ``::interfaces``, ``::pore_stats``; ``_relabel``
is checked against numpy fancy indexing.
"""

from __future__ import annotations

import numpy as np
from numba import types
from numba.typed import Dict

from porefsi._numba import jit, prange
from porefsi.network._mb_edt import _d2
from porefsi.network._mb_prefetch import _prefetch

#: Queue entries between a voxel's prefetch and its use in the label flood.
PREFETCH_AHEAD = 8


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
def _coords(n, dims):
    """Voxel (i, j, k) of flat index ``n`` (two integer divisions)."""
    q = n // dims[2]
    i = q // dims[1]
    return i, q - i * dims[1], n - q * dims[2]


@jit
def _neighbour(n, t, ijk, dims):
    """Flat index of the face neighbour ``t`` (-x, +x, -y, +y, -z, +z) of voxel ``n`` at ``ijk``, -1 outside.

    ``ijk`` = :func:`_coords` of ``n``, decoded once per voxel (a division costs more than the rest).
    """
    nx, ny, nz = dims
    i, j, k = ijk
    if t == 0:
        return -1 if i == 0 else n - ny * nz
    if t == 1:
        return -1 if i == nx - 1 else n + ny * nz
    if t == 2:
        return -1 if j == 0 else n - nz
    if t == 3:
        return -1 if j == ny - 1 else n + nz
    if t == 4:
        return -1 if k == 0 else n - 1
    return -1 if k == nz - 1 else n + 1


@jit(parallel=True)
def _sort_by_level(df, lf, buf):
    """Unlabelled pore voxels into ``buf`` by distance-map level, highest first; (segment starts, top).

    Within a level in C order. A counting sort over blocks of the flat arrays on numba's threads
    (block counts per level, offsets in block order, each block writes its voxels in order), so
    ``buf`` does not depend on the number of threads.
    """
    size = df.size
    nb = 64
    tops = np.zeros(nb, np.int64)
    for blk in prange(nb):
        t = 0
        for n in range(blk * size // nb, (blk + 1) * size // nb):
            if lf[n] < 0 and df[n] > t:
                t = df[n]
        tops[blk] = t
    top = tops.max()
    count = np.zeros((nb, top + 2), np.int64)
    for blk in prange(nb):
        for n in range(blk * size // nb, (blk + 1) * size // nb):
            if lf[n] < 0 and df[n] > 0:
                count[blk, top - df[n]] += 1
    start = np.zeros(top + 2, np.int64)
    run = 0
    for key in range(top + 2):
        start[key] = run
        for blk in range(nb):
            c = count[blk, key]
            count[blk, key] = run
            run += c
    for blk in prange(nb):
        for n in range(blk * size // nb, (blk + 1) * size // nb):
            if lf[n] < 0 and df[n] > 0:
                key = top - df[n]
                buf[count[blk, key]] = n
                count[blk, key] += 1
    return start, top


@jit
def _flood_level(df, lf, dims, segment, queue, level):
    """Flood one level: its voxels touching a label start a FIFO growth through voxels ``>= level``.

    ``segment`` is the level's slice of the level-sorted list (read before the queue reaches it).
    Returns the number of voxels labelled.
    """
    tail = 0
    sx, sy = np.int64(dims[1]) * dims[2], np.int64(dims[2])
    for s in range(segment.size):
        if s + PREFETCH_AHEAD < segment.size:
            f = np.int64(segment[s + PREFETCH_AHEAD])
            _prefetch(lf, f)
            _prefetch(lf, f - sx)
            _prefetch(lf, f + sx)
        n = np.int64(segment[s])
        if lf[n] != -1:
            continue
        ijk = _coords(n, dims)
        for t in range(6):
            m = _neighbour(n, t, ijk, dims)
            if m >= 0 and lf[m] >= 0:
                lf[n] = -2 - lf[m]  # pending: invisible to the rest of this scan
                queue[tail] = n
                tail += 1
                break
    for h in range(tail):
        n = np.int64(queue[h])
        lf[n] = -2 - lf[n]
    head = 0
    while head < tail:
        if head + PREFETCH_AHEAD < tail:  # the far neighbours of a voxel a few steps ahead
            f = np.int64(queue[head + PREFETCH_AHEAD])
            _prefetch(lf, f - sx)
            _prefetch(lf, f + sx)
            _prefetch(lf, f - sy)
            _prefetch(lf, f + sy)
            _prefetch(df, f - sx)
            _prefetch(df, f + sx)
        n = np.int64(queue[head])
        head += 1
        ijk = _coords(n, dims)
        for t in range(6):
            m = _neighbour(n, t, ijk, dims)
            if m >= 0 and lf[m] == -1 and df[m] >= level:
                lf[m] = lf[n]
                queue[tail] = m
                tail += 1
    return tail


@jit
def _flood(dt2, labels, buf, queue):
    """Grow the seed labels over the pore space, highest distance-map values first.

    Level by level from the largest ``dt2`` down: the unlabelled voxels of the level that touch
    a labelled face neighbour (C order; label of the first labelled neighbour in the order -x,
    +x, -y, +y, -z, +z) start a first-in first-out growth into every unlabelled pore voxel
    with ``dt2 >=`` the level (:func:`_flood_level`). So a region only ever grows through voxels
    at least as wide as the level being flooded, two floods meet at the narrowest section between
    them (the saddle of the distance map; on a plateau, half-way), and every region stays
    6-connected. Pore voxels not connected to a seed stay -1.

    Parameters
    ----------
    dt2 : ndarray of uint16 or int32, shape (nx, ny, nz)
        0 on solid.
    labels : ndarray of int32, shape (nx, ny, nz)
        Seeds ``>= 0``, -1 elsewhere; grown in place.
    buf, queue : ndarray of int32 or int64, shape (>= number of unlabelled pore voxels,)
        Work space (voxel indices sorted by level; the growth queue). They may be the same
        array: at level L the queue holds distinct unlabelled voxels of level >= L, so it never
        holds more entries than ``buf``'s segments of the levels >= L, which are read (the
        current one during its scan, before the queue passes it) and never read again.

    Returns
    -------
    int
        Voxels labelled.
    """
    df = dt2.reshape(-1)
    lf = labels.reshape(-1)
    start, top = _sort_by_level(df, lf, buf)
    done = 0
    for key in range(top):
        done += _flood_level(df, lf, dt2.shape, buf[start[key]:start[key + 1]], queue, top - key)
    return done


# --------------------------------------------------------------------------------------------
# Throats: interfaces between pore labels
# --------------------------------------------------------------------------------------------
@jit
def _grown(conns, w, point, nf, nt):
    """The four throat arrays with twice the capacity, their first ``nt`` rows kept."""
    cap = 2 * conns.shape[0]
    c2 = np.empty((cap, 2), np.int64)
    w2 = np.empty(cap, np.int64)
    p2 = np.empty((cap, 3), np.float64)
    n2 = np.empty(cap, np.int64)
    c2[:nt], w2[:nt], p2[:nt], n2[:nt] = conns[:nt], w[:nt], point[:nt], nf[:nt]
    return c2, w2, p2, n2


@jit
def _interfaces(labels, dt2, n_pores, walls=None):
    """Aggregate the voxel faces shared by two different pore labels into throats.

    For each pair ``(a < b)`` of touching labels: the number of shared faces, the largest
    ``w = min(dt2[u], dt2[v])`` over its faces ``(u, v)`` (squared inscribed radius on the
    interface) and the centre of the first face that attains it (voxel-index coordinates, a
    face between voxels ``i`` and ``i + 1`` sits at ``i + 0.5``). Throats are numbered in the
    order their first face is met in a C-order scan (x, then y, then z faces per voxel).
    ``walls`` (int64 (3,), optional): axes whose box faces count as solid for ``w``
    (:func:`porefsi.network._mb_edt._d2`); none by default. The faces are found by slabs on
    numba's threads (:func:`_interface_faces`, in scan order, so the result does not depend on
    their number) and aggregated in that order.

    Returns
    -------
    conns : ndarray of int64, shape (Nt, 2)
    w : ndarray of int64, shape (Nt,)
    point : ndarray of float64, shape (Nt, 3)
    n_faces : ndarray of int64, shape (Nt,)
    """
    nx, ny, nz = labels.shape
    box = np.zeros(3, np.int64) if walls is None else walls
    faces = _interface_faces(labels)
    table = Dict.empty(key_type=types.int64, value_type=types.int64)
    conns, w = np.empty((256, 2), np.int64), np.empty(256, np.int64)
    point, nf = np.empty((256, 3), np.float64), np.empty(256, np.int64)
    nt = 0
    for f in range(faces.size):
        code = faces[f]
        ax = code % 3
        q = code // 3 // nz
        i = q // ny
        j, k = q - i * ny, code // 3 - q * nz
        a, b, c = i + (ax == 0), j + (ax == 1), k + (ax == 2)
        la, lb = labels[i, j, k], labels[a, b, c]
        key = np.int64(min(la, lb)) * n_pores + max(la, lb)
        if key in table:
            t = table[key]
        else:
            if nt == conns.shape[0]:
                conns, w, point, nf = _grown(conns, w, point, nf, nt)
            t = np.int64(nt)
            nt += 1
            table[key] = t
            conns[t, 0], conns[t, 1] = min(la, lb), max(la, lb)
            w[t], nf[t] = -1, 0
        nf[t] += 1
        val = min(_d2(dt2, i, j, k, box), _d2(dt2, a, b, c, box))
        if val > w[t]:
            w[t] = val
            point[t, 0], point[t, 1], point[t, 2] = 0.5 * (i + a), 0.5 * (j + b), 0.5 * (k + c)
    return conns[:nt].copy(), w[:nt].copy(), point[:nt].copy(), nf[:nt].copy()


@jit(parallel=True)
def _interface_faces(labels):
    """Faces shared by two different pore labels, as ``3 * flat_index + axis`` of their lower voxel, in C order.

    Two passes over slabs along the first axis on numba's threads: count, then write each slab's
    faces at its offset, so the list is the sequential scan's (x, then y, then z face per voxel).
    """
    nx = labels.shape[0]
    count = np.zeros(nx + 1, np.int64)
    for i in prange(nx):
        count[i + 1] = _slab_faces(labels, i, count[:0], 0)
    for i in range(nx):
        count[i + 1] += count[i]
    out = np.empty(count[nx], np.int64)
    for i in prange(nx):
        _slab_faces(labels, i, out, count[i])
    return out


@jit
def _slab_faces(labels, i, out, start):
    """Interface faces of slab ``i``: counted, and written to ``out[start:]`` unless ``out`` is empty."""
    nx, ny, nz = labels.shape
    t = start
    for j in range(ny):
        for k in range(nz):
            la = labels[i, j, k]
            if la < 0:
                continue
            for ax in range(3):
                a, b, c = i + (ax == 0), j + (ax == 1), k + (ax == 2)
                if a >= nx or b >= ny or c >= nz:
                    continue
                lb = labels[a, b, c]
                if lb < 0 or lb == la:
                    continue
                if out.size:
                    out[t] = ((np.int64(i) * ny + j) * nz + k) * 3 + ax
                t += 1
    return t - start


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
