"""Naive pure-Python twins of ``porefsi/network/_mb_sections.py`` (clarity over speed).

Each twin restates its kernel's definition with plain loops over explicit voxel faces and shares
no code with it.
"""

from __future__ import annotations

import math
from itertools import product

import numpy as np


def sections(labels, conns, walls=(0, 0, 0)):
    """Vector area (Nt, 3), face count and wall-edge count of every throat interface.

    Walk every pair of face-neighbouring voxels ``p`` (lower coordinate) and ``q = p + e_ax``;
    a pair labelled ``{a, b}`` of a listed throat adds ``+e_ax`` to its vector area if ``p`` is
    labelled with the throat's first pore, ``-e_ax`` otherwise. For each such face, look at the
    four faces obtained by shifting both voxels by one step along an in-plane axis: inside the
    image, if either shifted voxel is solid (label < 0), the shared edge is a wall edge. With
    ``walls``, the labels are first padded with a solid (-1) layer across both faces of each
    walled axis, so the box faces there end the sections with wall edges.
    """
    pad = [(1, 1) if w else (0, 0) for w in walls]
    if any(walls):
        area, faces, wall = sections(np.pad(labels, pad, constant_values=-1), conns)
        return area, faces, wall
    index = {(int(a), int(b)): t for t, (a, b) in enumerate(conns)}
    n_t = len(conns)
    area = np.zeros((n_t, 3))
    faces = np.zeros(n_t, int)
    wall = np.zeros(n_t, int)
    shape = labels.shape
    for p in np.ndindex(shape):
        for ax in range(3):
            q = list(p)
            q[ax] += 1
            if q[ax] >= shape[ax]:
                continue
            q = tuple(q)
            a, b = int(labels[p]), int(labels[q])
            if a < 0 or b < 0 or a == b:
                continue
            t = index.get((min(a, b), max(a, b)))
            if t is None:
                continue
            area[t, ax] += 1 if a == conns[t][0] else -1
            faces[t] += 1
            for other in range(3):
                if other == ax:
                    continue
                for step in (-1, 1):
                    p2 = list(p)
                    q2 = list(q)
                    p2[other] += step
                    q2[other] += step
                    if not 0 <= p2[other] < shape[other]:
                        continue
                    if labels[tuple(p2)] < 0 or labels[tuple(q2)] < 0:
                        wall[t] += 1
    return area, faces, wall


def _padded_solid(solid_mask, walls):
    """Coordinates (in the box's frame) of the solid voxels of the image padded with one solid
    voxel layer across both faces of every axis with ``walls[axis]`` set."""
    pad = [(1, 1) if w else (0, 0) for w in walls]
    padded = np.pad(np.asarray(solid_mask, bool), pad, constant_values=True)
    return np.argwhere(padded) - np.array([p[0] for p in pad])


def box_walled(pore, walls):
    """Squared distance map of ``pore`` with solid layers just outside the faces of the walled axes:
    brute force over the solid voxels of the padded image (:func:`_padded_solid`), cropped back."""
    solid = _padded_solid(~np.asarray(pore, bool), walls)
    out = np.zeros(pore.shape, np.int64)
    for ijk in np.argwhere(pore):
        out[tuple(ijk)] = int(((solid - ijk) ** 2).sum(axis=1).min())
    return out


def stair_radius(dt2, idx, walls=(0, 0, 0)):
    """Distance from voxel ``idx``'s centre to the nearest solid voxel cube (``dt2 == 0``, plus the
    solid layers across the walled box faces), by brute force over every solid voxel; 0 in solid;
    the distance map's own bound ``sqrt(dt2) - 1/2`` when no solid voxel lies in the image
    (outside is not solid)."""
    if dt2[idx] == 0:
        return 0.0
    solid = _padded_solid(dt2 == 0, walls)
    if solid.size == 0:
        return math.sqrt(dt2[idx]) - 0.5
    gap = np.maximum(np.abs(solid - np.asarray(idx)) - 0.5, 0.0)
    return float(np.sqrt((gap**2).sum(axis=1)).min())


