"""CPU time by stage for fluid-only, decoupled and coupled runs (seed paper table 1).

Measures, on the built-in 120^3 Berea sample with the paper's table-2 set-up (20 s of injection
at 1.25e-13 m^3/s, 1 s exchange steps, mesh coarsened to the paper's size) and the paper's
method (convex-hull interface with 800 test points, TDG; pinned in ``case.toml``):

- fluid only: image -> maximal-ball extraction -> dynamic pore-network drainage (no solid);
- decoupled: the coupled loop with network.update = "none" (pore pressures load the solid, the
  network never changes: one-way);
- coupled: network.update = "geometric" (porefsi's default) and "reextract" (the paper's
  re-extraction with pre-coupling iterations), the latter twice: with porefsi's extraction cache
  (an image seen before reuses its extraction; at the paper's loads the deformed image is the
  reference image, so nothing is voxelised or extracted) and without it
  (``run_case(..., reuse_extractions=False)``: every re-extraction computed, the paper's cost);
- coupled at porefsi's defaults: the geometric update with the consistent traction interface and
  the quasi-static solid (``porefsi.Case()``), not a row of the paper's table.

CPU time is ``time.process_time`` (this process, all threads; BLAS pinned to one thread): of the
whole run, and by stage from the run summary's ``cpu_seconds_by_stage`` (wall time by stage is kept
next to it). A smoke-sized coupled run first warms up imports and numba caches, so the first
measured run does not pay them. The machine is shared: wall times are noisy, CPU times less so.

Usage: python cases/cost/run.py [--smoke] [--out DIR]
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from porefsi import Case, extract_network, load_case, percolating_cluster, run_case, simulate_drainage, smoke_case
from porefsi.case import coupled_options, load_case_image

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # cases/: the shared helpers
from _common import loadavg, output_dir, parse_args, pyplot, write_results  # noqa: E402

HERE = Path(__file__).resolve().parent
DEFAULT_ROW = "coupled, porefsi defaults (traction, static)"
NOCACHE_ROW = "coupled (re-extraction, extraction cache off)"

#: Seed paper table 1, FE-DPN* row: CPU minutes and cell counts (x 1e3 as printed).
PAPER = {"fluid_min": 2.0, "coupled_min": 186.9, "decoupled_min": 10.6, "fluid_cells_k": 640, "solid_cells_k": 56.5,
         "note": "fluid cells 640 (footnote: number of nodes and throats; 240 pores in table 2, so the "
                 "'x 10^3' of the header cannot apply to this entry)"}


def fluid_only(case) -> dict:
    wall, cpu = {}, {}
    w0, c0 = time.perf_counter(), time.process_time()

    def lap(stage, w, c):
        wall[stage], cpu[stage] = time.perf_counter() - w, time.process_time() - c
        return time.perf_counter(), time.process_time()

    img = load_case_image(case)
    w, c = lap("image", w0, c0)
    net = extract_network(percolating_cluster(img, case.image.axis).image).network
    w, c = lap("extraction", w, c)
    res = simulate_drainage(net, coupled_options(case).fluids, case.drainage, axis=case.image.axis)
    lap("fluid", w, c)
    return {"cpu_s": time.process_time() - c0, "wall_s": time.perf_counter() - w0, "stages_cpu_s": cpu,
            "stages_wall_s": wall, "n_pores": net.n_pores, "n_throats": net.n_throats, "final_sw": float(res.final.sw)}


def coupled(case, update: str, out: Path, tag: str | None = None, reuse_extractions: bool = True,
            **sections) -> dict:
    tag = tag or update
    c = case.replace(name=f"{case.name}-{tag}", network={"update": update}, **sections)
    c0 = time.process_time()
    res = run_case(c, out / f"run_{tag}", figures=False, progress=False, reuse_extractions=reuse_extractions,
                   overwrite=True)
    s = res.summary
    return {"cpu_s": time.process_time() - c0, "wall_s": s["wall_seconds"], "stages_cpu_s": s["cpu_seconds_by_stage"],
            "stages_wall_s": s["seconds_by_stage"], "reextraction": s["reextraction"],
            "n_pores": s["n_pores"], "n_throats": s["n_throats"], "n_nodes": s["n_nodes"], "n_tets": s["n_tets"],
            "n_steps": s["n_exchange_steps"], "final_sw": s["final_sw"], "max_displacement_m": s["max_displacement_m"],
            "interface": c.interface.method, "integrator": c.coupling.integrator}


STAGES = ("image", "extraction", "mesh", "interface_build", "fluid", "interface", "solid", "update", "stress",
          "permeability")


def figure(rows: dict, path: Path) -> Path:
    plt = pyplot()
    stages = [s for s in STAGES if any(s in r["stages_cpu_s"] for r in rows.values())]
    fig, ax = plt.subplots(figsize=(10, 4.8))
    x = np.arange(len(rows))
    bottom = np.zeros(len(rows))
    for st in stages:
        v = np.array([r["stages_cpu_s"].get(st, 0.0) for r in rows.values()])
        ax.bar(x, v, bottom=bottom, label=st)
        bottom += v
    cpu = [r["cpu_s"] for r in rows.values()]
    ax.plot(x, cpu, "k_", ms=30, mew=2, label="CPU total of the run")
    ax.plot(x, [r["wall_s"] for r in rows.values()], "r_", ms=20, mew=1.5, label="wall total (shared machine)")
    for xi, c in zip(x, cpu, strict=True):
        ax.annotate(f"{c:.2g} s", (xi, c), textcoords="offset points", xytext=(0, 4), ha="center", fontsize=7)
    ax.set_xticks(x, [n.replace(" (", "\n(").replace(", ", ",\n") for n in rows], fontsize=7)
    ax.set_ylabel("CPU seconds by stage (time.process_time)")
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
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
             NOCACHE_ROW: (PAPER["coupled_min"], "640, 56.5k"),
             DEFAULT_ROW: ("-", "-")}
    for name, r in rows.items():
        pm, pc = paper[name]
        tets = r.get("n_tets", "-")
        lines.append(f"| {name} | {r['cpu_s']:.1f} | {r['wall_s']:.1f} | {r['n_pores'] + r['n_throats']} | {tets} | "
                     f"{pm} | {pc} |")
    return "\n".join(lines)


def stage_markdown(rows: dict, key: str = "stages_cpu_s") -> str:
    stages = [s for s in STAGES if s != "image" and any(s in r[key] for r in rows.values())]
    lines = ["| run | " + " | ".join(stages) + " |", "|---" * (len(stages) + 1) + "|"]
    for name, r in rows.items():
        cells = [f"{r[key][s]:.2f}" if s in r[key] else "-" for s in stages]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    args = parse_args(__doc__, argv)
    out = output_dir(args, HERE)
    t0 = time.perf_counter()
    load0 = loadavg()
    case = load_case(HERE / "case.toml")
    if args.smoke:
        case = smoke_case(case)
    coupled(smoke_case(case), "reextract", Path(tempfile.mkdtemp(prefix="porefsi-cost-warmup-")), tag="warmup")
    rows = {"fluid only": fluid_only(case)}
    rows["decoupled (update none)"] = coupled(case, "none", out / "runs")
    rows["coupled (geometric)"] = coupled(case, "geometric", out / "runs")
    rows["coupled (re-extraction)"] = coupled(case, "reextract", out / "runs")
    rows[NOCACHE_ROW] = coupled(case, "reextract", out / "runs", tag="reextract_nocache", reuse_extractions=False)
    defaults = Case()
    rows[DEFAULT_ROW] = coupled(case, "geometric", out / "runs", tag="default",
                                interface={"method": defaults.interface.method},
                                coupling={"integrator": defaults.coupling.integrator})
    fig_dir = out / "figures"
    figure(rows, fig_dir / "cost_by_stage.png")
    table = markdown(rows)
    res = {"paper": PAPER, "runs": rows, "table_markdown": table, "stage_cpu_markdown": stage_markdown(rows),
           "stage_wall_markdown": stage_markdown(rows, "stages_wall_s"), "smoke": bool(args.smoke),
           "ratios": {"coupled_geometric_over_fluid_cpu":
                      rows["coupled (geometric)"]["cpu_s"] / rows["fluid only"]["cpu_s"],
                      "coupled_reextract_over_decoupled_cpu": rows["coupled (re-extraction)"]["cpu_s"]
                      / rows["decoupled (update none)"]["cpu_s"],
                      "coupled_reextract_nocache_over_decoupled_cpu": rows[NOCACHE_ROW]["cpu_s"]
                      / rows["decoupled (update none)"]["cpu_s"],
                      "coupled_geometric_over_decoupled_cpu": rows["coupled (geometric)"]["cpu_s"]
                      / rows["decoupled (update none)"]["cpu_s"],
                      "default_over_coupled_geometric_cpu": rows[DEFAULT_ROW]["cpu_s"]
                      / rows["coupled (geometric)"]["cpu_s"],
                      "paper_coupled_over_decoupled": PAPER["coupled_min"] / PAPER["decoupled_min"],
                      "paper_coupled_over_fluid": PAPER["coupled_min"] / PAPER["fluid_min"]},
           "figures": ["cost_by_stage.png"], "wall_s": time.perf_counter() - t0,
           "loadavg": {"before": load0, "after": loadavg()}}
    write_results(out / "results.json", res)
    print(table)
    print("\nCPU s by stage:\n" + res["stage_cpu_markdown"])
    print(f"cost: wall {res['wall_s']:.0f} s -> {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
