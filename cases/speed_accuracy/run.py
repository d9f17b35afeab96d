"""Case ``speed_accuracy``: what each second of compute buys in the coupled run.

Every fidelity knob of the coupled run is varied one at a time from the baseline (``case.toml`` =
the default case on the first 10 s of injection), plus a few combined settings. Each run is
compared with a high-fidelity porefsi reference and timed:

- reference: coarsen 3 (65k nodes, 261k tets), P1, consistent traction interface, 0.5 s
  exchange steps, TDG 2 passes; cached in ``reference/reference.npz`` (built when missing or with
  ``--rebuild-reference``), together with a check of the reference itself against coarsen 2
  (210k nodes; quasi-static solves at 5 s and 10 s) on the nodes both meshes share;
- error: relative L2 error of the nodal displacement over a fixed set of evaluation points (the
  reference's nodes at multiples of 6 voxels, i.e. nodes shared with the coarsen-2, 3 and 6 grids)
  and over the sample times 1, 2, ..., 10 s. A run's field is interpolated trilinearly from its
  own node grid (``porefsi.coupling.update.displacement_on_grid``) and linearly in time between
  its exchange steps. Also: max displacement, max von Mises, Sw and inlet pressure at the end;
- cost: CPU time of the process (set-up + coupled loop), BLAS and numba pinned to one thread; the
  machine is shared, so CPU time is the steadier measure, wall time is recorded too.

The Pareto front (no other run is both cheaper and at least as accurate, with 1 % error and 10 %
time tolerance for noise) is marked on the chart. Outputs: ``figures/speed_accuracy.png``,
``results.json``, ``table.md`` (the table of ``docs/speed_accuracy.md``).

Usage: ``python cases/speed_accuracy/run.py [--smoke] [--out DIR] [--rebuild-reference] [--only NAME ...]``.
"""

from __future__ import annotations

import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):  # numba: see cases/_common.py
    os.environ.setdefault(_v, "1")  # before numpy/numba load: single-thread CPU time is comparable

import gc  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy import ndimage  # noqa: E402

from porefsi import (  # noqa: E402
    CoupledRun,
    DrainageSimulator,
    PorefsiError,
    __version__,
    load_case,
    problem_from_case,
    smoke_case,
)
from porefsi.case import case_to_toml  # noqa: E402
from porefsi.coupling import clear_response_cache, displacement_on_grid  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # cases/: the shared helpers
from _common import git_head, output_dir, parse_args, pyplot, write_results  # noqa: E402

HERE = Path(__file__).resolve().parent
REF_FILE = HERE / "reference" / "reference.npz"
EVAL_STRIDE = 6  # evaluation points: reference nodes at multiples of 6 voxels (shared by coarsen 2, 3, 6)
SAMPLE_DT = 1.0  # s: required output resolution (runs with longer exchange steps are shown, not ranked)
TOL_ERR, TOL_TIME = 0.01, 0.10  # Pareto tolerances: errors within 1 %, times within 10 % are ties
AUTO_TOLERANCES = (0.25, 0.3, 0.45, 0.6)  # fidelity = "auto" points on the chart (porefsi.case.fidelity)


# ---------------------------------------------------------------------------------------------
# the study design
# ---------------------------------------------------------------------------------------------
def reference_overrides(smoke: bool) -> dict:
    """The high-fidelity reference relative to the baseline."""
    return {"solid": {"coarsen": 6 if smoke else 3, "order": 1}, "interface": {"method": "traction"},
            "coupling": {"exchange_dt": 0.5, "integrator": "tdg", "tdg_iterations": 2, "tdg_load_rule": "right"}}


