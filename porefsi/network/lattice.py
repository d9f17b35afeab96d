"""Synthetic pore networks built directly as :class:`~porefsi.network.network.Network` objects.

These are the networks with known answers that the flow tests, studies and benchmarks use:
a straight tube cut into pores, chains of spherical pores, two parallel paths, and 2-D-like and
3-D cubic lattices with random radii drawn from a caller-supplied ``rng``.

Geometry conventions shared by every builder: pores sit on a grid of spacing ``spacing`` (m) with
centres at ``(index + 0.5) * spacing``, so the box spans ``[0, n * spacing]`` along each axis and
``voxel_size = spacing``, ``shape`` = the grid shape. A conduit between two pores of radii ``R_i``,
``R_j`` at distance ``d`` has pore parts of lengths ``R_i`` and ``R_j`` and a cylinder of length
``d - R_i - R_j`` (so the radii must stay below ``spacing / 2``).
"""

from __future__ import annotations

import numpy as np

from porefsi.errors import InputError
from porefsi.image.voxel_image import axis_index
from porefsi.network.network import Network

__all__ = [
    "tube_network",
    "chain_network",
    "parallel_paths_network",
    "lattice_network",
]


def _faces_for_grid(index: np.ndarray, shape: tuple) -> np.ndarray:
    faces = np.zeros((index.shape[0], 6), dtype=bool)
    for ax in range(3):
        faces[:, 2 * ax] = index[:, ax] == 0
        faces[:, 2 * ax + 1] = index[:, ax] == shape[ax] - 1
    return faces


def _positive(name, value):
    arr = np.asarray(value, dtype=float)
    if not np.all(np.isfinite(arr)) or np.any(arr <= 0):
        raise InputError(f"{name} must be finite and > 0, got {value!r}")
    return arr


def tube_network(n_pores: int, radius: float, length: float, axis="x", gap: float = 1e-6) -> Network:
    """A straight cylindrical tube of radius ``radius`` and length ``length`` cut into ``n_pores`` pores.

    Pore ``k`` owns the tube piece ``[k, k + 1) * length / n_pores`` along ``axis`` (volume
    ``pi r^2 length / n_pores``) and has pore radius equal to the tube radius, so every conduit
    segment is a cylinder of radius ``radius``; consecutive pores are joined by a throat whose
    cylinder is ``gap * spacing`` long and whose pore parts fill the rest of the spacing. The
    conduits therefore tile the tube exactly (their lengths add up to the spacing). Pore 0 is the
    only inlet pore (low face), pore ``n_pores - 1`` the only outlet pore.

    Parameters
    ----------
    n_pores : int
        Number of pores, >= 1.
    radius, length : float
        Tube radius and length, m.
    axis : {'x', 'y', 'z'}
        Tube direction.
    gap : float
        Throat cylinder length as a fraction of the spacing, in (0, 1).

    Returns
    -------
    Network
    """
    n = int(n_pores)
    if n < 1:
        raise InputError(f"n_pores must be >= 1, got {n_pores!r}")
    r, L = (float(v) for v in _positive("radius/length", [radius, length]))
    if not 0 < gap < 1:
        raise InputError(f"gap must be in (0, 1), got {gap!r}")
    ax = axis_index(axis)
    dx = L / n
    shape = [1, 1, 1]
    shape[ax] = n
    idx = np.zeros((n, 3), dtype=np.int64)
    idx[:, ax] = np.arange(n)
    coords = np.full((n, 3), 0.5 * dx)
    coords[:, ax] = (np.arange(n) + 0.5) * dx
    conns = np.column_stack([np.arange(n - 1), np.arange(1, n)])
    half = 0.5 * dx * (1.0 - gap)
    return Network(
        pore_coords=coords,
        pore_radius=np.full(n, r),
        pore_volume=np.full(n, np.pi * r * r * dx),
        throat_conns=conns.reshape(-1, 2),
        throat_radius=np.full(n - 1, r),
        throat_length=np.full(n - 1, gap * dx),
        throat_pore_length=np.full((n - 1, 2), half),
        pore_faces=_faces_for_grid(idx, tuple(shape)),
        voxel_size=dx,
        shape=tuple(shape),
    )


def chain_network(pore_radius, throat_radius, spacing: float, axis="x") -> Network:
    """A chain of spherical pores joined in series along ``axis``.

    Parameters
    ----------
    pore_radius : array_like of float, shape (N,)
        Pore radii, m, each < ``spacing / 2``.
    throat_radius : array_like of float, shape (N - 1,)
        Throat radii, m, each <= both neighbouring pore radii.
    spacing : float
        Centre-to-centre distance, m.
    axis : {'x', 'y', 'z'}

    Returns
    -------
    Network
        Pore volumes are the sphere volumes ``4/3 pi R^3``; pore 0 is the inlet, pore N-1 the outlet.
    """
    R = _positive("pore_radius", pore_radius).ravel()
    n = R.size
    rt = np.asarray(throat_radius, dtype=float).ravel()
    if rt.size != n - 1:
        raise InputError(f"throat_radius needs {n - 1} entries for {n} pores, got {rt.size}")
    return _grid_network(n_shape=_axis_shape(n, axis), R=R, edges=np.column_stack(
        [np.arange(n - 1), np.arange(1, n)]).reshape(-1, 2), rt=rt, spacing=spacing)


