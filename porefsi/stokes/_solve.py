r"""Block-preconditioned MINRES for the symmetric Stokes saddle-point system of :mod:`._grid`.

The preconditioner is block diagonal, :math:`\operatorname{diag}(\hat A^{-1}, \hat S^{-1})`, both
blocks symmetric positive definite (MINRES needs that):

* :math:`\hat A^{-1}`: one symmetric Gauss-Seidel sweep on each of the three scalar Laplacians
  :math:`A_x, A_y, A_z` (matrix-free, :mod:`._kernels`). The no-slip walls keep these well
  conditioned in porous media: the sweep needed fewer MINRES iterations than one smoothed-aggregation
  AMG V-cycle per block, on rock and on sphere arrays, at a fraction of the cost (measured in
  ``docs/stokes.md``);
* :math:`\hat S^{-1}`: one smoothed-aggregation V-cycle (:mod:`._pressure`) on :math:`B D^{-1} B^T`,
  :math:`D = \operatorname{diag}(A)`, the pressure Laplacian SIMPLE-type methods use for the
  Schur complement :math:`S = B A^{-1} B^T`. A scaled pressure mass matrix (the textbook choice
  for Stokes) misses the Darcy-like behaviour of :math:`S` on pressure modes smoother than the
  pores and needs many more iterations on porous media (measured in ``docs/stokes.md``).
"""

from __future__ import annotations

import dataclasses
import logging
import time

import numpy as np
import scipy.sparse as sp

from porefsi.stokes import _kernels as kern
from porefsi.stokes._grid import StaggeredSystem
from porefsi.stokes._pressure import PressureMultigrid

__all__ = ["SolveInfo", "solve", "schur_approximation", "N_VECTORS"]

#: Full-length vectors :func:`minres` keeps (x, two Lanczos vectors and the new one in place of the
#: oldest, two preconditioned ones, two search directions).
N_VECTORS = 7

