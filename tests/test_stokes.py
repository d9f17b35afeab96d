"""Voxel Stokes permeability (porefsi.stokes): closed forms, the naive twin, conservation, invariances.

Truths used: plane Poiseuille, Hagen-Poiseuille, the square-duct series (White), the exact flow
through the staircase cross-section of a voxelised tube (tests/reference/stokes_ref.prism_flow_rate),
Zick & Homsy's (1982) sphere-array drag, and a loop-by-loop twin of the discretisation.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from porefsi.errors import ConvergenceError, InputError, NetworkError
from porefsi.image import VoxelImage
from porefsi.stokes import StokesResult, voxel_permeability
from porefsi.units import MILLIDARCY
from tests.reference.stokes_ref import (
    disk,
    naive_permeability,
    plates_flow_rate_per_width,
    prism_flow_rate,
    rectangular_duct_flow_rate,
    tube_flow_rate,
    zick_homsy_permeability,
)


def _k(a, axis="x", **kw) -> float:
    """Permeability in voxel units (voxel size 1 m)."""
    kw.setdefault("rtol", 1e-10)
    return voxel_permeability(VoxelImage(np.asarray(a, np.uint8), 1.0), axis, **kw).k_m2


def _prism(section, length=2):
    return np.repeat(np.asarray(section, bool)[None], length, axis=0).astype(np.uint8)


def test_millidarcy_is_the_literal():
    assert MILLIDARCY == 9.869233e-16


# --------------------------------------------------------------------------------- closed forms


@pytest.mark.parametrize("n", [2, 3, 5, 8])
def test_plane_poiseuille_error_is_exactly_two_over_n_squared(n):
    """Plates n voxels apart: the ghost-wall closure gives Q = Q_exact (1 + 2/n^2) exactly.

    (The discrete profile is the parabola plus G h^2 / 8 - uniform slip from the linear ghost -,
    and the face sum adds the midpoint-rule error G H h^2 / 24.)
    """
    a = np.zeros((3, n + 2, 4), np.uint8)
    a[:, 1:-1, :] = 1  # solid plates in the image, periodic along z
    k = _k(a, boundary="periodic", lateral="periodic", wall="ghost")
    q_per_width = k * a.shape[1]  # k = Q / (A G) with A = (n + 2) x width, G = 1, per unit width
    exact = plates_flow_rate_per_width(n)
    assert q_per_width / exact - 1 == pytest.approx(2 / n**2, rel=1e-6)


@pytest.mark.parametrize("n", [1, 2, 3, 5, 8])
def test_channel_closure_is_exact_for_plane_poiseuille(n):
    """The closure's construction (cell-averaged plane Poiseuille): exact flux at every gap, also 1 voxel;
    the plates lie along y and along z, so both tangential axes of the x faces are exercised."""
    a = np.zeros((3, n + 2, 4), np.uint8)
    a[:, 1:-1, :] = 1
    for b in (a, np.swapaxes(a, 1, 2)):
        k = _k(b, boundary="periodic", lateral="periodic", wall="channel")
        assert k * (n + 2) / plates_flow_rate_per_width(n) == pytest.approx(1.0, rel=1e-9)


def test_channel_wall_weights():
    from porefsi.stokes._kernels import WALL_CHANNEL, WALL_GHOST, wall_weight

    assert [wall_weight(n, WALL_CHANNEL) for n in (1, 2, 3, 4)] == pytest.approx([6.0, 3.0, 18 / 7, 2.4])
    assert wall_weight(10**6, WALL_CHANNEL) == pytest.approx(2.0, rel=1e-6)
    assert wall_weight(1, WALL_GHOST) == wall_weight(7, WALL_GHOST) == 2.0


@pytest.mark.parametrize("buffer", [0, 1, 2, 3])
def test_pressure_boundary_is_exact_for_fully_developed_flow(buffer):
    """A duct filling the box: buffers are the same duct, so every boundary treatment must agree."""
    a = np.ones((5, 4, 6), np.uint8)
    periodic = _k(a, boundary="periodic")
    assert _k(a, boundary="pressure", buffer=buffer) == pytest.approx(periodic, rel=1e-7)


def test_square_duct_matches_series_at_second_order():
    errs = {}
    for w in (4, 8, 16):
        k = _k(np.ones((2, w, w)), boundary="periodic", wall="ghost")
        exact = rectangular_duct_flow_rate(w / 2, w / 2) / w**2
        errs[w] = k / exact - 1
    assert 0 < errs[16] < 0.02
    for lo, hi in ((4, 8), (8, 16)):
        order = math.log(errs[lo] / errs[hi], 2)
        assert 1.8 < order < 2.2, errs


def test_square_duct_channel_closure_beats_ghost_and_converges():
    """Not built into the closure: the duct's corners make it 2-D. Errors against White's series."""
    errs = {w: {n: _k(np.ones((2, n, n)), boundary="periodic", wall=w) / (rectangular_duct_flow_rate(n / 2, n / 2)
                                                                          / n**2) - 1 for n in (1, 2, 4, 8)}
            for w in ("ghost", "channel")}
    assert errs["ghost"][1] == pytest.approx(2.5568, abs=1e-3) and errs["ghost"][2] == pytest.approx(0.7784, abs=1e-3)
    assert errs["channel"][1] == pytest.approx(0.1856, abs=1e-3)  # one voxel: 6 + 6 on both axes
    assert errs["channel"][2] == pytest.approx(0.1856, abs=1e-3)  # two voxels: the same 2-D problem, scaled
    assert 0.06 < errs["channel"][4] < 0.07 and 0.015 < errs["channel"][8] < 0.02
    for n in (1, 2, 4, 8):
        assert 0 < errs["channel"][n] < errs["ghost"][n] / 3


@pytest.mark.parametrize("radius", [1.5, 2, 3])
def test_channel_closure_halves_the_tube_error_against_the_staircase(radius):
    """Thin voxelised tubes, the rock's throat sizes: the exact staircase flow is the truth."""
    sec = disk(radius, "corner")
    stair = prism_flow_rate(sec, refine=(4, 8))
    err = {w: _k(_prism(sec), boundary="periodic", wall=w) * sec.size / stair - 1 for w in ("ghost", "channel")}
    assert 0 < err["channel"] < 0.6 * err["ghost"]
    assert err["channel"] < (0.28 if radius < 3 else 0.14)


