"""``porefsi sweep SWEEP.toml -o DIR``: many coupled runs from one base case, on dask.distributed.

See :mod:`porefsi.sweep` and ``docs/sweeps.md``.
"""

from __future__ import annotations

import argparse
import sys

from porefsi.cli._common import emit, positive_int

__all__ = ["register", "run"]

#: Exit status when the sweep ran but some members failed (their errors are in sweep.csv).
EXIT_MEMBERS_FAILED = 1


def run(args: argparse.Namespace) -> int:
    """Load and check the sweep, run it, print the counts; exit 1 if a member failed."""
    from porefsi.sweep import Cluster, load_sweep, run_sweep

    sweep = load_sweep(args.sweep)
    cluster = Cluster(serial=args.serial, scheduler=args.scheduler, scheduler_file=args.scheduler_file,
                      n_workers=args.workers, retries=args.retries)
    res = run_sweep(sweep, args.output, cluster, overwrite=args.overwrite, force=args.force,
                    figures=False if args.no_figures else None, progress=False if args.quiet else None)
    failed = [r for r in res.records if r is None or r["status"] != "completed"]
    summary = {"members": len(res.records), "completed": res.n_completed, "failed": res.n_failed,
               "skipped_already_completed": res.n_skipped, "table": str(res.table),
               "figure": str(res.figure) if res.figure else None}
    emit(summary, args.json)
    for r in failed:
        if r is not None:
            print(f"porefsi: member {r['name']} failed: {r['error']}", file=sys.stderr)
    return EXIT_MEMBERS_FAILED if failed else 0


def register(subparsers) -> None:
    """Add the ``sweep`` subcommand."""
    p = subparsers.add_parser(
        "sweep", help="many coupled runs (a base case and the keys to vary), on Dask",
        description="Run every member of a sweep file (a [base] case and a [vary] table of case keys to value "
        "lists) into DIR/<member>/, each with its own checkpoint, on a local Dask cluster sized to the machine "
        "(default), an existing Dask cluster (--scheduler / --scheduler-file) or in this process (--serial). "
        "Writes DIR/sweep.csv and DIR/figures/sweep.png. Running the same command again skips completed "
        "members and resumes interrupted ones. Exit 1 if a member failed.")
    p.add_argument("sweep", metavar="SWEEP.toml", help="sweep file")
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="sweep folder (one sub-folder per member)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="address of a running Dask scheduler (e.g. tcp://10.0.0.5:8786)")
    where.add_argument("--scheduler-file", default=None, metavar="PATH",
                       help="scheduler file of a running Dask cluster (dask scheduler --scheduler-file PATH)")
    where.add_argument("--serial", action="store_true", help="run the members one by one in this process, no Dask")
    p.add_argument("--workers", type=positive_int, default=None, metavar="N",
                   help="worker processes of the local cluster (default: the CPUs available)")
    p.add_argument("--retries", type=int, default=2, metavar="N",
                   help="resubmit a member whose worker died up to N times (it resumes from its checkpoint; "
                   "default 2)")
    p.add_argument("--overwrite", action="store_true",
                   help="run every member afresh (also over another sweep in DIR)")
    p.add_argument("--force", action="store_true", help="run members past the size limits (see porefsi run)")
    p.add_argument("--no-figures", action="store_true", help="no figures (the members' nor the sweep's)")
    p.add_argument("--quiet", action="store_true", help="no progress display on stderr")
    p.add_argument("--json", action="store_true", help="print the counts as one JSON object")
    p.set_defaults(func=run)
