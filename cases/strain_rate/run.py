"""Axial loading at several strain rates during drainage (seed paper section 3.3, figures 11-15).

Runs ``case.toml`` (strain rate 6.235e-4 1/s: strain 0.01247 at 20 s) and the same case at lower
rates (2.8e-5 and 8e-5 1/s reach the paper's figure-11 strains 0.00056 and 0.00160 at 20 s) and at
rate 0 (drainage only, the control), and draws:

- ``displacement_nodes.png`` (fig. 11): displacement of two FE nodes vs time, every rate;
- ``psd_over_time.png`` (fig. 13): pore-size distribution at 1, 4, 5, 8, 10, 14, 20 s (highest rate);
- ``pore_pressure_vs_strain.png`` (fig. 12b): inlet and max pore pressure vs strain, and their
  change against the rate-0 run at the same time;
- ``permeability_vs_time.png`` (fig. 15);
- ``network_before.png`` / ``network_after.png`` (fig. 14): pores coloured by radius change.

The four runs are the members of a sweep (``sweep.toml``; ``porefsi sweep sweep.toml -o DIR`` runs
the same members) into ``runs/<member>/`` with ``runs/sweep.csv``, on a local Dask cluster
(``--serial``: in this process, the default with ``--smoke``; ``--scheduler ADDRESS``: an existing
cluster). Each member writes its solid field at every exchange step (``vtk/solid_NNNN.vtu``) and
its pores (``pores/step_NNNN.npz``): the figures are drawn from those files.

Usage: python cases/strain_rate/run.py [--smoke] [--out DIR] [--serial | --scheduler ADDRESS] [--resume]
"""

from __future__ import annotations

import csv
import sys
import time
import types
from pathlib import Path

import meshio
import numpy as np

from porefsi import MILLIDARCY as MD
from porefsi import load_case, plot, problem_from_case, read_pore_steps, smoke_case
from porefsi.sweep import Cluster, load_sweep, run_sweep, sweep_from_dict

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # cases/: the shared helpers
from _common import output_dir, parse_args, pyplot, sweep_arguments, write_results  # noqa: E402

HERE = Path(__file__).resolve().parent
RATES = (0.0, 2.8e-5, 8.0e-5, 6.235e-4)  # 1/s
PSD_TIMES = (1.0, 4.0, 5.0, 8.0, 10.0, 14.0, 20.0)  # s (paper figure 13 and the end)


