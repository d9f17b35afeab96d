"""Fidelity presets: model no more than the scene needs (``[fidelity]``, ``porefsi run --fidelity``).

:func:`resolve_fidelity` turns a case with ``fidelity.preset`` into a case with every fidelity
setting chosen (:data:`porefsi.case.config.FIDELITY_KEYS`: mesh coarsening, interface, solid
integrator, network update, drainage scheme, solid response), the keys the case file set itself
left alone (``fidelity.keep``), and returns the choice with its expected error and cost.

- ``fast``, ``accurate``, ``paper``: fixed settings (:data:`PRESETS`; the speed-accuracy study's
  recommendations, docs/speed_accuracy.md), with their expected error on this image;
- ``auto``: every combination of the knobs is scored by a calibrated error model and a cost model
  (:mod:`porefsi.case._fidelity_model`, constants in ``fidelity_calibration.json``, fitted on the
  built-in sample's speed-accuracy study) evaluated on what the image tells before any run (size,
  pore and solid voxels, the mean pore chord, voxel size, the mesh size of each coarsening, the
  capillary number, the horizon); with ``tolerance`` the cheapest setting expected to meet it,
  with ``budget_s`` the most accurate one expected to fit.

The choice is deterministic (no timing, no free-memory reading: candidates are limited by the
machine's physical memory) and monotone: a tighter tolerance never picks a cheaper setting (costs
are compared in 10 % bins, the timing noise of the study, and within a bin the smaller error
wins), a larger budget never a larger expected error. Resolving a resolved case changes nothing.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import sys
import warnings

from porefsi.case._fidelity_model import Scene, Setting, calibration, expected_cpu, expected_error, scene_of
from porefsi.case.config import FIDELITY_KEYS, Case, case_from_dict, case_to_dict, case_to_toml

__all__ = ["PRESETS", "FidelityChoice", "resolve_fidelity", "fidelity_summary", "candidates", "choose",
           "COST_BIN", "graded_recipe"]

#: Fixed presets: the settings each chooses (a case file's own keys win).
PRESETS: dict[str, dict[str, object]] = {
    "fast": {"solid.coarsen": 6, "interface.method": "traction", "coupling.integrator": "static",
             "network.update": "geometric", "drainage.scheme": "exact", "solid.response": "nonlinear",
             "solid.mesh": "uniform"},
    "accurate": {"solid.coarsen": 3, "interface.method": "traction", "coupling.integrator": "static",
                 "network.update": "geometric", "drainage.scheme": "exact", "solid.response": "nonlinear",
             "solid.mesh": "uniform"},
    "paper": {"solid.coarsen": 5, "interface.method": "hull", "interface.n_test_points": 800,
              "coupling.integrator": "tdg", "coupling.tdg_iterations": 2, "coupling.tdg_load_rule": "left",
              "network.update": "reextract", "drainage.scheme": "exact", "solid.response": "nonlinear",
             "solid.mesh": "uniform"},
}

#: Width of the cost bins of the tolerance rule (relative): costs within one bin are ties.
COST_BIN = 1.10

#: What ``auto`` tries for each knob, the default first (ties go to the earlier value).
KNOB_VALUES: dict[str, tuple] = {
    "solid.coarsen": tuple(range(2, 17)),
    "interface.method": ("traction", "hull"),
    "coupling.integrator": ("static", "tdg"),
    "network.update": ("geometric", "none", "reextract"),
    "drainage.scheme": ("exact", "adaptive"),
    "solid.response": ("nonlinear", "auto"),
    "solid.mesh": ("uniform", "graded"),
}
#: The graded mesh's own keys: set with ``solid.mesh = "graded"`` from the calibrated recipe.
GRADED_KEYS = ("solid.coarsen_max", "solid.grading", "solid.refine", "solid.ligaments")


@dataclasses.dataclass(frozen=True)
class FidelityChoice:
    """What a preset chose, and why.

    Attributes
    ----------
    preset : str
        ``auto``, ``fast``, ``accurate`` or ``paper``.
    settings : dict
        Every fidelity key (``section.key``) -> the value the run uses (kept keys included).
    kept : tuple of str
        The keys the case set itself (not chosen by the preset).
    expected_error : float
        Expected relative L2 error of the displacement against a converged mesh with the
        consistent traction interface (the speed-accuracy study's measure).
    expected_error_vs_reference : float
        The same against the study's reference (coarsen 3), the number its runs report.
    expected_cpu_s : float
        Expected CPU seconds of the run (one thread).
    tolerance, budget_s : float or None
        The target of ``auto``.
    met : bool
        Whether the target is expected to be met (always True for fixed presets).
    """

    preset: str
    settings: dict
    kept: tuple
    expected_error: float
    expected_error_vs_reference: float
    expected_cpu_s: float
    tolerance: float | None = None
    budget_s: float | None = None
    met: bool = True

    def describe(self) -> str:
        """One line for the terminal: the choice, its expected error and cost."""
        target = (f" (tolerance {self.tolerance:g})" if self.tolerance is not None else
                  f" (budget {self.budget_s:g} CPU-s)" if self.budget_s is not None else "")
        chosen = ", ".join(f"{k} = {v}" for k, v in self.settings.items()
                           if k not in self.kept and _shown(k, self.settings))
        kept = f"; kept from the case: {', '.join(self.kept)}" if self.kept else ""
        miss = "" if self.met else "; the target cannot be met, this is the closest setting"
        return (f"fidelity {self.preset}{target}: {chosen}{kept}; expected displacement error "
                f"{self.expected_error:.2g}, expected CPU {self.expected_cpu_s:.2g} s{miss}")

    def summary(self) -> dict:
        """The ``summary.json`` fields (``fidelity``, ``fidelity_expected_error``, ...)."""
        return {"fidelity": self.preset, "fidelity_expected_error": self.expected_error,
                "fidelity_expected_error_vs_reference": self.expected_error_vs_reference,
                "fidelity_expected_cpu_s": self.expected_cpu_s, "fidelity_settings": dict(self.settings),
                "fidelity_target": {"tolerance": self.tolerance, "budget_s": self.budget_s, "met": self.met}}


def _shown(key: str, settings: dict) -> bool:
    """Whether ``key`` matters with ``settings`` (test points only with the hull, TDG keys only with TDG)."""
    if key in GRADED_KEYS:
        return settings["solid.mesh"] == "graded"
    if key == "interface.n_test_points":
        return settings["interface.method"] == "hull"
    if key.startswith("coupling.tdg_"):
        return settings["coupling.integrator"] == "tdg"
    return True


def _get(case: Case, key: str):
    sec, k = key.split(".")
    return getattr(getattr(case, sec), k)


def _with(case: Case, settings: dict) -> Case:
    """``case`` with ``settings`` (``section.key`` -> value) set, ``fidelity.keep`` unchanged."""
    d = case_to_dict(case)
    for key, v in settings.items():
        sec, k = key.split(".")
        d[sec][k] = v
    return case_from_dict(d, name=case.name)


def _setting(case: Case, values: dict) -> Setting:
    """The model's view of a case's fidelity settings with ``values`` overriding."""
    get = lambda k: values.get(k, _get(case, k))  # noqa: E731
    return Setting(coarsen=int(get("solid.coarsen")), interface=get("interface.method"),
                   n_test_points=int(get("interface.n_test_points")), integrator=get("coupling.integrator"),
                   tdg_iterations=int(get("coupling.tdg_iterations")), load_rule=get("coupling.tdg_load_rule"),
                   update=get("network.update"), scheme=get("drainage.scheme"), response=get("solid.response"),
                   order=int(case.solid.order), mesh=get("solid.mesh"), coarsen_max=int(get("solid.coarsen_max")),
                   grading=float(get("solid.grading")), refine=get("solid.refine"),
                   ligaments=float(get("solid.ligaments")))


def candidates(case: Case, cal: dict | None = None) -> list[dict]:
    """Every combination of :data:`KNOB_VALUES` with the case's kept keys fixed (in preference order).

    A graded mesh comes with the calibrated recipe's own keys (:func:`graded_recipe`, kept keys
    win) and only at the recipe's fine block sizes.
    """
    keep = set(case.fidelity.keep)
    axes = [((_get(case, k),) if k in keep else vals) for k, vals in KNOB_VALUES.items()]
    out = []
    for combo in itertools.product(*axes):
        cand = dict(zip(KNOB_VALUES, combo, strict=True))
        if cand["solid.mesh"] == "graded" and "solid.mesh" not in keep:
            recipe = graded_recipe(int(cand["solid.coarsen"]), cal)
            if recipe is None:
                continue
            cand.update({k: v for k, v in recipe.items() if k not in keep})
        out.append(cand)
    return out


def graded_recipe(coarsen: int, cal: dict | None = None) -> dict | None:
    """The graded mesh ``auto`` offers at fine block ``coarsen`` (None: not at this block size).

    Refined at the predicted invasion, leaves up to ``coarsen_max_factor`` fine blocks, the
    calibrated grading and ligament rule (``fidelity_calibration.json``, ``graded.recipe``).
    """
    r = (calibration() if cal is None else cal).get("graded", {}).get("recipe")
    if r is None or coarsen not in r["fine_blocks"]:
        return None
    return {"solid.coarsen_max": int(r["coarsen_max_factor"] * coarsen), "solid.grading": float(r["grading"]),
            "solid.refine": "invaded", "solid.ligaments": float(r["ligaments"])}


def _graded_allowed(scene: Scene, s: Setting, cal: dict) -> bool:
    """A graded candidate's refined region is a prediction: only up to the capillary number where it held."""
    return s.mesh != "graded" or ("graded" in cal
                                  and scene.capillary_number <= cal["graded"]["recipe"]["max_capillary_number"])