def variants(smoke: bool) -> list[dict]:
    """One knob at a time from the baseline, then combined settings (name, knob, label, overrides).

    The baseline is the default case (traction interface, quasi-static solid, coarsen 5, geometric
    update, 1 s steps): each knob moves away from it; the paper's own settings (hull interface,
    TDG with 2 passes, left load rule) are one of the combined runs.
    """
    def v(name, knob, label, skip=None, **ov):
        return {"name": name, "knob": knob, "label": label, "overrides": ov, "skip_solves": skip}
    if smoke:
        return [v("baseline", "baseline", "default"),
                v("tdg", "integrator", "TDG 2 passes", coupling={"integrator": "tdg"}),
                v("hull", "interface", "hull interface", interface={"method": "hull"})]
    tdg = {"integrator": "tdg"}
    out = [v("baseline", "baseline", "the default case (case.toml sets only the horizon)")]
    out += [v(f"coarsen{c}", "mesh", f"coarsen {c}", solid={"coarsen": c}) for c in (3, 4, 6, 8, 10, 12)]
    out += [v(f"p2_coarsen{c}", "order", f"P2, coarsen {c}", solid={"coarsen": c, "order": 2}) for c in (10,)]
    out += [v(f"tp{n}", "test points", f"hull, {n} test points", interface={"method": "hull", "n_test_points": n})
            for n in (100, 400, 800, 1000)]
    out += [v(f"update_{u}", "network update", f"update {u}", network={"update": u}) for u in ("reextract", "none")]
    out += [v(f"dt{d:g}", "exchange step", f"exchange dt {d:g} s", coupling={"exchange_dt": d})
            for d in (0.5, 2.0, 5.0)]
    out += [v(f"tdg{k}", "TDG passes", f"TDG {k} pass{'es' if k > 1 else ''}", coupling={**tdg, "tdg_iterations": k})
            for k in (1, 2)]
    out += [v("left", "load rule", "TDG 2 passes, left load rule (paper)",
              coupling={**tdg, "tdg_load_rule": "left"}),
            v("skip", "DPN skip", "DPN solve skipping on", skip=True),
            v("adaptive", "drainage scheme", "adaptive drainage scheme", drainage={"scheme": "adaptive"})]
    hull_tdg = {"interface": {"method": "hull"}, "coupling": tdg}
    out += [v("paper", "combined", "the paper's settings: hull 800 points, TDG 2 passes, left rule",
              interface={"method": "hull"}, coupling={**tdg, "tdg_load_rule": "left"}),
            v("old_default", "combined", "hull + TDG 2 passes (the default before this study)", **hull_tdg),
            v("hull_tdg_c6", "combined", "hull + TDG 2 passes, coarsen 6", solid={"coarsen": 6}, **hull_tdg),
            v("tdg1_c6", "combined", "TDG 1 pass, coarsen 6", solid={"coarsen": 6},
              coupling={**tdg, "tdg_iterations": 1})]
    return out


def graded_variants(smoke: bool) -> list[dict]:
    """Graded meshes refined at the predicted invasion (issue 16; docs/solid.md section 1b).

    Run by run.py only (not members of sweep.toml, like ``skip``). Their error is measured like
    every run's, on the node grid of their fine block with the grid points inside coarse leaves
    filled from the nearest node: slightly above the finite-element field's own error (0.132
    against 0.124 for ``graded_3_12``, benchmarks/bench_mesh_graded.py).
    """
    if smoke:
        return []
    graded = {"mesh": "graded", "refine": "invaded"}
    return [{"name": f"graded_{cf}_{cm}" + ("" if g == 0.5 else f"_g{g:g}") + (f"_lig{lig:g}" if lig else ""),
             "knob": "graded mesh", "skip_solves": None,
             "label": f"graded: {cf}-voxel blocks at the predicted invasion, leaves up to {cm}, grading {g:g}"
                      + (f", ligaments < {lig:g} loaded chords fine" if lig else ""),
             "overrides": {"solid": {**graded, "coarsen": cf, "coarsen_max": cm, "grading": g, "ligaments": lig}}}
            for cf, cm, g, lig in ((3, 12, 0.5, 0.0), (3, 12, 1.0, 0.0), (2, 16, 0.5, 0.0), (3, 12, 0.5, 1.0),
                                   (2, 8, 0.5, 1.0), (4, 16, 0.5, 1.0))]


def linear_variants(smoke: bool) -> list[dict]:
    """The linear-response solid (``solid.response = "auto"``: superposed unit responses; issue 16).

    ``cold``: the run computes its unit responses (a single run pays for them); ``warm``: the same
    case again in the same process, which finds them cached (what every further member of a rate
    sweep on the same image pays).
    """
    if smoke:
        return []
    out = []
    for tag, solid in (("c5", {}), ("graded_3_12", {"mesh": "graded", "refine": "invaded", "coarsen": 3,
                                                   "coarsen_max": 12, "grading": 0.5})):
        for warm in (False, True):
            out.append({"name": f"linear_{tag}_{'warm' if warm else 'cold'}", "knob": "linear response",
                        "skip_solves": None, "warm": warm,
                        "label": f"superposed unit responses, {'coarsen 5' if tag == 'c5' else 'graded 3_12'}, "
                                 f"{'responses cached (a sweep member)' if warm else 'responses computed'}",
                        "overrides": {"solid": {**solid, "response": "auto"}}})
    return out


