"""Benchmark: the sampled defect correction of the voxel Stokes permeability (porefsi.stokes.sampled).

Two studies:

* ``blocks``: the block factors of one image along one axis, one JSON line per block appended to
  ``--out`` as it finishes (a rerun skips the blocks already there, so a long study can be split
  into jobs under ``--time-limit``), then ``--summarise`` pools them with a native k
  (``--native`` mD, or ``--native-json`` with a ``k_mD`` per axis, e.g.
  cases/speed_accuracy/reference/berea400_voxel.json: the 400^3 native solves, ~25 CPU-min each,
  are reused, not re-run)::

      flock /work/wt/heavy.lock python benchmarks/bench_stokes_sampled.py blocks \\
          --image ../shared/data/berea_icl_400.npz --axis x,y,z --out berea400_blocks.jsonl --time-limit 1400
      python benchmarks/bench_stokes_sampled.py summarise berea400_blocks.jsonl \\
          --native-json cases/speed_accuracy/reference/berea400_voxel.json

* ``validate``: on images whose whole-image refinement fits, the sampled estimate against the
  whole-image Richardson value at the same levels (a convergence check of the estimator, not an
  accuracy check)::

      python benchmarks/bench_stokes_sampled.py validate --cases blobs,spheres,berea,sample --levels 1,2

Prints the CPU seconds and the load average next to every number.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from porefsi.image import VoxelImage, load_sample, read_image  # noqa: E402
from porefsi.stokes import (  # noqa: E402
    extrapolated_permeability,
    richardson,
    sampled_permeability,
    voxel_permeability,
)
from porefsi.stokes.sampled import block_side, choose_blocks, pool_blocks  # noqa: E402

#: The shared data folder next to the checkout (or next to the worktrees' folder).
DATA = next((d / "shared" / "data" for d in ROOT.parents[:2] if (d / "shared" / "data").is_dir()),
            ROOT.parent / "shared" / "data")
DNS = {"x": 1360.0, "y": 1304.0, "z": 1193.0}
BEREA_VOXEL = 5.345e-6


def _load() -> str:
    return open("/proc/loadavg").read().split()[0] if Path("/proc/loadavg").exists() else "?"


def _levels(text: str) -> tuple:
    return tuple(int(v) for v in text.split(","))


def _done(out: Path) -> set:
    """(axis, origin, levels, side) of the blocks already in ``out``."""
    if not out.exists():
        return set()
    rows = [json.loads(line) for line in out.read_text().splitlines() if line.strip()]
    return {(r["axis"], tuple(r["origin"]), tuple(r["levels"]), r["side"]) for r in rows}


def run_blocks(args) -> None:
    """Solve the blocks of one image along ``args.axis`` (comma-separated axes are interleaved block by
    block), appending one JSON line per block and axis to ``args.out``; blocks already there are skipped."""
    image = read_image(args.image)
    levels = _levels(args.levels)
    axes = args.axis.split(",")
    plan = {}
    for axis in axes:
        side = args.block or block_side(image.shape, image.porosity, levels[-1], "xyz".index(axis), 2)
        plan[axis] = (side, choose_blocks(image.pore, "xyz".index(axis), args.blocks, side))
    out = Path(args.out)
    done = _done(out)
    if args.rank_by_k1:
        plan = {axis: (side, _rank_by_k1(out, axis, side, chosen)) for axis, (side, chosen) in plan.items()}
    t0, longest = time.perf_counter(), 0.0
    for i in range(args.blocks):
        for axis in axes:
            side, chosen = plan[axis]
            if i >= len(chosen) or (axis, tuple(chosen[i][0]), levels, side) in done:
                continue
            if args.time_limit and time.perf_counter() - t0 + longest > args.time_limit:
                print("time limit reached (the slowest block so far would not finish): rerun to continue", flush=True)
                return
            t_block = time.perf_counter()
            row = _solve_block(image, axis, chosen[i], side, levels, args.rtol)
            longest = max(longest, time.perf_counter() - t_block)
            row["image"] = str(args.image)
            with out.open("a") as fh:
                fh.write(json.dumps(row) + "\n")
            print(json.dumps(row), flush=True)


def _rank_by_k1(out: Path, axis: str, side: int, chosen: list) -> list:
    """``chosen`` sorted by the blocks' level-1 k in ``out`` (largest first: the blocks that carry the most
    flow, whose share of the pooled sums is largest); blocks without a level-1 row keep their order, last."""
    k1 = {}
    if out.exists():
        for line in out.read_text().splitlines():
            r = json.loads(line) if line.strip() else None
            if r and r["axis"] == axis and r["side"] == side and 1 in r["levels"]:
                k1[tuple(r["origin"])] = r["k_mD"][r["levels"].index(1)]
    return sorted(chosen, key=lambda c: -k1.get(tuple(c[0]), -1.0))


def _solve_block(image, axis, chosen, side, levels, rtol) -> dict:
    (o, phi), c0, ks, its = chosen, time.process_time(), [], []
    sub = VoxelImage(np.ascontiguousarray(image.phases[o[0]:o[0] + side, o[1]:o[1] + side, o[2]:o[2] + side]),
                     image.voxel_size)
    for f in levels:
        r = voxel_permeability(sub, axis, refine=f, rtol=rtol)
        ks.append(r.k_mD)
        its.append(r.iterations)
    return {"axis": axis, "origin": list(o), "side": side, "levels": list(levels), "connected_porosity": phi,
            "k_mD": ks, "iterations": its, "rtol": rtol, "cpu_s": round(time.process_time() - c0, 1),
            "load": _load(), "wall": r.info["wall"]}


def _merge(rows) -> dict:
    """Per axis: ``(side, levels, origins, k)`` with ``k`` (K, n_levels) in mD, NaN where a level was not
    solved on a block; rows of the same block (axis, origin, side) at different levels are merged."""
    out = {}
    for axis in sorted({r["axis"] for r in rows}):
        by_block = {}
        for r in rows:
            if r["axis"] == axis:
                ks = by_block.setdefault((tuple(r["origin"]), r["side"]), {})
                ks.update(zip(r["levels"], r["k_mD"], strict=True))
        sides = {side for _, side in by_block}
        if len(sides) > 1:
            raise SystemExit(f"axis {axis}: blocks of several sides {sorted(sides)}; summarise one side at a time")
        levels = sorted({f for ks in by_block.values() for f in ks})
        origins, k = [], []
        for (o, _), ks in by_block.items():
            run = [ks.get(f, math.nan) for f in levels]
            n = next((i for i, v in enumerate(run) if math.isnan(v)), len(run))  # leading run only
            origins.append(o)
            k.append(run[:n] + [math.nan] * (len(run) - n))
        out[axis] = (sides.pop(), levels, origins, np.array(k))
    return out


def _axis_summary(side, levels, origins, k, k1, order=None) -> dict:
    """One axis: pooled sums, observed orders, factor, corrected k and its band (mD)."""
    factor, se, gci, pooled, blocks = pool_blocks(origins, side, k, levels, order=order)
    full = np.all(np.isfinite(k), axis=1)
    s = {"blocks": len(origins), "complete": int(full.sum()), "side": side, "levels": levels,
         "S_solved_mD": [round(float(v), 1) for v in np.nansum(k, axis=0)],  # over the blocks solved there
         "solved_per_level": [int(v) for v in np.isfinite(k).sum(axis=0)],
         "S_complete_mD": [round(float(v), 1) for v in k[full].sum(axis=0)],
         "complete_share_of_S1": float(k[full, 0].sum() / k[:, 0].sum()),
         "factor": factor, "se": se, "gci": gci, "order": pooled.order, "order_observed": pooled.order_observed,
         "observed_order_last3_complete": pooled.observed_order,
         "block_factors": [round(b.factor, 4) for b in blocks], "block_k1_mD": [round(b.k_mD[0], 1) for b in blocks]}
    if len(levels) >= 3:
        three = np.all(np.isfinite(k[:, :3]), axis=1)
        s["observed_order_123_all"] = richardson(levels[:3], k[three, :3].sum(axis=0)).observed_order
    if k1:
        unc = math.hypot(2 * se, gci)
        s.update(native_mD=k1, k_mD=factor * k1, uncertainty_mD=unc * k1)
    if pooled.order_observed and not full.all():
        g = s["gci_if_every_block_had_the_order"] = _gci_shared(k, levels, pooled.order)
        if k1:
            s["uncertainty_if_every_block_had_the_order_mD"] = math.hypot(2 * se, g) * k1
    return s


def _gci_shared(k, levels, p) -> float:
    """The pooled GCI relative to S_1 with the safety factor of an observed order (1.25) on every group of
    blocks, also those whose order is borrowed (pool_blocks gives them 3): a sensitivity, not the estimate."""
    solved, gci = np.isfinite(k).sum(axis=1), 0.0
    for n in np.unique(solved):
        rows, (f_prev, f_last) = solved == n, levels[n - 2:n]
        gci += 1.25 * abs(np.sum(k[rows, n - 1] - k[rows, n - 2])) / ((f_last / f_prev) ** p - 1.0)
    return float(gci / k[:, 0].sum())


def summarise(args) -> dict:
    """Pool the blocks of ``args.path`` per axis and correct the native k (``--levels`` picks the levels used)."""
    rows = [json.loads(line) for line in Path(args.path).read_text().splitlines() if line.strip()]
    native = json.loads(Path(args.native_json).read_text())["k_mD"] if args.native_json else {}
    merged = _merge(rows)
    if args.levels:
        keep = _levels(args.levels)
        for axis, (side, levels, origins, k) in merged.items():
            cols = [levels.index(f) for f in keep if f in levels]
            merged[axis] = (side, [levels[c] for c in cols], origins, k[:, cols])
    summary = {}
    for axis, (side, levels, origins, k) in merged.items():
        s = _axis_summary(side, levels, origins, k, native.get(axis, args.native))
        s["cpu_s"] = sum(r["cpu_s"] for r in rows if r["axis"] == axis and set(r["levels"]) <= set(levels))
        if "k_mD" in s and axis in DNS and "berea" in rows[0]["image"]:
            s["vs_dns_axis"] = s["k_mD"] / DNS[axis]
        summary[axis] = s
        print(axis, json.dumps(s), flush=True)
    _mean(summary, "mean")
    _order_variants(merged, native, summary)
    return summary


def _mean(summary: dict, key: str, quiet: bool = False) -> None:
    """Three-axis mean of ``summary``'s corrected k against the DNS mean (the axes' bands averaged, not
    combined in quadrature: their GCIs are not independent)."""
    axes = [a for a in "xyz" if a in summary and "k_mD" in summary[a]]
    if len(axes) == 3:
        mean = sum(summary[a]["k_mD"] for a in axes) / 3
        unc = sum(summary[a]["uncertainty_mD"] for a in axes) / 3
        summary[key] = {"k_mD": mean, "uncertainty_mD": unc, "vs_dns_mean": mean / 1286.0,
                        "vs_dns_range": [(mean - unc) / 1286.0, (mean + unc) / 1286.0]}
        if not quiet:
            print(key, json.dumps(summary[key]), flush=True)


def _order_variants(merged, native, summary) -> None:
    """Every axis at the order observed on all axes' complete blocks pooled, and at p = 1, 1.5, 2."""
    complete = [k[np.all(np.isfinite(k), axis=1)] for _, _, _, k in merged.values()]
    levels = next(iter(merged.values()))[1]
    if len(levels) < 3 or any(lv != levels for _, lv, _, _ in merged.values()):
        return
    pooled_all = richardson(levels, np.sum([c.sum(axis=0) for c in complete], axis=0))
    for name, p in {"all-axes observed": pooled_all.observed_order, "p=1": 1.0, "p=1.5": 1.5, "p=2": 2.0}.items():
        if not (p > 0):
            continue
        var = {axis: _axis_summary(side, lv, o, k, native.get(axis), order=p)
               for axis, (side, lv, o, k) in merged.items()}
        _mean(var, "mean", quiet=True)
        out = {"order": round(p, 3), "factor, k_mD per axis": {a: (round(v["factor"], 4), round(v.get("k_mD", 0), 1))
                                                                for a, v in var.items() if a != "mean"},
               "mean_mD": var.get("mean", {}).get("k_mD"), "vs_dns_mean": var.get("mean", {}).get("vs_dns_mean")}
        summary[f"variant {name}"] = out
        print(f"variant {name}", json.dumps(out), flush=True)


