"""The coupled loop and the case runner: smoke run, resume equivalence, linear-regime physics."""

import csv
import dataclasses
import json

import numpy as np
import pytest

from porefsi.case.config import Case, smoke_case
from porefsi.case.problem import problem_from_case as build_problem
from porefsi.case.run import run_case
from porefsi.cli import main
from porefsi.coupling.loop import TIMESERIES_COLUMNS, CoupledRun
from porefsi.errors import ConfigError

SUMMARY_KEYS = ("wall_seconds", "n_pores", "n_throats", "n_nodes", "n_tets", "t_end_s", "final_sw",
                "breakthrough_time_s", "max_displacement_m", "max_von_mises_Pa", "permeability_initial_m2",
                "permeability_final_m2", "mass_balance_error", "load_balance_error")


def _small(**sections) -> Case:
    """The default case made small: coarse mesh, 3 exchange steps of 1 s, few test points."""
    base = Case().replace(solid={"coarsen": 10}, drainage={"t_end": 3.0}, interface={"n_test_points": 100},
                          output={"snapshot_times": [1.0], "checkpoint_every": 1, "figures": False})
    return base.replace(**sections) if sections else base


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    out = tmp_path_factory.mktemp("full")
    return run_case(_small(), out, progress=False)


def test_smoke_run_writes_every_output(finished):
    out, s = finished.directory, finished.summary
    assert s["status"] == "completed"
    for k in SUMMARY_KEYS:
        assert k in s
    assert json.loads((out / "summary.json").read_text())["n_tets"] == s["n_tets"]
    rows = list(csv.DictReader((out / "timeseries.csv").open()))
    assert [r["step"] for r in rows] == ["0", "1", "2", "3"]
    assert set(TIMESERIES_COLUMNS) == set(rows[0])
    for f in ("case.toml", "solid.pvd", "network.pvd", "checkpoint.npz", "vtk/solid_0000.vtu", "vtk/network_0003.vtp"):
        assert (out / f).is_file(), f
    # Injection at a constant rate into incompressible fluids: Sw falls by exactly Q t / V_pore.
    sw = np.array([float(r["sw"]) for r in rows])
    assert np.all(np.diff(sw) < 0) and s["mass_balance_error"] < 1e-12
    assert s["max_displacement_m"] > 0 and s["max_von_mises_Pa"] > 0
    # set-up and per-step stages are reported apart (the interface is built once, used every step)
    stages = s["seconds_by_stage"]
    assert {"extraction", "mesh", "interface_build", "interface", "fluid", "solid"} <= set(stages)


def _assert_same_run(a, b):
    """Two runs (RunOutput) agree bit for bit: every time-series column but the wall time, and
    the final solid state (u and v) and network in their checkpoints."""
    from porefsi.io.results import load_checkpoint

    for k in TIMESERIES_COLUMNS:
        if k != "wall_s":
            np.testing.assert_array_equal(a.timeseries[k], b.timeseries[k], err_msg=k)
    ca, cb = (load_checkpoint(r.directory / "checkpoint.npz")[0] for r in (a, b))
    assert ca.keys() == cb.keys()
    for k in ("u", "v", "labels", *(k for k in ca if k.startswith(("sim.", "network.")))):
        if "seconds" not in k:  # the drainage solver's set-up time
            np.testing.assert_array_equal(ca[k], cb[k], err_msg=k)


def test_resume_gives_the_uninterrupted_result(finished, tmp_path):
    """Bit for bit: the static solve's factorisation is rebuilt from the (u, t) it was built at,
    which the checkpoint stores (rebuilding it at the resumed state agreed only to ~5e-10)."""
    out = tmp_path / "resumed"
    first = run_case(_small(), out, progress=False, stop_after=1)
    assert first.summary["status"] == "interrupted" and first.summary["n_exchange_steps"] == 1
    again = run_case(_small(), out, resume=True, progress=False)
    assert again.summary["status"] == "completed"
    _assert_same_run(finished, again)


RESUME_CASES = {
    # the paper's solid and interface: TDG (2 passes, left rule) with the hull; the stepper's
    # reused tangent and the velocity are part of the state
    "tdg-hull-left": {"interface": {"method": "hull"}, "coupling": {"integrator": "tdg", "tdg_load_rule": "left"}},
    # re-extraction across topology changes (network, labels and interface restored), TDG solid
    "reextract-tdg": {"solid": {"strain_rate": 5e-3}, "network": {"update": "reextract"},
                      "coupling": {"integrator": "tdg"}},
    # killed just before a shorter last step (t_end = 3.5 s): the resumed run makes a new stepper
    # for the new dt, as the uninterrupted one does, instead of reusing the checkpointed tangent
    "tdg-short-last-step": {"drainage": {"t_end": 3.5}, "coupling": {"integrator": "tdg"}},
}


