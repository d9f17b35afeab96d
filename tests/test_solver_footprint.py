"""Large runs: the solver choice (direct -> AMG-CG), the memory estimate and its refusal, AMG agreeing with LU."""

import warnings

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from porefsi.case import resources
from porefsi.case.config import Case, case_to_toml
from porefsi.case.problem import problem_from_case
from porefsi.cli import main
from porefsi.coupling import CoupledRun
from porefsi.coupling.problem import SolverChoiceWarning
from porefsi.errors import ConfigError
from porefsi.image.io import load_sample
from porefsi.image.ops import crop
from porefsi.solid import footprint
from porefsi.solid.mesh import mesh_size, mesh_solid

GiB = 2.0**30


def test_direct_stays_direct_when_small_and_room():
    assert footprint.choose_linear_solver("direct", 39_000, 20 * GiB) == footprint.SolverChoice("direct")
    for other in ("amg", "jacobi", "auto"):  # only "direct" is ever changed
        assert footprint.choose_linear_solver(other, 10**7, 1.0).kind == other


def test_direct_becomes_amg_above_the_size_threshold_or_without_room():
    big = footprint.choose_linear_solver("direct", footprint.DIRECT_MAX_DOFS + 1, 1e15)
    assert big.kind == "amg" and "direct" in big.reason and "GiB" in big.reason
    tight = footprint.choose_linear_solver("direct", 95_000, 2 * GiB)  # the factor needs ~1.7 GiB
    assert tight.kind == "amg" and "available" in tight.reason
    # a small factor never switches, however little is free (the estimate is no better than that)
    assert footprint.choose_linear_solver("direct", 39_000, 0.1 * GiB).kind == "direct"


