"""One member of a sweep, run where the scheduler puts it (a Dask worker, or in-process).

:func:`run_member` takes and returns plain data (dicts of str, numbers and lists), so it crosses
process and machine boundaries without pickling porefsi objects. It decides from the member's
folder alone what to do, so a member that a killed worker left half-done continues where its
last checkpoint is, whichever worker picks it up:

- ``summary.json`` says completed and the checkpoint holds the last step: nothing to run (the
  stored summary is returned);
- a checkpoint (``checkpoint.npz``): :func:`~porefsi.case.run.run_case` with ``resume=True``;
- otherwise a fresh run (``overwrite=True`` over the remains of an attempt that failed before
  its first checkpoint; the sweep has checked that the folder belongs to this member).

``DIR/<member>/member.json`` records the member's varied values and every attempt (worker,
pid, start and end, the step it resumed from, its status and error): the member's state on disk.
"""

from __future__ import annotations

import json
import os
import socket
import time
import traceback
from pathlib import Path

import numpy as np

from porefsi.io import results

__all__ = ["run_member", "MEMBER_FILE", "read_member_file"]

#: The member's own record in its folder.
MEMBER_FILE = "member.json"
_CHECKPOINT = "checkpoint.npz"


def read_member_file(folder: str | Path) -> dict | None:
    """The member record of ``folder`` (None when absent or unreadable)."""
    try:
        d = json.loads((Path(folder) / MEMBER_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return d if isinstance(d, dict) else None


def _checkpoint_step(folder: Path) -> int | None:
    """Exchange step of the folder's checkpoint, reading only its metadata (None: none or unreadable)."""
    try:
        with np.load(folder / _CHECKPOINT, allow_pickle=False) as z:
            return int(json.loads(bytes(z["__meta__"]).decode("utf-8"))["step_index"])
    except (OSError, ValueError, KeyError, TypeError, EOFError):
        return None
    except Exception:  # noqa: BLE001  (zipfile/zlib errors of a damaged file: run_case names them)
        return None


def one_line(exc: BaseException) -> str:
    """A failure as one line: porefsi's own message, or ``Type: message`` for anything else."""
    from porefsi.errors import PorefsiError

    text = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    if isinstance(exc, PorefsiError):
        return text or type(exc).__name__
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def run_member(task: dict) -> dict:
    """Run (or continue, or skip) one member; return its record.

    Parameters
    ----------
    task : dict
        ``index``, ``name``, ``values`` (dotted key -> value), ``case`` (nested dict of the whole
        case), ``out`` (the member's folder), ``overwrite`` (start over), ``force`` and
        ``figures`` (passed to :func:`~porefsi.case.run.run_case`).

    Returns
    -------
    dict
        ``index``, ``name``, ``values``, ``status`` (``completed`` or ``failed``), ``error`` (one
        line, or None), ``summary`` (the run's ``summary.json``, or None), ``attempts``,
        ``resumed_from_step`` (None for a fresh start), ``worker`` (host:pid), ``note``.

    Notes
    -----
    Any exception of the run (porefsi's, a solver's, a bug's) is recorded, not raised: a
    failing member never stops the others. ``KeyboardInterrupt`` and ``SystemExit`` pass (the
    run saved its checkpoint first). BLAS is pinned to one thread while the member runs.
    """
    from threadpoolctl import threadpool_limits

    from porefsi.case.config import case_from_dict
    from porefsi.case.run import run_case

    out = Path(task["out"])
    state = read_member_file(out) or {}
    attempts = list(state.get("attempts", [])) if not task.get("overwrite") else []
    step = None if task.get("overwrite") else _checkpoint_step(out)
    attempt = {"attempt": len(attempts) + 1, "worker": f"{socket.gethostname()}:{os.getpid()}",
               "started": time.strftime("%Y-%m-%dT%H:%M:%S"), "resumed_from_step": step}
    record = {"index": task["index"], "name": task["name"], "values": task["values"], "attempts": attempt["attempt"],
              "resumed_from_step": step, "worker": attempt["worker"], "status": "failed", "error": None,
              "summary": None, "note": ""}
    _write_state(out, task, attempts + [{**attempt, "status": "running"}])
    try:
        case = case_from_dict(task["case"], where=f"member {task['name']}")
        with threadpool_limits(limits=1, user_api="blas"):
            res = run_case(case, out, resume=step is not None, overwrite=step is None, force=task.get("force", False),
                           progress=False, figures=task.get("figures"))
        record.update(status="completed" if res.summary.get("status") == "completed" else "failed",
                      summary=res.summary, note=res.note, error=res.summary.get("error"))
    except Exception as exc:  # noqa: BLE001  (recorded: the other members go on)
        record["error"] = one_line(exc)
        record["traceback"] = "" if _is_porefsi(exc) else traceback.format_exc(limit=8)
        record["summary"] = _read_summary(out)
    attempt.update(ended=time.strftime("%Y-%m-%dT%H:%M:%S"), status=record["status"], error=record["error"])
    _write_state(out, task, attempts + [attempt])
    return record


def _is_porefsi(exc: BaseException) -> bool:
    from porefsi.errors import PorefsiError

    return isinstance(exc, PorefsiError)


def _read_summary(out: Path) -> dict | None:
    try:
        s = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return s if isinstance(s, dict) else None


def _write_state(out: Path, task: dict, attempts: list) -> None:
    """Write ``member.json`` (atomically; a failure to write it is not the member's failure)."""
    try:
        results.write_json(out / MEMBER_FILE, {"index": task["index"], "name": task["name"],
                                               "values": task["values"], "attempts": attempts})
    except OSError:
        pass
