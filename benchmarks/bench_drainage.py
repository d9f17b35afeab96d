"""Benchmark: dynamic drainage to breakthrough at the paper's rate on ~250, 10k and 100k pores.

Run: ``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_drainage.py [--sizes 250 10000 100000]``.
Prints events, solves, skipped solves and seconds per network (timings on a shared machine are noisy).
Synthetic 3-D cubic lattices with Berea-like sizes (spacing 40 um, pore radii 6-14 um).
"""

import argparse
import time

import numpy as np

from porefsi.flow.drainage import PAPER_RATE, simulate_drainage
from porefsi.flow.fluids import Fluids
from porefsi.network.lattice import lattice_network

SHAPES = {250: (10, 5, 5), 10000: (25, 20, 20), 100000: (50, 45, 45)}


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument("--sizes", type=int, nargs="+", default=[250, 10000])
    args = p.parse_args(argv)
    fl = Fluids()
    for n in args.sizes:
        shape = SHAPES[n]
        net = lattice_network(shape, 4e-5, np.random.default_rng(7))
        ca = fl.capillary_number(PAPER_RATE, float(np.prod(net.extent[1:])))
        # warm the numba caches outside the timing
        simulate_drainage(lattice_network((3, 3, 2), 4e-5, np.random.default_rng(0)), fl, t_end=1e3,
                          stop_at_breakthrough=True)
        t0 = time.perf_counter()
        res = simulate_drainage(net, fl, rate=PAPER_RATE, t_end=1e12, stop_at_breakthrough=True)
        dt = time.perf_counter() - t0
        c = res.counters
        print(f"{net.n_pores:>7d} pores  Ca={ca:.2e}  events={c['n_events']:>7d}  fills={c['n_fills']:>6d}  "
              f"solves={c['n_solves']:>6d}  skipped={c['n_skipped_solves']:>6d}  "
              f"t_bt={res.breakthrough_time:.4g} s  Sw_bt={res.breakthrough_sw:.3f}  "
              f"mass_err={res.mass_balance_error:.1e}  seconds={dt:.2f}", flush=True)


if __name__ == "__main__":
    main()
