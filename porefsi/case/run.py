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
from porefsi.case import _rundir as _rd
from porefsi.case.config import Case, case_to_dict, case_to_toml
from porefsi.case.problem import problem_from_case
from porefsi.coupling.loop import CoupledRun
from porefsi.coupling.records import TIMESERIES_COLUMNS, ExchangeRecord
from porefsi.errors import InputError, PorefsiError
from porefsi.flow import plausible as _plausible
from porefsi.image.io import check_voxel_size
from porefsi.io import interrupt, results, rundir
from porefsi.io.network_vtk import write_network_vtp

__all__ = ["run_case", "RunOutput"]


@dataclasses.dataclass(frozen=True)
class RunOutput:
    """What :func:`run_case` returns: the summary and where the files are."""

    summary: dict
    directory: Path
    timeseries: dict
    note: str = ""  # e.g. that a resumed run was already complete


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
#: Number of pore-size bins of ``pores/psd_NNNN.csv``.
PSD_BINS = 30
#: The bins span [0, PSD_SPAN x the largest pore radius of the reference network].
PSD_SPAN = 1.5


def _psd_edges(net) -> np.ndarray:
    r_max = float(np.max(net.pore_radius)) if net.n_pores else 1.0
    return np.linspace(0.0, PSD_SPAN * r_max, PSD_BINS + 1)


def _write_pores(out: Path, rec: ExchangeRecord, edges: np.ndarray) -> None:
    """``pores/step_NNNN.npz`` (per-pore arrays) and ``pores/psd_NNNN.csv`` of one exchange step."""
    net, f = rec.network, rec.flow
    results.write_npz(out / "pores" / f"step_{rec.step:04d}.npz", {
        "step": np.int64(rec.step), "time_s": np.float64(rec.t),
        "pore_pressure_Pa": np.asarray(f.fluid_pressure, float), "nw_saturation": np.asarray(f.nw_saturation, float),
        "pore_radius_m": net.pore_radius, "pore_volume_m3": net.pore_volume, "pore_coords_m": net.pore_coords})
    r = np.minimum(net.pore_radius, edges[-1])  # larger pores are counted in the last bin
    count, _ = np.histogram(r, bins=edges)
    vol, _ = np.histogram(r, bins=edges, weights=net.pore_volume)
    n = len(count)
    results.write_csv(out / "pores" / f"psd_{rec.step:04d}.csv", {
        "step": [rec.step] * n, "time_s": [rec.t] * n, "radius_lo_m": edges[:-1].tolist(),
        "radius_hi_m": edges[1:].tolist(), "n_pores": count.tolist(), "pore_volume_m3": vol.tolist()})


def _snapshot_due(case: Case, t0: float, t1: float, last: bool) -> bool:
    return last or any(t0 < s <= t1 + 1e-12 for s in case.output.snapshot_times)


def _write_snapshot(out: Path, rec: ExchangeRecord, run: CoupledRun, series: dict) -> None:
    vtk = out / "vtk"
    vtk.mkdir(exist_ok=True)
    mesh = run.problem.mesh
    solid_file = vtk / f"solid_{rec.step:04d}.vtu"
    mesh.write_vtu(solid_file, point_data={
        "displacement": rec.displacement, "von_mises": rec.von_mises, "pore_force": rec.nodal_force})
    net = rec.network
    f = rec.flow
    net_file = vtk / f"network_{rec.step:04d}.vtp"
    write_network_vtp(net, net_file, point_data={
        "pressure": np.nan_to_num(f.fluid_pressure), "nw_saturation": f.nw_saturation,
        "pore_state": f.pore_state.astype(float)})
    series["solid"].add(rec.t, solid_file)
    series["network"].add(rec.t, net_file)


