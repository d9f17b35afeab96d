"""Operations on segmented images: crop, downsample, keep the percolating pore cluster.

Every function returns a new :class:`~porefsi.image.VoxelImage` and leaves its input untouched.
Physical positions are preserved: a voxel keeps its place in space (``origin`` is shifted by a
crop), so networks extracted from a crop overlay the full image.
"""

from __future__ import annotations

import dataclasses
import math
from fractions import Fraction

import numpy as np
from scipy import ndimage

from porefsi.errors import InputError, NetworkError
from porefsi.image.voxel_image import AXES, VoxelImage, axis_index

__all__ = ["crop", "downsample", "percolating_cluster", "PercolationResult"]


def _check_image(image) -> VoxelImage:
    if not isinstance(image, VoxelImage):
        raise InputError(f"expected a VoxelImage, got {type(image).__name__}; read one with read_image(...)")
    return image


def crop(image: VoxelImage, start, stop) -> VoxelImage:
    """Cut the box ``[start, stop)`` (voxel indices per axis) out of ``image``.

    Parameters
    ----------
    image : VoxelImage
        The image; not modified.
    start, stop : sequence of 3 int
        First voxel kept and one past the last, per axis (x, y, z), with
        ``0 <= start < stop <= shape``. ``None`` entries mean 0 and the full extent.

    Returns
    -------
    VoxelImage
        Shape ``stop - start``, same voxel size, ``origin + start * voxel_size``: every voxel keeps
        its physical position.

    Raises
    ------
    InputError
        If the bounds are not 3 integers inside the image or the box is empty.

    Examples
    --------
    >>> import numpy as np
    >>> img = VoxelImage(np.ones((4, 4, 4), np.uint8), 1e-6)
    >>> c = crop(img, (1, 0, 2), (3, 4, 4))
    >>> c.shape, c.origin.tolist()
    ((2, 4, 2), [1e-06, 0.0, 2e-06])
    """
    image = _check_image(image)
    shape = image.shape

    def bounds(v, name, default):
        if v is None:
            return list(default)
        vals = list(v)
        if len(vals) != 3:
            raise InputError(f"crop {name} must be 3 voxel indices (x, y, z), got {v!r}")
        out = []
        for x, d in zip(vals, default, strict=True):
            if x is None:
                out.append(d)
            elif isinstance(x, (int, np.integer)) and not isinstance(x, bool):
                out.append(int(x))
            else:
                raise InputError(f"crop {name} must hold integers, got {v!r}")
        return out

    lo = bounds(start, "start", (0, 0, 0))
    hi = bounds(stop, "stop", shape)
    for ax in range(3):
        if not 0 <= lo[ax] < hi[ax] <= shape[ax]:
            raise InputError(
                f"crop [{lo[ax]}, {hi[ax]}) along {AXES[ax]} is outside the image or empty: need "
                f"0 <= start < stop <= {shape[ax]} (image shape {shape})"
            )
    sub = image.phases[lo[0] : hi[0], lo[1] : hi[1], lo[2] : hi[2]].copy()
    return VoxelImage(sub, image.voxel_size, image.origin + np.asarray(lo, dtype=float) * image.voxel_size)


