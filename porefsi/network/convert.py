r"""Network exchange formats: OpenPNM v3 arrays, the ``NET.npz`` file, and the Statoil files of pnflow.

Three doors onto the same :class:`~porefsi.network.network.Network`:

* :func:`to_openpnm` / :func:`from_openpnm`: a flat ``dict`` of arrays keyed the way OpenPNM v3 keys
  its networks (``pore.coords``, ``throat.conns``, ``throat.conduit_lengths`` ...). An OpenPNM user
  loads it with ``pn = openpnm.network.Network(); pn.update(d)``.
* :func:`save_network` / :func:`load_network`: those arrays plus porefsi's extras (``porefsi.*``)
  in one ``.npz`` file that ``numpy.load`` alone can read (no pickles).
* :func:`write_statoil` / :func:`read_statoil`: the four text files (``PREFIX_node1.dat``,
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
from porefsi.image.voxel_image import axis_index
from porefsi.network.geometry import duct_lengths, resistance_factors
from porefsi.network.network import CIRCLE_SHAPE_FACTOR, CONDUCTANCE_MODELS, FACES, Network

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
FORMAT_VERSION = 2

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
        them, ``porefsi.throat_duct_fraction`` (Nt, 3).

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
    d["porefsi.voxel_size"] = np.float64(net.voxel_size)
    d["porefsi.shape"] = np.asarray(net.shape, dtype=np.int64)
    d["porefsi.origin"] = net.origin.copy()
    d["porefsi.format_version"] = np.int64(FORMAT_VERSION)
    d["porefsi.has_shape_factors"] = np.bool_(shaped)
    d["porefsi.conductance"] = np.str_(net.conductance or "")
    if net.throat_duct_fraction is not None:
        d["porefsi.throat_duct_fraction"] = net.throat_duct_fraction.copy()
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
    model as before.
    """
    if not isinstance(d, Mapping) and not hasattr(d, "keys"):
        raise InputError(f"expected a mapping of OpenPNM arrays, got {type(d).__name__}")
    missing = [k for k in _REQUIRED if k not in d]
    cl = _conduit_lengths(d)
    if cl is None:
        missing.append("throat.conduit_lengths (Nt, 3)")
    missing += [f"pore.{f}" for f in FACES if f"pore.{f}" not in d]
    if voxel_size is None and "porefsi.voxel_size" not in d:
        missing.append("porefsi.voxel_size (or pass voxel_size=)")
    if shape is None and "porefsi.shape" not in d:
        missing.append("porefsi.shape (or pass shape=)")
    if missing:
        raise InputError(
            "network arrays are missing keys: " + ", ".join(missing)
            + "; add them (an OpenPNM network needs its boundary labels, e.g. "
            "pn['pore.xmin'] = pn.coords[:, 0] <= x0, and porefsi's sphere-cylinder conduit lengths)"
        )
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


# ---------------------------------------------------------------------------------------------
# Statoil (pnextract / pnflow)
# ---------------------------------------------------------------------------------------------
def _perm(axis) -> np.ndarray:
    """Cyclic axis permutation putting ``axis`` first (pnflow always flows along its x)."""
    ax = axis_index(axis)
    return np.array([ax, (ax + 1) % 3, (ax + 2) % 3])


def _fmt(x) -> str:
    return f"{float(x):.16e}"


