"""Pore networks: the :class:`Network` type, extraction from images, geometry, conversions."""

from porefsi._lazy import exports

#: Public name -> the module that defines it (imported on first use).
_EXPORTS = {
    "Network": "porefsi.network.network",
    "FACES": "porefsi.network.network",
    "CONDUCTANCE_MODELS": "porefsi.network.network",
    "Extraction": "porefsi.network.extract",
    "ExtractionInfo": "porefsi.network.extract",
    "extract_network": "porefsi.network.extract",
    "hydraulic_radius": "porefsi.network.floor",
    "noise_floor": "porefsi.network.floor",
    "conduit_conductance": "porefsi.network.geometry",
    "resistance_factors": "porefsi.network.geometry",
    "save_network": "porefsi.network.convert",
    "load_network": "porefsi.network.convert",
    "to_openpnm": "porefsi.network.convert",
    "from_openpnm": "porefsi.network.convert",
    "write_statoil": "porefsi.network.statoil",
    "read_statoil": "porefsi.network.statoil",
    "lattice_network": "porefsi.network.lattice",
    "tube_network": "porefsi.network.lattice",
    "chain_network": "porefsi.network.lattice",
    "parallel_paths_network": "porefsi.network.lattice",
}

__all__ = [
    "Network",
    "FACES",
    "CONDUCTANCE_MODELS",
    "Extraction",
    "ExtractionInfo",
    "extract_network",
    "hydraulic_radius",
    "noise_floor",
    "conduit_conductance",
    "resistance_factors",
    "save_network",
    "load_network",
    "to_openpnm",
    "from_openpnm",
    "write_statoil",
    "read_statoil",
    "lattice_network",
    "tube_network",
    "chain_network",
    "parallel_paths_network",
]

__getattr__, __dir__ = exports(__name__, _EXPORTS)
