"""Base columns of the ``'lowrank'`` pressure solver (private): batched triangular solves and their use.

Split from :mod:`porefsi.flow._drainage_solver` (one concept: the cached columns ``A0^-1 e_v``
of the low-rank base -- computed in batches, on a second thread for large ones -- and the
Woodbury correction that combines them).
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import scipy.linalg as sla

__all__ = ["solve_columns", "woodbury", "pool_", "POOL", "SPLIT_COLUMNS"]


def solve_columns(base, nodes):
    """Append ``A0^-1 e_v`` for ``nodes`` (none cached yet) to the base's cache: one batched solve.

    A batch of at least :data:`SPLIT_COLUMNS` is split in two halves, solved on two threads when
    there are two CPUs (SuperLU releases the GIL: 1.5x on two cores), one after the other
    otherwise. The split depends on the batch alone, so the columns, hence every answer, are the
    same with one CPU or two and in a resumed run.
    """
    k = base["ncols"]
    E = np.zeros((base["WT"].shape[1], nodes.size))
    E[nodes, np.arange(nodes.size)] = 1.0
    lu = base["lu"]
    if nodes.size >= SPLIT_COLUMNS:  # split the same way with one CPU: the same columns everywhere
        h = nodes.size // 2
        pool = pool_()
        second = pool.submit(lu.solve, E[:, h:]) if pool is not None else None
        base["WT"][k:k + h] = lu.solve(E[:, :h]).T
        base["WT"][k + h:k + nodes.size] = (second.result() if second is not None else lu.solve(E[:, h:])).T
    else:
        base["WT"][k:k + nodes.size] = lu.solve(E).T
    base["col_of"][nodes] = np.arange(k, k + nodes.size)
    base["ncols"] = k + nodes.size
    base["batches"].append(nodes.copy())


#: Batches of base columns at least this large are solved on two threads.
SPLIT_COLUMNS = 8
POOL: dict = {}  # process id -> executor (a forked child must not use its parent's dead worker)


def pool_():
    """A one-worker thread pool for the second half of large column batches (None on one CPU)."""
    pid = os.getpid()
    if pid not in POOL:
        n_cpu = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
        POOL.clear()
        POOL[pid] = ThreadPoolExecutor(1, thread_name_prefix="porefsi-columns") if n_cpu >= 2 else None
    return POOL[pid]


def woodbury(upd, y):
    """``y - W D M^-1 y_S`` for ``y = A0^-1 b`` (``W`` stored transposed as cached rows ``WT``)."""
    lu_m, S, cS, D, WT = upd
    if lu_m is None:
        return y
    z = sla.lu_solve(lu_m, y[S], check_finite=False)
    coef = np.zeros(WT.shape[0])  # the correction as a combination of all cached rows: no copy of
    coef[cS] = D @ z  # the |S| rows it needs (at 64k unknowns, 500 rows: a 256 MB copy per call)
    return y - coef @ WT
