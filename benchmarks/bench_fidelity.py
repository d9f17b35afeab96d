"""``fidelity = "auto"`` on images its calibration did not see: achieved vs predicted error.

The error model of :mod:`porefsi.case.fidelity` was calibrated on the built-in 120³ Berea sample
only (``cases/speed_accuracy``). This script checks it on held-out images:

- ``berea_crop``: a 120³ crop of the 400³ Berea away from the sample's region
  (``[20:140, 240:360, 40:160]``; needs ``--berea PATH`` to ``berea_icl_400.npz``);
- ``blobs``: a synthetic blob medium (Gaussian-smoothed noise thresholded to 25 % porosity, 96³,
  4 µm voxels; made here, no file needed);
- ``tiled``: the built-in sample mirror-tiled twice along the flow axis (240 x 120 x 120).

For each image: a high-fidelity reference (the speed-accuracy study's: coarsen 3, traction, TDG 2
passes, 0.5 s steps; cached in ``--work``), a sweep of the uniform coarsening (the mesh law out of
sample) and ``auto`` at two tolerances; each run's error is the study's measure (relative L2 of the
nodal displacement on the reference's nodes at multiples of 6 voxels over 1, 2, ..., 10 s), computed
by the study's own functions (``cases/speed_accuracy/run.py``). Heavy (minutes of CPU per image):
run it under the shared lock, ``flock /work/wt/heavy.lock python benchmarks/bench_fidelity.py``.

Usage: ``python benchmarks/bench_fidelity.py [--images NAME ...] [--phase ref|sweep|auto|all]
[--work DIR] [--berea PATH] [--tolerances T ...]``.
"""

from __future__ import annotations

import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import importlib.util  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy import ndimage  # noqa: E402

from porefsi import load_case  # noqa: E402
from porefsi.image.io import load_sample, read_image, write_image  # noqa: E402
from porefsi.image.voxel_image import VoxelImage  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
STUDY = ROOT / "cases" / "speed_accuracy"
BEREA_CROP = ((20, 140), (240, 360), (40, 160))  # the sample is [180:300, 20:140, 220:340]


