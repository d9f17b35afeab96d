"""TDG (Norsett predictor-corrector) against exact solutions, its literal twin and the exact TDG oracle."""

import math
from collections import deque

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.integrate import solve_ivp

from porefsi.errors import ConvergenceError, InputError
from porefsi.integrators import (
    ALPHA,
    LAMBDA,
    LinearSystem,
    TDGExactStepper,
    TDGStepper,
    effective_loads,
    integrate,
)
from tests.reference.integrators_ref import paper_tdg_step


def run(stepper, u0, v0, t_end):
    return deque(integrate(stepper, u0, v0, 0.0, t_end), maxlen=1)[0]


def slope(dts, errs):
    return np.polyfit(np.log(dts), np.log(errs), 1)[0]


# --- exact solutions -------------------------------------------------------------------------
W = 3.0  # rad/s


def free_exact(t):
    """u'' + W^2 u = 0, u(0)=1, v(0)=0.5: u = cos Wt + 0.5/W sin Wt."""
    return math.cos(W * t) + 0.5 / W * math.sin(W * t), -W * math.sin(W * t) + 0.5 * math.cos(W * t)


OMF = 1.7  # forcing frequency


def forced_exact(t):
    """u'' + W^2 u = sin(OMF t), u(0)=v(0)=0 (undamped forced oscillator, Thomson & Dahleh eq. 3.1)."""
    c = 1.0 / (W * W - OMF * OMF)
    u = c * (math.sin(OMF * t) - OMF / W * math.sin(W * t))
    v = c * OMF * (math.cos(OMF * t) - math.cos(W * t))
    return u, v


def two_dof():
    """Coupled 2-dof chain with widely separated frequencies (~1 and ~100 rad/s)."""
    M = np.array([1.0, 1e-2])
    K = np.array([[1.0 + 1e2, -1e2], [-1e2, 1e2]])
    return M, K


def two_dof_exact(M, K, u0, v0, t):
    """Modal superposition (generalized eigenproblem K x = w^2 M x)."""
    d = 1 / np.sqrt(M)
    lam, Q = np.linalg.eigh(d[:, None] * K * d[None, :])
    w = np.sqrt(lam)
    q0, p0 = Q.T @ (u0 / d), Q.T @ (v0 / d)
    q = q0 * np.cos(w * t) + p0 / w * np.sin(w * t)
    p = -q0 * w * np.sin(w * t) + p0 * np.cos(w * t)
    return d * (Q @ q), d * (Q @ p)


@pytest.mark.parametrize("n_iter, order", [(1, 2), (2, 3)])
def test_order_free_oscillator(n_iter, order):
    sys = LinearSystem(np.array([1.0]), np.array([[W * W]]))
    dts = [0.1, 0.05, 0.025, 0.0125]
    ue, ve = free_exact(2.0)
    errs = []
    for dt in dts:
        _, u, v = run(TDGStepper(sys, dt, n_iter=n_iter), [1.0], [0.5], 2.0)
        errs.append(math.hypot(u[0] - ue, (v[0] - ve) / W))
    assert abs(slope(dts, errs) - order) < 0.15


@pytest.mark.parametrize("n_iter, order", [(1, 2), (2, 3)])
def test_order_forced_oscillator(n_iter, order):
    sys = LinearSystem(np.array([1.0]), np.array([[W * W]]), load=lambda t: np.array([math.sin(OMF * t)]))
    dts = [0.1, 0.05, 0.025, 0.0125]
    ue, ve = forced_exact(2.0)
    errs = []
    for dt in dts:
        _, u, v = run(TDGStepper(sys, dt, n_iter=n_iter), [0.0], [0.0], 2.0)
        errs.append(math.hypot(u[0] - ue, (v[0] - ve) / W))
    assert abs(slope(dts, errs) - order) < 0.15


@pytest.mark.parametrize("n_iter, order", [(1, 2), (2, 3)])
def test_order_stiff_two_dof(n_iter, order):
    """Slow-mode accuracy in the asymptotic range (omega_max dt <= 0.8) of a stiff 2-dof chain."""
    M, K = two_dof()
    sys = LinearSystem(M, K)
    u0, v0 = np.array([1.0, 1.0]), np.array([0.0, 0.0])
    dts = [0.008, 0.004, 0.002, 0.001]
    ue, ve = two_dof_exact(M, K, u0, v0, 0.4)
    errs = []
    for dt in dts:
        _, u, v = run(TDGStepper(sys, dt, n_iter=n_iter, make_solver=None), u0, v0, 0.4)
        errs.append(np.linalg.norm(np.concatenate([u - ue, (v - ve) / 100.0])))
    assert abs(slope(dts, errs) - order) < 0.15


