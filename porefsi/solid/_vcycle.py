"""The V-cycle of the solid's AMG preconditioner: pointwise Gauss-Seidel on CSR levels, no norms.

pyamg builds the smoothed-aggregation hierarchy (:class:`porefsi.solid.linsolve.AMGSolverFactory`);
this module applies it. pyamg's own cycle (``MultilevelSolver.aspreconditioner``) smooths the
3 x 3 / 6 x 6 block (BSR) levels with its block Gauss-Seidel kernel and computes two fine-level
residual norms per application for its stopping test; measured on the 120³ Berea crop's graded
mesh (40,398 dofs, 3 levels, 2026-12-02): block Gauss-Seidel took ~60 % of a V-cycle, a pointwise
sweep on the same level in CSR form costs about one matrix-vector product, and CG needs the same
number of iterations with it (123 instead of 120 over a coupled run's 17 solves). Here every level
is CSR, the sweeps are pyamg's compiled pointwise kernel, and nothing is computed that the cycle
does not use: a V-cycle costs ~0.65x pyamg's (docs/solid.md section 5).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["VCycle", "relax_candidates", "lumped", "LEVEL_DROP"]


def _csr(A) -> sp.csr_matrix:
    """``A`` as CSR with sorted int32 indices (what pyamg's compiled kernels take)."""
    A = sp.csr_matrix(A, dtype=float)
    A.sort_indices()
    if A.indptr.dtype != np.int32 and A.nnz < 2**31:
        A.indptr, A.indices = A.indptr.astype(np.int32), A.indices.astype(np.int32)
    return A


def _reversed(A: sp.csr_matrix) -> sp.csr_matrix:
    """``A`` with rows and columns numbered from the end (``A[::-1, ::-1]``), built without sorting.

    Reversing the value and column-index arrays reverses the row order and each row's entries;
    the new row pointers are ``nnz - indptr[::-1]``.
    """
    n = A.shape[0]
    indptr = (A.nnz - A.indptr[::-1]).astype(A.indptr.dtype)
    indices = (n - 1 - A.indices[::-1]).astype(A.indices.dtype)
    return sp.csr_matrix((A.data[::-1].copy(), indices, indptr), shape=A.shape)


def relax_candidates(A, B: np.ndarray, sweeps: int = 4) -> np.ndarray:
    """Near-null-space candidates ``B`` (n, k) after ``sweeps`` symmetric Gauss-Seidel sweeps on ``A x = 0``.

    What pyamg's ``improve_candidates`` does on the finest level (its default: 4 symmetric block
    Gauss-Seidel sweeps), with the pointwise CSR sweeps of :class:`VCycle`: measured on the
    Berea crop's graded mesh (40,398 dofs, six rigid-body modes) 0.46 s of a 1.5 s set-up with
    pyamg's block kernel; CG's iteration count is the same within one per coupled run.
    Returns a new array; ``B`` is unchanged.
    """
    from pyamg import amg_core

    A = _csr(A)
    Ar = _reversed(A)
    n = A.shape[0]
    zero = np.zeros(n)
    out = np.array(B, dtype=float, order="F")
    for k in range(out.shape[1]):
        x = np.ascontiguousarray(out[:, k])
        for _ in range(sweeps):
            amg_core.gauss_seidel(A.indptr, A.indices, A.data, x, zero, 0, n, 1)
            xr = x[::-1].copy()
            amg_core.gauss_seidel(Ar.indptr, Ar.indices, Ar.data, xr, zero, 0, n, 1)
            x = xr[::-1].copy()
        out[:, k] = x
    return np.ascontiguousarray(out)


#: Entries of an intermediate level's operator below this fraction of sqrt(a_ii a_jj) are moved to the
#: diagonal (as |a_ij|, so the level stays SPD) before it is smoothed (:func:`lumped`). Measured
#: on the 120³ graded meshes (a coupled run's 17 recorded solves, 2026-12-02): at 1e-3 the second
#: level (6 x 6 blocks, ~300 nonzeros per row: more than the finest level) keeps 47-49 % of its
#: nonzeros, CG needs 124 -> 131 (Berea crop) and 115 -> 116 (sample) iterations, the solves take
#: 0.86x and 0.78x the time; at 1e-2 it keeps 17 % but needs 1.4x the iterations (0.84-0.94x the time).
LEVEL_DROP = 1e-3


def lumped(A, theta: float) -> sp.csr_matrix:
    r"""``A`` (SPD) with its small off-diagonal entries moved to the diagonal, as magnitudes.

    Every off-diagonal :math:`|a_{ij}| < \theta \sqrt{|a_{ii} a_{jj}|}` is dropped and
    :math:`|a_{ij}|` added to :math:`a_{ii}`. The result is :math:`A + (D - E)` with ``E`` the
    dropped (symmetric) part and :math:`D = \mathrm{diag}(\sum_j |e_{ij}|)`; :math:`D - E` is
    symmetric and diagonally dominant, so the result is symmetric and at least as positive
    definite as ``A``.
    """
    A = sp.csr_matrix(A)
    C = A.tocoo()
    d = np.abs(A.diagonal())
    keep = (C.row == C.col) | (np.abs(C.data) >= theta * np.sqrt(d[C.row] * d[C.col]))
    extra = np.bincount(C.row[~keep], weights=np.abs(C.data[~keep]), minlength=A.shape[0])
    out = sp.csr_matrix((C.data[keep], (C.row[keep], C.col[keep])), shape=A.shape)
    return _csr(out + sp.diags(extra))


class VCycle:
    r"""One symmetric V-cycle :math:`z = M r` over a pyamg multilevel hierarchy.

    Down the levels one forward pointwise Gauss-Seidel sweep from zero, restriction
    :math:`R = P^T` of the residual; an exact (LU) solve on the coarsest level; up the levels
    prolongation of the correction and one backward sweep. Forward down and backward up with
    :math:`R = P^T` and an exact coarse solve make :math:`M` symmetric (and positive definite for an
    SPD level hierarchy), as CG needs.

    Parameters
    ----------
    levels : list
        ``MultilevelSolver.levels`` of pyamg: each with ``A`` (n_l, n_l); all but the last with
        ``P`` (n_l, n_{l+1}) (the restriction is ``P.T``). Their ``A``, ``P``, ``R`` are replaced by
        the CSR forms the cycle uses (the same operators), so the hierarchy is held once.
    coarse_solver : callable
        ``coarse_solver(A, b) -> x``, exact on the last level (pyamg's ``MultilevelSolver.coarse_solver``:
        its sparse LU drops the zero rows and columns that aggregates of constrained nodes leave).
    drop : float, default :data:`LEVEL_DROP`
        The intermediate levels (neither the finest nor the coarsest) are smoothed with
        :func:`lumped` forms of their operators (0: exact). The cycle stays symmetric positive
        definite; it approximates the exact cycle a little less well (a few more CG iterations,
        each cheaper).
    """

    def __init__(self, levels, coarse_solver, drop: float = LEVEL_DROP):
        from pyamg import amg_core

        self._gs = amg_core.gauss_seidel
        self.A = [_csr(lv.A) for lv in levels[:-1]] + [levels[-1].A]
        self.P = [_csr(lv.P) for lv in levels[:-1]]
        for lv, A, P in zip(levels[:-1], self.A[:-1], self.P, strict=True):  # the CSR forms, held once
            lv.A, lv.P, lv.R = A, P, P.T
        if drop > 0:  # the intermediate levels only: the finest is the problem's, the coarsest solved exactly
            self.A[1:-1] = [lumped(a, drop) for a in self.A[1:-1]]
        self.A_rev = [_reversed(a) for a in self.A[:-1]]
        self._coarse_A, self._coarse = levels[-1].A, coarse_solver

    @property
    def sizes(self) -> list[int]:
        """Unknowns per level, finest first."""
        return [a.shape[0] for a in self.A]

    def _sweep(self, level: int, x: np.ndarray, b: np.ndarray, forward: bool) -> None:
        """One Gauss-Seidel sweep on ``level`` in place (rows in increasing order if ``forward``).

        The backward sweep runs forward over :func:`_reversed` (rows and unknowns numbered from the
        end): the same arithmetic in the same row order, but streaming through memory forwards,
        where a backward pass over the CSR arrays took 3x a forward one (measured on both levels
        of the Berea crop's graded mesh: 1.5 against 4.5 ms at 40,398 dofs, 1.4 M nonzeros).
        """
        if forward:
            A = self.A[level]
            self._gs(A.indptr, A.indices, A.data, x, b, 0, A.shape[0], 1)
            return
        Ar = self.A_rev[level]
        xr, br = x[::-1].copy(), np.ascontiguousarray(b[::-1])
        self._gs(Ar.indptr, Ar.indices, Ar.data, xr, br, 0, Ar.shape[0], 1)
        x[:] = xr[::-1]

    def __call__(self, b: np.ndarray, level: int = 0) -> np.ndarray:
        """``M b`` on ``level`` (default: the finest): ndarray (n_level,)."""
        b = np.ascontiguousarray(b, dtype=float)
        if level == len(self.A) - 1:
            return np.asarray(self._coarse(self._coarse_A, b), dtype=float)
        A = self.A[level]
        x = np.zeros_like(b)
        self._sweep(level, x, b, True)
        P = self.P[level]
        x += P @ self(P.T @ (b - A @ x), level + 1)  # R = P^T (pyamg's symmetric hierarchy)
        self._sweep(level, x, b, False)
        return x
