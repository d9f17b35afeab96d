"""ParaView-ready VTK XML PolyData (``.vtp``) of a pore network.

Pores are points (one VTK_VERTEX cell each) and throats are lines between them, laid out so
that ParaView's Glyph (spheres) and Tube filters draw every pore and throat at its own radius. Radii, volumes,
lengths and boundary labels travel as point and cell arrays, together with any per-pore or
per-throat arrays the caller adds (pressure, saturation, ...).

The file is written by a small hand-written XML writer rather than through pyvista/VTK: the
format is a fixed, documented schema (VTK "XML File Formats", PolyData), the writer adds no
import cost or VTK version dependence to ``porefsi extract``, and the output is byte-for-byte
deterministic. Arrays are stored inline as base64 binary (little-endian, UInt64 headers), which
VTK, ParaView and pyvista read; values round-trip exactly (float64). The tests read files back
with pyvista.
"""

from __future__ import annotations

import base64
import os
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from porefsi.errors import InputError
from porefsi.io.results import atomic_write_bytes
from porefsi.network.network import FACES, Network

__all__ = ["write_network_vtp"]

_VTK_TYPES = {
    "f4": "Float32",
    "f8": "Float64",
    "i1": "Int8",
    "i2": "Int16",
    "i4": "Int32",
    "i8": "Int64",
    "u1": "UInt8",
    "u2": "UInt16",
    "u4": "UInt32",
    "u8": "UInt64",
}


def _data_array(values: np.ndarray, name: str | None = None) -> str:
    a = np.asarray(values)
    if a.dtype == bool:
        a = a.astype(np.uint8)
    key = f"{a.dtype.kind}{a.dtype.itemsize}"
    if key not in _VTK_TYPES:
        raise InputError(f"array {name!r} has dtype {a.dtype}, which VTK cannot store; pass numbers")
    ncomp = 1 if a.ndim == 1 else int(np.prod(a.shape[1:]))
    raw = np.ascontiguousarray(a, dtype=a.dtype.newbyteorder("<")).tobytes()
    header = np.array([len(raw)], dtype="<u8").tobytes()
    # Header and data in one base64 stream: VTK seeks into inline arrays (e.g. the line part of a
    # cell array) by decoded byte offset, which is only right when both were encoded together.
    text = base64.b64encode(header + raw).decode("ascii")
    attr = f' Name="{name}"' if name else ""
    return (
        f'<DataArray type="{_VTK_TYPES[key]}"{attr} NumberOfComponents="{ncomp}" format="binary">'
        f"{text}</DataArray>\n"
    )


def _check_name(name: str) -> str:
    if not isinstance(name, str) or not name or any(c in name for c in '<>&"'):
        raise InputError(f"array name {name!r} is not a valid VTK array name; use letters, digits, '_'")
    return name


def _user_arrays(arrays: Mapping | None, n: int, what: str) -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    for name, val in (arrays or {}).items():
        a = np.asarray(val)
        if a.ndim == 0 or a.shape[0] != n:
            raise InputError(
                f"{what} array {name!r} has shape {a.shape}; it needs one value per {what} ({n},)"
            )
        out[_check_name(name)] = a
    return out


