r"""Quasi-static response: Newton solve of :math:`f_{int}(u,t) = f_{ext}(t)` (no inertia).

Elastic wave periods of a micro-CT rock mesh (~1e-7 s) are far below any pore-filling time
scale, so the solid is quasi-static in practice and this is the cheap model when inertia cannot
matter. Loads and prescribed boundary motion are functions of ``t``; when Newton fails at a
target time the interval from the last converged time is bisected (load stepping).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator

import numpy as np

from porefsi.errors import ConvergenceError, InputError
from porefsi.integrators._common import StepInfo, check_dt, check_state, check_time, default_solver
from porefsi.integrators._newton import newton
from porefsi.integrators.system import SecondOrderSystem, SolverFactory

__all__ = ["solve_static", "quasistatic", "QuasiStaticStepper"]


def solve_static(
    system: SecondOrderSystem,
    t: float,
    u0=None,
    make_solver: SolverFactory | None = None,
    rtol: float = 1e-10,
    max_iter: int = 25,
    line_search: bool = True,
) -> tuple[np.ndarray, StepInfo]:
    r"""Newton-Raphson solve of :math:`f_{int}(u, t) = f_{ext}(t)`.

    Parameters
    ----------
    system : SecondOrderSystem
        The model (its mass is not used).
    t : float
        Time at which loads and prescribed motion are evaluated, s.
    u0 : ndarray (n,), optional
        Initial guess, m (zeros when omitted).
    make_solver : callable, optional
        Factory for the tangent (default sparse LU).
    rtol : float
        Tolerance on :math:`\|f_{int}-f_{ext}\|` relative to :math:`\max(\|f_{int}\|,\|f_{ext}\|)`.
    max_iter : int
        Newton iterations.
    line_search : bool
        Armijo backtracking on the residual norm.

    Returns
    -------
    u : ndarray (n,)
    info : StepInfo
        ``residual_norms`` is the Newton history (N).

    Raises
    ------
    ConvergenceError
        With the residual history when Newton does not converge.
    """
    n = int(system.n_dofs)
    t = check_time(t)
    u0 = np.zeros(n) if u0 is None else check_state("u0", u0, n)
    f = system.external_force(t)

    def residual(x):
        fi = system.internal_force(x, t)
        return fi - f, max(np.linalg.norm(fi), np.linalg.norm(f), 1e-300)

    x, hist, ns, nf = newton(
        residual, lambda x: system.tangent(x, t), u0, make_solver or default_solver,
        rtol=rtol, max_iter=max_iter, line_search=line_search, what=f"static solve at t={t!r} s",
    )
    return x, StepInfo(len(hist) - 1, tuple(hist), ns, nf)


def quasistatic(
    system: SecondOrderSystem,
    u0,
    times: Iterable[float],
    max_bisections: int = 8,
    **newton_kw,
) -> Iterator[tuple[float, np.ndarray, StepInfo]]:
    """Generator of quasi-static states ``(t, u, info)`` at the given increasing ``times``.

    Each state starts Newton from the previous one; a failed solve is retried on halved
    sub-intervals (up to ``max_bisections`` levels) before :class:`ConvergenceError` is raised.
    ``info.extra['substeps']`` counts the sub-increments used. ``newton_kw`` go to
    :func:`solve_static`.
    """
    n = int(system.n_dofs)
    u = check_state("u0", u0, n)
    t_prev = None
    for t in times:
        t = check_time(t)
        if t_prev is not None and t <= t_prev:
            raise InputError(f"times must increase; got {t!r} after {t_prev!r}")
        if t_prev is None:
            u, info = solve_static(system, t, u, **newton_kw)
            t_prev = t
            yield t, u, StepInfo(info.iterations, info.residual_norms, info.n_solves,
                                 info.n_factorizations, extra={"substeps": 1})
            continue
        stack, t_done, sub, hist, last = [t], t_prev, 0, [], None
        while stack:
            target = stack[-1]
            try:
                u_new, last = solve_static(system, target, u, **newton_kw)
            except ConvergenceError as err:
                hist.extend(err.history)
                if len(stack) > max_bisections:
                    raise ConvergenceError(
                        f"quasi-static load step {t_done!r} -> {target!r} s failed after {max_bisections} "
                        "bisections; the load path may pass a limit point (use arc length) or the "
                        "material/mesh may have failed",
                        hist,
                    ) from err
                stack.append(0.5 * (t_done + target))
                continue
            u, t_done = u_new, stack.pop()
            sub += 1
        t_prev = t
        yield t, u, StepInfo(last.iterations, last.residual_norms, last.n_solves, last.n_factorizations,
                             extra={"substeps": sub, "failed_history": tuple(hist)})


class QuasiStaticStepper:
    """:func:`solve_static` as a stepper for :func:`porefsi.integrators.integrate`.

    ``step(u, v, t)`` returns the equilibrium at ``t + dt`` and the finite-difference velocity
    ``(u_new - u) / dt``.
    """

    def __init__(self, system: SecondOrderSystem, dt: float, **newton_kw):
        self.system, self.dt, self._kw = system, check_dt(dt), newton_kw

    def step(self, u, v, t: float) -> tuple[np.ndarray, np.ndarray, StepInfo]:
        """Equilibrium at ``t + dt`` starting Newton from ``u``."""
        u = check_state("u", u, int(self.system.n_dofs))
        u1, info = solve_static(self.system, check_time(t) + self.dt, u, **self._kw)
        return u1, (u1 - u) / self.dt, info
