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
   The reference's own error is measured by a P2 check: P2 elements on coarsen 4 (517k dofs, the
   finest P2 mesh within this case's time cap: coarsen 3 would have 1.2 M), half the exchange
   step (0.5 s), the pore-wall traction integrated against the P2 basis (what the library's
   coupled P2 does: ``solid.order = 2`` with the traction interface), quasi-static, AMG-CG;
   ~20 min CPU and 9.4 GB, cached in ``reference/`` as its field at the reference's nodes (exact
   P2 interpolation). Every run, the reference included, is compared with it there, each as its
   finite-element function (:func:`fe_at_points`).
2. Analytic set (``analytic.py``): Lamé cavity, Washburn, invasion-percolation limit, TDG order.

Usage: python cases/verification/run.py [--smoke] [--out DIR] [--no-cache [{all,reference,p2}]]
"""

from __future__ import annotations

import hashlib
import resource
import sys
import time
from pathlib import Path

import numpy as np
from scipy import ndimage

from porefsi import CoupledRun, load_case, problem_from_case, smoke_case, solve_static
from porefsi.case import case_to_toml
from porefsi.coupling import displacement_on_grid
from porefsi.solid import midpoint_nodes

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # cases/: the shared helpers
from _common import git_head, output_dir, parse_args, pyplot, write_results  # noqa: E402

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
# same-mesh pairs whose difference isolates one knob: exchange step (and integrator), integrator
SAME_MESH_PAIRS = (("c6, traction, TDG, dt 0.5 s", "c6, traction, static"),
                   ("c5, traction, TDG", "default (c5, traction, static)"))
SMOKE_REFERENCE = ("reference", 5, "traction", "static", 1.0)
SMOKE_RUNS = (("c10, traction, static", 10, "traction", "static", 1.0), ("c10, hull, TDG", 10, "hull", "tdg", 1.0))
SELECT_STRIDE = 12  # selected nodes: reference nodes on multiples of 12 voxels (nodes of coarsen 3, 4, 6)
# The P2 check of the reference: P2 elements, half the exchange step, the traction integrated
# against the P2 basis; coarsen 4 is the finest P2 mesh that fits this case's time cap
# (coarsen 3 P2 has 1.2 M dofs). name, coarsen, exchange_dt, linear solver.
P2_CHECK = ("P2 c4, dt 0.5 s", 4, 0.5, "amg")
SMOKE_P2_CHECK = ("P2 c10, dt 0.5 s", 10, 0.5, "direct")


def make_case(base, spec, t_end):
    _, coarsen, method, integ, dt = spec
    return base.replace(solid={"coarsen": coarsen}, interface={"method": method},
                        coupling={"integrator": integ, "exchange_dt": dt}, drainage={"t_end": t_end},
                        output={"snapshot_times": [], "vtk": False, "figures": False})


def run_coupled(case) -> dict:
    """Coupled run to ``case.drainage.t_end``; node grid indices and the final displacement."""
    t0, c0 = time.perf_counter(), time.process_time()
    p = problem_from_case(case)
    run = CoupledRun(p)
    rec = None
    for rec in run.steps():  # noqa: B007 - the last record is the one compared
        pass
    grid = np.rint((p.mesh.points - p.image.origin) / p.image.voxel_size).astype(np.int64)
    return {"grid": grid, "u": rec.displacement, "t": rec.t, "n_nodes": p.mesh.n_nodes, "n_tets": p.mesh.n_tets,
            "tets": p.mesh.tets,
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
    ref["code"] = git_head()
    if cache is not None:
        cache.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(cache, grid=ref["grid"].astype(np.int16), u=ref["u"], t=ref["t"],
                            n_nodes=ref["n_nodes"], n_tets=ref["n_tets"], wall_s=ref["wall_s"], cpu_s=ref["cpu_s"],
                            max_u=ref["max_u"], case_toml=np.array(toml), computed=np.array(ref["computed"]),
                            code=np.array(ref["code"]))
    ref["cached"] = False
    return ref


_TET_EDGES = ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))


def fe_at_points(xv: np.ndarray, tets: np.ndarray, U: np.ndarray, pts: np.ndarray, edge: np.ndarray | None = None):
    """A P1 or P2 field at points, all positions in voxel units: the finite-element function itself.

    P1: ``U`` (Nn, 3) on the vertices ``xv``, ``edge`` None (shapes λ_i). P2: ``U`` on all Lagrange
    nodes and ``edge`` (Ne, 6) the edge-node index of each tetrahedron's edges in
    :data:`_TET_EDGES` order (vertex shapes λ_i(2λ_i - 1), edge shapes 4 λ_i λ_j). A point outside
    the mesh (solid at a finer resolution, pore after this mesh's coarser block coarsening) takes
    the value at the nearest point of the closest tetrahedron (λ clipped to >= 0). Returns
    (values (M, 3), outside (M,) bool).
    """
    from scipy.spatial import cKDTree

    xv = np.asarray(xv, float)
    x0 = xv[tets[:, 0]]
    jinv = np.linalg.inv(np.stack([xv[tets[:, k]] - x0 for k in (1, 2, 3)], axis=2))  # (Ne, 3, 3)
    pts = np.asarray(pts, float)
    _, cand = cKDTree(xv[tets].mean(axis=1)).query(pts, k=16)
    lam123 = np.einsum("mkij,mkj->mki", jinv[cand], pts[:, None, :] - x0[cand])
    lam = np.concatenate([1.0 - lam123.sum(axis=2, keepdims=True), lam123], axis=2)  # (M, 16, 4)
    best = np.argmax(lam.min(axis=2), axis=1)
    rows = np.arange(len(pts))
    e = cand[rows, best]
    lam = lam[rows, best]
    outside = lam.min(axis=1) < -1e-9
    lam = np.clip(lam, 0.0, None)
    lam /= lam.sum(axis=1, keepdims=True)
    val = np.zeros((len(pts), 3))
    for i in range(4):
        w = lam[:, i] if edge is None else lam[:, i] * (2.0 * lam[:, i] - 1.0)
        val += w[:, None] * U[tets[e, i]]
    if edge is not None:
        for c, (i, j) in enumerate(_TET_EDGES):
            val += (4.0 * lam[:, i] * lam[:, j])[:, None] * U[edge[e, c]]
    return val, outside


def p2_at_points(p, U_all: np.ndarray, pts_vox: np.ndarray):
    """The P2 field ``U_all`` ((n_full/3, 3) on the Lagrange nodes of ``p``) at points in voxel units
    (:func:`fe_at_points`)."""
    tets = p.mesh.tets
    edge = np.stack([midpoint_nodes(p.mesh, p.model.dof_points, tets[:, i], tets[:, j]) for i, j in _TET_EDGES],
                    axis=1)
    xv = (p.mesh.points - p.image.origin) / p.image.voxel_size
    return fe_at_points(xv, tets, U_all, pts_vox, edge)


def make_p2_case(base, spec, t_end):
    _, coarsen, dt, solver = spec
    return base.replace(solid={"coarsen": coarsen, "order": 2, "linear_solver": solver},
                        interface={"method": "traction"},
                        coupling={"integrator": "static", "exchange_dt": dt}, drainage={"t_end": t_end},
                        output={"snapshot_times": [], "vtk": False, "figures": False})


def run_p2_check(case, ref_grid: np.ndarray) -> dict:
    """The P2 check run to ``case.drainage.t_end``, its field at the reference nodes ``ref_grid``.

    Also one static solve at the final pressures with the P1-consistent vertex forces as P2 point
    loads (what ``solid.order = 2`` did in a coupled run before the interface integrated the
    traction against the P2 basis), to show how much the P2-consistent load matters.
    """
    t0, c0 = time.perf_counter(), time.process_time()
    p = problem_from_case(case)  # P2: the traction interface integrates against the P2 basis
    run = CoupledRun(p)
    rec = None
    n_steps = 0
    for rec in run.steps():  # noqa: B007 - the last record is the one compared
        n_steps += 1
        print(f"  P2 check t = {rec.t:g} s, max|u| {rec.row['max_displacement_m']:.4g} m, "
              f"CPU {time.process_time() - c0:.0f} s", flush=True)
    U_all = run.model.full_displacement(run.u, rec.t).reshape(-1, 3)
    cpu, wall = time.process_time() - c0, time.perf_counter() - t0
    at_ref, outside = p2_at_points(p, U_all, ref_grid)
    # the vertex-load variant at the same pressures
    c1 = time.process_time()
    P = np.nan_to_num(np.asarray(run.sim.state.fluid_pressure, float), nan=0.0)
    mv = p.model.with_nodal_forces(p.interface.vertex_forces(P))
    uv, _ = solve_static(mv, rec.t, u0=run.u, t_prev=rec.t)
    at_ref_v, _ = p2_at_points(p, mv.full_displacement(uv, rec.t).reshape(-1, 3), ref_grid)
    return {"u_at_ref": at_ref, "outside": outside, "u_vertex_load_at_ref": at_ref_v, "t": rec.t,
            "n_nodes": p.mesh.n_nodes, "n_tets": p.mesh.n_tets, "n_dofs": p.model.n_dofs, "n_steps": n_steps,
            "max_u": float(np.linalg.norm(U_all, axis=1).max()),
            "max_u_vertex_load": float(np.linalg.norm(mv.full_displacement(uv, rec.t).reshape(-1, 3), axis=1).max()),
            "cpu_s": cpu, "wall_s": wall, "vertex_load_cpu_s": time.process_time() - c1,
            "max_rss_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6}


def _grid_hash(grid) -> str:
    return hashlib.sha256(np.ascontiguousarray(np.asarray(grid, np.int64)).tobytes()).hexdigest()[:16]


def p2_check(case, ref: dict, cache: Path | None, refresh: bool = False) -> dict:
    """The P2 check at the reference's nodes: cached like the reference (its case TOML and the
    reference's node set must match)."""
    toml, gh = case_to_toml(case), _grid_hash(ref["grid"])
    keys = ("u_at_ref", "outside", "u_vertex_load_at_ref")
    scal = ("t", "n_nodes", "n_tets", "n_dofs", "n_steps", "max_u", "max_u_vertex_load", "cpu_s", "wall_s",
            "vertex_load_cpu_s", "max_rss_gb")
    if cache is not None and cache.is_file() and not refresh:
        d = np.load(cache, allow_pickle=False)
        if str(d["case_toml"]) == toml and str(d["ref_grid_hash"]) == gh:
            out = {k: d[k] for k in keys} | {k: d[k].item() for k in scal}
            return out | {"cached": True, "computed": str(d["computed"]), "code": str(d["code"])}
    out = run_p2_check(case, ref["grid"])
    out["computed"] = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    out["code"] = git_head()
    if cache is not None:
        cache.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(cache, **{k: out[k] for k in keys}, **{k: out[k] for k in scal}, case_toml=np.array(toml),
                            ref_grid_hash=np.array(gh), computed=np.array(out["computed"]),
                            code=np.array(out["code"]))
    out["cached"] = False
    return out


def compare_p2(ref: dict, runs: dict, chk: dict, selected_idx, ref_name: str, chk_name: str) -> dict:
    """Every run (the reference included) against the P2 check, at the reference's nodes.

    Each run's field is its finite-element function (:func:`fe_at_points`: P1 in the run's own
    tetrahedron, the same clipping outside its mesh as for the P2 field); the reference's values
    are its nodal values. Relative L2 difference over all reference nodes, over those inside the
    P2 mesh (no extrapolation of the P2 field), and at the selected nodes; normalised by the P2
    field on the same points.
    """
    u2, inside = chk["u_at_ref"], ~np.asarray(chk["outside"], bool)

    def rel(u, sel):
        return float(np.linalg.norm(u[sel] - u2[sel]) / np.linalg.norm(u2[sel]))

    allp = np.ones(len(u2), bool)
    fields, n_out = {ref_name: ref["u"]}, {ref_name: 0}
    for n, r in runs.items():
        fields[n], out = fe_at_points(r["grid"], r["tets"], r["u"], ref["grid"])
        n_out[n] = int(out.sum())
    fields[f"{chk_name}, vertex loads"] = chk["u_vertex_load_at_ref"]
    n_out[f"{chk_name}, vertex loads"] = int((~inside).sum())
    rows = {}
    for name, u in fields.items():
        rows[name] = {"rel_diff_all": rel(u, allp), "rel_diff_inside": rel(u, inside),
                      "rel_diff_selected": rel(u, selected_idx), "n_outside_own_mesh": n_out[name],
                      "max_u_ratio_at_ref_nodes": float(np.linalg.norm(u, axis=1).max()
                                                        / np.linalg.norm(u2, axis=1).max())}
    return {"rows": rows, "n_points": int(len(u2)), "n_outside": int((~inside).sum())}


def same_mesh_difference(a: dict, b: dict) -> float:
    """Relative L2 difference |u_a - u_b| / |u_b| of two runs on the same mesh, node by node."""
    if a["grid"].shape != b["grid"].shape or not np.array_equal(a["grid"], b["grid"]):
        raise ValueError("the runs are not on the same mesh")
    return float(np.linalg.norm(a["u"] - b["u"]) / np.linalg.norm(b["u"]))


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
    return {"errors": out, "selected_grid": ref["grid"][ib].tolist(), "selected_index": ib.tolist(),
            "selected_norms": table,
            "n_reference_nodes": int(len(rid)), "select_stride_voxels": SELECT_STRIDE}


def figures(cmp: dict, ref_spec, lame, wash, ip, tdg, fig_dir: Path, p2: dict | None = None) -> list[str]:
    plt = pyplot()
    fig_dir.mkdir(parents=True, exist_ok=True)
    made = []
    ref_label = f"c{ref_spec[1]}, P1, traction, static"
    # figure 17 role: |u| at selected nodes
    tab = cmp["selected_norms"]
    names = list(tab)
    n = len(tab["reference"])
    w = 0.8 / len(names)
    fig, ax = plt.subplots(figsize=(14, 5))
    for i, name in enumerate(names):
        lab = f"reference ({ref_label})" if name == "reference" else name
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
    for k, (name, e) in enumerate(cmp["errors"].items()):
        ax.loglog(e["cpu_s"], e["rel_error_all_interp"], "o", color=f"C{k}")
        ax.annotate(name, (e["cpu_s"], e["rel_error_all_interp"]), fontsize=7)
        if p2 is not None and name in p2["rows"]:
            ax.loglog(e["cpu_s"], p2["rows"][name]["rel_diff_all"], "^", mfc="none", color=f"C{k}")
    if p2 is not None:
        ax.plot([], [], "ko", label=f"against the reference ({ref_label})")
        ax.plot([], [], "k^", mfc="none", label=f"against the P2 check ({p2['name']})")
        r0 = p2["rows"][p2["reference_row"]]
        ax.axhline(r0["rel_diff_all"], color="0.5", ls=":", label=f"reference vs P2 check: {r0['rel_diff_all']:.2f}")
        ax.legend(fontsize=7, loc="lower left")
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


def _arguments(p) -> None:
    p.add_argument("--no-cache", nargs="?", const="all", default=None, choices=("all", "reference", "p2"),
                   help="recompute and overwrite the cached runs: all (default), the P1 reference (~75 s CPU) or "
                        "the P2 check (~20 min CPU, 9.4 GB)")


def main(argv=None) -> int:
    args = parse_args(__doc__, argv, _arguments)
    out = output_dir(args, HERE)
    t0 = time.perf_counter()
    base = load_case(HERE / "case.toml")
    if args.smoke:
        base = smoke_case(base)
        ref_spec, specs, t_end = SMOKE_REFERENCE, SMOKE_RUNS, base.drainage.t_end
        cache = out / "reference" / "smoke_reference.npz"
    else:
        ref_spec, specs, t_end = REFERENCE, RUNS, T_COMPARE
        cache = HERE / "reference" / "reference_c3_traction_static.npz"
    ref = reference(make_case(base, ref_spec, t_end), cache, refresh=args.no_cache in ("all", "reference"))
    chk_spec = SMOKE_P2_CHECK if args.smoke else P2_CHECK
    chk_name = "smoke_p2_check.npz" if args.smoke else f"p2_check_c{chk_spec[1]}_dt{chk_spec[2]:g}.npz"
    chk_cache = cache.parent / chk_name
    chk = p2_check(make_p2_case(base, chk_spec, t_end), ref, chk_cache, refresh=args.no_cache in ("all", "p2"))
    runs = {s[0]: run_coupled(make_case(base, s, t_end)) for s in specs}
    cmp = compare(ref, runs)
    ref_name = f"reference (c{ref_spec[1]}, P1, dt {ref_spec[4]:g} s)"
    cmp_p2 = compare_p2(ref, runs, chk, cmp["selected_index"], ref_name, chk_spec[0])
    tab = cmp["selected_norms"]  # the P2 check's bars next to the reference's
    cmp["selected_norms"] = {"reference": tab.pop("reference"),
                             chk_spec[0]: np.linalg.norm(chk["u_at_ref"][cmp["selected_index"]], axis=1)} | tab
    pairs = {f"{a} vs {b}": same_mesh_difference(runs[a], runs[b]) for a, b in SAME_MESH_PAIRS
             if a in runs and b in runs}
    if args.smoke:
        lame = analytic.study_lame(n_cells=(12, 16))
        ip = analytic.study_ip_limit(cas=(1e-8, 1e-5), shape=(5, 5, 2), seeds=(0,))
    else:
        lame = analytic.study_lame(n_cells=(12, 16, 20, 24, 28))
        ip = analytic.study_ip_limit()
    wash = analytic.study_washburn()
    tdg = analytic.study_tdg_order()
    made = figures(cmp, ref_spec, lame, wash, ip, tdg, out / "figures",
                   p2=cmp_p2 | {"name": chk_spec[0], "reference_row": ref_name})
    res = {
        "paper": {"figure": 17, "reports": "FE-DPN and a coupled finite-volume solver agree at selected nodes at "
                  "step T-3 for low flow rates and separate at higher rates (no numbers given)"},
        "t_compare_s": t_end,
        "reference": {"spec": list(ref_spec), "n_nodes": ref["n_nodes"], "n_tets": ref["n_tets"],
                      "wall_s": ref["wall_s"], "cpu_s": ref["cpu_s"], "max_u_m": ref["max_u"], "cached": ref["cached"],
                      "computed": ref["computed"], "code": ref["code"]},
        "comparison": cmp,
        "p2_check": {"spec": list(chk_spec), "t_s": chk["t"], "n_nodes": chk["n_nodes"], "n_tets": chk["n_tets"],
                     "n_dofs": chk["n_dofs"], "n_steps": chk["n_steps"], "max_u_m": chk["max_u"],
                     "max_u_vertex_load_m": chk["max_u_vertex_load"], "cpu_s": chk["cpu_s"], "wall_s": chk["wall_s"],
                     "vertex_load_cpu_s": chk["vertex_load_cpu_s"], "max_rss_gb": chk["max_rss_gb"],
                     "cached": chk["cached"], "computed": chk["computed"], "code": chk["code"], **cmp_p2},
        "same_mesh_differences": pairs,
        "lame": lame,
        "washburn": {k: v for k, v in wash.items() if k.startswith("max_")},
        "ip_limit": {"ca": ip["ca"], "prefix_fraction_mean": ip["prefix_fraction"].mean(axis=0),
                     "jaccard_mean": ip["jaccard"].mean(axis=0), "shape": ip["shape"], "seeds": ip["seeds"]},
        "tdg_order": {"dt": tdg["dt"], "orders": tdg["orders"], "errors": tdg["errors"]},
        "figures": made,
        "smoke": bool(args.smoke),
        "computed": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "code": git_head(),
        "wall_s": time.perf_counter() - t0,
    }
    write_results(out / "results.json", res)
    for name, e in cmp["errors"].items():
        print(f"{name:32s} rel. error (shared {e['n_shared_nodes']} nodes) {e['rel_error_shared']:.3f}, all nodes "
              f"{e['rel_error_all_interp']:.3f}, selected {e['rel_error_selected']:.3f}, "
              f"max|u| ratio {e['max_u_ratio']:.3f}, CPU {e['cpu_s']:.1f} s, wall {e['wall_s']:.0f} s")
    for name, e in cmp_p2["rows"].items():
        print(f"vs {chk_spec[0]}: {name:32s} all {e['rel_diff_all']:.3f}, inside {e['rel_diff_inside']:.3f}, "
              f"selected {e['rel_diff_selected']:.3f}, max|u| ratio {e['max_u_ratio_at_ref_nodes']:.3f}")
    for name, d in pairs.items():
        print(f"same mesh: {name}: {d:.2e}")
    print(f"TDG orders {tdg['orders']}; Washburn {wash['max_rel_error_washburn']:.1e}; "
          f"verification wall {res['wall_s']:.0f} s -> {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
