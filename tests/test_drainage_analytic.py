"""Dynamic drainage against closed-form answers (DESIGN.md §5 "Assertable checks")."""

import numpy as np
import pytest

from porefsi.flow.drainage import DrainageSimulator, simulate_drainage
from porefsi.flow.fluids import Fluids
from porefsi.flow.invasion import invasion_percolation
from porefsi.flow.state import PORE_EMPTY, THROAT_PINNED
from porefsi.network.geometry import cylinder_resistance, resistance_factors
from porefsi.network.lattice import chain_network, parallel_paths_network, tube_network

R_TUBE, L_TUBE, N_TUBE = 1e-5, 2e-3, 25


def _tube_fill_time(l, L, r, mu_n, mu_w, dp_eff):
    """Front position l(t) in a tube, nw displacing w at constant overpressure dp_eff (Poiseuille)."""
    return 8.0 / (r * r * dp_eff) * (mu_n * l * l / 2 + mu_w * (L * l - l * l / 2))


def test_lucas_washburn_single_tube():
    # Washburn (1921): l^2 = sigma r cos(theta) t / (2 mu) for a tube filled against an inviscid fluid
    # by the capillary pressure 2 sigma cos(theta) / r. Here the same ODE: inlet overpressure over the
    # entry pressure equals 2 sigma cos(theta)/r, displaced fluid viscosity 1e-12 of the invading one.
    fl = Fluids(mu_w=1e-15, mu_n=1e-3, sigma=0.03, theta_deg=30.0)
    net = tube_network(N_TUBE, R_TUBE, L_TUBE)
    pe = float(fl.capillary_pressure(R_TUBE))
    sim = DrainageSimulator(net, fl, inlet_pressure=2 * pe)
    sim.advance_to(1.0)
    t_fill = sim.invasion_time()
    assert np.all(np.isfinite(t_fill))
    l = (np.arange(N_TUBE) + 1) * L_TUBE / N_TUBE
    t_lw = 2 * fl.mu_n * l**2 / (fl.sigma * R_TUBE * fl.cos_theta)
    np.testing.assert_allclose(t_fill, t_lw, rtol=1e-9)


def test_two_fluid_tube_constant_pressure_fill_time():
    # t_fill = 4 L^2 (mu_n + mu_w) / (r^2 (dP - Pe)): Poiseuille with the viscous lengths in series.
    fl = Fluids(mu_w=1e-3, mu_n=1e-2, sigma=0.03, theta_deg=0.0)
    net = tube_network(N_TUBE, R_TUBE, L_TUBE)
    pe = float(fl.capillary_pressure(R_TUBE))
    dp = 3.7 * pe
    res = simulate_drainage(net, fl, inlet_pressure=dp, t_end=10.0, stop_at_breakthrough=True)
    t_exact = 4 * L_TUBE**2 * (fl.mu_n + fl.mu_w) / (R_TUBE**2 * (dp - pe))
    assert res.breakthrough_time == pytest.approx(t_exact, rel=1e-10)
    l = (np.arange(N_TUBE) + 1) * L_TUBE / N_TUBE
    np.testing.assert_allclose(res.invasion_time, _tube_fill_time(l, L_TUBE, R_TUBE, fl.mu_n, fl.mu_w, dp - pe),
                               rtol=1e-10)


def _chain():
    R = np.array([30e-6, 24e-6, 35e-6, 28e-6, 32e-6])
    rt = np.array([9e-6, 12e-6, 7e-6, 10e-6])
    return chain_network(R, rt, 1e-4), R, rt


def test_pore_chain_constant_rate_pressure_plateaus():
    # While pore k fills at rate Q, the inlet pressure is Pc_b,k plus Q times the series resistances:
    # non-wetting in the conduits up to pore k, wetting beyond (P_in,k = Pc_b + Q[(k+1)/g_n + (N-k)/g_w]
    # for equal conduits; here the general sum).
    net, R, rt = _chain()
    fl = Fluids()
    Q = 2e-11
    sim = DrainageSimulator(net, fl, rate=Q)
    sim.advance_to(1e3, stop_at_breakthrough=True)
    h = sim.history()
    h_int = resistance_factors(net).sum(axis=1)
    h_in = cylinder_resistance(R[0], 0.5e-4)
    h_out = cylinder_resistance(R[-1], 0.5e-4)
    hs = np.concatenate([[h_in], h_int, [h_out]])  # conduit c feeds pore c
    grow = np.flatnonzero(np.diff(np.concatenate([[0], h["n_full"]])) > 0)
    assert grow.size == R.size
    for k, row in enumerate(grow):
        expect = fl.capillary_pressure(R[k]) + Q * (fl.mu_n * hs[:k + 1].sum() + fl.mu_w * hs[k + 1:].sum())
        assert h["inlet_pressure_pa"][row] == pytest.approx(expect, rel=1e-9)
    # the pores fill one after the other at rate Q: fill time of pore k is V_k / Q
    t = sim.invasion_time()
    np.testing.assert_allclose(np.diff(np.concatenate([[0.0], t])), net.pore_volume / Q, rtol=1e-12)


