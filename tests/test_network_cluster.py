"""percolating_pores (two-flood, no labels) against percolating_cluster (scipy.ndimage.label)."""

import numpy as np
import pytest

from porefsi.errors import InputError, NetworkError
from porefsi.image.ops import percolating_cluster
from porefsi.image.synthetic import sphere_lattice
from porefsi.image.voxel_image import VoxelImage
from porefsi.network.cluster import percolating_pores


@pytest.mark.parametrize("porosity", [0.3116, 0.35, 0.5])
@pytest.mark.parametrize("axis", ["x", "y", "z"])
def test_same_voxels_as_the_labelling(porosity, axis):
    rng = np.random.default_rng(int(porosity * 1e4))
    img = VoxelImage((rng.random((23, 31, 27)) < porosity).astype(np.uint8), 1e-6)
    try:
        ref = percolating_cluster(img, axis)
    except NetworkError:
        out, removed = percolating_pores(img, axis)
        assert removed == 1.0 and not out.phases.any()
        return
    out, removed = percolating_pores(img, axis)
    np.testing.assert_array_equal(out.phases, ref.image.phases)
    assert removed == ref.removed_fraction
    assert out.voxel_size == img.voxel_size and np.array_equal(out.origin, img.origin)
    assert not out.phases.flags.writeable


def test_cluster_touching_one_face_only_is_removed():
    a = np.zeros((6, 5, 5), np.uint8)
    a[:, 1, 1] = 1  # percolates along x
    a[0:5, 3, 3] = 1  # touches xmin only, one layer short of xmax
    a[1:, 3, 1] = 1  # touches xmax only, one layer short of xmin
    a[2, 1, 3] = 1  # isolated
    out, removed = percolating_pores(VoxelImage(a, 1e-6), "x")
    assert out.phases.sum() == 6 and out.phases[:, 1, 1].all()
    assert removed == pytest.approx(1 - 6 / a.sum())
    out_y, removed_y = percolating_pores(VoxelImage(a, 1e-6), "y")
    assert removed_y == 1.0 and out_y.phases.sum() == 0


def test_lattice_percolates_whole_and_input_untouched():
    img = sphere_lattice(n=(2, 2, 2)).image
    before = img.phases.copy()
    for ax in (0, 1, 2):
        out, removed = percolating_pores(img, ax)
        assert removed == 0.0 and np.array_equal(out.phases, before)
    assert np.array_equal(img.phases, before)


def test_bad_input():
    with pytest.raises(InputError, match="VoxelImage"):
        percolating_pores(np.ones((3, 3, 3), np.uint8), "x")
    with pytest.raises(InputError):
        percolating_pores(sphere_lattice(n=(1, 1, 1)).image, "w")
