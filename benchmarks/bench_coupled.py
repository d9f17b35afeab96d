"""Coupled run on the built-in Berea crop: wall time by stage, paper-faithful vs fast settings.

The paper (Fagbemi & Tahmasebi, table 1) reports 186.9 CPU-minutes for its coupled FE-DPN run on
the 120³ sample (and 10.6 min decoupled). Targets for porefsi on a 2-core machine: < 60 s wall with
paper-faithful settings (800 test points, re-extraction with pre-coupling iterations, 20 s of
injection), < 15 s with the geometric network update.

Run: ``python benchmarks/bench_coupled.py [--quick]``.
"""

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing

from porefsi.case.config import Case  # noqa: E402
from porefsi.coupling.loop import CoupledRun  # noqa: E402
from porefsi.coupling.problem import build_problem  # noqa: E402

PAPER_CPU_MIN = 186.9


def run(name: str, case: Case) -> dict:
    t0 = time.perf_counter()
    cpu0 = time.process_time()
    problem = build_problem(case)
    run = CoupledRun(problem)
    rows = [rec.row for rec in run.steps()]
    wall = time.perf_counter() - t0
    cpu = time.process_time() - cpu0
    stages = {**problem.seconds, **run.seconds}
    print(f"\n{name}: {problem.network.n_pores} pores, {problem.mesh.n_nodes} nodes, {problem.mesh.n_tets} tets, "
          f"{len(rows)} exchange steps")
    print(f"  wall {wall:7.2f} s   cpu {cpu:7.2f} s   paper/porefsi CPU ratio {PAPER_CPU_MIN * 60 / cpu:8.0f}x")
    for k, v in sorted(stages.items(), key=lambda kv: -kv[1]):
        print(f"    {k:<14} {v:7.2f} s  ({100 * v / wall:4.1f} %)")
    print(f"  final Sw {rows[-1]['sw']:.4f}, max |u| {max(r['max_displacement_m'] for r in rows):.3e} m, "
          f"max von Mises {max(r['max_von_mises_Pa'] for r in rows):.3e} Pa")
    return {"wall": wall, "cpu": cpu, **stages}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="4 s of injection instead of 20 s")
    args = ap.parse_args()
    t_end = 4.0 if args.quick else 20.0
    base = Case().replace(drainage={"t_end": t_end}, output={"figures": False, "vtk": False})
    faithful = base.replace(network={"update": "reextract"}, interface={"method": "hull", "n_test_points": 800},
                            coupling={"integrator": "tdg", "tdg_iterations": 2, "tdg_load_rule": "left"})
    geometric = faithful.replace(network={"update": "geometric"})
    default = base.replace(network={"update": "geometric"})
    a = run("paper-faithful (hull, 800 test points, re-extraction with pre-coupling, TDG 2 passes, left rule)",
            faithful)
    b = run("paper-faithful with the geometric update", geometric)
    c = run("default (traction interface, quasi-static solid, geometric update)", default)
    print(f"\ntargets (wall): paper-faithful < 60 s -> {a['wall']:.1f} s; geometric < 15 s -> {b['wall']:.1f} s "
          f"(paper settings) / {c['wall']:.1f} s (default)")


if __name__ == "__main__":
    main()
