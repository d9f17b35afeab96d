"""Throat cross-sections and constriction lengths from the voxels (private kernels of the extraction).

Integer voxel coordinates: voxel ``(i, j, k)`` has centre ``(i, j, k)``. Twins:
``tests/reference/sections_ref.py::sections`` and ``::constriction_lengths``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import types
from numba.typed import Dict

from porefsi._numba import jit, prange
from porefsi.network._mb_edt import _d2
from porefsi.network._mb_regions import _interfaces

#: Spacing (voxels) of the constriction samples along a pore-centre-to-throat line.
SAMPLE_STEP = 0.25


@jit
def _wall_edges(labels, i, j, k, ax, walls):
    """Edges of the face between voxel (i, j, k) and its +``ax`` neighbour that end at the wall.

    The face's four in-plane neighbour positions (the same pair of voxels shifted by one voxel
    along each in-plane axis) count when either voxel there is solid (< 0), or when the position
    is outside the image across a box face of an axis ``b`` with ``walls[b]`` set (a wall there).
    """
    dims = labels.shape
    n = 0
    for b in range(3):
        if b == ax:
            continue
        for s in (-1, 1):
            u = (i + s * (b == 0), j + s * (b == 1), k + s * (b == 2))
            if u[b] < 0 or u[b] >= dims[b]:
                n += walls[b] != 0
                continue
            if labels[u[0], u[1], u[2]] < 0 or labels[u[0] + (ax == 0), u[1] + (ax == 1), u[2] + (ax == 2)] < 0:
                n += 1
    return n


@jit
def _sections(labels, conns, n_pores, walls=None):
    """Vector area, face count and wall-edge count of every throat's interface.

    The interface of throat ``t`` is the set of voxel faces between a voxel of pore
    ``conns[t, 0]`` and a face neighbour of pore ``conns[t, 1]``. Each face is a unit area with
    normal ``+e_ax`` when the voxel at the lower coordinate belongs to ``conns[t, 0]`` and
    ``-e_ax`` otherwise; their sum is the throat's *vector area* (its length is the area of the
    section projected on the plane it is closest to: exact for a flat section of any orientation,
    the staircase cancels). A *wall edge* is an edge of an interface face whose in-plane
    neighbouring face position has a solid voxel on either side, or lies outside the image across
    a box face of a walled axis (:func:`_wall_edges`): the interface ends at the wall there.

    Parameters
    ----------
    labels : ndarray of int32, shape (nx, ny, nz)
        Pore index of each pore voxel, < 0 on solid and unlabelled voxels.
    conns : ndarray of int64, shape (Nt, 2)
        The throats, ``conns[:, 0] < conns[:, 1]``, each pair once.
    n_pores : int
    walls : ndarray of int64, shape (3,), optional
        Non-zero for an axis whose two box faces are walls; 0 (and the default): the box cuts the
        section open.

    Returns
    -------
    area_vec : ndarray of float64, shape (Nt, 3)
        Voxel-face units.
    n_faces : ndarray of int64, shape (Nt,)
    n_wall : ndarray of int64, shape (Nt,)
        Wall edges (voxel-edge units).
    """
    nx, ny, nz = labels.shape
    box = np.zeros(3, np.int64) if walls is None else walls
    n_t = conns.shape[0]
    table = Dict.empty(key_type=types.int64, value_type=types.int64)
    for t in range(n_t):
        table[np.int64(conns[t, 0]) * n_pores + conns[t, 1]] = t
    area = np.zeros((n_t, 3), np.float64)
    nf = np.zeros(n_t, np.int64)
    nw = np.zeros(n_t, np.int64)
    for i in range(nx):
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
                    key = np.int64(min(la, lb)) * n_pores + max(la, lb)
                    if lb < 0 or lb == la or key not in table:
                        continue
                    t = table[key]
                    area[t, ax] += 1.0 if la < lb else -1.0
                    nf[t] += 1
                    nw[t] += _wall_edges(labels, i, j, k, ax, box)
    return area, nf, nw


def _walled_points(labels, dt2, conns, n_pores, walls):
    """Each throat's largest ``w = min(d2[u], d2[v])`` over its interface faces and that face's centre.

    ``d2`` is the distance map with the walled box faces as solid (:func:`~porefsi.network._mb_edt._d2`):
    the extraction's own interface scan (:func:`porefsi.network._mb_regions._interfaces`) on that
    map, read in the order of ``conns`` (ties keep the first face met in its C-order scan; equal to
    the open map's when ``walls`` is all 0).

    Returns
    -------
    w : ndarray of int64, shape (Nt,)
    point : ndarray of float64, shape (Nt, 3)
        Voxel-index coordinates (a face between voxels ``i`` and ``i + 1`` at ``i + 0.5``).
    """
    n_p = np.int64(n_pores)
    pairs, w_all, p_all, _ = _interfaces(labels, dt2, n_p, np.asarray(walls, np.int64))
    key_all = pairs[:, 0] * n_p + pairs[:, 1]
    order = np.argsort(key_all)
    idx = order[np.searchsorted(key_all, conns[:, 0] * n_p + conns[:, 1], sorter=order)]
    return w_all[idx], p_all[idx]


@jit
def _ridge_radius(dt2, rad_tab, a, b, c, u, box):
    """Channel radius at voxel (a, b, c) on a line of unit direction u: the sub-voxel ridge estimate.

    ``f + max_b |g_perp,b|`` (capped at 1/2) with ``f`` the voxel's radius and ``g_perp`` the
    central-difference gradient of the radius with its component along u removed: the estimator
    of :func:`_subvoxel_peaks` applied across the channel, so a sample beside the channel's axis
    reads the axis's radius, as the throat radius does at the throat. ``box``: the walled axes
    (:func:`_d2`).
    """
    f = _stair_rad(dt2, a, b, c, box)
    if f == 0.0:
        return 0.0
    gx = 0.5 * (_rad_at(dt2, rad_tab, a + 1, b, c, box) - _rad_at(dt2, rad_tab, a - 1, b, c, box))
    gy = 0.5 * (_rad_at(dt2, rad_tab, a, b + 1, c, box) - _rad_at(dt2, rad_tab, a, b - 1, c, box))
    gz = 0.5 * (_rad_at(dt2, rad_tab, a, b, c + 1, box) - _rad_at(dt2, rad_tab, a, b, c - 1, box))
    ux, uy, uz = u
    gu = gx * ux + gy * uy + gz * uz
    px, py, pz = gx - gu * ux, gy - gu * uy, gz - gu * uz
    return f + min(max(abs(px), abs(py), abs(pz)), 0.5)


@jit
def _constriction_lengths_subvoxel(dt2, rad_tab, centre, point, conns, r_throat, r_pore, walls):
    """:func:`_constriction_lengths` with each sample read at its own position along the line.

    The staircase distance of the widest channel voxel is taken at that voxel's centre moved along
    the side onto the sample's section plane (:func:`_stair_dist` at a sub-voxel point, the box
    faces of ``walls`` included), not at the voxel centre: the distance field is continuous along
    the line, so a throat one voxel thick reads the same length in metres at every refinement
    (the voxel-snapped reading holds each voxel's value over its whole layer, a plateau of one
    voxel of whichever grid). Same arguments and returns.
    """
    return _lengths(dt2, rad_tab, centre, point, conns, (r_throat, r_pore), walls, True)


@jit
def _constriction_lengths(dt2, rad_tab, centre, point, conns, r_throat, r_pore, walls=None):
    """Per throat side: pore-centre-to-throat distance and its throat-equivalent length (:func:`_lengths`)."""
    box = np.zeros(3, np.int64) if walls is None else walls
    return _lengths(dt2, rad_tab, centre, point, conns, (r_throat, r_pore), box, False)


@jit
def _lengths(dt2, rad_tab, centre, point, conns, radii, box, sub):
    r"""Per throat side: pore-centre-to-throat distance and its resistance-equivalent throat length.

    Side ``s`` of throat ``t`` is the segment from the centre of pore ``conns[t, s]`` to the throat
    point. It is sampled at the midpoints of ``m = ceil(d / SAMPLE_STEP)`` equal parts; each sample takes
    the section radius (:func:`_section_radius`: the widest channel centre within the ball
    inscribed at the sample, in the plane normal to the side), clamped to
    ``[r_throat[t], r_pore[p]]`` (a sample in solid, where the straight line leaves the pore
    space, counts as throat-sized). With ``I = sum (d/m) / r^4`` the side's Hagen–Poiseuille
    integral, the throat length ``L_t`` and pore length ``d - L_t`` of two uniform ducts (radii
    r_t and R) with the same length and the same integral are

    .. math:: L_t = \frac{I - d / R^4}{r_t^{-4} - R^{-4}} \in [0, d],

    or ``d / 2`` when ``R <= r_t`` (no constriction: both ducts alike). ``radii``: the throat
    radii (Nt,) and pore radii (Np,). ``box`` (int64 (3,)): axes whose box faces are solid for the
    samples (:func:`_d2`). ``sub``: read each sample at its own position along the line
    (:func:`_constriction_lengths_subvoxel`) instead of at the channel voxel's centre.

    Returns
    -------
    d : ndarray of float64, shape (Nt, 2)
        Voxels.
    lt : ndarray of float64, shape (Nt, 2)
        Throat-equivalent length of each side, voxels.
    """
    r_throat, r_pore = radii
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
            m = max(1, int(math.ceil(d / SAMPLE_STEP)))
            e1, e2 = _perp_basis(dx / d, dy / d, dz / d)
            acc = 0.0
            for q in range(m):
                f = (q + 0.5) / m
                x = (centre[p, 0] + f * dx, centre[p, 1] + f * dy, centre[p, 2] + f * dz)
                r = _section_radius(dt2, rad_tab, x, (dx / d, dy / d, dz / d), (e1, e2), box, sub)
                r = min(max(r, rt), R)
                acc += 1.0 / (r * r * r * r)
            integral = acc * d / m
            inv_t = 1.0 / (rt * rt * rt * rt)
            inv_p = 1.0 / (R * R * R * R)
            lt = (integral - d * inv_p) / (inv_t - inv_p)
            lt_out[t, s] = min(max(lt, 0.0), d)
    return d_out, lt_out


@jit
def _perp_basis(ux, uy, uz):
    """Two unit vectors orthogonal to the unit vector u and to each other."""
    if abs(ux) < 0.9:
        ax, ay, az = 1.0, 0.0, 0.0
    else:
        ax, ay, az = 0.0, 1.0, 0.0
    dot = ax * ux + ay * uy + az * uz
    ax, ay, az = ax - dot * ux, ay - dot * uy, az - dot * uz
    n = math.sqrt(ax * ax + ay * ay + az * az)
    e1 = (ax / n, ay / n, az / n)
    e2 = (uy * e1[2] - uz * e1[1], uz * e1[0] - ux * e1[2], ux * e1[1] - uy * e1[0])
    return e1, e2


@jit
def _nearest(x, n):
    """Index of the voxel nearest to coordinate x (halves up), clipped to [0, n - 1]."""
    return min(max(int(math.floor(x + 0.5)), 0), n - 1)


@jit
def _section_radius(dt2, rad_tab, x, u, plane, box, sub=False):
    """Channel radius of the cross-section through point x normal to u: the widest ball centred there.

    ``rho`` is the radius at the voxel nearest to x (0 in solid). The voxels nearest to the points
    ``x + s e1 + t e2`` (integers s, t with ``s^2 + t^2 <= rho^2``: the disc of the ball inscribed
    at x, so the search stays in the channel and scales with it) are searched for the largest
    radius, and the ridge estimate (:func:`_ridge_radius`) of that voxel is returned: a line
    running beside the channel's axis, at any offset the channel's own ball covers, reads the
    axis's radius at every resolution. ``plane``: the unit pair (e1, e2) normal to u. ``box``:
    the walled axes (:func:`_d2`). ``sub``: the staircase distance is read at that voxel's centre
    moved along u onto the plane through x (:func:`_ridge_radius`).
    """
    e1, e2 = plane
    nx, ny, nz = dt2.shape
    a, b, c = _nearest(x[0], nx), _nearest(x[1], ny), _nearest(x[2], nz)
    best = _d2(dt2, a, b, c, box)
    rho = rad_tab[best]
    if rho == 0.0:
        return 0.0
    ba, bb, bc = a, b, c
    h = int(rho)
    for s in range(-h, h + 1):
        for t in range(-h, h + 1):
            if s * s + t * t > rho * rho:
                continue
            i = _nearest(x[0] + s * e1[0] + t * e2[0], nx)
            j = _nearest(x[1] + s * e1[1] + t * e2[1], ny)
            k = _nearest(x[2] + s * e1[2] + t * e2[2], nz)
            v = _d2(dt2, i, j, k, box)
            if v > best:
                best, ba, bb, bc = v, i, j, k
    if not sub:
        return _ridge_radius(dt2, rad_tab, ba, bb, bc, u, box)
    h = (x[0] - ba) * u[0] + (x[1] - bb) * u[1] + (x[2] - bc) * u[2]
    q = (ba + h * u[0], bb + h * u[1], bc + h * u[2])
    return _plane_peak(dt2, q, plane, box, math.sqrt(best) + 1.0)


@jit
def _plane_peak(dt2, q, plane, box, reach):
    """Largest staircase distance over a grid in the plane through q spanned by ``plane`` (e1, e2).

    ``(2 n + 1)^2`` points, ``n = 4``, at spacing ``1 / (2 n)`` within half a voxel of q along e1
    and e2: the throat radius's estimator (:func:`_stair_section_peaks`) in the section's own
    plane. Each distance is to the nearest solid voxel cube or walled box face (``box``,
    :func:`_box_gap`), at most ``reach``.
    """
    e1, e2 = plane
    n = 4
    best = 0.0
    for s in range(-n, n + 1):
        for t in range(-n, n + 1):
            a, b = 0.5 * s / n, 0.5 * t / n
            x = q[0] + a * e1[0] + b * e2[0]
            y = q[1] + a * e1[1] + b * e2[1]
            z = q[2] + a * e1[2] + b * e2[2]
            d = min(_stair_dist(dt2, x, y, z, reach), _box_gap(dt2.shape, x, y, z, box, -1))
            best = max(best, d)
    return best


@jit
def _rad_at(dt2, rad_tab, a, b, c, box):
    """Radius at voxel (a, b, c) on the walled map (:func:`_d2`), 0 outside the image."""
    nx, ny, nz = dt2.shape
    if a < 0 or a >= nx or b < 0 or b >= ny or c < 0 or c >= nz:
        return 0.0
    return rad_tab[_d2(dt2, a, b, c, box)]


@jit
def _stair_rad(dt2, a, b, c, box):
    """Distance (voxels) from the centre of voxel (a, b, c) to the nearest solid voxel *cube*; 0 in solid.

    The staircase's own inscribed radius: ``min sqrt(sum_i max(|k_i| - 1/2, 0)^2)`` over the
    offsets ``k`` of the solid voxels (outside the image is not solid, as in the distance map).
    The nearest solid centre (``sqrt(dt2)`` away) bounds it by ``sqrt(dt2) - 1/2``
    (:func:`wall_radius`), equal for an axis-aligned wall; :func:`_stair_dist` searches below it.
    On the walled map (:func:`_d2`, ``box``) the bound is also the distance to the walled box
    faces (``sqrt((i + 1)^2) - 1/2 = i + 1/2``), so those faces count as staircase walls.
    """
    nx, ny, nz = dt2.shape
    if a < 0 or a >= nx or b < 0 or b >= ny or c < 0 or c >= nz:
        return 0.0
    d2 = _d2(dt2, a, b, c, box)
    if d2 == 0:
        return 0.0
    return _stair_dist(dt2, float(a), float(b), float(c), math.sqrt(d2) - 0.5)


@jit
def _stair_dist(dt2, x, y, z, bound):
    """Distance from the point (x, y, z) to the nearest solid voxel cube, searched within ``bound``."""
    nx, ny, nz = dt2.shape
    best2 = bound * bound
    h = int(bound) + 1
    a0, b0, c0 = int(math.floor(x + 0.5)), int(math.floor(y + 0.5)), int(math.floor(z + 0.5))
    for i in range(max(a0 - h, 0), min(a0 + h, nx - 1) + 1):
        ei = max(abs(i - x) - 0.5, 0.0) ** 2
        if ei >= best2:
            continue
        for j in range(max(b0 - h, 0), min(b0 + h, ny - 1) + 1):
            ej = ei + max(abs(j - y) - 0.5, 0.0) ** 2
            if ej >= best2:
                continue
            for k in range(max(c0 - h, 0), min(c0 + h, nz - 1) + 1):
                if dt2[i, j, k] == 0:
                    e = ej + max(abs(k - z) - 0.5, 0.0) ** 2
                    if e < best2:
                        best2 = e
    return math.sqrt(best2)


@jit
def _box_gap(dims, x, y, z, walls, held):
    """Distance from (x, y, z) to the nearest box face of a walled axis other than ``held``; inf if none.

    Voxel ``i`` spans ``[i - 1/2, i + 1/2]``, so the faces of axis ``t`` lie at ``-1/2`` and
    ``dims[t] - 1/2``.
    """
    g = np.inf
    if held != 0 and walls[0] != 0:
        g = min(g, x + 0.5, dims[0] - 0.5 - x)
    if held != 1 and walls[1] != 0:
        g = min(g, y + 0.5, dims[1] - 0.5 - y)
    if held != 2 and walls[2] != 0:
        g = min(g, z + 0.5, dims[2] - 0.5 - z)
    return g


@jit(parallel=True)
def _stair_section_peaks(dt2, points, half, n, walls):
    """Largest distance to the voxel staircase over a grid of points around each point, voxels.

    ``(2 n + 1)`` points per axis at spacing ``half / n`` within ``half`` of the point, in the
    interface plane for a face point (one half-integer coordinate: that axis is held), in 3-D for
    a voxel point: the staircase's own inscribed radius near the point, read at sub-voxel
    positions (so a channel whose axis falls between voxel centres reads the same at every grid).
    The box faces of every axis with ``walls[axis]`` non-zero (int64 (3,)) other than the held one
    are walls too (:func:`_box_gap`): a section the box cuts reads the radius of its part inside.
    Points run on numba's threads (``prange``), each alone: the result does not depend on their number.
    """
    m = points.shape[0]
    out = np.zeros(m, np.float64)
    for q in prange(m):
        x0, y0, z0 = points[q, 0], points[q, 1], points[q, 2]
        held = -1
        for t in range(3):
            if points[q, t] - math.floor(points[q, t]) > 0.25:
                held = t
        nx, ny, nz = dt2.shape
        a, b, c = _nearest(x0, nx), _nearest(y0, ny), _nearest(z0, nz)
        bound = math.sqrt(max(dt2[a, b, c], 1)) + 2.0
        best = 0.0
        for s in range(-n, n + 1):
            for t in range(-n, n + 1):
                for u in range(-n, n + 1):
                    if (held == 0 and s != 0) or (held == 1 and t != 0) or (held == 2 and u != 0):
                        continue
                    x, y, z = x0 + s * half / n, y0 + t * half / n, z0 + u * half / n
                    d = min(_stair_dist(dt2, x, y, z, bound), _box_gap(dt2.shape, x, y, z, walls, held))
                    if d > best:
                        best = d
        out[q] = best
    return out


@jit
def _face_rad(dt2, rad_tab, a, b, c, ax, box):
    """Radius at voxel (a, b, c), or (``ax`` >= 0) the mean over it and its +``ax`` neighbour (a face)."""
    v = _stair_rad(dt2, a, b, c, box)
    if ax < 0:
        return v
    return 0.5 * (v + _stair_rad(dt2, a + (ax == 0), b + (ax == 1), c + (ax == 2), box))


@jit
def _subvoxel_peaks(dt2, rad_tab, points):
    """Sub-voxel estimate of the distance-map peak at each point (voxel or face centre), voxels.

    Near the centre ``c`` of the channel's inscribed section the distance to the voxel staircase
    falls off as ``f(x) = r - max_b |x_b - c_b|`` (its walls are flat and axis-aligned: the
    max-norm cone; exact for squares and slits at any offset, and at any refinement of a voxel
    image, where every wall is flat). The best grid sample sits up to half a voxel per axis from
    ``c`` and reads ``r - max_b |delta_b|``; the central differences
    ``g_b = (f(x + e_b) - f(x - e_b)) / 2`` recover ``|delta_b|`` (for ``|delta_b| <= 1/2``),
    so ``r ~ f(x) + max_b |g_b|``, capped at 1/2. A point with a half-integer coordinate is a
    face between two voxels: ``f`` there is the mean of the two, and only the two in-plane axes
    are searched (the throat is a saddle of the distance map: a maximum across the channel, a
    minimum along it). A voxel point (pores) searches all three axes.

    Parameters
    ----------
    dt2 : ndarray of int, shape (nx, ny, nz)
    rad_tab : ndarray of float64
        Radius of every distance-map value (``rad_tab[0] = 0``).
    points : ndarray of float64, shape (M, 3)
        Voxel-index coordinates; at most one coordinate half-integer.

    Returns
    -------
    ndarray of float64, shape (M,)
    """
    box = np.zeros(3, np.int64)  # the open map: pore centres see no box wall
    m = points.shape[0]
    out = np.zeros(m, np.float64)
    for q in range(m):
        base = np.zeros(3, np.int64)
        ax = -1
        for t in range(3):
            fl = math.floor(points[q, t])
            base[t] = int(fl)
            if points[q, t] - fl > 0.25:
                ax = t
        a, b, c = base[0], base[1], base[2]
        g = 0.0
        for t in range(3):
            if t == ax:
                continue
            hi = _face_rad(dt2, rad_tab, a + (t == 0), b + (t == 1), c + (t == 2), ax, box)
            lo = _face_rad(dt2, rad_tab, a - (t == 0), b - (t == 1), c - (t == 2), ax, box)
            g = max(g, 0.5 * abs(hi - lo))
        out[q] = _face_rad(dt2, rad_tab, a, b, c, ax, box) + min(g, 0.5)
    return out
