"""Constriction length from the local section's duct law, and Sampson's end resistance.

Truths: a naive twin of the section-law kernels (``tests/reference/section_law_ref.py``); a square
duct between two chambers (inside it every section is the duct's own, so each side's throat duct
is at least the duct's length; past the mouth the section jumps to the chamber's); Sampson's
closed form for a circular aperture, ``3 mu / a^3`` (Dagan, Weinbaum & Pfeffer 1982: a tube of
radius a and length L between reservoirs has resistance ``8 mu L / (pi a^4) + 3 mu / a^3`` within
1 % at every L / a), i.e. a Poiseuille length ``3 pi a / 8`` added to the throat duct; a sphere
lattice (cylinders of known exposed length between spheres) and its refinement (the same
staircase: the same lengths and permeability in metres).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import porefsi.network._mb_conduits as mc
from porefsi.flow.permeability import absolute_permeability
from porefsi.image.synthetic import sphere_lattice
from porefsi.image.voxel_image import VoxelImage
from porefsi.network._mb_section_law import section_law_lengths
from porefsi.network.extract import _distance_map, extract_network
from porefsi.network.geometry import duct_conductance_factor, duct_lengths
from tests.reference import section_law_ref as ref
from tests.reference.sections_ref import box_walled, tube_beside_face, wall_radius_table


@pytest.fixture
def law(monkeypatch):
    """The section law and the end resistance switched on for one test."""
    monkeypatch.setattr(mc, "SECTION_LAW", True)
    monkeypatch.setattr(mc, "SAMPSON_END", True)


def _labels_split(pore, x_split):
    """Two pore regions: voxels below ``x_split`` along x are pore 0, the rest pore 1; solid -1."""
    lab = np.where(pore, 0, -1).astype(np.int32)
    lab[int(math.ceil(x_split)):][pore[int(math.ceil(x_split)):]] = 1
    return lab


def _duct(f: int):
    """Chambers x in [2, 14) and [26, 38), y, z in [2, 15); a square duct x in [14, 26), y, z in [7, 10); x f."""
    pore = np.zeros((40 * f, 17 * f, 17 * f), bool)
    pore[2 * f:14 * f, 2 * f:15 * f, 2 * f:15 * f] = True
    pore[26 * f:38 * f, 2 * f:15 * f, 2 * f:15 * f] = True
    pore[14 * f:26 * f, 7 * f:10 * f, 7 * f:10 * f] = True
    c = 8.5 * f - 0.5
    centre = np.array([[8.0 * f - 0.5, c, c], [32.0 * f - 0.5, c, c]])
    point = np.array([[20.0 * f - 0.5, c, c]])
    return pore, centre, point


def _duct_lengths(f: int, walls=(0, 0, 0)):
    pore, centre, point = _duct(f)
    dt2 = _distance_map(pore)
    tab = wall_radius_table(dt2.max())
    lab = _labels_split(pore, 20.0 * f - 0.5)
    conns = np.array([[0, 1]])
    shape = (np.array([1 / 16]), np.array([1 / 16, 1 / 16]))
    radii = (np.array([1.5 * f]), np.array([6.0 * f, 6.0 * f]))
    got = section_law_lengths(lab, dt2, tab, (centre, point, conns), radii + shape, np.array(walls, np.int64))
    return (pore, dt2, tab, lab, centre, point, conns, radii, shape), got


def test_kernel_matches_the_twin_on_the_duct():
    (pore, dt2, tab, lab, centre, point, conns, radii, shape), got = _duct_lengths(1)
    want = ref.section_law_lengths(dt2, lab, tab, centre, point, conns.tolist(), radii, shape, (0, 0, 0))
    np.testing.assert_allclose(got[0], want[0], rtol=1e-12)
    np.testing.assert_allclose(got[1], want[1], rtol=1e-12, atol=1e-12)


def test_kernel_matches_the_twin_on_an_oblique_walled_line():
    # the tube's axis 1 voxel from the y face; the sides run obliquely: the planes are tilted
    pore, centre, point, conns, rt, rp = tube_beside_face()
    dt2 = _distance_map(pore)
    walls = (1, 1, 1)
    tab = wall_radius_table(dt2.max())
    lab = _labels_split(pore, 9.5)
    shape = (np.array([0.05]), np.array([0.04, 0.045]))
    got = section_law_lengths(lab, dt2, tab, (centre, point, conns), (rt, rp) + shape, np.array(walls, np.int64))
    want = ref.section_law_lengths(box_walled(pore, walls), lab, tab, centre, point, conns.tolist(), (rt, rp),
                                   shape, walls)
    np.testing.assert_allclose(got[1], want[1], rtol=1e-12, atol=1e-12)
    assert np.all((got[1] > 0.0) & (got[1] < got[0]))


def test_plane_area_of_the_duct_and_the_chamber():
    """Normal to the axis: the duct's section is 3 x 3 = 9 faces, the chamber's 13 x 13 = 169 (capped)."""
    (pore, dt2, tab, lab, *_), _ = _duct_lengths(1)
    u = (1.0, 0.0, 0.0)
    assert ref.plane_area(dt2, lab, (18.0, 8.0, 8.0), u, (0, 1), 1000) == 9
    assert ref.plane_area(dt2, lab, (8.0, 8.0, 8.0), u, (0, 1), 1000) == 169
    assert ref.plane_area(dt2, lab, (8.0, 8.0, 8.0), u, (0, 1), 50) == 50
    assert ref.plane_area(dt2, lab, (8.0, 8.0, 8.0), u, (1, 1), 1000) == 0  # pore 0's voxels only


@pytest.mark.parametrize("f", [1, 2])
def test_duct_side_is_the_duct_plus_less_than_the_radius_law_adds(f):
    """The section inside the duct is the duct's own (g = g_t): the throat duct is at least its 6 f voxels;
    past the mouth the section jumps to the chamber's, so the section law adds less than 1/r^4 does."""
    from porefsi.network._mb_sections import _constriction_lengths

    (pore, dt2, tab, lab, centre, point, conns, radii, shape), (d, lt) = _duct_lengths(f)
    np.testing.assert_allclose(d, 12.0 * f)
    _, lt_r4 = _constriction_lengths(dt2, tab, centre, point, conns, radii[0], radii[1])
    assert np.all(lt >= 6.0 * f - 0.25 * f)
    assert np.all(lt < lt_r4)  # 1/r^4 alone: 7.15 native voxels
    assert np.all(lt / f < 6.6)


