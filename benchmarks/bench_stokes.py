"""Benchmark: the voxel Stokes permeability (porefsi.stokes) on rock, with time and memory.

Every solve runs in its own subprocess, one after the other, so each peak memory (``ru_maxrss``)
is its own. Reported per solve: k (mD), MINRES iterations, flow-rate spread, wall and CPU seconds
(``time.process_time`` of the child), peak resident memory, the solver's own memory estimate, and
the load average when it finished (the machine the numbers in ``docs/stokes.md`` came from was
shared: wall times are noisy, CPU times less so).

Cases (``--cases``; default ``sample``):

* ``sample``: the built-in 120^3 Berea along x, y, z (target: <= 2 minutes each);
* ``centre``: the 200^3 centre crop [100:300]^3 of the 400^3 Berea along x, y, z (target: <= 15
  minutes and <= 8 GiB each);
* ``full``: the whole 400^3 Berea along x, y, z at its own resolution (~6 GiB and ~25 CPU minutes
  each here);
* ``crops``: the eight 200^3 octants of the 400^3 Berea along x, y, z, and their Cardwell-Parsons
  combination (below) per axis;
* ``coarse``: the whole 400^3 Berea coarsened 2x and 4x (``porefsi.image.downsample``), x, y, z;
* ``upsample``: each voxel -> 2^3 on a 60^3 corner of the built-in sample (discretisation check);
  ``upsample400``: each voxel -> 2^3 on 100^3 crops of the 400^3 Berea;
* ``buffer``: the built-in sample along x with 0, 1, 2, 4, 8 buffer layers, and periodic + mirror.

The 400^3 Berea (``--image``, default ``../shared/data/berea_icl_400.npz`` next to the checkout or
its parent) carries a published voxel-scale simulation: kx, ky, kz = 1360, 1304, 1193 mD, mean
1286 mD (which array axis is the published x is uncertain: compare the three-axis mean). For
octants (``crops``, ``octants120``) with permeabilities k_ijk (i along the flow), the Cardwell &
Parsons (1945) bounds are

    lower = mean over the 4 columns of the harmonic mean of their 2 octants in series,
    upper = harmonic mean over the 2 layers of the arithmetic mean of their 4 octants,

which bracket the arrangement of the octants' own k; cutting adds no-slip walls at the cut faces
(on the 120^3 sample the combination is 21-33 % below the whole along x and y: use ``full``).

Usage::

    python benchmarks/bench_stokes.py --quick            # built-in sample along x only
    python benchmarks/bench_stokes.py --cases sample crops coarse --out results.jsonl
    python benchmarks/bench_stokes.py --cases full --progress --out full.jsonl   # ~25 CPU min per axis
    python benchmarks/bench_stokes.py --cases full --axes x --wall channel --out full_channel.jsonl
    python benchmarks/bench_stokes.py --summarise full.jsonl \
        --case-reference cases/speed_accuracy/reference/berea400_voxel.json
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
CANDIDATES = [REPO.parent / "shared" / "data" / "berea_icl_400.npz",
              REPO.parent.parent / "shared" / "data" / "berea_icl_400.npz"]
PUBLISHED = {"x": 1360.0, "y": 1304.0, "z": 1193.0}


def _load(spec: dict):
    from porefsi.image import VoxelImage, downsample, load_sample

    if spec["image"] == "sample":
        img = load_sample()
    else:
        with np.load(spec["image"]) as d:
            img = VoxelImage(d["image"], float(d["voxel_size_m"]))
    if "crop" in spec:
        (a, b), (c, d_), (e, f) = spec["crop"]
        img = VoxelImage(img.phases[a:b, c:d_, e:f].copy(), img.voxel_size)
    if spec.get("upsample", 1) > 1:
        m = spec["upsample"]
        ph = img.phases.repeat(m, 0).repeat(m, 1).repeat(m, 2)
        img = VoxelImage(ph, img.voxel_size / m)
    if spec.get("coarsen", 1) > 1:
        img = downsample(img, spec["coarsen"])
    return img


def child(spec: dict) -> dict:
    """Run one solve (in this process) and return its record."""
    from porefsi.stokes import voxel_permeability

    img = _load(spec)
    t0, c0 = time.perf_counter(), time.process_time()
    r = voxel_permeability(img, spec["axis"], **spec.get("kw", {}))
    head = subprocess.run(["git", "rev-parse", "--short=12", "HEAD"], cwd=REPO, capture_output=True, text=True)
    return {
        **spec, "k_mD": r.k_mD, "iterations": r.iterations, "flux_spread": r.flux_spread, "converged": r.converged,
        "commit": head.stdout.strip() or None, "date_utc": time.strftime("%Y-%m-%d %H:%M", time.gmtime()),
        "residual": r.residual, "wall_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0,
        "peak_rss_GiB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20,
        "estimate_GiB": r.memory_bytes / 2**30, "n_unknowns": r.n_unknowns, "shape": list(img.shape),
        "voxel_size_m": img.voxel_size, "porosity": img.porosity, "connected_porosity": r.connected_porosity,
        "load": open("/proc/loadavg").read().split()[:3],
    }


def run(spec: dict, progress: bool = False) -> dict:
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "PYTHONPATH": str(REPO)}
    args = [sys.executable, __file__, "--child", json.dumps(spec)] + (["--progress"] if progress else [])
    out = subprocess.run(args, stdout=subprocess.PIPE, stderr=None if progress else subprocess.PIPE, text=True,
                         env=env)
    if out.returncode != 0:
        err = (out.stderr or "").strip()
        return {**spec, "error": err.splitlines()[-1] if err else f"failed (exit {out.returncode})"}
    return json.loads(out.stdout.strip().splitlines()[-1])


def case_reference(records, path: Path) -> dict:
    """Write the full-resolution solves (case ``full``) as ``cases/speed_accuracy/reference/berea400_voxel.json``.

    Per axis: k, iterations, convergence, times, peak memory and load; CPU and wall summed over the
    axes solved. An axis not solved is left out (the case then leaves the point out).
    """
    rows = {r["axis"]: r for r in records if r.get("case") == "full" and "k_mD" in r}
    walls = {r.get("kw", {}).get("wall", "default") for r in rows.values()}
    if len(walls) > 1:
        raise SystemExit(f"the 'full' records mix wall closures {sorted(walls)}: pass one closure's file")
    if not rows:
        raise SystemExit("no solved 'full' records to write")
    some = next(iter(rows.values()))
    ref = {"source": "benchmarks/bench_stokes.py --cases full", "image": some["image"],
           "commit": some.get("commit"), "date_utc": some.get("date_utc"),
           "voxel_size_m": some["voxel_size_m"], "shape": some["shape"], "wall": walls.pop(),
           "k_mD": {a: r["k_mD"] for a, r in rows.items()}, "iterations": {a: r["iterations"] for a, r in rows.items()},
           "residual": {a: r["residual"] for a, r in rows.items()},
           "flux_spread": {a: r["flux_spread"] for a, r in rows.items()},
           "converged": all(r.get("converged", True) for r in rows.values()),
           "cpu_s": sum(r["cpu_s"] for r in rows.values()), "wall_s": sum(r["wall_s"] for r in rows.values()),
           "cpu_s_per_axis": {a: r["cpu_s"] for a, r in rows.items()},
           "wall_s_per_axis": {a: r["wall_s"] for a, r in rows.items()},
           "peak_rss_GiB": {a: r["peak_rss_GiB"] for a, r in rows.items()},
           "load": {a: r["load"] for a, r in rows.items()}}
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(ref, indent=1) + "\n")
    return ref


def octants(n: int):
    h = n // 2
    for i in range(2):
        for j in range(2):
            for k in range(2):
                yield (i, j, k), [[i * h, (i + 1) * h], [j * h, (j + 1) * h], [k * h, (k + 1) * h]]


def cardwell_parsons(k: dict, axis: int) -> tuple[float, float]:
    """Lower and upper bound of a 2x2x2 block arrangement's permeability along ``axis``."""
    def idx(layer, a, b):
        o = [0, 0, 0]
        others = [d for d in range(3) if d != axis]
        o[axis], o[others[0]], o[others[1]] = layer, a, b
        return tuple(o)
    cols = [(a, b) for a in range(2) for b in range(2)]
    lower = np.mean([2 / (1 / k[idx(0, a, b)] + 1 / k[idx(1, a, b)]) for a, b in cols])
    layers = [np.mean([k[idx(L, a, b)] for a, b in cols]) for L in range(2)]
    upper = 2 / (1 / layers[0] + 1 / layers[1])
    return float(lower), float(upper)