def downsample(image: VoxelImage, factor: int, *, threshold: float = 0.5) -> VoxelImage:
    r"""Coarsen ``image`` by an integer ``factor``: block average of the pore indicator, thresholded.

    Parameters
    ----------
    image : VoxelImage
        The image; not modified.
    factor : int
        Block edge in voxels, >= 1. The new voxel size is ``factor * voxel_size``.
    threshold : float, default 0.5
        A block becomes pore when its pore fraction is ``>= threshold``, with
        ``0 < threshold <= 1`` (1 keeps only all-pore blocks).

    Returns
    -------
    VoxelImage
        Shape ``shape // factor``, voxel size ``factor * voxel_size``, same origin.

    Raises
    ------
    InputError
        If ``factor`` is not a positive integer, is larger than an axis, or ``threshold`` is
        outside (0, 1].

    Notes
    -----
    Block :math:`B` of the result is pore when

    .. math:: \frac{1}{f^3} \sum_{v \in B} \phi_v \ge t,

    evaluated exactly on integer voxel counts, with :math:`t` taken as the decimal it prints as
    (``0.1`` is exactly 1/10, so a block of 8^3 voxels needs ceil(51.2) = 52 pore voxels).
    When an axis length is not a multiple of ``factor``, the last ``n % factor`` layers on the
    high side are dropped (the origin and all kept positions are unchanged).

    Examples
    --------
    >>> import numpy as np
    >>> a = np.zeros((4, 2, 2), np.uint8); a[:2] = 1; a[2, 0, 0] = 1
    >>> downsample(VoxelImage(a, 1e-6), 2).phases[:, 0, 0].tolist()
    [1, 0]
    """
    image = _check_image(image)
    if isinstance(factor, bool) or not isinstance(factor, (int, np.integer)) or factor < 1:
        raise InputError(f"downsample factor must be a positive integer, got {factor!r}")
    f = int(factor)
    t = float(threshold)
    if not 0.0 < t <= 1.0:
        raise InputError(f"downsample threshold must be in (0, 1] (pore fraction of a block), got {threshold!r}")
    nb = tuple(n // f for n in image.shape)
    if min(nb) < 1:
        raise InputError(f"downsample factor {f} is larger than the image shape {image.shape}; use a smaller factor")
    if f == 1:
        return VoxelImage(image.phases.copy(), image.voxel_size, image.origin.copy())
    a = image.phases[: nb[0] * f, : nb[1] * f, : nb[2] * f]
    counts = a.reshape(nb[0], f, nb[1], f, nb[2], f).sum(axis=(1, 3, 5), dtype=np.int64)
    # count / f^3 >= t  <=>  count >= ceil(t f^3), with t the decimal it prints as (0.1 is 1/10)
    need = math.ceil(Fraction(repr(t)) * f**3)
    phases = (counts >= need).astype(np.uint8)
    return VoxelImage(phases, image.voxel_size * f, image.origin.copy())


@dataclasses.dataclass(frozen=True)
class PercolationResult:
    """The pore space connected to both faces of an axis.

    Attributes
    ----------
    image : VoxelImage
        Same box as the input; pore voxels not in a percolating cluster set to solid.
    removed_fraction : float
        Fraction of the input's pore voxels removed (isolated or touching at most one face).
    n_clusters : int
        Number of connected pore clusters in the input.
    n_percolating : int
        Number of those clusters that touch both faces.
    """

    image: VoxelImage
    removed_fraction: float
    n_clusters: int
    n_percolating: int


_STRUCTURES = {6: 1, 18: 2, 26: 3}


def percolating_cluster(image: VoxelImage, axis, *, connectivity: int = 6) -> PercolationResult:
    """Keep only the pore voxels connected to both faces normal to ``axis``.

    Parameters
    ----------
    image : VoxelImage
        The image; not modified.
    axis : {'x', 'y', 'z', 0, 1, 2}
        Flow axis; the faces are the first and last layers of voxels along it.
    connectivity : {6, 18, 26}, default 6
        Voxel neighbourhood: faces (6), faces and edges (18), or also corners (26). 6 is the
        conservative choice for flow: two voxels touching only along an edge share no area.

    Returns
    -------
    PercolationResult
        The filtered image, the fraction of pore voxels removed, cluster counts.

    Raises
    ------
    NetworkError
        If no pore cluster touches both faces.
    InputError
        If ``axis`` or ``connectivity`` is not valid.

    Examples
    --------
    >>> import numpy as np
    >>> a = np.zeros((3, 3, 3), np.uint8); a[:, 1, 1] = 1; a[0, 0, 0] = 1
    >>> r = percolating_cluster(VoxelImage(a, 1e-6), "x")
    >>> int(r.image.phases.sum()), r.removed_fraction, r.n_clusters
    (3, 0.25, 2)
    """
    image = _check_image(image)
    ax = axis_index(axis)
    if connectivity not in _STRUCTURES:
        raise InputError(f"connectivity must be 6, 18 or 26, got {connectivity!r}")
    structure = ndimage.generate_binary_structure(3, _STRUCTURES[connectivity])
    pore = image.pore
    labels, n = ndimage.label(pore, structure=structure)
    first = np.unique(np.take(labels, 0, axis=ax))
    last = np.unique(np.take(labels, -1, axis=ax))
    both = np.intersect1d(first[first > 0], last[last > 0])
    name = AXES[ax]
    if both.size == 0:
        raise NetworkError(
            f"no pore path connects the {name}min and {name}max faces (axis {name}, {connectivity}-connected; "
            f"{n} pore clusters, porosity {image.porosity:.4f}); try another axis, a larger crop, or extracting "
            "every cluster without this filter (CLI --axis, --keep-isolated; API: extract_network on the "
            "image as is)"
        )
    keep_label = np.zeros(n + 1, dtype=bool)
    keep_label[both] = True
    keep = keep_label[labels]
    n_pore = int(np.count_nonzero(pore))
    n_kept = int(np.count_nonzero(keep))
    out = VoxelImage(keep.view(np.uint8), image.voxel_size, image.origin.copy())
    return PercolationResult(out, (n_pore - n_kept) / n_pore, int(n), int(both.size))
