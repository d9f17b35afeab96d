"""numba P1 kernels: total-Lagrangian residual and tangent assembled straight into CSR storage.

Private: arrays and scalars only; the callers in :mod:`porefsi.solid.assembly` validate inputs.
The pure-Python twins live in ``tests/reference/solid_ref.py``.
"""

from __future__ import annotations

import numpy as np

from porefsi._numba import jit

SVK = 0
NEO_HOOKEAN = 1


@jit
def _p1_gradients(points, tets, dN, vol):
    """Shape-function gradients dN[e, a, J] (1/m) and volumes vol[e] (m^3) of P1 tetrahedra."""
    for e in range(tets.shape[0]):
        x0 = points[tets[e, 0]]
        Jm = np.empty((3, 3))
        for c in range(3):
            for d in range(3):
                Jm[d, c] = points[tets[e, c + 1], d] - x0[d]  # columns are edge vectors
        det = (Jm[0, 0] * (Jm[1, 1] * Jm[2, 2] - Jm[1, 2] * Jm[2, 1])
               - Jm[0, 1] * (Jm[1, 0] * Jm[2, 2] - Jm[1, 2] * Jm[2, 0])
               + Jm[0, 2] * (Jm[1, 0] * Jm[2, 1] - Jm[1, 1] * Jm[2, 0]))
        vol[e] = det / 6.0
        Ji = np.linalg.inv(Jm)  # rows of Ji are grad of barycentric coords 1..3
        for d in range(3):
            dN[e, 1, d] = Ji[0, d]
            dN[e, 2, d] = Ji[1, d]
            dN[e, 3, d] = Ji[2, d]
            dN[e, 0, d] = -(Ji[0, d] + Ji[1, d] + Ji[2, d])


@jit
def _stress_moduli(kind, lam, mu, H, F, P, A, want_A):
    """First PK stress P and moduli A_iJkL of material ``kind`` at F = I + H; returns det F.

    The Green strain is formed from the displacement gradient H, not from F^T F - I, so small
    strains keep their relative precision (F^T F - I cancels ~log10(1/strain) digits).
    """
    J = (F[0, 0] * (F[1, 1] * F[2, 2] - F[1, 2] * F[2, 1])
         - F[0, 1] * (F[1, 0] * F[2, 2] - F[1, 2] * F[2, 0])
         + F[0, 2] * (F[1, 0] * F[2, 1] - F[1, 1] * F[2, 0]))
    if kind == SVK:
        E = np.empty((3, 3))
        for a in range(3):
            for b in range(3):
                s = H[a, b] + H[b, a]
                for k in range(3):
                    s += H[k, a] * H[k, b]
                E[a, b] = 0.5 * s
        tr = E[0, 0] + E[1, 1] + E[2, 2]
        S = np.empty((3, 3))
        for a in range(3):
            for b in range(3):
                S[a, b] = 2.0 * mu * E[a, b] + (lam * tr if a == b else 0.0)
        for i in range(3):
            for b in range(3):
                s = 0.0
                for m in range(3):
                    s += F[i, m] * S[m, b]
                P[i, b] = s
        if want_A:
            FFt = F @ F.T
            for i in range(3):
                for jj in range(3):
                    for k in range(3):
                        for ll in range(3):
                            v = lam * F[i, jj] * F[k, ll] + mu * F[i, ll] * F[k, jj]
                            if i == k:
                                v += S[jj, ll]
                            if jj == ll:
                                v += mu * FFt[i, k]
                            A[i, jj, k, ll] = v
    else:
        if J <= 0.0:
            return J
        Fi = np.linalg.inv(F)
        # ln J = log1p(det(I + H) - 1) and F - F^-T = H + (F^-1 H)^T: no cancellation at small strain
        trH = H[0, 0] + H[1, 1] + H[2, 2]
        hh = 0.0
        for a in range(3):
            for b in range(3):
                hh += H[a, b] * H[b, a]
        detH = (H[0, 0] * (H[1, 1] * H[2, 2] - H[1, 2] * H[2, 1])
                - H[0, 1] * (H[1, 0] * H[2, 2] - H[1, 2] * H[2, 0])
                + H[0, 2] * (H[1, 0] * H[2, 1] - H[1, 1] * H[2, 0]))
        lnJ = np.log1p(trH + 0.5 * (trH * trH - hh) + detH)
        for i in range(3):
            for b in range(3):
                s = 0.0
                for m in range(3):
                    s += Fi[b, m] * H[m, i]
                P[i, b] = mu * (H[i, b] + s) + lam * lnJ * Fi[b, i]
        if want_A:
            c = mu - lam * lnJ
            for i in range(3):
                for jj in range(3):
                    for k in range(3):
                        for ll in range(3):
                            v = c * Fi[jj, k] * Fi[ll, i] + lam * Fi[jj, i] * Fi[ll, k]
                            if i == k and jj == ll:
                                v += mu
                            A[i, jj, k, ll] = v
    return J