def _synthetic(name: str, n: int):
    from bench_network_accuracy import blobs, sphere_pack

    if name == "blobs":
        return VoxelImage(blobs(n=n, porosity=0.30).astype(np.uint8), BEREA_VOXEL)
    return VoxelImage(sphere_pack(n=n, porosity=0.35, r_mean=6.0).astype(np.uint8), BEREA_VOXEL)


def _validation_image(case: str, n: int, image_path: str, lo: int = 150):
    if case in ("blobs", "spheres"):
        return f"{case} {n}^3", _synthetic(case, n)
    if case == "sample":
        img = load_sample()
        return f"built-in sample {img.shape[0]}^3", img
    img = read_image(image_path)
    sub = np.ascontiguousarray(img.phases[lo:lo + n, lo:lo + n, lo:lo + n])
    return f"Berea 400^3 crop {n}^3 @({lo},{lo},{lo})", VoxelImage(sub, img.voxel_size)


class _Native:
    """The native k of a whole image re-read from an earlier row (what sampled_permeability needs)."""

    def __init__(self, k_mD, axis):  # noqa: N803
        self.k_mD, self.axis = k_mD, axis


def _reuse_whole(args, name, levels):
    """``(Extrapolation, native)`` of ``name`` from an earlier row of ``args.out`` (``--reuse``), else None."""
    if not (args.reuse and args.out and Path(args.out).exists()):
        return None
    for line in Path(args.out).read_text().splitlines():
        r = json.loads(line)
        if r["case"] == name and r["axis"] == args.axis and tuple(r["levels"]) == levels:
            return richardson(levels, r["whole_levels_mD"]), _Native(r["whole_levels_mD"][0], args.axis)
    return None


