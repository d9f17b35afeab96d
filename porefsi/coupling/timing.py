"""Wall and CPU seconds of named stages (set-up and exchange-step timings of a coupled run)."""

from __future__ import annotations

import contextlib
import time

__all__ = ["StageClock"]


class StageClock:
    """Wall (``time.perf_counter``) and CPU (``time.process_time``) seconds of named stages.

    ``with clock("fluid"): ...`` adds the block's wall seconds to ``clock.wall["fluid"]`` and its
    CPU seconds (this process, all threads) to ``clock.cpu["fluid"]``; the two dicts may be shared
    with the caller (they are updated in place).
    """

    def __init__(self, wall: dict | None = None, cpu: dict | None = None):
        self.wall = {} if wall is None else wall
        self.cpu = {} if cpu is None else cpu

    @contextlib.contextmanager
    def __call__(self, stage: str):
        """Time the block as ``stage`` (accumulated: the same stage may be timed several times)."""
        w0, c0 = time.perf_counter(), time.process_time()
        yield
        self.wall[stage] = self.wall.get(stage, 0.0) + time.perf_counter() - w0
        self.cpu[stage] = self.cpu.get(stage, 0.0) + time.process_time() - c0
