r"""Stress recovery: Cauchy stress and von Mises per element, nodal averages, effective modulus.

.. math::

    \sigma = J^{-1} P F^T, \qquad
    \sigma_{vM} = \sqrt{\tfrac32\, s : s}, \quad s = \sigma - \tfrac13 \mathrm{tr}(\sigma) I
"""

from __future__ import annotations

import numpy as np
from skfem import Basis

from porefsi.errors import InputError
from porefsi.solid import _kernels
from porefsi.solid.mesh import SolidMesh, tet_volumes

__all__ = ["element_cauchy", "von_mises", "nodal_average", "effective_modulus"]


def element_cauchy(model, u: np.ndarray, t: float) -> np.ndarray:
    """Cauchy stress at each element centroid, Pa, shape (Ne, 3, 3).

    Parameters
    ----------
    model : SolidModel
    u : ndarray, shape (n,)
        Free dofs, m.
    t : float
        Time (for the prescribed motion), s.
    """
    full = model.full_displacement(u, t)
    mat = model.material
    if model.order == 1 and getattr(mat, "kind", -1) in (_kernels.SVK, _kernels.NEO_HOOKEAN):
        sigma = np.empty((model.mesh.n_tets, 3, 3))  # fused: gradient, P, sigma per element
        _kernels._p1_cauchy(model.mesh.tets, model.vertex_gradients(), np.ascontiguousarray(full.reshape(-1, 3)),
                            (int(mat.kind), float(mat.lam), float(mat.mu)), sigma)
        return sigma
    if model.order == 1:  # no scikit-fem basis for P1 (it would hold 12 gradient fields per element)
        dN = model.vertex_gradients()
        ue = full.reshape(-1, 3)[model.mesh.tets]  # (Ne, 4, 3)
        H = np.moveaxis(np.matmul(ue.transpose(0, 2, 1), dN), 0, -1)  # H_iJ = sum_a u_ai dN_aJ, (3, 3, Ne)
    else:
        centroid = (np.full((3, 1), 0.25), np.array([1.0 / 6.0]))
        feb = model.feb
        cb = Basis(feb.basis.mesh, feb.basis.elem, quadrature=centroid)
        H = np.asarray(cb.interpolate(full).grad)[..., 0]
    F = np.eye(3)[:, :, None] + H
    sigma = model.material.cauchy(F, H)
    return np.ascontiguousarray(np.moveaxis(sigma, -1, 0))


def von_mises(sigma: np.ndarray) -> np.ndarray:
    """Von Mises equivalent stress of Cauchy stresses ``sigma`` (..., 3, 3), Pa, shape (...)."""
    s = np.asarray(sigma, dtype=float)
    if s.shape[-2:] != (3, 3):
        raise InputError(f"sigma must have trailing shape (3, 3), got {s.shape}")
    dev = s - np.trace(s, axis1=-2, axis2=-1)[..., None, None] * np.eye(3) / 3.0
    return np.sqrt(1.5 * np.einsum("...ij,...ij->...", dev, dev))


def nodal_average(mesh: SolidMesh, values: np.ndarray) -> np.ndarray:
    """Volume-weighted average of per-element ``values`` (Ne, ...) at the nodes: (Nn, ...)."""
    v = np.asarray(values, dtype=float)
    if v.shape[0] != mesh.n_tets:
        raise InputError(f"values must have {mesh.n_tets} rows (one per element), got {v.shape[0]}")
    w = tet_volumes(mesh.points, mesh.tets)
    flat = v.reshape(len(v), -1)
    idx = mesh.tets.ravel()
    den = np.bincount(idx, weights=np.repeat(w, 4), minlength=mesh.n_nodes)
    out = np.stack([np.bincount(idx, weights=np.repeat(flat[:, c] * w, 4), minlength=mesh.n_nodes)
                    for c in range(flat.shape[1])], axis=1)
    return (out / den[:, None]).reshape((mesh.n_nodes,) + v.shape[1:])


def effective_modulus(reaction: float, area: float, strain: float) -> float:
    r"""Apparent Young's modulus :math:`E_{eff} = |R| / (A |\varepsilon|)`, Pa.

    Parameters
    ----------
    reaction : float
        Axial reaction on the loaded face, N.
    area : float
        Reference area of the box face (solid and pore), m^2.
    strain : float
        Imposed nominal axial strain (displacement / length).
    """
    if area <= 0 or strain == 0:
        raise InputError(f"need area > 0 and strain != 0, got area={area}, strain={strain}")
    return abs(float(reaction)) / (float(area) * abs(float(strain)))
