"""A line on stderr while a run is silent for long (private): batch logs show a run is alive.

The per-step progress lines of :func:`porefsi.case.run.run_case` come after each exchange step;
the set-up of a large image (reading, extraction, meshing, interface) and a long first step can
take minutes before the first of them. :class:`Heartbeat` writes ``porefsi run: step ..., still
running`` every :data:`HEARTBEAT_SECONDS` of silence from a daemon thread.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable

__all__ = ["Heartbeat", "HEARTBEAT_SECONDS"]

#: Wall seconds without a line after which the heartbeat writes one.
HEARTBEAT_SECONDS = 30.0


class Heartbeat:
    """Context manager: a line every ``every`` wall seconds while the block runs.

    Parameters
    ----------
    status : callable
        Returns what the run is doing (e.g. ``"step 3/20"``), asked at each line.
    every : float, optional
        Seconds between lines (default :data:`HEARTBEAT_SECONDS` at entry).
    enabled : bool, default True
        False: do nothing (a terminal has its bar; ``progress=False`` wants silence).
    stream : file, optional
        Where to write (default ``sys.stderr`` at each line).
    """

    def __init__(self, status: Callable[[], str], every: float | None = None, enabled: bool = True,
                 stream=None):
        self.status, self.every, self.enabled, self.stream = status, every, enabled, stream
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.lines = 0

    def __enter__(self) -> Heartbeat:
        if self.enabled:
            every = HEARTBEAT_SECONDS if self.every is None else self.every
            self._thread = threading.Thread(target=self._beat, args=(every,), daemon=True,
                                            name="porefsi-heartbeat")
            self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()

    def _beat(self, every: float) -> None:
        t0 = time.perf_counter()
        while not self._stop.wait(every):
            try:
                what = self.status()
                out = self.stream if self.stream is not None else sys.stderr
                out.write(f"porefsi run: {what}, still running, {time.perf_counter() - t0:.0f} s wall\n")
                out.flush()
                self.lines += 1
            except Exception:  # noqa: BLE001 - a log line must never break the run
                return
