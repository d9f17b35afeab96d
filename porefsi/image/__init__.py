"""Segmented images: the :class:`VoxelImage` type, readers/writers, crops, synthetic geometry."""

from porefsi._lazy import exports

#: Public name -> the module that defines it (imported on first use).
_EXPORTS = {
    "VoxelImage": "porefsi.image.voxel_image",
    "AXES": "porefsi.image.voxel_image",
    "axis_index": "porefsi.image.voxel_image",
    "read_image": "porefsi.image.io",
    "write_image": "porefsi.image.io",
    "segment": "porefsi.image.io",
    "load_sample": "porefsi.image.io",
    "SAMPLES": "porefsi.image.io",
    "READ_FORMATS": "porefsi.image.io",
    "MHD_UNITS": "porefsi.image.io",
    "PlausibilityWarning": "porefsi.image.io",
    "RawLayout": "porefsi.image.io",
    "crop": "porefsi.image.ops",
    "downsample": "porefsi.image.ops",
    "percolating_cluster": "porefsi.image.ops",
    "PercolationResult": "porefsi.image.ops",
    "SyntheticLattice": "porefsi.image.synthetic",
    "SyntheticBundle": "porefsi.image.synthetic",
    "sphere_lattice": "porefsi.image.synthetic",
    "cylinder_bundle": "porefsi.image.synthetic",
    "available_memory": "porefsi.image._memory",
    "format_bytes": "porefsi.image._memory",
}

__all__ = [
    "VoxelImage",
    "AXES",
    "axis_index",
    "read_image",
    "write_image",
    "segment",
    "load_sample",
    "SAMPLES",
    "READ_FORMATS",
    "MHD_UNITS",
    "PlausibilityWarning",
    "RawLayout",
    "crop",
    "downsample",
    "percolating_cluster",
    "PercolationResult",
    "SyntheticLattice",
    "SyntheticBundle",
    "sphere_lattice",
    "cylinder_bundle",
    "available_memory",
    "format_bytes",
]

__getattr__, __dir__ = exports(__name__, _EXPORTS)