def write_network_vtp(
    net: Network,
    path: str | os.PathLike,
    point_data: Mapping[str, np.ndarray] | None = None,
    cell_data: Mapping[str, np.ndarray] | None = None,
    *,
    tubes: bool = True,
) -> Path:
    """Write ``net`` as a ParaView-ready ``.vtp`` file: pores as points, throats as lines.

    Parameters
    ----------
    net : Network
    path : path-like
        Output file; ``.vtp`` is appended if it has another suffix.
    point_data : mapping of str to ndarray, shape (Np,) or (Np, k), optional
        Extra per-pore arrays (e.g. ``pressure`` in Pa, ``saturation``).
    cell_data : mapping of str to ndarray, shape (Nt,) or (Nt, k), optional
        Extra per-throat arrays (e.g. ``flow_rate`` in m³/s). In the file they are cell arrays of
        length Np + Nt: NaN on the Np pore (vertex) cells, the values on the Nt throat (line) cells.
    tubes : bool, default True
        Give every throat line its own two end points (at its pores' centres) so that point data
        can carry the throat radius along the line: ParaView's Tube filter then draws every
        throat with its own radius. With ``False`` the lines share the pore points (Np points).

    Returns
    -------
    pathlib.Path
        The file written.

    Notes
    -----
    Geometry: points ``0 .. Np-1`` are the pore centres (m), one vertex cell each (pore ``i`` is
    cell ``i``); then ``Nt`` line cells (throat ``t`` is cell ``Np + t``). With ``tubes`` the
    line of throat ``t`` joins points ``Np + 2t`` and ``Np + 2t + 1``, copies of its two pore
    centres (``conns[t, 0]`` then ``conns[t, 1]``); otherwise it joins the pore points.

    Point arrays: ``radius`` (m: the pore's inscribed radius on pore points, the throat radius on
    throat end points), ``is_throat`` (0/1), ``pore_index`` (the pore a point sits at),
    ``volume`` (m³), ``coordination`` and one ``UInt8`` array per box face (``xmin`` ...
    ``zmax``) of that pore, and the ``point_data`` arrays (a throat end point takes the value of
    the pore it sits at). Networks with measured sections add ``shape_factor`` (G = A/P², placed
    like ``radius``) and, with face cuts, ``face_cut_radius`` (m), ``face_cut_shape_factor`` and
    ``face_cut_duct_fraction``: 6 components in :data:`~porefsi.network.network.FACES` order, 0
    where the pore does not touch that face (:class:`~porefsi.network.network.Network`).
    Cell arrays: ``radius`` (pore radius on vertex cells, throat radius on line cells, m),
    ``length`` (0 on vertex cells; conduit length centre to centre on line cells, m),
    ``volume`` (m³, pore or throat), ``is_throat`` (0/1) and ``index`` (pore or throat index);
    with measured sections also ``shape_factor`` (pore or throat) and ``duct_fraction`` (3
    components: the shares of the pore-i, throat and pore-j ducts; NaN on vertex cells).

    In ParaView: spheres with Glyph (Glyph Type Sphere, Scale Array ``radius``, Scale Factor 2
    since the default sphere has radius 0.5, Glyph Mode All Points: the spheres drawn at throat
    end points have the throat radius <= the pore radius and stay hidden inside the pore's
    sphere); throats with Tube (Vary Radius By Absolute Scalar, Scalars ``radius``, Radius
    Factor 1) on the same file.
    """
    p = Path(path)
    if p.suffix.lower() != ".vtp":
        p = p.with_name(p.name + ".vtp")
    if not p.parent.exists():
        raise InputError(f"cannot write {p}: folder {p.parent} does not exist; create it first")
    at = np.concatenate([np.arange(net.n_pores), net.throat_conns.astype(np.int64).ravel()]) if tubes \
        else np.arange(net.n_pores)  # pore of every point: the pores, then (tubes) the two ends of every throat
    parts = _vtp_text(net, at, _point_arrays(net, at, point_data, tubes), _cell_arrays(net, cell_data), tubes)
    atomic_write_bytes(p, "".join(parts).encode("ascii"))  # atomic, with the umask's permissions
    return p


def _point_arrays(net: Network, at: np.ndarray, point_data, tubes: bool) -> dict:
    """The point arrays (module docstring of :func:`write_network_vtp`); ``at``: the pore of each point."""
    n_p = net.n_pores
    pore_vals = {
        "volume": net.pore_volume,
        "coordination": net.coordination.astype(np.int64),
        **{name: net.pore_faces[:, k] for k, name in enumerate(FACES)},
        **_face_cut_arrays(net),
    }
    own = {"radius": (net.pore_radius, net.throat_radius)}
    if net.pore_shape_factor is not None:
        own["shape_factor"] = (net.pore_shape_factor, net.throat_shape_factor)
    extra_p = _user_arrays(point_data, n_p, "pore")
    clash = sorted(set(extra_p) & ({"is_throat", "pore_index"} | set(own) | set(pore_vals)))
    if clash:
        raise InputError(f"point_data names {clash} are reserved by the network arrays; rename them")
    pore_vals.update(extra_p)
    return {  # radius and section: the pore's value on pore points, the throat's on its end points
        **{k: np.concatenate([p_, np.repeat(t_, 2)]) if tubes else p_ for k, (p_, t_) in own.items()},
        "is_throat": (np.arange(at.size) >= n_p).astype(np.uint8),
        "pore_index": at,
        **{k: v[at] for k, v in pore_vals.items()},
    }


