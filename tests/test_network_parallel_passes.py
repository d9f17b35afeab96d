"""The extraction's threaded whole-image passes against numpy twins, and 1 thread = all threads.

Counting sorts by level (``_flagged_by_level``, ``_sort_by_level``), the interface-face list
(``_interface_faces``), the core unflagging and the parallel fill: each must give exactly the
sequential scan's order, whatever the number of numba threads.
"""

import numba
import numpy as np
import pytest
from scipy import ndimage

from porefsi.network import _mb_balls as mb
from porefsi.network import _mb_regions as mr
from porefsi.network.extract import _distance_map


def _blob(seed, shape=(23, 19, 26), q=0.7):
    rng = np.random.default_rng(seed)
    field = ndimage.gaussian_filter(rng.standard_normal(shape), 1.6)
    return (field > np.quantile(field, q)).astype(np.uint8)


def _one_and_many(run):
    n = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = run()
    finally:
        numba.set_num_threads(n)
    return one, run()


def _by_level_twin(d, flag):
    """Flat indices where ``flag``, by ``d`` descending, then index ascending."""
    idx = np.flatnonzero(flag)
    return idx[np.lexsort((idx, -d.reshape(-1)[idx].astype(np.int64)))]


@pytest.mark.parametrize("seed", [1, 2])
def test_flagged_by_level_matches_twin(seed):
    d = _distance_map(_blob(seed))
    rng = np.random.default_rng(seed)
    flag = (d > 0) & (rng.random(d.shape) < 0.3)

    def run():
        scratch = np.where(flag, -2, -1).astype(np.int32)
        order = mb._flagged_by_level(d, scratch, int(d.max()), np.empty(0, np.int64))
        return order, scratch

    (one, s1), (many, s2) = _one_and_many(run)
    np.testing.assert_array_equal(one, _by_level_twin(d, flag))
    np.testing.assert_array_equal(one, many)
    assert (s1 == -1).all() and (s2 == -1).all()


@pytest.mark.parametrize("seed", [3, 4])
def test_sort_by_level_matches_twin(seed):
    d = _distance_map(_blob(seed))
    lab = np.full(d.shape, -1, np.int32)
    rng = np.random.default_rng(seed)
    seeds = np.flatnonzero(d.reshape(-1) > 0)
    lab.reshape(-1)[rng.choice(seeds, 40, replace=False)] = np.arange(40)
    todo = (lab < 0) & (d > 0)

    def run():
        buf = np.full(int(todo.sum()), -7, np.int64)
        start, top = mr._sort_by_level(d.reshape(-1), lab.reshape(-1), buf)
        return buf, start, top

    (b1, st1, t1), (b2, st2, t2) = _one_and_many(run)
    np.testing.assert_array_equal(b1, _by_level_twin(d, todo))
    top = int(d[lab < 0].max())
    assert t1 == t2 == top
    counts = np.bincount(top - d[todo].astype(np.int64), minlength=top + 2)
    np.testing.assert_array_equal(st1, np.concatenate([[0], np.cumsum(counts)[:-1]]))
    np.testing.assert_array_equal(b1, b2)
    np.testing.assert_array_equal(st1, st2)


def test_interface_faces_match_twin():
    rng = np.random.default_rng(5)
    lab = rng.integers(-1, 4, (17, 13, 15)).astype(np.int32)
    codes = []
    for ax in range(3):
        lo = [slice(None)] * 3
        hi = [slice(None)] * 3
        lo[ax], hi[ax] = slice(0, -1), slice(1, None)
        a, b = lab[tuple(lo)], lab[tuple(hi)]
        ijk = np.argwhere((a >= 0) & (b >= 0) & (a != b))
        codes.append(np.ravel_multi_index(ijk.T, lab.shape) * 3 + ax)
    twin = np.sort(np.concatenate(codes))  # C order of the lower voxel, then the axis
    one, many = _one_and_many(lambda: mr._interface_faces(lab))
    np.testing.assert_array_equal(one, twin)
    np.testing.assert_array_equal(many, twin)


def test_unflag_and_fill():
    rng = np.random.default_rng(6)
    lab = rng.integers(-9, 9, (7, 5, 6)).astype(np.int32)
    want = np.where(lab <= -2, -2 - lab, lab)
    mb._unflag(lab)
    np.testing.assert_array_equal(lab, want)
    mb._fill(lab, -1)
    assert (lab == -1).all()