# ---------------------------------------------------------------------------------------------
# running and comparing
# ---------------------------------------------------------------------------------------------
def run_variant(case, skip_solves=None, warm: bool = False) -> dict:
    """One coupled run: displacement at every exchange step, rows, sizes, CPU and wall time.

    The process's cached linear responses are dropped first unless ``warm``: every run pays for its own.
    """
    if not warm:
        clear_response_cache()
    gc.collect()
    c0, w0 = time.process_time(), time.perf_counter()
    res = {"status": "ok", "times": [0.0], "U": [], "rows": []}
    try:
        prob = problem_from_case(case)
        run = CoupledRun(prob)
        if skip_solves is not None:  # the DPN option drainage.skip_solves, varied here
            run.sim = DrainageSimulator(prob.network, prob.fluids, case.drainage, axis=case.image.axis,
                                        skip_solves=skip_solves)
        res["U"].append(np.zeros((prob.mesh.n_nodes, 3)))
        for rec in run.steps():
            res["times"].append(rec.t)
            res["U"].append(rec.displacement.copy())
            res["rows"].append(rec.row)
        img = prob.image
        res.update(points=prob.mesh.points, spacing=prob.node_spacing, origin=np.asarray(img.origin, float),
                   gshape=tuple(int(s) for s in np.floor(np.asarray(img.shape) * img.voxel_size / prob.node_spacing
                                                         + 1e-9).astype(int) + 1),
                   voxel_size=img.voxel_size, n_nodes=prob.mesh.n_nodes, n_tets=int(len(prob.mesh.tets)),
                   n_dofs=int(prob.model.n_dofs), stage_seconds={**{f"setup_{k}": v for k, v in prob.seconds.items()},
                                                                 **run.seconds},
                   stage_cpu_seconds={**{f"setup_{k}": v for k, v in prob.cpu_seconds.items()}, **run.cpu_seconds})
    except PorefsiError as exc:
        res["status"] = f"{type(exc).__name__}: {exc}"
    res["cpu_s"] = time.process_time() - c0
    res["wall_s"] = time.perf_counter() - w0
    res["times"] = np.array(res["times"])
    return res


def at_time(res: dict, t: float) -> np.ndarray:
    """Nodal displacement (Nn, 3) of a run at time t, linear in time between its exchange steps."""
    ts = res["times"]
    k = int(np.searchsorted(ts, t - 1e-9))
    if k < len(ts) and abs(ts[k] - t) < 1e-9:
        return res["U"][k]
    if k == 0 or k >= len(ts):
        raise ValueError(f"t = {t} outside the run's times [{ts[0]}, {ts[-1]}]")
    w = (t - ts[k - 1]) / (ts[k] - ts[k - 1])
    return (1 - w) * res["U"][k - 1] + w * res["U"][k]


def on_points(res: dict, U: np.ndarray, X: np.ndarray) -> np.ndarray:
    """A run's nodal field U (Nn, 3) at points X (M, 3): trilinear on its node grid (pores filled nearest)."""
    grid = displacement_on_grid(res["points"], U, res["spacing"], res["gshape"], res["origin"])
    g = ((X - res["origin"]) / res["spacing"]).T
    return np.stack([ndimage.map_coordinates(grid[..., d], g, order=1, mode="nearest") for d in range(3)], axis=1)


def rel_l2(parts_err, parts_ref) -> float:
    """sqrt(sum |e|^2 / sum |r|^2) over lists of arrays."""
    num = sum(float(np.sum(e ** 2)) for e in parts_err)
    den = sum(float(np.sum(r ** 2)) for r in parts_ref)
    return float(np.sqrt(num / den)) if den > 0 else float("nan")


