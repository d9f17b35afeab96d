"""Coupled run on the built-in Berea crop: wall and CPU time by stage, paper-faithful vs fast settings.

The paper (Fagbemi & Tahmasebi, table 1) reports 186.9 CPU-minutes for its coupled FE-DPN run on
the 120³ sample (and 10.6 min decoupled). Targets for porefsi on a 2-core machine: < 60 s wall with
paper-faithful settings (800 test points, re-extraction with pre-coupling iterations, 20 s of
injection), < 15 s with the geometric network update.

Re-extraction serves the extraction of a voxel image seen before from a digest cache (the
extraction is deterministic); at the paper's loads the deformed image is the reference image, so
the cached run computes no extraction at all. The paper-faithful setting is therefore run twice:
with the cache (porefsi's behaviour) and without it (``reuse_extractions=False``: every
re-extraction computed, the paper's cost). Each run prints the extractions computed and served
from the cache, and the voxelisation and extraction seconds inside the network update.

Run: ``python benchmarks/bench_coupled.py [--quick] [--no-extraction-cache]``
(``--no-extraction-cache``: only the cache-off paper-faithful run, not the cached one).
"""

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing

from porefsi.case import (
    Case,  # noqa: E402
    problem_from_case,  # noqa: E402
)
from porefsi.coupling import CoupledRun  # noqa: E402

PAPER_CPU_MIN = 186.9


def run(name: str, case: Case, reuse_extractions: bool = True) -> dict:
    t0 = time.perf_counter()
    cpu0 = time.process_time()
    problem = problem_from_case(case)
    run = CoupledRun(problem, reuse_extractions=reuse_extractions)
    rows = [rec.row for rec in run.steps()]
    wall = time.perf_counter() - t0
    cpu = time.process_time() - cpu0
    stages = {**problem.seconds, **run.seconds}
    cpu_stages = {**problem.cpu_seconds, **run.cpu_seconds}
    print(f"\n{name}: {problem.network.n_pores} pores, {problem.mesh.n_nodes} nodes, {problem.mesh.n_tets} tets, "
          f"{len(rows)} exchange steps")
    print(f"  wall {wall:7.2f} s   cpu {cpu:7.2f} s   paper/porefsi CPU ratio {PAPER_CPU_MIN * 60 / cpu:8.0f}x")
    print(f"    {'stage':<16} {'wall s':>7} {'CPU s':>7}  (CPU % of run CPU)")
    for k, v in sorted(stages.items(), key=lambda kv: -kv[1]):
        print(f"    {k:<16} {v:7.2f} {cpu_stages[k]:7.2f}  ({100 * cpu_stages[k] / cpu:4.1f} %)")
    if case.network.update == "reextract":
        us, uc = run.update_seconds, run.update_cpu_seconds
        print(f"  re-extraction: {run.n_extractions} extractions computed, {run.n_extractions_reused} served from "
              f"the digest cache (cache {'on' if reuse_extractions else 'off'}); within 'update' (wall / CPU): "
              f"voxelise {us['voxelise']:.2f} / {uc['voxelise']:.2f} s, extract {us['extract']:.2f} / "
              f"{uc['extract']:.2f} s, interface rebuild {us['interface_rebuild']:.2f} / "
              f"{uc['interface_rebuild']:.2f} s")
    print(f"  final Sw {rows[-1]['sw']:.4f}, max |u| {max(r['max_displacement_m'] for r in rows):.3e} m, "
          f"max von Mises {max(r['max_von_mises_Pa'] for r in rows):.3e} Pa")
    return {"wall": wall, "cpu": cpu, **stages, **{f"cpu_{k}": v for k, v in cpu_stages.items()}}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="4 s of injection instead of 20 s")
    ap.add_argument("--no-extraction-cache", action="store_true",
                    help="paper-faithful run only without the extraction cache (every re-extraction computed)")
    args = ap.parse_args()
    t_end = 4.0 if args.quick else 20.0
    try:
        print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())} ({os.cpu_count()} cores)")
    except OSError:
        pass
    base = Case().replace(drainage={"t_end": t_end}, output={"figures": False, "vtk": False})
    faithful = base.replace(network={"update": "reextract"}, interface={"method": "hull", "n_test_points": 800},
                            coupling={"integrator": "tdg", "tdg_iterations": 2, "tdg_load_rule": "left"})
    geometric = faithful.replace(network={"update": "geometric"})
    default = base.replace(network={"update": "geometric"})
    label = "paper-faithful (hull, 800 test points, re-extraction with pre-coupling, TDG 2 passes, left rule)"
    a = None
    if not args.no_extraction_cache:
        a = run(f"{label}, extraction cache on", faithful)
    a0 = run(f"{label}, extraction cache off (every re-extraction computed)", faithful, reuse_extractions=False)
    b = run("paper-faithful with the geometric update", geometric)
    c = run("default (traction interface, quasi-static solid, geometric update)", default)
    cached = f"; {a['wall']:.1f} s with the extraction cache" if a else ""
    print(f"\ntargets (wall): paper-faithful < 60 s -> {a0['wall']:.1f} s computing every extraction{cached}; "
          f"geometric < 15 s -> {b['wall']:.1f} s (paper settings) / {c['wall']:.1f} s (default)")
    try:
        print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    except OSError:
        pass


if __name__ == "__main__":
    main()
