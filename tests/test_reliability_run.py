"""`porefsi run` cannot destroy finished work (issue 13, sections 1-5), driven as a user would.

The real CLI runs in a subprocess (``python -m porefsi``) on a small case: a finished run, then
bad re-runs, corrupt checkpoints, a concurrent run, a kill and a SIGTERM. A failing command must
leave the run directory byte for byte as it was.
"""

from __future__ import annotations

import json
import os
import pickle
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

#: A small case: coarse mesh, few test points, no figures or VTK; 2 steps for the finished run.
CASE = """name = "rel"
[solid]
coarsen = 10
[interface]
n_test_points = 100
[drainage]
t_end = {t_end}
[coupling]
exchange_dt = {dt}
[output]
snapshot_times = []
checkpoint_every = 1
figures = false
vtk = false
"""


def porefsi(*args, timeout=120, **kw) -> subprocess.CompletedProcess:
    """Run the CLI in a subprocess (stdin closed, stderr not a terminal)."""
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    return subprocess.run([sys.executable, "-m", "porefsi", *map(str, args)], capture_output=True, text=True,
                          timeout=timeout, stdin=subprocess.DEVNULL, env=env, **kw)


def popen(*args) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    return subprocess.Popen([sys.executable, "-m", "porefsi", *map(str, args)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL, env=env)


def tree(d: Path) -> dict:
    """Every file under ``d`` with its bytes and mtime: a directory 'exactly as it was'."""
    return {str(p.relative_to(d)): (p.read_bytes(), p.stat().st_mtime_ns) for p in sorted(d.rglob("*"))
            if p.is_file()}


def one_line_error(r: subprocess.CompletedProcess, *words: str) -> str:
    assert r.returncode == 2, (r.returncode, r.stderr)
    assert r.stderr.startswith("porefsi: error: ") and r.stderr.count("\n") == 1, r.stderr
    assert "Traceback" not in r.stderr
    for w in words:
        assert w in r.stderr, (w, r.stderr)
    return r.stderr


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """A completed 2-step run: (case file, run directory, stderr of the run)."""
    d = tmp_path_factory.mktemp("rel")
    case = d / "case.toml"
    case.write_text(CASE.format(t_end=2.0, dt=1.0))
    # a figure of the run (own name): --resume of a finished run used to delete the figures
    out = d / "out"
    r = porefsi("run", case, "-o", out)
    assert r.returncode == 0, r.stderr
    (out / "figures").mkdir()
    (out / "figures" / "timeseries.png").write_bytes(b"figure")
    return case, out, r.stderr


def test_finished_run_reports_progress_lines_without_a_terminal(finished):
    """stderr is a pipe here: the batch log still shows the run is alive, one line per step."""
    err = finished[2]
    assert "porefsi run: step 2/2, t = 2 s" in err, err


@pytest.mark.parametrize("bad", ["missing_image", "bad_crop", "non_utf8"])
def test_a_failing_rerun_with_overwrite_leaves_the_finished_run_alone(finished, tmp_path, bad):
    case, out, _ = finished
    before = tree(out)
    c = tmp_path / "c.toml"
    if bad == "missing_image":
        c.write_text(case.read_text() + '[image]\npath = "no_such_image.npy"\nvoxel_size = 5e-6\n')
        words = ("no_such_image.npy", "does not exist")
    elif bad == "bad_crop":
        c.write_text(case.read_text() + "[image]\ncrop = [[0, 500], [0, 60], [0, 60]]\n")
        words = ("image.crop",)
    else:
        c.write_bytes(case.read_bytes().replace(b'"rel"', b'"r\xe9l"'))
        words = (str(c), "UTF-8")
    one_line_error(porefsi("run", c, "-o", out, "--overwrite"), *words)
    assert tree(out) == before


def test_a_fresh_run_into_a_finished_run_is_refused(finished):
    case, out, _ = finished
    before = tree(out)
    err = one_line_error(porefsi("run", case, "-o", out), "--overwrite", "completed")
    assert "2 exchange steps" in err
    assert tree(out) == before


def test_resume_of_a_finished_run_changes_nothing(finished):
    case, out, _ = finished
    before = tree(out)
    r = porefsi("run", case, "-o", out, "--resume", "--json")
    assert r.returncode == 0, r.stderr
    assert "already holds the completed run; nothing to do" in r.stderr
    assert json.loads(r.stdout)["status"] == "completed"
    assert tree(out) == before  # the figure is still there


@pytest.mark.parametrize("damage", ["empty", "truncated", "random", "pickle", "old_format"])
def test_a_damaged_checkpoint_is_one_line_and_changes_nothing(finished, tmp_path, damage):
    """The message names the file and the fix (run again without --resume); a planted pickle
    that would create a file when unpickled is never executed."""
    import shutil

    case, src, _ = finished
    out = tmp_path / "out"
    shutil.copytree(src, out)
    (out / "summary.json").write_text(json.dumps({"status": "interrupted"}))  # resumable, not complete
    ck = out / "checkpoint.npz"
    good = ck.read_bytes()
    marker = tmp_path / "pwned"
    data = {"empty": b"", "truncated": good[: len(good) // 2], "random": os.urandom(5000),
            "pickle": pickle.dumps(_Evil(str(marker)))}
    if damage == "old_format":  # a plain archive of another layout (e.g. an earlier porefsi's)
        import numpy as np

        from porefsi.io.results import save_checkpoint

        save_checkpoint(ck, {"simulator": np.zeros(3, np.uint8)}, {**_meta(good), "format": 1})
    else:
        ck.write_bytes(data[damage])
    before = tree(out)
    r = porefsi("run", case, "-o", out, "--resume")
    one_line_error(r, str(ck), "without --resume")
    assert "allow_pickle" not in r.stderr
    assert tree(out) == before
    assert not marker.exists()


def _meta(npz: bytes) -> dict:
    import io

    import numpy as np

    with np.load(io.BytesIO(npz)) as z:
        return json.loads(bytes(z["__meta__"]).decode())


class _Evil:
    """Unpickling this creates a file: proof that a checkpoint was unpickled."""

    def __init__(self, path):
        self.path = path

    def __reduce__(self):
        return (Path.touch, (Path(self.path),))


def test_output_paths_that_cannot_be_folders_are_one_line(finished, tmp_path):
    case, _, _ = finished
    f = tmp_path / "afile"
    f.write_text("x")
    one_line_error(porefsi("run", case, "-o", f), str(f), "not a folder")
    one_line_error(porefsi("run", case, "-o", f / "sub"), "is a file")
    assert f.read_text() == "x"


def test_too_many_exchange_steps_are_refused_before_anything_is_written(tmp_path):
    c = tmp_path / "c.toml"
    c.write_text(CASE.format(t_end=20.0, dt=1e-9))
    out = tmp_path / "out"
    one_line_error(porefsi("run", c, "-o", out), "2e+10 exchange steps", "--force")
    assert not out.exists()


def test_concurrent_runs_kill_and_sigterm(tmp_path):
    """A second run into a busy folder exits 2 naming the holder; kill -9 leaves a lock that does
    not block; SIGTERM finishes the step, checkpoints, writes status "interrupted" with the
    resume command and exits 143."""
    c = tmp_path / "c.toml"
    c.write_text(CASE.format(t_end=40.0, dt=0.5))  # 80 steps: long enough to catch in the act
    out = tmp_path / "out"
    a = popen("run", c, "-o", out)
    try:
        _wait_for(lambda: (out / "checkpoint.npz").exists(), a)
        b = porefsi("run", c, "-o", tmp_path / "out", "--overwrite")
        one_line_error(b, "in use by another porefsi run", f"pid {a.pid}")
        a.send_signal(signal.SIGKILL)
        a.wait(30)
    finally:
        a.kill()
    assert (out / ".porefsi.lock").exists()  # left behind by the killed run: harmless
    saved = (out / "checkpoint.npz").stat().st_mtime_ns
    resumed = popen("run", c, "-o", out, "--resume")
    try:  # SIGTERM once the resumed run has saved a step of its own
        _wait_for(lambda: (out / "checkpoint.npz").stat().st_mtime_ns != saved, resumed,
                  what="the resumed run's first checkpoint")
        resumed.send_signal(signal.SIGTERM)
        _, err = resumed.communicate(timeout=60)
    finally:
        resumed.kill()
    assert resumed.returncode == 143, err
    assert "SIGTERM at exchange step" in err and "--resume" in err and "Traceback" not in err
    s = json.loads((out / "summary.json").read_text())
    assert s["status"] == "interrupted" and "SIGTERM" in s["error"]
    assert s["resume_command"] == f"porefsi run {out / 'case.toml'} -o {out} --resume"
    from porefsi.io.results import load_checkpoint

    meta = load_checkpoint(out / "checkpoint.npz")[1]
    assert meta["step_index"] == s["n_exchange_steps"] < 80  # the step in progress finished and was saved
    rows = (out / "timeseries.csv").read_text().strip().splitlines()
    assert len(rows) == 1 + 1 + meta["step_index"]  # header, step 0, the steps done
    assert not (out / ".porefsi.lock").exists()


def _wait_for(cond, proc: subprocess.Popen, what: str = "the run's first checkpoint", timeout: float = 90) -> None:
    deadline = time.monotonic() + timeout
    while not cond():
        if proc.poll() is not None:
            raise AssertionError(f"the run ended before {what}: {proc.stderr.read()}")
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.05)


@pytest.fixture
def small_fs(tmp_path):
    """A real filesystem of a given size (tmpfs; root and mount permission needed, else skipped)."""
    mnt = tmp_path / "fs"
    mnt.mkdir()

    def mount(size: int, remount: bool = False):
        opts = f"{'remount,' if remount else ''}size={size}"
        r = subprocess.run(["mount", "-t", "tmpfs", "-o", opts, "tmpfs", str(mnt)], capture_output=True, text=True)
        if r.returncode != 0:
            pytest.skip(f"cannot mount a small tmpfs here: {r.stderr.strip()}")
        return mnt

    yield mount
    subprocess.run(["umount", str(mnt)], capture_output=True)


@pytest.mark.slow  # ~14 s; the default suite has the simulated ENOSPC (test_reliability_inputs)
def test_a_really_full_disk_keeps_the_last_checkpoint_and_resumes(finished, small_fs):
    """A tmpfs with room for one checkpoint but not for the atomic write of the next (old and new
    copies at once): exit 2 with one line saying the disk is full, the step-1 checkpoint intact,
    and --resume completes once there is room."""
    case, done, _ = finished
    size = (done / "checkpoint.npz").stat().st_size
    c = case.parent / "c3.toml"
    c.write_text(CASE.format(t_end=3.0, dt=1.0))
    fs = small_fs(int(1.6 * size) + 200_000)
    out = fs / "run"
    one_line_error(porefsi("run", c, "-o", out), "free", "disk")  # refused up front: estimated too large
    assert not out.exists()
    r = porefsi("run", c, "-o", out, "--force")
    err = "".join(line for line in r.stderr.splitlines(keepends=True) if not line.startswith("porefsi run: step"))
    one_line_error(subprocess.CompletedProcess(r.args, r.returncode, r.stdout, err), "no space left", "--resume")
    from porefsi.io.results import load_checkpoint

    assert load_checkpoint(out / "checkpoint.npz")[1]["step_index"] >= 1
    assert not [p for p in out.rglob("*.tmp*")]  # no half-written temporaries left behind
    small_fs(200 * 2**20, remount=True)
    r = porefsi("run", c, "-o", out, "--resume", "--json")
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["n_exchange_steps"] == 3
