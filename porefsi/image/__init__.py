"""Segmented images: the :class:`VoxelImage` type, readers/writers, crops, synthetic geometry."""

from porefsi.image.voxel_image import AXES, VoxelImage, axis_index

__all__ = ["VoxelImage", "AXES", "axis_index"]
