"""Shared plumbing of the time integrators: validation, solver factories, info objects, time loop.

Nothing here knows about a particular scheme. Every stepper in :mod:`porefsi.integrators`
exposes ``dt`` and ``step(u, v, t) -> (u_new, v_new, info)``; :func:`integrate` turns a
stepper into a generator of ``(t, u, v)`` (DESIGN.md: time loops are generators).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from porefsi.errors import InputError

__all__ = ["StepInfo", "default_solver", "integrate"]


@dataclass(frozen=True)
class StepInfo:
    """What one time step did (returned with every step, never printed).

    Attributes
    ----------
    iterations : int
        Corrector passes (TDG) or Newton iterations (implicit Newmark-type schemes).
    residual_norms : tuple of float
        Residual norm (N, Euclidean over the dofs) at the start of each iteration.
    n_solves : int
        Linear solves with the effective matrix during the step.
    n_factorizations : int
        New effective matrices handed to the solver factory during the step (0 when reused).
    converged : bool
        Whether a convergence criterion (when one was requested) was met.
    extra : dict
        Scheme-specific values (e.g. ``a``, the end-of-step acceleration, for the
        generalized-alpha and central-difference steppers).
    """

    iterations: int
    residual_norms: tuple = ()
    n_solves: int = 0
    n_factorizations: int = 0
    converged: bool = True
    extra: dict = field(default_factory=dict)


def default_solver(A) -> Callable[[np.ndarray], np.ndarray]:
    """Direct sparse LU factorisation of ``A`` (or exact division for a diagonal ndarray).

    Parameters
    ----------
    A : sparse matrix (n, n) or ndarray (n,)
        The matrix to factor; a 1-D array is a diagonal.

    Returns
    -------
    callable
        ``solve(b) -> x`` with ``x`` of the shape of ``b``.
    """
    if isinstance(A, np.ndarray) and A.ndim == 1:
        d = A.copy()
        return lambda b: np.asarray(b, dtype=float) / d
    lu = spla.splu(sp.csc_matrix(A))
    return lambda b: lu.solve(np.asarray(b, dtype=float))


def check_dt(dt: float) -> float:
    """Return ``dt`` as float or raise :class:`InputError` if it is not finite and positive."""
    dt = float(dt)
    if not np.isfinite(dt) or dt <= 0.0:
        raise InputError(f"time step dt={dt!r} s must be finite and > 0; pass a positive step")
    return dt


def check_state(name: str, x, n: int) -> np.ndarray:
    """Return ``x`` as a float (n,) array or raise :class:`InputError` (wrong shape, NaN/inf)."""
    a = np.asarray(x, dtype=float)
    if a.shape != (n,):
        raise InputError(f"{name} has shape {a.shape}, expected ({n},) (one entry per free dof)")
    if not np.all(np.isfinite(a)):
        bad = int(np.flatnonzero(~np.isfinite(a))[0])
        raise InputError(
            f"{name} is not finite (first bad entry {name}[{bad}]={a[bad]!r}); the previous step "
            "diverged or the initial state is corrupt: reduce dt or use an L-stable scheme (TDG)"
        )
    return a


def check_time(t: float) -> float:
    """Return ``t`` as float or raise :class:`InputError` if it is not finite."""
    t = float(t)
    if not np.isfinite(t):
        raise InputError(f"time t={t!r} must be finite")
    return t


def same_state(last, u, v, t: float, dt: float) -> bool:
    """Whether ``(u, v, t)`` is the state ``last = (t, u, v, a)`` a stepper returned (t to 1e-9 dt)."""
    return (
        last is not None
        and abs(last[0] - t) <= 1e-9 * dt
        and np.array_equal(last[1], u)
        and np.array_equal(last[2], v)
    )


class MassOperator:
    """The mass matrix of a system as an operator: ``apply``, ``solve`` and ``add_scaled``.

    A lumped mass (1-D ndarray) is kept as a vector so that ``M + c K`` costs one diagonal
    update of ``K`` instead of a sparse sum.
    """

    def __init__(self, M, make_solver):
        if sp.issparse(M):
            self.M = sp.csr_matrix(M, dtype=float)
            self.lumped = False
        else:
            self.M = np.asarray(M, dtype=float)
            if self.M.ndim != 1:
                self.M = sp.csr_matrix(self.M)
                self.lumped = False
            else:
                self.lumped = True
                if np.any(self.M <= 0) or not np.all(np.isfinite(self.M)):
                    raise InputError("lumped mass has non-positive or non-finite entries; check density")
        self._make_solver = make_solver
        self._solve = None

    @property
    def shape(self):
        """Matrix shape (n, n)."""
        n = self.M.shape[0]
        return (n, n)

    def apply(self, x: np.ndarray) -> np.ndarray:
        """``M @ x``."""
        return self.M * x if self.lumped else self.M @ x

    def solve(self, b: np.ndarray) -> np.ndarray:
        """``M^{-1} b`` (the factorisation of a consistent mass is made once and kept)."""
        if self.lumped:
            return b / self.M
        if self._solve is None:
            self._solve = self._make_solver(self.M)
        return self._solve(b)

    def add_scaled(self, c: float, K) -> sp.csr_matrix:
        """``M + c K`` as a CSR matrix (cheap diagonal update when the mass is lumped)."""
        K = sp.csr_matrix(K, dtype=float)
        if self.lumped:
            return (c * K + sp.diags(self.M)).tocsr()
        return (self.M + c * K).tocsr()


def integrate(stepper, u0, v0, t0: float, t_end: float) -> Iterator[tuple[float, np.ndarray, np.ndarray]]:
    """Advance ``stepper`` from ``t0`` to ``t_end``, yielding ``(t, u, v)`` after every step.

    The initial state is yielded first. The number of steps is ``round((t_end - t0) / dt)``;
    a range that is not a whole number of steps (to 1e-9 relative) is an error, so that the
    last yielded time is exactly ``t0 + n dt`` and never overshoots silently.

    Parameters
    ----------
    stepper : object
        Has ``dt`` (s) and ``step(u, v, t) -> (u, v, info)``.
    u0, v0 : ndarray (n,)
        Initial displacement (m) and velocity (m/s).
    t0, t_end : float
        Start and end times, s.

    Yields
    ------
    t : float
    u, v : ndarray (n,)
    """
    dt = stepper.dt
    span = float(t_end) - float(t0)
    n_steps = round(span / dt)
    if span < 0 or abs(n_steps * dt - span) > 1e-9 * max(abs(span), dt):
        raise InputError(
            f"t_end - t0 = {span!r} s is not a non-negative whole number of steps dt={dt!r} s; "
            "choose t_end = t0 + n*dt"
        )
    u, v = np.asarray(u0, float).copy(), np.asarray(v0, float).copy()
    yield float(t0), u, v
    for k in range(n_steps):
        t = float(t0) + k * dt
        u, v, _ = stepper.step(u, v, t)
        yield float(t0) + (k + 1) * dt, u, v
