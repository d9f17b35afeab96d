"""The linear-response solid (porefsi.coupling.linear_step) against the full nonlinear model.

Truths: the nonlinear (St Venant-Kirchhoff) Newton solve of the same mesh and load, whose
difference from the linearisation grows with the strain (exactly linear in it to first order),
and the Lamé thick-sphere bounds of a pressurised cavity (tests/test_coupling_lame.py's set-up).
"""

import dataclasses

import numpy as np
import pytest

from porefsi.case.config import Case
from porefsi.case.problem import problem_from_case
from porefsi.coupling import boundary_facet_normals, facet_pores_from_labels, traction_interface
from porefsi.coupling.linear_step import (
    LinearStepper,
    clear_response_cache,
    linear_response,
    make_stepper,
    max_green_lagrange,
)
from porefsi.coupling.loop import CoupledRun
from porefsi.coupling.solid_step import StaticStepper, TDGStepper
from porefsi.errors import ConfigError, InputError
from porefsi.image import VoxelImage
from porefsi.solid.bc import Fixed, uniaxial_bcs
from porefsi.solid.materials import make_material
from porefsi.solid.mesh import mesh_solid
from porefsi.solid.model import SolidModel
from porefsi.solid.static import solve_static

N, H = 14, 1e-6
P2 = np.array([3e3, 1e3])  # two different pore pressures, Pa (a swapped index changes the answer)


@pytest.fixture(scope="module")
def two_pores():
    """A 14³ block with two cavities of different size (labels 0 and 1) and their traction interface."""
    g = np.arange(N) + 0.5
    X, Y, Z = np.meshgrid(g, g, g, indexing="ij")
    lab = np.full((N, N, N), -1)
    lab[(X - 4.5) ** 2 + (Y - 7) ** 2 + (Z - 7) ** 2 < 2.6**2] = 0
    lab[(X - 10) ** 2 + (Y - 7) ** 2 + (Z - 7) ** 2 < 2.0**2] = 1
    mesh = mesh_solid(VoxelImage((lab >= 0).astype(np.uint8), H), coarsen=1, support_axis=None).mesh
    facets = mesh.facets_tagged("pore_wall")
    nrm, _ = boundary_facet_normals(mesh.points, mesh.tets, facets)
    owner = facet_pores_from_labels(mesh.points, facets, nrm, lab, H)
    return mesh, traction_interface(mesh.points, mesh.tets, facets, owner, 2)


def _model(mesh, E, rate=0.0):
    return SolidModel(mesh, make_material("svk", E=E, nu=0.28), uniaxial_bcs(2, rate=rate), linear_solver="direct")


def _nonlinear(model, itf, P, t=0.0):
    return solve_static(model.with_nodal_forces(itf.nodal_forces(P)), t, rtol=1e-12)[0]


def _rel(a, b):
    return float(np.abs(a - b).max() / np.abs(b).max())


def test_unit_responses_superpose_to_the_nonlinear_solution_at_small_strain(two_pores):
    mesh, itf = two_pores
    clear_response_cache()
    model = _model(mesh, 20e9)  # strain ~ P/E ~ 1e-7
    resp = linear_response(model)
    cols, U, a, b = resp.responses(itf)
    assert list(cols) == [0, 1] and U.shape == (model.n_dofs, 2)
    un = _nonlinear(model, itf, P2)
    ul = a + U @ P2
    assert _rel(ul, un) < 1e-6  # measured 1.0e-7: the nonlinearity at strain 1.5e-7
    # each column is the response to one pore alone (a swapped index or a scaled force fails here)
    for i in range(2):
        e = np.zeros(2)
        e[i] = P2[i]
        assert _rel(U[:, i] * P2[i], _nonlinear(model, itf, e)) < 1e-6
    # the back-substitution path gives the same (round-off)
    fext = model.with_nodal_forces(itf.nodal_forces(P2)).external_force(0.0)
    assert _rel(resp.static(fext, 0.0), ul) < 1e-12


