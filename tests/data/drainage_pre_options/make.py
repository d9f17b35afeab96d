"""Made the files of this folder with porefsi at 90ac23b (the last commit before DrainageOptions/RunControl).

Run: ``python make.py OUT_DIR OLD_CHECKOUT`` with OLD_CHECKOUT from ``git archive 90ac23b porefsi | tar -x -C
DIR``. Provenance of the checkpoints that tests/test_drainage_checkpoint_legacy.py reads (not a test itself):
``exact.npz`` and ``adaptive.npz`` are checkpoints of runs killed after 40 and 8 steps, ``reference.json`` the
uninterrupted runs' results (with the keyword arguments of the call).
"""

import importlib
import json
import sys

import numpy as np


class KilledError(Exception):
    """The process killed right after a checkpoint."""


def _killer(after):
    calls = []

    def progress(sim, seconds):
        calls.append(seconds)
        if len(calls) == after:
            raise KilledError

    return progress


def _finite(values):
    return [None if not np.isfinite(v) else float(v) for v in values]


def main(out, old):
    sys.path.insert(0, old)
    porefsi = importlib.import_module("porefsi")
    assert porefsi.__file__.startswith(old), porefsi.__file__
    simulate_drainage = importlib.import_module("porefsi.flow.drainage").simulate_drainage
    fl = importlib.import_module("porefsi.flow.fluids").Fluids()
    net = importlib.import_module("porefsi.network.lattice").lattice_network((6, 5, 4), 1e-4, np.random.default_rng(3))
    rate = 1e-6 * fl.sigma * float(net.extent[1] * net.extent[2]) / fl.mu_n
    t_end = float(1.5 * simulate_drainage(net, fl, rate=rate, t_end=1e9, stop_at_breakthrough=True).breakthrough_time)
    summary = {}
    for name, kill, kw in (("exact", 40, dict(solver="direct")),
                           ("adaptive", 8, dict(solver="direct", scheme="adaptive"))):
        kw = dict(rate=rate, t_end=t_end, times=[0.5 * t_end], **kw)
        ref = simulate_drainage(net, fl, **kw)
        try:
            simulate_drainage(net, fl, checkpoint=f"{out}/{name}.npz", checkpoint_every=1e-12,
                              progress=_killer(kill), **kw)
        except KilledError:
            pass
        h = ref.history
        summary[name] = dict(kwargs=kw, counters={k: int(v) for k, v in ref.counters.items()},
                             breakthrough_time=ref.breakthrough_time, final_sw=ref.final.sw,
                             invasion_time=_finite(ref.invasion_time), inlet_pressure=_finite(h["inlet_pressure_pa"]),
                             sw=h["sw"].tolist(), time=h["time_s"].tolist())
    with open(f"{out}/reference.json", "w") as f:
        json.dump(summary, f)


if __name__ == "__main__":
    main(*sys.argv[1:3])
