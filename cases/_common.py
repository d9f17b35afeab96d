"""Helpers shared by the case scripts (``cases/*/run.py``): command line, output folder, figures,
results file, machine load, code revision.

A case script puts this folder on ``sys.path`` and imports what it needs::

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # cases/: the shared helpers
    from _common import output_dir, parse_args, pyplot, write_results  # noqa: E402

Everything else a case uses is porefsi's public API (``porefsi`` and the ``__all__`` of its
subpackages; ``tests/test_cases_smoke.py`` checks).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import tempfile
from collections.abc import Callable
from pathlib import Path

from porefsi.io import write_json

__all__ = ["parse_args", "sweep_arguments", "output_dir", "pyplot", "loadavg", "git_head", "write_results", "CASES"]

#: The folder of the case folders.
CASES = Path(__file__).resolve().parent


def parse_args(doc: str, argv=None, extra: Callable[[argparse.ArgumentParser], None] | None = None,
               smoke_help: str = "seconds-long version (coarse mesh, 2 steps)") -> argparse.Namespace:
    """The case command line: ``--smoke``, ``--out DIR`` and the case's own options (``extra(parser)``).

    Parameters
    ----------
    doc : str
        The script's docstring (its first line is the description).
    argv : list of str, optional
        Arguments (default ``sys.argv[1:]``).
    extra : callable, optional
        Adds the case's own arguments to the parser.
    smoke_help : str
        What ``--smoke`` does in this case.
    """
    p = argparse.ArgumentParser(description=doc.splitlines()[0])
    p.add_argument("--smoke", action="store_true", help=smoke_help)
    p.add_argument("--out", type=Path, default=None,
                   help="where figures/ and results.json go (default: the case folder; with --smoke a temporary one)")
    if extra is not None:
        extra(p)
    args = p.parse_args(argv)
    single_threaded_numba()
    return args


def single_threaded_numba() -> None:
    """Run porefsi's parallel numba kernels on one thread, so the cases' CPU times compare.

    Through ``numba.set_num_threads``, not the ``NUMBA_NUM_THREADS`` variable: numba refuses a
    changed variable once its threads have started, which they have when a case runs inside a
    process that extracted a network before (the smoke tests).
    """
    import numba

    numba.set_num_threads(1)


def sweep_arguments(p: argparse.ArgumentParser) -> None:
    """The options of a case that runs its members as a sweep (:func:`porefsi.sweep.run_sweep`):
    ``--serial`` or ``--scheduler ADDRESS``, and ``--resume``."""
    where = p.add_mutually_exclusive_group()
    where.add_argument("--serial", action="store_true", help="run the members in this process (default with --smoke)")
    where.add_argument("--scheduler", default=None, help="address of a running Dask scheduler")
    p.add_argument("--resume", action="store_true", help="continue the sweep in OUT/runs (default: run it afresh)")


def output_dir(args: argparse.Namespace, case_dir: Path) -> Path:
    """The ``--out`` folder, defaulting to the case folder (full run) or a fresh temporary folder
    (smoke: a smoke run never touches the committed figures); made with its ``figures/``."""
    if args.out is not None:
        out = Path(args.out)
    elif args.smoke:
        out = Path(tempfile.mkdtemp(prefix=f"porefsi-{case_dir.name}-smoke-"))
    else:
        out = case_dir
    (out / "figures").mkdir(parents=True, exist_ok=True)
    return out


def pyplot():
    """``matplotlib.pyplot`` on the non-interactive Agg backend (case scripts run headless)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def loadavg() -> list | None:
    """1, 5 and 15 min load averages (the machine is shared: timings are noisy), or None."""
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:
        return None


def git_head(path: Path = CASES) -> str:
    """The checkout's commit (12 hex digits, ``+dirty`` with local changes to porefsi/), or ``unknown``."""
    try:
        head = subprocess.run(["git", "rev-parse", "--short=12", "HEAD"], cwd=path, capture_output=True,
                              text=True, timeout=10, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "porefsi"], cwd=CASES.parent,
                               capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return head + ("+dirty" if dirty else "")


def write_results(path: Path, results: dict) -> Path:
    """``results.json``: numpy values as Python ones, NaN/inf as null (porefsi's one JSON converter)."""
    return write_json(path, results)
