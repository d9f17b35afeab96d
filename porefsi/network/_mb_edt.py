"""Squared Euclidean distance transform and pore-surface kernels of the maximal-ball extraction (private).

Twins: ``tests/reference/extract_ref.py::sq_edt`` and ``::pore_solid_faces``.
"""

from __future__ import annotations

import numpy as np

from porefsi._numba import jit, prange

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


@jit(parallel=True)
def _sq_edt(pore, out, cap):
    """Squared distance (voxel units) from each pore voxel to the nearest solid voxel centre.

    Solid voxels get 0. Outside the image is *not* solid. Values are ``min(d^2, cap)``: exact
    wherever the true value is below ``cap`` (a capped intermediate only ever feeds candidates
    that are themselves ``>= cap``), ``cap`` where no solid voxel is nearer. The lines of each
    pass are independent, so each pass runs them on numba's threads (``prange``; the result does
    not depend on the number of threads).

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
    inf = np.int64(cap)
    for i in prange(nx):
        f, d, v, z = _scratch(nz)
        for j in range(ny):
            for k in range(nz):
                f[k] = inf if pore[i, j, k] else 0
            _envelope_line(f, nz, d, v, z, inf)
            for k in range(nz):
                out[i, j, k] = d[k]
    for i in prange(nx):
        f, d, v, z = _scratch(ny)
        for k in range(nz):
            for j in range(ny):
                f[j] = out[i, j, k]
            _envelope_line(f, ny, d, v, z, inf)
            for j in range(ny):
                out[i, j, k] = d[j]
    # last axis: gather a slab of lines at a time would be more cache friendly; the strided
    # gather costs ~20 % of the EDT on 400^3 and keeps the memory at one line per thread.
    for j in prange(ny):
        f, d, v, z = _scratch(nx)
        for k in range(nz):
            for i in range(nx):
                f[i] = out[i, j, k]
            _envelope_line(f, nx, d, v, z, inf)
            for i in range(nx):
                out[i, j, k] = d[i]


@jit
def _scratch(m):
    """Work arrays of one line of length ``m`` for :func:`_envelope_line`."""
    return np.empty(m, np.int64), np.empty(m, np.int64), np.empty(m, np.int64), np.empty(m + 1, np.float64)


@jit(parallel=True)
def _pore_solid_faces(pore):
    """Number of voxel faces shared by a pore voxel and a solid voxel (the staircase's area, voxel faces).

    Faces on the box boundary are not counted (outside the image is not solid, as in the distance
    map). Slabs along the first axis are counted on numba's threads and summed.

    Parameters
    ----------
    pore : ndarray of uint8, shape (nx, ny, nz)
        1 = pore, 0 = solid.

    Returns
    -------
    int
    """
    nx, ny, nz = pore.shape
    per = np.zeros(nx, np.int64)
    for i in prange(nx):
        n = 0
        for j in range(ny):
            for k in range(nz):
                a = pore[i, j, k] != 0
                if i + 1 < nx and a != (pore[i + 1, j, k] != 0):
                    n += 1
                if j + 1 < ny and a != (pore[i, j + 1, k] != 0):
                    n += 1
                if k + 1 < nz and a != (pore[i, j, k + 1] != 0):
                    n += 1
        per[i] = n
    return per.sum()


@jit
def _d2(dt2, a, b, c, box):
    """``dt2[a, b, c]`` with the box faces of every axis ``t`` with ``box[t]`` non-zero as solid.

    A solid voxel layer just outside a face is nearest straight across: the squared distance from
    voxel ``i`` to it is ``(i + 1)^2`` (low face) or ``(n - i)^2`` (high face), so the walled map is
    ``min(dt2, those)`` (``tests/reference/sections_ref.py::box_walled`` pads the image instead).
    """
    v = np.int64(dt2[a, b, c])
    if v == 0:
        return v
    nx, ny, nz = dt2.shape
    if box[0] != 0:
        g = np.int64(min(a + 1, nx - a))
        v = min(v, g * g)
    if box[1] != 0:
        g = np.int64(min(b + 1, ny - b))
        v = min(v, g * g)
    if box[2] != 0:
        g = np.int64(min(c + 1, nz - c))
        v = min(v, g * g)
    return v
