"""Verification (seed paper section 3.4, figure 17) and the analytic verification set.

1. High-fidelity comparison: porefsi at its default fidelity (``Case()``: P1, coarsen 5, consistent
   traction interface, quasi-static solid, 1 s exchange steps), at the paper's settings (coarsen 5,
   convex-hull interface, TDG) and at cheaper/finer alternatives against a high-fidelity porefsi
   reference (coarsen 3: 4.3x the nodes of coarsen 5, traction interface, quasi-static Newton solve
   at every exchange time), compared at t = 17 s, the third-to-last step of the 20 s run (the
   paper's ||d_{T-3}||). Two measures: (a) node by node on the nodes a run shares with the
   reference (a coarsen-c mesh has its nodes on the grid of c voxels: coarsen 4 and 6 share the
   multiples of 12 and 6 voxels with coarsen 3, coarsen 5 only the multiples of 15); (b) on every
   reference node, each run's field interpolated trilinearly from its own node grid (the same
   points for every run, so rows compare). The reference is cached in ``reference/`` with its case
   TOML, time and code revision (reused while its case is unchanged; ``--no-cache`` recomputes and
   overwrites it).
2. Analytic set (``analytic.py``): Lamé cavity, Washburn, invasion-percolation limit, TDG order.

Usage: python cases/verification/run.py [--smoke] [--out DIR] [--no-cache]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy import ndimage

from porefsi.case.config import case_to_toml, load_case, smoke_case
from porefsi.coupling.loop import CoupledRun
from porefsi.coupling.problem import build_problem
from porefsi.coupling.update import displacement_on_grid

HERE = Path(__file__).resolve().parent


def _load_analytic():
    """``analytic.py`` next to this script (the case folder is not a package)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("verification_analytic", HERE / "analytic.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


analytic = _load_analytic()
T_COMPARE = 17.0  # s: step T-3 of the 20-step run

# name -> (coarsen, interface, integrator, exchange_dt)
REFERENCE = ("reference", 3, "traction", "static", 1.0)
RUNS = (
    ("default (c5, traction, static)", 5, "traction", "static", 1.0),
    ("paper (c5, hull, TDG)", 5, "hull", "tdg", 1.0),
    ("c5, traction, TDG", 5, "traction", "tdg", 1.0),
    ("c4, traction, static", 4, "traction", "static", 1.0),
    ("c4, hull, TDG (old default)", 4, "hull", "tdg", 1.0),
    ("c6, traction, static", 6, "traction", "static", 1.0),
    ("c6, hull, TDG", 6, "hull", "tdg", 1.0),
    ("c6, traction, TDG, dt 0.5 s", 6, "traction", "tdg", 0.5),
)
SMOKE_REFERENCE = ("reference", 5, "traction", "static", 1.0)
SMOKE_RUNS = (("c10, traction, static", 10, "traction", "static", 1.0), ("c10, hull, TDG", 10, "hull", "tdg", 1.0))
SELECT_STRIDE = 12  # selected nodes: reference nodes on multiples of 12 voxels (nodes of coarsen 3, 4, 6)


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def make_case(base, spec, t_end):
    _, coarsen, method, integ, dt = spec
    return base.replace(solid={"coarsen": coarsen}, interface={"method": method},
                        coupling={"integrator": integ, "exchange_dt": dt}, drainage={"t_end": t_end},
                        output={"snapshot_times": [], "vtk": False, "figures": False})


def run_coupled(case) -> dict:
    """Coupled run to ``case.drainage.t_end``; node grid indices and the final displacement."""
    t0, c0 = time.perf_counter(), time.process_time()
    p = build_problem(case)
    run = CoupledRun(p)
    rec = None
    for rec in run.steps():  # noqa: B007 - the last record is the one compared
        pass
    grid = np.rint((p.mesh.points - p.image.origin) / p.image.voxel_size).astype(np.int64)
    return {"grid": grid, "u": rec.displacement, "t": rec.t, "n_nodes": p.mesh.n_nodes, "n_tets": p.mesh.n_tets,
            "coarsen": int(case.solid.coarsen),
            "wall_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0,
            "max_u": float(np.linalg.norm(rec.displacement, axis=1).max()), "shape": p.image.shape}


def reference(case, cache: Path | None, refresh: bool = False) -> dict:
    """The reference run: read from ``cache`` when it holds this exact case, else run it and write it.

    ``refresh=True`` ignores the cached run and overwrites it (after a code change that the case TOML
    cannot see).
    """
    toml = case_to_toml(case)
    if cache is not None and cache.is_file() and not refresh:
        d = np.load(cache, allow_pickle=False)
        if str(d["case_toml"]) == toml:
            return {"grid": d["grid"].astype(np.int64), "u": d["u"], "t": float(d["t"]),
                    "n_nodes": int(d["n_nodes"]), "n_tets": int(d["n_tets"]), "wall_s": float(d["wall_s"]),
                    "cpu_s": float(d["cpu_s"]), "max_u": float(d["max_u"]), "cached": True,
                    "computed": str(d["computed"]) if "computed" in d else "unknown",
                    "code": str(d["code"]) if "code" in d else "unknown"}
    ref = run_coupled(case)
    ref["computed"] = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    ref["code"] = _git_head()
    if cache is not None:
        cache.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(cache, grid=ref["grid"].astype(np.int16), u=ref["u"], t=ref["t"],
                            n_nodes=ref["n_nodes"], n_tets=ref["n_tets"], wall_s=ref["wall_s"], cpu_s=ref["cpu_s"],
                            max_u=ref["max_u"], case_toml=np.array(toml), computed=np.array(ref["computed"]),
                            code=np.array(ref["code"]))
    ref["cached"] = False
    return ref


def _git_head() -> str:
    """The checkout's commit (12 hex digits, '+dirty' with local changes), or 'unknown'."""
    import subprocess

    try:
        head = subprocess.run(["git", "rev-parse", "--short=12", "HEAD"], cwd=HERE, capture_output=True,
                              text=True, timeout=10, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "porefsi"], cwd=HERE.parent.parent,
                               capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return head + ("+dirty" if dirty else "")


def _ids(grid, n=1024):
    return (grid[:, 0] * n + grid[:, 1]) * n + grid[:, 2]


def _coarsen(r: dict) -> int:
    """A run's node spacing in voxels: its ``coarsen``, else the common divisor of its node grid."""
    if "coarsen" in r:
        return int(r["coarsen"])
    return max(int(np.gcd.reduce(np.asarray(r["grid"], np.int64).ravel())), 1)


def on_voxel_points(r: dict, grid_pts: np.ndarray) -> np.ndarray:
    """A run's nodal field at points given in voxel units (M, 3): trilinear on its node grid.

    Exact at the run's own nodes; grid corners inside pores take the nearest node's value
    (:func:`~porefsi.coupling.update.displacement_on_grid`).
    """
    c = _coarsen(r)
    gshape = tuple(int(g) for g in r["grid"].max(axis=0) // c + 1)
    field = displacement_on_grid(r["grid"] / c, r["u"], 1.0, gshape)
    x = (np.asarray(grid_pts, float) / c).T
    return np.stack([ndimage.map_coordinates(field[..., d], x, order=1, mode="nearest") for d in range(3)], axis=1)


def compare(ref: dict, runs: dict, n_select: int = 12) -> dict:
    """Errors against the reference: on shared nodes (exact) and on all reference nodes (interpolated).

    The selected nodes (figure 17's role) are the ``n_select`` reference nodes of largest |u| on
    multiples of ``SELECT_STRIDE`` voxels (nodes of coarsen 3, 4 and 6; coarsen 5 is interpolated).
    """
    rid = _ids(ref["grid"])
    ref_norm = float(np.linalg.norm(ref["u"]))
    out = {}
    for name, r in runs.items():
        ids = _ids(r["grid"])
        shared, ia, ib = np.intersect1d(ids, rid, return_indices=True)
        d = r["u"][ia] - ref["u"][ib]
        d_all = on_voxel_points(r, ref["grid"]) - ref["u"]
        out[name] = {"n_shared_nodes": int(shared.size),
                     "rel_error_shared": float(np.linalg.norm(d) / np.linalg.norm(ref["u"][ib])),
                     "rel_error_all_interp": float(np.linalg.norm(d_all) / ref_norm),
                     "max_u_ratio": r["max_u"] / ref["max_u"], "wall_s": r["wall_s"], "cpu_s": r["cpu_s"],
                     "n_nodes": r["n_nodes"], "n_tets": r["n_tets"], "coarsen": _coarsen(r)}
    cand = np.flatnonzero(np.all(ref["grid"] % SELECT_STRIDE == 0, axis=1))
    mag = np.linalg.norm(ref["u"][cand], axis=1)
    ib = cand[np.argsort(mag)[::-1][:n_select]]
    table = {"reference": np.linalg.norm(ref["u"][ib], axis=1)}
    for name, r in runs.items():
        us = on_voxel_points(r, ref["grid"][ib])
        table[name] = np.linalg.norm(us, axis=1)
        out[name]["rel_error_selected"] = float(np.linalg.norm(us - ref["u"][ib]) / np.linalg.norm(ref["u"][ib]))
    return {"errors": out, "selected_grid": ref["grid"][ib].tolist(), "selected_norms": table,
            "n_reference_nodes": int(len(rid)), "select_stride_voxels": SELECT_STRIDE}


def figures(cmp: dict, ref_spec, lame, wash, ip, tdg, fig_dir: Path) -> list[str]:
    plt = _plt()
    fig_dir.mkdir(parents=True, exist_ok=True)
    made = []
    # figure 17 role: |u| at selected nodes
    tab = cmp["selected_norms"]
    names = list(tab)
    n = len(tab["reference"])
    w = 0.8 / len(names)
    fig, ax = plt.subplots(figsize=(14, 5))
    for i, name in enumerate(names):
        lab = f"reference (c{ref_spec[1]}, traction, static)" if name == "reference" else name
        ax.bar(np.arange(n) + (i - len(names) / 2 + 0.5) * w, np.asarray(tab[name]) * 1e12, w, label=lab)
    ax.set_xticks(np.arange(n), [f"{g}" for g in cmp["selected_grid"]], rotation=45, fontsize=7)
    ax.set_xlabel("node (voxel-grid position)")
    ax.set_ylabel(f"|u| at t = {T_COMPARE:g} s (pm)")
    ax.legend(fontsize=7, ncol=2)
    ax.grid(alpha=0.3, axis="y")
    fig.tight_layout()
    made.append(fig_dir / "high_fidelity_nodes.png")
    fig.savefig(made[-1], dpi=120)
    plt.close(fig)
    # error vs cost
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    for name, e in cmp["errors"].items():
        ax.loglog(e["cpu_s"], e["rel_error_all_interp"], "o")
        ax.annotate(name, (e["cpu_s"], e["rel_error_all_interp"]), fontsize=7)
    ax.set_xlabel("CPU time of set-up + run (s, one thread, shared machine)")
    ax.set_ylabel("relative L2 displacement error, all reference nodes")
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    made.append(fig_dir / "high_fidelity_error_vs_time.png")
    fig.savefig(made[-1], dpi=120)
    plt.close(fig)
    # Lamé
    fig, ax = plt.subplots(figsize=(6, 4))
    nn = np.asarray(lame["n"])
    lo, hi = np.asarray(lame["lame_inscribed_J"]), np.asarray(lame["lame_circumscribed_J"])
    mid = 0.5 * (lo + hi)
    ax.fill_between(nn, lo / mid, hi / mid, color="0.85", label="Lamé bounds (clamped sphere b = L ... √3 L)")
    ax.plot(nn, np.asarray(lame["traction_J"]) / mid, "o-", label="traction interface")
    ax.plot(nn, np.asarray(lame["hull_J"]) / mid, "s-", label="convex-hull interface (paper)")
    ax.set_xlabel("cube edge N (voxels); cavity radius 0.2 N")
    ax.set_ylabel("work P ΔV / mid-bound")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    made.append(fig_dir / "lame_cavity.png")
    fig.savefig(made[-1], dpi=120)
    plt.close(fig)
    # Washburn
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(wash["l_m"] * 1e3, wash["t_washburn_s"] * 1e3, "-", label="Washburn l² = σ r cosθ t / 2μ")
    ax.plot(wash["l_m"] * 1e3, wash["t_porefsi_s"] * 1e3, "o", ms=4, label="porefsi, inviscid defender")
    ax.plot(wash["l_m"] * 1e3, wash["t_two_fluid_s"] * 1e3, "-", label="two fluids, constant ΔP (closed form)")
    ax.plot(wash["l_m"] * 1e3, wash["t_porefsi_two_fluid_s"] * 1e3, "s", ms=4, label="porefsi, two fluids")
    ax.set_xlabel("front position l (mm)")
    ax.set_ylabel("fill time (ms)")
    ax.set_title(f"max rel. error {wash['max_rel_error_washburn']:.1e} / {wash['max_rel_error_two_fluid']:.1e}")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    made.append(fig_dir / "washburn.png")
    fig.savefig(made[-1], dpi=120)
    plt.close(fig)
    # IP limit
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.semilogx(ip["ca"], ip["prefix_fraction"].mean(axis=0), "o-", label="identical prefix of the IP order")
    ax.semilogx(ip["ca"], ip["jaccard"].mean(axis=0), "s-", label="pores invaded by breakthrough (Jaccard)")
    ax.axvline(1e-7, color="k", ls=":", label="paper's rate on the sample, Ca ≈ 1e-7")
    ax.set_xlabel("capillary number Ca")
    ax.set_ylabel(f"agreement with IP (mean of {len(ip['seeds'])} lattices)")
    ax.set_ylim(0, 1.05)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    made.append(fig_dir / "ip_limit.png")
    fig.savefig(made[-1], dpi=120)
    plt.close(fig)
    # TDG order
    fig, ax = plt.subplots(figsize=(6, 4))
    for name, e in tdg["errors"].items():
        ax.loglog(tdg["dt"], e, "o-", label=f"{name}: slope {tdg['orders'][name]:.2f}")
    ax.set_xlabel("dt (s)")
    ax.set_ylabel("error at t = 2 s (energy norm)")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    made.append(fig_dir / "tdg_order.png")
    fig.savefig(made[-1], dpi=120)
    plt.close(fig)
    return [m.name for m in made]


def _json(x):
    if isinstance(x, dict):
        return {k: _json(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_json(v) for v in x]
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.generic):
        return x.item()
    return x


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--smoke", action="store_true", help="seconds-long version (coarse meshes, 2 steps)")
    ap.add_argument("--out", type=Path, default=None, help="output directory (default: this folder)")
    ap.add_argument("--no-cache", action="store_true",
                    help="recompute the high-fidelity reference and overwrite its cache")
    args = ap.parse_args(argv)
    out = args.out or (Path(tempfile.mkdtemp(prefix="porefsi-verification-")) if args.smoke else HERE)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    base = load_case(HERE / "case.toml")
    if args.smoke:
        base = smoke_case(base)
        ref_spec, specs, t_end = SMOKE_REFERENCE, SMOKE_RUNS, base.drainage.t_end
        cache = out / "reference" / "smoke_reference.npz"
    else:
        ref_spec, specs, t_end = REFERENCE, RUNS, T_COMPARE
        cache = HERE / "reference" / "reference_c3_traction_static.npz"
    ref = reference(make_case(base, ref_spec, t_end), cache, refresh=args.no_cache)
    runs = {s[0]: run_coupled(make_case(base, s, t_end)) for s in specs}
    cmp = compare(ref, runs)
    if args.smoke:
        lame = analytic.study_lame(n_cells=(12, 16))
        ip = analytic.study_ip_limit(cas=(1e-8, 1e-5), shape=(5, 5, 2), seeds=(0,))
    else:
        lame = analytic.study_lame(n_cells=(12, 16, 20, 24, 28))
        ip = analytic.study_ip_limit()
    wash = analytic.study_washburn()
    tdg = analytic.study_tdg_order()
    made = figures(cmp, ref_spec, lame, wash, ip, tdg, out / "figures")
    res = {
        "paper": {"figure": 17, "reports": "FE-DPN and a coupled finite-volume solver agree at selected nodes at "
                  "step T-3 for low flow rates and separate at higher rates (no numbers given)"},
        "t_compare_s": t_end,
        "reference": {"spec": list(ref_spec), "n_nodes": ref["n_nodes"], "n_tets": ref["n_tets"],
                      "wall_s": ref["wall_s"], "cpu_s": ref["cpu_s"], "max_u_m": ref["max_u"], "cached": ref["cached"],
                      "computed": ref["computed"], "code": ref["code"]},
        "comparison": cmp,
        "lame": lame,
        "washburn": {k: v for k, v in wash.items() if k.startswith("max_")},
        "ip_limit": {"ca": ip["ca"], "prefix_fraction_mean": ip["prefix_fraction"].mean(axis=0),
                     "jaccard_mean": ip["jaccard"].mean(axis=0), "shape": ip["shape"], "seeds": ip["seeds"]},
        "tdg_order": {"dt": tdg["dt"], "orders": tdg["orders"], "errors": tdg["errors"]},
        "figures": made,
        "smoke": bool(args.smoke),
        "wall_s": time.perf_counter() - t0,
    }
    (out / "results.json").write_text(json.dumps(_json(res), indent=1))
    for name, e in cmp["errors"].items():
        print(f"{name:32s} rel. error (shared {e['n_shared_nodes']} nodes) {e['rel_error_shared']:.3f}, all nodes "
              f"{e['rel_error_all_interp']:.3f}, selected {e['rel_error_selected']:.3f}, "
              f"max|u| ratio {e['max_u_ratio']:.3f}, CPU {e['cpu_s']:.1f} s, wall {e['wall_s']:.0f} s")
    print(f"TDG orders {tdg['orders']}; Washburn {wash['max_rel_error_washburn']:.1e}; "
          f"verification wall {res['wall_s']:.0f} s -> {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
