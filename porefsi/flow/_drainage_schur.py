r"""Split pressure solve of the drainage model (private): non-wetting block direct, wetting block AMG-CG.

The pressure matrix couples the non-wetting cluster ``N`` (full pores and the inlet node) to the
wetting region ``W`` only through the active menisci. Algebraic multigrid built once for the
whole network is a poor preconditioner for it (the cluster hangs on the wetting region by a few
meniscus conductances, and a hierarchy built before the cluster existed mixes the two across
the cut: 79-490 CG iterations on a 10k lattice half-way to breakthrough), so the solve is split:

.. math::

    S\,p_W = b_W - A_{WN} A_{NN}^{-1} b_N, \qquad S = A_{WW} - A_{WN} A_{NN}^{-1} A_{NW},
    \qquad p_N = A_{NN}^{-1} (b_N - A_{NW} p_W).

``A_NN`` (a tree-like cluster) is factorised directly; ``A_NW`` has one column per active
meniscus, so ``S`` is ``A_WW`` minus a k x k dense block on the menisci's pores, applied
matrix-free. ``S`` is solved by CG preconditioned with a smoothed-aggregation hierarchy of the
wetting block embedded in the full index set (other rows identity), which the caller keeps and
rebuilds when it goes stale. The answer is the direct solve's to the CG tolerance.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from porefsi.errors import ConvergenceError

__all__ = ["coupled_rows", "wetting_block", "split_solve"]


def coupled_rows(A: sp.csr_array) -> np.ndarray:
    """Mask of rows with a nonzero off-diagonal entry (the others are decoupled, ``d x = b``)."""
    rows = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))
    off = (rows != A.indices) & (A.data != 0)
    out = np.zeros(A.shape[0], dtype=bool)
    out[rows[off]] = True
    return out


def wetting_block(As: sp.csr_array, wmask: np.ndarray) -> sp.csr_array:
    """``As`` restricted to the rows and columns of ``wmask``, identity elsewhere, same pattern."""
    rows = np.repeat(np.arange(As.shape[0]), np.diff(As.indptr))
    keep = wmask[rows] & wmask[As.indices]
    data = np.where(keep, As.data, 0.0)
    data[(rows == As.indices) & ~wmask[rows]] = 1.0
    return sp.csr_array((data, As.indices, As.indptr), shape=As.shape)


def split_solve(As, bs, y0, nmask, ml, rtol: float, maxiter: int):
    """Solve ``As y = bs`` (scaled SPD) with the non-wetting rows ``nmask`` eliminated directly.

    Parameters
    ----------
    As : csr_array, shape (m, m)
        Symmetrically diagonal-scaled pressure matrix.
    bs, y0 : ndarray, shape (m,)
        Scaled right-hand side and initial guess (only its wetting part is used).
    nmask : ndarray of bool, shape (m,)
        Non-wetting rows (full pores, the inlet node).
    ml : pyamg MultilevelSolver
        Hierarchy of :func:`wetting_block` of (a recent) ``As``.
    rtol : float
        CG stops when the reduced residual is below ``rtol * ||bs||``.

    Returns
    -------
    y : ndarray, shape (m,)
    iterations : int
    """
    m = As.shape[0]
    if float(np.linalg.norm(bs)) == 0.0:
        return np.zeros(m), 0
    red = _reduce(As, bs, nmask)
    full = np.zeros(m)

    def prec(r):
        full[:] = 0.0
        full[red.iW] = r
        return ml.solve(full, maxiter=1, cycle="V", tol=1e-30)[red.iW]

    x, it = _pcg(red.op, prec, red.rhs, np.nan_to_num(y0[red.iW]), rtol, float(np.linalg.norm(bs)), maxiter)
    y = red.y
    y[red.iW] = x
    if red.iN.size:
        y[red.iN] = red.luN.solve(bs[red.iN] - red.ANW @ x)
    return y, it


class _Reduced:
    """The Schur complement of the non-wetting block: ``op(v) = (A_WW - A_WN A_NN^-1 A_NW) v`` and its rhs."""

    def __init__(self, **kw):
        self.__dict__.update(kw)

    def op(self, v):
        out = self.AWW @ v
        if self.J.size:
            out[self.J] -= self.T @ v[self.J]
        return out


def _reduce(As, bs, nmask) -> _Reduced:
    """Eliminate the coupled non-wetting rows ``nmask`` of ``As y = bs`` directly (sparse LU)."""
    coupled = coupled_rows(As)
    d = As.diagonal()
    y = np.where(coupled, 0.0, bs / d)  # decoupled rows: d y = b
    iN = np.flatnonzero(nmask & coupled)
    iW = np.flatnonzero(~nmask & coupled)
    Ar = As[iN]
    ANW = Ar[:, iW].tocsc()
    ANW.eliminate_zeros()  # the fixed pattern stores pinned menisci as explicit zeros
    J = np.flatnonzero(np.diff(ANW.indptr))  # wetting columns coupled to the cluster (menisci)
    luN = None
    if iN.size:
        luN = spla.splu(Ar[:, iN].tocsc(), permc_spec="MMD_AT_PLUS_A", options=dict(SymmetricMode=True))
        BJ = ANW[:, J].toarray()
        T = BJ.T @ luN.solve(BJ) if J.size else np.zeros((0, 0))
        yN0 = luN.solve(bs[iN])
        rhs = bs[iW] - ANW.T @ yN0
    else:
        T = np.zeros((0, 0))
        rhs = bs[iW].copy()
    return _Reduced(y=y, iN=iN, iW=iW, ANW=ANW, J=J, luN=luN, T=T, rhs=rhs, AWW=As[iW][:, iW])


def _pcg(op, prec, rhs, x, rtol: float, bn: float, maxiter: int):
    """Preconditioned CG on ``op x = rhs`` from ``x`` until ``||r|| <= rtol bn``; returns (x, iterations).

    Raises
    ------
    ConvergenceError
        Not converged in ``maxiter`` iterations (with the relative residual history).
    """
    tol = rtol * bn
    r = rhs - op(x)
    hist = [float(np.linalg.norm(r))]
    it = 0
    if hist[-1] <= tol:
        return x, it
    z = prec(r)
    p = z.copy()
    rz = float(r @ z)
    while True:
        Ap = op(p)
        alpha = rz / float(p @ Ap)
        x = x + alpha * p
        r = r - alpha * Ap
        it += 1
        hist.append(float(np.linalg.norm(r)))
        if hist[-1] <= tol:
            return x, it
        if it >= maxiter:
            raise ConvergenceError(
                f"split pressure solve did not reach rtol={rtol:g} in {maxiter} CG iterations (last "
                f"{hist[-1] / bn:.3g}); try solver='lowrank'", history=[h / bn for h in hist])
        z = prec(r)
        rz_new = float(r @ z)
        p = z + (rz_new / rz) * p
        rz = rz_new
