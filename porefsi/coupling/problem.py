"""Assemble a coupled problem from a case: image -> network, mesh, interface, solid model, fluids."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from porefsi.case.config import Case
from porefsi.coupling._loop_support import StageClock
from porefsi.coupling.interface import (
    Interface,
    boundary_facet_normals,
    facet_pores_from_labels,
    hull_interface,
    traction_interface,
)
from porefsi.errors import ConfigError, InputError
from porefsi.flow.fluids import Fluids
from porefsi.image.io import load_sample, read_image
from porefsi.image.ops import crop, percolating_cluster
from porefsi.image.voxel_image import VoxelImage, axis_index
from porefsi.network.extract import Extraction, extract_network
from porefsi.network.network import Network
from porefsi.solid.bc import check_load_path, midpoint_nodes, uniaxial_bcs
from porefsi.solid.materials import make_material
from porefsi.solid.mesh import MeshResult, SolidMesh, mesh_solid
from porefsi.solid.model import SolidModel

__all__ = ["CoupledProblem", "build_problem", "load_case_image", "build_interface", "fluids_from_case",
           "throat_cylinders"]


@dataclasses.dataclass(frozen=True, eq=False)
class CoupledProblem:
    """Everything a coupled run needs, built once from a :class:`~porefsi.case.config.Case`.

    Attributes
    ----------
    case : Case
    image : VoxelImage
        The (cropped) segmented image; the solid is meshed from it.
    extraction : Extraction
        Network of the percolating pore space along the flow axis, with its voxel labels.
    mesh_result : MeshResult
        Solid mesh and the removed (floating) solid fraction.
    interface : Interface
        Pore pressures -> nodal forces (hull or traction), built on the reference configuration.
    model : SolidModel
        The solid with the paper's loading frame along ``case.solid.load_axis``.
    fluids : Fluids
    seconds : dict
        Wall time of each set-up stage, s (``image``, ``extraction``, ``mesh``, ``interface_build``;
        distinct from the per-step stage names of :class:`~porefsi.coupling.loop.CoupledRun`).
    cpu_seconds : dict
        CPU time (``time.process_time``: this process, all threads) of the same stages, s
        (empty when the problem was assembled by hand).
    """

    case: Case
    image: VoxelImage
    extraction: Extraction
    mesh_result: MeshResult
    interface: Interface
    model: SolidModel
    fluids: Fluids
    seconds: dict
    cpu_seconds: dict = dataclasses.field(default_factory=dict)

    @property
    def network(self) -> Network:
        """The reference (undeformed) network."""
        return self.extraction.network

    @property
    def mesh(self) -> SolidMesh:
        """The reference solid mesh."""
        return self.mesh_result.mesh

    @property
    def node_spacing(self) -> float:
        """Spacing of the mesh's node grid, m (voxel size x coarsening)."""
        return self.image.voxel_size * self.mesh_result.coarsen


def load_case_image(case: Case) -> VoxelImage:
    """Read (or load the built-in sample), segment and crop the case's image."""
    ic = case.image
    if ic.path:
        if not Path(ic.path).exists():
            raise InputError(f"image.path {ic.path!r} does not exist; fix the path in the case file "
                             "or leave it empty for the built-in sample")
        img = read_image(ic.path, voxel_size=ic.voxel_size, threshold=ic.threshold, pore_value=ic.pore_value,
                         invert=ic.invert)
    else:
        img = load_sample()
        if ic.voxel_size is not None:
            img = VoxelImage(img.phases, ic.voxel_size, img.origin)
    if ic.crop:
        over = [f"{ax}: stop {c[1]} > {n}" for ax, c, n in zip("xyz", ic.crop, img.shape, strict=True) if c[1] > n]
        if over:
            raise ConfigError(f"image.crop {ic.crop!r} reaches beyond the image ({img.shape[0]} x {img.shape[1]} x "
                              f"{img.shape[2]} voxels; {', '.join(over)}); keep each stop <= the image size")
        img = crop(img, [c[0] for c in ic.crop], [c[1] for c in ic.crop])
    return img


