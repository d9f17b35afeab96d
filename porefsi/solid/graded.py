"""Graded conforming tetrahedral meshes of the solid: fine blocks where the load is, coarse elsewhere.

The image is block-coarsened as by :func:`~porefsi.solid.mesh.mesh_solid` with the fine block
size ``coarsen``. Blocks holding a voxel of the ``refine`` mask (the loaded pores; by default
every pore voxel) stay fine; elsewhere blocks merge into the leaves of a 2:1-balanced octree: a
leaf of edge ``s`` blocks must lie more than ``grading * s`` blocks (centre to centre) from every
fine block, consist of full-size blocks only, and touch (by a face, an edge or a corner) no leaf
more than one level finer or coarser. A leaf is solid when its solid voxel fraction is
``>= threshold``: near ``refine`` the walls are exactly those of the uniform mesh of ``coarsen``.

Every leaf cube is split into tetrahedra that conform with its neighbours (no hanging nodes):

- a leaf with no node on its edges or faces other than its corners (every neighbour at least as
  coarse) takes the 5-tet split of :func:`~porefsi.solid.mesh.mesh_voxels`, with the diagonal of
  every face joining the two corners of odd index sum at the leaf's scale;
- a leaf with finer neighbours (nodes at some of its edge midpoints or face centres) gets a node
  at its centre and a tetrahedron from it to every triangle of its boundary; a face whose centre
  is a node (four finer leaves behind it) is split into its four quarters, each by the diagonal
  rule at the finer scale; a face with hanging edge midpoints but no centre node gets a node at
  its centre and a fan of triangles over its boundary polygon; any other face takes its diagonal.

Both leaves sharing a face see the same nodes on it and so triangulate it the same way; with the
2:1 balance over faces, edges and corners, a face of a leaf of edge ``s`` carries nodes only on
the grid of spacing ``s / 2``, so every node of the mesh is a corner of the fine block grid (the
graded mesh's nodes lie on the uniform mesh's node grid of the same ``coarsen``). The hanging
nodes are the corners of every leaf, pore or solid, so a face centre always comes with its four
edge midpoints whatever is solid behind the face. The dihedral angles of all templates lie in
[35.26, 125.26] degrees whatever the grading (the quality check is in
:func:`porefsi.solid.quality.tet_quality`).
"""

from __future__ import annotations

import functools

import numpy as np
from scipy import ndimage

from porefsi.errors import InputError, MeshError
from porefsi.image.voxel_image import VoxelImage, axis_index
from porefsi.solid.mesh import (
    _TEMPLATES,
    PORE_WALL,
    MeshResult,
    SolidMesh,
    _boundary_facets,
    _check_mesh_args,
    _coarsen,
    _keep_components,
    _require_resolved,
    block_points,
    image_box,
)

__all__ = ["mesh_graded", "leaf_levels", "balance_levels", "ligament_region", "mean_chord"]

# The 3x3x3 lattice of a leaf cube: local point (a, b, c) in {0, 1, 2}^3 has index 9a + 3b + c.
_CENTRE = 13
_LATTICE = np.array([[a, b, c] for a in range(3) for b in range(3) for c in range(3)])
#: Edge midpoints and face centres of the lattice (the points a finer neighbour can add), in bit order.
_HANGING = np.array([p for p in range(27) if p != _CENTRE and np.count_nonzero(_LATTICE[p] == 1) >= 1])


def mean_chord(mask: np.ndarray) -> float:
    """Mean length (voxels) of the runs of ``mask`` voxels along the three axes (0 for an empty mask)."""
    runs = 0
    for ax in range(3):
        m = np.moveaxis(mask, ax, 0).astype(np.int8)
        runs += int(np.count_nonzero(np.diff(m, axis=0, prepend=0) == 1))
    return 3.0 * float(np.count_nonzero(mask)) / runs if runs else 0.0