def test_pore_chain_snapshots_fluid_pressure_and_breakthrough_sw():
    # Snapshot while pore k = 2 fills at rate Q with saturation s = 0.3: the scheme's pressure of a
    # filling or empty pore is its wetting pressure, Q times the wetting resistance to the outlet;
    # the wall load of the filling pore is the volume average s P_n + (1 - s) P_w with
    # P_n = P_w + Pc_b (its meniscus at the body pressure); full pores carry the non-wetting
    # pressure, one meniscus conduit (non-wetting) and Pc_b,2 above pore 2. Breakthrough: the last
    # pore fills at t = sum(V) / Q and every pore is then full, Sw = 0.
    net, R, rt = _chain()
    fl = Fluids()
    Q = 2e-11
    V = net.pore_volume
    h_int = resistance_factors(net).sum(axis=1)
    hs = np.concatenate([[cylinder_resistance(R[0], 0.5e-4)], h_int, [cylinder_resistance(R[-1], 0.5e-4)]])
    k, s = 2, 0.3
    times = [(V[:k].sum() + s * V[k]) / Q, 0.999 * V.sum() / Q]
    res = simulate_drainage(net, fl, rate=Q, t_end=2 * V.sum() / Q, times=times, stop_at_breakthrough=True)
    assert [st.t for st in res.snapshots[:2]] == times
    st = res.snapshots[0]
    pw = Q * fl.mu_w * np.array([hs[j + 1:].sum() for j in range(R.size)])  # wetting, downstream
    pcb = fl.capillary_pressure(R)
    assert st.nw_saturation[k] == pytest.approx(s, rel=1e-12)
    np.testing.assert_allclose(st.pressure[k:], pw[k:], rtol=1e-9)
    assert st.fluid_pressure[k] == pytest.approx(pw[k] + s * pcb[k], rel=1e-9)
    p_full = pw[k] + pcb[k] + Q * fl.mu_n * np.array([hs[j + 1:k + 1].sum() for j in range(k)])
    np.testing.assert_allclose(st.pressure[:k], p_full, rtol=1e-9)
    others = np.arange(R.size) != k
    np.testing.assert_array_equal(st.fluid_pressure[others], st.pressure[others])
    assert res.breakthrough_time == pytest.approx(V.sum() / Q, rel=1e-12)
    assert res.breakthrough_sw == pytest.approx(0.0, abs=1e-14)


def test_two_parallel_paths_critical_rate():
    # Inlet pore 0 feeds branch 1 (wide throat, opens first) and branch 2 (narrow throat 0-2).
    # While 1 fills, P_0 - P_2 = Pc_b,1 + Q (1/g_n(0-1) + 1/g_w(1-3)), so 0-2 opens during the filling
    # of 1 exactly when Q exceeds Q_c = (Pe_02 - Pc_b,1) / (1/g_n(0-1) + 1/g_w(1-3)).
    fl = Fluids()
    net = parallel_paths_network(30e-6, [14e-6, 8e-6, 6e-6, 13e-6], 1e-4)
    h = resistance_factors(net).sum(axis=1)
    qc = (fl.capillary_pressure(8e-6) - fl.capillary_pressure(30e-6)) / (fl.mu_n * h[0] + fl.mu_w * h[2])
    for factor, opens in ((0.98, False), (1.02, True)):
        sim = DrainageSimulator(net, fl, rate=factor * qc)
        sim.advance_to(1e3, stop_at_breakthrough=True)
        t_pore1 = sim.invasion_time()[1]
        t_02 = sim.throat_invasion_time()[1]
        assert (t_02 < t_pore1) == opens, (factor, t_02, t_pore1)


def test_series_of_throats_pc_s_staircase_equals_entry_pressures(rng):
    # Quasi-static drainage of a chain: the Pc-S curve is the running maximum of the entry pressures
    # (Young-Laplace 2 sigma cos(theta) / r of each throat; the inlet pore at its body pressure).
    n = 8
    R = rng.uniform(30e-6, 40e-6, n)
    rt = rng.uniform(5e-6, 25e-6, n - 1)
    net = chain_network(R, rt, 1e-4)
    fl = Fluids(theta_deg=20.0)
    entry = np.concatenate([[fl.capillary_pressure(R[0])], fl.capillary_pressure(rt)])
    staircase = np.maximum.accumulate(entry)
    ip = invasion_percolation(net, fl)
    np.testing.assert_array_equal(ip.pore_sequence, np.arange(n))
    np.testing.assert_allclose(ip.capillary_pressure, staircase, rtol=1e-14)
    np.testing.assert_allclose(ip.sw, 1 - np.cumsum(net.pore_volume) / net.pore_volume.sum(), rtol=1e-14)
    # the dynamic model at Ca ~ 1e-10 climbs the same staircase (viscous part ~ Ca)
    # (Ca ~ 1e-10), within the largest viscous pressure drop Q * mu_n * (sum of all resistances)
    Q = 1e-16
    sim = DrainageSimulator(net, fl, rate=Q)
    sim.advance_to(1e9, stop_at_breakthrough=True)
    h = sim.history()
    pmax = np.fmax.accumulate(h["inlet_pressure_pa"])
    grow = np.flatnonzero(np.diff(np.concatenate([[0], h["n_full"]])) > 0)
    viscous = Q * fl.mu_n * (resistance_factors(net).sum() + 2 * cylinder_resistance(R.min(), 0.5e-4))
    assert viscous < 1e-4 * staircase.min()
    assert np.all(pmax[grow] >= staircase * (1 - 1e-12))
    assert np.all(pmax[grow] <= staircase + viscous)


