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
           "available_memory", "SolverChoice", "choose_linear_solver", "format_bytes"]

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
#: 1.49M dofs (the 200³, 280³ crops and the whole 400³ Berea).
AMG_BYTES_PER_DOF = 2200.0
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
