"""Throat cross-sections and constriction lengths from the voxels (private kernels of the extraction).

Integer voxel coordinates: voxel ``(i, j, k)`` has centre ``(i, j, k)``. Twins:
``tests/reference/sections_ref.py::sections`` and ``::constriction_lengths``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import types
from numba.typed import Dict

from porefsi._numba import jit


@jit
def _sections(labels, conns, n_pores):
    """Vector area, face count and wall-edge count of every throat's interface.

    The interface of throat ``t`` is the set of voxel faces between a voxel of pore
    ``conns[t, 0]`` and a face neighbour of pore ``conns[t, 1]``. Each face is a unit area with
    normal ``+e_ax`` when the voxel at the lower coordinate belongs to ``conns[t, 0]`` and
    ``-e_ax`` otherwise; their sum is the throat's *vector area* (its length is the area of the
    section projected on the plane it is closest to: exact for a flat section of any orientation,
    the staircase cancels). A *wall edge* is an edge of an interface face whose in-plane
    neighbouring face position (the same pair of voxels shifted by one voxel along one of the
    four in-plane directions) has a solid voxel on either side: the interface ends at the wall
    there. Positions outside the image are not walls (the box cuts the section).

    Parameters
    ----------
    labels : ndarray of int32, shape (nx, ny, nz)
        Pore index of each pore voxel, < 0 on solid and unlabelled voxels.
    conns : ndarray of int64, shape (Nt, 2)
        The throats, ``conns[:, 0] < conns[:, 1]``, each pair once.
    n_pores : int

    Returns
    -------
    area_vec : ndarray of float64, shape (Nt, 3)
        Voxel-face units.
    n_faces : ndarray of int64, shape (Nt,)
    n_wall : ndarray of int64, shape (Nt,)
        Wall edges (voxel-edge units).
    """
    nx, ny, nz = labels.shape
    n_t = conns.shape[0]
    table = Dict.empty(key_type=types.int64, value_type=types.int64)
    for t in range(n_t):
        table[np.int64(conns[t, 0]) * n_pores + conns[t, 1]] = t
    area = np.zeros((n_t, 3), np.float64)
    nf = np.zeros(n_t, np.int64)
    nw = np.zeros(n_t, np.int64)
    dims = np.array([nx, ny, nz], np.int64)
    u = np.zeros(3, np.int64)
    v = np.zeros(3, np.int64)
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                la = labels[i, j, k]
                if la < 0:
                    continue
                for ax in range(3):
                    u[0] = i
                    u[1] = j
                    u[2] = k
                    v[0] = i
                    v[1] = j
                    v[2] = k
                    v[ax] += 1
                    if v[ax] >= dims[ax]:
                        continue
                    lb = labels[v[0], v[1], v[2]]
                    if lb < 0 or lb == la:
                        continue
                    lo = min(la, lb)
                    hi = max(la, lb)
                    key = np.int64(lo) * n_pores + hi
                    if key not in table:
                        continue
                    t = table[key]
                    area[t, ax] += 1.0 if la == lo else -1.0
                    nf[t] += 1
                    for b in range(3):
                        if b == ax:
                            continue
                        for s in (-1, 1):
                            ub = u[b] + s
                            if ub < 0 or ub >= dims[b]:
                                continue
                            u[b] = ub
                            v[b] = ub
                            if labels[u[0], u[1], u[2]] < 0 or labels[v[0], v[1], v[2]] < 0:
                                nw[t] += 1
                            u[b] -= s
                            v[b] -= s
    return area, nf, nw


@jit
def _ridge_radius(dt2, rad_tab, a, b, c, ux, uy, uz):
    """Channel radius at voxel (a, b, c) on a line of unit direction u: the sub-voxel ridge estimate.

    ``f + |g_perp|`` with ``f`` the voxel's radius and ``g_perp`` the central-difference gradient
    of the radius with its component along u removed (capped at half a voxel diagonal, 0.7071):
    the estimator of :func:`_subvoxel_peaks` applied across the channel, so a line running beside
    the channel's axis reads the axis's radius, as the throat radius does at the throat.
    """
    f = rad_tab[dt2[a, b, c]]
    if f == 0.0:
        return 0.0
    gx = 0.5 * (_rad_at(dt2, rad_tab, a + 1, b, c) - _rad_at(dt2, rad_tab, a - 1, b, c))
    gy = 0.5 * (_rad_at(dt2, rad_tab, a, b + 1, c) - _rad_at(dt2, rad_tab, a, b - 1, c))
    gz = 0.5 * (_rad_at(dt2, rad_tab, a, b, c + 1) - _rad_at(dt2, rad_tab, a, b, c - 1))
    gu = gx * ux + gy * uy + gz * uz
    px, py, pz = gx - gu * ux, gy - gu * uy, gz - gu * uz
    return f + min(math.sqrt(px * px + py * py + pz * pz), 0.5 * math.sqrt(2.0))


@jit
def _constriction_lengths(dt2, rad_tab, centre, point, conns, r_throat, r_pore, step):
    r"""Per throat side: pore-centre-to-throat distance and its resistance-equivalent throat length.

    Side ``s`` of throat ``t`` is the segment from the centre of pore ``conns[t, s]`` to the throat
    point. It is sampled at the midpoints of ``m = ceil(d / step)`` equal parts; each sample takes
    the ridge radius (:func:`_ridge_radius`) at the nearest voxel (rounding half up), clamped to
    ``[r_throat[t], r_pore[p]]`` (a sample in solid, where the straight line leaves the pore
    space, counts as throat-sized). With ``I = sum (d/m) / r^4`` the side's Hagen–Poiseuille
    integral, the throat length ``L_t`` and pore length ``d - L_t`` of two uniform ducts (radii
    r_t and R) with the same length and the same integral are

    .. math:: L_t = \frac{I - d / R^4}{r_t^{-4} - R^{-4}} \in [0, d],

    or ``d / 2`` when ``R <= r_t`` (no constriction: both ducts alike).

    Returns
    -------
    d : ndarray of float64, shape (Nt, 2)
        Voxels.
    lt : ndarray of float64, shape (Nt, 2)
        Throat-equivalent length of each side, voxels.
    """
    nx, ny, nz = dt2.shape
    n_t = conns.shape[0]
    d_out = np.zeros((n_t, 2), np.float64)
    lt_out = np.zeros((n_t, 2), np.float64)
    for t in range(n_t):
        rt = r_throat[t]
        for s in range(2):
            p = conns[t, s]
            R = r_pore[p]
            dx = point[t, 0] - centre[p, 0]
            dy = point[t, 1] - centre[p, 1]
            dz = point[t, 2] - centre[p, 2]
            d = math.sqrt(dx * dx + dy * dy + dz * dz)
            d_out[t, s] = d
            if R <= rt or d == 0.0:
                lt_out[t, s] = 0.5 * d
                continue
            m = max(1, int(math.ceil(d / step)))
            acc = 0.0
            for q in range(m):
                f = (q + 0.5) / m
                a = int(math.floor(centre[p, 0] + f * dx + 0.5))
                b = int(math.floor(centre[p, 1] + f * dy + 0.5))
                c = int(math.floor(centre[p, 2] + f * dz + 0.5))
                a = min(max(a, 0), nx - 1)
                b = min(max(b, 0), ny - 1)
                c = min(max(c, 0), nz - 1)
                r = _ridge_radius(dt2, rad_tab, a, b, c, dx / d, dy / d, dz / d)
                r = min(max(r, rt), R)
                acc += 1.0 / (r * r * r * r)
            integral = acc * d / m
            inv_t = 1.0 / (rt * rt * rt * rt)
            inv_p = 1.0 / (R * R * R * R)
            lt = (integral - d * inv_p) / (inv_t - inv_p)
            lt_out[t, s] = min(max(lt, 0.0), d)
    return d_out, lt_out


@jit
def _rad_at(dt2, rad_tab, a, b, c):
    """Radius at voxel (a, b, c), 0 outside the image."""
    nx, ny, nz = dt2.shape
    if a < 0 or a >= nx or b < 0 or b >= ny or c < 0 or c >= nz:
        return 0.0
    return rad_tab[dt2[a, b, c]]


@jit
def _subvoxel_peaks(dt2, rad_tab, points, reach):
    """Sub-voxel estimate of the distance-map peak at each point (voxel or face centre), voxels.

    The distance to a wall near the centre ``c`` of an inscribed circle or ball is the cone
    ``f(x) = r - |x - c|``; sampled on the grid, the best sample sits up to half a voxel per axis
    from ``c`` and reads ``r - |delta|``. The central differences
    ``g_b = (f(x + e_b) - f(x - e_b)) / 2`` of the sample's neighbours recover ``delta_b`` (exact
    in one dimension for ``|delta_b| <= 1/2``), so ``r ~ f(x) + |g|`` with ``|g|`` capped at half
    the diagonal of the cell searched. A point with a half-integer coordinate is a face between
    two voxels: ``f`` there is the mean of the two, and only the two in-plane axes are searched
    (the throat is a saddle of the distance map: a maximum across the channel, a minimum
    along it). A voxel point (pores) searches all three axes. ``reach`` is unused padding for a
    future wider stencil and must be 1.

    Parameters
    ----------
    dt2 : ndarray of int, shape (nx, ny, nz)
    rad_tab : ndarray of float64
        Radius of every distance-map value (``rad_tab[0] = 0``).
    points : ndarray of float64, shape (M, 3)
        Voxel-index coordinates; at most one coordinate half-integer.
    reach : int

    Returns
    -------
    ndarray of float64, shape (M,)
    """
    m = points.shape[0]
    out = np.zeros(m, np.float64)
    for q in range(m):
        base = np.zeros(3, np.int64)
        ax = -1
        for t in range(3):
            x = points[q, t]
            fl = math.floor(x)
            base[t] = int(fl)
            if x - fl > 0.25:
                ax = t
        g2 = 0.0
        n_axes = 0
        f0 = 0.0
        for t in range(3):
            if t == ax:
                continue
            n_axes += 1
            vals = np.zeros(2, np.float64)
            for side in range(2):
                s = 2 * side - 1
                a, b, c = base[0], base[1], base[2]
                if t == 0:
                    a += s
                elif t == 1:
                    b += s
                else:
                    c += s
                v = _rad_at(dt2, rad_tab, a, b, c)
                if ax >= 0:
                    a2, b2, c2 = a, b, c
                    if ax == 0:
                        a2 += 1
                    elif ax == 1:
                        b2 += 1
                    else:
                        c2 += 1
                    v = 0.5 * (v + _rad_at(dt2, rad_tab, a2, b2, c2))
                vals[side] = v
            g = 0.5 * (vals[1] - vals[0])
            g2 += g * g
        f0 = _rad_at(dt2, rad_tab, base[0], base[1], base[2])
        if ax >= 0:
            a2, b2, c2 = base[0], base[1], base[2]
            if ax == 0:
                a2 += 1
            elif ax == 1:
                b2 += 1
            else:
                c2 += 1
            f0 = 0.5 * (f0 + _rad_at(dt2, rad_tab, a2, b2, c2))
        cap = 0.5 * math.sqrt(n_axes) * reach
        out[q] = f0 + min(math.sqrt(g2), cap)
    return out
