"""Where a graded mesh's error sits: the error field of each run binned by distance from the load and by leaf size.

The speed-accuracy study's coupled run (``cases/speed_accuracy/case.toml``: default case, 10 s of
the paper's injection) on a 120^3 image, scored at 10 s against its uniform coarsen-2 solve
(the truth of ``bench_mesh_graded.py --image``) on the coarsen-2 nodes at multiples of 6 voxels.
Per run: the relative L2 error, and its square split over the evaluation points by

- distance (voxels) from the nearest ``refine`` voxel (the predicted invasion),
- the edge (voxels) of the graded leaf that holds the point (uniform meshes: their block),
- whether the point's 6-voxel neighbourhood holds pore voxels the leaf's coarse geometry turns
  to solid or solid voxels it turns to pore (a "moved wall").

The share of the error in each bin against the share of the reference's squared norm there says
where a mesh loses its accuracy. Usage: ``python benchmarks/bench_mesh_graded_where.py --image NPZ
[--corner X Y Z] [--runs NAME ...] [--out FILE]`` (NPZ holds ``image`` and ``voxel_size_m``).
"""

from __future__ import annotations

import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy import ndimage  # noqa: E402

from porefsi import load_case, problem_from_case  # noqa: E402
from porefsi.solid.interpolate import p1_interpolate  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_mesh_graded import _study  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
RUNS = {
    "uniform3": {"coarsen": 3},
    "uniform4": {"coarsen": 4},
    "uniform6": {"coarsen": 6},
    "graded_3_12_g0.5": {"mesh": "graded", "coarsen": 3, "coarsen_max": 12, "grading": 0.5, "refine": "invaded"},
    "graded_3_12_g1": {"mesh": "graded", "coarsen": 3, "coarsen_max": 12, "grading": 1.0, "refine": "invaded"},
    "graded_3_12_g0.5_lig0.5": {"mesh": "graded", "coarsen": 3, "coarsen_max": 12, "grading": 0.5, "refine": "invaded",
                                "ligaments": 0.5},
    "graded_3_12_g0.5_lig1": {"mesh": "graded", "coarsen": 3, "coarsen_max": 12, "grading": 0.5, "refine": "invaded",
                              "ligaments": 1.0},
    "graded_3_12_g0.5_lig2": {"mesh": "graded", "coarsen": 3, "coarsen_max": 12, "grading": 0.5, "refine": "invaded",
                              "ligaments": 2.0},
    "graded_2_16_g0.5": {"mesh": "graded", "coarsen": 2, "coarsen_max": 16, "grading": 0.5, "refine": "invaded"},
    "graded_2_16_g0.5_lig1": {"mesh": "graded", "coarsen": 2, "coarsen_max": 16, "grading": 0.5, "refine": "invaded",
                              "ligaments": 1.0},
    "graded_3_12_g1_lig1": {"mesh": "graded", "coarsen": 3, "coarsen_max": 12, "grading": 1.0, "refine": "invaded",
                            "ligaments": 1.0},
}
LIG_BINS = (0, 4, 8, 12, 16, 24, 1e9)
DIST_BINS = (0, 3, 6, 12, 24, 48, 1e9)


