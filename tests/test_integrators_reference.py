"""Reference integrators (Newmark, generalized-alpha, central difference, quasi-static) and energy."""

import math
from collections import deque

import numpy as np
import pytest
import scipy.sparse as sp

from porefsi.errors import ConvergenceError, InputError
from porefsi.integrators import (
    CentralDifferenceStepper,
    GeneralizedAlphaStepper,
    LinearSystem,
    NewmarkStepper,
    QuasiStaticStepper,
    TDGStepper,
    critical_time_step,
    integrate,
    quasistatic,
    solve_static,
)
from tests.reference.integrators_ref import r_tdg2

W = 3.0


def free_exact(t):
    """u'' + W^2 u = 0, u(0)=1, v(0)=0.5."""
    return math.cos(W * t) + 0.5 / W * math.sin(W * t)


def energy(M, K, u, v):
    return 0.5 * v @ (M * v) + 0.5 * u @ (K @ u)


@pytest.mark.parametrize(
    "make",
    [
        lambda s, dt: NewmarkStepper(s, dt),
        lambda s, dt: GeneralizedAlphaStepper(s, dt, rho_inf=0.5),
        lambda s, dt: CentralDifferenceStepper(s, dt),
    ],
    ids=["newmark", "generalized_alpha", "central_difference"],
)
def test_second_order_on_free_oscillator(make):
    sys = LinearSystem(np.array([1.0]), np.array([[W * W]]))
    dts = [0.05, 0.025, 0.0125, 0.00625]
    errs = []
    for dt in dts:
        _, u, v = deque(integrate(make(sys, dt), [1.0], [0.5], 0.0, 2.0), maxlen=1)[0]
        errs.append(abs(u[0] - free_exact(2.0)))
    assert abs(np.polyfit(np.log(dts), np.log(errs), 1)[0] - 2) < 0.15


def random_spd_system(rng, n=6, spread=1e4):
    """Random SPD stiffness with eigenvalues spread over `spread` (lumped random mass)."""
    Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    K = Q @ np.diag(np.geomspace(1.0, spread, n)) @ Q.T
    K = 0.5 * (K + K.T)
    return rng.uniform(0.5, 2.0, n), K


def test_newmark_conserves_energy_exactly_for_linear_system(rng):
    """Average acceleration: E = v.Mv/2 + u.Ku/2 is an exact invariant (Hughes 2000, sec. 9.3)."""
    M, K = random_spd_system(rng)
    sys = LinearSystem(M, K)
    u0, v0 = rng.standard_normal(6), rng.standard_normal(6)
    E0 = energy(M, K, u0, v0)
    Es = [energy(M, K, u, v) for _, u, v in integrate(NewmarkStepper(sys, 0.5), u0, v0, 0.0, 50.0)]
    assert np.max(np.abs(np.array(Es) / E0 - 1)) < 1e-10  # omega dt up to 50: no dissipation at all


def test_tdg_dissipates_only_high_frequencies():
    """Two uncoupled modes, omega dt = 0.05 and 500 (free, undamped).

    Derived from the amplification factor R2 (tests/reference): over 200 steps the low mode
    loses exactly 1 - |R2(0.05i)|^400 = 2.65e-5 of its energy; the high mode keeps a fraction
    |R2(500i)|^2 = 1.8e-6 per step; the total energy never increases.
    """
    M, K = np.array([1.0, 1.0]), np.diag([1.0, 1e8])
    sys = LinearSystem(M, K)
    u0, v0 = np.array([1.0, 1e-4]), np.array([0.0, 1.0])
    st = TDGStepper(sys, 0.05)
    Es = []
    for _t, u, v in integrate(st, u0, v0, 0.0, 10.0):
        Es.append((0.5 * (v[0] ** 2 + u[0] ** 2), 0.5 * (v[1] ** 2 + 1e8 * u[1] ** 2)))
    Es = np.array(Es)
    low_loss = 1 - abs(r_tdg2(0.05j)) ** 400
    assert 1 - Es[-1, 0] / Es[0, 0] == pytest.approx(low_loss, rel=1e-3)
    per_step = abs(r_tdg2(500j)) ** 2
    assert Es[4, 1] / Es[0, 1] == pytest.approx(per_step**4, rel=0.5, abs=0)
    total = Es.sum(axis=1)
    assert np.all(np.diff(total) <= 1e-12 * total[0])


