"""Synthetic images: the closed-form geometry they promise is the geometry they contain."""

import numpy as np
import pytest

from porefsi.errors import InputError
from porefsi.image.synthetic import cylinder_bundle, sphere_lattice


def test_lattice_geometry_and_porosity():
    lat = sphere_lattice(n=(3, 2, 2), spacing=14, pore_radius=5, throat_radius=2, voxel_size=2e-6)
    ph = lat.image.phases
    assert lat.image.shape == (2 * 4 + 28 + 1, 2 * 4 + 14 + 1, 2 * 4 + 14 + 1)
    assert lat.porosity == np.count_nonzero(ph) / ph.size
    assert len(lat.pore_centres) == 12
    # edges: (nx-1) ny nz + nx (ny-1) nz + nx ny (nz-1)
    assert len(lat.throat_conns) == 2 * 2 * 2 + 3 * 1 * 2 + 3 * 2 * 1
    assert np.all(lat.throat_conns[:, 0] < lat.throat_conns[:, 1])
    c = lat.pore_centre_voxels
    d = np.abs(c[lat.throat_conns[:, 0]] - c[lat.throat_conns[:, 1]]).sum(axis=1)
    assert np.all(d == 14)  # lattice neighbours only
    np.testing.assert_allclose(lat.pore_centres, (c + 0.5) * 2e-6)
    # the voxel at each centre and at each throat midpoint is pore; the one 1 voxel beyond a
    # sphere surface along a diagonal (no throat there) is solid
    assert np.all(ph[tuple(c.T)] == 1)
    mid = (c[lat.throat_conns[:, 0]] + c[lat.throat_conns[:, 1]]) // 2
    assert np.all(ph[tuple(mid.T)] == 1)
    off = np.array([4, 4, 0])  # |off| = 5.66 > 5, off any lattice edge
    assert ph[tuple(c[5] + off)] == 0
    # cylinder part outside both spheres, closed form
    np.testing.assert_allclose(lat.throat_length, (14 - 2 * np.sqrt(25 - 4)) * 2e-6)


def test_lattice_sphere_voxel_count_is_the_digital_ball():
    # a single sphere well inside the box holds exactly the lattice points within R
    lat = sphere_lattice(n=(1, 1, 1), pore_radius=6, margin=6)
    R = 6
    g = np.arange(-R, R + 1)
    n_lattice = int(np.count_nonzero((g[:, None, None] ** 2 + g[None, :, None] ** 2 + g[None, None, :] ** 2) <= R * R))
    assert np.count_nonzero(lat.image.phases) == n_lattice
    # and that count approximates the sphere volume (Gauss circle problem, error O(R^2))
    assert abs(n_lattice - 4 / 3 * np.pi * R**3) < 4 * np.pi * R**2 * 0.5


def test_lattice_percolates_along_every_axis():
    from scipy import ndimage

    lat = sphere_lattice(n=(2, 3, 2), pore_radius=[4, 5, 4, 5, 4, 5, 5, 4, 5, 4, 5, 4], spacing=12)
    lab, _ = ndimage.label(lat.image.phases)
    for ax in range(3):
        lo = set(np.unique(np.take(lab, 0, axis=ax))) - {0}
        hi = set(np.unique(np.take(lab, -1, axis=ax))) - {0}
        assert lo & hi, f"no pore cluster spans axis {ax}"


def test_lattice_rejects_bad_geometry():
    with pytest.raises(InputError, match="overlap"):
        sphere_lattice(spacing=9, pore_radius=5)
    with pytest.raises(InputError, match="smaller"):
        sphere_lattice(throat_radius=5, pore_radius=5)
    with pytest.raises(InputError, match="margin"):
        sphere_lattice(pore_radius=4, margin=5)
    with pytest.raises(InputError, match="whole number"):
        sphere_lattice(spacing=13.5)
    with pytest.raises(InputError, match="pore_radius"):
        sphere_lattice(pore_radius=[4, 5])


def test_bundle_hagen_poiseuille_value_and_bounds():
    b = cylinder_bundle(radii_vox=(2, 3, 4), axis="y", voxel_size=1e-6, gap=2, length=10)
    assert b.axis == 1 and b.image.shape[1] == 10
    a_box = b.image.shape[0] * b.image.shape[2] * 1e-12
    k = np.sum(np.pi * (np.array([2, 3, 4]) * 1e-6) ** 4 / 8) / a_box  # Hagen-Poiseuille
    assert b.permeability_m2 == pytest.approx(k, rel=1e-14, abs=0)
    lo, hi = b.permeability_bounds_m2
    assert lo < hi and hi == b.permeability_voxel_m2
    # the pixel areas of discs r = 2, 3, 4 are 13, 29, 49 (lattice points within r)
    areas = np.array([13, 29, 49]) * 1e-12
    assert hi == pytest.approx(np.sum(areas**2 / (8 * np.pi)) / a_box, rel=1e-14, abs=0)
    # the section is uniform along the axis and its pore area is the sum of the disc areas
    sec = np.take(b.image.phases, 0, axis=1)
    assert np.all(b.image.phases == sec[:, None, :])
    assert sec.sum() == 13 + 29 + 49
    # the inscribed discs are smaller than the nominal ones, so the lower bound is below the
    # nominal value; the upper bound is not ordered with it: the r = 4 disc digitises to 49 < 16 pi
    assert lo < b.permeability_m2


def test_bundle_tubes_are_separate_and_cross_the_box():
    from scipy import ndimage

    b = cylinder_bundle(radii_vox=(1.5, 2.5, 3), axis="x")
    lab, n = ndimage.label(b.image.phases)
    assert n == 3
    for c in range(1, n + 1):
        assert np.any(lab[0] == c) and np.any(lab[-1] == c)


def test_bundle_rejects_bad_input():
    with pytest.raises(InputError):
        cylinder_bundle(radii_vox=(0.2,))
    with pytest.raises(InputError, match="cannot hold"):
        cylinder_bundle(radii_vox=(4, 4), shape=(8, 8, 8))
