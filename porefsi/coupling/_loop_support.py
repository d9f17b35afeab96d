"""Helpers of the coupled loop (private).

The solid model as the TDG stepper sees it, solver failures as typed errors, topology comparison.
"""

from __future__ import annotations

import numpy as np

from porefsi.errors import ConvergenceError
from porefsi.network.network import Network


class _TangentLog:
    """The solid model as the TDG stepper sees it, noting where its tangent was evaluated.

    ``last`` is the ``(u, t)`` of the latest :meth:`tangent` call (what the stepper factorised);
    a ``pin`` set by :meth:`CoupledRun.restore` makes the next call evaluate there instead, so
    the resumed stepper factorises the same matrix as the run that wrote the checkpoint.
    """

    def __init__(self, model):
        self.model = model
        self.last: tuple[np.ndarray, float] | None = None
        self.pin: tuple[np.ndarray, float] | None = None

    @property
    def n_dofs(self) -> int:
        """Free dofs of the model."""
        return self.model.n_dofs

    def mass(self):
        """The model's mass."""
        return self.model.mass()

    def internal_force(self, u, t):
        """The model's internal force."""
        return self.model.internal_force(u, t)

    def external_force(self, t):
        """The model's external force."""
        return self.model.external_force(t)

    def tangent(self, u, t):
        """The model's tangent at ``(u, t)`` (or at the pinned state, once)."""
        if self.pin is not None:
            u, t = self.pin
            self.pin = None
        self.last = (np.array(u, dtype=float), float(t))
        return self.model.tangent(*self.last)


#: Exceptions solver libraries raise for a singular or broken system (SuperLU: RuntimeError).
_SOLVER_FAILURES = (RuntimeError, ArithmeticError, np.linalg.LinAlgError)


def _solver_failure(exc: BaseException, t: float, part: str = "solid") -> ConvergenceError:
    """A solver library's exception (e.g. SuperLU's "Factor is exactly singular") as a typed error."""
    if part == "fluid":
        return ConvergenceError(
            f"the drainage pressure solve failed at t = {t:g} s ({type(exc).__name__}: {exc}); the network's "
            "conductance matrix is singular: check the network for pores cut off from inlet and outlet")
    return ConvergenceError(
        f"the solid's linear solver failed at t = {t:g} s ({type(exc).__name__}: {exc}); the tangent is "
        "singular or not positive definite: check for floating or inverted elements (solid.coarsen), "
        "reduce coupling.exchange_dt, or try solid.linear_solver = 'amg'")


def _same_topology(a: Network, b: Network) -> bool:
    return a.n_pores == b.n_pores and np.array_equal(a.throat_conns, b.throat_conns) and \
        np.array_equal(a.pore_faces, b.pore_faces)
