r"""Time-discontinuous Galerkin (TDG) integration with the Nørsett-type predictor-corrector.

The semi-discrete system :math:`M\ddot u + f_{int}(u,t) = f_{ext}(t)` is written in first-order
form :math:`y=(u,v)`, :math:`\dot u = v`, :math:`M\dot v = f_{ext} - f_{int}`, and both fields are
taken piecewise linear in time and discontinuous at the step ends. That Galerkin step is the
(1,2)-Padé / Radau IIA-2 scheme (third order at step ends, L-stable); its exact solution couples
the two time nodes through a 2x2 block matrix with complex eigenvalues
(:mod:`porefsi.integrators.tdg_exact`). The Nørsett-type iteration of Mancuso & Ubertini replaces
that coupling by a lower-triangular one with the double real eigenvalue
:math:`\alpha^* = 1-\sqrt2/2`, so that every corrector pass costs two solves with

.. math:: M^* = M + \alpha^{*2}\Delta t^2 K .

Pass 1 is the L-stable two-stage SDIRK (second order); pass 2 is third order. The full
derivation, and why :math:`\lambda^* = \sqrt2-4/3` *is* required while the paper's printed
:math:`F_0` is not, is in ``docs/time_integration.md``.

Stage bookkeeping (the paper's eqs 2.18-2.24). The unknowns of a step are the stage derivatives
:math:`k_i=(\bar u_i,\bar v_i)`, i = 0, 1 (stage velocity, stage acceleration), with stage states

.. math::
    Y_0 = y_n + \Delta t[(\alpha^*+\lambda^*)k_0 - \lambda^* k_1],\qquad
    Y_1 = y_n + \Delta t[(1-\alpha^*)k_0 + \alpha^* k_1] = y_{n+1}.

That is the TDG step in a stage basis related to the Radau IIA one by
:math:`k^{Radau} = T k`, :data:`T_MATRIX`. Each pass evaluates the TDG residual (internal force at
the Radau points :math:`t_n+\Delta t/3,\ t_n+\Delta t`, loads from their linear interpolant
through :math:`t_n` and :math:`t_n+2\Delta t/3`) and corrects ``k`` with the lower-triangular
(Nørsett) approximation of its Jacobian. For a linear :math:`f_{int}=Ku` the corrector is
algebraically identical to the paper's predictor form (tested against a literal transcription);
for a nonlinear one it is a simplified Newton iteration whose fixed point is the nonlinear TDG
step, so third order is kept (a literal nonlinear reading of eq. 2.18 converges to a
second-order method).

References
----------
.. [1] M. Mancuso, F. Ubertini (2002), The Nørsett time integration methodology for finite element
   transient analysis, Comput. Methods Appl. Mech. Engrg. 191, 3297-3327.
.. [2] M. Mancuso, F. Ubertini (2003), An efficient integration procedure for linear dynamics
   based on a time discontinuous Galerkin formulation, Comput. Mech. 32, 154-168.
.. [3] S.P. Nørsett (1976), Runge-Kutta methods with a multiple real eigenvalue only, BIT 16.
"""

from __future__ import annotations

import math

import numpy as np

from porefsi.errors import ConvergenceError, InputError
from porefsi.integrators._common import (
    MassOperator,
    StepInfo,
    check_dt,
    check_state,
    check_time,
    default_solver,
)
from porefsi.integrators.system import SecondOrderSystem, SolverFactory

__all__ = ["TDGStepper", "ALPHA", "LAMBDA", "T_MATRIX", "LOAD_ABSCISSAE", "RADAU_ABSCISSAE"]

#: Nørsett's L-stable double eigenvalue, :math:`\alpha^* = 1-\sqrt2/2`.
ALPHA = 1.0 - math.sqrt(2.0) / 2.0
#: Lagged coupling of pass l+1 to pass l, :math:`\lambda^* = \mathrm{tr}A_{Radau} - 2\alpha^* = \sqrt2-4/3`.
LAMBDA = math.sqrt(2.0) - 4.0 / 3.0
#: Stage change of basis, Radau IIA stage derivatives = ``T_MATRIX @`` Nørsett stage derivatives.
T_MATRIX = np.array([[2.0 * math.sqrt(2.0) / 3.0, 1.0 - 2.0 * math.sqrt(2.0) / 3.0], [0.0, 1.0]])
#: Its inverse (rows sum to one).
T_INVERSE = np.array([[3.0 * math.sqrt(2.0) / 4.0, 1.0 - 3.0 * math.sqrt(2.0) / 4.0], [0.0, 1.0]])
#: Where the external load is sampled, as fractions of the step: the paper's left Radau abscissae,
#: or the right Radau ones (``load_rule="right"``).
LOAD_ABSCISSAE = {"left": (0.0, 2.0 / 3.0), "right": (1.0 / 3.0, 1.0)}
#: Where the internal force is evaluated, as fractions of the step (right Radau abscissae).
RADAU_ABSCISSAE = (1.0 / 3.0, 1.0)

