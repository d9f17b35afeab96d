"""Newton-Raphson with backtracking line search, shared by the implicit reference integrators."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from porefsi.errors import ConvergenceError

__all__ = ["newton"]


def _step(residual, x: np.ndarray, dx: np.ndarray, nr: float, line_search: bool):
    """``x + alpha dx`` with the step halved (to 1/32 at most) while |r| misses the Armijo decrease.

    Returns the new iterate, its residual, the residual's norm and its scale.
    """
    alpha = 1.0
    while True:
        x_try = x + alpha * dx
        r_try, scale_try = residual(x_try)
        nr_try = float(np.linalg.norm(r_try))
        if not line_search or nr_try <= (1.0 - 1e-4 * alpha) * nr or alpha < 1.0 / 32.0:
            return x_try, r_try, nr_try, scale_try
        alpha *= 0.5


def newton(
    residual: Callable[[np.ndarray], tuple[np.ndarray, float]],
    jacobian: Callable[[np.ndarray], object],
    x0: np.ndarray,
    make_solver,
    rtol: float = 1e-10,
    max_iter: int = 25,
    line_search: bool = True,
    what: str = "Newton solve",
) -> tuple[np.ndarray, list[float], int, int]:
    r"""Solve :math:`r(x) = 0` by Newton's method with an Armijo backtracking line search.

    Parameters
    ----------
    residual : callable
        ``residual(x) -> (r, scale)``; converged when :math:`\|r\| \le` ``rtol`` ``* max(scale, |r_0|)``
        (``scale`` is the size of the largest term that makes up ``r`` at the current iterate, in
        its units; the initial residual guards against terms that cancelled to round-off).
    jacobian : callable
        ``jacobian(x) -> A``; the solver is re-made only when a different object is returned
        (a linear problem returning the same matrix is factored once).
    x0 : ndarray (n,)
        Initial guess (not modified).
    make_solver : callable
        Solver factory ``make_solver(A) -> solve(b)``.
    rtol : float
        Relative tolerance.
    max_iter : int
        Maximum Newton iterations.
    line_search : bool
        Halve the step (at most 6 times) while :math:`\|r\|` does not decrease by the Armijo factor.
    what : str
        Name used in error messages.

    Returns
    -------
    x : ndarray (n,)
    history : list of float
        :math:`\|r\|` at every iterate, first to last.
    n_solves, n_factorizations : int

    Raises
    ------
    ConvergenceError
        Not converged in ``max_iter`` iterations or a non-finite residual; carries ``history``.
    """
    x = np.array(x0, dtype=float, copy=True)
    r, scale = residual(x)
    nr = float(np.linalg.norm(r))
    history = [nr]
    A_last, solve, n_solves, n_fact = None, None, 0, 0
    for _ in range(max_iter + 1):
        if not np.isfinite(nr):
            raise ConvergenceError(f"{what}: residual became non-finite; reduce the step", history)
        if nr <= rtol * max(scale, history[0]) or nr == 0.0:
            return x, history, n_solves, n_fact
        if len(history) > max_iter:
            break
        A = jacobian(x)
        try:
            if A is not A_last or solve is None:
                solve, A_last = make_solver(A), A
                n_fact += 1
            dx = -solve(r)
        except (RuntimeError, ArithmeticError, ValueError) as err:  # singular / failed linear solve
            raise ConvergenceError(f"{what}: linear solve failed ({err}); the tangent is singular", history) from err
        n_solves += 1
        if not np.all(np.isfinite(dx)):
            raise ConvergenceError(f"{what}: Newton update is not finite; the tangent is singular", history)
        x, r, nr, scale = _step(residual, x, dx, nr, line_search)
        history.append(nr)
    raise ConvergenceError(
        f"{what}: not converged in {max_iter} iterations (|r| {history[0]:.3e} -> {history[-1]:.3e}, "
        f"target {rtol * max(scale, history[0]):.3e}); reduce the step or use load stepping",
        history,
    )
