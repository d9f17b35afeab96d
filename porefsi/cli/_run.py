"""``porefsi run [CASE.toml] [-o DIR] [--resume]``: the coupled simulation, the main job.

With no case file it runs the built-in default: the seed paper's table 2 set-up on the shipped
120³ Berea crop. See :mod:`porefsi.case.run` for the files written.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from pathlib import Path

from porefsi.cli._common import emit
from porefsi.errors import ConfigError, InputError

__all__ = ["register", "run"]

_HEADLINE = ("status", "wall_seconds", "n_pores", "n_throats", "n_nodes", "n_tets", "t_end_s", "final_sw",
             "breakthrough_time_s", "max_displacement_m", "max_von_mises_Pa", "permeability_initial_m2",
             "permeability_final_m2", "mass_balance_error", "load_balance_error")


def run(args: argparse.Namespace) -> int:
    """Load the case (or the default), run it, print the headline figures."""
    from porefsi.case.config import Case, load_case, smoke_case
    from porefsi.case.fidelity import print_choice, resolve_fidelity
    from porefsi.case.run import run_case

    case = load_case(args.case) if args.case else Case()
    case = _with_fidelity(case, args)
    if args.smoke:
        case = smoke_case(case)
    case, choice = resolve_fidelity(case)
    print_choice(choice)
    if args.resume and args.overwrite:
        raise InputError("--resume continues the run in DIR and --overwrite replaces it: pass one of them")
    out = Path(args.output) if args.output else Path(case.output.dir)
    result = run_case(case, out, resume=args.resume, overwrite=args.overwrite, force=args.force,
                      figures=False if args.no_figures else None)
    if result.note:
        print(f"porefsi: {result.note}", file=sys.stderr)
    summary = {k: result.summary.get(k) for k in _HEADLINE}
    summary["output_dir"] = str(out)
    emit(summary if not args.json else result.summary | {"output_dir": str(out)}, args.json)
    return 0


def _with_fidelity(case, args: argparse.Namespace):
    """``case`` with the ``--fidelity`` preset and target of the command line (they win over the file's)."""
    from porefsi.case.config import FidelityConfig

    presets = dataclasses.fields(FidelityConfig)[0].metadata["choices"]
    if args.fidelity is not None and args.fidelity not in presets:
        raise ConfigError(f"--fidelity {args.fidelity!r} is not a preset; use one of {', '.join(presets)}")
    for opt, v in (("--fidelity-tolerance", args.fidelity_tolerance), ("--fidelity-budget", args.fidelity_budget)):
        if v is not None and not (v > 0 and math.isfinite(v)):
            raise ConfigError(f"{opt} must be a positive number, got {v!r}; e.g. {opt} "
                              f"{'0.3' if 'tol' in opt else '60'}")
    if args.fidelity_tolerance is not None and args.fidelity_budget is not None:
        raise ConfigError("give --fidelity-tolerance or --fidelity-budget, not both (auto meets one target)")
    fid = {}
    if args.fidelity is not None:
        fid["preset"] = args.fidelity
    if args.fidelity_tolerance is not None or args.fidelity_budget is not None:
        fid.update(tolerance=args.fidelity_tolerance, budget_s=args.fidelity_budget)
    if fid.get("preset", case.fidelity.preset) != "auto" and "preset" in fid:
        fid.setdefault("tolerance", None)
        fid.setdefault("budget_s", None)
    return case.replace(fidelity=fid) if fid else case


def register(subparsers) -> None:
    """Add the ``run`` subcommand."""
    p = subparsers.add_parser(
        "run", help="coupled drainage + rock deformation (the main job)",
        description="Run a coupled simulation: dynamic drainage on the pore network two-way coupled to the "
        "deformation of the rock (finite elements). Without CASE: the built-in default (paper table 2 on the "
        "shipped Berea crop).")
    p.add_argument("case", nargs="?", default=None, metavar="CASE.toml", help="case file (default: built-in case)")
    p.add_argument("-o", "--output", default=None, metavar="DIR", help="run directory (default: output.dir)")
    p.add_argument("--resume", action="store_true",
                   help="continue a killed or interrupted run from DIR/checkpoint.npz (a completed run: nothing to do)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace the results of an earlier run in DIR (refused without it), once the new run's "
                   "inputs have been read and checked")
    p.add_argument("--force", action="store_true",
                   help="run past the size limits (10000 exchange steps, 50 GiB of outputs, the disk's free space)")
    p.add_argument("--smoke", action="store_true", help="a seconds-long version of the case (CI, quick checks)")
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    p.add_argument("--json", action="store_true", help="print the whole summary as one JSON object")
    p.add_argument("--fidelity", default=None, metavar="PRESET",
                   help="none|auto|fast|accurate|paper: choose mesh, interface, integrator, network update, drainage "
                   "scheme and solid response (keys the case file sets win; docs/fidelity.md); auto needs "
                   "--fidelity-tolerance or --fidelity-budget (or the case's [fidelity] target)")
    p.add_argument("--fidelity-tolerance", type=float, default=None, metavar="ERR",
                   help="auto: target relative displacement error, e.g. 0.3")
    p.add_argument("--fidelity-budget", type=float, default=None, metavar="SECONDS",
                   help="auto: CPU-time budget of the run, s")
    p.set_defaults(func=run)