def test_prescribed_motion_is_superposed_too(two_pores):
    """A moving face (strain rate) adds ``t b``: the linear solution still matches Newton's at small strain."""
    mesh, itf = two_pores
    model = _model(mesh, 20e9, rate=-1e-7 * N * H)  # 1e-7 strain per second
    cols, U, a, b = linear_response(model).responses(itf)
    t = 2.0
    un = _nonlinear(model, itf, P2, t)
    assert _rel(a + t * b + U @ P2, un) < 1e-6
    assert np.abs(b).max() > 0.1 * np.abs(un).max() / t  # the motion is a real part of the answer


@pytest.mark.parametrize("E,lo,hi", [(2e7, 5e-5, 2e-4), (2e6, 5e-4, 2e-3), (2e5, 5e-3, 2e-2)])
def test_linearisation_error_grows_with_strain_and_the_estimate_tracks_it(two_pores, E, lo, hi):
    """Error ~ strain (P/E = 1.5e-4 .. 1.5e-2 -> 1e-4 .. 1e-2) and the one-Newton-step estimate within 10 %."""
    mesh, itf = two_pores
    model = _model(mesh, E)
    cols, U, a, b = linear_response(model).responses(itf)
    ul = a + U @ P2
    err = _rel(ul, _nonlinear(model, itf, P2))
    est = LinearStepper(StaticStepper(model), "auto", 1e-3, interface=itf).estimate(ul, 0.0)
    assert lo < err < hi
    assert abs(est / err - 1) < 0.1, (est, err)


def _forces(itf, P, t):
    return {t: itf.nodal_forces(P)}


def test_auto_falls_back_at_large_strain_and_linear_does_not(two_pores):
    mesh, itf = two_pores
    model = _model(mesh, 2e5)  # strain 1.5e-2: linear off by 1e-2
    u0 = np.zeros(model.n_dofs)
    pressures = {1.0: P2}
    auto = make_stepper(model, response="auto", response_tol=1e-3, interface=itf)
    u_auto, _ = auto.step(u0, u0, 0.0, 1.0, _forces(itf, P2, 1.0), pressures, itf)
    assert auto.fallen is not None and auto.path == "nonlinear"
    assert auto.summary()["fallback"]["estimate"] > 1e-3
    un = _nonlinear(model, itf, P2, 1.0)
    assert _rel(u_auto, un) < 1e-7  # the step was redone nonlinearly
    lin = make_stepper(model, response="linear", response_tol=1e-3, interface=itf)
    u_lin, _ = lin.step(u0, u0, 0.0, 1.0, _forces(itf, P2, 1.0), pressures, itf)
    assert lin.fallen is None and lin.max_estimate > 1e-3 and _rel(u_lin, un) > 5e-3
    # once fallen back, it stays nonlinear, and a checkpoint says so
    arrays, meta = auto.state()
    again = make_stepper(model, response="auto", interface=itf)
    again.restore(arrays, meta)
    assert again.fallen is not None


def test_auto_stays_linear_at_small_strain_and_falls_back_on_a_rebuilt_interface(two_pores):
    mesh, itf = two_pores
    model = _model(mesh, 20e9)
    st = make_stepper(model, response="auto", interface=itf, n_steps=1000)  # long run: unit responses at once
    u = v = np.zeros(model.n_dofs)
    for k in range(3):
        t1 = k + 1.0
        P = P2 * t1
        u, v = st.step(u, v, k, 1.0, _forces(itf, P, t1), {t1: P}, itf)
        assert _rel(u, _nonlinear(model, itf, P, t1)) < 1e-6
    assert st.fallen is None and st.path == "linear (unit responses)" and st.n_checks >= 1
    restored = dataclasses.replace(itf)  # the same operator in a new object (a resumed run's): still linear
    u, v = st.step(u, v, 3.0, 1.0, _forces(restored, P2 * 4, 4.0), {4.0: P2 * 4}, restored)
    assert st.fallen is None and _rel(u, _nonlinear(model, itf, P2 * 4, 4.0)) < 1e-6
    other = dataclasses.replace(itf, operator=itf.operator[:, [1, 0]].tocsr())  # a re-extraction's new pores
    st.step(u, v, 4.0, 1.0, _forces(other, P2, 5.0), {5.0: P2}, other)
    assert st.fallen is not None and "re-extraction" in st.fallen["reason"]


