"""Maximal-ball extraction, stage 5 (private): pore merging, radii, conduit lengths, sections.

Helpers of :func:`porefsi.network.extract.extract_network`, in voxel units.
"""

from __future__ import annotations

import numpy as np

from porefsi.network._mb_section_law import section_law_lengths
from porefsi.network._mb_sections import (
    _constriction_lengths,
    _constriction_lengths_subvoxel,
    _sections,
    _stair_section_peaks,
    _subvoxel_peaks,
    _walled_points,
)
from porefsi.network.network import CIRCLE_SHAPE_FACTOR

__all__ = [
    "MIN_SEGMENT", "digital_radius", "wall_radius", "sampson_length", "merge_shallow", "conduit_lengths",
    "subvoxel_radii", "measure_sections", "face_sections",
]

#: Smallest segment length of a conduit, in voxels (keeps every Network length > 0).
MIN_SEGMENT = 0.05

#: Axes whose two box faces are no-slip walls for the measured geometry ("wall" convention): the
#: voxel reference's side walls. All three: one network for every flow axis (``docs/extraction.md``).
BOX_WALLS = (True, True, True)

#: Under the "wall" convention, read each constriction sample at its own position along the
#: pore-centre-to-throat line (``_constriction_lengths_subvoxel``) rather than at the nearest
#: channel voxel's centre (``docs/extraction.md``, "Constriction samples at sub-voxel positions").
SUBVOXEL_SAMPLES = False

#: Under the "wall" convention, integrate each side's resistance with the duct law of the local
#: section (inscribed radius and planar section area per sample, ``section_law_lengths``) rather
#: than ``1 / r^4`` of the radius alone (``docs/extraction.md``, "Constriction length with the
#: section's own law").
SECTION_LAW = True

#: Under the "wall" convention, add Sampson's end resistance of a constriction's mouths to its
#: constriction length (:func:`sampson_length`, ``docs/extraction.md``): half of ``3 pi r / 8`` per
#: mouth, where a throat side or a face cut narrows from its pore, and where a face cut opens into
#: the reservoir.
SAMPSON_END = True


def sampson_length(radius):
    r"""Duct length (same unit as ``radius``) whose Poiseuille resistance is Sampson's end resistance.

    A circular aperture of radius a in a thin wall has resistance :math:`3\mu / a^3` (Sampson
    1891); a tube of length L between two reservoirs :math:`8\mu L / (\pi a^4) + 3\mu / a^3` within
    1 % at every L / a (Dagan, Weinbaum & Pfeffer 1982): the two mouths add the Poiseuille length
    :math:`3\pi a / 8`, each mouth half of it. Returned: that of both mouths, ``3 pi r / 8``.
    """
    return 3.0 * np.pi * np.asarray(radius, dtype=float) / 8.0


def _walls(on: bool, open_axis: int = -1) -> np.ndarray:
    """The ``walls`` flags (int64 (3,)) of the section kernels: :data:`BOX_WALLS` (but ``open_axis``), or none."""
    w = np.array(BOX_WALLS if on else (False, False, False), dtype=np.int64)
    if open_axis >= 0:
        w[open_axis] = 0
    return w


def _sum_of_three_squares(n: np.ndarray) -> np.ndarray:
    """Legendre: n >= 0 is a sum of three squares unless n = 4^a (8b + 7)."""
    m = n.copy()
    nz = m > 0
    while True:
        div4 = nz & (m % 4 == 0)
        if not div4.any():
            break
        m[div4] //= 4
    return ~(nz & (m % 8 == 7))


