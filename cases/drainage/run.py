"""Case ``drainage``: the default coupled run on the paper's set-up (figures 5-7) and its 2x4 panel figure.

One coupled run of ``case.toml`` through :func:`porefsi.run_case` (the same code path
as ``porefsi run case.toml``). At the snapshot times 1, 3, 5 and 15 s it keeps the network
saturation, the pore pressures and the solid displacement, then draws

- ``figures/drainage_panel.png``: top row, the network coloured by wetting saturation (paper
  figure 5: red = water, blue = oil); bottom row, the solid (half-cut at mid y) coloured by
  the displacement magnitude on one colour scale for all times (paper figures 6, 7e-h);
- ``figures/pore_pressure.png``: the network coloured by pore fluid pressure, the load the
  solid receives (paper figure 7a-d);
- ``figures/timeseries.png``: saturation, pressures, force, displacement, stress, permeability;

and writes the headline numbers to ``results.json``.

Usage: ``python cases/drainage/run.py [--smoke] [--out DIR] [--work DIR]``.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from porefsi import MILLIDARCY, load_case, plot, run_case, smoke_case

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # cases/: the shared helpers
from _common import loadavg, output_dir, parse_args, pyplot, write_results  # noqa: E402

HERE = Path(__file__).resolve().parent
#: What the paper reports for this run (section 3, table 2).
PAPER = {
    "max_displacement_m": 5.67e-11,  # "5.67e-5 um", at the end of the injection (figure 7h)
    "n_fe_nodes": 11976,
    "n_fe_elements": 56559,
    "n_pores": 240,
    "permeability_mD": 210.0,
    "porosity": 0.1882,
}


def _arguments(p) -> None:
    p.add_argument("--work", type=Path, default=None,
                   help="keep the run directory (ParaView series, timeseries.csv) here; default: temporary")


def _compose(paths, titles, out: Path, *, nrow: int, suptitle: str) -> Path:
    """Tile rendered PNGs into one figure (row-major)."""
    plt = pyplot()
    ncol = int(np.ceil(len(paths) / nrow))
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.2 * ncol, 3.6 * nrow), squeeze=False)
    for ax in axes.ravel():
        ax.axis("off")
    for ax, path, title in zip(axes.ravel(), paths, titles, strict=False):
        ax.imshow(plt.imread(str(path)))
        ax.set_title(title, fontsize=10)
    fig.suptitle(suptitle)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def main(argv=None) -> dict:
    """Run the case, draw the figures, write ``results.json``; return the results."""
    args = parse_args(__doc__, argv, _arguments)
    case = load_case(HERE / "case.toml")
    if args.smoke:
        case = smoke_case(case)
    out = output_dir(args, HERE)
    work_tmp = None
    if args.work is None:
        work_tmp = tempfile.TemporaryDirectory(prefix="porefsi-drainage-run-")
        work = Path(work_tmp.name)
    else:
        work = args.work
    want = [t for t in case.output.snapshot_times if t <= case.drainage.t_end + 1e-9] or [case.drainage.t_end]
    snaps: dict[float, dict] = {}

    def keep(rec) -> None:
        for t in want:
            if abs(rec.t - t) <= 1e-9 * max(1.0, t):
                snaps[t] = {
                    "sw_field": 1.0 - np.asarray(rec.flow.nw_saturation, float),
                    "pressure": np.nan_to_num(np.asarray(rec.flow.fluid_pressure, float)),
                    "coords": rec.network.pore_coords.copy(), "radius": rec.network.pore_radius.copy(),
                    "conns": rec.network.throat_conns.copy(), "u": rec.displacement.copy(), "row": dict(rec.row),
                }

    t0, c0 = time.perf_counter(), time.process_time()
    res = run_case(case, work, progress=False, figures=False, on_record=keep, overwrite=True)
    run_seconds, run_cpu = time.perf_counter() - t0, time.process_time() - c0
    if res.summary["status"] != "completed":
        raise RuntimeError(f"drainage run did not complete: {res.summary}")

    # The reference mesh, read back from the ParaView output of the run.
    import meshio

    m = meshio.read(work / "vtk" / "solid_0000.vtu")
    points, tets = m.points, m.cells_dict["tetra"]

    figs = out / "figures"
    renders = tempfile.TemporaryDirectory(prefix="porefsi-drainage-renders-")
    tmp = Path(renders.name)
    times = sorted(snaps)
    # |u| spans decades (largest next to the loaded pores): a log scale, 3 decades below the
    # largest value of all snapshots, one scale for all times.
    umax = max(float(np.linalg.norm(snaps[t]["u"], axis=1).max()) for t in times) * 1e9
    top = float(np.log10(max(umax, 1e-30)))
    pmax = max(float(snaps[t]["pressure"].max()) for t in times) * 1e-3
    sat_png, disp_png, pres_png, titles = [], [], [], []
    ws = (560, 460)
    for t in times:
        s = snaps[t]
        tag = f"{t:g}".replace(".", "_")
        sat_png.append(plot.render_network(s["coords"], s["radius"], s["conns"], s["sw_field"],
                                           tmp / f"sat_{tag}.png", label="Sw", clim=(0.0, 1.0), window_size=ws,
                                           fade_above=0.999))
        logu = np.log10(np.maximum(np.linalg.norm(s["u"], axis=1) * 1e9, 10.0 ** (top - 6)))
        disp_png.append(plot.render_solid(points, tets, logu, tmp / f"u_{tag}.png", label="log10 |u| nm", cut="y",
                                          clim=(top - 3.0, top), window_size=ws))
        if not args.smoke:  # (smoke: the panel and the time series only, to stay within seconds)
            pres_png.append(plot.render_network(s["coords"], s["radius"], s["conns"], s["pressure"] * 1e-3,
                                                tmp / f"p_{tag}.png", label="P kPa", clim=(0.0, max(pmax, 1e-30)),
                                                cmap="inferno", window_size=ws))
        titles.append(f"t = {t:g} s, Sw = {s['row']['sw']:.3f}")
    u_titles = [f"t = {t:g} s, max |u| = {snaps[t]['row']['max_displacement_m'] * 1e9:.3g} nm" for t in times]
    made = [
        _compose(sat_png + disp_png, titles + u_titles,
                 figs / "drainage_panel.png", nrow=2,
                 suptitle="Top: wetting saturation (red = water, blue = oil). Bottom: |u| of the solid cut at mid y\n"
                          "(log scale, 3 decades, one colour scale for all times)"),
        plot.plot_timeseries(res.timeseries, figs / "timeseries.png", title="drainage: paper case A, 20 s"),
    ]
    if pres_png:
        made.append(_compose(pres_png, [f"t = {t:g} s" for t in times], figs / "pore_pressure.png", nrow=1,
                             suptitle="Pore fluid pressure: the load handed to the solid (paper figure 7a-d)"))
    ts = res.timeseries
    s = res.summary
    results = {
        "case": case.name,
        "smoke": args.smoke,
        "settings": {"coarsen": case.solid.coarsen, "exchange_dt_s": case.coupling.exchange_dt,
                     "integrator": case.coupling.integrator, "interface": case.interface.method,
                     "n_test_points": case.interface.n_test_points,
                     "network_update": case.network.update, "t_end_s": case.drainage.t_end,
                     "rate_m3_s": case.drainage.rate},
        "n_pores": s["n_pores"], "n_throats": s["n_throats"], "n_fe_nodes": s["n_nodes"], "n_fe_elements": s["n_tets"],
        "permeability_mD": s["permeability_initial_m2"] / MILLIDARCY,
        "interface_unloaded_pores": s["interface_unloaded_pores"],
        "at_snapshots": [{"t_s": t, **{k: snaps[t]["row"][k] for k in (
            "sw", "inlet_pressure_Pa", "max_pore_pressure_Pa", "total_pore_force_N", "max_displacement_m",
            "max_von_mises_Pa")}} for t in times],
        "final": {k: ts[k][-1] for k in ("time_s", "sw", "inlet_pressure_Pa", "max_pore_pressure_Pa",
                                         "total_pore_force_N", "max_displacement_m", "max_von_mises_Pa",
                                         "permeability_m2")},
        "max_displacement_m": s["max_displacement_m"],
        "max_von_mises_Pa": s["max_von_mises_Pa"],
        "breakthrough_time_s": s["breakthrough_time_s"],
        "mass_balance_error": s["mass_balance_error"],
        "load_balance_error": s["load_balance_error"],
        "wall_seconds_run": run_seconds,
        "cpu_seconds_run": run_cpu,
        "seconds_by_stage": s["seconds_by_stage"],
        "cpu_seconds_by_stage": s["cpu_seconds_by_stage"],
        "loadavg": loadavg(),
        "paper": PAPER,
        "figures": [str(p.relative_to(out)) for p in made],
    }
    write_results(out / "results.json", results)
    renders.cleanup()
    if work_tmp is not None:
        work_tmp.cleanup()
    print(f"drainage: Sw(20 s) = {results['final']['sw']:.4f}, max |u| = {results['max_displacement_m']:.3e} m "
          f"(paper {PAPER['max_displacement_m']:.3g} m), max von Mises = {results['max_von_mises_Pa'] / 1e3:.3g} kPa, "
          f"run {run_seconds:.1f} s wall, {run_cpu:.1f} s CPU -> {out}")
    return results


if __name__ == "__main__":
    main()
