"""Naive, independent twins of :mod:`porefsi.stokes` (share no code with it), plus closed forms.

* :func:`naive_permeability`: the same MAC finite-volume model written voxel by voxel with Python
  loops and dictionaries (the flow axis is first moved to axis 0), clusters found by a breadth-first
  search, the saddle-point system solved directly (SuperLU). For tiny images only.
* :func:`prism_flow_rate`: fully developed flow through a straight prism of a given pixel cross-section,
  the 2-D Poisson problem on a grid refined ``m`` times per pixel (the exact staircase walls), with a
  Richardson extrapolation: the exact Stokes answer for the voxelised shape, which the 3-D solver can
  only approach.
* closed forms: Hagen-Poiseuille, plane Poiseuille, the square-duct series, Zick & Homsy's table.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

# --------------------------------------------------------------------------------------- closed forms


def tube_flow_rate(radius: float, gradient: float = 1.0, viscosity: float = 1.0) -> float:
    """Hagen-Poiseuille: Q = pi R^4 G / (8 mu)."""
    return math.pi * radius**4 * gradient / (8.0 * viscosity)


def plates_flow_rate_per_width(gap: float, gradient: float = 1.0, viscosity: float = 1.0) -> float:
    """Plane Poiseuille: Q / width = H^3 G / (12 mu)."""
    return gap**3 * gradient / (12.0 * viscosity)


def rectangular_duct_flow_rate(a: float, b: float, gradient: float = 1.0, viscosity: float = 1.0,
                               terms: int = 200) -> float:
    """Duct |y| <= a, |z| <= b (b >= a): White, Viscous Fluid Flow, as quoted by Saadatian & Wong (2020),

    Q = (4 b a^3 / (3 mu)) G [1 - (192 a / (pi^5 b)) sum_{n odd} tanh(n pi b / (2 a)) / n^5].
    """
    s = sum(math.tanh(n * math.pi * b / (2 * a)) / n**5 for n in range(1, 2 * terms, 2))
    return 4 * b * a**3 / (3 * viscosity) * gradient * (1 - 192 * a / (math.pi**5 * b) * s)


#: Zick & Homsy (1982, J. Fluid Mech. 115, table 2), simple cubic array: solid fraction c -> drag K,
#: with F = 6 pi mu a K U per sphere (U superficial), so k = L^3 / (6 pi a K). Values as tabulated
#: in the Basilisk test "Stokes flow past a periodic array of spheres" (src/test/spheres.c).
ZICK_HOMSY_SC = {0.027: 2.008, 0.064: 2.810, 0.125: 4.292, 0.216: 7.442, 0.343: 15.4, 0.45: 28.1, 0.5236: 42.1}


def zick_homsy_permeability(c: float, cell: float = 1.0) -> float:
    """k of a simple cubic array of spheres at solid fraction ``c`` (a key of ZICK_HOMSY_SC), cell edge ``cell``."""
    a = cell * (3 * c / (4 * math.pi)) ** (1 / 3)
    return cell**3 / (6 * math.pi * a * ZICK_HOMSY_SC[c])


# ------------------------------------------------------------------------ staircase prism reference


def _poisson_flow(section: np.ndarray) -> float:
    """Sum of w over the pixels of -lap w = 1 (unit spacing), w = 0 on pixel faces of solid or outside."""
    ny, nz = section.shape
    ids = -np.ones(section.shape, dtype=int)
    pts = list(zip(*np.nonzero(section), strict=True))
    for n, (i, j) in enumerate(pts):
        ids[i, j] = n
    M = sp.lil_matrix((len(pts), len(pts)))
    for n, (i, j) in enumerate(pts):
        for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            a, b = i + di, j + dj
            if 0 <= a < ny and 0 <= b < nz and section[a, b]:
                M[n, n] += 1.0
                M[n, ids[a, b]] -= 1.0
            else:
                M[n, n] += 2.0  # wall on the pixel face, half a pixel away
    w = spla.spsolve(M.tocsc(), np.ones(len(pts)))
    return float(w.sum())


def prism_flow_rate(section: np.ndarray, refine=(4, 8)) -> float:
    """Exact flow rate per unit gradient and viscosity through a prism of pixel cross-section ``section``.

    Each pixel is split into m x m sub-pixels (m in ``refine``); with spacing 1/m the flow rate is
    ``sum(w) / m^4`` of the unit-spacing Poisson solve. The two finest values are extrapolated
    assuming an m^-2 error.
    """
    section = np.asarray(section, dtype=bool)
    q = []
    for m in refine:
        fine = np.kron(section, np.ones((m, m), dtype=bool))
        q.append(_poisson_flow(fine) / m**4)
    m1, m2 = refine[-2], refine[-1]
    return (m2**2 * q[-1] - m1**2 * q[-2]) / (m2**2 - m1**2)


def disk(radius: float, centre: str = "corner") -> np.ndarray:
    """Pixels whose centre is within ``radius`` of the disc centre (a pixel corner or centre), plus a solid ring."""
    m = int(math.ceil(radius)) + 1
    if centre == "corner":
        c = np.arange(2 * m) - m + 0.5
    else:
        c = np.arange(2 * m + 1) - m
    y, z = np.meshgrid(c, c, indexing="ij")
    return y**2 + z**2 <= radius**2


# ------------------------------------------------------------------------------ naive 3-D twin


def _clusters_touching_both(pore, periodic):
    """BFS over face neighbours (wrapping on periodic axes); keep clusters touching x = 0 and x = n-1."""
    n0, n1, n2 = pore.shape
    label = -np.ones(pore.shape, dtype=int)
    keep = np.zeros(pore.shape, dtype=bool)
    lab = 0
    for start in zip(*np.nonzero(pore), strict=True):
        if label[start] >= 0:
            continue
        members = [start]
        label[start] = lab
        queue = deque([start])
        while queue:
            c = queue.popleft()
            for ax in range(3):
                for s in (-1, 1):
                    q = list(c)
                    q[ax] += s
                    if not 0 <= q[ax] < pore.shape[ax]:
                        if not periodic[ax]:
                            continue
                        q[ax] %= pore.shape[ax]
                    q = tuple(q)
                    if pore[q] and label[q] < 0:
                        label[q] = lab
                        members.append(q)
                        queue.append(q)
        xs = {m[0] for m in members}
        if 0 in xs and (n0 - 1) in xs:
            for m in members:
                keep[m] = True
        lab += 1
    return keep


def naive_permeability(pore: np.ndarray, axis: int, *, boundary: str = "pressure", buffer: int = 2,
                       lateral: str = "wall", mirror: bool = False, wall: str = "ghost") -> float:
    """k / h^2 of ``pore`` along ``axis`` (voxel units), the model of porefsi.stokes written naively.

    ``wall="channel"``: a tangential wall half a voxel away weighs 6N/(3N-2) instead of 2, N the
    number of velocity unknowns in the straight line through the face along the wall normal; a
    closed neighbour face with one solid voxel (a step) weighs (1 + 6N/(3N-2)) / 2 instead of 1.
    """
    W = np.moveaxis(np.asarray(pore, dtype=bool), axis, 0)
    lat_per = lateral == "periodic"
    periodic = (boundary == "periodic", lat_per, lat_per)
    W = _clusters_touching_both(W, periodic)
    n_img = W.shape[0]
    cross = W.shape[1] * W.shape[2]
    if boundary == "pressure":
        W = np.concatenate([np.ones((buffer,) + W.shape[1:], bool), W,
                            np.ones((buffer,) + W.shape[1:], bool)], axis=0)
    elif mirror:
        W = np.concatenate([W, W[::-1]], axis=0)
    N = W.shape
    is_open = boundary == "pressure"
    P_IN, P_OUT = float(N[0]), 0.0

    def voxel(c):
        """Is voxel c pore? Outside: wrap (periodic), mirror the edge (open flow axis), solid (wall)."""
        c = list(c)
        for a in range(3):
            if 0 <= c[a] < N[a]:
                continue
            if periodic[a]:
                c[a] %= N[a]
            elif a == 0 and is_open:
                c[a] = min(max(c[a], 0), N[a] - 1)
            else:
                return False
        return bool(W[tuple(c)])

    def n_planes(d):
        return N[d] if periodic[d] else N[d] + 1

    # unknowns
    index = {}
    for c in zip(*np.nonzero(W), strict=True):
        index[("p",) + tuple(int(v) for v in c)] = len(index)
    for d in range(3):
        for f in range(n_planes(d)):
            for t1 in range(N[(d + 1) % 3]):
                for t2 in range(N[(d + 2) % 3]):
                    c = [0, 0, 0]
                    c[d], c[(d + 1) % 3], c[(d + 2) % 3] = f, t1, t2
                    lo = list(c)
                    lo[d] -= 1
                    if voxel(lo) and voxel(c):
                        index[("u", d) + tuple(c)] = len(index)

    def face(d, c):
        """Index of the d-face at plane/position c (wrapping periodic axes), None if closed, or "outside"."""
        c = list(c)
        for a in range(3):
            lim = n_planes(a) if a == d else N[a]
            if not 0 <= c[a] < lim:
                if periodic[a]:
                    c[a] %= lim
                elif a == 0 and is_open:
                    return "outside"  # the reservoir: no term (zero normal gradient)
                else:
                    return None  # beyond a wall: a closed face
        return index.get(("u", d) + tuple(c))

    def pressure(c):
        c = list(c)
        for a in range(3):
            if not 0 <= c[a] < N[a]:
                if periodic[a]:
                    c[a] %= N[a]
                else:
                    return None
        return index.get(("p",) + tuple(c))

    def line_length(d, c, e):
        """Velocity unknowns of component d on the line along e through c (c included), walls ending it."""
        count = 1
        for s in (-1, 1):
            q = list(c)
            for _ in range(N[e]):
                q[e] += s
                g = face(d, q)
                if g is None or g == "outside" or g == index[("u", d) + tuple(c)]:
                    break
                count += 1
        return min(count, n_planes(e) if e == d else N[e])

    def parallel_wall(d, c, e):
        if wall == "ghost":
            return 2.0
        m = line_length(d, c, e)
        return 6.0 * m / (3.0 * m - 2.0)

    n = len(index)
    K = sp.lil_matrix((n, n))
    rhs = np.zeros(n)
    for key, row in index.items():
        if key[0] != "u":
            continue
        d, c = key[1], list(key[2:])
        boundary_face = is_open and d == 0 and c[0] in (0, N[0])
        for e in range(3):
            for s in (-1, 1):
                q = list(c)
                q[e] += s
                w = 1.0 if (e == d or not boundary_face) else 0.5
                g = face(d, q)
                if g == "outside":
                    continue  # beyond an open box face (normal), or along the open axis (tangential)
                if g is not None:
                    K[row, row] += w
                    K[row, g] -= w
                    continue
                if e == d:
                    K[row, row] += w  # the wall face a voxel away
                    continue
                lo = list(q)
                lo[d] -= 1
                solid = (not voxel(lo)) + (not voxel(q))
                if solid == 2:
                    K[row, row] += w * parallel_wall(d, c, e)
                elif wall == "channel":  # a step: half of that side of the control volume is wall
                    K[row, row] += w * 0.5 * (1.0 + parallel_wall(d, c, e))
                else:
                    K[row, row] += w * 1.0
        lo = list(c)
        lo[d] -= 1
        p_lo, p_hi = pressure(lo), pressure(c)
        if p_hi is not None:
            K[row, p_hi] += 1.0
        elif is_open and d == 0:
            rhs[row] -= P_OUT
        if p_lo is not None:
            K[row, p_lo] -= 1.0
        elif is_open and d == 0:
            rhs[row] += P_IN
        if boundary == "periodic" and d == 0:
            rhs[row] += 1.0
    for key, row in index.items():
        if key[0] != "p":
            continue
        c = list(key[1:])
        for d in range(3):
            hi = list(c)
            hi[d] += 1
            for cc, sign in ((c, -1.0), (hi, 1.0)):
                g = face(d, cc)
                if g not in (None, "outside"):
                    K[row, g] -= sign  # -B u = 0, B = outflow - inflow
    K = K.tocsr()
    if boundary == "periodic":  # pressure is defined up to a constant: zero mean by a multiplier
        prow = np.array([row for key, row in index.items() if key[0] == "p"])
        col = sp.csr_matrix((np.ones(prow.size), (prow, np.zeros(prow.size))), shape=(n, 1))
        K = sp.bmat([[K, col], [col.T, None]]).tocsr()
        rhs = np.append(rhs, 0.0)
    x = spla.spsolve(K.tocsc(), rhs)
    flux = [sum(x[index[k]] for k in index if k[0] == "u" and k[1] == 0 and k[2] == f) for f in range(n_planes(0))]
    q = float(np.mean(flux))
    if boundary == "periodic":
        return q / cross
    if buffer == 0:
        dp = P_IN - P_OUT
    else:
        def layer(i):
            vals = [x[index[k]] for k in index if k[0] == "p" and k[1] == i]
            return float(np.mean(vals))
        if buffer == 1:
            dp = (2 * layer(0) - P_IN) - (2 * layer(N[0] - 1) - P_OUT)
        else:
            a1, a2 = layer(buffer - 1), layer(buffer - 2)
            b1, b2 = layer(N[0] - buffer), layer(N[0] - buffer + 1)
            dp = (1.5 * a1 - 0.5 * a2) - (1.5 * b1 - 0.5 * b2)
    return q * n_img / (cross * dp)
