"""The resumable sampled estimate (porefsi.stokes.sampled_resume) and the CLI's sampled path.

Truths: an uninterrupted run of the same estimate (a resumed run must give the same numbers, to
the last bit, solving only what the interrupted one had not finished), and the benchmark's own
pooling (``benchmarks/bench_stokes_sampled.py blocks`` + ``summarise``): the CLI must give the same
estimate from the same blocks and levels.
"""

from __future__ import annotations

import importlib.util
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage

from porefsi.cli import main
from porefsi.errors import InputError
from porefsi.image import VoxelImage
from porefsi.stokes import resume_sampled_permeability, sampled_permeability
from porefsi.stokes import sampled as sm

ROOT = Path(__file__).resolve().parents[1]
LEVELS = (1, 2, 3)


def _blobs(n=16, sigma=1.5, porosity=0.35, seed=1):
    f = ndimage.gaussian_filter(np.random.default_rng(seed).standard_normal((n, n, n)), sigma, mode="wrap")
    return VoxelImage((f < np.quantile(f, porosity)).astype(np.uint8), 1e-6)


def _numbers(s):
    """Every number of a sampled estimate that a resumed run must reproduce."""
    return (s.k_mD, s.native_k_mD, s.factor, s.uncertainty_mD, s.factor_se, s.factor_gci, s.order,
            [b.origin for b in s.blocks], [b.k_mD for b in s.blocks], [b.k_inf_mD for b in s.blocks])


def _flat(s) -> np.ndarray:
    n = _numbers(s)
    return np.array([*n[:7], *np.ravel(n[7]), *np.ravel(n[8]), *n[9]], float)


def _same_solves(a, b):
    """Two runs that each solved everything: equal to the solver's run-to-run spread (measured: k 5e-11,
    the GCI, a difference of levels, 7e-10 relative on these 16^3 solves; the pooled numbers of one set
    of solves are bit-identical)."""
    return np.allclose(_flat(a), _flat(b), rtol=1e-7, atol=0)


class _Counting:
    """Wraps ``sampled.voxel_permeability``: counts the solves, optionally interrupts the n-th."""

    def __init__(self, real, stop_at=None):
        self.real, self.stop_at, self.calls = real, stop_at, 0

    def __call__(self, *a, **kw):
        self.calls += 1
        if self.stop_at is not None and self.calls == self.stop_at:
            raise KeyboardInterrupt
        return self.real(*a, **kw)


@pytest.fixture(scope="module")
def reference():
    img = _blobs()
    return img, sampled_permeability(img, "x", levels=LEVELS, blocks=3, block=8)


def _records(path):
    lines = Path(path).read_text().splitlines()
    return json.loads(lines[0]), [json.loads(x) for x in lines[1:]]


def test_interrupted_run_resumes_to_identical_numbers(reference, tmp_path, monkeypatch):
    img, ref = reference
    path = tmp_path / "run.jsonl"
    real = sm.voxel_permeability
    monkeypatch.setattr(sm, "voxel_permeability", _Counting(real, stop_at=6))  # native + 4 block levels kept
    with pytest.raises(KeyboardInterrupt):
        resume_sampled_permeability(img, path, "x", LEVELS, blocks=3, block=8)
    head, recs = _records(path)
    assert head["format"] == "porefsi-sampled-resume" and head["axis"] == "x" and head["block"] == 8
    assert [r["kind"] for r in recs] == ["native"] + ["block"] * 4
    assert [[r["origin"], r["refine"]] for r in recs[1:]] == [
        [list(ref.blocks[0].origin), 1], [list(ref.blocks[0].origin), 2], [list(ref.blocks[0].origin), 3],
        [list(ref.blocks[1].origin), 1]]
    with open(path, "ab") as fh:  # a kill in the middle of the next append: half a line
        fh.write(b'{"kind": "block", "origin": [0, 8')
    counting = _Counting(real)
    monkeypatch.setattr(sm, "voxel_permeability", counting)
    resumed = resume_sampled_permeability(img, path, "x", LEVELS, blocks=3, block=8)
    assert counting.calls == 1 + 3 * 3 - 5  # only what was not finished
    assert _same_solves(resumed, ref)
    _, recs = _records(path)  # the cut line is gone, every line is whole
    assert len(recs) == 10 and sorted((tuple(r["origin"]), r["refine"]) for r in recs[1:]) == sorted(
        (b.origin, f) for b in ref.blocks for f in LEVELS)
    k = {(tuple(r["origin"]), r["refine"]): r["k_mD"] for r in recs[1:]}  # the run pooled exactly what is on disk
    assert [b.k_mD for b in resumed.blocks] == [tuple(k[(b.origin, f)] for f in LEVELS) for b in resumed.blocks]
    assert resumed.native_k_mD == recs[0]["result"]["k_mD"]
    again = _Counting(real)
    monkeypatch.setattr(sm, "voxel_permeability", again)
    assert _numbers(resume_sampled_permeability(img, path, "x", LEVELS, blocks=3, block=8)) == _numbers(resumed)
    assert again.calls == 0


