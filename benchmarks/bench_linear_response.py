"""The linear-response solid (``solid.response``) against the full nonlinear model: accuracy, cost, limits.

Three parts, each printing one table (and all of them as JSON with ``--json FILE``):

1. **images**: the default case (built-in 120³ Berea, coarsen 5, 20 exchange steps) and other
   images (a 120³ crop of the 400³ Berea elsewhere in the sample when ``/work/shared`` has it, a
   synthetic sphere lattice), run nonlinear, then ``auto`` with a cold process cache (the
   factorisation is part of the run) and ``auto`` again (cache hit: a rate-sweep member). Per run:
   the largest relative differences against the nonlinear run of the max |u| history, the pore
   volumes, the inlet pressure and Sw, and the CPU seconds of the solid stage.
2. **flow_rates**: the paper's cases A-D with ``cases/flow_rates`` settings (coarsen 6, hull, static,
   the case's rate-adapted window) run one after the other in this process, nonlinear vs ``auto``.
3. **tdg**: the default case with the paper's TDG integrator, nonlinear vs ``auto`` (linearised TDG).
4. **limits**: the default case with the Young's modulus lowered by 10²..10⁶ (strain up to ~0.1),
   ``linear`` (no fallback) against nonlinear: where the linear result is off by more than 1 %,
   with the monitor's estimate and the largest Green-Lagrange strain; failing runs are listed.

Run: ``python benchmarks/bench_linear_response.py [--quick] [--part images|flow_rates|tdg|limits] [--json FILE]``.
"""

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing

import numpy as np  # noqa: E402
from _data import data_file  # noqa: E402

from porefsi.case import Case, problem_from_case  # noqa: E402
from porefsi.coupling import CoupledRun  # noqa: E402
from porefsi.coupling.linear_step import clear_response_cache, max_green_lagrange  # noqa: E402

BEREA_400 = data_file("berea_icl_400.npz")
FLOW_RATES = {"A": 1.25e-13, "B": 2.5e-13, "C": 5e-11, "D": 5e-10}


def run_once(case: Case, response: str, clear: bool = True, problem=None) -> dict:
    """One coupled run; its histories, CPU by stage and the linear stepper's summary."""
    if clear:
        clear_response_cache()
    prob = problem if problem is not None else problem_from_case(case)
    if problem is not None:
        prob = prob.__class__(prob.image, prob.extraction, prob.mesh_result, prob.interface, prob.model,
                              prob.options.replace(solid={"response": response}))
    out = {"response": response, "n_dofs": prob.model.n_dofs, "n_pores": prob.network.n_pores}
    run = CoupledRun(prob)
    cpu0 = time.process_time()
    hist = {"max_u": [], "pv": [], "pin": [], "sw": [], "strain": [], "U": [],
            "pv_ref": np.array(prob.network.pore_volume)}
    try:
        for rec in run.steps():
            hist["max_u"].append(rec.row["max_displacement_m"])
            hist["U"].append(np.array(rec.displacement))
            hist["pv"].append(np.array(rec.network.pore_volume))
            hist["pin"].append(rec.row["inlet_pressure_Pa"])
            hist["sw"].append(rec.row["sw"])
            hist["strain"].append(max_green_lagrange(prob.model, rec.displacement))
        out["error"] = None
    except Exception as exc:  # noqa: BLE001 - a failing run is a result here
        out["error"] = f"{type(exc).__name__}: {str(exc)[:160]}"
    out["cpu_s"] = time.process_time() - cpu0
    out["solid_cpu_s"] = run.cpu_seconds["solid"]
    out["steps"] = len(hist["max_u"])
    out["hist"] = hist
    out["linear"] = run.solid.summary() if hasattr(run.solid, "summary") else None
    return out


