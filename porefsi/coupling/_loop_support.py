"""Helpers of the coupled loop (private).

Solver failures as typed errors, image digests, topology comparison, invaded pores outside a
graded mesh's refined region.
"""

from __future__ import annotations

import hashlib

import numpy as np

from porefsi.errors import ConvergenceError
from porefsi.network.network import Network

__all__ = ["SOLVER_FAILURES", "solver_failure", "digest", "same_topology", "invaded_outside"]

#: Exceptions solver libraries raise for a singular or broken system (SuperLU: RuntimeError).
SOLVER_FAILURES = (RuntimeError, ArithmeticError, np.linalg.LinAlgError)


def solver_failure(exc: BaseException, t: float, part: str = "solid") -> ConvergenceError:
    """A solver library's exception (e.g. SuperLU's "Factor is exactly singular") as a typed error."""
    if part == "fluid":
        return ConvergenceError(
            f"the drainage pressure solve failed at t = {t:g} s ({type(exc).__name__}: {exc}); the network's "
            "conductance matrix is singular: check the network for pores cut off from inlet and outlet")
    return ConvergenceError(
        f"the solid's linear solver failed at t = {t:g} s ({type(exc).__name__}: {exc}); the tangent is "
        "singular or not positive definite: check for floating or inverted elements (solid.coarsen), "
        "reduce coupling.exchange_dt, or try solid.linear_solver = 'amg'")


def digest(phases: np.ndarray) -> bytes:
    """SHA-1 of a voxel image's bytes (the key of the extraction cache)."""
    return hashlib.sha1(memoryview(np.ascontiguousarray(phases)).cast("B")).digest()


def same_topology(a: Network, b: Network) -> bool:
    """Whether two networks have the same pores, throats and face pores (sizes may differ)."""
    return a.n_pores == b.n_pores and np.array_equal(a.throat_conns, b.throat_conns) and \
        np.array_equal(a.pore_faces, b.pore_faces)


def invaded_outside(refined: np.ndarray, labels: np.ndarray, nw_saturation: np.ndarray) -> np.ndarray:
    """Pores (indices) holding non-wetting fluid none of whose voxels lies in ``refined``.

    Parameters
    ----------
    refined : ndarray of bool, shape (nx, ny, nz)
        Voxels of the pores the graded mesh resolves finely.
    labels : ndarray of int, shape (nx, ny, nz)
        Pore index of each voxel of the current network (-1: none).
    nw_saturation : ndarray of float, shape (Np,)
        Non-wetting saturation of the current network's pores.

    Returns
    -------
    ndarray of int64, shape (k,)
    """
    n = len(nw_saturation)
    hit = labels[refined]
    inside = np.bincount(hit[(hit >= 0) & (hit < n)], minlength=n) > 0
    return np.flatnonzero((np.asarray(nw_saturation) > 0) & ~inside)