def test_a_killed_process_loses_only_the_solve_in_progress(reference, tmp_path):
    """SIGKILL (no clean-up at all) during the 7th solve: the six before it are on disk."""
    img, ref = reference
    path, npy = tmp_path / "run.jsonl", tmp_path / "img.npy"
    np.save(npy, img.phases)
    script = f"""
import os, signal, numpy as np
from porefsi.image import VoxelImage
from porefsi.stokes import resume_sampled_permeability
from porefsi.stokes import sampled as sm
real, n = sm.voxel_permeability, [0]
def solve(*a, **kw):
    n[0] += 1
    if n[0] == 7:
        os.kill(os.getpid(), signal.SIGKILL)
    return real(*a, **kw)
sm.voxel_permeability = solve
resume_sampled_permeability(VoxelImage(np.load({str(npy)!r}), 1e-6), {str(path)!r}, "x", (1, 2, 3), blocks=3, block=8)
"""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, timeout=300)
    assert done.returncode == -signal.SIGKILL, done.stderr.decode()[-2000:]
    assert len(_records(path)[1]) == 6
    assert _same_solves(resume_sampled_permeability(img, path, "x", LEVELS, blocks=3, block=8), ref)


def test_a_file_of_another_run_is_refused_before_anything_is_solved(reference, tmp_path, monkeypatch):
    img, _ = reference
    path = tmp_path / "run.jsonl"
    resume_sampled_permeability(img, path, "x", (1, 2), blocks=2, block=8)
    before = path.read_bytes()
    monkeypatch.setattr(sm, "voxel_permeability", _Counting(sm.voxel_permeability, stop_at=1))
    other = img.phases.copy()
    other[0, 0, 0] = 1 - other[0, 0, 0]
    for im, kw, msg in ((img, {"axis": "y"}, "axis 'x'"), (VoxelImage(other, 1e-6), {}, "image_sha256"),
                        (VoxelImage(img.phases, 2e-6), {}, "image_sha256"), (img, {"block": 10}, "block 8"),
                        (img, {"rtol": 1e-8}, "options"), (img, {"wall": "ghost"}, "options")):
        with pytest.raises(InputError, match=f"was written for {msg}.*use a new file"):
            resume_sampled_permeability(im, path, levels=(1, 2), blocks=2, **{"block": 8, **kw})
    assert path.read_bytes() == before
    bad = tmp_path / "bad.jsonl"
    bad.write_text(before.decode().splitlines()[0] + "\nnot json\n" + before.decode().splitlines()[1] + "\n")
    with pytest.raises(InputError, match="damaged"):
        resume_sampled_permeability(img, bad, "x", (1, 2), blocks=2, block=8)
    bad.write_text('{"a": 1}\n')
    with pytest.raises(InputError, match="not a porefsi sampled-resume file"):
        resume_sampled_permeability(img, bad, "x", (1, 2), blocks=2, block=8)
    with pytest.raises(InputError, match="existing folder"):
        resume_sampled_permeability(img, tmp_path / "nowhere" / "run.jsonl", "x", (1, 2), blocks=2, block=8)
    fresh = tmp_path / "fresh.jsonl"
    with pytest.raises(InputError, match="blocks must be"):  # validated before the file is created
        resume_sampled_permeability(img, fresh, "x", (1, 2), blocks=1, block=8)
    assert not fresh.exists()


def test_a_later_run_with_more_levels_reuses_the_coarser_ones(reference, tmp_path, monkeypatch):
    img, ref = reference
    path = tmp_path / "run.jsonl"
    resume_sampled_permeability(img, path, "x", (1, 2), blocks=3, block=8)
    counting = _Counting(sm.voxel_permeability)
    monkeypatch.setattr(sm, "voxel_permeability", counting)
    s = resume_sampled_permeability(img, path, "x", LEVELS, blocks=3, block=8)
    assert counting.calls == 3  # level 3 of each block, nothing else
    assert _same_solves(s, ref)


