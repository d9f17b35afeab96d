"""The run directory of :func:`porefsi.case.run.run_case` (private): what is there, what may go.

Everything here either only reads (what kind of run a directory holds, the checkpoint to resume
from, whether a run is finished, whether a new one is too large) or removes porefsi's own
files, and then only when :func:`porefsi.case.run.run_case` has validated every input and
holds the directory's lock.
"""

from __future__ import annotations

import csv
import json
import math
import re
import shlex
import shutil
from pathlib import Path

from porefsi.case.config import Case, case_from_dict, case_to_dict
from porefsi.errors import ConfigError, InputError, PorefsiError
from porefsi.io import results

__all__ = ["CHECKPOINT", "MAX_STEPS", "MAX_OUTPUT_BYTES", "clear_outputs", "refuse_existing", "load_resume",
           "read_completed", "check_steps", "check_output_volume", "resume_command", "n_exchange_steps"]

#: Checkpoint file name in a run directory.
CHECKPOINT = "checkpoint.npz"
#: A run of more exchange steps than this is refused unless forced (each step writes two files
#: and rewrites ``timeseries.csv``); ``--force`` (``force=True``) runs it anyway.
MAX_STEPS = 10_000
#: A run whose outputs are estimated above this many bytes is refused unless forced.
MAX_OUTPUT_BYTES = 50 * 2**30

#: Files porefsi writes in a run directory, by sub-folder (regular expressions on the name; a
#: group ``step`` marks per-step files). Only these are ever removed, never other files.
OUTPUT_FILES = {
    ".": (r"checkpoint\.npz", r"summary\.json", r"timeseries\.csv", r"solid\.pvd", r"network\.pvd"),
    "vtk": (r"solid_(?P<step>\d{4,})\.vtu", r"network_(?P<step>\d{4,})\.vtp"),
    "pores": (r"step_(?P<step>\d{4,})\.npz", r"psd_(?P<step>\d{4,})\.csv"),
    "figures": (r"timeseries\.png", r"pore_size_distribution\.png",
                r"(drainage|displacement|pore_force|von_mises)_t\d{3,}_\d{3}s\.png"),
}
#: A temporary file of :func:`porefsi.io.results.atomic_write_bytes` (or ``atomic_path``) a killed run left.
_TEMPORARY = r"\.(?P<name>.+?)\.[^.]+\.tmp(\.[^.]+)?"
_FRESH = "run again without --resume (with --overwrite) to start over"


def n_exchange_steps(case: Case) -> int:
    """Exchange steps of ``case`` (as :class:`~porefsi.coupling.loop.CoupledRun` counts them)."""
    return max(1, int(math.ceil(case.drainage.t_end / case.coupling.exchange_dt - 1e-9)))


def clear_outputs(out: Path, after_step: int | None = None) -> list[Path]:
    """Remove the files porefsi wrote in ``out``; return them.

    A fresh run (``after_step`` None) removes all of them; a resumed run only the per-step files
    of the steps after ``after_step`` and the figures. The temporary files of atomic writes a
    killed run left go too. Files of other names are never touched.
    """
    removed = []
    for sub, patterns in OUTPUT_FILES.items():
        d = out / sub
        if not d.is_dir():
            continue
        for f in d.iterdir():
            if not f.is_file():
                continue
            tmp = re.fullmatch(_TEMPORARY, f.name)
            name = tmp["name"] if tmp else f.name
            m = next((m for m in (re.fullmatch(pat, name) for pat in patterns) if m), None)
            if m is None:
                continue
            step = m.groupdict().get("step")
            if after_step is None or tmp or sub == "figures" or (step is not None and int(step) > after_step):
                f.unlink()
                removed.append(f)
        if sub != "." and after_step is None and not any(d.iterdir()):
            d.rmdir()
    return removed


def _read_summary(out: Path) -> dict | None:
    try:
        s = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return s if isinstance(s, dict) else None


def refuse_existing(out: Path, overwrite: bool) -> None:
    """Refuse a fresh run into a directory holding a finished or resumable run (unless ``overwrite``).

    Raises
    ------
    InputError
        ``out`` holds ``checkpoint.npz`` or ``summary.json``; the message names ``--resume``
        and ``--overwrite``.
    """
    if overwrite or not out.is_dir():
        return
    has_ckpt = (out / CHECKPOINT).is_file()
    if not has_ckpt and not (out / "summary.json").is_file():
        return
    s = _read_summary(out) or {}
    status = s.get("status")
    what = f"a {status} run" if status in ("completed", "interrupted", "failed") else "an earlier run"
    steps = f" ({s.get('n_exchange_steps')} exchange steps)" if "n_exchange_steps" in s else ""
    hint = " continue it with --resume, or" if has_ckpt and status != "completed" else ""
    raise InputError(f"output folder {out} already holds {what}{steps}:{hint} pass --overwrite to replace its "
                     "results, or pass another -o DIR")


