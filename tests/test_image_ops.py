"""crop, downsample and percolating_cluster on hand-built images with exact answers."""

from collections import deque

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from porefsi.errors import InputError, NetworkError
from porefsi.image import VoxelImage, crop, downsample, load_sample, percolating_cluster

VS = 2e-6


def _img(a, origin=(0.0, 0.0, 0.0)):
    return VoxelImage(np.asarray(a, dtype=np.uint8), VS, np.asarray(origin, dtype=float))


# ------------------------------------------------------------------------------------------
# crop
# ------------------------------------------------------------------------------------------
def test_crop_values_and_physical_positions(rng):
    a = (rng.random((6, 7, 8)) < 0.5).astype(np.uint8)
    img = _img(a, origin=(1e-3, -2e-3, 0.5e-3))
    before = img.phases.copy()
    c = crop(img, (1, 2, 3), (5, 7, 6))
    np.testing.assert_array_equal(c.phases, a[1:5, 2:7, 3:6])
    assert c.voxel_size == img.voxel_size
    # every kept voxel has the same centre in space as before
    ijk = np.argwhere(np.ones(c.shape, bool))
    np.testing.assert_allclose(c.voxel_centres(ijk), img.voxel_centres(ijk + [1, 2, 3]), rtol=0, atol=1e-18)
    np.testing.assert_array_equal(img.phases, before)
    assert not np.shares_memory(c.phases, img.phases)


def test_crop_none_means_full_extent(rng):
    a = (rng.random((3, 4, 5)) < 0.5).astype(np.uint8)
    c = crop(_img(a), (None, 1, None), (None, None, 2))
    np.testing.assert_array_equal(c.phases, a[:, 1:, :2])
    np.testing.assert_array_equal(crop(_img(a), None, None).phases, a)


@pytest.mark.parametrize(
    ("start", "stop", "fragment"),
    [
        ((0, 0, 0), (5, 4, 4), "crop [0, 5) along x is outside the image or empty: need 0 <= start < stop <= 4"),
        ((2, 0, 0), (2, 4, 4), "along x"),
        ((0, -1, 0), (4, 4, 4), "along y"),
        ((0, 0, 3), (4, 4, 2), "along z"),
        ((0, 0), (4, 4, 4), "3 voxel indices"),
        ((0, 0, 0.5), (4, 4, 4), "integers"),
        ((0, 0, True), (4, 4, 4), "integers"),
    ],
)
def test_crop_bad_bounds(start, stop, fragment):
    with pytest.raises(InputError) as info:
        crop(_img(np.ones((4, 4, 4))), start, stop)
    assert fragment in str(info.value)


# ------------------------------------------------------------------------------------------
# downsample
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("factor", [1, 2, 3])
def test_downsample_of_a_block_pattern_is_the_pattern(rng, factor):
    coarse = (rng.random((3, 4, 2)) < 0.5).astype(np.uint8)
    fine = np.kron(coarse, np.ones((factor,) * 3, np.uint8))
    img = _img(fine, origin=(1e-4, 0, -1e-4))
    for t in (1e-9, 0.5, 1.0):  # a pure block is 0 or 1: any threshold gives the pattern back
        d = downsample(img, factor, threshold=t)
        np.testing.assert_array_equal(d.phases, coarse)
        assert d.voxel_size == VS * factor
        np.testing.assert_array_equal(d.origin, img.origin)


def test_downsample_threshold_edges():
    """One 2x2x2 block with k pore voxels: pore iff k/8 >= threshold, exactly at the edge."""
    for k in range(9):
        a = np.zeros(8, np.uint8)
        a[:k] = 1
        img = _img(a.reshape(2, 2, 2))
        for t in (0.125, 0.25, 0.375, 0.5, 0.625, 0.75, 0.875, 1.0):
            assert downsample(img, 2, threshold=t).phases.item() == int(k / 8 >= t), (k, t)
    # 0.1 means 1/10 (the float 0.1 is a bit above 1/10): 100 of 1000 pore voxels reach it, 99 do not
    for t in (0.1, 0.3, 0.7):
        for k, expect in ((round(t * 1000), 1), (round(t * 1000) - 1, 0)):
            b = np.zeros(1000, np.uint8)
            b[:k] = 1
            assert downsample(_img(b.reshape(10, 10, 10)), 10, threshold=t).phases.item() == expect, (t, k)


def test_downsample_trims_the_high_side_and_keeps_positions():
    a = np.zeros((5, 4, 3), np.uint8)
    a[4] = 1  # the trimmed layer along x: must not leak into the result
    a[0:2, 0:2, 0:2] = 1
    img = _img(a, origin=(3e-6, 0, 0))
    before = img.phases.copy()
    d = downsample(img, 2)
    assert d.shape == (2, 2, 1)
    assert d.phases.tolist() == [[[1], [0]], [[0], [0]]]
    # coarse voxel (I, J, K) covers fine voxels 2I..2I+1: same box in space
    np.testing.assert_allclose(d.voxel_centres([[1, 1, 0]]), img.voxel_centres([[2.5, 2.5, 0.5]]), atol=1e-18)
    np.testing.assert_array_equal(img.phases, before)