def write_statoil(net: Network, prefix: str | os.PathLike, axis: str | int = "x") -> list[Path]:
    r"""Write the four Statoil files pnflow reads (``PREFIX_node1.dat``, ``_node2.dat``, ``_link*.dat``).

    Parameters
    ----------
    net : Network
    prefix : path-like
        Path prefix of the files (folder must exist).
    axis : {'x', 'y', 'z'} or int
        Flow axis. pnflow always flows along its own x, so coordinates and box lengths are permuted
        cyclically to put ``axis`` first (x→x for 'x'; (y, z, x) for 'y'; (z, x, y) for 'z').

    Returns
    -------
    list of pathlib.Path
        The files written.

    Notes
    -----
    Layout (whitespace separated, 1-based indices; pnextract's ``writePNM``):

    * ``_link1.dat``: first line ``Nt``; then ``index pore1 pore2 radius shape_factor total_length``.
    * ``_link2.dat``: ``index pore1 pore2 pore1_length pore2_length throat_length volume clay_volume``.
    * ``_node1.dat``: first line ``Np Lx Ly Lz``; then ``index x y z Z n_1..n_Z is_inlet is_outlet
      t_1..t_Z`` (``Z`` neighbours and the throats leading to them).
    * ``_node2.dat``: ``index volume radius shape_factor clay_volume``.

    Pore index ``-1`` is the inlet reservoir and ``0`` the outlet reservoir. Every inlet pore
    (``net.inlet(axis)``) gets a link to ``-1`` and every outlet pore a link to ``0``, numbered
    after the ``Nt`` internal throats. Such a boundary link has the pore's radius and, with ``d``
    the distance from the pore centre to the face (at least half a voxel), a pore-side length
    ``d/2``, a cylinder ``d/2``, a reservoir-side length 0 and volume 0. Coordinates are written
    relative to the box corner (pnflow ignores an origin). Shape factors are the network's measured
    ones and the lengths its shape-factor ducts (:func:`porefsi.network.geometry.duct_lengths`)
    when its conduit model is ``"shape_factor"``; otherwise the circle's :math:`1/(4\pi)` and the
    paper's lengths. Clay volumes 0. Values carry 17 significant digits, so :func:`read_statoil`
    recovers the internal network exactly (the four side-face labels other than ``axis``'s are not
    part of the format and come back ``False``).

    References
    ----------
    Valvatne, P. H. & Blunt, M. J. (2004) Predictive pore-scale modeling of two-phase flow in mixed
    wet media. Water Resour. Res. 40, W07406 (pnflow's predecessor and its network format).
    """
    ax = axis_index(axis)
    perm = _perm(ax)
    base = Path(prefix)
    if not base.parent.exists():
        raise InputError(f"cannot write Statoil files {base}_*.dat: folder {base.parent} does not exist")
    n_p = net.n_pores
    xyz = (net.pore_coords - net.origin)[:, perm]
    box = net.extent[perm]
    inl = np.flatnonzero(net.inlet(ax))
    out = np.flatnonzero(net.outlet(ax))
    # Throat table: internal throats, then inlet links, then outlet links (file pore indices).
    p1 = np.concatenate([net.throat_conns[:, 0] + 1, np.full(inl.size, -1), np.full(out.size, 0)])
    p2 = np.concatenate([net.throat_conns[:, 1] + 1, inl + 1, out + 1])
    d_in = np.maximum(xyz[inl, 0], 0.5 * net.voxel_size)
    d_out = np.maximum(box[0] - xyz[out, 0], 0.5 * net.voxel_size)
    dbd = np.concatenate([d_in, d_out])
    bd_pores = np.concatenate([inl, out])
    radius = np.concatenate([net.throat_radius, net.pore_radius[bd_pores]])
    shaped = net.conduit_model == "shape_factor"
    L = duct_lengths(net) if shaped else np.column_stack(
        [net.throat_pore_length[:, 0], net.throat_length, net.throat_pore_length[:, 1]])
    l1 = np.concatenate([L[:, 0], np.zeros(bd_pores.size)])
    l2 = np.concatenate([L[:, 2], 0.5 * dbd])
    lt = np.concatenate([L[:, 1], 0.5 * dbd])
    tG = net.throat_shape_factor if shaped else np.full(net.n_throats, CIRCLE_SHAPE_FACTOR)
    pG = net.pore_shape_factor if shaped else np.full(n_p, CIRCLE_SHAPE_FACTOR)
    link_G = np.concatenate([tG, pG[bd_pores]])
    vol = np.concatenate([net.throat_volume, np.zeros(bd_pores.size)])
    n_all = p1.size
    paths = [Path(f"{base}_{s}.dat") for s in ("link1", "link2", "node1", "node2")]
    with open(paths[0], "w") as f:
        f.write(f"{n_all}\n")
        for t in range(n_all):
            f.write(f"{t + 1} {p1[t]} {p2[t]} {_fmt(radius[t])} {_fmt(link_G[t])} {_fmt(l1[t] + lt[t] + l2[t])}\n")
    with open(paths[1], "w") as f:
        for t in range(n_all):
            f.write(f"{t + 1} {p1[t]} {p2[t]} {_fmt(l1[t])} {_fmt(l2[t])} {_fmt(lt[t])} {_fmt(vol[t])} 0\n")
    # Per-pore neighbour and throat lists, from both ends of every throat.
    ends = np.concatenate([p1, p2])  # file indices
    others = np.concatenate([p2, p1])
    tids = np.concatenate([np.arange(n_all), np.arange(n_all)])
    real = ends >= 1
    ends, others, tids = ends[real] - 1, others[real], tids[real]
    order = np.lexsort((tids, ends))
    ends, others, tids = ends[order], others[order], tids[order]
    starts = np.searchsorted(ends, np.arange(n_p + 1))
    is_in, is_out = net.inlet(ax), net.outlet(ax)
    with open(paths[2], "w") as f:
        f.write(f"{n_p} {_fmt(box[0])} {_fmt(box[1])} {_fmt(box[2])}\n")
        for p in range(n_p):
            s, e = starts[p], starts[p + 1]
            tok = [str(p + 1), *(_fmt(c) for c in xyz[p]), str(e - s)]
            tok += [str(int(o)) for o in others[s:e]]
            tok += [str(int(is_in[p])), str(int(is_out[p]))]
            tok += [str(int(t) + 1) for t in tids[s:e]]
            f.write(" ".join(tok) + "\n")
    with open(paths[3], "w") as f:
        for p in range(n_p):
            f.write(f"{p + 1} {_fmt(net.pore_volume[p])} {_fmt(net.pore_radius[p])} {_fmt(pG[p])} 0\n")
    return paths


