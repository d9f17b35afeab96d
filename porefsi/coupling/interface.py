"""Fluid-to-solid load transfer: pore pressures -> FE nodal forces.

Two operators, both linear in the pore pressures and stored as one sparse matrix ``T`` with
``F.ravel() = T @ P`` (``F`` nodal forces (Nn, 3) N, ``P`` pore pressures (Np,) Pa):

``hull``
    The seed paper's method (section 2.3.1): N test points on each pore sphere, their convex hull
    (Qhull) enlarged by a tolerance ε, the FE nodes inside it labelled 1, and the pore force
    ``F_i = ∫ P_i n ds`` handed to those nodes along ``n`` (pore centre -> node).
``traction``
    The consistent alternative: each pore's pressure acts as a traction ``-P n`` on the FE
    boundary facets that bound that pore's voxel region (P1 facet quadrature). Over a closed
    cavity it has zero resultant to round-off. Built by :mod:`porefsi.coupling.traction`
    (re-exported here).
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import scipy.sparse as sp
from scipy.spatial import ConvexHull

from porefsi.coupling import _kernels
from porefsi.errors import InputError

__all__ = [
    "Interface",
    "hull_interface",
    "traction_interface",
    "sphere_test_points",
    "hull_members",
    "boundary_facet_normals",
    "facet_pores_from_labels",
]


@dataclasses.dataclass(frozen=True, eq=False)
class Interface:
    """A linear map from pore pressures to nodal forces.

    Attributes
    ----------
    operator : scipy.sparse.csr_matrix, shape (3 Nn, Np)
        ``nodal_forces(P).ravel() == operator @ P``; units m² (force per unit pressure). ``Nn``
        is the number of mesh vertices, or of P2 Lagrange nodes (vertices, then edge midpoints)
        for a P2-consistent traction operator.
    method : str
        ``"hull"`` or ``"traction"``.
    wall_area : ndarray, shape (Np,)
        Area (m²) each pore's pressure acts on: ``4 pi r²`` for ``hull``, the summed facet areas
        of the pore's wall for ``traction``.
    pore_nodes : tuple of ndarray
        For each pore, the FE nodes that receive its load.
    n_unloaded : int
        Pores with nonzero area whose load reaches no node (their force is lost; see
        :meth:`load_balance_error`).
    seconds : float
        Build time, s.
    handed_area : ndarray, shape (Np,)
        ``hull``: per pore, the area booked while the operator was assembled, m² (equal to
        ``wall_area`` for every loaded pore; bookkeeping only: :meth:`load_balance_error` reads
        the operator instead); ``traction``: the facet area.
    wall_vector : ndarray, shape (Np, 3) or None
        ``traction``: per pore, the resultant of the wall traction per unit pressure,
        ``-sum_e A_e n_e`` over its wall facets, m² (zero for a closed cavity; a pore open to a
        throat or a box face pushes the solid away from the opening); computed from the facets,
        independently of the operator.
    throat_operator : scipy.sparse.csr_matrix, shape (3 Nn, Nt_loaded), or None
        ``hull`` with throat forces: column ``t`` is the nodal load of throat cylinder ``t`` per
        unit throat pressure (part of :attr:`operator`, which adds it with the mean pressure of
        the throat's two pores); kept apart so the load balance can be checked source by source.
    throat_pores : ndarray of int, shape (Nt_loaded, 2), or None
        The two pores of each column of :attr:`throat_operator`.
    throat_area : ndarray, shape (Nt_loaded,), or None
        Lateral area ``2 pi r L`` of each throat cylinder, m².
    vertex_operator : scipy.sparse.csr_matrix, shape (3 Nv, Np), or None
        For an operator on P2 Lagrange nodes: the P1 split of the same load on the mesh
        vertices (same resultant per pore), for outputs drawn on the vertices
        (:meth:`vertex_forces`); None when :attr:`operator` already acts on the vertices.
    """

    operator: sp.csr_matrix
    method: str
    wall_area: np.ndarray
    pore_nodes: tuple
    n_unloaded: int
    seconds: float
    handed_area: np.ndarray | None = None
    wall_vector: np.ndarray | None = None
    throat_operator: sp.csr_matrix | None = None
    throat_pores: np.ndarray | None = None
    throat_area: np.ndarray | None = None
    vertex_operator: sp.csr_matrix | None = None

    def __post_init__(self):
        if self.handed_area is None:
            object.__setattr__(self, "handed_area", np.asarray(self.wall_area, float).copy())

    @property
    def n_nodes(self) -> int:
        """Number of FE nodes Nn."""
        return self.operator.shape[0] // 3

    @property
    def n_pores(self) -> int:
        """Number of pores Np."""
        return self.operator.shape[1]

    def nodal_forces(self, pressure) -> np.ndarray:
        """Nodal forces (Nn, 3), N, for pore pressures ``pressure`` (Np,), Pa."""
        p = np.asarray(pressure, dtype=float)
        if p.shape != (self.n_pores,):
            raise InputError(f"pressure must have shape ({self.n_pores},), got {p.shape}")
        return (self.operator @ p).reshape(-1, 3)

    def vertex_forces(self, pressure) -> np.ndarray:
        """Nodal forces on the mesh vertices (Nv, 3), N, for outputs.

        :meth:`nodal_forces`, or for a P2 operator the P1 split of the same load
        (:attr:`vertex_operator`).
        """
        if self.vertex_operator is None:
            return self.nodal_forces(pressure)
        p = np.asarray(pressure, dtype=float)
        if p.shape != (self.n_pores,):
            raise InputError(f"pressure must have shape ({self.n_pores},), got {p.shape}")
        return (self.vertex_operator @ p).reshape(-1, 3)

    def load_balance_error(self, pressure) -> float:
        r"""Relative mismatch between the load handed over and the load the pores carry.

        ``hull`` (the paper's check): every source (pore sphere, and throat cylinder with
        throat forces) must hand its nodes force magnitudes adding up to its pressure times its
        wall area. The magnitudes are read from the operator itself: with
        :math:`m_i = \sum_k |T_{k,i}|` the force magnitude of pore column ``i`` at node ``k``
        (per unit pressure; the sphere part :math:`T - \Theta C` when throat forces are on,
        :math:`\Theta` = :attr:`throat_operator`, ``C`` its half-and-half pore weights),

        .. math:: e = \frac{\sum_i |P_i|\,|m_i - 4\pi r_i^2| + \sum_t |\bar P_t|\,|m_t - 2\pi r_t L_t|}
                            {\sum_i |P_i|\,4\pi r_i^2 + \sum_t |\bar P_t|\,2\pi r_t L_t} .

        It is round-off when every source reaches a node, and the fraction of the load lost
        otherwise (:attr:`n_unloaded`); a wrongly scaled or permuted operator shows up in it.
        ``traction``: ``sum_i |P_i| |R_i - w_i| / sum_i |P_i| A_i``, with ``R_i`` the resultant of
        the nodal forces the operator assigns to pore ``i`` per unit pressure and ``w_i`` the
        exact wall-traction resultant (:attr:`wall_vector`); without ``wall_vector`` the resultant
        of the whole load (a closed-cavity check). Zero pressures give 0.
        """
        p = np.asarray(pressure, dtype=float)
        f = self.nodal_forces(p)
        if self.method == "hull":
            return self._hull_balance(p)
        ref = float(np.sum(np.abs(p) * self.wall_area))
        if ref == 0.0:
            return 0.0
        if self.wall_vector is None:
            return float(np.linalg.norm(f.sum(axis=0))) / ref
        op = self.operator.tocsc()
        res = np.stack([np.asarray(op[k::3].sum(axis=0)).ravel() for k in range(3)], axis=1)  # (Np, 3)
        return float(np.sum(np.abs(p) * np.linalg.norm(res - self.wall_vector, axis=1))) / ref

    def _hull_balance(self, p: np.ndarray) -> float:
        sphere = self.wall_area.copy()
        T = self.operator
        dev = ref = 0.0
        if self.throat_operator is not None and self.throat_operator.shape[1]:
            conns = np.asarray(self.throat_pores, np.int64)
            area_t = np.asarray(self.throat_area, float)
            C = _throat_mean(conns, self.n_pores)
            T = T - self.throat_operator @ C
            np.subtract.at(sphere, conns[:, 0], 0.5 * area_t)
            np.subtract.at(sphere, conns[:, 1], 0.5 * area_t)
            pt = np.abs(C @ p)
            dev += float(np.sum(pt * np.abs(_column_magnitudes(self.throat_operator) - area_t)))
            ref += float(np.sum(pt * area_t))
        ap = np.abs(p)
        dev += float(np.sum(ap * np.abs(_column_magnitudes(T) - sphere)))
        ref += float(np.sum(ap * sphere))
        return dev / ref if ref > 0 else 0.0


def _throat_mean(conns: np.ndarray, n_pores: int) -> sp.csr_matrix:
    """``C`` (Nt, Np): row ``t`` takes the mean pressure of throat ``t``'s two pores."""
    n_t = len(conns)
    return sp.csr_matrix((np.full(2 * n_t, 0.5), (np.repeat(np.arange(n_t), 2), np.asarray(conns).ravel())),
                         shape=(n_t, n_pores))


def _column_magnitudes(T: sp.spmatrix) -> np.ndarray:
    """``sum_k |(T[3k], T[3k+1], T[3k+2])|`` of every column of a (3 Nn, m) nodal-force operator."""
    sq = sp.csr_matrix(T).multiply(T).tocsr()
    n_nodes = T.shape[0] // 3
    group = sp.csr_matrix((np.ones(3 * n_nodes), (np.repeat(np.arange(n_nodes), 3), np.arange(3 * n_nodes))),
                          shape=(n_nodes, 3 * n_nodes))
    per_node = (group @ sq).tocsr()
    per_node.data = np.sqrt(per_node.data)
    return np.asarray(per_node.sum(axis=0)).ravel()


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
    plane_ptr = np.asarray(plane_ptr, np.int64)
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
    args = (points, order, start, lo, cell, dims, centres, reach, planes, plane_ptr, eps)
    n = _kernels._hull_members(*args, empty, empty)
    pore = np.empty(n, np.int64)
    node = np.empty(n, np.int64)
    _kernels._hull_members(*args, pore, node)
    srt = np.lexsort((node, pore))
    pore, node = pore[srt], node[srt]
    member_ptr = np.searchsorted(pore, np.arange(n_p + 1))
    return member_ptr.astype(np.int64), node


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
) -> Interface:
    """The paper's convex-hull interface (section 2.3.1, eqs. 2.25-2.26, 3.2).

    Each pore i gets ``n_test_points`` points uniform on its sphere (centre ``c_i``, radius
    ``r_i``); Qhull builds their convex hull, which is enlarged by ``ε_i`` (the range of
    inclusivity, eq. 3.2); candidate FE nodes inside are the pore's members. The pore force
    ``F_i = ∫ P_i n ds`` is integrated with the test points as quadrature points (each carries area
    ``4 pi r_i² / N``) and each test point's share is lumped onto its nearest member node along
    ``n = (x_k - c_i)/|x_k - c_i|``, so per pore ``sum_k |f_k| = P_i 4 pi r_i²`` exactly.

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
        half of it is booked to each pore's column.

    Returns
    -------
    Interface
    """
    t0 = time.perf_counter()
    c = np.ascontiguousarray(pore_coords, dtype=float)
    r = np.ascontiguousarray(pore_radius, dtype=float)
    x = np.ascontiguousarray(points, dtype=float)
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
    rng = np.random.default_rng() if rng is None else rng
    n = int(n_test_points)
    if n < 4:
        raise InputError(f"need at least 4 test points per pore for a 3-D hull, got {n_test_points}")
    unit = sphere_test_points(n * n_p, rng).reshape(n_p, n, 3) if n_p else np.zeros((0, n, 3))
    unit = unit[_pore_rank(c)] if n_p else unit
    tp = (c[:, None, :] + r[:, None, None] * unit).reshape(-1, 3)
    tptr = np.arange(n_p + 1, dtype=np.int64) * n
    cand = np.arange(x.shape[0]) if candidates is None else np.flatnonzero(np.asarray(candidates, bool))
    mptr, mloc = hull_members(x[cand], c, r, tp, tptr, eps)
    members = cand[mloc]
    near = _kernels._nearest_member(tp, tptr, mptr, members, x)
    area = 4.0 * np.pi * r**2
    rows, cols, vals = [], [], []
    handed = np.zeros(n_p)
    loaded = _lump(x, members, near, tptr, c, None, area, n, (np.arange(n_p)[:, None], np.ones((n_p, 1))),
                   rows, cols, vals, handed)
    pore_nodes = [members[np.unique(near[tptr[i]:tptr[i + 1]][near[tptr[i]:tptr[i + 1]] >= 0])]
                  for i in range(n_p)]
    n_unloaded = int(np.sum(~loaded))
    wall = area.copy()
    throat_op = throat_area = None
    if throats is not None:
        conns, rt, ends = (np.asarray(v) for v in throats)
        ends = np.asarray(ends, float).reshape(-1, 2, 3)
        rt = np.asarray(rt, float)
        axis = ends[:, 1] - ends[:, 0]
        length = np.linalg.norm(axis, axis=1)
        ok = length > 0
        conns, rt, ends, axis, length = conns[ok], rt[ok], ends[ok], axis[ok], length[ok]
        n_t = len(conns)
        if n_t:
            ax_u = axis / length[:, None]
            # uniform on the lateral surface: uniform height, uniform angle
            h = rng.random((n_t, n))
            phi = 2 * np.pi * rng.random((n_t, n))
            e1 = np.cross(ax_u, np.where(np.abs(ax_u[:, [0]]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]]))
            e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
            e2 = np.cross(ax_u, e1)
            ring = np.cos(phi)[..., None] * e1[:, None] + np.sin(phi)[..., None] * e2[:, None]
            ttp = (ends[:, 0, None] + h[..., None] * axis[:, None] + rt[:, None, None] * ring).reshape(-1, 3)
            tptr_t = np.arange(n_t + 1, dtype=np.int64) * n
            mid = ends.mean(axis=1)
            eps_t = 0.5 * (eps[conns[:, 0]] + eps[conns[:, 1]])
            mp, ml = hull_members(x[cand], mid, np.maximum(rt, 0.5 * length), ttp, tptr_t, eps_t)
            mem_t = cand[ml]
            near_t = _kernels._nearest_member(ttp, tptr_t, mp, mem_t, x)
            area_t = 2 * np.pi * rt * length
            # each throat is its own column of Theta (per unit throat pressure); the operator adds
            # Theta C, C giving each throat the mean pressure of its two pores
            rows_t, cols_t, vals_t = [], [], []
            handed_t = np.zeros(n_t)
            own = (np.arange(n_t)[:, None], np.ones((n_t, 1)))
            _lump(x, mem_t, near_t, tptr_t, ends[:, 0], ax_u, area_t, n, own, rows_t, cols_t, vals_t, handed_t)
            throat_op = _assemble(rows_t, cols_t, vals_t, (3 * x.shape[0], n_t))
            conns = np.asarray(conns, np.int64)
            np.add.at(handed, conns[:, 0], 0.5 * handed_t)
            np.add.at(handed, conns[:, 1], 0.5 * handed_t)
            np.add.at(wall, conns[:, 0], 0.5 * area_t)
            np.add.at(wall, conns[:, 1], 0.5 * area_t)
    T = _assemble(rows, cols, vals, (3 * x.shape[0], n_p))
    if throat_op is not None:
        T = (T + throat_op @ _throat_mean(conns, n_p)).tocsr()
        throat_area = area_t
    return Interface(T, "hull", wall, tuple(pore_nodes), n_unloaded, time.perf_counter() - t0, handed,
                     throat_operator=throat_op, throat_pores=conns if throat_op is not None else None,
                     throat_area=throat_area)