def choose(scene: Scene, case: Case, tolerance: float | None = None, budget_s: float | None = None,
           cal: dict | None = None) -> tuple[dict, float, float, bool]:
    """The ``auto`` choice on ``scene``: (settings, expected error, expected CPU s, target met).

    Tolerance: the lowest cost bin (:data:`COST_BIN`) holding a candidate expected to meet it,
    within it the smallest error (then the earliest candidate). Budget: the smallest expected
    error among candidates expected to fit, then the lowest cost. A target nobody meets gives the
    most accurate (tolerance) or the cheapest (budget) candidate, with ``met = False``.
    Candidates the mesher would refuse or the machine could not hold are never chosen.
    """
    cal = calibration() if cal is None else cal
    scored = []
    for i, cand in enumerate(candidates(case, cal)):
        s = _setting(case, cand)
        if not (scene.feasible(s.coarsen) or "solid.coarsen" in case.fidelity.keep):
            continue
        if "solid.mesh" not in case.fidelity.keep and not _graded_allowed(scene, s, cal):
            continue
        scored.append((expected_error(scene, s, cal), expected_cpu(scene, s, cal), i, cand))
    if not scored:
        raise ValueError("no feasible coarsening for this image")  # the mesher refuses every one: caught below
    if tolerance is not None:
        ok = [x for x in scored if x[0] <= tolerance]
        best = min(ok, key=_tolerance_rank) if ok else min(scored, key=lambda x: (x[0], x[1], x[2]))
    else:
        ok = [x for x in scored if x[1] <= budget_s]
        best = min(ok, key=lambda x: (x[0], x[1], x[2])) if ok else min(scored, key=lambda x: (x[1], x[0], x[2]))
    return best[3], best[0], best[1], bool(ok)


