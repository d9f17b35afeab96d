"""Sweeps: many cases from one base case and the keys to vary, run on dask.distributed.

``porefsi sweep SWEEP.toml -o DIR`` (:mod:`porefsi.cli._sweep`) and, from Python::

    from porefsi.sweep import Cluster, load_sweep, run_sweep
    res = run_sweep(load_sweep("sweep.toml"), "out")          # a LocalCluster sized to the machine
    res = run_sweep(load_sweep("sweep.toml"), "out", Cluster(serial=True))  # in this process, no Dask

Layering: ``case -> sweep -> cli`` (the sweep calls :func:`porefsi.case.run.run_case` once per
member; nothing below imports it). Dask is imported only when a sweep runs on it.
See ``docs/sweeps.md``.
"""

from porefsi.sweep.engine import Cluster, SweepResult, run_sweep
from porefsi.sweep.member import run_member
from porefsi.sweep.spec import Member, PlotSpec, Sweep, load_sweep, member_name, sweep_from_dict

__all__ = ["Cluster", "Sweep", "Member", "PlotSpec", "SweepResult", "load_sweep", "sweep_from_dict", "member_name",
           "run_sweep", "run_member"]
