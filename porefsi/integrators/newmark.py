r"""Newmark's family (implicit, :math:`\beta>0`), average acceleration by default.

.. math::
    u_{n+1} = u_n + \Delta t\,v_n + \Delta t^2[(\tfrac12-\beta)a_n + \beta a_{n+1}],\quad
    v_{n+1} = v_n + \Delta t[(1-\gamma)a_n + \gamma a_{n+1}],\quad
    M a_{n+1} + f_{int}(u_{n+1}, t_{n+1}) = f_{ext}(t_{n+1}).

The acceleration at the start of a step is recomputed from equilibrium at :math:`t_n` (one mass
solve; free for a lumped mass), which is the value the previous step ended with, so the stepper
carries no hidden state. Average acceleration (:math:`\beta=1/4,\ \gamma=1/2`) conserves
:math:`\tfrac12 v^TMv + \tfrac12 u^TKu` exactly for a free linear system and has spectral radius 1
at every :math:`\omega\Delta t`: it never damps spurious high frequencies.

References
----------
.. [1] N.M. Newmark (1959), A method of computation for structural dynamics, J. Eng. Mech. Div.
   ASCE 85, 67-94.
"""

from __future__ import annotations

import numpy as np

from porefsi.errors import InputError
from porefsi.integrators._common import (
    MassOperator,
    StepInfo,
    check_dt,
    check_state,
    check_time,
    default_solver,
)
from porefsi.integrators._newton import newton
from porefsi.integrators.system import SecondOrderSystem, SolverFactory

__all__ = ["NewmarkStepper"]


class NewmarkStepper:
    r"""Implicit Newmark step with Newton iterations on :math:`u_{n+1}`.

    Parameters
    ----------
    system : SecondOrderSystem
        The model.
    dt : float
        Time step, s.
    beta, gamma : float, default 1/4, 1/2
        Newmark parameters (``beta > 0``; use :class:`CentralDifferenceStepper` for ``beta = 0``).
    make_solver : callable, optional
        Solver factory for :math:`M + \beta\Delta t^2 K` (default sparse LU).
    rtol : float, default 1e-10
        Newton tolerance on the equilibrium residual relative to its largest term.
    max_iter : int, default 25
        Newton iterations per step.
    """

    def __init__(
        self,
        system: SecondOrderSystem,
        dt: float,
        beta: float = 0.25,
        gamma: float = 0.5,
        make_solver: SolverFactory | None = None,
        rtol: float = 1e-10,
        max_iter: int = 25,
    ):
        if not isinstance(system, SecondOrderSystem):
            raise InputError(f"system {type(system).__name__} does not implement SecondOrderSystem")
        if not beta > 0:
            raise InputError(f"beta={beta!r} must be > 0 for the implicit step; use CentralDifferenceStepper")
        if not gamma >= 0.5:
            raise InputError(f"gamma={gamma!r} < 1/2 gives negative numerical damping (unstable); use >= 0.5")
        self.system, self.dt = system, check_dt(dt)
        self.beta, self.gamma = float(beta), float(gamma)
        self.rtol, self.max_iter = float(rtol), int(max_iter)
        self._make_solver = make_solver or default_solver
        self._mass = MassOperator(system.mass(), self._make_solver)
        self._n = int(system.n_dofs)
        self._Kcache = (None, None)

    def __repr__(self) -> str:
        return f"NewmarkStepper(n_dofs={self._n}, dt={self.dt!r}, beta={self.beta}, gamma={self.gamma})"

    def _jac(self, K):
        if K is not self._Kcache[0]:
            self._Kcache = (K, self._mass.add_scaled(self.beta * self.dt**2, K))
        return self._Kcache[1]

    def step(self, u, v, t: float) -> tuple[np.ndarray, np.ndarray, StepInfo]:
        """Advance one step from ``(u, v)`` at ``t``; returns ``(u_new, v_new, info)``."""
        n, dt, b, g, sys, mass = self._n, self.dt, self.beta, self.gamma, self.system, self._mass
        u, v, t = check_state("u", u, n), check_state("v", v, n), check_time(t)
        a = mass.solve(sys.external_force(t) - sys.internal_force(u, t))
        t1 = t + dt
        f1 = sys.external_force(t1)
        u_pred = u + dt * v + dt * dt * (0.5 - b) * a
        c = b * dt * dt

        def residual(x):
            Ma = mass.apply(x - u_pred)  # = beta dt^2 M a_{n+1}
            fi = sys.internal_force(x, t1)
            r = Ma + c * (fi - f1)
            # M x is in the scale: M (x - u_pred) is a difference of O(|x|) terms (round-off)
            sizes = (Ma, mass.apply(x), c * fi, c * f1)
            return r, max(max(np.linalg.norm(s) for s in sizes), 1e-300)

        x, hist, ns, nf = newton(
            residual, lambda x: self._jac(sys.tangent(x, t1)), u_pred, self._make_solver,
            rtol=self.rtol, max_iter=self.max_iter, what=f"Newmark step at t={t!r} s",
        )
        a1 = (x - u_pred) / c
        v1 = v + dt * ((1 - g) * a + g * a1)
        return x, v1, StepInfo(len(hist) - 1, tuple(h / c for h in hist), ns, nf, extra={"a": a1})
