"""Case ``flow_rates``: deformation and stress vs injection rate (paper cases A-D, figure 9).

Coupled runs of ``case.toml`` at the paper's four rates (A 1.25e-13, B 2.5e-13, C 5e-11,
D 5e-10 m^3/s) and intermediate ones. The paper runs 20 s at every rate; at 5e-10 m^3/s that is
200 pore volumes, with breakthrough after 0.04 s. Here each run lasts 20 s or 2 pore volumes,
whichever is shorter, with exchange steps of 1 s or 0.05 pore volumes, whichever is shorter (so
the pressure path before breakthrough reaches the solid; at most 40 steps per run). Per rate: the
largest displacement and von Mises stress over the run and at its end, the final saturation, the
breakthrough time and the capillary number Ca = mu_n (Q / A) / sigma (A = inlet face area).

A fluid-only scan on a finer grid of rates (the DPN is cheap; the solid is linear in the load at
these strains) locates where the behaviour changes: the inlet pressure at 20 s and its peak over
the run (every DPN event, so transients shorter than an exchange step are seen), against

- Pc_bt, the capillary pressure of the quasi-static (invasion-percolation) path at breakthrough;
- dP_visc(Q) = Q mu_n L / (k A), the viscous pressure drop of oil through the network
  (k the network's absolute permeability): the crossover rate Q* solves dP_visc(Q*) = Pc_bt.

The coupled runs are the members of a sweep (``sweep.toml``: ``porefsi sweep sweep.toml -o DIR``
runs the same members; ``python run.py --write-sweep`` regenerates it from the pore volume), run
on a local Dask cluster (``--serial`` in this process; the default for ``--smoke``;
``--scheduler ADDRESS`` an existing cluster) into ``runs/<member>/``, with ``runs/sweep.csv``.

Outputs: ``figures/flow_rates.png``, ``results.json``, ``runs/sweep.csv``.
Usage: ``python cases/flow_rates/run.py [--smoke] [--out DIR] [--serial | --scheduler ADDRESS] [--resume]``.
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import numpy as np

from porefsi import DrainageSimulator, absolute_permeability, load_case, problem_from_case, smoke_case
from porefsi.flow import invasion_percolation
from porefsi.sweep import Cluster, run_sweep, sweep_from_dict

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # cases/: the shared helpers
from _common import output_dir, parse_args, pyplot, sweep_arguments, write_results  # noqa: E402

HERE = Path(__file__).resolve().parent
PAPER_CASES = {"A": 1.25e-13, "B": 2.5e-13, "C": 5e-11, "D": 5e-10}
RATES_FULL = sorted({*PAPER_CASES.values(), 1e-12, 5e-12, 2e-11, 1e-10, 2e-10})
RATES_SMOKE = [1.25e-13, 5e-10]
SCAN_FULL = np.logspace(-13, -9, 25)
#: Rate-adapted window: at most PV_STEP injected pore volumes per exchange step (so the solid sees
#: the pressure path before breakthrough, which is over within ~0.3 PV), and the run stops after
#: PV_END pore volumes or the paper's 20 s, whichever comes first (steps: at most 40).
PV_STEP = 0.05
PV_END = 2.0
SCAN_SMOKE = np.logspace(-13, -9, 3)
#: The paper (section 3.2, figure 9): deformation and stress increase monotonically with rate up
#: to a critical point slightly below 1e-10 m^3/s; beyond it the solid deforms more significantly.
PAPER = {"cases_m3_s": PAPER_CASES, "critical_rate_m3_s": "slightly below 1e-10"}


def _arguments(p) -> None:
    sweep_arguments(p)
    p.add_argument("--write-sweep", action="store_true", help="write sweep.toml (the full study's members) and stop")


def window(rate: float, pore_volume: float, t_end: float, dt: float) -> tuple[float, float]:
    """Run length and exchange step at ``rate``: the case's (paper: 20 s, 1 s), shortened to
    :data:`PV_END` injected pore volumes and refined to :data:`PV_STEP` per step at high rates."""
    t_pv = pore_volume / rate
    dt_q = min(dt, PV_STEP * t_pv)
    t_q = min(t_end, PV_END * t_pv)
    n = max(1, int(round(t_q / dt_q)))
    return t_q, t_q / n


def sweep_dict(rates, pore_volume: float, base, smoke: bool) -> dict:
    """The coupled runs as a sweep: ``case.toml`` at each rate with its window (zip of rate, t_end, dt)."""
    wins = [window(q, pore_volume, base.drainage.t_end, base.coupling.exchange_dt) for q in rates]
    return {"base": {"case": "case.toml", "smoke": smoke, "output": {"vtk": False, "figures": False}},
            "vary": {"mode": "zip", "drainage.rate": [float(q) for q in rates],
                     "drainage.t_end": [w[0] for w in wins], "coupling.exchange_dt": [w[1] for w in wins]},
            "plot": {"x": "drainage.rate", "y": ["max_displacement_m", "max_von_mises_Pa", "final_sw"],
                     "logx": True, "logy": True}}


def sweep_toml(d: dict) -> str:
    """TOML text of :func:`sweep_dict` (what ``--write-sweep`` writes)."""
    def val(v):
        return repr(v) if not isinstance(v, (bool, str)) else ("true" if v is True else "false" if v is False
                                                                 else f'"{v}"')
    b, v, p = d["base"], d["vary"], d["plot"]
    lines = ["# The coupled runs of run.py (written by `python run.py --write-sweep`): case.toml at each rate,",
             "# with the rate-adapted window (<= 20 s or 2 pore volumes; <= 0.05 pore volumes per step).",
             "# `porefsi sweep sweep.toml -o DIR` runs them; run.py adds the fluid-only scan and the figure.",
             "[base]", f"case = {val(b['case'])}", f"smoke = {val(b['smoke'])}",
             *(f"output.{k} = {val(x)}" for k, x in b["output"].items()), "", "[vary]", f"mode = {val(v['mode'])}"]
    lines += [f'"{k}" = [{", ".join(val(x) for x in xs)}]' for k, xs in v.items() if k != "mode"]
    lines += ["", "[plot]", f"x = {val(p['x'])}", f"y = [{', '.join(val(y) for y in p['y'])}]",
              f"logx = {val(p['logx'])}", f"logy = {val(p['logy'])}"]
    return "\n".join(lines) + "\n"


def member_row(rec: dict, folder: Path) -> dict:
    """One coupled run's row from its sweep record and time series: extremes over the run, end state."""
    s = rec["summary"]
    with open(folder / "timeseries.csv", newline="") as fh:
        rows = [{k: float(x) if x != "" else float("nan") for k, x in r.items()} for r in csv.DictReader(fh)][1:]
    return {"rate_m3_s": rec["values"]["drainage.rate"], "max_displacement_m": s["max_displacement_m"],
            "max_von_mises_Pa": s["max_von_mises_Pa"], "final_displacement_m": rows[-1]["max_displacement_m"],
            "final_von_mises_Pa": rows[-1]["max_von_mises_Pa"], "final_sw": rows[-1]["sw"],
            "final_inlet_pressure_Pa": rows[-1]["inlet_pressure_Pa"],
            "max_pore_pressure_Pa": max(r["max_pore_pressure_Pa"] for r in rows),
            "breakthrough_time_s": s["breakthrough_time_s"], "mass_balance_error": s["mass_balance_error"],
            "wall_seconds": s["wall_seconds"], "cpu_seconds": s["cpu_seconds"], "member": rec["name"]}


