"""``porefsi sweep``: validation before anything runs, failing members, re-runs, and Dask vs serial.

The members are tiny coupled runs (built-in sample, coarsen 12: ~0.1 s CPU per exchange step).
The serial run (``--serial``, no Dask) is the reference: every other way of running the same
sweep must give the same numbers bit for bit (every summary number but the timings, and every
column of every member's ``timeseries.csv`` but ``wall_s``). The external-cluster test (a
``dask scheduler`` and a ``dask worker`` started as subprocesses, one worker killed mid-member)
is in ``test_sweep_cluster.py``.
"""

from __future__ import annotations

import csv
import json
import os
import shutil
import textwrap
from pathlib import Path

import pytest

from porefsi.case.run import run_case
from porefsi.cli import main
from porefsi.errors import ConfigError, InputError
from porefsi.sweep import Cluster, load_sweep, member_name, run_sweep, sweep_from_dict

#: A base of quick members (the seconds of each exchange step are in checkpoint and summary only).
BASE = textwrap.dedent("""\
    [base]
    drainage.t_end = {t_end}
    coupling.exchange_dt = 1.0
    solid.coarsen = 12
    output.vtk = false
    output.figures = false
    output.checkpoint_every = 1
    output.snapshot_times = []
    """)
#: Summary entries that are timings or paths (differ between two runs of the same member).
TIMING = ("wall_seconds", "wall_seconds_this_process", "cpu_seconds", "cpu_seconds_this_process",
          "seconds_by_stage", "cpu_seconds_by_stage", "figures", "resume_command", "reextraction")


def write_sweep(folder: Path, vary: str, t_end: float = 3.0, extra: str = "") -> Path:
    p = folder / "sweep.toml"
    p.write_text(BASE.format(t_end=t_end) + extra + "\n[vary]\n" + textwrap.dedent(vary))
    return p


def results_of(out: Path) -> dict:
    """member -> (summary without timings, time series without wall_s), from the files."""
    res = {}
    for d in sorted(p for p in out.iterdir() if (p / "member.json").is_file()):
        s = json.loads((d / "summary.json").read_text())
        with open(d / "timeseries.csv", newline="") as fh:
            ts = [{k: v for k, v in r.items() if k != "wall_s"} for r in csv.DictReader(fh)]
        res[d.name] = ({k: v for k, v in s.items() if k not in TIMING}, ts)
    return res


