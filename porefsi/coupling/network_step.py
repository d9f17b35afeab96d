"""The network part of an exchange step: the network (and interface) that follow a displacement.

One updater per ``network.update`` mode, each with ``update(U, current) -> NetworkState``:

:class:`NoUpdate`
    One-way coupling: the network never moves.
:class:`GeometricUpdate`
    Every pore carried by the local affine fit of the solid's displacement (sub-voxel, same
    topology; :func:`porefsi.coupling.update.geometric_update`), always from the *reference*
    network with the *total* displacement (no drift).
:class:`Reextraction` (the paper's)
    The deformed solid voxelised and the network extracted again; a new topology gets a new
    interface. Extractions of a voxel image seen before are served by an :class:`ExtractionCache`.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from porefsi.coupling._loop_support import digest, same_topology
from porefsi.coupling.interface import Interface
from porefsi.coupling.problem import CoupledProblem, extract_flow_network
from porefsi.coupling.timing import StageClock
from porefsi.coupling.update import deformed_image, geometric_update, update_nodes
from porefsi.network.extract import Extraction
from porefsi.network.network import Network

__all__ = ["NetworkState", "NoUpdate", "GeometricUpdate", "Reextraction", "ExtractionCache", "make_updater"]


@dataclasses.dataclass(frozen=True, eq=False)
class NetworkState:
    """The network of a moment of the run, with the interface and voxel labels that go with it.

    Attributes
    ----------
    network : Network
    interface : Interface
    labels : ndarray of int
        Voxel labels of the extraction the network came from (pore index, -1 elsewhere).
    """

    network: Network
    interface: Interface
    labels: np.ndarray


class NoUpdate:
    """One-way coupling: the network stays the reference one."""

    #: The updater needs no pre-coupling iterations.
    precoupling = False

    def update(self, U: np.ndarray, current: NetworkState) -> NetworkState:
        """``current`` unchanged."""
        return current


class GeometricUpdate:
    """Pores moved and resized by the local affine fit of the displacement (same topology).

    Parameters
    ----------
    reference : Network
        The undeformed network (every update maps it with the total displacement).
    points : ndarray, shape (Nn, 3)
        Reference mesh nodes, m.
    spacing : float
        Mesh node spacing, m.
    """

    precoupling = False

    def __init__(self, reference: Network, points: np.ndarray, spacing: float):
        self.reference, self.points, self.spacing = reference, points, spacing
        self._nodes = None  # per-pore nodes of the affine fits (built on first use)

    def update(self, U: np.ndarray, current: NetworkState) -> NetworkState:
        """The reference network carried by the nodal displacement ``U`` (Nn, 3), m."""
        if self._nodes is None:
            ref = self.reference
            self._nodes = update_nodes(ref.pore_coords, ref.pore_radius, current.interface.pore_nodes, self.points,
                                       self.spacing)
        return NetworkState(geometric_update(self.reference, self._nodes, self.points, U), current.interface,
                            current.labels)


class ExtractionCache:
    """Extractions by the digest of their voxel image.

    The extraction is deterministic: the same image gives the same network bit for bit, so one
    seen before is served instead of repeated.

    Parameters
    ----------
    enabled : bool, default True
        False computes every extraction (the paper's cost).
    size : int, default 4
        Extractions kept (the oldest goes first).

    Attributes
    ----------
    n_computed, n_reused : int
        Extractions computed, and served from the cache.
    """

    def __init__(self, enabled: bool = True, size: int = 4):
        self.enabled, self.size = bool(enabled), int(size)
        self._items: dict[bytes, Extraction] = {}
        self.n_computed = 0
        self.n_reused = 0

    def seed(self, phases: np.ndarray, extraction: Extraction) -> None:
        """Store a known extraction (not counted)."""
        self._items[digest(phases)] = extraction

    def get(self, phases: np.ndarray, extract, clock: StageClock | None = None) -> Extraction:
        """The extraction of voxel image ``phases``: cached, or ``extract()`` (timed as ``"extract"``)."""
        key = digest(phases)
        ex = self._items.get(key) if self.enabled else None
        if ex is not None:
            self.n_reused += 1
            return ex
        with (clock or StageClock())("extract"):
            ex = extract()
        self.n_computed += 1
        if self.enabled:
            if len(self._items) >= self.size:
                self._items.pop(next(iter(self._items)))
            self._items[key] = ex
        return ex


class Reextraction:
    """The paper's update: voxelise the deformed solid, extract again, rebuild the interface on a new topology.

    Parameters
    ----------
    problem : CoupledProblem
        Reference image, mesh, flow axis, conduit model and interface kind.
    cache : ExtractionCache
    clock : StageClock
        Times ``voxelise``, ``extract`` and ``interface_rebuild``.
    """

    precoupling = True

    def __init__(self, problem: CoupledProblem, cache: ExtractionCache, clock: StageClock):
        self.problem, self.cache, self.clock = problem, cache, clock
        opts = problem.options
        self._extract = lambda img: extract_flow_network(img, opts.axis, opts.network.conductance)

    def update(self, U: np.ndarray, current: NetworkState) -> NetworkState:
        """The network of the solid deformed by ``U`` (Nn, 3), m.

        It keeps ``current``'s interface and labels if the topology did not change.
        """
        p = self.problem
        with self.clock("voxelise"):
            img = deformed_image(p.image, p.mesh.points, U, p.node_spacing)
        # at the paper's loads (displacements ~1e-6 voxel) always the reference image: served from the cache
        ex = self.cache.get(img.phases, lambda: self._extract(img), self.clock)
        if same_topology(ex.network, current.network):
            return NetworkState(ex.network, current.interface, current.labels)
        with self.clock("interface_rebuild"):
            return NetworkState(ex.network, p.build_interface(ex), ex.labels)


def make_updater(problem: CoupledProblem, cache: ExtractionCache,
                 clock: StageClock) -> NoUpdate | GeometricUpdate | Reextraction:
    """The updater of ``problem.options.network.update``."""
    mode = problem.options.network.update
    if mode == "none":
        return NoUpdate()
    if mode == "geometric":
        return GeometricUpdate(problem.network, problem.mesh.points, problem.node_spacing)
    return Reextraction(problem, cache, clock)
