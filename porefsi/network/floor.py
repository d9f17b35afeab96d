r"""The extraction's noise floor in the image's own length: resolution-invariant by construction.

A maximal-ball pore must hold a ball of some least radius, or every ripple of the distance map
would be a pore. A floor fixed in voxels is not a property of the rock: the same rock scanned
(or upsampled) ``f`` times finer has its balls ``f`` times wider in voxels and yields more pores
(1.5-2.6x at 2-3x upsampling with a 2-voxel floor, docs/extraction.md). The automatic floor is a
fixed fraction of a length the image itself carries, its *hydraulic radius* (Kozeny's length)

.. math:: L = V_p / S_p,

pore volume over pore-solid surface, both counted on the voxels (pore voxels, and voxel faces
between a pore and a solid voxel: the staircase's area). Nearest-neighbour refinement by ``f``
keeps the staircase, so ``L`` in voxels is exactly ``f`` times the native one; for a smooth
surface the staircase area is a resolution-independent ~3/2 of the true one (the mean of
``|n_x| + |n_y| + |n_z|`` over isotropic orientations), so ``L`` still scales with the voxel
size (measured within 2 % at 2x and 3x, docs/extraction.md). The floor is applied to the ball's
distance to the wall, ``sqrt(dt2) - 1/2`` (exact at an axis-aligned wall):

.. math:: r_\min = \max\left(2,\; c\,L + \tfrac12\right), \qquad c = 0.93 ,

lowered to the largest ball of the image where it lies above it (:func:`largest_ball_cap`: a
uniform slit has ``L`` equal to its largest ball's wall distance).

The 2-voxel minimum is the resolution limit (a one-voxel error on a radius-1 ball is 100 %),
which the old fixed default applied everywhere; it also means that noise in a segmentation
(specks of solid in the pores, which add surface) can only bring the floor back down to it.
``c`` is the one calibrated constant: it keeps the floor at the old 2 voxels on the Berea images
at their scanned voxel (5.345 µm; ``L`` = 1.47-1.61 voxels over the 400³ image, its four 200³
octant crops and the 120³ sample, so ``c L + 1/2`` = 1.87-1.99: the same candidates
``sqrt(dt2) >= 2`` as before; any ``c`` in (0.84, 0.93] does, 0.95 moves one crop to
``dt2 >= 5``, 11 % fewer pores), and at the largest such value, where the pore counts of
upsampled images depend least on it (they grow as ``c L`` falls below ~1.4 native voxels,
measured on the sample and a Berea crop).
"""

from __future__ import annotations

import math

import numpy as np

from porefsi.errors import InputError
from porefsi.image.voxel_image import VoxelImage
from porefsi.network import _kernels as kern

__all__ = [
    "FLOOR_PER_HYDRAULIC_RADIUS",
    "MIN_RADIUS_VOXELS",
    "hydraulic_radius",
    "largest_ball_cap",
    "noise_floor",
    "resolve_min_radius",
]

#: ``c`` of the automatic floor: the wall distance a pore's ball must reach, in hydraulic radii.
FLOOR_PER_HYDRAULIC_RADIUS = 0.93

#: Least automatic floor, voxels (``sqrt(dt2)``): the resolution limit, the old fixed default.
MIN_RADIUS_VOXELS = 2.0


def _phases(image) -> np.ndarray:
    if not isinstance(image, VoxelImage):
        raise TypeError(f"expected a porefsi VoxelImage, got {type(image).__name__}")
    return np.ascontiguousarray(image.phases, dtype=np.uint8)


