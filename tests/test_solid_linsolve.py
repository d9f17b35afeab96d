"""Linear solvers: AMG-CG with rigid-body modes converges within a bound, is symmetric, is reused."""

from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from porefsi.errors import ConvergenceError, InputError
from porefsi.image.voxel_image import VoxelImage
from porefsi.solid.bc import uniaxial_bcs
from porefsi.solid.linsolve import (
    AMGSolverFactory,
    direct_solver_factory,
    jacobi_solver_factory,
    pcg,
    rigid_body_modes,
)
from porefsi.solid.materials import StVenantKirchhoff
from porefsi.solid.mesh import mesh_solid
from porefsi.solid.model import SolidModel

SAMPLE = Path(__file__).resolve().parents[1] / "porefsi" / "data" / "berea_icl_120_paper.npz"


@pytest.fixture(scope="module")
def rock_model():
    """The sample rock at coarsen 8 (~15k tets, ~10k free dofs), the paper's BCs."""
    d = np.load(SAMPLE)
    img = VoxelImage(d["image"], float(d["voxel_size_m"]))
    mesh = mesh_solid(img, coarsen=8).mesh
    return SolidModel(mesh, StVenantKirchhoff(20e9, 0.28), uniaxial_bcs("z", rate=-1e-3 * 0.641e-3))


def test_amg_cg_converges_fast_and_is_symmetric(rock_model, rng):
    """Smoothed aggregation with the six rigid-body modes: CG reaches 1e-8 in <= 40 iterations on the
    porous rock, and the V-cycle with symmetric Gauss-Seidel smoothing is a symmetric operator.

    On the rock the rotations help only modestly: measured 11 vs 14 iterations (six modes vs the
    three translations) at coarsen 8, 16 vs 20 at coarsen 5 (random right-hand sides): the
    compact, well-supported sample is not bending-dominated. Asserted: strictly fewer with six.
    test_rotations_matter_for_a_bending_dominated_beam shows where they matter."""
    m = rock_model
    K = m.tangent(np.zeros(m.n_dofs), 1.0)
    fac = AMGSolverFactory(m.dof_points, m.free, rtol=1e-8)
    b = rng.standard_normal(m.n_dofs)
    x = fac(K)(b)
    assert np.linalg.norm(K @ x - b) <= 1e-8 * np.linalg.norm(b)
    assert fac.last.iterations <= 40
    fac3 = AMGSolverFactory(m.dof_points, m.free, rtol=1e-8, rotations=False)
    assert fac3.B_full.shape[1] == 3
    fac3(K)(b)
    assert fac.last.iterations < fac3.last.iterations
    hist = np.asarray(fac.last.history)
    assert hist[-1] <= 1e-8 and len(hist) == fac.last.iterations + 1
    x1, x2 = rng.standard_normal((2, m.n_dofs))
    a, bb = x2 @ fac.precondition(x1), x1 @ fac.precondition(x2)
    assert abs(a - bb) <= 1e-10 * abs(a)
    assert x1 @ fac.precondition(x1) > 0


def test_rotations_matter_for_a_bending_dominated_beam():
    """A slender cantilever (80 x 2 x 2 cells, 8 mm x 0.2 mm x 0.2 mm, fixed at xmin) under a
    transverse tip load: its low-energy modes are bending, which the translations alone cannot
    represent on the coarse level (a bent beam is locally a rotation). Measured: 16 CG iterations
    with the six rigid-body modes, 156 with the three translations (default pyamg settings, 2
    levels). Asserted: the rotations cut the iterations at least 4x."""
    from porefsi.solid.bc import Fixed
    from porefsi.solid.shapes import box_mesh

    mesh = box_mesh((80, 2, 2), (8e-3, 2e-4, 2e-4))
    model = SolidModel(mesh, StVenantKirchhoff(20e9, 0.28), [Fixed("xmin")])
    tip = np.zeros((mesh.n_nodes, 3))
    tip[np.isclose(mesh.points[:, 0], 8e-3), 2] = -1.0  # N, bending about y
    b = model.with_nodal_forces(tip).external_force(0.0)
    K = model.tangent(np.zeros(model.n_dofs), 0.0)
    its = {}
    for rotations in (True, False):
        fac = AMGSolverFactory(model.dof_points, model.free, rtol=1e-8, rotations=rotations)
        x = fac(K)(b)
        assert np.linalg.norm(K @ x - b) <= 1e-8 * np.linalg.norm(b)
        its[rotations] = fac.last.iterations
    assert 4 * its[True] <= its[False]


