r"""The Statoil files of the Imperial College codes: pnextract writes them, pnflow reads them.

:func:`write_statoil` / :func:`read_statoil`: the four text files (``PREFIX_node1.dat``,
``_node2.dat``, ``_link1.dat``, ``_link2.dat``); ``docs/network_formats.md`` lists every column.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from porefsi.errors import InputError, NetworkError
from porefsi.image.voxel_image import axis_index
from porefsi.network.geometry import duct_lengths
from porefsi.network.network import CIRCLE_SHAPE_FACTOR, Network

__all__ = ["write_statoil", "read_statoil"]


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
    after the ``Nt`` internal throats. Such a boundary link has, with ``d`` the distance from the
    pore centre to the face (at least half a voxel), a reservoir-side length 0 and volume 0 and
    either (shape-factor model with face sections) the face cut's radius and shape factor, a
    cylinder ``f d`` and a pore-side length ``(1 - f) d`` (``f`` = ``pore_face_duct_fraction``),
    or the pore's radius, a cylinder ``d/2`` and a pore-side length ``d/2``; :func:`read_statoil`
    reads the face cuts of the flow axis's faces back from them. Coordinates are written
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
    base = Path(prefix)
    if not base.parent.exists():
        raise InputError(f"cannot write Statoil files {base}_*.dat: folder {base.parent} does not exist")
    paths = [Path(f"{base}_{s}.dat") for s in ("link1", "link2", "node1", "node2")]
    links, pore_G = _links(net, ax)
    _write_links(paths[0], paths[1], links)
    _write_node1(paths[2], net, ax, links["p1"], links["p2"])
    with open(paths[3], "w") as f:
        for p in range(net.n_pores):
            f.write(f"{p + 1} {_fmt(net.pore_volume[p])} {_fmt(net.pore_radius[p])} {_fmt(pore_G[p])} 0\n")
    return paths


def _links(net: Network, ax: int) -> tuple[dict, np.ndarray]:
    """Link table (internal throats, then inlet links, then outlet links; file pore indices) and pore G.

    Keys ``p1, p2`` (file indices, -1 inlet / 0 outlet reservoir), ``radius, G, l1, lt, l2, volume``.
    """
    perm = _perm(ax)
    xyz = (net.pore_coords - net.origin)[:, perm]
    box = net.extent[perm]
    inl = np.flatnonzero(net.inlet(ax))
    out = np.flatnonzero(net.outlet(ax))
    d_in = np.maximum(xyz[inl, 0], 0.5 * net.voxel_size)
    d_out = np.maximum(box[0] - xyz[out, 0], 0.5 * net.voxel_size)
    dbd = np.concatenate([d_in, d_out])
    bd_pores = np.concatenate([inl, out])
    shaped = net.conduit_model == "shape_factor"
    b_rad, b_G, b_f = _boundary_links(net, ax, inl, out, shaped)
    L = duct_lengths(net) if shaped else np.column_stack(
        [net.throat_pore_length[:, 0], net.throat_length, net.throat_pore_length[:, 1]])
    tG = net.throat_shape_factor if shaped else np.full(net.n_throats, CIRCLE_SHAPE_FACTOR)
    pG = net.pore_shape_factor if shaped else np.full(net.n_pores, CIRCLE_SHAPE_FACTOR)
    links = {
        "p1": np.concatenate([net.throat_conns[:, 0] + 1, np.full(inl.size, -1), np.full(out.size, 0)]),
        "p2": np.concatenate([net.throat_conns[:, 1] + 1, inl + 1, out + 1]),
        "radius": np.concatenate([net.throat_radius, b_rad]),
        "G": np.concatenate([tG, pG[bd_pores] if b_G is None else b_G]),
        "l1": np.concatenate([L[:, 0], np.zeros(bd_pores.size)]),
        "lt": np.concatenate([L[:, 1], b_f * dbd]),
        "l2": np.concatenate([L[:, 2], (1.0 - b_f) * dbd]),
        "volume": np.concatenate([net.throat_volume, np.zeros(bd_pores.size)]),
    }
    return links, pG


def _boundary_links(net: Network, ax: int, inl: np.ndarray, out: np.ndarray, shaped: bool):
    """Radius, shape factor (None: the pores') and throat share of the inlet then outlet links.

    The face cut (radius at most the pore's, its G and constriction share) when the network has
    face sections and the shape-factor model; else the pore radius and half the length.
    """
    bd = np.concatenate([inl, out])
    if not (shaped and net.has_face_sections):
        return net.pore_radius[bd], None, np.full(bd.size, 0.5)
    cols = np.concatenate([np.full(inl.size, 2 * ax), np.full(out.size, 2 * ax + 1)])
    rad = np.minimum(net.pore_face_radius[bd, cols], net.pore_radius[bd])
    return rad, net.pore_face_shape_factor[bd, cols], net.pore_face_duct_fraction[bd, cols]


def _write_links(path1: Path, path2: Path, k: dict) -> None:
    """``_link1.dat`` (radius, G, total length) and ``_link2.dat`` (the three lengths, volume)."""
    p1, p2, l1, lt, l2 = k["p1"], k["p2"], k["l1"], k["lt"], k["l2"]
    with open(path1, "w") as f:
        f.write(f"{p1.size}\n")
        for t in range(p1.size):
            f.write(f"{t + 1} {p1[t]} {p2[t]} {_fmt(k['radius'][t])} {_fmt(k['G'][t])} "
                    f"{_fmt(l1[t] + lt[t] + l2[t])}\n")
    with open(path2, "w") as f:
        for t in range(p1.size):
            f.write(f"{t + 1} {p1[t]} {p2[t]} {_fmt(l1[t])} {_fmt(l2[t])} {_fmt(lt[t])} {_fmt(k['volume'][t])} 0\n")


def _write_node1(path: Path, net: Network, ax: int, p1: np.ndarray, p2: np.ndarray) -> None:
    """``_node1.dat``: box, then per pore its position, neighbours, inlet/outlet flags and link ids."""
    perm = _perm(ax)
    xyz = (net.pore_coords - net.origin)[:, perm]
    box = net.extent[perm]
    n_p, n_all = net.n_pores, p1.size
    ends = np.concatenate([p1, p2])  # file indices, from both ends of every link
    others = np.concatenate([p2, p1])
    tids = np.concatenate([np.arange(n_all), np.arange(n_all)])
    real = ends >= 1
    ends, others, tids = ends[real] - 1, others[real], tids[real]
    order = np.lexsort((tids, ends))
    ends, others, tids = ends[order], others[order], tids[order]
    starts = np.searchsorted(ends, np.arange(n_p + 1))
    is_in, is_out = net.inlet(ax), net.outlet(ax)
    with open(path, "w") as f:
        f.write(f"{n_p} {_fmt(box[0])} {_fmt(box[1])} {_fmt(box[2])}\n")
        for p in range(n_p):
            s, e = starts[p], starts[p + 1]
            tok = [str(p + 1), *(_fmt(c) for c in xyz[p]), str(e - s)]
            tok += [str(int(o)) for o in others[s:e]]
            tok += [str(int(is_in[p])), str(int(is_out[p]))]
            tok += [str(int(t) + 1) for t in tids[s:e]]
            f.write(" ".join(tok) + "\n")


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
    box, coords, flags = _read_node1(Path(f"{base}_node1.dat"))
    n_p = coords.shape[0]
    if node2.shape[0] != n_p or link2.shape[0] != link1.shape[0]:
        raise InputError(
            f"Statoil files {base}_*.dat disagree: node1 has {n_p} pores, node2 {node2.shape[0]}; "
            f"link1 has {link1.shape[0]} throats, link2 {link2.shape[0]}"
        )
    shape = _voxel_shape(box[inv], vs)
    a = link1[:, 1].astype(np.int64)
    b = link1[:, 2].astype(np.int64)
    internal = (a >= 1) & (b >= 1)
    faces = _faces(a, b, flags, ax)
    org = np.zeros(3) if origin is None else np.asarray(origin, dtype=float)
    shape_factors = _statoil_shape_factors(link1[internal, 4], node2[:, 3])
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
        **shape_factors,
        **(_face_sections(link1, link2, faces, ax) if shape_factors else {}),
    )


def _face_sections(link1: np.ndarray, link2: np.ndarray, faces: np.ndarray, ax: int) -> dict:
    """Face cuts of the ``axis`` faces from the boundary links (radius, G, throat share of the length).

    Empty (no face sections) unless every pore on those faces has exactly one link to its
    reservoir with a positive finite radius and shape factor. The four other faces carry none
    (their labels are not part of the format).
    """
    a, b = link1[:, 1].astype(np.int64), link1[:, 2].astype(np.int64)
    n_p = faces.shape[0]
    out = {k: np.zeros((n_p, 6)) for k in ("pore_face_radius", "pore_face_shape_factor", "pore_face_duct_fraction")}
    for res, col in ((-1, 2 * ax), (0, 2 * ax + 1)):
        rows = np.flatnonzero((a == res) | (b == res))
        pores = np.maximum(a, b)[rows] - 1
        if np.unique(pores).size != pores.size or not np.array_equal(np.sort(pores), np.flatnonzero(faces[:, col])):
            return {}
        rad, G = link1[rows, 3], link1[rows, 4]
        if not (np.all(np.isfinite(rad) & (rad > 0)) and np.all(np.isfinite(G) & (G > 0))):
            return {}
        lt = link2[rows, 5]
        lp = np.where(b[rows] == pores + 1, link2[rows, 4], link2[rows, 3])
        total = lt + lp
        out["pore_face_radius"][pores, col] = rad
        out["pore_face_shape_factor"][pores, col] = np.minimum(G, CIRCLE_SHAPE_FACTOR)
        share = np.clip(lt / np.where(total > 0, total, 1.0), 0.0, 1.0)
        out["pore_face_duct_fraction"][pores, col] = np.where(total > 0, share, 0.5)
    return out


def _read_node1(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``_node1.dat``: box lengths (3,), pore positions (Np, 3) and inlet/outlet flags (Np, 2)."""
    if not path.is_file():
        raise InputError(f"Statoil file {str(path)!r} does not exist")
    with open(path) as f:
        head = f.readline().split()
        if len(head) < 4:
            raise InputError(f"{path}: first line must be 'Np Lx Ly Lz', got {' '.join(head)!r}")
        n_p = int(head[0])
        box = np.array([float(v) for v in head[1:4]])
        coords = np.empty((n_p, 3))
        flags = np.zeros((n_p, 2), dtype=bool)
        for p in range(n_p):
            tok = f.readline().split()
            if len(tok) < 5:
                raise InputError(f"{path}: pore line {p + 1} is truncated")
            coords[p] = [float(v) for v in tok[1:4]]
            z = int(tok[4])
            flags[p] = [tok[5 + z] == "1", tok[6 + z] == "1"]
    return box, coords, flags


def _voxel_shape(box: np.ndarray, vs: float) -> tuple[int, int, int]:
    """Image shape from box lengths (m) and the voxel size; refused unless whole voxels."""
    shape_f = box / vs
    shape = np.rint(shape_f).astype(int)
    if np.any(np.abs(shape_f - shape) > 1e-6 * np.maximum(shape, 1)) or np.any(shape < 1):
        raise InputError(
            f"box lengths {box} m are not whole numbers of voxels of {vs} m; pass the right voxel_size"
        )
    return tuple(int(v) for v in shape)


def _faces(a: np.ndarray, b: np.ndarray, flags: np.ndarray, ax: int) -> np.ndarray:
    """Face labels (Np, 6): pores linked to the inlet (-1) / outlet (0) reservoir or flagged in node1."""
    faces = np.zeros((flags.shape[0], 6), dtype=bool)
    for res, col in ((-1, 2 * ax), (0, 2 * ax + 1)):
        hit = (a == res) | (b == res)
        faces[np.maximum(a, b)[hit] - 1, col] = True
    faces[:, 2 * ax] |= flags[:, 0]
    faces[:, 2 * ax + 1] |= flags[:, 1]
    return faces


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