def test_central_difference_blows_up_beyond_critical_step(rng):
    M, K = random_spd_system(rng, spread=1e4)
    sys = LinearSystem(M, K)
    dtc = critical_time_step(sys)
    wmax = math.sqrt(np.max(np.linalg.eigvals(np.diag(1 / M) @ K).real))
    assert dtc == pytest.approx(2 / wmax, rel=1e-10)
    u0, v0 = rng.standard_normal(6), np.zeros(6)
    E0 = energy(M, K, u0, v0)
    _, u, v = deque(integrate(CentralDifferenceStepper(sys, 0.95 * dtc), u0, v0, 0.0, 200 * 0.95 * dtc), maxlen=1)[0]
    assert energy(M, K, u, v) < 10 * E0  # bounded below the limit
    _, u, v = deque(integrate(CentralDifferenceStepper(sys, 1.05 * dtc), u0, v0, 0.0, 200 * 1.05 * dtc), maxlen=1)[0]
    assert energy(M, K, u, v) > 1e6 * E0  # grows geometrically above it


class Spring:
    """Hardening spring network f_int = K u + c u^3 (quasi-static tests)."""

    def __init__(self, n=3, c=2.0, load=1.0):
        self.K = sp.diags([2.0] * n) - sp.diags([1.0] * (n - 1), 1) - sp.diags([1.0] * (n - 1), -1)
        self.K = self.K.tocsr()
        self.c, self.load, self.n_dofs = c, load, n

    def mass(self):
        return np.ones(self.n_dofs)

    def internal_force(self, u, t):
        return self.K @ u + self.c * u**3

    def tangent(self, u, t):
        return (self.K + sp.diags(3 * self.c * u**2)).tocsr()

    def external_force(self, t):
        return np.full(self.n_dofs, self.load * t)


def test_quasistatic_newton_converges_quadratically():
    sys = Spring(load=5.0)
    u, info = solve_static(sys, 1.0, rtol=1e-14, line_search=False)
    assert np.linalg.norm(sys.internal_force(u, 1.0) - sys.external_force(1.0)) < 1e-12
    r = np.array(info.residual_norms)
    r = r[r > 1e-11]  # above round-off
    rates = np.log(r[2:] / r[1:-1]) / np.log(r[1:-1] / r[:-2])
    assert rates[-1] == pytest.approx(2.0, abs=0.2)


class Arctan:
    """f_int = arctan(u - 10 t), f_ext = 0 (solution u = 10 t).

    Newton on arctan diverges from more than ~1.39 away from the root (a textbook example), so
    the jump 0 -> 10 fails and converges only through load stepping (bisection of the interval).
    """

    n_dofs = 1

    def mass(self):
        return np.ones(1)

    def internal_force(self, u, t):
        return np.arctan(u - 10.0 * t)

    def tangent(self, u, t):
        d = min(abs(u[0] - 10.0 * t), 1e150)  # a diverging Newton iterate must not overflow here
        return sp.csr_matrix([[1.0 / (1.0 + d * d)]])

    def external_force(self, t):
        return np.zeros(1)


def test_quasistatic_load_stepping_bisects_and_reports_history():
    sys = Arctan()
    with pytest.raises(ConvergenceError) as err:
        solve_static(sys, 1.0, line_search=False, max_iter=15)
    assert len(err.value.history) >= 2
    states = list(quasistatic(sys, np.zeros(1), [0.0, 1.0], line_search=False, max_iter=15))
    t, u, info = states[-1]
    assert u[0] == pytest.approx(10.0, rel=1e-9) and info.extra["substeps"] > 1
    assert len(info.extra["failed_history"]) > 0
    with pytest.raises(ConvergenceError):
        list(quasistatic(sys, np.zeros(1), [0.0, 1.0], max_bisections=0, line_search=False, max_iter=15))


def test_quasistatic_stepper_tracks_equilibrium():
    sys = Spring(load=1.0)
    for t, u, _ in integrate(QuasiStaticStepper(sys, 0.25), np.zeros(3), np.zeros(3), 0.0, 1.0):
        assert np.linalg.norm(sys.internal_force(u, t) - sys.external_force(t)) < 1e-9


def test_newmark_and_generalized_alpha_nonlinear_newton():
    """Nonlinear spring under a step load: implicit schemes converge every step (Newton history)."""
    sys = Spring(load=3.0)
    for st in (NewmarkStepper(sys, 0.1), GeneralizedAlphaStepper(sys, 0.1, rho_inf=0.8)):
        u, v = np.zeros(3), np.zeros(3)
        for k in range(20):
            u, v, info = st.step(u, v, 0.1 * k)
            assert info.converged and info.iterations <= 8


def test_reference_steppers_validate_input():
    sys = LinearSystem(np.array([1.0]), np.array([[1.0]]))
    with pytest.raises(InputError):
        NewmarkStepper(sys, 0.1, beta=0.0)
    with pytest.raises(InputError):
        NewmarkStepper(sys, 0.1, gamma=0.4)
    with pytest.raises(InputError):
        GeneralizedAlphaStepper(sys, 0.1, rho_inf=1.5)
    with pytest.raises(InputError):
        CentralDifferenceStepper(sys, -0.1)
    with pytest.raises(InputError):
        NewmarkStepper(sys, 0.1).step(np.array([np.inf]), np.zeros(1), 0.0)
