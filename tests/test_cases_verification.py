"""The verification case's analytic pieces (cases/verification/analytic.py) and node matching (run.py).

The closed forms are checked against their defining equations (not against themselves), and small
versions of the studies against the claims the docs make about them.
"""

import importlib.util
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

CASE = Path(__file__).resolve().parents[1] / "cases" / "verification"


def _load(name):
    spec = importlib.util.spec_from_file_location(f"verification_{name}", CASE / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    sys.path.insert(0, str(CASE))
    try:
        spec.loader.exec_module(mod)
    finally:
        sys.path.remove(str(CASE))
    return mod


A = _load("analytic")
E, NU, P = 20e9, 0.28, 1e6


def test_lame_solution_satisfies_its_boundary_conditions_and_equilibrium():
    # Timoshenko & Goodier sec. 135: u = A r + B/r^2 solves the radial Navier equation; sigma_rr(a) = -P, u(b) = 0
    a, b = 3e-6, 9e-6
    lam = E * NU / ((1 + NU) * (1 - 2 * NU))
    mu = E / (2 * (1 + NU))
    u = lambda r: A.lame_displacement(r, a, b, P, E, NU)  # noqa: E731
    h = 1e-12
    du = lambda r: (u(r + h) - u(r - h)) / (2 * h)  # noqa: E731
    sigma_rr = (lam + 2 * mu) * du(a) + 2 * lam * u(a) / a
    assert sigma_rr == pytest.approx(-P, rel=1e-5)
    assert abs(u(b)) < 1e-12 * abs(u(a))
    # Navier: d/dr (1/r^2 d(r^2 u)/dr) = 0, i.e. the volumetric strain du/dr + 2u/r is constant
    r = np.linspace(a, b, 7)
    div = du(r) + 2 * u(r) / r
    np.testing.assert_allclose(div, div[0], rtol=1e-5, atol=1e-9 * abs(div).max())


def test_lame_work_grows_with_the_clamped_radius():
    # a larger clamped sphere is more compliant: the cavity work increases with b towards the infinite-medium value
    a = 2e-6
    w = [A.lame_work(a, b, P, E, NU) for b in (3e-6, 6e-6, 1e-4)]
    assert w[0] < w[1] < w[2]
    G = E / (2 * (1 + NU))
    assert w[2] == pytest.approx(P * 4 * math.pi * a**2 * P * a / (4 * G), rel=1e-4, abs=0)  # u(a) = P a / 4G


def test_washburn_time_solves_the_poiseuille_ode():
    # d l/dt = r^2 Pc / (8 mu l) with Pc = 2 sigma cos(theta) / r (Washburn 1921), integrated numerically
    r, sigma, theta, mu = 1e-5, 0.03, 30.0, 1e-3
    pc = 2 * sigma * math.cos(math.radians(theta)) / r
    l_end = 2e-3
    t_end = float(A.washburn_time(l_end, r, sigma, theta, mu))
    sol = solve_ivp(lambda t, y: [r * r * pc / (8 * mu * y[0])], (0.0, t_end), [1e-9], rtol=1e-10, atol=1e-15)
    assert sol.y[0, -1] == pytest.approx(l_end, rel=1e-5)


def test_two_fluid_fill_time_reduces_to_washburn_without_a_defender():
    r, L, sigma, mu = 1e-5, 2e-3, 0.03, 1e-3
    l = np.linspace(1e-4, L, 5)
    pc = 2 * sigma / r
    np.testing.assert_allclose(A.two_fluid_fill_time(l, L, r, mu, 0.0, pc), A.washburn_time(l, r, sigma, 0.0, mu),
                               rtol=1e-12)


def test_fitted_order_of_a_power_law():
    dts = np.array([0.1, 0.05, 0.02])
    assert A.fitted_order(dts, 7.0 * dts**2.5) == pytest.approx(2.5, abs=1e-12)


def test_tdg_study_orders():
    r = A.study_tdg_order()
    assert abs(r["orders"]["TDG 2 passes"] - 3) < 0.15
    assert abs(r["orders"]["TDG 1 pass"] - 2) < 0.15
    assert abs(r["orders"]["Newmark (average acceleration)"] - 2) < 0.15


def test_washburn_study_matches_closed_forms():
    r = A.study_washburn(n_pores=10)
    assert r["max_rel_error_washburn"] < 1e-8
    assert r["max_rel_error_two_fluid"] < 1e-8


def test_ip_study_at_low_ca_reproduces_invasion_percolation():
    r = A.study_ip_limit(cas=(1e-9,), shape=(5, 5, 2), seeds=(3,))
    assert r["prefix_fraction"][0, 0] == 1.0
    assert r["jaccard"][0, 0] == 1.0


def test_lame_study_traction_within_bounds_and_balanced():
    r = A.study_lame(n_cells=(12,))
    lo, hi = r["lame_inscribed_J"][0], r["lame_circumscribed_J"][0]
    assert lo < hi
    assert 0.95 * lo < r["traction_J"][0] < hi  # P1 is stiffer: allowance on the lower bound only
    assert r["traction_resultant"][0] < 1e-12  # consistent traction on a closed cavity


def test_node_matching_by_position():
    run = _load("run")
    rng = np.random.default_rng(0)
    fine = np.array([(i, j, k) for i in range(0, 13, 3) for j in range(0, 13, 3) for k in range(0, 13, 3)])
    coarse = np.array([(i, j, k) for i in range(0, 13, 4) for j in range(0, 13, 4) for k in range(0, 13, 4)])
    u_ref = rng.normal(size=(len(fine), 3))
    idx = {tuple(g): n for n, g in enumerate(fine.tolist())}
    shared = [idx[tuple(g)] for g in coarse.tolist() if tuple(g) in idx]
    assert len(shared) == 8  # grid of lcm(3, 4) = 12 voxels: corners of the 12^3 block
    on_fine = np.array([tuple(g) in idx for g in coarse.tolist()])
    u_c = np.zeros((len(coarse), 3))
    u_c[on_fine] = 1.1 * u_ref[shared]
    ref = {"grid": fine, "u": u_ref, "max_u": 1.0}
    cmp = run.compare(ref, {"c": {"grid": coarse, "u": u_c, "max_u": 1.1, "wall_s": 0, "cpu_s": 0, "n_nodes": 0,
                                  "n_tets": 0}}, n_select=5)
    e = cmp["errors"]["c"]
    assert e["n_shared_nodes"] == 8
    assert e["rel_error_shared"] == pytest.approx(0.1, rel=1e-12)
    assert e["rel_error_selected"] == pytest.approx(0.1, rel=1e-12)
    sel = np.asarray(cmp["selected_grid"])
    assert np.all(sel % 12 == 0)
    mags = np.asarray(cmp["selected_norms"]["reference"])
    assert np.all(np.diff(mags) <= 0)


def test_p2_check_interpolation():
    # the P2 check's field evaluation reproduces the nodal values and any quadratic field exactly (its
    # pore-wall load is the library's P2-consistent traction, tested in test_coupled.py against
    # scikit-fem's facet quadrature)
    from porefsi import load_case, problem_from_case

    run = _load("run")
    case = run.make_p2_case(load_case(CASE / "case.toml"), ("P2 c12", 12, 1.0, "direct"), 1.0)
    p = problem_from_case(case)
    assert p.model.order == 2 and p.interface.operator.shape[0] == p.model.n_full
    mesh = p.mesh
    # interpolation
    xl = (p.model.dof_points - p.image.origin) / p.image.voxel_size
    q = lambda x: np.stack([x[:, 0] ** 2 - x[:, 1], x[:, 1] * x[:, 2], 3.0 - x[:, 2] ** 2], axis=1)  # noqa: E731
    v, out = run.p2_at_points(p, q(xl), xl)
    assert not out.any()
    np.testing.assert_allclose(v, q(xl), rtol=0, atol=1e-9)
    xv = (mesh.points - p.image.origin) / p.image.voxel_size
    inner = 0.6 * xv[mesh.tets].mean(axis=1) + 0.4 * xv[mesh.tets[:, 1]]
    v, out = run.p2_at_points(p, q(xl), inner)
    assert not out.any()
    np.testing.assert_allclose(v, q(inner), rtol=0, atol=1e-8 * np.abs(q(inner)).max())
    far = xv.max(axis=0) + 5.0  # outside the mesh: flagged, value from the closest tetrahedron
    _, out = run.p2_at_points(p, q(xl), far[None, :])
    assert out.all()