#: Progress of long solves (size, every 25th iteration): ``logging`` at INFO level.
log = logging.getLogger(__name__)


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
        Estimated working memory: stencil tables, preconditioner hierarchy, Krylov vectors.
    """

    iterations: int
    residual: float
    converged: bool
    seconds_setup: float
    seconds_solve: float
    history: np.ndarray
    memory_bytes: int


def schur_approximation(system: StaggeredSystem) -> sp.csr_matrix:
    r""":math:`B D^{-1} B^T`, :math:`D = \operatorname{diag}(A)`: the SIMPLE pressure Laplacian."""
    indptr, indices, data = kern.schur_csr(system.p_lo, system.p_hi, system.diag, system.n_p)
    S = sp.csr_matrix((data, indices, indptr), shape=(system.n_p, system.n_p))
    S.sum_duplicates()  # two faces join the same two voxels on a periodic axis two voxels long
    return S


def pressure_preconditioner(system: StaggeredSystem) -> PressureMultigrid:
    """The V-cycle for :func:`schur_approximation` (see :mod:`porefsi.stokes._pressure`)."""
    return PressureMultigrid(system, schur_approximation(system))


def solve(system: StaggeredSystem, *, rtol: float = 1e-6, maxiter: int = 3000, preconditioner=None, monitor=None):
    r"""Solve the Stokes system; return ``(u, p, SolveInfo)`` (voxel units).

    Parameters
    ----------
    system : StaggeredSystem
    rtol : float
        Relative reduction of the preconditioned residual norm at which to stop.
    maxiter : int
        Iteration limit (``SolveInfo.converged`` is False when it is reached).
    preconditioner : PressureMultigrid, optional
        :func:`pressure_preconditioner` of ``system``, when built earlier (before the neighbour
        table, to lower the peak memory).
    monitor : callable, optional
        ``monitor(iteration, relative_residual, x)`` every 25th iteration (progress of long solves;
        ``x`` is the current iterate, velocities then pressures; do not modify it). Default: log the
        residual at INFO level.
    """
    t0 = time.perf_counter()
    n_u = system.n_u
    prec_s = pressure_preconditioner(system) if preconditioner is None else preconditioner
    tables = system.tables
    mem = system.nbytes + prec_s.nbytes + N_VECTORS * 8 * (n_u + system.n_p)  # + pyamg's temporaries

    def precvec(v, out):
        kern.symmetric_gauss_seidel(system.neighbours, system.diag, system.half, v, out, n_u)
        out[n_u:] = prec_s.matvec(v[n_u:])

    t1 = time.perf_counter()
    log.info("MINRES starts: %d velocity + %d pressure unknowns, ~%.2f GiB", n_u, system.n_p, mem / 2**30)
    if monitor is None:
        def monitor(it, res, x):
            log.info("MINRES iteration %d: relative preconditioned residual %.3e", it, res)
    x, its, ok, hist = minres(tables, n_u, precvec, _rhs(system), rtol=rtol, maxiter=maxiter, monitor=monitor)
    t2 = time.perf_counter()
    r = np.empty_like(x)
    kern.stokes_matvec(tables, x, n_u, r)
    rhs = system.rhs_u()
    r[:n_u] -= rhs
    res = float(np.linalg.norm(r) / np.linalg.norm(rhs))
    del r
    return x[:n_u], x[n_u:], SolveInfo(its, res, ok, t1 - t0, t2 - t1, np.asarray(hist), int(mem))


def _rhs(system: StaggeredSystem) -> np.ndarray:
    return np.concatenate([system.rhs_u(), np.zeros(system.n_p)])


def minres(tables, n_u, precvec, b, *, rtol, maxiter, monitor=None):
    r"""Preconditioned MINRES from x = 0 (Paige & Saunders; the form of Elman, Silvester & Wathen, alg. 4.1).

    ``tables`` are the stencil arrays :func:`porefsi.stokes._kernels.stokes_matvec` takes;
    ``precvec(v, out)`` writes the SPD preconditioner applied to ``v`` into ``out``.
    Stops when the preconditioned residual norm :math:`\|r\|_{M^{-1}}` has dropped by ``rtol``
    from the initial one (scipy's ``minres`` tests against :math:`\|K\|\,\|x\|` instead, which
    stops far too early on these systems). Returns ``(x, iterations, converged, history)`` with
    ``history`` the relative preconditioned residual after each iteration. ``b`` is overwritten.
    """
    x = np.zeros_like(b)
    v = b
    z = np.empty_like(b)
    precvec(v, z)
    gamma = float(np.sqrt(max(kern.dot(z, v), 0.0)))
    if gamma == 0.0:
        return x, 0, True, []
    gamma0 = gamma
    v_old = np.zeros_like(b)
    z_new = np.empty_like(b)
    w = np.zeros_like(b)
    w_old = np.zeros_like(b)
    gamma_old, eta = 1.0, gamma
    c, c_old, s, s_old = 1.0, 1.0, 0.0, 0.0
    hist = []
    for it in range(1, maxiter + 1):
        z /= gamma
        delta = kern.lanczos_delta(tables, z, n_u)
        kern.lanczos_step(tables, z, n_u, v, v_old, delta / gamma, gamma / gamma_old)  # v_old <- v_new
        v, v_old = v_old, v
        precvec(v, z_new)
        gamma_new = float(np.sqrt(max(kern.dot(z_new, v), 0.0)))
        a0 = c * delta - c_old * s * gamma
        a1 = float(np.hypot(a0, gamma_new))
        a2 = s * delta + c_old * c * gamma
        a3 = s_old * gamma
        c_new, s_new = a0 / a1, gamma_new / a1
        kern.update_search(w_old, z, w, a1, a2, a3)  # w_old <- w_new
        w, w_old = w_old, w
        kern.axpy(x, c_new * eta, w)
        eta = -s_new * eta
        hist.append(abs(eta) / gamma0)
        if monitor is not None and it % 25 == 0:
            monitor(it, hist[-1], x)
        if hist[-1] < rtol or gamma_new == 0.0:
            return x, it, True, hist
        z, z_new = z_new, z
        gamma_old, gamma = gamma, gamma_new
        c_old, c, s_old, s = c, c_new, s, s_new
    return x, maxiter, False, hist
