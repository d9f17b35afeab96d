r"""Network exchange formats: OpenPNM v3 arrays, the ``NET.npz`` file, and the Statoil files of pnflow.

Three doors onto the same :class:`~porefsi.network.network.Network`:

* :func:`to_openpnm` / :func:`from_openpnm`: a flat ``dict`` of arrays keyed the way OpenPNM v3 keys
  its networks (``pore.coords``, ``throat.conns``, ``throat.conduit_lengths`` ...). An OpenPNM user
  loads it with ``pn = openpnm.network.Network(); pn.update(d)``.
* :func:`save_network` / :func:`load_network`: those arrays plus porefsi's extras (``porefsi.*``)
  in one ``.npz`` file that ``numpy.load`` alone can read (no pickles).
* :func:`write_statoil` / :func:`read_statoil` (in :mod:`porefsi.network.statoil`, re-exported here):
  the four text files (``PREFIX_node1.dat``,
  ``_node2.dat``, ``_link1.dat``, ``_link2.dat``) that the Imperial College codes pnextract writes
  and pnflow reads.

``docs/network_formats.md`` lists every key and column.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from porefsi.errors import InputError, NetworkError
from porefsi.network.geometry import resistance_factors
from porefsi.network.network import CIRCLE_SHAPE_FACTOR, CONDUCTANCE_MODELS, FACES, Network
from porefsi.network.statoil import read_statoil, write_statoil

__all__ = [
    "to_openpnm",
    "from_openpnm",
    "save_network",
    "load_network",
    "is_network_file",
    "write_statoil",
    "read_statoil",
    "FORMAT_VERSION",
    "CIRCLE_SHAPE_FACTOR",
]

#: Version of the porefsi extras in ``NET.npz`` (``porefsi.format_version``). Version 2 files carry
#: measured shape factors in ``pore.shape_factor`` / ``throat.shape_factor``, ``porefsi.conductance``
#: and ``porefsi.throat_duct_fraction``; version 1 files wrote the circle's G there (ignored).
#: Version 3 adds the face cuts' sections ``porefsi.pore_face_radius`` / ``_shape_factor`` /
#: ``_duct_fraction`` (Np, 6) (older files load without them: boundary conduits of the pore's section).
FORMAT_VERSION = 3

#: Network fields of the face cuts and their NET.npz keys.
_FACE_KEYS = {name: f"porefsi.{name}" for name in ("pore_face_radius", "pore_face_shape_factor",
                                                     "pore_face_duct_fraction")}

_REQUIRED = ("pore.coords", "pore.diameter", "pore.volume", "throat.conns", "throat.diameter")
_CONDUIT_PARTS = ("pore1", "throat", "pore2")


# ---------------------------------------------------------------------------------------------
# OpenPNM dict
# ---------------------------------------------------------------------------------------------
def to_openpnm(net: Network) -> dict[str, np.ndarray]:
    r"""Return the network as a dict of new arrays keyed as OpenPNM v3 keys them.

    Parameters
    ----------
    net : Network

    Returns
    -------
    dict of str to ndarray
        ``pore.coords`` (Np, 3) m; ``pore.diameter`` (Np,) m, twice the inscribed radius;
        ``pore.volume`` (Np,) m³; ``throat.conns`` (Nt, 2) int64 with ``conns[:, 0] < conns[:, 1]``;
        ``throat.diameter`` (Nt,) m; ``throat.length`` (Nt,) m, the cylinder part only;
        ``throat.conduit_lengths`` (Nt, 3) m, columns (pore 1 part, cylinder, pore 2 part);
        ``throat.total_length`` (Nt,) m, their sum; ``throat.volume`` (Nt,) m³;
        ``throat.cross_sectional_area`` (Nt,) m² (``r² / (4 G)``, the circle's with no shape
        factors); ``throat.hydraulic_size_factors`` (Nt, 3) m⁴, columns as
        ``throat.conduit_lengths``, under the network's conduit model; ``pore.shape_factor`` and
        ``throat.shape_factor`` (measured, or the circle's :math:`1/(4\pi)` when the network has
        none); ``pore.all``, ``throat.all``; boundary labels ``pore.xmin`` ... ``pore.zmax`` (Np,)
        bool; and the porefsi extras ``porefsi.voxel_size`` (m), ``porefsi.shape`` (3,) int,
        ``porefsi.origin`` (3,) m, ``porefsi.format_version``, ``porefsi.has_shape_factors``
        (bool), ``porefsi.conductance`` (str, empty for the default) and, when the network has
        them, ``porefsi.throat_duct_fraction`` (Nt, 3) and the face cuts ``porefsi.pore_face_radius``
        (Np, 6) m, ``porefsi.pore_face_shape_factor`` and ``porefsi.pore_face_duct_fraction`` (Np, 6).

    Notes
    -----
    The hydraulic size factors are :math:`S_k = 1/h_k` with :math:`h_k` from
    :func:`porefsi.network.geometry.resistance_factors`, so OpenPNM's
    ``models.physics.hydraulic_conductance.generic_hydraulic`` (:math:`g_k = S_k/\mu`, segments in
    series) reproduces porefsi's conduit conductances exactly. The input is not modified.

    Examples
    --------
    >>> from porefsi.network.network import Network
    >>> net = Network(pore_coords=[[1e-5, 5e-6, 5e-6], [3e-5, 5e-6, 5e-6]], pore_radius=[4e-6, 4e-6],
    ...               pore_volume=[1e-16, 1e-16], throat_conns=[[0, 1]], throat_radius=[2e-6],
    ...               throat_length=[1e-5], throat_pore_length=[[5e-6, 5e-6]],
    ...               pore_faces=[[1, 0, 0, 0, 0, 0], [0, 1, 0, 0, 0, 0]], voxel_size=1e-6,
    ...               shape=(40, 10, 10))
    >>> d = to_openpnm(net)
    >>> d["pore.diameter"].tolist(), d["throat.conduit_lengths"].tolist()
    ([8e-06, 8e-06], [[5e-06, 1e-05, 5e-06]])
    >>> back = from_openpnm(d)
    >>> bool((back.pore_coords == net.pore_coords).all()), back.shape
    (True, (40, 10, 10))
    """
    tpl = net.throat_pore_length
    cl = np.column_stack([tpl[:, 0], net.throat_length, tpl[:, 1]])
    shaped = net.has_shape_factors
    tG = net.throat_shape_factor if shaped else np.full(net.n_throats, CIRCLE_SHAPE_FACTOR)
    pG = net.pore_shape_factor if shaped else np.full(net.n_pores, CIRCLE_SHAPE_FACTOR)
    d: dict[str, np.ndarray] = {
        "pore.coords": net.pore_coords.copy(),
        "pore.diameter": 2.0 * net.pore_radius,
        "pore.volume": net.pore_volume.copy(),
        "pore.shape_factor": pG.copy(),
        "pore.all": np.ones(net.n_pores, dtype=bool),
        "throat.conns": net.throat_conns.astype(np.int64),
        "throat.diameter": 2.0 * net.throat_radius,
        "throat.length": net.throat_length.copy(),
        "throat.conduit_lengths": cl,
        "throat.total_length": cl.sum(axis=1),
        "throat.volume": net.throat_volume.copy(),
        "throat.cross_sectional_area": net.throat_radius**2 / (4.0 * tG),
        "throat.hydraulic_size_factors": 1.0 / resistance_factors(net),
        "throat.shape_factor": tG.copy(),
        "throat.all": np.ones(net.n_throats, dtype=bool),
    }
    for k, name in enumerate(FACES):
        d[f"pore.{name}"] = net.pore_faces[:, k].copy()
    d.update(_porefsi_extras(net, shaped))
    return d


def _porefsi_extras(net: Network, shaped: bool) -> dict[str, np.ndarray]:
    """The ``porefsi.*`` keys of :func:`to_openpnm`."""
    d: dict[str, np.ndarray] = {}
    d["porefsi.voxel_size"] = np.float64(net.voxel_size)
    d["porefsi.shape"] = np.asarray(net.shape, dtype=np.int64)
    d["porefsi.origin"] = net.origin.copy()
    d["porefsi.format_version"] = np.int64(FORMAT_VERSION)
    d["porefsi.has_shape_factors"] = np.bool_(shaped)
    d["porefsi.conductance"] = np.str_(net.conductance or "")
    if net.throat_duct_fraction is not None:
        d["porefsi.throat_duct_fraction"] = net.throat_duct_fraction.copy()
    if net.has_face_sections:
        for name, key in _FACE_KEYS.items():
            d[key] = getattr(net, name).copy()
    return d


def _check_file_values(d: Mapping) -> None:
    """Refuse NaN, infinite or non-positive sizes in a network file (one-line NetworkError).

    The :class:`Network` checks the arrays it keeps; this names the *file key* and also checks
    arrays it does not keep but a user may rely on (``throat.hydraulic_size_factors``).
    """
    checks = (
        ("pore.diameter", "> 0"), ("pore.volume", "> 0"), ("throat.diameter", "> 0"),
        ("throat.conduit_lengths", "> 0"), ("throat.conduit_lengths.pore1", "> 0"),
        ("throat.conduit_lengths.throat", "> 0"), ("throat.conduit_lengths.pore2", "> 0"),
        ("throat.hydraulic_size_factors", "> 0"), ("throat.volume", ">= 0"),
        ("pore.shape_factor", "> 0"), ("throat.shape_factor", "> 0"),
    )
    for key, rule in checks:
        if key not in d:
            continue
        try:
            a = np.asarray(d[key], dtype=float)
        except (TypeError, ValueError):
            raise NetworkError(f"network key {key!r} is not numeric; re-extract the network") from None
        bad = ~np.isfinite(a) | ((a < 0) if rule == ">= 0" else (a <= 0))
        if bad.any():
            flat = np.flatnonzero(bad.reshape(a.shape[0], -1).any(axis=1)) if a.ndim else np.array([0])
            i = int(flat[0])
            raise NetworkError(
                f"network key {key!r} has {int(bad.sum())} entr{'y' if bad.sum() == 1 else 'ies'} that are NaN, "
                f"infinite or not {rule} (first at row {i}: {a.reshape(a.shape[0], -1)[i].tolist() if a.ndim else a}); "
                "re-extract the network from the image (porefsi extract) or repair that key"
            )


def _conduit_lengths(d: Mapping) -> np.ndarray | None:
    if "throat.conduit_lengths" in d:
        return np.asarray(d["throat.conduit_lengths"], dtype=float)
    dotted = [f"throat.conduit_lengths.{p}" for p in _CONDUIT_PARTS]
    if all(k in d for k in dotted):  # OpenPNM v2 / Statoil-import naming
        return np.column_stack([np.asarray(d[k], dtype=float) for k in dotted])
    return None


def _scalar_extra(d: Mapping, key: str):
    return np.asarray(d[key]).reshape(-1) if key in d else None


def from_openpnm(d: Mapping, *, voxel_size: float | None = None, shape=None, origin=None) -> Network:
    """Build a :class:`Network` from OpenPNM-keyed arrays (an OpenPNM network, a dict, or ``NET.npz``).

    Parameters
    ----------
    d : mapping of str to array_like
        Must hold ``pore.coords``, ``pore.diameter``, ``pore.volume``, ``throat.conns``,
        ``throat.diameter``, the conduit lengths (``throat.conduit_lengths`` (Nt, 3), or the three
        OpenPNM-v2 keys ``throat.conduit_lengths.pore1/.throat/.pore2``) and the six boundary labels
        ``pore.xmin`` ... ``pore.zmax``. ``throat.volume`` is optional (zeros).
    voxel_size : float, optional
        Voxel size, m; overrides ``porefsi.voxel_size`` in ``d``. Required when ``d`` has none.
    shape : sequence of 3 int, optional
        Image shape; overrides ``porefsi.shape``. Required when ``d`` has none.
    origin : sequence of 3 float, optional
        Box corner, m; overrides ``porefsi.origin`` (default zeros).

    Returns
    -------
    Network
        With arrays copied from ``d`` (``d`` is not modified).

    Raises
    ------
    InputError
        Naming every missing key, or the values the :class:`Network` validation rejects.
    NetworkError
        A size, length, volume, size factor or shape factor key holding NaN, infinite or
        non-positive entries (:func:`_check_file_values`).

    Notes
    -----
    Measured shape factors (``pore.shape_factor`` and ``throat.shape_factor``) are taken from
    files written by porefsi format 2 with ``porefsi.has_shape_factors`` set and from files
    without porefsi extras (e.g. OpenPNM's import of pnextract networks); porefsi format-1 files
    wrote the circle's value there, which carries no measurement, so they load with the paper's
    model as before. The face cuts' sections come from format-3 files (older files load without
    them: boundary conduits of the pore's own section).
    """
    if not isinstance(d, Mapping) and not hasattr(d, "keys"):
        raise InputError(f"expected a mapping of OpenPNM arrays, got {type(d).__name__}")
    cl = _conduit_lengths(d)
    _check_keys(d, cl is not None, voxel_size is not None, shape is not None)
    conns = np.asarray(d["throat.conns"])
    n_t = conns.shape[0] if conns.ndim == 2 else 0
    if cl.shape != (n_t, 3):
        raise InputError(f"throat.conduit_lengths must have shape ({n_t}, 3), got {cl.shape}")
    vs = float(voxel_size) if voxel_size is not None else float(_scalar_extra(d, "porefsi.voxel_size")[0])
    shp = tuple(shape) if shape is not None else tuple(int(s) for s in _scalar_extra(d, "porefsi.shape"))
    if origin is None:
        origin = _scalar_extra(d, "porefsi.origin")
    origin = np.zeros(3) if origin is None else np.asarray(origin, dtype=float).copy()
    faces = np.column_stack([np.asarray(d[f"pore.{f}"], dtype=bool) for f in FACES])
    tv = d.get("throat.volume") if hasattr(d, "get") else None
    _check_file_values(d)
    return Network(
        pore_coords=np.array(d["pore.coords"], dtype=float),
        pore_radius=0.5 * np.asarray(d["pore.diameter"], dtype=float),
        pore_volume=np.array(d["pore.volume"], dtype=float),
        throat_conns=conns.copy(),
        throat_radius=0.5 * np.asarray(d["throat.diameter"], dtype=float),
        throat_length=cl[:, 1].copy(),
        throat_pore_length=cl[:, [0, 2]].copy(),
        pore_faces=faces,
        voxel_size=vs,
        shape=shp,
        origin=origin,
        throat_volume=None if tv is None else np.array(tv, dtype=float),
        **_shape_extras(d),
    )


def _check_keys(d: Mapping, has_lengths: bool, has_voxel_size: bool, has_shape: bool) -> None:
    """Refuse an OpenPNM mapping without the arrays :func:`from_openpnm` needs, naming them all."""
    missing = [k for k in _REQUIRED if k not in d]
    if not has_lengths:
        missing.append("throat.conduit_lengths (Nt, 3)")
    missing += [f"pore.{f}" for f in FACES if f"pore.{f}" not in d]
    if not has_voxel_size and "porefsi.voxel_size" not in d:
        missing.append("porefsi.voxel_size (or pass voxel_size=)")
    if not has_shape and "porefsi.shape" not in d:
        missing.append("porefsi.shape (or pass shape=)")
    if missing:
        raise InputError(
            "network arrays are missing keys: " + ", ".join(missing)
            + "; add them (an OpenPNM network needs its boundary labels, e.g. "
            "pn['pore.xmin'] = pn.coords[:, 0] <= x0, and porefsi's sphere-cylinder conduit lengths)"
        )


def _shape_extras(d: Mapping) -> dict:
    """Shape factors, duct fractions and conduit model of an OpenPNM-keyed mapping (see Notes above)."""
    version = _scalar_extra(d, "porefsi.format_version")
    if version is None:  # not a porefsi file: use the shape factors it holds
        shaped = "pore.shape_factor" in d and "throat.shape_factor" in d
    else:
        flag = _scalar_extra(d, "porefsi.has_shape_factors")
        shaped = int(version[0]) >= 2 and flag is not None and bool(flag[0])
    out: dict = {}
    if shaped:
        out["throat_shape_factor"] = np.array(d["throat.shape_factor"], dtype=float)
        out["pore_shape_factor"] = np.array(d["pore.shape_factor"], dtype=float)
        if "porefsi.throat_duct_fraction" in d:
            out["throat_duct_fraction"] = np.array(d["porefsi.throat_duct_fraction"], dtype=float)
        if version is not None and int(version[0]) >= 3 and all(k in d for k in _FACE_KEYS.values()):
            out.update({name: np.array(d[key], dtype=float) for name, key in _FACE_KEYS.items()})
    model = _scalar_extra(d, "porefsi.conductance")
    if model is not None and str(model[0]):
        name = str(model[0])
        if name not in CONDUCTANCE_MODELS:
            raise InputError(f"porefsi.conductance is {name!r}; use one of {CONDUCTANCE_MODELS}")
        out["conductance"] = name
    return out


# ---------------------------------------------------------------------------------------------
# NET.npz
# ---------------------------------------------------------------------------------------------
def save_network(net: Network, path: str | os.PathLike) -> Path:
    """Write ``net`` to ``path`` (``.npz``, appended if missing): the :func:`to_openpnm` arrays.

    The file is an uncompressed ``numpy.savez`` archive of plain arrays (no pickles): any tool reads
    it with ``numpy.load(path)``; OpenPNM users with ``pn.update(dict(numpy.load(path)))``.

    Returns
    -------
    pathlib.Path
        The path written.
    """
    p = Path(path)
    if p.suffix.lower() != ".npz":
        p = p.with_name(p.name + ".npz")
    if p.parent and not p.parent.exists():
        raise InputError(f"cannot write {p}: folder {p.parent} does not exist; create it first")
    np.savez(p, **to_openpnm(net))
    return p


def is_network_file(path: str | os.PathLike) -> bool:
    """Return whether ``path`` is a porefsi/OpenPNM network ``.npz`` (holds ``throat.conns``).

    Never raises: unreadable, missing or non-npz files give ``False``.
    """
    p = Path(path)
    if p.suffix.lower() != ".npz" or not p.is_file():
        return False
    try:
        with np.load(p, allow_pickle=False) as z:
            return "throat.conns" in z.files and "pore.coords" in z.files
    except Exception:  # noqa: BLE001 - any unreadable file is simply "not a network"
        return False


def load_network(path: str | os.PathLike, **kwargs) -> Network:
    """Read a network written by :func:`save_network` (or any npz of OpenPNM-keyed arrays).

    Parameters
    ----------
    path : path-like
        The ``.npz`` file.
    **kwargs
        ``voxel_size``, ``shape``, ``origin`` passed to :func:`from_openpnm` (needed for npz files
        written by other tools without the porefsi extras).

    Raises
    ------
    InputError
        Missing or unreadable file, or missing keys (named).
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(f"network file {str(p)!r} does not exist; check the path")
    try:
        with np.load(p, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except Exception as exc:  # noqa: BLE001 - surface as a typed error with the file name
        raise InputError(f"cannot read network file {str(p)!r} as .npz: {exc}") from None
    try:
        return from_openpnm(arrays, **kwargs)
    except InputError as exc:
        raise InputError(f"{p}: {exc}") from None
