"""Constriction samples with the local section's own duct law (private kernels of the extraction).

Integer voxel coordinates as in :mod:`porefsi.network._mb_sections`. Each sample along a
pore-centre-to-throat side reads the channel's inscribed radius (the ridge estimate of
:func:`porefsi.network._mb_sections._ridge_radius`, as the default samples do) *and* the area of
the channel's planar section normal to the side (:func:`_plane_area`), so the side's resistance
integral can use the conductance law of the ducts it is replaced by (``k G A^2``) instead of
``1 / r^4``. Twin: ``tests/reference/section_law_ref.py``.
"""

from __future__ import annotations

import math

import numpy as np

from porefsi._numba import jit, prange
from porefsi.network._mb_edt import _d2
from porefsi.network._mb_sections import SAMPLE_STEP, _nearest, _perp_basis, _ridge_radius
from porefsi.network.geometry import duct_conductance_factor
from porefsi.network.network import CIRCLE_SHAPE_FACTOR


@jit
def _grid_voxel(x, e1, e2, s, t, dims):
    """Voxel (i, j, k) nearest to the plane-grid point ``x + s e1 + t e2``; (-1, -1, -1) off the image."""
    i = int(math.floor(x[0] + s * e1[0] + t * e2[0] + 0.5))
    j = int(math.floor(x[1] + s * e1[1] + t * e2[1] + 0.5))
    k = int(math.floor(x[2] + s * e1[2] + t * e2[2] + 0.5))
    if i < 0 or i >= dims[0] or j < 0 or j >= dims[1] or k < 0 or k >= dims[2]:
        return -1, -1, -1
    return i, j, k


@jit
def _in_channel(dt2, labels, box, i, j, k, la, lb):
    """Voxel (i, j, k) is pore on the walled map and belongs to pore ``la`` or ``lb``."""
    if i < 0:
        return False
    if _d2(dt2, i, j, k, box) == 0:
        return False
    lab = labels[i, j, k]
    return lab == la or lab == lb


@jit
def _plane_area(dt2, labels, box, x, plane, seed, limits, work):
    """Area (voxel faces) of the channel's section through x in the plane spanned by ``plane``.

    The plane is sampled on the unit grid ``x + s e1 + t e2`` (integers s, t; each point stands for
    one voxel face of the plane), each point read at its nearest voxel. ``seed`` = (s0, t0, la, lb):
    from the grid point (s0, t0), the 4-connected set of points whose voxel is pore (walled map,
    ``box``) and belongs to pore ``la`` or ``lb`` is counted, up to ``cap`` points (the count
    then returns ``cap``); ``limits`` = (cap, stamp). ``work`` = (seen, stack): ``seen``
    (:func:`_flood_scratch`, int32 (W + 2) * 256, grid point (s, t) at ``(s + h + 1) * 256 + t + h
    + 1``, ``h = W // 2``, W odd and at most 253) holds the stamp of the flood that last visited
    each point, and its border (one point around the grid) holds the largest int32, so a point is
    new to this flood when its entry is below ``stamp`` (every flood sharing the scratch takes a
    larger stamp: no reset, no bounds test per point); ``stack`` int32 (W * W,). Points beyond the
    grid are not visited. The inner loop reads the voxel inline (no calls per point) and moves
    between keys by adding 1 or 256 (no divisions).
    """
    seen, stack = work
    cap, stamp = limits
    h = ((seen.size >> 8) - 2) >> 1
    nx, ny, nz = dt2.shape
    e1, e2 = plane
    s0, t0, la, lb = seed
    i, j, k = _grid_voxel(x, e1, e2, s0, t0, dt2.shape)
    if abs(s0) > h or abs(t0) > h or not _in_channel(dt2, labels, box, i, j, k, la, lb):
        return 0
    stack[0] = ((s0 + h + 1) << 8) | (t0 + h + 1)
    seen[stack[0]] = stamp
    n_stack, count = 1, 0
    while n_stack > 0 and count < cap:
        n_stack -= 1
        key = stack[n_stack]
        count += 1
        for q in range(4):
            nkey = key + (256 if q == 0 else (-256 if q == 1 else (1 if q == 2 else -1)))
            if seen[nkey] >= stamp:
                continue
            seen[nkey] = stamp
            u, v = (nkey >> 8) - h - 1, (nkey & 255) - h - 1
            i = int(math.floor(x[0] + u * e1[0] + v * e2[0] + 0.5))
            j = int(math.floor(x[1] + u * e1[1] + v * e2[1] + 0.5))
            k = int(math.floor(x[2] + u * e1[2] + v * e2[2] + 0.5))
            if i < 0 or i >= nx or j < 0 or j >= ny or k < 0 or k >= nz or dt2[i, j, k] == 0:
                continue
            # the walled map is 0 only where dt2 is (its box terms are >= 1)
            lab = labels[i, j, k]
            if lab == la or lab == lb:
                stack[n_stack] = nkey
                n_stack += 1
    return count


