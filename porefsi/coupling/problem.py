"""Assemble a coupled problem from an image and options: network, mesh, solid model, interface.

Nothing here reads a file: :func:`porefsi.case.problem_from_case` reads a case's image and
turns its sections into :class:`~porefsi.coupling.options.CoupledOptions` first.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np

from porefsi.coupling.interface import Interface
from porefsi.coupling.options import CoupledOptions, SolidOptions
from porefsi.coupling.timing import StageClock
from porefsi.flow.fluids import Fluids
from porefsi.flow.invasion import invasion_percolation
from porefsi.image.ops import percolating_cluster
from porefsi.image.voxel_image import VoxelImage, axis_index
from porefsi.network.extract import Extraction, extract_network
from porefsi.network.network import Network
from porefsi.solid.bc import check_load_path, uniaxial_bcs
from porefsi.solid.footprint import choose_linear_solver
from porefsi.solid.graded import ligament_region, mesh_graded
from porefsi.solid.materials import make_material
from porefsi.solid.mesh import MeshResult, SolidMesh, mesh_solid
from porefsi.solid.model import SolidModel

__all__ = ["CoupledProblem", "build_problem", "build_solid", "extract_flow_network", "SolverChoiceWarning",
           "CoarseLoadWarning", "predicted_invasion"]


class SolverChoiceWarning(UserWarning):
    """The solid got another linear solver than the one requested (a direct solve too large for the machine)."""


class CoarseLoadWarning(UserWarning):
    """Fluid entered a pore outside the graded mesh's refined region: its load sits on coarse leaves."""


@dataclasses.dataclass(frozen=True, eq=False)
class CoupledProblem:
    """Everything a coupled run needs, built once (:func:`build_problem`).

    Attributes
    ----------
    image : VoxelImage
        The segmented image; the solid is meshed from it.
    extraction : Extraction
        Network of the percolating pore space along the flow axis, with its voxel labels.
    mesh_result : MeshResult
        Solid mesh and the removed (floating) solid fraction.
    interface : Interface
        Pore pressures -> nodal forces (hull or traction), built on the reference configuration.
    model : SolidModel
        The solid with the paper's loading frame along ``options.solid.load_axis``.
    options : CoupledOptions
    seconds : dict
        Wall time of each set-up stage, s (``extraction``, ``mesh``, ``interface_build``, and
        ``image`` when the image was read by :func:`porefsi.case.problem_from_case`).
    cpu_seconds : dict
        CPU time (``time.process_time``: this process, all threads) of the same stages, s.
    refined : ndarray of bool, shape of the image, or None
        Pore voxels the graded mesh resolves at its fine block because the load was predicted
        there (``solid.refine = "invaded"``: :func:`predicted_invasion`); None when every pore wall
        is meshed alike (a uniform mesh, or ``refine = "walls"``). The run warns
        (:class:`CoarseLoadWarning`) when fluid enters a pore outside it.
    """

    image: VoxelImage
    extraction: Extraction
    mesh_result: MeshResult
    interface: Interface
    model: SolidModel
    options: CoupledOptions = dataclasses.field(default_factory=CoupledOptions)
    seconds: dict = dataclasses.field(default_factory=dict)
    cpu_seconds: dict = dataclasses.field(default_factory=dict)
    refined: np.ndarray | None = None

    @property
    def network(self) -> Network:
        """The reference (undeformed) network."""
        return self.extraction.network

    @property
    def mesh(self) -> SolidMesh:
        """The reference solid mesh."""
        return self.mesh_result.mesh

    @property
    def fluids(self) -> Fluids:
        """The two fluids (``options.fluids``)."""
        return self.options.fluids

    @property
    def node_spacing(self) -> float:
        """Spacing of the mesh's node grid, m (voxel size x coarsening)."""
        return self.image.voxel_size * self.mesh_result.coarsen

    def build_interface(self, extraction: Extraction) -> Interface:
        """The problem's kind of interface for another extraction of its image (after a re-extraction)."""
        return self.options.interface.build(extraction.network, extraction.labels, self.mesh,
                                            voxel_size=self.image.voxel_size, origin=self.image.origin,
                                            model=self.model)


def extract_flow_network(image: VoxelImage, axis: str, conductance: str) -> Extraction:
    """The network of the pore space of ``image`` that percolates along ``axis``."""
    return extract_network(percolating_cluster(image, axis).image, conductance=conductance)