def test_model_amg_rotations_switch_reaches_the_hierarchy():
    """``SolidModel.amg_rotations`` (default True) sets the near-null space of the model's AMG factory.

    On the slender cantilever of the test above, through the model's own ``make_solver``: six modes
    by default, three with ``amg_rotations = False``, both solving to the requested tolerance, the
    translations-only hierarchy needing at least 4x the iterations (the switch really reaches the
    hierarchy, and it costs there what the beam test measured)."""
    from porefsi.solid.bc import Fixed
    from porefsi.solid.shapes import box_mesh

    mesh = box_mesh((80, 2, 2), (8e-3, 2e-4, 2e-4))
    tip = np.zeros((mesh.n_nodes, 3))
    tip[np.isclose(mesh.points[:, 0], 8e-3), 2] = -1.0
    its, xs = {}, {}
    for rotations in (True, False):
        model = SolidModel(mesh, StVenantKirchhoff(20e9, 0.28), [Fixed("xmin")], linear_solver="amg")
        assert model.amg_rotations is True
        model.amg_rotations = rotations
        b = model.with_nodal_forces(tip).external_force(0.0)
        K = model.tangent(np.zeros(model.n_dofs), 0.0)
        xs[rotations] = model.make_solver(K)(b)
        assert model.solver_factory.B_full.shape[1] == (6 if rotations else 3)
        assert np.linalg.norm(K @ xs[rotations] - b) <= 1e-8 * np.linalg.norm(b)
        its[rotations] = model.solver_factory.last.iterations
    assert 4 * its[True] <= its[False]
    assert np.linalg.norm(xs[True] - xs[False]) <= 1e-5 * np.linalg.norm(xs[True])


def test_amg_hierarchy_reused_while_fast(rock_model, rng):
    m = rock_model
    fac = AMGSolverFactory(m.dof_points, m.free)
    K0 = m.tangent(np.zeros(m.n_dofs), 1.0)
    fac(K0)(rng.standard_normal(m.n_dofs))
    # a perturbed operator (a mass-like shift, as in M + c K): the old hierarchy still serves
    K1 = K0 + sp.diags(1e-3 * K0.diagonal())
    b = rng.standard_normal(m.n_dofs)
    x = fac(K1)(b)
    assert fac.n_setups == 1
    assert np.linalg.norm(K1 @ x - b) <= 1e-8 * np.linalg.norm(b)
    # a very different operator forces a rebuild instead of a slow solve
    fac.rebuild_iterations = 0
    fac(K1 * 0.5 + sp.diags(K0.diagonal()))(b)
    assert fac.n_setups == 2


def test_rigid_body_modes_are_orthonormalisable():
    pts = np.random.default_rng(0).uniform(size=(20, 3))
    B = rigid_body_modes(pts)
    assert B.shape == (60, 6)
    assert np.linalg.matrix_rank(B) == 6


def test_other_solvers_and_failure_history(rock_model, rng):
    m = rock_model
    K = m.tangent(np.zeros(m.n_dofs), 1.0)
    b = rng.standard_normal(m.n_dofs)
    xd = direct_solver_factory()(K)(b)
    xj = jacobi_solver_factory(rtol=1e-10, maxiter=20000)(K)(b)
    np.testing.assert_allclose(xj, xd, rtol=1e-6, atol=1e-6 * np.abs(xd).max())
    with pytest.raises(ConvergenceError) as exc:
        pcg(K, b, maxiter=5)
    assert len(exc.value.history) == 6 and exc.value.history[0] == 1.0
    with pytest.raises(ConvergenceError, match="breakdown"):
        pcg(-sp.identity(4), np.ones(4))


def test_solves_pin_blas_to_one_thread():
    """pcg (hence AMG-CG and Jacobi-CG) runs with every BLAS at one thread even when the caller
    allows two: the preconditioner, called from inside the CG loop, sees 1 thread; the caller's
    setting is back afterwards."""
    import scipy.linalg  # noqa: F401  (both BLAS libraries loaded)
    from threadpoolctl import threadpool_info, threadpool_limits

    def blas_threads():
        return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]

    seen = []

    def precondition(r):
        seen.extend(blas_threads())
        return r

    A = sp.diags(np.arange(1.0, 11.0)).tocsr()
    with threadpool_limits(limits=2, user_api="blas"):
        x, _ = pcg(A, np.ones(10), precondition)
        assert set(blas_threads()) == {2}
    assert seen and set(seen) == {1}
    np.testing.assert_allclose(A @ x, np.ones(10), rtol=1e-8)


