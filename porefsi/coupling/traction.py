"""Consistent traction transfer: each pore's pressure acts as ``-P n`` on its wall facets.

The alternative to the seed paper's convex hull (:mod:`porefsi.coupling.hull`): the FE
boundary facets that bound a pore's voxel region (found from the extraction's label image) carry
that pore's pressure as a surface traction, integrated exactly for P1. Over a closed cavity the
resultant is zero to round-off, and the work matches the Lamé cavity solution.
"""

from __future__ import annotations

import dataclasses
import time
from typing import ClassVar

import numpy as np
import scipy.sparse as sp

from porefsi.coupling._sparse import assemble, resultants
from porefsi.coupling.interface import LinearInterface
from porefsi.errors import InputError

__all__ = ["TractionInterface", "traction_interface", "boundary_facet_normals",
           "facet_pores_from_labels"]


@dataclasses.dataclass(frozen=True, eq=False)
class TractionInterface(LinearInterface):
    """The consistent wall-traction operator (an :class:`~porefsi.coupling.interface.Interface`).

    Attributes
    ----------
    operator : scipy.sparse.csr_matrix, shape (3 Nn, Np)
        ``nodal_forces(P).ravel() == operator @ P``; m². ``Nn`` is the number of mesh vertices,
        or of P2 Lagrange nodes (vertices, then edge midpoints) for a P2-consistent operator.
    wall_area : ndarray, shape (Np,)
        The summed facet areas of each pore's wall, m².
    pore_nodes : tuple of ndarray
        For each pore, the vertices of its wall facets.
    n_unloaded : int
        Always 0 (every facet loads its own nodes); kept for the common interface.
    seconds : float
        Build time, s.
    wall_vector : ndarray, shape (Np, 3)
        Per pore, the resultant of the wall traction per unit pressure, ``-sum_e A_e n_e`` over its
        wall facets, m² (zero for a closed cavity; a pore open to a throat or a box face pushes
        the solid away from the opening); computed from the facets, independently of the operator.
    vertex_operator : scipy.sparse.csr_matrix, shape (3 Nv, Np), or None
        For an operator on P2 Lagrange nodes: the P1 split of the same load on the mesh vertices
        (same resultant per pore), for outputs drawn on the vertices (:meth:`vertex_forces`);
        None when :attr:`operator` already acts on the vertices.
    """

    method: ClassVar[str] = "traction"
    operator: sp.csr_matrix
    wall_area: np.ndarray
    pore_nodes: tuple
    n_unloaded: int
    seconds: float
    wall_vector: np.ndarray | None = None
    vertex_operator: sp.csr_matrix | None = None

    @property
    def handed_area(self) -> np.ndarray:
        """The facet area of each pore, m² (as :attr:`wall_area`)."""
        return self.wall_area

    def load_balance_error(self, pressure) -> float:
        """``sum_i |P_i| |R_i - w_i| / sum_i |P_i| A_i``.

        ``R_i`` is the resultant of the nodal forces the operator assigns to pore ``i`` per unit
        pressure and ``w_i`` the exact wall-traction resultant (:attr:`wall_vector`); without
        ``wall_vector`` the resultant of the whole load (a closed-cavity check). Zero pressures give 0.
        """
        p = self._pressure(pressure)
        ref = float(np.sum(np.abs(p) * self.wall_area))
        if ref == 0.0:
            return 0.0
        if self.wall_vector is None:
            return float(np.linalg.norm(self.nodal_forces(p).sum(axis=0))) / ref
        res = resultants(self.operator)
        return float(np.sum(np.abs(p) * np.linalg.norm(res - self.wall_vector, axis=1))) / ref


def boundary_facet_normals(points, tets, facets):
    """Unit normals (Nf, 3) of boundary facets pointing out of the solid, and their areas (Nf,).

    The outward side is the one away from the fourth vertex of the tetrahedron owning the facet.

    Raises
    ------
    InputError
        If a facet is not a face of any tetrahedron.
    """
    x = np.asarray(points, float)
    tets = np.asarray(tets, np.int64)
    facets = np.asarray(facets, np.int64)
    faces = np.concatenate([tets[:, [1, 2, 3]], tets[:, [0, 2, 3]], tets[:, [0, 1, 3]], tets[:, [0, 1, 2]]])
    opposite = np.concatenate([tets[:, 0], tets[:, 1], tets[:, 2], tets[:, 3]])
    n = x.shape[0]

    def key(f):
        s = np.sort(f, axis=1)
        return (s[:, 0] * n + s[:, 1]) * n + s[:, 2]

    fk = key(faces)
    order = np.argsort(fk)
    fk = fk[order]
    q = key(facets)
    pos = np.searchsorted(fk, q)
    pos = np.minimum(pos, len(fk) - 1)
    if np.any(fk[pos] != q):
        raise InputError("a boundary facet is not a face of any tetrahedron; the mesh and facets disagree")
    opp = opposite[order[pos]]
    a, b, cpt = x[facets[:, 0]], x[facets[:, 1]], x[facets[:, 2]]
    nrm = np.cross(b - a, cpt - a)
    area = 0.5 * np.linalg.norm(nrm, axis=1)
    nrm = nrm / (2.0 * area[:, None])
    flip = np.einsum("ij,ij->i", nrm, x[opp] - a) > 0
    nrm[flip] *= -1.0
    return nrm, area