def _write_whole(args, name, img, levels, ext, cpu) -> None:
    """One ``part: whole`` row: the whole image's levels, for a later ``validate --reuse`` (the whole
    refinement and the blocks then run in separate lock turns)."""
    e = ext.extrapolation
    row = {"case": name, "part": "whole", "axis": args.axis, "porosity": img.porosity, "levels": list(levels),
           "whole_levels_mD": list(e.values), "whole_k_inf_mD": e.value, "whole_gci_mD": e.uncertainty,
           "whole_order": e.order, "whole_observed_order": e.observed_order,
           "iterations": [r.iterations for r in ext.results], "cpu_whole_s": round(cpu, 1), "load": _load()}
    print(json.dumps(row), flush=True)
    if args.out:
        with open(args.out, "a") as fh:
            fh.write(json.dumps(row) + "\n")


def validate(args) -> list:
    """Sampled estimate against whole-image Richardson on images where the whole refinement fits."""
    rows = []
    levels = _levels(args.levels)
    for case in args.cases.split(","):
        name, img = _validation_image(case, args.n, args.image, args.at)
        c0 = time.process_time()
        whole = _reuse_whole(args, name, levels)
        if whole is None:
            ext = extrapolated_permeability(img, args.axis, levels=levels, rtol=args.rtol)
            whole = (ext.extrapolation, ext.results[0])
            if args.whole_only:
                _write_whole(args, name, img, levels, ext, time.process_time() - c0)
        if args.whole_only:
            continue
        c_whole = time.process_time() - c0
        c0 = time.process_time()
        s = sampled_permeability(img, args.axis, levels=levels, blocks=args.blocks, block=args.block,
                                 native=whole[1], rtol=args.rtol)
        c_s = time.process_time() - c0
        k_blocks = [b.k_mD for b in s.blocks]
        whole = whole[0]
        at_whole = pool_blocks([b.origin for b in s.blocks], s.blocks[0].side, k_blocks, levels, order=whole.order)[0]
        w_vals = whole.values
        at_sampled = richardson(levels, w_vals, order=s.order).value / w_vals[0]
        row = {"case": name, "axis": args.axis, "porosity": img.porosity, "levels": list(levels),
               "native_mD": w_vals[0], "whole_k_inf_mD": whole.value, "whole_gci_mD": whole.uncertainty,
               "whole_order": whole.order, "whole_factor": whole.value / w_vals[0],
               "sampled_mD": s.k_mD, "sampled_unc_mD": s.uncertainty_mD, "sampled_factor": s.factor,
               "sampled_order": s.order, "se": s.factor_se, "gci": s.factor_gci, "blocks": len(s.blocks),
               "side": s.blocks[0].side, "block_factors": [round(b.factor, 4) for b in s.blocks],
               "sampled_vs_whole": s.k_mD / whole.value - 1, "whole_levels_mD": list(w_vals),
               "whole_observed_order": whole.observed_order,
               "pooled_levels_mD": list(s.pooled.values), "sampled_observed_order": s.pooled.observed_order,
               "sampled_factor_at_whole_order": at_whole, "whole_factor_at_sampled_order": at_sampled,
               "cpu_whole_s": round(c_whole, 1),
               "cpu_sampled_s": round(c_s, 1), "load": _load()}
        rows.append(row)
        print(json.dumps(row), flush=True)
        if args.out:
            with open(args.out, "a") as fh:
                fh.write(json.dumps(row) + "\n")
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="study", required=True)
    b = sub.add_parser("blocks")
    b.add_argument("--image", default=str(DATA / "berea_icl_400.npz"))
    b.add_argument("--axis", default="x")
    b.add_argument("--levels", default="1,2,3")
    b.add_argument("--blocks", type=int, default=8)
    b.add_argument("--block", type=int, default=None)
    b.add_argument("--rtol", type=float, default=1e-6)
    b.add_argument("--out", required=True)
    b.add_argument("--time-limit", type=float, default=0.0,
                   help="start no block that would end after this many seconds, judged by the slowest block so far")
    b.add_argument("--rank-by-k1", action="store_true",
                   help="solve the blocks in order of their level-1 k in --out, largest first (e.g. --levels 4)")
    s = sub.add_parser("summarise")
    s.add_argument("path")
    s.add_argument("--native", type=float, default=None)
    s.add_argument("--native-json", default=None)
    s.add_argument("--levels", default=None, help="use only these levels (e.g. 1,2,3: the earlier estimate)")
    v = sub.add_parser("validate")
    v.add_argument("--cases", default="blobs,spheres,berea")
    v.add_argument("--n", type=int, default=80)
    v.add_argument("--levels", default="1,2")
    v.add_argument("--axis", default="x")
    v.add_argument("--blocks", type=int, default=8)
    v.add_argument("--block", type=int, default=None)
    v.add_argument("--rtol", type=float, default=1e-6)
    v.add_argument("--image", default=str(DATA / "berea_icl_400.npz"))
    v.add_argument("--out", default=None)
    v.add_argument("--reuse", action="store_true", help="reuse the whole-image levels of an earlier row in --out")
    v.add_argument("--whole-only", action="store_true",
                   help="solve and write the whole image's levels only (a 'part: whole' row for a later --reuse)")
    v.add_argument("--at", type=int, default=150, help="berea: the crop's first voxel on every axis (default 150)")
    args = ap.parse_args(argv)
    return {"blocks": run_blocks, "summarise": summarise, "validate": validate}[args.study](args)


if __name__ == "__main__":
    main()