def test_auto_factorises_a_reused_matrix_and_keeps_amg_for_changing_ones(rock_model, rng, monkeypatch):
    """linear_solver="auto" above 3000 dofs: a matrix that keeps serving solves (a frozen TDG M*)
    is factorised once the AMG-CG work spent on it reaches its predicted factorisation cost (not
    before FACTOR_AFTER_SOLVES solves) and the factor used from then on; matrices used once each
    (Newton tangents) never are; nothing is factorised above direct_max_dofs. Same answers to the
    CG tolerance either way."""
    from porefsi.solid import linsolve
    from porefsi.solid.linsolve import FACTOR_AFTER_SOLVES, AdaptiveSolverFactory

    m = rock_model
    assert m.linear_solver == "auto" and m.n_dofs > 3000
    K = m.tangent(np.zeros(m.n_dofs), 1.0)
    A = (K + sp.diags(1e-2 * K.diagonal())).tocsr()  # M*-like: K plus a mass-like diagonal
    b = rng.standard_normal(m.n_dofs)
    solve = m.make_solver(A)
    auto = m._adaptive
    xs, its = [], []
    while auto.n_factorizations == 0 and len(xs) < 400:
        xs.append(solve(b))
        its.append(m.solver_factory.last.iterations if auto.n_factorizations == 0 else 0)
    k = len(xs) - 1  # solves made on AMG-CG before the factor
    assert k >= FACTOR_AFTER_SOLVES and auto.n_factorizations == 1 and m.solver_factory.n_setups == 1
    # the switch is where the counted AMG work first reaches the predicted factorisation (ski rental)
    per_it = auto._amg_seconds(A, 1)
    repaid = next(j for j in range(len(its) + 1) if per_it * sum(its[:j]) >= auto.predicted["factor_s"])
    assert k == max(FACTOR_AFTER_SOLVES, repaid)
    x_lu = xs[-1]
    np.testing.assert_allclose(x_lu, xs[-2], rtol=0, atol=1e-6 * np.abs(x_lu).max())
    assert np.linalg.norm(A @ x_lu - b) <= 1e-10 * np.linalg.norm(b)
    solve(b)
    assert auto.n_factorizations == 1  # the factor is reused
    for j in range(3):  # a new matrix per solve: AMG-CG on the shared hierarchy, no factorisation
        m.make_solver(A + sp.diags(1e-3 * (j + 1) * K.diagonal()))(b)
    assert auto.n_factorizations == 1
    capped = AdaptiveSolverFactory(m.solver_factory, factor_after=0, direct_max_dofs=m.n_dofs - 1)
    s = capped(A)
    s(b)
    s(b)
    assert capped.n_factorizations == 0
    # a factorisation predicted dearer than any run's AMG work is never made; a free one at factor_after
    monkeypatch.setattr(linsolve, "LU_SECONDS_PER_FLOP", 1e3)
    dear_rule = AdaptiveSolverFactory(m.solver_factory, factor_after=2)
    dear = dear_rule(A)
    for _ in range(6):
        dear(b)
    assert dear_rule.n_factorizations == 0 and dear_rule.predicted["factor_s"] > dear_rule.predicted["amg_s"]
    monkeypatch.setattr(linsolve, "LU_SECONDS_PER_FLOP", 0.0)
    cheap_rule = AdaptiveSolverFactory(m.solver_factory, factor_after=2)
    cheap = cheap_rule(A)
    for _ in range(3):
        cheap(b)
    assert cheap_rule.n_factorizations == 1 and cheap_rule.predicted["factor_s"] == 0.0