def fluids_from_case(case: Case) -> Fluids:
    """The case's fluids as a :class:`~porefsi.flow.fluids.Fluids`."""
    f = case.fluids
    return Fluids(mu_w=f.mu_w, mu_n=f.mu_n, sigma=f.sigma, theta_deg=f.theta_deg)


def build_interface(case: Case, network: Network, labels: np.ndarray, mesh: SolidMesh,
                    voxel_size: float, origin, model: SolidModel | None = None) -> Interface:
    """The case's pressure -> force operator on the pore-wall surface of ``mesh``.

    With a P2 ``model`` the traction operator integrates the wall traction against the P2
    basis (forces on the edge-midpoint nodes); the hull hands its forces to the vertices in
    every case (the paper's point loads).
    """
    ic = case.interface
    if ic.method == "hull":
        wall = np.zeros(mesh.n_nodes, bool)
        wall[mesh.nodes_tagged("pore_wall")] = True
        return hull_interface(network.pore_coords, network.pore_radius, mesh.points,
                              n_test_points=ic.n_test_points, tolerance=ic.tolerance,
                              rng=np.random.default_rng(ic.seed), candidates=wall,
                              throats=throat_cylinders(network) if ic.throat_forces else None)
    facets = mesh.facets_tagged("pore_wall")
    normals, _ = boundary_facet_normals(mesh.points, mesh.tets, facets)
    owner = facet_pores_from_labels(mesh.points, facets, normals, labels, voxel_size, origin,
                                    max_steps=max(4, 2 * case.solid.coarsen))
    p2 = None
    if model is not None and model.order == 2:
        p2 = (lambda a, b: midpoint_nodes(mesh, model.dof_points, a, b), model.n_full // 3)
    return traction_interface(mesh.points, mesh.tets, facets, owner, network.n_pores, p2_nodes=p2)


def throat_cylinders(net: Network):
    """(conns, radius, ends (Nt, 2, 3)) of the cylindrical part of every throat, m.

    The cylinder starts ``throat_pore_length[:, 0]`` from pore i's centre along the centre line
    and ends ``throat_pore_length[:, 1]`` before pore j's.
    """
    c = net.pore_coords
    i, j = net.throat_conns[:, 0], net.throat_conns[:, 1]
    d = c[j] - c[i]
    a = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)
    start = c[i] + a * net.throat_pore_length[:, [0]]
    end = c[j] - a * net.throat_pore_length[:, [1]]
    return net.throat_conns, net.throat_radius, np.stack([start, end], axis=1)


def build_problem(case: Case) -> CoupledProblem:
    """Build the coupled problem of ``case`` (image, network, mesh, interface, solid model)."""
    clock = StageClock()
    with clock("image"):
        img = load_case_image(case)

    with clock("extraction"):
        perc = percolating_cluster(img, case.image.axis)
        ex = extract_network(perc.image, conductance=case.network.conductance)

    with clock("mesh"):
        sc = case.solid
        mres = mesh_solid(img, coarsen=sc.coarsen, support_axis=sc.load_axis)
        material = make_material(sc.material, E=sc.E, nu=sc.nu, density=sc.density)
        ax = axis_index(sc.load_axis)
        if sc.strain_rate != 0:
            check_load_path(mres.mesh, ax)  # a load frame needs solid joining its two faces
        length = img.extent[ax]
        bcs = uniaxial_bcs(ax, rate=-sc.strain_rate * length)
        model = SolidModel(mres.mesh, material, bcs, order=sc.order, linear_solver=sc.linear_solver)

    with clock("interface_build"):
        itf = build_interface(case, ex.network, ex.labels, mres.mesh, img.voxel_size, img.origin, model)
    return CoupledProblem(case, img, ex, mres, itf, model, fluids_from_case(case), clock.wall, clock.cpu)
