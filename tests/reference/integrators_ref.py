"""Slow, literal twins of the integrators (dense NumPy), and closed forms derived by hand.

``paper_tdg_step`` transcribes eqs 2.18-2.24 of the seed paper line by line (with the corrected
F0 weight, see docs/time_integration.md) for a linear system; the production TDGStepper is a
residual/Newton form of the same iteration and must agree with it to round-off.
"""

from __future__ import annotations

import math

import numpy as np

ALPHA = 1.0 - math.sqrt(2.0) / 2.0
LAMBDA = math.sqrt(2.0) - 4.0 / 3.0


def paper_tdg_step(M, K, fext, u, v, t, dt, n_iter=2, fint=None):
    """One step of eqs 2.18-2.24 (predictor form), dense.

    ``fint=None`` is the linear scheme (``K @ u_tilde``). A callable ``fint(u)`` gives the
    *literal nonlinear reading* ``M* vbar = F - fint(u_tilde)`` (tangent ``K`` in ``M*``), which
    converges to a second-order method; kept to document why porefsi does not use it.
    """
    a, lam = ALPHA, LAMBDA
    f0, f23 = fext(t), fext(t + 2.0 * dt / 3.0)
    F = [(3 * math.sqrt(2) / 4 - 0.5) * f0 + (6 - 3 * math.sqrt(2)) / 4 * f23, 1.5 * f23 - 0.5 * f0]
    Ms = M + a * a * dt * dt * K
    force = (lambda x: K @ x) if fint is None else fint
    n = len(u)
    ubar = [np.zeros(n), np.zeros(n)]
    vbar = [np.zeros(n), np.zeros(n)]
    for _ in range(n_iter):
        vt0 = v + lam * dt * (vbar[0] - vbar[1])                                # 2.19a
        ut0 = u + lam * dt * (ubar[0] - ubar[1]) + a * dt * vt0                 # 2.19b
        vb0 = np.linalg.solve(Ms, F[0] - force(ut0))                            # 2.18
        ub0 = vt0 + a * dt * vb0                                                # 2.18
        vt1 = v + (1 - a) * dt * vb0                                            # 2.19c
        ut1 = u + (1 - a) * dt * ub0 + a * dt * vt1                             # 2.19d
        vb1 = np.linalg.solve(Ms, F[1] - force(ut1))                            # 2.18
        ub1 = vt1 + a * dt * vb1
        ubar, vbar = [ub0, ub1], [vb0, vb1]
    return u + dt * ((1 - a) * ubar[0] + a * ubar[1]), ubar[1]               # 2.24


def r_sdirk(z):
    """Pass 1 = Alexander's L-stable SDIRK2: (1 + (1-2a) z) / (1 - a z)^2."""
    return (1 + (1 - 2 * ALPHA) * z) / (1 - ALPHA * z) ** 2


def r_tdg2(z):
    """Pass 2 (derived in docs/time_integration.md): R1(z) - (lambda/2) z^3 / (1 - a z)^4."""
    return r_sdirk(z) - 0.5 * LAMBDA * z**3 / (1 - ALPHA * z) ** 4


def r_tdg_exact(z):
    """Exact piecewise-linear TDG = (1,2)-Pade approximant of exp(z)."""
    return (1 + z / 3) / (1 - 2 * z / 3 + z * z / 6)


def rho_central_difference(w):
    """Spectral radius of central difference: 1 for w <= 2, else the larger real root."""
    w = np.asarray(w, float)
    h = (w * w - 2.0) / 2.0
    return np.where(w <= 2.0, 1.0, h + np.sqrt(np.maximum(h * h - 1.0, 0.0)))