def test_lame_cavity_linear_work_within_the_thick_sphere_bounds():
    """The unit response of a pressurised spherical cavity: its work lies in the Lamé bracket."""
    n, a_vox, E, nu, P = 20, 4.0, 20e9, 0.28, 1e6
    g = np.arange(n) + 0.5
    X, Y, Z = np.meshgrid(g, g, g, indexing="ij")
    cav = (X - n / 2) ** 2 + (Y - n / 2) ** 2 + (Z - n / 2) ** 2 < a_vox**2
    mesh = mesh_solid(VoxelImage(cav.astype(np.uint8), H), coarsen=1, support_axis=None).mesh
    model = SolidModel(mesh, make_material("svk", E=E, nu=nu), [Fixed(f) for f in
                                                                ("xmin", "xmax", "ymin", "ymax", "zmin", "zmax")])
    facets = mesh.facets_tagged("pore_wall")
    nrm, _ = boundary_facet_normals(mesh.points, mesh.tets, facets)
    itf = traction_interface(mesh.points, mesh.tets, facets,
                             facet_pores_from_labels(mesh.points, facets, nrm, np.where(cav, 0, -1), H), 1)
    cols, U, _, _ = linear_response(model).responses(itf)
    work = float(P * (itf.nodal_forces([P]).ravel()[model.free] @ U[:, 0]))
    a = (3 * cav.sum() * H**3 / (4 * np.pi)) ** (1 / 3)
    G, K = E / (2 * (1 + nu)), E / (3 * (1 - 2 * nu))

    def lame(b):  # P dV of a thick sphere a < r < b clamped at b
        B = P / (3 * K / b**3 + 4 * G / a**3)
        return P * 4 * np.pi * a**2 * B * (1 / a**2 - a / b**3)

    L = n / 2 * H
    assert 0.95 * lame(L) < work < lame(np.sqrt(3) * L)


def _small_case(**solid):
    return Case().replace(solid={"coarsen": 10, **solid}, drainage={"t_end": 3.0})


@pytest.mark.parametrize("integrator", ["static", "tdg"])
def test_coupled_run_linear_matches_nonlinear(integrator):
    """Three exchange steps on the built-in sample (coarsen 10): same displacements to 1e-6."""
    runs = {}
    for resp in ("nonlinear", "auto"):
        prob = problem_from_case(_small_case(response=resp).replace(coupling={"integrator": integrator}))
        run = CoupledRun(prob)
        runs[resp] = (run, [r.displacement for r in run.steps()])
    (_, a), (lin, b) = runs["nonlinear"], runs["auto"]
    assert len(a) == len(b) == 3
    for x, y in zip(a, b, strict=True):
        assert _rel(y, x) < 1e-6
    s = lin.solid.summary()
    assert s["fallback"] is None and s["path"].startswith("linear") and s["checks"] >= 1
    assert 0 < s["max_estimated_error"] < 1e-5 and 0 < s["max_strain_at_checks"] < 1e-5


def test_options_validate_the_response_keys():
    with pytest.raises(ConfigError):
        _small_case(response="quadratic")
    with pytest.raises(ConfigError):
        _small_case(response_tol=0.0)
    with pytest.raises(InputError):
        LinearStepper(TDGStepper.__new__(TDGStepper), "nonlinear")


def test_run_case_records_the_solid_response_in_the_summary(tmp_path):
    from porefsi.case.run import run_case

    case = _small_case(response="auto").replace(drainage={"t_end": 2.0},
                                                output={"figures": False, "vtk": False, "snapshot_times": [1.0]})
    s = run_case(case, tmp_path / "run", progress=False).summary
    assert s["solid_response"]["requested"] == "auto" and s["solid_response"]["path"].startswith("linear")
    assert s["solid_response"]["fallback"] is None and s["solid_response"]["linear_steps"] == 2


