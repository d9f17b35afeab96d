"""Network update from displacements: exact on affine fields, invariant under rotation."""

import numpy as np
import pytest

from porefsi.coupling.update import (
    deformed_image,
    geometric_update,
    mean_size_change,
    pore_affine_maps,
    update_nodes,
)
from porefsi.errors import InputError
from porefsi.image import VoxelImage
from porefsi.network import Network


def _net():
    """Three pores in an L: throat 0 along x, throat 1 along y."""
    c = np.array([[10.0, 10, 10], [20, 10, 10], [10, 20, 10]]) * 1e-6
    return Network(
        pore_coords=c, pore_radius=np.full(3, 3e-6), pore_volume=np.full(3, 2e-16),
        throat_conns=[[0, 1], [0, 2]], throat_radius=[1e-6, 2e-6], throat_length=[4e-6, 4e-6],
        throat_pore_length=[[3e-6, 3e-6], [3e-6, 3e-6]], pore_faces=np.zeros((3, 6), bool),
        voxel_size=1e-6, shape=(30, 30, 30),
    )


def _wall(net, rng, n=40):
    """Wall nodes: random points on a shell around each pore."""
    pts, nodes = [], []
    for i, (c, r) in enumerate(zip(net.pore_coords, net.pore_radius, strict=True)):
        d = rng.standard_normal((n, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        pts.append(c + 1.3 * r * d)
        nodes.append(np.arange(i * n, (i + 1) * n))
    return np.vstack(pts), nodes


def test_affine_fit_is_exact_on_affine_fields(rng):
    net = _net()
    x, nodes = _wall(net, rng)
    G = 1e-3 * rng.standard_normal((3, 3))
    b = 1e-8 * rng.standard_normal(3)
    u = b + x @ G.T
    t, F = pore_affine_maps(net.pore_coords, nodes, x, u)
    np.testing.assert_allclose(F, np.broadcast_to(np.eye(3) + G, F.shape), atol=1e-12)
    np.testing.assert_allclose(t, b + net.pore_coords @ G.T, atol=1e-18)


def test_uniform_dilation_scales_everything(rng):
    net = _net()
    x, nodes = _wall(net, rng)
    lam = 1.01
    new = geometric_update(net, nodes, x, (lam - 1) * x)
    np.testing.assert_allclose(new.pore_coords, lam * net.pore_coords, rtol=1e-12)
    np.testing.assert_allclose(new.pore_radius, lam * net.pore_radius, rtol=1e-12)
    np.testing.assert_allclose(new.pore_volume, lam**3 * net.pore_volume, rtol=1e-12)
    np.testing.assert_allclose(new.throat_radius, lam * net.throat_radius, rtol=1e-12)
    np.testing.assert_allclose(new.throat_length, lam * net.throat_length, rtol=1e-12)
    np.testing.assert_allclose(new.throat_pore_length, lam * net.throat_pore_length, rtol=1e-12)


def test_rotation_changes_no_size(rng):
    net = _net()
    x, nodes = _wall(net, rng)
    a = 0.3
    R = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    new = geometric_update(net, nodes, x, x @ R.T - x)
    np.testing.assert_allclose(new.pore_radius, net.pore_radius, rtol=1e-12)
    np.testing.assert_allclose(new.throat_radius, net.throat_radius, rtol=1e-12)
    np.testing.assert_allclose(new.throat_length, net.throat_length, rtol=1e-12)


def test_uniaxial_compression_closes_throats_across_not_along(rng):
    """Compress x by (1 - e): the x-throat gets shorter, keeps its radius (its x-section is
    unchanged); the y-throat keeps its length, its section shrinks by (1 - e) so r * sqrt(1 - e)."""
    net = _net()
    x, nodes = _wall(net, rng)
    e = 0.01
    u = np.zeros_like(x)
    u[:, 0] = -e * x[:, 0]
    new = geometric_update(net, nodes, x, u)
    np.testing.assert_allclose(new.throat_length, net.throat_length * [1 - e, 1], rtol=1e-12)
    np.testing.assert_allclose(new.throat_radius, net.throat_radius * [1, np.sqrt(1 - e)], rtol=1e-12)
    np.testing.assert_allclose(new.pore_volume, net.pore_volume * (1 - e), rtol=1e-12)


def test_pores_without_nodes_only_keep_their_geometry(rng):
    net = _net()
    x, nodes = _wall(net, rng)
    nodes[1] = np.zeros(0, int)
    new = geometric_update(net, nodes, x, np.zeros_like(x))
    np.testing.assert_array_equal(new.pore_radius, net.pore_radius)


def test_inverting_displacement_is_an_error(rng):
    net = _net()
    x, nodes = _wall(net, rng)
    with pytest.raises(InputError, match="inverted"):
        geometric_update(net, nodes, x, -2.0 * x)
    with pytest.raises(InputError, match="entries"):
        geometric_update(net, nodes[:2], x, 0 * x)


def test_deformed_image_identity_and_translation(rng):
    ph = (rng.random((16, 16, 16)) < 0.4).astype(np.uint8)
    img = VoxelImage(ph, 1e-6)
    g = np.arange(9) * 2e-6
    P = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    assert np.array_equal(deformed_image(img, P, np.zeros_like(P), 2e-6).phases, ph)
    u = np.zeros_like(P)
    u[:, 2] = 2e-6  # two voxels along z
    moved = deformed_image(img, P, u, 2e-6).phases
    assert np.array_equal(moved[:, :, 2:], ph[:, :, :-2])
    with pytest.raises(InputError, match="grid"):
        deformed_image(img, P + 0.3e-6, u, 2e-6)


def test_mean_size_change_is_eq_3_3():
    net = _net()
    bigger = net.replace(pore_radius=net.pore_radius * 1.02)
    assert mean_size_change(net, bigger) == pytest.approx(0.02, rel=1e-12)


def test_pores_without_wall_nodes_take_the_surrounding_field(rng):
    """A pore smaller than a mesh cell has < 4 wall nodes (here: 2, and none): its map comes from
    the mesh nodes around it, so an affine field is still carried exactly (it used to be a pure
    translation: radius and volume unchanged)."""
    net = _net()
    x, nodes = _wall(net, rng)
    g = np.arange(0.0, 31.0, 5.0) * 1e-6  # a 5 um grid of mesh nodes over the domain
    grid = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    pts = np.vstack([x, grid])
    nodes = [nodes[0], nodes[1][:2], np.array([], np.int64)]
    un = update_nodes(net.pore_coords, net.pore_radius, nodes, pts, spacing=5e-6)
    np.testing.assert_array_equal(un[0], nodes[0])  # enough wall nodes: kept as they are
    assert len(un[1]) >= 8 and len(un[2]) >= 8
    G = 1e-3 * rng.standard_normal((3, 3))
    new = geometric_update(net, un, pts, pts @ G.T)
    J = np.linalg.det(np.eye(3) + G)
    np.testing.assert_allclose(new.pore_volume, J * net.pore_volume, rtol=1e-10)
    np.testing.assert_allclose(new.pore_coords, net.pore_coords @ (np.eye(3) + G).T, rtol=1e-12)
    old = geometric_update(net, nodes, pts, pts @ G.T)  # wall nodes alone
    np.testing.assert_array_equal(old.pore_volume[1:], net.pore_volume[1:])
    with pytest.raises(InputError, match="spacing"):
        update_nodes(net.pore_coords, net.pore_radius, nodes, pts, spacing=0.0)


def test_deformed_image_shortcut_below_a_quarter_voxel_is_exact(rng):
    """Below a quarter voxel of displacement the voxelisation cannot move any voxel: the shortcut
    returns the reference image, equal to the full fixed-point voxelisation; above it, the full
    computation runs (and moves voxels)."""
    ph = (rng.random((16, 16, 16)) < 0.4).astype(np.uint8)
    img = VoxelImage(ph, 1e-6)
    g = np.arange(9) * 2e-6
    P = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    for scale in (1e-17, 1e-9, 0.249e-6):
        u = scale * rng.uniform(-1.0, 1.0, P.shape)
        fast = deformed_image(img, P, u, 2e-6)
        assert fast.phases is img.phases  # the shortcut was taken
        assert np.array_equal(fast.phases, deformed_image(img, P, u, 2e-6, shortcut=False).phases)
    u = np.zeros_like(P)
    u[:, 0] = 0.6e-6  # beyond half a voxel: every voxel takes its neighbour's phase along x
    moved = deformed_image(img, P, u, 2e-6)
    assert np.array_equal(moved.phases[1:], ph[:-1])


def test_face_cuts_stretch_with_their_section(rng):
    """Compress x by (1 - e): a face cut on an x face keeps its radius (its section lies in the
    y-z plane), one on a y face shrinks by sqrt(1 - e); a uniform dilation scales both by lam."""
    base = _net()
    faces = np.zeros((3, 6), bool)
    faces[0, [0, 2]] = True  # pore 0 on xmin and ymin
    rad = np.zeros((3, 6))
    rad[0, [0, 2]] = [2e-6, 1.5e-6]
    gf = np.where(faces, 0.05, 0.0)
    net = base.replace(pore_faces=faces, pore_shape_factor=np.full(3, 0.05), throat_shape_factor=np.full(2, 0.05),
                       pore_face_radius=rad, pore_face_shape_factor=gf,
                       pore_face_duct_fraction=np.where(faces, 0.3, 0.0))
    x, nodes = _wall(net, rng)
    e = 0.01
    u = np.zeros_like(x)
    u[:, 0] = -e * x[:, 0]
    new = geometric_update(net, nodes, x, u)
    np.testing.assert_allclose(new.pore_face_radius[0, [0, 2]], [2e-6, 1.5e-6 * np.sqrt(1 - e)], rtol=1e-12)
    assert np.all(new.pore_face_radius[~faces] == 0)
    lam = 1.01
    new = geometric_update(net, nodes, x, (lam - 1) * x)
    np.testing.assert_allclose(new.pore_face_radius, lam * rad, rtol=1e-12)
