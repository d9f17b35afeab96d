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
  the flow half a voxel away, diagonal :math:`+c`, with the closure ``wall``:

  - ``"ghost"``: ghost reflection :math:`u_{\mathrm{ghost}} = -u_f`, :math:`c = 2`. The face value
    is read as a point value; plane Poiseuille between walls :math:`N` voxels apart comes out as the
    parabola plus a uniform slip :math:`G h^2/8`, a flux :math:`1 + 2/N^2` times the exact one
    (3x at :math:`N = 1`, 1.5x at 2);
  - ``"channel"``: :math:`c(N) = 6N/(3N - 2)` (6, 3, 2.57, ... :math:`\to 2`) with :math:`N` the
    number of open faces in the line of faces along the wall normal, between the closed faces
    that end it. The face values are read as cell averages over the control volumes: plane
    Poiseuille :math:`u = G y (H - y)/2` (:math:`h = \mu = 1`, :math:`H = N`) has averages
    :math:`\bar u_0 = (3N-2)/12` and :math:`\bar u_1 = (9N-14)/12` in the two cells next to a
    wall; the wall-cell equation :math:`(\bar u_0 - \bar u_1) + c\,\bar u_0 = G` holds exactly
    iff :math:`c = 6N/(3N-2)`, and the interior equations hold exactly for any quadratic, so the
    discrete flux equals the exact :math:`N^3 G/12` for every :math:`N` (at :math:`N = 1` the
    single cell has both walls: :math:`2c\,\bar u_0 = G`, the same :math:`c = 6`). Still a diagonal
    term, so :math:`A` stays symmetric positive definite;