def predicted_invasion(extraction: Extraction, options: CoupledOptions, volume_factor: float = 2.0) -> np.ndarray:
    """Pore voxels (bool, image shape) where the fluid load will sit, predicted before the run.

    The pores that invasion percolation fills first with ``volume_factor`` times the injected
    volume (``drainage.rate * drainage.t_end``): the graded mesh's ``refine = "invaded"``. At
    the paper's capillary numbers the dynamic invasion follows the invasion-percolation order
    (docs/drainage.md).
    """
    net = extraction.network
    ip = invasion_percolation(net, options.fluids, axis=options.axis)
    order = np.argsort(np.where(ip.pore_sequence >= 0, ip.pore_sequence, np.iinfo(np.int64).max))
    target = volume_factor * options.drainage.rate * options.drainage.t_end
    n = int(np.searchsorted(np.cumsum(net.pore_volume[order]), target)) + 1
    pores = order[:min(n, int(np.count_nonzero(ip.pore_sequence >= 0)))]
    return np.isin(extraction.labels, pores)


def build_solid(image: VoxelImage, options: SolidOptions, refine: np.ndarray | None = None
                ) -> tuple[MeshResult, SolidModel]:
    """The solid mesh of ``image`` and its model with the uniaxial loading frame of ``options``.

    ``refine``: the voxels a graded mesh (``options.mesh = "graded"``) resolves at ``coarsen``
    (default: every pore voxel); ignored by the uniform mesh.

    ``solid.linear_solver = "direct"`` on a system too large to factorise (above
    :data:`~porefsi.solid.footprint.DIRECT_MAX_DOFS` free dofs, or a factor that would not fit in
    memory) gets AMG-CG instead, with a :class:`SolverChoiceWarning` saying so
    (:func:`porefsi.solid.footprint.choose_linear_solver`).

    Raises
    ------
    MeshError
        A strain-rate load (``strain_rate > 0``) on a sample whose solid does not join the two
        load faces.
    """
    if options.mesh == "graded":
        mres = mesh_graded(image, coarsen=options.coarsen, coarsen_max=options.coarsen_max, grading=options.grading,
                           refine=refine, support_axis=options.load_axis)
    else:
        mres = mesh_solid(image, coarsen=options.coarsen, support_axis=options.load_axis)
    material = make_material(options.material, E=options.E, nu=options.nu, density=options.density)
    ax = axis_index(options.load_axis)
    if options.strain_rate != 0:
        check_load_path(mres.mesh, ax)  # a load frame needs solid joining its two faces
    bcs = uniaxial_bcs(ax, rate=-options.strain_rate * image.extent[ax])
    model = SolidModel(mres.mesh, material, bcs, order=options.order, linear_solver=options.linear_solver)
    choice = choose_linear_solver(options.linear_solver, model.n_dofs)
    if choice.reason:  # "direct" on a system whose factor would not pay or not fit
        warnings.warn(choice.reason, SolverChoiceWarning, stacklevel=2)
        model.linear_solver = choice.kind
    return mres, model


def build_problem(image: VoxelImage, options: CoupledOptions | None = None) -> CoupledProblem:
    """Build the coupled problem of ``image``: network, mesh, solid model and interface.

    Parameters
    ----------
    image : VoxelImage
        Segmented rock image (cropped as wanted).
    options : CoupledOptions, optional
        Default: the seed paper's set-up (:class:`~porefsi.coupling.options.CoupledOptions`).
    """
    options = CoupledOptions() if options is None else options
    clock = StageClock()
    with clock("extraction"):
        ex = extract_flow_network(image, options.axis, options.network.conductance)
    with clock("mesh"):
        graded_invaded = options.solid.mesh == "graded" and options.solid.refine == "invaded"
        refine = loaded = None
        if graded_invaded:  # the loaded pores and the thin solid ligaments that carry their load
            loaded = predicted_invasion(ex, options)
            refine = ligament_region(image.phases != 0, loaded, options.solid.ligaments)
        mres, model = build_solid(image, options.solid, refine)
    with clock("interface_build"):
        itf = options.interface.build(ex.network, ex.labels, mres.mesh, voxel_size=image.voxel_size,
                                      origin=image.origin, model=model)
    return CoupledProblem(image, ex, mres, itf, model, options, clock.wall, clock.cpu, loaded)
