"""Invasion order against OpenPNM's InvasionPercolation (peers env), before breakthrough."""

import numpy as np
import pytest

from porefsi.flow.fluids import Fluids
from porefsi.flow.invasion import invasion_percolation
from porefsi.network.lattice import lattice_network

pytestmark = pytest.mark.peers


def test_invasion_order_matches_openpnm(rng):
    op = pytest.importorskip("openpnm")
    net = lattice_network((8, 8, 3), 1e-4, rng)
    fl = Fluids()
    ours = invasion_percolation(net, fl, stop_at_breakthrough=True, inlet_pores_filled=True, trapping=False)
    pn = op.network.Network(coords=net.pore_coords, conns=net.throat_conns)
    phase = op.phase.Phase(network=pn)
    phase["throat.entry_pressure"] = fl.capillary_pressure(net.throat_radius)
    ip = op.algorithms.InvasionPercolation(network=pn, phase=phase)
    ip.set_inlet_BC(pores=np.flatnonzero(net.inlet("x")))
    ip.run()
    seq = np.asarray(ip["pore.invasion_sequence"])
    n_in = int(net.inlet("x").sum())
    k = ours.breakthrough_step + 1
    mine = np.argsort(np.where(ours.pore_sequence < 0, 2**62, ours.pore_sequence))[n_in:k]
    theirs = np.argsort(np.where(seq < 0, 2**62, seq), kind="stable")
    theirs = [p for p in theirs if not net.inlet("x")[p]][: k - n_in]
    np.testing.assert_array_equal(mine, theirs)