def _lump(x, members, near, tptr, origin, axis, area, n, share, rows, cols, vals, handed) -> np.ndarray:
    """Hand each source's test-point areas to its nearest member nodes (appends COO triplets).

    Source s (a pore sphere when ``axis`` is None, else a throat cylinder with unit ``axis[s]``
    through ``origin[s]``) pushes along the normal from its centre (or axis) to the node; its
    load enters pore columns ``share[0][s]`` with weights ``share[1][s]``. Returns which sources
    reached a node.
    """
    loaded = np.zeros(len(tptr) - 1, bool)
    for s in range(len(tptr) - 1):
        hits = near[tptr[s]:tptr[s + 1]]
        hits = hits[hits >= 0]
        if hits.size == 0:
            continue
        loaded[s] = True
        m, cnt = np.unique(hits, return_counts=True)
        nodes = members[m]
        d = x[nodes] - origin[s]
        if axis is not None:
            d = d - np.outer(d @ axis[s], axis[s])
        dn = np.linalg.norm(d, axis=1)
        unitd = np.where(dn[:, None] > 0, d / np.where(dn > 0, dn, 1.0)[:, None], 0.0)
        w = area[s] * cnt / n
        for i, wi in zip(share[0][s], share[1][s], strict=True):
            handed[i] += wi * area[s]
            for k in range(3):
                rows.append(3 * nodes + k)
                cols.append(np.full(nodes.size, i))
                vals.append(wi * w * unitd[:, k])
    return loaded


def _assemble(rows, cols, vals, shape) -> sp.csr_matrix:
    if rows:
        ij = (np.concatenate(rows), np.concatenate(cols))
        return sp.csr_matrix((np.concatenate(vals), ij), shape=shape)
    return sp.csr_matrix(shape)


# the traction operator lives in porefsi.coupling.traction (re-exported here)
from porefsi.coupling.traction import (  # noqa: E402
    boundary_facet_normals,
    facet_pores_from_labels,
    traction_interface,
)
