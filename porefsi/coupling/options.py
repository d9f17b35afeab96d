"""The option objects of a coupled simulation: small frozen dataclasses, validated when made.

Each class is one section of a case file (:mod:`porefsi.case.config` reads the TOML into these
very classes; ``[drainage]`` is the flow layer's :class:`~porefsi.flow.drainage.DrainageOptions`,
re-exported here), but nothing here knows of files: a Python user builds them directly. Defaults
are the seed paper's table 2 set-up; every field's unit, bounds and meaning are declared next to
it (:func:`porefsi._schema.option`), bounds of physical quantities taken from the physics
classes (:class:`~porefsi.solid.materials.Material`).

:class:`CoupledOptions` bundles one of each with the fluids, the flow axis and the interface
builder (:class:`~porefsi.coupling.traction.TractionOptions` or
:class:`~porefsi.coupling.hull.HullOptions`): what :func:`porefsi.coupling.problem.build_problem`
and :class:`~porefsi.coupling.loop.CoupledRun` take.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from porefsi._schema import Limits, option, validate
from porefsi.errors import ConfigError
from porefsi.flow.drainage import DrainageOptions
from porefsi.flow.fluids import Fluids
from porefsi.solid.materials import GRAIN_DENSITY, Material

if TYPE_CHECKING:
    from porefsi.coupling.hull import HullInterface
    from porefsi.coupling.traction import TractionInterface
    from porefsi.network.network import Network

__all__ = ["DrainageOptions", "SolidOptions", "NetworkOptions", "CouplingOptions", "HullOptions", "TractionOptions",
           "CoupledOptions"]

_POSITIVE = Limits(0.0, None, lo_open=True)


@dataclasses.dataclass(frozen=True)
class SolidOptions:
    """The rock frame: mesh, material, mechanical loading."""

    coarsen: int = option(5, "block-coarsening factor of the image before meshing (5: the paper's mesh size, "
                          "~57k tets on the 120³ sample)", limits=Limits(1))
    order: int = option(1, "finite-element order (1 = P1, 2 = P2)", choices=(1, 2))
    material: str = option("svk", "hyperelastic law", choices=("svk", "neo-hookean"))
    E: float = option(Material.E, "Young's modulus (paper: 20 GPa)", limits=Material.LIMITS["E"], unit="Pa")
    nu: float = option(Material.nu, "Poisson's ratio (paper: 0.28)", limits=Material.LIMITS["nu"])
    density: float = option(GRAIN_DENSITY, "grain density (quartz sandstone)", limits=Material.LIMITS["density"],
                            unit="kg/m^3")
    linear_solver: str = option("direct", "solid linear solves: direct = sparse LU factorised once and reused while "
                                "the tangent holds (fastest to ~1e5 dofs; above 1e5 free dofs, or where the factor "
                                "would not fit in memory, AMG-CG is used instead, with a warning); amg = CG + smoothed "
                                "aggregation (large meshes); jacobi = Jacobi-CG; auto = LU or AMG-CG per matrix, "
                                "chosen at its first solve from counted predicted costs when the stepper announces "
                                "how often its frozen tangent will be reused, else AMG-CG switching to a reused LU "
                                "once the AMG-CG work spent on it reaches its predicted factorisation (up to 1e5 "
                                "dofs)",
                                choices=("direct", "amg", "jacobi", "auto"))
    load_axis: str = option("z", "axis of the mechanical load (fixed low face, moving high face)",
                            choices=("x", "y", "z"))
    strain_rate: float = option(0.0, "compressive strain rate on the high face (paper section 3.3)", limits=Limits(0.0),
                                unit="1/s")
    response: str = option("nonlinear", "solid response in the coupled run: nonlinear = the hyperelastic solve "
                           "at every step; linear = superposed unit responses of the model linearised at u = 0 (one "
                           "factorisation, then a matrix-vector product or back-substitution per step), monitored; "
                           "auto = linear, falling back to nonlinear for good when the estimated error exceeds "
                           "response_tol or a re-extraction changes the pores (docs/coupling.md)",
                           choices=("nonlinear", "linear", "auto"))
    newton_rtol: float = option(1e-6, "static integrator: Newton tolerance on the residual relative to the load "
                                "(1e-6 moves the displacement by < 2e-7 relative from 1e-8 on the rocks measured, far "
                                "below the mesh's error; docs/solid.md section 5)",
                                limits=Limits(0.0, 1e-2, lo_open=True))
    response_tol: float = option(1e-3, "linear/auto: tolerance on the estimated relative displacement error of "
                                 "the linearisation (one Newton correction / max |u|)",
                                 limits=Limits(0.0, 1.0, lo_open=True, hi_open=True))
    mesh: str = option("uniform", "uniform = every block coarsen voxels across; graded = blocks of coarsen voxels "
                       "near the refined pores, leaves of 2, 4, ... x coarsen (up to coarsen_max) away from them, "
                       "2:1 balanced and conforming (docs/solid.md)", choices=("uniform", "graded"))
    coarsen_max: int = option(16, "graded mesh: largest leaf edge (voxels; leaves are coarsen x a power of 2)",
                              limits=Limits(1))
    grading: float = option(1.0, "graded mesh: a leaf of edge s blocks lies more than grading x s blocks from the "
                            "refined pores (smaller: coarser sooner)", limits=_POSITIVE)
    refine: str = option("walls", "graded mesh: where it stays at coarsen: walls = every pore wall (coarse only "
                         "inside grains); invaded = the pores invasion percolation fills with twice the injected "
                         "volume (drainage.rate x drainage.t_end), where the fluid load sits",
                         choices=("walls", "invaded"))
    ligaments: float = option(0.0, "graded mesh: also keep fine the solid ligaments between the refined pores "
                              "and the other pores thinner than this many mean chords of the refined pores "
                              "(where their load concentrates; 0 = off)", limits=Limits(0.0))

    def __post_init__(self):
        validate(self, "solid")


@dataclasses.dataclass(frozen=True)
class NetworkOptions:
    """How the pore network follows the deforming solid."""

    update: str = option("geometric", "reextract = paper (re-extraction with pre-coupling iterations); "
                         "geometric = move/resize pores from wall displacements; none = one-way",
                         choices=("reextract", "geometric", "none"))
    precoupling_tol: float = option(0.01, "tolerance on the mean-pore-size change E_a (eq. 3.3)", limits=_POSITIVE)
    precoupling_max_iter: int = option(10, "maximum pre-coupling re-extractions", limits=Limits(1))
    conductance: str = option("shape_factor", "conduit model of every flow computation: shape_factor = "
                              "Valvatne-Blunt sections measured from the image (agrees with the rock, "
                              "docs/extraction.md); paper = circular cylinders of the inscribed radius (the seed "
                              "paper's model)", choices=("shape_factor", "paper"))

    def __post_init__(self):
        validate(self, "network")


@dataclasses.dataclass(frozen=True)
class CouplingOptions:
    """The staggered two-way coupling loop (paper algorithm 1)."""

    exchange_dt: float = option(1.0, "exchange (coupling) time step", limits=_POSITIVE, unit="s")
    integrator: str = option("static", "solid time integrator: static (default; at ωΔt ~ 1e7 it matches 2-pass TDG "
                             "to 1e-15 for 12-20 % less CPU, docs/speed_accuracy.md) or tdg (the paper's, with "
                             "inertia)", choices=("tdg", "static"))
    tdg_iterations: int = option(2, "Nørsett predictor-corrector passes (2 = third order)", choices=(1, 2))
    tdg_load_rule: str = option("right", "TDG load samples: right = t+Δt/3, t+Δt (third order for the quasi-static "
                                "response of a stiff solid); left = t, t+2Δt/3 (the paper; second order there)",
                                choices=("right", "left"))
    subiterations: int = option(1, "fluid-solid sub-iterations per exchange step (1 = explicit staggering)",
                                limits=Limits(1))
    relaxation: str = option("aitken", "sub-iteration relaxation", choices=("none", "aitken"))
    subiteration_tol: float = option(1e-6, "relative displacement change that ends sub-iterations", limits=_POSITIVE)

    def __post_init__(self):
        validate(self, "coupling")


@dataclasses.dataclass(frozen=True)
class HullOptions:
    """How to build the hull interface (the ``[interface]`` keys of a case with ``method = "hull"``).

    Attributes
    ----------
    n_test_points : int, default 800
        Test points per pore sphere (the paper's 800).
    tolerance : float, optional
        Range of inclusivity ε, m; default half of each pore's radius.
    seed : int, default 0
        Seed of the test-point generator.
    throat_forces : bool, default False
        Also load the throat walls (the paper neglects them).
    """

    n_test_points: int = 800
    tolerance: float | None = None
    seed: int = 0
    throat_forces: bool = False

    def build(self, network: Network, labels, mesh, *, voxel_size: float, origin, model=None) -> HullInterface:
        """The hull interface of ``network`` on the pore-wall nodes of ``mesh`` (forces on its vertices).

        ``labels``, ``voxel_size``, ``origin`` and ``model`` are not needed by the hull (the
        :class:`~porefsi.coupling.interface.InterfaceBuilder` signature): its forces always go to
        the vertices (the paper's point loads).
        """
        from porefsi.coupling.hull import hull_interface, throat_cylinders

        wall = np.zeros(mesh.n_nodes, bool)
        wall[mesh.nodes_tagged("pore_wall")] = True
        return hull_interface(network.pore_coords, network.pore_radius, mesh.points,
                              n_test_points=self.n_test_points, tolerance=self.tolerance,
                              rng=np.random.default_rng(self.seed), candidates=wall,
                              throats=throat_cylinders(network) if self.throat_forces else None)


@dataclasses.dataclass(frozen=True)
class TractionOptions:
    """How to build the traction interface (a case with ``interface.method = "traction"``).

    Attributes
    ----------
    max_steps : int, default 4
        How far (voxels) :func:`facet_pores_from_labels` walks from a facet to find its pore; a
        coarsened mesh needs ``2 x coarsen`` (its facets sit up to a block away from the voxels).
    """

    max_steps: int = 4

    def build(self, network, labels, mesh, *, voxel_size: float, origin, model=None) -> TractionInterface:
        """The traction interface on the pore-wall facets of ``mesh``, owners from the voxel ``labels``.

        With a P2 ``model`` the traction is integrated against the P2 basis (forces on the
        edge-midpoint nodes; the vertex split is kept for outputs).
        """
        from porefsi.coupling.traction import boundary_facet_normals, facet_pores_from_labels, traction_interface
        from porefsi.solid.bc import midpoint_nodes

        facets = mesh.facets_tagged("pore_wall")
        normals, _ = boundary_facet_normals(mesh.points, mesh.tets, facets)
        owner = facet_pores_from_labels(mesh.points, facets, normals, labels, voxel_size, origin,
                                        max_steps=self.max_steps)
        p2 = None
        if model is not None and model.order == 2:
            p2 = (lambda a, b: midpoint_nodes(mesh, model.dof_points, a, b), model.n_full // 3)
        return traction_interface(mesh.points, mesh.tets, facets, owner, network.n_pores, p2_nodes=p2)


@dataclasses.dataclass(frozen=True)
class CoupledOptions:
    """Everything that defines a coupled simulation besides the image.

    Attributes
    ----------
    axis : {"x", "y", "z"}, default "x"
        Flow axis: inlet at the image's low face, outlet at its high face.
    fluids : Fluids
    drainage : DrainageOptions
    solid : SolidOptions
    interface : TractionOptions or HullOptions
        Builds the pressure -> force operator (also after a re-extraction changes the pores).
    network : NetworkOptions
    coupling : CouplingOptions
    """

    axis: str = "x"
    fluids: Fluids = dataclasses.field(default_factory=Fluids)
    drainage: DrainageOptions = dataclasses.field(default_factory=DrainageOptions)
    solid: SolidOptions = dataclasses.field(default_factory=SolidOptions)
    interface: TractionOptions | HullOptions = dataclasses.field(default_factory=TractionOptions)
    network: NetworkOptions = dataclasses.field(default_factory=NetworkOptions)
    coupling: CouplingOptions = dataclasses.field(default_factory=CouplingOptions)

    def __post_init__(self):
        if self.axis not in ("x", "y", "z"):
            raise ConfigError(f"option: CoupledOptions.axis = {self.axis!r} is not one of ['x', 'y', 'z']")
        if self.coupling.exchange_dt > self.drainage.t_end:
            raise ConfigError(f"option: coupling.exchange_dt = {self.coupling.exchange_dt} s exceeds drainage.t_end = "
                              f"{self.drainage.t_end} s; use a smaller exchange step")

    def replace(self, **changes) -> CoupledOptions:
        """A copy with parts replaced (``solid=SolidOptions(...)``) or updated (``solid={"coarsen": 10}``)."""
        new = {}
        for name, val in changes.items():
            cur = getattr(self, name)
            new[name] = dataclasses.replace(cur, **val) if isinstance(val, dict) else val
        return dataclasses.replace(self, **new)

    @property
    def n_exchange_steps(self) -> int:
        """Exchange steps from 0 to ``drainage.t_end`` (the last one may be shorter)."""
        import math

        return max(1, int(math.ceil(self.drainage.t_end / self.coupling.exchange_dt - 1e-9)))
