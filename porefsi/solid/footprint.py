"""Memory of the solid's linear solvers, estimated before they allocate, and the choice between them.

A sparse LU of the P1 elasticity tangent fills in far faster than the matrix grows: on centred
crops of the 400³ Berea at coarsen 5 (SuperLU, minimum degree on AᵀA + A) the factor held
3.3e6, 9.2e6, 2.5e7, 5.4e7 nonzeros at 11k, 22k, 39k, 63k free dofs, about
``n ** 1.7``; extrapolated to the whole image's 1.5e6 dofs that is ~1e10 nonzeros, 100+ GiB,
and hours of factorisation (the reported 400³ run that grew to 20.8 GB before it was
stopped). The smoothed-aggregation hierarchy of AMG-CG grows linearly with the dofs.

:func:`choose_linear_solver` turns the requested ``solid.linear_solver`` into the one used:
``"direct"`` stays direct up to :data:`DIRECT_MAX_DOFS` free dofs and while its factor fits in
the memory budget, otherwise AMG-CG (``"amg"``), the reason returned as one line.
"""

from __future__ import annotations

import dataclasses
import os
import resource

__all__ = ["DIRECT_MAX_DOFS", "MEMORY_FLOOR", "lu_factor_bytes", "amg_bytes", "tangent_bytes", "memory_budget",
           "available_memory", "SolverChoice", "choose_linear_solver", "format_bytes", "lu_factor_flops",
           "amg_iteration_work", "LU_SECONDS_PER_FLOP", "AMG_SECONDS_PER_WORK", "lu_solve_flops", "SolverCosts",
           "predict_solver_costs", "LU_SOLVE_SECONDS_PER_FLOP", "AMG_OPERATOR_COMPLEXITY", "AMG_SETUP_WORK_PER_NNZ"]

#: Fill of the LU, nonzeros of L + U = LU_FILL_COEF * n ** LU_FILL_EXP (n free dofs), fitted to the
#: crops in the module docstring (within 10 % of each; the exponent still grows with n, so this
#: under-estimates the very large systems it is used to refuse).
LU_FILL_COEF = 0.34
LU_FILL_EXP = 1.71
#: Bytes per nonzero of the factor (value, row index, SuperLU's supernode work arrays), measured.
LU_BYTES_PER_NNZ = 16.0
#: Nonzeros of the P1 tangent per free dof (measured 33.5-35.8 on the Berea crops).
TANGENT_NNZ_PER_DOF = 36.0
#: AMG-CG bytes per free dof: the free-dof tangent, the padded BSR copy of it, the hierarchy
#: (operator complexity 2.3-2.4 with six near-null-space vectors), CG's vectors. Measured as the
#: rise of the run's peak over what mesh and model hold: 2,170, 2,060, 2,190 B/dof at 185k, 509k,
#: 1.49M dofs (the 200³, 280³ crops and the whole 400³ Berea), with pyamg's own V-cycle; plus
#: 1,150 B/dof since 2026-12-02 for porefsi's V-cycle (porefsi.solid._vcycle: the levels in CSR
#: instead of BSR and a row-reversed copy of each for the backward sweep, counted as the
#: hierarchy's array bytes on the 120³ Berea crop's graded mesh, 1,288 -> 2,439 B/dof; not yet
#: re-measured as a run's peak).
AMG_BYTES_PER_DOF = 3350.0
#: Estimates below this change no choice and refuse no run: the estimate's error and the swings of
#: the machine's available memory are of their size, and a run this small cannot take a machine down.
MEMORY_FLOOR = float(2**30)
#: "direct" switches to AMG-CG above this many free dofs: the factorisation then costs more than
#: the AMG-CG solves of a whole 20-step run (measured: docs/benchmarks.md, "The coupled run at 400³").
DIRECT_MAX_DOFS = 100_000


def lu_factor_bytes(n_dofs: int) -> float:
    """Estimated peak bytes of a sparse LU of an ``n_dofs`` P1 elasticity tangent (factor + matrix copy)."""
    n = max(int(n_dofs), 1)
    return LU_BYTES_PER_NNZ * LU_FILL_COEF * n**LU_FILL_EXP + tangent_bytes(n)


def tangent_bytes(n_dofs: int) -> float:
    """Bytes of one CSR tangent on ``n_dofs`` free dofs (values + column indices)."""
    return 12.0 * TANGENT_NNZ_PER_DOF * max(int(n_dofs), 1)


def amg_bytes(n_dofs: int) -> float:
    """Estimated peak bytes of an AMG-CG set-up and solve on ``n_dofs`` free dofs."""
    return AMG_BYTES_PER_DOF * max(int(n_dofs), 1)


def memory_budget() -> float | None:
    """Bytes a new allocation can have: the machine's available memory, and the address-space limit.

    ``ulimit -v`` (RLIMIT_AS) caps the virtual size of the process: what is left under it is
    the limit less the current virtual size. None if neither is known.
    """
    avail = available_memory()
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft != resource.RLIM_INFINITY:
        left = soft - _vm_size()
        avail = left if avail is None else min(avail, left)
    return None if avail is None else float(max(avail, 0))