@jit
def _flood_scratch(half):
    """Scratch of :func:`_plane_area` for the grid ``|s|, |t| <= half``: (seen, stack), seen's border set."""
    w = 2 * half + 1
    seen = np.zeros((w + 2) * 256, np.int32)
    big = np.iinfo(np.int32).max
    for a in range(w + 2):
        seen[a << 8] = seen[(a << 8) | (w + 1)] = big
        seen[a] = seen[((w + 1) << 8) | a] = big
    return seen, np.zeros(w * w, np.int32)


@jit
def _radius_seed(dt2, rad_tab, x, u, plane, box):
    """The sample's radius, its flood's seed offset (s0, t0) and whether it is in the channel, in one disc scan.

    One pass over the disc ``s^2 + t^2 <= rho^2`` of the ball inscribed at x (``rho`` at x's
    nearest voxel, walled map ``box``) keeps two maxima of the walled map: that of
    :func:`porefsi.network._mb_sections._section_radius` (points read at their nearest voxel
    clipped to the image, the voxel nearest to x winning ties, then the first met), whose ridge
    estimate (:func:`porefsi.network._mb_sections._ridge_radius`) is the radius, and the flood's
    seed (points off the image skipped, the first met winning ties). Returns (r, s0, t0, 1), or
    (0, 0, 0, 0) when x's voxel is solid.
    """
    e1, e2 = plane
    nx, ny, nz = dt2.shape
    a, b, c = _nearest(x[0], nx), _nearest(x[1], ny), _nearest(x[2], nz)
    best = _d2(dt2, a, b, c, box)
    rho = rad_tab[best]
    if rho == 0.0:
        return 0.0, 0, 0, 0
    ba, bb, bc = a, b, c
    wide, bs, bt = np.int64(-1), 0, 0
    h = int(rho)
    for s in range(-h, h + 1):
        for t in range(-h, h + 1):
            if s * s + t * t > rho * rho:
                continue
            fi = int(math.floor(x[0] + s * e1[0] + t * e2[0] + 0.5))
            fj = int(math.floor(x[1] + s * e1[1] + t * e2[1] + 0.5))
            fk = int(math.floor(x[2] + s * e1[2] + t * e2[2] + 0.5))
            i, j, k = min(max(fi, 0), nx - 1), min(max(fj, 0), ny - 1), min(max(fk, 0), nz - 1)
            v = _d2(dt2, i, j, k, box)
            if v > best:
                best, ba, bb, bc = v, i, j, k
            if v > wide and i == fi and j == fj and k == fk:
                wide, bs, bt = v, s, t
    return _ridge_radius(dt2, rad_tab, ba, bb, bc, u, box), bs, bt, 1


@jit
def _sample_point(c, pt, j, m):
    """Sample ``j`` of ``m`` on the side from c to pt: its point, the side's unit direction and normal plane."""
    dx, dy, dz = pt[0] - c[0], pt[1] - c[1], pt[2] - c[2]
    d = math.sqrt(dx * dx + dy * dy + dz * dz)
    u = (dx / d, dy / d, dz / d)
    f = (j + 0.5) / m
    return (c[0] + f * dx, c[1] + f * dy, c[2] + f * dz), u, _perp_basis(u[0], u[1], u[2])


