"""Naive pure-Python twin of ``porefsi/network/_mb_section_law.py`` (clarity over speed).

The plane sections are flooded with a Python set over explicit grid points; the radius samples
reuse the twin of the default samples (:func:`tests.reference.sections_ref.section_radius`). The
conductance law is the network's public one (``porefsi.network.geometry.duct_conductance_factor``,
itself checked against closed forms in ``tests/test_network_geometry.py``): what this twin restates
is the sampling, the flood and the integral.
"""

from __future__ import annotations

import math

import numpy as np

from porefsi.network.geometry import duct_conductance_factor
from tests.reference.sections_ref import section_radius

HALF = 64  # the kernel's plane grid: |s|, |t| <= 64


def _plane(u):
    """e1, e2 as the kernel's: e1 from the x axis (the y axis when u is within ~25 degrees of x)."""
    a = np.array([1.0, 0, 0]) if abs(u[0]) < 0.9 else np.array([0, 1.0, 0])
    e1 = a - np.dot(a, u) * u
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(u, e1)


def _voxel(dt2w, x, e1, e2, s, t):
    """Nearest voxel to x + s e1 + t e2 (halves up), or None off the image."""
    p = [x[k] + s * e1[k] + t * e2[k] for k in range(3)]
    v = tuple(math.floor(p[k] + 0.5) for k in range(3))
    return v if all(0 <= v[k] < dt2w.shape[k] for k in range(3)) else None


def plane_area(dt2w, labels, x, u, pair, cap):
    """Grid points of the 4-connected channel set in the plane through x normal to u.

    Started at the widest voxel (largest walled ``dt2w``, first met in s then t ascending) among the
    points with ``s^2 + t^2 <= rho^2`` (rho: ``sqrt(dt2w) - 1/2`` at x's nearest voxel); a point is in
    the channel when its voxel is pore on ``dt2w`` and labelled ``pair[0]`` or ``pair[1]``; at most
    ``cap`` points counted (a depth-first walk stops there); 0 when x's voxel is solid.
    """
    e1, e2 = _plane(np.asarray(u, float))
    here = tuple(min(max(math.floor(x[k] + 0.5), 0), dt2w.shape[k] - 1) for k in range(3))
    if dt2w[here] == 0:
        return 0
    rho = math.sqrt(dt2w[here]) - 0.5
    best, start = -1, (0, 0)
    for s in range(-int(rho), int(rho) + 1):
        for t in range(-int(rho), int(rho) + 1):
            v = _voxel(dt2w, x, e1, e2, s, t) if s * s + t * t <= rho * rho else None
            if v is not None and dt2w[v] > best:
                best, start = int(dt2w[v]), (s, t)

    def inside(st):
        v = _voxel(dt2w, x, e1, e2, *st)
        return v is not None and dt2w[v] > 0 and labels[v] in pair and max(abs(st[0]), abs(st[1])) <= HALF

    if not inside(start):
        return 0
    seen, stack, count = {start}, [start], 0
    while stack and count < cap:
        s, t = stack.pop()
        count += 1
        for nb in ((s + 1, t), (s - 1, t), (s, t + 1), (s, t - 1)):
            if nb not in seen and max(abs(nb[0]), abs(nb[1])) <= HALF:
                seen.add(nb)
                if inside(nb):
                    stack.append(nb)
    return count


def section_law_lengths(dt2w, labels, tab, centre, point, conns, radii, shape, walls, step=0.25):
    """Side lengths d (Nt, 2) and duct-law throat lengths (Nt, 2), voxels.

    ``radii`` = (r_throat, r_pore), ``shape`` = (G_throat, G_pore); ``dt2w`` the walled map. Per side
    with a constriction (R > r_t and g_p > g_t): midpoint samples of ``ceil(d / step)`` parts read
    r (the default samples' twin, clamped to [r_t, R]) and A (:func:`plane_area`, cap
    ``ceil(2 max(R^2 / (4 G_p), r_t^2 / (4 G_t)))``); g = law(r, min(r^2 / 4A, 1 / 4 pi)) clamped to
    [g_t, g_p]; ``L_t = (sum (d/m)/g - d/g_p) / (1/g_t - 1/g_p)`` in [0, d]; else d / 2.
    """
    r_t, r_p = radii
    G_t, G_p = shape
    out_d, out_l = np.zeros((len(conns), 2)), np.zeros((len(conns), 2))
    for t, pair in enumerate(conns):
        gt = float(duct_conductance_factor(r_t[t], G_t[t]))
        for s in range(2):
            p = pair[s]
            vec = np.asarray(point[t], float) - np.asarray(centre[p], float)
            d = float(np.linalg.norm(vec))
            out_d[t, s] = d
            R = r_p[p]
            gp = float(duct_conductance_factor(R, G_p[p]))
            if not (R > r_t[t] and d > 0 and gp > gt):
                out_l[t, s] = d / 2
                continue
            m = max(1, math.ceil(d / step))
            cap = math.ceil(2 * max(R * R / (4 * G_p[p]), r_t[t] ** 2 / (4 * G_t[t])))
            total = 0.0
            for q in range(m):
                x = np.asarray(centre[p], float) + (q + 0.5) / m * vec
                r = section_radius(dt2w, lambda v: tab[v], x, vec / d, walls)
                r = min(max(r, r_t[t]), R)
                A = plane_area(dt2w, labels, x, vec / d, (pair[0], pair[1]), cap)
                G = min(r * r / (4 * max(A, 1e-300)), 1 / (4 * math.pi))
                g = min(max(float(duct_conductance_factor(r, G)), gt), gp)
                total += (d / m) / g
            out_l[t, s] = min(max((total - d / gp) / (1 / gt - 1 / gp), 0.0), d)
    return out_d, out_l
