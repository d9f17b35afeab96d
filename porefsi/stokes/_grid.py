r"""The staggered (MAC) finite-volume Stokes system on the pore voxels of a binary image.

Everything here is in voxel units (voxel edge :math:`h = 1`, viscosity :math:`\mu = 1`);
:mod:`porefsi.stokes.permeability` scales to SI.

Unknowns
--------
* a pressure :math:`p_c` at the centre of every pore voxel :math:`c`;
* for each axis :math:`d`, a velocity component :math:`u_f` on every face :math:`f` normal to
  :math:`d` whose two voxels are pore (and, with an open boundary along :math:`d`, on the box faces of
  pore voxels). A face with a solid voxel on either side is a wall:
  its normal velocity is zero and it is no unknown.

Faces of axis :math:`d` lie on *planes* :math:`f = 0, 1, \dots`: plane :math:`f` separates voxel
layers :math:`f - 1` and :math:`f` (with a periodic axis, plane 0 separates the last and the first
layer; with a bounded one, planes 0 and :math:`N_d` are the box faces).

Equations
---------
Momentum for :math:`u_f`, integrated over the voxel-sized control volume centred on the face:

.. math:: \sum_{g \sim f} w_{fg} (u_f - u_g) + w^{\mathrm{wall}}_f u_f + (p_{\mathrm{hi}} - p_{\mathrm{lo}})
          = b_f \, V_f ,

with the six neighbours :math:`g` of the 7-point Laplacian. A missing neighbour is handled by where
the wall is:

* along :math:`d` (normal direction): the neighbour face is a wall face, a whole voxel away:
  :math:`u = 0` there, diagonal :math:`+1`;
* across (tangential direction) with *both* voxels of the neighbour face solid: a wall parallel to
  the flow half a voxel away; ghost reflection :math:`u_{\mathrm{ghost}} = -u_f`, diagonal :math:`+2`;
* across with *one* voxel of the neighbour face solid: that face is the face of a solid voxel, so
  the no-slip point lies exactly on it, a whole voxel away: :math:`u = 0` there, diagonal :math:`+1`.

On an open box face (pressure boundary) the control volume is the half voxel inside the box:
tangential terms weigh 1/2 (their walls are those of the image voxel the half volume lies in),
the outward normal term vanishes (zero normal velocity gradient) and the reservoir pressure,
applied on the box face itself, enters the right-hand side. Continuity in each pore voxel,
:math:`\sum_{\mathrm{faces}} \pm u_f = 0`, is the matrix :math:`B` (outflow positive), so the
system is symmetric:

.. math:: \begin{pmatrix} A & -B^T \\ -B & 0 \end{pmatrix}
          \begin{pmatrix} u \\ p \end{pmatrix} = \begin{pmatrix} f \\ 0 \end{pmatrix},

with :math:`A = \operatorname{diag}(A_x, A_y, A_z)` three decoupled scalar Laplacians.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.sparse as sp

__all__ = ["StaggeredSystem", "assemble"]

#: Ghost-reflection weight of a tangential wall half a voxel away (u_ghost = -u).
GHOST_WALL = 2.0
#: Weight of a no-slip point a whole voxel away (u = 0 there).
POINT_WALL = 1.0


@dataclasses.dataclass(frozen=True, eq=False)
class StaggeredSystem:
    """The assembled saddle-point system (voxel units).

    Attributes
    ----------
    pore : ndarray of bool, shape (nx, ny, nz)
        Pore voxels of the working domain (image plus buffer layers).
    pressure_id : ndarray of int64, shape (nx, ny, nz)
        Index of each voxel's pressure unknown, -1 for solid.
    face_id : tuple of 3 ndarray of int64
        For axis d, shape ``shape`` with ``n_planes[d]`` along d: index of the face's velocity
        unknown in the full velocity vector, -1 for a wall face.
    n_planes : tuple of 3 int
        Face planes per axis: ``N_d`` if periodic, ``N_d + 1`` if bounded.
    blocks : tuple of 3 scipy.sparse.csr_matrix
        :math:`A_x, A_y, A_z`, symmetric positive (semi)definite.
    offsets : ndarray of int64, shape (4,)
        Start of each component in the velocity vector; ``offsets[3]`` = number of velocities.
    B : scipy.sparse.csr_matrix, shape (n_p, n_u)
        Discrete divergence, +1 for a face the voxel's flow leaves by (its high side), -1 else.
    rhs_u : ndarray of float, shape (n_u,)
        Momentum right-hand side: reservoir pressures and body force times control volume.
    periodic : tuple of 3 bool
        Which axes wrap around.
    open_axis : int or None
        Axis whose box faces are open to reservoirs (pressure boundary), or None.
    """

    pore: np.ndarray
    pressure_id: np.ndarray
    face_id: tuple
    n_planes: tuple
    blocks: tuple
    offsets: np.ndarray
    B: sp.csr_matrix
    rhs_u: np.ndarray
    periodic: tuple
    open_axis: int | None

    @property
    def n_p(self) -> int:
        """Number of pressure unknowns."""
        return int(self.B.shape[0])

    @property
    def n_u(self) -> int:
        """Number of velocity unknowns."""
        return int(self.offsets[3])


def _pad(a: np.ndarray, periodic, open_axis, fill) -> np.ndarray:
    """Pad ``a`` by one layer per side: wrap on periodic axes, ``fill`` on wall axes.

    Along ``open_axis`` a boolean array is padded by repeating its edge layer (a box-face velocity's
    half control volume lies in the image voxel, so that voxel alone says where its walls are);
    any other array by ``fill``.
    """
    out = a
    for d in range(3):
        widths = [(0, 0)] * 3
        widths[d] = (1, 1)
        if periodic[d]:
            out = np.pad(out, widths, mode="wrap")
        elif d == open_axis and a.dtype == bool:
            out = np.pad(out, widths, mode="edge")
        else:
            out = np.pad(out, widths, mode="constant", constant_values=fill)
    return out


def _pad_transverse(inner: np.ndarray, d: int, periodic) -> np.ndarray:
    """Pad a plane array by one layer on each transverse side: wrap if periodic, else -1."""
    out = inner
    for a in range(3):
        if a == d:
            continue
        widths = [(0, 0)] * 3
        widths[a] = (1, 1)
        if periodic[a]:
            out = np.pad(out, widths, mode="wrap")
        else:
            out = np.pad(out, widths, mode="constant", constant_values=-1)
    return out


def _planes(E: np.ndarray, d: int, n_planes: int, shift: int) -> np.ndarray:
    """The padded array's voxel layer ``f + shift`` for every plane f (all transverse indices kept)."""
    idx = [slice(None)] * 3
    idx[d] = slice(shift, shift + n_planes)
    return E[tuple(idx)]


