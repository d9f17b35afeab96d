"""The segmented image type that every other module reads."""

from __future__ import annotations

import dataclasses

import numpy as np

from porefsi.errors import InputError

__all__ = ["VoxelImage", "AXES", "axis_index", "positive_length"]

#: Axis names; x, y, z are array axes 0, 1, 2.
AXES = ("x", "y", "z")


def positive_length(value, name: str, hint: str = "") -> float:
    """``value`` as a float length in metres, or :class:`InputError` unless it is finite and > 0.

    The message reads ``"{name} must be a positive length in metres, got {value!r}{hint}"``.
    """
    try:
        x = float(value)
    except (TypeError, ValueError):  # e.g. a string that is not a number
        x = float("nan")
    if not np.isfinite(x) or x <= 0:
        raise InputError(f"{name} must be a positive length in metres, got {value!r}{hint}")
    return x


def axis_index(axis: str | int) -> int:
    """Return the array axis (0, 1, 2) named by ``axis`` ('x', 'y', 'z' or 0, 1, 2).

    Raises
    ------
    InputError
        If ``axis`` names no axis.
    """
    if isinstance(axis, (int, np.integer)) and not isinstance(axis, bool) and 0 <= int(axis) <= 2:
        return int(axis)
    if isinstance(axis, str) and axis.lower() in AXES:
        return AXES.index(axis.lower())
    raise InputError(f"unknown axis {axis!r}; use 'x', 'y' or 'z' (array axes 0, 1, 2)")


@dataclasses.dataclass(frozen=True, eq=False)
class VoxelImage:
    """A segmented 3-D image: 1 = pore, 0 = solid.

    Parameters
    ----------
    phases : ndarray of uint8, shape (nx, ny, nz)
        1 where the voxel is pore space, 0 where it is solid. A writable array of the caller's is
        copied (the caller's array is never frozen or aliased); a read-only one is shared.
    voxel_size : float
        Edge length of a cubic voxel, m. Must be positive and finite.
    origin : ndarray of float, shape (3,), optional
        Position of the corner of voxel (0, 0, 0), m. Voxel (i, j, k) spans
        ``origin + voxel_size * [i, i+1) x [j, j+1) x [k, k+1)``; its centre is at
        ``origin + voxel_size * (i + 1/2, j + 1/2, k + 1/2)``.

    Notes
    -----
    The stored array is read-only so that a ``VoxelImage`` can be shared between stages.
    """

    phases: np.ndarray
    voxel_size: float
    origin: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(3))

    def __post_init__(self):
        ph = np.asarray(self.phases)
        if ph.ndim != 3:
            raise InputError(f"image must be 3-D, got shape {ph.shape}; pass a (nx, ny, nz) array")
        if min(ph.shape) < 1:
            raise InputError(f"image has an empty axis, shape {ph.shape}")
        if ph.dtype != np.uint8:
            if ph.dtype == bool or np.issubdtype(ph.dtype, np.integer):
                vals = np.unique(ph)
                if not np.all(np.isin(vals, (0, 1))):
                    raise InputError(
                        f"VoxelImage.phases must hold only 0 (solid) and 1 (pore), got values {vals[:8]}; "
                        "segment it with porefsi.image.segment(..., threshold=... or pore_value=...)"
                    )
                ph = ph.astype(np.uint8)
            else:
                raise InputError(
                    f"VoxelImage.phases must be uint8 0/1, got dtype {ph.dtype}; segment the image first"
                )
        elif ph.max(initial=0) > 1:
            raise InputError(
                "VoxelImage.phases must hold only 0 (solid) and 1 (pore), got values up to "
                f"{int(ph.max())}; segment it with porefsi.image.segment(..., threshold=...)"
            )
        ph = np.ascontiguousarray(ph)
        if ph.flags.writeable and isinstance(self.phases, np.ndarray) and np.shares_memory(ph, self.phases):
            ph = ph.copy()  # never freeze (or alias) the caller's array
        ph.setflags(write=False)
        vs = positive_length(self.voxel_size, "voxel size")
        org = np.asarray(self.origin, dtype=float).reshape(-1)
        if org.shape != (3,) or not np.all(np.isfinite(org)):
            raise InputError(f"origin must be 3 finite numbers (m), got {self.origin!r}")
        object.__setattr__(self, "phases", ph)
        object.__setattr__(self, "voxel_size", vs)
        object.__setattr__(self, "origin", org)

    @property
    def shape(self) -> tuple[int, int, int]:
        """Image shape (nx, ny, nz)."""
        return tuple(int(s) for s in self.phases.shape)  # type: ignore[return-value]

    @property
    def porosity(self) -> float:
        """Pore voxel fraction, dimensionless.

        From a count (the same float as the mean of the 0/1 array, ~8x faster on a 1000^3 image).
        """
        return int(np.count_nonzero(self.phases)) / self.phases.size

    @property
    def extent(self) -> np.ndarray:
        """Physical edge lengths of the box, m, shape (3,)."""
        return np.asarray(self.shape, dtype=float) * self.voxel_size

    @property
    def pore(self) -> np.ndarray:
        """Boolean view of the pore space, shape (nx, ny, nz)."""
        return self.phases.view(bool)

    def voxel_centres(self, ijk: np.ndarray) -> np.ndarray:
        """Centres of voxels ``ijk`` (shape (N, 3) integer), m, shape (N, 3)."""
        return self.origin + (np.asarray(ijk, dtype=float) + 0.5) * self.voxel_size

    def __repr__(self) -> str:
        return (
            f"VoxelImage(shape={self.shape}, voxel_size={self.voxel_size:.4g} m, "
            f"porosity={self.porosity:.4f})"
        )