def compare(ref: dict, other: dict) -> dict:
    """Largest relative differences of the histories over the steps both runs completed."""
    n = min(ref["steps"], other["steps"])
    if n == 0:
        return {}
    h0, h1 = ref["hist"], other["hist"]

    def rel(a, b, scale=None):
        a, b = np.asarray(a[:n], float), np.asarray(b[:n], float)
        s = np.abs(a).max() if scale is None else scale
        return float(np.abs(a - b).max() / s) if s > 0 else 0.0

    pv0, pv1 = np.array(h0["pv"][:n]), np.array(h1["pv"][:n])
    pv = float((np.abs(pv0 - pv1) / pv0).max())
    dv = float(np.abs(pv0 - pv1).max() / max(np.abs(pv0 - h0["pv_ref"]).max(), 1e-300))
    U0, U1 = np.array(h0["U"][:n]), np.array(h1["U"][:n])
    du = float(np.abs(U0 - U1).max() / np.abs(U0).max())
    return {"max_u": rel(h0["max_u"], h1["max_u"]), "displacement": du, "pore_volume": pv, "pore_volume_change": dv,
            "inlet_pressure": rel(h0["pin"], h1["pin"]), "sw": rel(h0["sw"], h1["sw"]),
            "max_strain": float(max(h0["strain"][:n]))}


def _images(quick: bool) -> list[tuple[str, Case]]:
    base = Case().replace(output={"figures": False, "vtk": False})
    out = [("berea120 (built-in), coarsen 5", base)]
    if quick:
        return [("berea120 (built-in), coarsen 10", base.replace(solid={"coarsen": 10}))]
    if BEREA_400.is_file():
        out.append(("berea400 crop [250:370]^3, coarsen 5",
                    base.replace(image={"path": str(BEREA_400), "crop": [[250, 370], [250, 370], [250, 370]]})))
    return out


def _lattice_case(tmp: Path) -> Case:
    from porefsi.image.synthetic import sphere_lattice

    lat = sphere_lattice((4, 4, 4), spacing=14, pore_radius=5.0, throat_radius=2.0, voxel_size=5e-6)
    path = tmp / "lattice.npz"
    np.savez_compressed(path, image=lat.image.phases.astype(np.uint8), voxel_size_m=5e-6)
    return Case().replace(image={"path": str(path)}, solid={"coarsen": 2}, output={"figures": False, "vtk": False})


def part_images(quick: bool, tmp: Path) -> list[dict]:
    cases = _images(quick)
    if not quick:
        cases.append(("sphere lattice 4x4x4 (synthetic), coarsen 2", _lattice_case(tmp)))
    rows = []
    for name, case in cases:
        prob = problem_from_case(case)
        ref = run_once(case, "nonlinear", problem=prob)
        cold = run_once(case, "auto", problem=prob)
        warm = run_once(case, "auto", clear=False, problem=prob)
        row = {"image": name, "n_dofs": ref["n_dofs"], "n_pores": ref["n_pores"], "steps": ref["steps"],
               "solid_cpu_nonlinear": ref["solid_cpu_s"], "solid_cpu_auto_cold": cold["solid_cpu_s"],
               "solid_cpu_auto_warm": warm["solid_cpu_s"], "cpu_nonlinear": ref["cpu_s"],
               "cpu_auto_warm": warm["cpu_s"],
               "diff": compare(ref, cold), "diff_warm": compare(ref, warm), "linear": cold["linear"],
               "errors": [r["error"] for r in (ref, cold, warm) if r["error"]]}
        rows.append(row)
        d = row["diff"]
        print(f"{name}: {row['n_dofs']} dofs, {row['n_pores']} pores, {row['steps']} steps; solid CPU nonlinear "
              f"{row['solid_cpu_nonlinear']:.2f} s, auto cold {row['solid_cpu_auto_cold']:.2f} s "
              f"({row['solid_cpu_nonlinear'] / row['solid_cpu_auto_cold']:.1f}x), warm {row['solid_cpu_auto_warm']:.2f}"
              f" s ({row['solid_cpu_nonlinear'] / max(row['solid_cpu_auto_warm'], 1e-9):.1f}x); max rel diff: "
              f"max|u| {d['max_u']:.2e}, u field {d['displacement']:.2e}, pore volume {d['pore_volume']:.2e} "
              f"(of its change "
              f"{d['pore_volume_change']:.2e}), inlet P {d['inlet_pressure']:.2e}, Sw {d['sw']:.2e}; "
              f"estimate {cold['linear']['max_estimated_error']:.2e}, path {cold['linear']['path']}, max strain "
              f"{d['max_strain']:.2e}", flush=True)
    return rows