@jit(parallel=True)
def _law_radii(dt2, rad_tab, geom, offsets, box):
    """Inscribed radius and the plane flood's seed at every constriction sample of every throat side.

    Side ``q = 2 t + s`` of throat ``t`` runs from the centre of pore ``conns[t, s]`` to the throat
    point; it is sampled at the midpoints of ``offsets[q + 1] - offsets[q]`` equal parts (as
    :func:`porefsi.network._mb_sections._lengths`, zero parts for a side not integrated). Each
    sample reads the radius of :func:`porefsi.network._mb_sections._section_radius` (the ridge
    estimate of the widest channel voxel within the ball inscribed at the sample, in the plane
    normal to the side) and the grid offset of the widest voxel on the image in that disc, where
    :func:`_law_areas` starts the sample's plane flood, both in one scan (:func:`_radius_seed`).
    Sides run on numba's threads (``prange``); each sample is computed alone, so the result does
    not depend on the number of threads.

    Parameters
    ----------
    geom : tuple (centre (Np, 3) float64, point (Nt, 3) float64, conns (Nt, 2) int64)
    offsets : ndarray of int64, shape (2 Nt + 1,)
    box : ndarray of int64, shape (3,)
        Walled axes (:func:`porefsi.network._mb_edt._d2`).

    Returns
    -------
    r : ndarray of float64, shape (offsets[-1],)
        Voxels.
    seed : ndarray of int32, shape (offsets[-1], 3)
        Grid offsets (s0, t0) and 1 where the sample is in the channel (0: no flood, area 0).
    """
    centre, point, conns = geom
    n_s = offsets[-1]
    r_out = np.zeros(n_s, np.float64)
    seed = np.zeros((n_s, 3), np.int32)
    for q in prange(offsets.size - 1):
        m = offsets[q + 1] - offsets[q]
        for j in range(m):
            x, u, plane = _sample_point(centre[conns[q // 2, q % 2]], point[q // 2], j, m)
            i = offsets[q] + j
            r_out[i], seed[i, 0], seed[i, 1], seed[i, 2] = _radius_seed(dt2, rad_tab, x, u, plane, box)
    return r_out, seed


@jit(parallel=True)
def _law_areas(dt2, labels, geom, offsets, seed, caps, box):
    """Area of the channel's section at every constriction sample (:func:`_law_radii`'s samples).

    The plane flood of :func:`_plane_area` from the sample's ``seed``, restricted to the throat's
    two pores, at most ``caps[i]`` voxel faces for sample ``i`` (shape (offsets[-1],) int64); 0
    where ``seed[i, 2]`` is 0. Blocks of :data:`BLOCK` throats run on numba's threads, each with
    its own scratch (:func:`_flood_scratch`; its floods take stamps 1, 2, ...), so the result does
    not depend on the number of threads. Returns ndarray of float64, shape (offsets[-1],), voxel faces.
    """
    centre, point, conns = geom
    a_out = np.zeros(offsets[-1], np.float64)
    n_t = conns.shape[0]
    for blk in prange((n_t + BLOCK - 1) // BLOCK):
        work = _flood_scratch(64)
        stamp = 0
        for q in range(2 * blk * BLOCK, min(2 * n_t, 2 * (blk + 1) * BLOCK)):
            m = offsets[q + 1] - offsets[q]
            pair = (conns[q // 2, 0], conns[q // 2, 1])
            for j in range(m):
                i = offsets[q] + j
                if seed[i, 2] == 0:
                    continue
                x, _, plane = _sample_point(centre[conns[q // 2, q % 2]], point[q // 2], j, m)
                stamp += 1
                a_out[i] = _plane_area(dt2, labels, box, x, plane, (seed[i, 0], seed[i, 1], pair[0], pair[1]),
                                       (caps[i], stamp), work)
    return a_out


#: Throats per block of :func:`_law_areas` (one scratch allocation per block; blocks run in parallel).
BLOCK = 8


def section_law_lengths(labels, dt2, rad_tab, geom, sections, box):
    r"""Per throat side: pore-centre-to-throat distance and its throat-equivalent length, duct-law integral.

    The side is sampled as the default constriction samples are
    (:func:`porefsi.network._mb_sections._lengths`: midpoints of ``ceil(d / SAMPLE_STEP)`` parts),
    each sample reading the inscribed radius ``r`` and the planar section area ``A``
    (:func:`_law_radii`, :func:`_law_areas`), and its conductance per length is the duct law of the network,
    ``g = duct_conductance_factor(r, min(r^2 / (4 A), 1 / (4 pi)))``
    (:func:`porefsi.network.geometry.duct_conductance_factor`), with r clamped to
    ``[r_t, R]`` and g to ``[g_t, g_p]`` (the throat's and the pore's ducts: radius and measured
    shape factor). With ``I = sum (d / m) / g`` the throat length of the two ducts that have the
    side's length and resistance is

    .. math:: L_t = \frac{I - d / g_p}{1 / g_t - 1 / g_p} \in [0, d],

    ``d / 2`` when ``R <= r_t`` or ``g_p <= g_t`` (no constriction). For a circular channel it is
    the ``1 / r^4`` integral of the default samples; where the section widens faster than its
    inscribed radius (a slit opening sideways into the pore) the constriction is shorter.

    Parameters
    ----------
    labels : ndarray of int32, shape (nx, ny, nz)
    dt2 : ndarray of int, shape (nx, ny, nz)
    rad_tab : ndarray of float64
        Radius of every distance-map value.
    geom : tuple (centre (Np, 3), point (Nt, 3), conns (Nt, 2) int64)
        Voxel-index coordinates.
    sections : tuple (r_throat (Nt,), r_pore (Np,), G_throat (Nt,), G_pore (Np,))
        Voxels; shape factors.
    box : ndarray of int64, shape (3,)

    Returns
    -------
    d, lt : ndarray of float64, shape (Nt, 2)
        Voxels.
    """
    centre, point, conns = geom
    r_t, r_p, G_t, G_p = sections
    n_t = conns.shape[0]
    d = np.stack([np.linalg.norm(point - centre[conns[:, s]], axis=1) for s in (0, 1)], axis=1)
    R = r_p[conns]
    g_t = np.repeat(duct_conductance_factor(r_t, G_t)[:, None], 2, axis=1)
    g_p = duct_conductance_factor(R, G_p[conns])
    live = (R > r_t[:, None]) & (d > 0.0) & (g_p > g_t)
    m = np.where(live, np.maximum(1, np.ceil(d / SAMPLE_STEP)), 0).astype(np.int64).ravel()
    offsets = np.concatenate(([0], np.cumsum(m))).astype(np.int64)
    area_p = R**2 / (4.0 * G_p[conns])
    caps = np.ceil(AREA_CAP * np.maximum(area_p, r_t[:, None] ** 2 / (4.0 * G_t[:, None]))).astype(np.int64).ravel()
    integral = np.zeros(2 * n_t)
    lims = (r_t, R.ravel(), g_t.ravel(), g_p.ravel(), d.ravel())
    for a, b in _chunks(offsets, max(CHUNK, labels.size // CHUNK_VOXELS)):  # throats a..b-1: bounded arrays
        geom_ab = (centre, point[a:b], conns[a:b])
        off = offsets[2 * a:2 * b + 1] - offsets[2 * a]
        rs, seed = _law_radii(dt2, rad_tab, geom_ab, off, box)
        cap = np.repeat(caps[2 * a:2 * b], m[2 * a:2 * b])
        As = _law_areas(dt2, labels, geom_ab, off, seed, cap, box)
        integral[2 * a:2 * b] = _side_integrals(rs, As, m[2 * a:2 * b], lims, 2 * a)
    integral = integral.reshape(n_t, 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        lt = (integral - d / g_p) / (1.0 / g_t - 1.0 / g_p)
    lt = np.where(live, np.clip(lt, 0.0, d), 0.5 * d)
    return d, lt


#: A plane flood stops at this many times the larger of the pore's and the throat's section area (the
#: samples' conductance is clamped at the pore duct's): measured, 4x gives the same k as 2x on four
#: images, 1x 0.4-1.7 % less.
AREA_CAP = 2.0

#: Constriction samples per batch of :func:`section_law_lengths`, at least (bounds its arrays: ~100 B a
#: sample, so the flood stays the extraction's peak on small images) ...
CHUNK = 4096

#: ... and one per this many voxels of the image (0.05 B/voxel of arrays: each batch is one parallel
#: launch of each kernel; 4096-sample batches cost 10-20 % more CPU on a 300^3 Berea than 65536).
CHUNK_VOXELS = 2000


def _chunks(offsets, size):
    """Throat ranges [a, b) whose sides hold about ``size`` samples each (at least one throat)."""
    n_t = (offsets.size - 1) // 2
    ends = offsets[2::2]  # samples up to the end of throat t
    out, a = [], 0
    while a < n_t:
        b = max(int(np.searchsorted(ends, offsets[2 * a] + size, side="right")), a + 1)
        out.append((a, min(b, n_t)))
        a = b
    return out


def _law(r, A):
    """The samples' duct law: conductance factor of inscribed radius r and section area A (voxels)."""
    G = np.minimum(r**2 / (4.0 * np.maximum(A, 1e-300)), CIRCLE_SHAPE_FACTOR)
    return duct_conductance_factor(r, G)


def _clamped_radius(rs, lims, glob):
    """Sample radii clamped to ``[r_t, R]`` of their sides ``glob``."""
    r_t, R = lims[0], lims[1]
    return np.minimum(np.maximum(rs, r_t[glob // 2]), R[glob])


def _side_integrals(rs, As, m, lims, first):
    """``sum (d / m) / g`` per side of one batch (sides ``first``, ``first + 1``, ...), g the clamped duct law."""
    r_t, R, g_t, g_p, d = lims
    side = np.repeat(np.arange(m.size), m)
    glob = side + first
    r = _clamped_radius(rs, lims, glob)
    g = np.clip(_law(r, As), g_t[glob], g_p[glob])
    step = d[glob] / m[side]
    return np.bincount(side, weights=step / g, minlength=m.size)