def _figures(out: Path, ts: dict, snapshots: list, run: CoupledRun, title: str) -> list[str]:
    from porefsi import plot

    fig = out / "figures"
    fig.mkdir(exist_ok=True)
    made = [plot.plot_timeseries(ts, fig / "timeseries.png", title=title)]
    made.append(plot.plot_psd([(s["t"], s["radius"]) for s in snapshots], fig / "pore_size_distribution.png"))
    net0 = run.problem.network
    for s in snapshots:
        tag = f"t{s['t']:07.3f}s".replace(".", "_")
        made.append(plot.render_network(s["coords"], s["radius"], net0.throat_conns, 1.0 - s["nw_saturation"],
                                        fig / f"drainage_{tag}.png", label="wetting saturation", clim=(0, 1),
                                        fade_above=0.999))
        # Colour scales stop at the 99th percentile: the extremes sit at a few nodes next to loaded pores.
        mag = np.linalg.norm(s["displacement"], axis=1) * 1e9
        made.append(plot.render_solid(run.problem.mesh.points, run.problem.mesh.tets, mag,
                                      fig / f"displacement_{tag}.png", label="|u| (nm)", cut="y",
                                      clim=(0.0, max(float(np.percentile(mag, 99)), 1e-30))))
        fn = np.linalg.norm(s["force"], axis=1) * 1e9
        made.append(plot.render_solid(run.problem.mesh.points, run.problem.mesh.tets, fn,
                                      fig / f"pore_force_{tag}.png", label="|pore force| (nN)", cmap="inferno",
                                      cut="y", clim=(0.0, max(float(np.percentile(fn[fn > 0], 99)) if np.any(fn > 0)
                                                          else 0.0, 1e-30))))
        vm = s["von_mises"] * 1e-6
        made.append(plot.render_solid(run.problem.mesh.points, run.problem.mesh.tets, vm,
                                      fig / f"von_mises_{tag}.png", label="von Mises (MPa)", cmap="magma", cut="y",
                                      clim=(0.0, max(float(np.percentile(vm, 99)), 1e-30))))
    return [str(p.relative_to(out)) for p in made]


