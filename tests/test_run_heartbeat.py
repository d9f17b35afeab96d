"""A run whose stderr is not a terminal says it is alive while it sets up and while a step runs
(issue 13, section 4: a batch log must show a long set-up is not hung)."""

from __future__ import annotations

import io
import time

import pytest

from porefsi.case import _heartbeat
from porefsi.case._heartbeat import Heartbeat


def test_heartbeat_writes_while_silent_and_stops_with_the_block():
    out = io.StringIO()
    state = {"what": "step 0, setting up"}
    with Heartbeat(lambda: state["what"], every=0.05, stream=out) as hb:
        time.sleep(0.3)
        state["what"] = "step 1/4"
        time.sleep(0.3)
    n = hb.lines
    time.sleep(0.2)
    lines = out.getvalue().splitlines()
    assert n == len(lines) >= 4  # nothing written after the block
    assert lines[0].startswith("porefsi run: step 0, setting up, still running, ")
    assert lines[-1].startswith("porefsi run: step 1/4, still running, ")
    assert all(line.endswith(" s wall") for line in lines)


def test_disabled_heartbeat_writes_nothing():
    out = io.StringIO()
    with Heartbeat(lambda: "x", every=0.01, enabled=False, stream=out):
        time.sleep(0.1)
    assert out.getvalue() == ""


def test_a_broken_status_never_breaks_the_run():
    def status():
        raise RuntimeError("bug in the status")

    with Heartbeat(status, every=0.01, stream=io.StringIO()) as hb:
        time.sleep(0.1)
    assert hb.lines == 0


@pytest.mark.parametrize("progress", [None, False])
def test_run_case_beats_on_a_pipe_during_setup(tmp_path, monkeypatch, capsys, progress):
    """In-process run_case with stderr captured (not a terminal): lines name the set-up, then steps."""
    from porefsi.case import Case, run_case

    monkeypatch.setattr(_heartbeat, "HEARTBEAT_SECONDS", 0.02)
    case = Case().replace(solid={"coarsen": 10}, interface={"n_test_points": 100},
                          drainage={"t_end": 1.0}, coupling={"exchange_dt": 1.0},
                          output={"snapshot_times": [], "figures": False, "vtk": False})
    run_case(case, tmp_path / "out", progress=progress)
    err = capsys.readouterr().err
    beats = [ln for ln in err.splitlines() if "still running" in ln]
    if progress is False:
        assert beats == []
    else:
        assert any("setting up" in ln for ln in beats), err


def test_status_names_each_step_and_the_end_never_a_step_past_the_last():
    """After the last step the run writes figures: the line must not say 'step 21/20'."""
    from types import SimpleNamespace

    from porefsi.case.run import _doing

    assert _doing([]).startswith("step 0, setting up")
    box = [SimpleNamespace(run=SimpleNamespace(step_index=3, n_steps=20))]
    assert _doing(box) == "step 4/20"
    box[0].run.step_index = 20
    assert _doing(box) == "all 20 steps done, writing outputs and figures"