def _bench():
    spec = importlib.util.spec_from_file_location("bench_stokes_sampled",
                                                  ROOT / "benchmarks" / "bench_stokes_sampled.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_cli_gives_the_benchmarks_pooled_estimate_for_the_same_blocks_and_levels(tmp_path, capsys):
    """--sampled --refine 4 pools levels 1, 2, 3, 4 (the order from 2, 3, 4) exactly as the benchmark's
    ``blocks`` + ``summarise`` do on the same blocks; --resume gives the same again."""
    path = tmp_path / "blobs.npz"
    np.savez(path, image=_blobs(n=20, seed=4).phases, voxel_size_m=1e-6)
    argv = ["permeability", str(path), "--method", "voxel", "--sampled", "--refine", "4", "--blocks", "3",
            "--block", "8", "--json"]
    assert main(argv) == 0
    cli = json.loads(capsys.readouterr().out)
    e = cli["extrapolation"]
    assert e["levels"] == [1, 2, 3, 4] and e["blocks"] == 3
    bench, out = _bench(), tmp_path / "blocks.jsonl"
    bench.main(["blocks", "--image", str(path), "--axis", "x", "--levels", "1,2,3,4", "--blocks", "3", "--block", "8",
                "--out", str(out)])
    summary = bench.main(["summarise", str(out), "--native", repr(e["permeability_mD_native"])])
    capsys.readouterr()
    rows = [json.loads(line) for line in out.read_text().splitlines()]
    assert [r["origin"] for r in rows] == e["block_origins"]
    assert np.allclose(np.array([r["k_mD"] for r in rows]), e["block_permeability_mD_levels"], rtol=1e-7, atol=0)
    x = summary["x"]  # separate solves of the same blocks: the solver's run-to-run spread (~1e-10)
    assert x["factor"] == pytest.approx(e["factor"], rel=1e-7) and x["order"] == pytest.approx(e["order"], rel=1e-6)
    assert x["k_mD"] == pytest.approx(cli["permeability_mD"], rel=1e-7)
    assert x["uncertainty_mD"] == pytest.approx(e["uncertainty_mD"], rel=1e-6)
    # the CLI's own block solves in the benchmark's file format: summarise pools them to the last bit
    for r, k in zip(rows, e["block_permeability_mD_levels"], strict=True):
        r["k_mD"] = k
    out.write_text("".join(json.dumps(r) + "\n" for r in rows))
    x = bench.main(["summarise", str(out), "--native", repr(e["permeability_mD_native"])])["x"]
    capsys.readouterr()
    assert (x["factor"], x["order"], x["k_mD"], x["uncertainty_mD"]) == (
        e["factor"], e["order"], cli["permeability_mD"], e["uncertainty_mD"])
    resume, runs = tmp_path / "run.jsonl", []
    for _ in range(2):  # solves everything, then nothing: the same numbers
        assert main(argv + ["--resume", str(resume)]) == 0
        runs.append(json.loads(capsys.readouterr().out))
        assert runs[-1]["permeability_mD"] == pytest.approx(cli["permeability_mD"], rel=1e-7)
        assert runs[-1]["extrapolation"]["resume_file"] == str(resume)
    assert runs[1]["permeability_mD"] == runs[0]["permeability_mD"]  # from the file: bit-identical
    assert runs[1]["uncertainty_mD"] == runs[0]["uncertainty_mD"]


def test_cli_resume_needs_the_sampled_estimate(tmp_path, capsys):
    path = tmp_path / "blobs.npz"
    np.savez(path, image=_blobs().phases, voxel_size_m=1e-6)
    assert main(["permeability", str(path), "--method", "voxel", "--resume", str(tmp_path / "r.jsonl")]) == 2
    assert "add --extrapolate or --sampled" in capsys.readouterr().err
    assert main(["permeability", str(path), "--method", "voxel", "--extrapolate", "--refine", "2",
                 "--resume", str(tmp_path / "r.jsonl")]) == 2  # the whole image's refinement fits: not sampled
    assert "add --sampled, or drop --resume" in capsys.readouterr().err
    assert main(["permeability", str(path), "--resume", "r.jsonl"]) == 2  # --method network
    assert "voxel-solver options" in capsys.readouterr().err
    assert not (tmp_path / "r.jsonl").exists()
