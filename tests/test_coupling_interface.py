"""Pore-pressure -> nodal-force operators: kernels vs twins, load balance, invariances."""

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from porefsi.coupling import (
    _kernels,
    boundary_facet_normals,
    facet_pores_from_labels,
    hull_interface,
    hull_members,
    sphere_test_points,
    traction_interface,
)
from porefsi.errors import InputError
from tests.reference.coupling_ref import hull_members_ref, nearest_member_ref


def _grid(n, lo=0.0, hi=1.0):
    g = np.linspace(lo, hi, n)
    return np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)


def _pores(rng, n):
    return rng.uniform(0.2, 0.8, (n, 3)), rng.uniform(0.04, 0.12, n)


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n_pores=st.integers(1, 6), eps=st.floats(0.0, 0.08))
def test_hull_members_equal_brute_force(seed, n_pores, eps):
    rng = np.random.default_rng(seed)
    x = rng.uniform(0, 1, (400, 3))
    c, r = _pores(rng, n_pores)
    n = 30
    unit = sphere_test_points(n * n_pores, rng).reshape(n_pores, n, 3)
    tp = (c[:, None] + r[:, None, None] * unit).reshape(-1, 3)
    ptr = np.arange(n_pores + 1) * n
    eps_a = np.full(n_pores, eps)
    mptr, nodes = hull_members(x, c, r, tp, ptr, eps_a)
    ref = hull_members_ref(x, c, r, tp, ptr, eps_a)
    for i in range(n_pores):
        np.testing.assert_array_equal(nodes[mptr[i]:mptr[i + 1]], ref[i])
    near = _kernels._nearest_member(tp, ptr, mptr, nodes, x)
    np.testing.assert_array_equal(near, nearest_member_ref(tp, ptr, mptr, nodes, x))


def test_sphere_points_are_uniform(rng):
    """The distribution itself, not only its moments (which any symmetric sampler matches).

    Uniform on the unit sphere <=> each coordinate is uniform on [-1, 1] (Archimedes' hat-box
    theorem) and the azimuth about it is uniform on [-pi, pi), independently; the joint test bins
    the points into 8 x 16 equal-area (z, azimuth) cells. A normalised-cube sampler (uniform in
    [-1, 1]^3, divided by the norm) has moments 0 and 1/3 too, but its coordinates sit a KS
    distance of 0.033 from uniform (measured, 1e6 points), nearly three times the 1e-6-level KS
    critical value at n = 50 000 (0.012): KS p ~ 1e-47..1e-68 (planted in the library: 1.5e-57)
    and chi-square ~5300 on 127 degrees of freedom (p = 0), against p = 0.27..0.97 and chi-square
    110-131 for the Gaussian sampler (seeds 0-2).
    """
    p = sphere_test_points(50_000, rng)
    np.testing.assert_allclose(np.linalg.norm(p, axis=1), 1.0, rtol=1e-14)
    assert np.all(np.abs(p.mean(axis=0)) < 1e-2)
    np.testing.assert_allclose((p**2).mean(axis=0), 1 / 3, atol=1e-2)
    for k in range(3):
        assert stats.kstest(p[:, k], stats.uniform(loc=-1.0, scale=2.0).cdf).pvalue > 1e-6, k
    phi = np.arctan2(p[:, 1], p[:, 0])
    assert stats.kstest(phi, stats.uniform(loc=-np.pi, scale=2 * np.pi).cdf).pvalue > 1e-6
    iz = np.minimum(((p[:, 2] + 1.0) / 2.0 * 8).astype(int), 7)  # equal z-bands are equal areas
    ip = np.minimum(((phi + np.pi) / (2 * np.pi) * 16).astype(int), 15)
    counts = np.bincount(16 * iz + ip, minlength=128)
    assert stats.chisquare(counts).pvalue > 1e-6


def test_hull_load_balance_is_exact(rng):
    """Force magnitudes handed to the nodes of a pore add up to P * 4 pi r^2 (paper eq. 2.25)."""
    x = _grid(31)
    c, r = _pores(rng, 12)
    itf = hull_interface(c, r, x, n_test_points=400, tolerance=0.05, rng=rng)
    assert itf.n_unloaded == 0
    p = rng.uniform(1e3, 1e5, len(c))
    assert itf.load_balance_error(p) < 1e-12
    np.testing.assert_allclose(itf.handed_area, 4 * np.pi * r**2, rtol=1e-12)
    # Each nodal force of a pore points from the pore centre towards the node.
    f = itf.operator[:, [0]].toarray().reshape(-1, 3)
    nodes = itf.pore_nodes[0]
    d = x[nodes] - c[0]
    cos = np.einsum("ij,ij->i", f[nodes], d) / (np.linalg.norm(f[nodes], axis=1) * np.linalg.norm(d, axis=1))
    np.testing.assert_allclose(cos, 1.0, atol=1e-12)