def final_scalars(res: dict) -> dict:
    """End-of-run max displacement, max von Mises, Sw, inlet pressure."""
    r = res["rows"][-1]
    return {"max_displacement_m": r["max_displacement_m"], "max_von_mises_Pa": r["max_von_mises_Pa"],
            "sw": r["sw"], "inlet_pressure_Pa": r["inlet_pressure_Pa"]}


def eval_points(res: dict) -> np.ndarray:
    """Reference nodes on the multiples of EVAL_STRIDE voxels (exact nodes of coarsen 2, 3 and 6)."""
    ijk = np.rint((res["points"] - res["origin"]) / res["voxel_size"]).astype(np.int64)
    keep = np.all(ijk % EVAL_STRIDE == 0, axis=1)
    return np.flatnonzero(keep)


def build_reference(base, smoke: bool, sample_times) -> dict:
    """Run the reference; return evaluation points, sampled fields and scalars (and the coarsen-2 check)."""
    case = base.replace(name=f"{base.name}-reference", **reference_overrides(smoke))
    res = run_variant(case)
    if res["status"] != "ok":
        raise RuntimeError(f"reference run failed: {res['status']}")
    idx = eval_points(res)
    ref = {"points": res["points"][idx], "times": np.asarray(sample_times, float),
           "u": np.stack([at_time(res, t)[idx] for t in sample_times]), "case_toml": case_to_toml(case),
           "porefsi_version": __version__, "commit": git_head(),
           "built_utc": time.strftime("%Y-%m-%d %H:%M", time.gmtime()),
           "cpu_s": res["cpu_s"], "wall_s": res["wall_s"], "n_nodes": res["n_nodes"], "n_tets": res["n_tets"],
           **{k: v for k, v in final_scalars(res).items()}}
    return ref


def reference_stale(ref: dict, base, smoke: bool) -> str | None:
    """Why a cached reference no longer fits the study (None: it does).

    It must have been built from the reference case the current code makes of ``case.toml`` (the
    whole case file, every key, as ``case_to_toml`` writes it: a new key or a changed default
    makes it stale). The commit it was built at is recorded and printed, not compared: most
    commits do not touch the solution, so a code change that does must be judged (and the
    reference rebuilt with ``--rebuild-reference``).
    """
    want = case_to_toml(base.replace(name=f"{base.name}-reference", **reference_overrides(smoke)))
    if _without_fidelity(ref.get("case_toml", "")) != _without_fidelity(want):
        return "its case differs from the reference case of the current case.toml and code"
    return None


def _without_fidelity(toml: str) -> str:
    """Case text without a ``[fidelity]`` section that sets no preset (it changes nothing in the run)."""
    head, sep, rest = toml.partition("\n[fidelity]\n")
    if not sep:
        return toml
    body, nxt, tail = rest.partition("\n[")
    if 'preset = "none"' not in body:
        return toml
    return head + ("\n[" + tail if nxt else "\n")


def auto_variants(base, smoke: bool) -> list[dict]:
    """``fidelity = "auto"`` at each of :data:`AUTO_TOLERANCES`: the settings it chooses on this image."""
    from porefsi.case import FIDELITY_KEYS, resolve_fidelity

    out = []
    for tol in AUTO_TOLERANCES[:1] if smoke else AUTO_TOLERANCES:
        case, choice = resolve_fidelity(base.replace(fidelity={"preset": "auto", "tolerance": tol}))
        ov: dict = {}
        for key in FIDELITY_KEYS:
            sec, k = key.split(".")
            if getattr(getattr(case, sec), k) != getattr(getattr(base, sec), k):
                ov.setdefault(sec, {})[k] = getattr(getattr(case, sec), k)
        out.append({"name": f"auto{tol:g}", "knob": "auto", "overrides": ov, "skip_solves": None,
                    "label": f"fidelity auto, tolerance {tol:g} (expected {choice.expected_error_vs_reference:.2f} "
                             "vs this reference)",
                    "expected_err_vs_reference": choice.expected_error_vs_reference,
                    "expected_cpu_s": choice.expected_cpu_s})
    return out