def hydraulic_radius(image: VoxelImage) -> float:
    """Pore volume over pore-solid surface of a segmented image, voxels.

    Parameters
    ----------
    image : VoxelImage
        Segmented image, 1 = pore.

    Returns
    -------
    float
        ``L = n_pore / n_faces``: pore voxels over voxel faces shared by a pore and a solid voxel
        (faces on the box boundary are not counted: outside the image is not solid). Multiply by
        ``image.voxel_size`` for metres. A slit of half-aperture ``h`` voxels has ``L = h``, a
        square duct of side ``w`` has ``w / 4``.

    Raises
    ------
    TypeError
        If ``image`` is not a VoxelImage.
    InputError
        If the image has no pore-solid face (all pore or all solid).

    Examples
    --------
    >>> import numpy as np
    >>> from porefsi.image.voxel_image import VoxelImage
    >>> slit = np.zeros((10, 10, 8), np.uint8)
    >>> slit[:, :, 2:6] = 1                       # 4 voxels wide: half-aperture 2
    >>> hydraulic_radius(VoxelImage(slit, 1e-6))
    2.0
    """
    pore = _phases(image)
    n_faces = int(kern._pore_solid_faces(pore))
    if n_faces == 0:
        raise InputError(
            "the image has no face between a pore and a solid voxel, so no hydraulic radius (and no automatic "
            "noise floor); pass an image holding both phases, or a numeric min_radius"
        )
    return int(np.count_nonzero(pore)) / n_faces


def noise_floor(image: VoxelImage) -> float:
    """The automatic ``min_radius`` of :func:`porefsi.network.extract.extract_network`, voxels.

    ``max(MIN_RADIUS_VOXELS, FLOOR_PER_HYDRAULIC_RADIUS * L + 1/2)`` with ``L`` the
    :func:`hydraulic_radius`: a pore's ball must reach ``c L`` from the wall (``sqrt(dt2) - 1/2``),
    and at least the 2-voxel resolution limit. See the module docstring for why. The extraction
    also lowers it to the image's largest ball (:func:`largest_ball_cap`).

    Parameters
    ----------
    image : VoxelImage
        Segmented image, 1 = pore.

    Returns
    -------
    float
        Noise floor, voxels (compared with ``sqrt(dt2)``, the distance to the nearest solid voxel
        centre).

    Raises
    ------
    TypeError, InputError
        As :func:`hydraulic_radius`.
    """
    return max(MIN_RADIUS_VOXELS, FLOOR_PER_HYDRAULIC_RADIUS * hydraulic_radius(image) + 0.5)


def resolve_min_radius(min_radius, image: VoxelImage) -> float:
    """The noise floor in voxels for ``min_radius`` (``"auto"`` or a number >= 1).

    Raises
    ------
    InputError
        If ``min_radius`` is neither ``"auto"`` nor a finite number >= 1 (one line naming the fix).
    """
    if isinstance(min_radius, str):
        if min_radius.strip().lower() == "auto":
            return noise_floor(image)
        raise InputError(
            f"min_radius must be 'auto' or a number of voxels >= 1, got {min_radius!r}; the default is 'auto'"
        )
    if isinstance(min_radius, (bool, np.bool_)) or not isinstance(min_radius, (int, float, np.integer, np.floating)):
        raise InputError(
            f"min_radius must be 'auto' or a number of voxels >= 1, got {min_radius!r} "
            f"({type(min_radius).__name__}); the default is 'auto'"
        )
    value = float(min_radius)
    if not (math.isfinite(value) and value >= 1.0):
        raise InputError(f"min_radius must be >= 1 voxel (or 'auto'), got {min_radius!r}; the default is 'auto'")
    return value


def largest_ball_cap(floor: float, max_d2: int) -> float:
    """The automatic floor, lowered to the image's largest ball if it lies above it (never below 2 voxels).

    In a uniform layer (a slit) the hydraulic radius is the largest ball's own wall distance
    (``L = h``) and, on an even number of voxels, no voxel centre lies on the mid-plane, so
    ``c L + 1/2`` can exceed every ball (a slit 4 voxels wide: 2.36 against 2). Every maximum of
    such an image is real; the floor is then the largest ball, so the extraction finds its pores
    instead of none. Rocks are far from it (Berea: largest ball 8-20 voxels, ``L`` 1.5).

    Parameters
    ----------
    floor : float
        The automatic floor of :func:`noise_floor`, voxels.
    max_d2 : int
        Largest squared distance of the image's distance map (``sqrt`` = the largest ball, voxels).
    """
    return max(MIN_RADIUS_VOXELS, min(float(floor), math.sqrt(max_d2)))