def test_duct_side_is_the_same_in_metres_at_1x_and_2x():
    one = _duct_lengths(1)[1][1]
    two = _duct_lengths(2)[1][1] / 2
    np.testing.assert_allclose(two, one, rtol=0.03)


def test_end_resistance_is_sampsons_length_per_side(monkeypatch):
    """With the end correction, each constricted side's throat duct grows by 3 pi r_t / 16 (both mouths of a
    circular throat: 3 pi r / 8 of Poiseuille length = Sampson's 3 mu / r^3)."""
    pore, centre, point = _duct(1)
    dt2 = _distance_map(pore)
    lab = _labels_split(pore, 19.5)
    conns = np.array([[0, 1]])
    rt, rp = np.array([1.5]), np.array([6.0, 6.0])
    monkeypatch.setattr(mc, "SECTION_LAW", True)
    monkeypatch.setattr(mc, "SAMPSON_END", False)
    base = mc.measure_sections(lab, dt2, centre, point, conns, rt, rp)
    monkeypatch.setattr(mc, "SAMPSON_END", True)
    end = mc.measure_sections(lab, dt2, centre, point, conns, rt, rp)
    np.testing.assert_allclose(end["side_lt"] - base["side_lt"], 3 * math.pi * 1.5 / 16, rtol=1e-12)
    # Dagan et al.: the resistance of the throat duct is Poiseuille over the duct plus Sampson
    r = 0.7e-6
    g = duct_conductance_factor(r, 1 / (4 * math.pi))
    np.testing.assert_allclose(mc.sampson_length(r) / g, 3 / r**3, rtol=1e-12)


def test_sphere_lattice_throat_duct_and_refinement(law):
    """Cylinders of radius 2.5 between spheres of 5.5, 16 apart, throat point midway: circular sections, so the
    lubrication integral of the union's radius ``max(r_t, sqrt(R^2 - x^2))`` (the staircase's radii) gives the
    throat duct (~7.8 voxels for both sides), plus the end lengths 3 pi r_t / 8 (~2.5); within 0.3 voxel. The
    refined image (f = 3: the native centres are fine centres) gives the same k within 5 %."""
    lat = sphere_lattice(n=(2, 2, 2), spacing=16, pore_radius=5.5, throat_radius=2.5)
    pore, vs = lat.image.phases, lat.image.voxel_size
    nat = extract_network(VoxelImage(pore, vs)).network
    lt = duct_lengths(nat)[:, 1] / vs
    rt, big = nat.throat_radius / vs, float(np.median(nat.pore_radius / vs))  # the staircase's: ~2.1, ~5.5
    x = np.linspace(0.0, 8.0, 200001)
    for t in range(nat.n_throats):
        r = np.maximum(rt[t], np.sqrt(np.maximum(big**2 - x * x, 0.0)))
        side = (np.trapezoid(r**-4, x) - 8.0 / big**4) / (rt[t] ** -4 - big**-4)
        assert lt[t] == pytest.approx(2 * side + 3 * math.pi * rt[t] / 8, abs=0.3)  # measured 0.15
    fine_img = pore
    for ax in range(3):
        fine_img = np.repeat(fine_img, 3, axis=ax)
    fine = extract_network(VoxelImage(np.ascontiguousarray(fine_img), vs / 3)).network
    for ax in "xyz":
        k1 = absolute_permeability(nat, ax).k_m2
        assert absolute_permeability(fine, ax).k_m2 == pytest.approx(k1, rel=0.05)


