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
- multi-step runs of ``case.toml`` (E = 3 kPa, 1.5 kPa) with both relaxations: iterations per step;
- the **amplified loop gain**: the physical loop never reaches a gain of 1 before the solid fails
  (README: the load of a filling pore is proportional to 1/V, a self-limiting feedback), so to
  show what the staggered scheme does beyond it, the first step at E = 100 kPa is re-run with the
  pore loads ``P* + kappa (P(U) - P*)`` handed to the solid, ``P(U)`` the DPN's pore pressures
  on the network deformed by ``U`` and ``(U*, P*)`` the converged physical step: the fixed point
  is unchanged and the loop's Jacobian is kappa times the physical one. That sub-iteration is
  :class:`porefsi.CoupledRun`'s own, given the amplification as its ``load_map`` and observed
  through ``on_iteration`` (every iterate); at kappa = 1 it is the physical loop itself (the
  residual history of the sweep's first step, checked in every run).

The solid is solved quasi-statically (``integrator = "static"``: every elastic period is far
below the 1 s exchange step even at E = 1 kPa), neo-Hookean (valid at finite strain; St
Venant-Kirchhoff also swept, it softens in compression and fails earlier), on the coarsen-10 mesh.

Outputs: ``figures/stability_histories.png``, ``figures/stability_vs_E.png``,
``figures/stability_multistep.png``, ``figures/stability_amplified.png``, ``results.json``.
Usage: ``python cases/coupling_stability/run.py [--smoke] [--out DIR] [--parts sweep multistep amplified]``
(``--parts`` runs only those parts and keeps the others' results from ``OUT/results.json``).
"""

from __future__ import annotations

import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS"):  # not NUMBA_NUM_THREADS: see cases/_common.py
    os.environ.setdefault(_v, "1")

import dataclasses  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from porefsi import ConvergenceError, CoupledRun, PorefsiError, load_case, problem_from_case  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # cases/: the shared helpers
from _common import git_head, output_dir, parse_args, pyplot, write_results  # noqa: E402

HERE = Path(__file__).resolve().parent
N_ITER = 25
FLOOR = 1e-11  # residual ratios are measured only above this (round-off floor ~1e-13)
TOL = 1e-6
REGIMES = {  # name: (rate m^3/s, exchange step s)
    "A: 1.25e-13 m^3/s (capillary)": (1.25e-13, 1.0),
    "D: 5e-10 m^3/s (viscous)": (5e-10, 1.0),
}
PARTS = ("sweep", "multistep", "amplified")
AMP_REGIME, AMP_E = "A: 1.25e-13 m^3/s (capillary)", 1e5  # small strain (max |u| 0.8 um, 1.5 % of a mesh cell)
#: Amplifications beyond kappa = 1 (the check, run first) as multiples of the predicted threshold
#: 1/g, g the physical loop's factor measured at kappa = 1: the threshold moves with the rock's
#: network (it was ~55 with the paper's network, ~280 with the voxel-staircase radii).
AMP_MULTIPLES = (0.2, 0.5, 0.8, 1.0, 1.3, 2.0, 4.0)
AMP_MULTIPLES_SMOKE = (2.0,)
MECH_E = 1.5e3  # softest E at which the case-A first step runs (1.2 kPa inverts an element)


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
        run = CoupledRun(problem_from_case(case))
        for rec in run.steps():  # "converges" only when an iterate repeats bit for bit (residual 0)
            n_used = int(rec.row["subiterations"])
            out.update(status="ran", history=[0.0])
        if n_used > 1:  # the same deterministic iteration stopped one short returns the history before the 0
            try:
                next(CoupledRun(problem_from_case(case.replace(coupling={"subiterations": n_used - 1}))).steps())
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
    rec = next(CoupledRun(problem_from_case(case)).steps())
    return {"inlet_pressure_Pa": rec.row["inlet_pressure_Pa"], "max_pore_pressure_Pa": rec.row["max_pore_pressure_Pa"],
            "sw": rec.row["sw"]}


def multistep(base, E: float, relaxation: str, t_end: float) -> dict:
    """Whole run of case.toml at E with the given relaxation: sub-iterations per step."""
    case = base.replace(solid={"E": E}, drainage={"t_end": t_end}, coupling={"relaxation": relaxation})
    out = {"E": E, "relaxation": relaxation, "iterations": [], "residual": [], "max_displacement_m": []}
    c0 = time.process_time()
    try:
        for rec in CoupledRun(problem_from_case(case)).steps():
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


N_LOAD = 4.0 / 3.0  # load of the filling pore ~ V^(-n): S_n ~ 1/V and 2 sigma / R ~ V^(-1/3)


def model_volume_ratio(g0) -> np.ndarray:
    """Fixed point ``x`` of ``x = 1 + (g0/n) x^(-n)`` (Newton from 1; the right side falls, so one root)."""
    c = np.asarray(g0, float) / N_LOAD
    x = np.ones_like(c)
    for _ in range(60):
        f = x - 1.0 - c * x**-N_LOAD
        x = x - f / (1.0 + N_LOAD * c * x ** (-N_LOAD - 1.0))
    return x


def gain_model(rows: list[dict]) -> dict:
    """Loop-gain models against the measured contraction factors: the 1-D capillary model (case A), linear gains.

    At t = 1 s of case A one pore, the one being filled, carries the load: its volume-averaged
    pressure ``S_n Pc + (1 - S_n) P_w ~ S_n 2 sigma / R`` with ``S_n = V_n / V`` (``V_n`` the
    injected volume) and ``R ~ V^(1/3)``, so ``P ~ V^(-n)``, ``n = 4/3``. With a linear solid,
    ``V = V0 (1 + c P)``, the fixed point ``x = V/V0`` solves ``x = 1 + (g0/n) x^(-n)`` (``g0`` the
    gain at zero strain) and the map's slope there is ``g* = n (x - 1) / x``: above 1 only when the
    pore's volume at the fixed point exceeds ``n / (n - 1) = 4`` times its reference volume.
    ``g0 = a / E``, ``a`` from the stiffest point (where ``g* = g0``).
    """
    out = {}
    for mat in ("neo-hookean", "svk"):
        sel = sorted([r for r in rows if r["regime"].startswith("A") and r["material"] == mat
                      and r["relaxation"] == "none" and r["contraction"] is not None], key=lambda r: -r["E"])
        if not sel:
            continue
        a = sel[0]["contraction"] * sel[0]["E"]
        E = np.array([r["E"] for r in sel])
        g0 = a / E
        x = model_volume_ratio(g0)
        pred = N_LOAD * (x - 1.0) / x
        meas = np.array([r["contraction"] for r in sel])
        out[mat] = {"n": N_LOAD, "a_Pa": a, "E": E.tolist(), "g0": g0.tolist(), "volume_ratio": x.tolist(),
                    "predicted": pred.tolist(), "measured": meas.tolist(),
                    "ratio_measured_over_predicted": (meas / pred).tolist()}
    # Small-strain loop gain g = a / E of each regime (neo-Hookean): the E at which it would reach 1,
    # against the stiffest E at which an element inverts.
    out["linear_gain"] = {}
    for reg in REGIMES:
        sel = [r for r in rows if r["regime"] == reg and r["material"] == "neo-hookean" and r["relaxation"] == "none"]
        ok = sorted([r for r in sel if r["contraction"] is not None], key=lambda r: -r["E"])
        bad = [r["E"] for r in sel if not r["history"]]
        if ok:
            out["linear_gain"][reg] = {"a_Pa": ok[0]["contraction"] * ok[0]["E"],
                                       "E_gain_1_Pa": ok[0]["contraction"] * ok[0]["E"],
                                       "E_element_inverts_Pa": max(bad) if bad else None,
                                       "softest_E_ran_Pa": ok[-1]["E"], "factor_at_softest": ok[-1]["contraction"]}
    return out


def _amp_case(base, n_iter: int, relaxation: str = "none"):
    rate, dt = REGIMES[AMP_REGIME]
    return base.replace(solid={"E": AMP_E, "material": "neo-hookean"}, drainage={"rate": rate, "t_end": dt},
                        coupling={"exchange_dt": dt, "subiterations": n_iter, "subiteration_tol": 1e-300,
                                  "relaxation": relaxation, "integrator": "static"})


def substeps(problem, n_iter: int, relaxation: str, kappa: float = 1.0, target=None, trace: bool = False) -> dict:
    """The first exchange step's sub-iterations, run by :class:`porefsi.CoupledRun`, pore loads amplified by kappa.

    ``problem``'s loop (static solid, geometric update of the reference network with the relaxed
    total displacement) with ``n_iter`` sub-iterations to a tolerance of 1e-300 (all of them run)
    and ``relaxation``; the solid is loaded with ``P* + kappa (P(U_k) - P*)`` (``target = (U*, P*)``
    as the loop's ``load_map``; without ``target`` the DPN's own pressures), and every iterate is
    observed through ``on_iteration``.
    """
    opts = problem.options.replace(coupling={"subiterations": n_iter, "subiteration_tol": 1e-300,
                                             "relaxation": relaxation})
    problem = dataclasses.replace(problem, options=opts)
    t1 = opts.coupling.exchange_dt
    iterates = []
    load_map = None if target is None else (lambda P: target[1] + kappa * (P - target[1]))
    status = "ran"
    try:
        CoupledRun(problem, load_map=load_map, on_iteration=iterates.append).advance()
    except ConvergenceError:  # every sub-iteration ran (the tolerance is 1e-300)
        pass
    except PorefsiError as exc:  # the diverging iterate inverts an element or a pore
        status = f"{type(exc).__name__} at sub-iteration {len(iterates) + 1}: {str(exc)[:120]}"
    out = {"relaxation": relaxation, "kappa": kappa, "status": status,
           "history": [it.residual for it in iterates], "omega": [it.omega for it in iterates],
           "U": iterates[-1].relaxed if iterates else None, "P": iterates[-1].pressures[t1] if iterates else None}
    if target is not None:  # |U_k - U*| / |U*| after each sub-iteration (relaxed iterate)
        out["error_history"] = [float(np.linalg.norm(it.relaxed - target[0]) / np.linalg.norm(target[0]))
                                for it in iterates]
    if trace:
        out["trace"] = _trace(problem, iterates, t1)
    return out


def _trace(problem, iterates: list, t1: float) -> dict:
    """The most loaded pore of the first iteration, followed through the iterations."""
    itf, ref = problem.interface, problem.network
    P0 = iterates[0].pressures[t1]
    top = int(np.argmax(P0))
    tr = {"pore": top, "load_Pa": [], "nw_saturation": [], "volume_ratio": [], "share_of_force": []}
    for it in iterates:
        P = it.pressures[t1]
        tr["load_Pa"].append(float(P[top]))
        tr["nw_saturation"].append(float(np.asarray(it.flow.nw_saturation)[top]))
        tr["volume_ratio"].append(float(it.network.network.pore_volume[top] / ref.pore_volume[top]))
        only = np.where(np.arange(P.size) == top, P, 0.0)
        tr["share_of_force"].append(float(np.linalg.norm(itf.nodal_forces(only)) / np.linalg.norm(itf.nodal_forces(P))))
    return tr


def growth(h) -> float | None:
    """Geometric mean of r_{k+1}/r_k from the second residual on (contraction < 1, growth > 1)."""
    h = np.asarray(h, float)
    ratios = [h[k + 1] / h[k] for k in range(1, len(h) - 1) if h[k] > FLOOR and h[k + 1] > FLOOR][:6]
    return float(np.exp(np.mean(np.log(ratios)))) if ratios else None


def amplified(base, smoke: bool) -> dict:
    """The amplified-loop-gain study at E = 100 kPa, case A (see the module docstring)."""
    n_iter = 10 if smoke else N_ITER
    multiples = AMP_MULTIPLES_SMOKE if smoke else AMP_MULTIPLES
    c0 = time.process_time()
    problem = problem_from_case(_amp_case(base, n_iter))
    fixed = substeps(problem, n_iter, "aitken")  # the physical step, converged to round-off
    target = (fixed["U"], fixed["P"])
    rows = []
    kappas = [1.0]  # the rest follow from the factor measured at kappa = 1
    for kappa in kappas:
        for rel in ("none",) if smoke and kappa == 1.0 else ("none", "aitken"):
            t = time.process_time()
            r = substeps(problem, n_iter, rel, kappa, target)
            r.pop("U"), r.pop("P")
            h = np.asarray(r["history"], float)
            below = np.flatnonzero(h < TOL)
            e = r["error_history"]
            r.update(factor=growth([1.0, *e]), iterations_to_tol=int(below[0]) + 1 if below.size else None,
                     final_error=e[-1] if e and r["status"] == "ran" else None, cpu_s=time.process_time() - t)
            rows.append(r)
            f = r["factor"]
            fs = "-" if f is None else f"{f:.3g}"
            print(f"amplified kappa={kappa:5g} {rel:>6}: {r['status'][:40]:<8} factor={fs}"
                  f" it={r['iterations_to_tol']} |U-U*|/|U*|={e[-1] if e else float('nan'):.2g}"
                  f" ({r['cpu_s']:.1f} s)", flush=True)
        if kappa == 1.0 and rows[0]["factor"]:
            kappas += [float(f"{m / rows[0]['factor']:.3g}") for m in multiples]
    check = {}  # kappa = 1 is the physical loop: the observed iterates must give the sweep's first-step history
    for rel in (("none",) if smoke else ("none", "aitken")):
        lib = first_step(base, AMP_REGIME, "neo-hookean", AMP_E, rel, n_iter)["history"]
        own = next(r for r in rows if r["kappa"] == 1.0 and r["relaxation"] == rel)["history"]
        above = [k for k in range(min(len(lib), len(own))) if lib[k] > 1e-8]
        check[rel] = {"n_compared": len(above),
                      "max_rel_diff": max(abs(own[k] - lib[k]) / lib[k] for k in above)}
    g_phys = next(r for r in rows if r["kappa"] == 1.0 and r["relaxation"] == "none")["factor"]
    mech = None
    if not smoke:  # the mechanism at the softest E that runs: the filling pore's load vs its volume
        mp = problem_from_case(_amp_case(base, 10).replace(solid={"E": MECH_E}))
        mech = substeps(mp, 10, "none", trace=True)
        mech = {"E": MECH_E, "history": mech["history"], **mech["trace"]}
        ld = np.asarray(mech["load_Pa"])
        dl = np.diff(ld[1:])
        mech["load_ratio"] = (np.abs(dl[1:] / dl[:-1])).tolist()  # the map's slope at the fixed point
        print(f"mechanism E={MECH_E:g}: pore {mech['pore']} load {np.round(ld, 1).tolist()} Pa, V/V0 "
              f"{np.round(mech['volume_ratio'], 3).tolist()}", flush=True)
    return {"regime": AMP_REGIME, "E": AMP_E, "material": "neo-hookean", "n_iter": n_iter, "mechanism": mech,
            "physical_factor": g_phys, "kappa_critical_predicted": 1.0 / g_phys if g_phys else None,
            "fixed_point_max_displacement_m": float(np.abs(target[0]).max()),
            "fixed_point_residual": fixed["history"][-1], "kappa_1_check": check, "rows": rows,
            "cpu_s": time.process_time() - c0}


def plot_amplified(amp: dict, path: Path) -> None:
    """Residual histories at each kappa (left) and the factor per sub-iteration vs kappa (right)."""
    plt = pyplot()
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(13, 4.8))
    rows = amp["rows"]
    kappas = sorted({r["kappa"] for r in rows})
    cmap = plt.get_cmap("plasma")
    for i, kap in enumerate(kappas):
        col = cmap(0.85 * i / max(1, len(kappas) - 1))
        for r in rows:
            if r["kappa"] != kap or not r["error_history"]:
                continue
            ls = "-" if r["relaxation"] == "none" else "--"
            end = "x" if r["status"] != "ran" else "."
            e = r["error_history"]
            ax.semilogy(np.arange(1, len(e) + 1), e, ls, color=col, marker=".", ms=3,
                        label=f"kappa = {kap:g}" if r["relaxation"] == "none" else None)
            if end == "x":
                ax.semilogy([len(e) + 1], [e[-1]], "x", color=col, ms=9, mew=2)
    ax.set_xlabel("sub-iteration")
    ax.set_ylabel("distance to the fixed point |U_k - U*| / |U*|")
    ax.set_title(f"amplified loop gain, {amp['regime'].split(':')[0]}, E = {amp['E']:.3g} Pa: - none, -- Aitken;"
                 " x: an element or pore inverted", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    g = amp["physical_factor"]
    kk = np.logspace(np.log10(min(kappas)), np.log10(max(kappas)), 50)
    ax2.loglog(kk, g * kk, color="k", lw=0.8, label=f"kappa x physical factor ({g:.3g})")
    for rel, st, lab in (("none", "-o", "none: factor per sub-iteration"), ("aitken", "--s", "Aitken")):
        sel = [r for r in rows if r["relaxation"] == rel and r["factor"] is not None]
        ax2.loglog([r["kappa"] for r in sel], [r["factor"] for r in sel], st, ms=5, label=lab)
    sel = [r for r in rows if r["relaxation"] == "aitken" and len(r["omega"]) > 1]
    ax2.loglog([r["kappa"] for r in sel], [r["omega"][1] for r in sel], "^", color="C2", ms=6,
               label="Aitken's first factor omega_2")
    ax2.loglog(kk, 1.0 / (1.0 + g * kk), color="C2", lw=0.8, label="1 / (1 + kappa g): eigenvalue -kappa g")
    ax2.axhline(1.0, color="r", lw=1)
    if amp.get("kappa_critical_predicted"):
        ax2.axvline(amp["kappa_critical_predicted"], color="r", lw=0.8, ls=":",
                    label=f"predicted threshold kappa = {amp['kappa_critical_predicted']:.3g}")
    ax2.set_xlabel("kappa (loop-gain amplification)")
    ax2.set_ylabel("error ratio per sub-iteration (geometric mean); Aitken omega")
    ax2.set_title("plain iteration diverges above the threshold, Aitken converges", fontsize=9)
    ax2.grid(True, which="both", alpha=0.3)
    ax2.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def plot_histories(rows: list[dict], path: Path) -> None:
    """Residual histories, one panel per regime (neo-Hookean), none solid / Aitken dashed."""
    plt = pyplot()
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


def plot_vs_E(rows: list[dict], pressures: dict, path: Path, model: dict | None = None) -> None:
    """Contraction factor and iterations to 1e-6 against E, with the failure region and the 1-D model."""
    plt = pyplot()
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
    nh = (model or {}).get("neo-hookean")
    if nh:
        Eg = np.logspace(2.5, 7.2, 60)
        x = model_volume_ratio(nh["a_Pa"] / Eg)
        ax.loglog(Eg, N_LOAD * (x - 1.0) / x, color="C0", lw=2, alpha=0.35,
                  label="A: 1-D model, filling pore's load ~ V^-4/3 (> 1 needs V > 4 V0)")
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
    plt = pyplot()
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


def _arguments(p) -> None:
    p.add_argument("--parts", nargs="+", choices=PARTS, default=list(PARTS),
                   help="run only these parts; the others' results are kept from OUT/results.json")


def main(argv=None) -> int:
    """Run the study (all parts, or those of ``--parts``)."""
    args = parse_args(__doc__, argv, _arguments, smoke_help="two E values, 8 sub-iterations, no whole runs, "
                      "kappa 1 and 100")
    out = output_dir(args, HERE)
    base = load_case(HERE / "case.toml")
    n_iter = 8 if args.smoke else N_ITER
    old = {}
    if set(args.parts) != set(PARTS):
        prev = out / "results.json"
        if not prev.is_file():
            raise SystemExit(f"--parts {' '.join(args.parts)} keeps the other parts from {prev}, which does not exist")
        old = json.loads(prev.read_text())
        if bool(old.get("smoke")) != args.smoke:
            raise SystemExit(f"{prev} is a {'smoke' if old.get('smoke') else 'full'} run; run all parts")
    summary = {"case": "coupling_stability", "smoke": args.smoke, "n_iter": n_iter, "tol": TOL}
    runs = dict(old.get("runs", {}))
    stamp = {"date_utc": time.strftime("%Y-%m-%d %H:%M", time.gmtime()), "code": git_head()}
    if "sweep" in args.parts:
        design = sweep_design(args.smoke)
        t0 = time.process_time()
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
        runs["sweep"] = stamp | {"cpu_s": time.process_time() - t0}
    else:
        pressures, rows = old["pressures"], old["first_step"]
    if "multistep" in args.parts:
        ms = []
        t0 = time.process_time()
        if not args.smoke:
            for E in (3e3, 1.5e3):
                for rel in ("none", "aitken"):
                    m = multistep(base, E, rel, base.drainage.t_end)
                    ms.append(m)
                    print(f"multistep E={E:g} {rel}: {m['status'][:80]} its={m['iterations']} ({m['cpu_s']:.1f} s)",
                          flush=True)
        runs["multistep"] = stamp | {"cpu_s": time.process_time() - t0}
    else:
        ms = old.get("multistep", [])
    if "amplified" in args.parts:
        amp = amplified(base, args.smoke)
        runs["amplified"] = stamp | {"cpu_s": amp["cpu_s"]}
    else:
        amp = old.get("amplified")
    for part in PARTS:
        if part not in args.parts and part not in runs:
            runs[part] = {"date_utc": None, "code": None, "note": "kept from an earlier results.json (no stamp)"}
    model = gain_model(rows)
    summary.update(pressures=pressures, first_step=rows, gain_model=model, multistep=ms, amplified=amp,
                   runs=runs)
    write_results(out / "results.json", summary)
    plot_histories(rows, out / "figures" / "stability_histories.png")
    plot_vs_E(rows, pressures, out / "figures" / "stability_vs_E.png", model)
    if ms:
        plot_multistep(ms, out / "figures" / "stability_multistep.png")
    if amp:
        plot_amplified(amp, out / "figures" / "stability_amplified.png")
    print(f"outputs in {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