def facet_pores_from_labels(points, facets, normals, labels, voxel_size, origin=(0.0, 0.0, 0.0), max_steps=4):
    """Which pore each boundary facet faces, from the extraction's voxel labels.

    Walks from the facet centroid along its outward normal in half-voxel steps (up to
    ``max_steps`` voxels) and takes the first pore label met.

    Returns
    -------
    ndarray of int, shape (Nf,)
        Pore index, or -1 where no labelled pore voxel is met (e.g. box faces).
    """
    x = np.asarray(points, float)
    f = np.asarray(facets, np.int64)
    cen = x[f].mean(axis=1)
    lab = np.asarray(labels)
    shape = np.asarray(lab.shape)
    out = np.full(len(f), -1, np.int64)
    todo = np.ones(len(f), bool)
    for s in np.arange(1, 2 * max_steps + 1) * 0.5:
        p = cen[todo] + (s * voxel_size) * np.asarray(normals, float)[todo]
        ijk = np.floor((p - np.asarray(origin, float)) / voxel_size).astype(np.int64)
        ok = np.all((ijk >= 0) & (ijk < shape), axis=1)
        val = np.full(len(p), -1, np.int64)
        val[ok] = lab[ijk[ok, 0], ijk[ok, 1], ijk[ok, 2]]
        idx = np.flatnonzero(todo)
        hit = val >= 0
        out[idx[hit]] = val[hit]
        todo[idx[hit]] = False
        if not todo.any():
            break
    return out


def traction_interface(points, tets, facets, facet_pore, n_pores: int, *, p2_nodes=None) -> TractionInterface:
    """Consistent traction transfer: pore pressure acts as ``-P n`` on its wall facets.

    Each boundary facet ``e`` facing pore ``i = facet_pore[e]`` (>= 0) carries the force
    ``-P_i A_e n_e``, split over the facet's nodes as the exact integral of a constant traction
    against the basis: P1 (default), a third to each vertex; P2 (``p2_nodes`` given), a third to
    each edge-midpoint node and nothing to the vertices (a P2 vertex function integrates to zero
    over a flat triangle, so vertex forces would be point loads the P2 field resolves).

    Parameters
    ----------
    points : ndarray, shape (Nn, 3)
    tets : ndarray of int, shape (Ne, 4)
    facets : ndarray of int, shape (Nf, 3)
        Boundary facets that may carry pore pressure.
    facet_pore : ndarray of int, shape (Nf,)
        Pore each facet faces, -1 for none (see :func:`facet_pores_from_labels`).
    n_pores : int
    p2_nodes : tuple (callable, int), optional
        ``(midpoint_nodes, n_lagrange)`` of a P2 basis: ``midpoint_nodes(a, b)`` gives the
        Lagrange node of each edge (e.g. :func:`porefsi.solid.bc.midpoint_nodes`),
        ``n_lagrange`` the number of Lagrange nodes. The operator then acts on all Lagrange
        nodes, and :attr:`TractionInterface.vertex_operator` keeps the P1
        vertex split for outputs.

    Returns
    -------
    TractionInterface
    """
    t0 = time.perf_counter()
    fp = np.asarray(facet_pore, np.int64)
    f = np.asarray(facets, np.int64)
    if fp.shape != (f.shape[0],):
        raise InputError(f"facet_pore must have shape ({f.shape[0]},), got {fp.shape}")
    if fp.size and fp.max() >= n_pores:
        raise InputError(f"facet_pore refers to pore {int(fp.max())} but there are {n_pores} pores")
    use = fp >= 0
    nrm, area = boundary_facet_normals(points, tets, f[use])
    fu, pu = f[use], fp[use]
    n_nodes = np.asarray(points).shape[0]

    def split(node_sets, n_rows):
        rows, cols, vals = [], [], []
        for m in node_sets:
            for k in range(3):
                rows.append(3 * m + k)
                cols.append(pu)
                vals.append(-area * nrm[:, k] / 3.0)
        return assemble(rows, cols, vals, (3 * n_rows, n_pores))

    T1 = split([fu[:, a] for a in range(3)], n_nodes)
    if p2_nodes is None:
        T, vertex_T = T1, None
    else:
        midpoint_nodes, n_lagrange = p2_nodes
        pairs = ((0, 1), (1, 2), (2, 0))
        mids = np.asarray(midpoint_nodes(np.concatenate([fu[:, a] for a, _ in pairs]),
                                         np.concatenate([fu[:, b] for _, b in pairs])), np.int64)
        T, vertex_T = split(np.split(mids, 3), int(n_lagrange)), T1
    wall = np.bincount(pu, weights=area, minlength=n_pores)
    vec = np.stack([np.bincount(pu, weights=-area * nrm[:, k], minlength=n_pores) for k in range(3)], axis=1)
    order = np.argsort(pu, kind="stable")
    ptr = np.searchsorted(pu[order], np.arange(n_pores + 1))
    nodes = tuple(np.unique(fu[order[ptr[i]:ptr[i + 1]]]) for i in range(n_pores))
    return TractionInterface(T, wall, nodes, 0, time.perf_counter() - t0, wall_vector=vec, vertex_operator=vertex_T)