def study_module():
    """cases/speed_accuracy/run.py as a module (its reference, error measure and run helpers)."""
    spec = importlib.util.spec_from_file_location("speed_accuracy_run", STUDY / "run.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def blobs(shape=(96, 96, 96), porosity=0.25, sigma=2.5, voxel_size=4e-6, seed=7) -> VoxelImage:
    """A blob medium: smoothed Gaussian noise, the top ``porosity`` quantile is pore."""
    rng = np.random.default_rng(seed)
    field = ndimage.gaussian_filter(rng.standard_normal(shape), sigma, mode="wrap")
    pore = field > np.quantile(field, 1.0 - porosity)
    return VoxelImage(pore.astype(np.uint8), voxel_size)


def tiled() -> VoxelImage:
    """The built-in sample mirror-tiled twice along x (240 x 120 x 120)."""
    s = load_sample()
    return VoxelImage(np.concatenate([s.phases, s.phases[::-1]], axis=0), s.voxel_size)


def berea_crop(path: Path) -> VoxelImage:
    """A 120³ crop of the 400³ Berea away from the built-in sample's region."""
    with np.load(path) as z:
        a, vs = z["image"], float(z["voxel_size_m"])
    (x0, x1), (y0, y1), (z0, z1) = BEREA_CROP
    return VoxelImage(np.ascontiguousarray(a[x0:x1, y0:y1, z0:z1]).astype(np.uint8), vs)


def image_file(name: str, work: Path, berea: Path | None) -> Path:
    """Write (once) the held-out image ``name`` to ``work`` and return its path."""
    p = work / f"{name}.npz"
    if not p.exists():
        if name == "blobs":
            img = blobs()
        elif name == "tiled":
            img = tiled()
        elif name == "berea_crop":
            if berea is None:
                raise SystemExit("berea_crop needs --berea PATH/berea_icl_400.npz")
            img = berea_crop(berea)
        else:
            raise SystemExit(f"unknown image {name!r}")
        write_image(img, p)
    return p


def base_case(path: Path):
    """The study's case (10 s of the paper's injection) on the image at ``path``."""
    base = load_case(STUDY / "case.toml")
    return base.replace(name=f"heldout-{path.stem}", image={"path": str(path)})


def reference(sa, base, name: str, work: Path) -> dict:
    """The image's high-fidelity reference (built once, cached in ``work``).

    The calibration's: coarsen 3, traction, quasi-static with 1 s steps (the study measured it equal
    to its TDG 2-pass, 0.5 s-step reference to 1e-8 on the sample, at a seventh of the cost).
    """
    p = work / f"ref_{name}_static.npz"
    if p.exists():
        return sa.load_reference(p)
    times = list(np.arange(1.0, base.drainage.t_end + 1e-9, 1.0))
    res = sa.run_variant(base.replace(name=f"{name}-reference", **SAMPLE_REFERENCE))
    if res["status"] != "ok":
        raise RuntimeError(f"reference of {name} failed: {res['status']}")
    idx = sa.eval_points(res)
    ref = {"points": res["points"][idx], "times": np.asarray(times, float),
           "u": np.stack([sa.at_time(res, t)[idx] for t in times]), "commit": _git_head(),
           "built_utc": time.strftime("%Y-%m-%d %H:%M", time.gmtime()), "cpu_s": res["cpu_s"],
           "n_nodes": res["n_nodes"], "n_tets": res["n_tets"], **sa.final_scalars(res)}
    sa.save_reference(ref, p)
    return ref


def measure(sa, case, ref) -> dict:
    """Run ``case``; its error against ``ref`` (the study's measure) and its CPU time."""
    res = sa.run_variant(case)
    row = {"status": res["status"], "cpu_s": res["cpu_s"], "n_nodes": res.get("n_nodes"),
           "n_tets": res.get("n_tets")}
    if res["status"] == "ok":
        row["err_field"] = sa.compare(res, ref, None)["err_field"]
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--images", nargs="*", default=["berea_crop", "blobs", "tiled"])
    ap.add_argument("--phase", default="all", choices=("ref", "sweep", "auto", "all", "calibrate", "from_study", "fit",
                                                       "report", "sample_auto", "chart"))
    ap.add_argument("--work", type=Path, default=ROOT / "_heldout")
    ap.add_argument("--berea", type=Path, default=None)
    ap.add_argument("--tolerances", nargs="*", type=float, default=[0.3, 0.45])
    ap.add_argument("--coarsen", nargs="*", type=int, default=[4, 5, 6, 8, 10, 12])
    ap.add_argument("--graded", nargs="*", type=int, default=[], help="fine blocks of graded-recipe sweep runs")
    args = ap.parse_args(argv)
    args.work.mkdir(parents=True, exist_ok=True)
    sa = study_module()
    if args.phase == "calibrate":
        return calibrate(sa, args.work)
    if args.phase == "from_study":
        return calibrate_from_study(args.work)
    if args.phase == "fit":
        return write_calibration(args.work / "calibration.json")
    if args.phase == "report":
        return report(args.work, args.images)
    if args.phase == "sample_auto":
        return sample_auto(sa, args.work)
    if args.phase == "chart":
        return chart(sa, args.work)
    out_file = args.work / "heldout.json"
    results = json.loads(out_file.read_text()) if out_file.exists() else {}
    for name in args.images:
        path = image_file(name, args.work, args.berea)
        base = base_case(path)
        t0 = time.process_time()
        ref = reference(sa, base, name, args.work)
        entry = results.setdefault(name, {})
        entry["reference"] = {k: ref[k] for k in ("n_nodes", "n_tets", "cpu_s", "commit", "built_utc")}
        print(f"{name}: reference {ref['n_nodes']} nodes, {ref['cpu_s']:.1f} CPU-s "
              f"(this call {time.process_time() - t0:.1f}), load {os.getloadavg()}", flush=True)
        if args.phase in ("sweep", "all"):
            shape = read_image(path).shape
            for c in [c for c in args.coarsen if all(n % c == 0 for n in shape)]:  # blocks that tile the image
                row = measure(sa, base.replace(solid={"coarsen": c}), ref)
                entry.setdefault("sweep", {})[str(c)] = row
                print(f"  coarsen {c}: {row}", flush=True)
                out_file.write_text(json.dumps(results, indent=1))
            for c in args.graded:  # the graded recipe auto offers, at fine blocks c
                from porefsi.case.fidelity import graded_recipe

                solid = {k.split(".")[1]: v for k, v in graded_recipe(c).items()}
                row = measure(sa, base.replace(solid={"mesh": "graded", "coarsen": c, **solid}), ref)
                entry.setdefault("graded", {})[str(c)] = row
                print(f"  graded recipe at {c}: {row}", flush=True)
                out_file.write_text(json.dumps(results, indent=1))
        if args.phase in ("auto", "all"):
            auto_runs(sa, base, ref, path, args.tolerances, entry)
        out_file.write_text(json.dumps(results, indent=1))
    return 0


#: Calibration runs on the built-in sample beyond the speed-accuracy study's variants (a coarser
#: mesh, the linear-response solid, the adaptive drainage).
CALIBRATION_RUNS = {"coarsen12": {"solid": {"coarsen": 12}},
                    "response_auto": {"solid": {"response": "auto"}},
                    "adaptive": {"drainage": {"scheme": "adaptive"}}}
#: The calibration's reference on the sample: the study's (coarsen 3, traction) quasi-static with 1 s
#: steps (the study measured TDG 2 passes and 0.5 s steps equal to it within 1e-8: its table).
SAMPLE_REFERENCE = {"solid": {"coarsen": 3}, "interface": {"method": "traction"}, "coupling": {"integrator": "static"}}


def _row(sa, res, ref, base_res) -> dict:
    row = {"status": res["status"], "cpu_s": res["cpu_s"], "n_nodes": res.get("n_nodes"), "n_dofs": res.get("n_dofs"),
           "n_tets": res.get("n_tets"), "stage_seconds": res.get("stage_cpu_seconds"),
           "stage_wall_seconds": res.get("stage_seconds")}
    if res["status"] == "ok":
        c = sa.compare(res, ref, base_res)
        row.update(err_field=c["err_field"], diff_vs_baseline=c.get("diff_vs_baseline"))
    return row


def calibrate(sa, work: Path) -> int:
    """The speed-accuracy study's variants and :data:`CALIBRATION_RUNS` on the sample, against a
    reference run with the current code; CPU time per stage (``calibration.json``)."""
    base = load_case(STUDY / "case.toml")
    f = work / "calibration.json"
    out = json.loads(f.read_text()) if f.exists() else {}
    out.update(load=os.getloadavg(), utc=time.strftime("%Y-%m-%d %H:%M", time.gmtime()), commit=_git_head())
    times = list(np.arange(1.0, base.drainage.t_end + 1e-9, 1.0))
    res = sa.run_variant(base.replace(name="sample-reference", **SAMPLE_REFERENCE))
    idx = sa.eval_points(res)
    ref = {"points": res["points"][idx], "times": np.asarray(times), "u": np.stack([sa.at_time(res, t)[idx]
                                                                                   for t in times]),
           **sa.final_scalars(res)}
    runs = {"coarsen3_static": {**_row(sa, res, ref, None), "overrides": SAMPLE_REFERENCE}}
    del res
    todo = [(v["name"], v["overrides"]) for v in sa.variants(False) if v["name"] != "skip"]
    base_res = None
    for name, ov in todo + list(CALIBRATION_RUNS.items()):
        res = sa.run_variant(base.replace(name=name, **ov))
        runs[name] = {**_row(sa, res, ref, base_res), "overrides": ov}
        if name == "baseline":
            base_res = res
        print(name, {k: v for k, v in runs[name].items() if "stage" not in k}, flush=True)
        out["runs"] = runs
        f.write_text(json.dumps(out, indent=1))
    return 0


#: Study runs (cases/speed_accuracy/results.json) under the names the fit reads them by.
STUDY_NAMES = {"coarsen3": "coarsen3_static", "linear_c5_cold": "response_auto"}


def calibrate_from_study(work: Path) -> int:
    """``calibration.json`` from the speed-accuracy study's own last run (no new runs).

    The study measures every run the calibration needs (coarsen 3 static, coarsen 12, the linear
    response, the adaptive drainage are among its variants) against its reference (coarsen 3,
    TDG 2 passes, 0.5 s steps: equal to the quasi-static 1 s-step one to 1e-8) with CPU seconds per
    stage, so the chart and the calibration are the same runs.
    """
    study = json.loads((STUDY / "results.json").read_text())
    runs = {}
    for r in study["runs"]:
        if r.get("status") != "ok" or r.get("stage_cpu_seconds") is None:
            continue
        runs[STUDY_NAMES.get(r["name"], r["name"])] = {
            "status": r["status"], "cpu_s": r["cpu_s"], "n_nodes": r["n_nodes"], "n_dofs": r["n_dofs"],
            "n_tets": r["n_tets"], "stage_seconds": r["stage_cpu_seconds"], "stage_wall_seconds": r["stage_seconds"],
            "err_field": r["err_field"], "diff_vs_baseline": r.get("diff_vs_baseline"), "overrides": r["overrides"],
            "load": r.get("load")}
    loads = [x for r in runs.values() if r.get("load") for x in r["load"][:1]]
    out = {"load": [min(loads), float(np.median(loads)), max(loads)] if loads else [float("nan")] * 3,
           "utc": study["runs"][0].get("utc", study["reference"].get("built_utc")), "commit": _git_head(),
           "from_study": str(STUDY / "results.json"), "runs": runs}
    (work / "calibration.json").write_text(json.dumps(out, indent=1))
    print(f"calibration.json: {len(runs)} runs from the study, load min/median/max {out['load']}")
    return 0


#: The adaptive drainage scheme against the exact one on the 400³ Berea network (docs/drainage.md,
#: "Adaptive scheme", the table's Berea rows: Ca, Sw history max rel. difference, inlet pressure
#: median rel. difference, CPU s of both schemes); its exact paper-rate row gives the DPN's cost.
ADAPTIVE_DRAINAGE = {"source": "docs/drainage.md, Adaptive scheme, Berea 400^3 rows (commit 01ef00a)",
                     "ca": [9.1e-9, 1e-6, 1e-5], "sw_max_rel": [8.3e-5, 4.7e-4, 2.9e-2],
                     "p_in_median_rel": [1.7e-12, 2.0e-2, 3.4e-2], "exact_cpu_s": [3.3, 14.7, 24.9],
                     "adaptive_cpu_s": [3.2, 13.3, 29.5]}
DRAINAGE_COST = {"source": "docs/drainage.md, Berea 400^3 exact scheme at the paper rate", "exact_cpu_s": 3.3,
                 "fills": 930, "pores": 8153}
RUN_KEYS = ("coarsen", "n_tets", "n_dofs", "n_steps", "cpu_s", "err_field", "diff_vs_baseline", "stage_seconds")


def _sample_data(case) -> dict:
    """The built-in sample's scene figures the calibration needs (its real pore count included)."""
    from porefsi.case._fidelity_model import pore_chord
    from porefsi.coupling.problem import extract_flow_network

    img = load_sample()
    n_pores = int(extract_flow_network(img, case.image.axis, case.network.conductance).network.n_pores)
    lam = pore_chord(img.phases)
    n_pore_vox = int(img.phases.sum())
    entry = 2 * case.fluids.sigma / (lam * img.voxel_size / 2)
    pore_vol = n_pore_vox * img.voxel_size ** 3 / n_pores
    return {"n_voxels": int(img.phases.size), "n_pore_voxels": n_pore_vox, "pore_chord": lam, "n_pores": n_pores,
            "n_steps": 10, "strain": entry / case.solid.E,
            "n_events": min(n_pores, case.drainage.rate * case.drainage.t_end / pore_vol)}


def sample_auto(sa, work: Path) -> int:
    """``auto`` at the study's tolerances on the sample (in-sample: the calibration's own image), against
    the calibration's reference (rebuilt; same code), added to ``calibration.json`` as ``auto`` rows."""
    from porefsi.case import resolve_fidelity

    base = load_case(STUDY / "case.toml")
    f = work / "calibration.json"
    cal = json.loads(f.read_text())
    times = list(np.arange(1.0, base.drainage.t_end + 1e-9, 1.0))
    res = sa.run_variant(base.replace(name="sample-reference", **SAMPLE_REFERENCE))
    idx = sa.eval_points(res)
    ref = {"points": res["points"][idx], "times": np.asarray(times), "u": np.stack([sa.at_time(res, t)[idx]
                                                                                   for t in times]),
           **sa.final_scalars(res)}
    del res
    rows = {}
    for tol in sa.AUTO_TOLERANCES:
        case, choice = resolve_fidelity(base.replace(fidelity={"preset": "auto", "tolerance": tol}))
        row = _row(sa, sa.run_variant(case), ref, None)
        row.update(choice.summary())
        rows[f"auto{tol:g}"] = row
        print(f"auto {tol}", {k: v for k, v in row.items() if "stage" not in k}, flush=True)
        cal["auto"] = rows
        f.write_text(json.dumps(cal, indent=1))
    return 0


def chart(sa, work: Path) -> int:
    """The study's chart of the calibration runs (current code) with the ``auto`` points: docs/figures."""
    cal = json.loads((work / "calibration.json").read_text())
    knobs = {v["name"]: (v["knob"], v["label"]) for v in sa.variants(False)}
    rows = []
    for name, r in {**cal["runs"], **cal.get("auto", {})}.items():
        if r.get("status") != "ok" or name == "coarsen3_static" or r["err_field"] < 1e-6:
            continue  # the reference itself (auto at 0.25 picks it: error 0 by construction)
        knob, label = knobs.get(name, ("auto" if name.startswith("auto") else "mesh", name))
        dt = r.get("overrides", {}).get("coupling", {}).get("exchange_dt", 1.0)
        row = {**r, "name": name, "knob": knob, "label": label, "meets_output_resolution": dt <= 1.0}
        if name.startswith("auto"):
            row["expected_err_vs_reference"] = r["fidelity_expected_error_vs_reference"]
        rows.append(row)
    ok = [r for r in rows if r["meets_output_resolution"]]
    for r, m in zip(ok, sa.pareto([r["cpu_s"] for r in ok], [r["err_field"] for r in ok]), strict=True):
        r["pareto"] = bool(m)
    for r in rows:
        r.setdefault("pareto", False)
    ref = {"case_toml": "coarsen = 3", "n_nodes": cal["runs"]["coarsen3_static"]["n_nodes"]}
    dest = ROOT / "docs" / "figures" / "fidelity_speed_accuracy.png"
    sa.plot(rows, ref, dest)
    print(f"wrote {dest}")
    return 0


def _git_head() -> str:
    import subprocess

    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def write_calibration(extra_file: Path) -> int:
    """Assemble the calibration data (study + calibration runs), fit, write the package's JSON."""
    from porefsi.case._fidelity_fit import fit_calibration

    study = json.loads((STUDY / "results.json").read_text())
    extra = json.loads(extra_file.read_text())
    base = load_case(STUDY / "case.toml")
    runs = {}
    for name, r in extra["runs"].items():
        if r.get("status") == "ok":
            ov = r["overrides"]
            runs[name] = {**{k: r.get(k) for k in RUN_KEYS},
                          "coarsen": ov.get("solid", {}).get("coarsen", base.solid.coarsen),
                          "n_steps": round(base.drainage.t_end / ov.get("coupling", {}).get("exchange_dt", 1.0))}
    ref = study["reference"]
    how = ("cases/speed_accuracy/run.py's own runs (results.json, read by bench_fidelity.py --phase from_study)"
           if "from_study" in extra else "benchmarks/bench_fidelity.py --phase calibrate (the speed-accuracy study's "
           "variants on the built-in sample)")
    data = {"source": {"runs": f"{how}, CPU seconds per stage, {extra['utc']} UTC, "
                               f"load {[round(x, 1) for x in extra['load']]}, commit {_git_head()}",
                       "reference_vs_coarsen2": f"cases/speed_accuracy --check-reference (built {ref['built_utc']} "
                                                f"on {ref['commit']})"},
            "sample": _sample_data(base), "runs": runs,
            "reference": {"coarsen": 3, "vs_finer": ref["check"]["rel_l2_ref_vs_coarsen2"], "finer": 2},
            "mesh_series": ["coarsen4", "baseline", "coarsen6", "coarsen8", "coarsen10", "coarsen12"],
            "direct_series": ["coarsen4", "baseline", "coarsen6", "coarsen8", "coarsen10", "coarsen12"],
            "step_series": ["dt5", "dt2", "baseline", "dt0.5"], "hull_runs": ["tp100", "tp400", "tp800", "tp1000",
                                                                             "paper", "old_default", "hull_tdg_c6"],
            "drainage": DRAINAGE_COST, "adaptive_drainage": ADAPTIVE_DRAINAGE}
    if GRADED_RUN in runs:
        data["graded"] = _graded_data(base, extra["runs"][GRADED_RUN]["overrides"]["solid"])
    out = {"about": "porefsi fidelity model: constants fitted (porefsi/case/_fidelity_fit.py) from 'data'; "
                    "docs/fidelity.md", **fit_calibration(data), "data": data}
    dest = ROOT / "porefsi" / "case" / "fidelity_calibration.json"
    dest.write_text(json.dumps(out, indent=1) + "\n")
    print(json.dumps({k: v for k, v in out.items() if k != "data"}, indent=1))
    return 0


#: The graded mesh ``auto`` offers: the study's run of it (fine blocks of 3 = the reference's, so
#: its error against the reference is its coarse leaves' alone) and the recipe it stands for.
GRADED_RUN = "graded_3_12_lig1"
GRADED_RECIPE = {"fine_blocks": [2, 3, 4], "coarsen_max_factor": 4, "grading": 0.5, "ligaments": 1.0,
                 # the predicted invasion held up to 100x the paper's rate (docs/stability.md (e) item 5)
                 "max_capillary_number": 1e-5}


def _graded_data(base, solid: dict) -> dict:
    """The calibration data of the graded run on the sample: its recipe, fine block, sizes."""
    from porefsi.solid.mesh import mesh_size

    img = load_sample()
    cf = int(solid["coarsen"])
    assert solid["coarsen_max"] == GRADED_RECIPE["coarsen_max_factor"] * cf and solid["grading"] == \
        GRADED_RECIPE["grading"] and solid["ligaments"] == GRADED_RECIPE["ligaments"], "recipe and run differ"
    return {"run": GRADED_RUN, "coarsen": cf, "recipe": GRADED_RECIPE,
            "injected_voxels": 2 * base.drainage.rate * base.drainage.t_end / img.voxel_size ** 3,
            "n_tets_coarsest": int(mesh_size(img, coarsen=int(solid["coarsen_max"]))[0])}


def _predict(image, base, c: int) -> tuple[float, float]:
    """The model's expected error (converged, vs the coarsen-3 reference) of coarsen ``c`` otherwise default."""
    from porefsi.case._fidelity_model import Setting, expected_error, scene_of

    scene = scene_of(image, base, extra_coarsen=[c])
    return expected_error(scene, Setting(coarsen=c)), expected_error(scene, Setting(coarsen=c), vs_reference=True)


def report(work: Path, images) -> int:
    """Markdown tables of the held-out images: the coarsening sweep and the auto runs, predicted vs achieved."""
    print("| image | run | coarsen | predicted vs ref | achieved | achieved / predicted | CPU s (predicted) |")
    print("|---|---|---:|---:|---:|---:|---:|")
    for name in images:
        f = work / name / "heldout.json"
        if not f.exists():
            continue
        entry = json.loads(f.read_text())[name]
        path = work / name / f"{name}.npz"
        img, base = read_image(path), base_case(path)
        for c, row in sorted(entry.get("sweep", {}).items(), key=lambda kv: int(kv[0])):
            if "err_field" not in row:
                print(f"| {name} | coarsen {c} | {c} | | {row['status'][:60]} | | |")
                continue
            _, pr = _predict(img, base, int(c))
            print(f"| {name} | coarsen {c} | {c} | {pr:.3f} | {row['err_field']:.3f} | {row['err_field'] / pr:.2f} | "
                  f"{row['cpu_s']:.1f} |")
        for tol, row in entry.get("auto", {}).items():
            pr = row["fidelity_expected_error_vs_reference"]
            st = row["fidelity_settings"]
            c = (f"graded {st['solid.coarsen']}-{st['solid.coarsen_max']}" if st.get("solid.mesh") == "graded"
                 else st["solid.coarsen"])
            print(f"| {name} | **auto {tol}** | {c} | {pr:.3f} | {row['err_field']:.3f} | "
                  f"{row['err_field'] / pr:.2f} | {row['cpu_s']:.1f} ({row['fidelity_expected_cpu_s']:.1f}) |")
    return 0


def auto_runs(sa, base, ref, path, tolerances, entry) -> None:
    """``auto`` at each tolerance: the choice, its predicted and achieved error, its cost."""
    from porefsi.case.fidelity import resolve_fidelity

    for tol in tolerances:
        case, choice = resolve_fidelity(base.replace(fidelity={"preset": "auto", "tolerance": tol}))
        row = measure(sa, case, ref)
        row.update(choice.summary())
        entry.setdefault("auto", {})[f"{tol:g}"] = row
        print(f"  auto tol {tol:g}: {row}", flush=True)


if __name__ == "__main__":
    raise SystemExit(main())
