"""Case ``coupling_stability``: does the staggered fluid-solid iteration diverge for a soft solid?

Within one exchange step, porefsi's strong coupling (``coupling.subiterations > 1``) iterates the
fixed point ``U -> network(U) -> DPN pressures P -> nodal forces -> solid U'`` (geometric network
update). This study sweeps the Young's modulus E of the solid down from rock to hydrogel values,
at the paper's rate (case A, capillary-dominated) and at case D (5e-10 m^3/s, viscous), with
relaxation ``none`` (plain fixed point) and ``aitken``, and records:

- the full sub-iteration residual history of the first exchange step (the loop is asked for a
  tolerance of 1e-300, so it runs all ``N_ITER`` iterations and returns the history in the
  :class:`~porefsi.errors.ConvergenceError` it raises; nothing is patched);
- the contraction factor (geometric mean of successive residual ratios above round-off) and the
  iterations to reach 1e-6;
- where the solid model itself fails (an element inverts under the pore pressure: ``MeshError``);
- multi-step runs of ``case.toml`` (E = 3 kPa, 1.5 kPa) with both relaxations: iterations per step.

The solid is solved quasi-statically (``integrator = "static"``: every elastic period is far
below the 1 s exchange step even at E = 1 kPa), neo-Hookean (valid at finite strain; St
Venant-Kirchhoff also swept, it softens in compression and fails earlier), on the coarsen-10 mesh.

Outputs: ``figures/stability_histories.png``, ``figures/stability_vs_E.png``,
``figures/stability_multistep.png``, ``results.json``.
Usage: ``python cases/coupling_stability/run.py [--smoke] [--out DIR]``.
"""

from __future__ import annotations

import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from porefsi.case.config import load_case  # noqa: E402
from porefsi.coupling.loop import CoupledRun  # noqa: E402
from porefsi.coupling.problem import build_problem  # noqa: E402
from porefsi.errors import ConvergenceError, PorefsiError  # noqa: E402

HERE = Path(__file__).resolve().parent
N_ITER = 25
FLOOR = 1e-11  # residual ratios are measured only above this (round-off floor ~1e-13)
TOL = 1e-6
REGIMES = {  # name: (rate m^3/s, exchange step s)
    "A: 1.25e-13 m^3/s (capillary)": (1.25e-13, 1.0),
    "D: 5e-10 m^3/s (viscous)": (5e-10, 1.0),
}


def sweep_design(smoke: bool) -> list[tuple[str, str, list[float]]]:
    """(regime, material, E values) of the sweep."""
    if smoke:
        return [("A: 1.25e-13 m^3/s (capillary)", "neo-hookean", [1e5, 3e3])]
    return [
        ("A: 1.25e-13 m^3/s (capillary)", "neo-hookean", [1e7, 1e6, 1e5, 3e4, 1e4, 5e3, 3e3, 2e3, 1.5e3, 1.2e3, 1e3]),
        ("A: 1.25e-13 m^3/s (capillary)", "svk", [1e5, 1e4, 5e3, 3e3, 2.5e3]),
        ("D: 5e-10 m^3/s (viscous)", "neo-hookean", [1e8, 1e7, 3e6, 1e6, 5e5, 3e5, 2e5, 1e5]),
    ]


def first_step(base, regime: str, material: str, E: float, relaxation: str, n_iter: int) -> dict:
    """Residual history of the first exchange step (all n_iter sub-iterations), or the failure."""
    rate, dt = REGIMES[regime]
    case = base.replace(solid={"E": E, "material": material}, drainage={"rate": rate, "t_end": dt},
                        coupling={"exchange_dt": dt, "subiterations": n_iter, "subiteration_tol": 1e-300,
                                  "relaxation": relaxation, "integrator": "static"})
    out = {"regime": regime, "material": material, "E": E, "relaxation": relaxation}
    c0 = time.process_time()
    try:
        run = CoupledRun(build_problem(case))
        for rec in run.steps():  # "converges" only when an iterate repeats bit for bit (residual 0)
            n_used = int(rec.row["subiterations"])
            out.update(status="ran", history=[0.0])
        if n_used > 1:  # the same deterministic iteration stopped one short returns the history before the 0
            try:
                next(CoupledRun(build_problem(case.replace(coupling={"subiterations": n_used - 1}))).steps())
            except ConvergenceError as exc:
                out["history"] = [float(h) for h in exc.history] + [0.0]
    except ConvergenceError as exc:
        out.update(status="ran", history=[float(h) for h in exc.history])
    except PorefsiError as exc:
        out.update(status=f"{type(exc).__name__}: {str(exc)[:160]}", history=[])
    out["cpu_s"] = time.process_time() - c0
    h = np.asarray(out["history"], float)
    out["contraction"] = contraction(h)
    below = np.flatnonzero(h < TOL)
    out["iterations_to_tol"] = int(below[0]) + 1 if below.size else None
    return out


