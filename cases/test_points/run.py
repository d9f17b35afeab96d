"""Case ``test_points``: 100 to 1000 test points per pore (paper figure 8).

For each number N of test points per pore sphere, the coupled run of ``case.toml`` (two-way:
geometric network update) is repeated. Measured per N:

- the capillary-pressure-saturation path of the run (inlet pressure vs Sw at each exchange
  step), and its largest difference from the N = 1000 run. In porefsi the DPN does not see
  the test points at all in one-way coupling; in two-way coupling it sees them only through the
  network update, i.e. through sub-nanometre changes of the pore radii;
- what the test points *do* change: the nodal-force field and the displacement field at the
  end of the run (relative L2 difference from N = 1000), the loaded nodes, the unloaded pores;
- the sampling noise of the same N with another seed (seed 1 vs seed 0, same final
  pressures), which sets how much of the N-dependence is Monte-Carlo noise;
- wall time: interface build (Qhull hulls + node search) and the whole run.

Outputs: ``figures/test_points.png``, ``results.json``.
Usage: ``python cases/test_points/run.py [--smoke] [--out DIR]``.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from porefsi import CoupledRun, load_case, problem_from_case, smoke_case
from porefsi.flow import invasion_percolation

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # cases/: the shared helpers
from _common import output_dir, parse_args, pyplot, write_results  # noqa: E402

HERE = Path(__file__).resolve().parent
N_FULL = [100, 200, 400, 600, 800, 1000]
N_SMOKE = [100, 200]
#: The paper (section 3.2, figure 8): more test points lower Pc by ~13.5 kPa early in the
#: drainage; the dependence fades as Sw falls; 800 points judged sufficient.
PAPER = {"pc_shift_early_Pa": 13.5e3, "n_test_points_chosen": 800, "range": [100, 1000]}


SMOKE_HELP = "seconds-long version (coarse mesh, 2 steps, N = 100, 200)"



def _rel(a: np.ndarray, b: np.ndarray) -> float:
    nb = float(np.linalg.norm(b))
    return float(np.linalg.norm(a - b)) / nb if nb > 0 else 0.0


def run_one(case) -> dict:
    """One coupled run; returns its time series, final fields and timings."""
    t0 = time.perf_counter()
    prob = problem_from_case(case)
    t_setup = time.perf_counter() - t0
    run = CoupledRun(prob)
    rows = [run.initial_record().row]
    last = None
    for rec in run.steps():
        rows.append(rec.row)
        last = rec
    itf = prob.interface
    loaded = np.unique(np.concatenate([n for n in itf.pore_nodes if n.size] or [np.zeros(0, int)]))
    return {
        "sw": np.array([r["sw"] for r in rows]), "pc": np.array([r["capillary_pressure_Pa"] for r in rows]),
        "radius": last.network.pore_radius.copy(), "U": last.displacement, "F": last.nodal_force,
        "P": np.nan_to_num(np.asarray(last.flow.fluid_pressure, float)),
        "interface_seconds": itf.seconds, "setup_seconds": t_setup, "wall_seconds": time.perf_counter() - t0,
        "n_unloaded_pores": int(itf.n_unloaded), "n_loaded_nodes": int(loaded.size),
        "max_displacement_m": float(np.linalg.norm(last.displacement, axis=1).max()),
        "max_von_mises_Pa": float(last.von_mises.max()), "problem": prob,
    }


def main(argv=None) -> dict:
    """Sweep N, draw the figure, write ``results.json``; return the results."""
    args = parse_args(__doc__, argv, smoke_help=SMOKE_HELP)
    base = load_case(HERE / "case.toml")
    ns = N_SMOKE if args.smoke else N_FULL
    if args.smoke:
        base = smoke_case(base)
    out = output_dir(args, HERE)
    # Warm-up (not timed): first-use costs (numba cache loading, imports) would otherwise be
    # charged to the first setting.
    run_one(smoke_case(base).replace(drainage={"t_end": base.coupling.exchange_dt}))
    runs = {}
    for n in ns:
        runs[n] = run_one(base.replace(interface={"n_test_points": n}))
        print(f"  N = {n}: run {runs[n]['wall_seconds']:.1f} s (interface {runs[n]['interface_seconds']:.3f} s), "
              f"max |u| = {runs[n]['max_displacement_m']:.4e} m", flush=True)
    ref = runs[ns[-1]]
    # The consistent interface (no test points): pressure as a traction on the pore-wall facets.
    traction = run_one(base.replace(interface={"method": "traction"}))
    # Sampling noise: the same N with seed 1, applied to the same final pressures.
    for n in ns:
        prob1 = problem_from_case(base.replace(interface={"n_test_points": n, "seed": base.interface.seed + 1}))
        runs[n]["F_seed1_rel"] = _rel(prob1.interface.nodal_forces(runs[n]["P"]), runs[n]["F"])
    table = []
    for n in ns:
        r = runs[n]
        pos = ref["pc"] > 0
        table.append({
            "n_test_points": n,
            "pc_max_abs_diff_Pa": float(np.max(np.abs(r["pc"] - ref["pc"]))),
            "pc_max_rel_diff": float(np.max(np.abs(r["pc"][pos] - ref["pc"][pos]) / ref["pc"][pos])) if pos.any()
            else 0.0,
            "sw_max_abs_diff": float(np.max(np.abs(r["sw"] - ref["sw"]))),
            "pore_radius_max_rel_diff": float(np.max(np.abs(r["radius"] - ref["radius"]) / ref["radius"])),
            "force_rel_diff_vs_ref": _rel(r["F"], ref["F"]),
            "force_rel_diff_seed": r["F_seed1_rel"],
            "displacement_rel_diff_vs_ref": _rel(r["U"], ref["U"]),
            "max_displacement_m": r["max_displacement_m"], "max_von_mises_Pa": r["max_von_mises_Pa"],
            "n_loaded_nodes": r["n_loaded_nodes"], "n_unloaded_pores": r["n_unloaded_pores"],
            "interface_seconds": r["interface_seconds"], "wall_seconds": r["wall_seconds"],
        })
    nn = np.array(ns, float)
    seed = np.array([row["force_rel_diff_seed"] for row in table])
    slope = float(np.polyfit(np.log(nn), np.log(seed), 1)[0]) if len(ns) > 2 and np.all(seed > 0) else None

    # Quasi-static reference curve (invasion percolation with trapping) on the same network.
    prob = ref["problem"]
    ip = invasion_percolation(prob.network, prob.fluids, axis=base.image.axis)
    ip_sw, ip_pc = ip.pc_curve()

    plt = pyplot()

    fig, ax = plt.subplots(1, 3, figsize=(15, 4.3))
    ax[0].plot(ip_sw, ip_pc * 1e-3, "k-", lw=1, label="quasi-static IP (same network)")
    for n in ns:
        ax[0].plot(runs[n]["sw"][1:], runs[n]["pc"][1:] * 1e-3, "o-", ms=3, lw=1, label=f"N = {n}")
    ax[0].set_xlabel("wetting saturation Sw")
    ax[0].set_ylabel("capillary (inlet) pressure, kPa")
    ax[0].set_xlim(min(0.9, float(np.min(ref["sw"])) - 0.01), 1.0)
    ax[0].set_ylim(0.0, 1.5 * max(float(np.max(r["pc"])) for r in runs.values()) * 1e-3)
    ax[0].set_title(f"Pc-S over the run (coarsen {base.solid.coarsen})")
    ax[0].legend(fontsize=8)
    ax[0].grid(alpha=0.3)
    for key, lab, st in (("force_rel_diff_vs_ref", f"nodal forces vs N = {ns[-1]}", "o-"),
                         ("displacement_rel_diff_vs_ref", f"displacement vs N = {ns[-1]}", "s-"),
                         ("force_rel_diff_seed", "nodal forces, seed 1 vs seed 0", "^--"),
                         ("pc_max_rel_diff", f"Pc along the run vs N = {ns[-1]}", "x-")):
        y = np.array([row[key] for row in table])
        m = y > 0
        ax[1].loglog(nn[m], y[m], st, label=lab)
    ax[1].loglog(nn, seed[0] * (nn / nn[0]) ** -0.5, "k:", lw=1, label="N^-1/2")
    ax[1].set_xlabel("test points per pore N")
    ax[1].set_ylabel("relative L2 / max difference")
    ax[1].set_title("what the test points change (end of run)")
    ax[1].legend(fontsize=8)
    ax[1].grid(alpha=0.3, which="both")
    ax[2].plot(nn, [row["interface_seconds"] for row in table], "o-", label="interface build")
    ax[2].plot(nn, [row["wall_seconds"] for row in table], "s-", label="whole coupled run")
    ax[2].set_xlabel("test points per pore N")
    ax[2].set_ylabel("wall time, s (shared 2-core machine)")
    ax[2].set_yscale("log")
    ax[2].legend(fontsize=8)
    ax[2].grid(alpha=0.3, which="both")
    fig.tight_layout()
    fig_path = out / "figures" / "test_points.png"
    fig.savefig(fig_path, dpi=110)
    plt.close(fig)

    results = {
        "case": base.name, "smoke": args.smoke,
        "settings": {"coarsen": base.solid.coarsen, "exchange_dt_s": base.coupling.exchange_dt,
                     "t_end_s": base.drainage.t_end, "network_update": base.network.update,
                     "integrator": base.coupling.integrator, "tolerance": "0.5 r_i (default)"
                     if base.interface.tolerance is None else base.interface.tolerance},
        "reference_n": ns[-1], "table": table, "seed_noise_slope_vs_N": slope,
        "traction_interface": {
            "max_displacement_m": traction["max_displacement_m"], "max_von_mises_Pa": traction["max_von_mises_Pa"],
            "displacement_rel_diff_vs_hull_ref": _rel(traction["U"], ref["U"]),
            "pc_max_abs_diff_vs_hull_ref_Pa": float(np.max(np.abs(traction["pc"] - ref["pc"]))),
            "n_loaded_nodes": traction["n_loaded_nodes"], "n_unloaded_pores": traction["n_unloaded_pores"],
            "interface_seconds": traction["interface_seconds"], "wall_seconds": traction["wall_seconds"]},
        "final_sw": float(ref["sw"][-1]), "pc_range_Pa": [float(ref["pc"][1:].min()), float(ref["pc"].max())],
        "paper": PAPER, "figures": [str(fig_path.relative_to(out))],
    }
    write_results(out / "results.json", results)
    worst = max(row["pc_max_abs_diff_Pa"] for row in table)
    print(f"test_points: max Pc difference over N = {worst:.3g} Pa (paper: ~13.5 kPa); force field "
          f"{table[0]['force_rel_diff_vs_ref']:.3g} rel. at N = {ns[0]}; seed-noise slope {slope} -> {out}")
    return results


if __name__ == "__main__":
    main()