def test_rectangular_duct_series_against_plates_limit():
    """The series itself: a very flat duct tends to plates (per unit width)."""
    q = rectangular_duct_flow_rate(1.0, 200.0)
    assert q / (2 * 200.0) == pytest.approx(plates_flow_rate_per_width(2.0), rel=0.01)


@pytest.mark.parametrize("radius,centre", [(3, "corner"), (3, "centre"), (8, "corner"), (8, "centre")])
def test_hagen_poiseuille_tube(radius, centre):
    """Voxelised tubes, ghost closure: within 6 % of Poiseuille for a circle of the same area (the voxel area
    itself differs from pi R^2 by up to 13 % at R = 3), and above the exact flow through the
    staircase section (the 5-point stencil misses the solid corners diagonal to a face)."""
    sec = disk(radius, centre)
    k = _k(_prism(sec), boundary="periodic", wall="ghost")
    q = k * sec.size
    r_eq = math.sqrt(sec.sum() / math.pi)
    assert abs(q / tube_flow_rate(r_eq) - 1) < 0.06
    stair = prism_flow_rate(sec, refine=(4, 8))
    assert 0 < q / stair - 1 < (0.30 if radius == 3 else 0.08)


def test_tube_error_against_staircase_shrinks_with_radius():
    errs = [(_k(_prism(disk(r)), boundary="periodic") * disk(r).size) / prism_flow_rate(disk(r)) - 1
            for r in (2, 4, 8)]
    assert errs[0] > errs[1] > errs[2] > 0


