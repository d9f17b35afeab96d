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

# Public functions, resolved lazily from the module that defines them.
_LAZY = {
    "VoxelImage": "porefsi.image",
    "Network": "porefsi.network",
    "read_image": "porefsi.image.io",
    "write_image": "porefsi.image.io",
    "load_sample": "porefsi.image.io",
    "segment": "porefsi.image.io",
    "crop": "porefsi.image.ops",
    "downsample": "porefsi.image.ops",
    "percolating_cluster": "porefsi.image.ops",
    "extract_network": "porefsi.network.extract",
    "absolute_permeability": "porefsi.flow.permeability",
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
