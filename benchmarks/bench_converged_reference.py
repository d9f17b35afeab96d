"""Converged voxel Stokes permeability of the network-accuracy images, measured on the whole image.

The network accuracy benchmark (``bench_network_accuracy.py``) compares the network with the
*converged* voxel reference: the exact Stokes flow through the image's voxel staircase. This
measures it on the whole image, not on crops: each image of ``bench_network_accuracy.images`` is
solved along an axis refined ``f`` times (``voxel_permeability(refine=f)``, every voxel split
into f^3), with the same options as the stored native references of
``network_accuracy_reference.json`` (``wall="ghost"``, pressure drop, 2 buffer layers, lateral
walls), and the levels are Richardson-extrapolated (:func:`porefsi.stokes.richardson`).

Three subcommands:

* ``solve``: one solve per call (so that the peak RSS is the solve's own), one JSON line appended
  to ``--out``: k, iterations, CPU and wall seconds, peak RSS and the resident memory before the
  solve, the memory estimates (``refined_memory_bytes`` and the solver's own), load, date, commit.
  ``--crop o0,o1,o2,side`` solves a cubic block instead (the sampled defect correction's blocks).
  Run heavy ones under the shared lock, one at a time::

      flock /work/wt/heavy.lock python benchmarks/bench_converged_reference.py solve \
          --image spheres_p35 --axis x --refine 2 --out runs.jsonl [--crop 32,32,32,56]

* ``summarise RUNS.jsonl ... --reference network_accuracy_reference.json [--write FILE]``: per image
  and axis, the whole image's levels Richardson-extrapolated (two levels: at the order observed on
  the image's blocks solved at f = 1, 2, 3; the stored native k is level 1 if not re-solved), else
  the stored native k times the pooled block factor (blocks at f = 1, 2, the order from those at
  f = 1, 2, 3 along this axis or along x); ``--write`` stores a ``converged`` entry per image.
* ``berea-blocks RUNS.jsonl [--write FILE]``: the ghost factor of the 400^3 Berea from its sampled
  blocks' channel sequences (``results_stokes_sampled_berea400.jsonl``) and their ghost natives,
  applied to the stored natives of the 200^3 crops.

Reproduce the 2026-12-02 values from the stored solves::

    python benchmarks/bench_converged_reference.py summarise benchmarks/results_converged_reference.jsonl \
        --reference benchmarks/network_accuracy_reference.json
    python benchmarks/bench_converged_reference.py berea-blocks benchmarks/results_converged_reference.jsonl
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_network_accuracy import images  # noqa: E402

from porefsi.image.voxel_image import VoxelImage, axis_index  # noqa: E402
from porefsi.stokes import voxel_permeability  # noqa: E402
from porefsi.stokes._refine_grid import refined_memory_bytes  # noqa: E402
from porefsi.stokes.refine import richardson  # noqa: E402


def _load() -> str:
    return " ".join(open("/proc/loadavg").read().split()[:3])


def _status(key: str) -> int:
    """A ``/proc/self/status`` memory field (VmRSS, VmHWM), bytes; 0 if unknown."""
    try:
        for line in open("/proc/self/status", encoding="ascii"):
            if line.startswith(key + ":"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


def _commit() -> str:
    try:
        return subprocess.run(
            ["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=True
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "?"


def _image(name: str, data: str | None, crop: str | None):
    for n, pore, vs, _ in images(data if name.startswith("berea") else None):
        if n == name:
            if crop:
                o0, o1, o2, b = (int(v) for v in crop.split(","))
                pore = pore[o0 : o0 + b, o1 : o1 + b, o2 : o2 + b]
            return pore, vs
    raise SystemExit(f"unknown image {name!r}; see bench_network_accuracy.images")


def run_solve(a) -> dict:
    """One solve, appended to ``a.out`` as a JSON line."""
    pore, vs = _image(a.image, a.data, a.crop)
    img = VoxelImage(pore.astype(np.uint8), voxel_size=vs)
    ax = axis_index(a.axis)
    estimate = refined_memory_bytes(img.shape, int(np.count_nonzero(img.pore)), a.refine, ax, 2)
    load0 = _load()
    rss_before = _status("VmRSS")
    t0, c0 = time.perf_counter(), time.process_time()
    r = voxel_permeability(img, a.axis, wall=a.wall, refine=a.refine, rtol=a.rtol)
    row = {
        "image": a.image,
        "crop": a.crop,
        "axis": a.axis,
        "refine": a.refine,
        "wall": a.wall,
        "rtol": a.rtol,
        "k_mD": r.k_mD,
        "iterations": r.iterations,
        "flux_spread": r.flux_spread,
        "converged": r.converged,
        "n_unknowns": int(r.n_unknowns),
        "cpu_s": time.process_time() - c0,
        "wall_s": time.perf_counter() - t0,
        "peak_rss_bytes": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024,
        "rss_before_bytes": rss_before,
        "estimate_refined_bytes": int(estimate),
        "estimate_solver_bytes": int(r.memory_bytes),
        "n_pore": int(np.count_nonzero(img.pore)),
        "shape": list(img.shape),
        "load_start": load0,
        "load_end": _load(),
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "commit": _commit(),
    }
    with open(a.out, "a", encoding="utf-8") as fh:
        fh.write(json.dumps(row) + "\n")
    print(json.dumps(row), flush=True)
    return row


def _rows(paths) -> list:
    return [json.loads(s) for p in paths for s in Path(p).read_text().splitlines() if s.strip()]


def pooled_blocks(rows: list, name: str, axis: str, fallback_order: float | None = None) -> dict | None:
    """Pooled block sequence of image ``name`` along ``axis``: S_f = sum of the blocks' k at f = 1, 2.

    The pooled ratio is the dissipation-weighted mean of the block factors (porefsi.stokes.sampled,
    module notes). The order is observed on the blocks also solved at f = 3 (their pooled sums of
    levels 1, 2, 3; ``fallback_order`` if none along this axis); every block solved at f = 1 and 2
    enters the factor at that order.
    """
    blocks = {}
    for r in rows:
        if r["image"] == name and r["axis"] == axis and r.get("crop"):
            blocks.setdefault(r["crop"], {})[r["refine"]] = r
    two = {c: b for c, b in blocks.items() if {1, 2} <= set(b)}
    three = {c: b for c, b in two.items() if 3 in b}
    if not two or not (three or fallback_order):
        return None
    if three:
        s3 = [sum(b[f]["k_mD"] for b in three.values()) for f in (1, 2, 3)]
        e3 = richardson([1, 2, 3], s3)
        order, observed, trusted, f3 = e3.order, e3.observed_order, e3.order_observed, e3.value / s3[0]
    else:
        order, observed, trusted, f3 = fallback_order, float("nan"), True, float("nan")
    sums = [sum(b[f]["k_mD"] for b in two.values()) for f in (1, 2)]
    e = richardson([1, 2], sums, order=order)
    per = {c: [round(b[f]["k_mD"], 1) for f in sorted(b)] for c, b in two.items()}
    return {
        "blocks": per,
        "sums_mD": sums,
        "order_observed": observed,
        "order": order,
        "order_source": "observed on these blocks" if three else "observed along x",
        "trusted": trusted,
        "factor": e.value / sums[0],
        "factor_3_levels": f3,
        "cpu_s": round(sum(r["cpu_s"] for b in two.values() for r in b.values()), 1),
        "loads": sorted({r["load_start"].split()[0] for b in two.values() for r in b.values()}),
    }


def converged_axis(
    rows: list, name: str, axis: str, native: float | None, order: float | None, fallback_order: float | None = None
) -> dict | None:
    """Converged k of the whole image along ``axis``: Richardson of its own levels, or native x block factor.

    ``native``: the stored native k (mD), used as level 1 when no f = 1 solve is in ``rows``.
    """
    seq = sorted(
        (r["refine"], r["k_mD"], r["cpu_s"], r["load_start"].split()[0], r["date"])
        for r in rows
        if r["image"] == name and r["axis"] == axis and not r.get("crop")
    )
    if seq and seq[0][0] != 1 and native:
        seq.insert(0, (1, native, float("nan"), "stored", ""))
    blocks = pooled_blocks(rows, name, axis, fallback_order)
    if len(seq) >= 2:
        levels, ks = [s[0] for s in seq], [s[1] for s in seq]
        e = richardson(levels, ks, order=None if len(seq) >= 3 else order)
        out = {
            "k_mD": e.value,
            "method": "whole-image refinement, Richardson",
            "levels": levels,
            "k_levels_mD": ks,
            "order": e.order,
            "order_source": "observed"
            if len(seq) >= 3
            else ("observed on the image's refined blocks" if order else "assumed"),
            "gci_mD": e.uncertainty,
            "cpu_s": [round(s[2], 1) for s in seq],
            "load": [s[3] for s in seq],
            "date": seq[-1][4][:10],
        }
        f = levels[-1] / levels[-2]
        out["k_p1_mD"] = ks[-1] + (ks[-1] - ks[-2]) / (f - 1)
        out["k_p2_mD"] = ks[-1] + (ks[-1] - ks[-2]) / (f**2 - 1)
    elif blocks and (native or seq):
        k1 = seq[0][1] if seq else native
        out = {
            "k_mD": blocks["factor"] * k1,
            "method": "sampled defect correction: native whole-image k x pooled block factor",
            "levels": [1, 2, 3],
            "native_mD": k1,
            "order": blocks["order"],
            "order_source": blocks["order_source"] if blocks["trusted"] else "assumed",
            "cpu_s": blocks["cpu_s"],
            "load": blocks["loads"],
        }
    else:
        return None
    if blocks:
        out["blocks"] = blocks
    return out


def run_summarise(a) -> dict:
    rows = _rows(a.runs)
    refs = json.loads(Path(a.reference).read_text()) if a.reference else {}
    out = {}
    for name in sorted({r["image"] for r in rows}):
        if name == "berea_400" or (a.only and name not in a.only.split(",")):
            continue
        per = {}
        bx = pooled_blocks(rows, name, "x")
        for ax in "xyz":
            order = a.order
            b = pooled_blocks(rows, name, ax, bx["order"] if bx else None)
            if b:
                print(
                    f"{name} {ax} blocks: {b['blocks']}, order {b['order']:.2f} ({b['order_source']}), "
                    f"factor {b['factor']:.3f} (blocks with 3 levels alone: {b['factor_3_levels']:.3f})"
                )
            if order is None and (b or bx):
                order = (b or bx)["order"]
            c = converged_axis(rows, name, ax, refs.get(name, {}).get(ax), order, bx["order"] if bx else None)
            if c is None:
                continue
            if (
                ax != "x"
                and c["method"].startswith("sampled")
                and per.get("x", {}).get("method", "").startswith("whole")
                and refs.get(name, {}).get(ax)
            ):
                # the whole image refined along x beats blocks along this axis: its factor, the blocks kept as
                # the isotropy check (their factor along this axis against theirs along x)
                fx = per["x"]["k_mD"] / refs[name]["x"]
                c = {
                    "k_mD": fx * refs[name][ax],
                    "method": "stored native x the whole image's x-axis factor (this "
                    "axis refined on blocks only, kept as the isotropy check)",
                    "native_mD": refs[name][ax],
                    "factor": fx,
                    "order": per["x"]["order"],
                    "order_source": per["x"]["order_source"],
                    "blocks_check": c.get("blocks"),
                }
            per[ax] = c
        for ax in "xyz":  # an axis without its own levels or blocks: the x factor, flagged
            if ax not in per and "x" in per and refs.get(name, {}).get(ax) and refs.get(name, {}).get("x"):
                fx = per["x"]["k_mD"] / refs[name]["x"]
                per[ax] = {
                    "k_mD": fx * refs[name][ax],
                    "method": "stored native x the x axis's factor (this axis not refined)",
                    "native_mD": refs[name][ax],
                    "factor": fx,
                    "order": per["x"]["order"],
                    "order_source": per["x"]["order_source"],
                }
        for ax, c in per.items():
            native = refs.get(name, {}).get(ax)
            fac = c["k_mD"] / native if native else float("nan")
            print(
                f"{name} {ax}: {c['method']}: k_inf {c['k_mD']:.1f} mD, k_inf/k_1(stored) {fac:.3f}, order "
                f"{c['order']:.2f} ({c['order_source']})"
                + (f"; p=1 {c['k_p1_mD']:.1f}, p=2 {c['k_p2_mD']:.1f}" if "k_p1_mD" in c else "")
            )
        if per:
            out[name] = per
    if a.write:
        ref = json.loads(Path(a.write).read_text())
        conv = ref.setdefault("converged", {})
        for name, per in out.items():
            conv[name] = {ax: round(v["k_mD"], 1) for ax, v in per.items()} | {"_detail": per}
        tmp = Path(a.write).with_suffix(".tmp")
        tmp.write_text(json.dumps(ref, indent=1))
        tmp.replace(a.write)
    return out


def run_berea_blocks(a) -> dict:
    """Ghost-closure factor k_inf/k_1 of the 400^3 Berea from its sampled blocks (per axis, pooled).

    k_inf of each block: its channel-closure sequence f = 1, 2, 3 (``--channel``, the sampled defect
    correction's blocks, docs/stokes.md) extrapolated at ``--order`` (1.5: the observed orders of
    the channel sequences on rock are a pre-asymptotic artefact, docs/stokes.md "Which order"); the
    converged flow does not depend on the closure (0.7-2.0 % on three Berea crops). k_1: the same
    block solved natively with the ghost closure (``solve --image berea_400 --crop ...``), the
    closure of the stored native references. Pooled: sum k_inf / sum k_1 per axis.
    """
    ch = {(r["axis"], tuple(r["origin"])): r["k_mD"] for r in _rows([a.channel])}
    gh = {
        (r["axis"], tuple(int(v) for v in r["crop"].split(",")[:3])): r["k_mD"]
        for r in _rows(a.runs)
        if r["image"] == "berea_400" and r.get("crop") and r["refine"] == 1 and r["wall"] == "ghost"
    }
    out = {}
    for ax in "xyz":
        keys = sorted(k for k in ch if k[0] == ax and k in gh)
        if not keys:
            continue
        kinf = {k: richardson([1, 2, 3], ch[k], order=a.order).value for k in keys}
        f = sum(kinf.values()) / sum(gh[k] for k in keys)
        out[ax] = {"factor": f, "blocks": {str(k[1]): [round(gh[k], 1), round(kinf[k], 1)] for k in keys}}
        print(
            f"berea_400 {ax}: {len(keys)} blocks, pooled ghost k_inf/k_1 {f:.3f} (per block "
            + ", ".join(f"{kinf[k] / gh[k]:.3f}" for k in keys)
            + ")"
        )
    if a.write:
        ref = json.loads(Path(a.write).read_text())
        conv = ref.setdefault("converged", {})
        loads = sorted({r["load_start"].split()[0] for r in _rows(a.runs) if r["image"] == "berea_400"})
        for crop in ("a", "b", "c", "d"):
            name = f"berea_200_{crop}"
            conv[name] = {ax: round(out[ax]["factor"] * ref[name][ax], 1) for ax in out} | {
                "_detail": {
                    "method": "stored native (ghost) x the pooled ghost factor k_inf/k_1 of the 400^3 Berea's sampled "
                    "40^3 blocks (5 per axis; k_inf from their channel sequences f = 1, 2, 3 at order "
                    f"{a.order}); not measured on the crop itself",
                    "factor": {ax: round(v["factor"], 4) for ax, v in out.items()},
                    "blocks_ghost_k1_and_k_inf_mD": {ax: v["blocks"] for ax, v in out.items()},
                    "levels": [1, 2, 3],
                    "order": a.order,
                    "date": "2026-12-02",
                    "load": loads,
                    "cpu_s": "blocks 33-126 s each for the three channel levels (docs/stokes.md), "
                    "1-2 s per ghost native",
                }
            }
        tmp = Path(a.write).with_suffix(".tmp")
        tmp.write_text(json.dumps(ref, indent=1))
        tmp.replace(a.write)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("solve")
    s.add_argument("--image", required=True)
    s.add_argument("--axis", default="x")
    s.add_argument("--refine", type=int, default=1)
    s.add_argument("--crop", help="o0,o1,o2,side: a cubic crop instead of the whole image")
    s.add_argument("--wall", default="ghost", help="ghost: as the stored native references")
    s.add_argument("--rtol", type=float, default=1e-6)
    s.add_argument("--data", default=os.environ.get("POREFSI_DATA"))
    s.add_argument("--out", required=True)
    m = sub.add_parser("summarise")
    m.add_argument("runs", nargs="+", help="JSON-lines files of solve")
    m.add_argument(
        "--order",
        type=float,
        default=None,
        help="order for two-level whole-image sequences (default: observed on the image's blocks)",
    )
    m.add_argument("--reference", help="native references (network_accuracy_reference.json), for block factors")
    m.add_argument("--write", help="store a 'converged' entry per image in this reference JSON")
    m.add_argument("--only", help="comma-separated image names")
    g = sub.add_parser("berea-blocks")
    g.add_argument("runs", nargs="+", help="JSON-lines files of solve (the blocks' ghost native solves)")
    g.add_argument("--channel", default=str(ROOT / "benchmarks" / "results_stokes_sampled_berea400.jsonl"))
    g.add_argument("--order", type=float, default=1.5)
    g.add_argument("--write", help="store converged entries of the 200^3 crops in this reference JSON")
    a = ap.parse_args(argv)
    return {"solve": run_solve, "summarise": run_summarise, "berea-blocks": run_berea_blocks}[a.cmd](a)


if __name__ == "__main__":
    main()