def test_factor_work_prediction_follows_superlu(rock_model):
    """lu_factor_flops (a node-level analysis, no factorisation of A) is within 0.6-1.6x of the sum of
    squared column counts of SuperLU's own factor of the rock's tangent, and a stiffer coupling of
    the same graph (a denser node graph: more fill) is predicted dearer."""
    import scipy.sparse.linalg as spla

    from porefsi.solid.footprint import lu_factor_flops, lu_solve_flops

    m = rock_model
    K = sp.csc_matrix(m.tangent(np.zeros(m.n_dofs), 1.0))
    lu = spla.splu(K, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    true = float(np.sum(np.diff(sp.csc_matrix(lu.L).indptr).astype(float) ** 2))
    pred = lu_factor_flops(K, m.free)
    assert 0.6 * true <= pred <= 1.6 * true
    # a substitution touches every nonzero of L and U once
    assert 0.75 * (lu.L.nnz + lu.U.nnz) <= lu_solve_flops(K, m.free) <= 1.6 * (lu.L.nnz + lu.U.nnz)  # 1.20 here
    K2 = sp.csr_matrix(K @ K)  # the squared operator's graph: every node joined to its second neighbours
    assert lu_factor_flops(K2, m.free) > 2 * pred


def test_recycled_amg_solves_match_the_direct_solve_and_skip_known_loads(rock_model, rng):
    """AMG-CG with ``recycle`` (off by default) keeps earlier solutions of one matrix (SolutionSpace)
    and starts each solve from the A-orthogonal projection of the new right-hand side onto them.
    Every answer agrees with the sparse LU to the CG tolerance; a load that combines earlier ones
    is answered by the projection alone (0 CG iterations); a partly new load needs fewer
    iterations than from zero; a new matrix starts with an empty space. Measured on this rock
    (coarsen 8, 9,783 dofs, rtol 1e-10): 13 iterations from zero, 0 for a combination, 9 for a
    combination plus a 1e-3 new part."""
    m = rock_model
    K = m.tangent(np.zeros(m.n_dofs), 1.0)
    lu = direct_solver_factory()(K)
    fac = AMGSolverFactory(m.dof_points, m.free, rtol=1e-10)
    fac.recycle = 24
    for bad in (-1, 2.5):
        with pytest.raises(InputError, match="recycle must be an integer >= 0"):
            fac.recycle = bad
    solve = fac(K)
    b1, b2, b3 = rng.standard_normal((3, m.n_dofs))

    def check(b):
        x, xd = solve(b), lu(b)
        np.testing.assert_allclose(x, xd, rtol=0, atol=1e-7 * np.abs(xd).max())
        return fac.last.iterations

    cold = check(b1)
    assert cold >= 8
    check(b2)
    assert check(2.0 * b1 - 0.5 * b2) == 0
    partly = check(b1 + b2 + 1e-3 * np.linalg.norm(b1) / np.linalg.norm(b3) * b3)
    assert 0 < partly < cold
    fresh = AMGSolverFactory(m.dof_points, m.free, rtol=1e-10)  # the default: no recycling
    s0 = fresh(K)
    s0(b1)
    s0(2.0 * b1 - 0.5 * b2)
    assert fresh.recycle == 0 and fresh.last.iterations >= 8
    K2 = (K + sp.diags(0.3 * K.diagonal())).tocsr()  # another matrix: nothing recycled from K
    x2 = fac(K2)(2.0 * b1 - 0.5 * b2)
    assert fac.last.iterations >= 5
    np.testing.assert_allclose(x2, direct_solver_factory()(K2)(2.0 * b1 - 0.5 * b2), rtol=0,
                               atol=1e-7 * np.abs(x2).max())


def test_solution_space_is_a_orthonormal_and_bounded(rng):
    """The stored directions stay A-orthonormal (W^T A W = I), a vector already in the span adds
    nothing, the oldest is dropped beyond the capacity, and the guess for b = A x with x in the span
    is x itself."""
    from porefsi.solid.linsolve import SolutionSpace

    n = 40
    G = rng.standard_normal((n, n))
    A = sp.csr_matrix(G @ G.T + n * np.eye(n))
    space = SolutionSpace(A, capacity=3)
    assert space.guess(np.ones(n)) is None
    xs = rng.standard_normal((4, n))
    space.add(xs[0])
    space.add(xs[1])
    space.add(2.0 * xs[0] - xs[1])  # in the span: no-op
    assert len(space.W) == 2
    W = np.column_stack(space.W)
    np.testing.assert_allclose(W.T @ (A @ W), np.eye(2), atol=1e-10)
    np.testing.assert_allclose(space.guess(A @ (xs[0] + 3 * xs[1])), xs[0] + 3 * xs[1], rtol=1e-9)
    space.add(xs[2])
    space.add(xs[3])
    assert len(space.W) == 3
    W = np.column_stack(space.W)
    np.testing.assert_allclose(W.T @ (A @ W), np.eye(3), atol=1e-10)
    np.testing.assert_allclose(np.column_stack(space.AW), A @ W, atol=1e-10)


def test_model_recycle_reaches_its_amg_solves(rock_model, rng):
    """``SolidModel.recycle`` (default 0) is handed to the AMG factory; each solve exposes its space
    (what a checkpoint would need), and with recycling a repeated load costs no CG iteration."""
    import copy

    m = copy.copy(rock_model)
    assert m.recycle == 0
    m.recycle, m._solver_factory = 6, None
    K = m.tangent(np.zeros(m.n_dofs), 1.0)
    solve = m.solver_factory(K)
    assert m.solver_factory.recycle == 6 and solve.space.capacity == 6
    b = rng.standard_normal(m.n_dofs)
    x = solve(b)
    assert len(solve.space.W) == 1
    np.testing.assert_allclose(solve(3.0 * b), 3.0 * x, rtol=0, atol=1e-7 * np.abs(x).max())
    assert m.solver_factory.last.iterations == 0


def _fresh_auto(m):
    """An "auto" rule on a fresh AMG factory (no hierarchy built yet) of the model ``m``."""
    from porefsi.solid.linsolve import AdaptiveSolverFactory

    return AdaptiveSolverFactory(AMGSolverFactory(m.dof_points, m.free))


def test_frozen_hint_chooses_at_the_first_solve_by_predicted_cost(rock_model, rng):
    """With ``expected_solves`` (the hint that a matrix is frozen) "auto" decides at the matrix's first
    solve: the sparse LU when factor + that many substitutions is predicted cheaper than an AMG set-up
    + HINT_ITERATIONS_PER_SOLVE iterations per solve, AMG-CG otherwise. On this rock (9,783 dofs) the
    break-even is ~9 solves: half of it stays on AMG-CG (no factor, then or at the 2nd solve), twice
    it factorises before the first solve (no hierarchy built). Both answer like the default (the
    counting rule: AMG-CG here) to the CG tolerance; ``use_hints = False`` ignores the hint."""
    from porefsi.solid import linsolve
    from porefsi.solid.footprint import predict_solver_costs

    m = rock_model
    K = m.tangent(np.zeros(m.n_dofs), 1.0)
    b = rng.standard_normal(m.n_dofs)
    cost = predict_solver_costs(K, m.free)
    per_solve = linsolve.HINT_ITERATIONS_PER_SOLVE * cost.amg_iteration_s - cost.lu_solve_s
    n_even = (cost.factor_s - cost.amg_setup_s) / per_solve
    assert per_solve > 0 and 4 < n_even < 40  # the rock sits where both choices occur
    x_default = _fresh_auto(m)(K)(b)
    few, many = _fresh_auto(m), _fresh_auto(m)
    s_few, s_many = few(K, expected_solves=int(n_even / 2)), many(K, expected_solves=int(2 * n_even) + 1)
    x_few, x_many = s_few(b), s_many(b)
    assert few.predicted["choice"] == "amg" and few.n_factorizations == 0 and few.amg.n_setups == 1
    assert many.predicted["choice"] == "direct" and many.n_factorizations == 1 and many.amg.ml is None
    assert many.predicted["direct_s"] < many.predicted["amg_s"] and few.predicted["direct_s"] > few.predicted["amg_s"]
    s_few(b)
    assert few.n_factorizations == 0  # AMG-CG chosen: the counting rule waits for its 20th solve
    for x in (x_few, x_many):
        np.testing.assert_allclose(x, x_default, rtol=0, atol=1e-6 * np.abs(x_default).max())
    assert np.linalg.norm(K @ x_many - b) <= 1e-10 * np.linalg.norm(b)
    off = _fresh_auto(m)
    off.use_hints = False
    off(K, expected_solves=int(2 * n_even) + 1)(b)
    assert off.n_factorizations == 0 and "choice" not in off.predicted


def test_static_stepper_hints_its_frozen_tangent(rock_model):
    """The static coupled stepper passes ``2 x horizon_steps`` solves as the hint for its reused
    tangent: a long horizon factorises it at the first step, a short one (or none: the default rule)
    stays on AMG-CG, and all three reach the same equilibrium to the Newton tolerance."""
    import copy

    from porefsi.coupling.solid_step import StaticStepper

    F = np.zeros((rock_model.mesh.n_nodes, 3))
    F[:, 0] = 1e-4 * np.sin(rock_model.mesh.points[:, 2] / 1e-4)  # a smooth lateral load, N
    out = {}
    for horizon in (0, 2, 100):
        m = copy.copy(rock_model)
        m._solver_factory = m._adaptive = None
        m.horizon_steps = horizon
        u0 = np.zeros(m.n_dofs)
        u1, _ = StaticStepper(m).step(u0, u0, 0.0, 0.1, {0.1: F})
        out[horizon] = (u1, m._adaptive)
    assert out[0][1].n_factorizations == 0 and "expected_solves" not in out[0][1].predicted
    assert out[2][1].n_factorizations == 0 and out[2][1].predicted["expected_solves"] == 4
    assert out[100][1].n_factorizations == 1 and out[100][1].predicted["expected_solves"] == 200
    u_ref = out[0][0]
    for h in (2, 100):
        np.testing.assert_allclose(out[h][0], u_ref, rtol=0, atol=1e-6 * np.abs(u_ref).max())