def load_run(rec: dict, folder: Path) -> dict:
    """One member's results from its folder: summary, time series, displacement and pores at every step."""
    with open(folder / "timeseries.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    ts = {k: [float(r[k]) if r[k] != "" else float("nan") for r in rows] for k in rows[0]}
    steps = read_pore_steps(folder)[1:]  # step 0 is the initial state
    U = [meshio.read(folder / "vtk" / f"solid_{s['step']:04d}.vtu").point_data["displacement"] for s in steps]
    return {"rate": rec["values"]["solid.strain_rate"], "summary": rec["summary"], "ts": ts, "U": U,
            "t": [s["time_s"] for s in steps],
            "nets": [types.SimpleNamespace(pore_radius=s["pore_radius_m"], pore_coords=s["pore_coords_m"])
                     for s in steps]}


def the_sweep(smoke: bool):
    """``sweep.toml``; with ``smoke`` its seconds-long variant at the lowest and highest rate."""
    sweep = load_sweep(HERE / "sweep.toml")
    if not smoke:
        return sweep
    d = {"base": {"case": "case.toml", "smoke": True, "output": {"vtk": True, "snapshot_times": [1.0, 2.0]}},
         "vary": {"solid.strain_rate": [RATES[0], RATES[-1]]}}
    return sweep_from_dict(d, base_dir=HERE, where="strain_rate smoke sweep")


def pick_nodes(mesh, length: float) -> list[int]:
    """Two pore-wall nodes near the sample's axis, at 1/2 and 3/4 of the height (z)."""
    wall = mesh.nodes_tagged("pore_wall")
    x = mesh.points[wall]
    c = 0.5 * (x.min(axis=0) + x.max(axis=0))
    out = []
    for frac in (0.5, 0.75):
        target = np.array([c[0], c[1], frac * length])
        out.append(int(wall[np.argmin(np.linalg.norm(x - target, axis=1))]))
    return out


def figures(runs: list[dict], problem, nodes: list[int], fig_dir: Path) -> list[str]:
    plt = pyplot()
    fig_dir.mkdir(parents=True, exist_ok=True)
    made = []
    # fig. 11: displacement at two nodes
    fig, axs = plt.subplots(1, 2, figsize=(11, 4))
    for ax, n in zip(axs, nodes, strict=True):
        for r in runs:
            u = np.array([np.linalg.norm(U[n]) for U in r["U"]])
            ax.plot(r["ts"]["time_s"][1:], u * 1e9, "o-", ms=3, label=f"rate {r['rate']:g} 1/s")
        z = problem.mesh.points[n] * 1e6
        ax.set_title(f"node {n} at ({z[0]:.0f}, {z[1]:.0f}, {z[2]:.0f}) µm")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("|u| (nm)")
        ax.set_yscale("log")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    made.append(fig_dir / "displacement_nodes.png")
    fig.savefig(made[-1], dpi=120)
    plt.close(fig)
    # fig. 13: PSD over time at the highest rate
    hi = runs[-1]
    times = [0.0] + [t for t in PSD_TIMES if t <= hi["t"][-1] + 1e-9]
    radii = [(0.0, problem.network.pore_radius)]
    for t in times[1:]:
        i = int(np.argmin(np.abs(np.array(hi["t"]) - t)))
        radii.append((hi["t"][i], hi["nets"][i].pore_radius))
    made.append(plot.plot_psd(radii, fig_dir / "psd_over_time.png", bins=20))
    # the shift itself: per-pore relative radius change (far below the PSD's bin width)
    fig, ax = plt.subplots(figsize=(6, 4))
    r0 = problem.network.pore_radius
    for t, r in radii[1:]:
        ch = np.sort((np.asarray(r) / r0 - 1.0) * 100)
        ax.plot(ch, np.arange(1, ch.size + 1) / ch.size, "-", label=f"t = {t:g} s (strain {hi['rate'] * t:.2g})")
    ax.set_xlabel("pore radius change r(t)/r(0) - 1 (%)")
    ax.set_ylabel("cumulative fraction of pores")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    made.append(fig_dir / "radius_change_cdf.png")
    fig.savefig(made[-1], dpi=120)
    plt.close(fig)
    # fig. 12b: pore pressure vs strain
    base = runs[0]["ts"]
    fig, axs = plt.subplots(1, 2, figsize=(11, 4))
    for r in runs[1:]:
        ts = r["ts"]
        strain = r["rate"] * np.asarray(ts["time_s"])
        pin = np.asarray(ts["inlet_pressure_Pa"], float)
        pmax = np.asarray(ts["max_pore_pressure_Pa"], float)
        axs[0].plot(strain, pin * 1e-3, "o-", ms=3, label=f"inlet, rate {r['rate']:g}")
        axs[0].plot(strain, pmax * 1e-3, "x--", ms=3, label=f"max pore, rate {r['rate']:g}")
        n = min(len(pin), len(base["inlet_pressure_Pa"]))
        dp = pin[:n] - np.asarray(base["inlet_pressure_Pa"][:n], float)
        axs[1].plot(strain[:n], dp, "o-", ms=3, label=f"rate {r['rate']:g}")
    axs[0].set_ylabel("pressure (kPa)")
    axs[1].set_ylabel("inlet pressure minus rate-0 run (Pa)")
    for ax in axs:
        ax.set_xlabel("axial strain")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    made.append(fig_dir / "pore_pressure_vs_strain.png")
    fig.savefig(made[-1], dpi=120)
    plt.close(fig)
    # fig. 15: permeability over time
    fig, ax = plt.subplots(figsize=(6, 4))
    for r in runs:
        ax.plot(r["ts"]["time_s"], np.asarray(r["ts"]["permeability_m2"]) / MD, "o-", ms=3,
                label=f"rate {r['rate']:g} 1/s")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("absolute permeability (mD)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    made.append(fig_dir / "permeability_vs_time.png")
    fig.savefig(made[-1], dpi=120)
    plt.close(fig)
    # fig. 14: network before / after, coloured by relative radius change
    net0, net1 = problem.network, hi["nets"][-1]
    change = (net1.pore_radius / net0.pore_radius - 1.0) * 100
    lim = max(float(np.max(np.abs(change))), 1e-6)
    made.append(plot.render_network(net0.pore_coords, net0.pore_radius, net0.throat_conns, np.zeros(net0.n_pores),
                                    fig_dir / "network_before.png", label="radius change (%)", clim=(-lim, lim)))
    # the geometric update moves and resizes pores; the throats (net0.throat_conns) stay
    made.append(plot.render_network(net1.pore_coords, net1.pore_radius, net0.throat_conns, change,
                                    fig_dir / "network_after.png", label="radius change (%)", clim=(-lim, lim)))
    return [Path(m).name for m in made]


def main(argv=None) -> int:
    args = parse_args(__doc__, argv, sweep_arguments)
    out = output_dir(args, HERE)
    t0 = time.perf_counter()
    case = load_case(HERE / "case.toml")
    if args.smoke:
        case = smoke_case(case)
    sweep = the_sweep(args.smoke)
    res = run_sweep(sweep, out / "runs", Cluster(serial=args.serial or (args.smoke and not args.scheduler),
                                             scheduler=args.scheduler), overwrite=not args.resume)
    failed = [r["name"] for r in res.records if r["status"] != "completed"]
    if failed:
        raise SystemExit(f"strain_rate: members {failed} failed; see {res.table}")
    runs = [load_run(r, out / "runs" / m.name) for m, r in zip(sweep.members, res.records, strict=True)]
    problem = problem_from_case(case)
    nodes = pick_nodes(problem.mesh, problem.image.extent[2])
    made = figures(runs, problem, nodes, out / "figures")
    per_rate = []
    for r in runs:
        ts, net0, net1 = r["ts"], problem.network, r["nets"][-1]
        per_rate.append({
            "strain_rate_per_s": r["rate"],
            "final_strain": r["rate"] * r["t"][-1],
            "t_end_s": r["t"][-1],
            "node_displacement_final_m": [float(np.linalg.norm(r["U"][-1][n])) for n in nodes],
            "max_displacement_m": r["summary"]["max_displacement_m"],
            "max_von_mises_Pa": r["summary"]["max_von_mises_Pa"],
            "mean_pore_radius_change": float(np.mean(net1.pore_radius) / np.mean(net0.pore_radius) - 1),
            "pore_radius_change_min_max": [float(np.min(net1.pore_radius / net0.pore_radius - 1)),
                                           float(np.max(net1.pore_radius / net0.pore_radius - 1))],
            # pores with fewer than 4 wall nodes in the interface keep their size under the geometric update
            "fraction_pores_radius_unchanged": float(np.mean(np.abs(net1.pore_radius / net0.pore_radius - 1)
                                                             < 1e-12)),
            "permeability_initial_mD": ts["permeability_m2"][0] / MD,
            "permeability_final_mD": ts["permeability_m2"][-1] / MD,
            "permeability_change": ts["permeability_m2"][-1] / ts["permeability_m2"][0] - 1,
            "inlet_pressure_final_Pa": ts["inlet_pressure_Pa"][-1],
            "sw_final": ts["sw"][-1],
            "wall_s": r["summary"]["wall_seconds"],
        })
    res = {
        "paper": {"strains_fig11": [0.00056, 0.00160], "max_strain": 0.01247,
                  "reports": "PSD shifts left (pores shrink), pore pressure rises with strain, "
                             "permeability decreases with load (figures 12b, 13, 15)"},
        "nodes": nodes,
        "node_positions_m": problem.mesh.points[nodes].tolist(),
        "runs": per_rate,
        "figures": made,
        "smoke": bool(args.smoke),
        "sweep_table": str(res.table.relative_to(out)),
        "wall_s": time.perf_counter() - t0,
    }
    write_results(out / "results.json", res)
    for r in per_rate:
        print(f"rate {r['strain_rate_per_s']:g}: strain {r['final_strain']:.4g}, k {r['permeability_initial_mD']:.0f}"
              f" -> {r['permeability_final_mD']:.1f} mD ({100 * r['permeability_change']:+.2f} %), mean r "
              f"{100 * r['mean_pore_radius_change']:+.3f} %, inlet p {r['inlet_pressure_final_Pa']:.0f} Pa")
    print(f"strain_rate: wall {res['wall_s']:.0f} s -> {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