def _sphere_cell(n, c):
    a = n * (3 * c / (4 * math.pi)) ** (1 / 3)
    x = np.arange(n) + 0.5 - n / 2
    X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
    return (X**2 + Y**2 + Z**2 > a**2).astype(np.uint8)


@pytest.mark.parametrize("c,wall", [(0.125, "ghost"), (0.343, "ghost"), (0.5236, "ghost"), (0.125, "channel"),
                                    (0.343, "channel")])
def test_sphere_array_against_zick_homsy(c, wall):
    """Simple cubic array, 16 voxels per cell: within 10 % of Zick & Homsy (the 32-voxel sweep is slow).

    Touching spheres (c = 0.5236) are left out for the channel closure: there the voxelised contact
    is not the smooth one (at 8 voxels per cell the staircase's own converged k is 0.66-0.67 of Zick
    & Homsy's), and the channel closure, closer to the staircase, lands 17 % below the smooth value.
    """
    k = _k(_sphere_cell(16, c), boundary="periodic", lateral="periodic", rtol=1e-8, wall=wall)
    assert k / zick_homsy_permeability(c, 16) == pytest.approx(1.0, abs=0.10)


# ------------------------------------------------------------------------------ twin, conservation


CONFIGS = [
    dict(boundary="pressure", buffer=2),
    dict(boundary="pressure", buffer=0),
    dict(boundary="pressure", buffer=1, lateral="periodic"),
    dict(boundary="periodic", mirror=True),
    dict(boundary="periodic", lateral="periodic"),
]


@pytest.mark.parametrize("wall", ["ghost", "channel"])
@pytest.mark.parametrize("cfg", CONFIGS, ids=lambda c: "-".join(f"{k}={v}" for k, v in c.items()))
@pytest.mark.parametrize("axis", [0, 1, 2])
def test_matches_naive_twin(cfg, axis, wall):
    rng = np.random.default_rng(7 + axis)
    a = (rng.random((5, 4, 6)) < 0.65).astype(np.uint8)
    assert _k(a, axis, wall=wall, **cfg) == pytest.approx(naive_permeability(a, axis, wall=wall, **cfg), rel=1e-8)


def test_channel_twin_on_long_runs():
    """Runs of several faces, a periodic lateral axis and the buffers' long open lines (the random
    images above are mostly 1-2 voxel runs)."""
    a = np.zeros((6, 9, 8), np.uint8)
    a[:, 1:8, 1:5] = 1
    a[2:4, 3:6, 5:7] = 1
    a[3, 4, 1:3] = 0
    for cfg in (dict(boundary="pressure", buffer=2), dict(boundary="periodic", lateral="periodic")):
        assert _k(a, 0, wall="channel", **cfg) == pytest.approx(
            naive_permeability(a, 0, wall="channel", **cfg), rel=1e-8)


def _random_rock(shape=(14, 12, 13), seed=1, porosity=0.55):
    rng = np.random.default_rng(seed)
    from scipy import ndimage

    field = ndimage.gaussian_filter(rng.standard_normal(shape), 1.2)
    return (field < np.quantile(field, porosity)).astype(np.uint8)


def test_mass_conservation_flux_equal_on_every_cross_section():
    from porefsi.stokes._grid import assemble
    from porefsi.stokes._kernels import stokes_matvec
    from porefsi.stokes._solve import solve
    from porefsi.stokes.permeability import plane_fluxes

    a = _random_rock().astype(bool)
    pore = np.concatenate([np.ones((2, 12, 13), bool), a, np.ones((2, 12, 13), bool)])
    system = assemble(pore, open_axis=0, pressures=(18.0, 0.0))
    u, p, info = solve(system, rtol=1e-9)
    q = plane_fluxes(system, u, 0)
    assert q.shape == (19,) and q.min() > 0
    assert np.ptp(q) / q.mean() < 1e-6
    div = np.empty(system.n_u + system.n_p)  # K (u, 0) = (A u, -B u): its pressure rows are -div u
    stokes_matvec(system.tables, np.concatenate([u, np.zeros(system.n_p)]), system.n_u, div)
    assert np.abs(div[system.n_u:]).max() < 1e-7 * q.mean()
    res = voxel_permeability(VoxelImage(a.astype(np.uint8), 1.0), "x", rtol=1e-6)
    assert res.flux_spread < 1e-4 and res.converged and res.residual < 1e-4


