r"""scikit-fem forms of total-Lagrangian hyperelasticity: the reference implementation.

Weak form (reference configuration :math:`\Omega_0`, dead loads):

.. math::

    r(u; v) = \int_{\Omega_0} P(F) : \nabla_X v \,\mathrm dV
              - \int_{\Gamma_N} \bar t \cdot v \,\mathrm dA, \qquad F = I + \nabla_X u,

    K(u; \delta u, v) = \int_{\Omega_0} \nabla_X v : \mathbb A(F) : \nabla_X \delta u \,\mathrm dV,
    \qquad M(\delta u, v) = \int_{\Omega_0} \rho_0\, \delta u \cdot v \,\mathrm dV.

P1 uses one quadrature point (exact: F is constant per element), P2 four (exact for the linear
stiffness). Stress and moduli are evaluated once per assembly and passed into the forms as
fields and unwrapped to plain arrays (a plain array passed to a form arrives as a
``DiscreteField``; see :func:`_field`).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.sparse as sp
from skfem import Basis, BilinearForm, ElementTetP1, ElementTetP2, ElementVector, FacetBasis, LinearForm
from skfem.helpers import ddot, dot, grad

from porefsi.errors import InputError, MeshError
from porefsi.solid.materials import Material
from porefsi.solid.mesh import SolidMesh

__all__ = ["FEBasis", "make_basis", "internal_force", "tangent", "consistent_mass", "lumped_mass_p1",
           "facet_load", "deformation_gradient"]

_INTORDER = {1: 1, 2: 2}


@dataclasses.dataclass(frozen=True, eq=False)
class FEBasis:
    """A scikit-fem vector basis on a :class:`SolidMesh` and what is derived from it.

    Attributes
    ----------
    mesh : SolidMesh
    order : int
        1 (P1) or 2 (P2).
    basis : skfem.CellBasis
    n_dofs : int
        3 x number of Lagrange nodes. Dofs are interleaved: dof ``3 a + c`` is component c of
        Lagrange node a; nodes 0..Nn-1 are the mesh vertices, then (P2) the edge midpoints.
    dof_points : ndarray, shape (n_dofs // 3, 3)
        Lagrange node positions, m.
    """

    mesh: SolidMesh
    order: int
    basis: object
    n_dofs: int
    dof_points: np.ndarray


def make_basis(mesh: SolidMesh, order: int = 1) -> FEBasis:
    """Vector Lagrange basis of ``order`` (1 or 2) on ``mesh``."""
    if order not in (1, 2):
        raise InputError(f"order must be 1 (P1) or 2 (P2), got {order!r}")
    m = mesh.to_skfem()
    elem = ElementVector(ElementTetP1() if order == 1 else ElementTetP2())
    basis = Basis(m, elem, intorder=_INTORDER[order])
    pts = np.ascontiguousarray(basis.doflocs[:, ::3].T)
    # interleaved ordering is what every other module assumes; check it rather than trust it
    nd = basis.nodal_dofs
    if not np.array_equal(nd, 3 * np.arange(nd.shape[1]) + np.arange(3)[:, None]):
        raise MeshError("unexpected scikit-fem dof ordering (expected interleaved vertex dofs)")
    return FEBasis(mesh=mesh, order=order, basis=basis, n_dofs=basis.N, dof_points=pts)


def deformation_gradient(feb: FEBasis, u: np.ndarray) -> np.ndarray:
    """F = I + grad u at the quadrature points, shape (3, 3, Ne, nqp)."""
    return np.eye(3)[:, :, None, None] + grad(feb.basis.interpolate(u))


def _check_J(F):
    J = (F[0, 0] * (F[1, 1] * F[2, 2] - F[1, 2] * F[2, 1]) - F[0, 1] * (F[1, 0] * F[2, 2] - F[1, 2] * F[2, 0])
         + F[0, 2] * (F[1, 0] * F[2, 1] - F[1, 1] * F[2, 0]))
    bad = np.any(J <= 0, axis=-1)
    if np.any(bad):
        raise MeshError(
            f"{int(bad.sum())} elements inverted (J <= 0) under the current displacement; "
            "take a smaller load or time step"
        )


def _field(f) -> np.ndarray:
    """A precomputed array passed into a form, as a plain ndarray.

    scikit-fem wraps it in a ``DiscreteField``; helpers such as ``skfem.helpers.inv`` applied to
    that wrapper silently return zeros in some versions, and ``.value`` is deprecated in
    scikit-fem 12, so unwrap explicitly.
    """
    return np.asarray(f)  # DiscreteField subclasses ndarray in scikit-fem >= 8


@LinearForm
def _residual_form(v, w):
    return ddot(_field(w["P"]), grad(v))


@BilinearForm
def _tangent_form(du, v, w):
    return ddot(np.einsum("iJkL...,kL...->iJ...", _field(w["A"]), grad(du)), grad(v))


@BilinearForm
def _mass_form(du, v, w):
    return _field(w["rho"]) * dot(du, v)


def internal_force(feb: FEBasis, material: Material, u: np.ndarray) -> np.ndarray:
    """Internal force vector f_int(u) = int P : grad v dV, N, shape (n_dofs,).

    The stress is formed from the displacement gradient H (F = I + H) so that the small strains
    of pore-pressure loading (~1e-7) keep their precision: a Newton residual on F^T F - I stalls at
    ~1e-7 relative.
    """
    H = np.asarray(grad(feb.basis.interpolate(u)))
    F = np.eye(3)[:, :, None, None] + H
    _check_J(F)
    return _residual_form.assemble(feb.basis, P=material.first_pk(F, H))


def tangent(feb: FEBasis, material: Material, u: np.ndarray) -> sp.csr_matrix:
    """Tangent stiffness K(u), N/m, sparse (n_dofs, n_dofs), symmetric."""
    F = deformation_gradient(feb, u)
    _check_J(F)
    return _tangent_form.assemble(feb.basis, A=material.moduli(F)).tocsr()


def consistent_mass(feb: FEBasis, density: float) -> sp.csr_matrix:
    """Consistent mass matrix, kg, sparse (n_dofs, n_dofs) (exact quadrature)."""
    b = feb.basis
    mb = Basis(b.mesh, b.elem, intorder=2 * feb.order)
    rho = np.full((feb.mesh.n_tets, mb.X.shape[1]), float(density))
    return _mass_form.assemble(mb, rho=rho).tocsr()


def lumped_mass_p1(mesh: SolidMesh, density: float) -> np.ndarray:
    """Row-sum lumped P1 mass, kg, diagonal of shape (3 Nn,): each node gets rho V_e / 4 per element.

    For P2 the row-sum lumped mass has negative vertex entries; use :func:`consistent_mass`.
    """
    from porefsi.solid.mesh import tet_volumes

    vol = tet_volumes(mesh.points, mesh.tets)
    m = np.bincount(mesh.tets.ravel(), weights=np.repeat(vol * density / 4.0, 4), minlength=mesh.n_nodes)
    return np.repeat(m, 3)


def _skfem_facet_ids(feb: FEBasis, facets: np.ndarray) -> np.ndarray:
    """Indices into ``skfem_mesh.facets`` of the triangles ``facets`` (k, 3)."""
    m = feb.basis.mesh
    all_f = np.sort(m.facets.T, axis=1).astype(np.int64)
    n = np.int64(m.nvertices)
    key_all = (all_f[:, 0] * n + all_f[:, 1]) * n + all_f[:, 2]
    s = np.sort(facets, axis=1).astype(np.int64)
    key = (s[:, 0] * n + s[:, 1]) * n + s[:, 2]
    order = np.argsort(key_all)
    pos = np.searchsorted(key_all, key, sorter=order)
    pos = np.clip(pos, 0, len(order) - 1)
    ids = order[pos]
    if not np.array_equal(key_all[ids], key):
        raise MeshError("some tagged facets are not facets of the mesh")
    return ids


def facet_load(feb: FEBasis, facets: np.ndarray, traction=None, pressure: float | None = None) -> np.ndarray:
    """Consistent nodal forces of a dead load on boundary triangles, N, shape (n_dofs,).

    Parameters
    ----------
    facets : ndarray of int, shape (k, 3)
        Boundary triangles (node indices).
    traction : array_like, shape (3,), optional
        Uniform traction vector t (Pa) in the reference configuration.
    pressure : float, optional
        Uniform pressure p (Pa) pushing on the solid: traction ``-p N`` with N the outward
        reference normal.
    """
    if len(facets) == 0:
        return np.zeros(feb.n_dofs)
    b = feb.basis
    fb = FacetBasis(b.mesh, b.elem, facets=_skfem_facet_ids(feb, facets), intorder=2 * feb.order)
    t = np.zeros(3) if traction is None else np.asarray(traction, dtype=float).reshape(3)
    p = 0.0 if pressure is None else float(pressure)

    @LinearForm
    def load(v, w):
        # skfem's facet normal points out of the mesh on boundary facets
        return dot(t[:, None, None] - p * w.n, v)

    return load.assemble(fb)