def test_hull_zero_pressure_zero_force(rng):
    x = _grid(21)
    c, r = _pores(rng, 5)
    itf = hull_interface(c, r, x, n_test_points=100, tolerance=0.05, rng=rng)
    assert np.all(itf.nodal_forces(np.zeros(5)) == 0)


def test_hull_invariant_to_pore_renumbering():
    x = _grid(25)
    c, r = _pores(np.random.default_rng(3), 8)
    perm = np.random.default_rng(4).permutation(8)
    a = hull_interface(c, r, x, n_test_points=200, tolerance=0.04, rng=np.random.default_rng(7))
    b = hull_interface(c[perm], r[perm], x, n_test_points=200, tolerance=0.04, rng=np.random.default_rng(7))
    np.testing.assert_allclose(b.operator.toarray(), a.operator.toarray()[:, perm], rtol=0, atol=1e-15)


def test_hull_more_tolerance_more_nodes(rng):
    x = _grid(25)
    c, r = _pores(rng, 4)
    seeds = [hull_interface(c, r, x, n_test_points=200, tolerance=e, rng=np.random.default_rng(1))
             for e in (0.0, 0.03, 0.06)]
    counts = [sum(len(n) for n in s.pore_nodes) for s in seeds]
    assert counts[0] <= counts[1] <= counts[2] and counts[2] > counts[0]


def test_hull_bad_input(rng):
    with pytest.raises(InputError, match="test points"):
        hull_interface(np.zeros((1, 3)), np.ones(1), np.zeros((3, 3)), n_test_points=3, rng=rng)
    with pytest.raises(InputError, match="radii"):
        hull_interface(np.zeros((1, 3)), -np.ones(1), np.zeros((3, 3)), rng=rng)
    with pytest.raises(InputError, match="tolerance"):
        hull_interface(np.zeros((1, 3)), np.ones(1), np.zeros((3, 3)), tolerance=-1.0, rng=rng)


def _block_with_cavity(n=6, hole=(2, 4)):
    """Structured tet mesh of the unit cube minus a cubic cavity of cells hole[0]:hole[1]."""
    skfem = pytest.importorskip("skfem")
    g = np.linspace(0, 1, n + 1)
    m = skfem.MeshTet.init_tensor(g, g, g)
    p, t = m.p.T.copy(), m.t.T.copy()
    cen = p[t].mean(axis=1)
    h = 1.0 / n
    lo, hi = hole[0] * h, hole[1] * h
    keep = ~np.all((cen > lo) & (cen < hi), axis=1)
    t = t[keep]
    faces = np.concatenate([t[:, [1, 2, 3]], t[:, [0, 2, 3]], t[:, [0, 1, 3]], t[:, [0, 1, 2]]])
    faces = np.sort(faces, axis=1)
    u, cnt = np.unique(faces, axis=0, return_counts=True)
    bnd = u[cnt == 1]
    fc = p[bnd].mean(axis=1)
    inner = np.all((fc > lo - 1e-12) & (fc < hi + 1e-12), axis=1)
    return p, t, bnd[inner], lo, hi


def test_traction_closed_cavity_zero_resultant_and_projected_area(rng):
    p, t, cav, lo, hi = _block_with_cavity()
    nrm, area = boundary_facet_normals(p, t, cav)
    np.testing.assert_allclose(area.sum(), 6 * (hi - lo) ** 2, rtol=1e-12)
    # Outward from the solid = into the cavity: normals point towards the cavity centre.
    mid = 0.5 * (lo + hi)
    assert np.all(np.einsum("ij,ij->i", nrm, mid - p[cav].mean(axis=1)) > 0)
    itf = traction_interface(p, t, cav, np.zeros(len(cav), int), 1)
    P = 2.5e4
    f = itf.nodal_forces([P])
    assert itf.load_balance_error([P]) < 1e-14
    # closed cavity: the pressure load has no resultant, and the interface knows it
    assert np.linalg.norm(f.sum(axis=0)) < 1e-13 * P * area.sum()
    assert np.linalg.norm(itf.wall_vector) < 1e-13 * area.sum()
    # The cavity pushes its +x wall towards +x with force P * (wall area).
    on_xhi = np.isclose(p[:, 0], hi) & np.all((p[:, 1:] >= lo - 1e-12) & (p[:, 1:] <= hi + 1e-12), axis=1)
    face = np.isclose(p[cav].mean(axis=1)[:, 0], hi)
    nodes = np.unique(cav[face])
    assert on_xhi[nodes].all()
    fx = f[nodes, 0].sum()
    # Edge/corner nodes are shared with neighbouring walls, whose loads have no x component.
    np.testing.assert_allclose(fx, P * (hi - lo) ** 2, rtol=1e-12)