def specs(cases, image, axes="xyz", wall=None):
    """Every solve of ``cases``; ``axes`` filters the flow axes, ``wall`` sets the closure of each."""
    for spec in _specs(cases, image):
        if spec["axis"] not in axes:
            continue
        if wall is not None:
            spec = {**spec, "kw": {**spec.get("kw", {}), "wall": wall}}
        yield spec


def _specs(cases, image):
    for case in cases:
        if case == "sample":
            for ax in "xyz":
                yield {"case": case, "image": "sample", "axis": ax}
        elif case == "quick":
            yield {"case": case, "image": "sample", "axis": "x"}
        elif case == "buffer":
            for b in (0, 1, 2, 4, 8):
                yield {"case": case, "image": "sample", "axis": "x", "kw": {"buffer": b}}
            yield {"case": case, "image": "sample", "axis": "x", "kw": {"boundary": "periodic", "mirror": True}}
            yield {"case": case, "image": "sample", "axis": "x", "kw": {"lateral": "periodic"}}
        elif case == "upsample":
            for m in (1, 2):
                for ax in "xyz":
                    yield {"case": case, "image": "sample", "crop": [[0, 60]] * 3, "upsample": m, "axis": ax}
        elif case == "octants120":
            for ax in "xyz":
                for o, box in octants(120):
                    yield {"case": case, "image": "sample", "crop": box, "octant": o, "axis": ax}
        elif case == "crops" and image:
            for ax in "xyz":
                for o, box in octants(400):
                    yield {"case": case, "image": str(image), "crop": box, "octant": o, "axis": ax}
        elif case == "centre" and image:
            for ax in "xyz":
                yield {"case": case, "image": str(image), "crop": [[100, 300]] * 3, "axis": ax}
        elif case == "full" and image:
            for ax in "xyz":
                yield {"case": case, "image": str(image), "axis": ax}
        elif case == "upsample400" and image:
            for lo in (100, 200, 0):
                for m in (1, 2):
                    for ax in "xyz":
                        yield {"case": case, "image": str(image), "crop": [[lo, lo + 100]] * 3, "upsample": m,
                               "axis": ax}
        elif case == "coarse" and image:
            for f in (4, 2):
                for ax in "xyz":
                    yield {"case": case, "image": str(image), "coarsen": f, "axis": ax}


