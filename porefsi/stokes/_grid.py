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

with :math:`A = \operatorname{diag}(A_x, A_y, A_z)` three decoupled scalar Laplacians. Neither
:math:`A` nor :math:`B` is stored as a matrix: :mod:`porefsi.stokes._kernels` applies them from a
per-face neighbour table.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from porefsi.stokes import _kernels as kern

__all__ = ["StaggeredSystem", "assemble"]


@dataclasses.dataclass(frozen=True, eq=False)
class StaggeredSystem:
    """The discrete Stokes system (voxel units), as stencil tables.

    Attributes
    ----------
    shape : tuple of 3 int
        Working domain (image plus buffer layers or mirror copy).
    n_planes : tuple of 3 int
        Face planes per axis: ``N_d`` if periodic, ``N_d + 1`` if bounded.
    offsets : ndarray of int64, shape (4,)
        Start of each velocity component in the velocity vector; ``offsets[3]`` = n_u.
    neighbours : ndarray of int32, shape (n_u, 6)
        Neighbour face ids (slots: normal before/after, then the two other axes), -1 = none.
    diag : ndarray of float32, shape (n_u,)
        Diagonal of the velocity block (links plus wall terms; sums of 1/2, 1 and 2, exact in float32).
    half : ndarray of uint8, shape (n_u,)
        1 for faces on an open box face (half control volume: tangential links weigh 1/2).
    p_lo, p_hi : ndarray of int32, shape (n_u,)
        Pressure unknowns of the voxels before and after each face, -1 for a reservoir.
    face_cell : ndarray of int32 (int64 for boxes of 2^31 faces or more), shape (n_u,)
        Flat index of each face in its component's plane array (shape ``shape`` with
        ``n_planes[d]`` along d).
    pressure_cell : ndarray of int64, shape (n_p,)
        Flat index of each pressure unknown's voxel in the working domain.
    rhs_u : ndarray of float, shape (n_u,)
        Momentum right-hand side: reservoir pressures and body force times control volume.
    periodic : tuple of 3 bool
    open_axis : int or None
    """

    shape: tuple
    n_planes: tuple
    offsets: np.ndarray
    neighbours: np.ndarray
    diag: np.ndarray
    half: np.ndarray
    p_lo: np.ndarray
    p_hi: np.ndarray
    face_cell: np.ndarray
    pressure_cell: np.ndarray
    rhs_u: np.ndarray
    periodic: tuple
    open_axis: int | None

    @property
    def n_p(self) -> int:
        """Number of pressure unknowns."""
        return int(self.pressure_cell.shape[0])

    @property
    def n_u(self) -> int:
        """Number of velocity unknowns."""
        return int(self.offsets[3])

    def plane_shape(self, d: int) -> tuple:
        """Shape of the face array of axis ``d``."""
        s = list(self.shape)
        s[d] = self.n_planes[d]
        return tuple(s)

    def face_plane(self, d: int) -> np.ndarray:
        """Plane index (coordinate along d) of every face of component ``d``."""
        cells = self.face_cell[self.offsets[d]:self.offsets[d + 1]]
        return np.unravel_index(cells, self.plane_shape(d))[d]

    @property
    def nbytes(self) -> int:
        """Bytes held by the tables."""
        return int(sum(a.nbytes for a in (self.neighbours, self.diag, self.half, self.p_lo, self.p_hi,
                                           self.face_cell, self.pressure_cell, self.rhs_u)))


def assemble(pore: np.ndarray, *, periodic=(False, False, False), open_axis: int | None = None,
             body_axis: int | None = None, body_force: float = 0.0,
             p_in: float = 1.0, p_out: float = 0.0) -> StaggeredSystem:
    r"""Build the MAC Stokes system on ``pore`` (voxel units, :math:`\mu = 1`).

    Parameters
    ----------
    pore : ndarray of bool, shape (nx, ny, nz)
        Pore voxels.
    periodic : 3 bools
        Axes that wrap around; the others are no-slip walls, except ``open_axis``.
    open_axis : int or None
        Axis whose box faces open onto reservoirs at ``p_in`` (plane 0) and ``p_out`` (last plane).
    body_axis : int or None
        Axis of the body force density ``body_force`` (per unit volume); only without ``open_axis``
        (every control volume is then a whole voxel).
    body_force, p_in, p_out : float
        Driving terms, voxel units.

    Returns
    -------
    StaggeredSystem
    """
    if body_force and open_axis is not None:
        raise ValueError("a body force drives periodic flow only; with an open axis use p_in and p_out")
    pore = np.ascontiguousarray(pore, dtype=bool)
    shape = pore.shape
    periodic = tuple(bool(x) for x in periodic)
    oa = -1 if open_axis is None else int(open_axis)
    n_planes = tuple(shape[d] if periodic[d] else shape[d] + 1 for d in range(3))
    pressure_cell = np.flatnonzero(pore)
    pid = np.full(shape, -1, dtype=np.int32)
    pid.reshape(-1)[pressure_cell] = np.arange(pressure_cell.size, dtype=np.int32)
    counts = []
    for d in range(3):
        _, c = kern.number_faces(pore, d, n_planes[d], periodic, oa, 0)
        counts.append(c)
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    n_u = int(offsets[3])
    nb = np.empty((n_u, 6), dtype=np.int32)
    diag = np.empty(n_u, dtype=np.float32)  # exact: sums of 1/2, 1 and 2
    half = np.empty(n_u, dtype=np.uint8)
    plo = np.empty(n_u, dtype=np.int32)
    phi = np.empty(n_u, dtype=np.int32)
    big = (shape[0] + 1) * (shape[1] + 1) * (shape[2] + 1) >= 2**31
    cell = np.empty(n_u, dtype=np.int64 if big else np.int32)
    rhs = np.zeros(n_u)
    for d in range(3):
        fid, _ = kern.number_faces(pore, d, n_planes[d], periodic, oa, int(offsets[d]))
        kern.face_tables(pore, pid, fid, d, periodic, oa, nb, diag, half, plo, phi, cell)
        sl = slice(offsets[d], offsets[d + 1])
        plane = np.unravel_index(cell[sl], fid.shape)[d]
        if d == body_axis and body_force:
            rhs[sl] += body_force
        if d == open_axis:
            rhs[sl] += np.where(plane == 0, p_in, 0.0) - np.where(plane == n_planes[d] - 1, p_out, 0.0)
        del fid
    return StaggeredSystem(tuple(shape), n_planes, offsets, nb, diag, half, plo, phi, cell, pressure_cell, rhs,
                           periodic, open_axis)
