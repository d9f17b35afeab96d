"""The case gallery: every case file loads, the study cases keep the paper's physics, and one
case (``drainage``) runs end to end in smoke mode through its ``run.py``.

The full studies are run by ``python cases/run_cases.py`` (``tox -e cases`` runs all of them in
smoke mode); here only what is cheap enough for the default suite.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from porefsi.case.config import Case, case_to_dict, load_case, smoke_case

CASES = Path(__file__).resolve().parent.parent / "cases"
CASE_FILES = sorted(CASES.glob("*/case.toml"))
# The paper's table 2 / section 3.1 set-up (seed paper, 'Numerical results').
PAPER_PHYSICS = {
    ("drainage", "rate"): 1.25e-13, ("drainage", "t_end"): 20.0, ("solid", "E"): 20.0e9, ("solid", "nu"): 0.28,
    ("fluids", "mu_w"): 1.0e-3, ("fluids", "mu_n"): 1.0e-2, ("fluids", "theta_deg"): 0.0,
}
# The studies vary only fidelity knobs (and the swept parameter) around the drainage case
# (test_points, tolerance and flow_rates use the paper's hull interface, their subject).
FIDELITY_KEYS = {("solid", "coarsen"), ("coupling", "exchange_dt"), ("coupling", "integrator"),
                 ("output", "snapshot_times"), ("interface", "method"),
                 ("interface", "tolerance"), ("interface", "n_test_points")}


def _load_module(path: Path, name: str):
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _flat(d: dict) -> dict:
    return {(s, k): v for s, sec in d.items() if isinstance(sec, dict) for k, v in sec.items()}


def test_cases_exist():
    names = {p.parent.name for p in CASE_FILES}
    assert {"drainage", "test_points", "tolerance", "flow_rates"} <= names


@pytest.mark.parametrize("path", CASE_FILES, ids=[p.parent.name for p in CASE_FILES])
def test_case_file_loads(path):
    case = load_case(path)
    smoke = smoke_case(case)
    assert smoke.drainage.t_end <= 2 * case.coupling.exchange_dt


def test_every_case_has_a_readme():
    """Issue 6: every case states what the paper reports, what porefsi gets and why they differ."""
    missing = [p.parent.name for p in CASE_FILES if not (p.parent / "README.md").is_file()]
    assert not missing, f"cases without README.md: {missing}"


def test_drainage_case_is_the_paper_setup():
    flat = _flat(case_to_dict(load_case(CASES / "drainage" / "case.toml")))
    for key, val in PAPER_PHYSICS.items():
        assert flat[key] == pytest.approx(val), key
    assert flat[("output", "snapshot_times")] == [1.0, 3.0, 5.0, 15.0]  # paper figure 7


def test_drainage_case_is_the_default_case():
    """cases/drainage is ``Case()`` with its keys written out (the README's "default coupled run")."""
    flat = _flat(case_to_dict(load_case(CASES / "drainage" / "case.toml")))
    default = _flat(case_to_dict(Case()))
    assert {k for k in default if default[k] != flat[k]} == set()


@pytest.mark.parametrize("name", ["test_points", "tolerance", "flow_rates"])
def test_studies_differ_from_drainage_only_in_fidelity(name):
    ref = _flat(case_to_dict(load_case(CASES / "drainage" / "case.toml")))
    flat = _flat(case_to_dict(load_case(CASES / name / "case.toml")))
    changed = {k for k in ref if ref[k] != flat[k]}
    assert changed <= FIDELITY_KEYS, changed - FIDELITY_KEYS


def test_run_cases_rejects_unknown_names(capsys):
    runner = _load_module(CASES / "run_cases.py", "porefsi_run_cases")
    assert runner.main(["no-such-case"]) == 2
    assert "known cases" in capsys.readouterr().err
    cmd = runner.command("drainage", True, Path("x"))
    assert cmd[-3:] == ["--smoke", "--out", "x"]


def test_drainage_case_smoke(tmp_path):
    mod = _load_module(CASES / "drainage" / "run.py", "porefsi_case_drainage")
    res = mod.main(["--smoke", "--out", str(tmp_path)])
    saved = json.loads((tmp_path / "results.json").read_text())
    assert saved["final"]["sw"] == pytest.approx(res["final"]["sw"])
    # Injection displaces water: Sw falls, and by exactly the injected volume fraction before
    # breakthrough (mass balance of the DPN, round-off).
    sws = [s["sw"] for s in saved["at_snapshots"]] + [saved["final"]["sw"]]
    assert all(b < a for a, b in zip([1.0, *sws], sws, strict=False))
    assert saved["mass_balance_error"] < 1e-12
    # The pore pressure loads the rock: a finite, nonzero, sub-voxel displacement.
    assert 0.0 < saved["max_displacement_m"] < 1e-7
    assert np.isfinite(saved["max_von_mises_Pa"]) and saved["max_von_mises_Pa"] > 0
    assert saved["settings"]["coarsen"] >= 10 and saved["smoke"] is True
    for fig in saved["figures"]:
        assert (tmp_path / fig).stat().st_size > 10_000, fig
