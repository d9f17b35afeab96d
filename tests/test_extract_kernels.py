"""Each numba kernel of the maximal-ball extraction against its naive twin (tests/reference)."""

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy import ndimage

from porefsi.network import _kernels as kern
from porefsi.network.extract import digital_radius
from tests.reference import extract_ref as ref

SETTINGS = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@st.composite
def images(draw, max_side=7, p_min=0.3, p_max=0.9):
    """Small random binary images with at least one solid voxel (distance map defined)."""
    shape = tuple(draw(st.integers(1, max_side)) for _ in range(3))
    p = draw(st.floats(p_min, p_max))
    u = draw(arrays(np.float64, shape, elements=st.floats(0, 1, allow_nan=False)))
    img = (u < p).astype(np.uint8)
    img.reshape(-1)[draw(st.integers(0, img.size - 1))] = 0
    return img


def _edt(img, dtype=np.uint16, cap=None):
    """The distance map as extract_network computes it (uint16 unless a radius reaches 256)."""
    out = np.empty(img.shape, dtype)
    kern._sq_edt(img, out, int(np.iinfo(dtype).max if cap is None else cap))
    return out


@SETTINGS
@given(images(max_side=9))
def test_sq_edt_equals_brute_force_and_scipy(img):
    d = _edt(img)
    want = ref.sq_edt(img)
    np.testing.assert_array_equal(d, want)
    np.testing.assert_array_equal(_edt(img, np.int32), want)
    # independent implementation: scipy measures the distance to the nearest 0 (solid) voxel
    # centre and, like porefsi, does not treat the outside of the array as solid.
    np.testing.assert_array_equal(d, np.rint(ndimage.distance_transform_edt(img) ** 2).astype(np.int64))


@SETTINGS
@given(images(max_side=9, p_min=0.7, p_max=0.95), st.integers(1, 12))
def test_sq_edt_cap_is_exact_below_the_cap(img, cap):
    # the uint16 map caps squared distances; every value below the cap must stay exact
    want = np.minimum(ref.sq_edt(img), cap)
    np.testing.assert_array_equal(_edt(img, np.uint16, cap), want)


@SETTINGS
@given(images(max_side=9, p_min=0.1, p_max=0.9))
def test_pore_solid_faces_equals_twin(img):
    assert int(kern._pore_solid_faces(img)) == ref.pore_solid_faces(img)


def test_sq_edt_line_without_solid_is_inf():
    img = np.ones((3, 1, 1), np.uint8)
    assert np.all(_edt(img, np.int32) == kern.INF)


def _balls(d, min_dt2, half_width=1):
    scratch = np.full(d.shape, -1, np.int32)
    offsets = kern.ball_offsets(half_width)
    off_class, reach2 = kern.ball_reach_table(offsets, int(d.max()))
    out = kern._maximal_balls(d, np.int64(min_dt2), offsets, off_class, reach2, scratch, np.empty(0, np.int64))
    assert np.all(scratch == -1)  # scratch restored
    out32 = kern._maximal_balls(d, np.int64(min_dt2), offsets, off_class, reach2, scratch, np.empty(0, np.int32))
    assert out32[0].dtype == np.int32 and out32[1] == out[1]
    np.testing.assert_array_equal(out32[0], out[0])
    return out


@SETTINGS
@given(images(), st.integers(1, 4), st.sampled_from([1, 2]))
def test_maximal_balls_equal_twin(img, min_dt2, half_width):
    d = _edt(img)
    order, ncand = _balls(d, min_dt2, half_width)
    order_ref, ncand_ref = ref.maximal_balls(d, min_dt2, half_width)
    assert ncand == ncand_ref == int(np.count_nonzero(d >= min_dt2))
    np.testing.assert_array_equal(order, order_ref)


@pytest.mark.parametrize("half_width", [1, 2])
def test_ball_reach_table_equals_brute_force(half_width):
    offsets = kern.ball_offsets(half_width)
    off_class, reach2 = kern.ball_reach_table(offsets, 40)
    for t in range(0, offsets.shape[0], 3):
        for d2 in range(1, 41):
            assert reach2[off_class[t], d2] == ref.ball_reach(tuple(offsets[t]), d2), (offsets[t], d2)


def test_maximal_balls_keep_the_centre_of_a_digital_ball():
    # a voxelised ball of radius 5 in solid: one maximal ball, at its centre; a ball inside a
    # neighbour's ball is dropped even where the continuum test (R_q >= R_p + |q - p|) keeps it
    g = np.indices((15, 15, 15)) - 7
    img = ((g**2).sum(axis=0) <= 25).astype(np.uint8)
    d = _edt(img)
    order, _ = _balls(d, 1)
    assert order[0] == np.ravel_multi_index((7, 7, 7), img.shape)
    assert order.size < np.count_nonzero(img) // 2


@SETTINGS
@given(
    images(max_side=6, p_min=0.6, p_max=0.95),
    st.sampled_from([1.0, 1.5, 2.0, 3.0]),
    st.sampled_from([0.0, 0.9]),
    st.sampled_from([0.0, 0.5, 0.8]),
)
def test_families_equal_twin(img, extent, ratio, core):
    d = _edt(img)
    tab = np.sqrt(np.arange(d.max() + 1, dtype=float))
    balls, _ = _balls(d, 1)
    labels = np.full(img.shape, -1, np.int32)
    master, n_kept = kern._families(d, balls, tab, extent, ratio, labels, core)
    master_ref, labels_ref = ref.families(d, balls, extent, ratio, core)
    np.testing.assert_array_equal(master, master_ref)
    np.testing.assert_array_equal(labels, labels_ref)
    assert n_kept <= balls.size and (core > 0 or n_kept == balls.size)
    # properties: masters are their own master; a master owns its centre voxel
    for k in np.flatnonzero(master == np.arange(balls.size)):
        assert labels.reshape(-1)[balls[k]] == k


