"""The seed paper's convex-hull interface (section 2.3.1, eqs. 2.25-2.26, 3.2).

Each pore i gets N points uniform on its sphere (centre ``c_i``, radius ``r_i``); Qhull builds
their convex hull, which is enlarged by ``ε_i`` (the range of inclusivity, eq. 3.2); candidate FE
nodes inside are the pore's members. The pore force ``F_i = ∫ P_i n ds`` is integrated with the
test points as quadrature points (each carries area ``4 pi r_i² / N``) and each test point's
share is lumped onto its nearest member node along ``n = (x_k - c_i)/|x_k - c_i|``, so per pore
``sum_k |f_k| = P_i 4 pi r_i²`` exactly. Optionally the throat walls are loaded the same way
(cylinders, the mean pressure of the two pores).
"""

from __future__ import annotations

import dataclasses
import time
from typing import ClassVar

import numpy as np
import scipy.sparse as sp
from scipy.spatial import ConvexHull

from porefsi.coupling import _kernels
from porefsi.coupling._sparse import assemble, column_magnitudes, throat_mean
from porefsi.coupling.interface import LinearInterface
from porefsi.errors import InputError
from porefsi.network.network import Network

__all__ = ["HullInterface", "hull_interface", "hull_members", "sphere_test_points",
           "throat_cylinders"]


@dataclasses.dataclass(frozen=True, eq=False)
class HullInterface(LinearInterface):
    """The convex-hull operator (an :class:`~porefsi.coupling.interface.Interface`).

    Attributes
    ----------
    operator : scipy.sparse.csr_matrix, shape (3 Nn, Np)
        ``nodal_forces(P).ravel() == operator @ P``; m².
    wall_area : ndarray, shape (Np,)
        ``4 pi r²`` per pore (plus half the lateral area of each of its throats with throat forces), m².
    pore_nodes : tuple of ndarray
        For each pore, the FE nodes that receive its load.
    n_unloaded : int
        Pores whose hull holds no candidate node (their force is lost; see :meth:`load_balance_error`).
    seconds : float
        Build time, s.
    handed_area : ndarray, shape (Np,)
        Per pore, the area booked while the operator was assembled, m² (equal to ``wall_area`` for
        every loaded pore; bookkeeping only: :meth:`load_balance_error` reads the operator).
    throat_operator : scipy.sparse.csr_matrix, shape (3 Nn, Nt_loaded), or None
        With throat forces: column ``t`` is the nodal load of throat cylinder ``t`` per unit throat
        pressure (part of :attr:`operator`, which adds it with the mean pressure of the throat's
        two pores); kept apart so the load balance can be checked source by source.
    throat_pores : ndarray of int, shape (Nt_loaded, 2), or None
        The two pores of each column of :attr:`throat_operator`.
    throat_area : ndarray, shape (Nt_loaded,), or None
        Lateral area ``2 pi r L`` of each throat cylinder, m².
    """

    method: ClassVar[str] = "hull"
    operator: sp.csr_matrix
    wall_area: np.ndarray
    pore_nodes: tuple
    n_unloaded: int
    seconds: float
    handed_area: np.ndarray | None = None
    throat_operator: sp.csr_matrix | None = None
    throat_pores: np.ndarray | None = None
    throat_area: np.ndarray | None = None

    def __post_init__(self):
        if self.handed_area is None:
            object.__setattr__(self, "handed_area", np.asarray(self.wall_area, float).copy())

    def load_balance_error(self, pressure) -> float:
        r"""Relative mismatch between the load handed over and the load the pores carry (the paper's check).

        Every source (pore sphere, and throat cylinder with throat forces) must hand its nodes
        force magnitudes adding up to its pressure times its wall area. The magnitudes are read
        from the operator itself: with :math:`m_i = \sum_k |T_{k,i}|` the force magnitude of pore
        column ``i`` at node ``k`` (per unit pressure; the sphere part :math:`T - \Theta C` when
        throat forces are on, :math:`\Theta` = :attr:`throat_operator`, ``C`` its half-and-half
        pore weights),

        .. math:: e = \frac{\sum_i |P_i|\,|m_i - 4\pi r_i^2| + \sum_t |\bar P_t|\,|m_t - 2\pi r_t L_t|}
                            {\sum_i |P_i|\,4\pi r_i^2 + \sum_t |\bar P_t|\,2\pi r_t L_t} .

        It is round-off when every source reaches a node, and the fraction of the load lost
        otherwise (:attr:`n_unloaded`); a wrongly scaled or permuted operator shows up in it.
        Zero pressures give 0.
        """
        p = self._pressure(pressure)
        sphere = self.wall_area.copy()
        T = self.operator
        dev = ref = 0.0
        if self.throat_operator is not None and self.throat_operator.shape[1]:
            conns = np.asarray(self.throat_pores, np.int64)
            area_t = np.asarray(self.throat_area, float)
            C = throat_mean(conns, self.n_pores)
            T = T - self.throat_operator @ C
            np.subtract.at(sphere, conns[:, 0], 0.5 * area_t)
            np.subtract.at(sphere, conns[:, 1], 0.5 * area_t)
            pt = np.abs(C @ p)
            dev += float(np.sum(pt * np.abs(column_magnitudes(self.throat_operator) - area_t)))
            ref += float(np.sum(pt * area_t))
        ap = np.abs(p)
        dev += float(np.sum(ap * np.abs(column_magnitudes(T) - sphere)))
        ref += float(np.sum(ap * sphere))
        return dev / ref if ref > 0 else 0.0