def leaf_edge(prob, X: np.ndarray) -> np.ndarray:
    """Edge (voxels) of the leaf (graded) or block (uniform) holding each point X (M, 3) in m."""
    img, mr = prob.image, prob.mesh_result
    ijk = np.clip(np.floor((X - np.asarray(img.origin)) / img.voxel_size + 1e-6).astype(int), 0,
                  np.asarray(img.shape) - 1)
    if not mr.leaf_counts:
        return np.full(len(X), float(mr.coarsen))
    m = prob.mesh
    # the longest edge of the tetrahedron nearest each point: 2 x the leaf's half edge at its centre node
    from scipy.spatial import cKDTree

    cen = m.points[m.tets].mean(axis=1)
    _, e = cKDTree(cen).query(img.voxel_size * (ijk + 0.5) + np.asarray(img.origin))
    p = m.points[m.tets[e]]
    ext = (p.max(axis=1) - p.min(axis=1)).max(axis=1) / img.voxel_size
    return np.rint(ext).astype(float)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--image", required=True)
    ap.add_argument("--corner", nargs=3, type=int, default=None)
    ap.add_argument("--size", type=int, default=120)
    ap.add_argument("--runs", nargs="*", default=list(RUNS))
    ap.add_argument("--extra", default=None, help="JSON dict name -> solid overrides, added to the runs")
    ap.add_argument("--out", default=None)
    ap.add_argument("--truth", type=int, default=2, help="uniform coarsening of the truth (2; 3 isolates the grading "
                                                            "of 3-voxel fine blocks, ~1 GB instead of ~3)")
    args = ap.parse_args(argv)
    sa = _study()
    runs = dict(RUNS)
    if args.extra:
        runs.update(json.loads(args.extra))
    with np.load(args.image) as d:
        img = d["image"]
        if args.corner is not None:
            x, y, z = args.corner
            n = args.size
            img = img[x:x + n, y:y + n, z:z + n]
        path = Path(args.out or "/tmp/where.json").with_suffix(".img.npz")
        np.savez_compressed(path, image=img.astype(np.uint8), voxel_size_m=float(d["voxel_size_m"]))
    base = load_case(REPO / "cases" / "speed_accuracy" / "case.toml").replace(name="where", image={"path": str(path)})
    t_end = float(base.drainage.t_end)
    r2 = sa.run_variant(base.replace(name="truth", solid={"coarsen": args.truth, "linear_solver": "amg"},
                                     coupling={"integrator": "static", "exchange_dt": t_end}))
    idx = sa.eval_points(r2)
    X, c2 = r2["points"][idx], sa.at_time(r2, t_end)[idx]
    print(f"truth coarsen {args.truth}: {r2['n_nodes']} nodes, {r2['cpu_s']:.1f} CPU-s, {len(X)} points", flush=True)
    if args.truth != 2:
        runs.pop(f"uniform{args.truth}", None)
    del r2
    out = {"image": args.image, "corner": args.corner, "truth_coarsen": args.truth,
           "date_utc": time.strftime("%Y-%m-%d %H:%M", time.gmtime()),
           "runs": {}}
    probe = problem_from_case(base.replace(solid=runs["graded_3_12_g0.5"]))
    from porefsi.coupling.problem import predicted_invasion

    refine = predicted_invasion(probe.extraction, probe.options)
    dist = ndimage.distance_transform_edt(~refine)
    vs = probe.image.voxel_size
    ijk = np.clip(np.rint((X - np.asarray(probe.image.origin)) / vs).astype(int), 0, np.asarray(img.shape) - 1)
    d_pt = dist[ijk[:, 0], ijk[:, 1], ijk[:, 2]]
    pore = probe.image.phases != 0
    lig = dist + ndimage.distance_transform_edt(~(pore & ~refine))  # ligament thickness through each voxel
    t_pt = lig[ijk[:, 0], ijk[:, 1], ijk[:, 2]]
    from porefsi.solid.graded import mean_chord

    print(f"refined voxels {int(refine.sum())}, their mean chord {mean_chord(refine):.2f} voxels", flush=True)
    ref2 = np.sum(c2 ** 2, axis=1)
    for name in [r for r in args.runs if r in runs]:
        res = sa.run_variant(base.replace(name=name, solid=runs[name]))
        prob = problem_from_case(base.replace(name=name, solid=runs[name]))
        u = p1_interpolate(prob.mesh, sa.at_time(res, t_end), X)[0]
        e2 = np.sum((u - c2) ** 2, axis=1)
        edge = leaf_edge(prob, X)
        row = {"solid": runs[name], "cpu_s": res["cpu_s"], "n_nodes": res["n_nodes"],
               "err": float(np.sqrt(e2.sum() / ref2.sum())), "load": open("/proc/loadavg").read().split()[:3],
               "by_distance": [], "by_leaf": []}
        for lo, hi in zip(DIST_BINS[:-1], DIST_BINS[1:], strict=True):
            sel = (d_pt >= lo) & (d_pt < hi)
            row["by_distance"].append({"from": lo, "to": hi, "n": int(sel.sum()),
                                       "err_share": float(e2[sel].sum() / e2.sum()),
                                       "ref_share": float(ref2[sel].sum() / ref2.sum()),
                                       "err_contrib": float(np.sqrt(e2[sel].sum() / ref2.sum()))})
        row["by_ligament"] = []
        for lo, hi in zip(LIG_BINS[:-1], LIG_BINS[1:], strict=True):
            sel = (t_pt >= lo) & (t_pt < hi)
            row["by_ligament"].append({"from": lo, "to": hi, "n": int(sel.sum()),
                                       "err_share": float(e2[sel].sum() / e2.sum()),
                                       "ref_share": float(ref2[sel].sum() / ref2.sum()),
                                       "err_contrib": float(np.sqrt(e2[sel].sum() / ref2.sum()))})
        for s in np.unique(edge):
            sel = edge == s
            row["by_leaf"].append({"edge": float(s), "n": int(sel.sum()), "err_share": float(e2[sel].sum() / e2.sum()),
                                   "ref_share": float(ref2[sel].sum() / ref2.sum()),
                                   "err_contrib": float(np.sqrt(e2[sel].sum() / ref2.sum()))})
        out["runs"][name] = row
        print(f"{name}: err {row['err']:.3f} CPU {res['cpu_s']:.1f} nodes {res['n_nodes']}", flush=True)
        for b in row["by_distance"]:
            print(f"   dist [{b['from']:g},{b['to']:g}) n {b['n']:5d} err share {b['err_share']:.2f} "
                  f"ref share {b['ref_share']:.2f} contrib {b['err_contrib']:.3f}")
        for b in row["by_ligament"]:
            print(f"   ligament [{b['from']:g},{b['to']:g}) n {b['n']:5d} err share {b['err_share']:.2f} "
                  f"ref share {b['ref_share']:.2f} contrib {b['err_contrib']:.3f}")
        for b in row["by_leaf"]:
            print(f"   leaf {b['edge']:g} n {b['n']:5d} err share {b['err_share']:.2f} ref share {b['ref_share']:.2f} "
                  f"contrib {b['err_contrib']:.3f}", flush=True)
        del res
    if args.out:
        Path(args.out).write_text(json.dumps(out, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
