"""Sweeps on Dask: the speed-accuracy study serial vs a 2-worker LocalCluster, and the overhead per member.

1. The members of ``cases/speed_accuracy/sweep.toml`` (22, or the first ``--members N``) run
   ``--serial`` (one after the other in this process) and on a LocalCluster of ``--workers``
   processes; both into fresh folders. Printed: wall time of each, the ratio, the sum of the
   members' own CPU and wall seconds, and whether the two runs' numbers agree bit for bit.
2. Overhead: (a) Dask alone, ``N`` no-op tasks through ``client.submit`` + ``as_completed`` on a
   running LocalCluster (per task); (b) porefsi's bookkeeping, a serial sweep of tiny members:
   sweep wall minus the members' own wall seconds, per member (CSV rewrite, member.json, the
   completed-member check); (c) the cluster's start-up (LocalCluster + Client).

The machine is shared: ``/proc/loadavg`` is printed before and after each timing.

Usage: ``python benchmarks/bench_sweep.py [--members N] [--workers 2] [--out DIR] [--skip-study]``.
"""

from __future__ import annotations

import argparse
import csv
import os
import tempfile
import time
from pathlib import Path

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

from porefsi.sweep import Cluster, load_sweep, run_sweep, sweep_from_dict  # noqa: E402
from porefsi.sweep.spec import Sweep  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
STUDY = ROOT / "cases" / "speed_accuracy" / "sweep.toml"
#: Summary entries that are timings (differ between two runs of the same member).
TIMING = ("wall_seconds", "wall_seconds_this_process", "cpu_seconds", "cpu_seconds_this_process",
          "seconds_by_stage", "cpu_seconds_by_stage", "reextraction", "figures", "resume_command")


def load() -> str:
    with open("/proc/loadavg") as fh:
        return " ".join(fh.read().split()[:3])


def subset(sweep: Sweep, n: int | None) -> Sweep:
    if n is None or n >= len(sweep.members):
        return sweep
    import dataclasses

    return dataclasses.replace(sweep, members=sweep.members[:n])


def timed_sweep(sweep: Sweep, out: Path, cluster: Cluster) -> dict:
    la0, t0 = load(), time.perf_counter()
    res = run_sweep(sweep, out, cluster, progress=False, figures=False)
    wall = time.perf_counter() - t0
    ok = [r for r in res.records if r["status"] == "completed"]
    return {"wall": wall, "load_before": la0, "load_after": load(), "n_ok": len(ok), "n": len(res.records),
            "member_wall": sum(r["summary"]["wall_seconds"] for r in ok),
            "member_cpu": sum(r["summary"]["cpu_seconds"] for r in ok),
            "numbers": {r["name"]: {k: v for k, v in r["summary"].items() if k not in TIMING} for r in ok}}


def study(args, root: Path) -> None:
    sweep = subset(load_sweep(STUDY), args.members)
    print(f"== speed_accuracy sweep: {len(sweep.members)} of 22 members (t_end 10 s, figures and VTK off)")
    ser = timed_sweep(sweep, root / "serial", Cluster(serial=True))
    print(f"serial:       wall {ser['wall']:7.1f} s  (members: wall {ser['member_wall']:.1f} s, CPU "
          f"{ser['member_cpu']:.1f} s; load {ser['load_before']} -> {ser['load_after']})", flush=True)
    dk = timed_sweep(sweep, root / "dask", Cluster(n_workers=args.workers))
    print(f"LocalCluster: wall {dk['wall']:7.1f} s  ({args.workers} workers; members: wall {dk['member_wall']:.1f} s, "
          f"CPU {dk['member_cpu']:.1f} s; load {dk['load_before']} -> {dk['load_after']})")
    print(f"speed-up serial / LocalCluster = {ser['wall'] / dk['wall']:.2f} (ideal {args.workers} on an idle machine "
          f"with {args.workers} free cores); members completed {ser['n_ok']}/{ser['n']} and {dk['n_ok']}/{dk['n']}; "
          f"numbers bit-identical: {ser['numbers'] == dk['numbers']}")


def dask_overhead(n_tasks: int, workers: int) -> None:
    from distributed import Client, LocalCluster, as_completed

    la0, t0 = load(), time.perf_counter()
    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None) as cl, \
            Client(cl) as client:
        t_up = time.perf_counter() - t0
        client.submit(dict, a=1, pure=False).result()  # warm
        t1 = time.perf_counter()
        futs = [client.submit(dict, i=i, pure=False) for i in range(n_tasks)]
        for f in as_completed(futs):
            f.result()
        t_tasks = time.perf_counter() - t1
    print(f"LocalCluster start-up ({workers} workers) + Client: {t_up:.2f} s; {n_tasks} no-op tasks: "
          f"{1e3 * t_tasks / n_tasks:.2f} ms per task (load {la0} -> {load()})")


def bookkeeping(n: int, root: Path) -> None:
    d = {"base": {"smoke": True, "solid": {"coarsen": 12}, "drainage": {"t_end": 1.0},
                  "output": {"vtk": False, "figures": False, "snapshot_times": []}},
         "vary": {"drainage.rate": [1.25e-13 * (1 + i / n) for i in range(n)]}}
    sweep = sweep_from_dict(d)
    r = timed_sweep(sweep, root / "tiny", Cluster(serial=True))
    assert r["n_ok"] == n, "tiny members failed"
    per = (r["wall"] - r["member_wall"]) / n
    print(f"porefsi bookkeeping, serial sweep of {n} tiny members: sweep wall {r['wall']:.2f} s, members' own "
          f"{r['member_wall']:.2f} s -> {1e3 * per:.1f} ms per member (load {r['load_before']} -> {r['load_after']})")
    with open(root / "tiny" / "sweep.csv", newline="") as fh:
        assert len(list(csv.DictReader(fh))) == n


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--members", type=int, default=None, help="only the first N members of the study (default all)")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--out", type=Path, default=None, help="where the sweeps run (default: a temporary folder)")
    p.add_argument("--skip-study", action="store_true", help="only the overhead measurements")
    p.add_argument("--quick", action="store_true", help="the first 3 members only")
    args, _ = p.parse_known_args(argv)  # run_all.py passes every script the same arguments
    if args.quick and args.members is None:
        args.members = 3
    tmp = None
    if args.out is None:
        tmp = tempfile.TemporaryDirectory(prefix="porefsi-bench-sweep-")
        root = Path(tmp.name)
    else:
        root = args.out
    print(f"cpus available: {len(os.sched_getaffinity(0))}; load {load()}")
    dask_overhead(200, args.workers)
    bookkeeping(20, root)
    if not args.skip_study:
        study(args, root)
    if tmp is not None:
        tmp.cleanup()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
