"""porefsi: pore-scale hydromechanics.

From a segmented micro-CT image of rock: a maximal-ball pore network, dynamic two-phase
drainage on it, and the deformation it causes in the solid (finite elements), two-way coupled.

``import porefsi`` is cheap: it compiles no numba kernel and imports scikit-fem, pyvista and
matplotlib only when a function that needs them runs.
"""

from __future__ import annotations

import importlib

from porefsi._version import __version__
from porefsi.errors import (
    ConfigError,
    ConvergenceError,
    InputError,
    MeshError,
    NetworkError,
    PorefsiError,
)

# The public API, resolved lazily from the module that defines each name (docs/api.md).
_LAZY = {
    # images
    "VoxelImage": "porefsi.image.voxel_image",
    "read_image": "porefsi.image.io",
    "write_image": "porefsi.image.io",
    "load_sample": "porefsi.image.io",
    "segment": "porefsi.image.io",
    "crop": "porefsi.image.ops",
    "downsample": "porefsi.image.ops",
    "percolating_cluster": "porefsi.image.ops",
    # networks
    "Network": "porefsi.network.network",
    "Extraction": "porefsi.network.extract",
    "extract_network": "porefsi.network.extract",
    "save_network": "porefsi.network.convert",
    "load_network": "porefsi.network.convert",
    # flow
    "Fluids": "porefsi.flow.fluids",
    "absolute_permeability": "porefsi.flow.permeability",
    "PermeabilityResult": "porefsi.flow.permeability",
    "voxel_permeability": "porefsi.stokes.permeability",
    "StokesResult": "porefsi.stokes.permeability",
    "simulate_drainage": "porefsi.flow.drainage",
    "DrainageSimulator": "porefsi.flow.drainage",
    "DrainageResult": "porefsi.flow.state",
    "FlowState": "porefsi.flow.state",
    # solid
    "mesh_solid": "porefsi.solid.mesh",
    "make_material": "porefsi.solid.materials",
    "uniaxial_bcs": "porefsi.solid.bc",
    "SolidModel": "porefsi.solid.model",
    "solve_static": "porefsi.solid.static",
    # coupling
    "CoupledOptions": "porefsi.coupling.options",
    "DrainageOptions": "porefsi.coupling.options",
    "SolidOptions": "porefsi.coupling.options",
    "NetworkOptions": "porefsi.coupling.options",
    "CouplingOptions": "porefsi.coupling.options",
    "HullOptions": "porefsi.coupling.options",
    "TractionOptions": "porefsi.coupling.options",
    "CoupledProblem": "porefsi.coupling.problem",
    "build_problem": "porefsi.coupling.problem",
    "CoupledRun": "porefsi.coupling.loop",
    "ExchangeRecord": "porefsi.coupling.records",
    # cases
    "Case": "porefsi.case.config",
    "load_case": "porefsi.case.config",
    "smoke_case": "porefsi.case.config",
    "problem_from_case": "porefsi.case.problem",
    "run_case": "porefsi.case.run",
    "RunOutput": "porefsi.case.run",
    "read_pore_steps": "porefsi.io.results",
    # units
    "MILLIDARCY": "porefsi.units",
}

__all__ = [
    "__version__",
    "PorefsiError",
    "InputError",
    "ConfigError",
    "MeshError",
    "NetworkError",
    "ConvergenceError",
    *_LAZY,
]


def __getattr__(name: str):
    mod = _LAZY.get(name)
    if mod is None:
        raise AttributeError(f"module 'porefsi' has no attribute {name!r}")
    return getattr(importlib.import_module(mod), name)


def __dir__():
    return sorted(__all__)
