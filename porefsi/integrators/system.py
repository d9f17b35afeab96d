r"""The abstract second-order system that every time integrator advances.

Integrators know nothing of porefsi physics: they see a semi-discrete system

.. math:: M \ddot u + f_{int}(u, t) = f_{ext}(t)

on ``n_dofs`` free unknowns (Dirichlet constraints are condensed out by whoever builds the
system; a prescribed boundary motion enters through the ``t`` argument of ``internal_force``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol, runtime_checkable

import numpy as np
import scipy.sparse as sp

__all__ = ["SecondOrderSystem", "SolverFactory", "LinearSystem"]

#: ``make_solver(A)`` returns ``solve(b) -> x`` for the SPD matrix ``A`` (sparse, (n, n)).
SolverFactory = Callable[[sp.spmatrix], Callable[[np.ndarray], np.ndarray]]


@runtime_checkable
class SecondOrderSystem(Protocol):
    """What an integrator needs of a structural model (all on the free dofs, SI units)."""

    @property
    def n_dofs(self) -> int:
        """Number of free unknowns n."""

    def mass(self) -> sp.spmatrix | np.ndarray:
        """Mass matrix, sparse (n, n), or its diagonal as an ndarray (n,) when lumped; kg."""

    def internal_force(self, u: np.ndarray, t: float) -> np.ndarray:
        """Internal force f_int(u, t), N, shape (n,)."""

    def tangent(self, u: np.ndarray, t: float) -> sp.spmatrix:
        """Tangent stiffness d f_int / d u at (u, t), N/m, sparse (n, n), symmetric."""

    def external_force(self, t: float) -> np.ndarray:
        """External load f_ext(t), N, shape (n,)."""


class LinearSystem:
    """A linear :class:`SecondOrderSystem`: ``M u'' + K u = f(t)`` (for tests and studies).

    Parameters
    ----------
    M : sparse or ndarray, shape (n, n) or (n,)
        Mass matrix (or lumped diagonal).
    K : sparse or ndarray, shape (n, n)
        Stiffness matrix.
    load : callable, optional
        ``load(t) -> ndarray (n,)``; zero when omitted.
    """

    def __init__(self, M, K, load: Callable[[float], np.ndarray] | None = None):
        self._M = M if (sp.issparse(M) or np.ndim(M) == 1) else sp.csr_matrix(np.asarray(M, float))
        self._K = sp.csr_matrix(K)
        self._load = load

    @property
    def n_dofs(self) -> int:
        """Number of unknowns."""
        return self._K.shape[0]

    def mass(self):
        """Mass matrix (as given)."""
        return self._M

    def internal_force(self, u, t):
        """``K u``."""
        return self._K @ u

    def tangent(self, u, t):
        """``K``."""
        return self._K

    def external_force(self, t):
        """``load(t)`` or zeros."""
        return np.zeros(self.n_dofs) if self._load is None else np.asarray(self._load(t), dtype=float)