def test_traction_open_pore_resultant_and_load_balance():
    """A pore open on one side (its +x wall is a throat opening, not solid) pushes the solid
    towards -x with P * (opening area); the load-balance check compares each pore's assembled
    resultant with that facet integral and stays at round-off."""
    p, t, cav, lo, hi = _block_with_cavity()
    open_x = np.isclose(p[cav].mean(axis=1)[:, 0], hi)
    fp = np.where(open_x, -1, 0)
    itf = traction_interface(p, t, cav, fp, 1)
    P = 2.5e4
    np.testing.assert_allclose(itf.nodal_forces([P]).sum(axis=0), [-P * (hi - lo) ** 2, 0, 0],
                               atol=1e-12 * P)
    np.testing.assert_allclose(itf.wall_vector[0], [-(hi - lo) ** 2, 0, 0], atol=1e-14)
    assert itf.load_balance_error([P]) < 1e-14
    # an assembly defect (one nodal load component doubled) is caught
    bad = itf.operator.tolil()
    row = int(np.flatnonzero(bad[:, 0].toarray().ravel())[0])
    bad[row, 0] = 2 * bad[row, 0]
    broken = dataclasses.replace(itf, operator=bad.tocsr())
    assert broken.load_balance_error([P]) > 1e-3


def test_facet_pores_from_labels_walks_into_the_pore():
    p, t, cav, lo, hi = _block_with_cavity(n=6, hole=(2, 4))
    nrm, _ = boundary_facet_normals(p, t, cav)
    vox = 1.0 / 12
    lab = -np.ones((12, 12, 12), np.int32)
    lab[4:8, 4:8, 4:8] = 3
    got = facet_pores_from_labels(p, cav, nrm, lab, vox)
    assert np.all(got == 3)


def test_traction_bad_input():
    p, t, cav, _, _ = _block_with_cavity()
    with pytest.raises(InputError, match="facet_pore"):
        traction_interface(p, t, cav, np.zeros(len(cav) + 1, int), 1)
    with pytest.raises(InputError, match="pores"):
        traction_interface(p, t, cav, np.full(len(cav), 5), 2)


def test_hull_with_throat_forces_balances_and_pushes_radially(rng):
    """The throat-wall switch: each cylinder hands P_t 2 pi r L to nodes, normal to its axis,
    half booked to each end pore; the load balance stays exact."""
    x = _grid(31)
    c = np.array([[0.3, 0.5, 0.5], [0.7, 0.5, 0.5]])
    r = np.array([0.08, 0.08])
    ends = np.array([[[0.38, 0.5, 0.5], [0.62, 0.5, 0.5]]])
    itf = hull_interface(c, r, x, n_test_points=400, tolerance=0.04, rng=np.random.default_rng(0),
                         throats=(np.array([[0, 1]]), np.array([0.05]), ends))
    a_t = 2 * np.pi * 0.05 * 0.24
    np.testing.assert_allclose(itf.wall_area, 4 * np.pi * r**2 + a_t / 2, rtol=1e-12)
    p = np.array([2.0e4, 1.0e4])
    assert itf.load_balance_error(p) < 1e-12
    plain = hull_interface(c, r, x, n_test_points=400, tolerance=0.04, rng=np.random.default_rng(0))
    # Same seed: the sphere test points come first, so the difference is the throat's load alone.
    extra = itf.nodal_forces(p) - plain.nodal_forces(p)
    assert np.abs(extra[:, 0]).max() < 1e-12 * np.abs(extra).max()  # normal to the x-axis throat
    np.testing.assert_allclose(np.linalg.norm(extra, axis=1).sum(), p.mean() * a_t, rtol=1e-12)
    with pytest.raises(InputError):
        hull_interface(c, r, x, n_test_points=2, rng=rng, throats=(np.array([[0, 1]]), [0.05], ends))
