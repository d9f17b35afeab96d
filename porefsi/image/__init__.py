"""Segmented images: the :class:`VoxelImage` type, readers/writers, crops, synthetic geometry."""

from porefsi.image.io import MHD_UNITS, READ_FORMATS, SAMPLES, load_sample, read_image, segment, write_image
from porefsi.image.ops import PercolationResult, crop, downsample, percolating_cluster
from porefsi.image.voxel_image import AXES, VoxelImage, axis_index

__all__ = [
    "VoxelImage",
    "AXES",
    "axis_index",
    # io
    "read_image",
    "write_image",
    "segment",
    "load_sample",
    "SAMPLES",
    "READ_FORMATS",
    "MHD_UNITS",
    # ops
    "crop",
    "downsample",
    "percolating_cluster",
    "PercolationResult",
    # synthetic (added by its module)
]
