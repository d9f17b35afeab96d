"""Numba kernels of the voxel Stokes solver: face enumeration, stencil tables, matrix-free operators.

They exist for memory: the velocity block and the divergence are applied from a neighbour table
(6 int32 + a diagonal per face, ~36 bytes) instead of sparse matrices (~130 bytes per face for
A, B and B^T), and the Krylov updates are fused so that no full-length temporary is made. Every
kernel is checked against the loop-by-loop twin in ``tests/reference/stokes_ref.py`` through
:func:`porefsi.stokes.voxel_permeability`, and the operators against explicit sparse matrices in
``tests/test_stokes_kernels.py``.

Conventions (see :mod:`porefsi.stokes._grid`): faces of axis ``d`` live on an array of shape
``shape`` with ``n_planes`` along ``d``; plane ``f`` separates voxel layers ``f - 1`` and ``f``.
Neighbour slots per face: 0, 1 = the faces before/after along the face normal; 2, 3 and 4, 5 =
before/after along the two other axes in increasing order. -1 = no neighbour unknown.
"""

from __future__ import annotations

import numpy as np

from porefsi._numba import jit

#: Ghost-reflection weight of a tangential wall half a voxel away (u_ghost = -u).
GHOST_WALL = 2.0
#: Tangential wall closures (:func:`wall_weight`): ghost reflection, or exact cell-averaged channel flow.
WALL_GHOST, WALL_CHANNEL = 0, 1
#: Weight of a no-slip point a whole voxel away (u = 0 there).
POINT_WALL = 1.0

# voxel lookup results
_SOLID, _PORE, _RESERVOIR = 0, 1, 2


@jit
def _wrap(i, n, periodic, is_open):
    """Index ``i`` on an axis of length ``n``: wrapped (periodic), clamped (open: -2 marks it), or -1 (wall)."""
    if 0 <= i < n:
        return i
    if periodic:
        return i % n
    if is_open:
        return -2
    return -1


@jit
def _voxel(pore, i, j, k, periodic, open_axis):
    """Pore (1) or solid (0) at (i, j, k); beyond an open box face the edge voxel repeats."""
    idx = (i, j, k)
    out = [0, 0, 0]
    for a in range(3):
        n = pore.shape[a]
        w = _wrap(idx[a], n, periodic[a], a == open_axis)
        if w == -1:
            return _SOLID
        if w == -2:
            w = 0 if idx[a] < 0 else n - 1
        out[a] = w
    return _PORE if pore[out[0], out[1], out[2]] else _SOLID


@jit
def number_faces(pore, d, n_planes, periodic, open_axis, offset):
    """Dense face-id array of axis ``d`` (int32, -1 = wall face) and the number of open faces.

    A face is open when both its voxels are pore (beyond an open box face the edge voxel repeats,
    so a box face of a pore voxel is open).
    """
    shape = (n_planes if d == 0 else pore.shape[0], n_planes if d == 1 else pore.shape[1],
             n_planes if d == 2 else pore.shape[2])
    fid = np.full(shape, -1, dtype=np.int32)
    count = 0
    for i in range(shape[0]):
        for j in range(shape[1]):
            for k in range(shape[2]):
                lo = [i, j, k]
                lo[d] -= 1
                if _voxel(pore, i, j, k, periodic, open_axis) and _voxel(pore, lo[0], lo[1], lo[2], periodic,
                                                                          open_axis):
                    fid[i, j, k] = offset + count
                    count += 1
    return fid, count


@jit
def wall_weight(n, wall):
    """Diagonal weight of a tangential wall half a voxel away, for a run of ``n`` open faces.

    ``wall`` 0 (ghost): :data:`GHOST_WALL`. ``wall`` 1 (channel): ``6 n / (3 n - 2)``, the weight
    that makes the face values the cell averages of plane Poiseuille flow between two such walls
    ``n`` voxels apart (6, 3, 2.57, ... -> 2; derivation in :mod:`porefsi.stokes._grid`).
    """
    if wall == WALL_GHOST:
        return GHOST_WALL
    return 6.0 * n / (3.0 * n - 2.0)


