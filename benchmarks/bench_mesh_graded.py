"""Graded against uniform solid meshes on the speed-accuracy chart's terms (issue 16 section 2).

Every run is the speed-accuracy study's coupled run (``cases/speed_accuracy/run.py``'s
``run_variant`` on its ``case.toml``: the default case, first 10 s of the paper's injection) with
one mesh setting changed; its error is measured against the study's cached high-fidelity
reference (uniform coarsen 3, traction, 0.5 s TDG steps) on the reference's evaluation points
(relative L2 over the sample times 1..10 s), and its cost is the CPU time of set-up + coupled loop
(one thread), as in the study. Two ways of evaluating a run's field at the points:

- ``err_grid``: the study's own (trilinear on the run's node grid, grid points without a node
  filled from the nearest node). Exact for uniform meshes' nodes; for a graded mesh the nodes
  inside coarse leaves are missing, so this measures a nearest-node fill there, not the FE field;
- ``err_p1``: the finite-element field itself (:func:`porefsi.solid.interpolate.p1_interpolate`).

A second truth: uniform coarsen 2 (210k nodes), one quasi-static solve at 10 s (AMG-CG), the
study's check of its reference; ``err_c2`` is each run's relative L2 error at 10 s against it.

Another rock (``--image NPZ --corner X Y Z``): a 120^3 crop of it at that corner, the current
default conductance model, and as truth the uniform coarsen-2 solve at 10 s only (no cached
reference): ``err_c2`` of every run at 10 s on the coarsen-2 nodes at multiples of 6 voxels.

Usage: ``python benchmarks/bench_mesh_graded.py [--only NAME ...] [--no-c2] [--image NPZ --corner X Y Z]
[--out FILE]``. Prints one row per run and writes JSON.
"""

from __future__ import annotations

import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import importlib.util  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from porefsi import load_case  # noqa: E402
from porefsi.solid import SolidMesh  # noqa: E402
from porefsi.solid.interpolate import p1_interpolate  # noqa: E402
from porefsi.solid.quality import tet_quality  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
STUDY = REPO / "cases" / "speed_accuracy"


def _study():
    spec = importlib.util.spec_from_file_location("speed_accuracy_run", STUDY / "run.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def variants() -> list[tuple[str, dict]]:
    """(name, solid overrides) of the runs."""
    out = [(f"uniform{c}", {"coarsen": c}) for c in (6, 5, 4)]
    out += [("graded_walls_4_16", {"mesh": "graded", "coarsen": 4, "coarsen_max": 16})]
    for cf, cm, g in ((3, 6, 1.0), (3, 12, 1.0), (3, 12, 0.5), (3, 24, 0.5), (4, 8, 1.0), (4, 16, 0.5), (2, 8, 1.0),
                      (2, 16, 0.5)):
        out.append((f"graded_invaded_{cf}_{cm}_g{g:g}", {"mesh": "graded", "coarsen": cf, "coarsen_max": cm,
                                                          "grading": g, "refine": "invaded"}))
    return out


def p1_at(res: dict, U: np.ndarray, X: np.ndarray) -> np.ndarray:
    """A run's FE field at points X."""
    mesh = res["mesh"]
    return p1_interpolate(mesh, U, X)[0]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="*")
    ap.add_argument("--no-c2", action="store_true")
    ap.add_argument("--conductance", default="paper",
                    help="network conductance model of every run (paper: the one the cached reference was built with)")
    ap.add_argument("--image", help="another rock (npz with image, voxel_size_m): a 120^3 crop at --corner")
    ap.add_argument("--corner", nargs=3, type=int, default=(20, 200, 40))
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "bench_mesh_graded.json"))
    args = ap.parse_args(argv)
    sa = _study()
    base = load_case(STUDY / "case.toml")
    if args.image:
        return other_rock(sa, base, args)
    base = base.replace(network={"conductance": args.conductance})
    ref = sa.load_reference(sa.REF_FILE)
    X, times = ref["points"], ref["times"]
    rows = []
    c2 = None
    if not args.no_c2:
        case = base.replace(name="c2", solid={"coarsen": 2, "linear_solver": "amg"}, interface={"method": "traction"},
                            coupling={"integrator": "static", "exchange_dt": float(times[-1])})
        r2 = _run(sa, case)
        c2 = p1_at(r2, sa.at_time(r2, float(times[-1])), X)
        print(f"coarsen-2 check: {r2['n_nodes']} nodes, {r2['cpu_s']:.1f} CPU-s; reference vs it "
              f"{sa.rel_l2([ref['u'][-1] - c2], [c2]):.3f}", flush=True)
    for name, solid in variants():
        if args.only and name not in args.only:
            continue
        res = _run(sa, base.replace(name=name, solid=solid))
        row = {"name": name, "solid": solid, "status": res["status"], "cpu_s": res["cpu_s"],
               "load": open("/proc/loadavg").read().split()[:3]}
        if res["status"] == "ok":
            uh = [p1_at(res, sa.at_time(res, t), X) for t in times]
            row.update(n_nodes=res["n_nodes"], n_tets=res["n_tets"], leaf_counts=res["leaf_counts"],
                       err_p1=sa.rel_l2([a - b for a, b in zip(uh, ref["u"], strict=True)], list(ref["u"])),
                       err_grid=sa.compare(res, ref, None)["err_field"], min_dihedral=res["min_dihedral"],
                       stage_cpu=res["stage_seconds"])
            if c2 is not None:
                row["err_c2"] = sa.rel_l2([uh[-1] - c2], [c2])
        rows.append(row)
        print(json.dumps({k: (round(v, 4) if isinstance(v, float) else v) for k, v in row.items()
                          if k not in ("stage_cpu", "solid")}), flush=True)
    Path(args.out).write_text(json.dumps({"date_utc": time.strftime("%Y-%m-%d %H:%M", time.gmtime()),
                                          "rows": rows}, indent=1, default=float))
    return 0