def test_paper_model_ignores_the_switches(law):
    lat = sphere_lattice(n=(2, 2, 1), spacing=14, pore_radius=5.0, throat_radius=2.0)
    with_law = extract_network(lat.image, conductance="paper").network
    mc.SECTION_LAW, mc.SAMPSON_END = False, False
    without = extract_network(lat.image, conductance="paper").network
    np.testing.assert_array_equal(with_law.throat_length, without.throat_length)
    np.testing.assert_array_equal(with_law.throat_pore_length, without.throat_pore_length)


def test_threads_do_not_change_the_samples():
    """The plane floods run on numba's threads: one thread and all of them give the same lengths to the bit
    (a lattice of unequal pores and throats, walled box)."""
    import numba

    rng = np.random.default_rng(3)
    lat = sphere_lattice(n=(3, 3, 3), spacing=14, pore_radius=rng.uniform(4.0, 6.0, 27),
                         throat_radius=rng.uniform(1.5, 3.0, 54))
    dt2 = _distance_map(lat.image.phases.astype(bool))
    ex = extract_network(lat.image)
    vs, net = lat.image.voxel_size, ex.network
    centre = net.pore_coords / vs - 0.5
    conns = net.throat_conns.astype(np.int64)
    point = 0.5 * (centre[conns[:, 0]] + centre[conns[:, 1]])
    rt, rp = net.throat_radius / vs, net.pore_radius / vs
    sections = (rt, rp, np.full(rt.size, 0.05), np.full(rp.size, 0.04))
    args = (ex.labels, dt2, wall_radius_table(dt2.max()), (centre, point, conns), sections, np.ones(3, np.int64))
    n = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = section_law_lengths(*args)
    finally:
        numba.set_num_threads(n)
    many = section_law_lengths(*args)
    assert np.count_nonzero((many[1] > 0.0) & (many[1] < many[0])) > 20  # constrictions measured
    np.testing.assert_array_equal(one[0], many[0])
    np.testing.assert_array_equal(one[1], many[1])


def _blob_case(seed=5, n=22, porosity=0.35):
    """A random blob image (smoothed noise), its extraction, the walled distance map and every throat side."""
    from scipy import ndimage

    rng = np.random.default_rng(seed)
    field = ndimage.gaussian_filter(rng.standard_normal((n, n, n)), 1.6)
    pore = field > np.quantile(field, 1.0 - porosity)
    ex = extract_network(VoxelImage(pore.astype(np.uint8), 1e-6))
    net = ex.network
    centre = net.pore_coords / 1e-6 - 0.5
    conns = net.throat_conns.astype(np.int64)
    point = 0.5 * (centre[conns[:, 0]] + centre[conns[:, 1]])
    return pore, ex.labels, _distance_map(pore), centre, point, conns


@pytest.mark.parametrize("walls", [(1, 1, 1), (0, 0, 0)])
def test_every_plane_flood_matches_the_twin(walls):
    """Sample by sample on oblique planes of a blob image (walled box): the kernel's radii, seeds and plane
    areas (one disc scan per sample, then its flood) against the twin's disc scans and set flood, with caps that
    stop some floods (7 faces) and caps that do not (10^4). With open faces (a face cut's own axis) the discs
    reach past the image, where the radius reads the clipped voxel and the seed skips the point."""
    import porefsi.network._mb_section_law as sl

    pore, labels, dt2, centre, point, conns = _blob_case()
    box = np.array(walls, np.int64)
    dt2w = box_walled(pore, walls)
    tab = wall_radius_table(dt2.max())
    d = np.linalg.norm(point[:, None, :] - centre[conns], axis=2).ravel()
    m = np.maximum(1, np.ceil(d / 0.25)).astype(np.int64)
    offsets = np.concatenate(([0], np.cumsum(m))).astype(np.int64)
    caps = np.where(np.arange(offsets[-1]) % 3 == 0, 7, 10_000).astype(np.int64)
    r, seed = sl._law_radii(dt2, tab, (centre, point, conns), offsets, box)
    got = sl._law_areas(dt2, labels, (centre, point, conns), offsets, seed, caps, box)
    assert offsets[-1] > 500 and np.count_nonzero(got == 7) > 50 and np.count_nonzero(got > 7) > 100
    for q in range(2 * conns.shape[0]):
        c, pt, pair = centre[conns[q // 2, q % 2]], point[q // 2], (conns[q // 2, 0], conns[q // 2, 1])
        vec = pt - c
        for j in range(m[q]):
            x = c + (j + 0.5) / m[q] * vec
            i = offsets[q] + j
            assert got[i] == ref.plane_area(dt2w, labels, x, vec / d[q], pair, caps[i]), (q, j)
            if q % 4 == 0:  # the radius of the same disc scan (its twin is slow)
                want_r = ref.section_radius(dt2w, lambda v: tab[v], x, vec / d[q], walls)
                assert r[i] == pytest.approx(want_r, abs=1e-12), (q, j)
