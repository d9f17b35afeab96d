"""Benchmark: where the adaptive drainage's quasi-static batches stop being certified (docs/stability.md).

Run: ``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_drainage_certificate.py [--shape 12 10 10]
[--seeds 7 8] [--ca 1e-8 1e-7 1e-6 1e-5 1e-4] [--tie 0 0.1 1]``.

For each lattice seed, capillary number and ``tie_tolerance`` (``local_solves=0``: the
approximation measured is the tolerance's alone), drains with the exact and the adaptive scheme
to breakthrough and prints the fraction of fills certified without a solve, the CPU ratio, and
the adaptive run's differences from the exact one: Spearman rank correlation of the invasion
times, pores invaded by one run only, relative difference of the breakthrough time and of the
saturation at breakthrough. Rows failing the 1 % target (breakthrough time or Sw) are marked
FAIL. CPU seconds; the load average is printed.
"""

import argparse
import pathlib
import sys
import time

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))  # run from a checkout

from porefsi.flow.drainage import DrainageOptions, simulate_drainage  # noqa: E402
from porefsi.flow.fluids import Fluids  # noqa: E402
from porefsi.network.lattice import lattice_network  # noqa: E402


def _run(net, fl, **kw):
    c = time.process_time()
    res = simulate_drainage(net, fl, DrainageOptions(t_end=1e15, skip_solves="on", **kw), stop_at_breakthrough=True)
    return res, time.process_time() - c


def main(argv=None):
    """Print one line per (seed, Ca, tie_tolerance)."""
    from scipy.stats import spearmanr

    p = argparse.ArgumentParser()
    p.add_argument("--shape", nargs=3, type=int, default=[12, 10, 10])
    p.add_argument("--seeds", nargs="+", type=int, default=[7, 8])
    p.add_argument("--ca", nargs="+", type=float, default=[1e-8, 1e-7, 1e-6, 1e-5, 1e-4])
    p.add_argument("--tie", nargs="+", type=float, default=[0.0, 0.1, 1.0])
    args = p.parse_args(argv)
    fl = Fluids()
    print(f"load {open('/proc/loadavg').read().split()[:3]}")
    for seed in args.seeds:
        net = lattice_network(tuple(args.shape), 4e-5, np.random.default_rng(seed))
        area = float(net.extent[1] * net.extent[2])
        for ca in args.ca:
            rate = ca * fl.sigma * area / fl.mu_n
            ref, c_ref = _run(net, fl, rate=rate)
            for tie in args.tie:
                res, c = _run(net, fl, rate=rate, scheme="adaptive", local_solves=0, tie_tolerance=tie)
                k = res.counters
                ta, tb = ref.invasion_time, res.invasion_time
                both = np.isfinite(ta) & np.isfinite(tb)
                bt = abs(res.breakthrough_time / ref.breakthrough_time - 1)
                sw = abs(res.breakthrough_sw / ref.breakthrough_sw - 1)
                flag = "FAIL" if max(bt, sw) > 0.01 else "ok"
                print(f"seed {seed} {net.n_pores} pores Ca {ca:.0e} tie {tie:<4g}: certified "
                      f"{k['n_certified_fills'] / max(k['n_fills'], 1):5.1%} of {k['n_fills']} fills, solves "
                      f"{k['n_solves']} (exact {ref.counters['n_solves']}), cpu {c_ref:.2f}/{c:.2f} s = "
                      f"{c_ref / c:.2f}x, spearman {spearmanr(ta[both], tb[both])[0]:.5f}, only "
                      f"{int(np.isfinite(ta).sum() - both.sum())}/{int(np.isfinite(tb).sum() - both.sum())}, "
                      f"t_bt rel {bt:.1e}, Sw_bt rel {sw:.1e} {flag}", flush=True)


if __name__ == "__main__":
    main()