def test_axis_permutation_and_voxel_size_scaling():
    a = _random_rock()
    k = [voxel_permeability(VoxelImage(a, 2e-6), ax, rtol=1e-9).k_m2 for ax in "xyz"]
    b = np.transpose(a, (2, 0, 1))  # array axis 0 -> 1, 1 -> 2, 2 -> 0
    kb = [voxel_permeability(VoxelImage(b, 2e-6), ax, rtol=1e-9).k_m2 for ax in "yzx"]
    np.testing.assert_allclose(kb, k, rtol=1e-6)
    assert min(abs(k[0] / k[1] - 1), abs(k[0] / k[2] - 1)) > 0.05  # the axes do differ on this image
    assert voxel_permeability(VoxelImage(a, 1e-6), "x", rtol=1e-9).k_m2 == pytest.approx(k[0] / 4, rel=1e-9)


def test_units_flow_rate_and_darcy():
    a = _random_rock()
    r1 = voxel_permeability(VoxelImage(a, 3e-6), "z", viscosity=1e-3, dp=10.0)
    r2 = voxel_permeability(VoxelImage(a, 3e-6), "z", viscosity=2e-3, dp=5.0)
    assert isinstance(r1, StokesResult)
    assert r2.k_m2 == pytest.approx(r1.k_m2, rel=1e-9)
    assert r2.flow_rate == pytest.approx(r1.flow_rate / 4, rel=1e-9)
    assert r1.k_mD == pytest.approx(r1.k_m2 / 9.869233e-16, rel=1e-15)
    assert r1.length == pytest.approx(13 * 3e-6) and r1.area == pytest.approx(14 * 12 * 9e-12)
    assert r1.flow_rate == pytest.approx(r1.k_m2 * r1.area * r1.dp / (r1.viscosity * r1.length), rel=1e-12)
    tube = _prism(disk(3), length=4)
    q = voxel_permeability(VoxelImage(tube, 1e-6), "x", boundary="periodic", viscosity=1e-3, dp=4.0,
                           rtol=1e-10).flow_rate
    expect = (_k(tube, boundary="periodic") * tube[0].size) * 1e-6**4 * (4.0 / 4e-6) / 1e-3
    assert q == pytest.approx(expect, rel=1e-8)


def test_closed_and_dead_end_pores_change_nothing():
    a = np.zeros((8, 9, 9), np.uint8)
    a[:, 2:6, 2:6] = 1
    k0 = _k(a)
    b = a.copy()
    b[3:5, 7:9, 7:9] = 1  # a closed pocket
    b[0:3, 0, 0] = 1  # a dead end open to the inlet only
    r = voxel_permeability(VoxelImage(b, 1.0), "x", rtol=1e-10)
    assert r.k_m2 == pytest.approx(k0, rel=1e-9)
    assert r.connected_porosity < r.porosity


def test_fields_are_consistent_with_the_flow_rate():
    a = _random_rock()
    r = voxel_permeability(VoxelImage(a, 1e-6), "y", boundary="periodic", mirror=True, fields=True, rtol=1e-9)
    assert r.pressure.shape == a.shape and r.velocity.shape == a.shape + (3,)
    assert np.all(np.isnan(r.pressure[a == 0])) and np.all(r.velocity[a == 0] == 0)
    # mean y-velocity over the box (faces averaged to centres) = superficial velocity Q / A
    assert r.velocity[..., 1].mean() == pytest.approx(r.flow_rate / r.area, rel=1e-6)


