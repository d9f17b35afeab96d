r"""Block-preconditioned MINRES for the symmetric Stokes saddle-point system of :mod:`._grid`.

The preconditioner is block diagonal, :math:`\operatorname{diag}(\hat A^{-1}, \hat S^{-1})`, both
blocks symmetric positive definite (MINRES needs that):

* :math:`\hat A^{-1}`: one symmetric Gauss-Seidel sweep (default) or one algebraic-multigrid
  V-cycle (pyamg smoothed aggregation, symmetric smoothing) on each of the three scalar Laplacians
  :math:`A_x, A_y, A_z`. The no-slip walls keep these well conditioned in porous media: the sweep
  needed no more MINRES iterations than the V-cycle on rock and costs a fraction of it;
* :math:`\hat S^{-1}`: one V-cycle on :math:`B D^{-1} B^T`, :math:`D = \operatorname{diag}(A)`, the
  pressure Laplacian SIMPLE-type methods use for the Schur complement :math:`S = B A^{-1} B^T`.
  A scaled pressure mass matrix (the textbook choice for Stokes) misses the Darcy-like behaviour
  of :math:`S` on pressure modes smoother than the pores and needs many more iterations on
  porous media (measured in ``docs/stokes.md``).
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import pyamg
import scipy.sparse as sp
from pyamg.relaxation.relaxation import gauss_seidel

from porefsi.stokes._grid import StaggeredSystem

__all__ = ["SolveInfo", "solve"]


@dataclasses.dataclass(frozen=True, eq=False)
class SolveInfo:
    r"""How the linear solve went.

    Attributes
    ----------
    iterations : int
        MINRES iterations.
    residual : float
        Final true relative residual :math:`\|b - Kx\| / \|b\|`.
    converged : bool
        Whether MINRES reached ``rtol``.
    seconds_setup, seconds_solve : float
        Wall time of the preconditioner set-up and of the iterations.
    history : ndarray of float
        Relative preconditioned residual norm after each iteration.
    memory_bytes : int
        Estimated working memory: matrices, preconditioner hierarchies, Krylov vectors.
    """

    iterations: int
    residual: float
    converged: bool
    seconds_setup: float
    seconds_solve: float
    history: np.ndarray
    memory_bytes: int


def _amg(M: sp.csr_matrix):
    """Smoothed-aggregation AMG hierarchy with symmetric Gauss-Seidel smoothing (a symmetric V-cycle)."""
    return pyamg.smoothed_aggregation_solver(
        M.tocsr(), symmetry="symmetric", max_coarse=500,
        presmoother=("gauss_seidel", {"sweep": "symmetric"}),
        postsmoother=("gauss_seidel", {"sweep": "symmetric"}),
    )


class _SymmetricGaussSeidel:
    """One symmetric Gauss-Seidel sweep from zero: :math:`(D+L)^{-1} D (D+U)^{-1}`, SPD for SPD A."""

    def __init__(self, A: sp.csr_matrix):
        self.A = A.tocsr()

    def matvec(self, r: np.ndarray) -> np.ndarray:
        x = np.zeros_like(r)
        gauss_seidel(self.A, x, r, iterations=1, sweep="symmetric")
        return x

    @property
    def nbytes(self) -> int:
        return 0  # works on the matrix itself


def schur_approximation(system: StaggeredSystem) -> sp.csr_matrix:
    r""":math:`B D^{-1} B^T`, :math:`D = \operatorname{diag}(A)`: the SIMPLE pressure Laplacian."""
    d = 1.0 / np.concatenate([blk.diagonal() for blk in system.blocks])
    return (system.B @ sp.diags(d) @ system.B.T).tocsr()


def _nbytes(M) -> int:
    M = M.tocsr() if not sp.isspmatrix_csr(M) else M
    return int(M.data.nbytes + M.indices.nbytes + M.indptr.nbytes)


def _hierarchy_nbytes(ml) -> int:
    """Bytes of an AMG hierarchy's matrices (every level's A, P, R)."""
    return sum(_nbytes(getattr(lev, name)) for lev in ml.levels for name in ("A", "P", "R")
               if sp.issparse(getattr(lev, name, None)))


#: Vectors of the system's length that :func:`minres` and :func:`solve` keep alive at once.
N_VECTORS = 12


def solve(system: StaggeredSystem, *, rtol: float = 1e-6, maxiter: int = 3000, velocity_preconditioner: str = "sgs"):
    r"""Solve the Stokes system; return ``(u, p, SolveInfo)`` (voxel units).

    Parameters
    ----------
    system : StaggeredSystem
    rtol : float
        Relative reduction of the preconditioned residual norm at which to stop.
    maxiter : int
        Iteration limit (``SolveInfo.converged`` is False when it is reached).
    velocity_preconditioner : {'sgs', 'amg'}
        :math:`\hat A^{-1}` per velocity block: one symmetric Gauss-Seidel sweep (default: the
        walls keep these Laplacians well conditioned in porous media; measured faster overall), or
        one smoothed-aggregation AMG V-cycle (for open geometries).
    """
    t0 = time.perf_counter()
    n_u, n_p = system.n_u, system.n_p
    off = system.offsets
    if velocity_preconditioner == "amg":
        mls = [_amg(blk) for blk in system.blocks]
        precs = [ml.aspreconditioner(cycle="V") for ml in mls]
        mem = sum(_hierarchy_nbytes(ml) for ml in mls)
    else:
        precs = [_SymmetricGaussSeidel(blk) for blk in system.blocks]
        mem = sum(_nbytes(blk) for blk in system.blocks)
    S = schur_approximation(system)
    S = S + sp.diags(1e-12 * S.diagonal())  # periodic or closed clusters: keep the V-cycle definite
    ml_s = _amg(S)
    del S
    prec_s = ml_s.aspreconditioner(cycle="V")
    B = system.B
    BT = B.T.tocsr()
    mem += _hierarchy_nbytes(ml_s) + 2 * _nbytes(B) + N_VECTORS * 8 * (n_u + n_p)

    def matvec(x):
        u, p = x[:n_u], x[n_u:]
        out = np.empty_like(x)
        for d in range(3):
            out[off[d]:off[d + 1]] = system.blocks[d] @ u[off[d]:off[d + 1]]
        out[:n_u] -= BT @ p
        out[n_u:] = -(B @ u)
        return out

    def precvec(x):
        out = np.empty_like(x)
        for d in range(3):
            if off[d + 1] > off[d]:
                out[off[d]:off[d + 1]] = precs[d].matvec(x[off[d]:off[d + 1]])
        out[n_u:] = prec_s.matvec(x[n_u:])
        return out

    b = np.concatenate([system.rhs_u, np.zeros(n_p)])
    t1 = time.perf_counter()
    x, its, ok, hist = minres(matvec, precvec, b, rtol=rtol, maxiter=maxiter)
    t2 = time.perf_counter()
    res = float(np.linalg.norm(b - matvec(x)) / np.linalg.norm(b))
    return x[:n_u], x[n_u:], SolveInfo(its, res, ok, t1 - t0, t2 - t1, np.asarray(hist), mem)


def minres(matvec, precvec, b, *, rtol, maxiter, x0=None):
    r"""Preconditioned MINRES (Paige & Saunders; the form of Elman, Silvester & Wathen, alg. 4.1).

    Stops when the preconditioned residual norm :math:`\|r\|_{M^{-1}}` has dropped by ``rtol``
    from the initial one (scipy's ``minres`` tests against :math:`\|K\|\,\|x\|` instead, which
    stops far too early on these systems). Returns ``(x, iterations, converged, history)`` with
    ``history`` the relative preconditioned residual after each iteration.
    """
    x = np.zeros_like(b) if x0 is None else np.array(x0, dtype=float)
    v = b - matvec(x) if x0 is not None else b.copy()
    z = precvec(v)
    gamma = float(np.sqrt(max(z @ v, 0.0)))
    if gamma == 0.0:
        return x, 0, True, []
    gamma0 = gamma
    v_old = np.zeros_like(b)
    w = np.zeros_like(b)
    w_old = np.zeros_like(b)
    gamma_old, eta = 1.0, gamma
    c, c_old, s, s_old = 1.0, 1.0, 0.0, 0.0
    hist = []
    for it in range(1, maxiter + 1):
        z /= gamma
        Az = matvec(z)
        delta = float(Az @ z)
        v_new = Az - (delta / gamma) * v - (gamma / gamma_old) * v_old
        z_new = precvec(v_new)
        gamma_new = float(np.sqrt(max(z_new @ v_new, 0.0)))
        a0 = c * delta - c_old * s * gamma
        a1 = float(np.hypot(a0, gamma_new))
        a2 = s * delta + c_old * c * gamma
        a3 = s_old * gamma
        c_new, s_new = a0 / a1, gamma_new / a1
        w_new = (z - a3 * w_old - a2 * w) / a1
        x += (c_new * eta) * w_new
        eta = -s_new * eta
        hist.append(abs(eta) / gamma0)
        if hist[-1] < rtol or gamma_new == 0.0:
            return x, it, True, hist
        v_old, v, z = v, v_new, z_new
        w_old, w = w, w_new
        gamma_old, gamma = gamma, gamma_new
        c_old, c, s_old, s = c, c_new, s, s_new
    return x, maxiter, False, hist
