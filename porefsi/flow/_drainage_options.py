"""The options of a drainage run as two small frozen objects (private; public via :mod:`porefsi.flow.drainage`).

:class:`DrainageOptions` is *what* is simulated (boundary condition, end time, scheme, solver):
one declaration of each option's default, unit and bounds (:func:`porefsi._schema.option`),
used by :func:`~porefsi.flow.drainage.simulate_drainage`, by
:class:`~porefsi.flow.drainage.DrainageSimulator` and, as the ``[drainage]`` section of a case
file, by the coupled run. :class:`RunControl` is *how* a run is driven (checkpoints, resume,
progress callbacks); it never changes the result.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from pathlib import Path

from porefsi._schema import Limits, option, validate
from porefsi.errors import ConfigError, InputError

__all__ = ["DrainageOptions", "RunControl", "SCHEMES", "SOLVERS", "DEFAULT_LOCAL_SOLVES", "DEFAULT_HOPS",
           "DEFAULT_LOCAL_MENISCI", "DEFAULT_TIE_TOLERANCE", "DEFAULT_PREDICT_FILLS", "DEFAULT_FLUX_TOLERANCE",
           "DEFAULT_BACKOFF", "DEFAULT_BLOCK_PIVOTS", "PREDICTOR_KNOBS", "TIE_MAX_CA", "options_from"]

#: Drainage schemes: ``'exact'`` (a pressure solve after every event, the reference) and
#: ``'adaptive'`` (certified quasi-static batches without solves, dynamic events elsewhere).
SCHEMES = ("exact", "adaptive")
#: Pressure solvers (see :class:`~porefsi.flow.drainage.DrainageSimulator`).
SOLVERS = ("auto", "lowrank", "direct", "amg", "jacobi", "split", "hybrid", "selinv")
#: Defaults of the adaptive scheme's knobs (see docs/drainage.md, "Adaptive scheme", for the measurements).
DEFAULT_LOCAL_SOLVES = 0
DEFAULT_HOPS = 3
DEFAULT_LOCAL_MENISCI = 8
DEFAULT_TIE_TOLERANCE = 1.0
#: Flux-split predictor-corrector where menisci are active (:mod:`porefsi.flow._drainage_predictor`):
#: most fills per predicted batch and the corrector's flux-split tolerance (L1 / rate). Off by
#: default: measured (docs/drainage.md, "Several active menisci"), almost every batch is rejected
#: because a meniscus opens right after the fill that starts it, so it costs more than it saves.
DEFAULT_PREDICT_FILLS = 0
DEFAULT_FLUX_TOLERANCE = 0.05
#: Most steps without a quasi-static batch attempt after attempts that certified nothing (0: none skipped).
DEFAULT_BACKOFF = 32
#: Block pivots in the active-set resolution of an event (:mod:`porefsi.flow._drainage_pivots`).
DEFAULT_BLOCK_PIVOTS = "on"
#: Knobs added after the options object (2026-12-02): a checkpoint without them ran with them off.
PREDICTOR_KNOBS = {"predict_fills": 0, "flux_tolerance": DEFAULT_FLUX_TOLERANCE, "backoff": DEFAULT_BACKOFF,
                   "block_pivots": "off"}
#: Capillary number (on the inlet face) above which ``tie_tolerance`` is not applied: the rigorous
#: certificate only. Measured (docs/stability.md, section f): at Ca = 1e-5 a tolerance of 1 put the
#: breakthrough time of a 1200-pore lattice 4.7 % off; at 1e-6 and below every run stayed within 0.3 %.
TIE_MAX_CA = 1e-6
#: Above this many pores the adaptive scheme's ``solver="auto"`` is ``"lowrank_or_split"``: the
#: first factorisation decides, ``"split"`` (AMG-CG on the wetting block) when its fill exceeds
#: 300 entries per unknown, else ``"lowrank"``. After a batch hundreds of rows have changed, which
#: costs the low-rank solver a refactorisation: worth it where the factor is sparse (2x2x2-tiled
#: Berea network, 211 per unknown: ~4.7x the split's progress), not where it is dense (30k
#: lattice, 436: split 35 CPU s against low-rank 154 s). Below, ``"lowrank"`` (10k: 1.9 s against 3.3 s).
ADAPTIVE_SPLIT_ABOVE = 20000
_ADAPTIVE_KNOBS = {"local_solves": DEFAULT_LOCAL_SOLVES, "hops": DEFAULT_HOPS, "local_menisci": DEFAULT_LOCAL_MENISCI,
                   "tie_tolerance": DEFAULT_TIE_TOLERANCE, "predict_fills": DEFAULT_PREDICT_FILLS,
                   "flux_tolerance": DEFAULT_FLUX_TOLERANCE, "backoff": DEFAULT_BACKOFF,
                   "block_pivots": DEFAULT_BLOCK_PIVOTS}

_POSITIVE = Limits(0.0, None, lo_open=True)


@dataclasses.dataclass(frozen=True)
class DrainageOptions:
    """Injection of the non-wetting fluid and how the drainage is computed.

    Every field is validated when the object is made (:class:`~porefsi.errors.ConfigError`
    naming the field). ``skip_solves`` also takes ``True``/``False`` (stored as ``'on'``/``'off'``).
    """

    rate: float = option(1.25e-13, "volumetric injection rate (paper case A)", limits=_POSITIVE, unit="m^3/s")
    t_end: float = option(20.0, "injection time (paper: 20 s)", limits=_POSITIVE, unit="s")
    scheme: str = option("exact", "exact = a pressure solve after every event (the reference); adaptive = "
                         "quasi-static fills in certified batches, local pressure updates elsewhere (docs/drainage.md)",
                         choices=SCHEMES)
    inlet_pressure: float | None = option(None, "constant inlet pressure (gauge, outlet at 0) instead of the "
                                          "constant rate", unit="Pa", optional=True)
    solver: str = option("auto", "pressure solver: auto = direct up to 400 unknowns, else lowrank (adaptive scheme "
                         "above 20000 pores: lowrank, or split when the first LU has over 300 entries per unknown); "
                         "direct = a fresh "
                         "sparse LU per solve; lowrank = one LU reused through low-rank updates (a direct solve to "
                         "round-off); amg = CG with a reused AMG hierarchy; jacobi = diagonal CG (tests); split, "
                         "hybrid = non-wetting block direct, wetting block CG", choices=SOLVERS)
    skip_solves: str = option("auto", "skip the solve after a quasi-static jump when a resistance bound proves no "
                              "other meniscus moves (same outcome; constant rate only); auto = on above 5000 pores",
                              choices=("auto", "on", "off"))
    max_active_set_iter: int = option(0, "cap of active-set iterations per event (0 = 4 x edges + 10)",
                                      limits=Limits(0))
    block_pivots: str = option(DEFAULT_BLOCK_PIVOTS, "adaptive only: close every pushed-back meniscus of an event "
                               "at once, each checked by the next solve and reopened if it fails (on, the default: "
                               "the exact scheme's events, 6-23 % fewer solves measured), instead of one per solve "
                               "as the exact scheme (off); docs/drainage.md", choices=("on", "off"))
    local_solves: int = option(DEFAULT_LOCAL_SOLVES, "adaptive only: local pressure solves allowed between two "
                               "global ones (0, the default: every solve global; measured slower and less "
                               "accurate, docs/drainage.md)", limits=Limits(0))
    hops: int = option(DEFAULT_HOPS, "adaptive only: radius, in throats, of the wetting patch of a local solve",
                       limits=Limits(1))
    local_menisci: int = option(DEFAULT_LOCAL_MENISCI, "adaptive only: most active menisci for a local solve",
                                limits=Limits(0))
    tie_tolerance: float = option(DEFAULT_TIE_TOLERANCE, "adaptive only: relative band by which a quasi-static "
                                  "fill's inlet-pressure bound may exceed the next entry threshold and still be filled "
                                  "without a solve, in invasion-percolation order (0 = the rigorous certificate: the "
                                  "exact scheme's events; > 0 = near-ties resolved quasi-statically, an approximation "
                                  "measured in docs/drainage.md; 1 = the default: Sw and breakthrough within 0.3 % of "
                                  "the exact scheme on the lattices and rates measured); applied at capillary numbers "
                                  "up to 1e-6 only (above: the rigorous certificate)", limits=Limits(0.0))
    predict_fills: int = option(DEFAULT_PREDICT_FILLS, "adaptive only: where menisci are active, most fills made "
                                "with the last solve's flux split (the filled pore's inflow handed to the other "
                                "menisci in proportion) before one solve checks them and rolls back if the check "
                                "fails (0 or 1 = off, the default: the exact scheme's events; an approximation, "
                                "measured in docs/drainage.md to save nothing: almost every batch is rejected)",
                                limits=Limits(0))
    flux_tolerance: float = option(DEFAULT_FLUX_TOLERANCE, "adaptive only: the predictor's check, largest "
                                   "sum over pores of |predicted - solved inflow| relative to the rate",
                                   limits=Limits(0.0, 2.0))
    backoff: int = option(DEFAULT_BACKOFF, "adaptive only: most steps without a quasi-static batch attempt after "
                          "attempts that certified nothing (doubling from 1; 0 = attempt at every step)",
                          limits=Limits(0))

    def __post_init__(self):
        if isinstance(self.skip_solves, bool):
            object.__setattr__(self, "skip_solves", "on" if self.skip_solves else "off")
        validate(self, "drainage")
        if self.scheme != "adaptive":
            changed = [k for k, v in _ADAPTIVE_KNOBS.items() if getattr(self, k) != v]
            if changed:
                raise ConfigError(f"option: drainage.{', '.join(changed)} apply to scheme = 'adaptive' only "
                                  f"(scheme is {self.scheme!r}); drop them or set scheme='adaptive'")

    def engine_options(self, n_pores: int, ca: float) -> dict:
        """Keyword arguments of the event engine for ``n_pores`` kept pores at capillary number ``ca``.

        Above :data:`TIE_MAX_CA` the tie tolerance is 0 (the rigorous certificate); the adaptive
        scheme's ``'auto'`` solver is ``'lowrank_or_split'`` above :data:`ADAPTIVE_SPLIT_ABOVE` pores.
        """
        skip = n_pores > 5000 if self.skip_solves == "auto" else self.skip_solves == "on"
        out = dict(solver=self.solver, skip_solves=skip, max_active_set_iter=self.max_active_set_iter or None,
                   scheme=self.scheme)
        if self.scheme == "adaptive":
            out.update({k: getattr(self, k) for k in _ADAPTIVE_KNOBS})
            if self.solver == "auto" and n_pores > ADAPTIVE_SPLIT_ABOVE:
                out["solver"] = "lowrank_or_split"
            if not ca <= TIE_MAX_CA * (1 + 1e-9):  # (a rate made from Ca = 1e-6 may round above it)
                out["tie_tolerance"] = 0.0
        return out


@dataclasses.dataclass(frozen=True)
class RunControl:
    """How a :func:`~porefsi.flow.drainage.simulate_drainage` run is driven (never changes its result).

    Attributes
    ----------
    checkpoint : str or Path, optional
        File the run is saved to, between two events, every ``checkpoint_every`` seconds of wall
        time and at the end (atomically: a killed run leaves the previous checkpoint intact). The
        first Ctrl-C (SIGINT, main thread) is then deferred to the end of the current event: the
        run is saved there and :class:`KeyboardInterrupt` raised (a second Ctrl-C interrupts at once).
    checkpoint_every : float
        Wall seconds between checkpoints (default 60).
    resume : bool
        Continue from ``checkpoint`` (written by a run with the same arguments) instead of
        starting at t = 0; the resumed run repeats the uninterrupted run's arithmetic ('direct'
        and 'lowrank' solvers: the same result to the last bit; 'amg' rebuilds its hierarchy, so
        it agrees to the solver tolerance). ``seconds`` counts all processes.
    progress : callable, optional
        Called as ``progress(sim, seconds)`` after each checkpoint.
    report : callable, optional
        Called as ``report(sim, seconds)`` once the run starts (after a resumed run's checkpoint
        is read) and then every ``report_every`` seconds of wall time, between two events.
    report_every : float
        Wall seconds between two ``report`` calls (default 5).

    Raises
    ------
    InputError
        Non-positive intervals, or ``resume`` without a checkpoint.
    """

    checkpoint: str | Path | None = None
    checkpoint_every: float = 60.0
    resume: bool = False
    progress: Callable | None = None
    report: Callable | None = None
    report_every: float = 5.0

    def __post_init__(self):
        for name in ("checkpoint_every", "report_every"):
            object.__setattr__(self, name, positive(name, getattr(self, name), "s"))
        if self.resume and self.checkpoint is None:
            raise InputError("resume=True needs the checkpoint file to resume from (checkpoint=...)")


def positive(name: str, v, unit: str) -> float:
    """``v`` as a finite float > 0, else an :class:`InputError` naming ``name`` and ``unit``."""
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number ({unit}), got {v!r}") from None
    if not math.isfinite(x) or x <= 0:
        raise InputError(f"{name} must be a finite number > 0 {unit}, got {v!r}")
    return x


_OPTION_NAMES = frozenset(f.name for f in dataclasses.fields(DrainageOptions))
_RUN_NAMES = frozenset(f.name for f in dataclasses.fields(RunControl))


def options_from(options: DrainageOptions | None, keywords: dict, run_ok: bool = False):
    """``(options, run_keywords)``: ``options`` with the keyword overrides of the older keyword API.

    Keywords naming :class:`DrainageOptions` fields replace those fields; with ``run_ok`` the
    ones naming :class:`RunControl` fields are returned apart. Invalid values raise
    :class:`InputError` (the keyword API's error) with the option's one-line message.
    """
    if options is None:
        options = DrainageOptions()
    elif not isinstance(options, DrainageOptions):
        raise InputError(f"options must be a porefsi DrainageOptions, got {type(options).__name__}")
    allowed = _OPTION_NAMES | (_RUN_NAMES if run_ok else frozenset())
    bad = sorted(set(keywords) - allowed)
    if bad:
        raise InputError(f"unknown drainage option(s) {', '.join(bad)}; known: {', '.join(sorted(allowed))}")
    run = {k: v for k, v in keywords.items() if k in _RUN_NAMES and k not in _OPTION_NAMES}
    over = {k: v for k, v in keywords.items() if k in _OPTION_NAMES}
    for k in ("max_active_set_iter", *_ADAPTIVE_KNOBS):  # the keyword API's "None = default"
        if k in over and over[k] is None:
            over[k] = 0 if k == "max_active_set_iter" else _ADAPTIVE_KNOBS[k]
    if over:
        try:
            options = dataclasses.replace(options, **over)
        except ConfigError as exc:
            raise InputError(str(exc).removeprefix("option: ")) from None
    return options, run
