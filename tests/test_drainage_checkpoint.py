"""Checkpoints of a drainage run: a killed run resumes to the uninterrupted run's result, bit for bit."""

import json

import numpy as np
import pytest

from porefsi.cli import main
from porefsi.errors import InputError
from porefsi.flow import _drainage_checkpoint as ckpt
from porefsi.flow.drainage import simulate_drainage
from porefsi.flow.fluids import Fluids
from porefsi.network.lattice import lattice_network

convert = pytest.importorskip("porefsi.network.convert")


class _KilledError(Exception):
    """Stands in for the process being killed right after a checkpoint."""


def _saved(path):
    """The checkpoint at ``path`` as simulate_drainage would load it (whatever run it belongs to)."""
    from porefsi.io.results import load_checkpoint

    return ckpt.load(path, load_checkpoint(path)[1]["key"])


def _rate_for_ca(net, fl, ca):
    ext = net.extent
    return ca * fl.sigma * float(ext[1] * ext[2]) / fl.mu_n


def _killer(after):
    calls = []

    def progress(sim, seconds):
        calls.append(seconds)
        if len(calls) == after:
            raise _KilledError

    return progress


@pytest.fixture(scope="module")
def case():
    net = lattice_network((10, 7, 6), 1e-4, np.random.default_rng(3))
    fl = Fluids()
    rate = _rate_for_ca(net, fl, 1e-6)
    ref = simulate_drainage(net, fl, rate=rate, t_end=1e9, stop_at_breakthrough=True)
    t_end = 1.5 * ref.breakthrough_time  # past breakthrough: outflow of both fluids
    return net, fl, rate, t_end


@pytest.mark.parametrize("solver", ["direct", "lowrank", "selinv"])
def test_resumed_run_equals_uninterrupted_bit_for_bit(case, tmp_path, solver):
    net, fl, rate, t_end = case
    kw = dict(rate=rate, t_end=t_end, times=[0.3 * t_end, 0.6 * t_end], solver=solver)
    ref = simulate_drainage(net, fl, **kw)
    path = tmp_path / "run.npz"
    with pytest.raises(_KilledError):  # checkpoint after every event; killed after the 120th
        simulate_drainage(net, fl, checkpoint=path, checkpoint_every=1e-12, progress=_killer(120), **kw)
    saved = _saved(path)
    so = saved["sim"]._engine.solver
    assert so.method == solver and saved["sim"]._engine.n_events == 120
    if solver == "lowrank":  # the base factorisation travels as its recipe (values + column batches)
        assert so._saved_base is not None and len(so._saved_base["batches"]) > 0
    if solver == "selinv":  # its base travels as the base's values and the node batches
        assert so._sel is None and so._sel_saved is not None and len(so._sel_saved[1]) > 0
    res = simulate_drainage(net, fl, checkpoint=path, resume=True, **kw)
    for k, v in ref.history.items():
        np.testing.assert_array_equal(res.history[k], v, err_msg=k)
    np.testing.assert_array_equal(res.invasion_time, ref.invasion_time)
    assert len(res.snapshots) == len(ref.snapshots) == 3
    for a, b in zip(res.snapshots, ref.snapshots, strict=True):
        assert a.t == b.t
        np.testing.assert_array_equal(a.pressure, b.pressure)
        np.testing.assert_array_equal(a.nw_saturation, b.nw_saturation)
    assert res.counters == ref.counters
    assert res.breakthrough_time == ref.breakthrough_time and res.final.sw == ref.final.sw
    assert res.seconds >= saved["seconds"]  # all processes counted


def test_stop_at_breakthrough_stops_at_the_breakthrough_event(case):
    net, fl, rate, t_end = case
    res = simulate_drainage(net, fl, rate=rate, t_end=t_end, times=[0.1 * t_end, 0.9 * t_end],
                            stop_at_breakthrough=True)
    assert res.final.t == res.breakthrough_time  # not one event later
    assert [s.t for s in res.snapshots] == [0.1 * t_end, res.breakthrough_time]


