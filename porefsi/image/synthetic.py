"""Synthetic segmented images with closed-form geometry, for tests and verification.

All construction lengths (spacing, radii, margins, shapes) are in **voxels**; every returned
geometric quantity is in **metres**. A voxel is pore when its *centre* lies inside the shape
(closed set), so a sphere of radius R centred on a voxel centre holds the voxels with
``|x - c| <= R``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from porefsi.errors import InputError
from porefsi.image.voxel_image import VoxelImage, axis_index

__all__ = ["SyntheticLattice", "SyntheticBundle", "sphere_lattice", "cylinder_bundle"]


@dataclasses.dataclass(frozen=True, eq=False)
class SyntheticLattice:
    """A cubic lattice of spheres joined by cylinders along the lattice edges.

    Attributes
    ----------
    image : VoxelImage
    pore_centres : ndarray of float, shape (Np, 3)
        Sphere centres, m (centres of voxels ``pore_centre_voxels``).
    pore_centre_voxels : ndarray of int, shape (Np, 3)
        Voxel index of each sphere centre.
    pore_radius : ndarray of float, shape (Np,)
        Sphere radii, m.
    throat_conns : ndarray of int, shape (Nt, 2)
        Lattice edges, ``conns[:, 0] < conns[:, 1]``; pores numbered in C order of the lattice.
    throat_radius : ndarray of float, shape (Nt,)
        Cylinder radii, m.
    throat_length : ndarray of float, shape (Nt,)
        Length of each cylinder outside both spheres, m:
        ``spacing - sqrt(R_i^2 - r^2) - sqrt(R_j^2 - r^2)``.
    porosity : float
        Exact pore-voxel fraction of ``image``.
    """

    image: VoxelImage
    pore_centres: np.ndarray
    pore_centre_voxels: np.ndarray
    pore_radius: np.ndarray
    throat_conns: np.ndarray
    throat_radius: np.ndarray
    throat_length: np.ndarray
    porosity: float


@dataclasses.dataclass(frozen=True, eq=False)
class SyntheticBundle:
    r"""Straight parallel cylinders (tubes) crossing the box along one axis.

    Attributes
    ----------
    image : VoxelImage
    axis : int
        Array axis of the tubes.
    centres_vox : ndarray of int, shape (Nc, 2)
        Tube axis positions in the cross-section (voxel indices of the two other axes, in
        increasing axis order).
    radius : ndarray of float, shape (Nc,)
        Nominal tube radii, m.
    permeability_m2 : float
        Hagen–Poiseuille permeability of the nominal tubes, m²:
        :math:`k = \sum_c \pi r_c^4 / 8 \,/\, A_{box}`.
    permeability_voxel_m2 : float
        Saint-Venant upper bound for Stokes flow in the *voxelised* tubes, m²:
        :math:`k \le \sum_c A_c^2 / (8\pi) \,/\, A_{box}` with :math:`A_c` the tube's
        voxelised cross-section area (the disc has the largest flow rate of all sections of
        equal area; Pólya & Szegő 1951).
    permeability_bounds_m2 : tuple of float
        ``(lower, upper)``: the exact Stokes permeability of the voxelised image lies between
        the Hagen–Poiseuille value of each tube's largest inscribed disc (the section contains
        it, and the flow rate grows with the domain) and ``permeability_voxel_m2``.
    porosity : float
        Exact pore-voxel fraction.
    """

    image: VoxelImage
    axis: int
    centres_vox: np.ndarray
    radius: np.ndarray
    permeability_m2: float
    permeability_voxel_m2: float
    permeability_bounds_m2: tuple
    porosity: float


def _positive_int(name, value):
    v = np.asarray(value)
    if v.ndim != 0 or not float(v).is_integer() or float(v) < 0:
        raise InputError(f"{name} must be a non-negative whole number of voxels, got {value!r}")
    return int(v)


def sphere_lattice(
    n: tuple[int, int, int] = (3, 3, 3),
    spacing: int = 14,
    pore_radius: float | np.ndarray = 5.0,
    throat_radius: float | np.ndarray = 2.0,
    voxel_size: float = 1e-5,
    margin: int | None = None,
) -> SyntheticLattice:
    """Build a lattice of spheres joined by cylinders along every lattice edge.

    Sphere ``(a, b, c)`` is centred on voxel ``margin + spacing * (a, b, c)``; the image has
    ``2 * margin + spacing * (n - 1) + 1`` voxels along each axis, so the end spheres cross the
    faces (``margin <= R``) and the pore space percolates along every axis.

    Parameters
    ----------
    n : tuple of 3 int, default (3, 3, 3)
        Spheres along x, y, z (>= 1 each).
    spacing : int, default 14
        Centre-to-centre distance, voxels; must exceed ``R_i + R_j`` for every edge.
    pore_radius : float or array_like, default 5.0
        Sphere radius, voxels: one value, or one per sphere (shape ``n`` or ``(Np,)``, C order).
    throat_radius : float or array_like, default 2.0
        Cylinder radius, voxels: one value or one per edge (``(Nt,)`` in ``throat_conns``
        order); must be below both sphere radii.
    voxel_size : float, default 1e-5
        m.
    margin : int, optional
        Voxels between a face and the nearest sphere centres, at most the smallest end-sphere
        radius (so every end sphere crosses its faces). Default
        ``min(min R_end, ceil(0.7 max R_end))``. With ``margin < R / sqrt(2)`` the distance-map
        maximum of a sphere cut by two or three faces moves from its centre towards the
        edge or corner (outside the image is not solid), so an extracted centre can shift.

    Returns
    -------
    SyntheticLattice

    Raises
    ------
    InputError
        Overlapping spheres, throats wider than a sphere, end spheres that miss the faces,
        non-integer spacing/margin.

    Examples
    --------
    >>> lat = sphere_lattice(n=(2, 2, 2))
    >>> lat.image.shape, len(lat.throat_conns)
    ((23, 23, 23), 12)
    """
    n = tuple(int(v) for v in n)
    if len(n) != 3 or min(n) < 1:
        raise InputError(f"n must be 3 positive ints (spheres per axis), got {n!r}")
    spacing = _positive_int("spacing", spacing)
    R = _per_item(pore_radius, int(np.prod(n)), "pore_radius", 1.0)
    grid = np.stack(np.meshgrid(*[np.arange(k) for k in n], indexing="ij"), axis=-1).reshape(-1, 3)
    conns = _lattice_edges(n)
    r = _per_item(throat_radius, conns.shape[0], "throat_radius", 0.5)
    _check_lattice_sizes(R, r, conns, spacing)
    end = np.any((grid == 0) | (grid == np.array(n) - 1), axis=1)  # spheres on the lattice's faces
    margin = _lattice_margin(R[end], margin)
    shape = tuple(2 * margin + spacing * (k - 1) + 1 for k in n)
    cvox = margin + spacing * grid
    phases = np.zeros(shape, np.uint8)
    for c, rp in zip(cvox, R, strict=True):
        _paint_sphere(phases, c, rp)
    for (a, b), rt in zip(conns, r, strict=True):
        _paint_cylinder(phases, cvox[a], cvox[b], rt)
    img = VoxelImage(phases, voxel_size)
    lt = spacing - np.sqrt(R[conns[:, 0]] ** 2 - r**2) - np.sqrt(R[conns[:, 1]] ** 2 - r**2)  # cylinder part
    return SyntheticLattice(
        image=img,
        pore_centres=img.voxel_centres(cvox),
        pore_centre_voxels=cvox,
        pore_radius=R * img.voxel_size,
        throat_conns=conns,
        throat_radius=r * img.voxel_size,
        throat_length=lt * img.voxel_size,
        porosity=float(np.count_nonzero(phases)) / phases.size,
    )


def _per_item(value, count: int, name: str, least: float) -> np.ndarray:
    """``value`` (one number or ``count`` numbers, voxels) as a float array, each finite and >= ``least``."""
    a = np.asarray(value, dtype=float)
    a = np.full(count, float(a)) if a.ndim == 0 else a.reshape(-1)
    if a.shape != (count,) or not np.all(np.isfinite(a)) or (count and a.min() < least):
        raise InputError(f"{name} must be >= {least:g} voxel, one value or {count} values; got {value!r}")
    return a


def _lattice_edges(n: tuple[int, int, int]) -> np.ndarray:
    """Nearest-neighbour pairs of an ``n`` lattice of spheres (C order ids), shape (n_t, 2), x then y then z."""
    ids = np.arange(int(np.prod(n))).reshape(n)
    edges = []
    for ax in range(3):
        sl_lo = [slice(None)] * 3
        sl_hi = [slice(None)] * 3
        sl_lo[ax] = slice(0, -1)
        sl_hi[ax] = slice(1, None)
        edges.append(np.stack([ids[tuple(sl_lo)].ravel(), ids[tuple(sl_hi)].ravel()], axis=1))
    return np.concatenate(edges).astype(np.int64)


def _check_lattice_sizes(R: np.ndarray, r: np.ndarray, conns: np.ndarray, spacing: int) -> None:
    """Throats narrower than both their spheres; neighbouring spheres that do not overlap."""
    if not conns.shape[0]:
        return
    if np.any(r >= np.minimum(R[conns[:, 0]], R[conns[:, 1]])):
        raise InputError("every throat_radius must be smaller than both of its sphere radii")
    if np.any(R[conns[:, 0]] + R[conns[:, 1]] >= spacing):
        raise InputError(
            f"spheres overlap: spacing {spacing} must exceed the sum of neighbouring radii "
            f"(largest {float((R[conns[:, 0]] + R[conns[:, 1]]).max()):g}); increase spacing"
        )


def _lattice_margin(r_end: np.ndarray, margin: int | None) -> int:
    """Voxels between the image faces and the centres of the end spheres (default: they cut the faces)."""
    if margin is None:
        margin = int(min(r_end.min(), np.ceil(0.7 * r_end.max())))
    margin = _positive_int("margin", margin)
    if np.any(r_end < margin):
        raise InputError(
            f"margin {margin} exceeds the radius of an end sphere ({r_end.min():g}): it would not "
            "touch the faces; lower margin"
        )
    return margin


def _box(shape, c, h):
    lo = np.maximum(np.floor(c - h).astype(int), 0)
    hi = np.minimum(np.ceil(c + h).astype(int) + 1, shape)
    return lo, hi


def _paint_sphere(phases, c, R):
    lo, hi = _box(np.array(phases.shape), np.asarray(c, float), R)
    x, y, z = np.ogrid[lo[0] : hi[0], lo[1] : hi[1], lo[2] : hi[2]]
    inside = (x - c[0]) ** 2 + (y - c[1]) ** 2 + (z - c[2]) ** 2 <= R * R
    phases[lo[0] : hi[0], lo[1] : hi[1], lo[2] : hi[2]] |= inside.astype(np.uint8)


def _paint_cylinder(phases, c0, c1, r):
    ax = int(np.flatnonzero(c1 != c0)[0])
    lo = np.minimum(c0, c1).astype(int)
    hi = np.maximum(c0, c1).astype(int)
    sl = []
    for a in range(3):
        if a == ax:
            sl.append(slice(lo[a], hi[a] + 1))
        else:
            sl.append(slice(max(int(np.floor(c0[a] - r)), 0), min(int(np.ceil(c0[a] + r)) + 1, phases.shape[a])))
    grids = np.ogrid[tuple(sl)]
    d2 = sum((grids[a] - c0[a]) ** 2 for a in range(3) if a != ax)
    phases[tuple(sl)] |= np.broadcast_to(d2 <= r * r, phases[tuple(sl)].shape).astype(np.uint8)


def _disc_pixels(r):
    h = int(np.floor(r))
    u, v = np.meshgrid(np.arange(-h - 1, h + 2), np.arange(-h - 1, h + 2), indexing="ij")
    return u, v, (u * u + v * v) <= r * r


def _tube_section(shape2: tuple[int, int], radii: np.ndarray, centres: np.ndarray):
    """Voxelised discs of ``radii`` at ``centres`` (pixels) in a ``shape2`` section.

    Returns the section (uint8, 1 = pore), each disc's pixel area and the radius of the largest
    disc about its centre inside the union of its pore pixels (the nearest solid pixel square).
    """
    section = np.zeros(shape2, np.uint8)
    area = np.empty(radii.size)
    r_in = np.empty(radii.size)
    for c, (rc, cc) in enumerate(zip(radii, centres, strict=True)):
        u, v, inside = _disc_pixels(rc)
        area[c] = inside.sum()
        du = np.maximum(np.abs(u) - 0.5, 0.0)
        dv = np.maximum(np.abs(v) - 0.5, 0.0)
        r_in[c] = np.sqrt(du**2 + dv**2)[~inside].min()
        section[u[inside] + cc[0], v[inside] + cc[1]] = 1
    return section, area, r_in


def cylinder_bundle(
    radii_vox: tuple[float, ...] | np.ndarray = (2.0, 3.0, 4.0),
    axis: str | int = "z",
    shape: tuple[int, int, int] | None = None,
    voxel_size: float = 1e-5,
    gap: int = 2,
    length: int = 32,
) -> SyntheticBundle:
    """Build a bundle of straight tubes crossing the box along ``axis``.

    Tubes are laid in a row along the first cross axis, ``gap`` solid voxels apart and from the
    box sides; the tube axes pass through voxel centres.

    Parameters
    ----------
    radii_vox : sequence of float, default (2, 3, 4)
        Tube radii, voxels (>= 0.5).
    axis : 'x', 'y', 'z' or 0, 1, 2, default 'z'
    shape : tuple of 3 int, optional
        Image shape; default: the smallest box holding the row, ``length`` long along ``axis``.
        A larger box adds solid around the row.
    voxel_size : float, default 1e-5
        m.
    gap : int, default 2
        Solid voxels between tubes and between a tube and a box side.
    length : int, default 32
        Voxels along ``axis`` when ``shape`` is not given.

    Returns
    -------
    SyntheticBundle
        With ``permeability_m2`` (nominal radii, Hagen–Poiseuille) and the voxelised bounds.

    References
    ----------
    G. Pólya and G. Szegő, Isoperimetric Inequalities in Mathematical Physics, Princeton (1951):
    Saint-Venant's inequality, flow rate (torsional rigidity) <= that of the equal-area disc.
    """
    ax = axis_index(axis)
    radii = np.asarray(radii_vox, dtype=float).reshape(-1)
    if radii.size == 0 or not np.all(np.isfinite(radii)) or radii.min() < 0.5:
        raise InputError(f"radii_vox must be >= 0.5 voxel each, got {radii_vox!r}")
    gap = _positive_int("gap", gap)
    widths = 2 * np.floor(radii).astype(int) + 1
    cross = [int(widths.sum() + gap * (radii.size + 1)), int(widths.max() + 2 * gap)]
    if shape is None:
        shp = [0, 0, 0]
        shp[ax] = _positive_int("length", length)
        others = [a for a in range(3) if a != ax]
        shp[others[0]], shp[others[1]] = cross
        shape = tuple(shp)
    shape = tuple(int(s) for s in shape)
    others = [a for a in range(3) if a != ax]
    if len(shape) != 3 or shape[others[0]] < cross[0] or shape[others[1]] < cross[1] or shape[ax] < 1:
        raise InputError(f"shape {shape!r} cannot hold the tubes; it needs a cross-section of at least {cross}")
    pos = gap + np.concatenate(([0], np.cumsum(widths + gap)[:-1])) + widths // 2
    centres = np.stack([pos, np.full(radii.size, gap + widths.max() // 2)], axis=1)
    section, area, r_in = _tube_section((shape[others[0]], shape[others[1]]), radii, centres)
    phases = np.moveaxis(np.repeat(section[:, :, None], shape[ax], axis=2), 2, ax)
    img = VoxelImage(np.ascontiguousarray(phases), voxel_size)
    vs = img.voxel_size
    a_box = shape[others[0]] * shape[others[1]] * vs * vs
    k_nom = float(np.sum(np.pi * (radii * vs) ** 4 / 8) / a_box)
    k_upper = float(np.sum((area * vs * vs) ** 2 / (8 * np.pi)) / a_box)
    k_lower = float(np.sum(np.pi * (r_in * vs) ** 4 / 8) / a_box)
    return SyntheticBundle(
        image=img,
        axis=ax,
        centres_vox=centres,
        radius=radii * vs,
        permeability_m2=k_nom,
        permeability_voxel_m2=k_upper,
        permeability_bounds_m2=(k_lower, k_upper),
        porosity=float(np.count_nonzero(phases)) / phases.size,
    )
