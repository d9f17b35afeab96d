"""Boundary conditions of the solid: Dirichlet specs on box faces, loads on tagged facets.

Dirichlet values are affine in time, ``u_c(t) = value + rate * t`` (a constant strain rate on a
face is ``rate = -strain_rate * L``): the prescribed dofs have zero acceleration, so condensing
them out of a lumped or consistent mass system adds no inertial load.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence

import numpy as np

from porefsi.errors import InputError, MeshError
from porefsi.image.voxel_image import axis_index
from porefsi.solid.mesh import FACE_NAMES, FACET_TAGS, SolidMesh

__all__ = ["Fixed", "Roller", "Prescribed", "Affine", "Traction", "Constraints", "uniaxial_bcs", "face_dofs",
           "face_nodes", "midpoint_nodes", "check_load_path"]

#: Tolerance, relative to the mesh extent, for matching edge midpoints to P2 Lagrange nodes (both
#: are midpoints of the same two vertices, up to rounding).
_MIDPOINT_RTOL = 1e-9


def _face(face: str) -> str:
    if face not in FACE_NAMES:
        raise InputError(f"unknown face {face!r}; use one of {FACE_NAMES}")
    return face


@dataclasses.dataclass(frozen=True)
class Fixed:
    """All displacement components zero on box face ``face`` ('xmin', ..., 'zmax')."""

    face: str

    def items(self):  # noqa: D102
        return [(_face(self.face), c, 0.0, 0.0) for c in range(3)]


@dataclasses.dataclass(frozen=True)
class Roller:
    """Zero normal displacement on ``face``; tangential motion free (frictionless wall).

    Acts on the solid at that face of the image box; none there, no constraint.
    """

    face: str

    def items(self):  # noqa: D102
        return [(_face(self.face), FACE_NAMES.index(self.face) // 2, 0.0, 0.0)]


@dataclasses.dataclass(frozen=True)
class Prescribed:
    """Component ``component`` on ``face`` follows ``value + rate * t`` (m, m/s)."""

    face: str
    component: int | str
    value: float = 0.0
    rate: float = 0.0

    def items(self):  # noqa: D102
        return [(_face(self.face), axis_index(self.component), float(self.value), float(self.rate))]


@dataclasses.dataclass(frozen=True, eq=False)
class Affine:
    """Kinematic uniform condition on ``face``: ``u(X, t) = (G + G_rate t) X + c`` (all components).

    Used for patch tests and for homogenisation with kinematic uniform boundary conditions.
    ``G``, ``G_rate``: (3, 3) (dimensionless, 1/s); ``c``: (3,) m.
    """

    face: str
    G: np.ndarray
    c: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(3))
    G_rate: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((3, 3)))

    def resolve(self, mesh, dof_points):  # noqa: D102
        out = []
        G, c, Gr = (np.asarray(a, dtype=float) for a in (self.G, self.c, self.G_rate))
        for comp in range(3):
            dofs = face_dofs(mesh, dof_points, self.face, comp)
            X = dof_points[dofs // 3]
            out.append((self.face, comp, dofs, X @ G[comp] + c[comp], X @ Gr[comp]))
        return out


@dataclasses.dataclass(frozen=True)
class Traction:
    """Dead surface load on the facets tagged ``tag``: a traction vector (Pa) and/or a pressure.

    ``pressure`` p pushes on the solid (traction ``-p N``, N the outward reference normal).
    ``factor`` (``t -> float``, optional) scales the load in time (default: constant).
    """

    tag: str
    traction: tuple[float, float, float] | None = None
    pressure: float | None = None
    factor: Callable[[float], float] | None = None

    def __post_init__(self):
        if self.tag not in FACET_TAGS:
            raise InputError(f"unknown facet tag {self.tag!r}; use one of {sorted(FACET_TAGS)}")


def face_nodes(mesh: SolidMesh, dof_points: np.ndarray, face: str) -> np.ndarray:
    """Lagrange nodes on the boundary facets tagged ``face``: the solid on that face of the image box.

    Parameters
    ----------
    mesh : SolidMesh
        The mesh whose facet tags say which boundary triangles lie on the image box faces.
    dof_points : ndarray of float, shape (N, 3)
        Lagrange node positions, m: the mesh vertices first (``N == mesh.n_nodes`` for P1), then
        (P2) the edge midpoints.
    face : {"xmin", "xmax", "ymin", "ymax", "zmin", "zmax"}

    Returns
    -------
    ndarray of int64, shape (k,)
        Sorted node indices; empty when no solid reaches that face of the image box.

    Notes
    -----
    The faces are those of the image box (:attr:`SolidMesh.box`), identified by the facet tags,
    not the extreme coordinates of the mesh: if solid fills only the bottom of the image, the top
    face has no nodes (the mesh's highest points are pore wall, not the box face).
    """
    tri = mesh.facets_tagged(_face(face))
    nodes = np.unique(tri)
    if len(dof_points) <= mesh.n_nodes or len(tri) == 0:
        return nodes.astype(np.int64)
    # P2: the edge midpoints of the tagged triangles
    edges = np.unique(np.sort(tri[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), axis=1), axis=0)
    mids = midpoint_nodes(mesh, dof_points, edges[:, 0], edges[:, 1])
    return np.concatenate([nodes, np.unique(mids)]).astype(np.int64)


def midpoint_nodes(mesh: SolidMesh, dof_points: np.ndarray, a, b) -> np.ndarray:
    """P2 Lagrange node at the midpoint of each mesh edge ``(a[i], b[i])``, shape (k,).

    Parameters
    ----------
    mesh : SolidMesh
    dof_points : ndarray of float, shape (N, 3)
        Lagrange node positions, m: the mesh vertices, then the edge midpoints (P2).
    a, b : array_like of int, shape (k,)
        Vertex pairs (mesh edges).

    Raises
    ------
    MeshError
        If ``dof_points`` has no edge nodes (P1) or a pair's midpoint is not one of them.
    """
    from scipy.spatial import cKDTree

    extra = np.asarray(dof_points[mesh.n_nodes:], dtype=float)
    if len(extra) == 0:
        raise MeshError("edge midpoint nodes exist for P2 Lagrange nodes only; these are the mesh vertices")
    a, b = np.asarray(a, np.int64), np.asarray(b, np.int64)
    mid = 0.5 * (mesh.points[a] + mesh.points[b])
    dist, idx = cKDTree(extra).query(mid)
    tol = _MIDPOINT_RTOL * float(np.ptp(mesh.points, axis=0).max())
    if np.any(dist > tol):
        raise MeshError(f"{int(np.count_nonzero(dist > tol))} edge midpoints are not P2 nodes: dof_points do "
                        "not belong to this mesh")
    return mesh.n_nodes + idx.astype(np.int64)


def face_dofs(mesh: SolidMesh, dof_points: np.ndarray, face: str, component: int) -> np.ndarray:
    """Dofs (interleaved numbering ``3 node + component``) of the nodes of :func:`face_nodes`, shape (k,)."""
    return 3 * face_nodes(mesh, dof_points, face) + int(component)


def check_load_path(mesh: SolidMesh, axis: str | int) -> None:
    """Check that solid connects the min and max faces of the image box along ``axis``.

    A uniaxial test fixes one face and drives the opposite one; without solid on both faces, or
    without a connected piece of the mesh touching both, the sample carries no axial load.

    Parameters
    ----------
    mesh : SolidMesh
    axis : {"x", "y", "z", 0, 1, 2}

    Raises
    ------
    MeshError
        If no solid reaches one of the two faces, or no connected piece reaches both.
    """
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    ax = axis_index(axis)
    lo, hi = FACE_NAMES[2 * ax], FACE_NAMES[2 * ax + 1]
    name = "xyz"[ax]
    ends = {f: mesh.nodes_tagged(f) for f in (lo, hi)}
    for f, nodes in ends.items():
        if len(nodes) == 0:
            b = mesh.bounds[:, ax]
            raise MeshError(
                f"no solid reaches the {f} face of the image box: the solid spans {name} in "
                f"[{b[0]:.4g}, {b[1]:.4g}] m of the box [{mesh.box[0, ax]:.4g}, {mesh.box[1, ax]:.4g}] m, so a "
                f"load frame along {name} has nothing to hold or push there; load along another axis, or crop "
                "the image to the solid"
            )
    # nodes are connected when they share a tetrahedron (what the stiffness couples)
    t = mesh.tets
    rows = np.repeat(t[:, 0], 3)
    cols = t[:, 1:].ravel()
    graph = sp.coo_matrix((np.ones(len(rows), dtype=np.int8), (rows, cols)), shape=(mesh.n_nodes,) * 2)
    _, label = connected_components(graph, directed=False)
    if not np.intersect1d(label[ends[lo]], label[ends[hi]]).size:
        raise MeshError(
            f"no connected solid joins the {lo} and {hi} faces of the image box: the pieces on the fixed face "
            f"and those on the loaded face are separate, so the sample carries no load along {name}; load along "
            "another axis, or use an image (or a smaller coarsen) in which the solid spans the sample"
        )


@dataclasses.dataclass(frozen=True, eq=False)
class Constraints:
    """Compiled Dirichlet conditions: ``dofs (nd,)`` sorted, ``u(t) = value + rate t`` on them.

    Attributes
    ----------
    dofs, value, rate : ndarray, shape (nd,)
    free : ndarray of int64, shape (n,)
        The complementary free dofs.
    n_full : int
    """

    dofs: np.ndarray
    value: np.ndarray
    rate: np.ndarray
    free: np.ndarray
    n_full: int

    @classmethod
    def build(cls, mesh: SolidMesh, dof_points: np.ndarray, specs: Sequence) -> Constraints:
        """Compile ``specs`` (Fixed/Roller/Prescribed/Affine) on the Lagrange nodes ``dof_points`` (N, 3) of ``mesh``.

        A spec on a box face acts on the nodes of the facets tagged with that face
        (:func:`face_nodes`), i.e. on the solid at that face of the image box. A :class:`Roller`
        on a face that no solid reaches is dropped (a wall the solid does not touch exerts no
        force); any other condition there is an error, since it would support or drive nothing.

        Raises
        ------
        InputError
            If two specs prescribe different motions for the same dof.
        MeshError
            If a spec names a box face that no solid reaches.
        """
        n_full = 3 * len(dof_points)
        dofs_l, val_l, rate_l = [], [], []
        for spec in specs:
            if hasattr(spec, "resolve"):
                parts = spec.resolve(mesh, dof_points)
            else:
                parts = [(f, c, face_dofs(mesh, dof_points, f, c), v, r) for f, c, v, r in spec.items()]
            for face, _comp, dofs, val, rate in parts:
                if len(dofs) == 0 and isinstance(spec, Roller):
                    continue  # a frictionless wall that no solid touches holds nothing
                if len(dofs) == 0:
                    ax = FACE_NAMES.index(face) // 2
                    raise MeshError(
                        f"{type(spec).__name__} condition on face {face}, but no solid reaches the {face} face of "
                        f"the image box (no boundary facet tagged {face!r}; the solid spans {'xyz'[ax]} in "
                        f"[{mesh.bounds[0, ax]:.4g}, {mesh.bounds[1, ax]:.4g}] m of the box "
                        f"[{mesh.box[0, ax]:.4g}, {mesh.box[1, ax]:.4g}] m); support the sample on faces its "
                        "solid touches, or crop the image to the solid"
                    )
                dofs_l.append(dofs)
                val_l.append(np.broadcast_to(np.asarray(val, dtype=float), dofs.shape))
                rate_l.append(np.broadcast_to(np.asarray(rate, dtype=float), dofs.shape))
        if dofs_l:
            d = np.concatenate(dofs_l)
            v = np.concatenate(val_l)
            r = np.concatenate(rate_l)
        else:
            d, v, r = np.zeros(0, np.int64), np.zeros(0), np.zeros(0)
        dofs, first = np.unique(d, return_index=True)
        inv = np.searchsorted(dofs, d)
        scale = max(float(np.abs(v).max(initial=0)), float(np.abs(r).max(initial=0)), 1e-300)
        clash = (np.abs(v - v[first][inv]) > 1e-12 * scale) | (np.abs(r - r[first][inv]) > 1e-12 * scale)
        if np.any(clash):
            k = int(np.argmax(clash))
            raise InputError(
                f"conflicting Dirichlet conditions at dof {int(d[k])} (node {int(d[k]) // 3}, component "
                f"{int(d[k]) % 3}): value/rate {v[k]:g}/{r[k]:g} vs {v[first][inv][k]:g}/{r[first][inv][k]:g}; "
                "make the conditions agree on shared edges"
            )
        free = np.setdiff1d(np.arange(n_full, dtype=np.int64), dofs)
        return cls(dofs=dofs.astype(np.int64), value=v[first].copy(), rate=r[first].copy(), free=free,
                   n_full=n_full)

    def values(self, t: float) -> np.ndarray:
        """Prescribed displacements at time t, m, shape (nd,)."""
        return self.value + self.rate * float(t)


def uniaxial_bcs(axis: str | int = "z", *, displacement: float = 0.0, rate: float = 0.0,
                 lateral: str = "roller") -> list:
    """The paper's loading frame along ``axis``.

    The min face is fixed, the max face moves by ``displacement + rate * t`` along ``axis``
    (negative = compression) with its tangential components held (a bonded platen), and the four
    lateral faces are on rollers (``lateral='roller'``) or free (``lateral='free'``).
    """
    ax = axis_index(axis)
    lo, hi = FACE_NAMES[2 * ax], FACE_NAMES[2 * ax + 1]
    specs: list = [Fixed(lo), Prescribed(hi, ax, displacement, rate)]
    specs += [Prescribed(hi, c, 0.0, 0.0) for c in range(3) if c != ax]
    if lateral == "roller":
        specs += [Roller(FACE_NAMES[2 * a + s]) for a in range(3) if a != ax for s in (0, 1)]
    elif lateral != "free":
        raise InputError(f"lateral must be 'roller' or 'free', got {lateral!r}")
    return specs

