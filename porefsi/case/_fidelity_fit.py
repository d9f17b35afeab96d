"""Fit the constants of the fidelity model from its measurements (private).

``fit_calibration(data)`` turns the ``"data"`` part of ``fidelity_calibration.json`` (measured
runs, copied from the speed-accuracy study's ``results.json`` and the calibration runs of
``benchmarks/bench_fidelity.py --phase calibrate``) into the constants the model reads
(``"mesh"``, ``"interface"``, ..., ``"cost"``). The shipped file holds both; a test refits the
data and compares, so the constants cannot drift from the measurements they claim.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import least_squares

__all__ = ["fit_calibration", "fit_mesh_law", "fit_direct_solid", "fit_graded"]


def fit_mesh_law(chord: float, coarsen, err_vs_ref, c_ref: int, ref_vs_finer: float,
                 c_finer: int) -> tuple[float, float]:
    """``(A, p)`` of ``E(c) = A (c/chord)^p`` from errors against a coarsen-``c_ref`` reference.

    Each measured ``err_vs_ref[i]`` is modelled as ``hypot(E(c_i), E(c_ref))`` and the reference's
    own distance from a finer mesh as ``hypot(E(c_ref), E(c_finer))``; least squares in log.
    """
    c = np.asarray(coarsen, float)
    e = np.asarray(err_vs_ref, float)

    def resid(th):
        a, p = th
        law = lambda x: a * (np.asarray(x, float) / chord) ** p  # noqa: E731
        r = np.log(np.hypot(law(c), law(c_ref))) - np.log(e)
        return np.append(r, np.log(np.hypot(law(c_ref), law(c_finer))) - math.log(ref_vs_finer))

    sol = least_squares(resid, [0.5, 1.0])
    return float(sol.x[0]), float(sol.x[1])


def fit_direct_solid(dofs, solid_s, steps, dt_steps, dt_solid_s, dt_dofs: float) -> dict:
    """The direct solid's cost: per-step solve at ``dt_dofs`` and the factorisation's log-log quadratic.

    ``dt_steps``/``dt_solid_s``: the solid stage of one mesh at several step counts (its slope is
    the per-step cost, scaled to other meshes as dofs^(4/3)); the rest of each mesh's solid stage
    is the factorisation, fitted as ``exp(q0 + q1 ln d + q2 ln^2 d)``.
    """
    slope, _ = np.polyfit(np.asarray(dt_steps, float), np.asarray(dt_solid_s, float), 1)
    d = np.asarray(dofs, float)
    factor = np.asarray(solid_s, float) - np.asarray(steps, float) * slope * (d / dt_dofs) ** (4.0 / 3.0)
    q = np.polyfit(np.log(d), np.log(np.maximum(factor, 1e-6)), 2)[::-1]
    return {"direct_step_s": float(slope), "direct_step_dofs": float(dt_dofs),
            "direct_factor_loglog": [float(x) for x in q]}


def _stage(run: dict, name: str) -> float:
    return float(run["stage_seconds"].get(name, 0.0))


def fit_calibration(data: dict) -> dict:
    """Every constant of the model from ``data`` (the ``"data"`` part of the calibration file)."""
    sample, runs = data["sample"], data["runs"]
    base = runs["baseline"]
    steps = sample["n_steps"]
    chord, n_pores = sample["pore_chord"], sample["n_pores"]
    mesh_runs = [runs[k] for k in data["mesh_series"]]
    A, p = fit_mesh_law(chord, [r["coarsen"] for r in mesh_runs], [r["err_field"] for r in mesh_runs],
                        data["reference"]["coarsen"], data["reference"]["vs_finer"], data["reference"]["finer"])
    strain = sample["strain"]
    hull = max(runs[k]["err_field"] for k in data["hull_runs"])
    cost = {"pore_voxels_per_chord3": sample["n_pore_voxels"] / (n_pores * chord ** 3),
            "extract_per_voxel": _stage(base, "setup_extraction") / sample["n_voxels"],
            "mesh_per_tet": float(np.mean([_stage(r, "setup_mesh") / r["n_tets"] for r in mesh_runs])),
            "traction_per_tet": _stage(base, "setup_interface_build") / base["n_tets"],
            "hull_per_pore_point": _stage(runs["tp800"], "setup_interface_build") / (n_pores * 800),
            "stress_per_tet_step": float(np.mean([_stage(r, "stress") / (r["n_tets"] * steps) for r in mesh_runs])),
            "update_per_pore_step": _stage(base, "update") / (n_pores * steps),
            "tdg_factor": {"1": _stage(runs["tdg1"], "solid") / _stage(base, "solid"),
                           "2": _stage(runs["tdg2"], "solid") / _stage(base, "solid")},
            "response_auto_factor": _stage(runs["response_auto"], "solid") / _stage(base, "solid"),
            "p2_dofs_factor": runs["p2_coarsen10"]["n_dofs"] / runs["coarsen10"]["n_dofs"]}
    dr = data["drainage"]
    cost["fluid_per_event_pore"] = dr["exact_cpu_s"] / (dr["fills"] * dr["pores"])
    cost["fluid_per_step"] = max(_stage(base, "fluid") - cost["fluid_per_event_pore"] * sample["n_events"] * n_pores,
                                 0.0) / steps
    direct = [runs[k] for k in data["direct_series"]]
    dts = [runs[k] for k in data["step_series"]]
    cost.update(fit_direct_solid([r["n_dofs"] for r in direct], [_stage(r, "solid") for r in direct],
                                 [steps] * len(direct), [r["n_steps"] for r in dts], [_stage(r, "solid") for r in dts],
                                 base["n_dofs"]))
    amg = runs["coarsen3_static"]
    cost["amg_per_dof_step"] = _stage(amg, "solid") / (amg["n_dofs"] * steps)
    cost["adaptive_fluid_extra_s"] = max(_stage(runs["adaptive"], "fluid") - _stage(base, "fluid"), 0.0)
    ad = data["adaptive_drainage"]
    out = {
        "mesh": {"A": A, "p": p, "reference_coarsen": data["reference"]["coarsen"]},
        "interface": {"traction": 0.0, "hull": hull},
        "integrator": {"tdg_left": runs["left"]["diff_vs_baseline"]},
        "update": {"geometric": 0.0, "none": runs["update_none"]["diff_vs_baseline"] / strain,
                   "reextract": runs["update_reextract"]["diff_vs_baseline"] / strain},
        "response": {"nonlinear": 0.0, "auto": runs["response_auto"]["diff_vs_baseline"] / strain},
        "scheme": {"adaptive": {"log10_ca": [math.log10(x) for x in ad["ca"]],
                                "error": [max(a, b) for a, b in zip(ad["sw_max_rel"], ad["p_in_median_rel"],
                                                                    strict=True)],
                                "fluid_cost_ratio": [a / e for a, e in zip(ad["adaptive_cpu_s"], ad["exact_cpu_s"],
                                                                           strict=True)]}},
        "cost": cost,
    }
    if "graded" in data:
        out["graded"] = fit_graded(data["graded"], runs)
    return out


def fit_graded(g: dict, runs: dict) -> dict:
    """The graded mesh's error term and size constant from its calibration run.

    ``g["run"]``: a graded run whose fine block is the reference's (its error against the reference
    is then the error of its coarse leaves alone); ``kappa``: its tetrahedra beyond the uniform mesh
    of its largest leaf per injected voxel / fine block^3.
    """
    r = runs[g["run"]]
    cf = g["coarsen"]
    return {"recipe": dict(g["recipe"]), "error": float(r["err_field"]),
            "kappa": float((r["n_tets"] - g["n_tets_coarsest"]) / (g["injected_voxels"] / cf ** 3))}
