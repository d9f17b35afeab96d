"""Command line: ``porefsi SUBCOMMAND ...``.

:func:`main` is the only place in porefsi where exceptions become exit codes. Each subcommand
lives in its own module here and exposes ``register(subparsers)``, which adds its parser and
sets ``func=run`` where ``run(args) -> int`` may raise :class:`porefsi.errors.PorefsiError`.
"""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
import warnings

from porefsi._version import __version__
from porefsi.errors import PorefsiError

__all__ = ["main", "build_parser"]

#: Subcommand modules, in the order ``porefsi --help`` lists them.
_MODULES = ("run", "extract", "drainage", "solid", "sweep")

EXIT_OK = 0
EXIT_ERROR = 2
EXIT_INTERRUPTED = 130
#: Exit status after SIGTERM (a batch scheduler's time limit): 128 + 15, as the shell reports it.
EXIT_TERMINATED = 143
#: BLAS threads while a command runs.
BLAS_THREADS = 1


class _Parser(argparse.ArgumentParser):
    """argparse with one-line usage errors (``porefsi: error: ...``, exit 2), like porefsi's own."""

    def error(self, message):
        self.exit(EXIT_ERROR, f"porefsi: error: {self.prog}: {message} (see '{self.prog} --help')\n")


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Warnings during a command: one ``porefsi: warning: ...`` line on stderr (no source line)."""
    from porefsi.image.io import PlausibilityWarning

    kind = "" if issubclass(category, PlausibilityWarning) else f"{category.__name__}: "
    print(f"porefsi: warning: {kind}{message}", file=sys.stderr if file is None else file)


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser with every subcommand registered."""
    parser = _Parser(
        prog="porefsi",
        description="Pore-scale hydromechanics: pore networks from rock images, dynamic drainage, "
        "and the rock deformation it causes (two-way coupled).",
    )
    parser.add_argument("--version", action="version", version=f"porefsi {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name in _MODULES:
        try:
            mod = importlib.import_module(f"porefsi.cli._{name}")
        except ModuleNotFoundError as exc:  # a subcommand not built yet
            if exc.name != f"porefsi.cli._{name}":
                raise
            continue
        mod.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command line with ``argv`` (default ``sys.argv[1:]``); return the exit code.

    Errors that porefsi raises on purpose print one line ``porefsi: error: ...`` to stderr and
    return 2; argparse usage errors also return 2. So do the operating system's errors on the
    user's files that reach this point (a full disk, a read-only folder) and running out of
    memory: never a traceback for a problem with the user's files or options. Ctrl-C returns
    130 and SIGTERM (a batch scheduler's time limit), which is handled like Ctrl-C, 143.

    The command runs with BLAS pinned to one thread (threadpoolctl; restored on return): the
    solvers' dot products and small dense operations are on vectors of 1e4-1e6 entries, where
    threaded BLAS was measured 10-30x slower (DESIGN.md section 5).
    """
    import scipy.linalg  # noqa: F401  (loads scipy's own BLAS, so that the limit below reaches it)
    from threadpoolctl import threadpool_limits

    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse: --help, --version, usage errors
        return int(exc.code or 0)
    if not getattr(args, "func", None):
        parser.print_help()
        return EXIT_OK
    from porefsi.io import interrupt
    from porefsi.io.rundir import describe_os_error

    interrupt.reset()
    try:
        with threadpool_limits(limits=BLAS_THREADS, user_api="blas"), interrupt.terminate_like_interrupt(), \
                warnings.catch_warnings():
            warnings.showwarning = _one_line_warning
            code = int(args.func(args) or 0)
        sys.stdout.flush()  # a reader that closed early shows up here, not at interpreter exit
        return code
    except PorefsiError as exc:
        print(f"porefsi: error: {exc}", file=sys.stderr)
        return EXIT_ERROR
    except KeyboardInterrupt as exc:  # a run that saved itself says where and how to continue
        print(f"porefsi: interrupted{f': {exc}' if str(exc) else ''}", file=sys.stderr)
        return EXIT_TERMINATED if interrupt.last_signal() == signal.SIGTERM else EXIT_INTERRUPTED
    except MemoryError:
        print("porefsi: error: out of memory; use a smaller image (crop it, [image] crop), a coarser mesh "
              "(--coarsen / [solid] coarsen) or a machine with more memory", file=sys.stderr)
        return EXIT_ERROR
    except BrokenPipeError:  # output piped into e.g. `head`, which closed early: not an error of ours
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # Python would otherwise report it again at exit
        return EXIT_OK
    except OSError as exc:  # the operating system refused a file operation (disk full, read-only, ...)
        print(f"porefsi: error: {describe_os_error(exc)}", file=sys.stderr)
        return EXIT_ERROR


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
