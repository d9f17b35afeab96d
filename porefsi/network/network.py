"""The pore network type: spheres (pores) joined by cylinders (throats)."""

from __future__ import annotations

import dataclasses

import numpy as np

from porefsi.errors import InputError, NetworkError
from porefsi.image.voxel_image import axis_index, positive_length

__all__ = ["Network", "FACES"]

#: Column order of :attr:`Network.pore_faces`.
FACES = ("xmin", "xmax", "ymin", "ymax", "zmin", "zmax")


#: Relative slack allowed when checking throat radius <= pore radius: both are products of voxel
#: counts and the voxel size, or halves of stored diameters, so equal radii may differ by round-off.
_RADIUS_RTOL = 1e-12


def _own(name, value, dtype) -> np.ndarray:
    """``value`` as a C-contiguous array of ``dtype`` the network can make read-only.

    A caller's writable array is copied (so freezing the network never changes the caller's
    array, and the caller cannot change the network through it); an array that is already
    read-only (e.g. a field of another Network, passed on by :meth:`Network.replace`) is shared.
    """
    try:
        a = np.asarray(value)
        if isinstance(value, np.ndarray) and a.flags.writeable and a.dtype == np.dtype(dtype):
            return np.array(a, dtype=dtype, order="C", copy=True)
        return np.ascontiguousarray(a, dtype=dtype)
    except (TypeError, ValueError) as exc:
        raise InputError(f"Network.{name} must be an array of numbers, got {type(value).__name__} ({exc})") from None


def _arr(name, value, dtype, shape):
    a = _own(name, value, dtype)
    if a.shape != shape:
        raise InputError(f"Network.{name} must have shape {shape}, got {a.shape}")
    if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
        raise InputError(f"Network.{name} has NaN or infinite entries")
    return a


