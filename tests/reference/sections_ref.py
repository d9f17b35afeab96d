"""Naive pure-Python twins of ``porefsi/network/_mb_sections.py`` (clarity over speed).

Each twin restates its kernel's definition with plain loops over explicit voxel faces and shares
no code with it.
"""

from __future__ import annotations

import math

import numpy as np


def sections(labels, conns):
    """Vector area (Nt, 3), face count and wall-edge count of every throat interface.

    Walk every pair of face-neighbouring voxels ``p`` (lower coordinate) and ``q = p + e_ax``;
    a pair labelled ``{a, b}`` of a listed throat adds ``+e_ax`` to its vector area if ``p`` is
    labelled with the throat's first pore, ``-e_ax`` otherwise. For each such face, look at the
    four faces obtained by shifting both voxels by one step along an in-plane axis: inside the
    image, if either shifted voxel is solid (label < 0), the shared edge is a wall edge.
    """
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


def ridge_radius(dt2, radius_of, idx, u):
    """Radius at voxel ``idx`` plus the length of the across-line part of its central-difference
    gradient (voxels outside the image read 0), capped at sqrt(2)/2; 0 in solid."""
    f = radius_of(int(dt2[idx]))
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
    return f + min(float(np.linalg.norm(across)), math.sqrt(2) / 2)


def constriction_lengths(dt2, radius_of, centre, point, conns, r_throat, r_pore, step):
    """Side lengths d (Nt, 2) and resistance-equivalent throat lengths (Nt, 2), voxels.

    ``radius_of(v)`` gives the radius of a distance-map value. Along the straight segment from a
    pore centre to the throat point, midpoint samples of ``ceil(d / step)`` equal parts take the
    ridge radius (:func:`ridge_radius`) of the nearest voxel (halves rounded up, indices clipped
    to the image), clamped to [r_t, R]; the throat length solves
    ``L_t / r_t^4 + (d - L_t) / R^4 = sum(dx / r^4)``.
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
                idx = tuple(min(max(math.floor(x[k] + 0.5), 0), dt2.shape[k] - 1) for k in range(3))
                r = min(max(ridge_radius(dt2, radius_of, idx, [v / d for v in vec]), rt), R)
                total += (d / m) / r**4
            lt = (total - d / R**4) / (1 / rt**4 - 1 / R**4)
            lt_out[t, s] = min(max(lt, 0.0), d)
    return d_out, lt_out