def check_reference(base, ref: dict) -> dict:
    """How far the reference is from coarsen 2 (one quasi-static solve at the last sample time).

    The evaluation points lie on multiples of 6 voxels, i.e. on nodes of both meshes, so this is a
    node-to-node comparison (no interpolation). AMG-CG keeps the memory at ~3 GB (a direct
    factorisation of the 600k dofs needs far more); ~1-2 min CPU.
    """
    t_end = float(ref["times"][-1])
    case = base.replace(name=f"{base.name}-reference-check", solid={"coarsen": 2, "linear_solver": "amg"},
                        interface={"method": "traction"},
                        coupling={"integrator": "static", "exchange_dt": t_end})
    chk = run_variant(case)
    if chk["status"] != "ok":
        return {"status": chk["status"]}
    uc = on_points(chk, at_time(chk, t_end), ref["points"])
    return {"coarsen": 2, "t_s": t_end, "n_nodes": chk["n_nodes"], "n_tets": chk["n_tets"], "cpu_s": chk["cpu_s"],
            "rel_l2_ref_vs_coarsen2": rel_l2([ref["u"][-1] - uc], [uc]),
            **{f"c2_{k}": v for k, v in final_scalars(chk).items()}}


def save_reference(ref: dict, path: Path) -> None:
    """Cache the reference (float32 fields: ~1 MB)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    meta = {k: v for k, v in ref.items() if k not in ("points", "times", "u")}
    np.savez_compressed(path, points=ref["points"], times=ref["times"], u=ref["u"].astype(np.float32),
                        meta=np.array(json.dumps(meta)))


def load_reference(path: Path) -> dict:
    """Read a cached reference."""
    with np.load(path) as z:
        ref = {"points": z["points"], "times": z["times"], "u": z["u"].astype(float)}
        ref.update(json.loads(str(z["meta"])))
    return ref


def compare(res: dict, ref: dict, base_res: dict | None) -> dict:
    """Errors of one run against the reference (and its difference from the baseline on the same mesh)."""
    X = ref["points"]
    uh = [on_points(res, at_time(res, t), X) for t in ref["times"]]
    out = {"err_field": rel_l2([a - b for a, b in zip(uh, ref["u"], strict=True)], list(ref["u"])),
           "err_final": rel_l2([uh[-1] - ref["u"][-1]], [ref["u"][-1]])}
    fs = final_scalars(res)
    for k in ("max_displacement_m", "max_von_mises_Pa", "inlet_pressure_Pa"):
        out[f"err_{k}"] = (fs[k] - ref[k]) / ref[k]
    out["sw_minus_ref"] = fs["sw"] - ref["sw"]
    out.update(fs)
    if base_res is not None and base_res.get("n_nodes") == res.get("n_nodes") and \
            np.array_equal(base_res["points"], res["points"]):
        out["diff_vs_baseline"] = rel_l2([at_time(res, t) - at_time(base_res, t) for t in ref["times"]],
                                         [at_time(base_res, t) for t in ref["times"]])
    return out


def _exchange_dt(base, overrides: dict) -> float:
    """Exchange step of a variant (its override, else the baseline's)."""
    return float(overrides.get("coupling", {}).get("exchange_dt", base.coupling.exchange_dt))


def pareto(cost, err, tol_err: float = TOL_ERR, tol_time: float = TOL_TIME) -> np.ndarray:
    """Mask of the points no other point dominates (ties within the tolerances are not dominance).

    ``a`` dominates ``b`` if it is no worse in both (``err_a <= (1+tol_err) err_b``,
    ``cost_a <= (1+tol_time) cost_b``) and clearly better in one (``err_a < (1-tol_err) err_b`` or
    ``cost_a < (1-tol_time) cost_b``).
    """
    c, e = np.asarray(cost, float), np.asarray(err, float)
    n = len(c)
    keep = np.ones(n, bool)
    for b in range(n):
        for a in range(n):
            if a == b:
                continue
            no_worse = e[a] <= (1 + tol_err) * e[b] and c[a] <= (1 + tol_time) * c[b]
            better = e[a] < (1 - tol_err) * e[b] or c[a] < (1 - tol_time) * c[b]
            if no_worse and better:
                keep[b] = False
                break
    return keep


def recommend(rows: list[dict]) -> dict:
    """Cheapest Pareto point at least as accurate as the baseline (within the error tolerance)."""
    ok = [r for r in rows if r["status"] == "ok"]
    base = next(r for r in ok if r["name"] == "baseline")
    front = [r for r in ok if r["pareto"]]
    good = [r for r in front if r["err_field"] <= (1 + TOL_ERR) * base["err_field"]]
    best = min(good, key=lambda r: r["cpu_s"]) if good else None
    return {"baseline_on_front": bool(base["pareto"]), "baseline_err": base["err_field"],
            "baseline_cpu_s": base["cpu_s"],
            "recommended": None if best is None else {k: best[k] for k in ("name", "label", "overrides", "err_field",
                                                                             "cpu_s")},
            "front": [r["name"] for r in sorted(front, key=lambda r: r["cpu_s"])]}


# ---------------------------------------------------------------------------------------------
# outputs
# ---------------------------------------------------------------------------------------------
KNOB_STYLE = {"baseline": ("k", "*"), "mesh": ("C0", "o"), "order": ("C1", "s"), "test points": ("C2", "^"),
              "interface": ("C3", "D"), "network update": ("C4", "v"), "exchange step": ("C5", "<"),
              "TDG passes": ("C6", ">"), "integrator": ("C7", "P"), "load rule": ("C8", "X"),
              "DPN skip": ("C9", "h"), "combined": ("navy", "d"), "graded mesh": ("darkgreen", "p"),
              "linear response": ("olive", "H"), "drainage scheme": ("teal", "8"), "auto": ("red", "*")}


def plot(rows: list[dict], ref: dict, path: Path) -> None:
    """Error vs CPU time (log-log) with the Pareto front; same-mesh differences from the default."""
    plt = pyplot()
    ok = [r for r in rows if r["status"] == "ok" and r["err_field"] > 1e-6]  # not the reference's own mesh (0)
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(14, 6), gridspec_kw={"width_ratios": [1.6, 1]})
    seen = set()
    for r in ok:
        col, mk = KNOB_STYLE.get(r["knob"], ("grey", "o"))
        lab = r["knob"] if r["knob"] not in seen else None
        seen.add(r["knob"])
        hollow = not r.get("meets_output_resolution", True)
        ax.scatter(r["cpu_s"], r["err_field"], c="none" if hollow else col, marker=mk,
                   s=160 if r["knob"] == "baseline" else 55, edgecolors="k" if r["pareto"] else col,
                   linewidths=1.2, label=lab, zorder=3)
        labelled = ("baseline", "mesh", "order", "combined", "graded mesh", "linear response")
        if r["knob"] == "auto":
            ax.annotate(f"{r['name']} (exp. {r['expected_err_vs_reference']:.2f})", (r["cpu_s"], r["err_field"]),
                        fontsize=6.5, xytext=(3, -9), textcoords="offset points", color="red")
        elif r["pareto"] or r["knob"] in labelled or r["name"] == "update_reextract":
            ax.annotate(r["name"], (r["cpu_s"], r["err_field"]), fontsize=6.5, xytext=(3, 3),
                        textcoords="offset points")
    fr = sorted([r for r in ok if r["pareto"]], key=lambda r: r["cpu_s"])
    if fr:
        xs, ys = [fr[0]["cpu_s"]], [fr[0]["err_field"]]
        for r in fr[1:]:
            xs += [r["cpu_s"], r["cpu_s"]]
            ys += [ys[-1], r["err_field"]]
        ax.plot(xs, ys, "k--", lw=1, zorder=2, label="Pareto front (black outline)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("CPU time of set-up + coupled run, s (one thread; shared machine)")
    ax.set_ylabel("relative L2 error of displacement (all nodes, all sample times)")
    ax.set_title(f"speed vs accuracy, reference coarsen {_ref_coarsen(ref)} traction ({ref['n_nodes']} nodes)\n"
                 "hollow: exchange step > 1 s (coarser outputs than the scene needs; not ranked)", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    lo = min(r["err_field"] for r in ok)
    ax.set_ylim(lo / 3.5, None)  # room for the legend below the most accurate run
    ax.legend(fontsize=6.5, loc="lower right", framealpha=0.85, ncol=3)
    same = [r for r in ok if r.get("diff_vs_baseline") and r["name"] != "baseline"]  # 0: the default itself
    if same:
        vals = [r["diff_vs_baseline"] for r in same]
        cols = [KNOB_STYLE.get(r["knob"], ("grey", "o"))[0] for r in same]
        yy = np.arange(len(same))
        ax2.barh(yy, vals, color=cols)
        ax2.set_yticks(yy, [r["label"] for r in same], fontsize=7)
        ax2.set_xscale("log")
        ax2.set_xlabel("relative L2 difference from the default run (same mesh)")
        e0 = next(r["err_field"] for r in ok if r["name"] == "baseline")
        ax2.axvline(e0, color="k", ls=":", lw=1)
        ax2.text(e0, len(same) - 0.5, " default's error\n vs reference", fontsize=7, va="top", ha="right")
        ax2.set_title("knobs that keep the mesh: change vs default", fontsize=10)
        ax2.grid(True, axis="x", which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def _ref_coarsen(ref: dict) -> str:
    for line in ref["case_toml"].splitlines():
        if line.startswith("coarsen"):
            return line.split("=")[1].strip()
    return "?"


def table(rows: list[dict]) -> str:
    """Markdown table of every run."""
    hd = ("| run | knob | setting | CPU s | wall s | error (field, all t) | error (final) | max u | max vM | "
          "Sw | P_in | Δ vs default (same mesh) | Pareto |\n"
          "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|:-:|")
    lines = [hd]
    for r in rows:
        if r["status"] != "ok":
            lines.append(f"| {r['name']} | {r['knob']} | {r['label']} | {r['cpu_s']:.1f} | {r['wall_s']:.1f} | "
                         f"failed: {r['status'][:80]} | | | | | | | |")
            continue
        d = r.get("diff_vs_baseline")
        lines.append(
            f"| {r['name']} | {r['knob']} | {r['label']} | {r['cpu_s']:.1f} | {r['wall_s']:.1f} | "
            f"{r['err_field']:.3f} | {r['err_final']:.3f} | {r['err_max_displacement_m']:+.1%} | "
            f"{r['err_max_von_mises_Pa']:+.1%} | {r['sw']:.4f} | {r['inlet_pressure_Pa']:.0f} | "
            f"{'' if d is None else f'{d:.1e}'} | {_front_mark(r)} |")
    return "\n".join(lines) + "\n"


def _front_mark(r: dict) -> str:
    if r["pareto"]:
        return "**yes**"
    if not r.get("meets_output_resolution", True):
        return "(not ranked)"
    return ""


def _arguments(p) -> None:
    p.add_argument("--rebuild-reference", action="store_true", help="recompute the cached reference")
    p.add_argument("--check-reference", action="store_true",
                   help="also compare the reference with a coarsen-2 quasi-static solve (~2 min CPU, several GB)")
    p.add_argument("--replot", action="store_true", help="redraw the figure and table from results.json")
    p.add_argument("--only", nargs="*", default=None, help="run only these variants (plus the baseline)")


def main(argv=None) -> int:
    """Run the study."""
    args = parse_args(__doc__, argv, _arguments,
                      smoke_help="seconds-long version (coarsen 10 runs, coarsen 6 reference)")
    out = output_dir(args, HERE)
    if args.replot:
        summary = json.loads((out / "results.json").read_text())
        order = {v["name"]: i for i, v in enumerate(variants(False) + graded_variants(False) + linear_variants(False))}
        summary["runs"].sort(key=lambda r: order.get(r["name"], len(order)))  # the study's order, auto last
        (out / "table.md").write_text(table(summary["runs"]))
        plot(summary["runs"], summary["reference"], out / "figures" / "speed_accuracy.png")
        return 0
    base = load_case(HERE / "case.toml")
    if args.smoke:
        base = smoke_case(base)
    sample_times = list(np.arange(SAMPLE_DT, base.drainage.t_end + 1e-9, SAMPLE_DT))
    run_variant(smoke_case(base).replace(drainage={"t_end": 1.0}))  # warm-up: numba cache loads, imports
    ref_path = out / "reference" / "reference.npz" if args.smoke else REF_FILE
    stale = None
    if not (args.smoke or args.rebuild_reference) and ref_path.exists():
        cached = load_reference(ref_path)
        stale = reference_stale(cached, base, args.smoke)
        print(f"cached reference: built {cached.get('built_utc', 'before build dates were recorded')} at commit "
              f"{cached.get('commit', 'not recorded')}; {'stale: ' + stale if stale else 'case matches'}", flush=True)
    if args.smoke or args.rebuild_reference or stale or not ref_path.exists():
        print("building the reference ...", flush=True)
        ref = build_reference(base, args.smoke, sample_times)
        if not args.smoke:
            save_reference(ref, ref_path)
        print(f"reference: {ref['n_nodes']} nodes, {ref['cpu_s']:.1f} s CPU", flush=True)
    ref = load_reference(ref_path) if ref_path.exists() else ref
    if args.check_reference and not args.smoke:
        print("checking the reference against coarsen 2 ...", flush=True)
        ref["check"] = check_reference(base, ref)
        save_reference(ref, ref_path)
        print(f"check: {ref['check']}", flush=True)
    vs = (variants(args.smoke) + graded_variants(args.smoke) + linear_variants(args.smoke)
          + auto_variants(base, args.smoke))
    if args.only:
        vs = [v for v in vs if v["name"] == "baseline" or v["name"] in args.only]
    rows, base_res = [], None
    for v in vs:
        case = base.replace(name=f"{base.name}-{v['name']}", **v["overrides"])
        res = run_variant(case, v["skip_solves"], v.get("warm", False))
        row = {k: v[k] for k in ("name", "knob", "label", "overrides", "expected_err_vs_reference",
                                  "expected_cpu_s") if k in v}
        row.update(status=res["status"], cpu_s=res["cpu_s"], wall_s=res["wall_s"], n_nodes=res.get("n_nodes"),
                   n_tets=res.get("n_tets"), n_dofs=res.get("n_dofs"), stage_seconds=res.get("stage_seconds"),
                   stage_cpu_seconds=res.get("stage_cpu_seconds"), load=os.getloadavg())
        if res["status"] == "ok":
            row.update(compare(res, ref, base_res))
        if v["name"] == "baseline":
            base_res = res
        rows.append(row)
        print(f"{v['name']:>18}: {res['status'][:60]:<8} CPU {res['cpu_s']:6.1f} s  wall {res['wall_s']:6.1f} s  "
              f"err {row.get('err_field', float('nan')):.4f}  dbase {row.get('diff_vs_baseline', float('nan')):.1e}",
              flush=True)
        del res
    if args.only and (out / "results.json").is_file():  # the other runs of the last full study stay, in place
        ran = {r["name"]: r for r in rows}
        old = json.loads((out / "results.json").read_text())["runs"]
        rows = [ran.get(r["name"], r) for r in old] + [r for r in rows if r["name"] not in {o["name"] for o in old}]
    for r in rows:  # the scene needs outputs every SAMPLE_DT (the paper's figures at 1, 3, 5, 15 s)
        r["meets_output_resolution"] = _exchange_dt(base, r["overrides"]) <= SAMPLE_DT + 1e-12
    # ranked: outputs every SAMPLE_DT, and not the reference's own mesh (coarsen 3: error ~1e-8 by construction)
    ok = [r for r in rows if r["status"] == "ok" and r["meets_output_resolution"] and r["err_field"] > 1e-6]
    mask = pareto([r["cpu_s"] for r in ok], [r["err_field"] for r in ok])
    for r, m in zip(ok, mask, strict=True):
        r["pareto"] = bool(m)
    ok_all = [r for r in rows if r["status"] == "ok" and r["err_field"] > 1e-6]
    mask_all = pareto([r["cpu_s"] for r in ok_all], [r["err_field"] for r in ok_all])
    for r, m in zip(ok_all, mask_all, strict=True):
        r["pareto_without_resolution_requirement"] = bool(m)
    for r in rows:
        r.setdefault("pareto", False)
    rec = recommend(rows)
    meta = {k: v for k, v in ref.items() if k not in ("points", "times", "u")}
    summary = {"case": "speed_accuracy", "smoke": args.smoke, "sample_times_s": sample_times,
               "n_eval_points": int(len(ref["points"])), "reference": meta, "tolerances": {"err": TOL_ERR,
                                                                                          "time": TOL_TIME},
               "recommendation": rec, "runs": rows}
    previous = json.loads((out / "results.json").read_text()) if (out / "results.json").is_file() else {}
    if "permeability" in previous:  # permeability.py's part of the study (its own script) is kept
        summary["permeability"] = previous["permeability"]
    write_results(out / "results.json", summary)
    (out / "table.md").write_text(table(rows))
    plot(rows, ref, out / "figures" / "speed_accuracy.png")
    print(json.dumps(rec, indent=1, default=float))
    print(f"outputs in {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