def test_lu_fill_model_matches_a_factorisation():
    """The fill model (fitted on Berea crops) predicts the LU of another rock within 35 %."""
    img = crop(load_sample(), [0, 0, 0], [60, 60, 60])  # 10k dofs at coarsen 4
    from porefsi.coupling.options import SolidOptions
    from porefsi.coupling.problem import build_solid

    _, model = build_solid(img, SolidOptions(coarsen=4))
    K = sp.csc_matrix(model.tangent(np.zeros(model.n_dofs), 0.0))
    lu = spla.splu(K, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    nnz = lu.L.nnz + lu.U.nnz
    model_nnz = footprint.LU_FILL_COEF * model.n_dofs**footprint.LU_FILL_EXP
    assert 0.65 < model_nnz / nnz < 1.35, (model.n_dofs, nnz, model_nnz)


@pytest.mark.parametrize("coarsen", [1, 2, 4])
def test_mesh_size_counts_the_mesh_without_building_it(coarsen):
    img = crop(load_sample(), [0, 0, 0], [40, 40, 40])
    m = mesh_solid(img, coarsen=coarsen, keep="largest", support_axis=None)
    n_tets, n_nodes = mesh_size(img, coarsen=coarsen)
    # upper bounds (floating solid is counted), equal up to the grains mesh_solid drops
    assert m.mesh.n_tets <= n_tets <= m.mesh.n_tets / (1 - m.removed_solid_fraction) + 1e-9
    assert m.mesh.n_nodes <= n_nodes <= 1.02 * m.mesh.n_nodes


def test_estimate_refuses_with_the_need_and_the_fix():
    est = resources.estimate_run(load_sample(), 5, "direct", budget=20 * GiB)
    assert est.linear_solver == "direct" and est.n_tets == mesh_size(load_sample(), coarsen=5)[0]
    resources.require_memory(est, budget=20 * GiB)  # fits: no error
    resources.require_memory(est, budget=0.05 * GiB)  # below the 1 GiB floor: never refused
    full = resources.estimate_run(load_sample(), 1, "direct", budget=4 * GiB)  # every voxel meshed: 7M tets
    assert full.linear_solver == "amg" and full.peak_bytes > 4 * GiB
    need = r"needs ~[0-9.]+ GiB .*7,013,835 tetrahedra.*4 GiB is available.*coarsen \(now 1"
    with pytest.raises(ConfigError, match=need):
        resources.require_memory(full, budget=4 * GiB)


def test_cli_stops_in_one_line_before_building(tmp_path, monkeypatch, capsys):
    """A run the machine cannot hold: exit 2, one line naming the memory and the setting, no outputs."""
    monkeypatch.setattr(resources, "memory_budget", lambda: 4 * GiB)
    case_file = tmp_path / "case.toml"
    case_file.write_text(case_to_toml(Case().replace(solid={"coarsen": 1}, output={"figures": False, "vtk": False})))
    out = tmp_path / "out"
    assert main(["run", str(case_file), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "memory" in err[0] and "[solid] coarsen" in err[0], err
    assert not out.exists() or not any(out.iterdir())


def _run(case: Case, steps: int):
    run = CoupledRun(problem_from_case(case))
    recs = [run.advance() for _ in range(steps)]
    return run, recs


def test_amg_path_agrees_with_direct_on_a_mid_size_crop(monkeypatch):
    """Above the threshold "direct" runs AMG-CG (with a warning); the run agrees with the LU's.

    The static solid's modified Newton stops at a residual 1e-8 of the load, and AMG-CG
    at a residual 1e-8 of the right-hand side: the displacements must agree to 1e-6 relative
    (measured: 4e-10 to 1.4e-9).
    """
    case = Case().replace(image={"crop": [[20, 100], [20, 100], [20, 100]]}, solid={"coarsen": 4},
                          drainage={"t_end": 2.0}, output={"figures": False, "vtk": False})
    direct_run, direct = _run(case, 2)
    assert direct_run.model.linear_solver == "direct"
    monkeypatch.setattr(footprint, "DIRECT_MAX_DOFS", 1000)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        amg_run, amg = _run(case, 2)
    assert amg_run.model.linear_solver == "amg" and amg_run.model.solver_factory.n_setups >= 1
    assert direct_run.model._solver_factory is None  # the LU run never built a hierarchy
    assert any(issubclass(w.category, SolverChoiceWarning) for w in caught)
    for a, b in zip(direct, amg, strict=True):
        assert a.row["sw"] == b.row["sw"]  # the fluid does not see the solid's solver (one-way per step)
        scale = np.abs(a.displacement).max()
        assert scale > 0
        assert np.abs(a.displacement - b.displacement).max() <= 1e-6 * scale


def test_padded_matrix_is_the_free_block_with_the_mean_diagonal_elsewhere():
    """The AMG hierarchy's full-size matrix, built in CSR order, against a dense construction."""
    from porefsi.solid.linsolve import AMGSolverFactory

    rng = np.random.default_rng(1)
    n_nodes = 50
    free = np.sort(rng.choice(3 * n_nodes, 120, replace=False))
    M = sp.random(120, 120, density=0.2, random_state=2)
    A = (M + M.T + 5 * sp.eye(120)).tocsr()
    padded = AMGSolverFactory(rng.random((n_nodes, 3)), free)._padded(A)
    assert padded.blocksize == (3, 3)
    ref = np.zeros((3 * n_nodes, 3 * n_nodes))
    ref[np.ix_(free, free)] = A.toarray()
    cons = np.setdiff1d(np.arange(3 * n_nodes), free)
    ref[cons, cons] = A.diagonal().mean()
    assert np.array_equal(padded.toarray(), ref)


def test_resumed_amg_run_repeats_the_uninterrupted_one_bit_for_bit():
    """The warm start of the static solid's AMG solves is checkpointed: a restored run goes on exactly."""
    case = Case().replace(image={"crop": [[20, 80], [20, 80], [20, 80]]}, solid={"coarsen": 3, "linear_solver": "amg"},
                          drainage={"t_end": 3.0}, output={"figures": False, "vtk": False})
    problem = problem_from_case(case)
    whole = CoupledRun(problem)
    for _ in range(3):
        whole.advance()
    first = CoupledRun(problem)
    first.advance()
    first.advance()
    arrays, meta = first.checkpoint()
    assert "static_guess" in arrays
    resumed = CoupledRun.restore(problem, arrays, meta)
    resumed.advance()
    assert np.array_equal(resumed.u, whole.u)
