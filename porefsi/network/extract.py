"""Maximal-ball pore-network extraction from a segmented image (after Dong & Blunt 2009).

Pipeline (each stage a numba kernel gathered in :mod:`porefsi.network._kernels`):

1. squared Euclidean distance map of the pore space (uint16, int32 if a radius reaches 256
   voxels; separable lower-envelope EDT);
2. candidate balls at every pore voxel whose radius reaches the noise floor, minus those
   whose digital ball lies inside a neighbour's: the *maximal balls*;
3. master/slave hierarchy: balls visited largest first adopt the largest ball they overlap
   (if its family master is near enough or clearly larger), else become masters = pores; a
   ball centred in the core of a larger one joins it unscanned, so the work per voxel does not
   grow with the pore radius in voxels;
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

from porefsi._memory import available_memory, format_bytes
from porefsi.errors import InputError, NetworkError
from porefsi.image.voxel_image import VoxelImage
from porefsi.network import _kernels as kern
from porefsi.network._mb_conduits import (
    MIN_SEGMENT,
    conduit_lengths,
    digital_radius,
    face_sections,
    measure_sections,
    merge_shallow,
    subvoxel_radii,
)
from porefsi.network.floor import hydraulic_radius, largest_ball_cap, noise_floor, resolve_min_radius
from porefsi.network.network import CONDUCTANCE_MODELS, Network

__all__ = [
    "Extraction",
    "ExtractionInfo",
    "extract_network",
    "memory_needed",
    "check_memory",
    "digital_radius",
    "MIN_SEGMENT",
    "hydraulic_radius",
    "noise_floor",
]

#: Largest uint16 squared distance kept (module constant so a test can force the int32 path).
_DT2_CAP16 = int(kern.CAP16)

#: Half-width of the neighbourhood searched for a ball containing a candidate ball, voxels.
BALL_TEST_REACH = 1

#: Core of a visited ball, in its radius: a later ball centred inside it is skipped (joins that
#: ball's family without scanning its own ball), so the balls scanned are spaced about this many
#: radii apart along the medial axis and the hierarchy's work per voxel does not grow with the
#: pore radius in voxels (see ``_mb_balls._families``).
BALL_CORE = 0.35


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
    n_scanned_balls : int
        Maximal balls whose voxels the hierarchy scanned (the others lie in the core of a larger
        ball, see :data:`BALL_CORE`).
    n_pores, n_throats : int
    n_pore_voxels : int
        Pore voxels in the image.
    n_labelled_voxels : int
        Pore voxels assigned to a pore (the rest lie in clusters without any maximal ball).
    n_flooded_voxels : int
        Pore voxels labelled by the flood (all labelled voxels but the seeds).
    min_radius : float
        Noise floor used, voxels.
    min_radius_rule : {'auto', 'voxels'}
        How it was set: from the image (:func:`porefsi.network.floor.noise_floor`) or given in voxels.
    extent : float
        Family reach used, master radii.
    merge_ratio : float
        Size ratio used for joining and merging.
    """

    seconds: dict
    n_candidate_balls: int
    n_maximal_balls: int
    n_scanned_balls: int
    n_pores: int
    n_throats: int
    n_pore_voxels: int
    n_labelled_voxels: int
    n_flooded_voxels: int
    min_radius: float
    min_radius_rule: str
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


def memory_needed(shape, n_pore: int) -> int:
    """Bytes :func:`extract_network` allocates on top of the image, at its peak (an estimate).

    The distance map (2 bytes per voxel; 4 if a radius reaches 256 voxels, not known before it
    is computed) and the labels (4), plus per pore voxel 4 bytes (8 above 2^31 voxels) for the
    flood's level-sorted list, which bounds the maximal-ball lists of the hierarchy (3 indices
    per ball, balls about a quarter of the pore voxels or fewer, measured 0.2-0.25 on Berea at
    1x-3x). Everything else (throats, sections) scales with the pores, not the voxels.
    """
    n_vox = int(np.prod([int(s) for s in shape], dtype=object))
    index = 4 if n_vox < np.iinfo(np.int32).max else 8
    return n_vox * 6 + int(n_pore) * index


