"""DrainageSimulator API: bad input, disconnected networks, carrying the state onto a deformed network."""

import numpy as np
import pytest

from porefsi.errors import InputError, NetworkError
from porefsi.flow.drainage import DrainageSimulator, simulate_drainage
from porefsi.flow.fluids import Fluids
from porefsi.network.lattice import chain_network, lattice_network


@pytest.mark.parametrize("kw", [dict(mu_w=0), dict(mu_n=-1e-3), dict(sigma=0.0), dict(theta_deg=90),
                                dict(theta_deg=120.0), dict(sigma=float("nan"))])
def test_bad_fluids(kw):
    with pytest.raises(InputError):
        Fluids(**kw)


@pytest.mark.parametrize("rate", [0.0, -1e-12, float("inf")])
def test_bad_rate(rng, rate):
    with pytest.raises(InputError, match="rate"):
        DrainageSimulator(lattice_network((3, 3, 1), 1e-4, rng), rate=rate)


@pytest.mark.parametrize("solver", ["lu", "AMG", None])
def test_unknown_solver_is_an_input_error_naming_the_choices(rng, solver):
    choices = r"not one of .*'auto', 'lowrank', 'direct', 'amg', 'jacobi'"
    with pytest.raises(InputError, match=rf"solver (.*{choices}|must be set)"):
        DrainageSimulator(lattice_network((3, 3, 1), 1e-4, rng), rate=1e-12, solver=solver)


def test_no_inlet_or_outlet_on_axis(rng):
    net = lattice_network((4, 4, 1), 1e-4, rng)
    net = net.replace(pore_faces=np.zeros_like(net.pore_faces))
    with pytest.raises(NetworkError, match="face"):
        DrainageSimulator(net)


def test_disconnected_pores_are_dropped_and_counted(rng):
    net = lattice_network((5, 4, 1), 1e-4, rng)
    keep = ~np.any(net.throat_conns == 6, axis=1)  # isolate pore 6 (interior)
    sub = net.replace(throat_conns=net.throat_conns[keep], throat_radius=net.throat_radius[keep],
                      throat_length=net.throat_length[keep], throat_pore_length=net.throat_pore_length[keep],
                      throat_volume=net.throat_volume[keep])
    res = simulate_drainage(sub, rate=1e-12, t_end=5.0)
    assert res.n_dropped == 1
    assert np.isnan(res.final.pressure[6]) and res.final.pore_state[6] == -1
    assert np.isnan(res.invasion_time[6])


def test_network_that_does_not_span_the_axis(rng):
    net = lattice_network((4, 4, 1), 1e-4, rng)
    c = net.throat_conns
    ix = c // 4  # lattice index along x of both ends
    cut = ~((ix[:, 0] == 1) & (ix[:, 1] == 2))
    sub = net.replace(throat_conns=c[cut], throat_radius=net.throat_radius[cut],
                      throat_length=net.throat_length[cut], throat_pore_length=net.throat_pore_length[cut],
                      throat_volume=net.throat_volume[cut])
    with pytest.raises(NetworkError, match="percolate"):
        DrainageSimulator(sub)


def test_advance_to_rejects_going_back(rng):
    sim = DrainageSimulator(lattice_network((3, 3, 1), 1e-4, rng), rate=1e-12)
    sim.advance_to(1.0)
    with pytest.raises(InputError):
        sim.advance_to(0.5)


def test_state_is_consistent_and_read_only(rng):
    sim = DrainageSimulator(lattice_network((6, 5, 2), 1e-4, rng), rate=1e-12)
    s = sim.advance_to(3.0)
    assert s.t == 3.0
    assert s.injected_volume == pytest.approx(3e-12, rel=1e-12, abs=0)
    assert s.mass_balance_error <= 1e-12
    with pytest.raises(ValueError):
        s.pressure[0] = 1.0
    filling = s.pore_state == 1
    full = s.pore_state == 2
    assert np.all(s.nw_saturation[full] == 1.0)
    assert np.all((s.nw_saturation[filling] > 0) & (s.nw_saturation[filling] < 1))
    # pore-wall load: volume average of the two phase pressures, between P_w and P_w + Pc_b
    assert np.all(s.fluid_pressure[filling] >= s.pressure[filling])
    np.testing.assert_array_equal(s.fluid_pressure[~filling & (s.pore_state >= 0)],
                                  s.pressure[~filling & (s.pore_state >= 0)])


def test_with_network_keeps_saturations_and_mass_balance(rng):
    net = lattice_network((6, 5, 2), 1e-4, rng)
    sim = DrainageSimulator(net, rate=1e-12)
    s0 = sim.advance_to(2.0)
    scale = rng.uniform(0.9, 1.1, net.n_pores)
    grown = net.replace(pore_volume=net.pore_volume * scale)
    sim2 = sim.with_network(grown)
    s1 = sim2.state
    np.testing.assert_allclose(s1.nw_saturation, s0.nw_saturation, rtol=1e-14)
    assert s1.deformation_volume == pytest.approx(np.sum(s0.nw_saturation * net.pore_volume * (scale - 1)),
                                                  rel=1e-10, abs=0)
    assert s1.mass_balance_error <= 1e-12
    s2 = sim2.advance_to(4.0)
    assert s2.mass_balance_error <= 1e-12
    assert np.all(s2.nw_saturation >= s1.nw_saturation)
    # the original simulator is untouched
    assert sim.t == 2.0
    with pytest.raises(InputError):
        sim.with_network(lattice_network((3, 3, 1), 1e-4, rng))


def test_with_network_narrower_throats_raise_the_entry_pressure():
    # Young-Laplace: halving the throat radius doubles the jump pressure into the next pore
    net = chain_network([30e-6] * 3, [10e-6, 10e-6], 1e-4)
    fl = Fluids()
    sim = DrainageSimulator(net, fl, rate=1e-16)
    sim.advance_to(1e-3)  # the inlet pore is filling
    narrow = sim.with_network(net.replace(throat_radius=net.throat_radius * 0.5))
    n0 = len(narrow.history()["time_s"])
    narrow.advance_to(1e4, stop_at_breakthrough=True)
    p = narrow.history()["inlet_pressure_pa"][n0:]
    assert np.nanmax(p) == pytest.approx(float(fl.capillary_pressure(5e-6)), rel=1e-6)
