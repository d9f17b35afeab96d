"""CPU time by stage for fluid-only, decoupled and coupled runs (seed paper table 1).

Measures, on the built-in 120^3 Berea sample with the paper's table-2 set-up (20 s of injection
at 1.25e-13 m^3/s, 1 s exchange steps, mesh coarsened to the paper's size) and the paper's
method (convex-hull interface with 800 test points, TDG; pinned in ``case.toml``):

- fluid only: image -> maximal-ball extraction -> dynamic pore-network drainage (no solid);
- decoupled: the coupled loop with network.update = "none" (pore pressures load the solid, the
  network never changes: one-way);
- coupled: network.update = "geometric" (porefsi's default) and "reextract" (the paper's
  re-extraction with pre-coupling iterations);
- coupled at porefsi's defaults: the geometric update with the consistent traction interface and
  the quasi-static solid (``porefsi.case.config.Case()``), not a row of the paper's table.

CPU time is ``time.process_time`` of the whole run (this process, all threads; BLAS pinned to one
thread), wall time by stage comes from the run summary. The machine is shared: wall times are noisy.

Usage: python cases/cost/run.py [--smoke] [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from porefsi.case.config import Case, load_case, smoke_case
from porefsi.case.run import run_case
from porefsi.coupling.problem import fluids_from_case, load_case_image
from porefsi.flow.drainage import simulate_drainage
from porefsi.image.ops import percolating_cluster
from porefsi.network.extract import extract_network

HERE = Path(__file__).resolve().parent
DEFAULT_ROW = "coupled, porefsi defaults (traction, static)"

#: Seed paper table 1, FE-DPN* row: CPU minutes and cell counts (x 1e3 as printed).
PAPER = {"fluid_min": 2.0, "coupled_min": 186.9, "decoupled_min": 10.6, "fluid_cells_k": 640, "solid_cells_k": 56.5,
         "note": "fluid cells 640 (footnote: number of nodes and throats; 240 pores in table 2, so the "
                 "'x 10^3' of the header cannot apply to this entry)"}


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def fluid_only(case) -> dict:
    w0, c0 = time.perf_counter(), time.process_time()
    img = load_case_image(case)
    t_img = time.perf_counter()
    net = extract_network(percolating_cluster(img, case.image.axis).image).network
    t_ex = time.perf_counter()
    res = simulate_drainage(net, fluids_from_case(case), rate=case.drainage.rate, t_end=case.drainage.t_end,
                            axis=case.image.axis)
    t_end = time.perf_counter()
    return {"cpu_s": time.process_time() - c0, "wall_s": t_end - w0,
            "stages_wall_s": {"image": t_img - w0, "extraction": t_ex - t_img, "fluid": t_end - t_ex},
            "n_pores": net.n_pores, "n_throats": net.n_throats, "final_sw": float(res.final.sw)}


def coupled(case, update: str, out: Path, tag: str | None = None, **sections) -> dict:
    tag = tag or update
    c = case.replace(name=f"{case.name}-{tag}", network={"update": update}, **sections)
    c0 = time.process_time()
    res = run_case(c, out / f"run_{tag}", figures=False, progress=False)
    s = res.summary
    return {"cpu_s": time.process_time() - c0, "wall_s": s["wall_seconds"], "stages_wall_s": s["seconds_by_stage"],
            "n_pores": s["n_pores"], "n_throats": s["n_throats"], "n_nodes": s["n_nodes"], "n_tets": s["n_tets"],
            "n_steps": s["n_exchange_steps"], "final_sw": s["final_sw"], "max_displacement_m": s["max_displacement_m"],
            "interface": c.interface.method, "integrator": c.coupling.integrator}


def figure(rows: dict, path: Path) -> Path:
    plt = _plt()
    stages = sorted({k for r in rows.values() for k in r["stages_wall_s"]})
    fig, ax = plt.subplots(figsize=(8, 4.5))
    bottom = np.zeros(len(rows))
    for st in stages:
        v = np.array([r["stages_wall_s"].get(st, 0.0) for r in rows.values()])
        ax.bar(list(rows), v, bottom=bottom, label=st)
        bottom += v
    ax.plot(list(rows), [r["cpu_s"] for r in rows.values()], "k_", ms=30, mew=2, label="CPU total (process_time)")
    ax.set_ylabel("seconds")
    ax.set_yscale("log")
    ax.set_ylim(0.1, None)
    ax.legend(fontsize=7, ncol=2)
    ax.grid(alpha=0.3, axis="y")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def markdown(rows: dict) -> str:
    lines = ["| run | porefsi CPU (s) | porefsi wall (s) | fluid elements (pores+throats) | solid tets | "
             "paper CPU (min) | paper cells (fluid, solid) |", "|---|---|---|---|---|---|---|"]
    paper = {"fluid only": (PAPER["fluid_min"], "640, -"),
             "decoupled (update none)": (PAPER["decoupled_min"], "640, 56.5k"),
             "coupled (geometric)": (PAPER["coupled_min"], "640, 56.5k"),
             "coupled (re-extraction)": (PAPER["coupled_min"], "640, 56.5k"),
             DEFAULT_ROW: ("-", "-")}
    for name, r in rows.items():
        pm, pc = paper[name]
        tets = r.get("n_tets", "-")
        lines.append(f"| {name} | {r['cpu_s']:.1f} | {r['wall_s']:.1f} | {r['n_pores'] + r['n_throats']} | {tets} | "
                     f"{pm} | {pc} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--smoke", action="store_true", help="seconds-long version (coarse mesh, 2 steps)")
    ap.add_argument("--out", type=Path, default=None, help="output directory (default: this folder)")
    args = ap.parse_args(argv)
    out = args.out or (Path(tempfile.mkdtemp(prefix="porefsi-cost-")) if args.smoke else HERE)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    case = load_case(HERE / "case.toml")
    if args.smoke:
        case = smoke_case(case)
    rows = {"fluid only": fluid_only(case)}
    rows["decoupled (update none)"] = coupled(case, "none", out / "runs")
    rows["coupled (geometric)"] = coupled(case, "geometric", out / "runs")
    rows["coupled (re-extraction)"] = coupled(case, "reextract", out / "runs")
    defaults = Case()
    rows[DEFAULT_ROW] = coupled(case, "geometric", out / "runs", tag="default",
                                interface={"method": defaults.interface.method},
                                coupling={"integrator": defaults.coupling.integrator})
    fig_dir = out / "figures"
    fig_dir.mkdir(parents=True, exist_ok=True)
    figure(rows, fig_dir / "cost_by_stage.png")
    table = markdown(rows)
    res = {"paper": PAPER, "runs": rows, "table_markdown": table, "smoke": bool(args.smoke),
           "ratios": {"coupled_geometric_over_fluid_cpu":
                      rows["coupled (geometric)"]["cpu_s"] / rows["fluid only"]["cpu_s"],
                      "coupled_reextract_over_decoupled_cpu": rows["coupled (re-extraction)"]["cpu_s"]
                      / rows["decoupled (update none)"]["cpu_s"],
                      "coupled_geometric_over_decoupled_cpu": rows["coupled (geometric)"]["cpu_s"]
                      / rows["decoupled (update none)"]["cpu_s"],
                      "default_over_coupled_geometric_cpu": rows[DEFAULT_ROW]["cpu_s"]
                      / rows["coupled (geometric)"]["cpu_s"],
                      "paper_coupled_over_decoupled": PAPER["coupled_min"] / PAPER["decoupled_min"],
                      "paper_coupled_over_fluid": PAPER["coupled_min"] / PAPER["fluid_min"]},
           "figures": ["cost_by_stage.png"], "wall_s": time.perf_counter() - t0}
    (out / "results.json").write_text(json.dumps(res, indent=1, default=float))
    print(table)
    print(f"cost: wall {res['wall_s']:.0f} s -> {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