@jit
def _element_gradient(tets, dN, u, e, H, F):
    """Displacement gradient H_iJ = sum_a u[tets[e, a], i] dN[e, a, J] of element e, and F = I + H."""
    for i in range(3):
        for jj in range(3):
            s = 0.0
            for a in range(4):
                s += u[tets[e, a], i] * dN[e, a, jj]
            H[i, jj] = s
            F[i, jj] = s + (1.0 if i == jj else 0.0)


@jit
def _assemble_p1(geometry, u, material, want_K, fint, csr):
    """Add f_int (3 Nn,) and, if ``want_K``, the tangent into CSR ``data``; return # inverted.

    ``geometry = (tets, dN, vol)`` (P1 mesh and its shape-function gradients and volumes),
    ``material = (kind, lam, mu)``, ``csr = (data, nptr, deg, pos)``: ``pos[e, a, b]`` is the
    position of node ``tets[e, b]`` in the node-graph row of ``tets[e, a]``; dof row ``3 n + i``
    starts at ``9 nptr[n] + 3 i deg[n]``.
    """
    tets, dN, vol = geometry
    kind, lam, mu = material
    data, nptr, deg, pos = csr
    n_bad = 0
    F = np.empty((3, 3))
    Hd = np.empty((3, 3))
    P = np.empty((3, 3))
    A = np.empty((3, 3, 3, 3))
    H = np.empty((3, 3))  # H[i, J] = sum_L A_iJkL dN_bL for the current (b, k)
    for e in range(tets.shape[0]):
        _element_gradient(tets, dN, u, e, Hd, F)
        J = _stress_moduli(kind, lam, mu, Hd, F, P, A, want_K)
        if J <= 0.0:
            n_bad += 1
            continue
        v = vol[e]
        for a in range(4):
            na = tets[e, a]
            for i in range(3):
                s = 0.0
                for jj in range(3):
                    s += P[i, jj] * dN[e, a, jj]
                fint[3 * na + i] += v * s
        if not want_K:
            continue
        for b in range(4):
            for k in range(3):
                for i in range(3):
                    for jj in range(3):
                        s = 0.0
                        for ll in range(3):
                            s += A[i, jj, k, ll] * dN[e, b, ll]
                        H[i, jj] = s
                for a in range(4):
                    na = tets[e, a]
                    base = 9 * nptr[na] + 3 * pos[e, a, b] + k
                    for i in range(3):
                        s = 0.0
                        for jj in range(3):
                            s += dN[e, a, jj] * H[i, jj]
                        data[base + 3 * i * deg[na]] += v * s
    return n_bad


@jit
def _p1_cauchy(tets, dN, u, material, sigma):
    """Cauchy stress sigma[e] = P F^T / J (Pa) of every P1 tetrahedron; returns # inverted.

    ``u`` (Nn, 3) nodal displacements, m; ``dN`` (Ne, 4, 3) shape-function gradients;
    ``material = (kind, lam, mu)``. An inverted element (J <= 0) counts; its stress is NaN
    (St Venant-Kirchhoff: the formula's value for J < 0, as :meth:`Material.cauchy`).
    """
    kind, lam, mu = material
    n_bad = 0
    F = np.empty((3, 3))
    H = np.empty((3, 3))
    P = np.empty((3, 3))
    A = np.empty((1, 1, 1, 1))
    for e in range(tets.shape[0]):
        _element_gradient(tets, dN, u, e, H, F)
        J = _stress_moduli(kind, lam, mu, H, F, P, A, False)
        if J <= 0.0:
            n_bad += 1
            if kind != SVK or J == 0.0:  # Neo-Hookean has no stress there (ln J)
                sigma[e] = np.nan
                continue
        for i in range(3):
            for k in range(3):
                sigma[e, i, k] = (P[i, 0] * F[k, 0] + P[i, 1] * F[k, 1] + P[i, 2] * F[k, 2]) / J
    return n_bad
