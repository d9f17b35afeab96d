r"""Aitken's dynamic relaxation of a fixed-point iteration (fluid-solid sub-iterations).

For the iteration :math:`U_{k+1} = U_k + \omega_k r_k` with residual :math:`r_k = G(U_k) - U_k`,
Aitken's factor is

.. math:: \omega_k = -\omega_{k-1}\,\frac{r_{k-1}\cdot(r_k - r_{k-1})}{\|r_k - r_{k-1}\|^2},

which is exact for a linear one-dimensional map and contracts the error of a scalar-dominated
one (Irons & Tuck 1969; Küttler & Wall 2008).

References
----------
.. [1] Irons, B. M., Tuck, R. C. (1969). A version of the Aitken accelerator for computer
   iteration. Int. J. Numer. Methods Eng. 1, 275-277.
.. [2] Küttler, U., Wall, W. A. (2008). Fixed-point fluid-structure interaction solvers with
   dynamic relaxation. Comput. Mech. 43, 61-72.
"""

from __future__ import annotations

import numpy as np

__all__ = ["aitken_omega", "Relaxation"]


def aitken_omega(omega_prev: float, r: np.ndarray, r_prev: np.ndarray | None) -> float:
    """Aitken relaxation factor for the residual ``r`` after ``r_prev`` (same shape, any units).

    Parameters
    ----------
    omega_prev : float
        The factor used for ``r_prev``.
    r, r_prev : ndarray
        Current and previous residuals; ``r_prev`` None (first iteration) keeps ``omega_prev``.

    Returns
    -------
    float
        The next factor; ``omega_prev`` when the residual did not change (no information).

    Examples
    --------
    >>> import numpy as np
    >>> # the linear map G(U) = 0.5 U + 1 (fixed point 2): from U0 = 0, r0 = 1; U1 = 1, r1 = 0.5
    >>> aitken_omega(1.0, np.array([0.5]), np.array([1.0]))
    2.0
    """
    if r_prev is None:
        return float(omega_prev)
    dr = np.asarray(r, dtype=float) - np.asarray(r_prev, dtype=float)
    den = float(np.vdot(dr, dr))
    return -float(omega_prev) * float(np.vdot(r_prev, dr)) / den if den > 0 else float(omega_prev)


class Relaxation:
    """The relaxed fixed-point iteration of one exchange step's displacement (sub-iterations).

    Iterate ``k`` gives the solid's answer ``U1`` to the network of the previous iterate; the
    residual is ``r_k = U1 - U_k`` (``U_0``: the displacement at the start of the step) and the
    next iterate ``U_{k+1} = U_k + omega_k r_k``, with Aitken's ``omega_k`` or 1.

    Parameters
    ----------
    start : ndarray
        Displacement at the start of the step (any shape), m.
    aitken : bool, default True
        Aitken's dynamic factor; False iterates plainly (``omega = 1``).

    Attributes
    ----------
    residuals : list of float
        ``|r_k| / |U1|`` of each iterate.
    omegas : list of float
        The factor used after each iterate.
    """

    def __init__(self, start: np.ndarray, aitken: bool = True):
        self.start, self.aitken = start, bool(aitken)
        self.current: np.ndarray | None = None
        self._omega, self._r_prev = 1.0, None
        self.residuals: list[float] = []
        self.omegas: list[float] = []

    def __call__(self, U1: np.ndarray) -> np.ndarray:
        """The next (relaxed) iterate after the solid answered ``U1``."""
        base = self.start if self.current is None else self.current
        r = U1 - base
        if self.aitken:
            self._omega = aitken_omega(self._omega, r, self._r_prev)
        self.residuals.append(float(np.linalg.norm(r)) / max(float(np.linalg.norm(U1)), 1e-300))
        self.current, self._r_prev = base + self._omega * r, r
        self.omegas.append(float(self._omega))
        return self.current
