"""Carrying a drainage state onto a network of different topology (DrainageSimulator.remap)."""

import numpy as np
import pytest

from porefsi.errors import InputError
from porefsi.flow.drainage import DrainageSimulator
from porefsi.flow.fluids import Fluids
from porefsi.flow.state import PORE_FILLING, PORE_FULL
from porefsi.network.lattice import lattice_network

SPACING = 1e-4


def _rate(net, fl, ca):
    return ca * fl.sigma * float(np.prod(net.extent[1:])) / fl.mu_n


def _merge(net, i, j):
    """Merge pore j into neighbouring pore i (volume-weighted centre, summed volume, throats rewired)."""
    keep = np.flatnonzero(np.arange(net.n_pores) != j)
    new_id = np.full(net.n_pores, -1)
    new_id[keep] = np.arange(keep.size)
    new_id[j] = new_id[i]
    c = new_id[net.throat_conns]
    ok = c[:, 0] != c[:, 1]
    c = np.sort(c[ok], axis=1)
    _, first = np.unique(c, axis=0, return_index=True)
    t = np.flatnonzero(ok)[np.sort(first)]
    c = np.sort(new_id[net.throat_conns[t]], axis=1)
    vol = net.pore_volume[keep].copy()
    vol[new_id[i]] += net.pore_volume[j]
    R = net.pore_radius[keep].copy()
    R[new_id[i]] = max(net.pore_radius[i], net.pore_radius[j])
    faces = net.pore_faces[keep].copy()
    faces[new_id[i]] |= net.pore_faces[j]
    tpl = net.throat_pore_length[t]
    swap = new_id[net.throat_conns[t, 0]] > new_id[net.throat_conns[t, 1]]
    tpl = np.where(swap[:, None], tpl[:, ::-1], tpl)
    merged = net.replace(pore_coords=net.pore_coords[keep], pore_radius=R, pore_volume=vol,
                         pore_faces=faces, throat_conns=c, throat_radius=net.throat_radius[t],
                         throat_length=net.throat_length[t], throat_pore_length=tpl,
                         throat_volume=net.throat_volume[t])
    return merged, new_id


def test_identity_remap_continues_exactly(rng):
    net = lattice_network((8, 6, 2), SPACING, rng)
    fl = Fluids()
    rate = _rate(net, fl, 1e-7)
    ref = DrainageSimulator(net, fl, rate=rate)
    t_bt = DrainageSimulator(net, fl, rate=rate).advance_to(1e9, stop_at_breakthrough=True).breakthrough_time
    s0 = ref.advance_to(0.4 * t_bt)
    assert ((s0.pore_state == PORE_FULL).sum() > 3) and (s0.pore_state == PORE_FILLING).any()
    sim = ref.remap(net, s0.nw_saturation, invasion_time=ref.invasion_time())
    s1 = sim.state
    np.testing.assert_array_equal(s1.pore_state, s0.pore_state)
    # every throat the original run invaded is invaded; remap also marks throats between two full
    # pores (non-wetting conduits either way, so this does not change the flow)
    assert np.all(s1.throat_invaded[s0.throat_invaded])
    np.testing.assert_array_equal(s1.throat_state, s0.throat_state)
    assert s1.deformation_volume == 0.0 and s1.mass_balance_error <= 1e-12
    assert sim.last_remap["n_stranded"] == 0
    np.testing.assert_allclose(s1.pressure, s0.pressure, rtol=1e-9, atol=1e-9 * np.nanmax(s0.pressure))
    a = ref.advance_to(1e9, stop_at_breakthrough=True)
    b = sim.advance_to(1e9, stop_at_breakthrough=True)
    np.testing.assert_allclose(sim.invasion_time(), ref.invasion_time(), rtol=1e-9)
    assert b.breakthrough_time == pytest.approx(a.breakthrough_time, rel=1e-12)
    np.testing.assert_allclose(b.nw_saturation, a.nw_saturation, rtol=1e-9, atol=1e-12)


def test_remap_onto_merged_pore_network_conserves_mass(rng):
    net = lattice_network((7, 6, 2), SPACING, rng)
    fl = Fluids()
    rate = _rate(net, fl, 1e-6)
    t_bt = DrainageSimulator(net, fl, rate=rate).advance_to(1e9, stop_at_breakthrough=True).breakthrough_time
    sim = DrainageSimulator(net, fl, rate=rate)
    st = sim.advance_to(0.7 * t_bt)
    # merge a full pore with a neighbour, and perturb all volumes (a deformed re-extraction)
    full = np.flatnonzero(st.pore_state == PORE_FULL)
    i = int(full[len(full) // 2])
    c = net.throat_conns
    j = int(np.concatenate([c[c[:, 0] == i, 1], c[c[:, 1] == i, 0]])[0])
    merged, new_id = _merge(net, i, j)
    merged = merged.replace(pore_volume=merged.pore_volume * rng.uniform(0.95, 1.05, merged.n_pores))
    vn_old = st.nw_saturation * net.pore_volume
    vn_new = np.bincount(new_id, vn_old, minlength=merged.n_pores)
    sat_new = np.minimum(vn_new / merged.pore_volume, 1.0)
    new = sim.remap(merged, sat_new)
    s1 = new.state
    assert s1.mass_balance_error <= 1e-12
    stored_old = st.stored_nw_volume
    assert s1.deformation_volume == pytest.approx(st.deformation_volume + s1.stored_nw_volume - stored_old,
                                                  rel=1e-12, abs=1e-30)
    assert s1.injected_volume == st.injected_volume and s1.t == st.t
    assert np.all((s1.nw_saturation >= 0) & (s1.nw_saturation <= 1))
    # continuing keeps every invariant
    s2 = new.advance_to(st.t * 1.5)
    assert s2.mass_balance_error <= 1e-12
    assert np.all((s2.nw_saturation >= 0) & (s2.nw_saturation <= 1))
    assert s2.stored_nw_volume >= s1.stored_nw_volume


def test_remap_strands_disconnected_non_wetting_and_reports_it(rng):
    net = lattice_network((6, 5, 1), SPACING, rng)
    sim = DrainageSimulator(net, rate=1e-12)
    sat = np.zeros(net.n_pores)
    sat[net.n_pores // 2 + 2] = 0.5  # an interior pore, not attached to any full pore
    new = sim.remap(net, sat)
    assert new.last_remap["n_stranded"] == 1
    st = new.state
    assert st.stored_nw_volume == 0.0
    assert st.deformation_volume == 0.0 and st.mass_balance_error == 0.0


@pytest.mark.parametrize("bad", [np.full(3, 0.5), "nan", "neg", "big"])
def test_remap_rejects_bad_saturations(rng, bad):
    net = lattice_network((4, 4, 1), SPACING, rng)
    sim = DrainageSimulator(net, rate=1e-12)
    sat = {"nan": np.full(net.n_pores, np.nan), "neg": np.full(net.n_pores, -0.1),
           "big": np.full(net.n_pores, 1.5)}.get(bad, bad) if isinstance(bad, str) else bad
    with pytest.raises(InputError, match="saturation"):
        sim.remap(net, sat)