@SETTINGS
@given(images(max_side=8, p_min=0.5, p_max=0.95), st.integers(0, 2**32 - 1))
def test_flood_equals_twin(img, seed):
    rng = np.random.default_rng(seed)
    d = _edt(img)
    pores = np.flatnonzero(d.reshape(-1) > 0)
    centres = rng.choice(pores, size=min(len(pores), int(rng.integers(1, 5))), replace=False)
    labels = np.full(img.shape, -1, np.int32)
    labels.reshape(-1)[centres] = np.arange(centres.size)  # one seed voxel per region
    n_work = max(int(np.count_nonzero(img)) - centres.size, 1)
    got = labels.copy()
    n = kern._flood(d, got, np.empty(n_work, np.int32), np.empty(n_work, np.int32))
    want, n_ref = ref.flood(d, labels)
    assert n == n_ref
    np.testing.assert_array_equal(got, want)
    # the growth queue may share the level-sorted list (as extract_network runs it)
    shared = labels.copy()
    buf = np.empty(n_work, np.int32)
    assert kern._flood(d, shared, buf, buf) == n_ref
    np.testing.assert_array_equal(shared, want)
    # solid never labelled; every pore voxel connected to a seed labelled; regions connected
    assert np.all(got[img == 0] == -1)
    lab, _ = ndimage.label(img)
    seeded = np.unique(lab[labels >= 0])
    assert np.all(got[np.isin(lab, seeded) & (img == 1)] >= 0)
    for p in np.unique(got[got >= 0]):
        assert ndimage.label(got == p)[1] == 1


@SETTINGS
@given(st.integers(0, 2**32 - 1), st.tuples(*[st.integers(1, 6)] * 3), st.integers(1, 5))
def test_interfaces_and_pore_stats_equal_twin(seed, shape, n_pores):
    rng = np.random.default_rng(seed)
    labels = rng.integers(-1, n_pores, shape).astype(np.int32)
    dt2 = rng.integers(1, 30, shape).astype(np.uint16)
    conns, w, point, nf = kern._interfaces(labels, dt2, np.int64(n_pores))
    c_ref, w_ref, p_ref, nf_ref = ref.interfaces(labels, dt2)
    np.testing.assert_array_equal(conns.reshape(-1, 2), c_ref)
    np.testing.assert_array_equal(w, w_ref)
    np.testing.assert_array_equal(point.reshape(-1, 3), p_ref)
    np.testing.assert_array_equal(nf, nf_ref)
    assert np.all(conns[:, 0] < conns[:, 1])  # canonical, no self-loops
    count, faces = kern._pore_stats(labels, np.int64(n_pores))
    count_ref, faces_ref = ref.pore_stats(labels, n_pores)
    np.testing.assert_array_equal(count, count_ref)
    np.testing.assert_array_equal(faces, faces_ref)


def test_digital_radius_midpoint_of_lattice_shells():
    # brute-force sums of three squares up to 200
    sums = sorted({a * a + b * b + c * c for a in range(15) for b in range(15) for c in range(15)})
    n = np.arange(1, 200)
    got = digital_radius(n)
    for ni, r in zip(n, got, strict=True):
        prev = max(s for s in sums if s < ni)
        assert r == pytest.approx(0.5 * (math.sqrt(ni) + math.sqrt(prev)), rel=1e-14)
    assert digital_radius(1) == 0.5  # one-voxel channel: half a voxel
    # integer-radius discretised balls: R < r < R + 1/(2R) (sqrt(R^2 + 1) ~ R + 1/(2R))
    R = np.arange(1, 40)
    r = digital_radius(R * R + 1)
    assert np.all((r > R) & (r < R + 0.5 / R))


@SETTINGS
@given(st.integers(0, 2**32 - 1), st.tuples(*[st.integers(1, 6)] * 3), st.integers(1, 6))
def test_relabel_equals_fancy_indexing(seed, shape, n):
    rng = np.random.default_rng(seed)
    labels = rng.integers(-1, n, shape).astype(np.int32)
    table = rng.integers(0, 100, n).astype(np.int32)
    want = np.where(labels >= 0, table[np.maximum(labels, 0)], -1)
    got = labels.copy()
    kern._relabel(got, table)
    np.testing.assert_array_equal(got, want)


def test_isqrt_is_the_integer_square_root():
    for x in list(range(2000)) + [2**31 - 1, 10**12, 10**12 - 1]:
        assert kern._isqrt(x) == math.isqrt(x)


def test_threaded_kernels_do_not_depend_on_the_number_of_threads():
    """The maximal-ball test (slabs on numba's threads) and the throat radii (points on them): one thread
    and all of them give the same arrays to the bit on a blob image."""
    import numba

    from porefsi.network._mb_sections import _stair_section_peaks

    rng = np.random.default_rng(11)
    field = ndimage.gaussian_filter(rng.standard_normal((30, 26, 28)), 1.8)
    img = (field > np.quantile(field, 0.7)).astype(np.uint8)
    d = _edt(img)
    pts = np.argwhere(d > 0)[::7].astype(np.float64)
    pts[::2, 1] += 0.5  # face points (one half-integer coordinate) and voxel points
    walls = np.array([1, 0, 1], np.int64)

    def run():
        return _balls(d, 2, 2)[0], _stair_section_peaks(d, pts, 0.5, 4, walls)

    n = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = run()
    finally:
        numba.set_num_threads(n)
    many = run()
    assert one[0].size > 50 and n >= 1
    for a, b in zip(one, many, strict=True):
        np.testing.assert_array_equal(a, b)
