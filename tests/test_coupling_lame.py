"""A pressurised spherical cavity in an elastic block: both interfaces against the Lamé solution.

The block (side 2L, all faces clamped) lies between two clamped balls, of radius L (inscribed)
and sqrt(3) L (circumscribed). For a cavity under pressure P, a larger clamped domain is more
compliant, so the work P ΔV = f·u of the block lies between the two thick-sphere (Lamé) values

    u(a) = B (1/a² - a/b³),  B = P / (3K/b³ + 4G/a³)   (u(b) = 0, σ_rr(a) = -P),

with a the radius of a ball of the voxel cavity's volume. Linear P1 elements are stiffer than the
continuum, so only the lower bound gets a discretisation allowance.
"""

import numpy as np
import pytest

from porefsi.coupling import (
    boundary_facet_normals,
    facet_pores_from_labels,
    hull_interface,
    traction_interface,
)
from porefsi.image import VoxelImage
from porefsi.solid.bc import Fixed
from porefsi.solid.materials import make_material
from porefsi.solid.mesh import mesh_solid
from porefsi.solid.model import SolidModel
from porefsi.solid.static import solve_static

N, A_VOX, H = 20, 4.0, 1e-6
E, NU, P = 20e9, 0.28, 1e6


@pytest.fixture(scope="module")
def cavity():
    g = np.arange(N) + 0.5
    X, Y, Z = np.meshgrid(g, g, g, indexing="ij")
    cav = (X - N / 2) ** 2 + (Y - N / 2) ** 2 + (Z - N / 2) ** 2 < A_VOX**2
    mesh = mesh_solid(VoxelImage(cav.astype(np.uint8), H), coarsen=1, support_axis=None).mesh
    model = SolidModel(mesh, make_material("svk", E=E, nu=NU), [Fixed(f) for f in
                                                                 ("xmin", "xmax", "ymin", "ymax", "zmin", "zmax")])
    return cav, mesh, model


def _work(model, F):
    u, _ = solve_static(model.with_nodal_forces(F), 0.0)
    return float(np.sum(F * model.expand(u, 0.0)))


def _lame_bounds(cav):
    a = (3 * cav.sum() * H**3 / (4 * np.pi)) ** (1 / 3)
    G, K = E / (2 * (1 + NU)), E / (3 * (1 - 2 * NU))

    def work(b):
        B = P / (3 * K / b**3 + 4 * G / a**3)
        return P * 4 * np.pi * a**2 * B * (1 / a**2 - a / b**3)

    L = N / 2 * H
    return work(L), work(np.sqrt(3) * L)


def test_traction_interface_matches_lame_bounds(cavity):
    cav, mesh, model = cavity
    facets = mesh.facets_tagged("pore_wall")
    normals, _ = boundary_facet_normals(mesh.points, mesh.tets, facets)
    owner = facet_pores_from_labels(mesh.points, facets, normals, np.where(cav, 0, -1), H)
    assert np.all(owner == 0)
    itf = traction_interface(mesh.points, mesh.tets, facets, owner, 1)
    F = itf.nodal_forces([P])
    assert itf.load_balance_error([P]) < 1e-12  # closed cavity: zero resultant
    lo, hi = _lame_bounds(cav)
    w = _work(model, F)
    assert 0.95 * lo < w < hi, (lo, w, hi)


HULL_SEEDS = range(4)  # include the extremes of seeds 0-11 (seed 0: 0.982 x upper, seed 1: 0.996 x lower)


def test_hull_interface_matches_lame_bounds_for_every_seed(cavity):
    """The paper's hull operator, at several test-point seeds.

    What this pins: a cavity of radius 4 voxels in a 20^3 block (P1 mesh, coarsen 1). Here the
    hull's work lies inside the Lame bracket for every seed tried (seeds 0-11: 0.996-1.119 x the
    lower value, 0.874-0.982 x the upper) and the test checks seeds 0-3. It is *not* a property
    of the operator at every resolution: the same cavity at radius 3.2, 4.8 and 5.6 voxels in
    16^3, 24^3 and 28^3 blocks gave 0.98-1.09, 1.07-1.15 and 1.00-1.03 x the upper value (seeds
    0-3), because the operator lumps P 4 pi r_in^2 as point loads onto the ~40 % of wall nodes
    inside the enlarged hull (more compliant than a traction by an amount that depends on which
    nodes fall inside). What holds for every seed and resolution tried: exact load balance,
    radial forces (tests/test_coupling_interface.py) and a resultant below 7 % of the total
    magnitude (measured 1.7-6.6 %).
    """
    cav, mesh, model = cavity
    wall = np.zeros(mesh.n_nodes, bool)
    wall[mesh.nodes_tagged("pore_wall")] = True
    c = np.full((1, 3), N / 2 * H)
    r_in = float(np.min(np.linalg.norm(mesh.points[wall] - c, axis=1)))  # the maximal (inscribed) ball
    lo, hi = _lame_bounds(cav)
    works = []
    for seed in HULL_SEEDS:
        itf = hull_interface(c, [r_in], mesh.points, n_test_points=800, tolerance=H,
                             rng=np.random.default_rng(seed), candidates=wall)
        F = itf.nodal_forces([P])
        assert itf.load_balance_error([P]) < 1e-12  # sum of magnitudes = P 4 pi r²
        # The paper's operator is not a consistent traction: its resultant is small, not zero.
        assert np.linalg.norm(F.sum(axis=0)) / np.linalg.norm(F, axis=1).sum() < 0.1, seed
        works.append(_work(model, F))
    works = np.array(works)
    assert np.all((0.95 * lo < works) & (works < hi)), (lo, works, hi)