@pytest.mark.parametrize("name", list(RESUME_CASES))
def test_resume_is_bit_for_bit(tmp_path, name):
    """Killed after 2 (or 3) of 4 steps and resumed: equal to the uninterrupted run bit for bit.
    The restored velocity matters (zeroing it on restore changes u and v in the last bits)."""
    case = _small(drainage={"t_end": 4.0}).replace(**RESUME_CASES[name])
    whole = run_case(case, tmp_path / "whole", progress=False)
    run_case(case, tmp_path / "cut", progress=False, stop_after=3 if "short" in name else 2)
    resumed = run_case(case, tmp_path / "cut", resume=True, progress=False)
    assert resumed.summary["n_exchange_steps"] == 4
    _assert_same_run(whole, resumed)
    if name.startswith("reextract"):
        assert resumed.summary["n_pores"] == whole.summary["n_pores"]


def test_resumed_wall_seconds_are_cumulative(tmp_path):
    """summary.wall_seconds counts the interrupted process up to its checkpoint plus the resuming
    one; wall_seconds_this_process only the latter."""
    from porefsi.io.results import load_checkpoint

    out = tmp_path / "r"
    first = run_case(_small(), out, progress=False, stop_after=2)
    saved = load_checkpoint(out / "checkpoint.npz")[1]["wall_seconds"]
    assert 0 < saved <= first.summary["wall_seconds"]
    s = run_case(_small(), out, resume=True, progress=False).summary
    assert s["wall_seconds"] == pytest.approx(saved + s["wall_seconds_this_process"], rel=1e-6)
    assert s["wall_seconds"] > s["wall_seconds_this_process"] > 0


def test_cpu_seconds_by_stage():
    """cpu_seconds_by_stage (time.process_time) has the stages of the wall-time breakdown, each
    >= 0, and they sum to no more than the CPU time of the whole run measured around it."""
    import tempfile
    import time

    with tempfile.TemporaryDirectory() as d:
        c0 = time.process_time()
        s = run_case(_small(), d, progress=False).summary
        cpu = time.process_time() - c0
    stages = s["cpu_seconds_by_stage"]
    assert set(stages) == set(s["seconds_by_stage"])
    assert {"image", "extraction", "mesh", "interface_build", "fluid", "interface", "solid", "update", "stress",
            "permeability"} <= set(stages)
    assert all(v >= 0 for v in stages.values())
    assert stages["solid"] > 0 and stages["mesh"] > 0
    assert sum(stages.values()) <= s["cpu_seconds_this_process"] <= cpu
    assert s["cpu_seconds"] == s["cpu_seconds_this_process"]
    assert s["reextraction"] is None  # geometric update


def test_resumed_cpu_seconds_are_cumulative(tmp_path):
    """CPU time is checkpointed like the wall time: the resumed summary's stage CPU seconds
    include the interrupted process's (up to its checkpoint), and so does cpu_seconds."""
    from porefsi.io.results import load_checkpoint

    out = tmp_path / "r"
    run_case(_small(), out, progress=False, stop_after=2)
    meta = load_checkpoint(out / "checkpoint.npz")[1]
    saved_stage, saved_setup, saved = meta["cpu_seconds"], meta["setup_cpu_seconds"], meta["process_cpu_seconds"]
    assert saved_stage["solid"] > 0 and saved > 0
    recs = []
    s = run_case(_small(), out, resume=True, progress=False, on_record=recs.append).summary
    stages = s["cpu_seconds_by_stage"]
    assert len(recs) == 1  # one more step on top of the checkpointed two
    for k, v in saved_stage.items():  # the checkpointed stages plus the resumed step's
        assert stages[k] == pytest.approx(v + recs[0].cpu_seconds[k], rel=1e-12, abs=1e-12), k
    assert all(stages[k] == v for k, v in saved_setup.items())  # set-up counted once, in the first process
    assert s["cpu_seconds"] == pytest.approx(saved + s["cpu_seconds_this_process"], rel=1e-6)


def test_progress_eta_counts_only_this_process(monkeypatch):
    """After a resume from step 6 of 10, one step in 2 s leaves 3 steps: ETA 6 s (it used to
    divide by all 7 done steps: 0.9 s)."""
    import io

    from porefsi.case import run as run_mod

    clock = iter([100.0, 102.0])
    monkeypatch.setattr(run_mod.time, "perf_counter", lambda: next(clock))
    buf = io.StringIO()
    bar = run_mod._Progress(10, True, start=6, stream=buf)
    bar.update(7, 7.0, "Sw=0.990")
    line = buf.getvalue()
    assert line.startswith("\r[#####################") and " 7/10 t=7 s" in line
    assert "2.0 s, ETA    6.0 s Sw=0.990" in line


def test_resumed_run_starts_its_progress_bar_at_the_checkpoint(tmp_path, monkeypatch):
    import io

    from porefsi.case import run as run_mod

    made = []

    class Spy(run_mod._Progress):
        def __init__(self, total, enabled, start=0, stream=None, lines=False):
            super().__init__(total, enabled, start, stream=io.StringIO(), lines=lines)
            made.append(self)

    monkeypatch.setattr(run_mod, "_Progress", Spy)
    out = tmp_path / "r"
    run_case(_small(), out, progress=True, stop_after=1)
    run_case(_small(), out, resume=True, progress=True)
    assert [(b.start, b.total) for b in made] == [(0, 3), (1, 3)]
    text = made[1].stream.getvalue()
    assert " 2/3 " in text and " 3/3 " in text and " 1/3 " not in text and text.endswith("\n")


