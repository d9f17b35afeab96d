r"""Explicit central difference (velocity form, Newmark :math:`\beta=0,\ \gamma=1/2`) and its critical step.

.. math::
    u_{n+1} = u_n + \Delta t\,v_n + \tfrac12\Delta t^2 a_n,\quad
    M a_{n+1} = f_{ext}(t_{n+1}) - f_{int}(u_{n+1}, t_{n+1}),\quad
    v_{n+1} = v_n + \tfrac12\Delta t(a_n + a_{n+1}).

Stable only for :math:`\omega_{max}\Delta t \le 2` (:func:`critical_time_step`). On an elastic
mesh with micrometre elements :math:`\omega_{max}\sim10^9` rad/s, i.e. a critical step of
nanoseconds: the scheme is here to show what happens beyond it.

References
----------
.. [1] T.J.R. Hughes (2000), The Finite Element Method, Dover, ch. 9.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from porefsi.errors import InputError
from porefsi.integrators._common import (
    MassOperator,
    StepInfo,
    check_dt,
    check_state,
    check_time,
    default_solver,
    same_state,
)
from porefsi.integrators.system import SecondOrderSystem, SolverFactory

__all__ = ["CentralDifferenceStepper", "critical_time_step", "max_frequency"]


def max_frequency(system: SecondOrderSystem, u=None, t: float = 0.0) -> float:
    r"""Largest natural angular frequency :math:`\omega_{max}` (rad/s) of the tangent at ``u``.

    Largest eigenvalue of :math:`K x = \omega^2 M x` (ARPACK; dense for n <= 50).
    """
    n = int(system.n_dofs)
    u = np.zeros(n) if u is None else check_state("u", u, n)
    K = sp.csr_matrix(system.tangent(u, t), dtype=float)
    M = system.mass()
    if not sp.issparse(M) and np.ndim(M) == 1:
        d = 1.0 / np.sqrt(np.asarray(M, float))
        S = sp.diags(d) @ K @ sp.diags(d)
        lam = np.linalg.eigvalsh(S.toarray())[-1] if n <= 50 else spla.eigsh(S, k=1, which="LA")[0][0]
    else:
        Md = sp.csr_matrix(M).toarray() if n <= 50 else sp.csc_matrix(M)
        if n <= 50:
            import scipy.linalg as sla

            lam = sla.eigh(K.toarray(), Md, eigvals_only=True)[-1]
        else:
            lam = spla.eigsh(K, k=1, M=Md, which="LA")[0][0]
    return float(np.sqrt(max(lam, 0.0)))


def critical_time_step(system: SecondOrderSystem, u=None, t: float = 0.0) -> float:
    r"""Stability limit :math:`\Delta t_{cr} = 2/\omega_{max}` of the central-difference step, s."""
    w = max_frequency(system, u, t)
    return np.inf if w == 0 else 2.0 / w


class CentralDifferenceStepper:
    """Explicit central-difference step (one mass solve, one internal force per step).

    Parameters
    ----------
    system : SecondOrderSystem
        The model (a lumped mass makes the step a division).
    dt : float
        Time step, s. Not checked against :func:`critical_time_step` (studies cross it on purpose).
    make_solver : callable, optional
        Factory used once for a consistent mass matrix.
    """

    def __init__(self, system: SecondOrderSystem, dt: float, make_solver: SolverFactory | None = None):
        if not isinstance(system, SecondOrderSystem):
            raise InputError(f"system {type(system).__name__} does not implement SecondOrderSystem")
        self.system, self.dt = system, check_dt(dt)
        self._mass = MassOperator(system.mass(), make_solver or default_solver)
        self._n = int(system.n_dofs)
        self._last = None

    def __repr__(self) -> str:
        return f"CentralDifferenceStepper(n_dofs={self._n}, dt={self.dt!r})"

    def step(self, u, v, t: float, a=None) -> tuple[np.ndarray, np.ndarray, StepInfo]:
        """Advance one step; ``info.extra['a']`` is the end-of-step acceleration."""
        n, dt, sys = self._n, self.dt, self.system
        u, v, t = check_state("u", u, n), check_state("v", v, n), check_time(t)
        last = self._last
        if a is not None:
            a = check_state("a", a, n)
        elif same_state(last, u, v, t, self.dt):
            a = last[3]
        else:
            a = self._mass.solve(sys.external_force(t) - sys.internal_force(u, t))
        t1 = t + dt
        u1 = u + dt * v + 0.5 * dt * dt * a
        a1 = self._mass.solve(sys.external_force(t1) - sys.internal_force(u1, t1))
        v1 = v + 0.5 * dt * (a + a1)
        self._last = (t1, u1, v1, a1)
        return u1, v1, StepInfo(0, (), 0, 0, extra={"a": a1})