def digital_radius(dt2: np.ndarray | int) -> np.ndarray:
    r"""Radius (voxels) of the ball whose centre has squared distance map value ``dt2``.

    ``dt2`` is the squared distance from a voxel centre to the nearest solid voxel centre.
    The solid boundary lies between that solid centre and the farthest pore centre that can
    exist closer than it, i.e. at a squared distance equal to the largest sum of three squares
    below ``dt2``. The radius is the midpoint of the two:

    .. math:: r = \tfrac12\left(\sqrt{d^2} + \sqrt{\max\{m < d^2 : m = a^2 + b^2 + c^2\}}\right)

    so a digitised ball or cylinder of integer radius R (voxel centres within R) is measured
    as R + O(1/R), and a one-voxel-wide channel as 0.5.

    Parameters
    ----------
    dt2 : array_like of int, >= 1

    Returns
    -------
    ndarray of float
        Radius in voxels.
    """
    d = np.asarray(dt2, dtype=np.int64)
    top = int(d.max(initial=1))
    n = np.arange(top + 1, dtype=np.int64)
    ok = _sum_of_three_squares(n)
    # largest representable m < n
    last = np.maximum.accumulate(np.where(ok, n, 0))
    prev = np.concatenate(([0], last[:-1]))
    return 0.5 * (np.sqrt(d) + np.sqrt(prev[d]))


def wall_radius(dt2: np.ndarray | int) -> np.ndarray:
    r"""Radius (voxels) of the measured geometry: from a voxel centre to the wall of the voxel staircase.

    ``sqrt(dt2) - 1/2``: the distance to the face of the nearest solid voxel when it lies along an
    axis, so exact for flat walls (a slit ``n`` voxels wide reads ``n/2`` at its middle). The image's
    voxel staircase is the geometry the converged voxel reference solves and the one a voxel
    refinement (each voxel -> f^3) keeps exactly; its walls are flat at every finer grid, so this
    convention reads the same radius in metres at every refinement, where :func:`digital_radius`
    (the midpoint to the nearest representable distance, which assumes curved walls) reads about
    0.4 voxel of whichever grid higher on the staircase (``docs/extraction.md``).

    Parameters
    ----------
    dt2 : array_like of int, >= 1

    Returns
    -------
    ndarray of float
        Radius in voxels, >= 0.5.
    """
    return np.sqrt(np.asarray(dt2, dtype=np.float64)) - 0.5


def _radius_table(dt2, convention: str = "digital") -> np.ndarray:
    """Radius of every value 0 .. max(dt2) (0 for solid) under ``convention``."""
    fn = wall_radius if convention == "wall" else digital_radius
    tab = fn(np.maximum(np.arange(int(dt2.max()) + 1), 1))
    tab[0] = 0.0
    return tab


def subvoxel_radii(dt2, labels, centre, conns):
    """Throat points and pore and throat radii (voxels) of the measured geometry: the voxel staircase's own.

    The box faces of the :data:`BOX_WALLS` axes are walls, as the voxel reference's no-slip side
    walls are (``docs/extraction.md``, "Box faces"). Throat point: the interface face of largest
    ``min(d2)`` on the distance map with those faces solid
    (:func:`porefsi.network._mb_sections._walled_points`). Throat radius:
    :func:`porefsi.network._mb_sections._stair_section_peaks` there, the largest distance to the
    staircase and the walled faces over points within half a voxel in the interface plane (the
    same in metres at every refinement of the image), clipped to both pore radii. Pore:
    :func:`porefsi.network._mb_sections._subvoxel_peaks` at its master ball's centre voxel (the
    distance to the nearest solid voxel cube plus the max-norm sub-voxel correction) on the open
    map: a master ball's centre often sits on the box face (the maximal balls see no wall there),
    so walling it would read ~half a voxel (measured: the r 9 pack's k falls to 0.17x).

    Returns
    -------
    point : ndarray of float64, shape (Nt, 3)
    r_pore : ndarray of float64, shape (Np,)
    r_throat : ndarray of float64, shape (Nt,)
    """
    tab = _radius_table(dt2, "wall")
    walls = _walls(True)
    c = np.rint(centre).astype(np.float64)
    r_pore = _subvoxel_peaks(dt2, tab, c)
    n_p = np.int64(r_pore.size)
    _, point = _walled_points(labels, dt2, conns, n_p, walls)
    rt = _stair_section_peaks(dt2, point, 0.5, 4, walls)
    rt = np.minimum(rt, np.minimum(r_pore[conns[:, 0]], r_pore[conns[:, 1]]))
    return point, r_pore, rt


