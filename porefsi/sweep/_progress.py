"""Progress of a sweep on stderr: a rich bar on a terminal, one line per finished member in a log."""

from __future__ import annotations

import sys
import time

__all__ = ["SweepProgress"]


class SweepProgress:
    """Show how many members are done, failed and left, with the elapsed time and an ETA.

    Parameters
    ----------
    total : int
        Members of the sweep.
    skipped : int
        Members already completed by an earlier run of the sweep (counted as done at the start).
    enabled : bool or None
        False: nothing. None: a rich progress bar when stderr is a terminal, else one line per
        finished member (batch logs). True: the same as None.
    stream : file, optional
        Where to write (default ``sys.stderr``).
    """

    def __init__(self, total: int, skipped: int = 0, enabled: bool | None = None, stream=None):
        self.total, self.done, self.failed = total, skipped, 0
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = enabled is not False
        self.t0 = time.perf_counter()
        self.n_this_run = 0
        self._rich = None
        if self.enabled and _isatty(self.stream):
            from rich.console import Console
            from rich.progress import (
                BarColumn,
                MofNCompleteColumn,
                Progress,
                TextColumn,
                TimeElapsedColumn,
                TimeRemainingColumn,
            )

            self._rich = Progress(TextColumn("porefsi sweep"), BarColumn(), MofNCompleteColumn(),
                                  TextColumn("{task.fields[failed]} failed"), TimeElapsedColumn(),
                                  TextColumn("ETA"), TimeRemainingColumn(), TextColumn("{task.fields[last]}"),
                                  console=Console(file=self.stream), transient=False)
            self._task = self._rich.add_task("members", total=total, completed=skipped, failed=0, last="")
            self._rich.start()
        elif self.enabled and skipped:
            self._line(f"{skipped} of {total} members already completed (skipped)")

    def member_done(self, record: dict) -> None:
        """Count a finished member (its record from :func:`porefsi.sweep.member.run_member`)."""
        self.done += 1
        self.n_this_run += 1
        ok = record.get("status") == "completed"
        self.failed += not ok
        if not self.enabled:
            return
        wall = (record.get("summary") or {}).get("wall_seconds")
        how = f"completed in {wall:.1f} s" if ok and isinstance(wall, (int, float)) else (
            "completed" if ok else f"FAILED: {record.get('error')}")
        if record.get("resumed_from_step") is not None and ok:
            how += f" (resumed from step {record['resumed_from_step']})"
        if self._rich is not None:
            self._rich.update(self._task, completed=self.done, failed=self.failed, last=f"{record['name']}: "
                              f"{'ok' if ok else 'failed'}")
            if not ok:
                self._rich.console.print(f"porefsi sweep: {record['name']} {how}")
            return
        el = time.perf_counter() - self.t0
        left = self.total - self.done
        eta = el / max(self.n_this_run, 1) * left
        self._line(f"{self.done}/{self.total} ({self.failed} failed), {el:.1f} s, ETA {eta:.0f} s: "
                   f"{record['name']} {how}")

    def _line(self, text: str) -> None:
        self.stream.write(f"porefsi sweep: {text}\n")
        self.stream.flush()

    def close(self) -> None:
        """Stop the bar (its last state stays on the terminal)."""
        if self._rich is not None:
            self._rich.stop()
            self._rich = None


def _isatty(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False
