r"""The exact piecewise-linear TDG step (the coupled 2x2-block solve), used as a test oracle.

Derived directly from the Galerkin statement, independently of the Nørsett iteration of
:mod:`porefsi.integrators.tdg`. On the step :math:`[t_n, t_n+\Delta t]`, with
:math:`\tau = (t-t_n)/\Delta t`, displacement and velocity are linear in :math:`\tau` with nodal
values :math:`U_0, U_1, V_0, V_1` (index 0 is the value just after :math:`t_n`, the jump side).
For every linear test function :math:`w(\tau)\in\{1-\tau,\tau\}`:

.. math::
    \int_0^1 w\,(U' - \Delta t\,V)\,d\tau + w(0)\,(U_0-u_n) = 0,

    \int_0^1 w\,(M V' + \Delta t\,[f_{int}(u,t) - f_{ext}(t)])\,d\tau + w(0)\,M(V_0-v_n) = 0 .

The displacement equations give :math:`U_1 = u_n + \Delta t (V_0+V_1)/2`,
:math:`U_0 = u_n + \Delta t (V_0-V_1)/6`. The load integral is taken with the two-point left
Radau rule (abscissae 0, 2/3; weights 1/4, 3/4), i.e. exactly for the linear interpolant of the
load samples at :math:`t_n` and :math:`t_n+2\Delta t/3`:
:math:`L_0 = (f_0+f_{2/3})/4`, :math:`L_1 = f_{2/3}/2`. The internal-force integral is taken with
the two-point right Radau rule (abscissae 1/3, 1; weights 3/4, 1/4), exact for a linear
:math:`f_{int}` and making the nonlinear step the Radau IIA-2 collocation method. The remaining
two vector equations in :math:`(V_0, V_1)`,

.. math::
    R_0 = \tfrac12 M(V_0+V_1) - M v_n + \Delta t\,[\tfrac12 g_{1/3} - L_0] = 0,\qquad
    R_1 = \tfrac12 M(V_1-V_0) + \Delta t\,[\tfrac14 g_{1/3} + \tfrac14 g_1 - L_1] = 0,

with :math:`g_{1/3} = f_{int}(u_n + \Delta t(\tfrac5{18}V_0+\tfrac1{18}V_1),\ t_n+\Delta t/3)` and
:math:`g_1 = f_{int}(U_1, t_n+\Delta t)`, are solved together (Newton on the non-symmetric
:math:`2n\times 2n` block system; one iteration when :math:`f_{int}` is linear). The step ends at
:math:`u_{n+1}=U_1`, :math:`v_{n+1}=V_1`.

References
----------
.. [1] T.J.R. Hughes, G.M. Hulbert (1988), Space-time finite element methods for elastodynamics:
   formulations and error estimates, Comput. Methods Appl. Mech. Engrg. 66, 339-363.
.. [2] P. Lesaint, P.-A. Raviart (1974), On a finite element method for solving the neutron
   transport equation (DG in time = Radau IIA with right-Radau quadrature).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from porefsi.errors import InputError
from porefsi.integrators._common import StepInfo, check_dt, check_state, check_time, default_solver
from porefsi.integrators._newton import newton
from porefsi.integrators.system import SecondOrderSystem

__all__ = ["TDGExactStepper"]


class TDGExactStepper:
    r"""Exact (fully coupled) piecewise-linear TDG step; the oracle for :class:`TDGStepper`.

    Parameters
    ----------
    system : SecondOrderSystem
        The model.
    dt : float
        Time step, s.
    rtol : float, default 1e-11
        Newton tolerance on the block residual, relative to its largest term.
    max_iter : int, default 30
        Newton iterations.
    load_rule : {"left", "right"}, default "left"
        Load samples at :math:`t, t+2\Delta t/3` (left Radau, the paper's) or
        :math:`t+\Delta t/3, t+\Delta t` (right Radau: :math:`L_0 = f_{1/3}/2`,
        :math:`L_1 = (f_{1/3}+f_1)/4`), as in :class:`~porefsi.integrators.TDGStepper`.

    Notes
    -----
    A direct sparse LU of the :math:`2n\times 2n` block matrix every Newton iteration: meant for
    tests and small studies, not for production meshes.
    """

    def __init__(
        self, system: SecondOrderSystem, dt: float, rtol: float = 1e-11, max_iter: int = 30, load_rule: str = "left"
    ):
        if load_rule not in ("left", "right"):
            raise InputError(f"load_rule={load_rule!r} is not one of ('left', 'right')")
        self.load_rule = load_rule
        if not isinstance(system, SecondOrderSystem):
            raise InputError(f"system {type(system).__name__} does not implement SecondOrderSystem")
        self.system = system
        self.dt = check_dt(dt)
        self.rtol = float(rtol)
        self.max_iter = int(max_iter)
        M = system.mass()
        self._M = sp.diags(np.asarray(M, float)) if (not sp.issparse(M) and np.ndim(M) == 1) else sp.csr_matrix(M)
        self._n = int(system.n_dofs)
        self._cache = None

    def load_times(self, t: float) -> tuple[float, float]:
        """Load sampling times (left Radau ``t, t + 2 dt / 3`` or right Radau ``t + dt/3, t + dt``)."""
        if self.load_rule == "right":
            return (t + self.dt / 3.0, t + self.dt)
        return (t, t + 2.0 * self.dt / 3.0)

    def step(self, u, v, t: float, loads=None) -> tuple[np.ndarray, np.ndarray, StepInfo]:
        """Advance one step; same signature and meaning as :meth:`TDGStepper.step`."""
        n, dt, M, sys = self._n, self.dt, self._M, self.system
        u = check_state("u", u, n)
        v = check_state("v", v, n)
        t = check_time(t)
        if loads is None:
            loads = tuple(sys.external_force(s) for s in self.load_times(t))
        f0 = check_state("loads[0]", loads[0], n)
        f23 = check_state("loads[1]", loads[1], n)
        if self.load_rule == "left":
            L0, L1 = 0.25 * (f0 + f23), 0.5 * f23
        else:
            L0, L1 = 0.5 * f0, 0.25 * (f0 + f23)
        Mv = M @ v
        t13, t1 = t + dt / 3.0, t + dt

        def states(x):
            V0, V1 = x[:n], x[n:]
            return V0, V1, u + dt * (5.0 / 18.0 * V0 + 1.0 / 18.0 * V1), u + 0.5 * dt * (V0 + V1)

        def residual(x):
            V0, V1, uq, U1 = states(x)
            g13, g1 = sys.internal_force(uq, t13), sys.internal_force(U1, t1)
            a, b = 0.5 * (M @ (V0 + V1)), 0.5 * (M @ (V1 - V0))
            r = np.concatenate([a - Mv + dt * (0.5 * g13 - L0), b + dt * (0.25 * (g13 + g1) - L1)])
            scale = max(
                np.linalg.norm(a), np.linalg.norm(Mv), dt * np.linalg.norm(g13), dt * np.linalg.norm(g1),
                dt * np.linalg.norm(L0), dt * np.linalg.norm(L1), 1e-300,
            )
            return r, scale

        def jacobian(x):
            V0, V1, uq, U1 = states(x)
            K1, K2 = sys.tangent(uq, t13), sys.tangent(U1, t1)
            key = (id(K1), id(K2))
            if self._cache is not None and self._cache[0] == key and self._cache[1] is K1 and self._cache[2] is K2:
                return self._cache[3]
            h = dt * dt
            A = sp.bmat(
                [
                    [0.5 * M + h * 5.0 / 36.0 * K1, 0.5 * M + h / 36.0 * K1],
                    [-0.5 * M + h * (5.0 / 72.0 * K1 + 0.125 * K2), 0.5 * M + h * (K1 / 72.0 + 0.125 * K2)],
                ],
                format="csc",
            )
            self._cache = (key, K1, K2, A)
            return A

        x, hist, n_solves, n_fact = newton(
            residual, jacobian, np.concatenate([v, v]), default_solver,
            rtol=self.rtol, max_iter=self.max_iter, what=f"exact TDG step at t={t!r} s",
        )
        V0, V1, _, U1 = states(x)
        info = StepInfo(iterations=len(hist) - 1, residual_norms=tuple(hist), n_solves=n_solves,
                        n_factorizations=n_fact)
        return U1, V1.copy(), info
