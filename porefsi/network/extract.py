"""Maximal-ball pore-network extraction from a segmented image (after Dong & Blunt 2009).

Pipeline (each stage a numba kernel gathered in :mod:`porefsi.network._kernels`):

1. squared Euclidean distance map of the pore space (uint16, int32 if a radius reaches 256
   voxels; separable lower-envelope EDT);
2. candidate balls at every pore voxel whose radius reaches the noise floor, minus those
   contained in a neighbour's ball: the *maximal balls*;
3. master/slave hierarchy: balls visited largest first adopt the largest ball they overlap
   (if its family master is near enough or clearly larger), else become masters = pores;
4. voxel labels: the master-ball centres seed a priority flood on the distance map, so
   regions are connected and meet at the narrowest sections;
5. throats are the interfaces between pore labels (pores separated by no real constriction
   are merged first); lengths from centre-to-throat distances.

See ``docs/extraction.md`` for every definition and the measured performance.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from porefsi.errors import InputError, NetworkError
from porefsi.image.voxel_image import VoxelImage
from porefsi.network import _kernels as kern
from porefsi.network._mb_sections import _constriction_lengths, _sections, _subvoxel_peaks
from porefsi.network.network import CIRCLE_SHAPE_FACTOR, CONDUCTANCE_MODELS, Network

__all__ = ["Extraction", "ExtractionInfo", "extract_network", "digital_radius"]

#: Smallest segment length of a conduit, in voxels (keeps every Network length > 0).
MIN_SEGMENT = 0.05

#: Largest uint16 squared distance kept (module constant so a test can force the int32 path).
_DT2_CAP16 = int(kern.CAP16)

#: Half-width of the neighbourhood searched for a ball containing a candidate ball, voxels.
BALL_TEST_REACH = 1


@dataclasses.dataclass(frozen=True)
class ExtractionInfo:
    """What the extraction did and how long each stage took.

    Attributes
    ----------
    seconds : dict of str to float
        Wall time per stage (``edt``, ``maximal_balls``, ``families``, ``flood``, ``throats``,
        ``assemble``) and ``total``, s.
    n_candidate_balls : int
        Pore voxels whose ball radius reaches ``min_radius``.
    n_maximal_balls : int
        Candidate balls not contained in a neighbour's ball.
    n_pores, n_throats : int
    n_pore_voxels : int
        Pore voxels in the image.
    n_labelled_voxels : int
        Pore voxels assigned to a pore (the rest lie in clusters without any maximal ball).
    n_flooded_voxels : int
        Pore voxels labelled by the flood (all labelled voxels but the seeds).
    min_radius : float
        Noise floor used, voxels.
    extent : float
        Family reach used, master radii.
    merge_ratio : float
        Size ratio used for joining and merging.
    """

    seconds: dict
    n_candidate_balls: int
    n_maximal_balls: int
    n_pores: int
    n_throats: int
    n_pore_voxels: int
    n_labelled_voxels: int
    n_flooded_voxels: int
    min_radius: float
    extent: float
    merge_ratio: float


@dataclasses.dataclass(frozen=True, eq=False)
class Extraction:
    """Result of :func:`extract_network`.

    Attributes
    ----------
    network : Network
        Pores (maximal-ball masters) and throats (label interfaces), SI units.
    labels : ndarray of int32, shape (nx, ny, nz)
        Index of the pore owning each pore voxel; -1 for solid and for pore voxels in clusters
        that hold no maximal ball (see ``info.n_labelled_voxels``). Read-only.
    info : ExtractionInfo
    sections : dict of str to ndarray
        Per-throat measurements behind the shape factors (SI units, shape (Nt,) unless noted):
        ``area`` (length of the interface's vector area, m²), ``face_area`` (number of interface
        voxel faces times the voxel face area, m²), ``wall_perimeter`` (interface edges on the
        wall times the voxel size, a staircase length, m), ``radius`` (inscribed radius, m),
        ``side_length`` (Nt, 2) (pore centre to throat point, m) and ``side_throat_length``
        (Nt, 2) (resistance-equivalent constriction length of each side, m).
    """

    network: Network
    labels: np.ndarray
    info: ExtractionInfo
    sections: dict | None = None

    @property
    def porosity(self) -> float:
        """Fraction of the image volume owned by pores (labelled voxels / all voxels)."""
        return self.info.n_labelled_voxels / float(self.labels.size)

    def __repr__(self) -> str:
        return f"Extraction({self.network!r}, porosity={self.porosity:.4f})"


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


def _distance_map(pore: np.ndarray) -> np.ndarray:
    """Squared distance map, uint16 when every value fits (radii < 256 voxels), else int32.

    uint16 halves the largest array of the extraction (2 instead of 4 bytes per voxel); an
    image with a value at the cap is recomputed in int32, so results never depend on the type.
    """
    dt2 = np.empty(pore.shape, np.uint16)
    kern._sq_edt(pore, dt2, int(_DT2_CAP16))
    if int(dt2.max()) < _DT2_CAP16:
        return dt2
    del dt2
    dt2 = np.empty(pore.shape, np.int32)
    kern._sq_edt(pore, dt2, int(kern.INF))
    return dt2


def _check(image, min_radius, extent, merge_ratio):
    if not isinstance(image, VoxelImage):
        raise TypeError(f"extract_network needs a porefsi VoxelImage, got {type(image).__name__}")
    if min(image.shape) < 3:
        raise InputError(
            f"image shape {image.shape} is too small to hold a pore network; "
            "use an image at least 3 voxels along every axis"
        )
    n_pore = int(np.count_nonzero(image.phases))
    if n_pore == 0:
        raise InputError(
            "image has no pore voxels (porosity 0); porefsi reads 1 as pore: invert the image if its pore space is 0"
        )
    if n_pore == image.phases.size:
        raise InputError(
            "image has no solid voxels (porosity 1): the distance map and the maximal balls are "
            "undefined; crop to a region containing rock"
        )
    if not (np.isfinite(min_radius) and min_radius >= 1.0):
        raise InputError(f"min_radius must be >= 1 voxel, got {min_radius!r}; the default is 2")
    if not (np.isfinite(extent) and extent >= 1.0):
        raise InputError(f"extent must be >= 1 master radius, got {extent!r}; the default is 2")
    if not (np.isfinite(merge_ratio) and 0.0 < merge_ratio <= 1.0):
        raise InputError(f"merge_ratio must be in (0, 1], got {merge_ratio!r}; the default is 0.9")
    return n_pore


def extract_network(
    image: VoxelImage, *, min_radius: float = 2.0, extent: float = 2.0, merge_ratio: float = 0.9,
    conductance: str | None = None,
) -> Extraction:
    """Extract a maximal-ball pore network from a segmented image.

    Parameters
    ----------
    image : VoxelImage
        Segmented image, 1 = pore.
    min_radius : float, default 2.0
        Noise floor, voxels: only balls with ``sqrt(dt2) >= min_radius`` are candidates (the
        distance to the nearest solid voxel centre; 1 keeps every pore voxel). A pore must hold
        a ball of this radius: smaller maxima of the distance map are resolution noise (a
        one-voxel error on a radius-1 ball is 100 %). Their voxels join neighbouring pores.
    extent : float, default 2.0
        Family reach, in master radii: a ball of about the master's size joins the master's pore
        only if its centre lies within ``extent`` master radii of the master's centre, else it
        starts a new pore. This splits long uniform channels into chains of pores about
        ``extent`` radii apart instead of one pore spanning the sample; >= 1.
    merge_ratio : float, default 0.9
        A ball smaller than ``merge_ratio`` times a master's radius joins that master's pore at
        any distance (channels and crevices belong to the body they open into), and two pores
        whose throat radius is at least ``merge_ratio`` times the smaller pore radius are
        merged (no real constriction separates them); in (0, 1].
    conductance : {'paper', 'shape_factor'} or None
        Conduit model stored on the network (:attr:`Network.conductance`); ``None`` leaves the
        default (``'shape_factor'``, since the extraction measures the sections). The measured
        shape factors and duct fractions are stored either way.

    Returns
    -------
    Extraction
        ``network`` (pores are the masters of the ball hierarchy; radii are the digital inscribed
        radii of :func:`digital_radius`; volumes are region voxel counts), ``labels`` and
        ``info``.

    Raises
    ------
    TypeError
        If ``image`` is not a VoxelImage.
    InputError
        All-solid or all-pore image, an axis shorter than 3 voxels, or bad parameters.
    NetworkError
        No ball reaches ``min_radius`` (no pore found), or no two pore regions touch (no throat).

    Notes
    -----
    Voxel labels come from a priority flood of the distance map seeded at the pore centres
    (a marker watershed whose markers are the maximal-ball pores): every region is connected,
    contains its centre, and meets its neighbours at the narrowest section between them. Pore
    clusters holding no pore stay -1 and are not counted in :attr:`Extraction.porosity`.

    Conduit lengths: with ``d_i`` the distance from pore ``i``'s centre to the throat point (the
    interface face of largest inscribed radius) and ``a_i = sqrt(R_i^2 - r_t^2)`` the distance
    over which pore ``i``'s sphere narrows to the throat radius, the pore-side length is
    ``min(d_i, a_i)`` and the cylinder takes the rest of ``d_i + d_j``; when the cylinder would
    be shorter than :data:`MIN_SEGMENT` voxels the pore parts are scaled down so the three
    segments still add up to ``d_i + d_j``.

    References
    ----------
    H. Dong and M. J. Blunt, Pore-network extraction from micro-computerized-tomography images,
    Phys. Rev. E 80, 036307 (2009).
    P. F. Felzenszwalb and D. P. Huttenlocher, Distance transforms of sampled functions,
    Theory of Computing 8, 415-428 (2012).

    Examples
    --------
    >>> from porefsi.image.synthetic import sphere_lattice
    >>> lat = sphere_lattice(n=(2, 2, 2))
    >>> ext = extract_network(lat.image)
    >>> ext.network.n_pores, ext.network.n_throats
    (8, 12)
    """
    min_radius = float(min_radius)
    extent = float(extent)
    merge_ratio = float(merge_ratio)
    n_pore = _check(image, min_radius, extent, merge_ratio)
    if conductance is not None and conductance not in CONDUCTANCE_MODELS:
        raise InputError(f"unknown conductance model {conductance!r}; use one of {CONDUCTANCE_MODELS}")
    pore = image.phases
    secs: dict[str, float] = {}
    t_all = t0 = time.perf_counter()

    dt2 = _distance_map(pore)
    secs["edt"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    max_d2 = int(dt2.max())
    sqrt_tab = np.sqrt(np.arange(max_d2 + 1, dtype=np.float64))
    min_dt2 = max(1, math.ceil(min_radius * min_radius - 1e-9))
    labels = np.full(image.shape, -1, np.int32)
    balls, n_cand = kern._maximal_balls(dt2, np.int64(min_dt2), sqrt_tab, kern.ball_offsets(BALL_TEST_REACH), labels)
    secs["maximal_balls"] = time.perf_counter() - t0
    if balls.size == 0:
        raise NetworkError(
            f"no pore found: the largest ball radius in the image is {math.sqrt(max_d2):.3g} voxels, "
            f"below min_radius={min_radius:g}; lower min_radius (>= 1; CLI --min-radius) or use a finer image"
        )

    t0 = time.perf_counter()
    master = kern._families(dt2, balls, sqrt_tab, extent, merge_ratio, labels)
    n_balls = int(balls.size)
    centre_idx = balls[master == np.arange(balls.size, dtype=np.int32)]
    del master, balls
    secs["families"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    labels.fill(-1)
    labels.reshape(-1)[centre_idx] = np.arange(centre_idx.size, dtype=np.int32)  # one seed voxel each
    n_seed = int(centre_idx.size)
    itype = np.int32 if pore.size < np.iinfo(np.int32).max else np.int64
    n_work = n_pore - n_seed
    n_flooded = int(kern._flood(dt2, labels, np.empty(n_work, itype), np.empty(n_work, itype)))
    secs["flood"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    n_p = int(centre_idx.size)
    conns, w, point, _ = kern._interfaces(labels, dt2, np.int64(n_p))
    r_pore = digital_radius(dt2.reshape(-1)[centre_idx])
    centre = np.stack(np.unravel_index(centre_idx, image.shape), axis=1).astype(float)
    keep, roots = _merge_shallow(centre, r_pore, conns, digital_radius(np.maximum(w, 1)), merge_ratio, extent)
    n_merged = n_p - int(keep.max()) - 1
    if n_merged:
        kern._relabel(labels, keep.astype(np.int32))
        centre_idx, r_pore, centre = centre_idx[roots], r_pore[roots], centre[roots]
        n_p = int(roots.size)
        conns, w, point, _ = kern._interfaces(labels, dt2, np.int64(n_p))
    count, faces = kern._pore_stats(labels, np.int64(n_p))
    secs["throats"] = time.perf_counter() - t0

    if conns.shape[0] == 0:
        raise NetworkError(
            f"the image yields {n_p} pore(s) and no throat: no two pore regions touch; use a larger "
            f"image, or lower extent={extent:g} (>= 1; CLI --extent): a shorter family reach splits long "
            "channels into chains of pores"
        )
    t0 = time.perf_counter()
    r_throat = np.minimum(digital_radius(np.maximum(w, 1)), np.minimum(r_pore[conns[:, 0]], r_pore[conns[:, 1]]))
    lt, lp = _conduit_lengths(centre, r_pore, conns, r_throat, point)
    if conductance != "paper":
        r_pore, r_throat = _subvoxel_radii(dt2, centre, point, conns, r_pore, r_throat)
    sec = _measure_sections(labels, dt2, centre, point, conns, r_throat, r_pore)
    secs["sections"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    del dt2
    vs = image.voxel_size
    net = Network(
        pore_coords=image.origin + (centre + 0.5) * vs,
        pore_radius=r_pore * vs,
        pore_volume=count * vs**3,
        throat_conns=conns,
        throat_radius=r_throat * vs,
        throat_length=lt * vs,
        throat_pore_length=lp * vs,
        pore_faces=faces,
        voxel_size=vs,
        shape=image.shape,
        origin=image.origin,
        throat_shape_factor=sec["throat_G"],
        pore_shape_factor=sec["pore_G"],
        throat_duct_fraction=sec["fraction"],
        conductance=conductance,
    )
    labels.setflags(write=False)
    secs["assemble"] = time.perf_counter() - t0
    secs["total"] = time.perf_counter() - t_all
    info = ExtractionInfo(
        seconds=secs,
        n_candidate_balls=int(n_cand),
        n_maximal_balls=n_balls,
        n_pores=n_p,
        n_throats=int(conns.shape[0]),
        n_pore_voxels=n_pore,
        n_labelled_voxels=int(count.sum()),
        n_flooded_voxels=n_flooded,
        min_radius=min_radius,
        extent=extent,
        merge_ratio=merge_ratio,
    )
    sections = {
        "area": sec["area"] * vs**2,
        "face_area": sec["n_faces"] * vs**2,
        "wall_perimeter": sec["n_wall"] * vs,
        "radius": r_throat * vs,
        "side_length": sec["d"] * vs,
        "side_throat_length": sec["side_lt"] * vs,
    }
    return Extraction(network=net, labels=labels, info=info, sections=sections)


def _radius_table(dt2) -> np.ndarray:
    """:func:`digital_radius` of every value 0 .. max(dt2) (0 for solid)."""
    tab = digital_radius(np.maximum(np.arange(int(dt2.max()) + 1), 1))
    tab[0] = 0.0
    return tab


def _subvoxel_radii(dt2, centre, point, conns, r_pore, r_throat):
    """Pore and throat radii (voxels), throats corrected for the sub-voxel offset of their centres.

    :func:`porefsi.network._mb_sections._subvoxel_peaks` at the throat points (in the interface
    plane), never below the digital radius, then clipped to both pore radii. Pore radii stay
    digital (they also order the pores, largest ball first; their relative error is smaller).
    On voxelised tubes at random offsets the digital radius reads 0.17-0.33 voxel low on average
    (radii 1.5-6), the corrected one -0.28..+0.41 (mean +0.06); see ``docs/extraction.md``.
    """
    tab = _radius_table(dt2)
    rt = np.maximum(_subvoxel_peaks(dt2, tab, point, 1), r_throat)
    rt = np.minimum(rt, np.minimum(r_pore[conns[:, 0]], r_pore[conns[:, 1]]))
    return r_pore, rt


def _measure_sections(labels, dt2, centre, point, conns, r_throat, r_pore):
    """Shape factors and duct fractions from the voxels (voxel units); see ``docs/extraction.md``.

    Throat: inscribed radius r (the throat radius), section area A = |vector area of the
    interface| (at least the inscribed circle's), ``G = r^2 / (4 A)`` (the shape factor of a
    polygon of that area with that inscribed circle, whose perimeter is ``2 A / r``). Pore: the
    throat-area-weighted mean of its throats' G (pnextract's rule), the circle's for a pore
    without throats. Duct lengths: each side's resistance-equivalent constriction length
    (:func:`porefsi.network._mb_sections._constriction_lengths`) makes the throat duct, the rest
    of the side the pore duct; each at least :data:`MIN_SEGMENT` voxels.
    """
    n_p = r_pore.size
    area_vec, n_faces, n_wall = _sections(labels, conns, np.int64(n_p))
    area = np.maximum(np.linalg.norm(area_vec, axis=1), np.pi * r_throat**2)
    throat_G = np.minimum(r_throat**2 / (4.0 * area), CIRCLE_SHAPE_FACTOR)
    wsum = np.bincount(conns.ravel(), weights=np.repeat(area, 2), minlength=n_p)
    gsum = np.bincount(conns.ravel(), weights=np.repeat(area * throat_G, 2), minlength=n_p)
    pore_G = np.where(wsum > 0, gsum / np.where(wsum > 0, wsum, 1.0), CIRCLE_SHAPE_FACTOR)
    rad_tab = _radius_table(dt2)
    d, side_lt = _constriction_lengths(dt2, rad_tab, centre, point, conns, r_throat, r_pore, 0.25)
    ducts = np.column_stack([d[:, 0] - side_lt[:, 0], side_lt.sum(axis=1), d[:, 1] - side_lt[:, 1]])
    ducts = np.maximum(ducts, MIN_SEGMENT)
    return {
        "area": area, "n_faces": n_faces, "n_wall": n_wall, "throat_G": throat_G, "pore_G": pore_G,
        "d": d, "side_lt": side_lt, "fraction": ducts / ducts.sum(axis=1, keepdims=True),
    }


def _conduit_lengths(centre, r_pore, conns, r_throat, point):
    """Cylinder length (Nt,) and pore-side lengths (Nt, 2), voxels; see :func:`extract_network`."""
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


def _merge_shallow(centre, r_pore, conns, r_interface, merge_ratio, extent):
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