def fluid_scan(net, fluids, axis: str, rates, t_end: float, window_end) -> list[dict]:
    """DPN alone at each rate for ``t_end``: inlet pressure at the end and its peak over all events
    (and over the coupled run's window ``[0, window_end(rate)]``)."""
    out = []
    for q in rates:
        sim = DrainageSimulator(net, fluids, rate=float(q), axis=axis)
        st = sim.advance_to(t_end)
        h = sim.history()
        p = h["inlet_pressure_pa"]
        bt = sim.breakthrough_time
        in_win = np.isfinite(p) & (h["time_s"] <= window_end(q) * (1 + 1e-12))
        out.append({"rate_m3_s": float(q), "final_inlet_pressure_Pa": float(st.inlet_pressure),
                    "peak_inlet_pressure_Pa": float(np.nanmax(p)) if np.isfinite(p).any() else float("nan"),
                    "peak_inlet_pressure_window_Pa": float(p[in_win].max()) if in_win.any() else float("nan"),
                    "final_sw": float(st.sw), "breakthrough_time_s": None if not np.isfinite(bt) else float(bt),
                    "mass_balance_error": float(st.mass_balance_error), "n_events": sim.counters["n_events"]})
    return out


def main(argv=None) -> dict:
    """Sweep the rate, draw the figure, write ``results.json``; return the results."""
    args = parse_args(__doc__, argv, _arguments, smoke_help="seconds-long version (coarse mesh, 2 steps, 2 rates)")
    base = load_case(HERE / "case.toml")
    if args.smoke:
        base = smoke_case(base)
    out = output_dir(args, HERE)
    prob = problem_from_case(base)
    net, fl, axis = prob.network, prob.fluids, base.image.axis
    ax_i = "xyz".index(axis)
    extent = np.asarray(prob.image.extent, float)
    area = float(np.prod(np.delete(extent, ax_i)))
    length = float(extent[ax_i])
    k = absolute_permeability(net, axis).k_m2
    ip = invasion_percolation(net, fl, axis=axis)
    pc_bt = float(ip.capillary_pressure[ip.breakthrough_step]) if ip.breakthrough_step >= 0 else float("nan")
    q_star = pc_bt * k * area / (fl.mu_n * length)
    pore_volume = float(net.pore_volume.sum())

    scan = fluid_scan(net, fl, axis, SCAN_SMOKE if args.smoke else SCAN_FULL, base.drainage.t_end,
                      lambda q: window(q, pore_volume, base.drainage.t_end, base.coupling.exchange_dt)[0])
    # Measured change: first scanned rate whose peak inlet pressure exceeds twice the capillary
    # path value (viscous drop = capillary pressure), interpolated in log-log.
    q_meas = None
    for a, b in zip(scan[:-1], scan[1:], strict=False):
        pa, pb = a["peak_inlet_pressure_Pa"], b["peak_inlet_pressure_Pa"]
        if pa < 2 * pc_bt <= pb:
            w = (np.log(2 * pc_bt) - np.log(pa)) / (np.log(pb) - np.log(pa))
            q_meas = float(np.exp(np.log(a["rate_m3_s"]) + w * (np.log(b["rate_m3_s"]) - np.log(a["rate_m3_s"]))))
            break

    rates = RATES_SMOKE if args.smoke else RATES_FULL
    spec = sweep_dict(rates, pore_volume, base, args.smoke)
    if args.write_sweep:
        (HERE / "sweep.toml").write_text(sweep_toml(sweep_dict(RATES_FULL, pore_volume, base, False)))
        print(f"wrote {HERE / 'sweep.toml'}")
        return {}
    sweep = sweep_from_dict(spec, base_dir=HERE, where="flow_rates sweep")
    res = run_sweep(sweep, out / "runs", Cluster(serial=args.serial or (args.smoke and not args.scheduler),
                                             scheduler=args.scheduler), overwrite=not args.resume)
    failed = [r["name"] for r in res.records if r["status"] != "completed"]
    if failed:
        raise SystemExit(f"flow_rates: members {failed} failed; see {res.table}")
    rows = []
    for m, rec in zip(sweep.members, res.records, strict=True):
        q = m.case.drainage.rate
        r = member_row(rec, out / "runs" / m.name)
        r["t_end_s"], r["exchange_dt_s"] = m.case.drainage.t_end, m.case.coupling.exchange_dt
        r["capillary_number"] = fl.capillary_number(q, area)
        r["injected_pore_volumes"] = q * r["t_end_s"] / pore_volume
        r["paper_case"] = next((n for n, v in PAPER_CASES.items() if np.isclose(v, q, rtol=1e-9, atol=0.0)), None)
        rows.append(r)
        print(f"  Q = {q:.3g} m^3/s (Ca {r['capillary_number']:.2g}): max |u| = {r['max_displacement_m']:.4e} m, "
              f"max vM = {r['max_von_mises_Pa'] / 1e3:.4g} kPa, Sw = {r['final_sw']:.3f} ({r['wall_seconds']:.1f} s)",
              flush=True)

    plt = pyplot()

    q = np.array([r["rate_m3_s"] for r in rows])
    fig, ax = plt.subplots(1, 3, figsize=(16, 4.5))
    for a_, key, fin, lab, sc in ((ax[0], "max_displacement_m", "final_displacement_m", "|u| max, nm", 1e9),
                                  (ax[1], "max_von_mises_Pa", "final_von_mises_Pa", "von Mises max, kPa", 1e-3)):
        a_.loglog(q, [r[key] * sc for r in rows], "o-", label="max over the run")
        a_.loglog(q, [r[fin] * sc for r in rows], "s--", mfc="none", label="at the end of the run")
        for r in rows:
            if r["paper_case"]:
                a_.annotate(r["paper_case"], (r["rate_m3_s"], r[key] * sc), textcoords="offset points",
                            xytext=(-4, 6), fontsize=9)
        a_.axvline(q_star, color="k", ls=":", lw=1, label="Q*: viscous drop = Pc_bt")
        a_.set_xlabel("injection rate Q, m³/s")
        a_.set_ylabel(lab)
        a_.grid(alpha=0.3, which="both")
        a_.legend(fontsize=8)
        sec = a_.secondary_xaxis("top", functions=(lambda x: fl.capillary_number(1.0, area) * x,
                                                   lambda c: c / fl.capillary_number(1.0, area)))
        sec.set_xlabel("Ca")
    ax[0].set_title("deformation vs rate (coupled runs)")
    ax[1].set_title("stress vs rate (coupled runs)")
    qs = np.array([s["rate_m3_s"] for s in scan])
    ax[2].loglog(qs, [s["peak_inlet_pressure_Pa"] * 1e-3 for s in scan], "o-", ms=3, label="peak over the run")
    ax[2].loglog(qs, [s["peak_inlet_pressure_window_Pa"] * 1e-3 for s in scan], "^:", ms=3,
                 label="peak within the coupled run's window")
    ax[2].loglog(qs, [s["final_inlet_pressure_Pa"] * 1e-3 for s in scan], "s--", ms=3, mfc="none",
                 label=f"at t = {base.drainage.t_end:g} s")
    ax[2].axhline(pc_bt * 1e-3, color="C2", lw=1, label=f"Pc_bt (IP) = {pc_bt / 1e3:.2f} kPa")
    ax[2].loglog(qs, qs * fl.mu_n * length / (k * area) * 1e-3, "k:", lw=1, label="Q μ_n L / (k A)")
    ax[2].axvline(q_star, color="k", ls=":", lw=1)
    ax[2].set_ylim(0.3 * pc_bt * 1e-3, None)
    ax[2].set_xlabel("injection rate Q, m³/s")
    ax[2].set_ylabel("inlet pressure, kPa")
    ax[2].set_title("fluid only: where viscous forces take over")
    ax[2].grid(alpha=0.3, which="both")
    tw = ax[2].twinx()
    tw.semilogx(qs, [s["final_sw"] for s in scan], "-", color="C3", alpha=0.6)
    tw.set_ylabel(f"Sw at {base.drainage.t_end:g} s", color="C3")
    tw.set_ylim(0, 1.05)
    ax[2].legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    fig_path = out / "figures" / "flow_rates.png"
    fig.savefig(fig_path, dpi=110)
    plt.close(fig)

    results = {
        "case": base.name, "smoke": args.smoke,
        "settings": {"coarsen": base.solid.coarsen, "exchange_dt_s": base.coupling.exchange_dt,
                     "t_end_s": base.drainage.t_end, "pv_per_step_max": PV_STEP, "pv_end": PV_END,
                     "integrator": base.coupling.integrator,
                     "network_update": base.network.update, "n_test_points": base.interface.n_test_points},
        "inlet_area_m2": area, "length_m": length, "permeability_m2": k, "pore_volume_m3": pore_volume,
        "pc_breakthrough_ip_Pa": pc_bt,
        "critical_rate_estimate_m3_s": q_star, "critical_rate_measured_m3_s": q_meas,
        "critical_capillary_number": fl.capillary_number(q_star, area),
        "coupled": rows, "fluid_scan": scan, "paper": PAPER, "figures": [str(fig_path.relative_to(out))],
        "sweep_table": str(res.table.relative_to(out)),
    }
    write_results(out / "results.json", results)
    print(f"flow_rates: Q* = {q_star:.3g} m^3/s estimated, {q_meas} measured (Ca* = "
          f"{results['critical_capillary_number']:.2g}); paper: slightly below 1e-10 -> {out}")
    return results


if __name__ == "__main__":
    main()