def measure_sections(labels, dt2, centre, point, conns, r_throat, r_pore, convention="wall"):
    """Shape factors and duct fractions from the voxels (voxel units); see ``docs/extraction.md``.

    Throat: inscribed radius r (the throat radius), section area A = |vector area of the
    interface| (at least the inscribed circle's), ``G = r^2 / (4 A)`` (the shape factor of a
    polygon of that area with that inscribed circle, whose perimeter is ``2 A / r``). Pore: the
    throat-area-weighted mean of its throats' G (pnextract's rule), the circle's for a pore
    without throats. Duct lengths: each side's resistance-equivalent constriction length
    (:func:`porefsi.network._mb_sections._constriction_lengths`) makes the throat duct, the rest
    of the side the pore duct; each at least :data:`MIN_SEGMENT` voxels. ``convention`` ('wall'
    or 'digital', the paper's) is the radius table the constriction samples read; under 'wall'
    the :data:`BOX_WALLS` faces are walls for the samples and end wall edges of the sections, the
    side's integral takes the local section's duct law when :data:`SECTION_LAW` is set
    (:func:`porefsi.network._mb_section_law.section_law_lengths`), and each side narrowing from
    its pore gains half of :func:`sampson_length` (its mouth) when :data:`SAMPSON_END` is set.
    """
    n_p = r_pore.size
    area_vec, n_faces, n_wall = _sections(labels, conns, np.int64(n_p), _walls(convention == "wall"))
    area = np.maximum(np.linalg.norm(area_vec, axis=1), np.pi * r_throat**2)
    throat_G = np.minimum(r_throat**2 / (4.0 * area), CIRCLE_SHAPE_FACTOR)
    wsum = np.bincount(conns.ravel(), weights=np.repeat(area, 2), minlength=n_p)
    gsum = np.bincount(conns.ravel(), weights=np.repeat(area * throat_G, 2), minlength=n_p)
    pore_G = np.where(wsum > 0, gsum / np.where(wsum > 0, wsum, 1.0), CIRCLE_SHAPE_FACTOR)
    rad_tab = _radius_table(dt2, convention)
    if convention == "wall" and SECTION_LAW:
        d, side_lt = section_law_lengths(labels, dt2, rad_tab, (centre, point, conns),
                                         (r_throat, r_pore, throat_G, pore_G), _walls(True))
    else:
        d, side_lt = _lengths_kernel(convention)(dt2, rad_tab, centre, point, conns, r_throat, r_pore,
                                                 _walls(convention == "wall"))
    if convention == "wall" and SAMPSON_END:  # one mouth per side that narrows from its pore
        mouth = 0.5 * sampson_length(r_throat)[:, None]
        side_lt = np.where(r_pore[conns] > r_throat[:, None], np.minimum(side_lt + mouth, d), side_lt)
    ducts = np.column_stack([d[:, 0] - side_lt[:, 0], side_lt.sum(axis=1), d[:, 1] - side_lt[:, 1]])
    ducts = np.maximum(ducts, MIN_SEGMENT)
    return {
        "area": area, "n_faces": n_faces, "n_wall": n_wall, "throat_G": throat_G, "pore_G": pore_G,
        "d": d, "side_lt": side_lt, "fraction": ducts / ducts.sum(axis=1, keepdims=True),
    }


def _lengths_kernel(convention: str):
    """The constriction-length kernel of ``convention``.

    Samples read at their own position along the line under 'wall' when :data:`SUBVOXEL_SAMPLES`
    is set (``docs/extraction.md``), at the channel voxel's centre otherwise (the paper's model).
    """
    if convention == "wall" and SUBVOXEL_SAMPLES:
        return _constriction_lengths_subvoxel
    return _constriction_lengths


