"""Result files: atomic writes, CSV/JSON/PVD/checkpoint round trips."""

import csv
import json
import os

import numpy as np
import pytest

from porefsi.io import results


def test_json_handles_numpy_and_nan(tmp_path):
    p = results.write_json(tmp_path / "s.json", {"a": np.float64(1.5), "b": float("nan"), "c": np.arange(3)})
    assert json.loads(p.read_text()) == {"a": 1.5, "b": None, "c": [0, 1, 2]}


def test_csv_round_trip_is_exact(tmp_path):
    t = np.linspace(0, 1, 7) / 3
    p = results.write_csv(tmp_path / "ts.csv", {"time_s": t, "n": np.arange(7), "x": [np.nan] * 7})
    rows = list(csv.DictReader(p.open()))
    assert [float(r["time_s"]) for r in rows] == list(t)
    assert rows[0]["x"] == ""
    with pytest.raises(ValueError, match="lengths"):
        results.write_csv(tmp_path / "bad.csv", {"a": [1], "b": [1, 2]})


def test_atomic_write_leaves_old_file_on_failure(tmp_path, monkeypatch):
    p = tmp_path / "f.txt"
    results.atomic_write_text(p, "old")

    def boom(*a, **k):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(OSError):
        results.atomic_write_text(p, "new")
    assert p.read_text() == "old"
    assert [f.name for f in tmp_path.iterdir()] == ["f.txt"]


def test_pvd_series_round_trip_and_truncate(tmp_path):
    s = results.PvdSeries(tmp_path / "solid.pvd")
    for k, t in enumerate([0.0, 1.0, 2.0]):
        s.add(t, tmp_path / "vtk" / f"solid_{k:04d}.vtu")
    back = results.PvdSeries.read(tmp_path / "solid.pvd")
    assert back.entries == [(0.0, "vtk/solid_0000.vtu"), (1.0, "vtk/solid_0001.vtu"), (2.0, "vtk/solid_0002.vtu")]
    back.truncate(1.0)
    assert len(results.PvdSeries.read(tmp_path / "solid.pvd").entries) == 2


def test_checkpoint_round_trip(tmp_path):
    a = {"u": np.random.default_rng(0).standard_normal((5, 3)), "k": np.arange(4)}
    results.save_checkpoint(tmp_path / "c.npz", a, {"step": 3, "t": 1.5})
    arrays, meta = results.load_checkpoint(tmp_path / "c.npz")
    assert meta == {"step": 3, "t": 1.5}
    for k in a:
        np.testing.assert_array_equal(arrays[k], a[k])
