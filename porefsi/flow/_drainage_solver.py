"""Pressure solves of the drainage model (private): a grounded weighted graph Laplacian, SPD.

Small systems use a sparse LU (``splu``; a fresh factorisation costs well under a millisecond
at a few hundred unknowns). Large systems use preconditioned conjugate gradients on the
symmetrically diagonal-scaled matrix ``D^-1/2 A D^-1/2`` with a pyamg smoothed-aggregation
hierarchy that is built once and *reused* across events (the matrix changes by a few
conductances per event, so a stale hierarchy stays a good SPD preconditioner), rebuilt only when
the iteration count grows, and warm-started from the previous pressure field.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from porefsi.errors import ConvergenceError

__all__ = ["PressureSolver"]


class PressureSolver:
    """Solve ``A x = b`` for a sequence of SPD matrices sharing one sparsity pattern.

    Parameters
    ----------
    n : int
        Number of unknowns.
    method : {'auto', 'direct', 'amg', 'jacobi'}
        'auto' picks 'direct' up to ``direct_max`` unknowns, else 'amg'.
    rtol : float
        Relative residual target of the iterative solves, in the scaled norm.
    maxiter : int
        Iteration cap; exceeding it raises :class:`ConvergenceError` with the residual history.
    """

    def __init__(self, n: int, method: str = "auto", rtol: float = 1e-11, maxiter: int = 2000,
                 direct_max: int = 5000, rebuild_iters: int = 25):
        if method == "auto":
            method = "direct" if n <= direct_max else "amg"
        if method not in ("direct", "amg", "jacobi"):
            raise ValueError(f"unknown solver method {method!r}")
        self.method = method
        self.rtol = rtol
        self.maxiter = maxiter
        self.rebuild_iters = rebuild_iters
        self._ml = None
        self.n_solves = 0
        self.n_setups = 0
        self.iterations = 0

    def solve(self, A: sp.csr_array, b: np.ndarray, x0: np.ndarray | None = None) -> np.ndarray:
        """Return x with ``A x = b`` (A symmetric positive definite, CSR)."""
        self.n_solves += 1
        d = A.diagonal()
        s = 1.0 / np.sqrt(d)
        As = sp.csr_array((A.data * s[_rows(A)] * s[A.indices], A.indices, A.indptr), shape=A.shape)
        bs = b * s
        if self.method == "direct":
            y = spla.splu(As.tocsc(), permc_spec="MMD_AT_PLUS_A").solve(bs)
            return y * s
        y0 = np.zeros_like(b) if x0 is None else np.nan_to_num(x0 / s)
        if self.method == "amg":
            if self._ml is None:
                self._setup(As)
            y, hist = _pcg(As, bs, y0, self._ml, self.rtol, self.maxiter)
            if len(hist) - 1 > self.rebuild_iters:  # stale hierarchy: rebuild for next time
                self._ml = None
        else:
            y, hist = _pcg(As, bs, y0, None, self.rtol, self.maxiter)
        self.iterations += len(hist) - 1
        return y * s

    def _setup(self, As):
        import pyamg

        self.n_setups += 1
        self._ml = pyamg.smoothed_aggregation_solver(As, max_coarse=500)


def _rows(A):
    return np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))


def _pcg(A, b, x, ml, rtol, maxiter):
    """Preconditioned CG (preconditioner: one V-cycle of ``ml``, or identity on the scaled system)."""
    r = b - A @ x
    bn = float(np.linalg.norm(b))
    if bn == 0.0:
        return np.zeros_like(b), [0.0]
    hist = [float(np.linalg.norm(r)) / bn]
    if hist[0] <= rtol:
        return x, hist
    z = ml.solve(r, maxiter=1, cycle="V", tol=1e-30) if ml is not None else r.copy()
    p = z.copy()
    rz = float(r @ z)
    for _ in range(maxiter):
        Ap = A @ p
        alpha = rz / float(p @ Ap)
        x = x + alpha * p
        r = r - alpha * Ap
        hist.append(float(np.linalg.norm(r)) / bn)
        if hist[-1] <= rtol:
            return x, hist
        z = ml.solve(r, maxiter=1, cycle="V", tol=1e-30) if ml is not None else r.copy()
        rz_new = float(r @ z)
        p = z + (rz_new / rz) * p
        rz = rz_new
    raise ConvergenceError(
        f"pressure solve did not reach rtol={rtol:g} in {maxiter} CG iterations (last {hist[-1]:.3g}); "
        "the network may have nearly disconnected parts: try solver='direct'", history=hist)