def _proc_kib(path: str, key: str) -> int | None:
    """The ``key:`` entry (kB) of a /proc file, in bytes; None where there is none (not Linux)."""
    try:
        with open(path, encoding="ascii") as fh:
            for line in fh:
                if line.startswith(key + ":"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def available_memory() -> int | None:
    """Bytes the machine can give a new allocation (``MemAvailable``), or None if unknown."""
    avail = _proc_kib("/proc/meminfo", "MemAvailable")
    if avail is None:
        try:
            avail = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        except (ValueError, OSError, AttributeError):
            return None
    return avail


def _vm_size() -> int:
    return _proc_kib(f"/proc/{os.getpid()}/status", "VmSize") or 0


def format_bytes(n: float) -> str:
    """``n`` bytes as a short text ('782 MiB', '1.5 GiB')."""
    for unit in ("bytes", "KiB", "MiB", "GiB", "TiB"):
        if abs(n) < 1024 or unit == "TiB":
            return f"{n:.3g} {unit}" if unit != "bytes" else f"{int(n)} bytes"
        n /= 1024
    return f"{n:.3g} TiB"  # pragma: no cover


@dataclasses.dataclass(frozen=True)
class SolverChoice:
    """The linear solver a model gets: ``kind`` ("direct", "amg", "jacobi", "auto") and why (``reason``, or "")."""

    kind: str
    reason: str = ""


def choose_linear_solver(requested: str, n_dofs: int, budget: float | None = None, *,
                         direct_max_dofs: int | None = None) -> SolverChoice:
    """The solver used for a request of ``requested`` on ``n_dofs`` free dofs.

    Parameters
    ----------
    requested : {"direct", "amg", "jacobi", "auto"}
        ``solid.linear_solver``.
    n_dofs : int
        Free dofs of the model.
    budget : float, optional
        Bytes available (default :func:`memory_budget`).
    direct_max_dofs : int, optional
        Largest system "direct" factorises (default :data:`DIRECT_MAX_DOFS`).

    Returns
    -------
    SolverChoice
        ``requested`` unchanged, except "direct" above ``direct_max_dofs`` dofs or with a
        factor larger than half the budget (and than :data:`MEMORY_FLOOR`): "amg", with the reason.
    """
    if requested != "direct":
        return SolverChoice(requested)
    direct_max_dofs = DIRECT_MAX_DOFS if direct_max_dofs is None else int(direct_max_dofs)
    need = lu_factor_bytes(n_dofs)
    budget = memory_budget() if budget is None else budget
    too_big = n_dofs > direct_max_dofs
    no_room = budget is not None and need > max(0.5 * budget, MEMORY_FLOOR)
    if not (too_big or no_room):
        return SolverChoice("direct")
    why = (f"above {direct_max_dofs:,} dofs a factorisation costs more time than AMG-CG's solves"
           if too_big else f"only {format_bytes(budget)} is available")
    return SolverChoice("amg", f"solid.linear_solver = 'direct' on {n_dofs:,} free dofs would need a sparse LU of "
                               f"~{format_bytes(need)} ({why}); using 'amg' (AMG-preconditioned CG, "
                               f"~{format_bytes(amg_bytes(n_dofs))}) instead")


#: Seconds per multiply-add of SuperLU's factorisation (the sum of squared column counts of L), measured
#: on the 120³ crops' P1 tangents at 23k-37k dofs on one shared core (2026-12-02): 0.29-0.36 ns.
LU_SECONDS_PER_FLOP = 0.33e-9
#: Seconds per unit of :func:`amg_iteration_work` of one AMG-CG iteration, measured on the same
#: meshes (15.4 ms per iteration at 10.7 M units on the Berea crop's graded mesh): 1.4 ns.
AMG_SECONDS_PER_WORK = 1.4e-9


#: Seconds per multiply-add of a forward and back substitution with the factor, measured with
#: :func:`lu_solve_flops` on the 120³ crops' uniform-6 and graded meshes (8k-37k dofs, one shared core,
#: 2026-12-02): 1.1-2.0 ns, 1.4 typical.
LU_SOLVE_SECONDS_PER_FLOP = 1.4e-9
#: Nonzeros of a smoothed-aggregation hierarchy (all levels) per nonzero of the matrix: measured 2.16-2.50.
AMG_OPERATOR_COMPLEXITY = 2.35
#: Work units (:data:`AMG_SECONDS_PER_WORK`) of an AMG set-up per nonzero of the matrix: measured
#: 0.25-0.55 us per nonzero on the same meshes (0.45 typical).
AMG_SETUP_WORK_PER_NNZ = 320.0


@dataclasses.dataclass(frozen=True)
class SolverCosts:
    """Predicted seconds of the two ways of solving with one matrix (counted, not timed).

    Attributes
    ----------
    factor_s, lu_solve_s : float
        One sparse LU factorisation; one substitution with it.
    amg_setup_s, amg_iteration_s : float
        One AMG hierarchy build; one AMG-CG iteration.
    """

    factor_s: float
    lu_solve_s: float
    amg_setup_s: float
    amg_iteration_s: float

    def direct_s(self, solves: float) -> float:
        """Factorise, then ``solves`` substitutions."""
        return self.factor_s + solves * self.lu_solve_s

    def amg_s(self, solves: float, iterations_per_solve: float, setup: bool = True) -> float:
        """(Build a hierarchy, then) ``solves`` AMG-CG solves of ``iterations_per_solve`` iterations."""
        return (self.amg_setup_s if setup else 0.0) + solves * iterations_per_solve * self.amg_iteration_s


def predict_solver_costs(A, free, level_nnz=None) -> SolverCosts:
    """Predicted :class:`SolverCosts` of the free-dof matrix ``A`` (n, n) with dofs ``free`` (n,).

    The LU side from the node-level analysis (:func:`lu_factor_flops`, :func:`lu_solve_flops`; costs
    1/15-1/20 of the factorisation), the AMG side from the nonzeros of ``level_nnz`` (a hierarchy
    already built) or of :data:`AMG_OPERATOR_COMPLEXITY` times ``A``'s.
    """
    import numpy as np

    counts = _node_column_counts(A, free)
    levels = [AMG_OPERATOR_COMPLEXITY * A.nnz] if level_nnz is None else list(level_nnz)
    return SolverCosts(factor_s=LU_SECONDS_PER_FLOP * 27.0 * float(np.sum(counts**2)),
                       lu_solve_s=LU_SOLVE_SECONDS_PER_FLOP * 18.0 * float(np.sum(counts)),
                       amg_setup_s=AMG_SECONDS_PER_WORK * AMG_SETUP_WORK_PER_NNZ * A.nnz,
                       amg_iteration_s=AMG_SECONDS_PER_WORK * amg_iteration_work(levels, A.nnz))


def lu_factor_flops(A, free) -> float:
    """Predicted multiply-adds of a sparse LU (minimum degree on AᵀA + A) of the elasticity matrix ``A``.

    A node-level analysis instead of a factorisation: the graph of ``A``'s nodes (each ``free``
    dof belongs to node ``free // 3``: three interleaved components) is factorised as a scalar
    SPD matrix with the same ordering method, and the sum of its squared column counts times 27
    (three dofs per node in each of row, column, pivot) estimates the elasticity factor's work.
    Measured against SuperLU's own factor of the 120³ crops' tangents (23k-37k dofs): 0.74-1.35x
    the true sum, the right order between meshes whose fill per dof differs by 1.5x (the Berea
    crop's graded mesh 699, the sample's 471), in 1/15-1/20 of the factorisation's time.

    Parameters
    ----------
    A : sparse matrix, shape (n, n)
        Free-dof SPD matrix.
    free : ndarray of int, shape (n,)
        Full (interleaved, 3 per node) dof index of each row.
    """
    import numpy as np

    return 27.0 * float(np.sum(_node_column_counts(A, free) ** 2))


def lu_solve_flops(A, free) -> float:
    """Predicted multiply-adds of one forward and back substitution with that factor.

    ``2 x 9 x`` the nonzeros of the node-level factor of :func:`lu_factor_flops` (3 x 3 per node pair).
    """
    import numpy as np

    return 18.0 * float(np.sum(_node_column_counts(A, free)))


def _node_column_counts(A, free):
    """Column counts (m,) of the factor of ``A``'s node graph (minimum degree on AᵀA + A, as the real LU).

    The graph is read from one row per node (its first free dof: every free dof of a node couples to
    the same neighbouring nodes) and factorised in single precision (the structure is all that is
    used): 0.21 instead of 0.33 s on the Berea crop's graded mesh (37,379 dofs), the same counts.
    """
    import numpy as np
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    A = sp.csr_matrix(A)
    free = np.asarray(free)
    if len(free) == 0:
        return np.zeros(0)
    node = free // 3
    first = np.flatnonzero(np.r_[True, node[1:] != node[:-1]])  # free is sorted: a node's dofs are adjacent
    nid = np.cumsum(np.r_[0, node[1:] != node[:-1]])  # node number of each free dof
    R = A[first]
    m = len(first)
    G = sp.csr_matrix((np.full(R.nnz, -1.0, dtype=np.float32), nid[R.indices], R.indptr), shape=(m, m))
    G.sum_duplicates()
    G.data[:] = -1.0
    G = G + sp.diags(np.asarray(-G.sum(axis=1)).ravel() + 2.0).astype(np.float32)  # a diagonally dominant SPD stand-in
    lu = spla.splu(sp.csc_matrix(G, dtype=np.float32), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                   options={"SymmetricMode": True})
    return np.diff(lu.L.indptr).astype(float)


def amg_iteration_work(level_nnz, matrix_nnz: int) -> float:
    """Work units of one AMG-CG iteration: two sweeps and a residual per level, and CG's product.

    ``level_nnz``: nonzeros of each level's matrix of the hierarchy; ``matrix_nnz``: of the
    free-dof matrix CG multiplies by.
    """
    return 3.0 * float(sum(level_nnz)) + float(matrix_nnz)
