"""`porefsi drainage -o DIR` cannot destroy finished work (issue 13, sections 1-4)."""

from __future__ import annotations

import json
import os
import signal

import numpy as np
import pytest

from porefsi.cli import EXIT_TERMINATED, main
from porefsi.network.lattice import lattice_network
from tests.test_reliability_run import one_line_error, popen, porefsi, tree

convert = pytest.importorskip("porefsi.network.convert")


@pytest.fixture(scope="module")
def done(tmp_path_factory):
    """A finished drainage run in DIR (subprocess): (network file, DIR, its command)."""
    d = tmp_path_factory.mktemp("drain")
    net = convert.save_network(lattice_network((8, 6, 4), 1e-4, np.random.default_rng(1)), d / "net.npz")
    out = d / "out"
    cmd = ["drainage", net, "--rate", "1e-12", "--t-end", "20", "-o", out, "--snapshots", "3"]
    r = porefsi(*cmd)
    assert r.returncode == 0, r.stderr
    return net, out, cmd


@pytest.mark.parametrize("what", ["changed_option", "empty", "truncated", "old_pickle"])
def test_resume_refusals_change_nothing(done, tmp_path, what):
    """--resume with another option or a damaged checkpoint used to delete drainage.csv,
    invasion.csv, the snapshots and the figure before refusing."""
    import shutil

    net, src, cmd = done
    out = tmp_path / "out"
    shutil.copytree(src, out)
    ck = out / "drainage_checkpoint.npz"
    args = [*cmd[:-4], "-o", out, "--snapshots", "3", "--resume"]
    if what == "changed_option":
        args[args.index("--rate") + 1] = "2e-12"
        words = ("different run",)
    elif what == "empty":
        ck.write_bytes(b"")
        words = (str(ck), "empty", "without --resume")
    elif what == "truncated":
        ck.write_bytes(ck.read_bytes()[:3000])
        words = (str(ck), "truncated or corrupt", "without --resume")
    else:
        ck.write_bytes(b"\x80\x04K\x01.")  # a pickle, as porefsi before format 2 wrote
        words = (str(ck), "pickle", "without --resume")
    before = tree(out)
    one_line_error(porefsi(*args), *words)
    assert tree(out) == before


def test_fresh_run_into_a_finished_run_is_refused_then_overwritten(done, tmp_path):
    net, src, cmd = done
    before = tree(src)
    one_line_error(porefsi(*cmd), "--resume", "--overwrite")
    one_line_error(porefsi(*cmd[:-2], "--snapshots", "2", "--overwrite", "--axis", "q"), "--axis")  # usage error
    assert tree(src) == before


def test_resume_of_a_finished_run_keeps_the_results(done):
    net, out, cmd = done
    csv = {n: (out / n).read_text() for n in ("drainage.csv", "invasion.csv", "snapshot_2.csv")}
    r = porefsi(*cmd, "--resume")
    assert r.returncode == 0, r.stderr
    for n, text in csv.items():
        assert (out / n).read_text() == text, n


def test_second_drainage_into_a_busy_folder_exits_2_naming_the_holder(tmp_path):
    net = convert.save_network(lattice_network((24, 12, 10), 1e-4, np.random.default_rng(5)), tmp_path / "n.npz")
    out = tmp_path / "out"
    a = popen("drainage", net, "--rate", "1e-12", "--t-end", "200", "-o", out, "--checkpoint-every", "0.05")
    try:
        import time

        deadline = time.monotonic() + 60
        while not (out / "drainage_checkpoint.npz").exists() and a.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)
        if a.poll() is not None:
            pytest.skip("the first run ended before the second started")
        r = porefsi("drainage", net, "-o", out, "--overwrite")
        if a.poll() is not None:
            pytest.skip("the first run ended while the second was starting")
        one_line_error(r, "in use by another porefsi run", f"pid {a.pid}")
    finally:
        a.kill()
        a.wait()


def test_sigterm_saves_at_the_end_of_the_event_and_exits_143(tmp_path, monkeypatch, capsys):
    """In process (the signal sent from inside the 30th event): exit 143, the checkpoint saved,
    the resume hint printed; then --resume completes."""
    from porefsi.flow._drainage_engine import Engine

    net = convert.save_network(lattice_network((10, 7, 6), 1e-4, np.random.default_rng(3)), tmp_path / "n.npz")
    out = tmp_path / "out"
    step = Engine.step

    def step_with_sigterm(self, t_target):
        if self.n_events == 29:
            os.kill(os.getpid(), signal.SIGTERM)
        return step(self, t_target)

    monkeypatch.setattr(Engine, "step", step_with_sigterm)
    before = signal.getsignal(signal.SIGTERM)
    argv = ["drainage", str(net), "--rate", "1e-12", "--t-end", "200", "-o", str(out), "--checkpoint-every", "1e9",
            "--json"]
    assert main(argv) == EXIT_TERMINATED
    assert signal.getsignal(signal.SIGTERM) is before
    err = capsys.readouterr().err
    assert "porefsi: interrupted: drainage interrupted at t =" in err and "--resume" in err
    monkeypatch.undo()
    from tests.test_drainage_checkpoint import _saved

    assert _saved(out / "drainage_checkpoint.npz")["sim"]._engine.n_events == 30
    assert main([*argv, "--resume"]) == 0
    assert json.loads(capsys.readouterr().out)["n_events"] > 30
