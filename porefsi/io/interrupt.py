"""Ctrl-C (SIGINT) and a batch scheduler's SIGTERM: stop at a safe point, save, say how to resume.

:func:`deferred` defers the first SIGINT or SIGTERM to the caller's next safe point (it polls the
yielded test between steps, saves a checkpoint and raises :class:`KeyboardInterrupt` itself); a
second signal of the same kind interrupts at once. :func:`terminate_like_interrupt` makes SIGTERM
raise :class:`KeyboardInterrupt` outside such blocks too, so that porefsi's clean-up runs (the
default SIGTERM action kills the process without it). :func:`last_signal` tells the command
line which signal stopped the run (exit status 130 for SIGINT, 143 for SIGTERM).
"""

from __future__ import annotations

import contextlib
import signal
import threading

__all__ = ["deferred", "terminate_like_interrupt", "last_signal", "reset", "SIGNAL_NAMES"]

#: Names used in messages.
SIGNAL_NAMES = {signal.SIGINT: "Ctrl-C (SIGINT)", signal.SIGTERM: "SIGTERM"}

_last: list[int | None] = [None]


def last_signal() -> int | None:
    """The last SIGINT/SIGTERM number seen by porefsi's handlers in this process (None if none)."""
    return _last[0]


def reset() -> None:
    """Forget :func:`last_signal` (at the start of a command)."""
    _last[0] = None


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


def _handler(signum):
    """The current handler of ``signum`` (SIG_DFL for one installed outside Python)."""
    h = signal.getsignal(signum)
    return signal.SIG_DFL if h is None else h


@contextlib.contextmanager
def terminate_like_interrupt():
    """Within the block, SIGTERM raises :class:`KeyboardInterrupt` (as Ctrl-C does); main thread only."""
    if not _main_thread():
        yield
        return

    def handler(signum, frame):
        _last[0] = signum
        raise KeyboardInterrupt(f"stopped by {SIGNAL_NAMES.get(signum, signum)}")

    previous = _handler(signal.SIGTERM)
    signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


@contextlib.contextmanager
def deferred(enabled: bool = True):
    """Defer the first SIGINT or SIGTERM; yield a test returning the signal number received (0 if none).

    The first signal restores that signal's previous handler, so a second one acts at once.
    Outside the main thread, or with ``enabled`` False, nothing is installed and the test is
    always 0.
    """
    hit = [0]
    if not enabled or not _main_thread():
        yield lambda: 0
        return
    previous = {s: _handler(s) for s in (signal.SIGINT, signal.SIGTERM)}

    def handler(signum, frame):
        _last[0] = signum
        if not hit[0]:
            hit[0] = signum
        signal.signal(signum, previous[signum])

    for s in previous:
        signal.signal(s, handler)
    try:
        yield lambda: hit[0]
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