_POLICIES = ("step", "frozen", "auto")


def effective_loads(f0: np.ndarray, f23: np.ndarray, load_rule: str = "left") -> tuple[np.ndarray, np.ndarray]:
    r"""Stage loads :math:`F_0, F_1` from the samples at :math:`t` and :math:`t+2\Delta t/3`.

    .. math::
        F_0 = (\tfrac{3\sqrt2}{4}-\tfrac12) f_0 + \tfrac{6-3\sqrt2}{4} f_{2/3},\qquad
        F_1 = \tfrac32 f_{2/3} - \tfrac12 f_0,

    the linear interpolant of the samples evaluated at the stage abscissae :math:`\alpha^*` and 1.
    (The paper's eq. 2.21 prints the second weight without the /4; its weights then sum to 2.32.)
    With ``load_rule="right"`` the samples are at :math:`t+\Delta t/3` and :math:`t+\Delta t` and
    the same interpolation gives :math:`F_0 = \tfrac{3\sqrt2}{4}f_{1/3} + (1-\tfrac{3\sqrt2}{4})f_1`,
    :math:`F_1 = f_1`.
    """
    s0, s1 = LOAD_ABSCISSAE[load_rule]
    w0 = (ALPHA - s0) / (s1 - s0)
    w1 = (1.0 - s0) / (s1 - s0)
    return (1.0 - w0) * f0 + w0 * f23, (1.0 - w1) * f0 + w1 * f23