def _window(rate: float, pore_volume: float, t_end: float = 20.0, dt: float = 1.0) -> tuple[float, float]:
    """cases/flow_rates' window: <= 20 s or 2 pore volumes, steps <= 1 s or 0.05 pore volumes."""
    t_pv = pore_volume / rate
    dt_q, t_q = min(dt, 0.05 * t_pv), min(t_end, 2.0 * t_pv)
    n = max(1, int(round(t_q / dt_q)))
    return t_q, t_q / n


def part_flow_rates(quick: bool) -> dict:
    base = Case().replace(solid={"coarsen": 10 if quick else 6}, interface={"method": "hull", "n_test_points": 800},
                          network={"update": "geometric"}, coupling={"integrator": "static"},
                          output={"figures": False, "vtk": False})
    prob = problem_from_case(base)
    pv = float(prob.network.pore_volume.sum())
    out = {"cases": {}}
    for response in ("nonlinear", "auto"):
        clear_response_cache()
        tot_cpu = tot_solid = 0.0
        for name, q in FLOW_RATES.items():
            t_end, dt = _window(q, pv)
            opts = prob.options.replace(drainage={"rate": q, "t_end": t_end}, coupling={"exchange_dt": dt},
                                        solid={"response": response})
            p = prob.__class__(prob.image, prob.extraction, prob.mesh_result, prob.interface, prob.model, opts)
            r = run_once(base, response, clear=False, problem=p)
            tot_cpu += r["cpu_s"]
            tot_solid += r["solid_cpu_s"]
            out["cases"].setdefault(name, {})[response] = r
        out[response] = {"cpu_s": tot_cpu, "solid_cpu_s": tot_solid}
    for name in FLOW_RATES:
        c = out["cases"][name]
        c["diff"] = compare(c["nonlinear"], c["auto"])
        c["steps"] = c["nonlinear"]["steps"]
        c["path"] = c["auto"]["linear"]["path"]
        for r in ("nonlinear", "auto"):
            c[r] = {k: c[r][k] for k in ("cpu_s", "solid_cpu_s", "error")}
        print(f"flow rate case {name} ({FLOW_RATES[name]:.3g} m^3/s, {c['steps']} steps): solid CPU nonlinear "
              f"{c['nonlinear']['solid_cpu_s']:.2f} s, auto {c['auto']['solid_cpu_s']:.2f} s ({c['path']}); max rel "
              f"diff max|u| {c['diff']['max_u']:.2e}, Sw {c['diff']['sw']:.2e}", flush=True)
    n, a = out["nonlinear"], out["auto"]
    print(f"cases A-D: run CPU nonlinear {n['cpu_s']:.1f} s (solid {n['solid_cpu_s']:.1f}), auto {a['cpu_s']:.1f} s "
          f"(solid {a['solid_cpu_s']:.1f}): solid {n['solid_cpu_s'] / a['solid_cpu_s']:.1f}x, run "
          f"{n['cpu_s'] / a['cpu_s']:.2f}x", flush=True)
    return out


def part_tdg(quick: bool) -> dict:
    case = Case().replace(solid={"coarsen": 10 if quick else 5}, coupling={"integrator": "tdg"},
                          output={"figures": False, "vtk": False})
    prob = problem_from_case(case)
    ref = run_once(case, "nonlinear", problem=prob)
    lin = run_once(case, "auto", problem=prob)
    d = compare(ref, lin)
    print(f"TDG ({ref['n_dofs']} dofs, {ref['steps']} steps): solid CPU nonlinear {ref['solid_cpu_s']:.2f} s, auto "
          f"{lin['solid_cpu_s']:.2f} s ({ref['solid_cpu_s'] / lin['solid_cpu_s']:.1f}x, {lin['linear']['path']}); "
          f"max rel diff u field {d['displacement']:.2e}, max|u| {d['max_u']:.2e}; estimate "
          f"{lin['linear']['max_estimated_error']:.2e}", flush=True)
    return {"solid_cpu_nonlinear": ref["solid_cpu_s"], "solid_cpu_auto": lin["solid_cpu_s"], "diff": d,
            "linear": lin["linear"]}


