"""Slow pure-Python twins of the solid kernels (porefsi/solid/_kernels.py).

Written independently of the kernels: shape-function gradients from the inverse of the
barycentric-coordinate matrix, stress and moduli from the vectorised material classes, a dense
element loop.
"""

import numpy as np


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
    """Internal force (3 Nn,) and dense tangent (3 Nn, 3 Nn) by a plain element loop."""
    n = 3 * len(points)
    f = np.zeros(n)
    K = np.zeros((n, n))
    dN, vol = p1_gradients_ref(points, tets)
    for e, tet in enumerate(tets):
        H = u[tet].T @ dN[e]  # H_iJ = sum_a u_ai dN_aJ
        F = np.eye(3) + H
        P = material.first_pk(F[:, :, None], H[:, :, None])[:, :, 0]
        A = material.moduli(F[:, :, None])[..., 0]
        dofs = (3 * tet[:, None] + np.arange(3)).ravel()
        fe = vol[e] * (dN[e] @ P.T)  # (4, 3): fe[a, i] = sum_J P_iJ dN_aJ
        Ke = vol[e] * np.einsum("aJ,iJkL,bL->aibk", dN[e], A, dN[e]).reshape(12, 12)
        f[dofs] += fe.ravel()
        K[np.ix_(dofs, dofs)] += Ke
    return f, K
