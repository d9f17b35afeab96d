"""Run a case end to end: build, couple, write results, checkpoint, resume, figures.

Outputs in the run directory:

- ``case.toml``: the resolved case (every key);
- ``timeseries.csv``: one row per exchange step (:data:`porefsi.coupling.records.TIMESERIES_COLUMNS`);
- ``summary.json``: headline figures (and ``status``/``error`` if the run failed);
- ``solid.pvd`` + ``vtk/solid_NNNN.vtu`` (displacement, von Mises, nodal pore force) and
  ``network.pvd`` + ``vtk/network_NNNN.vtp`` (pressure, saturation, radius) at the snapshot times;
- ``pores/step_NNNN.npz`` (every exchange step, step 0 included): pore pressure, non-wetting
  saturation, radius, volume and centre of every pore (:func:`porefsi.io.results.read_pore_steps`),
  and ``pores/psd_NNNN.csv``: the pore-size distribution of that step on fixed bins;
- ``figures/*.png``: time series, pore-size distributions, drainage and deformation scenes;
- ``checkpoint.npz``: written atomically every ``output.checkpoint_every`` steps; ``--resume``
  continues from it and ends with the same results as an uninterrupted run.

Every file is written atomically, with the user's umask. Nothing in the directory is touched
before every input has been read and validated (case, image, crop, network, mesh, the checkpoint
and its case): a run that fails there leaves the directory as it found it. A fresh run refuses a
directory that holds a finished or resumable run unless ``overwrite`` (CLI ``--overwrite``), and
then removes the files an earlier run wrote there (the names above; files of other names, e.g. a
user's own figures, are kept); a resumed run removes the per-step files of the steps after its
checkpoint (it rewrites them) and the figures (made again at the end); resuming a completed run
changes nothing. A run holds an exclusive lock on the directory (:func:`porefsi.io.rundir.lock`):
a second run into it fails at once. The first Ctrl-C or SIGTERM ends the run after the current
exchange step, with a checkpoint and ``summary.json`` status ``"interrupted"`` and the command
that resumes it.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import sys
import time
import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path

import numpy as np

from porefsi._version import __version__
from porefsi.case import _outputs as _out
from porefsi.case import _rundir as _rd
from porefsi.case._heartbeat import Heartbeat
from porefsi.case.config import Case, case_to_dict, case_to_toml
from porefsi.case.fidelity import fidelity_summary, resolve_fidelity
from porefsi.case.problem import problem_from_case
from porefsi.coupling.loop import CoupledRun
from porefsi.coupling.records import TIMESERIES_COLUMNS, ExchangeRecord
from porefsi.errors import InputError, PorefsiError
from porefsi.flow import plausible as _plausible
from porefsi.image.io import check_voxel_size
from porefsi.io import interrupt, results, rundir

__all__ = ["run_case", "RunOutput", "RunControl"]


@dataclasses.dataclass(frozen=True)
class RunOutput:
    """What :func:`run_case` returns: the summary and where the files are."""

    summary: dict
    directory: Path
    timeseries: dict
    note: str = ""  # e.g. that a resumed run was already complete


@dataclasses.dataclass(frozen=True)
class RunControl:
    """How :func:`run_case` runs a case (its keyword options; the case itself says what is run).

    Attributes
    ----------
    resume : bool
        Continue from ``out/checkpoint.npz`` (the case must be the one saved in ``out/case.toml``).
        Resuming a completed run changes nothing and returns its summary.
    overwrite : bool
        A fresh run into a directory that holds a run (a checkpoint or ``summary.json``) replaces
        that run's results; without it such a run is refused.
    force : bool
        Run a case past the size limits (:data:`porefsi.case._rundir.MAX_STEPS` exchange steps,
        :data:`porefsi.case._rundir.MAX_OUTPUT_BYTES` of outputs, the disk's free space).
    progress : bool, optional
        Progress on stderr: True a redrawn bar, False none; default a bar when stderr is a
        terminal, else one line per exchange step (batch logs).
    figures : bool, optional
        Override ``case.output.figures``.
    stop_after : int, optional
        Stop after this many exchange steps of this call (for tests of interrupted runs).
    reuse_extractions : bool, default True
        Re-extraction mode: serve the extraction of a voxel image seen before from a digest cache
        (:class:`~porefsi.coupling.network_step.ExtractionCache`); False computes every
        re-extraction, the paper's cost, with the same results (for cost studies).
    """

    resume: bool = False
    overwrite: bool = False
    force: bool = False
    progress: bool | None = None
    figures: bool | None = None
    stop_after: int | None = None
    reuse_extractions: bool = True


@dataclasses.dataclass
class _Sofar:
    """A run in progress: the loop, its rows, snapshots and ParaView series, the set-up times."""

    run: CoupledRun | None = None
    rows: list = dataclasses.field(default_factory=list)
    snapshots: list = dataclasses.field(default_factory=list)
    series: dict = dataclasses.field(default_factory=dict)
    setup_seconds: dict = dataclasses.field(default_factory=dict)
    setup_cpu: dict = dataclasses.field(default_factory=dict)


class _Progress:
    """Progress on stderr: a redrawn bar with ETA (a terminal), or plain lines (a batch log).

    Parameters
    ----------
    total : int
        Exchange steps of the whole run.
    enabled : bool
        Draw the bar.
    start : int, default 0
        Steps already done when this process started (restored from a checkpoint): the ETA is
        the time per step *of this process* times the steps left.
    stream : file, optional
        Where to draw (default ``sys.stderr`` at the time of each update).
    lines : bool, default False
        Instead of the bar, one line per exchange step (at most one per
        :data:`LINE_SECONDS`, and always the last), for logs of batch jobs.
    """

    def __init__(self, total: int, enabled: bool, start: int = 0, stream=None, lines: bool = False):
        self.total, self.enabled, self.start, self.stream, self.lines = total, enabled, start, stream, lines
        self.t0 = time.perf_counter()
        self._last_line = -math.inf

    def update(self, done: int, t: float, extra: str = "") -> None:
        """Redraw after ``done`` of ``total`` steps, at simulated time ``t`` (s)."""
        if not self.enabled:
            return
        out = self.stream if self.stream is not None else sys.stderr
        el = time.perf_counter() - self.t0
        eta = el / max(done - self.start, 1) * (self.total - done)
        if self.lines:
            if done == self.total or el - self._last_line >= LINE_SECONDS:
                self._last_line = el
                out.write(f"porefsi run: step {done}/{self.total}, t = {t:.4g} s, {extra}, {el:.1f} s, "
                          f"ETA {eta:.0f} s\n")
                out.flush()
            return
        bar = "#" * int(30 * done / self.total)
        out.write(f"\r[{bar:<30}] {done}/{self.total} t={t:.3g} s  {el:6.1f} s, ETA {eta:6.1f} s {extra}")
        if done == self.total:
            out.write("\n")
        out.flush()


#: Least wall seconds between two progress lines of a run whose stderr is not a terminal.
LINE_SECONDS = 1.0
def run_case(case: Case, out: str | Path | None = None, *, on_record: Callable[[ExchangeRecord], None] | None = None,
             **control) -> RunOutput:
    """Run ``case`` and write its results to ``out`` (default ``case.output.dir``).

    Parameters
    ----------
    case : Case
    out : path, optional
        Run directory.
    on_record : callable, optional
        Called with every :class:`~porefsi.coupling.records.ExchangeRecord` (e.g. by case scripts).
    **control
        :class:`RunControl` options: ``resume``, ``overwrite``, ``force``, ``progress``,
        ``figures``, ``stop_after``, ``reuse_extractions``.

    Raises
    ------
    ConfigError
        ``resume`` without a checkpoint, or with a different case; a case past the size limits.
    InputError
        ``out`` unusable (a file, under a file, read-only) or holding a run (without
        ``overwrite``); a damaged checkpoint; another process running in ``out``
        (:class:`porefsi.io.rundir.RunLockedError`); a write failing (full disk: the last
        checkpoint is kept).
    PorefsiError
        A failure of the run (solver libraries' exceptions arrive as ``ConvergenceError``).
        Once the run has started writing, on *any* exception (also a bug's or
        ``KeyboardInterrupt``) the last checkpoint and the outputs so far are kept,
        ``summary.json`` records ``status`` (``"failed"`` or ``"interrupted"``), the error and
        the resume command, and the exception is re-raised.

    Notes
    -----
    ``wall_seconds`` in the summary is cumulative over the processes of a resumed run: each
    interrupted process counts up to its last checkpoint (the steps it did after that are
    redone, and counted, by the resuming process); ``wall_seconds_this_process`` is this call's.
    ``cpu_seconds`` / ``cpu_seconds_this_process`` are the same for CPU time
    (``time.process_time``: this process, all threads), and ``cpu_seconds_by_stage`` is the CPU
    counterpart of the wall-time ``seconds_by_stage`` (set-up stages, then the loop's, cumulative
    over a resumed run like the totals).
    """
    ctl = RunControl(**control)
    clock = _RunClock(time.perf_counter(), time.process_time())
    case = resolve_fidelity(case)[0]  # a [fidelity] preset: its settings (a resolved case resolves to itself)
    out = rundir.check_output_dir(Path(out if out is not None else case.output.dir))
    # 1. read and validate everything; nothing in ``out`` changes before the lock below
    saved = None
    if ctl.resume:
        saved = _rd.load_resume(out, case)
        done = _rd.read_completed(out, case, saved[1])
        if done is not None:  # a completed run: nothing to do, nothing to change
            return RunOutput(done[0], out, done[1], note=f"{out} already holds the completed run; nothing to do")
    else:
        _rd.refuse_existing(out, ctl.overwrite)
        _rd.check_steps(case, ctl.force)
    sofar_box: list = []  # the run once set up, for the heartbeat's lines
    beat = Heartbeat(lambda: _doing(sofar_box), enabled=ctl.progress is None and not sys.stderr.isatty())
    with beat:
        return _validated_run(case, out, ctl, clock, saved, sofar_box, on_record)


def _doing(sofar_box: list) -> str:
    """What the run is doing, for the heartbeat's line."""
    run = sofar_box[0].run if sofar_box and sofar_box[0].run is not None else None
    if run is None:
        return "step 0, setting up (image, network, mesh, solid, interface)"
    if run.step_index >= run.n_steps:
        return f"all {run.n_steps} steps done, writing outputs and figures"
    return f"step {run.step_index + 1}/{run.n_steps}"


def _validated_run(case: Case, out: Path, ctl: RunControl, clock: _RunClock, saved, sofar_box: list,
                   on_record) -> RunOutput:
    """:func:`run_case` after the run folder and the checkpoint were checked: set up, lock, run."""
    problem = problem_from_case(case)
    _plausible.warn_injection_pressure(problem.network, case.image.axis, case.drainage.rate, case.fluids.mu_n)
    if not case.image.path and case.image.voxel_size is not None:  # a file's is checked when it is read
        check_voxel_size(case.image.voxel_size, "image.voxel_size")
    sofar = _restore(problem, out, saved, ctl.reuse_extractions) if saved else None
    _rd.check_output_volume(out, case, problem, ctl.force or ctl.resume)
    # 2. the directory is ours: clear what goes, then run
    with rundir.lock(out), rundir.output_errors(out):
        if saved is None:
            _rd.refuse_existing(out, ctl.overwrite)  # again: a run may have finished there meanwhile
            _rd.clear_outputs(out)
        else:
            clock.wall_before = float(saved[1].get("wall_seconds", 0.0))
            clock.cpu_before = float(saved[1].get("process_cpu_seconds", 0.0))
            # the steps after the checkpoint are redone: their files go (they are rewritten)
            _rd.clear_outputs(out, after_step=int(saved[1]["step_index"]))
        results.atomic_write_text(out / "case.toml", case_to_toml(case))
        if ctl.figures is None:
            ctl = dataclasses.replace(ctl, figures=case.output.figures)
        if sofar is None:
            sofar = _fresh(problem, out)
        sofar_box.append(sofar)
        return _execute(case, out, problem, sofar, clock, ctl, on_record)


def _restore(problem, out: Path, saved: tuple[dict, dict], reuse_extractions: bool) -> _Sofar:
    """The run state of a checkpoint, validated against ``problem`` (reads only)."""
    arrays, meta = saved
    ckpt = out / _rd.CHECKPOINT
    try:
        run = CoupledRun.restore(problem, arrays, meta, reuse_extractions=reuse_extractions)
        # JSON keeps NaN as null: give the restored rows their NaN back
        rows = [{k: float("nan") if v is None else v for k, v in r.items()} for r in meta["rows"]]
        snapshots = _load_snapshots(arrays, meta)
        setup = (dict(meta["setup_seconds"]), dict(meta.get("setup_cpu_seconds", {})))
    except (KeyError, ValueError, TypeError, IndexError, AttributeError, PorefsiError) as exc:
        raise InputError(f"{ckpt} is not a usable run checkpoint: damaged, or written by another porefsi version "
                         f"({type(exc).__name__}: {exc}); run again without --resume (with --overwrite) to start "
                         "over") from None
    series = {}
    for k in ("solid", "network"):
        try:
            series[k] = results.PvdSeries.read(out / f"{k}.pvd")
        except (OSError, ValueError, TypeError, ET.ParseError) as exc:
            raise InputError(f"{out / f'{k}.pvd'} is damaged ({exc}); delete it to resume without the earlier "
                             "snapshots in the series, or run again with --overwrite") from None
    return _Sofar(run, rows, snapshots, series, *setup)


def _fresh(problem, out: Path) -> _Sofar:
    """A fresh run's state (before its first step; the ParaView series not yet written)."""
    return _Sofar(None, [], [], {k: results.PvdSeries(out / f"{k}.pvd") for k in ("solid", "network")},
                  dict(problem.seconds), dict(problem.cpu_seconds))


def _start(case: Case, out: Path, problem, sofar: _Sofar, clock: _RunClock, ctl: RunControl, edges) -> None:
    """A restored run: its series cut to the checkpoint; a fresh one: made, and its step 0 written."""
    clock.setup_cpu = sofar.setup_cpu
    if sofar.run is not None:
        for s in sofar.series.values():
            s.truncate(sofar.run.t)
        return
    sofar.run = CoupledRun(problem, reuse_extractions=ctl.reuse_extractions)
    rec0 = sofar.run.initial_record()
    sofar.rows.append(rec0.row)
    _out.write_pores(out, rec0, edges)
    if case.output.vtk:
        _out.write_snapshot(out, rec0, sofar.run, sofar.series)
    sofar.snapshots.append(_out.snapshot(rec0))


def _after_step(case: Case, out: Path, sofar: _Sofar, rec: ExchangeRecord, edges) -> None:
    """The files of one exchange step: pores, snapshot when due, the time series so far."""
    run = sofar.run
    sofar.rows.append(rec.row)
    _out.write_pores(out, rec, edges)
    if _out.snapshot_due(case, sofar.rows[-2]["time_s"], rec.t, run.step_index == run.n_steps):
        if case.output.vtk:
            _out.write_snapshot(out, rec, run, sofar.series)
        sofar.snapshots.append(_out.snapshot(rec))
    results.write_csv(out / "timeseries.csv", _columns(sofar.rows))


def _execute(case: Case, out: Path, problem, sofar: _Sofar, clock: _RunClock, ctl: RunControl,
             on_record) -> RunOutput:
    """The loop of :func:`run_case` in a validated, locked, cleared directory."""
    ckpt = out / _rd.CHECKPOINT
    status, error = "completed", None
    try:
        edges = _out.psd_edges(problem.network)  # fixed pore-size bins of the whole run
        _start(case, out, problem, sofar, clock, ctl, edges)
        run = sofar.run
        tty = sys.stderr.isatty()
        bar = _Progress(run.n_steps, ctl.progress is not False, start=run.step_index,
                        lines=ctl.progress is None and not tty)
        n_done = 0
        with interrupt.deferred() as signalled:  # Ctrl-C / SIGTERM: finish the step, save, stop
            for rec in run.steps():
                _after_step(case, out, sofar, rec, edges)
                if on_record is not None:
                    on_record(rec)
                last = run.step_index == run.n_steps
                if run.step_index % case.output.checkpoint_every == 0 or last or signalled():
                    _save(ckpt, case, sofar, clock)
                bar.update(run.step_index, rec.t, f"Sw={rec.row['sw']:.3f}")
                n_done += 1
                if signalled() and not last:
                    raise KeyboardInterrupt(
                        f"{interrupt.SIGNAL_NAMES.get(signalled(), 'a signal')} at exchange step {run.step_index} of "
                        f"{run.n_steps}; saved to {ckpt}: continue with {_rd.resume_command(out)}")
                if ctl.stop_after is not None and n_done >= ctl.stop_after:
                    status = "interrupted"
                    break
    except BaseException as exc:
        # Whatever stopped the run (a porefsi error, a solver library's, a bug, Ctrl-C, SIGTERM, a full
        # disk): record it next to the last checkpoint (kept as it was) and the outputs so far, re-raise.
        status = "interrupted" if isinstance(exc, KeyboardInterrupt) else "failed"
        error = f"{type(exc).__name__}: {exc}"
        with contextlib.suppress(Exception):  # never hide the original error behind a write error
            _write_summary(out, case, sofar, clock, status, error, [])
        raise
    ts = _columns(sofar.rows)
    _plausible.warn_pressure_reached(max((p for p in ts["inlet_pressure_Pa"] if math.isfinite(p)), default=math.nan))
    made = _out.figures(out, ts, sofar.snapshots, run, case.name) if (ctl.figures and status == "completed") else []
    summary = _write_summary(out, case, sofar, clock, status, error, made)
    return RunOutput(summary, out, ts)


@dataclasses.dataclass
class _RunClock:
    """Wall and CPU time of :func:`run_case`, cumulative over the processes of a resumed run."""

    wall_start: float  # perf_counter at the start of this process's run_case
    cpu_start: float  # process_time at the same moment
    wall_before: float = 0.0  # wall seconds of earlier processes of this run, up to their last checkpoint
    cpu_before: float = 0.0  # CPU seconds of earlier processes of this run, up to their last checkpoint
    setup_cpu: dict = dataclasses.field(default_factory=dict)  # CPU seconds of the set-up stages

    def wall_this_process(self) -> float:
        return time.perf_counter() - self.wall_start

    def cpu_this_process(self) -> float:
        return time.process_time() - self.cpu_start


def _save(path, case: Case, sofar: _Sofar, clock: _RunClock) -> None:
    arrays, meta = sofar.run.checkpoint()
    for i, s in enumerate(sofar.snapshots):
        for k in _out.SNAP_KEYS:
            arrays[f"snap{i}_{k}"] = s[k]
    meta.update(case=case_to_dict(case), rows=sofar.rows, setup_seconds=sofar.setup_seconds,
                snapshots=[{"t": s["t"], "step": s["step"]} for s in sofar.snapshots], version=__version__,
                wall_seconds=clock.wall_before + clock.wall_this_process(), setup_cpu_seconds=clock.setup_cpu,
                process_cpu_seconds=clock.cpu_before + clock.cpu_this_process())
    results.save_checkpoint(path, arrays, meta)


def _load_snapshots(arrays, meta) -> list:
    return [{**s, **{k: arrays[f"snap{i}_{k}"] for k in _out.SNAP_KEYS}} for i, s in enumerate(meta["snapshots"])]


def _columns(rows: list[dict]) -> dict:
    return {k: [r[k] for r in rows] for k in TIMESERIES_COLUMNS}


def _write_summary(out, case, sofar: _Sofar, clock: _RunClock, status, error, figures) -> dict:
    run, rows, setup_seconds = sofar.run, sofar.rows, sofar.setup_seconds
    this_process = clock.wall_this_process()
    wall_seconds = clock.wall_before + this_process
    cpu_this = clock.cpu_this_process()
    if run is None:  # failed while setting up: what is known
        summary = {"status": status, "error": error, "case": case.name, "porefsi_version": __version__,
                   "wall_seconds": wall_seconds, "wall_seconds_this_process": this_process,
                   "cpu_seconds": clock.cpu_before + cpu_this, "cpu_seconds_this_process": cpu_this,
                   "n_exchange_steps": 0, "figures": figures, **fidelity_summary(case)}
        results.write_json(out / "summary.json", summary)
        return json.loads(json.dumps(results.jsonable(summary)))
    p = run.problem
    last = rows[-1] if rows else {}
    mass = max((r["mass_balance_error"] for r in rows), default=0.0)
    load = max((r["load_balance_error"] for r in rows), default=0.0)
    bt = run.sim.breakthrough_time
    summary = {
        "status": status,
        "error": error,
        "case": case.name,
        "porefsi_version": __version__,
        "wall_seconds": wall_seconds,
        "wall_seconds_this_process": this_process,
        "seconds_by_stage": {**setup_seconds, **run.seconds},
        "cpu_seconds": clock.cpu_before + cpu_this,
        "cpu_seconds_this_process": cpu_this,
        "cpu_seconds_by_stage": {**clock.setup_cpu, **run.cpu_seconds},
        "n_pores": p.network.n_pores,
        "n_throats": p.network.n_throats,
        "n_nodes": p.mesh.n_nodes,
        "n_tets": p.mesh.n_tets,
        "removed_solid_fraction": p.mesh_result.removed_solid_fraction,
        "n_exchange_steps": run.step_index,
        "t_end_s": run.t,
        "final_sw": last.get("sw"),
        "breakthrough_time_s": None if not np.isfinite(bt) else float(bt),
        "max_displacement_m": max((r["max_displacement_m"] for r in rows), default=0.0),
        "max_von_mises_Pa": max((r["max_von_mises_Pa"] for r in rows), default=0.0),
        "permeability_initial_m2": rows[0]["permeability_m2"] if rows else None,
        "permeability_final_m2": last.get("permeability_m2"),
        "mass_balance_error": mass,
        "load_balance_error": load,
        "interface_unloaded_pores": run.interface.n_unloaded,
        "load_outside_refined": run.coarse_load,  # graded mesh: fluid left the refined region (CoarseLoadWarning)
        "solid_response": run.solid.summary() if hasattr(run.solid, "summary") else {
            "requested": "nonlinear", "path": "nonlinear"},
        "reextraction": None if case.network.update != "reextract" else {
            "n_computed": run.n_extractions, "n_reused": run.n_extractions_reused,
            "reuse_extractions": run.reuse_extractions,
            "seconds": dict(run.update_seconds), "cpu_seconds": dict(run.update_cpu_seconds)},
        "figures": figures,
        "resume_command": _rd.resume_command(out) if status != "completed" and (out / _rd.CHECKPOINT).is_file()
        else None,
        **fidelity_summary(case),
    }
    results.write_json(out / "summary.json", summary)
    return json.loads(json.dumps(results.jsonable(summary)))
