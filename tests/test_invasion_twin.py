"""porefsi.flow.invasion against its naive twin (tests/reference/invasion_ref.py).

The twin shares nothing with the library (no DrainageGraph, no numba trapping kernel, no
Fluids.capillary_pressure): the entry pressures are its own Young-Laplace closed form, so a
wrong threshold (a throat diameter taken for its radius, a missing factor 2 or cos(theta)) or a
wrong trapping rule shows up as a different sequence, entry pressure or saturation.
"""

import dataclasses

import numpy as np
import pytest

from porefsi.flow.fluids import Fluids
from porefsi.flow.invasion import invasion_percolation
from porefsi.network.lattice import lattice_network
from tests.reference.invasion_ref import invasion_ref_for

SPACING = 1e-4


def _cut(net, rng, fraction):
    """The network with a random ``fraction`` of its throats removed (isolated and dead-end clusters)."""
    keep = rng.random(net.n_throats) >= fraction
    return dataclasses.replace(
        net, throat_conns=net.throat_conns[keep], throat_radius=net.throat_radius[keep],
        throat_length=net.throat_length[keep], throat_pore_length=net.throat_pore_length[keep],
        throat_volume=net.throat_volume[keep])


def _assert_same(ip, ref):
    np.testing.assert_array_equal(ip.pore_sequence, ref["sequence"])
    np.testing.assert_allclose(ip.pore_entry_pressure, ref["entry"], rtol=1e-14, atol=0)
    np.testing.assert_array_equal(ip.throat_sequence, ref["via"])
    np.testing.assert_array_equal(ip.trapped, ref["trapped"])
    assert ip.breakthrough_step == ref["breakthrough"]
    np.testing.assert_allclose(ip.capillary_pressure, ref["pc"], rtol=1e-14, atol=0)
    np.testing.assert_allclose(ip.sw, ref["sw"], rtol=0, atol=1e-14)


CASES = [  # (shape, seed, removed throat fraction, contact angle, axis)
    ((10, 10, 1), 1, 0.0, 0.0, 0),
    ((12, 9, 1), 3, 0.3, 30.0, 1),
    ((6, 5, 4), 2, 0.0, 0.0, 2),
    ((7, 6, 5), 4, 0.35, 60.0, 0),
]


@pytest.mark.parametrize("shape, seed, cut, theta, axis", CASES)
@pytest.mark.parametrize("trapping", [True, False])
def test_invasion_percolation_equals_naive_twin(shape, seed, cut, theta, axis, trapping):
    rng = np.random.default_rng(seed)
    net = lattice_network(shape, SPACING, rng)
    if cut:
        net = _cut(net, rng, cut)
    fl = Fluids(sigma=0.025, theta_deg=theta)
    ref = invasion_ref_for(net, fl, axis=axis, trapping=trapping)
    ip = invasion_percolation(net, fl, axis="xyz"[axis], trapping=trapping)
    _assert_same(ip, ref)
    # the cases exercise what they are meant to: trapping traps, cuts drop non-spanning pores
    assert (sum(ref["trapped"]) > 0) == trapping
    if cut:
        assert 0 < sum(ref["keep"]) < net.n_pores
    stopped = invasion_percolation(net, fl, axis="xyz"[axis], trapping=trapping, stop_at_breakthrough=True)
    ref_bt = invasion_ref_for(net, fl, axis=axis, trapping=trapping, stop_at_breakthrough=True)
    _assert_same(stopped, ref_bt)