def stair_section_peaks(dt2, points, half, n, walls):
    """Per point: the largest distance to the nearest solid voxel cube over the grid points at
    spacing ``half / n`` within ``half`` per axis (only in the plane of a face point: the axis of its
    half-integer coordinate is held), the image padded with solid layers across the faces of the
    walled axes other than the held one (:func:`_padded_solid`); each distance at most
    ``sqrt(max(dt2, 1)) + 2`` of the voxel nearest to the point (the search's reach)."""
    out = np.zeros(len(points))
    for q, p in enumerate(np.asarray(points, float)):
        held = [a for a in range(3) if p[a] - math.floor(p[a]) > 0.25]
        w = [walls[a] and a not in held for a in range(3)]
        solid = _padded_solid(dt2 == 0, w)
        near = tuple(min(max(math.floor(p[a] + 0.5), 0), dt2.shape[a] - 1) for a in range(3))
        reach = math.sqrt(max(int(dt2[near]), 1)) + 2.0
        steps = np.arange(-n, n + 1) * half / n
        for off in product(*[[0.0] if a in held else steps for a in range(3)]):
            x = p + np.array(off)
            gap = np.maximum(np.abs(solid - x) - 0.5, 0.0)
            d = float(np.sqrt((gap**2).sum(axis=1)).min()) if solid.size else reach
            out[q] = max(out[q], min(d, reach))
    return out


def ridge_radius(dt2, radius_of, idx, u, walls=(0, 0, 0)):
    """Staircase radius at voxel ``idx`` (:func:`stair_radius`) plus the largest component of the
    across-line part of the central-difference gradient of ``radius_of`` (voxels outside the image
    read 0), capped at 1/2; 0 in solid."""
    f = stair_radius(dt2, idx, walls)
    if f == 0:
        return 0.0

    def at(j):
        return radius_of(int(dt2[j])) if all(0 <= j[k] < dt2.shape[k] for k in range(3)) else 0.0

    g = np.zeros(3)
    for k in range(3):
        hi = list(idx)
        lo = list(idx)
        hi[k] += 1
        lo[k] -= 1
        g[k] = (at(tuple(hi)) - at(tuple(lo))) / 2
    u = np.asarray(u, dtype=float)
    across = g - np.dot(g, u) * u
    return f + min(float(np.max(np.abs(across))), 0.5)


def plane_peak(dt2, q, e1, e2, reach, walls=(0, 0, 0)):
    """Largest distance to the nearest solid voxel cube (the padded image, :func:`_padded_solid`)
    over the 9 x 9 points q + a e1 + b e2, a, b in {-1/2, -3/8, ..., 1/2}; each at most reach."""
    solid = _padded_solid(dt2 == 0, walls)
    best = 0.0
    for a in np.arange(-4, 5) / 8:
        for b in np.arange(-4, 5) / 8:
            x = np.asarray(q, float) + a * np.asarray(e1) + b * np.asarray(e2)
            gap = np.maximum(np.abs(solid - x) - 0.5, 0.0)
            d = float(np.sqrt((gap**2).sum(axis=1)).min()) if solid.size else reach
            best = max(best, min(d, reach))
    return best


def section_radius(dt2, radius_of, x, u, walls=(0, 0, 0), subvoxel=False):
    """Largest ridge radius over the voxels nearest to the points x + s e1 + t e2 (integer s, t,
    s^2 + t^2 <= rho^2, rho the radius at the voxel nearest to x; e1, e2 an orthonormal pair
    normal to u, e1 from the x axis, or the y axis when u is within ~25 degrees of x); 0 in solid.
    Ties keep the first voxel met (s, then t, ascending; x's own voxel before all). ``subvoxel``:
    instead of that voxel's ridge radius, :func:`plane_peak` at its centre moved along u into the
    plane through x, reach ``sqrt(dt2) + 1`` of the voxel."""
    def nearest(p):
        return tuple(min(max(math.floor(p[k] + 0.5), 0), dt2.shape[k] - 1) for k in range(3))

    u = np.asarray(u, dtype=float)
    here = nearest(x)
    rho = radius_of(int(dt2[here]))
    if rho == 0:
        return 0.0
    a = np.array([1.0, 0, 0]) if abs(u[0]) < 0.9 else np.array([0, 1.0, 0])
    e1 = a - np.dot(a, u) * u
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    best, where = int(dt2[here]), here
    h = int(rho)
    for s in range(-h, h + 1):
        for t in range(-h, h + 1):
            if s * s + t * t > rho * rho:
                continue
            v = nearest([x[k] + s * e1[k] + t * e2[k] for k in range(3)])
            if int(dt2[v]) > best:
                best, where = int(dt2[v]), v
    if subvoxel:
        w = np.asarray(where, float)
        q = w + np.dot(np.asarray(x, float) - w, u) * u
        return plane_peak(dt2, q, e1, e2, math.sqrt(best) + 1.0, walls)
    return ridge_radius(dt2, radius_of, where, u, walls)


