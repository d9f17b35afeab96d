"""The solid's own AMG V-cycle (porefsi/solid/_vcycle.py) against plain-numpy twins and the sparse LU.

The twins share no code with the module: a row-by-row Gauss-Seidel sweep written from its
definition, and a V-cycle built from dense level matrices.
"""

import numpy as np
import pytest
import scipy.sparse as sp
from scipy import ndimage

from porefsi.image.voxel_image import VoxelImage
from porefsi.solid._vcycle import LEVEL_DROP, VCycle, _reversed, lumped, relax_candidates
from porefsi.solid.bc import uniaxial_bcs
from porefsi.solid.graded import mesh_graded
from porefsi.solid.linsolve import AMGSolverFactory, direct_solver_factory
from porefsi.solid.materials import StVenantKirchhoff
from porefsi.solid.model import SolidModel


def _gs_twin(A: np.ndarray, x: np.ndarray, b: np.ndarray, forward: bool) -> np.ndarray:
    """One Gauss-Seidel sweep from the definition, on a dense matrix (rows in order or reversed)."""
    x = x.copy()
    rows = range(len(x)) if forward else range(len(x) - 1, -1, -1)
    for i in rows:
        x[i] = (b[i] - A[i] @ x + A[i, i] * x[i]) / A[i, i]
    return x


def _spd(n: int, rng) -> sp.csr_matrix:
    """A random sparse SPD matrix (a graph Laplacian plus a positive diagonal)."""
    R = sp.random(n, n, density=8.0 / n, random_state=np.random.RandomState(int(rng.integers(1 << 30))))
    W = abs(R + R.T)
    L = sp.diags(np.asarray(W.sum(axis=1)).ravel()) - W
    return sp.csr_matrix(L + sp.diags(rng.uniform(0.1, 1.0, n)))


@pytest.fixture(scope="module")
def graded_model():
    """A graded mesh of a blob rock (40^3, fine blocks of 2 at one corner's pores, leaves to 8), loaded in z."""
    f = ndimage.gaussian_filter(np.random.default_rng(3).standard_normal((40, 40, 40)), 3.0, mode="wrap")
    phases = (f > np.quantile(f, 0.7)).astype(np.uint8)
    img = VoxelImage(phases, 5e-6)
    refine = np.zeros(phases.shape, bool)
    refine[:14, :14, :14] = phases[:14, :14, :14] != 0
    mesh = mesh_graded(img, coarsen=2, coarsen_max=8, grading=0.5, refine=refine, support_axis="z").mesh
    return SolidModel(mesh, StVenantKirchhoff(20e9, 0.28), uniaxial_bcs("z", rate=-1e-3 * 40 * 5e-6))


