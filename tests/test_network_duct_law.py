"""The duct law of elongated sections against closed forms (the rectangle series, exact pixel flows)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from porefsi.network.geometry import (
    TRIANGLE_MAX_G,
    duct_conductance_factor,
    rectangle_conductance_factor,
    tangential_conductance_factor,
)
from tests.reference.stokes_ref import prism_flow_rate


@pytest.mark.parametrize("a, b", [(2, 2), (2, 5), (3, 12), (1, 10)])
def test_rectangle_law_is_the_exact_flow_of_a_pixel_rectangle(a, b):
    # a pixel rectangle is exactly a rectangle: its Poisson flow (naive twin) is the closed form
    want = prism_flow_rate(np.ones((a, b), bool), refine=(8, 16))
    assert rectangle_conductance_factor(float(a), float(b)) == pytest.approx(want, rel=2e-3)
    assert rectangle_conductance_factor(float(a), float(b)) == pytest.approx(
        rectangle_conductance_factor(float(a), float(b), n_terms=200), rel=1e-6)


def test_elongated_sections_take_the_mean_of_the_triangle_and_rectangle_laws():
    r = 1.5e-6
    # at and above the equilateral triangle's G: Valvatne-Blunt (exact for circle, square, triangle)
    for G in (TRIANGLE_MAX_G, 0.06, 1 / 16, 0.07, 1 / (4 * math.pi)):
        assert duct_conductance_factor(r, G) == tangential_conductance_factor(r, G)
    # a slit of half-aperture r and width w: A = 2 r w, G = r^2 / (4 A) (as measured)
    for w in (10 * r, 40 * r):
        A = 2 * r * w
        G = r * r / (4 * A)
        vb = 0.6 * G * A * A  # the triangle law, k = 3/5
        exact = (2 * r) ** 3 * w / 12 * (1 - 0.630 * 2 * r / w)  # thin-slit asymptote (error < 1e-3 here)
        got = duct_conductance_factor(r, G)
        assert got == pytest.approx(math.sqrt(vb * exact), rel=2e-3)
        # Valvatne-Blunt alone reads a slit at 0.45-0.51 of it; the mean at 0.67-0.72 (sqrt of that)
        assert vb / exact < 0.52
        assert 0.66 < got / exact < 0.73
    # just below the equilateral triangle's G the mean is 1.077x the triangle law (rectangle 1.16x)
    G = TRIANGLE_MAX_G * (1 - 1e-6)
    ratio = duct_conductance_factor(r, G) / tangential_conductance_factor(r, G)
    assert ratio == pytest.approx(math.sqrt(rectangle_conductance_factor(2 * r, r / (8 * G))
                                            / tangential_conductance_factor(r, G)), rel=1e-12)
    assert 1.05 < ratio < 1.10
