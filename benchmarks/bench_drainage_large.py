"""Benchmark: the adaptive drainage scheme on networks the exact scheme cannot finish (issue 16 targets).

Run: ``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_drainage_large.py --net lat100k [--ca paper]
[--opt tie_tolerance=1 local_solves=0] [--max-cpu 900] [--image ../shared/data/berea_icl_400.npz]
[--cache DIR] [--checkpoint FILE [--resume]]``.

Networks as in ``bench_drainage_scheme.py`` (``lat10k`` ... ``lat100k``, ``berea``, ``berea2`` =
the 400³ Berea network mirror-tiled 2x2x2, extracted once and cached). Drains with the adaptive
scheme to breakthrough (``simulate_drainage(..., stop_at_breakthrough=True)``), printing a
progress line every 30 s (fills, certified fills, solves, Sw, CPU seconds), then one result
line: CPU seconds, counters, breakthrough time and Sw, and, as the only truth that runs at this
size, the quasi-static limit on the same network (invasion percolation with trapping): Spearman
rank correlation of the invasion order, pores invaded by one only, the breakthrough volume.
With ``--checkpoint FILE`` a run that reaches ``--max-cpu`` / ``--max-wall`` is saved there (the
drainage checkpoint, bit for bit the uninterrupted run) and ``--resume`` continues it in a later
process (a later turn of the heavy-job lock); the CPU and wall seconds of every segment, the
checkpoint reads and writes and the resumed base factorisations included, are summed in
``FILE.cpu.json`` and reported as the run's. Where the exact scheme can run,
``bench_drainage_scheme.py`` compares against it. The load
average is printed (a shared 2-core machine: CPU seconds are the comparable number).
"""

import argparse
import json
import os
import pathlib
import resource
import signal
import sys
import time

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))  # run from a checkout
sys.path.insert(0, str(HERE))

from bench_drainage_scheme import _network, _number, _rate  # noqa: E402
from drainage_compare import _load  # noqa: E402

from porefsi.flow.drainage import DrainageOptions, RunControl, simulate_drainage  # noqa: E402
from porefsi.flow.fluids import Fluids  # noqa: E402
from porefsi.flow.invasion import invasion_percolation  # noqa: E402


def _spearman(a, b):
    from scipy.stats import spearmanr

    return float(spearmanr(a, b)[0])


