"""Solid meshing from images: conformity, exact volume, tags, floating grains, bad inputs."""

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from porefsi.errors import InputError, MeshError
from porefsi.image.voxel_image import VoxelImage
from porefsi.solid.mesh import (
    _TEMPLATES,
    FACE_NAMES,
    FACET_TAGS,
    PORE_WALL,
    SolidMesh,
    mesh_solid,
    mesh_voxels,
    tet_volumes,
)

SAMPLE = Path(__file__).resolve().parents[1] / "porefsi" / "data" / "berea_icl_120_paper.npz"


def _faces_count(tets):
    f = np.sort(tets[:, [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]]].reshape(-1, 3), axis=1)
    _, cnt = np.unique(f, axis=0, return_counts=True)
    return cnt


def _dihedral_angles(x):
    """The six interior dihedral angles (deg) of a tetrahedron with vertices x (4, 3)."""
    out = []
    for i, j in [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]:
        k, m = [v for v in range(4) if v not in (i, j)]
        e = x[j] - x[i]
        n1 = np.cross(e, x[k] - x[i])
        n2 = np.cross(e, x[m] - x[i])
        c = n1 @ n2 / np.linalg.norm(n1) / np.linalg.norm(n2)
        out.append(np.degrees(np.arccos(np.clip(c, -1, 1))))
    return np.array(out)


def test_five_tet_templates_fill_the_cube_with_good_angles():
    from porefsi.solid.mesh import _CORNERS

    for tmpl in _TEMPLATES:
        x = _CORNERS[tmpl].astype(float)
        vol = np.einsum("ij,ij->i", np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), x[:, 3] - x[:, 0]) / 6
        assert np.all(vol > 0)
        assert vol.sum() == pytest.approx(1.0, abs=1e-15)
        # 5-tet split: corner tets have right dihedral angles, the central regular tet arccos(1/3)
        ang = np.concatenate([_dihedral_angles(xx) for xx in x])
        assert ang.min() >= np.degrees(np.arccos(1 / np.sqrt(3))) - 1e-9  # 54.7356 deg


@settings(max_examples=25, deadline=None)
@given(arrays(np.bool_, st.tuples(st.integers(1, 5), st.integers(1, 5), st.integers(1, 5))))
def test_voxel_mesh_is_conforming_and_exact(solid):
    """Random solids: each face shared by <= 2 tets, volume = voxel count, closed boundary."""
    if not solid.any():
        with pytest.raises(MeshError):
            mesh_voxels(solid)
        return
    ijk, tets, facets, tags = mesh_voxels(solid)
    assert len(np.unique(ijk, axis=0)) == len(ijk)  # no duplicate nodes
    assert len(tets) == 5 * solid.sum()
    pts = ijk.astype(float)
    vol = tet_volumes(pts, tets)
    assert np.all(vol > 0)
    assert vol.sum() == pytest.approx(solid.sum(), rel=1e-14)
    cnt = _faces_count(tets)
    assert cnt.max() <= 2
    # the faces met once are exactly the boundary facets
    assert np.count_nonzero(cnt == 1) == len(facets)
    # closed surface: sum of oriented area vectors vanishes; divergence theorem gives the volume
    x = pts[facets]
    an = 0.5 * np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
    assert np.abs(an.sum(axis=0)).max() < 1e-12
    assert np.einsum("ij,ij->", x.mean(axis=1), an) / 3 == pytest.approx(solid.sum(), rel=1e-12)
    # box-face facets lie on their plane and their area equals the solid voxel faces there
    for code in range(len(FACE_NAMES)):
        ax, hi = divmod(code, 2)
        sel = tags == code
        plane = solid.shape[ax] if hi else 0
        assert np.all(x[sel][:, :, ax] == plane)
        layer = np.take(solid, -1 if hi else 0, axis=ax)
        assert np.linalg.norm(an[sel], axis=1).sum() == pytest.approx(layer.sum(), abs=1e-12)
    assert set(np.unique(tags)) <= set(FACET_TAGS.values())


