"""The pore network type: spheres (pores) joined by cylinders (throats)."""

from __future__ import annotations

import dataclasses

import numpy as np

from porefsi.errors import InputError, NetworkError
from porefsi.image.voxel_image import axis_index, positive_length

__all__ = ["Network", "FACES", "CONDUCTANCE_MODELS", "CIRCLE_SHAPE_FACTOR"]

#: Column order of :attr:`Network.pore_faces`.
FACES = ("xmin", "xmax", "ymin", "ymax", "zmin", "zmax")

#: Names of the conduit models (:attr:`Network.conductance`): ``"paper"`` = circular cylinders of
#: the inscribed radius in spheres (the seed paper's model); ``"shape_factor"`` = Valvatne & Blunt
#: (2004) triangle / square / circle sections of the measured shape factor.
CONDUCTANCE_MODELS = ("paper", "shape_factor")

#: Shape factor G = A / P^2 of a circle, 1 / (4 pi): the largest of any cross-section.
CIRCLE_SHAPE_FACTOR = 1.0 / (4.0 * np.pi)


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


def _shape_fields(net, n_p: int, n_t: int) -> dict:
    """Validated ``throat_shape_factor``, ``pore_shape_factor`` and ``conductance`` of ``net``."""
    tg, pg = net.throat_shape_factor, net.pore_shape_factor
    if (tg is None) != (pg is None):
        given = "throat_shape_factor" if pg is None else "pore_shape_factor"
        raise InputError(
            f"Network.{given} is given without the other shape factor; give both "
            "throat_shape_factor and pore_shape_factor, or neither (paper model)"
        )
    out: dict = {"throat_shape_factor": None, "pore_shape_factor": None}
    if tg is not None:
        for name, val, n in (("throat_shape_factor", tg, n_t), ("pore_shape_factor", pg, n_p)):
            a = _arr(name, val, float, (n,))
            bad = np.flatnonzero((a <= 0) | (a > CIRCLE_SHAPE_FACTOR * (1 + 1e-9)))
            if bad.size:
                raise InputError(
                    f"Network.{name} entry {int(bad[0])} is {a[bad[0]]!r}: a shape factor G = A/P^2 lies in "
                    f"(0, 1/(4 pi) = {CIRCLE_SHAPE_FACTOR:.6f}]; fix the value or re-extract the network"
                )
            out[name] = a
    model = net.conductance
    if model is not None:
        if model not in CONDUCTANCE_MODELS:
            raise InputError(f"unknown conductance model {model!r}; use one of {CONDUCTANCE_MODELS}")
        if model == "shape_factor" and tg is None:
            raise InputError(
                "conductance='shape_factor' needs the network's measured shape factors, which this network "
                "lacks (an older file or a lattice); re-extract it from the image (porefsi extract) or use "
                "conductance='paper'"
            )
    out["conductance"] = model
    return out


def _duct_fraction(value, n_t: int, swapped) -> np.ndarray | None:
    """Validated ``throat_duct_fraction`` (columns 0 and 2 swapped where the conns were)."""
    if value is None:
        return None
    a = _arr("throat_duct_fraction", value, float, (n_t, 3))
    bad = np.flatnonzero((a <= 0).any(axis=1) | (np.abs(a.sum(axis=1) - 1.0) > 1e-9))
    if bad.size:
        raise InputError(
            f"Network.throat_duct_fraction row {int(bad[0])} is {a[bad[0]].tolist()}: each row holds three "
            "shares > 0 of the conduit length summing to 1; fix it or re-extract the network"
        )
    if swapped is not None and swapped.any():
        a = a.copy()
        a[swapped] = a[swapped, ::-1]
    return a


#: The per-pore, per-face section fields of the face cuts (:attr:`Network.pore_face_radius` ...).
_FACE_FIELDS = ("pore_face_radius", "pore_face_shape_factor", "pore_face_duct_fraction")