def contraction(h: np.ndarray, max_ratios: int = 6) -> float | None:
    """Geometric mean of r_{k+1}/r_k from the second residual on, while above the round-off floor."""
    ratios = []
    for k in range(1, len(h) - 1):
        if h[k + 1] <= FLOOR or h[k] <= FLOOR or len(ratios) >= max_ratios:
            break
        ratios.append(h[k + 1] / h[k])
    return float(np.exp(np.mean(np.log(ratios)))) if ratios else None


def plain_pressure(base, regime: str) -> dict:
    """Inlet and maximum pore pressure after the first step on the stiff rock (E = 20 GPa, one pass)."""
    rate, dt = REGIMES[regime]
    case = base.replace(solid={"E": 20e9, "material": "svk"}, drainage={"rate": rate, "t_end": dt},
                        coupling={"exchange_dt": dt, "subiterations": 1, "integrator": "static"})
    rec = next(CoupledRun(build_problem(case)).steps())
    return {"inlet_pressure_Pa": rec.row["inlet_pressure_Pa"], "max_pore_pressure_Pa": rec.row["max_pore_pressure_Pa"],
            "sw": rec.row["sw"]}


def multistep(base, E: float, relaxation: str, t_end: float) -> dict:
    """Whole run of case.toml at E with the given relaxation: sub-iterations per step."""
    case = base.replace(solid={"E": E}, drainage={"t_end": t_end}, coupling={"relaxation": relaxation})
    out = {"E": E, "relaxation": relaxation, "iterations": [], "residual": [], "max_displacement_m": []}
    c0 = time.process_time()
    try:
        for rec in CoupledRun(build_problem(case)).steps():
            out["iterations"].append(rec.row["subiterations"])
            out["residual"].append(rec.row["coupling_residual"])
            out["max_displacement_m"].append(rec.row["max_displacement_m"])
        out["status"] = "ok"
    except ConvergenceError as exc:
        out["status"] = f"ConvergenceError: {str(exc)[:200]}"
        out["failed_history"] = [float(h) for h in exc.history]
    except PorefsiError as exc:
        out["status"] = f"{type(exc).__name__}: {str(exc)[:200]}"
    out["cpu_s"] = time.process_time() - c0
    return out