def ligament_region(pore: np.ndarray, refine: np.ndarray, factor: float) -> np.ndarray:
    """``refine`` plus the solid ligaments between it and the other pores thinner than ``factor`` loaded chords.

    A solid voxel ``v`` lies on a ligament of thickness about ``t(v) = d_R(v) + d_P(v)``, its
    distances (voxels) to the nearest ``refine`` voxel and to the nearest other pore voxel (equality
    on the segment joining the two nearest points). The ligament keeps the load's stress
    concentrated when it is thin against the loaded pore (a wall of thickness ``t`` between two
    holes of diameter ``D`` carries about ``D / t`` times the pressure): voxels with
    ``t(v) <= factor * D``, ``D`` the mean chord of ``refine`` (:func:`mean_chord`), join the
    region meshed at the fine block size.

    Parameters
    ----------
    pore, refine : ndarray of bool, shape (nx, ny, nz)
        Pore voxels; voxels to resolve finely (the loaded pores; only its pore voxels count).
    factor : float
        Ligament thickness limit in loaded chords (>= 0; 0 returns ``refine``).

    Returns
    -------
    ndarray of bool, shape (nx, ny, nz)
    """
    if not (isinstance(factor, (int, float, np.floating, np.integer)) and np.isfinite(factor) and factor >= 0):
        raise InputError(f"ligaments must be a finite number >= 0 (loaded chords), got {factor!r}; 0 turns it off")
    if refine.shape != pore.shape:
        raise InputError(f"refine {refine.shape} and pore {pore.shape} masks must have the same shape")
    refine = refine & pore
    if factor <= 0 or not refine.any():
        return refine.copy()
    reach = factor * mean_chord(refine)
    # A voxel v joins when d_R(v) + d_P(v) <= reach: v and its nearest other pore voxel p then lie
    # within ``reach`` of a refine voxel (|p - r| <= d_P + d_R), so both distances computed on the
    # box around ``refine`` grown by the reach are exact wherever they decide (a pore outside it can
    # only be farther than the reach allows), at a fraction of the image's cost when the load is local.
    box = _grown_box(refine, int(np.ceil(reach)) + 1)
    ref, other = refine[box], pore[box] & ~refine[box]
    out = refine.copy()
    if other.any():
        t = ndimage.distance_transform_edt(~ref) + ndimage.distance_transform_edt(~other)
        out[box] |= ~pore[box] & (t <= reach)
    return out


def _grown_box(mask: np.ndarray, margin: int) -> tuple[slice, ...]:
    """Slices of the bounding box of ``mask``'s True voxels grown by ``margin`` voxels (clipped to the array)."""
    idx = np.argwhere(mask)
    lo, hi = np.maximum(idx.min(axis=0) - margin, 0), np.minimum(idx.max(axis=0) + margin + 1, mask.shape)
    return tuple(slice(int(a), int(b)) for a, b in zip(lo, hi, strict=True))


