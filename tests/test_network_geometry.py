"""Shape-factor conduit model: sections measured from voxels, conductances, entry pressures.

Truths: closed forms (Hagen-Poiseuille, the equilateral triangle's exact duct flow, the square
duct's series solution, a numerical Mayer-Stowe-Princen energy balance) and voxelised ducts of
known section; the kernels against naive twins in tests/reference/sections_ref.py.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from porefsi.errors import InputError
from porefsi.flow.fluids import Fluids
from porefsi.flow.invasion import invasion_percolation
from porefsi.flow.permeability import absolute_permeability
from porefsi.image.synthetic import sphere_lattice
from porefsi.network._mb_sections import _constriction_lengths, _sections, _subvoxel_peaks
from porefsi.network.extract import _distance_map, digital_radius, extract_network
from porefsi.network.geometry import duct_conductance_factor, resistance_factors, shape_class
from porefsi.network.network import CIRCLE_SHAPE_FACTOR, Network
from tests.reference.sections_ref import constriction_lengths, sections

TRI_G = math.sqrt(3) / 36


# ------------------------------------------------------------------------------------------
# Duct conductances against closed forms
# ------------------------------------------------------------------------------------------
def _square_duct_series(side):
    """Exact square-duct conductance x viscosity (Poiseuille series), m^4."""
    s = sum(math.tanh(n * math.pi / 2) / n**5 for n in range(1, 200, 2))
    return side**4 / 12 * (1 - 192 / math.pi**5 * s)


def _rect_series(a, b, terms=60):
    """Poiseuille flow (g mu, m^4) of an a x b rectangle, a <= b: the series written out by hand."""
    tail = sum(math.tanh((2 * i + 1) * math.pi * b / (2 * a)) / (2 * i + 1) ** 5 for i in range(terms))
    return a**3 * b / 12 * (1 - 192 * a / (math.pi**5 * b) * tail)


def test_duct_conductance_closed_forms():
    r = 2e-6
    # circle: Hagen-Poiseuille pi r^4 / 8
    assert duct_conductance_factor(r, CIRCLE_SHAPE_FACTOR) == pytest.approx(math.pi * r**4 / 8, rel=1e-12)
    # equilateral triangle of inscribed radius r: side a = 2 sqrt(3) r, exact g mu = sqrt(3) a^4 / 320
    a = 2 * math.sqrt(3) * r
    assert duct_conductance_factor(r, TRI_G) == pytest.approx(math.sqrt(3) * a**4 / 320, rel=1e-9)
    # square of inscribed radius r: side 2r, Poiseuille series (k = 0.5623 is its 4-digit value)
    assert duct_conductance_factor(r, 1 / 16) == pytest.approx(_square_duct_series(2 * r), rel=2e-4)


def test_shape_classes_follow_pnflow_bounds():
    G = np.array([0.01, TRI_G, TRI_G * 1.001, 1 / 16, 0.0699, 0.07, CIRCLE_SHAPE_FACTOR])
    assert shape_class(G).tolist() == [0, 0, 1, 1, 1, 2, 2]


# ------------------------------------------------------------------------------------------
# Entry pressures: Mayer-Stowe-Princen against a numerical energy balance
# ------------------------------------------------------------------------------------------
def _msp_numeric(r, half_angles, sigma, theta):
    """Entry pressure from the energy balance Pc A_eff = sigma (L_nw + L_ns cos theta), by root finding.

    Polygon with inscribed radius r and corner half-angles beta: side tangent lengths r cot(beta).
    Corner wetting menisci of radius R (Pc = sigma / R) meet the walls at the contact angle.
    """
    b = np.asarray(half_angles)
    P = 2 * r * np.sum(1 / np.tan(b))
    A = r * P / 2

    def f(R):
        corner_area = R * R * np.sum(np.cos(theta) * np.cos(theta + b) / np.sin(b) - (np.pi / 2 - theta - b))
        l_ns = P - 2 * R * np.sum(np.cos(theta + b) / np.sin(b))
        l_nw = 2 * R * np.sum(np.pi / 2 - theta - b)
        return (A - corner_area) - R * (l_nw + l_ns * np.cos(theta))

    R = brentq(f, 1e-6 * r, 0.999 * r, xtol=1e-24, rtol=1e-15)
    return sigma / R


@pytest.mark.parametrize("theta_deg", [0.0, 25.0])
def test_entry_pressure_triangle_and_square_match_energy_balance(theta_deg):
    r, sigma = 3e-6, 0.03
    fl = Fluids(sigma=sigma, theta_deg=theta_deg)
    th = math.radians(theta_deg)
    # a scalene triangle: half-angles summing to pi/2
    b = np.array([0.25, 0.5, np.pi / 2 - 0.75])
    G = 1 / (4 * np.sum(1 / np.tan(b)))  # G = r / (2 P) for a polygon with an inscribed circle
    assert fl.entry_pressure(r, G) == pytest.approx(_msp_numeric(r, b, sigma, th), rel=1e-9)
    sq = _msp_numeric(r, [np.pi / 4] * 4, sigma, th)
    assert fl.entry_pressure(r, 1 / 16) == pytest.approx(sq, rel=1e-9)
    # circles: Young-Laplace
    assert fl.entry_pressure(r, CIRCLE_SHAPE_FACTOR) == pytest.approx(2 * sigma * math.cos(th) / r, rel=1e-12)
    assert fl.entry_pressure(r) == pytest.approx(2 * sigma * math.cos(th) / r, rel=1e-12)


# ------------------------------------------------------------------------------------------
# Sections of voxelised ducts
# ------------------------------------------------------------------------------------------
def _duct_labels(section2d, length=8, cut=None):
    """Labels of a duct of the given 2-D section along x, pore 0 before the cut, pore 1 after it."""
    nx = length
    lab = np.full((nx, *section2d.shape), -1, np.int32)
    x = np.arange(nx)[:, None, None]
    cut = (lambda x, y, z: x < nx // 2) if cut is None else cut
    y, z = np.indices(section2d.shape)
    side = cut(x, y[None], z[None])
    lab[:] = np.where(section2d[None], np.where(side, 0, 1), -1)
    return lab


def _disc(R, n):
    y, z = np.indices((n, n))
    c = (n - 1) / 2
    return (y - c) ** 2 + (z - c) ** 2 <= R * R


def test_vector_area_of_any_spanning_cut_is_the_section_area():
    sec = _disc(4.3, 13)
    conns = np.array([[0, 1]])
    straight, nf0, _ = _sections(_duct_labels(sec), conns, np.int64(2))
    oblique, nf1, _ = _sections(
        _duct_labels(sec, length=24, cut=lambda x, y, z: x + y + 0.5 * z < 16), conns, np.int64(2))
    assert straight[0].tolist() == [sec.sum(), 0, 0]
    # along the duct, any spanning cut's vector area is the section area exactly (the lateral wall
    # faces have no x component): the staircase cancels, while the face count grows
    assert oblique[0, 0] == sec.sum()
    assert nf1[0] > 1.5 * nf0[0]


@pytest.mark.parametrize("case", ["circle", "square", "triangle", "slit"])
def test_extracted_shape_factor_of_voxelised_sections(case):
    """G = r^2 / (4 A) with the measured A and inscribed r, on sections of known G."""
    n = 29
    y, z = np.indices((n, n)).astype(float)
    c = (n - 1) / 2
    if case == "circle":
        sec, G = (y - c) ** 2 + (z - c) ** 2 <= 10.0**2, CIRCLE_SHAPE_FACTOR
    elif case == "square":
        sec, G = (abs(y - c) <= 9.5) & (abs(z - c) <= 9.5), 1 / 16
    elif case == "triangle":
        a = 26.0  # side, apex up; inscribed radius a / (2 sqrt 3)
        h = a * math.sqrt(3) / 2
        yy, zz = y - 1.5, z - c
        sec, G = (yy >= 0) & (yy <= h) & (abs(zz) <= (h - yy) / math.sqrt(3)), TRI_G
    else:  # 5 x 27 voxels; G = h / (16 w) with the inscribed radius h / 2 = 2.5
        sec, G = (abs(y - c) <= 2.5) & (abs(z - c) <= 13.5), 5 / (16 * 27)
    lab = _duct_labels(sec)
    area, _, _ = _sections(lab, np.array([[0, 1]]), np.int64(2))
    A = np.linalg.norm(area[0])
    dt2 = _distance_map(lab >= 0)
    r = digital_radius(int(dt2[lab.shape[0] // 2].max()))  # inscribed radius on the section
    measured = r * r / (4 * A)
    if case in ("slit", "square"):
        # flat walls: the digital radius puts the wall half-way between the solid centre at d
        # voxels and the farthest representable distance below it, sqrt(d^2 - 1), not at d - 1/2
        # (exact for curved walls): 2.91 instead of 2.5, 9.97 instead of 9.5 voxels
        half = 2.5 if case == "slit" else 9.5
        d = half + 0.5
        assert r == pytest.approx(0.5 * (d + math.sqrt(d * d - 1)), rel=1e-12)
        G = (r / half) ** 2 * G
    assert measured == pytest.approx(G, rel=0.05)
    if case != "triangle":  # a digitised equilateral triangle sits on the triangle/square bound
        assert shape_class(measured) == shape_class(G)


def test_sections_kernel_matches_naive_twin():
    rng = np.random.default_rng(3)
    lab = rng.integers(-1, 4, size=(7, 6, 5)).astype(np.int32)
    pairs = set()
    for ax in range(3):
        a = np.moveaxis(lab, ax, 0)
        u, v = a[:-1].ravel(), a[1:].ravel()
        m = (u >= 0) & (v >= 0) & (u != v)
        pairs |= {(min(p, q), max(p, q)) for p, q in zip(u[m].tolist(), v[m].tolist(), strict=True)}
    conns = np.array(sorted(pairs), dtype=np.int64)
    got = _sections(lab, conns, np.int64(4))
    want = sections(lab, conns.tolist())
    for g, w in zip(got, want, strict=True):
        np.testing.assert_array_equal(g, w)


def test_constriction_lengths_kernel_matches_twin_and_closed_form():
    lat = sphere_lattice(n=(3, 2, 2), spacing=16, pore_radius=5.0, throat_radius=2.0)
    pore = lat.image.phases.astype(bool)
    dt2 = _distance_map(pore)
    tab = digital_radius(np.maximum(np.arange(int(dt2.max()) + 1), 1))
    tab[0] = 0.0
    ext = extract_network(lat.image)
    vs = lat.image.voxel_size
    centre = (ext.network.pore_coords - lat.image.origin) / vs - 0.5
    conns = ext.network.throat_conns
    point = 0.5 * (centre[conns[:, 0]] + centre[conns[:, 1]])
    rt = ext.network.throat_radius / vs  # the staircase's radii of the r 2 cylinders and r 5 spheres
    rp = ext.network.pore_radius / vs
    got = _constriction_lengths(dt2, tab, centre, point, conns, rt, rp)
    want = constriction_lengths(dt2, lambda v: tab[v], centre.tolist(), point.tolist(), conns.tolist(),
                                rt.tolist(), rp.tolist(), 0.25)
    np.testing.assert_allclose(got[0], want[0], rtol=1e-12)
    np.testing.assert_allclose(got[1], want[1], rtol=1e-12, atol=1e-12)
    # the straight cylinder of radius 2 from the sphere wall (~5 voxels out) to the mid-point
    # (8 voxels out) is about 3 voxels of throat per side (the narrowing sphere adds a little)
    assert np.all((got[1] > 2.5) & (got[1] < 5.0))  # 4.67 with the staircase radii (r_t 1.58)


def _staircase_inscribed_radius(section, centre, half=1.5, step=0.05):
    """Largest distance from a point near ``centre`` to the nearest solid pixel square (grid search)."""
    solid = np.argwhere(~section)
    best = 0.0
    for x in np.arange(centre[0] - half, centre[0] + half + 1e-9, step):
        for y in np.arange(centre[1] - half, centre[1] + half + 1e-9, step):
            gx = np.maximum(np.abs(solid[:, 0] - x) - 0.5, 0.0)
            gy = np.maximum(np.abs(solid[:, 1] - y) - 0.5, 0.0)
            best = max(best, float(np.sqrt(gx * gx + gy * gy).min()))
    return best


def test_subvoxel_radius_reads_the_staircase_inscribed_radius():
    """Tubes at random sub-voxel offsets: the throat radius is the voxel staircase's inscribed radius.

    Truth: the largest distance from any point of the section to the nearest solid pixel square
    (a grid search at 0.05 voxel). The digital radius (the paper's) reads it ~0.4 voxel high.
    """
    rng = np.random.default_rng(0)
    err_d, err_s = [], []
    for R in (2.5, 3.0, 4.0):
        for _ in range(4):
            off = rng.random(2)
            n = int(2 * R) + 8
            x, y, _ = np.meshgrid(np.arange(n), np.arange(n), np.arange(5), indexing="ij")
            pore = (x - n // 2 - off[0]) ** 2 + (y - n // 2 - off[1]) ** 2 <= R * R
            dt2 = _distance_map(pore)
            tab = digital_radius(np.maximum(np.arange(int(dt2.max()) + 1), 1))
            tab[0] = 0
            sl = dt2[:, :, 2]
            i, j = np.unravel_index(np.argmax(sl), sl.shape)
            truth = _staircase_inscribed_radius(pore[:, :, 2], (n // 2 + off[0], n // 2 + off[1]))
            err_d.append(tab[sl[i, j]] - truth)
            err_s.append(_subvoxel_peaks(dt2, tab, np.array([[i, j, 2.5]]))[0] - truth)
    assert np.mean(err_d) > 0.2
    assert abs(np.mean(err_s)) < 0.05 and max(np.abs(err_s)) < 0.35, err_s  # measured 0.0002, 0.31


# ------------------------------------------------------------------------------------------
# Network fields, conduits, flow
# ------------------------------------------------------------------------------------------
def _two_pores(**kw):
    base = dict(pore_coords=[[1e-5, 5e-6, 5e-6], [3e-5, 5e-6, 5e-6]], pore_radius=[5e-6, 3e-6],
                pore_volume=[1e-16, 1e-16], throat_conns=[[0, 1]], throat_radius=[2e-6],
                throat_length=[1e-5], throat_pore_length=[[6e-6, 4e-6]],
                pore_faces=[[1, 0, 0, 0, 0, 0], [0, 1, 0, 0, 0, 0]], voxel_size=1e-6, shape=(40, 10, 10))
    base.update(kw)
    return Network(**base)


def test_shape_factor_conduit_is_three_ducts_in_series():
    Gp, Gt = [0.03, 0.065], [0.02]
    frac = [[0.2, 0.5, 0.3]]
    net = _two_pores(pore_shape_factor=Gp, throat_shape_factor=Gt, throat_duct_fraction=frac)
    assert net.conduit_model == "shape_factor"
    L = 2e-5  # 6 + 10 + 4 um
    # by hand: g mu = k G A^2 with A = r^2 / (4 G) -> k r^4 / (16 G); pore 1 is a square (G = 1/16);
    # below the equilateral triangle's G the geometric mean with the 2r x A/(2r) rectangle
    c0 = math.sqrt(0.6 * (5e-6) ** 4 / (16 * 0.03) * _rect_series(1e-5, 5e-6 / (8 * 0.03)))
    ct = math.sqrt(0.6 * (2e-6) ** 4 / (16 * 0.02) * _rect_series(4e-6, 2e-6 / (8 * 0.02)))
    c1 = 0.5623 * (3e-6) ** 4 / (16 * (1 / 16))
    want = [0.2 * L / c0, 0.5 * L / ct, 0.3 * L / c1]
    np.testing.assert_allclose(resistance_factors(net)[0], want, rtol=1e-6)  # series truncations differ
    # reversed conns: the fractions follow their pores
    rev = _two_pores(pore_shape_factor=Gp, throat_shape_factor=Gt, throat_duct_fraction=[[0.3, 0.5, 0.2]],
                     throat_conns=[[1, 0]], throat_pore_length=[[4e-6, 6e-6]])
    np.testing.assert_allclose(resistance_factors(rev)[0], want, rtol=1e-6)
    # the paper model on the same network ignores the shape factors
    paper = net.with_conductance("paper")
    assert paper.conduit_model == "paper"
    assert resistance_factors(paper)[0, 1] == pytest.approx(8 * 1e-5 / (math.pi * (2e-6) ** 4))
    k_sf = absolute_permeability(net, "x").k_m2
    k_p = absolute_permeability(paper, "x").k_m2
    assert k_sf > k_p


@pytest.mark.parametrize("bad", [
    dict(throat_shape_factor=[0.02]),  # one without the other
    dict(throat_shape_factor=[np.nan], pore_shape_factor=[0.03, 0.03]),
    dict(throat_shape_factor=[-0.01], pore_shape_factor=[0.03, 0.03]),
    dict(throat_shape_factor=[0.1], pore_shape_factor=[0.03, 0.03]),  # above the circle's 1/(4 pi)
    dict(conductance="shape_factor"),  # no shape factors
    dict(conductance="ellipse"),
    dict(throat_shape_factor=[0.02], pore_shape_factor=[0.03, 0.03], throat_duct_fraction=[[0.2, 0.5, 0.2]]),
    dict(throat_shape_factor=[0.02], pore_shape_factor=[0.03, 0.03], throat_duct_fraction=[[0.0, 0.5, 0.5]]),
])
def test_bad_shape_fields_are_refused(bad):
    with pytest.raises(InputError):
        _two_pores(**bad)


def test_invasion_uses_msp_entry_pressures():
    G = 0.03
    net = _two_pores(pore_shape_factor=[CIRCLE_SHAPE_FACTOR] * 2, throat_shape_factor=[G])
    fl = Fluids()
    ip = invasion_percolation(net, fl, "x")
    pe_t = fl.sigma * (1 + 2 * math.sqrt(math.pi * G)) / 2e-6  # theta = 0: F_d = 1
    assert ip.pore_entry_pressure[1] == pytest.approx(pe_t, rel=1e-12)
    paper = invasion_percolation(net.with_conductance("paper"), fl, "x")
    assert paper.pore_entry_pressure[1] == pytest.approx(2 * fl.sigma / 2e-6, rel=1e-12)


def test_extracted_lattice_sections_are_the_voxel_staircase():
    lat = sphere_lattice(n=(2, 2, 2), spacing=18, pore_radius=6.0, throat_radius=3.0)
    ext = extract_network(lat.image)
    net, vs = ext.network, lat.image.voxel_size
    assert net.conduit_model == "shape_factor"
    # the voxelised circle of radius 3 on a voxel centre: 29 pixels; its staircase's inscribed radius
    # is the distance to the nearest solid pixel's corner, (2.5, 0.5) from the axis
    r = math.hypot(2.5, 0.5)
    np.testing.assert_allclose(net.throat_radius, r * vs, rtol=1e-12)
    np.testing.assert_allclose(ext.sections["area"], 29 * vs**2, rtol=1e-12)
    np.testing.assert_allclose(net.throat_shape_factor, r * r / (4 * 29), rtol=1e-12)
    np.testing.assert_allclose(net.throat_duct_fraction.sum(axis=1), 1.0, rtol=1e-12)
    paper = extract_network(lat.image, conductance="paper").network
    assert paper.conduit_model == "paper"


# ------------------------------------------------------------------------------------------
# Files: round trips, old files, bad values
# ------------------------------------------------------------------------------------------
def test_npz_and_statoil_round_trips_keep_the_model(tmp_path):
    from porefsi.network.convert import load_network, read_statoil, save_network, write_statoil

    lat = sphere_lattice(n=(3, 2, 2), spacing=16, pore_radius=5.0, throat_radius=2.0)
    net = extract_network(lat.image).network
    rng = np.random.default_rng(1)  # sections of every class (the lattice's are all circles)
    net = net.replace(throat_shape_factor=rng.uniform(0.02, 0.079, net.n_throats),
                      pore_shape_factor=rng.uniform(0.02, 0.079, net.n_pores))
    k = absolute_permeability(net, "x").k_m2
    back = load_network(save_network(net, tmp_path / "n.npz"))
    assert back.conduit_model == "shape_factor"
    np.testing.assert_array_equal(back.throat_shape_factor, net.throat_shape_factor)
    np.testing.assert_array_equal(back.throat_duct_fraction, net.throat_duct_fraction)
    assert absolute_permeability(back, "x").k_m2 == pytest.approx(k, rel=1e-12)
    paper = load_network(save_network(net.with_conductance("paper"), tmp_path / "p.npz"))
    assert paper.conduit_model == "paper" and paper.has_shape_factors
    write_statoil(net, tmp_path / "st", "x")
    st = read_statoil(tmp_path / "st", voxel_size=net.voxel_size)
    assert st.conduit_model == "shape_factor"
    assert absolute_permeability(st, "x").k_m2 == pytest.approx(k, rel=1e-9)


def test_format_1_files_load_with_the_paper_model(tmp_path):
    from porefsi.network.convert import load_network, to_openpnm

    lat = sphere_lattice(n=(2, 2, 2), spacing=16, pore_radius=5.0, throat_radius=2.0)
    d = to_openpnm(extract_network(lat.image).network)
    d["porefsi.format_version"] = np.int64(1)
    for key in ("porefsi.has_shape_factors", "porefsi.conductance", "porefsi.throat_duct_fraction"):
        d.pop(key)
    np.savez(tmp_path / "old.npz", **d)
    assert load_network(tmp_path / "old.npz").conduit_model == "paper"


@pytest.mark.parametrize("key, value", [
    ("throat.hydraulic_size_factors", np.nan),
    ("throat.conduit_lengths", 0.0),
    ("throat.diameter", -1e-6),
    ("throat.shape_factor", np.nan),
])
def test_bad_file_values_are_a_network_error(tmp_path, key, value):
    from porefsi.errors import NetworkError
    from porefsi.network.convert import load_network, to_openpnm

    lat = sphere_lattice(n=(2, 2, 2), spacing=16, pore_radius=5.0, throat_radius=2.0)
    d = to_openpnm(extract_network(lat.image).network)
    a = np.array(d[key], dtype=float)
    a.reshape(a.shape[0], -1)[1, 0] = value
    d[key] = a
    np.savez(tmp_path / "bad.npz", **d)
    with pytest.raises(NetworkError, match=key.replace(".", r"\.")) as err:
        load_network(tmp_path / "bad.npz")
    assert "\n" not in str(err.value) and "re-extract" in str(err.value)