def throat_cylinders(net: Network):
    """(conns, radius, ends (Nt, 2, 3)) of the cylindrical part of every throat, m.

    The cylinder starts ``throat_pore_length[:, 0]`` from pore i's centre along the centre line
    and ends ``throat_pore_length[:, 1]`` before pore j's.
    """
    c = net.pore_coords
    i, j = net.throat_conns[:, 0], net.throat_conns[:, 1]
    d = c[j] - c[i]
    a = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)
    start = c[i] + a * net.throat_pore_length[:, [0]]
    end = c[j] - a * net.throat_pore_length[:, [1]]
    return net.throat_conns, net.throat_radius, np.stack([start, end], axis=1)


def sphere_test_points(n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` points uniformly distributed on the unit sphere, shape (n, 3).

    Normalised Gaussian vectors (Marsaglia 1972), which are exactly uniform on the sphere.
    """
    if int(n) < 4:
        raise InputError(f"need at least 4 test points per pore for a 3-D hull, got {n}")
    x = rng.standard_normal((int(n), 3))
    return x / np.linalg.norm(x, axis=1, keepdims=True)


def _pore_rank(coords: np.ndarray) -> np.ndarray:
    """Rank of each pore in lexicographic (x, y, z) order of its centre (renumbering-invariant)."""
    order = np.lexsort((coords[:, 2], coords[:, 1], coords[:, 0]))
    rank = np.empty(len(order), np.int64)
    rank[order] = np.arange(len(order))
    return rank


def _hull_planes(centres, test_points, test_ptr, eps):
    """Hull planes of each source, CSR by source, and the reach of its enlarged hull.

    Planes are outward (``n.x + d <= 0`` inside); the reach is the radius of a ball about each
    centre that holds the hull enlarged by ``eps``.
    """
    n_p = centres.shape[0]
    planes, plane_ptr = [], [0]
    reach = np.empty(n_p)
    for i in range(n_p):
        pts = test_points[test_ptr[i]:test_ptr[i + 1]]
        eq = ConvexHull(pts).equations  # outward unit normals: n.x + d <= 0 inside
        planes.append(eq)
        plane_ptr.append(plane_ptr[-1] + len(eq))
        # The enlarged hull {n.x + d <= eps} lies inside the hull scaled about c by (1 + eps/h_min),
        # h_min the smallest facet distance from the centre, hence inside this ball:
        h_min = float(np.min(-(eq[:, :3] @ centres[i] + eq[:, 3])))
        rad = float(np.max(np.linalg.norm(pts - centres[i], axis=1)))
        reach[i] = rad * (1.0 + eps[i] / h_min) if h_min > 0 else np.inf
    planes = np.ascontiguousarray(np.vstack(planes)) if planes else np.zeros((0, 4))
    return planes, np.asarray(plane_ptr, np.int64), reach


def hull_members(points, centres, radii, test_points, test_ptr, tolerance):
    """FE nodes inside each pore's hull enlarged by ``tolerance``.

    Parameters
    ----------
    points : ndarray, shape (Nn, 3)
        Candidate FE node coordinates, m.
    centres, radii : ndarray, shapes (Np, 3), (Np,)
        Pore centres and radii, m.
    test_points : ndarray, shape (sum N_i, 3)
        Test points of all pores, pore by pore, m.
    test_ptr : ndarray of int, shape (Np + 1,)
        Pore i owns ``test_points[test_ptr[i]:test_ptr[i+1]]``.
    tolerance : ndarray, shape (Np,)
        ε_i, m: a node is inside when ``n . x + d <= ε_i`` for every outward unit facet plane.

    Returns
    -------
    member_ptr : ndarray of int, shape (Np + 1,)
    member_nodes : ndarray of int
        Pore i's member nodes are ``member_nodes[member_ptr[i]:member_ptr[i+1]]`` (ascending).
    """
    points = np.ascontiguousarray(points, dtype=float)
    centres = np.ascontiguousarray(centres, dtype=float)
    n_p = centres.shape[0]
    eps = np.ascontiguousarray(tolerance, dtype=float)
    planes, plane_ptr, reach = _hull_planes(centres, test_points, test_ptr, eps)
    if points.shape[0] == 0 or n_p == 0:
        return np.zeros(n_p + 1, np.int64), np.zeros(0, np.int64)
    lo = points.min(axis=0) - 1e-12
    span = points.max(axis=0) - lo
    finite = reach[np.isfinite(reach)]
    reach = np.where(np.isfinite(reach), reach, float(np.linalg.norm(span)) + 1.0)
    cell = max(float(np.median(finite)) if finite.size else 0.0, float(span.max()) / 256.0, 1e-300)
    dims = np.maximum(np.ceil(span / cell).astype(np.int64), 1)
    order, start = _kernels._bin_points(points, lo, cell, dims)
    empty = np.zeros(0, np.int64)
    args = ((points, order, start, lo, cell, dims), (centres, reach, planes, plane_ptr, eps))
    n = _kernels._hull_members(*args, empty, empty)
    pore = np.empty(n, np.int64)
    node = np.empty(n, np.int64)
    _kernels._hull_members(*args, pore, node)
    srt = np.lexsort((node, pore))
    pore, node = pore[srt], node[srt]
    member_ptr = np.searchsorted(pore, np.arange(n_p + 1))
    return member_ptr.astype(np.int64), node


@dataclasses.dataclass(frozen=True)
class _Sources:
    """Load sources sampled by test points: pore spheres (``axis`` None) or throat cylinders.

    Source ``s`` owns test points ``test_ptr[s]:test_ptr[s+1]`` (``n`` per source), pushes along
    the normal from ``origin[s]`` (or from its axis through ``origin[s]`` along unit ``axis[s]``)
    to the node, and carries ``area[s]`` (m²) into operator column ``s``.
    """

    test_points: np.ndarray
    test_ptr: np.ndarray
    origin: np.ndarray
    axis: np.ndarray | None
    area: np.ndarray
    n: int

    @property
    def count(self) -> int:
        return len(self.test_ptr) - 1


def _loads(x: np.ndarray, cand: np.ndarray, src: _Sources, centres, reach_radius, eps):
    """Operator (3 Nn, n_sources) of ``src`` on candidate nodes ``cand``, and per source its nodes.

    Also returns, per source, whether it reached a node and the area it handed over. Each source's
    test-point areas go to their nearest member nodes of the source's enlarged hull.
    """
    mptr, mloc = hull_members(x[cand], centres, reach_radius, src.test_points, src.test_ptr, eps)
    members = cand[mloc]
    near = _kernels._nearest_member(src.test_points, src.test_ptr, mptr, members, x)
    rows, cols, vals = [], [], []
    handed = np.zeros(src.count)
    loaded = np.zeros(src.count, bool)
    for s in range(src.count):
        hits = near[src.test_ptr[s]:src.test_ptr[s + 1]]
        hits = hits[hits >= 0]
        if hits.size == 0:
            continue
        loaded[s] = True
        m, cnt = np.unique(hits, return_counts=True)
        nodes = members[m]
        d = x[nodes] - src.origin[s]
        if src.axis is not None:
            d = d - np.outer(d @ src.axis[s], src.axis[s])
        dn = np.linalg.norm(d, axis=1)
        unitd = np.where(dn[:, None] > 0, d / np.where(dn > 0, dn, 1.0)[:, None], 0.0)
        w = src.area[s] * cnt / src.n
        handed[s] += src.area[s]
        for k in range(3):
            rows.append(3 * nodes + k)
            cols.append(np.full(nodes.size, s))
            vals.append(w * unitd[:, k])
    nodes_of = [members[np.unique(near[src.test_ptr[s]:src.test_ptr[s + 1]][near[src.test_ptr[s]:src.test_ptr[s + 1]]
                                                                            >= 0])] for s in range(src.count)]
    T = assemble(rows, cols, vals, (3 * x.shape[0], src.count))
    return T, nodes_of, loaded, handed


def _throat_sources(throats, n: int, rng: np.random.Generator):
    """(conns, sources, centres, reach radii) of the throat cylinders of positive length, or None."""
    conns, rt, ends = (np.asarray(v) for v in throats)
    ends = np.asarray(ends, float).reshape(-1, 2, 3)
    rt = np.asarray(rt, float)
    axis = ends[:, 1] - ends[:, 0]
    length = np.linalg.norm(axis, axis=1)
    ok = length > 0
    conns, rt, ends, axis, length = conns[ok], rt[ok], ends[ok], axis[ok], length[ok]
    n_t = len(conns)
    if not n_t:
        return None
    ax_u = axis / length[:, None]
    # uniform on the lateral surface: uniform height, uniform angle
    h = rng.random((n_t, n))
    phi = 2 * np.pi * rng.random((n_t, n))
    e1 = np.cross(ax_u, np.where(np.abs(ax_u[:, [0]]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]]))
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(ax_u, e1)
    ring = np.cos(phi)[..., None] * e1[:, None] + np.sin(phi)[..., None] * e2[:, None]
    ttp = (ends[:, 0, None] + h[..., None] * axis[:, None] + rt[:, None, None] * ring).reshape(-1, 3)
    tptr = np.arange(n_t + 1, dtype=np.int64) * n
    src = _Sources(ttp, tptr, ends[:, 0], ax_u, 2 * np.pi * rt * length, n)
    return np.asarray(conns, np.int64), src, ends.mean(axis=1), np.maximum(rt, 0.5 * length)


def _check_inputs(c, r, x, tolerance, n_test_points) -> tuple[np.ndarray, int]:
    """Validated (ε per pore, test points per pore)."""
    if c.ndim != 2 or c.shape[1] != 3 or r.shape != (c.shape[0],):
        raise InputError(f"pore_coords must be (Np, 3) and pore_radius (Np,), got {c.shape}, {r.shape}")
    if x.ndim != 2 or x.shape[1] != 3:
        raise InputError(f"points must be (Nn, 3), got {x.shape}")
    if np.any(~np.isfinite(r)) or np.any(r <= 0):
        raise InputError("pore radii must be positive and finite")
    n_p = c.shape[0]
    eps = 0.5 * r if tolerance is None else np.broadcast_to(np.asarray(tolerance, float), (n_p,)).copy()
    if np.any(~np.isfinite(eps)) or np.any(eps < 0):
        raise InputError(f"tolerance (range of inclusivity) must be >= 0 m, got {tolerance!r}")
    n = int(n_test_points)
    if n < 4:
        raise InputError(f"need at least 4 test points per pore for a 3-D hull, got {n_test_points}")
    return eps, n


def hull_interface(
    pore_coords,
    pore_radius,
    points,
    *,
    n_test_points: int = 800,
    tolerance=None,
    rng: np.random.Generator | None = None,
    candidates=None,
    throats=None,
) -> HullInterface:
    """The paper's convex-hull interface (module docstring).

    Parameters
    ----------
    pore_coords, pore_radius : ndarray, shapes (Np, 3), (Np,)
        Pore centres and radii, m.
    points : ndarray, shape (Nn, 3)
        FE node coordinates, m.
    n_test_points : int, default 800
        Test points per pore (paper: 800 after a 100-1000 sensitivity study).
    tolerance : float or ndarray (Np,), optional
        ε_i, m. Default ``0.5 r_i``.
    rng : numpy.random.Generator, optional
        Source of the test points; sample k goes to the pore of rank k in (x, y, z) order of
        the centres, so the operator does not depend on pore numbering.
    candidates : ndarray of bool (Nn,), optional
        Nodes allowed to receive load (e.g. pore-wall surface nodes); default all.
    throats : tuple (conns (Nt, 2), radius (Nt,), ends (Nt, 2, 3)), optional
        Also load the throat walls (the paper neglects them, section 3.2): each throat cylinder
        from ``ends[t, 0]`` to ``ends[t, 1]`` carries the mean pressure of its two pores on its
        lateral area ``2 pi r L``, with test points uniform on that surface, its own enlarged hull
        (tolerance: the mean of its pores') and forces along the normal from the axis to the node;
        half of it is booked to each pore's column (:func:`throat_cylinders` makes the tuple).

    Returns
    -------
    HullInterface
    """
    t0 = time.perf_counter()
    c = np.ascontiguousarray(pore_coords, dtype=float)
    r = np.ascontiguousarray(pore_radius, dtype=float)
    x = np.ascontiguousarray(points, dtype=float)
    eps, n = _check_inputs(c, r, x, tolerance, n_test_points)
    n_p = c.shape[0]
    rng = np.random.default_rng() if rng is None else rng
    unit = sphere_test_points(n * n_p, rng).reshape(n_p, n, 3) if n_p else np.zeros((0, n, 3))
    unit = unit[_pore_rank(c)] if n_p else unit
    tp = (c[:, None, :] + r[:, None, None] * unit).reshape(-1, 3)
    cand = np.arange(x.shape[0]) if candidates is None else np.flatnonzero(np.asarray(candidates, bool))
    area = 4.0 * np.pi * r**2
    spheres = _Sources(tp, np.arange(n_p + 1, dtype=np.int64) * n, c, None, area, n)
    T, pore_nodes, loaded, handed = _loads(x, cand, spheres, c, r, eps)
    wall = area.copy()
    throat = _throat_sources(throats, n, rng) if throats is not None else None
    if throat is None:
        return HullInterface(T, wall, tuple(pore_nodes), int(np.sum(~loaded)), time.perf_counter() - t0, handed)
    conns, src, mid, reach = throat
    eps_t = 0.5 * (eps[conns[:, 0]] + eps[conns[:, 1]])
    throat_op, _, _, handed_t = _loads(x, cand, src, mid, reach, eps_t)
    # each throat is its own column of Theta (per unit throat pressure); the operator adds Theta C,
    # C giving each throat the mean pressure of its two pores
    for side in (0, 1):
        np.add.at(handed, conns[:, side], 0.5 * handed_t)
    for side in (0, 1):
        np.add.at(wall, conns[:, side], 0.5 * src.area)
    T = (T + throat_op @ throat_mean(conns, n_p)).tocsr()
    return HullInterface(T, wall, tuple(pore_nodes), int(np.sum(~loaded)), time.perf_counter() - t0, handed,
                         throat_operator=throat_op, throat_pores=conns, throat_area=src.area)
