"""Checkpoints of a drainage run (private; used by :func:`porefsi.flow.drainage.simulate_drainage`).

A checkpoint is one pickle, written atomically (a temporary file renamed over the old one), of
the simulator between two events, the snapshots taken so far and the run's elapsed seconds,
stamped with a fingerprint of everything that determines the run (network arrays, fluids,
boundary condition, axis, end and snapshot times, solver options). A resumed run refuses a
checkpoint of a different run.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import pickle
import signal
import threading
from pathlib import Path

import numpy as np

from porefsi.errors import InputError
from porefsi.io.results import atomic_write_bytes

__all__ = ["fingerprint", "save", "load", "deferred_interrupt", "FORMAT"]

#: Layout version of the checkpoint payload.
FORMAT = 1


def fingerprint(net, fluids, settings: dict) -> str:
    """SHA-1 (hex) of the network's arrays, the fluids and the run ``settings``."""
    h = hashlib.sha1()
    for f in dataclasses.fields(net):
        v = getattr(net, f.name)
        h.update(f.name.encode())
        if isinstance(v, np.ndarray):
            h.update(str((v.dtype, v.shape)).encode())
            h.update(memoryview(np.ascontiguousarray(v)).cast("B"))
        else:
            h.update(repr(v).encode())
    h.update(repr(dataclasses.astuple(fluids)).encode())
    h.update(repr(sorted(settings.items())).encode())
    return h.hexdigest()


def save(path: str | Path, key: str, payload: dict) -> Path:
    """Write ``payload`` with its fingerprint ``key`` to ``path`` atomically; return the path."""
    data = pickle.dumps({"format": FORMAT, "key": key, **payload}, protocol=pickle.HIGHEST_PROTOCOL)
    return atomic_write_bytes(path, data)


def load(path: str | Path, key: str) -> dict:
    """Read a checkpoint written by :func:`save` for the run with fingerprint ``key``.

    Raises
    ------
    InputError
        No checkpoint at ``path``, an unreadable one, or one of a different run.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"cannot resume: no drainage checkpoint at {path}; run without --resume first "
                         "(a checkpoint is written there while the run goes on)")
    try:
        with open(path, "rb") as f:
            d = pickle.load(f)  # noqa: S301 - our own checkpoint file
    except Exception as exc:  # truncated or foreign file
        raise InputError(f"cannot resume: {path} is not a readable drainage checkpoint ({type(exc).__name__}: "
                         f"{exc}); delete it and run without --resume") from None
    if not isinstance(d, dict) or d.get("format") != FORMAT:
        raise InputError(f"cannot resume: {path} is not a drainage checkpoint of this porefsi version; "
                         "delete it and run without --resume")
    if d["key"] != key:
        raise InputError(f"cannot resume: the checkpoint {path} belongs to a different run (network, fluids, "
                         "rate, axis, times or solver options differ); repeat the original command with "
                         "--resume, or run without --resume to start over")
    return d


@contextlib.contextmanager
def deferred_interrupt(enabled: bool = True):
    """Defer the first Ctrl-C (SIGINT) to the caller's next safe point; yield a "was it pressed" test.

    The caller polls the yielded function between events, saves a checkpoint when it returns True
    and raises :class:`KeyboardInterrupt` itself, so an interrupted run loses no finished event.
    The first Ctrl-C restores the previous handler: a second one interrupts at once (an event that
    takes long, e.g. a factorisation). Outside the main thread, or with ``enabled`` False, nothing
    is installed and the test is always False.
    """
    hit = [False]
    if not enabled or threading.current_thread() is not threading.main_thread():
        yield lambda: False
        return
    previous = signal.getsignal(signal.SIGINT)

    def handler(signum, frame):
        hit[0] = True
        signal.signal(signal.SIGINT, previous)

    signal.signal(signal.SIGINT, handler)
    try:
        yield lambda: hit[0]
    finally:
        signal.signal(signal.SIGINT, previous)