def test_resume_refuses_another_case_or_no_checkpoint(finished, tmp_path):
    with pytest.raises(ConfigError, match="differs"):
        run_case(_small(fluids={"sigma": 0.05}), finished.directory, resume=True, progress=False)
    with pytest.raises(ConfigError, match="no checkpoint"):
        run_case(_small(), tmp_path / "empty", resume=True, progress=False)


def test_case_newton_rtol_reaches_the_run_stepper():
    """``solid.newton_rtol`` of a case is the tolerance of the coupled run's static stepper."""
    run = CoupledRun(build_problem(_small(solid={"coarsen": 10, "newton_rtol": 3e-5})))
    assert run.solid.rtol == 3e-5
    with pytest.raises(ConfigError, match="newton_rtol"):
        _small(solid={"newton_rtol": 0.5})


def test_no_pressure_no_strain_no_motion():
    run = CoupledRun(build_problem(_small(drainage={"t_end": 2.0})))
    itf = run.interface
    run.interface = dataclasses.replace(itf, operator=itf.operator * 0.0)
    for rec in run.steps():
        assert np.all(rec.displacement == 0.0) and rec.row["max_von_mises_Pa"] == 0.0


@pytest.mark.parametrize("integrator", ["static", "tdg"])
def test_doubling_stiffness_halves_the_fluid_displacement(integrator):
    """Linear regime (strains ~1e-7): u scales like 1/E. One-way coupling keeps the loads identical."""
    def umax(E):
        case = _small(solid={"E": E}, network={"update": "none"}, coupling={"integrator": integrator},
                      drainage={"t_end": 2.0})
        return np.array([r.row["max_displacement_m"] for r in CoupledRun(build_problem(case)).steps()])

    u1, u2 = umax(20e9), umax(40e9)
    np.testing.assert_allclose(u2 / u1, 0.5, rtol=1e-5)


def test_geometric_update_moves_the_network_and_keeps_mass(finished):
    ts = finished.timeseries
    assert ts["mean_pore_radius_m"][-1] != ts["mean_pore_radius_m"][0]
    assert max(ts["mass_balance_error"]) < 1e-12