def table_of(out: Path) -> list[dict]:
    with open(out / "sweep.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def snapshot(folder: Path) -> dict:
    return {p: p.read_bytes() for p in folder.rglob("*") if p.is_file()}


RATES = '"drainage.rate" = [1.25e-13, 5e-10]\n'


@pytest.fixture(scope="module")
def serial_ref(tmp_path_factory):
    """The two-rate sweep run serially: the reference of the other tests."""
    folder = tmp_path_factory.mktemp("ref")
    out = folder / "out"
    res = run_sweep(load_sweep(write_sweep(folder, RATES)), out, Cluster(serial=True), progress=False)
    assert res.n_completed == 2 and res.n_failed == 0
    return out


# ---- validation: one line, nothing written ----------------------------------------------------------


@pytest.mark.parametrize("text, match", [
    ("[base]\nsmoke = 1\n[vary]\n\"drainage.rate\" = [1e-13]\n", "base.smoke must be true or false"),
    ("mode = \"zip\"\n[vary]\n\"drainage.rate\" = [1e-13]\n", "put mode in \\[vary\\]"),
    ("[base]\ndrainage.rat = 1e-13\n[vary]\n\"drainage.rate\" = [1e-13]\n", "unknown key drainage.rat"),
    ("[vary]\n\"drainage.rat\" = [1e-13]\n", "unknown key drainage.rat"),
    ("[vary]\n\"drainag.rate\" = [1e-13]\n", "unknown section \\[drainag\\]"),
    ("[vary]\n\"rate\" = [1e-13]\n", "must be section.key"),
    ("[vary]\n\"drainage.rate\" = []\n", "non-empty list"),
    ("[vary]\n\"drainage.rate\" = 1e-13\n", "non-empty list"),
    ("[vary]\nmode = \"zip\"\n\"drainage.rate\" = [1e-13, 2e-13]\n\"solid.coarsen\" = [10]\n",
     "lengths differ: drainage.rate 2, solid.coarsen 1"),
    ("[vary]\nmode = \"zap\"\n\"drainage.rate\" = [1e-13]\n", "vary.mode = 'zap'"),
    ("[vary]\n\"drainage.rate\" = [1e-13, -1e-13]\n", "member 1-rate=-1e-13: drainage.rate must be > 0"),
    ("[vary]\n\"solid.order\" = [1, 3]\n", "solid.order = 3 is not one of"),
    ("[vary]\n\"image.path\" = [\"no/such.npz\"]\n", "image.path .*no/such.npz' does not exist"),
    ("[vary]\n\"drainage.rate\" = [1e-13, 2e-13]\nlabel = [\"a\", \"b\"]\n", "needs mode = \"zip\""),
    ("[vary]\n\"drainage.rate\" = [1e-13]\n[plot]\ny = \"final_sv\"\n", "plot.y must name summary numbers"),
    ("[vary]\n\"drainage.rate\" = [1e-13]\n[plot]\nx = \"solid.coarsen\"\n", "plot.x = 'solid.coarsen' is not"),
    ("[base]\ncase = \"missing.toml\"\n[vary]\n\"drainage.rate\" = [1e-13]\n", "case file .*missing.toml.* not found"),
])
def test_bad_sweep_files_refused_in_one_line(tmp_path, text, match):
    p = tmp_path / "s.toml"
    p.write_text(text)
    with pytest.raises(ConfigError, match=match) as err:
        load_sweep(p)
    assert "\n" not in str(err.value)


def test_cli_refusal_changes_nothing(tmp_path, capsys):
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "mine.txt").write_text("user data")
    before = snapshot(tmp_path)
    p = write_sweep(tmp_path, '"drainage.rate" = [1e-13, -1.0]\n')
    before = snapshot(tmp_path)
    assert main(["sweep", str(p), "-o", str(tmp_path / "new"), "--serial"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("porefsi: error:") and "drainage.rate must be > 0" in err
    # a folder with other files, a missing scheduler file: refused before anything is written
    p.write_text(p.read_text().replace("-1.0", "2e-13"))
    before = snapshot(tmp_path)
    assert main(["sweep", str(p), "-o", str(tmp_path / "out"), "--serial"]) == 2
    assert "not empty and holds no porefsi sweep" in capsys.readouterr().err
    assert main(["sweep", str(p), "-o", str(tmp_path / "new"), "--scheduler-file", str(tmp_path / "no.json")]) == 2
    assert "scheduler file" in capsys.readouterr().err
    assert snapshot(tmp_path) == before and not (tmp_path / "new").exists()


def test_zip_product_and_member_names(tmp_path):
    s = sweep_from_dict({"vary": {"drainage": {"rate": [1e-13, 2e-13]}, "solid.coarsen": [10, 12]}},
                        base_dir=tmp_path)
    assert [m.name for m in s.members] == ["0-rate=1e-13,coarsen=10", "1-rate=1e-13,coarsen=12",
                                           "2-rate=2e-13,coarsen=10", "3-rate=2e-13,coarsen=12"]
    assert [m.case.solid.coarsen for m in s.members] == [10, 12, 10, 12]
    z = sweep_from_dict({"vary": {"mode": "zip", "drainage.rate": [1e-13, 2e-13], "solid.coarsen": [10, 12],
                                  "label": ["slow/coarse", "fast"]}, "base": {"smoke": True}}, base_dir=tmp_path)
    assert [(m.name, m.case.drainage.rate, m.case.solid.coarsen) for m in z.members] == [
        ("0-slow_coarse", 1e-13, 10), ("1-fast", 2e-13, 12)]
    assert z.members[0].case.drainage.t_end == 2.0  # smoke: applied to every member
    # stable, filesystem-safe, bounded, distinct
    long = {f"interface.k{i}": "x" * 30 for i in range(5)}
    a, b = member_name(7, long, 2), member_name(7, {**long, "interface.k4": "y" * 30}, 2)
    assert len(a) <= 80 and a != b and a == member_name(7, dict(long), 2)
    assert member_name(0, {"image.path": "/data/rock a.npz"}) == "0-path=rock_a"


def test_base_case_file_and_inline_keys(tmp_path):
    (tmp_path / "c.toml").write_text("name = \"c\"\n[drainage]\nrate = 3e-13\nt_end = 5.0\n[solid]\ncoarsen = 8\n")
    s = sweep_from_dict({"base": {"case": "c.toml", "solid": {"coarsen": 11}}, "vary": {"drainage.t_end": [3.0]}},
                        base_dir=tmp_path)
    c = s.members[0].case
    assert (c.drainage.rate, c.drainage.t_end, c.solid.coarsen, c.name) == (3e-13, 3.0, 11, "c-0-t_end=3")


# ---- running: failures, re-runs, Dask == serial ------------------------------------------------------


def test_failing_member_recorded_others_go_on(tmp_path, capsys):
    bad = tmp_path / "bad.npy"
    bad.write_bytes(b"not an image at all")
    shutil.copy(Path(__file__).parent.parent / "porefsi" / "data" / "berea_icl_120_paper.npz", tmp_path / "rock.npz")
    paths = ['""', f'"{bad.name}"', '"rock.npz"']
    p = write_sweep(tmp_path, f'"image.path" = [{", ".join(paths)}]\n')
    code = main(["sweep", str(p), "-o", str(tmp_path / "out"), "--serial", "--json"])
    assert code == 1
    cap = capsys.readouterr()
    counts = json.loads(cap.out)
    assert counts["members"] == len(paths) and counts["failed"] == 1
    assert "member 1-path=bad failed:" in cap.err
    rows = {r["member"]: r for r in table_of(tmp_path / "out")}
    assert rows["1-path=bad"]["status"] == "failed" and "bad.npy" in rows["1-path=bad"]["error"]
    assert "\n" not in rows["1-path=bad"]["error"]
    assert rows["0-path=builtin"]["status"] == "completed" and float(rows["0-path=builtin"]["final_sw"]) < 1.0
    # every summary field is a column; the failed member has its attempt recorded on disk
    assert {"max_displacement_m", "permeability_final_m2", "cpu_seconds", "wall_seconds"} <= set(rows["0-path=builtin"])
    assert rows["2-path=rock"]["status"] == "completed"
    assert rows["2-path=rock"]["final_sw"] == rows["0-path=builtin"]["final_sw"]  # the same rock
    state = json.loads((tmp_path / "out" / "1-path=bad" / "member.json").read_text())
    assert state["attempts"][-1]["status"] == "failed"


def test_rerun_skips_completed_and_resumes_interrupted(tmp_path, serial_ref):
    sweep = load_sweep(write_sweep(tmp_path, RATES))
    out = tmp_path / "out"
    run_sweep(sweep, out, Cluster(serial=True), progress=False)
    m0, m1 = sweep.members
    # member 1 stopped after one exchange step (as a killed or Ctrl-C'd run leaves it)
    run_case(m1.case, out / m1.name, overwrite=True, stop_after=1, progress=False)
    assert json.loads((out / m1.name / "summary.json").read_text())["status"] == "interrupted"
    kept = (out / m0.name / "summary.json").stat().st_mtime_ns
    early = {f: f.stat().st_mtime_ns for f in (out / m1.name / "pores").glob("step_000[01].npz")}
    assert len(early) == 2
    res = run_sweep(sweep, out, Cluster(serial=True), progress=False)
    assert res.n_skipped == 1 and res.n_completed == 2
    assert (out / m0.name / "summary.json").stat().st_mtime_ns == kept  # not run again
    assert res.records[1]["resumed_from_step"] == 1
    assert {f: f.stat().st_mtime_ns for f in early} == early  # resumed: steps 0-1 not redone
    assert results_of(out) == results_of(serial_ref)
    # another design into the same folder: refused, nothing changed
    other = load_sweep(write_sweep(tmp_path, '"drainage.rate" = [1.25e-13, 5e-11]\n'))
    before = snapshot(out)
    with pytest.raises(InputError, match="holds another sweep"):
        run_sweep(other, out, Cluster(serial=True), progress=False)
    assert snapshot(out) == before


def test_local_cluster_equals_serial(tmp_path, serial_ref):
    out = tmp_path / "out"
    res = run_sweep(load_sweep(write_sweep(tmp_path, RATES)), out, Cluster(n_workers=2), progress=True)
    assert res.n_completed == 2
    workers = {r["worker"] for r in res.records}
    assert all(w and int(w.split(":")[1]) != os.getpid() for w in workers)  # ran in worker processes
    assert results_of(out) == results_of(serial_ref)
    rows = table_of(out)
    assert [r["status"] for r in rows] == ["completed", "completed"]
    assert (out / "figures" / "sweep.png").read_bytes()[:4] == b"\x89PNG"


def test_docs_sweep_examples_are_valid(tmp_path):
    """The sweep files of docs/sweeps.md load (the case file they name is the flow_rates case's)."""
    import re
    import tomllib

    from porefsi.sweep import sweep_from_dict

    text = (Path(__file__).parent.parent / "docs" / "sweeps.md").read_text()
    blocks = re.findall(r"^```\{code-block\} toml\n(.*?)^```", text, re.M | re.S)
    assert blocks
    for b in blocks:
        s = sweep_from_dict(tomllib.loads(b), base_dir=Path(__file__).parent.parent / "docs")
        assert len(s.members) == 8 and s.plot.logx


@pytest.mark.parametrize("name, n", [("flow_rates", 9), ("strain_rate", 4), ("speed_accuracy", 25)])
def test_case_sweeps_load(name, n):
    """The cases' sweep files are valid and hold the studies' members (speed_accuracy: all but `skip`)."""
    s = load_sweep(Path(__file__).parent.parent / "cases" / name / "sweep.toml")
    assert len(s.members) == n and len({m.name for m in s.members}) == n


def test_speed_accuracy_sweep_is_the_study():
    """Each member of cases/speed_accuracy/sweep.toml is its variant of run.py (same whole case)."""
    import importlib.util

    from porefsi.case.config import case_to_dict, load_case

    folder = Path(__file__).parent.parent / "cases" / "speed_accuracy"
    spec = importlib.util.spec_from_file_location("porefsi_case_sa_sweep", folder / "run.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    base = load_case(folder / "case.toml").replace(output={"vtk": False, "figures": False})
    variants = {v["name"]: v for v in mod.variants(False) if v["skip_solves"] is None}
    members = load_sweep(folder / "sweep.toml").members
    assert [m.label for m in members] == list(variants)
    for m in members:
        want = case_to_dict(base.replace(**variants[m.label]["overrides"]))
        got = case_to_dict(m.case)
        assert {k: v for k, v in got.items() if k != "name"} == {k: v for k, v in want.items() if k != "name"}, m.name
