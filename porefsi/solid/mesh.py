"""Conforming tetrahedral meshes of the solid phase of a segmented image.

The solid voxels (after optional block coarsening) are split into five tetrahedra each, with
the split alternating with voxel parity so that the face diagonals of neighbouring voxels
coincide (a conforming mesh with no hanging edges). Only solid that is face-connected to the
supported boundaries is kept: floating grains would make the stiffness singular.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
from scipy import ndimage

from porefsi.errors import InputError, MeshError
from porefsi.image.voxel_image import VoxelImage, axis_index

__all__ = ["SolidMesh", "MeshResult", "mesh_solid", "mesh_size", "FACET_TAGS", "FACE_NAMES", "PORE_WALL", "tet_volumes",
           "SolidBlocks", "solid_blocks", "block_points", "image_box"]

#: Box faces in the order of their tag codes 0..5.
FACE_NAMES = ("xmin", "xmax", "ymin", "ymax", "zmin", "zmax")
#: Tag code of boundary facets that are not on the image box (the solid-pore interface).
PORE_WALL = 6
#: Relative slack when checking that a mesh's image box contains its points (coordinates are
#: computed as origin + index * spacing, so they carry a few ulps of rounding).
_BOX_RTOL = 1e-12
#: Facet tag codes: ``{"xmin": 0, "xmax": 1, ..., "zmax": 5, "pore_wall": 6}``.
FACET_TAGS = {**{name: code for code, name in enumerate(FACE_NAMES)}, "pore_wall": PORE_WALL}

# Local cube corners (a, b, c) in {0,1}^3; index = 4a + 2b + c.
_CORNERS = np.array([[a, b, c] for a in (0, 1) for b in (0, 1) for c in (0, 1)])
# Outward-oriented local faces of a positively oriented tetrahedron (v0, v1, v2, v3).
_TET_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])


def _five_tet_template(parity: int) -> np.ndarray:
    """The 5-tet split of the unit cube as corner indices (5, 4), positively oriented.

    For ``parity`` 0 the central tetrahedron joins the corners with odd coordinate sum, for
    parity 1 those with even sum; the corner tetrahedra cut off the remaining four corners.
    """
    odd = [i for i in range(8) if _CORNERS[i].sum() % 2 == 1]
    even = [i for i in range(8) if _CORNERS[i].sum() % 2 == 0]
    central, cut = (odd, even) if parity == 0 else (even, odd)
    tets = [central]
    for c in cut:
        nbrs = [j for j in range(8) if np.abs(_CORNERS[j] - _CORNERS[c]).sum() == 1]
        tets.append([c, *nbrs])
    tets = np.array(tets)
    x = _CORNERS[tets].astype(float)
    vol = np.einsum("ij,ij->i", np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), x[:, 3] - x[:, 0])
    flip = vol < 0
    tets[flip, 1], tets[flip, 2] = tets[flip, 2].copy(), tets[flip, 1].copy()
    return tets


_TEMPLATES = (_five_tet_template(0), _five_tet_template(1))


def tet_volumes(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Signed volumes of tetrahedra, m^3, shape (Ne,); positive for positive orientation."""
    x = points[tets]
    return np.einsum("ij,ij->i", np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), x[:, 3] - x[:, 0]) / 6.0