def part_limits(quick: bool) -> list[dict]:
    coarsen = 10 if quick else 5
    base = Case().replace(solid={"coarsen": coarsen}, output={"figures": False, "vtk": False})
    prob = problem_from_case(base)
    factors = (1e2, 1e4, 1e5) if quick else (1e2, 1e3, 1e4, 3e4, 1e5, 3e5, 1e6)
    rows = []
    for f in factors:
        opts = prob.options.replace(solid={"E": prob.options.solid.E / f})
        from porefsi.coupling.problem import build_solid

        mres, model = build_solid(prob.image, opts.solid)
        p = prob.__class__(prob.image, prob.extraction, mres, prob.interface, model, opts)
        ref = run_once(base, "nonlinear", problem=p)
        lin = run_once(base, "linear", problem=p)
        auto = run_once(base, "auto", clear=False, problem=p)
        d = compare(ref, lin)
        row = {"E_Pa": opts.solid.E, "E_factor": f, "steps_nonlinear": ref["steps"], "steps_linear": lin["steps"],
               "diff": d, "estimate": lin["linear"]["max_estimated_error"] if lin["linear"] else None,
               "auto_fallback": auto["linear"]["fallback"] if auto["linear"] else None,
               "auto_diff": compare(ref, auto),
               "errors": {"nonlinear": ref["error"], "linear": lin["error"], "auto": auto["error"]}}
        rows.append(row)
        fb = row["auto_fallback"]
        print(f"E = {row['E_Pa']:.3g} Pa (/{f:g}): steps {ref['steps']}/{lin['steps']}; max strain "
              f"{d.get('max_strain', float('nan')):.2e}; linear vs nonlinear max|u| {d.get('max_u', float('nan')):.2e},"
              f" u field {d.get('displacement', float('nan')):.2e},"
              f" pore volume change {d.get('pore_volume_change', float('nan')):.2e}, inlet P "
              f"{d.get('inlet_pressure', float('nan')):.2e}; estimate {row['estimate']:.2e}; auto: "
              f"{'fell back at t = ' + format(fb['t'], 'g') + ' s' if fb else 'stayed linear'} (max|u| diff "
              f"{row['auto_diff'].get('max_u', float('nan')):.2e}); errors {row['errors']}", flush=True)
    return rows


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="coarse meshes, fewer runs")
    p.add_argument("--part", choices=("images", "flow_rates", "tdg", "limits"), action="append", default=None)
    p.add_argument("--json", default=None, metavar="FILE", help="write every number as JSON")
    args = p.parse_args(argv)
    parts = args.part or ["images", "flow_rates", "tdg", "limits"]
    import tempfile

    print(f"load {open('/proc/loadavg').read().split()[:3]}", flush=True)
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        if "images" in parts:
            out["images"] = part_images(args.quick, Path(tmp))
        if "flow_rates" in parts:
            out["flow_rates"] = part_flow_rates(args.quick)
        if "tdg" in parts:
            out["tdg"] = part_tdg(args.quick)
        if "limits" in parts:
            out["limits"] = part_limits(args.quick)
    print(f"load {open('/proc/loadavg').read().split()[:3]}", flush=True)
    if args.json:
        def strip(o):
            if isinstance(o, dict):
                return {k: strip(v) for k, v in o.items() if k not in ("hist", "nonlinear_run", "auto_run")}
            if isinstance(o, list):
                return [strip(v) for v in o]
            return o if not isinstance(o, np.generic) else o.item()
        Path(args.json).write_text(json.dumps(strip(out), indent=1, default=str))
    return out


if __name__ == "__main__":
    main()