def _layer_walled(d2, shape, ax: int, walls) -> np.ndarray:
    """A face layer's ``dt2`` (2-D, normal ``ax``) with the walled in-plane box faces solid (as ``_d2``)."""
    out = d2.astype(np.int64)
    plane = [a for a in range(3) if a != ax]
    for k, a in enumerate(plane):
        if walls[a]:
            n = shape[a]
            i = np.arange(n)
            g = np.minimum(i + 1, n - i).astype(np.int64) ** 2
            out = np.minimum(out, g.reshape([-1, 1] if k == 0 else [1, -1]))
    return np.where(d2 == 0, 0, out)


def _face_cuts(labels, dt2, n_p: int, walls):
    """Per pore and face: voxels of its region in the face layer and the face point of its widest one.

    Returns ``count`` (Np, 6) int64 and ``point`` (Np, 6, 3) float64, the face point being the
    centre of the widest (largest ``dt2``, the in-plane ``walls`` faces solid; the first in C order
    on ties) layer voxel moved half a voxel outwards onto the box face.
    """
    count = np.zeros((n_p, 6), np.int64)
    point = np.zeros((n_p, 6, 3))
    for col in range(6):
        ax, hi = divmod(col, 2)
        layer = labels.shape[ax] - 1 if hi else 0
        lab = np.take(labels, layer, axis=ax).ravel()
        d2 = _layer_walled(np.take(dt2, layer, axis=ax), labels.shape, ax, walls).ravel()
        idx = np.flatnonzero(lab >= 0)
        count[:, col] = np.bincount(lab[idx], minlength=n_p)
        order = idx[np.lexsort((idx, -d2[idx].astype(np.int64), lab[idx]))]
        pores, first = np.unique(lab[order], return_index=True)
        best = order[first]
        plane_shape = [s for a, s in enumerate(labels.shape) if a != ax]
        uv = np.stack(np.unravel_index(best, plane_shape), axis=1).astype(float)
        pts = np.insert(uv, ax, layer + (0.5 if hi else -0.5), axis=1)
        point[pores, col] = pts
    return count, point


def face_sections(labels, dt2, centre, r_pore, convention="wall", pore_G=None):
    """The face cuts' inscribed radius, shape factor and duct fraction (Np, 6) each; 0 off the faces.

    For every pore region touching a box face: area ``A`` = its voxels in the face layer (voxel
    faces on the face), inscribed radius ``r`` = the largest distance to the voxel staircase
    within half a voxel of the face point in the face plane (:func:`_face_cuts`; the throat
    radius's estimator: the box faces of the other walled axes bound it and its samples under
    the "wall" convention, none under the paper's), at most the pore radius, ``A`` at least
    ``pi r^2``, ``G = r^2 / (4 A)`` (as for throats), and the share of the
    pore-centre-to-face-point line the constriction takes: the resistance-equivalent
    constriction length (:func:`porefsi.network._mb_sections._constriction_lengths`) over the
    line's length. Voxel units; ``convention`` as in :func:`measure_sections`. ``pore_G`` (Np,):
    the pores' shape factors, for the section-law constriction length (:data:`SECTION_LAW`). With
    :data:`SAMPSON_END` the constriction length gains half of :func:`sampson_length` for the mouth
    into the reservoir and, where the cut is narrower than the pore, half for the mouth from it.
    """
    n_p = r_pore.size
    walled = convention == "wall"
    count, point = _face_cuts(labels, dt2, n_p, _walls(walled))
    on = count > 0
    p_idx, col = np.nonzero(on)
    pts = point[p_idx, col]
    r = np.minimum(_stair_section_peaks(dt2, pts, 0.5, 4, _walls(walled)), r_pore[p_idx])
    area = np.maximum(count[p_idx, col].astype(float), np.pi * r**2)
    conns = np.column_stack([p_idx, p_idx]).astype(np.int64)
    tab = _radius_table(dt2, convention)
    d, lt = np.zeros((p_idx.size, 2)), np.zeros((p_idx.size, 2))
    G_f = np.minimum(r**2 / (4.0 * area), CIRCLE_SHAPE_FACTOR)
    law = walled and SECTION_LAW and pore_G is not None
    for ax in range(3):  # the face's own axis stays open: the reservoir is there
        m = col // 2 == ax
        if law:
            d[m], lt[m] = section_law_lengths(labels, dt2, tab, (centre, pts[m], conns[m]),
                                              (r[m], r_pore, G_f[m], pore_G), _walls(True, ax))
        else:
            d[m], lt[m] = _lengths_kernel(convention)(dt2, tab, centre, pts[m], conns[m], r[m], r_pore,
                                                      _walls(walled, ax))
    out = {k: np.zeros((n_p, 6)) for k in ("radius", "G", "fraction")}
    out["radius"][p_idx, col] = r
    out["G"][p_idx, col] = G_f
    if walled and SAMPSON_END:  # the mouth into the reservoir, and the one from the pore
        lt[:, 0] += 0.5 * sampson_length(r) * (1.0 + (r_pore[p_idx] > r))
    out["fraction"][p_idx, col] = np.clip(lt[:, 0] / np.maximum(d[:, 0], 1e-300), 0.0, 1.0)
    return out


