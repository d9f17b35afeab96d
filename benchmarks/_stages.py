"""Per-stage wall, CPU and peak memory for benchmarks (Linux: /proc/self).

The peak resident set of a stage is read from ``VmHWM`` after resetting it (``echo 5 >
/proc/self/clear_refs``) at the stage's start, so it is the true peak of that stage, not of the
process so far; ``ru_maxrss`` (the process peak) is printed at the end.
"""

from __future__ import annotations

import contextlib
import os
import resource
import time


def _status_kib(key: str) -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key + ":"):
                return int(line.split()[1])
    return 0


def _reset_peak() -> bool:
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


class Stages:
    """``with stages("name"): ...`` records wall, CPU, RSS at the end and the stage's peak RSS (GiB)."""

    def __init__(self, echo: bool = True):
        self.rows: list[dict] = []
        self.echo = echo

    @contextlib.contextmanager
    def __call__(self, name: str):
        _reset_peak()
        rss0 = _status_kib("VmRSS")
        w0, c0 = time.perf_counter(), time.process_time()
        try:
            yield
        finally:
            row = {"stage": name, "wall": time.perf_counter() - w0, "cpu": time.process_time() - c0,
                   "rss_start": rss0 / 2**20, "rss_end": _status_kib("VmRSS") / 2**20,
                   "peak": _status_kib("VmHWM") / 2**20, "load": os.getloadavg()[0]}
            self.rows.append(row)
            if self.echo:
                print(self.format(row), flush=True)

    @staticmethod
    def header() -> str:
        return f"    {'stage':<22} {'wall s':>8} {'CPU s':>8} {'RSS end':>8} {'peak':>8} {'+peak':>8}  load"

    @staticmethod
    def format(r: dict) -> str:
        return (f"    {r['stage']:<22} {r['wall']:8.2f} {r['cpu']:8.2f} {r['rss_end']:8.3f} {r['peak']:8.3f} "
                f"{r['peak'] - r['rss_start']:8.3f}  {r['load']:.2f}")


def process_peak_gib() -> float:
    """Peak resident set of this process so far (ru_maxrss), GiB."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20


def cap_memory(gib: float) -> None:
    """Limit this process's address space to ``gib`` GiB (a runaway allocation fails, not the machine)."""
    lim = int(gib * 2**30)
    resource.setrlimit(resource.RLIMIT_AS, (lim, lim))
