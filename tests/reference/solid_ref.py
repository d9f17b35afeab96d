"""Slow pure-Python twins of the solid kernels (porefsi/solid/_kernels.py).

Written independently of the library: shape-function gradients from the inverse of the
barycentric-coordinate matrix; the two hyperelastic laws written here from the textbooks (only
E and nu are read from the library's material object, never its Lame constants, stress or
moduli); the tangent moduli by complex-step differentiation of that stress (exact to round-off
for these analytic laws, and sharing no formula with the library's hand-derived moduli); a dense
element loop.

References
----------
.. [1] Holzapfel, G. A. (2000). Nonlinear Solid Mechanics, Wiley: St Venant-Kirchhoff, sec. 6.5;
   Lame constants from E and nu, sec. 6.6.
.. [2] Bonet, J. & Wood, R. D. (2008). Nonlinear Continuum Mechanics for Finite Element Analysis,
   2nd ed., Cambridge: compressible neo-Hookean, eq. 6.28 (P = mu (F - F^-T) + lam ln J F^-T).
.. [3] Martins, J. R. R. A., Sturdza, P., Alonso, J. J. (2003). The complex-step derivative
   approximation, ACM TOMS 29, 245-262.
"""

import numpy as np


def lame_ref(E, nu):
    """Lame constants (lambda, mu), Pa, of isotropic linear elasticity from Young's modulus and Poisson ratio."""
    lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    mu = E / (2.0 * (1.0 + nu))
    return lam, mu


def first_pk_ref(law, E, nu, H):
    """First Piola-Kirchhoff stress (3, 3), Pa, from the displacement gradient ``H = F - I``.

    ``law`` is ``"svk"`` or ``"neo-hookean"``. Written in ``H`` (not ``F^T F - I``) so that strains
    of 1e-11 keep their digits; accepts complex ``H`` (complex-step tangent).
    """
    lam, mu = lame_ref(E, nu)
    eye = np.eye(3)
    F = eye + H
    if law == "svk":
        # Green-Lagrange strain E = (C - I)/2 = (H + H^T + H^T H)/2, S = lam tr(E) I + 2 mu E, P = F S
        Egl = 0.5 * (H + H.T + H.T @ H)
        S = lam * np.trace(Egl) * eye + 2.0 * mu * Egl
        return F @ S
    if law == "neo-hookean":
        # F - F^-T = (F F^T - I) F^-T = (H + H^T + H H^T) F^-T;
        # J = det(I + H) = 1 + I1 + I2 + I3 (principal invariants of H, Cayley-Hamilton)
        FinvT = np.linalg.inv(F).T
        i1 = np.trace(H)
        i2 = 0.5 * (i1 * i1 - np.trace(H @ H))
        i3 = np.linalg.det(H)
        lnJ = np.log1p(i1 + i2 + i3)
        return mu * (H + H.T + H @ H.T) @ FinvT + lam * lnJ * FinvT
    raise ValueError(f"no reference law {law!r}")


def moduli_ref(law, E, nu, H, h=1e-30):
    """First elasticity tensor A_iJkL = dP_iJ/dF_kL (3, 3, 3, 3), Pa, by complex step."""
    A = np.empty((3, 3, 3, 3))
    for k in range(3):
        for L in range(3):
            dH = np.zeros((3, 3), complex)
            dH[k, L] = 1j * h
            A[:, :, k, L] = first_pk_ref(law, E, nu, H + dH).imag / h
    return A


def p1_gradients_ref(points, tets):
    """dN (Ne, 4, 3) and signed volumes (Ne,) from [[1, x, y, z]] inversion per element."""
    dN = np.empty((len(tets), 4, 3))
    vol = np.empty(len(tets))
    for e, tet in enumerate(tets):
        Mx = np.ones((4, 4))
        Mx[:, 1:] = points[tet]
        vol[e] = np.linalg.det(Mx) / 6.0
        C = np.linalg.inv(Mx)  # N_a(x) = C[0, a] + C[1:, a] . x
        dN[e] = C[1:, :].T
    return dN, vol


def assemble_p1_ref(points, tets, u, material):
    """Internal force (3 Nn,) and dense tangent (3 Nn, 3 Nn) by a plain element loop.

    Only ``material.name``, ``material.E`` and ``material.nu`` are used.
    """
    law, E, nu = material.name, float(material.E), float(material.nu)
    n = 3 * len(points)
    f = np.zeros(n)
    K = np.zeros((n, n))
    dN, vol = p1_gradients_ref(points, tets)
    for e, tet in enumerate(tets):
        H = u[tet].T @ dN[e]  # H_iJ = sum_a u_ai dN_aJ
        P = first_pk_ref(law, E, nu, H)
        A = moduli_ref(law, E, nu, H)
        dofs = (3 * tet[:, None] + np.arange(3)).ravel()
        fe = vol[e] * (dN[e] @ P.T)  # (4, 3): fe[a, i] = sum_J P_iJ dN_aJ
        Ke = vol[e] * np.einsum("aJ,iJkL,bL->aibk", dN[e], A, dN[e]).reshape(12, 12)
        f[dofs] += fe.ravel()
        K[np.ix_(dofs, dofs)] += Ke
    return f, K
