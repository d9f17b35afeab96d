"""Constriction lengths with the samples read at sub-voxel positions (``_constriction_lengths_subvoxel``).

Truth: a square duct between two cubic chambers, voxel-exact at every refinement, whose
staircase radius along the axis has a closed form (the duct's half-width inside it, the distance
to the mouth's rim in the chamber), so the resistance-equivalent throat length is analytic and
the same in physical units at every grid.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from porefsi.network._mb_sections import _constriction_lengths_subvoxel
from porefsi.network.extract import _distance_map
from tests.reference.sections_ref import box_walled, constriction_lengths, tube_beside_face, wall_radius_table


def _duct(f: int):
    """Chambers x in [2, 14) and [26, 38), y, z in [2, 15); a duct x in [14, 26), y, z in [7, 10); x f."""
    pore = np.zeros((40 * f, 17 * f, 17 * f), bool)
    pore[2 * f:14 * f, 2 * f:15 * f, 2 * f:15 * f] = True
    pore[26 * f:38 * f, 2 * f:15 * f, 2 * f:15 * f] = True
    pore[14 * f:26 * f, 7 * f:10 * f, 7 * f:10 * f] = True
    c = 8.5 * f - 0.5  # the axis in voxel-centre coordinates
    centre = np.array([[8.0 * f - 0.5, c, c], [32.0 * f - 0.5, c, c]])
    point = np.array([[20.0 * f - 0.5, c, c]])
    return pore, centre, point


def _analytic(f: int) -> float:
    """Throat length (voxels) of one side: 6f of duct (radius a = 1.5f), then the chamber, whose
    radius on the axis at a distance x from the mouth is sqrt(a^2 + x^2) up to R = 6f."""
    a, big, d = 1.5 * f, 6.0 * f, 12.0 * f
    xr = math.sqrt(big**2 - a**2)
    j = xr / (2 * a**2 * (a**2 + xr**2)) + math.atan(xr / a) / (2 * a**3)
    integral = 6.0 * f / a**4 + j + (d - 6.0 * f - xr) / big**4
    return (integral - d / big**4) / (a**-4 - big**-4)


def _lengths(f: int):
    pore, centre, point = _duct(f)
    dt2 = _distance_map(pore)
    tab = np.sqrt(np.maximum(np.arange(int(dt2.max()) + 1), 1)) - 0.5
    tab[0] = 0.0
    conns = np.array([[0, 1]])
    rt, rp = np.array([1.5 * f]), np.array([6.0 * f, 6.0 * f])
    got = _constriction_lengths_subvoxel(dt2, tab, centre, point, conns, rt, rp, np.zeros(3, np.int64))
    return dt2, tab, (centre, point, conns, rt, rp), got


@pytest.mark.parametrize("f", [1, 2])
def test_duct_throat_length_matches_the_closed_form_at_two_resolutions(f):
    _, _, _, (d, lt) = _lengths(f)
    np.testing.assert_allclose(d, 12.0 * f)
    want = _analytic(f)  # 6 f of duct plus about (pi / 4) a of the chamber
    np.testing.assert_allclose(lt / f, want / f, rtol=1e-3)  # 7.1519 at 1x, 2x and 3x


def test_duct_throat_length_is_the_same_in_metres_at_1x_and_2x():
    one = _lengths(1)[3][1]
    two = _lengths(2)[3][1] / 2
    np.testing.assert_allclose(two, one, rtol=1e-3)


def test_subvoxel_kernel_matches_the_twin():
    dt2, tab, (centre, point, conns, rt, rp), got = _lengths(1)
    want = constriction_lengths(dt2, lambda v: tab[v], centre.tolist(), point.tolist(), conns.tolist(),
                                rt.tolist(), rp.tolist(), 0.25, (0, 0, 0), subvoxel=True)
    np.testing.assert_allclose(got[0], want[0], rtol=1e-12)
    np.testing.assert_allclose(got[1], want[1], rtol=1e-12, atol=1e-12)


def test_subvoxel_kernel_matches_the_twin_on_an_oblique_walled_line():
    # the tube's axis 1 voxel from the y face; the sides run obliquely: samples fall off the voxel centres
    pore, centre, point, conns, rt, rp = tube_beside_face()
    dt2 = _distance_map(pore)
    walls = (1, 1, 1)
    tab = wall_radius_table(dt2.max())
    got = _constriction_lengths_subvoxel(dt2, tab, centre, point, conns, rt, rp, np.array(walls, np.int64))
    want = constriction_lengths(box_walled(pore, walls), lambda v: tab[v], centre.tolist(), point.tolist(),
                                conns.tolist(), rt.tolist(), rp.tolist(), 0.25, walls, subvoxel=True)
    np.testing.assert_allclose(got[1], want[1], rtol=1e-12, atol=1e-12)
    assert np.all((got[1] > 0.1) & (got[1] < got[0]))  # 0.255 of 5.59 voxels
