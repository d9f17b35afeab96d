"""Case ``tolerance``: the range of inclusivity ε of the hull interface (paper eq. 3.2, figure 11).

The coupled run of ``case.toml`` is repeated for a sweep of ε (absolute, in m, the same for
every pore) and for porefsi's default ε_i = 0.5 r_i (the reference). Measured per ε at the end
of the run:

- the displacement magnitude at two FE nodes picked deterministically from the reference
  run: A = the node of largest displacement, B = the node of largest displacement farther than
  a quarter of the sample edge from A (the paper shows two nodes, figure 11);
- the largest displacement and von Mises stress;
- the FE nodes that receive load (members of some pore's enlarged hull that are nearest to at
  least one test point) and the pores whose load reaches no node (lost load);
- the resultant of the hull forces relative to their magnitude sum, |sum f| / sum |f| (a
  consistent pressure load on closed cavities has zero resultant).

Outputs: ``figures/tolerance.png``, ``results.json``.
Usage: ``python cases/tolerance/run.py [--smoke] [--out DIR]``.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from porefsi import CoupledRun, load_case, problem_from_case, smoke_case

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # cases/: the shared helpers
from _common import output_dir, parse_args, pyplot, write_results  # noqa: E402

HERE = Path(__file__).resolve().parent
EPS_FULL = [0.0, 2.5e-6, 5e-6, 1e-5, 2e-5, 4e-5, 8e-5]  # m; 8e-5 is the value of the paper's figure 11
EPS_SMOKE = [0.0, 2e-5]
#: The paper: results shown for two FE nodes with 800 test points and eps_{i+r_n} = 8e-5 (figure 11
#: caption; the text gives no unit and no sweep values).
PAPER = {"eps_figure_11": 8e-5, "n_test_points": 800, "n_nodes_shown": 2}


SMOKE_HELP = "seconds-long version (coarse mesh, 2 steps, 2 values)"



def run_one(case) -> dict:
    """One coupled run; the final displacement/force fields and interface statistics."""
    t0 = time.perf_counter()
    prob = problem_from_case(case)
    run = CoupledRun(prob)
    last = None
    for rec in run.steps():
        last = rec
    itf = prob.interface
    F = last.nodal_force
    fmag = np.linalg.norm(F, axis=1)
    loaded_geom = np.unique(np.concatenate([n for n in itf.pore_nodes if n.size] or [np.zeros(0, int)]))
    return {
        "U": last.displacement, "points": prob.mesh.points, "extent": prob.image.extent,
        "mean_pore_radius_m": float(prob.network.pore_radius.mean()), "node_spacing_m": float(prob.node_spacing),
        "n_loaded_nodes": int(loaded_geom.size), "n_unloaded_pores": int(itf.n_unloaded),
        "n_pores": int(prob.network.n_pores), "n_nodes": int(prob.mesh.n_nodes),
        "resultant_ratio": float(np.linalg.norm(F.sum(axis=0)) / fmag.sum()) if fmag.sum() > 0 else 0.0,
        "total_force_N": float(fmag.sum()),
        "max_displacement_m": float(np.linalg.norm(last.displacement, axis=1).max()),
        "max_von_mises_Pa": float(last.von_mises.max()),
        "interface_seconds": float(itf.seconds), "wall_seconds": time.perf_counter() - t0,
    }


def pick_nodes(U: np.ndarray, points: np.ndarray, extent) -> tuple[int, int]:
    """Node of largest |u|, and the node of largest |u| farther than min(extent)/4 from it."""
    mag = np.linalg.norm(U, axis=1)
    a = int(np.argmax(mag))
    far = np.linalg.norm(points - points[a], axis=1) > 0.25 * float(np.min(extent))
    b = int(np.flatnonzero(far)[np.argmax(mag[far])])
    return a, b


def main(argv=None) -> dict:
    """Sweep ε, draw the figure, write ``results.json``; return the results."""
    args = parse_args(__doc__, argv, smoke_help=SMOKE_HELP)
    base = load_case(HERE / "case.toml")
    if args.smoke:
        base = smoke_case(base)
    out = output_dir(args, HERE)
    ref = run_one(base.replace(interface={"tolerance": None}))
    a, b = pick_nodes(ref["U"], ref["points"], ref["extent"])
    print(f"  reference eps = 0.5 r_i: max |u| = {ref['max_displacement_m']:.4e} m, nodes A = {a}, B = {b}", flush=True)
    eps_list = EPS_SMOKE if args.smoke else EPS_FULL
    table = []
    for eps in eps_list:
        r = run_one(base.replace(interface={"tolerance": eps}))
        mag = np.linalg.norm(r["U"], axis=1)
        table.append({"eps_m": eps, "u_node_A_m": float(mag[a]), "u_node_B_m": float(mag[b]),
                      **{k: r[k] for k in ("max_displacement_m", "max_von_mises_Pa", "n_loaded_nodes",
                                           "n_unloaded_pores", "resultant_ratio", "total_force_N",
                                           "interface_seconds", "wall_seconds")}})
        print(f"  eps = {eps:.3g} m: |u_A| = {mag[a]:.4e}, |u_B| = {mag[b]:.4e}, loaded nodes {r['n_loaded_nodes']}, "
              f"unloaded pores {r['n_unloaded_pores']} ({r['wall_seconds']:.1f} s)", flush=True)
    mag_ref = np.linalg.norm(ref["U"], axis=1)
    reference = {"eps": "0.5 r_i", "u_node_A_m": float(mag_ref[a]), "u_node_B_m": float(mag_ref[b]),
                 **{k: ref[k] for k in ("max_displacement_m", "max_von_mises_Pa", "n_loaded_nodes", "n_unloaded_pores",
                                        "resultant_ratio", "total_force_N", "interface_seconds", "wall_seconds",
                                        "mean_pore_radius_m", "n_pores", "n_nodes", "node_spacing_m")}}

    plt = pyplot()

    e_um = np.array([row["eps_m"] for row in table]) * 1e6
    eref = 0.5 * ref["mean_pore_radius_m"] * 1e6
    fig, ax = plt.subplots(1, 3, figsize=(15, 4.3))
    h_um = reference["node_spacing_m"] * 1e6
    for a_ in ax:
        a_.axvline(h_um, color="grey", ls=":", lw=1)
        a_.text(h_um, 0.98, " node spacing", transform=a_.get_xaxis_transform(), va="top", fontsize=8, color="grey")
    for key, lab, st, c in (("u_node_A_m", "node A", "o-", "C0"), ("u_node_B_m", "node B", "s-", "C1"),
                            ("max_displacement_m", "max over nodes", "^--", "C2")):
        ax[0].plot(e_um, [row[key] * 1e9 for row in table], st, color=c, label=lab)
        ax[0].plot([eref], [reference[key] * 1e9], "*", ms=12, color=c)
    ax[0].set_xlabel("range of inclusivity ε, µm (star: default 0.5 r_i at mean r)")
    ax[0].set_ylabel("|u| at t_end, nm")
    ax[0].set_title("displacement at chosen nodes vs ε")
    ax[0].legend(fontsize=8)
    ax[0].grid(alpha=0.3)
    ax[1].plot(e_um, [row["n_loaded_nodes"] for row in table], "o-", label="loaded FE nodes")
    ax[1].plot(e_um, [row["n_unloaded_pores"] for row in table], "s-", label="pores whose load is lost")
    ax[1].plot([eref], [reference["n_loaded_nodes"]], "*", ms=12, color="C0")
    ax[1].plot([eref], [reference["n_unloaded_pores"]], "*", ms=12, color="C1")
    ax[1].set_xlabel("ε, µm")
    ax[1].set_ylabel("count")
    ax[1].set_title(f"interface reach ({reference['n_pores']} pores, {reference['n_nodes']} nodes)")
    ax[1].legend(fontsize=8)
    ax[1].grid(alpha=0.3)
    ax[2].plot(e_um, [row["resultant_ratio"] for row in table], "o-")
    ax[2].plot([eref], [reference["resultant_ratio"]], "*", ms=12, color="C0")
    ax[2].set_xlabel("ε, µm")
    ax[2].set_ylabel("|Σ f| / Σ |f|")
    ax[2].set_title("net force of the hull load (0 for a consistent traction)")
    ax[2].grid(alpha=0.3)
    fig.tight_layout()
    fig_path = out / "figures" / "tolerance.png"
    fig.savefig(fig_path, dpi=110)
    plt.close(fig)

    results = {
        "case": base.name, "smoke": args.smoke,
        "settings": {"coarsen": base.solid.coarsen, "exchange_dt_s": base.coupling.exchange_dt,
                     "t_end_s": base.drainage.t_end, "n_test_points": base.interface.n_test_points,
                     "integrator": base.coupling.integrator, "network_update": base.network.update},
        "nodes": {"A": a, "B": b, "A_xyz_m": ref["points"][a].tolist(), "B_xyz_m": ref["points"][b].tolist()},
        "reference": reference, "table": table, "paper": PAPER, "figures": [str(fig_path.relative_to(out))],
    }
    write_results(out / "results.json", results)
    print(f"tolerance: |u_A| from {table[0]['u_node_A_m']:.3e} (eps = {eps_list[0]:g}) to "
          f"{table[-1]['u_node_A_m']:.3e} m (eps = {eps_list[-1]:g}); reference {reference['u_node_A_m']:.3e} m "
          f"-> {out}")
    return results


if __name__ == "__main__":
    main()