def test_interior_faces_shared_by_two_tets_in_a_full_block():
    ijk, tets, facets, _ = mesh_voxels(np.ones((3, 4, 2), dtype=bool))
    cnt = _faces_count(tets)
    n_interior = (len(tets) * 4 - len(facets)) // 2
    assert np.count_nonzero(cnt == 2) == n_interior
    # boundary of a box: 2 triangles per voxel face on the outside
    assert len(facets) == 2 * 2 * (3 * 4 + 4 * 2 + 3 * 2)


def _image(solid, h=2e-6, origin=(1e-5, 0.0, -3e-5)):
    return VoxelImage((~solid).astype(np.uint8), h, np.asarray(origin))


def test_points_in_image_frame_and_volume():
    solid = np.ones((4, 5, 6), dtype=bool)
    solid[1:3, 1:4, 2:4] = False  # a pore inside
    img = _image(solid)
    r = mesh_solid(img)
    m = r.mesh
    h = img.voxel_size
    assert np.allclose(m.points.min(axis=0), img.origin, rtol=1e-12, atol=1e-9 * h)
    assert np.allclose(m.points.max(axis=0), img.origin + np.array(solid.shape) * h, rtol=1e-12, atol=1e-9 * h)
    assert m.volume == pytest.approx(solid.sum() * h**3, rel=1e-12, abs=0)
    assert r.removed_solid_fraction == 0.0
    np.testing.assert_array_equal(m.box, [img.origin, img.origin + np.array(solid.shape) * h])
    # pore-wall area = faces of the 2x3x2 pore box = 2(6+4+6) voxel faces
    fa = m.points[m.facets_tagged("pore_wall")]
    area = 0.5 * np.linalg.norm(np.cross(fa[:, 1] - fa[:, 0], fa[:, 2] - fa[:, 0]), axis=1).sum()
    assert area == pytest.approx(2 * (6 + 4 + 6) * h**2, rel=1e-12, abs=0)


def test_floating_grain_removed_and_reported():
    solid = np.zeros((6, 6, 6), dtype=bool)
    solid[:, :, :2] = True  # a slab on zmin
    solid[:, :2, :] = True  # a wall joining zmin and zmax
    solid[3:5, 3:5, 3:5] = True  # a grain in the pore, touching nothing
    img = _image(solid)
    r = mesh_solid(img, support_axis="z")
    grain, total = 8, solid.sum()
    assert r.n_components_removed == 1
    assert r.removed_solid_fraction == pytest.approx(grain / total, rel=1e-14)
    assert r.mesh.volume == pytest.approx((total - grain) * img.voxel_size**3, rel=1e-12, abs=0)
    # "largest" keeps the same here (the grain is the small one)
    assert mesh_solid(img, keep="largest").mesh.n_tets == r.mesh.n_tets


def test_edge_contact_is_not_support():
    """A grain touching the frame along an edge only is a hinge: it is removed."""
    solid = np.zeros((4, 4, 4), dtype=bool)
    solid[0, 0, :] = True  # a column spanning z: supported
    solid[1, 1, 2] = True  # shares only the edge x=1, y=1 of voxel (0, 0, 2)
    r = mesh_solid(_image(solid), support_axis="z")
    assert r.n_components_removed == 1
    assert r.mesh.n_tets == 5 * 4


def test_coarsening_counts_blocks():
    solid = np.zeros((5, 4, 4), dtype=bool)
    solid[:, :, :2] = True  # half solid along z
    solid[4, :, :] = True  # the thin last block along x (5 = 2 + 2 + 1) is all solid
    r = mesh_solid(_image(solid), coarsen=2, support_axis="x")
    # blocks (3, 2, 2): k=0 blocks solid (fraction 1), k=1 blocks: solid only where i-block is the last
    assert r.mesh.n_tets == 5 * (3 * 2 + 2)
    h = 2e-6
    assert np.allclose(r.mesh.points.max(axis=0) - r.mesh.points.min(axis=0), np.array([5, 4, 4]) * h, rtol=1e-12,
                       atol=1e-9 * h)