def conduit_lengths(centre, r_pore, conns, r_throat, point):
    """Cylinder length (Nt,) and pore-side lengths (Nt, 2), voxels (see ``extract_network``)."""
    d = np.stack([np.linalg.norm(point - centre[conns[:, s]], axis=1) for s in (0, 1)], axis=1)  # (Nt, 2)
    rp = r_pore[conns]
    a = np.sqrt(np.maximum(rp * rp - r_throat[:, None] ** 2, 0.0))
    lp = np.maximum(np.minimum(d, a), MIN_SEGMENT)
    total = d.sum(axis=1)
    lt = total - lp.sum(axis=1)
    short = lt < MIN_SEGMENT
    if short.any():
        scale = (total[short] - MIN_SEGMENT) / lp[short].sum(axis=1)
        lp[short] *= scale[:, None]
        lt[short] = MIN_SEGMENT
    return lt, lp


def merge_shallow(centre, r_pore, conns, r_interface, merge_ratio, extent):
    """New pore ids (Np,) and surviving old ids after merging pores with no real constriction.

    A throat whose interface radius is at least ``merge_ratio`` times the smaller pore radius
    does not separate two bodies: the smaller pore is a bump on the larger one's flank (a
    saddle of the distance map barely below its maximum). Its region joins the larger pore when
    its centre lies within ``extent`` radii of that pore's centre or it is clearly smaller
    (``R_small < merge_ratio R_big``): the same rule as the ball hierarchy, so uniform channels
    stay chains. Throats are taken from the
    weakest constriction up; returns new ids ``0 .. Np' - 1`` numbered in the order of the
    surviving pores (so radius descending is kept).
    """
    n_p = r_pore.size
    parent = np.arange(n_p)

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    if conns.shape[0] and merge_ratio <= 1.0:
        ratio = r_interface / np.minimum(r_pore[conns[:, 0]], r_pore[conns[:, 1]])
        for t in np.argsort(-ratio, kind="stable"):
            if ratio[t] < merge_ratio:
                break
            a, b = find(conns[t, 0]), find(conns[t, 1])
            if a == b:
                continue
            big, small = (a, b) if (r_pore[a], -a) >= (r_pore[b], -b) else (b, a)
            near = np.sum((centre[big] - centre[small]) ** 2) < (extent * r_pore[big]) ** 2
            if near or r_pore[small] < merge_ratio * r_pore[big]:
                parent[small] = big
    top = np.array([find(a) for a in range(n_p)], dtype=np.int64)
    survivors = np.flatnonzero(top == np.arange(n_p))
    new_id = np.full(n_p, -1, np.int64)
    new_id[survivors] = np.arange(survivors.size)
    return new_id[top], survivors