def test_cli_run_smoke_with_figures(tmp_path, capsys):
    case = tmp_path / "c.toml"
    case.write_text('[drainage]\nt_end = 4.0\n[coupling]\nexchange_dt = 2.0\n[output]\nsnapshot_times = [2.0]\n')
    assert main(["run", str(case), "--smoke", "-o", str(tmp_path / "o"), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["status"] == "completed" and s["n_exchange_steps"] == 2 and s["t_end_s"] == 4.0
    for f in s["figures"]:
        assert (tmp_path / "o" / f).stat().st_size > 1000
    assert "figures/timeseries.png" in s["figures"]


def test_cli_run_bad_case_is_one_line(tmp_path, capsys):
    case = tmp_path / "c.toml"
    case.write_text("[solid]\nyoungs = 1\n")
    assert main(["run", str(case), "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "solid.youngs" in err


def test_smoke_case_keeps_the_physics():
    c = Case().replace(interface={"method": "traction"}, network={"update": "none"})
    s = smoke_case(c)
    assert s.interface.method == "traction" and s.network.update == "none" and s.fluids == c.fluids
    assert s.drainage.t_end == 2 * c.coupling.exchange_dt and s.solid.coarsen >= 10


def test_subiterations_converge_in_weak_coupling():
    """A stiff rock barely changes the pores: Aitken sub-iterations stop at the tolerance, and the
    result equals the explicitly staggered one to that tolerance."""
    explicit = [r.row for r in CoupledRun(build_problem(_small(drainage={"t_end": 2.0}))).steps()]
    case = _small(drainage={"t_end": 2.0}, coupling={"subiterations": 6, "subiteration_tol": 1e-9})
    recs = list(CoupledRun(build_problem(case)).steps())
    for a, rec in zip(explicit, recs, strict=True):
        b = rec.row
        assert 2 <= b["subiterations"] <= 6 and b["coupling_residual"] < 1e-9
        np.testing.assert_allclose(b["max_displacement_m"], a["max_displacement_m"], rtol=1e-6)
        # the history behind the row: one residual and one relaxation factor per sub-iteration
        assert len(rec.residual_history) == len(rec.relaxation_history) == b["subiterations"]
        assert rec.residual_history[-1] == b["coupling_residual"] and rec.relaxation_history[0] == 1.0
        assert rec.precoupling_history == ()


def test_failure_mid_run_keeps_checkpoint_and_outputs(tmp_path, monkeypatch):
    """A solver failure at step 2 stops with the typed error; step 1's checkpoint, the time series
    so far and a summary saying what failed stay; --resume then finishes the run."""
    from porefsi.coupling.solid_step import StaticStepper
    from porefsi.errors import ConvergenceError

    real = StaticStepper.step
    calls = {"n": 0}

    def flaky(self, *a, **k):
        calls["n"] += 1
        if calls["n"] == 2:
            raise ConvergenceError("CG did not converge (injected)", [1.0, 0.5])
        return real(self, *a, **k)

    monkeypatch.setattr(StaticStepper, "step", flaky)
    out = tmp_path / "run"
    with pytest.raises(ConvergenceError):
        run_case(_small(), out, progress=False)
    s = json.loads((out / "summary.json").read_text())
    assert s["status"] == "failed" and "injected" in s["error"] and s["n_exchange_steps"] == 1
    assert len(list(csv.DictReader((out / "timeseries.csv").open()))) == 2
    monkeypatch.setattr(StaticStepper, "step", real)
    done = run_case(_small(), out, resume=True, progress=False)
    assert done.summary["status"] == "completed" and done.summary["n_exchange_steps"] == 3


def test_reextraction_across_topology_changes_keeps_mass():
    """Compressing by ~1 voxel per second changes the re-extracted pores; the drainage state is
    remapped by voxel overlap and the injected volume stays accounted for to round-off."""
    case = _small(solid={"strain_rate": 5e-3}, network={"update": "reextract"}, coupling={"integrator": "static"},
                  drainage={"t_end": 2.0})
    run = CoupledRun(build_problem(case))
    n0 = run.network.n_pores
    recs = list(run.steps())
    assert any(r.network.n_pores != n0 for r in recs)  # the topology did change
    for r in recs:
        assert r.row["mass_balance_error"] < 1e-12 and r.row["precoupling_iterations"] >= 1
        assert 0.0 <= r.flow.nw_saturation.min() and r.flow.nw_saturation.max() <= 1.0


def test_reextraction_of_an_unchanged_image_is_not_repeated():
    """At the paper's loads the deformed voxel image is the reference image (displacements ~1e-6
    voxel): re-extraction returns the reference network, so the run equals the one-way run exactly
    and no extraction is computed (they are served by image digest)."""
    runs = {}
    for mode in ("reextract", "none"):
        run = CoupledRun(build_problem(_small(drainage={"t_end": 2.0}, network={"update": mode})))
        runs[mode] = ([r.row for r in run.steps()], run)
    (re_rows, re_run), (none_rows, _) = runs["reextract"], runs["none"]
    assert re_run.n_extractions == 0
    for a, b in zip(re_rows, none_rows, strict=True):
        for k in ("sw", "max_displacement_m", "permeability_m2", "inlet_pressure_Pa"):
            assert a[k] == b[k], k
        assert a["precoupling_iterations"] == 1 and a["precoupling_Ea"] == 0.0


def test_precoupling_iterates_across_a_topology_change():
    """A second pre-coupling re-extraction after the first changed the pore count: the start-of-step
    load stays the one of the t0 network (it used to be converted with the new interface and failed)."""
    case = _small(solid={"strain_rate": 5e-3}, coupling={"integrator": "static"}, drainage={"t_end": 2.0},
                  network={"update": "reextract", "precoupling_tol": 1e-12, "precoupling_max_iter": 4})
    run = CoupledRun(build_problem(case))
    n_prev = run.network.n_pores
    changed = []
    for r in run.steps():
        changed.append(r.network.n_pores != n_prev and r.row["precoupling_iterations"] >= 2)
        assert len(r.precoupling_history) == r.row["precoupling_iterations"]
        n_prev = r.network.n_pores
    assert any(changed) and run.n_extractions > 0


@pytest.mark.parametrize(("rule", "fractions"), [("left", (0.0, 2.0 / 3.0)), ("right", (1.0 / 3.0, 1.0))])
def test_tdg_receives_the_pore_loads_at_its_sample_times(monkeypatch, rule, fractions):
    """The loop hands the TDG step f_ext(s) = restriction of T P(s) at the rule's sample times
    s = t0 + a dt (left: the paper's t0 and t0 + 2dt/3; right: t0 + dt/3, t0 + dt), with P(s) the
    pore pressures of an independent drainage advanced through the same stops. One-way coupling
    (the network stays the reference one), so the independent drainage is exact."""
    from porefsi.flow.drainage import DrainageSimulator
    from porefsi.integrators.tdg import TDGStepper

    case = _small(network={"update": "none"}, coupling={"integrator": "tdg", "tdg_load_rule": rule})
    run = CoupledRun(build_problem(case))
    seen = []
    real = TDGStepper.step

    def spy(self, u, v, t, loads=None):
        seen.append((t, self.dt, tuple(np.array(f) for f in loads)))
        return real(self, u, v, t, loads=loads)

    monkeypatch.setattr(TDGStepper, "step", spy)
    list(run.steps())
    p = run.problem
    sim = DrainageSimulator(p.network, p.fluids, rate=case.drainage.rate, axis=case.image.axis)
    itf, model = p.interface, p.model
    assert [t for t, _, _ in seen] == [0.0, 1.0, 2.0]
    for t0, dt, loads in seen:
        times = [t0 + a * dt for a in fractions]
        assert run.load_times(t0, dt) == tuple(times)
        stops = sorted((set(times) | {t0 + dt}) - {t0})  # the loop's stops within the step
        P = {t0: np.nan_to_num(sim.state.fluid_pressure)}
        P |= {s: np.nan_to_num(sim.advance_to(s).fluid_pressure) for s in stops}
        for s, f in zip(times, loads, strict=True):
            expected = model.with_nodal_forces(itf.nodal_forces(P[s])).external_force(s)
            assert np.linalg.norm(expected) > 0 or s == 0.0
            np.testing.assert_array_equal(f, expected)
        # the two samples are different loads (the drainage moves between them)
        assert not np.array_equal(loads[0], loads[1])


def _hull_on_grid(throats: bool):
    """Hull interface of three pores (one throat) on a 31³ node grid of the unit cube, every
    pore reaching nodes, so the paper's load balance holds to round-off."""
    from porefsi.coupling.hull import hull_interface

    g = np.linspace(0.0, 1.0, 31)
    x = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    c = np.array([[0.3, 0.5, 0.5], [0.7, 0.5, 0.5], [0.5, 0.25, 0.7]])
    r = np.array([0.08, 0.11, 0.06])
    thr = (np.array([[0, 1]]), np.array([0.05]), np.array([[[0.38, 0.5, 0.5], [0.59, 0.5, 0.5]]]))
    return hull_interface(c, r, x, n_test_points=300, tolerance=0.04, rng=np.random.default_rng(5),
                          throats=thr if throats else None)


@pytest.mark.parametrize("throats", [False, True])
def test_hull_load_balance_reads_the_operator(throats):
    """The hull's load balance (sum of |f| over a pore's nodes = P x wall area) is computed from
    the operator, so an operator that hands over the wrong load fails it even though the areas
    booked during assembly are right: scaled by 3 (error 2), or two pores' columns swapped."""
    import dataclasses

    itf = _hull_on_grid(throats)
    assert itf.n_unloaded == 0 and (itf.throat_operator is not None) == throats
    p = np.array([3.0e4, 1.0e4, 2.0e4])
    assert itf.load_balance_error(p) < 1e-12
    tripled = dataclasses.replace(itf, operator=3.0 * itf.operator)
    if throats:  # the sphere part (T - Theta C) is then 3 S + 2 Theta C: most of the load is extra
        assert tripled.load_balance_error(p) > 1.0
    else:
        np.testing.assert_allclose(tripled.load_balance_error(p), 2.0, rtol=1e-9)
    swapped = dataclasses.replace(itf, operator=itf.operator[:, [1, 0, 2]].tocsr())
    assert swapped.load_balance_error(p) > 0.1
    if throats:  # a throat load handed over twice is caught too
        doubled = dataclasses.replace(itf, throat_operator=2.0 * itf.throat_operator)
        assert doubled.load_balance_error(p) > 0.01


def test_solver_library_failure_is_a_convergence_error_and_keeps_the_checkpoint(tmp_path, monkeypatch):
    """SuperLU's "Factor is exactly singular" (a RuntimeError from the solid's direct solver
    factory) arrives as ConvergenceError from the coupled loop; run_case records it in
    summary.json and leaves the step-1 checkpoint as it was."""
    import porefsi.solid.model as model_mod
    from porefsi.errors import ConvergenceError

    out = tmp_path / "run"
    run_case(_small(), out, progress=False, stop_after=1)
    before = (out / "checkpoint.npz").read_bytes()

    def singular(*a, **k):
        def make(A):
            raise RuntimeError("Factor is exactly singular")
        return make

    monkeypatch.setattr(model_mod, "direct_solver_factory", singular)
    with pytest.raises(ConvergenceError, match="linear solver failed .*exactly singular") as err:
        run_case(_small(), out, resume=True, progress=False)
    assert isinstance(err.value.__cause__, RuntimeError)
    s = json.loads((out / "summary.json").read_text())
    assert s["status"] == "failed" and s["error"].startswith("ConvergenceError") and s["n_exchange_steps"] == 1
    assert (out / "checkpoint.npz").read_bytes() == before


def test_any_exception_writes_the_failed_summary_and_is_reraised(tmp_path):
    """Not only porefsi's errors: a bug (here in the caller's on_record) at step 2 still leaves a
    failed summary, the step-1 checkpoint and the time series, and propagates unchanged."""
    def boom(rec):
        if rec.step == 2:
            raise KeyError("not porefsi's")

    out = tmp_path / "run"
    with pytest.raises(KeyError, match="not porefsi's"):
        run_case(_small(), out, progress=False, on_record=boom)
    s = json.loads((out / "summary.json").read_text())
    assert s["status"] == "failed" and s["error"].startswith("KeyError")
    from porefsi.io.results import load_checkpoint

    assert load_checkpoint(out / "checkpoint.npz")[1]["step_index"] == 1
    assert len(list(csv.DictReader((out / "timeseries.csv").open()))) == 3
    done = run_case(_small(), out, resume=True, progress=False)
    assert done.summary["status"] == "completed" and done.summary["n_exchange_steps"] == 3


def test_failure_while_setting_up_leaves_the_directory_alone(tmp_path):
    """Inputs are validated before anything is written (issue 13): a bad crop creates no files."""
    out = tmp_path / "run"
    with pytest.raises(ConfigError, match="image.crop"):
        run_case(_small(image={"crop": [[0, 500], [0, 60], [0, 60]]}), out, progress=False)
    assert not out.exists()


def test_drainage_solver_failure_is_a_convergence_error(monkeypatch):
    from porefsi.errors import ConvergenceError
    from porefsi.flow.drainage import DrainageSimulator

    def broken(self, t, stop_at_breakthrough=False):
        raise RuntimeError("Factor is exactly singular")

    run = CoupledRun(build_problem(_small()))
    monkeypatch.setattr(DrainageSimulator, "advance_to", broken)
    with pytest.raises(ConvergenceError, match="drainage pressure solve failed at t = 0 s"):
        next(run.steps())


def test_pore_files_every_exchange_step(finished):
    """pores/step_NNNN.npz and pores/psd_NNNN.csv for steps 0..3: the arrays behind the time
    series (their aggregates equal its columns) and a PSD on the same bins at every step."""
    from porefsi.io.results import read_pore_steps

    out, ts = finished.directory, finished.timeseries
    steps = read_pore_steps(out)
    assert [s["step"] for s in steps] == ts["step"] == [0, 1, 2, 3]
    edges = None
    for s, k in zip(steps, range(4), strict=True):
        assert s["time_s"] == ts["time_s"][k]
        assert np.mean(s["pore_radius_m"]) == ts["mean_pore_radius_m"][k]
        assert np.nan_to_num(s["pore_pressure_Pa"]).max(initial=0.0) == ts["max_pore_pressure_Pa"][k]
        n = len(s["pore_radius_m"])
        assert s["nw_saturation"].shape == s["pore_volume_m3"].shape == (n,) and s["pore_coords_m"].shape == (n, 3)
        rows = list(csv.DictReader((out / "pores" / f"psd_{k:04d}.csv").open()))
        assert sum(int(r["n_pores"]) for r in rows) == n
        np.testing.assert_allclose(sum(float(r["pore_volume_m3"]) for r in rows), s["pore_volume_m3"].sum(),
                                   rtol=1e-12)
        e = [(float(r["radius_lo_m"]), float(r["radius_hi_m"])) for r in rows]
        assert edges is None or e == edges
        edges = e
    # the pressures load the rock and the drainage moves them: they change between steps
    assert not np.array_equal(steps[1]["pore_pressure_Pa"], steps[3]["pore_pressure_Pa"])
    assert steps[3]["nw_saturation"].sum() > steps[1]["nw_saturation"].sum() > 0
    # capillary pressure = inlet minus outlet node, the outlet held at 0
    assert ts["capillary_pressure_Pa"][1:] == ts["inlet_pressure_Pa"][1:]


def _plant(out, names):
    for n in names:
        (out / n).parent.mkdir(parents=True, exist_ok=True)
        (out / n).write_text("stale")


OWN_STALE = ("vtk/solid_0042.vtu", "vtk/network_0042.vtp", "pores/step_0042.npz", "pores/psd_0042.csv",
             "figures/drainage_t042_000s.png", "figures/von_mises_t015_000s.png", "figures/timeseries.png",
             "vtk/.solid_0002.vtu.k3j_x9.tmp")
USER_FILES = ("notes.txt", "figures/my_plot.png", "vtk/mine.vtu", "pores/analysis.py")


def test_fresh_run_clears_only_porefsi_outputs(tmp_path):
    """Re-running into an old directory: the files an earlier run wrote (here of a longer run: steps
    and snapshot times this run does not have) are removed first; a user's other files stay."""
    out = tmp_path / "old"
    _plant(out, OWN_STALE + USER_FILES)
    res = run_case(_small(drainage={"t_end": 2.0}), out, progress=False)
    for n in OWN_STALE:
        assert not (out / n).exists(), n
    for n in USER_FILES:
        assert (out / n).read_text() == "stale", n
    assert sorted(p.name for p in (out / "pores").glob("step_*.npz")) == [f"step_{k:04d}.npz" for k in range(3)]
    assert sorted(p.name for p in (out / "vtk").glob("solid_*.vtu")) == ["solid_0000.vtu", "solid_0001.vtu",
                                                                          "solid_0002.vtu"]
    assert res.summary["status"] == "completed"


def test_resume_rewrites_the_per_step_files_after_the_checkpoint(finished, tmp_path):
    """Steps after the checkpoint are redone: their old per-step files go and come back equal to
    the uninterrupted run's; user files are kept."""
    from porefsi.io.results import read_pore_steps

    out = tmp_path / "r"
    run_case(_small(), out, progress=False, stop_after=1)
    _plant(out, ("pores/step_0003.npz", "vtk/solid_0009.vtu") + USER_FILES)
    run_case(_small(), out, resume=True, progress=False)
    assert not (out / "vtk" / "solid_0009.vtu").exists()
    for n in USER_FILES:
        assert (out / n).read_text() == "stale", n
    a, b = read_pore_steps(finished.directory), read_pore_steps(out)
    assert len(a) == len(b) == 4
    for x, y in zip(a, b, strict=True):
        assert x.keys() == y.keys()
        for k in x:
            np.testing.assert_array_equal(x[k], y[k], err_msg=k)
    for k in range(4):
        name = f"pores/psd_{k:04d}.csv"
        assert (out / name).read_text() == (finished.directory / name).read_text()


def _renumbered(net, labels, perm):
    """The same network with new pore k = old pore perm[k] (throats follow, conns kept ordered)."""
    inv = np.empty_like(perm)
    inv[perm] = np.arange(len(perm))
    conns = inv[net.throat_conns]
    flip = conns[:, 0] > conns[:, 1]
    conns[flip] = conns[flip][:, ::-1]
    tpl = net.throat_pore_length.copy()
    tpl[flip] = tpl[flip][:, ::-1]
    per_pore = {k: getattr(net, k)[perm] for k in ("pore_shape_factor", "pore_face_radius", "pore_face_shape_factor",
                                                   "pore_face_duct_fraction") if getattr(net, k) is not None}
    new = net.replace(pore_coords=net.pore_coords[perm], pore_radius=net.pore_radius[perm],
                      pore_volume=net.pore_volume[perm], pore_faces=net.pore_faces[perm], throat_conns=conns,
                      throat_pore_length=tpl, **per_pore)
    return new, np.where(labels >= 0, inv[np.maximum(labels, 0)], labels)


@pytest.mark.parametrize("method", ["traction", "hull"])
def test_interface_is_invariant_to_pore_renumbering(method):
    """Renumber the pores (network and voxel labels): the case's interface builder gives the operator
    with its columns permuted the same way, so the nodal forces of the same physical pressures are equal."""
    from porefsi.case.problem import interface_options

    case = _small(interface={"method": method})
    p = build_problem(case)
    perm = np.random.default_rng(11).permutation(p.network.n_pores)
    net_b, lab_b = _renumbered(p.network, p.extraction.labels, perm)
    a = p.interface
    b = interface_options(case).build(net_b, lab_b, p.mesh, voxel_size=p.image.voxel_size, origin=p.image.origin)
    assert abs(b.operator - a.operator[:, perm]).max() == 0.0
    np.testing.assert_array_equal(b.wall_area, a.wall_area[perm])
    for k in range(0, len(perm), 17):
        np.testing.assert_array_equal(b.pore_nodes[k], a.pore_nodes[perm[k]])
    P = np.random.default_rng(2).uniform(0.0, 2.0e3, len(perm))
    np.testing.assert_allclose(b.nodal_forces(P[perm]), a.nodal_forces(P), rtol=1e-13, atol=1e-30)
    assert np.abs(a.nodal_forces(P)).max() > 0
    assert b.load_balance_error(P[perm]) == pytest.approx(a.load_balance_error(P), rel=1e-12, abs=1e-15)


def test_case_hull_loads_only_pore_wall_nodes():
    """Through the case path (interface_options), the hull's labelled nodes are pore-wall surface
    nodes: at coarsen 10 the enlarged hulls also contain 42 interior solid nodes, which an
    unrestricted search would load."""
    from porefsi.coupling.hull import hull_interface

    p = build_problem(_small(interface={"method": "hull"}))
    wall = np.zeros(p.mesh.n_nodes, bool)
    wall[p.mesh.nodes_tagged("pore_wall")] = True
    loaded = np.unique(np.concatenate(p.interface.pore_nodes))
    assert loaded.size > 0 and wall[loaded].all()
    rows = np.unique(p.interface.operator.tocoo().row // 3)
    assert wall[rows].all()
    # the restriction matters here: without it interior nodes fall inside the enlarged hulls
    net = p.network
    free = hull_interface(net.pore_coords, net.pore_radius, p.mesh.points, n_test_points=100,
                          rng=np.random.default_rng(0))
    assert not wall[np.unique(np.concatenate(free.pore_nodes))].all()


def test_throat_forces_switch_through_the_case_file(tmp_path):
    """interface.throat_forces = true (hull) loads the throat walls: each throat's lateral area is
    added half to each of its pores' wall area and handed to nodes (the load balance then checks
    it too); with the traction method it is a ConfigError naming the key."""
    from porefsi.case.config import load_case

    path = tmp_path / "c.toml"
    path.write_text('[interface]\nmethod = "hull"\nthroat_forces = true\nn_test_points = 100\n'
                    '[solid]\ncoarsen = 10\n[drainage]\nt_end = 2.0\n')
    case = load_case(path)
    assert case.interface.throat_forces
    with_t = build_problem(case).interface
    plain = build_problem(case.replace(interface={"throat_forces": False})).interface
    assert with_t.throat_operator is not None and plain.throat_operator is None
    assert with_t.throat_operator.shape[1] > 0
    added = with_t.wall_area - plain.wall_area
    assert np.all(added >= 0) and added.sum() == pytest.approx(with_t.throat_area.sum(), rel=1e-12)
    P = np.full(with_t.n_pores, 1.0e3)
    assert np.linalg.norm(with_t.nodal_forces(P) - plain.nodal_forces(P)) > 0
    path.write_text('[interface]\nmethod = "traction"\nthroat_forces = true\n')
    with pytest.raises(ConfigError, match=r"interface\.throat_forces = true needs interface\.method = 'hull'"):
        load_case(path)


def test_extraction_cache_can_be_disabled():
    """reuse_extractions=False computes every re-extraction (the paper's cost) and gives the same
    run bit for bit; the counters and the voxelise/extract split say which happened."""
    case = _small(drainage={"t_end": 2.0}, network={"update": "reextract"})
    runs = {}
    for reuse in (True, False):
        run = CoupledRun(build_problem(case), reuse_extractions=reuse)
        runs[reuse] = ([r.row for r in run.steps()], run)
    (cached, rc), (fresh, rf) = runs[True], runs[False]
    n = sum(r["precoupling_iterations"] for r in cached)
    assert n == 2
    assert (rc.n_extractions, rc.n_extractions_reused) == (0, n)
    assert (rf.n_extractions, rf.n_extractions_reused) == (n, 0)
    assert rc.update_seconds["extract"] == 0.0 < rf.update_seconds["extract"]
    assert rc.update_seconds["voxelise"] > 0 and rf.update_seconds["voxelise"] > 0
    assert rc.update_cpu_seconds["extract"] == 0.0 < rf.update_cpu_seconds["extract"]
    assert sum(rf.update_cpu_seconds.values()) <= rf.cpu_seconds["update"]
    # the same switch through run_case, and the counters in summary.json
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        s = run_case(case, d, progress=False, reuse_extractions=False).summary
    assert (s["reextraction"]["n_computed"], s["reextraction"]["n_reused"]) == (n, 0)
    assert s["reextraction"]["cpu_seconds"]["extract"] > 0 and s["final_sw"] == cached[-1]["sw"]
    # A freshly extracted (equal) network is a new object, onto which the drainage is carried with
    # its solver state reset: one more pressure solve, every result the same.
    skip = ("wall_s", "n_solves")
    for a, b in zip(cached, fresh, strict=True):
        assert {k: v for k, v in a.items() if k not in skip} == {k: v for k, v in b.items() if k not in skip}


def test_strain_loading_needs_solid_joining_the_load_faces(tmp_path):
    """Two solid slabs, one on each z face, with the pore layer between them: each slab is held by
    a face (no floating grain) but nothing carries load from zmin to zmax, so an axial strain rate
    is refused with a MeshError naming the faces; fluid loading alone (no frame) still builds."""
    from porefsi.errors import MeshError

    ph = np.zeros((12, 12, 12), dtype=np.uint8)
    ph[:, :, 4:8] = 1  # a pore layer spanning x: solid below (z < 4) and above (z >= 8)
    np.save(tmp_path / "slabs.npy", ph)
    case = _small(image={"path": str(tmp_path / "slabs.npy"), "voxel_size": 5e-6},
                  solid={"coarsen": 2, "strain_rate": 1e-4, "load_axis": "z"})
    with pytest.raises(MeshError, match="no connected solid joins the zmin and zmax faces"):
        build_problem(case)
    build_problem(case.replace(solid={"coarsen": 2, "strain_rate": 0.0, "load_axis": "z"}))


def test_p2_traction_is_the_p2_integral_of_the_wall_pressure():
    """With P2 elements the traction operator integrates -P n against the P2 basis (scikit-fem's
    facet quadrature of the same pore-wall pressures); it used to hand the P1 vertex split to
    the P2 vertices, i.e. point loads (0.34 relative difference in u at coarsen 10). The vertex
    view kept for outputs has the same resultant per pore."""
    from porefsi.coupling.traction import boundary_facet_normals, facet_pores_from_labels
    from porefsi.solid import forms

    case = _small(solid={"coarsen": 10, "order": 2, "linear_solver": "amg"})
    p = build_problem(case)
    mesh, itf, model = p.mesh, p.interface, p.model
    assert itf.operator.shape == (model.n_full, p.network.n_pores)
    P = np.random.default_rng(3).uniform(1e3, 2e3, p.network.n_pores)
    facets = mesh.facets_tagged("pore_wall")
    normals, _ = boundary_facet_normals(mesh.points, mesh.tets, facets)
    owner = facet_pores_from_labels(mesh.points, facets, normals, p.extraction.labels, p.image.voxel_size,
                                    p.image.origin, max_steps=max(4, 2 * case.solid.coarsen))
    ref = np.zeros(model.n_full)
    for i in np.unique(owner[owner >= 0]):
        ref += forms.facet_load(model.feb, facets[owner == i], pressure=P[i])
    got = itf.nodal_forces(P).ravel()
    assert np.abs(got - ref).max() <= 1e-12 * np.abs(ref).max()
    assert np.abs(got[: 3 * mesh.n_nodes]).max() <= 1e-12 * np.abs(ref).max()  # nothing on the vertices
    fv = itf.vertex_forces(P)
    assert fv.shape == (mesh.n_nodes, 3)
    np.testing.assert_allclose(fv.sum(axis=0), got.reshape(-1, 3).sum(axis=0), rtol=1e-12,
                               atol=1e-12 * np.abs(fv).max())
    run = CoupledRun(p)
    rec = next(run.steps())
    assert rec.nodal_force.shape == (mesh.n_nodes, 3) and rec.row["max_displacement_m"] > 0
