"""Benchmark: solution verification of the voxel Stokes permeability by grid refinement.

Every voxel is split into f^3 (``voxel_permeability(refine=f)``), k is solved at each level and
Richardson-extrapolated (``porefsi.stokes.richardson``): the observed order p, the converged k_inf
and the discretisation error of the unrefined solve, (k_1 - k_inf) / k_inf. Printed as one table
row per image and axis; ``--json`` writes every number.

Cases (``--cases``; default ``closed,synthetic,sample``):

* ``closed``: voxelised tubes (R = 1.5, 2, 3, 5 voxels, axis on a voxel corner) against the exact
  flow through their staircase section (tests/reference/stokes_ref.prism_flow_rate: the truth the
  refinement converges to), square ducts (w = 3, 4) against White's series, plates (n = 3);
* ``synthetic``: a Gaussian blob medium (porosity 0.30) and an overlapping-sphere grain pack
  (porosity 0.35, grain radius 6 voxels), ``--n``^3, along x;
* ``sample``: ``--n``^3 corner crops (0,0,0) and (60,60,60) of the built-in 120^3 Berea, along x;
* ``berea``: ``--n``^3 crops of the 400^3 Berea (``--image``) at ``--positions``, along ``--axes``.

Run from the repository root (the closed forms come from tests/reference)::

    python benchmarks/bench_stokes_refine.py --levels 1,2,3 --n 40
    python benchmarks/bench_stokes_refine.py --cases berea --image ../shared/data/berea_icl_400.npz \\
        --positions "160,160,160;40,40,40" --axes x,y,z

Cost grows as f^3 (unknowns) times ~f (iterations): a 40^3 crop takes ~1, 12 and ~45 CPU seconds
at f = 1, 2, 3. Keep ``ulimit -v`` on: the memory check refuses a refinement that would not fit.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from porefsi.errors import NetworkError  # noqa: E402
from porefsi.image import VoxelImage, load_sample, read_image  # noqa: E402
from porefsi.stokes import richardson, voxel_permeability  # noqa: E402
from porefsi.units import MILLIDARCY  # noqa: E402

BEREA_VOXEL = 5.345e-6
#: The tangential wall closure of every solve (``--wall``; default: voxel_permeability's).
WALL = [None]


def _load() -> str:
    return open("/proc/loadavg").read().split()[0] if Path("/proc/loadavg").exists() else "?"


def _levels_of(image, axis, levels, **kw) -> tuple[list, list, float]:
    """k (mD) at each level, and the CPU seconds of all of them."""
    ks, done, c0 = [], [], time.process_time()
    rtol = kw.pop("rtol", 1e-7)
    if WALL[0] is not None:
        kw.setdefault("wall", WALL[0])
    for f in levels:
        r = voxel_permeability(image, axis, refine=f, rtol=rtol, maxiter=8000, **kw)
        ks.append(r.k_mD)
        done.append(f)
    return done, ks, time.process_time() - c0


def _row(name, axis, levels, ks, truth_mD=None, cpu=0.0) -> dict:
    row = {"case": name, "axis": axis, "levels": levels, "k_mD": ks, "cpu_s": round(cpu, 1), "load": _load()}
    if len(levels) >= 2:
        e = richardson(levels, ks)
        row.update(order=e.order, order_observed=e.order_observed, k_inf_mD=e.value, gci_mD=e.uncertainty,
                   native_error=e.error_at(levels[0]) if levels[0] == 1 else float("nan"))
    if truth_mD is not None:
        row["truth_mD"] = truth_mD
        row["native_vs_truth"] = ks[0] / truth_mD - 1
        if "k_inf_mD" in row:
            row["extrapolated_vs_truth"] = row["k_inf_mD"] / truth_mD - 1
    return row


def closed_forms(levels) -> list[dict]:
    from tests.reference.stokes_ref import (
        disk,
        plates_flow_rate_per_width,
        prism_flow_rate,
        rectangular_duct_flow_rate,
    )

    rows = []
    for R in (1.5, 2, 3, 5):
        sec = disk(R)
        a = np.repeat(sec[None], 2, axis=0).astype(np.uint8)
        truth = prism_flow_rate(sec, refine=(8, 16)) / sec.size * 1e-12 / MILLIDARCY  # voxel 1 um
        lv, ks, cpu = _levels_of(VoxelImage(a, 1e-6), "x", levels, boundary="periodic", rtol=1e-9)
        rows.append(_row(f"tube R={R} (staircase)", "x", lv, ks, truth, cpu))
    for w in (3, 4):
        a = np.zeros((2, w + 2, w + 2), np.uint8)
        a[:, 1:-1, 1:-1] = 1
        truth = rectangular_duct_flow_rate(w / 2, w / 2) / a[0].size * 1e-12 / MILLIDARCY
        lv, ks, cpu = _levels_of(VoxelImage(a, 1e-6), "x", levels, boundary="periodic", rtol=1e-9)
        rows.append(_row(f"square duct w={w}", "x", lv, ks, truth, cpu))
    a = np.zeros((2, 5, 3), np.uint8)
    a[:, 1:-1, :] = 1
    truth = plates_flow_rate_per_width(3) / 5 * 1e-12 / MILLIDARCY
    lv, ks, cpu = _levels_of(VoxelImage(a, 1e-6), "x", levels, boundary="periodic", lateral="periodic",
                             rtol=1e-10)
    rows.append(_row("plates n=3", "x", lv, ks, truth, cpu))
    return rows


def crops(name, phases, vs, n, positions, axes, levels) -> list[dict]:
    rows = []
    for lo in positions:
        sub = phases[lo[0]:lo[0] + n, lo[1]:lo[1] + n, lo[2]:lo[2] + n]
        img = VoxelImage(np.ascontiguousarray(sub), vs)
        for axis in axes:
            tag = f"{name} {n}^3 @({','.join(map(str, lo))}) phi={img.porosity:.3f}"
            try:
                lv, ks, cpu = _levels_of(img, axis, levels)
            except NetworkError:
                rows.append({"case": tag, "axis": axis, "error": "does not percolate"})
                continue
            rows.append(_row(tag, axis, lv, ks, None, cpu))
            print(_fmt(rows[-1]), flush=True)
    return rows


def synthetic(n, levels) -> list[dict]:
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from bench_network_accuracy import blobs, sphere_pack

    rows = []
    for name, pore in (("blobs p=0.30", blobs(n=n, porosity=0.30)),
                       ("sphere pack p=0.35 r=6", sphere_pack(n=n, porosity=0.35, r_mean=6.0))):
        rows += crops(name, pore.astype(np.uint8), BEREA_VOXEL, n, [(0, 0, 0)], ["x"], levels)
    return rows


def _fmt(r: dict) -> str:
    if "error" in r:
        return f"{r['case']:<46} {r['axis']}  {r['error']}"
    ks = " ".join(f"{k:9.2f}" for k in r["k_mD"])
    s = f"{r['case']:<46} {r['axis']}  f={r['levels']}  k={ks}"
    if "order" in r:
        s += (f"  p={r['order']:.2f}{'' if r['order_observed'] else '(assumed)'}  k_inf={r['k_inf_mD']:.2f}"
              f" +-{r['gci_mD']:.2f}  native {100 * r['native_error']:+.1f}%")
    if "truth_mD" in r:
        s += f"  vs truth: native {100 * r['native_vs_truth']:+.1f}%"
        if "extrapolated_vs_truth" in r:
            s += f", extrapolated {100 * r['extrapolated_vs_truth']:+.2f}%"
    return s + f"  [{r['cpu_s']} CPU s, load {r['load']}]"


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", default="closed,synthetic,sample")
    ap.add_argument("--levels", default="1,2,3", help="refinement factors, increasing")
    ap.add_argument("--n", type=int, default=40, help="crop edge (voxels) for rock and synthetic cases")
    ap.add_argument("--image", default=str(ROOT.parent / "shared" / "data" / "berea_icl_400.npz"))
    ap.add_argument("--positions", default="160,160,160;40,40,40;300,60,200;100,300,300")
    ap.add_argument("--axes", default="x")
    ap.add_argument("--wall", default=None, choices=["channel", "ghost"], help="wall closure of every solve")
    ap.add_argument("--json", default=None, help="write every row to this file")
    args = ap.parse_args(argv)
    WALL[0] = args.wall
    levels = [int(v) for v in args.levels.split(",")]
    cases = args.cases.split(",")
    rows = []
    if "closed" in cases:
        rows += closed_forms(levels)
        for r in rows:
            print(_fmt(r), flush=True)
    if "synthetic" in cases:
        rows += synthetic(args.n, levels)
    if "sample" in cases:
        s = load_sample()
        rows += crops("sample120", s.phases, s.voxel_size, args.n, [(0, 0, 0), (60, 60, 60)], ["x"], levels)
    if "berea" in cases:
        img = read_image(args.image)
        pos = [tuple(int(v) for v in p.split(",")) for p in args.positions.split(";")]
        rows += crops("berea400", img.phases, img.voxel_size, args.n, pos, args.axes.split(","), levels)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return rows


if __name__ == "__main__":
    main()