* across with *one* voxel of the neighbour face solid (a step of the wall along :math:`d`): that
  face is the face of a solid voxel, so :math:`u = 0` on it, a whole voxel away. ``"ghost"``:
  diagonal :math:`+1` (that point value alone). ``"channel"``: :math:`+(1 + c(N))/2`. The side of
  the face's control volume toward that neighbour is half wall (the half over the solid voxel,
  shear :math:`c(N)\,u_f` as for a whole wall) and half fluid (the half over the pore voxel, shear
  :math:`(u_f - 0)/h` toward the closed face); each half weighs 1/2.

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
    pore : ndarray of bool, shape (nx, ny, nz)
        The working domain (image plus buffer layers or mirror copy).
    n_planes : tuple of 3 int
        Face planes per axis: ``N_d`` if periodic, ``N_d + 1`` if bounded.
    offsets : ndarray of int64, shape (4,)
        Start of each velocity component in the velocity vector; ``offsets[3]`` = n_u.
    diag : ndarray of float64, shape (n_u,)
        Diagonal of the velocity block (links plus wall terms).
    half : ndarray of uint8, shape (n_u,)
        1 for faces on an open box face (half control volume: tangential links weigh 1/2).
    p_lo, p_hi : ndarray of int32, shape (n_u,)
        Pressure unknowns of the voxels before and after each face, -1 for a reservoir.
    pressure_cell : ndarray of int32 (int64 for 2^31 voxels or more), shape (n_p,)
        Flat index of each pressure unknown's voxel in the working domain.
    periodic : tuple of 3 bool
    open_axis : int or None
    drive : tuple of (int or None, float, float, float)
        ``(body_axis, body_force, p_in, p_out)``.
    wall : str
        Tangential wall closure, ``"ghost"`` or ``"channel"`` (see the module notes).
    neighbours : ndarray of int32, shape (n_u, 6), or None
        Neighbour face ids (slots: normal before/after, then the two other axes), -1 = none;
        None until :func:`with_neighbours` (built last: the pressure preconditioner does not need it).
    """

    pore: np.ndarray
    n_planes: tuple
    offsets: np.ndarray
    diag: np.ndarray
    half: np.ndarray
    p_lo: np.ndarray
    p_hi: np.ndarray
    pressure_cell: np.ndarray
    periodic: tuple
    open_axis: int | None
    drive: tuple
    wall: str = "ghost"
    neighbours: np.ndarray | None = None

    @property
    def shape(self) -> tuple:
        """Shape of the working domain."""
        return tuple(int(n) for n in self.pore.shape)

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

    def face_cells(self, d: int) -> np.ndarray:
        """Flat index, in the face array of axis ``d``, of every face of component ``d`` (in id order)."""
        fid, _ = kern.number_faces(self.pore, d, self.n_planes[d], self.periodic, _oa(self.open_axis), 0)
        return np.flatnonzero(fid.reshape(-1) >= 0)

    def face_plane(self, d: int) -> np.ndarray:
        """Plane index (coordinate along d) of every face of component ``d``."""
        return np.unravel_index(self.face_cells(d), self.plane_shape(d))[d]

    def rhs_u(self) -> np.ndarray:
        """Momentum right-hand side, shape (n_u,): reservoir pressures on the open box faces, body force."""
        body_axis, body_force, p_in, p_out = self.drive
        rhs = np.zeros(self.n_u)
        if body_axis is not None and body_force:
            rhs[self.offsets[body_axis]:self.offsets[body_axis + 1]] = body_force
        if self.open_axis is not None:
            sl = slice(self.offsets[self.open_axis], self.offsets[self.open_axis + 1])
            rhs[sl] += np.where(self.p_lo[sl] < 0, p_in, 0.0) - np.where(self.p_hi[sl] < 0, p_out, 0.0)
        return rhs

    @property
    def tables(self) -> tuple:
        """``(neighbours, diag, half, p_lo, p_hi)``: what the operator kernels of :mod:`._kernels` take."""
        if self.neighbours is None:
            raise ValueError("build the neighbour table first (porefsi.stokes._grid.with_neighbours)")
        return (self.neighbours, self.diag, self.half, self.p_lo, self.p_hi)

    @property
    def nbytes(self) -> int:
        """Bytes held by the tables."""
        arrays = [self.pore, self.diag, self.half, self.p_lo, self.p_hi, self.pressure_cell]
        if self.neighbours is not None:
            arrays.append(self.neighbours)
        return int(sum(a.nbytes for a in arrays))


#: Tangential wall closures (module notes) and their kernel codes.
WALLS = {"ghost": kern.WALL_GHOST, "channel": kern.WALL_CHANNEL}


def _oa(open_axis):
    return -1 if open_axis is None else int(open_axis)


def assemble(pore: np.ndarray, *, periodic=(False, False, False), open_axis: int | None = None,
             body_axis: int | None = None, body_force: float = 0.0, pressures=(1.0, 0.0),
             wall: str = "ghost", neighbours: bool = True) -> StaggeredSystem:
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
    body_force : float
        Body force density, voxel units.
    pressures : (float, float)
        Reservoir pressures ``(p_in, p_out)`` at plane 0 and the last plane of ``open_axis``.
    wall : {'ghost', 'channel'}
        Tangential wall closure (module notes).
    neighbours : bool, default True
        Also build the neighbour table (else call :func:`with_neighbours` later).

    Returns
    -------
    StaggeredSystem
    """
    if body_force and open_axis is not None:
        raise ValueError("a body force drives periodic flow only; with an open axis use pressures")
    if wall not in WALLS:
        raise ValueError(f"unknown wall closure {wall!r}; use one of {tuple(WALLS)}")
    p_in, p_out = pressures
    pore = np.ascontiguousarray(pore, dtype=bool)
    shape = pore.shape
    periodic = tuple(bool(x) for x in periodic)
    oa = _oa(open_axis)
    n_planes = tuple(shape[d] if periodic[d] else shape[d] + 1 for d in range(3))
    pressure_cell = np.flatnonzero(pore)
    if pore.size < 2**31:
        pressure_cell = pressure_cell.astype(np.int32)
    counts = [kern.number_faces(pore, d, n_planes[d], periodic, oa, 0)[1] for d in range(3)]
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    n_u = int(offsets[3])
    diag = np.empty(n_u, dtype=np.float64)
    half = np.empty(n_u, dtype=np.uint8)
    plo = np.empty(n_u, dtype=np.int32)
    phi = np.empty(n_u, dtype=np.int32)
    system = StaggeredSystem(pore, n_planes, offsets, diag, half, plo, phi, pressure_cell, periodic, open_axis,
                             (body_axis, float(body_force), float(p_in), float(p_out)), wall)
    _fill(system, None)
    return with_neighbours(system) if neighbours else system


def with_neighbours(system: StaggeredSystem) -> StaggeredSystem:
    """``system`` with its neighbour table built."""
    nb = np.empty((system.n_u, 6), dtype=np.int32)
    _fill(system, nb)
    return dataclasses.replace(system, neighbours=nb)


def _fill(system: StaggeredSystem, nb) -> None:
    """Run the table kernel per axis: coupling tables (``nb`` None) or the neighbour table."""
    pid = np.full(system.shape, -1, dtype=np.int32)
    pid.reshape(-1)[system.pressure_cell] = np.arange(system.n_p, dtype=np.int32)
    table = nb if nb is not None and nb.shape[0] == system.n_u else np.empty((0, 6), dtype=np.int32)
    out = (table, system.diag, system.half, system.p_lo, system.p_hi)
    oa = _oa(system.open_axis)
    for d in range(3):
        fid, _ = kern.number_faces(system.pore, d, system.n_planes[d], system.periodic, oa, int(system.offsets[d]))
        kern.face_tables(system.pore, pid, fid, d, system.periodic, oa, out, WALLS[system.wall])