def test_matches_literal_paper_equations(rng):
    """Residual form == eqs 2.18-2.24 transcribed line by line (linear system, forced), to round-off."""
    n = 5
    A = rng.standard_normal((n, n))
    K = A @ A.T + n * np.eye(n)
    Md = rng.uniform(0.5, 2.0, n)
    f = lambda t: np.sin(2 * t + np.arange(n)) + t  # noqa: E731
    sys = LinearSystem(Md, K, load=f)
    u, v = rng.standard_normal(n), rng.standard_normal(n)
    for n_iter in (1, 2, 3):
        u1, v1, info = TDGStepper(sys, 0.3, n_iter=n_iter).step(u, v, 0.7)
        u2, v2 = paper_tdg_step(np.diag(Md), K, f, u, v, 0.7, 0.3, n_iter=n_iter)
        assert np.allclose(u1, u2, rtol=1e-12, atol=1e-12) and np.allclose(v1, v2, rtol=1e-12, atol=1e-12)
        assert info.n_solves == 2 * n_iter


def test_iterations_converge_to_exact_tdg_linear(rng):
    """|TDG(l passes) - exact TDG| shrinks geometrically with l (Norsett iteration is a contraction)."""
    M, K = two_dof()
    sys = LinearSystem(M, K, load=lambda t: np.array([np.cos(t), 0.0]))
    u0, v0 = np.array([1.0, -1.0]), np.array([0.3, 0.0])
    dt = 0.01  # omega_max dt ~ 1.4
    ue, ve, _ = TDGExactStepper(sys, dt).step(u0, v0, 0.2)
    diffs = []
    for n_iter in range(1, 9):
        u, v, _ = TDGStepper(sys, dt, n_iter=n_iter).step(u0, v0, 0.2)
        diffs.append(np.linalg.norm(np.concatenate([u - ue, dt * (v - ve)])))
    ratios = np.array(diffs[1:]) / np.array(diffs[:-1])
    assert np.all(ratios < 0.5)
    u, v, info = TDGStepper(sys, dt, n_iter=200, rtol=1e-14).step(u0, v0, 0.2)
    assert np.allclose(u, ue, rtol=1e-11, atol=1e-13) and np.allclose(v, ve, rtol=1e-11, atol=1e-13)
    assert info.converged


def test_exact_tdg_is_pade_12_and_order_3():
    """The DG oracle reproduces R(z) = (1+z/3)/(1-2z/3+z^2/6) (independent derivation) and order 3."""
    sys = LinearSystem(np.array([1.0]), np.array([[W * W]]))
    dts = [0.1, 0.05, 0.025]
    ue, _ = free_exact(2.0)
    errs = [abs(run(TDGExactStepper(sys, dt), [1.0], [0.5], 2.0)[1][0] - ue) for dt in dts]
    assert abs(slope(dts, errs) - 3) < 0.15


class Duffing:
    """Forced 2-dof Duffing chain: f_int = k u + c u^3 + C u (hardening springs)."""

    n_dofs = 2

    def __init__(self):
        self.k, self.c = np.array([4.0, 30.0]), np.array([3.0, 1.0])
        self.C = sp.csr_matrix([[0.0, 0.5], [0.5, 0.0]])

    def mass(self):
        return np.array([1.0, 2.0])

    def internal_force(self, u, t):
        return self.k * u + self.c * u**3 + self.C @ u

    def tangent(self, u, t):
        return sp.diags(self.k + 3 * self.c * u**2).tocsr() + self.C

    def external_force(self, t):
        return np.array([np.sin(3 * t), np.cos(t)])


def duffing_reference(sys, y0, t_end):
    def rhs(t, y):
        u, v = y[:2], y[2:]
        return np.concatenate([v, (sys.external_force(t) - sys.internal_force(u, t)) / sys.mass()])

    return solve_ivp(rhs, (0, t_end), y0, method="DOP853", rtol=1e-13, atol=1e-13).y[:, -1]