def _axis_shape(n, axis):
    shape = [1, 1, 1]
    shape[axis_index(axis)] = n
    return tuple(shape)


def _grid_network(n_shape, R, edges, rt, spacing, coords=None, index=None) -> Network:
    d = float(_positive("spacing", spacing))
    if np.any(R >= 0.5 * d):
        raise InputError(f"pore radii must be < spacing/2 = {0.5 * d:.4g} m, got max {R.max():.4g} m")
    if index is None:
        index = np.stack(np.unravel_index(np.arange(R.size), n_shape), axis=1)
    if coords is None:
        coords = (index + 0.5) * d
    dist = np.linalg.norm(coords[edges[:, 1]] - coords[edges[:, 0]], axis=1)
    cyl = dist - R[edges[:, 0]] - R[edges[:, 1]]
    return Network(
        pore_coords=coords,
        pore_radius=R,
        pore_volume=4.0 / 3.0 * np.pi * R**3,
        throat_conns=edges,
        throat_radius=rt,
        throat_length=cyl,
        throat_pore_length=np.column_stack([R[edges[:, 0]], R[edges[:, 1]]]),
        pore_faces=_faces_for_grid(index, tuple(n_shape)),
        voxel_size=d,
        shape=tuple(n_shape),
    )


def parallel_paths_network(pore_radius: float, throat_radii, spacing: float) -> Network:
    """Two parallel paths between an inlet pore and an outlet pore (flow along x).

    Inlet pore 0 at grid (0, 0); branch pores 1 at (1, 0) and 2 at (1, 1); outlet pore 3 at
    (2, 0); throats ``0-1, 0-2, 1-3, 2-3`` (in that order) with radii ``throat_radii``. Pore 2 is
    joined to 0 and 3 by diagonals (length ``sqrt(2) * spacing``). Only pore 0 touches xmin and only
    pore 3 touches xmax.

    Parameters
    ----------
    pore_radius : float
        Radius of every pore, m (< spacing / 2).
    throat_radii : array_like of float, shape (4,)
        Radii of throats 0-1, 0-2, 1-3, 2-3, m.
    spacing : float
        Grid spacing, m.
    """
    rt = np.asarray(throat_radii, dtype=float).ravel()
    if rt.size != 4:
        raise InputError(f"throat_radii needs 4 entries (0-1, 0-2, 1-3, 2-3), got {rt.size}")
    index = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [2, 0, 0]])
    d = float(spacing)
    coords = (index + 0.5) * d
    # pore 2 sits off-axis: its links to 0 and 3 are diagonals, longer than the spacing.
    edges = np.array([[0, 1], [0, 2], [1, 3], [2, 3]])
    R = np.full(4, float(pore_radius))
    net = _grid_network((3, 2, 1), R, edges, rt, spacing, coords=coords, index=index)
    faces = np.zeros((4, 6), dtype=bool)
    faces[0, 0] = True
    faces[3, 1] = True
    return net.replace(pore_faces=faces)


def lattice_network(shape, spacing: float, rng: np.random.Generator, pore_radius=(0.15, 0.35),
                    throat_ratio=(0.2, 0.9)) -> Network:
    """A cubic lattice (2-D-like when one dimension is 1) with random radii.

    Parameters
    ----------
    shape : tuple of 3 int
        Number of pores along x, y, z.
    spacing : float
        Lattice spacing, m.
    rng : numpy.random.Generator
        Source of the random radii (the caller seeds it).
    pore_radius : (float, float)
        Pore radii are uniform in this range times ``spacing`` (upper bound < 0.5).
    throat_ratio : (float, float)
        Throat radius = uniform factor in this range times the smaller pore radius.

    Returns
    -------
    Network
        Nearest-neighbour throats only; coordination 4 (2-D-like) or 6 (3-D) in the interior.
    """
    shp = tuple(int(s) for s in shape)
    if len(shp) != 3 or min(shp) < 1:
        raise InputError(f"shape must be 3 positive ints, got {shape!r}")
    lo, hi = (float(v) for v in pore_radius)
    tlo, thi = (float(v) for v in throat_ratio)
    if not (0 < lo <= hi < 0.5 and 0 < tlo <= thi <= 1):
        raise InputError(f"need 0 < pore_radius <= 0.5 and 0 < throat_ratio <= 1, got {pore_radius}, "
                         f"{throat_ratio}")
    n = int(np.prod(shp))
    ids = np.arange(n).reshape(shp)
    edges = []
    for ax in range(3):
        a = np.take(ids, np.arange(shp[ax] - 1), axis=ax).ravel()
        b = np.take(ids, np.arange(1, shp[ax]), axis=ax).ravel()
        edges.append(np.column_stack([a, b]))
    edges = np.concatenate(edges).reshape(-1, 2)
    d = float(spacing)
    R = rng.uniform(lo, hi, n) * d
    rt = rng.uniform(tlo, thi, edges.shape[0]) * np.minimum(R[edges[:, 0]], R[edges[:, 1]])
    return _grid_network(shp, R, edges, rt, d)
