"""Kernels of porefsi.stokes: the operators are what MINRES assumes (symmetric, SPD preconditioners)
and the fused kernels equal their plain definitions. End-to-end correctness is pinned by the naive
twin and the closed forms in tests/test_stokes.py."""

from __future__ import annotations

import numpy as np
import pytest

from porefsi.stokes import _kernels as kern
from porefsi.stokes._grid import assemble
from porefsi.stokes._pressure import PressureMultigrid
from porefsi.stokes._solve import schur_approximation


def _system(periodic=(False, False, False), open_axis=0, seed=2, wall="channel"):
    rng = np.random.default_rng(seed)
    pore = rng.random((9, 8, 7)) < 0.7
    if open_axis is None:
        return assemble(pore, periodic=periodic, body_axis=0, body_force=1.0, wall=wall)
    return assemble(pore, periodic=periodic, open_axis=open_axis, pressures=(3.0, 0.0), wall=wall)


def _K(system, x):
    out = np.empty_like(x)
    kern.stokes_matvec(system.tables, x, system.n_u, out)
    return out


CASES = [dict(), dict(periodic=(False, True, True)), dict(periodic=(True, False, True), open_axis=None),
         dict(periodic=(True, True, True), open_axis=None)]


@pytest.mark.parametrize("case", CASES, ids=range(len(CASES)))
def test_stokes_operator_is_symmetric(case):
    s = _system(**case)
    rng = np.random.default_rng(0)
    x, y = rng.standard_normal((2, s.n_u + s.n_p))
    assert y @ _K(s, x) == pytest.approx(x @ _K(s, y), rel=1e-12)
    # the velocity block alone is positive definite
    xu = np.concatenate([x[:s.n_u], np.zeros(s.n_p)])
    assert xu @ _K(s, xu) > 0


@pytest.mark.parametrize("case", CASES, ids=range(len(CASES)))
def test_preconditioners_are_symmetric_positive(case):
    s = _system(**case)
    rng = np.random.default_rng(1)
    x, y = rng.standard_normal((2, s.n_u + s.n_p))

    def sgs(r):
        out = np.zeros_like(r)
        kern.symmetric_gauss_seidel(s.neighbours, s.diag, s.half, r, out, s.n_u)
        return out[:s.n_u]

    assert y[:s.n_u] @ sgs(x) == pytest.approx(x[:s.n_u] @ sgs(y), rel=1e-10)
    assert x[:s.n_u] @ sgs(x) > 0
    mg = PressureMultigrid(s, schur_approximation(s))
    xp, yp = x[s.n_u:], y[s.n_u:]
    assert yp @ mg.matvec(xp) == pytest.approx(xp @ mg.matvec(yp), rel=1e-8)
    assert xp @ mg.matvec(xp) > 0


def test_matrix_free_schur_equals_the_assembled_one():
    s = _system(periodic=(False, True, False))
    S = schur_approximation(s)
    assert abs(S - S.T).max() == 0
    rng = np.random.default_rng(3)
    b, x = rng.standard_normal((2, s.n_p))
    pf = kern.pressure_faces(s.p_lo, s.p_hi, s.offsets, s.n_p)
    r = np.empty(s.n_p)
    kern.schur_residual(pf, s.p_lo, s.p_hi, s.diag, b, x, r)
    np.testing.assert_allclose(r, b - S @ x - 1e-12 * S.diagonal() * x, rtol=1e-12, atol=1e-12)
    # S = B D^-1 B^T from the divergence the Stokes operator applies
    B = np.zeros((s.n_p, s.n_u))
    for f in range(s.n_u):
        if s.p_lo[f] >= 0:
            B[s.p_lo[f], f] += 1
        if s.p_hi[f] >= 0:
            B[s.p_hi[f], f] -= 1
    np.testing.assert_allclose(S.toarray(), B @ np.diag(1 / s.diag.astype(float)) @ B.T, atol=1e-14)
    u = rng.standard_normal(s.n_u)
    np.testing.assert_allclose(_K(s, np.concatenate([u, np.zeros(s.n_p)]))[s.n_u:], -(B @ u), atol=1e-12)


def test_fused_lanczos_kernels_equal_their_definitions():
    s = _system()
    rng = np.random.default_rng(4)
    z, v, v_old = rng.standard_normal((3, s.n_u + s.n_p))
    tables = s.tables
    kz = _K(s, z)
    assert kern.lanczos_delta(tables, z, s.n_u) == pytest.approx(z @ kz, rel=1e-12)
    expect = kz - 0.3 * v - 0.7 * v_old
    kern.lanczos_step(tables, z, s.n_u, v, v_old, 0.3, 0.7)
    np.testing.assert_allclose(v_old, expect, rtol=1e-12, atol=1e-12)
    w_old, w = rng.standard_normal((2, 5))
    zz = rng.standard_normal(5)
    expect = (zz - 0.2 * w_old - 0.4 * w) / 1.5
    kern.update_search(w_old, zz, w, 1.5, 0.4, 0.2)
    np.testing.assert_allclose(w_old, expect, rtol=1e-14)