def summarise(records):
    for case in ("octants120", "crops"):
        rows = [r for r in records if r.get("case") == case and "k_mD" in r]
        for ax in "xyz":
            k = {tuple(r["octant"]): r["k_mD"] for r in rows if r["axis"] == ax}
            if len(k) == 8:
                lo, hi = cardwell_parsons(k, "xyz".index(ax))
                extra = f", published {PUBLISHED[ax]:.0f}" if case == "crops" else ""
                print(f"{case} {ax}: octants {min(k.values()):.0f}-{max(k.values()):.0f} mD, "
                      f"Cardwell-Parsons [{lo:.0f}, {hi:.0f}] mean {(lo + hi) / 2:.0f} mD{extra}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--child", help=argparse.SUPPRESS)
    ap.add_argument("--quick", action="store_true", help="built-in sample along x only")
    ap.add_argument("--cases", nargs="+", default=["sample"],
                    choices=["sample", "quick", "buffer", "upsample", "upsample400", "octants120", "crops", "centre",
                             "full", "coarse"])
    ap.add_argument("--image", default=None, help="the 400^3 Berea npz (default: ../shared/data/berea_icl_400.npz)")
    ap.add_argument("--out", default=None, help="append one JSON line per solve to this file")
    ap.add_argument("--axes", default="xyz", help="flow axes to solve (e.g. x: one heavy solve at a time)")
    ap.add_argument("--wall", default=None, choices=["ghost", "channel"],
                    help="tangential wall closure of every solve (default: voxel_permeability's)")
    ap.add_argument("--summarise", default=None, metavar="JSONL", help="only summarise an earlier --out file")
    ap.add_argument("--progress", action="store_true",
                    help="print each solve's set-up time and every 25th MINRES residual (stderr)")
    ap.add_argument("--case-reference", default=None, metavar="JSON",
                    help="with --summarise: write its 'full' records as the speed_accuracy case's cached "
                         "full-resolution point (cases/speed_accuracy/reference/berea400_voxel.json)")
    args = ap.parse_args(argv)
    if args.child:
        if args.progress:
            logging.basicConfig(level=logging.INFO, stream=sys.stderr, format="%(asctime)s %(message)s")
        print(json.dumps(child(json.loads(args.child))))
        return 0
    if args.summarise:
        records = [json.loads(line) for line in open(args.summarise)]
        summarise(records)
        if args.case_reference:
            print(json.dumps(case_reference(records, Path(args.case_reference)), indent=1))
        return 0
    image = Path(args.image) if args.image else next((p for p in CANDIDATES if p.exists()), None)
    cases = ["quick"] if args.quick else args.cases
    if image is None and any(c in ("crops", "coarse", "centre", "full", "upsample400") for c in cases):
        print("400^3 Berea not found (--image): skipping the cases that need it")
    records = []
    for spec in specs(cases, image, args.axes, args.wall):
        rec = run(spec, args.progress)
        records.append(rec)
        if args.out:
            with open(args.out, "a") as fh:
                fh.write(json.dumps(rec) + "\n")
        if "error" in rec:
            print(f"{spec}: ERROR {rec['error']}", flush=True)
            continue
        tag = {k: rec[k] for k in ("case", "axis", "crop", "coarsen", "upsample", "kw") if k in rec}
        print(f"{json.dumps(tag)}: k {rec['k_mD']:.1f} mD, {rec['iterations']} its, spread {rec['flux_spread']:.1e}, "
              f"{rec['wall_s']:.0f} s wall, {rec['cpu_s']:.0f} s CPU, peak {rec['peak_rss_GiB']:.2f} GiB "
              f"(estimate {rec['estimate_GiB']:.2f}), load {' '.join(rec['load'])}", flush=True)
    summarise(records)
    return 0


if __name__ == "__main__":
    sys.exit(main())
