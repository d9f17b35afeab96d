"""Fluid-to-solid load transfer: the interface protocol shared by the two operators.

An interface maps pore pressures to FE nodal forces. Both operators porefsi has are linear in
the pore pressures and stored as one sparse matrix ``T`` with ``F.ravel() = T @ P`` (``F`` nodal
forces (Nn, 3) N, ``P`` pore pressures (Np,) Pa):

:class:`~porefsi.coupling.hull.HullInterface` (:mod:`porefsi.coupling.hull`)
    The seed paper's method (section 2.3.1): N test points on each pore sphere, their convex hull
    (Qhull) enlarged by a tolerance ε, the FE nodes inside it labelled 1, and the pore force
    ``F_i = ∫ P_i n ds`` handed to those nodes along ``n`` (pore centre -> node).
:class:`~porefsi.coupling.traction.TractionInterface` (:mod:`porefsi.coupling.traction`)
    The consistent alternative: each pore's pressure acts as a traction ``-P n`` on the FE
    boundary facets that bound that pore's voxel region. Over a closed cavity it has zero
    resultant to round-off.

Each is built by an option object with a ``build`` method (:class:`InterfaceBuilder`:
:class:`~porefsi.coupling.hull.HullOptions`, :class:`~porefsi.coupling.traction.TractionOptions`),
so the coupled loop rebuilds whichever it was given after a re-extraction without knowing which.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar, Protocol, runtime_checkable

import numpy as np

from porefsi.errors import InputError

if TYPE_CHECKING:
    import scipy.sparse as sp

    from porefsi.network.network import Network
    from porefsi.solid.mesh import SolidMesh
    from porefsi.solid.model import SolidModel

__all__ = ["Interface", "InterfaceBuilder", "LinearInterface"]


@runtime_checkable
class Interface(Protocol):
    """What the coupled loop needs of a pressure -> nodal-force operator.

    Attributes
    ----------
    method : str
        ``"hull"`` or ``"traction"`` (the case-file name of the operator; for records only).
    operator : scipy.sparse.csr_matrix, shape (3 Nn, Np)
        ``nodal_forces(P).ravel() == operator @ P``; m² (force per unit pressure).
    wall_area : ndarray, shape (Np,)
        Area (m²) each pore's pressure acts on.
    pore_nodes : tuple of ndarray
        For each pore, the FE nodes that receive its load.
    n_unloaded : int
        Pores with nonzero area whose load reaches no node.
    """

    method: ClassVar[str]
    operator: sp.csr_matrix
    wall_area: np.ndarray
    pore_nodes: tuple
    n_unloaded: int

    @property
    def n_nodes(self) -> int: ...  # noqa: D102

    @property
    def n_pores(self) -> int: ...  # noqa: D102

    def nodal_forces(self, pressure) -> np.ndarray: ...  # noqa: D102

    def vertex_forces(self, pressure) -> np.ndarray: ...  # noqa: D102

    def load_balance_error(self, pressure) -> float: ...  # noqa: D102


@runtime_checkable
class InterfaceBuilder(Protocol):
    """Options that build an :class:`Interface` on a network and a mesh (hull or traction)."""

    def build(self, network: Network, labels: np.ndarray, mesh: SolidMesh, *, voxel_size: float, origin,
              model: SolidModel | None = None) -> Interface:
        """The interface of ``network`` (voxel ``labels``) on ``mesh`` (and ``model``'s basis)."""


class LinearInterface:
    """The shared half of the two operators: forces from :attr:`operator` (and a P2 vertex split).

    Subclasses are frozen dataclasses with at least ``operator``; a ``vertex_operator`` field
    (None when :attr:`operator` already acts on the mesh vertices) serves :meth:`vertex_forces`.
    """

    operator: sp.csr_matrix
    vertex_operator = None

    @property
    def n_nodes(self) -> int:
        """Number of FE nodes Nn."""
        return self.operator.shape[0] // 3

    @property
    def n_pores(self) -> int:
        """Number of pores Np."""
        return self.operator.shape[1]

    def _pressure(self, pressure) -> np.ndarray:
        p = np.asarray(pressure, dtype=float)
        if p.shape != (self.n_pores,):
            raise InputError(f"pressure must have shape ({self.n_pores},), got {p.shape}")
        return p

    def nodal_forces(self, pressure) -> np.ndarray:
        """Nodal forces (Nn, 3), N, for pore pressures ``pressure`` (Np,), Pa."""
        return (self.operator @ self._pressure(pressure)).reshape(-1, 3)

    def vertex_forces(self, pressure) -> np.ndarray:
        """Nodal forces on the mesh vertices (Nv, 3), N, for outputs.

        :meth:`nodal_forces`, or for a P2 operator the P1 split of the same load
        (``vertex_operator``).
        """
        if self.vertex_operator is None:
            return self.nodal_forces(pressure)
        return (self.vertex_operator @ self._pressure(pressure)).reshape(-1, 3)