def _tolerance_rank(x: tuple) -> tuple:
    """Rank of a scored candidate (error, cpu, index, settings) under a tolerance: cost bin, error, index."""
    return math.floor(math.log(max(x[1], 1e-9)) / math.log(COST_BIN)), x[0], x[2]


_MEMO: dict[str, tuple[Case, FidelityChoice | None]] = {}


def resolve_fidelity(case: Case, image=None) -> tuple[Case, FidelityChoice | None]:
    """``case`` with its fidelity preset applied, and the choice (None without a preset).

    Parameters
    ----------
    case : Case
    image : VoxelImage, optional
        The case's (cropped) image, if already read (default: read it).

    Raises
    ------
    InputError, ConfigError
        The image cannot be read; no coarsening of it can be meshed.
    """
    fc = case.fidelity
    if fc.preset == "none":
        return case, None
    key = case_to_toml(case)
    if key in _MEMO:
        return _MEMO[key]
    if image is None:
        from porefsi.case.problem import load_case_image

        image = load_case_image(case)
    keep = set(fc.keep)
    scene = scene_of(image, case, extra_coarsen=[p["solid.coarsen"] for p in PRESETS.values()])
    if fc.preset == "auto":
        try:
            chosen, _, _, met = choose(scene, case, fc.tolerance, fc.budget_s)
        except ValueError:
            from porefsi.errors import ConfigError

            raise ConfigError(f"fidelity auto: no mesh coarsening of the {'x'.join(map(str, image.shape))}-voxel "
                              "image can be meshed; use a larger image or crop") from None
    else:
        chosen, met = dict(PRESETS[fc.preset]), True
    chosen = {k: v for k, v in chosen.items() if k not in keep}
    out = _with(case, chosen)
    s = _setting(out, {})
    cal = calibration()
    choice = FidelityChoice(fc.preset, {k: _get(out, k) for k in FIDELITY_KEYS}, tuple(sorted(keep)),
                            expected_error(scene, s, cal), expected_error(scene, s, cal, vs_reference=True),
                            expected_cpu(scene, s, cal), fc.tolerance, fc.budget_s, met)
    if not met:
        warnings.warn(f"porefsi: {choice.describe()}", stacklevel=2)
    _MEMO.clear()  # one case at a time: a resolved case resolves to itself
    _MEMO[key] = _MEMO[case_to_toml(out)] = (out, choice)
    return out, choice


def fidelity_summary(case: Case) -> dict:
    """The ``summary.json`` fields of ``case``'s fidelity (``fidelity = "none"`` without a preset)."""
    if case.fidelity.preset == "none":
        return {"fidelity": "none", "fidelity_expected_error": None}
    return resolve_fidelity(case)[1].summary()


def print_choice(choice: FidelityChoice | None, stream=None) -> None:
    """Print the choice (one line) to ``stream`` (default stderr)."""
    if choice is not None:
        print(f"porefsi: {choice.describe()}", file=stream if stream is not None else sys.stderr)
