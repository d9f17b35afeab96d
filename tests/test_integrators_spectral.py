"""Spectral radius of every scheme, measured on the implementations, against derived closed forms.

Closed forms (tests/reference/integrators_ref.py, derivations in docs/time_integration.md):
pass 1 of TDG is Alexander's SDIRK2, R1(z) = (1 + (1-2a) z)/(1 - a z)^2; pass 2 is
R2(z) = R1(z) - (lambda*/2) z^3 / (1 - a z)^4; exact TDG is the (1,2)-Pade approximant.
"""

import numpy as np
import pytest

from porefsi.errors import InputError
from porefsi.integrators import amplification_matrix, spectral_radius
from tests.reference.integrators_ref import r_sdirk, r_tdg2, r_tdg_exact, rho_central_difference

W = np.logspace(-3, 6, 91)


@pytest.mark.parametrize(
    "scheme, opts, closed",
    [("tdg", {"n_iter": 2}, r_tdg2), ("tdg", {"n_iter": 1}, r_sdirk), ("tdg_exact", {}, r_tdg_exact)],
)
def test_tdg_spectral_radius_bounded_and_equal_to_closed_form(scheme, opts, closed):
    rho = spectral_radius(scheme, W, **opts)
    assert np.all(rho <= 1.0 + 1e-12)
    # eigenvalues of the (u, v) amplification matrix are R(+-i w dt)
    # atol: at omega dt ~ 1e6 the stage solves cancel O(1e12) terms, leaving ~1e-11 round-off
    assert np.allclose(rho, np.abs(closed(1j * W)), rtol=1e-8, atol=1e-10)


def test_tdg_two_pass_values_at_10_and_100():
    """Derived: |R2(10i)| = 0.18515, |R2(100i)| = 0.006961 (DESIGN.md quotes 0.185 and 0.007)."""
    derived = np.abs(r_tdg2(1j * np.array([10.0, 100.0])))
    assert derived == pytest.approx([0.18515, 0.006961], abs=1e-5)
    assert spectral_radius("tdg", [10.0, 100.0]) == pytest.approx(derived, abs=1e-3)
    # L-stability: annihilation as omega dt -> infinity
    assert spectral_radius("tdg", 1e6) < 1e-5 and spectral_radius("tdg", 1e6, n_iter=1) < 1e-5


def test_newmark_average_acceleration_never_dissipates():
    assert np.allclose(spectral_radius("newmark", W), 1.0, atol=1e-9)


def test_central_difference_unstable_beyond_two():
    w = np.array([0.01, 0.5, 1.0, 1.9, 2.0, 2.01, 2.5, 10.0, 100.0])
    rho = spectral_radius("central_difference", w)
    assert np.allclose(rho, rho_central_difference(w), rtol=1e-6)
    assert np.all(rho[w <= 2.0] <= 1 + 1e-6) and np.all(rho[w > 2.0] > 1.0)


@pytest.mark.parametrize("rho_inf", [0.0, 0.5, 0.8, 1.0])
def test_generalized_alpha_reaches_rho_inf(rho_inf):
    rho = spectral_radius("generalized_alpha", W, rho_inf=rho_inf)
    assert np.all(rho <= 1 + 1e-9)
    assert rho[-1] == pytest.approx(rho_inf, abs=1e-3)
    assert rho[0] == pytest.approx(1.0, abs=1e-6)


def test_amplification_matrix_bad_input():
    with pytest.raises(InputError):
        amplification_matrix("leapfrog", 1.0)
    with pytest.raises(InputError):
        amplification_matrix("tdg", -1.0)
