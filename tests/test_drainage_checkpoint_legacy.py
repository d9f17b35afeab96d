"""Drainage checkpoints written before DrainageOptions/RunControl (porefsi 90ac23b; files in tests/data).

Truth: the uninterrupted runs of that version (``reference.json``, made with the checkpoints by
``tests/data/drainage_pre_options/make.py``). A coupled run's checkpoint stores its simulator in
this layout, and :func:`simulator_from_state` reads it: the resumed run must finish as that version
would have. A standalone drainage checkpoint of that version carries a run fingerprint of the old
keyword API, which this version cannot recompute: resuming it is refused with a one-line error.
"""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from porefsi.errors import InputError
from porefsi.flow import _drainage_checkpoint as ckpt
from porefsi.flow.drainage import simulate_drainage
from porefsi.flow.fluids import Fluids
from porefsi.io.results import load_checkpoint
from porefsi.network.lattice import lattice_network

DATA = Path(__file__).parent / "data" / "drainage_pre_options"


def _reference(name):
    return json.loads((DATA / "reference.json").read_text())[name]


def _floats(values):
    return np.array([np.nan if v is None else v for v in values], dtype=float)


@pytest.mark.parametrize("name", ["exact", "adaptive"])
def test_state_written_before_drainage_options_resumes_to_that_versions_result(name):
    ref = _reference(name)
    arrays, meta = load_checkpoint(DATA / f"{name}.npz")
    assert "sim.options" not in meta and meta["format"] == 2  # the old layout: engine options only
    sim = ckpt.simulator_from_state("sim", arrays, meta)
    e = sim._engine
    assert 0 < e.n_events < ref["counters"]["n_events"]  # killed half-way
    if name == "adaptive":  # that version's adaptive scheme: the rigorous certificate, 8 local solves
        assert sim.options.tie_tolerance == 0.0 and sim.options.local_solves == 8
        assert e.margin < 1.0
    t_end = ref["kwargs"]["t_end"]
    for k in range(int(meta["k"]), 2):  # the snapshot time (a state read: a solve), then the end, as the old driver
        t = [0.5 * t_end, t_end][k]
        while e.t < t:
            e.step(t)
        assert sim.state.t == t
    # Same events in the same order (counters, invaded set, record count); the floats (times too) to
    # round-off: the reference was made with other numpy/scipy/numba builds, whose sums and
    # sparse solves may differ in the last bits (seen: 2e-14 relative on a fresh install).
    same = {"rtol": 1e-11, "atol": 0.0}
    t_inv = sim.invasion_time()
    np.testing.assert_array_equal(np.isnan(t_inv), np.isnan(_floats(ref["invasion_time"])))
    np.testing.assert_allclose(t_inv, _floats(ref["invasion_time"]), **same)
    h = sim.history()
    np.testing.assert_allclose(h["time_s"], ref["time"], **same)
    np.testing.assert_allclose(h["sw"], ref["sw"], **same)
    np.testing.assert_allclose(h["inlet_pressure_pa"], _floats(ref["inlet_pressure"]), **same)
    assert {k: sim.counters[k] for k in ref["counters"]} == ref["counters"]
    assert sim.breakthrough_time == pytest.approx(ref["breakthrough_time"], rel=1e-11)


def test_standalone_checkpoint_written_before_drainage_options_is_refused_in_one_line(tmp_path):
    ref = _reference("exact")
    path = tmp_path / "exact.npz"
    shutil.copy(DATA / "exact.npz", path)
    net = lattice_network((6, 5, 4), 1e-4, np.random.default_rng(3))
    with pytest.raises(InputError) as info:
        simulate_drainage(net, Fluids(), checkpoint=path, resume=True, **ref["kwargs"])
    msg = str(info.value)
    assert "\n" not in msg and str(path) in msg
    assert "before the drainage options" in msg and "without --resume" in msg