def check_memory(shape, n_pore: int) -> None:
    """Raise a one-line :class:`InputError` if :func:`memory_needed` exceeds the available memory.

    Also honours the address-space limit (``ulimit -v``). The CLI calls it before filtering the
    image (whose cluster flood needs about 3 bytes per voxel, less than the extraction).
    """
    need = memory_needed(shape, n_pore)
    avail = available_memory()
    if avail is not None and need > avail:
        raise InputError(
            f"extracting a {'x'.join(str(int(s)) for s in shape)} image needs about {format_bytes(need)} more memory "
            f"({need / float(np.prod(shape, dtype=object)):.2g} bytes per voxel) but {format_bytes(avail)} is "
            "available; extract crops of it "
            "(porefsi.image.ops.crop; there is no chunked extraction), coarsen it (porefsi.image.ops.downsample), "
            "or free memory"
        )


def _check(image, extent, merge_ratio):
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
    if not (np.isfinite(extent) and extent >= 1.0):
        raise InputError(f"extent must be >= 1 master radius, got {extent!r}; the default is 2")
    if not (np.isfinite(merge_ratio) and 0.0 < merge_ratio <= 1.0):
        raise InputError(f"merge_ratio must be in (0, 1], got {merge_ratio!r}; the default is 0.9")
    return n_pore


def extract_network(
    image: VoxelImage,
    *,
    min_radius: float | str = "auto",
    extent: float = 2.0,
    merge_ratio: float = 0.9,
    conductance: str | None = None,
) -> Extraction:
    """Extract a maximal-ball pore network from a segmented image.

    Parameters
    ----------
    image : VoxelImage
        Segmented image, 1 = pore.
    min_radius : 'auto' or float, default 'auto'
        Noise floor, voxels: only balls with ``sqrt(dt2) >= min_radius`` (distance to the nearest
        solid voxel centre) are candidates; smaller maxima are resolution noise, their voxels
        join neighbouring pores. ``'auto'`` (:func:`porefsi.network.floor.noise_floor`): a fixed
        fraction of the image's hydraulic radius, at least 2 voxels, so the same rock imaged
        finer gives the same pores. A number fixes the floor in voxels (2 was the default).
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
        Conduit model stored on the network (:attr:`Network.conductance`); ``None``: the default,
        ``'shape_factor'``. The measured shape factors and duct fractions are stored either way.

    Returns
    -------
    Extraction
        ``network`` (pores: the masters of the ball hierarchy; radii: :func:`digital_radius`;
        volumes: region voxel counts), ``labels`` and ``info``.

    Raises
    ------
    TypeError
        If ``image`` is not a VoxelImage.
    InputError
        All-solid or all-pore image, an axis shorter than 3 voxels, bad parameters, or more
        memory needed (:func:`memory_needed`) than is available (checked before allocating).
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
    return _extract([image], min_radius=min_radius, extent=extent, merge_ratio=merge_ratio, conductance=conductance)


def _extract(holder: list, *, min_radius, extent, merge_ratio, conductance) -> Extraction:
    """:func:`extract_network` of the image in ``holder`` (a one-item list, emptied).

    The image is released once the distance map is computed: a caller that hands over its only
    reference (the CLI) saves 1 byte per voxel at the peak.
    """
    image = holder.pop()
    extent, merge_ratio = float(extent), float(merge_ratio)
    n_pore = _check(image, extent, merge_ratio)
    rule = "auto" if isinstance(min_radius, str) else "voxels"
    min_radius = resolve_min_radius(min_radius, image)
    if conductance is not None and conductance not in CONDUCTANCE_MODELS:
        raise InputError(f"unknown conductance model {conductance!r}; use one of {CONDUCTANCE_MODELS}")
    check_memory(image.shape, n_pore)
    shape, vs, origin = image.shape, image.voxel_size, image.origin.copy()
    laps = _Laps()
    dt2 = _distance_map(image.phases)
    del image
    max_d2 = int(dt2.max())
    if rule == "auto":
        min_radius = largest_ball_cap(min_radius, max_d2)
    laps("edt")
    centre_idx, labels, counts = _pore_centres(dt2, max_d2, min_radius, extent, merge_ratio, laps)
    counts["flooded"] = _flood_regions(dt2, labels, centre_idx, n_pore)
    laps("flood")
    top = _pores_and_throats(shape, labels, dt2, centre_idx, merge_ratio, extent)
    laps("throats")
    if top.conns.shape[0] == 0:
        raise NetworkError(
            f"the image yields {top.n_pores} pore(s) and no throat: no two pore regions touch; use a larger "
            f"image, or lower extent={extent:g} (>= 1; CLI --extent): a shorter family reach splits long "
            "channels into chains of pores"
        )
    geo = _conduits(dt2, labels, top, conductance)
    laps("sections")
    del dt2
    net = _network(shape, vs, origin, top, geo, conductance)
    labels.setflags(write=False)
    laps("assemble")
    info = ExtractionInfo(
        seconds=laps.total(),
        n_candidate_balls=counts["candidates"],
        n_maximal_balls=counts["balls"],
        n_scanned_balls=counts["scanned"],
        n_pores=top.n_pores,
        n_throats=int(top.conns.shape[0]),
        n_pore_voxels=n_pore,
        n_labelled_voxels=int(top.count.sum()),
        n_flooded_voxels=counts["flooded"],
        min_radius=min_radius,
        min_radius_rule=rule,
        extent=extent,
        merge_ratio=merge_ratio,
    )
    sections = {
        "area": geo.sec["area"] * vs**2,
        "face_area": geo.sec["n_faces"] * vs**2,
        "wall_perimeter": geo.sec["n_wall"] * vs,
        "radius": geo.r_throat * vs,
        "side_length": geo.sec["d"] * vs,
        "side_throat_length": geo.sec["side_lt"] * vs,
    }
    return Extraction(network=net, labels=labels, info=info, sections=sections)


class _Laps:
    """Wall seconds of the extraction's stages: ``laps(name)`` closes the stage that ran since the last call."""

    def __init__(self):
        self.seconds: dict[str, float] = {}
        self._start = self._last = time.perf_counter()

    def __call__(self, stage: str) -> None:
        now = time.perf_counter()
        self.seconds[stage] = now - self._last
        self._last = now

    def total(self) -> dict[str, float]:
        """The stages and their ``total``, s."""
        self.seconds["total"] = time.perf_counter() - self._start
        return self.seconds


