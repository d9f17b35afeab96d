r"""Amplification matrices and spectral radii of the integrators, measured on the real code.

Each scheme is applied, through its own stepper class, to the single-dof oscillator
:math:`\ddot u + \omega^2 u = 0` with :math:`\Delta t = 1`; stepping each unit state gives one
column of the amplification matrix :math:`A(\omega\Delta t)` (2x2 on :math:`(u, v)`; 3x3 on
:math:`(u, v, a)` for schemes that carry the acceleration). The spectral radius
:math:`\rho = \max|\mathrm{eig}\,A|` is the per-step amplification of the worst mode: > 1 is
instability, 1 is no numerical dissipation, 0 annihilates that frequency in one step. Nothing
here is a typed closed form; the closed forms live in the tests, which compare against this.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from porefsi.errors import InputError
from porefsi.integrators.central_difference import CentralDifferenceStepper
from porefsi.integrators.generalized_alpha import GeneralizedAlphaStepper
from porefsi.integrators.newmark import NewmarkStepper
from porefsi.integrators.system import LinearSystem
from porefsi.integrators.tdg import TDGStepper
from porefsi.integrators.tdg_exact import TDGExactStepper

__all__ = ["SCHEMES", "amplification_matrix", "modal_amplification_matrix", "spectral_radius"]

#: name -> (stepper class, carries acceleration state)
SCHEMES: dict[str, tuple[Callable, bool]] = {
    "tdg": (TDGStepper, False),
    "tdg_exact": (TDGExactStepper, False),
    "newmark": (NewmarkStepper, False),
    "generalized_alpha": (GeneralizedAlphaStepper, True),
    "central_difference": (CentralDifferenceStepper, True),
}


def amplification_matrix(scheme: str, omega_dt: float, **options) -> np.ndarray:
    r"""Amplification matrix of ``scheme`` for :math:`\omega\Delta t` = ``omega_dt``.

    Parameters
    ----------
    scheme : str
        One of :data:`SCHEMES`.
    omega_dt : float
        Non-dimensional frequency :math:`\omega\Delta t` (> 0).
    **options
        Passed to the stepper (e.g. ``n_iter=1`` for TDG, ``rho_inf=0.5``).

    Returns
    -------
    ndarray (2, 2) or (3, 3)
        Maps :math:`(u_n, v_n[, a_n])` to :math:`(u_{n+1}, v_{n+1}[, a_{n+1}])`, with
        :math:`\Delta t = 1` (so :math:`v` is in units of :math:`\omega`-free step lengths).
    """
    if scheme not in SCHEMES:
        raise InputError(f"unknown scheme {scheme!r}; choose one of {sorted(SCHEMES)}")
    w = float(omega_dt)
    if not np.isfinite(w) or w <= 0:
        raise InputError(f"omega_dt={omega_dt!r} must be finite and > 0")
    system = LinearSystem(np.array([1.0]), np.array([[w * w]]))
    return modal_amplification_matrix(scheme, system, 1.0, np.array([1.0]), np.array([1.0]), **options)


def modal_amplification_matrix(scheme: str, system, dt: float, phi: np.ndarray, weight: np.ndarray,
                               **options) -> np.ndarray:
    r"""Amplification matrix of one step of ``scheme`` on the mode ``phi`` of ``system``.

    Steps the unit modal states :math:`(u, v[, a]) = e_j\,\phi` and projects each result on
    :math:`\phi` (:math:`\phi^T W x`): the columns of that mode's amplification matrix. For a
    mode of a linear system its eigenvalues equal the one-dof matrix's at
    :math:`\omega\Delta t` (:func:`amplification_matrix` is this on a one-dof system).

    Parameters
    ----------
    scheme : str
        One of :data:`SCHEMES`.
    system : LinearSystem
        The (linear) system the stepper integrates.
    dt : float
        Time step, s.
    phi : ndarray, shape (n,)
        The mode, W-orthonormal (:math:`\phi^T W \phi = 1`).
    weight : ndarray, shape (n,)
        Diagonal of W (e.g. the lumped mass), for the projection.
    **options
        Passed to the stepper.

    Returns
    -------
    ndarray (2, 2) or (3, 3)
    """
    if scheme not in SCHEMES:
        raise InputError(f"unknown scheme {scheme!r}; choose one of {sorted(SCHEMES)}")
    cls, with_a = SCHEMES[scheme]
    stepper = cls(system, float(dt), **options)
    phi = np.asarray(phi, dtype=float)
    weight = np.asarray(weight, dtype=float)
    m = 3 if with_a else 2
    A = np.empty((m, m))
    for j in range(m):
        e = np.zeros(m)
        e[j] = 1.0
        if with_a:
            u1, v1, info = stepper.step(e[0] * phi, e[1] * phi, 0.0, a=e[2] * phi)
            cols = (u1, v1, info.extra["a"])
        else:
            u1, v1, _ = stepper.step(e[0] * phi, e[1] * phi, 0.0)
            cols = (u1, v1)
        A[:, j] = [phi @ (weight * x) for x in cols]
    return A


def spectral_radius(scheme: str, omega_dt, **options) -> np.ndarray:
    """Spectral radius of :func:`amplification_matrix` for each value of ``omega_dt``."""
    w = np.atleast_1d(np.asarray(omega_dt, dtype=float))
    out = np.array([np.max(np.abs(np.linalg.eigvals(amplification_matrix(scheme, x, **options)))) for x in w])
    return out if np.ndim(omega_dt) else out[0]