def _face_fields(net, f: dict, n_p: int) -> dict:
    """Validated face-cut sections: all three (Np, 6) fields or none; zero off the faces."""
    given = [getattr(net, name) is not None for name in _FACE_FIELDS]
    out: dict = dict.fromkeys(_FACE_FIELDS)
    if not any(given):
        return out
    if not all(given):
        missing = [n for n, g in zip(_FACE_FIELDS, given, strict=True) if not g]
        raise InputError(
            f"Network face-cut sections are incomplete ({', '.join(missing)} missing); give all of "
            f"{', '.join(_FACE_FIELDS)} or none (re-extract the network)"
        )
    if net.throat_shape_factor is None:
        raise InputError(
            "Network face-cut sections (pore_face_*) need the measured shape factors too; give "
            "throat_shape_factor and pore_shape_factor, or drop the pore_face_* fields"
        )
    on = f["pore_faces"]
    rules = {
        "pore_face_radius": (lambda a: a > 0, "> 0"),
        "pore_face_shape_factor": (lambda a: (a > 0) & (a <= CIRCLE_SHAPE_FACTOR * (1 + 1e-9)),
                                   f"in (0, 1/(4 pi) = {CIRCLE_SHAPE_FACTOR:.6f}]"),
        "pore_face_duct_fraction": (lambda a: (a >= 0) & (a <= 1), "in [0, 1]"),
    }
    for name, (ok, what) in rules.items():
        a = _arr(name, getattr(net, name), float, (n_p, 6))
        bad = np.argwhere(np.where(on, ~ok(a), a != 0))
        if bad.size:
            p, k = (int(v) for v in bad[0])
            where = f"on face {FACES[k]}, must be {what}" if on[p, k] else f"off face {FACES[k]}, must be 0"
            raise InputError(
                f"Network.{name}[{p}, {k}] is {a[p, k]!r} ({where}); fix the value or re-extract the network"
            )
        out[name] = a
    return out


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
    throat_shape_factor, pore_shape_factor : ndarray of float, shapes (Nt,) and (Np,), optional
        Dimensionless shape factor G = A / P² of each throat's and pore's cross-section, in
        (0, 1/(4 pi)] (the circle's is the largest). Give both or neither. With the inscribed
        radius r the section area is ``A = r² / (4 G)`` (exact for circles, squares, triangles and
        every polygon with an inscribed circle). ``None`` for networks without measured sections
        (older files, lattices): they use the paper's model.
    throat_duct_fraction : ndarray of float, shape (Nt, 3), optional
        Shares of each conduit's pore-to-pore length (``throat_pore_length[:, 0] + throat_length +
        throat_pore_length[:, 1]``) taken by the pore-i duct, the throat duct and the pore-j duct of
        the shape-factor model, each > 0, rows summing to 1 (dimensionless, so a deformation that
        scales the lengths keeps them). ``None``: the shape-factor model uses the stored lengths
        themselves (as for networks read from pnextract's files).
    pore_face_radius, pore_face_shape_factor, pore_face_duct_fraction : ndarray of float, shape (Np, 6), optional
        The *face cut* of every pore on a box face (columns in :data:`FACES` order; 0 where the
        pore does not touch that face): the inscribed radius (m, > 0; the flow models use at most
        the pore radius, so a deformation that shrinks the pore need not update it) and shape
        factor (in (0, 1/(4 pi)]) of the section of the pore region's voxels the face shows, and
        the share of the boundary conduit (pore centre to face) its constriction takes, in [0, 1]
        (dimensionless, like ``throat_duct_fraction``). The shape-factor model's boundary
        conduits are a pore duct and a face-cut duct in series
        (:func:`porefsi.network.geometry.boundary_resistance`). Give all three or none (they need
        the shape factors); ``None``: boundary conduits of the pore's own section (older files).
    conductance : {'paper', 'shape_factor'} or None, optional
        Conduit model every flow computation uses (:data:`CONDUCTANCE_MODELS`; see
        :mod:`porefsi.network.geometry`). ``None`` (default): ``'shape_factor'`` when both shape
        factors are given, else ``'paper'``. Read :attr:`conduit_model` for the resolved name.

    Raises
    ------
    InputError
        Shapes, non-numeric or non-integer entries, NaNs, non-positive sizes, self-loops,
        duplicate throats (in either order), throat radius larger than a pore radius, pore
        indices out of range, a bad ``voxel_size`` or ``shape``, shape factors outside
        (0, 1/(4 pi)] or only one of the two given, an unknown ``conductance``,
        ``conductance='shape_factor'`` without shape factors, or face-cut sections incomplete,
        without shape factors, out of range on a face or non-zero off it.

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
    throat_shape_factor: np.ndarray | None = None
    pore_shape_factor: np.ndarray | None = None
    throat_duct_fraction: np.ndarray | None = None
    conductance: str | None = None
    pore_face_radius: np.ndarray | None = None
    pore_face_shape_factor: np.ndarray | None = None
    pore_face_duct_fraction: np.ndarray | None = None

    def __post_init__(self):
        coords = _own("pore_coords", self.pore_coords, float)
        if coords.ndim != 2 or coords.shape[1] != 3:
            raise InputError(f"Network.pore_coords must have shape (Np, 3), got {coords.shape}")
        n_p = coords.shape[0]
        conns = _conns_array(self.throat_conns)
        n_t = conns.shape[0]
        f = _size_fields(self, coords, n_t)
        f["throat_conns"], swapped = _check_throats(conns, f, n_p)
        f.update(_shape_fields(self, n_p, n_t))
        f["throat_duct_fraction"] = _duct_fraction(self.throat_duct_fraction, n_t, swapped)
        f.update(_face_fields(self, f, n_p))
        f["voxel_size"] = positive_length(self.voxel_size, "Network.voxel_size")
        f["shape"] = _image_shape(self.shape)
        for k, v in f.items():
            if isinstance(v, np.ndarray):
                v.setflags(write=False)
            object.__setattr__(self, k, v)

    @property
    def conduit_model(self) -> str:
        """Resolved conduit model, one of :data:`CONDUCTANCE_MODELS` (see ``conductance``)."""
        if self.conductance is not None:
            return self.conductance
        return "paper" if self.throat_shape_factor is None else "shape_factor"

    @property
    def has_face_sections(self) -> bool:
        """Whether the network carries the face cuts' sections (``pore_face_*``)."""
        return self.pore_face_radius is not None

    @property
    def has_shape_factors(self) -> bool:
        """Whether the network carries measured throat and pore shape factors."""
        return self.throat_shape_factor is not None

    def with_conductance(self, model: str | None) -> Network:
        """Copy using conduit ``model`` (``None``: the default for its data); validated.

        Only the conduit law changes; the geometry stays as it was measured. The two models
        measure throats differently at the image box (the default walls its faces, the paper's
        leaves it open), so to reproduce the paper's network extract with
        ``extract_network(image, conductance="paper")`` rather than relabelling a default one.
        """
        return self.replace(conductance=model)

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

    def spanning_clusters(self, axis: str | int) -> tuple[np.ndarray, int, int]:
        """The pores of the connected clusters that touch both faces of ``axis``.

        The one spanning-cluster search of porefsi (single-phase permeability, drainage).

        Returns
        -------
        mask : ndarray of bool, shape (Np,)
            Pores of a spanning cluster.
        n_clusters, n_spanning : int
            Connected clusters of pores (throats as edges), and those touching both faces.
        """
        from scipy import sparse
        from scipy.sparse import csgraph

        ax = axis_index(axis)
        n_p, conns = self.n_pores, self.throat_conns
        adj = sparse.coo_array((np.ones(self.n_throats), (conns[:, 0], conns[:, 1])), shape=(n_p, n_p))
        n_comp, comp = csgraph.connected_components(adj, directed=False)
        has_in = np.zeros(n_comp, bool)
        has_out = np.zeros(n_comp, bool)
        has_in[comp[self.inlet(ax)]] = True
        has_out[comp[self.outlet(ax)]] = True
        spanning = has_in & has_out
        return spanning[comp], int(n_comp), int(spanning.sum())

    def replace(self, **changes) -> Network:
        """Return a copy with fields replaced (validated again)."""
        return dataclasses.replace(self, **changes)

    def __repr__(self) -> str:
        return (
            f"Network(n_pores={self.n_pores}, n_throats={self.n_throats}, shape={self.shape}, "
            f"voxel_size={self.voxel_size:.4g} m)"
        )


def _conns_array(conns) -> np.ndarray:
    """``throat_conns`` as an (Nt, 2) int64 array (not yet checked against the pores)."""
    conns = np.asarray(conns)
    if conns.size == 0:
        conns = conns.reshape(0, 2)
    if conns.ndim != 2 or conns.shape[1] != 2:
        raise InputError(f"Network.throat_conns must have shape (Nt, 2), got {conns.shape}")
    if conns.dtype.kind not in "iu":
        raise InputError(f"Network.throat_conns must be integers, got dtype {conns.dtype}")
    return conns.astype(np.int64)


def _size_fields(net, coords: np.ndarray, n_t: int) -> dict:
    """The validated size arrays of ``net`` (positive, finite coordinates), by field name."""
    n_p = coords.shape[0]
    f = {
        "pore_coords": coords,
        "pore_radius": _arr("pore_radius", net.pore_radius, float, (n_p,)),
        "pore_volume": _arr("pore_volume", net.pore_volume, float, (n_p,)),
        "throat_radius": _arr("throat_radius", net.throat_radius, float, (n_t,)),
        "throat_length": _arr("throat_length", net.throat_length, float, (n_t,)),
        "throat_pore_length": _arr("throat_pore_length", net.throat_pore_length, float, (n_t, 2)),
        "pore_faces": _arr("pore_faces", net.pore_faces, bool, (n_p, 6)),
        "origin": _arr("origin", net.origin, float, (3,)),
    }
    tv = np.zeros(n_t) if net.throat_volume is None else net.throat_volume
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
    return f


def _check_throats(conns: np.ndarray, f: dict, n_p: int) -> tuple[np.ndarray, np.ndarray | None]:
    """Throats checked against the pores and canonicalised (``conns[:, 0] < conns[:, 1]``).

    Swapped rows also swap ``f["throat_pore_length"]``; returns the conns and which rows were
    swapped (None: none).
    """
    n_t = conns.shape[0]
    if not n_t:
        return conns, None
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
    swapped = None
    swap = conns[:, 0] > conns[:, 1]
    if swap.any():
        conns = conns.copy()
        conns[swap] = conns[swap, ::-1]
        tpl = f["throat_pore_length"].copy()
        tpl[swap] = tpl[swap, ::-1]
        f["throat_pore_length"] = tpl
        swapped = swap
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
    return conns, swapped


def _image_shape(shape) -> tuple:
    """``Network.shape`` as 3 positive ints."""
    try:
        shp = tuple(int(s) for s in shape)
    except (TypeError, ValueError):
        shp = ()
    if len(shp) != 3 or min(shp) < 1:
        raise InputError(f"Network.shape must be 3 positive ints (nx, ny, nz), got {shape!r}")
    return shp
