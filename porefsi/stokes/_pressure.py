r"""Memory-lean multigrid preconditioner for the pressure Laplacian :math:`S = B D^{-1} B^T`.

A symmetric V-cycle whose finest level is matrix-free (:mod:`._kernels`: the face tables already
hold :math:`S`), so :math:`S` is assembled only while the hierarchy is built and dropped before the
iterations start. The first coarse level is smoothed aggregation built here step by step with the
building blocks of pyamg (standard aggregation, the tentative prolongator for the constant, one
damped-Jacobi smoothing :math:`P = (I - \tfrac{4}{3\rho} D_S^{-1} S) T`, Galerkin
:math:`A_1 = P^T S P`), freeing each temporary as it goes; the coarser levels are pyamg's own
smoothed-aggregation hierarchy of :math:`A_1`. Every level smooths with a symmetric Gauss-Seidel
sweep before and after, so the cycle is symmetric positive definite, as MINRES requires.

Measured peak memory of the whole solve on a 200^3 crop of the 400^3 Berea: 1.10 GiB with pyamg's
hierarchy of the assembled :math:`S` against less with this one (``docs/stokes.md``).
"""

from __future__ import annotations

import numpy as np
import pyamg
import scipy.sparse as sp
from pyamg.aggregation import fit_candidates, standard_aggregation

from porefsi.stokes import _kernels as kern

__all__ = ["PressureMultigrid"]

#: Damping of the prolongator smoothing (pyamg's default).
OMEGA = 4.0 / 3.0


def _csr(M):
    return M.tocsr() if not sp.isspmatrix_csr(M) else M


def _nbytes(M) -> int:
    return int(M.data.nbytes + M.indices.nbytes + M.indptr.nbytes)


def _spectral_radius_jacobi(S: sp.csr_matrix, d: np.ndarray, dinv: np.ndarray, iterations: int = 30) -> float:
    """Largest eigenvalue of D^-1 S (S symmetric positive semi-definite): power iteration in the D-inner product."""
    rng = np.random.default_rng(0)
    x = (rng.random(S.shape[0]) + 0.5) * (d > 0)
    lam = 0.0
    for _ in range(iterations):
        y = dinv * (S @ x)
        lam = float(np.sqrt(np.dot(y, d * y) / np.dot(x, d * x)))
        x = y / np.max(np.abs(y))
    return 1.1 * lam  # a little above, as pyamg's safety factor: over-smoothing diverges, under only slows


class PressureMultigrid:
    """Symmetric V-cycle for :math:`S` (see the module notes); ``matvec(b)`` applies it once.

    Parameters
    ----------
    system : porefsi.stokes._grid.StaggeredSystem
        Only its coupling tables (``diag``, ``p_lo``, ``p_hi``, ``offsets``) are used.
    schur : scipy.sparse.csr_matrix
        :math:`S` assembled (consumed: the caller should drop its reference).
    """

    def __init__(self, system, schur: sp.csr_matrix):
        self.plo, self.phi, self.diag = system.p_lo, system.p_hi, system.diag
        self.pf = kern.pressure_faces(system.p_lo, system.p_hi, system.offsets, system.n_p)
        S = _csr(schur)
        d = S.diagonal()
        dinv = np.divide(1.0, d, out=np.zeros_like(d), where=d > 0)  # a voxel with no open face: a null row
        agg, _ = standard_aggregation(S)
        T, b_coarse = fit_candidates(agg, np.ones((S.shape[0], 1)))
        del agg
        T = _csr(T)
        ST = _csr(S @ T)
        ST.data *= np.repeat(dinv * (OMEGA / _spectral_radius_jacobi(S, d, dinv)), np.diff(ST.indptr))
        P = _csr(T - ST)
        del ST, T
        SP = _csr(S @ P)
        del S
        A1 = _csr(P.T @ SP)
        del SP
        self.P = P
        self.R = P.T  # a transposed view, no copy
        self.coarse = pyamg.smoothed_aggregation_solver(
            A1, B=b_coarse, symmetry="symmetric", max_coarse=500, strength=None,
            presmoother=("gauss_seidel", {"sweep": "symmetric"}),
            postsmoother=("gauss_seidel", {"sweep": "symmetric"}),
        )
        for lev in self.coarse.levels:  # pyamg keeps coarse levels as 1x1-block BSR: CSR smooths 1.7x faster
            lev.A = _csr(lev.A)
            if sp.issparse(getattr(lev, "P", None)):
                lev.P = _csr(lev.P)
                lev.R = lev.P.T
        self._coarse_prec = self.coarse.aspreconditioner(cycle="V")
        self.levels = 1 + len(self.coarse.levels)

    @property
    def nbytes(self) -> int:
        """Bytes of the face table of the finest level, P, and the coarse hierarchy."""
        coarse = sum(_nbytes(getattr(lev, name)) for lev in self.coarse.levels for name in ("A", "P")
                     if sp.issparse(getattr(lev, name, None)))
        return int(self.pf.nbytes + _nbytes(self.P) + coarse)

    def matvec(self, b: np.ndarray) -> np.ndarray:
        """One symmetric V-cycle on :math:`S x = b` from :math:`x = 0`."""
        x = np.zeros_like(b)
        kern.schur_symmetric_gauss_seidel(self.pf, self.plo, self.phi, self.diag, b, x)
        r = np.empty_like(b)
        kern.schur_residual(self.pf, self.plo, self.phi, self.diag, b, x, r)
        x += self.P @ self._coarse_prec.matvec(self.R @ r)
        del r
        kern.schur_symmetric_gauss_seidel(self.pf, self.plo, self.phi, self.diag, b, x)
        return x