def _repin_network():
    """Parallel paths (throats 0-1, 0-2, 1-3, 2-3) with a small pore 1 and a narrow throat 1-3.

    Pore-body pressures 2 sigma / R: 2 kPa for pores 0, 2, 3 (R = 30 um), 5 kPa for pore 1
    (12 um). Entry pressures: 0-1 5.22 kPa (11.5 um, opens first), 0-2 5.45 kPa (11 um),
    1-3 15 kPa (4 um: a large wetting resistance behind pore 1), 2-3 2.4 kPa (25 um).
    """
    net = parallel_paths_network(30e-6, [11.5e-6, 11e-6, 4e-6, 25e-6], 1e-4)
    R = np.array([30e-6, 12e-6, 30e-6, 30e-6])
    c = net.throat_conns
    dist = np.linalg.norm(net.pore_coords[c[:, 1]] - net.pore_coords[c[:, 0]], axis=1)
    return net.replace(pore_radius=R, pore_volume=4.0 / 3.0 * np.pi * R**3,
                       throat_pore_length=np.column_stack([R[c[:, 0]], R[c[:, 1]]]),
                       throat_length=dist - R[c[:, 0]] - R[c[:, 1]])


def test_backward_meniscus_is_re_pinned():
    # While the meniscus 0 -> 1 is the only active one, P_0 - P_2 = Pc_b,1 + Q (1/g_n,01 + 1/g_w,13)
    # (pore 2 is a wetting dead end at the outlet-side pressure) exceeds the entry pressure of 0-2,
    # which opens. With 0-2 open the non-wetting fluid needs only Pc_b,2 = 2 kPa to enter pore 2, the
    # inlet pressure drops and P_0 - P_1 = Pc_b,2 + Q (1/g_n,02 + 1/g_w,23) < Pc_b,1: the meniscus in
    # 0-1 would move backwards, so it is re-pinned (stalled) and all of Q fills pore 2 at
    #   P_in = Pc_b,2 + Q [mu_n (h_in + h_02) + mu_w (h_23 + h_out)]   (series resistances).
    # Without the re-pinning the solve lets 0-1 carry a backward flux and P_in comes out lower.
    net = _repin_network()
    fl = Fluids()
    h = resistance_factors(net).sum(axis=1)
    pcb = fl.capillary_pressure(net.pore_radius)
    pe = fl.capillary_pressure(net.throat_radius)
    Q = 1500.0 / (fl.mu_n * h[0] + fl.mu_w * h[2])  # 1.5 kPa of viscous drop along 0-1-3
    assert pcb[1] + Q * (fl.mu_n * h[0] + fl.mu_w * h[2]) > max(pe[1], pcb[2])  # 0-2 opens with 0-1
    assert pcb[2] + Q * (fl.mu_n * h[1] + fl.mu_w * h[3]) < pcb[1]  # and then 0-1 is pushed back
    h_in = cylinder_resistance(net.pore_radius[0], 0.5e-4)
    h_out = cylinder_resistance(net.pore_radius[3], 0.5e-4)
    p_in = pcb[2] + Q * (fl.mu_n * (h_in + h[1]) + fl.mu_w * (h[3] + h_out))
    V = net.pore_volume
    sim = DrainageSimulator(net, fl, rate=Q)
    st = sim.advance_to((V[0] + 0.5 * V[2]) / Q)  # halfway through the filling of pore 2
    assert st.inlet_pressure == pytest.approx(p_in, rel=1e-9)
    assert st.throat_invaded[0] and st.throat_state[0] == THROAT_PINNED
    assert st.pore_state[1] == PORE_EMPTY and st.nw_saturation[1] == 0.0
    assert st.nw_saturation[2] == pytest.approx(0.5, rel=1e-12)
    sim.advance_to(1e3, stop_at_breakthrough=True)
    t = sim.invasion_time()
    assert t[2] == pytest.approx((V[0] + V[2]) / Q, rel=1e-12)
    assert np.isnan(t[1])  # the stalled meniscus never resumed before breakthrough (through 2-3)
    # breakthrough when pore 3 is full: everything but pore 1 holds non-wetting fluid
    res = simulate_drainage(net, fl, rate=Q, t_end=1e3, stop_at_breakthrough=True)
    assert res.breakthrough_time == pytest.approx(V[[0, 2, 3]].sum() / Q, rel=1e-12)
    assert res.breakthrough_sw == pytest.approx(V[1] / V.sum(), rel=1e-12)