def _read_table(path: Path, skip: int, ncols: int) -> np.ndarray:
    if not path.is_file():
        raise InputError(f"Statoil file {str(path)!r} does not exist; all four PREFIX_*.dat files are needed")
    try:
        a = np.loadtxt(path, skiprows=skip, ndmin=2)
    except ValueError as exc:
        raise InputError(f"cannot parse Statoil file {str(path)!r}: {exc}") from None
    if a.size == 0:
        return np.zeros((0, ncols))
    if a.shape[1] < ncols:
        raise InputError(f"Statoil file {str(path)!r} has {a.shape[1]} columns, expected {ncols}")
    return a


def read_statoil(
    prefix: str | os.PathLike, *, voxel_size: float, axis: str | int = "x", origin=None
) -> Network:
    """Read the four Statoil files written by :func:`write_statoil` or by pnextract.

    Parameters
    ----------
    prefix : path-like
        Path prefix: ``PREFIX_node1.dat`` etc.
    voxel_size : float
        Voxel size, m (the format does not carry it); the image shape is the box lengths of
        ``_node1.dat`` divided by it, which must be whole numbers.
    axis : {'x', 'y', 'z'} or int
        The flow axis the files were written for (undoes the permutation of :func:`write_statoil`).
    origin : sequence of 3 float, optional
        Box corner, m (default zeros).

    Returns
    -------
    Network
        Internal throats only; pores linked to the inlet (``-1``) or outlet (``0``) reservoir, or
        flagged in ``_node1.dat``, get the ``axis`` min/max face labels.

    Raises
    ------
    InputError
        Missing or malformed files, box lengths not a whole number of voxels, or inconsistent counts.
    """
    ax = axis_index(axis)
    perm = _perm(ax)
    inv = np.argsort(perm)
    vs = float(voxel_size)
    if not np.isfinite(vs) or vs <= 0:
        raise InputError(f"voxel_size must be a positive length in metres, got {voxel_size!r}")
    base = Path(prefix)
    link1 = _read_table(Path(f"{base}_link1.dat"), 1, 6)
    link2 = _read_table(Path(f"{base}_link2.dat"), 0, 7)
    node2 = _read_table(Path(f"{base}_node2.dat"), 0, 4)
    node1_path = Path(f"{base}_node1.dat")
    if not node1_path.is_file():
        raise InputError(f"Statoil file {str(node1_path)!r} does not exist")
    with open(node1_path) as f:
        head = f.readline().split()
        if len(head) < 4:
            raise InputError(f"{node1_path}: first line must be 'Np Lx Ly Lz', got {' '.join(head)!r}")
        n_p = int(head[0])
        box = np.array([float(v) for v in head[1:4]])
        coords = np.empty((n_p, 3))
        flags = np.zeros((n_p, 2), dtype=bool)
        for p in range(n_p):
            tok = f.readline().split()
            if len(tok) < 5:
                raise InputError(f"{node1_path}: pore line {p + 1} is truncated")
            coords[p] = [float(v) for v in tok[1:4]]
            z = int(tok[4])
            flags[p] = [tok[5 + z] == "1", tok[6 + z] == "1"]
    if node2.shape[0] != n_p or link2.shape[0] != link1.shape[0]:
        raise InputError(
            f"Statoil files {base}_*.dat disagree: node1 has {n_p} pores, node2 {node2.shape[0]}; "
            f"link1 has {link1.shape[0]} throats, link2 {link2.shape[0]}"
        )
    shape_f = box[inv] / vs
    shape = np.rint(shape_f).astype(int)
    if np.any(np.abs(shape_f - shape) > 1e-6 * np.maximum(shape, 1)) or np.any(shape < 1):
        raise InputError(
            f"box lengths {box[inv]} m are not whole numbers of voxels of {vs} m; pass the right voxel_size"
        )
    a = link1[:, 1].astype(np.int64)
    b = link1[:, 2].astype(np.int64)
    internal = (a >= 1) & (b >= 1)
    faces = np.zeros((n_p, 6), dtype=bool)
    for res, col in ((-1, 2 * ax), (0, 2 * ax + 1)):
        hit = (a == res) | (b == res)
        faces[np.maximum(a, b)[hit] - 1, col] = True
    faces[:, 2 * ax] |= flags[:, 0]
    faces[:, 2 * ax + 1] |= flags[:, 1]
    org = np.zeros(3) if origin is None else np.asarray(origin, dtype=float)
    return Network(
        pore_coords=coords[:, inv] + org,
        pore_radius=node2[:, 2],
        pore_volume=node2[:, 1],
        throat_conns=np.column_stack([a[internal], b[internal]]) - 1,
        throat_radius=link1[internal, 3],
        throat_length=link2[internal, 5],
        throat_pore_length=link2[internal][:, [3, 4]],
        pore_faces=faces,
        voxel_size=vs,
        shape=tuple(shape),
        origin=org,
        throat_volume=link2[internal, 6],
        **_statoil_shape_factors(link1[internal, 4], node2[:, 3]),
    )


def _statoil_shape_factors(throat_G: np.ndarray, pore_G: np.ndarray) -> dict:
    r"""Shape factors of Statoil files, unless every one is the circle's (no measurement: paper model).

    pnextract writes measured values; porefsi before format 2 (and for paper-model networks) wrote
    the circle's :math:`1/(4\pi)` everywhere. Values above the circle's (pnextract caps at 0.079)
    are clipped to it.
    """
    G = np.concatenate([throat_G, pore_G])
    if G.size == 0 or np.allclose(G, CIRCLE_SHAPE_FACTOR, rtol=1e-12, atol=0.0):
        return {}
    bad = ~np.isfinite(G) | (G <= 0)
    if bad.any():
        raise NetworkError(
            f"Statoil files hold {int(bad.sum())} shape factor(s) that are NaN or <= 0; "
            "re-extract the network or repair the shape-factor columns"
        )
    return {
        "throat_shape_factor": np.minimum(throat_G, CIRCLE_SHAPE_FACTOR),
        "pore_shape_factor": np.minimum(pore_G, CIRCLE_SHAPE_FACTOR),
    }