@dataclasses.dataclass(frozen=True, eq=False)
class SolidMesh:
    """A linear tetrahedral mesh of the solid, in metres, in the image frame.

    Parameters
    ----------
    points : ndarray of float, shape (Nn, 3)
        Node coordinates, m. For meshes from images, node of voxel grid corner (i, j, k) sits at
        ``origin + voxel_size * (i, j, k)`` (times the coarsening), so pore centres of a network
        extracted from the same image, at ``(i + 1/2) * voxel_size``, overlay exactly.
    tets : ndarray of int64, shape (Ne, 4)
        Node indices of each tetrahedron, positively oriented (positive signed volume).
    facets : ndarray of int64, shape (Nf, 3)
        Boundary triangles, ordered so that their normal points out of the solid.
    facet_tags : ndarray of int8, shape (Nf,)
        Codes from :data:`FACET_TAGS` (box faces 0..5, pore wall 6).
    box : ndarray of float, shape (2, 3), optional
        The image box ``[[xmin, ymin, zmin], [xmax, ymax, zmax]]``, m, that the box-face tags
        refer to (for :func:`mesh_solid`, ``origin`` to ``origin + shape * voxel_size``). It can
        be larger than the bounding box of the points: solid need not reach every face. Default:
        the bounding box of ``points``.

    Raises
    ------
    MeshError
        If any tetrahedron has non-positive volume (inverted or degenerate).
    InputError
        If ``box`` is not a (2, 3) box that contains every point.
    """

    points: np.ndarray
    tets: np.ndarray
    facets: np.ndarray
    facet_tags: np.ndarray
    box: np.ndarray | None = None

    def __post_init__(self):
        p = np.ascontiguousarray(self.points, dtype=float)
        t = np.ascontiguousarray(self.tets, dtype=np.int64)
        f = np.ascontiguousarray(self.facets, dtype=np.int64).reshape(-1, 3)
        g = np.ascontiguousarray(self.facet_tags, dtype=np.int8).reshape(-1)
        if p.ndim != 2 or p.shape[1] != 3 or not np.all(np.isfinite(p)):
            raise InputError(f"points must be finite (Nn, 3) in metres, got shape {p.shape}")
        if t.ndim != 2 or t.shape[1] != 4 or t.shape[0] == 0:
            raise InputError(f"tets must be (Ne, 4) node indices with Ne >= 1, got shape {t.shape}")
        if t.min() < 0 or t.max() >= len(p) or (f.size and (f.min() < 0 or f.max() >= len(p))):
            raise InputError(f"node index out of range [0, {len(p)}) in tets or facets")
        if len(g) != len(f):
            raise InputError(f"facet_tags has {len(g)} entries for {len(f)} facets")
        vol = tet_volumes(p, t)
        bad = int(np.count_nonzero(vol <= 0))
        if bad:
            raise MeshError(
                f"{bad} of {len(t)} tetrahedra are inverted or degenerate (volume <= 0, first at "
                f"element {int(np.argmax(vol <= 0))}); reorder their nodes or remesh"
            )
        lo, hi = p.min(axis=0), p.max(axis=0)
        if self.box is None:
            b = np.stack([lo, hi])
        else:
            b = np.array(self.box, dtype=float)
            # points are computed as origin + index * spacing: allow their rounding
            slack = _BOX_RTOL * max(float(np.abs(b).max(initial=0.0)), float(np.abs(p).max()))
            if (b.shape != (2, 3) or not np.all(np.isfinite(b)) or np.any(b[1] <= b[0])
                    or np.any(b[0] > lo + slack) or np.any(b[1] < hi - slack)):
                raise InputError(
                    f"box must be [[xmin, ymin, zmin], [xmax, ymax, zmax]] (m) containing every point "
                    f"(points span {lo.tolist()} to {hi.tolist()}), got {b.tolist()}"
                )
        for name, arr in (("points", p), ("tets", t), ("facets", f), ("facet_tags", g), ("box", b)):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @property
    def n_nodes(self) -> int:
        """Number of nodes Nn."""
        return len(self.points)

    @property
    def n_tets(self) -> int:
        """Number of tetrahedra Ne."""
        return len(self.tets)

    @property
    def volume(self) -> float:
        """Total volume, m^3."""
        return float(tet_volumes(self.points, self.tets).sum())

    @property
    def bounds(self) -> np.ndarray:
        """Bounding box of the points ``[[xmin, ymin, zmin], [xmax, ymax, zmax]]``, m, shape (2, 3).

        Not the image box (:attr:`box`) when solid does not reach every face of the image.
        """
        return np.stack([self.points.min(axis=0), self.points.max(axis=0)])

    def facets_tagged(self, tag: str | int) -> np.ndarray:
        """Boundary triangles with tag ``tag`` (name from :data:`FACET_TAGS` or code), shape (k, 3)."""
        code = FACET_TAGS[tag] if isinstance(tag, str) else int(tag)
        if isinstance(tag, str) and tag not in FACET_TAGS:
            raise InputError(f"unknown facet tag {tag!r}; use one of {sorted(FACET_TAGS)}")
        return self.facets[self.facet_tags == code]

    def nodes_tagged(self, tag: str | int) -> np.ndarray:
        """Sorted unique nodes of the facets tagged ``tag``, shape (k,)."""
        return np.unique(self.facets_tagged(tag))

    def to_skfem(self):
        """Return the :class:`skfem.MeshTet`; the single place where points become (3, Nn)."""
        from skfem import MeshTet

        return MeshTet(np.ascontiguousarray(self.points.T), np.ascontiguousarray(self.tets.T))

    def write_vtu(self, path: str | Path, point_data: dict | None = None, cell_data: dict | None = None):
        """Write the mesh (and (Nn, ...) point / (Ne, ...) cell arrays) to a ``.vtu`` file."""
        from porefsi.io.solid_vtk import write_solid_vtu

        return write_solid_vtu(path, self.points, self.tets, point_data=point_data, cell_data=cell_data)

    def __repr__(self) -> str:
        return f"SolidMesh(n_nodes={self.n_nodes}, n_tets={self.n_tets}, volume={self.volume:.4g} m^3)"