def _face_cut_arrays(net: Network) -> dict:
    """Per-pore face-cut sections (:attr:`Network.pore_face_radius` ...), 6 components in FACES order."""
    if not net.has_face_sections:
        return {}
    return {
        "face_cut_radius": net.pore_face_radius,
        "face_cut_shape_factor": net.pore_face_shape_factor,
        "face_cut_duct_fraction": net.pore_face_duct_fraction,
    }


def _cell_arrays(net: Network, cell_data) -> dict:
    """The cell arrays: Np pore vertex cells, then Nt throat line cells (user arrays NaN on the pores)."""
    n_p, n_t = net.n_pores, net.n_throats
    total_len = net.throat_length + net.throat_pore_length.sum(axis=1)
    cdata = {
        "radius": np.concatenate([net.pore_radius, net.throat_radius]),
        "length": np.concatenate([np.zeros(n_p), total_len]),
        "volume": np.concatenate([net.pore_volume, net.throat_volume]),
        "is_throat": np.concatenate([np.zeros(n_p, np.uint8), np.ones(n_t, np.uint8)]),
        "index": np.concatenate([np.arange(n_p), np.arange(n_t)]).astype(np.int64),
    }
    if net.pore_shape_factor is not None:
        cdata["shape_factor"] = np.concatenate([net.pore_shape_factor, net.throat_shape_factor])
    if net.throat_duct_fraction is not None:  # (pore i, throat, pore j) shares: NaN on the pore cells
        cdata["duct_fraction"] = np.concatenate([np.full((n_p, 3), np.nan), net.throat_duct_fraction])
    extra_c = _user_arrays(cell_data, n_t, "throat")
    clash = sorted(set(extra_c) & set(cdata))
    if clash:
        raise InputError(f"cell_data names {clash} are reserved by the network arrays; rename them")
    for name, a in extra_c.items():
        a = a.astype(float) if a.dtype.kind in "biu" else a
        if a.dtype.kind != "f":
            raise InputError(f"cell_data {name!r} must be numeric, got dtype {a.dtype}")
        pad = np.full((n_p, *a.shape[1:]), np.nan, dtype=a.dtype)
        cdata[name] = np.concatenate([pad, a])
    return cdata


def _vtp_text(net: Network, at: np.ndarray, pdata: dict, cdata: dict, tubes: bool) -> list[str]:
    """The VTK XML PolyData file, as pieces of text."""
    n_p, n_t = net.n_pores, net.n_throats
    points = net.pore_coords[at]
    line_conn = np.arange(n_p, n_p + 2 * n_t, dtype=np.int64) if tubes else net.throat_conns.astype(np.int64).ravel()
    return [
        '<?xml version="1.0"?>\n',
        '<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian" header_type="UInt64">\n',
        "<PolyData>\n",
        f'<Piece NumberOfPoints="{points.shape[0]}" NumberOfVerts="{n_p}" NumberOfLines="{n_t}" '
        'NumberOfStrips="0" NumberOfPolys="0">\n',
        '<PointData Scalars="radius">\n',
        *(_data_array(v, k) for k, v in pdata.items()),
        "</PointData>\n",
        '<CellData Scalars="radius">\n',
        *(_data_array(v, k) for k, v in cdata.items()),
        "</CellData>\n",
        "<Points>\n",
        _data_array(points, "Points"),
        "</Points>\n",
        "<Verts>\n",
        _data_array(np.arange(n_p, dtype=np.int64), "connectivity"),
        _data_array(np.arange(1, n_p + 1, dtype=np.int64), "offsets"),
        "</Verts>\n",
        "<Lines>\n",
        _data_array(line_conn, "connectivity"),
        _data_array(2 * np.arange(1, n_t + 1, dtype=np.int64), "offsets"),
        "</Lines>\n",
        "</Piece>\n</PolyData>\n</VTKFile>\n",
    ]
