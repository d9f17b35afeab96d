"""Naive pure-Python twins of the kernels in ``porefsi/network/_kernels.py``.

Written for clarity, not speed (use on images of a few hundred voxels): brute-force distance
map, explicit neighbour loops, Python dicts and deques. Each twin states the same definition as
its kernel's docstring, independently coded.
"""

from __future__ import annotations

import math
from collections import deque
from itertools import product

import numpy as np

INF = np.iinfo(np.int32).max


def sq_edt(pore):
    """Squared distance from each voxel centre to the nearest solid voxel centre (brute force).

    INF (the int32 maximum) where the image has no solid voxel at all.
    """
    solid = np.argwhere(pore == 0)
    out = np.zeros(pore.shape, np.int64)
    for ijk in np.argwhere(pore != 0):
        if solid.size == 0:
            out[tuple(ijk)] = INF
        else:
            out[tuple(ijk)] = int(((solid - ijk) ** 2).sum(axis=1).min())
    return out


def pore_solid_faces(pore):
    """Voxel faces between a pore and a solid voxel inside the box (explicit loop over voxel pairs)."""
    n = 0
    for ijk in np.argwhere(pore != 0):
        for ax in range(3):
            for step in (-1, 1):
                q = ijk.copy()
                q[ax] += step
                if 0 <= q[ax] < pore.shape[ax] and pore[tuple(q)] == 0:
                    n += 1
    return n


def _ball(c, d2, shape=None):
    """Lattice points x with |x - c|^2 < d2 (inside ``shape`` when given)."""
    r = math.isqrt(max(d2 - 1, 0))
    pts = []
    for off in product(range(-r, r + 1), repeat=3):
        if sum(o * o for o in off) < d2:
            x = tuple(a + o for a, o in zip(c, off, strict=True))
            if shape is None or all(0 <= x[a] < shape[a] for a in range(3)):
                pts.append(x)
    return pts


def ball_reach(offset, d2):
    """Largest squared distance from ``offset`` to a lattice point of the ball |y|^2 < d2 (brute force)."""
    return max(sum((y[a] - offset[a]) ** 2 for a in range(3)) for y in _ball((0, 0, 0), d2))


def maximal_balls(dt2, min_dt2, half_width=1):
    """Maximal-ball centres (radius descending, linear index ascending) and candidate count.

    A candidate is dropped when its whole digital ball (lattice points, not clipped to the image)
    lies inside the digital ball of a neighbour within ``half_width``, checked point by point.
    """
    shape = dt2.shape
    found = []
    ncand = 0
    for ijk in product(*[range(s) for s in shape]):
        dp = int(dt2[ijk])
        if dp < min_dt2:
            continue
        ncand += 1
        ball = _ball(ijk, dp)
        contained = False
        for off in product(range(-half_width, half_width + 1), repeat=3):
            q = tuple(a + o for a, o in zip(ijk, off, strict=True))
            if off == (0, 0, 0) or not all(0 <= q[a] < shape[a] for a in range(3)):
                continue
            dq = int(dt2[q])
            if all(sum((x[a] - q[a]) ** 2 for a in range(3)) < dq for x in ball):
                contained = True
        if not contained:
            found.append((-dp, int(np.ravel_multi_index(ijk, shape))))
    found.sort()
    return np.array([f[1] for f in found], dtype=np.int64), ncand


def families(dt2, balls, extent, ratio, core=0.0):
    """Ball hierarchy and painted labels (see ``_kernels._families``)."""
    shape = dt2.shape
    labels = -np.ones(shape, np.int64)
    in_core = np.zeros(shape, bool)
    centres = [np.unravel_index(int(b), shape) for b in balls]
    radius = [math.sqrt(dt2[c]) for c in centres]
    master = []
    for k, c in enumerate(centres):
        if in_core[c]:  # skipped: joins the family of the ball owning its centre
            master.append(master[int(labels[c])])
            continue
        d2 = int(dt2[c])
        ball = _ball(c, d2, shape)
        for v in ball:
            if sum((v[a] - c[a]) ** 2 for a in range(3)) < core * core * d2:
                in_core[v] = True
        owners = sorted({int(labels[v]) for v in ball if labels[v] >= 0})
        chosen = None
        for o in owners:  # ascending visit order = descending radius
            m = master[o]
            dist2 = sum((centres[m][a] - c[a]) ** 2 for a in range(3))
            if dist2 < (extent * radius[m]) ** 2 or radius[k] < ratio * radius[m]:
                chosen = o
                break
        if chosen is None:
            master.append(k)
            for v in ball:
                labels[v] = k
        else:
            master.append(master[chosen])
            for v in ball:
                if labels[v] < 0:
                    labels[v] = k
    return np.array(master, dtype=np.int64), labels


def _face_neighbours(v, shape):
    for ax in range(3):
        for step in (-1, 1):
            q = list(v)
            q[ax] += step
            if 0 <= q[ax] < shape[ax]:
                yield tuple(q)


def flood(dt2, labels):
    """Seeded flood, level by level from the top (see ``_kernels._flood``), with a deque."""
    lab = labels.copy()
    shape = dt2.shape
    n = 0
    for level in range(int(dt2.max()), 0, -1):
        queue = deque()
        starts = []
        for v in product(*[range(s) for s in shape]):  # C order
            if dt2[v] == level and lab[v] == -1:
                for q in _face_neighbours(v, shape):
                    if lab[q] >= 0:
                        starts.append((v, int(lab[q])))
                        break
        for v, s in starts:
            lab[v] = s
            queue.append(v)
        while queue:
            v = queue.popleft()
            n += 1
            for q in _face_neighbours(v, shape):
                if lab[q] == -1 and dt2[q] >= level:
                    lab[q] = lab[v]
                    queue.append(q)
    return lab, n


def interfaces(labels, dt2):
    """Throats from label interfaces: conns, max min-dt2, first face attaining it, face count."""
    shape = labels.shape
    throats = {}
    order = []
    for v in product(*[range(s) for s in shape]):
        la = int(labels[v])
        if la < 0:
            continue
        for ax in range(3):
            q = list(v)
            q[ax] += 1
            q = tuple(q)
            if q[ax] >= shape[ax]:
                continue
            lb = int(labels[q])
            if lb < 0 or lb == la:
                continue
            key = (min(la, lb), max(la, lb))
            val = int(min(dt2[v], dt2[q]))
            point = tuple(v[a] + 0.5 * (q[a] - v[a]) for a in range(3))
            if key not in throats:
                throats[key] = [val, point, 0]
                order.append(key)
            rec = throats[key]
            rec[2] += 1
            if val > rec[0]:
                rec[0], rec[1] = val, point
    conns = np.array(order, dtype=np.int64).reshape(-1, 2)
    w = np.array([throats[k][0] for k in order], dtype=np.int64)
    point = np.array([throats[k][1] for k in order], dtype=float).reshape(-1, 3)
    nf = np.array([throats[k][2] for k in order], dtype=np.int64)
    return conns, w, point, nf


def pore_stats(labels, n_pores):
    """Voxel counts and touched faces per pore, with numpy slicing."""
    count = np.bincount(labels[labels >= 0].ravel(), minlength=n_pores)
    faces = np.zeros((n_pores, 6), bool)
    for ax in range(3):
        for side, idx in ((0, 0), (1, labels.shape[ax] - 1)):
            sl = np.take(labels, idx, axis=ax)
            faces[np.unique(sl[sl >= 0]), 2 * ax + side] = True
    return count, faces
