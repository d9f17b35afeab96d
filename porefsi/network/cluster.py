"""The pore space percolating along an axis, by floods from one face (no cluster labels).

:func:`percolating_pores` gives the same voxels as :func:`porefsi.image.ops.percolating_cluster`
(6-connected) without labelling every cluster: each cluster met on the first face is flooded
from there and kept if the flood reaches the last face. It needs 1 byte per voxel (the result)
plus a 4-byte queue entry per voxel of the largest cluster (8 above 2^31 voxels) instead of the
labelling's 4 bytes per voxel and its mask: ``porefsi extract`` uses it. Checked against
``percolating_cluster`` in ``tests/test_network_cluster.py``.
"""

from __future__ import annotations

import numpy as np

from porefsi._numba import jit, prange
from porefsi.errors import InputError
from porefsi.image.voxel_image import VoxelImage, axis_index
from porefsi.network._mb_prefetch import _prefetch

__all__ = ["percolating_pores"]


@jit
def _flood_cluster(mark, dims, ax, queue, tail):
    """Breadth-first flood from ``queue[:tail]`` (marked 2) through 6-neighbours marked 1, marking them 2.

    Returns the queue's length (the cluster's voxels are ``queue[:length]``) and whether one of
    them lies in the last layer along axis ``ax``.
    """
    nx, ny, nz = dims
    sx = ny * nz
    last = dims[ax] - 1
    hit = False
    head = 0
    while head < tail:
        if head + 8 < tail:  # the far neighbours of a voxel a few steps ahead (latency-bound flood)
            f = np.int64(queue[head + 8])
            _prefetch(mark, f - sx)
            _prefetch(mark, f + sx)
            _prefetch(mark, f - nz)
            _prefetch(mark, f + nz)
        n = np.int64(queue[head])
        head += 1
        q = n // nz
        i = q // ny
        j = q - i * ny
        k = n - q * nz
        if (ax == 0 and i == last) or (ax == 1 and j == last) or (ax == 2 and k == last):
            hit = True
        for t in range(6):
            if t == 0:
                m = n - sx if i > 0 else -1
            elif t == 1:
                m = n + sx if i < nx - 1 else -1
            elif t == 2:
                m = n - nz if j > 0 else -1
            elif t == 3:
                m = n + nz if j < ny - 1 else -1
            elif t == 4:
                m = n - 1 if k > 0 else -1
            else:
                m = n + 1 if k < nz - 1 else -1
            if m >= 0 and mark[m] == 1:
                mark[m] = 2
                queue[tail] = m
                tail += 1
    return tail, hit


@jit(parallel=True)
def _keep_marked(mark, nx, value):
    """``mark = (mark == value)`` in place over ``nx`` slabs on numba's threads; voxels kept."""
    per = np.zeros(nx, np.int64)
    slab = mark.size // nx
    for i in prange(nx):
        n = 0
        for p in range(i * slab, (i + 1) * slab):
            keep = mark[p] == value
            mark[p] = 1 if keep else 0
            n += keep
        per[i] = n
    return per.sum()


@jit
def _percolating(mark, dims, ax, queue):
    """Keep in ``mark`` (1 = pore, modified in place) the pore voxels 6-connected to both faces of axis ``ax``.

    Each cluster met on the first face (C order) is flooded alone (:func:`_flood_cluster`) and,
    if it reaches the last face, its voxels (the queue) are marked 3. Returns the voxels kept.
    """
    nx, ny, nz = dims
    for i in range(nx if ax != 0 else 1):
        for j in range(ny if ax != 1 else 1):
            for k in range(nz if ax != 2 else 1):
                n = (np.int64(i) * ny + j) * nz + k
                if mark[n] != 1:
                    continue
                mark[n] = 2
                queue[0] = n
                tail, hit = _flood_cluster(mark, dims, ax, queue, 1)
                if hit:
                    for h in range(tail):
                        if h + 16 < tail:
                            _prefetch(mark, queue[h + 16])
                        mark[np.int64(queue[h])] = 3
    return _keep_marked(mark, nx, 3)


def percolating_pores(image: VoxelImage, axis) -> tuple[VoxelImage, float]:
    """The pore voxels 6-connected to both faces normal to ``axis``, and the fraction removed.

    Parameters
    ----------
    image : VoxelImage
        Segmented image (1 = pore); not modified.
    axis : {'x', 'y', 'z', 0, 1, 2}
        Flow axis.

    Returns
    -------
    image : VoxelImage
        Same box, voxel size and origin; pore voxels in no percolating cluster set to solid. Its
        array is new and read-only (no copy is made for the VoxelImage).
    removed_fraction : float
        Fraction of the input's pore voxels removed; 1.0 when no cluster percolates (the image
        then holds no pore voxel).

    Raises
    ------
    InputError
        If ``image`` is not a VoxelImage or ``axis`` is not valid.
    """
    if not isinstance(image, VoxelImage):
        raise InputError(f"percolating_pores needs a porefsi VoxelImage, got {type(image).__name__}")
    ax = axis_index(axis)
    mark = image.phases.copy()
    n_pore = int(np.count_nonzero(mark))
    if n_pore == 0:
        return VoxelImage(_frozen(mark), image.voxel_size, image.origin.copy()), 0.0
    queue = np.empty(n_pore, np.int32 if mark.size < np.iinfo(np.int32).max else np.int64)
    dims = tuple(int(s) for s in mark.shape)
    n_kept = int(_percolating(mark.reshape(-1), dims, np.int64(ax), queue))
    del queue
    return VoxelImage(_frozen(mark), image.voxel_size, image.origin.copy()), (n_pore - n_kept) / n_pore


def _frozen(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)  # VoxelImage keeps a read-only array as it is (no copy)
    return a