class TDGStepper:
    r"""Piecewise-linear TDG step by the Nørsett-type predictor-corrector.

    Parameters
    ----------
    system : SecondOrderSystem
        The model (mass, internal force, tangent, external load) on its free dofs.
    dt : float
        Time step, s (> 0).
    n_iter : int, default 2
        Corrector passes. 1 gives the L-stable SDIRK (order 2), 2 the paper's third-order scheme;
        more passes converge to the exact TDG step. With ``rtol`` set this is the maximum.
    make_solver : callable, optional
        ``make_solver(A) -> solve(b)`` for :math:`M^*`; default sparse LU. Called once per
        distinct :math:`M^*` (new ``dt`` or refreshed tangent).
    rtol : float, optional
        Iterate until the relative stage update is below ``rtol`` (then ``n_iter`` is the
        maximum and :class:`ConvergenceError` is raised if it is reached).
    tangent : {"step", "frozen", "auto"}, default "step"
        When :math:`K` in :math:`M^*` is re-evaluated. ``"step"``: at :math:`u_n` every step (the
        factorisation is reused when ``system.tangent`` returns the same matrix object, as for a
        linear system). ``"frozen"``: once, at the first step. ``"auto"``: kept until a secant
        check shows it stale: :math:`\|\Delta f_{int} - K\Delta u\| > ` ``tangent_rtol``
        :math:`\|\Delta f_{int}\|` over a step triggers a refresh at the next step.
    tangent_rtol : float, default 0.1
        Staleness threshold of the ``"auto"`` policy.
    load_rule : {"left", "right"}, default "left"
        Load samples at :math:`t, t+2\Delta t/3` (the paper's left Radau rule) or at
        :math:`t+\Delta t/3, t+\Delta t` (right Radau). Both give third order for resolved
        dynamics. For stiff, quasi-statically responding modes (:math:`\omega\Delta t\gg1`, the
        normal case for a rock mesh under coupling-sized steps) the end displacement follows the
        load *extrapolated* to :math:`t+\Delta t` under the left rule (an :math:`O(\Delta t^2)`
        error), and the exact end load under the right rule (third order kept).

    Notes
    -----
    Per pass: two internal-force evaluations (at :math:`t_n+\Delta t/3` and :math:`t_n+\Delta t`),
    two solves with :math:`M^*`, three products with :math:`K`. The external load is sampled at
    :meth:`load_times`; pass ``loads=`` to :meth:`step` to provide those samples directly (the
    coupling does, with pore forces computed at exactly those times).
    """

    def __init__(
        self,
        system: SecondOrderSystem,
        dt: float,
        n_iter: int = 2,
        make_solver: SolverFactory | None = None,
        rtol: float | None = None,
        tangent: str = "step",
        tangent_rtol: float = 0.1,
        load_rule: str = "left",
    ):
        if not isinstance(system, SecondOrderSystem):
            raise InputError(f"system {type(system).__name__} does not implement SecondOrderSystem")
        if int(n_iter) != n_iter or n_iter < 1:
            raise InputError(f"n_iter={n_iter!r} must be an integer >= 1 (2 for the third-order scheme)")
        if tangent not in _POLICIES:
            raise InputError(f"tangent={tangent!r} is not one of {_POLICIES}")
        if load_rule not in LOAD_ABSCISSAE:
            raise InputError(f"load_rule={load_rule!r} is not one of {tuple(LOAD_ABSCISSAE)}")
        if rtol is not None and not (0.0 < float(rtol) < 1.0):
            raise InputError(f"rtol={rtol!r} must be in (0, 1)")
        self.system = system
        self.dt = check_dt(dt)
        self.n_iter = int(n_iter)
        self.rtol = None if rtol is None else float(rtol)
        self.tangent_policy = tangent
        self.tangent_rtol = float(tangent_rtol)
        self.load_rule = load_rule
        self._make_solver = make_solver or default_solver
        self._mass = MassOperator(system.mass(), self._make_solver)
        self._n = int(system.n_dofs)
        self._K = None  # tangent currently factored into M*
        self._solve = None
        self._stale = True

    def __repr__(self) -> str:
        return f"TDGStepper(n_dofs={self._n}, dt={self.dt!r}, n_iter={self.n_iter}, tangent={self.tangent_policy!r})"

    def load_times(self, t: float) -> tuple[float, float]:
        """Times at which :meth:`step` samples the external load (``t``, ``t + 2 dt / 3`` by default)."""
        s0, s1 = LOAD_ABSCISSAE[self.load_rule]
        return (t + s0 * self.dt, t + s1 * self.dt)

    def _update_tangent(self, u, t) -> int:
        if self.tangent_policy == "step" or self._K is None or (self.tangent_policy == "auto" and self._stale):
            K = self.system.tangent(u, t)
        else:
            return 0
        self._stale = False
        if K is self._K and self._solve is not None:
            return 0
        self._K = K
        self._solve = self._make_solver(self._mass.add_scaled(ALPHA**2 * self.dt**2, K))
        return 1

    def step(self, u, v, t: float, loads=None) -> tuple[np.ndarray, np.ndarray, StepInfo]:
        """Advance one step from ``(u, v)`` at time ``t``.

        Parameters
        ----------
        u, v : ndarray (n,)
            Displacement (m) and velocity (m/s) at ``t``.
        t : float
            Start time of the step, s.
        loads : tuple of two ndarray (n,), optional
            External load (N) at :meth:`load_times`; sampled from the system when omitted.

        Returns
        -------
        u_new, v_new : ndarray (n,)
            State at ``t + dt``.
        info : StepInfo
            ``residual_norms`` are the force residuals (N) of the TDG equations at the start of
            each pass; ``extra['tangent_defect']`` is the secant check value (``"auto"`` policy).
        """
        n = self._n
        u = check_state("u", u, n)
        v = check_state("v", v, n)
        t = check_time(t)
        if loads is None:
            f0, f23 = (self.system.external_force(s) for s in self.load_times(t))
        else:
            f0, f23 = loads
        F = effective_loads(check_state("loads[0]", f0, n), check_state("loads[1]", f23, n), self.load_rule)
        n_fact = self._update_tangent(u, t)
        ku = [np.zeros(n), np.zeros(n)]
        kv = [np.zeros(n), np.zeros(n)]
        norms, n_solves, converged = [], 0, self.rtol is None
        f_first = du_last = f_last = None
        for it in range(self.n_iter):
            ku, kv, dk, U1, fR1 = self._pass(u, v, t, ku, kv, F, norms)
            n_solves += 2
            if it == 0:
                f_first = fR1
            else:
                du_last, f_last = U1 - u, fR1
            if self.rtol is not None and max(_rel(dk[0], ku[0]), _rel(dk[1], ku[1]), _rel(dk[2], kv[0]),
                                             _rel(dk[3], kv[1])) <= self.rtol:
                converged = True
                break
        if not converged:
            raise ConvergenceError(
                f"TDG corrector did not reach rtol={self.rtol} in {self.n_iter} passes at t={t!r} s; "
                "raise n_iter or reduce dt (stiff modes contract by ~0.94 per pass)",
                norms,
            )
        g, dt = ALPHA, self.dt
        u_new = u + dt * ((1 - g) * ku[0] + g * ku[1])
        v_new = v + dt * ((1 - g) * kv[0] + g * kv[1])
        extra = {} if du_last is None else {"tangent_defect": self._tangent_defect(du_last, f_first, f_last)}
        info = StepInfo(iterations=len(norms), residual_norms=tuple(norms), n_solves=n_solves,
                        n_factorizations=n_fact, converged=converged, extra=extra)
        return u_new, v_new, info

    def _pass(self, u, v, t, ku, kv, F, norms: list):
        """One Nørsett predictor-corrector pass on the stage increments ``ku``, ``kv``.

        Appends the force residual norm at the start of the pass (N) to ``norms``; returns the
        corrected ``ku``, ``kv``, the corrections ``(dku0, dku1, dkv0, dkv1)`` and the end-of-step
        stage state ``U1`` with its internal force ``fR1`` (for the secant check).
        """
        dt, g, lam = self.dt, ALPHA, LAMBDA
        K, solve, mass, Ti = self._K, self._solve, self._mass, T_INVERSE
        # stage states in the Nørsett basis (A' = [[g+lam, -lam], [1-g, g]])
        U0 = u + dt * ((g + lam) * ku[0] - lam * ku[1])
        V0 = v + dt * ((g + lam) * kv[0] - lam * kv[1])
        U1 = u + dt * ((1 - g) * ku[0] + g * ku[1])
        V1 = v + dt * ((1 - g) * kv[0] + g * kv[1])
        # internal force at the Radau points, mapped back to the Nørsett basis with T^-1
        UR0 = T_MATRIX[0, 0] * U0 + T_MATRIX[0, 1] * U1
        fR0 = self.system.internal_force(UR0, t + RADAU_ABSCISSAE[0] * dt)
        fR1 = self.system.internal_force(U1, t + RADAU_ABSCISSAE[1] * dt)
        rv0 = mass.apply(kv[0]) + Ti[0, 0] * fR0 + Ti[0, 1] * fR1 - F[0]
        rv1 = mass.apply(kv[1]) + fR1 - F[1]
        ru0, ru1 = ku[0] - V0, ku[1] - V1
        norms.append(float(math.hypot(np.linalg.norm(rv0), np.linalg.norm(rv1))))
        if not np.isfinite(norms[-1]):
            raise ConvergenceError(f"TDG residual is not finite at t={t!r} s (pass {len(norms)}); reduce dt", norms)
        # lower-triangular (Nørsett) correction: two solves with M* = M + g^2 dt^2 K
        dkv0 = solve(-rv0 + g * dt * (K @ ru0))
        dku0 = -ru0 + g * dt * dkv0
        dkv1 = solve(-rv1 - (1 - g) * dt * (K @ (dku0 + g * dt * dkv0)) + g * dt * (K @ ru1))
        dku1 = -ru1 + dt * ((1 - g) * dkv0 + g * dkv1)
        return [ku[0] + dku0, ku[1] + dku1], [kv[0] + dkv0, kv[1] + dkv1], (dku0, dku1, dkv0, dkv1), U1, fR1

    def _tangent_defect(self, du, f_first, f_last) -> float:
        """Secant check of the factorised tangent over the step; flags it stale (``"auto"``) when it fails."""
        df = f_last - f_first
        ndf = float(np.linalg.norm(df))
        defect = float(np.linalg.norm(df - self._K @ du)) / ndf if ndf > 0 else 0.0
        if self.tangent_policy == "auto" and defect > self.tangent_rtol:
            self._stale = True
        return defect


def _rel(d: np.ndarray, x: np.ndarray) -> float:
    nx = float(np.linalg.norm(x))
    nd = float(np.linalg.norm(d))
    return nd / nx if nx > 0 else (0.0 if nd == 0 else math.inf)
