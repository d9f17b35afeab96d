"""The working domain of a voxel Stokes solve: flow-carrying pore clusters, buffer layers, mirroring."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy import ndimage
from scipy.sparse.csgraph import connected_components

from porefsi.errors import NetworkError
from porefsi.image.voxel_image import AXES

__all__ = ["flowing_clusters", "with_buffers", "mirrored"]


def flowing_clusters(pore: np.ndarray, axis: int, periodic) -> tuple[np.ndarray, int]:
    """Keep the face-connected pore clusters that touch both box faces normal to ``axis``.

    Clusters are joined across the box faces of the ``periodic`` axes first. Any other cluster
    carries no net flow along ``axis`` (it is closed, or open to one reservoir only), so removing
    it changes no flow rate; it would only add undetermined pressure constants.

    Returns
    -------
    kept : ndarray of bool, same shape
    n_clusters : int
        Number of clusters (after the periodic joins) in ``pore``.

    Raises
    ------
    NetworkError
        If no cluster touches both faces.
    """
    labels, n = ndimage.label(pore)
    pairs = []
    for a in range(3):
        if periodic[a]:
            lo, hi = np.take(labels, 0, axis=a).ravel(), np.take(labels, -1, axis=a).ravel()
            both = (lo > 0) & (hi > 0)
            pairs.append(np.stack([lo[both], hi[both]]))
    if pairs:
        e = np.concatenate(pairs, axis=1)
        g = sp.coo_matrix((np.ones(e.shape[1]), (e[0], e[1])), shape=(n + 1, n + 1))
        n, merged = connected_components(g, directed=False)
        merged = merged - merged[0]  # the background label 0 stays 0 (its component holds only it)
        merged[merged < 0] += n
        labels = merged[labels]
    first = np.unique(np.take(labels, 0, axis=axis))
    last = np.unique(np.take(labels, -1, axis=axis))
    both = np.intersect1d(first[first > 0], last[last > 0])
    if both.size == 0:
        name = AXES[axis]
        raise NetworkError(
            f"no pore path connects the {name}min and {name}max faces (face-connected voxels, porosity "
            f"{float(np.mean(pore)):.4f}): no flow along {name}; try another axis or a larger crop"
        )
    keep = np.zeros(int(labels.max()) + 1, dtype=bool)
    keep[both] = True
    return keep[labels], int(n - 1 if pairs else n)


def with_buffers(pore: np.ndarray, axis: int, layers: int) -> np.ndarray:
    """``pore`` with ``layers`` all-fluid layers added before and after along ``axis``."""
    if layers == 0:
        return pore
    shape = list(pore.shape)
    shape[axis] = layers
    slab = np.ones(shape, dtype=bool)
    return np.concatenate([slab, pore, slab], axis=axis)


def mirrored(pore: np.ndarray, axis: int) -> np.ndarray:
    """``pore`` followed by its mirror image along ``axis`` (twice as long; periodic along it)."""
    return np.concatenate([pore, np.flip(pore, axis=axis)], axis=axis)