@pytest.mark.parametrize(
    ("factor", "threshold", "fragment"),
    [
        (0, 0.5, "positive integer"),
        (1.5, 0.5, "positive integer"),
        (True, 0.5, "positive integer"),
        (5, 0.5, "larger than the image shape"),
        (2, 0.0, "in (0, 1]"),
        (2, 1.2, "in (0, 1]"),
        (2, float("nan"), "in (0, 1]"),
    ],
)
def test_downsample_bad_arguments(factor, threshold, fragment):
    with pytest.raises(InputError) as info:
        downsample(_img(np.ones((4, 4, 4))), factor, threshold=threshold)
    assert fragment in str(info.value)


# ------------------------------------------------------------------------------------------
# percolating cluster
# ------------------------------------------------------------------------------------------
def _rock():
    """A 9x7x7 box: a channel along x with a side branch, a dead-end pocket at the inlet, a blob."""
    a = np.zeros((9, 7, 7), np.uint8)
    a[:, 1, 1] = 1  # channel spanning x: 9 voxels
    a[4, 2:5, 1] = 1  # side branch of the channel (connected to it): 3 voxels, kept
    a[0:3, 5, 5] = 1  # pocket touching only the xmin face: 3 voxels, removed
    a[5:7, 4:6, 4] = 1  # isolated blob: 4 voxels, removed
    return a


def test_percolating_cluster_removes_pocket_and_blob_exactly():
    img = _img(_rock(), origin=(1e-5, 2e-5, 3e-5))
    before = img.phases.copy()
    r = percolating_cluster(img, "x")
    expect = np.zeros_like(before)
    expect[:, 1, 1] = 1
    expect[4, 2:5, 1] = 1
    np.testing.assert_array_equal(r.image.phases, expect)
    assert r.removed_fraction == 7 / 19  # (3 + 4) of 19 pore voxels
    assert (r.n_clusters, r.n_percolating) == (3, 1)
    assert r.image.voxel_size == img.voxel_size
    np.testing.assert_array_equal(r.image.origin, img.origin)
    np.testing.assert_array_equal(img.phases, before)


def test_no_percolation_names_axis_and_fix():
    with pytest.raises(NetworkError, match=r"ymin and ymax faces \(axis y.*another axis, a larger crop"):
        percolating_cluster(_img(_rock()), "y")
    with pytest.raises(InputError, match="unknown axis"):
        percolating_cluster(_img(_rock()), "w")
    with pytest.raises(InputError, match="6, 18 or 26"):
        percolating_cluster(_img(_rock()), 0, connectivity=8)


def test_connectivity_edge_and_corner_contacts():
    edge = np.zeros((2, 2, 1), np.uint8)
    edge[0, 0, 0] = edge[1, 1, 0] = 1  # voxels sharing only an edge
    with pytest.raises(NetworkError):
        percolating_cluster(_img(edge), "x")
    assert percolating_cluster(_img(edge), "x", connectivity=18).removed_fraction == 0
    corner = np.zeros((2, 2, 2), np.uint8)
    corner[0, 0, 0] = corner[1, 1, 1] = 1  # sharing only a corner
    with pytest.raises(NetworkError):
        percolating_cluster(_img(corner), "x", connectivity=18)
    assert percolating_cluster(_img(corner), "x", connectivity=26).n_percolating == 1


def _reach(pore, seeds):
    """Naive 6-connected flood fill (breadth first) from seed voxels: an independent twin of label."""
    seen = np.zeros_like(pore, dtype=bool)
    q = deque(tuple(s) for s in seeds)
    for s in q:
        seen[s] = True
    while q:
        i, j, k = q.popleft()
        for d in ((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)):
            n = (i + d[0], j + d[1], k + d[2])
            if all(0 <= n[m] < pore.shape[m] for m in range(3)) and pore[n] and not seen[n]:
                seen[n] = True
                q.append(n)
    return seen


@settings(max_examples=60, deadline=None)
@given(
    a=arrays(np.uint8, st.tuples(*[st.integers(1, 6)] * 3), elements=st.integers(0, 1)),
    axis=st.integers(0, 2),
)
def test_percolating_cluster_equals_flood_fill_from_both_faces(a, axis):
    """Kept voxels = reachable from the inlet face AND from the outlet face (6-connectivity)."""
    pore = a.astype(bool)
    idx = np.argwhere(pore)
    n = a.shape[axis] - 1
    kept = _reach(pore, idx[idx[:, axis] == 0]) & _reach(pore, idx[idx[:, axis] == n])
    if not kept.any():
        with pytest.raises(NetworkError):
            percolating_cluster(_img(a), axis)
        return
    r = percolating_cluster(_img(a), axis)
    np.testing.assert_array_equal(r.image.phases.astype(bool), kept)
    assert r.removed_fraction == (pore.sum() - kept.sum()) / pore.sum()


def test_builtin_sample_percolating_cluster():
    """The data README states the largest cluster of the sample is 18.45 % of the volume and that
    it percolates on all three axes; with 6-connectivity that cluster is the percolating one."""
    img = load_sample()
    for axis in "xyz":
        r = percolating_cluster(img, axis)
        assert r.n_percolating == 1
        assert r.image.porosity == pytest.approx(0.1845, abs=5e-5)
        assert r.removed_fraction == pytest.approx(1 - r.image.porosity / img.porosity, rel=1e-12)