def test_pressure_boundary_and_mirrored_periodic_agree_on_a_rock_like_image():
    a = _random_rock((20, 12, 12), seed=3)
    kp = _k(a, rtol=1e-8)
    km = _k(a, boundary="periodic", mirror=True, rtol=1e-8)
    assert km == pytest.approx(kp, rel=0.15)


# --------------------------------------------------------------------------------------- errors


def test_bad_inputs_raise_one_line_errors():
    img = VoxelImage(np.ones((3, 3, 3), np.uint8), 1e-6)
    bad = ((dict(boundary="open"), "boundary"), (dict(lateral="slip"), "lateral"), (dict(buffer=-1), "buffer"),
           (dict(viscosity=0), "viscosity"), (dict(dp=float("nan")), "dp"), (dict(rtol=2.0), "rtol"),
           (dict(maxiter=0), "maxiter"), (dict(wall="bounce"), "wall"), (dict(refine=0), "refine"),
           (dict(walls="ghost"), "unknown voxel_permeability option"))
    for kw, word in bad:
        with pytest.raises(InputError, match=word):
            voxel_permeability(img, "x", **kw)
    with pytest.raises(InputError, match="axis"):
        voxel_permeability(img, "w")
    with pytest.raises(InputError, match="VoxelImage"):
        voxel_permeability(np.ones((3, 3, 3)), "x")
    with pytest.raises(InputError, match="no wall"):
        voxel_permeability(img, "x", boundary="periodic", lateral="periodic")
    blocked = np.ones((4, 3, 3), np.uint8)
    blocked[2] = 0
    with pytest.raises(NetworkError, match="no pore path"):
        voxel_permeability(VoxelImage(blocked, 1e-6), "x")


def test_non_convergence_raises_with_history():
    with pytest.raises(ConvergenceError, match="did not converge") as exc:
        voxel_permeability(VoxelImage(_random_rock(), 1e-6), "x", maxiter=2)
    assert len(exc.value.history) == 2


def test_a_preconditioner_that_hides_residuals_is_caught(monkeypatch):
    """MINRES stops on the preconditioned residual: a badly scaled pressure block (1e-8) makes the
    divergence residual nearly invisible to it, so the solver checks the true residual too."""
    from porefsi.stokes import _pressure

    original = _pressure.PressureMultigrid.matvec
    monkeypatch.setattr(_pressure.PressureMultigrid, "matvec", lambda self, b: 1e-8 * original(self, b))
    with pytest.raises(ConvergenceError, match="true relative residual"):
        voxel_permeability(VoxelImage(_random_rock(), 1e-6), "x")


def test_progress_log_reports_the_k_of_each_iterate(caplog):
    """With INFO logging, every 25th MINRES iteration logs its residual and the k of its iterate
    (the convergence state of an hour-long solve), converging on the k returned."""
    import logging
    import re

    img = VoxelImage(_random_rock(shape=(20, 18, 19), seed=3), 1e-6)
    with caplog.at_level(logging.INFO, logger="porefsi.stokes._solve"):
        r = voxel_permeability(img, "y", rtol=1e-10)
    pat = re.compile(r"iteration (\d+): relative preconditioned residual (\S+), k of the iterate (\S+) mD")
    rows = [(int(m[1]), float(m[2]), float(m[3])) for m in map(pat.search, caplog.messages) if m]
    assert r.iterations >= 50 and [it for it, _, _ in rows] == list(range(25, r.iterations + 1, 25))
    assert rows[-1][1] < rows[0][1]
    assert rows[-1][2] == pytest.approx(r.k_mD, rel=1e-4)
    assert abs(rows[0][2] / r.k_mD - 1) < 0.2  # a k, not a raw flux or a pressure
    with caplog.at_level(logging.WARNING, logger="porefsi.stokes._solve"):
        caplog.clear()
        voxel_permeability(img, "y")
    assert not caplog.messages