def test_resume_refuses_missing_corrupt_and_foreign_checkpoints(case, tmp_path):
    net, fl, rate, t_end = case
    path = tmp_path / "run.npz"
    with pytest.raises(InputError, match="no drainage checkpoint"):
        simulate_drainage(net, fl, rate=rate, t_end=t_end, checkpoint=path, resume=True)
    with pytest.raises(InputError, match="needs the checkpoint file"):
        simulate_drainage(net, fl, rate=rate, t_end=t_end, resume=True)
    with pytest.raises(_KilledError):
        simulate_drainage(net, fl, rate=rate, t_end=t_end, checkpoint=path, checkpoint_every=1e-12,
                          progress=_killer(5))
    for other in (dict(rate=2 * rate, t_end=t_end), dict(rate=rate, t_end=2 * t_end),
                  dict(rate=rate, t_end=t_end, solver="direct")):
        with pytest.raises(InputError, match="different run"):
            simulate_drainage(net, fl, checkpoint=path, resume=True, **other)
    with pytest.raises(InputError, match="different run"):
        simulate_drainage(net, Fluids(mu_n=2e-2), rate=rate, t_end=t_end, checkpoint=path, resume=True)
    path.write_bytes(b"not a checkpoint")
    with pytest.raises(InputError, match="not a usable drainage checkpoint"):
        simulate_drainage(net, fl, rate=rate, t_end=t_end, checkpoint=path, resume=True)
    with pytest.raises(InputError, match="needs a porefsi Network and Fluids"):
        simulate_drainage("net.npz", fl, rate=rate, checkpoint=path)
    with pytest.raises(InputError, match="needs a porefsi Network and Fluids"):
        simulate_drainage(net, {"sigma": 0.03}, rate=rate, checkpoint=path)
    with pytest.raises(InputError, match="checkpoint_every"):
        simulate_drainage(net, fl, rate=rate, t_end=t_end, checkpoint=path, checkpoint_every=0)


def test_a_failed_checkpoint_write_keeps_the_previous_one(case, tmp_path, monkeypatch):
    from porefsi.flow.drainage import DrainageSimulator

    net, fl, rate, _ = case
    sim = DrainageSimulator(net, fl, rate=rate)
    path = tmp_path / "c.npz"
    ckpt.save(path, "k", {"sim": sim, "snaps": [], "k": 1, "seconds": 0.0})

    from porefsi.io import results

    def broken(fd):  # the new bytes are in the temporary file, then the disk fails
        raise OSError("disk full")

    monkeypatch.setattr(results.os, "fsync", broken)
    with pytest.raises(OSError):
        ckpt.save(path, "k", {"sim": sim, "snaps": [], "k": 2, "seconds": 0.0})
    monkeypatch.undo()
    assert ckpt.load(path, "k")["k"] == 1


def test_cli_drainage_checkpoints_and_resumes(tmp_path, capsys):
    net = lattice_network((6, 5, 3), 1e-4, np.random.default_rng(0))
    path = convert.save_network(net, tmp_path / "net.npz")
    out = tmp_path / "out"
    argv = ["drainage", str(path), "--rate", "1e-12", "--t-end", "20", "-o", str(out), "--json",
            "--checkpoint-every", "1e-9"]
    assert main(argv) == 0
    cap = capsys.readouterr()
    first = json.loads(cap.out)
    assert "checkpoint saved" in cap.err and (out / "drainage_checkpoint.npz").is_file()
    csv = (out / "drainage.csv").read_text()
    (out / "drainage.csv").unlink()
    assert main([*argv, "--resume"]) == 0  # from the final checkpoint: the same outputs again
    again = json.loads(capsys.readouterr().out)
    assert (out / "drainage.csv").read_text() == csv
    for k in ("n_events", "n_solves", "final_sw", "breakthrough_time_s", "mass_balance_error"):
        assert again[k] == first[k]
    code = main(["drainage", str(path), "--rate", "2e-12", "--t-end", "20", "-o", str(out), "--resume"])
    assert code == 2 and "different run" in capsys.readouterr().err
    code = main(["drainage", str(path), "-o", str(tmp_path / "empty"), "--resume"])
    assert code == 2 and "no drainage checkpoint" in capsys.readouterr().err
    code = main(["drainage", str(path), "--resume"])
    assert code == 2 and "needs -o DIR" in capsys.readouterr().err