def leaf_levels(refine: np.ndarray, full: np.ndarray, n_levels: int, grading: float) -> np.ndarray:
    """Octree level of the leaf holding each block, before balancing.

    Parameters
    ----------
    refine : ndarray of bool, shape (bx, by, bz)
        Blocks to keep fine (those holding loaded pore voxels).
    full : ndarray of bool, shape (bx, by, bz)
        Blocks of full size (not the thinner last block of an axis); only these merge.
    n_levels : int
        Highest level: leaves up to ``2**n_levels`` blocks across.
    grading : float
        A leaf of ``s`` blocks needs every block centre > ``grading * s`` blocks from the nearest
        ``refine`` block centre.

    Returns
    -------
    ndarray of int16, shape (bx, by, bz)
        Level L of the leaf (``2**L`` blocks across) containing each block.
    """
    lev = np.zeros(refine.shape, np.int16)
    dist = np.full(refine.shape, np.inf) if not refine.any() else ndimage.distance_transform_edt(~refine)
    for L in range(1, n_levels + 1):
        s = 2**L
        nc = [n // s for n in refine.shape]
        if min(nc) == 0:
            break
        crop = tuple(slice(0, m * s) for m in nc)
        shp = (nc[0], s, nc[1], s, nc[2], s)
        ok = full[crop].reshape(shp).all(axis=(1, 3, 5)) & (dist[crop].reshape(shp).min(axis=(1, 3, 5))
                                                             > grading * s)
        if not ok.any():
            break
        lev[crop][_expand(ok, s)] = L
    return lev


def _expand(cubes: np.ndarray, s: int) -> np.ndarray:
    """A per-cube array repeated ``s`` times along each axis (cube grid -> block grid)."""
    return np.repeat(np.repeat(np.repeat(cubes, s, 0), s, 1), s, 2)


def _pool(a: np.ndarray, s: int, reduce) -> tuple[np.ndarray, tuple]:
    """``reduce`` of ``a`` over the aligned ``s``-cubes inside it, and the crop they cover."""
    nc = [n // s for n in a.shape]
    crop = tuple(slice(0, m * s) for m in nc)
    return reduce(a[crop].reshape(nc[0], s, nc[1], s, nc[2], s), axis=(1, 3, 5)), crop


def balance_levels(lev: np.ndarray) -> np.ndarray:
    """Split leaves until no two leaves that touch (face, edge or corner) differ by more than one level.

    ``lev`` as from :func:`leaf_levels` (int16); returns a new array. Leaves are only split.
    """
    lev = lev.copy()
    big = np.int16(np.iinfo(np.int16).max - 1)
    while True:
        allowed = ndimage.minimum_filter(lev, size=3, mode="constant", cval=big) + 1
        viol = lev > allowed
        if not viol.any():
            return lev
        before = lev.copy()  # each leaf splits at most once per pass (a split leaf is re-checked next pass)
        for L in range(int(lev.max()), 0, -1):
            s = 2**L
            hit = viol & (before == L)
            if not hit.any():
                continue
            cubes, crop = _pool(hit, s, np.any)  # leaves of level L lie inside this crop
            sub = lev[crop]
            sub[_expand(cubes, s) & (sub == L)] = L - 1


def _orient(tets: np.ndarray) -> np.ndarray:
    """Tetrahedra of lattice points (k, 4), reordered to positive volume in lattice coordinates."""
    x = _LATTICE[tets].astype(float)
    vol = np.einsum("ij,ij->i", np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), x[:, 3] - x[:, 0])
    if np.any(vol == 0):
        raise AssertionError("degenerate template tetrahedron")  # pragma: no cover - a template bug
    tets = tets.copy()
    flip = vol < 0
    tets[flip, 1], tets[flip, 2] = tets[flip, 2].copy(), tets[flip, 1].copy()
    return tets


def _face_triangles(present: np.ndarray, axis: int, side: int, parity: int) -> list[tuple[int, int, int]]:
    """Triangles (lattice indices) of the face ``axis = side`` of a leaf, given the nodes present on it.

    ``parity``: the leaf's index sum at its own scale, mod 2 (the coarse diagonal rule).
    """
    u, v = [d for d in range(3) if d != axis]

    def pt(a: int, b: int) -> int:
        q = [0, 0, 0]
        q[axis], q[u], q[v] = side, a, b
        return 9 * q[0] + 3 * q[1] + q[2]

    def square(a0: int, b0: int, step: int, odd) -> list[tuple[int, int, int]]:
        p00, p10, p11, p01 = pt(a0, b0), pt(a0 + step, b0), pt(a0 + step, b0 + step), pt(a0, b0 + step)
        if odd(p00):  # the diagonal joins the two corners of odd index sum
            return [(p00, p10, p11), (p00, p11, p01)]
        return [(p00, p10, p01), (p10, p11, p01)]

    if present[pt(1, 1)]:  # four finer leaves behind: their faces, by the fine diagonal rule
        return [t for a0 in (0, 1) for b0 in (0, 1) for t in square(a0, b0, 1, lambda p: _LATTICE[p].sum() % 2)]
    ring = [(0, 0), (1, 0), (2, 0), (2, 1), (2, 2), (1, 2), (0, 2), (0, 1)]
    loop = [pt(a, b) for a, b in ring if present[pt(a, b)]]
    if len(loop) > 4:  # hanging edge midpoints: fan from a new node at the face centre
        return [(pt(1, 1), loop[i], loop[(i + 1) % len(loop)]) for i in range(len(loop))]
    return square(0, 0, 2, lambda p: (parity + _LATTICE[p].sum() // 2) % 2)


@functools.cache
def _template(bits: int, parity: int) -> np.ndarray:
    """Positively oriented tetrahedra (k, 4) of lattice indices of a leaf with hanging-node ``bits``.

    Bit i of ``bits`` says whether lattice point ``_HANGING[i]`` is a node.
    """
    if bits == 0:  # the 5-tet split on the corners: local corner (a, b, c) in {0,1}^3 -> lattice 2 (a, b, c)
        corner = np.array([18 * a + 6 * b + 2 * c for a in (0, 1) for b in (0, 1) for c in (0, 1)])
        return corner[_TEMPLATES[parity]]
    present = np.ones(27, bool)
    present[_HANGING] = [(bits >> i) & 1 for i in range(len(_HANGING))]
    tris = [t for axis in range(3) for side in (0, 2) for t in _face_triangles(present, axis, side, parity)]
    return _orient(np.array([(_CENTRE, *t) for t in tris], dtype=np.int64))


def _leaf_tets(lev: np.ndarray, solid: np.ndarray) -> tuple[np.ndarray, dict]:
    """Tetrahedra of the solid leaves as node coordinates in half-block units, shape (Ne, 4, 3).

    ``lev``: balanced levels; ``solid``: block mask, constant over each leaf. Also returns the
    number of solid leaves per level. The hanging nodes are the corners of every leaf, pore or
    solid: a face or edge of a solid leaf then carries the nodes the balanced octree puts there
    (a face centre only with its four edge midpoints), whatever is solid behind it.
    """
    shape = np.asarray(lev.shape)
    isnode = np.zeros(tuple(shape + 1), bool)
    leaves = {}
    for L in range(int(lev.max()) + 1):
        s = 2**L
        o = np.argwhere(lev == L)
        o = o[np.all(o % s == 0, axis=1)]
        for c in _LATTICE[[0, 2, 6, 8, 18, 20, 24, 26]] // 2:
            q = o + s * c
            isnode[q[:, 0], q[:, 1], q[:, 2]] = True
        leaves[L] = o[solid[o[:, 0], o[:, 1], o[:, 2]]]
    out = []
    for L, o in leaves.items():
        if len(o) == 0:
            continue
        parity = (o // 2**L).sum(axis=1) % 2
        bits = np.zeros(len(o), np.int64)
        if L > 0:  # a level-0 leaf has no finer neighbour
            h = 2 ** (L - 1)
            for i, p in enumerate(_HANGING):
                q = o + h * _LATTICE[p]
                bits |= isnode[q[:, 0], q[:, 1], q[:, 2]].astype(np.int64) << i
        key = bits * 2 + parity
        for k in np.unique(key):
            sel = key == k
            tmpl = _template(int(k // 2), int(k % 2))  # (m, 4) lattice indices
            # half-block units: the lattice step of a level-L leaf is 2**L half blocks
            out.append((2 * o[sel][:, None, None, :] + 2**L * _LATTICE[tmpl][None]).reshape(-1, 4, 3))
    return np.concatenate(out), {L: len(o) for L, o in leaves.items()}


def _leaf_solid(fine: np.ndarray, lines, lev: np.ndarray, threshold: float) -> np.ndarray:
    """Block mask of solid leaves: a leaf is solid when its solid voxel fraction is >= ``threshold``."""
    counts = fine
    for ax in range(3):
        counts = np.add.reduceat(counts, lines[ax][:-1], axis=ax, dtype=np.int64)
    sizes = [np.diff(g) for g in lines]
    nvox = sizes[0][:, None, None] * sizes[1][None, :, None] * sizes[2][None, None, :]
    out = counts >= threshold * nvox
    for L in range(1, int(lev.max()) + 1):
        s = 2**L
        (c_sum, crop), (n_sum, _) = _pool(counts, s, np.sum), _pool(nvox, s, np.sum)
        here = lev[crop] == L
        out[crop][here] = _expand(c_sum >= threshold * n_sum, s)[here]
    return out


def _check_graded_args(image, coarsen_max, grading, refine) -> np.ndarray:
    """The refine mask (voxels) of :func:`mesh_graded`, after checking its own arguments."""
    if isinstance(coarsen_max, bool) or not isinstance(coarsen_max, (int, np.integer)) or coarsen_max < 1:
        raise InputError(f"coarsen_max must be an integer >= 1 (voxels), got {coarsen_max!r}")
    if not (isinstance(grading, (int, float, np.floating, np.integer)) and np.isfinite(grading) and grading > 0):
        raise InputError(f"grading must be a finite number > 0, got {grading!r}; 1 is the usual choice")
    if refine is None:
        return image.phases != 0
    refine = np.asarray(refine)
    if refine.shape != image.phases.shape or refine.dtype != bool:
        raise InputError(f"refine must be a boolean array of the image's shape {image.phases.shape}, got "
                         f"{refine.dtype} {refine.shape}")
    return refine


def mesh_graded(
    image: VoxelImage,
    *,
    coarsen: int = 2,
    coarsen_max: int = 16,
    grading: float = 1.0,
    refine: np.ndarray | None = None,
    threshold: float = 0.5,
    keep: str = "supported",
    support_axis: str | int | None = "z",
) -> MeshResult:
    """Mesh the solid of ``image`` with blocks of ``coarsen`` voxels near ``refine``, coarser away from it.

    Parameters
    ----------
    image : VoxelImage
        Segmented image (1 = pore, 0 = solid).
    coarsen : int, default 2
        Fine block size c_f (voxels) near ``refine``: there the solid is that of
        ``mesh_solid(image, coarsen=coarsen)``.
    coarsen_max : int, default 16
        Largest leaf edge, voxels: leaves are ``coarsen * 2**L`` voxels across for ``L`` up to
        ``floor(log2(coarsen_max / coarsen))`` (``coarsen_max <= coarsen``: the uniform mesh).
    grading : float, default 1.0
        Distance from ``refine`` per leaf size (> 0): a leaf of edge ``s`` blocks lies more than
        ``grading * s`` blocks (centre to centre) from every block holding a ``refine`` voxel.
        Smaller: coarser sooner, fewer nodes.
    refine : ndarray of bool, shape of the image, optional
        Voxels to resolve finely: the loaded pores, with the solid ligaments that carry their
        load (:func:`ligament_region`). Default: every pore voxel (fine at every wall, coarse
        only inside grains). Away from it a leaf is solid when its solid voxel
        fraction is >= ``threshold``, so the walls there are those of the coarser block size.
    threshold, keep, support_axis
        As for :func:`~porefsi.solid.mesh.mesh_solid`.

    Returns
    -------
    MeshResult
        ``coarsen`` is the fine block size (the node grid spacing in voxels); ``leaf_counts``
        the number of solid leaves of each edge length (voxels).

    Raises
    ------
    InputError
        Bad arguments (as :func:`~porefsi.solid.mesh.mesh_solid`, plus ``coarsen_max`` < 1,
        ``grading`` <= 0, or a ``refine`` mask of another shape).
    MeshError
        No solid, or no solid connected to the supports.
    """
    _check_mesh_args(image, coarsen, threshold, keep)
    refine = _check_graded_args(image, coarsen_max, grading, refine)
    c = int(coarsen)
    fine = image.phases == 0
    fraction, lines = _coarsen(fine, c)
    sizes = [np.diff(g) for g in lines]
    _require_resolved(image, fine, fraction >= float(threshold), (sizes[0][:, None, None] * sizes[1][None, :, None]
                                                                 * sizes[2][None, None, :]).astype(float), c)
    n_levels = max(0, int(np.floor(np.log2(max(coarsen_max, c) / c) + 1e-12)))
    full = (sizes[0] == c)[:, None, None] & (sizes[1] == c)[None, :, None] & (sizes[2] == c)[None, None, :]
    lev = balance_levels(leaf_levels(_coarsen(refine, c)[0] > 0, full, n_levels, float(grading)))
    solid = _leaf_solid(fine, lines, lev, float(threshold))
    if not solid.any():
        raise MeshError(f"no solid left after coarsening by {c} (graded up to {coarsen_max}): every block and "
                        "leaf is mostly pore; use a smaller coarsen or a lower threshold")
    mask, n_removed = _keep_components(solid, keep, None if support_axis is None else axis_index(support_axis))
    corners, counts = _leaf_tets(lev, mask)
    ijk, tets = _number_nodes(corners, lev.shape)
    facets = _boundary_facets(tets, len(ijk))
    mesh = SolidMesh(points=block_points(image, lines, ijk), tets=tets, facets=facets,
                     facet_tags=_box_tags(ijk[facets], lev.shape), box=image_box(image))
    vol = (sizes[0][:, None, None] * sizes[1][None, :, None] * sizes[2][None, None, :]).astype(float)
    total, kept = float((vol * solid).sum()), float((vol * mask).sum())
    return MeshResult(mesh=mesh, removed_solid_fraction=(total - kept) / total, coarsen=c,
                      solid_fraction_coarse=total / float(vol.sum()), n_components_removed=n_removed,
                      leaf_counts={c * 2**L: int(n) for L, n in counts.items() if n})


def _number_nodes(corners: np.ndarray, shape) -> tuple[np.ndarray, np.ndarray]:
    """Unique nodes of tets given as half-block coordinates (Ne, 4, 3): block indices (Nn, 3), tets (Ne, 4)."""
    shape2 = 2 * np.asarray(shape, dtype=np.int64) + 1
    gid = (corners[..., 0] * shape2[1] + corners[..., 1]) * shape2[2] + corners[..., 2]
    used, inv = np.unique(gid.reshape(-1), return_inverse=True)
    half = np.stack([used // (shape2[1] * shape2[2]), (used // shape2[2]) % shape2[1], used % shape2[2]], axis=1)
    if np.any(half % 2):  # pragma: no cover - every node is a block-grid corner (module docstring)
        raise AssertionError("graded mesh node off the block grid")
    return half // 2, inv.reshape(-1, 4).astype(np.int64)


def _box_tags(fijk: np.ndarray, shape) -> np.ndarray:
    """Facet tags from the block indices (Nf, 3, 3) of the facets' corners: box faces 0..5, else pore wall."""
    tags = np.full(len(fijk), PORE_WALL, dtype=np.int8)
    for ax in range(3):
        tags[np.all(fijk[:, :, ax] == 0, axis=1)] = 2 * ax
        tags[np.all(fijk[:, :, ax] == shape[ax], axis=1)] = 2 * ax + 1
    return tags