@jit
def run_length(fid, c, e, periodic_e):
    """Open faces in the line along axis ``e`` through face ``c`` (itself included) up to the first closed face.

    Stops at a bounded box face; wraps on a periodic axis (at most the axis length).
    """
    lim = fid.shape[e]
    n = 1
    for step in (-1, 1):
        q = [c[0], c[1], c[2]]
        for _ in range(lim - 1):
            q[e] += step
            if not 0 <= q[e] < lim:
                if not periodic_e:
                    break
                q[e] %= lim
            if fid[q[0], q[1], q[2]] < 0:
                break
            n += 1
    return min(n, lim)


@jit
def face_tables(pore, pid, fid, d, periodic, open_axis, out, wall):
    """Fill the stencil tables of the open faces of axis ``d`` (ids from ``fid``; arrays global-indexed).

    ``out`` = (nb, diag, half, plo, phi): nb (n_u, 6) int32 (written only if it has n_u rows),
    diag (n_u,) float64, half (n_u,) uint8 (1 = half control volume on an open box face),
    plo/phi (n_u,) int32 pressure ids of the voxels before/after (-1 = reservoir). Two passes
    (coupling first with a one-row ``nb``, neighbours later) let the pressure preconditioner be
    built before the neighbour table exists (lower peak memory). ``wall``: :data:`WALL_GHOST` or
    :data:`WALL_CHANNEL` (:func:`wall_weight`).
    """
    nb, diag, half, plo, phi = out
    want_nb = nb.shape[0] == diag.shape[0]
    n_planes = fid.shape[d]
    axes = (d, 0 if d != 0 else 1, 2 if d != 2 else 1)
    for i in range(fid.shape[0]):
        for j in range(fid.shape[1]):
            for k in range(fid.shape[2]):
                f = fid[i, j, k]
                if f < 0:
                    continue
                c = (i, j, k)
                boundary = open_axis == d and (c[d] == 0 or c[d] == n_planes - 1)
                half[f] = 1 if boundary else 0
                dg = 0.0
                for s in range(6):
                    g, term = _neighbour(pore, fid, c, d, axes[s // 2], s % 2, (periodic, open_axis), wall)
                    if want_nb:
                        nb[f, s] = g
                    dg += term * (1.0 if (s < 2 or not boundary) else 0.5)
                diag[f] = dg
                lo = [i, j, k]
                lo[d] -= 1
                plo[f] = _pressure_id(pid, lo, periodic)
                phi[f] = _pressure_id(pid, c, periodic)


@jit
def _neighbour(pore, fid, c, d, e, after, bc, wall):
    """(neighbour face id or -1, unweighted diagonal term) of face ``c`` of axis ``d`` along ``e``.

    ``after``: the neighbour after (1) or before (0) along ``e``; ``bc`` = (periodic, open_axis).
    """
    periodic, open_axis = bc
    q = [c[0], c[1], c[2]]
    q[e] += 1 if after else -1
    lim = fid.shape[e]
    if not 0 <= q[e] < lim:
        if periodic[e]:
            q[e] %= lim
        elif e == open_axis:
            return -1, 0.0  # beyond an open box face: no term
        else:  # beyond a side wall: both voxels of that face are solid
            return -1, _wall_term(fid, c, e, periodic[e], wall)
    g = fid[q[0], q[1], q[2]]
    if g == fid[c[0], c[1], c[2]]:
        return -1, 0.0  # periodic axis one voxel long: the face is its own neighbour, no net term
    if g >= 0:
        return g, 1.0
    if e == d:
        return -1, POINT_WALL  # a wall face a whole voxel away
    lo = [q[0], q[1], q[2]]
    lo[d] -= 1
    solid = 2 - _voxel(pore, q[0], q[1], q[2], periodic, open_axis) - _voxel(pore, lo[0], lo[1], lo[2], periodic,
                                                                             open_axis)
    if solid == 2:
        return -1, _wall_term(fid, c, e, periodic[e], wall)
    if wall == WALL_CHANNEL:  # half the control volume's side is wall, half faces the closed face's u = 0
        return -1, 0.5 * (POINT_WALL + _wall_term(fid, c, e, periodic[e], wall))
    return -1, POINT_WALL


@jit
def _wall_term(fid, c, e, periodic_e, wall):
    if wall == WALL_GHOST:
        return GHOST_WALL
    return wall_weight(run_length(fid, c, e, periodic_e), wall)


@jit
def _pressure_id(pid, c, periodic):
    out = [0, 0, 0]
    for a in range(3):
        n = pid.shape[a]
        if 0 <= c[a] < n:
            out[a] = c[a]
        elif periodic[a]:
            out[a] = c[a] % n
        else:
            return -1
    return pid[out[0], out[1], out[2]]


@jit
def _row(nb, diag, half, x, f):
    """(A x)_f from the neighbour table."""
    w_t = 0.5 if half[f] else 1.0
    acc = diag[f] * x[f]
    for s in range(6):
        g = nb[f, s]
        if g >= 0:
            acc -= (1.0 if s < 2 else w_t) * x[g]
    return acc


@jit
def stokes_matvec(tables, x, n_u, out):
    """Write K x into ``out``, K = [[A, -B^T], [-B, 0]] (x and out of length n_u + n_p).

    ``tables`` = (nb, diag, half, plo, phi), as :func:`face_tables` fills them.
    """
    nb, diag, half, plo, phi = tables
    out[n_u:] = 0.0
    for f in range(n_u):
        acc = _row(nb, diag, half, x, f)
        lo, hi = plo[f], phi[f]
        u = x[f]
        if lo >= 0:
            acc -= x[n_u + lo]
            out[n_u + lo] -= u
        if hi >= 0:
            acc += x[n_u + hi]
            out[n_u + hi] += u
        out[f] = acc


@jit
def lanczos_step(tables, z, n_u, v, v_old, c_v, c_old):
    """v_old <- K z - c_v v - c_old v_old in place (the next Lanczos vector); returns z . K z."""
    nb, diag, half, plo, phi = tables
    n = z.shape[0]
    kz_p = np.zeros(n - n_u)
    delta = 0.0
    for f in range(n_u):
        acc = _row(nb, diag, half, z, f)
        lo, hi = plo[f], phi[f]
        if lo >= 0:
            acc -= z[n_u + lo]
            kz_p[lo] -= z[f]
        if hi >= 0:
            acc += z[n_u + hi]
            kz_p[hi] += z[f]
        delta += acc * z[f]
        v_old[f] = acc - c_v * v[f] - c_old * v_old[f]
    for i in range(n - n_u):
        delta += kz_p[i] * z[n_u + i]
        v_old[n_u + i] = kz_p[i] - c_v * v[n_u + i] - c_old * v_old[n_u + i]
    return delta


@jit
def lanczos_delta(tables, z, n_u):
    """Return z . K z without storing K z."""
    nb, diag, half, plo, phi = tables
    n = z.shape[0]
    kz_p = np.zeros(n - n_u)
    delta = 0.0
    for f in range(n_u):
        acc = _row(nb, diag, half, z, f)
        lo, hi = plo[f], phi[f]
        if lo >= 0:
            acc -= z[n_u + lo]
            kz_p[lo] -= z[f]
        if hi >= 0:
            acc += z[n_u + hi]
            kz_p[hi] += z[f]
        delta += acc * z[f]
    for i in range(n - n_u):
        delta += kz_p[i] * z[n_u + i]
    return delta


@jit
def symmetric_gauss_seidel(nb, diag, half, r, x, n_u):
    """x[:n_u] = one symmetric Gauss-Seidel sweep on A x = r[:n_u] from x = 0 (an SPD preconditioner)."""
    for f in range(n_u):
        x[f] = 0.0
    for sweep in range(2):
        for m in range(n_u):
            f = m if sweep == 0 else n_u - 1 - m
            w_t = 0.5 if half[f] else 1.0
            acc = r[f]
            for s in range(6):
                g = nb[f, s]
                if g >= 0:
                    acc += (1.0 if s < 2 else w_t) * x[g]
            x[f] = acc / diag[f]


@jit
def update_search(w_old, z, w, a1, a2, a3):
    """w_old <- (z - a3 w_old - a2 w) / a1 in place (the next MINRES search direction)."""
    for i in range(w_old.shape[0]):
        w_old[i] = (z[i] - a3 * w_old[i] - a2 * w[i]) / a1


@jit
def axpy(x, a, y):
    """Update x <- x + a y in place."""
    for i in range(x.shape[0]):
        x[i] += a * y[i]


@jit
def dot(a, b):
    acc = 0.0
    for i in range(a.shape[0]):
        acc += a[i] * b[i]
    return acc


@jit
def schur_csr(plo, phi, diag, n_p):
    """CSR arrays of B diag(A)^-1 B^T (n_p x n_p): a weighted pressure Laplacian, diagonal first per row."""
    n_u = plo.shape[0]
    count = np.ones(n_p, dtype=np.int64)
    for f in range(n_u):
        if plo[f] >= 0 and phi[f] >= 0 and plo[f] != phi[f]:
            count[plo[f]] += 1
            count[phi[f]] += 1
    # a face whose two sides are the same voxel (periodic axis one voxel long) has a zero B column
    indptr = np.zeros(n_p + 1, dtype=np.int64)
    for i in range(n_p):
        indptr[i + 1] = indptr[i] + count[i]
    indices = np.empty(indptr[n_p], dtype=np.int32)
    data = np.zeros(indptr[n_p])
    fill = np.ones(n_p, dtype=np.int64)
    for i in range(n_p):
        indices[indptr[i]] = i
    for f in range(n_u):
        w = 1.0 / diag[f]
        lo, hi = plo[f], phi[f]
        if lo == hi:
            continue
        if lo >= 0:
            data[indptr[lo]] += w
        if hi >= 0:
            data[indptr[hi]] += w
        if lo >= 0 and hi >= 0 and lo != hi:
            p = indptr[lo] + fill[lo]
            indices[p] = hi
            data[p] = -w
            fill[lo] += 1
            p = indptr[hi] + fill[hi]
            indices[p] = lo
            data[p] = -w
            fill[hi] += 1
    return indptr, indices, data


@jit
def pressure_faces(plo, phi, offsets, n_p):
    """(n_p, 6) int32 table of each pressure voxel's faces (slots: axis 0 low/high side, axis 1, axis 2).

    -1 where the face is a wall. A face whose two sides are the same voxel (periodic axis one voxel
    long) is left out: its divergence column is zero.
    """
    pf = np.full((n_p, 6), -1, dtype=np.int32)
    for d in range(3):
        for f in range(offsets[d], offsets[d + 1]):
            lo, hi = plo[f], phi[f]
            if lo == hi:
                continue
            if lo >= 0:
                pf[lo, 2 * d + 1] = f
            if hi >= 0:
                pf[hi, 2 * d] = f
    return pf


@jit
def _schur_row(pf, plo, phi, diag, x, c):
    """Return (diagonal, sum of w x_other) of row ``c`` of B diag(A)^-1 B^T."""
    dg = 0.0
    off = 0.0
    for s in range(6):
        f = pf[c, s]
        if f < 0:
            continue
        w = 1.0 / diag[f]
        dg += w
        o = phi[f] if plo[f] == c else plo[f]
        if o >= 0:
            off += w * x[o]
    return dg * (1.0 + 1e-12), off  # the 1e-12 keeps periodic or closed clusters definite


@jit
def schur_residual(pf, plo, phi, diag, b, x, r):
    """Write r = b - S x, S = B diag(A)^-1 B^T (matrix-free)."""
    for c in range(b.shape[0]):
        dg, off = _schur_row(pf, plo, phi, diag, x, c)
        r[c] = b[c] - (dg * x[c] - off)


@jit
def schur_symmetric_gauss_seidel(pf, plo, phi, diag, b, x):
    """One forward then one backward Gauss-Seidel sweep on S x = b, in place (matrix-free)."""
    n = b.shape[0]
    for sweep in range(2):
        for m in range(n):
            c = m if sweep == 0 else n - 1 - m
            dg, off = _schur_row(pf, plo, phi, diag, x, c)
            x[c] = (b[c] + off) / dg if dg > 0.0 else 0.0  # a voxel with no open face: a null row