def other_rock(sa, base, args) -> int:
    """The runs on a 120^3 crop of another image, scored at 10 s against its uniform coarsen-2 solve."""
    with np.load(args.image) as d:
        x, y, z = args.corner
        crop = d["image"][x:x + 120, y:y + 120, z:z + 120].astype(np.uint8)
        path = Path(args.out).with_suffix(".crop.npz")
        np.savez_compressed(path, image=crop, voxel_size_m=float(d["voxel_size_m"]))
    base = base.replace(name="other_rock", image={"path": str(path)})
    t_end = float(base.drainage.t_end)
    r2 = _run(sa, base.replace(name="c2", solid={"coarsen": 2, "linear_solver": "amg"},
                               coupling={"integrator": "static", "exchange_dt": t_end}))
    X = r2["points"][sa.eval_points(r2)]
    c2 = sa.at_time(r2, t_end)[sa.eval_points(r2)]
    print(f"{args.image} crop at {args.corner}: porosity {float(crop.mean()):.3f}; coarsen 2: {r2['n_nodes']} nodes, "
          f"{r2['cpu_s']:.1f} CPU-s, {len(X)} evaluation points", flush=True)
    rows = []
    for name, solid in [(f"uniform{c}", {"coarsen": c}) for c in (3,)] + variants():
        if args.only and name not in args.only:
            continue
        res = _run(sa, base.replace(name=name, solid=solid))
        row = {"name": name, "solid": solid, "status": res["status"], "cpu_s": res["cpu_s"],
               "load": open("/proc/loadavg").read().split()[:3]}
        if res["status"] == "ok":
            u = p1_at(res, sa.at_time(res, t_end), X)
            row.update(n_nodes=res["n_nodes"], leaf_counts=res["leaf_counts"], min_dihedral=res["min_dihedral"],
                       err_c2=sa.rel_l2([u - c2], [c2]))
        rows.append(row)
        print(json.dumps({k: (round(v, 4) if isinstance(v, float) else v) for k, v in row.items() if k != "solid"}),
              flush=True)
    Path(args.out).write_text(json.dumps({"date_utc": time.strftime("%Y-%m-%d %H:%M", time.gmtime()),
                                          "image": args.image, "corner": list(args.corner), "rows": rows},
                                         indent=1, default=float))
    return 0


def _run(sa, case) -> dict:
    """The study's run_variant plus the mesh, its leaf counts and its worst dihedral angle."""
    res = sa.run_variant(case)
    if res["status"] == "ok":
        from porefsi import problem_from_case  # the mesh again (cheap): run_variant keeps only the points

        prob = problem_from_case(case)
        mesh: SolidMesh = prob.mesh
        assert np.array_equal(mesh.points, res["points"])
        res["mesh"], res["leaf_counts"] = mesh, prob.mesh_result.leaf_counts
        res["min_dihedral"] = float(tet_quality(mesh.points, mesh.tets)[0].min())
    return res


if __name__ == "__main__":
    sys.exit(main())