def test_checkpoint_resume_of_a_linear_run_agrees_to_round_off():
    prob = problem_from_case(_small_case(response="auto"))
    whole = CoupledRun(prob)
    ref = [r.displacement for r in whole.steps()]
    first = CoupledRun(prob)
    first.advance()
    arrays, meta = first.checkpoint()
    assert meta["linear_steps"] == 1 and meta["linear_fallen"] is False
    clear_response_cache()  # a new process: nothing cached
    again = CoupledRun.restore(prob, arrays, meta)
    rest = [r.displacement for r in again.steps()]
    assert len(rest) == 2 and again.solid.n_linear == 3
    for x, y in zip(ref[1:], rest, strict=True):
        assert _rel(y, x) < 1e-12


def test_max_green_lagrange_of_a_homogeneous_deformation():
    """E = (F^T F - I) / 2 for u = G X: the largest |principal value|, in closed form."""
    mesh = mesh_solid(VoxelImage(np.zeros((3, 3, 3), np.uint8), H), coarsen=1, support_axis=None).mesh
    G = np.array([[0.1, 0.02, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, -0.05]])
    F = np.eye(3) + G
    E = 0.5 * (F.T @ F - np.eye(3))
    got = max_green_lagrange(SolidModel(mesh, make_material("svk")), mesh.points @ G.T)
    assert got == pytest.approx(np.abs(np.linalg.eigvalsh(E)).max(), rel=1e-12)


def test_unit_responses_only_within_the_memory_budget(two_pores, monkeypatch):
    import porefsi.coupling.linear_step as ls

    mesh, itf = two_pores
    model = _model(mesh, 20e9)
    u0 = np.zeros(model.n_dofs)
    monkeypatch.setattr(ls, "RESPONSE_BUDGET_BYTES", 8 * model.n_dofs * 2 - 1)  # one column short
    st = make_stepper(model, response="auto", interface=itf, n_steps=1000)
    u1, _ = st.step(u0, u0, 0.0, 1.0, _forces(itf, P2, 1.0), {1.0: P2}, itf)
    assert st.path == "linear (back-substitution)"
    monkeypatch.setattr(ls, "RESPONSE_BUDGET_BYTES", 8 * model.n_dofs * 2)
    st = make_stepper(model, response="auto", interface=itf, n_steps=1000)
    u2, _ = st.step(u0, u0, 0.0, 1.0, _forces(itf, P2, 1.0), {1.0: P2}, itf)
    assert st.path == "linear (unit responses)" and _rel(u2, u1) < 1e-12


def test_auto_falls_back_before_the_error_can_pass_the_tolerance(two_pores):
    """An estimate just below the tolerance may grow 25 % before the next check: auto falls back already."""
    mesh, itf = two_pores
    model = _model(mesh, 2e7)
    u0 = np.zeros(model.n_dofs)
    lin = make_stepper(model, response="linear", interface=itf)
    lin.step(u0, u0, 0.0, 1.0, _forces(itf, P2, 1.0), {1.0: P2}, itf)
    est = lin.max_estimate
    for tol, falls in ((1.1 * est, True), (1.3 * est, False)):
        auto = make_stepper(model, response="auto", response_tol=tol, interface=itf)
        auto.step(u0, u0, 0.0, 1.0, _forces(itf, P2, 1.0), {1.0: P2}, itf)
        assert (auto.fallen is not None) == falls, tol / est


def test_stepper_with_a_moving_face_through_the_unit_responses(two_pores):
    """The unit-response path adds the prescribed motion at the step's end time (``a + t b``)."""
    mesh, itf = two_pores
    model = _model(mesh, 20e9, rate=-1e-7 * N * H)
    st = make_stepper(model, response="auto", interface=itf, n_steps=1000)
    u = v = np.zeros(model.n_dofs)
    for k in range(2):
        u, v = st.step(u, v, float(k), 1.0, _forces(itf, P2, k + 1.0), {k + 1.0: P2}, itf)
    assert st.path == "linear (unit responses)"
    assert _rel(u, _nonlinear(model, itf, P2, 2.0)) < 1e-6