def plot_histories(rows: list[dict], path: Path) -> None:
    """Residual histories, one panel per regime (neo-Hookean), none solid / Aitken dashed."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    regimes = [r for r in REGIMES if any(x["regime"] == r for x in rows)]
    fig, axes = plt.subplots(1, len(regimes), figsize=(6.5 * len(regimes), 4.8), squeeze=False)
    for ax, reg in zip(axes[0], regimes, strict=True):
        sel = [x for x in rows if x["regime"] == reg and x["material"] == "neo-hookean" and x["history"]]
        Es = sorted({x["E"] for x in sel}, reverse=True)
        cmap = plt.get_cmap("viridis")
        for i, E in enumerate(Es):
            col = cmap(i / max(1, len(Es) - 1))
            for x in sel:
                if x["E"] == E:
                    ls = "-" if x["relaxation"] == "none" else "--"
                    ax.semilogy(np.arange(1, len(x["history"]) + 1), x["history"], ls, color=col, marker=".",
                                ms=3, label=f"E = {E:.3g} Pa" if x["relaxation"] == "none" else None)
        failed = sorted({x["E"] for x in rows if x["regime"] == reg and x["material"] == "neo-hookean"
                         and not x["history"]})
        ax.set_title(f"{reg}\nsolid: - none, -- Aitken; element inversion at E <= "
                     f"{max(failed) if failed else float('nan'):.3g} Pa", fontsize=9)
        ax.set_xlabel("sub-iteration")
        ax.set_ylabel("|U_k - U_{k-1}| / |U_k|")
        ax.axhline(TOL, color="grey", lw=0.8, ls=":")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def plot_vs_E(rows: list[dict], pressures: dict, path: Path) -> None:
    """Contraction factor and iterations to 1e-6 against E, with the failure region."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(13, 4.8))
    styles = {("neo-hookean", "none"): ("-o", "none"), ("neo-hookean", "aitken"): ("--s", "Aitken"),
              ("svk", "none"): (":^", "none (SVK)"), ("svk", "aitken"): (":v", "Aitken (SVK)")}
    for ci, reg in enumerate(REGIMES):
        col = f"C{ci}"
        for (mat, rel), (st, lab) in styles.items():
            sel = sorted([x for x in rows if x["regime"] == reg and x["material"] == mat and x["relaxation"] == rel],
                         key=lambda x: x["E"])
            ok = [x for x in sel if x["contraction"] is not None]
            if ok:
                ax.loglog([x["E"] for x in ok], [x["contraction"] for x in ok], st, color=col, ms=4,
                          label=f"{reg.split(':')[0]} {lab}")
            it = [x for x in sel if x["history"]]
            if it:
                ax2.semilogx([x["E"] for x in it], [x["iterations_to_tol"] or np.nan for x in it], st, color=col,
                             ms=4, label=f"{reg.split(':')[0]} {lab}")
            bad = [x["E"] for x in sel if not x["history"]]
            if bad and mat == "neo-hookean" and rel == "none":
                for a in (ax, ax2):
                    a.axvspan(min(bad) / 1.5, max(bad), color=col, alpha=0.12)
        p = pressures.get(reg)
        if p:
            Eg = np.logspace(2.5, 8.5, 50)
            ax.loglog(Eg, p["inlet_pressure_Pa"] / Eg, color=col, lw=0.8, alpha=0.6,
                      label=f"{reg.split(':')[0]} P_in/E (P_in = {p['inlet_pressure_Pa']:.3g} Pa)")
    ax.axhline(1.0, color="k", lw=1)
    ax.text(3e2, 1.1, "divergence of the plain iteration needs contraction > 1", fontsize=8)
    ax.set_ylim(1e-6, 5)
    ax.set_xlabel("Young's modulus E, Pa")
    ax.set_ylabel("contraction factor per sub-iteration")
    ax.set_title("shaded: solid fails (element inverts) before the coupling can diverge", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    ax2.set_xlabel("Young's modulus E, Pa")
    ax2.set_ylabel(f"sub-iterations to reach {TOL:g} (first step)")
    ax2.grid(True, which="both", alpha=0.3)
    ax2.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def plot_multistep(ms: list[dict], path: Path) -> None:
    """Sub-iterations per exchange step, whole runs."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for i, m in enumerate(ms):
        ls = "-o" if m["relaxation"] == "none" else "--s"
        if m["iterations"]:
            ax.plot(np.arange(1, len(m["iterations"]) + 1), m["iterations"], ls, color=f"C{i // 2}",
                    label=f"E = {m['E']:.3g} Pa, {m['relaxation']} ({m['cpu_s']:.0f} s CPU)")
    ax.set_xlabel("exchange step (1 s)")
    ax.set_ylabel("sub-iterations to 1e-8")
    ax.set_title("whole runs of case.toml: iterations per step", fontsize=9)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def main(argv=None) -> int:
    """Run the study."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--smoke", action="store_true", help="two E values, 8 sub-iterations, no whole runs")
    p.add_argument("--out", type=Path, default=None, help="output folder (default: this folder; --smoke: temp)")
    args = p.parse_args(argv)
    out = args.out if args.out is not None else (
        Path(tempfile.mkdtemp(prefix="porefsi-coupling_stability-smoke-")) if args.smoke else HERE)
    (out / "figures").mkdir(parents=True, exist_ok=True)
    base = load_case(HERE / "case.toml")
    n_iter = 8 if args.smoke else N_ITER
    design = sweep_design(args.smoke)
    pressures = {reg: plain_pressure(base, reg) for reg in {d[0] for d in design}}
    rows = []
    for reg, mat, Es in design:
        for E in Es:
            for rel in ("none", "aitken"):
                r = first_step(base, reg, mat, E, rel, n_iter)
                rows.append(r)
                c = r["contraction"]
                print(f"{reg[:1]} {mat:>11} E={E:8.3g} {rel:>6}: {r['status'][:50]:<12} "
                      f"rho={'-' if c is None else f'{c:.3g}'} it={r['iterations_to_tol']} "
                      f"({r['cpu_s']:.1f} s)", flush=True)
    ms = []
    if not args.smoke:
        for E in (3e3, 1.5e3):
            for rel in ("none", "aitken"):
                m = multistep(base, E, rel, base.drainage.t_end)
                ms.append(m)
                print(f"multistep E={E:g} {rel}: {m['status'][:80]} its={m['iterations']} ({m['cpu_s']:.1f} s)",
                      flush=True)
    summary = {"case": "coupling_stability", "smoke": args.smoke, "n_iter": n_iter, "tol": TOL,
               "pressures": pressures, "first_step": rows, "multistep": ms}
    (out / "results.json").write_text(json.dumps(summary, indent=1, default=float))
    plot_histories(rows, out / "figures" / "stability_histories.png")
    plot_vs_E(rows, pressures, out / "figures" / "stability_vs_E.png")
    if ms:
        plot_multistep(ms, out / "figures" / "stability_multistep.png")
    print(f"outputs in {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