def test_sweeps_match_the_definition(rng):
    """Forward and backward sweeps (the backward one on the reversed copy) agree with the twin to rounding."""
    A = _spd(120, rng)
    vc = VCycle([type("L", (), {"A": A})()], lambda M, b: np.linalg.solve(M.toarray(), b))
    Ad = A.toarray()
    b, x0 = rng.standard_normal((2, 120))
    for forward in (True, False):
        x = x0.copy()
        vc.A = [A, A]  # the sweeps of level 0 (VCycle keeps reversed copies of all but the coarsest level)
        vc.A_rev = [_reversed(A)]
        vc._sweep(0, x, b, forward)
        np.testing.assert_allclose(x, _gs_twin(Ad, x0, b, forward), rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(_reversed(A).toarray(), Ad[::-1, ::-1])


def test_vcycle_matches_a_dense_twin_and_is_symmetric(rng):
    """Two levels with a random aggregation P: the cycle is forward GS, coarse correction, backward GS."""
    n, nc = 90, 12
    A = _spd(n, rng)
    P = sp.csr_matrix((np.ones(n), (np.arange(n), rng.integers(0, nc, n))), shape=(n, nc))
    P = sp.csr_matrix(P[:, np.unique(P.indices)])
    Ac = sp.csr_matrix(P.T @ A @ P)
    levels = [type("L", (), {"A": A, "P": P, "R": sp.csr_matrix(P.T)})(), type("L", (), {"A": Ac})()]
    vc = VCycle(levels, lambda M, b: np.linalg.solve(M.toarray(), b))
    Ad, Pd = A.toarray(), P.toarray()
    b = rng.standard_normal(n)
    x = _gs_twin(Ad, np.zeros(n), b, True)
    x = x + Pd @ np.linalg.solve(Pd.T @ Ad @ Pd, Pd.T @ (b - Ad @ x))
    x = _gs_twin(Ad, x, b, False)
    np.testing.assert_allclose(vc(b), x, rtol=1e-11, atol=1e-12 * np.abs(x).max())
    M = np.column_stack([vc(e) for e in np.eye(n)])
    np.testing.assert_allclose(M, M.T, atol=1e-11 * np.abs(M).max())
    assert np.linalg.eigvalsh(0.5 * (M + M.T)).min() > 0


def test_relax_candidates_is_symmetric_gauss_seidel_on_zero(rng):
    """Each candidate column gets ``sweeps`` forward+backward sweeps on A x = 0 (the twin's)."""
    A = _spd(60, rng)
    B = rng.standard_normal((60, 3))
    out = relax_candidates(A, B, sweeps=2)
    Ad = A.toarray()
    for k in range(3):
        x = B[:, k]
        for _ in range(2):
            x = _gs_twin(Ad, _gs_twin(Ad, x, np.zeros(60), True), np.zeros(60), False)
        np.testing.assert_allclose(out[:, k], x, rtol=1e-11, atol=1e-13)
    assert np.array_equal(B, B.copy())  # input untouched (a fresh array is returned)


def test_amg_cg_equals_the_sparse_lu_on_a_graded_mesh(graded_model, rng):
    """On a graded mesh (hanging-node templates, leaves of 2-8 voxels) AMG-CG to 1e-10 gives the LU's
    displacement to 1e-8 relative, in few iterations; a broken near-null space (translations only)
    needs more (the rotations are what the hierarchy is built on)."""
    m = graded_model
    K = m.tangent(np.zeros(m.n_dofs), 1.0)
    b = rng.standard_normal(m.n_dofs)  # (the uniaxial frame's load is on constrained dofs only)
    x_lu = direct_solver_factory()(K)(b)
    fac = AMGSolverFactory(m.dof_points, m.free, rtol=1e-10)
    x = fac(K)(b)
    assert np.linalg.norm(x - x_lu) <= 1e-8 * np.linalg.norm(x_lu)
    assert fac.last.iterations <= 30
    fac3 = AMGSolverFactory(m.dof_points, m.free, rtol=1e-10, rotations=False)
    fac3(K)(b)
    assert fac3.last.iterations > fac.last.iterations


def test_lumped_level_is_the_definition_and_stays_spd(rng):
    """lumped(A, theta): entries below theta * sqrt(a_ii a_jj) leave, their magnitudes join the diagonal
    (a dense twin); the result is symmetric and A' - A is positive semidefinite."""
    A = _spd(80, rng)
    Ad = A.toarray()
    d = np.sqrt(np.outer(np.diag(Ad), np.diag(Ad)))
    off = ~np.eye(80, dtype=bool)
    theta = float(np.median((np.abs(Ad) / d)[off & (Ad != 0)]))  # half the entries go
    small = (np.abs(Ad) < theta * d) & off & (Ad != 0)
    twin = np.where(small, 0.0, Ad) + np.diag(np.where(small, np.abs(Ad), 0.0).sum(axis=1))
    out = lumped(A, theta).toarray()
    assert small.any() and (~small & (Ad != 0) & off).any()
    np.testing.assert_allclose(out, twin, rtol=1e-14, atol=1e-14)
    np.testing.assert_array_equal(out, out.T)
    assert np.linalg.eigvalsh(out - Ad).min() > -1e-12


def test_amg_on_a_graded_mesh_with_lumped_levels(graded_model, rng):
    """With an intermediate level (lumped by default) AMG-CG still reaches the LU's answer, and the
    cycle is still a symmetric positive definite preconditioner."""
    m = graded_model
    K = m.tangent(np.zeros(m.n_dofs), 1.0)
    b = rng.standard_normal(m.n_dofs)
    x_lu = direct_solver_factory()(K)(b)
    fac = AMGSolverFactory(m.dof_points, m.free, rtol=1e-10, max_coarse=30)
    x = fac(K)(b)
    assert len(fac.ml.levels) >= 3  # an intermediate level exists, so the lumping is exercised
    np.testing.assert_array_equal(fac._M.A[1].toarray(), lumped(fac.ml.levels[1].A, LEVEL_DROP).toarray())
    assert np.linalg.norm(x - x_lu) <= 1e-8 * np.linalg.norm(x_lu)
    x1, x2 = rng.standard_normal((2, m.n_dofs))
    a, c = x2 @ fac.precondition(x1), x1 @ fac.precondition(x2)
    assert abs(a - c) <= 1e-10 * abs(a) and x1 @ fac.precondition(x1) > 0
