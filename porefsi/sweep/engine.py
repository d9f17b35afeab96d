"""Run a sweep's members in-process or on dask.distributed, and keep its results on disk.

The output folder ``DIR`` holds ``sweep.json`` (the design: every member's name and whole case),
``sweep.csv`` (one row per member, rewritten atomically whenever a member finishes),
``figures/sweep.png`` and one folder per member (:mod:`porefsi.sweep.member`). Nothing in
``DIR`` changes before the sweep file, every member case and the scheduler have been checked;
the sweep holds ``DIR/.porefsi.lock`` while it runs and each member its own folder's.

Running the same sweep into the same ``DIR`` again continues it: completed members are skipped
(their rows come from their folders), interrupted ones resume from their checkpoints, failed
ones run again. A folder holding another sweep is refused unless ``overwrite``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import sys
import uuid
from pathlib import Path

from porefsi.errors import InputError
from porefsi.io import results, rundir
from porefsi.sweep import table
from porefsi.sweep._progress import SweepProgress
from porefsi.sweep.member import one_line, read_member_file, run_member
from porefsi.sweep.spec import Sweep

__all__ = ["run_sweep", "Cluster", "SweepResult", "DESIGN_FILE", "TABLE_FILE", "FIGURE_FILE", "default_workers"]

DESIGN_FILE = "sweep.json"
TABLE_FILE = "sweep.csv"
FIGURE_FILE = "figures/sweep.png"
#: Seconds to wait for a scheduler given by address or file before giving up.
CONNECT_TIMEOUT = 20
#: Environment of LocalCluster workers: one BLAS / OpenMP / numba thread per worker process.
WORKER_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1",
              "MPLBACKEND": "Agg",
              "PYVISTA_OFF_SCREEN": "true"}


@dataclasses.dataclass(frozen=True)
class SweepResult:
    """What :func:`run_sweep` returns: one record per member and where the files are."""

    directory: Path
    records: list
    n_completed: int
    n_failed: int
    n_skipped: int
    table: Path
    figure: Path | None


@dataclasses.dataclass(frozen=True)
class Cluster:
    """Where a sweep's members run (checked on construction).

    Parameters
    ----------
    serial : bool
        One after the other in this process, without Dask (the reference).
    scheduler, scheduler_file : str, optional
        Address (``tcp://host:8786``) or scheduler file of a running Dask cluster; default a
        LocalCluster of ``n_workers`` processes (default :func:`default_workers`), one thread each.
    n_workers : int, optional
        Worker processes of the LocalCluster.
    retries : int
        Times a member is resubmitted after losing its worker (it resumes from its checkpoint);
        a member that raises is not retried (it is recorded as failed).

    Raises
    ------
    InputError
        Contradictory or out-of-range settings.
    """

    serial: bool = False
    scheduler: str | None = None
    scheduler_file: str | Path | None = None
    n_workers: int | None = None
    retries: int = 2

    def __post_init__(self) -> None:
        if self.retries < 0:
            raise InputError(f"retries must be >= 0, got {self.retries}")
        if self.n_workers is not None and self.n_workers < 1:
            raise InputError(f"workers must be >= 1, got {self.n_workers}")
        if self.serial and (self.remote or self.n_workers):
            raise InputError("--serial runs in this process: drop --scheduler, --scheduler-file and --workers")
        if self.scheduler and self.scheduler_file:
            raise InputError("give --scheduler ADDRESS or --scheduler-file PATH, not both")
        if self.n_workers is not None and self.remote:
            raise InputError("--workers sizes the LocalCluster; an existing cluster has its own workers: "
                             "drop --workers")

    @property
    def remote(self) -> bool:
        """True when the members run on an existing cluster (address or scheduler file)."""
        return bool(self.scheduler or self.scheduler_file)


def default_workers() -> int:
    """Worker processes of the default LocalCluster: the CPUs this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


def run_sweep(sweep: Sweep, out: str | Path, cluster: Cluster | None = None, *, overwrite: bool = False,
              force: bool = False, figures: bool | None = None, progress: bool | None = None) -> SweepResult:
    """Run every member of ``sweep`` into ``out/<member>/``; write ``sweep.csv`` and the figure.

    Parameters
    ----------
    sweep : Sweep
        From :func:`porefsi.sweep.load_sweep`.
    out : path
        The sweep's folder.
    cluster : Cluster, optional
        Where the members run; default ``Cluster()``, a LocalCluster sized to the machine.
    overwrite : bool
        Start every member afresh (also in a folder that holds another sweep).
    force, figures : passed to :func:`porefsi.case.run.run_case` (``figures`` overrides
        ``output.figures`` of the members; the sweep's own figure is drawn unless False).
    progress : bool, optional
        See :class:`porefsi.sweep._progress.SweepProgress`.

    Raises
    ------
    InputError
        ``out`` unusable or holding another sweep (without ``overwrite``), in use by another
        sweep, or the scheduler unreachable; nothing in ``out`` has changed then.
    KeyboardInterrupt
        Ctrl-C / SIGTERM: the running members are stopped (their checkpoints stay); running the
        same command again continues the sweep.
    """
    cluster = Cluster() if cluster is None else cluster
    out = rundir.check_output_dir(out)
    _check_folder(out, sweep, overwrite)
    records = [None if overwrite else _completed_record(out, m) for m in sweep.members]
    skipped = sum(r is not None for r in records)
    tasks = [_task(out, m, overwrite, force, figures) for m, r in zip(sweep.members, records, strict=True)
             if r is None]
    if not tasks and not cluster.remote:  # nothing to run: start no local cluster
        cluster = Cluster(serial=True)
    with _executor(cluster) as client, \
            rundir.lock(out, command=" ".join(["porefsi", *sys.argv[1:]])), rundir.output_errors(out):
        results.write_json(out / DESIGN_FILE, {"format": 1, "source": sweep.source, "mode": sweep.mode,
                                               "keys": list(sweep.keys), "smoke": sweep.smoke,
                                               "members": sweep.design()})
        table.write_table(out / TABLE_FILE, sweep, records)
        bar = SweepProgress(len(sweep.members), skipped, progress)
        try:
            def done(rec: dict) -> None:
                records[rec["index"]] = rec
                table.write_table(out / TABLE_FILE, sweep, records)
                bar.member_done(rec)

            if client is None:
                for t in tasks:
                    done(run_member(t))
            else:
                _run_dask(client, tasks, cluster.retries, done)
        except KeyboardInterrupt as exc:
            raise KeyboardInterrupt(f"{exc or 'stopped'}; every member keeps its last checkpoint: run the same "
                                    "command again to continue the sweep") from None
        finally:
            bar.close()
        fig = table.plot_sweep(out / FIGURE_FILE, sweep, records) if figures is not False else None
    n_ok = sum(r is not None and r["status"] == "completed" for r in records)
    return SweepResult(out, records, n_ok, len(records) - n_ok, skipped, out / TABLE_FILE, fig)


def _task(out: Path, m, overwrite: bool, force: bool, figures: bool | None) -> dict:
    from porefsi.case.config import case_to_dict

    return {"index": m.index, "name": m.name, "values": m.values, "case": case_to_dict(m.case),
            "out": str(out / m.name), "overwrite": overwrite, "force": force, "figures": figures}


def _completed_record(out: Path, m) -> dict | None:
    """The record of a member an earlier run of this sweep completed (None: run it)."""
    folder = out / m.name
    state = read_member_file(folder)
    try:
        summary = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not state or not isinstance(summary, dict) or summary.get("status") != "completed":
        return None
    last = (state.get("attempts") or [{}])[-1]
    return {"index": m.index, "name": m.name, "values": m.values, "status": "completed", "error": None,
            "summary": summary, "attempts": len(state.get("attempts", [])),
            "resumed_from_step": last.get("resumed_from_step"), "worker": last.get("worker"),
            "note": "completed by an earlier run of the sweep"}


def _check_folder(out: Path, sweep: Sweep, overwrite: bool) -> None:
    """Refuse a folder that holds another sweep, or files that are not a sweep's (reads only)."""
    if overwrite or not out.is_dir():
        return
    design = out / DESIGN_FILE
    if design.is_file():
        try:
            saved = json.loads(design.read_text(encoding="utf-8"))
            members = saved["members"]
        except (OSError, ValueError, KeyError, TypeError):
            raise InputError(f"{design} is damaged; pass --overwrite to run the sweep afresh in {out}, or "
                             "another -o DIR") from None
        if members != json.loads(json.dumps(results.jsonable(sweep.design()))):
            raise InputError(f"output folder {out} holds another sweep (its members or their cases differ); pass "
                             "another -o DIR, or --overwrite to run this sweep there afresh")
        return
    if any(out.iterdir()):
        raise InputError(f"output folder {out} is not empty and holds no porefsi sweep ({DESIGN_FILE}); pass a new "
                         "or empty -o DIR, or --overwrite to write the sweep there anyway")


@contextlib.contextmanager
def _executor(cluster: Cluster):
    """A dask Client (LocalCluster, address or scheduler file) for the block, or None (serial)."""
    if cluster.serial:
        yield None
        return
    from distributed import Client, LocalCluster

    if cluster.remote:
        with _connect(Client, cluster.scheduler, cluster.scheduler_file) as client:
            yield client
        return
    with LocalCluster(n_workers=cluster.n_workers or default_workers(), threads_per_worker=1, processes=True,
                      dashboard_address=None, env=WORKER_ENV) as cluster, Client(cluster) as client:
        yield client


def _connect(Client, scheduler, scheduler_file):
    what = f"scheduler {scheduler}" if scheduler else f"scheduler file {scheduler_file}"
    if scheduler_file and not Path(scheduler_file).is_file():
        raise InputError(f"scheduler file {scheduler_file} not found; start one with `dask scheduler "
                         f"--scheduler-file {scheduler_file}`, or pass --scheduler ADDRESS")
    try:
        if scheduler:
            return Client(scheduler, timeout=CONNECT_TIMEOUT)
        return Client(scheduler_file=str(scheduler_file), timeout=CONNECT_TIMEOUT)
    except (OSError, TimeoutError, ValueError) as exc:
        raise InputError(f"cannot reach the Dask {what} ({one_line(exc)}); start it (`dask scheduler`, then "
                         "`dask worker ADDRESS`), or run without --scheduler for a local cluster") from None


def _run_dask(client, tasks: list[dict], retries: int, done) -> None:
    """Submit every task; hand each record to ``done`` as it arrives; resubmit after a lost worker.

    A member that raises inside :func:`run_member` returns a failed record (never an exception),
    so an exception here means the member's worker died (``KilledWorker``) or vanished: the task
    is submitted again (``retries`` times), and resumes from the member's last checkpoint.
    """
    from distributed import as_completed

    tag = uuid.uuid4().hex[:8]
    by_future, lost = {}, {}

    def submit(t: dict):
        fut = client.submit(run_member, t, key=f"porefsi-member-{t['name']}-{tag}-{lost.get(t['index'], 0)}",
                            pure=False, retries=0)
        by_future[fut.key] = t
        return fut

    ac = as_completed([submit(t) for t in tasks])
    try:
        for fut in ac:
            t = by_future[fut.key]
            try:
                rec = fut.result()
            except Exception as exc:  # noqa: BLE001  (the worker was lost, not the member's own failure)
                lost[t["index"]] = lost.get(t["index"], 0) + 1
                if lost[t["index"]] <= retries:
                    ac.add(submit(t))
                    continue
                rec = {"index": t["index"], "name": t["name"], "values": t["values"], "status": "failed",
                       "error": f"worker lost {lost[t['index']]} times ({one_line(exc)}); run the sweep again to "
                       "resume it from its checkpoint", "summary": None, "attempts": None,
                       "resumed_from_step": None, "worker": None, "note": ""}
            fut.release()
            done(rec)
    except BaseException:
        for f in list(ac.futures):
            with contextlib.suppress(Exception):
                f.cancel()
        raise
