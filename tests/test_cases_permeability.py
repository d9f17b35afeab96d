"""The permeability part of ``cases/speed_accuracy`` (``permeability.py``, issue 12 section 3):
its smoke run end to end, and the error bookkeeping (which truth each point is measured against)."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

CASE = Path(__file__).resolve().parent.parent / "cases" / "speed_accuracy"


def _module():
    spec = importlib.util.spec_from_file_location("porefsi_case_speed_accuracy_permeability", CASE / "permeability.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def perm():
    return _module()


def _row(method, model, coarsen, k):
    return {"method": method, "model": model, "coarsen": coarsen, "k_mD": dict(zip("xyz", k, strict=True)),
            "cpu_s": 1.0}


def test_published_dns_is_the_truth_of_the_whole_berea(perm):
    """400^3 points are scored against the published mean 1286 mD, the full-resolution solve included."""
    rows = [_row("voxel", None, 1, (1360.0, 1304.0, 1193.0)), _row("voxel", None, 2, (2000.0, 1500.0, 1645.2)),
            _row("network", "paper", 1, (200.0, 190.0, 210.0))]
    truth = perm.score(rows, "published DNS")
    assert truth == pytest.approx(1285.6666666666667, rel=1e-12)
    assert rows[0]["error"] == pytest.approx(0.0, abs=1e-12) and not rows[0]["is_truth"]
    assert rows[1]["error"] == pytest.approx((2000 + 1500 + 1645.2) / 3 / truth - 1, rel=1e-12)
    assert rows[2]["error"] == pytest.approx(200.0 / truth - 1, rel=1e-12)


def test_finest_voxel_solve_is_the_truth_elsewhere(perm):
    """Images without a published value are scored against their own full-resolution voxel solve."""
    rows = [_row("network", "shape_factor", 1, (300.0, 600.0, 900.0)), _row("voxel", None, 2, (500.0, 500.0, 500.0)),
            _row("voxel", None, 1, (100.0, 400.0, 400.0))]
    assert perm.score(rows, "finest voxel solve") == pytest.approx(300.0)
    assert [r["error"] for r in rows] == pytest.approx([1.0, 2.0 / 3.0, 0.0])
    assert [r["is_truth"] for r in rows] == [False, False, True]


def test_permeability_smoke(perm, tmp_path):
    before = {p: p.stat().st_mtime_ns for p in CASE.rglob("*") if p.is_file() and "__pycache__" not in p.parts}
    assert perm.main(["--smoke", "--out", str(tmp_path), "--walls", "channel", "ghost"]) == 0
    after = {p: p.stat().st_mtime_ns for p in CASE.rglob("*") if p.is_file() and "__pycache__" not in p.parts}
    assert after == before  # a smoke run never touches the committed outputs
    saved = json.loads((tmp_path / "results.json").read_text())["permeability"]
    assert saved["smoke"] and saved["dns_mean_mD"] == pytest.approx(1285.6666666666667)
    (st,) = saved["studies"]
    pts = {(p["method"], p["model"], p["coarsen"]): p for p in st["points"]}
    assert set(pts) == {("network", "shape_factor", 1), ("network", "paper", 1), ("voxel", "channel", 1),
                        ("voxel", "channel", 2), ("voxel", "ghost", 1), ("voxel", "ghost", 2)}
    for p in pts.values():
        assert p["cpu_s"] > 0 and all(np.isfinite(v) and v > 0 for v in p["k_mD"].values())
        assert p["k_mean_mD"] == pytest.approx(np.mean(list(p["k_mD"].values())), rel=1e-12)
    fine, coarse = pts["voxel", "channel", 1], pts["voxel", "channel", 2]
    assert fine["is_truth"] and fine["error"] == 0.0 and st["truth_mD"] == pytest.approx(fine["k_mean_mD"])
    ghost = pts["voxel", "ghost", 1]  # the earlier closure: a point against the same truth, more conductive
    assert not ghost["is_truth"] and ghost["error"] > 0.05
    assert coarse["voxel_size_m"] == pytest.approx(2 * fine["voxel_size_m"]) and coarse["shape"] == [16, 16, 16]
    # the two conduit models are different models: per axis they differ (on this corner, where
    # nearly every throat touches a box face, their means happen to agree within ~2 %)
    sf, paper = pts["network", "shape_factor", 1], pts["network", "paper", 1]
    ratio = [sf["k_mD"][ax] / paper["k_mD"][ax] for ax in sorted(sf["k_mD"])]
    assert max(abs(r - 1) for r in ratio) > 0.05, ratio
    for p in (sf, paper, coarse):  # every estimate of this corner within a factor 4 of the voxel truth
        assert 0.25 < p["k_mean_mD"] / fine["k_mean_mD"] < 4.0
    assert (tmp_path / "figures" / "permeability_speed_accuracy.png").stat().st_size > 10_000
    assert (tmp_path / "permeability_table.md").read_text().count("\n|") == 1 + len(pts)



def test_committed_chart_exists():
    assert (CASE / "figures" / "permeability_speed_accuracy.png").is_file()


def test_berea_option_missing_file_is_a_one_line_error_before_any_output(perm, tmp_path):
    """``--berea PATH`` that does not exist stops the run before the output folder is made."""
    out = tmp_path / "out"
    with pytest.raises(perm.InputError, match="--berea .*no such file"):
        perm.main(["--out", str(out), "--images", "crop200", "--berea", str(tmp_path / "nope.npz")])
    assert not out.exists()


def test_without_the_berea_the_skip_is_said_and_returned(perm, tmp_path, monkeypatch, capsys):
    """No ``--berea`` and no file next to the repository: crop200 and berea400 are SKIPPED, loudly."""
    monkeypatch.setattr(perm, "BEREA400", [tmp_path / "a.npz", tmp_path / "b.npz"])
    path, skipped = perm.locate_berea(None, ["sample", "crop200", "berea400"])
    assert path is None and skipped == ["crop200", "berea400"]
    assert "SKIPPED crop200, berea400" in capsys.readouterr().out
    given = tmp_path / "berea.npz"
    given.write_bytes(b"")
    assert perm.locate_berea(given, ["berea400"]) == (given, [])
    assert perm.locate_berea(None, ["sample"]) == (None, [])  # not needed: nothing looked for
