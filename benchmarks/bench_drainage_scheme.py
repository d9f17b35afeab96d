"""Benchmark: the adaptive drainage scheme against the exact one (speed and accuracy, same run).

Run: ``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_drainage_scheme.py [--nets lat10k lat30k]
[--ca paper 1e-6 1e-5] [--cache DIR] [--max-cpu S] [--image PATH]``.

Networks: ``lat10k``, ``lat30k``, ``lat100k`` (the cubic lattices of ``bench_drainage.py``:
spacing 40 um, seed 7) and, with ``--image`` (e.g. ``../shared/data/berea_icl_400.npz``),
``berea`` (its network) and ``berea2`` (mirror-tiled 2x2x2, ~62k pores). Rates: ``paper``
(1.25e-13 m^3/s) or a capillary number ``Ca = mu_n Q / (A sigma)`` on the inlet face.

Each (network, rate) runs both schemes to 1.25 x breakthrough with pressure samples
(:mod:`drainage_compare`) and prints one line: CPU seconds of each, the ratio exact / adaptive,
and the adaptive run's differences from the exact one (Spearman rank correlation of the invasion
times, pores invaded by one run only, max relative difference of the saturation history, of the
inlet pressure at the samples (median / max / 5-sample running mean), relative difference of
the breakthrough time). Records go to ``--cache`` (default ``benchmarks/_drainage_scheme``), so a
long exact reference runs once; ``--max-cpu`` stops a run that has not reached its end (an
incomplete exact run is compared up to where it stopped). The load average is printed with each
line (timings on a shared machine are noisy; CPU time is used).
"""

import argparse
import pathlib
import sys

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))  # run from a checkout
sys.path.insert(0, str(HERE))

from drainage_compare import _load, compare, git_commit, load_run, run_sampled, save_run  # noqa: E402

from porefsi.flow.drainage import PAPER_RATE  # noqa: E402
from porefsi.flow.fluids import Fluids  # noqa: E402
from porefsi.network.lattice import lattice_network  # noqa: E402

LATTICES = {"lat1k": (12, 10, 10), "lat10k": (25, 20, 20), "lat30k": (40, 28, 27), "lat100k": (50, 45, 45)}


def _network(name, image, cache):
    if name in LATTICES:
        return lattice_network(LATTICES[name], 4e-5, np.random.default_rng(7))
    tile = {"berea": (1, 1, 1), "berea2": (2, 2, 2)}[name]
    path = cache / f"{name}_network.npz"
    from porefsi.network.network import Network

    if path.exists():
        with np.load(path) as z:
            return Network(**{k: (z[k] if z[k].shape != () else z[k].item()) for k in z.files})
    if image is None:
        raise SystemExit(f"network {name!r} needs --image")
    from bench_drainage import _rock_network

    net = _rock_network(image, tile)
    import dataclasses

    np.savez(path, **{f.name: getattr(net, f.name) for f in dataclasses.fields(net)
                      if getattr(net, f.name) is not None})
    return net


def _number(v: str):
    """An option value from the command line: int, else float, else the string (e.g. solver=lowrank)."""
    for kind in (int, float):
        try:
            return kind(v)
        except ValueError:
            pass
    return v


def _rate(spec, net, fl):
    if spec == "paper":
        return PAPER_RATE
    area = float(np.prod(net.extent[1:]))
    return float(spec) * fl.sigma * area / fl.mu_n


def main(argv=None):
    """Run the (network, rate) pairs and print one comparison line each."""
    p = argparse.ArgumentParser()
    p.add_argument("--nets", nargs="+", default=["lat10k"])
    p.add_argument("--ca", nargs="+", default=["paper"])
    p.add_argument("--cache", default=str(HERE / "_drainage_scheme"))
    p.add_argument("--max-cpu", type=float, default=np.inf)
    p.add_argument("--max-wall", type=float, default=np.inf, help="stop a run after this many wall seconds")
    p.add_argument("--samples", type=int, default=40, help="inlet-pressure samples to breakthrough (a solve each)")
    p.add_argument("--image")
    p.add_argument("--schemes", nargs="+", default=["exact", "adaptive"])
    p.add_argument("--fresh", action="store_true", help="recompute the adaptive runs even if cached")
    p.add_argument("--opt", nargs="*", default=[], metavar="KEY=VALUE",
                   help="adaptive options, e.g. tie_tolerance=0.01 local_solves=0 (numbers parsed)")
    args = p.parse_args(argv)
    opts = {k: _number(v) for k, v in (o.split("=", 1) for o in args.opt)}
    tag = "".join(f"_{k}{v}" for k, v in sorted(opts.items())).replace(".", "p")  # no dot: file suffixes
    cache = pathlib.Path(args.cache)
    cache.mkdir(parents=True, exist_ok=True)
    fl = Fluids()
    warm = lattice_network((6, 4, 4), 4e-5, np.random.default_rng(0))  # numba caches outside the timing
    for s in args.schemes:
        run_sampled(warm, fl, PAPER_RATE, s, samples=4)
    for name in args.nets:
        net = _network(name, args.image, cache)
        for spec in args.ca:
            rate = _rate(spec, net, fl)
            ca = fl.capillary_number(rate, float(np.prod(net.extent[1:])))
            recs = {}
            for s in args.schemes:
                path = cache / f"{name}_{spec}_{s}{tag if s != 'exact' else ''}"
                rec = load_run(path)
                if rec is None or (s != "exact" and args.fresh):
                    rec = run_sampled(net, fl, rate, s, samples=args.samples, max_cpu=args.max_cpu,
                                      max_wall=args.max_wall, **(opts if s != "exact" else {}))
                    save_run(path, rec, dict(net=name, n_pores=net.n_pores, ca=ca, commit=git_commit()))
                recs[s] = rec
                c = rec["counters"]
                label = s + (tag if s != "exact" else "")
                print(f"{name} ({net.n_pores} pores) Ca={ca:.2e} {label:>8s}: cpu {rec['cpu_s']:.1f} s "
                      f"{'' if rec['complete'] else '(STOPPED) '}events {c['n_events']} solves {c['n_solves']}"
                      + (f" certified {c['n_certified_fills']} local {c['n_local_solves']} global "
                         f"{c['n_global_solves']}" if "n_certified_fills" in c else "")
                      + (f" predicted {c['n_predicted_fills']} batches {c['n_predict_batches']} rollbacks "
                         f"{c['n_predict_rollbacks']}" if c.get("n_predict_batches") else "")
                      + f"  bt {rec['breakthrough_time']:.4g} s  load {rec['load_before']}", flush=True)
            if "exact" in recs and "adaptive" in recs:
                d = compare(recs["exact"], recs["adaptive"])
                print(f"  exact/adaptive cpu = {d['speedup_cpu']:.2f}x  spearman {d['spearman']:.5f}  "
                      f"only exact/adaptive {d['only_ref']}/{d['only_run']}  Sw max rel {d['sw_max_rel']:.2e}  "
                      f"Pin rel median {d['p_rel_median']:.1e} max {d['p_rel_max']:.1e} smoothed "
                      f"{d['p_smooth_rel_max']:.1e}  bt rel {d['bt_rel']:.1e}  load {_load()}", flush=True)


if __name__ == "__main__":
    main()