def _interior(a: np.ndarray, d: int) -> np.ndarray:
    """Drop the transverse padding of a plane array (keep everything along ``d``)."""
    idx = [slice(1, -1)] * 3
    idx[d] = slice(None)
    return a[tuple(idx)]


def assemble(pore: np.ndarray, *, periodic=(False, False, False), open_axis: int | None = None,
             body_axis: int | None = None, body_force: float = 0.0,
             p_in: float = 1.0, p_out: float = 0.0) -> StaggeredSystem:
    r"""Assemble the MAC Stokes system on ``pore`` (voxel units, :math:`\mu = 1`).

    Parameters
    ----------
    pore : ndarray of bool, shape (nx, ny, nz)
        Pore voxels.
    periodic : 3 bools
        Axes that wrap around; the others are no-slip walls, except ``open_axis``.
    open_axis : int or None
        Axis whose box faces open onto reservoirs at ``p_in`` (plane 0) and ``p_out`` (last plane).
    body_axis : int or None
        Axis of the body force density ``body_force`` (per unit volume).
    body_force, p_in, p_out : float
        Driving terms, voxel units.

    Returns
    -------
    StaggeredSystem
    """
    pore = np.ascontiguousarray(pore, dtype=bool)
    shape = pore.shape
    periodic = tuple(bool(x) for x in periodic)
    pid = np.full(shape, -1, dtype=np.int64)
    pid[pore] = np.arange(int(np.count_nonzero(pore)), dtype=np.int64)
    E = _pad(pore, periodic, open_axis, False)
    P = _pad(pid, periodic, open_axis, -1)
    n_planes = tuple(shape[d] if periodic[d] else shape[d] + 1 for d in range(3))
    lo = [_planes(E, d, n_planes[d], 0) for d in range(3)]  # voxel before each plane (padded transverse)
    hi = [_planes(E, d, n_planes[d], 1) for d in range(3)]
    opened = [lo[d] & hi[d] for d in range(3)]
    counts = [int(np.count_nonzero(_interior(opened[d], d))) for d in range(3)]
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    face_id = []
    for d in range(3):
        m = _interior(opened[d], d)
        inner = np.full(m.shape, -1, dtype=np.int64)
        inner[m] = offsets[d] + np.arange(counts[d], dtype=np.int64)
        face_id.append(_pad_transverse(inner, d, periodic))
    blocks, rhs_parts, b_rows, b_cols, b_vals = [], [], [], [], []
    for d in range(3):
        A_d, rhs_d = _momentum_block(d, face_id[d], lo[d], hi[d], periodic, open_axis, offsets[d], counts[d])
        if d == body_axis and body_force:
            rhs_d += body_force * _control_volume(d, face_id[d], open_axis, n_planes[d])
        if d == open_axis:
            fid_in = _interior(face_id[d], d)
            first = np.take(fid_in, 0, axis=d)
            last = np.take(fid_in, n_planes[d] - 1, axis=d)
            rhs_d[first[first >= 0] - offsets[d]] += p_in
            rhs_d[last[last >= 0] - offsets[d]] -= p_out
        blocks.append(A_d)
        rhs_parts.append(rhs_d)
        fid_in = _interior(face_id[d], d)
        m = fid_in >= 0
        plo = _interior(_planes(P, d, n_planes[d], 0), d)[m]
        phi = _interior(_planes(P, d, n_planes[d], 1), d)[m]
        f = fid_in[m]
        ok = plo >= 0
        b_rows += [plo[ok], phi[phi >= 0]]
        b_cols += [f[ok], f[phi >= 0]]
        b_vals += [np.ones(int(ok.sum())), -np.ones(int((phi >= 0).sum()))]
    n_p = int(np.count_nonzero(pore))
    B = sp.csr_matrix((np.concatenate(b_vals), (np.concatenate(b_rows), np.concatenate(b_cols))),
                      shape=(n_p, int(offsets[3])))
    return StaggeredSystem(pore, pid, tuple(_interior(f, d) for d, f in enumerate(face_id)), n_planes,
                           tuple(blocks), offsets, B, np.concatenate(rhs_parts), periodic, open_axis)