def _pore_centres(dt2, max_d2: int, min_radius: float, extent: float, merge_ratio: float, laps: _Laps):
    """Stages 2-3: the maximal balls and their master/slave families.

    Returns the flat indices of the master-ball centres (the pores, largest first), the label
    image (all -1, int32) and the candidate and maximal ball counts.
    """
    sqrt_tab = np.sqrt(np.arange(max_d2 + 1, dtype=np.float64))
    min_dt2 = max(1, math.ceil(min_radius * min_radius - 1e-9))
    labels = np.empty(dt2.shape, np.int32)
    kern._fill(labels, -1)
    offsets = kern.ball_offsets(BALL_TEST_REACH)
    off_class, reach2 = kern.ball_reach_table(offsets, max_d2)
    like = np.empty(0, np.int32 if dt2.size < np.iinfo(np.int32).max else np.int64)
    balls, n_cand = kern._maximal_balls(dt2, np.int64(min_dt2), offsets, off_class, reach2, labels, like)
    del reach2
    laps("maximal_balls")
    if balls.size == 0:
        raise NetworkError(
            f"no pore found: the largest ball radius in the image is {math.sqrt(max_d2):.3g} voxels, "
            f"below min_radius={min_radius:g}; lower min_radius (>= 1; CLI --min-radius) or use a finer image"
        )
    master, n_kept = kern._families(dt2, balls, sqrt_tab, extent, merge_ratio, labels, float(BALL_CORE))
    centre_idx = balls[master == np.arange(balls.size, dtype=np.int32)]
    laps("families")
    kern._fill(labels, -1)
    return centre_idx, labels, {"candidates": int(n_cand), "balls": int(balls.size), "scanned": int(n_kept)}


def _flood_regions(dt2, labels, centre_idx, n_pore: int) -> int:
    """Stage 4: the priority flood of the distance map from one seed voxel per pore; voxels flooded."""
    labels.reshape(-1)[centre_idx] = np.arange(centre_idx.size, dtype=np.int32)
    itype = np.int32 if dt2.size < np.iinfo(np.int32).max else np.int64
    buf = np.empty(n_pore - int(centre_idx.size), itype)
    return int(kern._flood(dt2, labels, buf, buf))  # the queue may share the level-sorted list