def test_duffing_order_3_and_converged_iteration_is_nonlinear_tdg():
    sys = Duffing()
    y0 = np.array([1.0, 0.5, 0.0, 0.3])
    ref = duffing_reference(sys, y0, 2.0)
    dts = [0.1, 0.05, 0.025, 0.0125]
    errs = []
    for dt in dts:
        _, u, v = run(TDGStepper(sys, dt, n_iter=2), y0[:2], y0[2:], 2.0)
        errs.append(np.linalg.norm(np.concatenate([u, v]) - ref))
    assert abs(slope(dts, errs) - 3) < 0.15
    # fixed point of the corrector == Newton-solved nonlinear DG step (independent derivation)
    u0, v0 = y0[:2], y0[2:]
    ue, ve, _ = TDGExactStepper(sys, 0.05).step(u0, v0, 0.1)
    u, v, _ = TDGStepper(sys, 0.05, n_iter=100, rtol=1e-14).step(u0, v0, 0.1)
    assert np.allclose(u, ue, rtol=0, atol=1e-12) and np.allclose(v, ve, rtol=0, atol=1e-12)


def test_literal_nonlinear_reading_of_paper_is_only_second_order():
    """Why porefsi evaluates the TDG residual: eq. 2.18 read as M* vbar = F - f_int(u_tilde) is order 2.

    Its fixed point is the Runge-Kutta method of the Norsett stage basis (c = (alpha*, 1)), for
    which b^T c^2 = 0.3536 != 1/3 (docs/time_integration.md); the TDGStepper on the same problem
    is third order (test above). Asymptotic range checked: successive error ratios 4.06, 3.92, 3.94.
    """
    sys = Duffing()
    y0 = np.array([1.0, 0.5, 0.0, 0.3])
    ref = duffing_reference(sys, y0, 1.0)
    dts = [0.01, 0.005, 0.0025, 0.00125]
    errs = []
    for dt in dts:
        u, v, t = y0[:2], y0[2:], 0.0
        for _ in range(round(1.0 / dt)):
            K = sys.tangent(u, t).toarray()
            u, v = paper_tdg_step(np.diag(sys.mass()), K, sys.external_force, u, v, t, dt, n_iter=2,
                                  fint=lambda x: sys.internal_force(x, 0.0))
            t += dt
        errs.append(np.linalg.norm(np.concatenate([u, v]) - ref))
    assert abs(slope(dts, errs) - 2) < 0.15


def test_effective_loads_are_interpolant_at_stage_abscissae():
    """F0 = load at t + alpha* dt, F1 = extrapolation to t + dt (exact for a linear load in time)."""
    f = lambda s: 2.0 - 5.0 * s  # noqa: E731
    dt, t = 0.3, 1.1
    F0, F1 = effective_loads(np.array([f(t)]), np.array([f(t + 2 * dt / 3)]))
    assert F0[0] == pytest.approx(f(t + ALPHA * dt), rel=1e-14)
    assert F1[0] == pytest.approx(f(t + dt), rel=1e-14)
    # the code's weights, read off with unit loads: F0 = w0 f(t) + w1 f(t + 2 dt / 3) must be the
    # consistent reading of the paper's F0 (DESIGN.md section 5; the printed one sums to 2.32)
    # and F1 = -f(t)/2 + 3 f(t + 2 dt/3)/2 (linear extrapolation to t + dt); both sum to 1, so a
    # constant load passes unchanged
    (a0, b0), (a1, b1) = (effective_loads(np.array([1.0]), np.array([0.0])),
                          effective_loads(np.array([0.0]), np.array([1.0])))
    w0, w1 = (a0[0], a1[0]), (b0[0], b1[0])
    np.testing.assert_allclose(w0, (3 * math.sqrt(2) / 4 - 0.5, (6 - 3 * math.sqrt(2)) / 4), rtol=1e-14)
    np.testing.assert_allclose(w1, (-0.5, 1.5), rtol=1e-14)
    assert sum(w0) == pytest.approx(1.0, abs=1e-15) and sum(w1) == pytest.approx(1.0, abs=1e-15)
    assert LAMBDA == pytest.approx(2.0 / 3.0 - 2.0 * ALPHA, abs=1e-15)


def test_loads_override_and_load_times():
    f = lambda t: np.array([np.sin(t), t * t])  # noqa: E731
    sys = LinearSystem(np.array([1.0, 2.0]), np.array([[3.0, -1.0], [-1.0, 2.0]]), load=f)
    st = TDGStepper(sys, 0.2)
    t0, t23 = st.load_times(0.5)
    assert (t0, t23) == (0.5, pytest.approx(0.5 + 0.4 / 3))
    a = st.step(np.ones(2), np.zeros(2), 0.5)
    b = st.step(np.ones(2), np.zeros(2), 0.5, loads=(f(t0), f(t23)))
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])