def run_case(case: Case, out: str | Path | None = None, *, resume: bool = False, overwrite: bool = False,
             force: bool = False, progress: bool | None = None, figures: bool | None = None,
             on_record: Callable[[ExchangeRecord], None] | None = None, stop_after: int | None = None,
             reuse_extractions: bool = True) -> RunOutput:
    """Run ``case`` and write its results to ``out`` (default ``case.output.dir``).

    Parameters
    ----------
    case : Case
    out : path, optional
        Run directory.
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
    on_record : callable, optional
        Called with every :class:`~porefsi.coupling.loop.ExchangeRecord` (e.g. by case scripts).
    stop_after : int, optional
        Stop after this many exchange steps of this call (for tests of interrupted runs).
    reuse_extractions : bool, default True
        Re-extraction mode: serve the extraction of a voxel image seen before from a digest cache
        (:class:`~porefsi.coupling.loop.CoupledRun`); False computes every re-extraction, the
        paper's cost, with the same results (for cost studies).

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
    clock = _RunClock(time.perf_counter(), time.process_time())
    out = rundir.check_output_dir(Path(out if out is not None else case.output.dir))
    # 1. read and validate everything; nothing in ``out`` changes before the lock below
    saved = None
    if resume:
        saved = _rd.load_resume(out, case)
        done = _rd.read_completed(out, case, saved[1])
        if done is not None:  # a completed run: nothing to do, nothing to change
            return RunOutput(done[0], out, done[1], note=f"{out} already holds the completed run; nothing to do")
    else:
        _rd.refuse_existing(out, overwrite)
        _rd.check_steps(case, force)
    problem = problem_from_case(case)
    _plausible.warn_injection_pressure(problem.network, case.image.axis, case.drainage.rate, case.fluids.mu_n)
    if not case.image.path and case.image.voxel_size is not None:  # a file's is checked when it is read
        check_voxel_size(case.image.voxel_size, "image.voxel_size")
    state = _restore(problem, out, saved, reuse_extractions) if saved else None
    _rd.check_output_volume(out, case, problem, force or resume)
    # 2. the directory is ours: clear what goes, then run
    with rundir.lock(out), rundir.output_errors(out):
        if saved is None:
            _rd.refuse_existing(out, overwrite)  # again: a run may have finished there meanwhile
            _rd.clear_outputs(out)
        else:
            clock.wall_before = float(saved[1].get("wall_seconds", 0.0))
            clock.cpu_before = float(saved[1].get("process_cpu_seconds", 0.0))
            # the steps after the checkpoint are redone: their files go (they are rewritten)
            _rd.clear_outputs(out, after_step=int(saved[1]["step_index"]))
        results.atomic_write_text(out / "case.toml", case_to_toml(case))
        opts = dict(progress=progress, figures=case.output.figures if figures is None else figures,
                    on_record=on_record, stop_after=stop_after, reuse_extractions=reuse_extractions)
        return _execute(case, out, problem, state, clock, opts)


def _restore(problem, out: Path, saved: tuple[dict, dict], reuse_extractions: bool) -> dict:
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
    return {"run": run, "rows": rows, "snapshots": snapshots, "series": series, "setup": setup}


def _execute(case: Case, out: Path, problem, state: dict | None, clock: _RunClock, opts: dict) -> RunOutput:
    """The loop of :func:`run_case` in a validated, locked, cleared directory."""
    progress, on_record, stop_after = opts["progress"], opts["on_record"], opts["stop_after"]
    ckpt = out / _rd.CHECKPOINT
    run, rows, setup_seconds = None, [], {}
    status, error = "completed", None
    try:
        edges = _psd_edges(problem.network)  # fixed pore-size bins of the whole run
        if state is not None:
            run, rows, snapshots, series = state["run"], state["rows"], state["snapshots"], state["series"]
            for s in series.values():
                s.truncate(run.t)
            setup_seconds, clock.setup_cpu = state["setup"]
        else:
            run = CoupledRun(problem, reuse_extractions=opts["reuse_extractions"])
            snapshots = []
            series = {k: results.PvdSeries(out / f"{k}.pvd") for k in ("solid", "network")}
            setup_seconds = dict(problem.seconds)
            clock.setup_cpu = dict(problem.cpu_seconds)
            rec0 = run.initial_record()
            rows.append(rec0.row)
            _write_pores(out, rec0, edges)
            if case.output.vtk:
                _write_snapshot(out, rec0, run, series)
            snapshots.append(_snapshot(rec0))
        tty = sys.stderr.isatty()
        bar = _Progress(run.n_steps, progress is not False, start=run.step_index, lines=progress is None and not tty)
        n_done = 0
        with interrupt.deferred() as signalled:  # Ctrl-C / SIGTERM: finish the step, save, stop
            for rec in run.steps():
                rows.append(rec.row)
                _write_pores(out, rec, edges)
                t_prev = rows[-2]["time_s"]
                last = run.step_index == run.n_steps
                if _snapshot_due(case, t_prev, rec.t, last):
                    if case.output.vtk:
                        _write_snapshot(out, rec, run, series)
                    snapshots.append(_snapshot(rec))
                results.write_csv(out / "timeseries.csv", _columns(rows))
                if on_record is not None:
                    on_record(rec)
                if run.step_index % case.output.checkpoint_every == 0 or last or signalled():
                    _save(ckpt, run, case, rows, snapshots, setup_seconds, clock)
                bar.update(run.step_index, rec.t, f"Sw={rec.row['sw']:.3f}")
                n_done += 1
                if signalled() and not last:
                    raise KeyboardInterrupt(
                        f"{interrupt.SIGNAL_NAMES.get(signalled(), 'a signal')} at exchange step {run.step_index} of "
                        f"{run.n_steps}; saved to {ckpt}: continue with {_rd.resume_command(out)}")
                if stop_after is not None and n_done >= stop_after:
                    status = "interrupted"
                    break
    except BaseException as exc:
        # Whatever stopped the run (a porefsi error, a solver library's, a bug, Ctrl-C, SIGTERM, a full
        # disk): record it next to the last checkpoint (kept as it was) and the outputs so far, re-raise.
        status = "interrupted" if isinstance(exc, KeyboardInterrupt) else "failed"
        error = f"{type(exc).__name__}: {exc}"
        with contextlib.suppress(Exception):  # never hide the original error behind a write error
            _write_summary(out, case, run, rows, setup_seconds, status, error, [], clock)
        raise
    ts = _columns(rows)
    _plausible.warn_pressure_reached(max((p for p in ts["inlet_pressure_Pa"] if math.isfinite(p)), default=math.nan))
    made = _figures(out, ts, snapshots, run, case.name) if (opts["figures"] and status == "completed") else []
    summary = _write_summary(out, case, run, rows, setup_seconds, status, error, made, clock)
    return RunOutput(summary, out, ts)


def _snapshot(rec: ExchangeRecord) -> dict:
    return {"t": rec.t, "step": rec.step, "coords": rec.network.pore_coords.copy(),
            "radius": rec.network.pore_radius.copy(), "nw_saturation": np.asarray(rec.flow.nw_saturation).copy(),
            "displacement": rec.displacement, "von_mises": rec.von_mises, "force": rec.nodal_force}


_SNAP_KEYS = ("coords", "radius", "nw_saturation", "displacement", "von_mises", "force")


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


def _save(path, run: CoupledRun, case: Case, rows, snapshots, setup_seconds, clock: _RunClock) -> None:
    arrays, meta = run.checkpoint()
    for i, s in enumerate(snapshots):
        for k in _SNAP_KEYS:
            arrays[f"snap{i}_{k}"] = s[k]
    meta.update(case=case_to_dict(case), rows=rows, setup_seconds=setup_seconds,
                snapshots=[{"t": s["t"], "step": s["step"]} for s in snapshots], version=__version__,
                wall_seconds=clock.wall_before + clock.wall_this_process(), setup_cpu_seconds=clock.setup_cpu,
                process_cpu_seconds=clock.cpu_before + clock.cpu_this_process())
    results.save_checkpoint(path, arrays, meta)


def _load_snapshots(arrays, meta) -> list:
    return [{**s, **{k: arrays[f"snap{i}_{k}"] for k in _SNAP_KEYS}} for i, s in enumerate(meta["snapshots"])]


def _columns(rows: list[dict]) -> dict:
    return {k: [r[k] for r in rows] for k in TIMESERIES_COLUMNS}


def _write_summary(out, case, run: CoupledRun | None, rows, setup_seconds, status, error, figures,
                   clock: _RunClock) -> dict:
    this_process = clock.wall_this_process()
    wall_seconds = clock.wall_before + this_process
    cpu_this = clock.cpu_this_process()
    if run is None:  # failed while setting up: what is known
        summary = {"status": status, "error": error, "case": case.name, "porefsi_version": __version__,
                   "wall_seconds": wall_seconds, "wall_seconds_this_process": this_process,
                   "cpu_seconds": clock.cpu_before + cpu_this, "cpu_seconds_this_process": cpu_this,
                   "n_exchange_steps": 0, "figures": figures}
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
        "reextraction": None if case.network.update != "reextract" else {
            "n_computed": run.n_extractions, "n_reused": run.n_extractions_reused,
            "reuse_extractions": run.reuse_extractions,
            "seconds": dict(run.update_seconds), "cpu_seconds": dict(run.update_cpu_seconds)},
        "figures": figures,
        "resume_command": _rd.resume_command(out) if status != "completed" and (out / _rd.CHECKPOINT).is_file()
        else None,
    }
    results.write_json(out / "summary.json", summary)
    return json.loads(json.dumps(results.jsonable(summary)))