@dataclasses.dataclass(frozen=True, eq=False)
class MeshResult:
    """What :func:`mesh_solid` returns.

    Attributes
    ----------
    mesh : SolidMesh
    removed_solid_fraction : float
        Volume of solid (after coarsening) dropped as not connected to the supports, divided by
        the total solid volume after coarsening.
    coarsen : int
        Block size used.
    solid_fraction_coarse : float
        Solid volume fraction of the coarsened image (before removal).
    n_components_removed : int
        Number of face-connected solid components dropped.
    leaf_counts : dict or None
        Graded meshes (``porefsi.solid.graded``): number of leaf cubes of each edge length
        in voxels, ``{coarsen: n, 2 coarsen: n, ...}``; None for a uniform mesh.
    """

    mesh: SolidMesh
    removed_solid_fraction: float
    coarsen: int
    solid_fraction_coarse: float
    n_components_removed: int
    leaf_counts: dict | None = None


def _coarsen(solid: np.ndarray, c: int) -> tuple[np.ndarray, list[np.ndarray]]:
    """Block-coarsen a boolean solid array: solid fraction per block and the voxel-index grid lines per axis."""
    if c == 1:
        return solid.astype(np.float64), [np.arange(n + 1) for n in solid.shape]
    nb = [-(-n // c) for n in solid.shape]
    lines = [np.minimum(np.arange(m + 1) * c, n) for m, n in zip(nb, solid.shape, strict=True)]
    counts = solid
    for ax in range(3):  # block sums along each axis via reduceat (integer: no float copy of the image)
        counts = np.add.reduceat(counts, lines[ax][:-1], axis=ax, dtype=np.int64 if ax else np.int32)
    sizes = [np.diff(g) for g in lines]
    nvox = sizes[0][:, None, None] * sizes[1][None, :, None] * sizes[2][None, None, :]
    return counts / nvox, lines


def _boundary_facets(tets: np.ndarray, n_nodes: int) -> np.ndarray:
    """Faces of ``tets`` that belong to exactly one tet, outward oriented, shape (Nf, 3)."""
    faces = tets[:, _TET_FACES].reshape(-1, 3)
    s = np.sort(faces, axis=1)
    if n_nodes < 2**21:
        key = (s[:, 0] << 42) | (s[:, 1] << 21) | s[:, 2]
        _, idx, cnt = np.unique(key, return_index=True, return_counts=True)
    else:  # pragma: no cover - very large meshes
        _, idx, cnt = np.unique(s, axis=0, return_index=True, return_counts=True)
    if np.any(cnt > 2):
        raise MeshError("non-manifold mesh: a face is shared by more than two tetrahedra")
    return faces[np.sort(idx[cnt == 1])]


def mesh_voxels(solid: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Conforming 5-tet mesh of the True cells of a 3-D boolean array, in grid-index space.

    Parameters
    ----------
    solid : ndarray of bool, shape (nx, ny, nz)
        Cells to mesh. Cell (i, j, k) is the unit cube with corners (i..i+1, j..j+1, k..k+1).

    Returns
    -------
    ijk : ndarray of int64, shape (Nn, 3)
        Grid indices of the used corners (no duplicates).
    tets : ndarray of int64, shape (Ne, 4)
        Five positively oriented tetrahedra per cell, cell-major in C order of ``solid``.
    facets : ndarray of int64, shape (Nf, 3)
        Outward boundary triangles.
    tags : ndarray of int8, shape (Nf,)
        0..5 for facets on the box faces xmin..zmax of the array, 6 (:data:`PORE_WALL`) otherwise.

    Notes
    -----
    The split alternates with the parity of i + j + k, so every face diagonal joins the two
    corners of that face with odd i + j + k: neighbouring cells share their diagonal and the
    mesh is conforming. All dihedral angles are >= 54.7 degrees.
    """
    solid = np.asarray(solid, dtype=bool)
    cells = np.argwhere(solid).astype(np.int64)
    if len(cells) == 0:
        raise MeshError("no solid cells to mesh")
    parity = cells.sum(axis=1) % 2
    tmpl = np.stack(_TEMPLATES)[parity]  # (Nc, 5, 4) corner ids
    corner_ijk = cells[:, None, None, :] + _CORNERS[tmpl]  # (Nc, 5, 4, 3)
    n1 = np.asarray(solid.shape, dtype=np.int64) + 1
    gid = (corner_ijk[..., 0] * n1[1] + corner_ijk[..., 1]) * n1[2] + corner_ijk[..., 2]
    used, inv = np.unique(gid.reshape(-1), return_inverse=True)
    tets = inv.reshape(-1, 4).astype(np.int64)
    ijk = np.stack([used // (n1[1] * n1[2]), (used // n1[2]) % n1[1], used % n1[2]], axis=1)
    facets = _boundary_facets(tets, len(used))
    fijk = ijk[facets]  # (Nf, 3, 3)
    tags = np.full(len(facets), PORE_WALL, dtype=np.int8)
    for ax in range(3):
        coord = fijk[:, :, ax]
        tags[np.all(coord == 0, axis=1)] = 2 * ax
        tags[np.all(coord == solid.shape[ax], axis=1)] = 2 * ax + 1
    return ijk, tets, facets, tags


def _keep_components(solid: np.ndarray, keep: str, support_axis: int | None) -> tuple[np.ndarray, int]:
    """Keep face-connected solid components per ``keep``; return the mask and the count dropped."""
    labels, n = ndimage.label(solid)  # 6-connectivity: edge contacts are hinges, not supports
    if n == 0:
        raise MeshError("the image has no solid voxels; there is nothing to mesh")
    if keep == "largest":
        sizes = np.bincount(labels.ravel())[1:]
        keep_ids = np.array([int(np.argmax(sizes)) + 1])
    else:
        axes = range(3) if support_axis is None else [support_axis]
        ids = set()
        for ax in axes:
            for sl in (0, -1):
                face = np.take(labels, sl, axis=ax)
                ids.update(np.unique(face[face > 0]).tolist())
        keep_ids = np.array(sorted(ids), dtype=np.int64)
        if len(keep_ids) == 0:
            where = "any box face" if support_axis is None else f"the {'xyz'[support_axis]}min/max faces"
            raise MeshError(
                f"no solid touches {where}: every grain floats; choose another support_axis, "
                "a smaller coarsen or a lower threshold"
            )
    mask = np.isin(labels, keep_ids)
    return mask, int(n - len(keep_ids))


#: A coarsening must leave at least this many blocks across every axis of the image (or every voxel).
MIN_BLOCKS = 2
#: ... and keep at least this fraction of the image's pore volume fraction as pore blocks.
MIN_PORE_KEPT = 0.5


def _require_resolved(image: VoxelImage, fine: np.ndarray, solid: np.ndarray, cell_vol: np.ndarray, c: int) -> None:
    """Refuse a coarsening that leaves the solid unresolved: too few blocks across, or pores lost.

    A block of 1000 voxels on a 120-voxel image is one cell: 5 tetrahedra, no pores, a modulus
    above the grain's. Raises :class:`InputError` naming the coarsening that would do.
    """
    if c == 1:
        return
    shape = image.phases.shape
    few = [d for d in range(3) if solid.shape[d] < min(MIN_BLOCKS, shape[d])]
    phi = 1.0 - float(fine.mean())
    phi_c = 1.0 - float((cell_vol * solid).sum()) / float(cell_vol.sum())
    fix = "use a smaller coarsening (--coarsen N, or [solid] coarsen = N in a case file)"
    if few:
        raise InputError(f"coarsen = {c} leaves {solid.shape[few[0]]} block(s) across axis {'xyz'[few[0]]} of the "
                         f"{'x'.join(map(str, shape))}-voxel image (need >= {MIN_BLOCKS}): the solid would not be "
                         f"resolved; {fix}, at most {max(1, min(shape) // MIN_BLOCKS)}")
    if phi > 0 and phi_c < MIN_PORE_KEPT * phi:
        raise InputError(f"coarsen = {c} turns most pores into solid blocks: porosity {phi:.3g} of the image, "
                         f"{phi_c:.3g} of the coarsened one (need >= {MIN_PORE_KEPT:g} x): the mesh would miss "
                         f"the pores and be too stiff; {fix}, e.g. {max(1, c // 2)}")


def _check_mesh_args(image, coarsen, threshold, keep) -> None:
    """Raise :class:`InputError` naming a bad argument of :func:`mesh_solid` / ``mesh_graded``."""
    if not isinstance(image, VoxelImage):
        raise InputError(f"image must be a VoxelImage, got {type(image).__name__}")
    if isinstance(coarsen, bool) or not isinstance(coarsen, (int, np.integer)) or coarsen < 1:
        raise InputError(f"coarsen must be an integer >= 1, got {coarsen!r}")
    if not (0.0 < float(threshold) <= 1.0):
        raise InputError(f"threshold must be in (0, 1], got {threshold!r}; 0.5 is the usual choice")
    if keep not in ("supported", "largest"):
        raise InputError(f"keep must be 'supported' or 'largest', got {keep!r}")


@dataclasses.dataclass(frozen=True, eq=False)
class SolidBlocks:
    """The block grid a mesh is built on (what :func:`solid_blocks` returns).

    Attributes
    ----------
    mask : ndarray of bool, shape (bx, by, bz)
        Kept solid blocks (solid enough and connected to the supports).
    lines : list of 3 ndarray of int
        Voxel index of every block boundary per axis (``bx + 1`` entries along x, ...).
    total, kept : float
        Solid volume (in voxels) of the blocks before and after dropping floating components.
    fraction_coarse : float
        Solid volume fraction of the block grid before the removal.
    n_removed : int
        Face-connected solid components dropped.
    """

    mask: np.ndarray
    lines: list
    total: float
    kept: float
    fraction_coarse: float
    n_removed: int


def solid_blocks(image: VoxelImage, coarsen: int, threshold: float, keep: str, support_axis) -> SolidBlocks:
    """Block-coarsen the solid of ``image`` and keep the supported components (see :func:`mesh_solid`)."""
    _check_mesh_args(image, coarsen, threshold, keep)
    ax = None if support_axis is None else axis_index(support_axis)
    fine = image.phases == 0
    if not fine.any():
        raise MeshError("the image has no solid voxels (phase 0); there is nothing to mesh")
    fraction, lines = _coarsen(fine, int(coarsen))
    solid = fraction >= float(threshold)
    sizes = [np.diff(g).astype(float) for g in lines]
    cell_vol = sizes[0][:, None, None] * sizes[1][None, :, None] * sizes[2][None, None, :]
    total = float((cell_vol * solid).sum())
    if total == 0:
        shape = "x".join(str(n) for n in image.phases.shape)
        raise MeshError(
            f"no solid left after coarsening by {coarsen}: in the {shape}-voxel image (solid fraction "
            f"{float(fine.mean()):.3g}) no {coarsen}^3 block is at least {threshold:g} solid (the most solid "
            f"block is {float(fraction.max()):.3g}), so every block became pore; the image is too small or too "
            f"porous for this coarsening: use a smaller coarsen (--coarsen 1 meshes every voxel) or a lower "
            "threshold"
        )
    _require_resolved(image, fine, solid, cell_vol, int(coarsen))
    mask, n_removed = _keep_components(solid, keep, ax)
    kept = float((cell_vol * mask).sum())
    return SolidBlocks(mask, lines, total, kept, total / float(cell_vol.sum()), n_removed)


def mesh_solid(
    image: VoxelImage,
    *,
    coarsen: int = 1,
    threshold: float = 0.5,
    keep: str = "supported",
    support_axis: str | int | None = "z",
) -> MeshResult:
    """Mesh the solid voxels of ``image`` with a conforming 5-tet split.

    Parameters
    ----------
    image : VoxelImage
        Segmented image (1 = pore, 0 = solid).
    coarsen : int, default 1
        Block size c: c^3 voxel blocks become one cell (the last block along an axis may be
        thinner so the mesh spans the image box exactly). Elements scale like 5 (n / c)^3 (1 - phi).
    threshold : float, default 0.5
        A block is solid when its solid voxel fraction is >= ``threshold`` (0 < threshold <= 1).
    keep : {"supported", "largest"}
        ``"supported"`` keeps every face-connected solid component touching the min or max face
        along ``support_axis`` (where the load frame fixes and drives the sample); ``"largest"``
        keeps only the largest component.
    support_axis : {"x", "y", "z", 0, 1, 2} or None, default "z"
        The loading axis. None means any of the six box faces supports.

    Returns
    -------
    MeshResult
        The mesh and the removed solid volume fraction.

    Raises
    ------
    InputError
        Bad ``coarsen``, ``threshold`` or ``keep``; a coarsening that leaves fewer than
        :data:`MIN_BLOCKS` blocks across an axis, or keeps less than :data:`MIN_PORE_KEPT` of the
        image's porosity (pores lost).
    MeshError
        No solid, or no solid connected to the supports.
    """
    blocks = solid_blocks(image, coarsen, threshold, keep, support_axis)
    ijk, tets, facets, tags = mesh_voxels(blocks.mask)
    pts = block_points(image, blocks.lines, ijk)
    mesh = SolidMesh(points=pts, tets=tets, facets=facets, facet_tags=tags, box=image_box(image))
    return MeshResult(
        mesh=mesh,
        removed_solid_fraction=(blocks.total - blocks.kept) / blocks.total,
        coarsen=int(coarsen),
        solid_fraction_coarse=blocks.fraction_coarse,
        n_components_removed=blocks.n_removed,
    )


def block_points(image: VoxelImage, lines, ijk: np.ndarray) -> np.ndarray:
    """Coordinates (m), shape (Nn, 3), of block-grid corners ``ijk`` (Nn, 3) of ``image``'s block ``lines``."""
    return np.stack([lines[d][ijk[:, d]] for d in range(3)], axis=1) * image.voxel_size + image.origin


def image_box(image: VoxelImage) -> np.ndarray:
    """The image box ``[[xmin, ymin, zmin], [xmax, ymax, zmax]]``, m, shape (2, 3)."""
    return np.stack([image.origin, image.origin + np.asarray(image.phases.shape) * image.voxel_size])


def mesh_size(image: VoxelImage, *, coarsen: int = 1, threshold: float = 0.5) -> tuple[int, int]:
    """``(n_tets, n_nodes)`` of :func:`mesh_solid` of ``image``, counted on the block grid without meshing.

    Floating solid is counted too (:func:`mesh_solid` drops it), so these are upper bounds,
    reached when every solid block is supported. Costs one integer pass over the image.
    """
    c = max(1, int(coarsen))
    solid = image.phases == 0  # (threshold > 0: a voxel is a block of fraction 0 or 1)
    if c > 1:
        solid = _coarsen(solid, c)[0] >= float(threshold)
    pad = np.pad(solid, 1)
    corners = np.zeros(tuple(n + 1 for n in solid.shape), bool)  # a corner is used by any of its 8 blocks
    for a in (0, 1):
        for b in (0, 1):
            for c in (0, 1):
                corners |= pad[a:a + corners.shape[0], b:b + corners.shape[1], c:c + corners.shape[2]]
    return 5 * int(np.count_nonzero(solid)), int(np.count_nonzero(corners))