def load_resume(out: Path, case: Case) -> tuple[dict, dict]:
    """Read and check the checkpoint to resume ``case`` from: (arrays, metadata). Changes nothing.

    Raises
    ------
    ConfigError
        No checkpoint, or one of another case.
    InputError
        An empty, truncated, corrupt or old-format checkpoint (names the file and the fix).
    """
    ckpt = out / CHECKPOINT
    if not ckpt.is_file():
        raise ConfigError(f"--resume: no checkpoint in {str(out)!r}; run without --resume to start")
    arrays, meta = results.load_checkpoint(ckpt, "run checkpoint", _FRESH)
    try:
        saved = case_from_dict(meta["case"], name=meta["case"].get("name", "case"))
        int(meta["step_index"])
    except (KeyError, TypeError, AttributeError, ValueError) as exc:
        raise InputError(f"{ckpt} is not a usable run checkpoint: damaged metadata ({type(exc).__name__}: "
                         f"{exc}); {_FRESH}") from None
    except PorefsiError as exc:
        raise InputError(f"{ckpt} is not a usable run checkpoint: its case is invalid ({exc}); {_FRESH}") from None
    if case_to_dict(saved) != case_to_dict(case):
        raise ConfigError(f"--resume: the case differs from the one that started {str(out)!r}; "
                          "resume with the same case file or start a new run directory")
    return arrays, meta


def read_completed(out: Path, case: Case, meta: dict) -> tuple[dict, dict] | None:
    """(summary, time series) of the completed run in ``out``, or None if it is not complete."""
    s = _read_summary(out)
    if s is None or s.get("status") != "completed" or int(meta["step_index"]) < n_exchange_steps(case):
        return None
    try:
        with open(out / "timeseries.csv", newline="", encoding="utf-8") as fh:
            rows = list(csv.DictReader(fh))
    except OSError:
        return None
    ts = {k: [float(r[k]) if r[k] not in ("", None) else float("nan") for r in rows] for k in (rows[0] if rows else {})}
    return s, ts


def resume_command(out: Path) -> str:
    """The command that continues the run in ``out`` (its resolved ``case.toml`` is the case)."""
    return f"porefsi run {shlex.quote(str(out / 'case.toml'))} -o {shlex.quote(str(out))} --resume"


def check_steps(case: Case, force: bool) -> None:
    """Refuse a case of more than :data:`MAX_STEPS` exchange steps unless ``force``.

    Raises
    ------
    ConfigError
        Too many steps; the message gives the count and the fix.
    """
    n = case.drainage.t_end / case.coupling.exchange_dt
    if n > MAX_STEPS and not force:
        raise ConfigError(
            f"coupling.exchange_dt = {case.coupling.exchange_dt:g} s over drainage.t_end = {case.drainage.t_end:g} s "
            f"makes {n:.3g} exchange steps (limit {MAX_STEPS}; each writes two files): raise exchange_dt, or pass "
            "--force (force=True) to run it anyway")


def check_output_volume(out: Path, case: Case, problem, force: bool) -> int:
    """Estimate the bytes a run will write; refuse past :data:`MAX_OUTPUT_BYTES` or the free space.

    The estimate: per step the pore file (7 doubles per pore) and the pore-size table, plus the
    VTK snapshots (about 60 bytes per mesh node and 70 per pore each), the time series, and
    twice the checkpoint (an atomic write holds the old and the new one at once; the checkpoint
    is mostly the voxel labels, the displacements and the interface operator).

    Raises
    ------
    InputError
        The estimate exceeds the limit or the free space of the disk (unless ``force``).
    """
    n_pores, n_nodes = problem.network.n_pores, problem.mesh.n_nodes
    steps = n_exchange_steps(case)
    n_snap = (len(case.output.snapshot_times) + 2) if case.output.vtk else 0
    checkpoint = (problem.extraction.labels.nbytes + 12 * problem.interface.operator.nnz + 48 * n_nodes
                  + 400 * n_pores)
    estimate = steps * (56 * n_pores + 4400) + n_snap * (60 * n_nodes + 70 * n_pores) + 2 * checkpoint
    probe = out
    while not probe.exists() and probe.parent != probe:
        probe = probe.parent
    try:
        free = shutil.disk_usage(probe).free
    except OSError:
        free = None
    gib = 2.0**30
    if not force and estimate > MAX_OUTPUT_BYTES:
        raise InputError(f"this run would write about {estimate / gib:.3g} GiB to {out} (limit "
                         f"{MAX_OUTPUT_BYTES / gib:g} GiB): use fewer exchange steps or snapshots, or pass --force")
    if not force and free is not None and estimate > free:
        raise InputError(f"this run would write about {estimate / gib:.3g} GiB but the disk of {out} has "
                         f"{free / gib:.3g} GiB free: free some space or pass another -o DIR (or --force)")
    return estimate