def test_cli_run_killed_with_sigkill_resumes_to_the_uninterrupted_outputs(tmp_path):
    # a real kill (no chance to clean up) during the run: the atomic checkpoint survives and the
    # resumed run writes the very files of a run that was never interrupted
    import subprocess
    import sys
    import time

    net = lattice_network((24, 12, 10), 1e-4, np.random.default_rng(5))
    path = convert.save_network(net, tmp_path / "net.npz")

    def cmd(out, *extra):
        return [sys.executable, "-m", "porefsi", "drainage", str(path), "--rate", "1e-12", "--t-end", "200",
                "-o", str(out), "--json", "--snapshots", "3", *extra]

    ref = subprocess.run(cmd(tmp_path / "ref"), capture_output=True, text=True, check=True)
    out = tmp_path / "killed"
    proc = subprocess.Popen(cmd(out, "--checkpoint-every", "0.05"), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    ck_file = out / "drainage_checkpoint.npz"
    deadline = time.monotonic() + 120
    while not ck_file.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    proc.kill()
    proc.wait()
    if proc.returncode == 0:
        pytest.skip("the run finished before it could be killed")
    events_at_kill = _saved(ck_file)["sim"]._engine.n_events
    res = subprocess.run(cmd(out, "--resume"), capture_output=True, text=True, check=True)
    first, again = json.loads(ref.stdout), json.loads(res.stdout)
    assert events_at_kill < first["n_events"]
    for k in ("n_events", "n_solves", "final_sw", "breakthrough_time_s", "mass_balance_error"):
        assert again[k] == first[k]
    for name in ("drainage.csv", "invasion.csv", *(f"snapshot_{i}.csv" for i in range(3))):
        assert (out / name).read_text() == (tmp_path / "ref" / name).read_text(), name


def test_ctrl_c_saves_at_the_end_of_the_event_and_resumes_bit_for_bit(case, tmp_path, monkeypatch):
    import os
    import signal

    from porefsi.flow._drainage_engine import Engine

    net, fl, rate, t_end = case
    kw = dict(rate=rate, t_end=t_end, solver="lowrank")
    ref = simulate_drainage(net, fl, **kw)
    path = tmp_path / "run.npz"
    step = Engine.step

    def step_with_ctrl_c(self, t_target):  # Ctrl-C arrives during the 50th event
        if self.n_events == 49:
            os.kill(os.getpid(), signal.SIGINT)
        return step(self, t_target)

    monkeypatch.setattr(Engine, "step", step_with_ctrl_c)
    before = signal.getsignal(signal.SIGINT)
    with pytest.raises(KeyboardInterrupt, match="saved to"):  # no periodic checkpoint: the Ctrl-C's
        simulate_drainage(net, fl, checkpoint=path, checkpoint_every=1e9, **kw)
    assert signal.getsignal(signal.SIGINT) is before  # the handler is restored
    monkeypatch.undo()
    saved = _saved(path)
    assert saved["sim"]._engine.n_events == 50  # the event in progress finished, then saved
    res = simulate_drainage(net, fl, checkpoint=path, resume=True, **kw)
    for k, v in ref.history.items():
        np.testing.assert_array_equal(res.history[k], v, err_msg=k)


def test_cli_ctrl_c_saves_and_says_how_to_resume(tmp_path):
    import signal
    import subprocess
    import sys
    import time

    from porefsi.cli import EXIT_INTERRUPTED

    net = lattice_network((24, 12, 10), 1e-4, np.random.default_rng(5))
    path = convert.save_network(net, tmp_path / "net.npz")
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "porefsi", "drainage", str(path), "--rate", "1e-12", "--t-end", "200",
           "-o", str(out), "--json", "--checkpoint-every", "0.05"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while not (out / "drainage_checkpoint.npz").exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate()
    if proc.returncode == 0:
        pytest.skip("the run finished before Ctrl-C arrived")
    assert proc.returncode == EXIT_INTERRUPTED
    assert "porefsi: interrupted: drainage interrupted at t =" in err and "--resume" in err
    res = subprocess.run([*cmd, "--resume"], capture_output=True, text=True, check=True)
    ref = subprocess.run([*cmd[:-5], "-o", str(tmp_path / "ref"), "--json"], capture_output=True, text=True,
                         check=True)
    assert (out / "drainage.csv").read_text() == (tmp_path / "ref" / "drainage.csv").read_text()
    assert json.loads(res.stdout)["n_events"] == json.loads(ref.stdout)["n_events"]


def test_cli_fresh_run_removes_the_outputs_of_an_earlier_run_only(tmp_path, capsys):
    net = lattice_network((6, 5, 3), 1e-4, np.random.default_rng(0))
    path = convert.save_network(net, tmp_path / "net.npz")
    out = tmp_path / "out"
    assert main(["drainage", str(path), "-o", str(out), "--snapshots", "4"]) == 0
    assert len(list(out.glob("snapshot_*.csv"))) == 4
    (out / "notes.txt").write_text("mine")
    assert main(["drainage", str(path), "-o", str(out), "--snapshots", "2"]) == 2  # refused: --overwrite
    assert "--overwrite" in capsys.readouterr().err and len(list(out.glob("snapshot_*.csv"))) == 4
    assert main(["drainage", str(path), "-o", str(out), "--snapshots", "2", "--overwrite"]) == 0
    assert sorted(f.name for f in out.glob("snapshot_*.csv")) == ["snapshot_0.csv", "snapshot_1.csv"]
    assert (out / "notes.txt").read_text() == "mine"
    capsys.readouterr()
