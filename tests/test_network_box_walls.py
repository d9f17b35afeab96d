"""The image box faces are no-slip walls for the measured throat geometry (the voxel reference's side walls).

Truths: closed-form sections of ducts lying against a box face (a 3 x 8 slot: inscribed radius
1.5, area 24, perimeter 22; a half tube of radius R cut by the face through its axis: inscribed
radius R / 2, area pi R^2 / 2), and naive twins in ``tests/reference/sections_ref.py`` that pad
the image with a solid voxel layer instead of bounding distances by the faces.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from porefsi.image.voxel_image import VoxelImage
from porefsi.network._mb_sections import (
    _constriction_lengths,
    _d2,
    _sections,
    _stair_section_peaks,
    _walled_points,
)
from porefsi.network.extract import _distance_map, extract_network
from tests.reference.extract_ref import interfaces
from tests.reference.sections_ref import (
    box_walled,
    constriction_lengths,
    sections,
    stair_section_peaks,
    tube_beside_face,
    wall_radius_table,
)

WALLS = [(1, 1, 1), (0, 1, 0), (1, 0, 1), (0, 0, 0)]


def _rock(shape=(9, 8, 7), seed=5, porosity=0.7):
    rng = np.random.default_rng(seed)
    return rng.random(shape) < porosity


def _labels(pore, seed=6, n=4):
    rng = np.random.default_rng(seed)
    return np.where(pore, rng.integers(0, n, pore.shape), -1).astype(np.int32)


@pytest.mark.parametrize("walls", WALLS)
def test_walled_distance_map_matches_the_padded_image(walls):
    pore = _rock()
    dt2 = _distance_map(pore)
    w = np.array(walls, np.int64)
    got = np.array([_d2(dt2, *ijk, w) for ijk in np.ndindex(pore.shape)]).reshape(pore.shape)
    np.testing.assert_array_equal(got, box_walled(pore, walls))


@pytest.mark.parametrize("walls", WALLS)
def test_walled_throat_points_match_the_interfaces_of_the_padded_map(walls):
    pore = _rock(seed=7)
    lab = _labels(pore)
    conns, w_ref, p_ref, _ = interfaces(lab, box_walled(pore, walls))
    w, p = _walled_points(lab, _distance_map(pore), conns, np.int64(4), np.array(walls, np.int64))
    np.testing.assert_array_equal(w, w_ref)
    np.testing.assert_array_equal(p, p_ref)


@pytest.mark.parametrize("walls", WALLS)
def test_wall_edges_on_walled_faces_match_the_twin(walls):
    pore = _rock(seed=8)
    lab = _labels(pore, seed=9)
    conns = interfaces(lab, box_walled(pore, (0, 0, 0)))[0]
    got = _sections(lab, conns, np.int64(4), np.array(walls, np.int64))
    want = sections(lab, conns.tolist(), walls)
    for g, v in zip(got, want, strict=True):
        np.testing.assert_array_equal(g, v)


@pytest.mark.parametrize("walls", WALLS)
def test_section_peaks_bounded_by_walled_faces_match_the_twin(walls):
    pore = _rock(shape=(8, 9, 7), seed=10, porosity=0.8)
    dt2 = _distance_map(pore)
    rng = np.random.default_rng(11)
    pts = []
    for _ in range(25):  # face points (one half-integer coordinate), many next to a box face
        p = [float(rng.integers(0, s)) for s in pore.shape]
        ax = int(rng.integers(0, 3))
        p[ax] = min(p[ax], pore.shape[ax] - 2) + 0.5
        pts.append(p)
    pts += [[-0.5, 4.0, 3.0], [7.5, 0.0, 6.0]]  # face-cut points on the box (their axis held)
    pts = np.array(pts)
    got = _stair_section_peaks(dt2, pts, 0.5, 2, np.array(walls, np.int64))
    np.testing.assert_allclose(got, stair_section_peaks(dt2, pts, 0.5, 2, walls), rtol=1e-12, atol=1e-12)


def test_constriction_lengths_on_the_walled_map_match_the_twin():
    pore, centre, point, conns, rt, rp = tube_beside_face()  # the tube's axis 1 voxel from the y face
    dt2 = _distance_map(pore)
    walls = (1, 1, 1)
    dtw = box_walled(pore, walls)
    tab = wall_radius_table(dt2.max())
    got = _constriction_lengths(dt2, tab, centre, point, conns, rt, rp, np.array(walls, np.int64))
    want = constriction_lengths(dtw, lambda v: tab[v], centre.tolist(), point.tolist(), conns.tolist(),
                                rt.tolist(), rp.tolist(), 0.25, walls)
    np.testing.assert_allclose(got[0], want[0], rtol=1e-12)
    np.testing.assert_allclose(got[1], want[1], rtol=1e-12, atol=1e-12)
    open_ = _constriction_lengths(dt2, tab, centre, point, conns, rt, rp)
    assert np.all(got[1] > open_[1])  # the face narrows the samples: a longer constriction


# ------------------------------------------------------------------------------------------
# Closed-form sections of ducts lying against a box face
# ------------------------------------------------------------------------------------------
def _throats_in(ext, lo, hi):
    """Throats whose section sits in x in (lo, hi) voxels: radius, area, wall perimeter (voxel units), G."""
    net = ext.network
    vs = net.voxel_size
    x = (net.pore_coords[:, 0] - net.origin[0]) / vs - 0.5
    mid = 0.5 * (x[net.throat_conns[:, 0]] + x[net.throat_conns[:, 1]])
    sel = (mid > lo) & (mid < hi)
    s = ext.sections
    return s["radius"][sel] / vs, s["area"][sel] / vs**2, s["wall_perimeter"][sel] / vs, net.throat_shape_factor[sel]


def test_slot_against_a_face_reads_its_closed_form_section():
    """A 3 x 8 slot lying on the y = 0 face between two wide chambers: r 1.5, A 24, P 22 voxels."""
    pore = np.zeros((30, 10, 16), bool)
    pore[:, 0:3, 4:12] = True  # the slot, open to the y face (x from 0 to 29)
    pore[0:10, 0:7, 1:15] = True  # chambers
    pore[20:30, 0:7, 1:15] = True
    ext = extract_network(VoxelImage(pore.astype(np.uint8), 1e-6), min_radius=1.0)
    r, area, perim, G = _throats_in(ext, 10, 20)
    assert r.size >= 1
    np.testing.assert_allclose(r, 1.5, atol=0.05)  # the open box read up to 2.0 (half a voxel past the face)
    np.testing.assert_array_equal(area, 24.0)
    np.testing.assert_array_equal(perim, 22.0)  # the face's 8 edges count; 14 without them
    np.testing.assert_allclose(G, 1.5**2 / (4 * 24), rtol=0.05)  # r^2 / (4 A); the circle's 1/(4 pi) before


@pytest.mark.parametrize("R", [5.0, 7.0])
def test_half_tube_cut_by_a_face_reads_half_its_radius(R):
    """A tube of radius R whose axis lies on the z = -1/2 face: a half disc, inscribed radius R/2.

    Between two larger half-spheres (chambers) so the tube holds throats; the open box read the
    radius as about R (4.5 and 6.5 voxels for R 5 and 7), ~2x too wide.
    """
    n = (40, int(2 * R) + 9, int(R) + 6)
    g = np.indices(n).astype(float)
    cy, cz = (n[1] - 1) / 2, -0.5
    pore = (g[1] - cy) ** 2 + (g[2] - cz) ** 2 <= R * R
    for cx in (6.0, 33.0):
        pore |= (g[0] - cx) ** 2 + (g[1] - cy) ** 2 + (g[2] - cz) ** 2 <= (R + 3) ** 2
    ext = extract_network(VoxelImage(pore.astype(np.uint8), 1e-6), min_radius=1.0)
    r, area, _, _ = _throats_in(ext, 13, 26)
    assert r.size >= 1
    np.testing.assert_allclose(r, R / 2, atol=0.5)  # voxel tolerance (the staircase)
    np.testing.assert_allclose(area, math.pi * R * R / 2, rtol=0.1)
