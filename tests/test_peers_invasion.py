"""Invasion order against OpenPNM's InvasionPercolation (peers env), before breakthrough.

Our invasion percolation without trapping against OpenPNM's, and the dynamic model at Ca = 1e-8
against OpenPNM's with trapping (``set_outlet_BC`` + ``apply_trapping``). Run with
``pytest -m peers tests/test_peers_invasion.py`` where openpnm is installed (tested with 3.6.4).
"""

import numpy as np
import pytest

from porefsi.flow.drainage import DrainageSimulator
from porefsi.flow.fluids import Fluids
from porefsi.flow.invasion import invasion_percolation
from porefsi.network.lattice import lattice_network

pytestmark = pytest.mark.peers

SPACING = 1e-4


def test_invasion_order_matches_openpnm(rng):
    op = pytest.importorskip("openpnm")
    net = lattice_network((8, 8, 3), SPACING, rng)
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


def _openpnm_order_with_trapping(op, net, fl):
    """OpenPNM's invasion order before breakthrough, trapped pores removed, on porefsi's thresholds.

    The thresholds are written down here from the model's definitions, not taken from porefsi's
    graph: an interior throat opens at ``max(P_e, P_c,b(i), P_c,b(j))`` (Young-Laplace on the
    throat and on both pore bodies), and a virtual inlet pore (OpenPNM's single inlet) joins every
    inlet-face pore through a throat at that pore's body pressure, as the dynamic model's inlet
    node does. OpenPNM's IP invades without trapping; ``apply_trapping`` (Masson's reverse
    invasion, outlets from ``set_outlet_BC``) then removes the pores that were cut off from the
    outlet when invaded. Invasion percolation with trapping invades the other pores in the same
    order (a trapped cluster, entered or not, borders only invaded pores), so this is the order of
    IP with trapping.
    """
    n = net.n_pores
    c = net.throat_conns
    inlet = np.flatnonzero(net.inlet("x"))
    outlet = np.flatnonzero(net.outlet("x"))
    pcb = fl.capillary_pressure(net.pore_radius)
    thr = np.maximum(fl.capillary_pressure(net.throat_radius), np.maximum(pcb[c[:, 0]], pcb[c[:, 1]]))
    coords = np.vstack([net.pore_coords, [[-SPACING, 0.0, 0.0]]])
    conns = np.vstack([c, np.column_stack([np.full(inlet.size, n), inlet])])
    pn = op.network.Network(coords=coords, conns=conns)
    phase = op.phase.Phase(network=pn)
    phase["throat.entry_pressure"] = np.concatenate([thr, pcb[inlet]])
    ip = op.algorithms.InvasionPercolation(network=pn, phase=phase)
    ip.set_inlet_BC(pores=[n])
    ip.set_outlet_BC(pores=outlet)
    ip.run()
    seq = np.array(ip["pore.invasion_sequence"], dtype=float)  # a copy: apply_trapping edits in place
    seq_bt = seq[outlet].min()  # the first outlet pore invaded
    ip.apply_trapping()
    trapped = np.asarray(ip["pore.trapped"])[:n]
    seq = seq[:n]
    before = np.flatnonzero((seq > 0) & (seq <= seq_bt) & ~trapped)
    return before[np.argsort(seq[before], kind="stable")], int(np.count_nonzero(trapped[seq < seq_bt]))


@pytest.mark.parametrize("shape", [(10, 10, 1), (8, 8, 3), (6, 5, 4)])
def test_dynamic_invasion_order_at_ca_1e_8_matches_openpnm_with_trapping(shape):
    # DESIGN.md §5: at low capillary number the dynamic model fills the pores in the order of
    # invasion percolation with trapping; OpenPNM's InvasionPercolation + apply_trapping is the
    # independent peer (same thresholds, same inlet and outlet faces), compared up to breakthrough
    op = pytest.importorskip("openpnm")
    net = lattice_network(shape, SPACING, np.random.default_rng(20261122))
    fl = Fluids()
    theirs, n_trapped = _openpnm_order_with_trapping(op, net, fl)
    rate = 1e-8 * fl.sigma * float(np.prod(net.extent[1:])) / fl.mu_n  # Ca = mu_n (Q / A_face) / sigma
    sim = DrainageSimulator(net, fl, rate=rate)
    sim.advance_to(1e12, stop_at_breakthrough=True)
    t = sim.invasion_time()
    mine = np.argsort(np.where(np.isnan(t), np.inf, t), kind="stable")[: int(np.isfinite(t).sum())]
    # OpenPNM invades 1, 12 and 1 pores before breakthrough that apply_trapping removes (40, 107 and
    # 52 pores compared): without trapping on both sides the orders would differ
    assert n_trapped > 0
    np.testing.assert_array_equal(mine, theirs)