def constriction_lengths(dt2, radius_of, centre, point, conns, r_throat, r_pore, step, walls=(0, 0, 0),
                         subvoxel=False):
    """Side lengths d (Nt, 2) and resistance-equivalent throat lengths (Nt, 2), voxels.

    ``radius_of(v)`` gives the radius of a distance-map value. Along the straight segment from a
    pore centre to the throat point, midpoint samples of ``ceil(d / step)`` equal parts take the
    section radius (:func:`section_radius`) at the sample, clamped to [r_t, R]; the throat
    length solves
    ``L_t / r_t^4 + (d - L_t) / R^4 = sum(dx / r^4)``. With ``walls``, ``dt2`` is the walled map
    (:func:`box_walled`) and the staircase includes the solid layers across the walled faces.
    ``subvoxel``: the samples read :func:`section_radius` with ``subvoxel``.
    """
    n_t = len(conns)
    d_out = np.zeros((n_t, 2))
    lt_out = np.zeros((n_t, 2))
    for t in range(n_t):
        for s in range(2):
            p = conns[t][s]
            vec = [point[t][k] - centre[p][k] for k in range(3)]
            d = math.sqrt(sum(v * v for v in vec))
            d_out[t, s] = d
            R, rt = r_pore[p], r_throat[t]
            if R <= rt or d == 0:
                lt_out[t, s] = d / 2
                continue
            m = max(1, math.ceil(d / step))
            total = 0.0
            for q in range(m):
                x = [centre[p][k] + (q + 0.5) / m * vec[k] for k in range(3)]
                r = min(max(section_radius(dt2, radius_of, x, [v / d for v in vec], walls, subvoxel), rt), R)
                total += (d / m) / r**4
            lt = (total - d / R**4) / (1 / rt**4 - 1 / R**4)
            lt_out[t, s] = min(max(lt, 0.0), d)
    return d_out, lt_out


def tube_beside_face():
    """Test geometry: two spheres of radius 4 joined by a tube whose axis runs 1 voxel from the y face.

    Returns ``pore`` (bool (20, 9, 9)), the wall-convention radius table ``tab`` (index: squared
    distance) for its distance map up to ``max_d2``, and one throat between the spheres:
    ``centre`` (2, 3), ``point`` (1, 3), ``conns`` (1, 2), ``r_throat`` (1,), ``r_pore`` (2,).
    """
    pore = np.zeros((20, 9, 9), bool)
    g = np.indices(pore.shape)
    pore |= (g[1] - 1) ** 2 + (g[2] - 4) ** 2 <= 12
    for cx in (4, 15):
        pore |= (g[0] - cx) ** 2 + (g[1] - 2) ** 2 + (g[2] - 4) ** 2 <= 16
    centre = np.array([[4.0, 2.0, 4.0], [15.0, 2.0, 4.0]])
    point = np.array([[9.5, 1.0, 4.0]])
    return pore, centre, point, np.array([[0, 1]]), np.array([1.2]), np.array([3.0, 3.0])


def wall_radius_table(max_d2):
    """``sqrt(d2) - 1/2`` for d2 = 0 ... max_d2 (0 at d2 = 0): the 'wall' radius, voxels."""
    tab = np.sqrt(np.maximum(np.arange(int(max_d2) + 1), 1)) - 0.5
    tab[0] = 0.0
    return tab