def main(argv=None):
    """Drain one network with the adaptive scheme to breakthrough; print progress and the result."""
    p = argparse.ArgumentParser()
    p.add_argument("--net", default="lat100k")
    p.add_argument("--ca", default="paper")
    p.add_argument("--opt", nargs="*", default=[], metavar="KEY=VALUE")
    p.add_argument("--scheme", default="adaptive", choices=("adaptive", "exact"),
                   help="exact: the reference scheme on the same network (resumable with --checkpoint)")
    p.add_argument("--max-cpu", type=float, default=900.0, help="stop (no result) after this many CPU seconds")
    p.add_argument("--max-wall", type=float, default=1440.0,
                   help="stop (no result) after this many wall seconds (the shared heavy-job lock's turn)")
    p.add_argument("--profile", help="write a cProfile of the drainage run to this file")
    p.add_argument("--image")
    p.add_argument("--cache", default=str(HERE / "_drainage_scheme"))
    p.add_argument("--json", help="append the result record to this file (JSON lines)")
    p.add_argument("--save", help="write the run's invasion times and history to this .npz")
    p.add_argument("--checkpoint", help="save the run here when it stops at a limit (and every 300 s of wall)")
    p.add_argument("--resume", action="store_true", help="continue the run saved at --checkpoint")
    p.add_argument("--report-every", type=float, default=30.0, help="wall seconds between progress lines")
    args = p.parse_args(argv)
    cache = pathlib.Path(args.cache)
    cache.mkdir(parents=True, exist_ok=True)
    fl = Fluids()
    net = _network(args.net, args.image, cache)
    rate = _rate(args.ca, net, fl)
    ca = fl.capillary_number(rate, float(np.prod(net.extent[1:])))
    opts = {k: _number(v) for k, v in (o.split("=", 1) for o in args.opt)}
    options = DrainageOptions(rate=rate, t_end=1e12, scheme=args.scheme, skip_solves="on", **opts)
    from porefsi.network.lattice import lattice_network

    warm = lattice_network((8, 6, 6), 4e-5, np.random.default_rng(0))  # numba caches outside the timing
    for solver in ("split", "lowrank", "selinv"):
        simulate_drainage(warm, fl, options, stop_at_breakthrough=True, solver=solver)
    side = pathlib.Path(str(args.checkpoint) + ".cpu.json") if args.checkpoint else None
    prev = json.loads(side.read_text()) if args.resume and side.is_file() else dict(cpu_s=0.0, wall_s=0.0, segments=0)
    c0, w0 = time.process_time() - prev["cpu_s"], time.perf_counter() - prev["wall_s"]
    w_seg = time.perf_counter()

    class TooLongError(Exception):
        pass

    def report(sim, seconds):
        c = sim.counters
        cpu = time.process_time() - c0
        print(f"  t = {sim.t:.4g} s fills {c['n_fills']} certified {c.get('n_certified_fills', 0)} "
              f"solves {c['n_solves']} local {c.get('n_local_solves', 0)} setups {c['n_solver_setups']} "
              f"cpu {cpu:.0f} s load {_load()}", flush=True)
        if cpu > args.max_cpu or time.perf_counter() - w_seg > args.max_wall:
            if args.checkpoint:  # the run's own deferred interrupt: saved after this event, then stopped
                os.kill(os.getpid(), signal.SIGINT)
                return
            raise TooLongError(f"stopped after {cpu:.0f} CPU s, {time.perf_counter() - w0:.0f} wall s")

    print(f"{args.net}: {net.n_pores} pores, Ca = {ca:.2e}, options {opts}, load {_load()}", flush=True)
    prof = None
    if args.profile:
        import cProfile

        prof = cProfile.Profile()
        prof.enable()
    ckpt = dict(checkpoint=args.checkpoint, checkpoint_every=300.0, resume=args.resume) if args.checkpoint else {}
    try:
        res = simulate_drainage(net, fl, options, stop_at_breakthrough=True,
                                run=RunControl(report=report, report_every=args.report_every, **ckpt))
    except TooLongError as exc:
        print(f"{args.net}: NOT FINISHED ({exc})", flush=True)
        return 1
    except KeyboardInterrupt as exc:
        seg = dict(cpu_s=time.process_time() - c0, wall_s=time.perf_counter() - w0, segments=prev["segments"] + 1)
        side.write_text(json.dumps(seg))
        print(f"{args.net}: PAUSED after {seg['cpu_s']:.0f} CPU s, {seg['wall_s']:.0f} wall s in {seg['segments']} "
              f"segment(s) ({exc}); continue with --resume", flush=True)
        return 2
    finally:
        if prof is not None:
            prof.disable()
            prof.dump_stats(args.profile)
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    ip = invasion_percolation(net, fl, axis="x", stop_at_breakthrough=True)
    t = res.invasion_time
    a, b = np.isfinite(t), ip.pore_sequence >= 0
    both = a & b
    rec = dict(net=args.net, n_pores=net.n_pores, ca=ca, scheme=args.scheme, options=opts,
               cpu_s=cpu, wall_s=wall, counters=res.counters,
               segments=prev["segments"] + 1, peak_rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
               breakthrough_time=res.breakthrough_time, breakthrough_sw=res.breakthrough_sw,
               spearman_vs_ip=_spearman(t[both], ip.pore_sequence[both]), only_dpn=int((a & ~b).sum()),
               only_ip=int((b & ~a).sum()), ip_breakthrough_fills=int(ip.breakthrough_step + 1),
               ip_breakthrough_time=float(net.pore_volume[b].sum() / rate), load=_load())
    c = res.counters
    print(f"{args.net}: cpu {cpu:.1f} s, wall {wall:.1f} s, {c['n_fills']} fills ({c.get('n_certified_fills', 0)} "
          f"certified), {c['n_solves']} solves ({c['n_solves'] / max(c['n_fills'], 1):.2f} per fill), "
          f"{c['n_solver_setups']} factorisations, breakthrough t = {res.breakthrough_time:.5g} s Sw = "
          f"{res.breakthrough_sw:.4f}; invasion percolation: t_bt = {rec['ip_breakthrough_time']:.5g} s, Spearman "
          f"{rec['spearman_vs_ip']:.4f}, only DPN / IP {rec['only_dpn']} / {rec['only_ip']}; load {_load()}",
          flush=True)
    if args.save:
        h = res.history
        np.savez_compressed(args.save, invasion_time=t, hist_t=h["time_s"], hist_sw=h["sw"],
                            hist_pin=h["inlet_pressure_pa"], ip_sequence=ip.pore_sequence)
    if args.json:
        with open(args.json, "a") as f:
            f.write(json.dumps(rec) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
