r"""Generalized-:math:`\alpha` (Chung & Hulbert 1993) with user-set high-frequency dissipation.

.. math::
    M a_{n+1-\alpha_m} + f_{int}(u_{n+1-\alpha_f}, t_{n+1-\alpha_f}) = (1-\alpha_f) f_{n+1} + \alpha_f f_n,
    \qquad x_{n+1-\alpha} = (1-\alpha) x_{n+1} + \alpha x_n,

with Newmark updates and
:math:`\alpha_m = (2\rho_\infty-1)/(\rho_\infty+1)`, :math:`\alpha_f = \rho_\infty/(\rho_\infty+1)`,
:math:`\gamma = \tfrac12-\alpha_m+\alpha_f`, :math:`\beta = \tfrac14(1-\alpha_m+\alpha_f)^2`:
second order, unconditionally stable, spectral radius :math:`\rho_\infty` as
:math:`\omega\Delta t\to\infty`.

The acceleration is part of the state (it does not satisfy equilibrium at :math:`t_n`). The
stepper remembers the acceleration of the state it last returned; a call with another state
(or ``a=None`` and a new state) starts from the equilibrium acceleration. Pass ``a=`` to set it.

References
----------
.. [1] J. Chung, G.M. Hulbert (1993), A time integration algorithm for structural dynamics with
   improved numerical dissipation: the generalized-alpha method, J. Appl. Mech. 60, 371-375.
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
    same_state,
)
from porefsi.integrators._newton import newton
from porefsi.integrators.system import SecondOrderSystem, SolverFactory

__all__ = ["GeneralizedAlphaStepper", "generalized_alpha_parameters"]


def generalized_alpha_parameters(rho_inf: float) -> dict[str, float]:
    """Chung-Hulbert parameters ``alpha_m, alpha_f, beta, gamma`` for ``0 <= rho_inf <= 1``."""
    r = float(rho_inf)
    if not 0.0 <= r <= 1.0:
        raise InputError(f"rho_inf={rho_inf!r} must lie in [0, 1]")
    am, af = (2 * r - 1) / (r + 1), r / (r + 1)
    return {"alpha_m": am, "alpha_f": af, "gamma": 0.5 - am + af, "beta": 0.25 * (1 - am + af) ** 2}


class GeneralizedAlphaStepper:
    r"""Generalized-alpha step with Newton iterations on :math:`u_{n+1}`.

    Parameters
    ----------
    system : SecondOrderSystem
        The model.
    dt : float
        Time step, s.
    rho_inf : float, default 0.5
        Spectral radius at infinite :math:`\omega\Delta t` (1: no dissipation).
    make_solver : callable, optional
        Solver factory (default sparse LU).
    rtol, max_iter : float, int
        Newton tolerance (relative) and iteration cap.
    """

    def __init__(
        self,
        system: SecondOrderSystem,
        dt: float,
        rho_inf: float = 0.5,
        make_solver: SolverFactory | None = None,
        rtol: float = 1e-10,
        max_iter: int = 25,
    ):
        if not isinstance(system, SecondOrderSystem):
            raise InputError(f"system {type(system).__name__} does not implement SecondOrderSystem")
        self.system, self.dt = system, check_dt(dt)
        self.rho_inf = float(rho_inf)
        p = generalized_alpha_parameters(rho_inf)
        self.alpha_m, self.alpha_f, self.beta, self.gamma = p["alpha_m"], p["alpha_f"], p["beta"], p["gamma"]
        self.rtol, self.max_iter = float(rtol), int(max_iter)
        self._make_solver = make_solver or default_solver
        self._mass = MassOperator(system.mass(), self._make_solver)
        self._n = int(system.n_dofs)
        self._last = None
        self._Kcache = (None, None)

    def __repr__(self) -> str:
        return f"GeneralizedAlphaStepper(n_dofs={self._n}, dt={self.dt!r}, rho_inf={self.rho_inf})"

    def _start_acceleration(self, u, v, t, a):
        if a is not None:
            return check_state("a", a, self._n)
        last = self._last
        if same_state(last, u, v, t, self.dt):
            return last[3]
        return self._mass.solve(self.system.external_force(t) - self.system.internal_force(u, t))

    def step(self, u, v, t: float, a=None) -> tuple[np.ndarray, np.ndarray, StepInfo]:
        """Advance one step; ``info.extra['a']`` is the end-of-step acceleration (m/s^2)."""
        n, dt, sys, mass = self._n, self.dt, self.system, self._mass
        am, af, b, g = self.alpha_m, self.alpha_f, self.beta, self.gamma
        u, v, t = check_state("u", u, n), check_state("v", v, n), check_time(t)
        a = self._start_acceleration(u, v, t, a)
        t1 = t + dt
        tf = t + (1 - af) * dt
        f_alpha = (1 - af) * sys.external_force(t1) + af * sys.external_force(t)
        u_pred = u + dt * v + dt * dt * (0.5 - b) * a
        c = b * dt * dt / (1 - am)  # residual scaled by beta dt^2 / (1 - alpha_m)
        Ma_n = mass.apply(a)

        def residual(x):
            a1 = (x - u_pred) / (b * dt * dt)
            inert = mass.apply((1 - am) * a1) + am * Ma_n
            fi = sys.internal_force((1 - af) * x + af * u, tf)
            r = c * (inert + fi - f_alpha)
            # M x / (beta dt^2) is in the scale: a1 is a difference of O(|x|) terms (round-off)
            sizes = (c * inert, c * fi, c * f_alpha, mass.apply(x) * (1 - am))
            return r, max(max(np.linalg.norm(s) for s in sizes), 1e-300)

        def jacobian(x):
            K = sys.tangent((1 - af) * x + af * u, tf)
            if K is not self._Kcache[0]:
                self._Kcache = (K, mass.add_scaled(c * (1 - af), K))
            return self._Kcache[1]

        x, hist, ns, nf = newton(residual, jacobian, u_pred, self._make_solver, rtol=self.rtol,
                                 max_iter=self.max_iter, what=f"generalized-alpha step at t={t!r} s")
        a1 = (x - u_pred) / (b * dt * dt)
        v1 = v + dt * ((1 - g) * a + g * a1)
        self._last = (t1, x, v1, a1)
        return x, v1, StepInfo(len(hist) - 1, tuple(h / c for h in hist), ns, nf, extra={"a": a1})