def test_lumped_and_sparse_mass_agree(rng):
    n = 4
    A = rng.standard_normal((n, n))
    K = A @ A.T + np.eye(n)
    m = rng.uniform(1, 2, n)
    u, v = rng.standard_normal(n), rng.standard_normal(n)
    a = TDGStepper(LinearSystem(m, K), 0.1).step(u, v, 0.0)
    b = TDGStepper(LinearSystem(sp.diags(m).tocsr(), K), 0.1).step(u, v, 0.0)
    assert np.allclose(a[0], b[0], rtol=1e-13) and np.allclose(a[1], b[1], rtol=1e-13)


class CountingFactory:
    def __init__(self):
        self.calls = 0

    def __call__(self, A):
        self.calls += 1
        from porefsi.integrators import default_solver

        return default_solver(A)


def test_solver_factory_called_once_for_linear_system():
    fac = CountingFactory()
    sys = LinearSystem(np.array([1.0, 1.0]), np.array([[2.0, -1.0], [-1.0, 2.0]]))
    st = TDGStepper(sys, 0.1, make_solver=fac)
    run(st, np.ones(2), np.zeros(2), 1.0)
    assert fac.calls == 1


def test_tangent_policies_refactor_as_documented():
    sys = Duffing()
    y0 = np.array([1.0, 0.5, 0.0, 0.3])
    calls = {}
    for policy in ("step", "frozen", "auto"):
        fac = CountingFactory()
        _, u, v = run(TDGStepper(sys, 0.02, make_solver=fac, tangent=policy), y0[:2], y0[2:], 1.0)
        calls[policy] = fac.calls
        err = np.linalg.norm(np.concatenate([u, v]) - duffing_reference(sys, y0, 1.0))
        assert err < 1e-3, policy
    assert calls["step"] == 50 and calls["frozen"] == 1 and 1 < calls["auto"] < 50


@pytest.mark.parametrize("dt", [0.0, -1.0, float("nan"), float("inf")])
def test_bad_dt(dt):
    with pytest.raises(InputError):
        TDGStepper(LinearSystem(np.array([1.0]), np.array([[1.0]])), dt)


def test_bad_state_and_options():
    st = TDGStepper(LinearSystem(np.array([1.0]), np.array([[1.0]])), 0.1)
    with pytest.raises(InputError, match="not finite"):
        st.step(np.array([np.nan]), np.array([0.0]), 0.0)
    with pytest.raises(InputError, match="shape"):
        st.step(np.zeros(2), np.zeros(1), 0.0)
    with pytest.raises(InputError):
        TDGStepper(LinearSystem(np.array([1.0]), np.array([[1.0]])), 0.1, n_iter=0)
    with pytest.raises(InputError):
        TDGStepper(LinearSystem(np.array([1.0]), np.array([[1.0]])), 0.1, tangent="never")
    with pytest.raises(InputError, match="whole number"):
        list(integrate(st, [0.0], [0.0], 0.0, 0.25))


def test_rtol_not_reached_raises_with_history():
    sys = LinearSystem(np.array([1.0]), np.array([[1e8]]))  # omega dt = 1e3: contraction ~0.94/pass
    with pytest.raises(ConvergenceError) as err:
        TDGStepper(sys, 0.1, n_iter=3, rtol=1e-12).step(np.array([1.0]), np.array([0.0]), 0.0)
    assert len(err.value.history) == 3


def stiff_forced_case():
    """2-dof chain with omega = 1 and 1e4 rad/s; forced at 2 rad/s from the particular solution.

    Exact solution by modal superposition: the fast mode follows the load quasi-statically.
    """
    M, K = np.array([1.0, 1e-8]), np.array([[2.0, -1.0], [-1.0, 1.0]])
    d = 1 / np.sqrt(M)
    lam, Q = np.linalg.eigh(d[:, None] * K * d[None, :])
    Om, wf, fvec = np.sqrt(lam), 2.0, np.array([1.0, 1.0])
    g = Q.T @ (d * fvec)

    def exact(t):
        q, p = g * np.sin(wf * t) / (Om**2 - wf**2), g * wf * np.cos(wf * t) / (Om**2 - wf**2)
        q[0] += np.cos(Om[0] * t)
        p[0] -= Om[0] * np.sin(Om[0] * t)
        return d * (Q @ q), d * (Q @ p)

    return LinearSystem(M, K, load=lambda t: fvec * np.sin(wf * t)), exact


