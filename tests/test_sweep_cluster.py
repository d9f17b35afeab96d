"""``porefsi sweep --scheduler-file`` on a separately started ``dask scheduler`` + ``dask worker``.

Issue 15's "done means": the scheduler and the workers are subprocesses on localhost, as a user
starts them by hand or as dask-jobqueue starts them in batch jobs; porefsi's own process only
connects. One worker process is killed (SIGKILL) in the middle of a member, after that member's
first checkpoint: the member is submitted again, resumes from the checkpoint on a worker that
lives, and the sweep ends with the numbers of a serial run, bit for bit.

The scheduler runs with ``allowed-failures = 0``, so the loss is not absorbed by Dask's own
rescheduling: it is porefsi's resubmission (``--retries``) that is tested.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from porefsi.sweep import Cluster, load_sweep, run_sweep
from tests.test_sweep import results_of, write_sweep

ROOT = Path(__file__).resolve().parent.parent
RATES = '"drainage.rate" = [1.25e-13, 2.5e-13, 5e-10]\n'
T_END = 12.0  # exchange steps per member: long enough to kill a worker between two of them


def _env(**extra) -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH", "")) if p)
    env.update(OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MPLBACKEND="Agg", **extra)
    return env


def _wait_for(test, timeout: float, what: str, procs=()):
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        v = test()
        if v:
            return v
        for p in procs:
            assert p.poll() is None, f"{what}: a process exited early ({p.args})"
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what}")


def _running_member(out: Path):
    """(member folder, worker pid) of a member past its first checkpoint and still running."""
    for d in sorted(out.glob("[0-9]*")):
        try:
            state = json.loads((d / "member.json").read_text())
            summary_done = (d / "summary.json").is_file()
        except (OSError, ValueError):
            continue
        last = state["attempts"][-1]
        if last.get("status") == "running" and (d / "checkpoint.npz").is_file() and not summary_done:
            return d, int(last["worker"].rsplit(":", 1)[1])
    return None


@pytest.fixture
def cluster(tmp_path):
    """A scheduler (scheduler file) and a worker with two processes, as subprocesses; stopped after."""
    sched_file = tmp_path / "scheduler.json"
    logs = {n: open(tmp_path / f"{n}.log", "wb") for n in ("scheduler", "worker")}
    procs = [subprocess.Popen([sys.executable, "-m", "dask", "scheduler", "--scheduler-file", str(sched_file),
                               "--host", "127.0.0.1", "--port", "0", "--no-dashboard"],
                              env=_env(DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES="0"),
                              stdout=logs["scheduler"], stderr=subprocess.STDOUT)]
    try:
        _wait_for(sched_file.is_file, 60, "the scheduler file", procs)
        procs.append(subprocess.Popen([sys.executable, "-m", "dask", "worker", "--scheduler-file", str(sched_file),
                                       "--nworkers", "2", "--nthreads", "1", "--no-dashboard"], env=_env(),
                                      stdout=logs["worker"], stderr=subprocess.STDOUT))
        yield sched_file
    finally:
        for p in reversed(procs):
            p.send_signal(signal.SIGTERM)
            try:
                p.wait(30)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        for f in logs.values():
            f.close()


@pytest.mark.slow  # ~45 s on 2 busy cores
def test_scheduler_and_workers_started_by_hand_survive_a_killed_worker(tmp_path, cluster):
    ref_dir = tmp_path / "ref"
    ref_dir.mkdir()
    run_sweep(load_sweep(write_sweep(ref_dir, RATES, t_end=T_END)), ref_dir / "out", Cluster(serial=True),
              progress=False)
    sweep_file = write_sweep(tmp_path, RATES, t_end=T_END)
    out = tmp_path / "out"
    with open(tmp_path / "sweep.log", "wb") as log:
        proc = subprocess.Popen([sys.executable, "-m", "porefsi", "sweep", str(sweep_file), "-o", str(out),
                                 "--scheduler-file", str(cluster), "--json"], env=_env(), stdout=subprocess.PIPE,
                                stderr=log, cwd=tmp_path)
        try:
            folder, pid = _wait_for(lambda: _running_member(out), 180, "a member past its first checkpoint", [proc])
            os.kill(pid, signal.SIGKILL)
            killed_at = time.time()
            stdout, _ = proc.communicate(timeout=300)
        finally:
            if proc.poll() is None:
                proc.kill()
    err = (tmp_path / "sweep.log").read_text()
    assert proc.returncode == 0, err
    assert json.loads(stdout)["completed"] == 3
    attempts = json.loads((folder / "member.json").read_text())["attempts"]
    assert len(attempts) == 2, attempts
    assert attempts[0]["status"] == "running" and attempts[0]["worker"].endswith(f":{pid}")  # killed there
    assert attempts[1]["status"] == "completed" and attempts[1]["resumed_from_step"] >= 1
    assert int(attempts[1]["worker"].rsplit(":", 1)[1]) != pid
    # resumed, not redone: the files of the steps up to the checkpoint are the killed attempt's
    kept = [folder / "pores" / f"step_{k:04d}.npz" for k in range(attempts[1]["resumed_from_step"] + 1)]
    assert all(f.stat().st_mtime < killed_at for f in kept)
    assert results_of(out) == results_of(ref_dir / "out")
    assert f"resumed from step {attempts[1]['resumed_from_step']}" in err  # the progress line says so