def _boundary_plane_weight(d: int, open_axis, n_planes: int, shape) -> np.ndarray:
    """1 for faces inside the box, 1/2 on the open box faces (half control volume); plane-broadcastable."""
    w = np.ones(n_planes)
    if d == open_axis:
        w[0] = w[-1] = 0.5
    s = [1, 1, 1]
    s[d] = n_planes
    return w.reshape(s)


def _control_volume(d, fid_padded, open_axis, n_planes) -> np.ndarray:
    fid = _interior(fid_padded, d)
    w = np.broadcast_to(_boundary_plane_weight(d, open_axis, n_planes, fid.shape), fid.shape)
    return w[fid >= 0].astype(float)


def _momentum_block(d, fid, lo, hi, periodic, open_axis, offset, count):
    """Scalar Laplacian for the component along ``d`` on its open faces (see module notes)."""
    n_planes = fid.shape[d]
    inner = _interior(fid, d)
    m = inner >= 0
    rows_all = inner[m] - offset
    wplane = np.broadcast_to(_boundary_plane_weight(d, open_axis, n_planes, inner.shape), inner.shape)[m]
    diag = np.zeros(count)
    rows, cols, vals = [], [], []
    for t in range(3):
        for step in (-1, 1):
            if t == d:
                nb, wall = _normal_neighbour(inner, d, step, periodic[d])
                w = np.ones(count) if open_axis != d else _normal_weight(inner, d, step, m)
            else:
                nb, wall = _tangential_neighbour(fid, lo, hi, d, t, step)
                w = wplane
            nb = nb[m]
            wall = wall[m]
            link = nb >= 0
            rows.append(rows_all[link])
            cols.append(nb[link] - offset)
            vals.append(-w[link])
            diag += np.where(link, w, 0.0) + w * wall
    rows.append(np.arange(count))
    cols.append(np.arange(count))
    vals.append(diag)
    A = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(count, count))
    return A, np.zeros(count)


def _normal_weight(inner, d, step, m):
    """Normal-direction coupling weight: 1, except 0 outward from an open box face (nothing beyond)."""
    n = inner.shape[d]
    idx = np.arange(n)
    w = np.ones(n)
    w[(idx + step < 0) | (idx + step >= n)] = 0.0
    s = [1, 1, 1]
    s[d] = n
    return np.broadcast_to(w.reshape(s), inner.shape)[m]


def _normal_neighbour(inner, d, step, periodic_d):
    """Neighbour face id along the face normal, and the wall weight when that face is a wall.

    A closed neighbour plane face is a wall face a whole voxel away (weight POINT_WALL); beyond the
    last plane of a bounded axis there is either a wall plane (already closed faces) or an open box
    face, whose outward side has no term.
    """
    if periodic_d:
        nb = np.roll(inner, -step, axis=d)
        exists = np.ones(inner.shape, dtype=bool)
    else:
        nb = np.full(inner.shape, -1, dtype=np.int64)
        exists = np.zeros(inner.shape, dtype=bool)
        src = [slice(None)] * 3
        dst = [slice(None)] * 3
        if step > 0:
            src[d], dst[d] = slice(1, None), slice(0, -1)
        else:
            src[d], dst[d] = slice(0, -1), slice(1, None)
        nb[tuple(dst)] = inner[tuple(src)]
        exists[tuple(dst)] = True
    wall = np.where(exists & (nb < 0), POINT_WALL, 0.0)
    return nb, wall


def _tangential_neighbour(fid, lo, hi, d, t, step):
    """Neighbour face id across (axis ``t``), and the wall weight when that face is closed."""
    sl = [slice(None)] * 3
    sl[t] = slice(1 + step, fid.shape[t] - 1 + step)
    for a in range(3):
        if a not in (d, t):
            sl[a] = slice(1, -1)
    sl = tuple(sl)
    nb = fid[sl]
    solid = (~lo[sl]).astype(np.int8) + (~hi[sl]).astype(np.int8)
    wall = np.where(nb >= 0, 0.0, np.where(solid == 2, GHOST_WALL, np.where(solid == 1, POINT_WALL, 0.0)))
    return nb, wall