@dataclasses.dataclass(frozen=True, eq=False)
class Network:
    """A pore network of spherical pores joined by cylindrical throats (SI units).

    Each throat is a *conduit* of three segments in series: a length inside pore ``i``
    (``throat_pore_length[:, 0]``), the cylinder itself (``throat_length``) and a length inside
    pore ``j`` (``throat_pore_length[:, 1]``), where ``(i, j) = throat_conns[t]`` with ``i < j``.

    Parameters
    ----------
    pore_coords : ndarray of float, shape (Np, 3)
        Pore centres, m, in the image frame (voxel (0,0,0) spans [0, voxel_size)³ + origin).
    pore_radius : ndarray of float, shape (Np,)
        Inscribed (maximal-ball) radius of each pore, m, > 0.
    pore_volume : ndarray of float, shape (Np,)
        Pore-body volume, m³, > 0 (the voxel region the pore owns).
    throat_conns : ndarray of int, shape (Nt, 2)
        Pores joined by each throat. Rows are canonicalised to ``conns[:, 0] < conns[:, 1]``
        (with ``throat_pore_length`` columns swapped to match).
    throat_radius : ndarray of float, shape (Nt,)
        Throat (cylinder) radius, m, > 0 and <= both pore radii.
    throat_length : ndarray of float, shape (Nt,)
        Length of the cylindrical part, m, > 0.
    throat_pore_length : ndarray of float, shape (Nt, 2)
        Length of the conduit inside each of the two pores, m, > 0.
    pore_faces : ndarray of bool, shape (Np, 6)
        Whether each pore touches the box faces, columns in :data:`FACES` order.
    voxel_size : float
        Voxel size of the image the network came from, m.
    shape : tuple of 3 int
        Shape of that image (nx, ny, nz).
    origin : ndarray of float, shape (3,), optional
        Corner of the image box, m.
    throat_volume : ndarray of float, shape (Nt,), optional
        Throat volume, m³, >= 0 (zeros when pore regions own all the pore voxels).

    Raises
    ------
    InputError
        Shapes, non-numeric or non-integer entries, NaNs, non-positive sizes, self-loops,
        duplicate throats (in either order), throat radius larger than a pore radius, pore
        indices out of range, or a bad ``voxel_size`` or ``shape``.

    Notes
    -----
    The dataclass is frozen and its arrays are read-only. Writable arrays passed in are copied,
    so the caller's arrays stay writable and cannot change the network afterwards; read-only
    arrays (e.g. another network's fields) are shared. ``dataclasses.replace`` and
    :meth:`replace` run the same validation again.
    """

    pore_coords: np.ndarray
    pore_radius: np.ndarray
    pore_volume: np.ndarray
    throat_conns: np.ndarray
    throat_radius: np.ndarray
    throat_length: np.ndarray
    throat_pore_length: np.ndarray
    pore_faces: np.ndarray
    voxel_size: float
    shape: tuple
    origin: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(3))
    throat_volume: np.ndarray | None = None

    def __post_init__(self):
        coords = _own("pore_coords", self.pore_coords, float)
        if coords.ndim != 2 or coords.shape[1] != 3:
            raise InputError(f"Network.pore_coords must have shape (Np, 3), got {coords.shape}")
        n_p = coords.shape[0]
        conns = np.asarray(self.throat_conns)
        if conns.size == 0:
            conns = conns.reshape(0, 2)
        if conns.ndim != 2 or conns.shape[1] != 2:
            raise InputError(f"Network.throat_conns must have shape (Nt, 2), got {conns.shape}")
        if conns.dtype.kind not in "iu":
            raise InputError(f"Network.throat_conns must be integers, got dtype {conns.dtype}")
        conns = conns.astype(np.int64)
        n_t = conns.shape[0]
        f = {
            "pore_coords": coords,
            "pore_radius": _arr("pore_radius", self.pore_radius, float, (n_p,)),
            "pore_volume": _arr("pore_volume", self.pore_volume, float, (n_p,)),
            "throat_radius": _arr("throat_radius", self.throat_radius, float, (n_t,)),
            "throat_length": _arr("throat_length", self.throat_length, float, (n_t,)),
            "throat_pore_length": _arr("throat_pore_length", self.throat_pore_length, float, (n_t, 2)),
            "pore_faces": _arr("pore_faces", self.pore_faces, bool, (n_p, 6)),
            "origin": _arr("origin", self.origin, float, (3,)),
        }
        tv = np.zeros(n_t) if self.throat_volume is None else self.throat_volume
        f["throat_volume"] = _arr("throat_volume", tv, float, (n_t,))
        if not np.all(np.isfinite(coords)):
            raise InputError("Network.pore_coords has NaN or infinite entries")
        for name in ("pore_radius", "pore_volume", "throat_radius", "throat_length", "throat_pore_length"):
            a = f[name]
            bad = np.flatnonzero((a <= 0).reshape(a.shape[0], -1).any(axis=1)) if a.size else np.zeros(0, int)
            if bad.size:
                raise InputError(f"Network.{name} must be > 0; entry {int(bad[0])} is {f[name][bad[0]]}")
        if np.any(f["throat_volume"] < 0):
            raise InputError("Network.throat_volume must be >= 0")
        if n_t:
            if conns.min() < 0 or conns.max() >= n_p:
                raise InputError(
                    f"Network.throat_conns refers to pores outside 0..{n_p - 1} "
                    f"(min {int(conns.min())}, max {int(conns.max())}); conns must index pore_coords rows"
                )
            loops = np.flatnonzero(conns[:, 0] == conns[:, 1])
            if loops.size:
                raise InputError(
                    f"throat {int(loops[0])} joins pore {int(conns[loops[0], 0])} to itself "
                    f"({loops.size} such self-loop(s)); drop those rows of throat_conns"
                )
            swap = conns[:, 0] > conns[:, 1]
            if swap.any():
                conns = conns.copy()
                conns[swap] = conns[swap, ::-1]
                tpl = f["throat_pore_length"].copy()
                tpl[swap] = tpl[swap, ::-1]
                f["throat_pore_length"] = tpl
            key = conns[:, 0] * n_p + conns[:, 1]
            uniq, first, counts = np.unique(key, return_index=True, return_counts=True)
            if uniq.size != n_t:
                d = first[np.argmax(counts > 1)]
                raise InputError(
                    f"duplicate throat between pores {tuple(int(c) for c in conns[d])} "
                    f"({n_t - uniq.size} duplicate row(s) in throat_conns, either order); keep one throat per pair"
                )
            rmax = np.minimum(f["pore_radius"][conns[:, 0]], f["pore_radius"][conns[:, 1]])
            wide = np.flatnonzero(f["throat_radius"] > rmax * (1 + _RADIUS_RTOL))
            if wide.size:
                t = int(wide[0])
                raise InputError(
                    f"throat {t} radius {f['throat_radius'][t]:.4g} m exceeds the smaller of its pore radii "
                    f"{rmax[t]:.4g} m; clip throat radii to min(pore radii)"
                )
        f["throat_conns"] = conns
        f["voxel_size"] = positive_length(self.voxel_size, "Network.voxel_size")
        try:
            shp = tuple(int(s) for s in self.shape)
        except (TypeError, ValueError):
            shp = ()
        if len(shp) != 3 or min(shp) < 1:
            raise InputError(f"Network.shape must be 3 positive ints (nx, ny, nz), got {self.shape!r}")
        f["shape"] = shp
        for k, v in f.items():
            if isinstance(v, np.ndarray):
                v.setflags(write=False)
            object.__setattr__(self, k, v)

    # -- sizes ---------------------------------------------------------------------------
    @property
    def n_pores(self) -> int:
        """Number of pores Np."""
        return int(self.pore_coords.shape[0])

    @property
    def n_throats(self) -> int:
        """Number of throats Nt."""
        return int(self.throat_conns.shape[0])

    @property
    def extent(self) -> np.ndarray:
        """Physical edge lengths of the image box, m, shape (3,)."""
        return np.asarray(self.shape, dtype=float) * self.voxel_size

    @property
    def coordination(self) -> np.ndarray:
        """Number of throats at each pore, shape (Np,)."""
        return np.bincount(self.throat_conns.ravel(), minlength=self.n_pores)

    # -- labels --------------------------------------------------------------------------
    def face(self, name: str) -> np.ndarray:
        """Boolean mask (Np,) of pores touching box face ``name`` (one of :data:`FACES`)."""
        if name not in FACES:
            raise InputError(f"unknown face {name!r}; use one of {FACES}")
        return self.pore_faces[:, FACES.index(name)]

    def inlet(self, axis: str | int) -> np.ndarray:
        """Pores on the low face of ``axis`` (the inlet of a flow along it), bool (Np,)."""
        return self.pore_faces[:, 2 * axis_index(axis)]

    def outlet(self, axis: str | int) -> np.ndarray:
        """Pores on the high face of ``axis`` (the outlet of a flow along it), bool (Np,)."""
        return self.pore_faces[:, 2 * axis_index(axis) + 1]

    def require_inlet_outlet(self, axis: str | int) -> None:
        """Raise :class:`NetworkError` unless ``axis`` has inlet and outlet pores."""
        ax = axis_index(axis)
        name = "xyz"[ax]
        if not self.inlet(ax).any() or not self.outlet(ax).any():
            raise NetworkError(
                f"network has no pores on the {name}min or {name}max face: nothing can flow along {name}; "
                "choose another --axis or a larger image"
            )

    def replace(self, **changes) -> Network:
        """Return a copy with fields replaced (validated again)."""
        return dataclasses.replace(self, **changes)

    def __repr__(self) -> str:
        return (
            f"Network(n_pores={self.n_pores}, n_throats={self.n_throats}, shape={self.shape}, "
            f"voxel_size={self.voxel_size:.4g} m)"
        )
