"""Permeability of an extracted bundle of straight tubes against the Stokes bounds of the voxelised image.

``cylinder_bundle`` gives two rigorous bounds on the exact Stokes permeability of its voxelised tubes
(``permeability_bounds_m2``): below, Hagen-Poiseuille in each tube's largest inscribed disc (the flow
rate grows with the domain); above, Saint-Venant's inequality (the disc carries the most flow of all
sections of equal area; Polya & Szego, Isoperimetric Inequalities in Mathematical Physics, 1951),
pi r_eq^4 / 8 per tube with r_eq = sqrt(A_voxels / pi).

The extracted network has one more, stated, source of excess: its pore and throat radius is the
digital radius ``R + 1/(4R)`` of a digitised disc of integer radius R (docs/extraction.md, "Digital
radius"), larger than the equal-area radius r_eq (2.118 vs 2.034 voxels for R = 2, 6.041 vs 5.997 for
R = 6). Tubes of the extracted radii spanning the box carry k_HP(R_ext) = sum pi R_ext^4 / 8 / A_box,
which is ``sum R_ext^4 / sum r_eq^4`` (= 1.046 here, computed below from the image, not assumed) times
the upper bound. The network's k can only reach that value if its flow path is the box length: the
boundary-conduit model makes it the box length up to the R/4 floor at each end, so the test bounds are
``lower <= k <= upper * sum R_ext^4 / sum r_eq^4``. Imposing the reservoir pressures at the face pore
centres (``boundary="centre"``) shortens the path to the centre-to-centre distance (39 of 48 voxels for
R = 6) while Darcy's law divides by the box length: k then exceeds even that bound.
"""

import numpy as np
import pytest
from scipy import ndimage

from porefsi.flow.permeability import absolute_permeability
from porefsi.image.synthetic import cylinder_bundle
from porefsi.network.extract import extract_network

RADII = (2, 3, 4, 6)  # voxels


def _bundle(length, axis="z"):
    b = cylinder_bundle(radii_vox=RADII, axis=axis, length=length)
    net = extract_network(b.image).network
    ax = b.axis
    others = [a for a in range(3) if a != ax]
    # Equal-area radius of each voxelised tube section, from the image itself.
    section = np.take(b.image.phases, 0, axis=ax)
    lab, _ = ndimage.label(section)
    r_eq = np.array([np.sqrt(np.sum(lab == lab[tuple(c)]) / np.pi) for c in b.centres_vox]) * b.image.voxel_size
    # Extracted radius of each tube: largest pore on the tube's axis.
    cross = (net.pore_coords[:, others] - net.origin[others]) / net.voxel_size - 0.5
    r_ext = np.array([net.pore_radius[np.all(np.isclose(cross, c), axis=1)].max() for c in b.centres_vox])
    radius_factor = float(np.sum(r_ext**4) / np.sum(r_eq**4))
    return b, net, radius_factor


@pytest.mark.parametrize(("length", "axis"), [(48, "z"), (48, "x"), (24, "y")])
def test_conduit_boundary_within_voxel_stokes_bounds_and_centre_biased(length, axis):
    b, net, radius_factor = _bundle(length, axis)
    lower, upper = b.permeability_bounds_m2
    # The measured radius is the staircase's inscribed one (the nearest solid voxel cube) with its
    # sub-voxel correction, about the equal-area radius here: a few per cent, not a free fudge.
    assert 0.9 < radius_factor < 1.05
    k = absolute_permeability(net, axis).k_m2
    k_centre = absolute_permeability(net, axis, boundary="centre").k_m2
    assert lower <= k <= upper * max(radius_factor, 1.0)
    assert k / upper == pytest.approx(1.0, abs=0.05), (k / upper, radius_factor)
    # The centre condition is biased: above the upper bound, by more than the radius excess accounts for
    # (measured 1.20x upper * radius_factor at 48 voxels, 1.72x at 24, with the extraction of 2026-12-01;
    # 1.09x at 48 since the hierarchy's core skipping, which places the tubes' pores differently).
    assert k_centre > 1.05 * upper * radius_factor


def test_conduit_k_is_intrinsic_to_the_tubes_not_the_sample_length():
    """Straight tubes: k must not depend on the sample length. The conduit boundary keeps it within the R/4
    floor (at most R_max / 4 per end over 24 voxels, i.e. < 15 %; measured 1.8 %); the centre boundary
    loses a different fraction of the length at each sample length (measured 44 % change)."""
    ks = {}
    for length in (24, 48):
        _, net, _ = _bundle(length)
        ks[length] = [absolute_permeability(net, "z", boundary=bd).k_m2 for bd in ("conduit", "centre")]
    ratio_conduit = ks[24][0] / ks[48][0]
    ratio_centre = ks[24][1] / ks[48][1]
    assert ratio_conduit == pytest.approx(1.0, abs=0.03)
    assert ratio_centre > 1.3


def test_short_bundle_pores_on_both_faces():
    """An 8-voxel bundle: the two largest tubes are single pores touching both faces. With boundary
    conduits each gets both links and k stays inside the bounds; the centre condition cannot be posed."""
    b, net, radius_factor = _bundle(8)
    assert np.any(net.inlet("z") & net.outlet("z"))
    lower, upper = b.permeability_bounds_m2
    res = absolute_permeability(net, "z")
    assert lower <= res.k_m2 <= upper * max(radius_factor, 1.0)
    assert res.info["mass_balance_error"] < 1e-12