def test_sample_reaches_paper_size():
    """The paper's mesh (11,976 nodes, 56,559 tets) is reachable: coarsen 5 on the 120^3 sample.

    Exact identity checked: 5 tets per kept solid block; the size lands within 15 % of the paper's.
    """
    d = np.load(SAMPLE)
    img = VoxelImage(d["image"], float(d["voxel_size_m"]))
    r = mesh_solid(img, coarsen=5)
    assert abs(r.mesh.n_tets - 56559) / 56559 < 0.15
    blocks = r.solid_fraction_coarse * 24**3 * (1 - r.removed_solid_fraction)
    assert r.mesh.n_tets == pytest.approx(5 * blocks, rel=1e-12)
    assert r.removed_solid_fraction < 0.01


def test_bad_inputs():
    solid = np.ones((3, 3, 3), dtype=bool)
    img = _image(solid)
    with pytest.raises(InputError):
        mesh_solid(img, coarsen=0)
    with pytest.raises(InputError):
        mesh_solid(img, threshold=0.0)
    with pytest.raises(InputError):
        mesh_solid(img, keep="all")
    with pytest.raises(MeshError, match="no solid"):
        mesh_solid(_image(np.zeros((3, 3, 3), dtype=bool)))
    floating = np.zeros((5, 5, 5), dtype=bool)
    floating[2, 2, 2] = True
    with pytest.raises(MeshError, match="floats"):
        mesh_solid(_image(floating))


def test_small_image_coarsened_away_names_cause_and_fix():
    """A 4^3 image, 37.5 % solid: with the CLI's default coarsen 5 one block covers it and is < 50 %
    solid, so nothing is left; the error says why (block fraction vs threshold) and to lower coarsen."""
    solid = np.zeros((4, 4, 4), dtype=bool)
    solid[:, :, 0] = True
    solid[:2, :, 1] = True  # 24 of 64 voxels, all on or joined to zmin
    frac = solid.mean()
    assert frac == 0.375
    with pytest.raises(MeshError, match=rf"4x4x4-voxel image.*no 5\^3 block is at least 0.5 solid.*"
                                        rf"most solid block is {frac:.3g}.*--coarsen 1"):
        mesh_solid(_image(solid), coarsen=5)
    assert mesh_solid(_image(solid), coarsen=1).mesh.n_tets == 5 * int(solid.sum())


def test_box_must_contain_the_points():
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    args = (pts, np.array([[0, 1, 2, 3]]), np.zeros((0, 3), int), np.zeros(0, np.int8))
    np.testing.assert_array_equal(SolidMesh(*args).box, [[0, 0, 0], [1, 1, 1]])  # default: bounding box
    np.testing.assert_array_equal(SolidMesh(*args, box=[[0, 0, 0], [2, 1, 1]]).box, [[0, 0, 0], [2, 1, 1]])
    with pytest.raises(InputError, match="containing every point"):
        SolidMesh(*args, box=[[0, 0, 0], [0.5, 1, 1]])


def test_inverted_tet_rejected():
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    SolidMesh(pts, np.array([[0, 1, 2, 3]]), np.zeros((0, 3), int), np.zeros(0, np.int8))
    with pytest.raises(MeshError, match="1 of 1 tetrahedra are inverted"):
        SolidMesh(pts, np.array([[0, 2, 1, 3]]), np.zeros((0, 3), int), np.zeros(0, np.int8))


def test_vtu_round_trip_does_not_modify_inputs(tmp_path):
    from porefsi.io.solid_vtk import read_solid_vtu

    m = mesh_solid(_image(np.ones((2, 2, 3), dtype=bool))).mesh
    u = np.arange(m.n_nodes * 3, dtype=float).reshape(-1, 3) * 1e-9
    u0 = u.copy()
    vm = np.linspace(0, 1, m.n_tets)
    path = m.write_vtu(tmp_path / "s.vtu", point_data={"u": u}, cell_data={"vm": vm})
    p, t, pd, cd = read_solid_vtu(path)
    assert np.array_equal(p, m.points) and np.array_equal(t, m.tets)
    assert np.array_equal(pd["u"], u) and np.array_equal(cd["vm"], vm)
    assert np.array_equal(u, u0)
    with pytest.raises(InputError):
        m.write_vtu(tmp_path / "s.vtk")
    assert PORE_WALL == FACET_TAGS["pore_wall"]