def test_stiff_forced_left_radau_loads_give_second_order_right_radau_fixes_it():
    """omega_max dt = 125..1000: the quasi-static fast mode follows the end-of-step load.

    Left Radau (paper): that load is extrapolated from t, t+2dt/3 -> O(dt^2) displacement error.
    Right Radau: the end load is sampled exactly; the error is > 100x smaller at every step size.
    """
    sys, exact = stiff_forced_case()
    u0, v0 = exact(0.0)
    ue, _ = exact(2.0)
    dts = [0.1, 0.05, 0.025, 0.0125]
    err = {"left": [], "right": []}
    for rule in err:
        for dt in dts:
            _, u, _ = run(TDGStepper(sys, dt, load_rule=rule), u0, v0, 2.0)
            err[rule].append(np.linalg.norm(u - ue))
    assert abs(slope(dts, err["left"]) - 2) < 0.15
    assert all(r < 1e-2 * left for r, left in zip(err["right"], err["left"], strict=True))


def test_right_radau_rule_converges_to_its_oracle():
    sys, exact = stiff_forced_case()
    sys = LinearSystem(np.array([1.0, 1e-2]), np.array([[2.0, -1.0], [-1.0, 1.0]]), load=sys._load)
    u0, v0 = exact(0.0)
    a = TDGExactStepper(sys, 0.05, load_rule="right").step(u0, v0, 0.3)
    b = TDGStepper(sys, 0.05, n_iter=200, rtol=1e-14, load_rule="right").step(u0, v0, 0.3)
    assert np.allclose(a[0], b[0], rtol=0, atol=1e-12) and np.allclose(a[1], b[1], rtol=0, atol=1e-10)


# --- loads that enter through the internal force's time argument ------------------------------
# The paper's strain-rate loading moves a support: the prescribed boundary displacement enters
# f_int(u, t), not f_ext(t), so these tests are the ones that see *when* f_int is evaluated
# (RADAU_ABSCISSAE). Measured: with the first stage time moved from dt/3 to 2 dt/3 both fall to
# order 0.92-0.96 (errors 1.3e-3..1.8e-4 instead of 1.1e-4..2.2e-7 for the support case).
RATE = 0.2  # support speed, m/s


class MovingSupport:
    """Mass on a spring whose far end moves at constant speed: f_int = W^2 (u - RATE t)."""

    n_dofs = 1

    def mass(self):
        return np.array([1.0])

    def internal_force(self, u, t):
        return W * W * (u - RATE * t)

    def tangent(self, u, t):
        return sp.csr_matrix([[W * W]])

    def external_force(self, t):
        return np.zeros(1)


def moving_support_exact(t):
    """u'' + W^2 u = W^2 RATE t, u(0) = v(0) = 0: u = RATE (t - sin(Wt)/W) (hand-derived)."""
    return RATE * (t - math.sin(W * t) / W), RATE * (1.0 - math.cos(W * t))


class PulsingStiffness:
    """f_int = k(t) u with k(t) = W^2 (1 + sin(2t)/2): a time-dependent, state-linear stiffness."""

    n_dofs = 1

    def k(self, t):
        return W * W * (1.0 + 0.5 * math.sin(2.0 * t))

    def mass(self):
        return np.array([1.0])

    def internal_force(self, u, t):
        return self.k(t) * u

    def tangent(self, u, t):
        return sp.csr_matrix([[self.k(t)]])

    def external_force(self, t):
        return np.zeros(1)


def pulsing_reference(sys, y0, t_end):
    """Mathieu-type equation u'' + k(t) u = 0 by DOP853 at 1e-13 (independent integrator)."""
    sol = solve_ivp(lambda t, y: [y[1], -sys.k(t) * y[0]], (0.0, t_end), y0, method="DOP853", rtol=1e-13,
                    atol=1e-13)
    return sol.y[:, -1]


@pytest.mark.parametrize("case", ["moving_support", "pulsing_stiffness"])
def test_order_3_when_time_enters_through_internal_force(case):
    if case == "moving_support":
        sys, y0 = MovingSupport(), np.array([0.0, 0.0])
        ue, ve = moving_support_exact(2.0)
    else:
        sys, y0 = PulsingStiffness(), np.array([1.0, 0.5])
        ue, ve = pulsing_reference(sys, y0, 2.0)
    dts = [0.1, 0.05, 0.025, 0.0125]
    errs = []
    for dt in dts:
        _, u, v = run(TDGStepper(sys, dt), y0[:1], y0[1:], 2.0)
        errs.append(math.hypot(u[0] - ue, (v[0] - ve) / W))
    assert abs(slope(dts, errs) - 3) < 0.15, errs
    # and the error constant is small, not only the slope right: measured 2.2e-7 (support, response
    # ~RATE * 2 s = 0.4 m) and 5.7e-6 (pulsing, amplitude ~1) at dt = 0.0125
    scale = RATE * 2.0 if case == "moving_support" else 1.0
    assert errs[-1] < 1e-5 * scale, errs