@dataclasses.dataclass(frozen=True, eq=False)
class _Topology:
    """Pores and throats after merging (voxel units): centres, digital radii, throat interfaces."""

    n_pores: int
    centre: np.ndarray  # (Np, 3) voxel coordinates of the pore centres
    r_pore: np.ndarray  # (Np,)
    conns: np.ndarray  # (Nt, 2)
    w: np.ndarray  # (Nt,) largest dt2 on each interface
    point: np.ndarray  # (Nt, 3) throat points
    count: np.ndarray  # (Np,) voxels of each pore region
    faces: np.ndarray  # pore_faces of the network


def _pores_and_throats(shape, labels, dt2, centre_idx, merge_ratio: float, extent: float) -> _Topology:
    """Stage 5: label interfaces as throats, pores with no real constriction between them merged."""
    n_p = int(centre_idx.size)
    conns, w, point, _ = kern._interfaces(labels, dt2, np.int64(n_p))
    r_pore = digital_radius(dt2.reshape(-1)[centre_idx])
    centre = np.stack(np.unravel_index(centre_idx, shape), axis=1).astype(float)
    keep, roots = merge_shallow(centre, r_pore, conns, digital_radius(np.maximum(w, 1)), merge_ratio, extent)
    if n_p - int(keep.max()) - 1:
        kern._relabel(labels, keep.astype(np.int32))
        r_pore, centre = r_pore[roots], centre[roots]
        n_p = int(roots.size)
        conns, w, point, _ = kern._interfaces(labels, dt2, np.int64(n_p))
    count, faces = kern._pore_stats(labels, np.int64(n_p))
    return _Topology(n_p, centre, r_pore, conns, w, point, count, faces)


@dataclasses.dataclass(frozen=True, eq=False)
class _Conduits:
    """Radii, conduit lengths and section measurements (voxel units)."""

    r_pore: np.ndarray
    r_throat: np.ndarray
    lt: np.ndarray
    lp: np.ndarray
    sec: dict


def _conduits(dt2, labels, top: _Topology, conductance) -> _Conduits:
    """Throat radii (sub-voxel unless the paper's model), conduit lengths and section shape factors."""
    r_pore, conns = top.r_pore, top.conns
    r_throat = np.minimum(digital_radius(np.maximum(top.w, 1)), np.minimum(r_pore[conns[:, 0]], r_pore[conns[:, 1]]))
    lt, lp = conduit_lengths(top.centre, r_pore, conns, r_throat, top.point)
    convention = "digital" if conductance == "paper" else "wall"
    point = top.point
    if convention == "wall":
        point, r_pore, r_throat = subvoxel_radii(dt2, labels, top.centre, conns)
    sec = measure_sections(labels, dt2, top.centre, point, conns, r_throat, r_pore, convention)
    sec["face"] = face_sections(labels, dt2, top.centre, r_pore, convention, sec["pore_G"])
    return _Conduits(r_pore, r_throat, lt, lp, sec)


def _network(shape, vs: float, origin, top: _Topology, geo: _Conduits, conductance) -> Network:
    """The :class:`Network` in SI units."""
    return Network(
        pore_coords=origin + (top.centre + 0.5) * vs,
        pore_radius=geo.r_pore * vs,
        pore_volume=top.count * vs**3,
        throat_conns=top.conns,
        throat_radius=geo.r_throat * vs,
        throat_length=geo.lt * vs,
        throat_pore_length=geo.lp * vs,
        pore_faces=top.faces,
        voxel_size=vs,
        shape=shape,
        origin=origin,
        throat_shape_factor=geo.sec["throat_G"],
        pore_shape_factor=geo.sec["pore_G"],
        throat_duct_fraction=geo.sec["fraction"],
        conductance=conductance,
        pore_face_radius=geo.sec["face"]["radius"] * vs,
        pore_face_shape_factor=geo.sec["face"]["G"],
        pore_face_duct_fraction=geo.sec["face"]["fraction"],
    )
