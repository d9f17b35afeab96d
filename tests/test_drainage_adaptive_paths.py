"""Every adaptive drainage path against the exact scheme, and the switch that turns it off (issue 16).

Paths covered in test_drainage_adaptive.py: certified batches (switch: ``scheme="exact"``), the
tie tolerance (``tie_tolerance=0``; off above ``TIE_MAX_CA``), local solves (``local_solves=0``,
the default), the split solver (``solver="split"``), checkpoints. Here: the exact scheme's
per-jump skip inside the adaptive engine (``skip_solves="off"``; on by default above 5000 pores),
the solver the adaptive scheme picks above ``ADAPTIVE_SPLIT_ABOVE`` pores (any explicit
``solver`` turns it off), constant inlet pressure (no batches: the exact events), and a simulator
carried onto a deformed network (``with_network``: the non-wetting distances of the certificate
must follow the new conductances). Truth: the exact scheme on the same network.
"""

import numpy as np
import pytest

from porefsi.flow._drainage_options import ADAPTIVE_SPLIT_ABOVE, DrainageOptions
from porefsi.flow.drainage import DrainageSimulator, simulate_drainage
from porefsi.flow.fluids import Fluids
from porefsi.flow.invasion import invasion_percolation
from porefsi.network.lattice import lattice_network


def _rate_for_ca(net, fl, ca):
    ext = net.extent
    return ca * fl.sigma * float(ext[1] * ext[2]) / fl.mu_n


@pytest.fixture(scope="module")
def net():
    return lattice_network((12, 8, 6), 4e-5, np.random.default_rng(5))


def _order(t):
    inv = np.flatnonzero(np.isfinite(t))
    return inv[np.argsort(t[inv], kind="stable")], np.sort(t[inv])


def _same_events(ta, tb):
    (oa, sa), (ob, sb) = _order(ta), _order(tb)
    np.testing.assert_array_equal(ob, oa)
    np.testing.assert_allclose(sb, sa, rtol=1e-7)


@pytest.mark.parametrize("ca", [1e-7, 1e-6])
def test_per_jump_skip_inside_the_adaptive_scheme_keeps_the_exact_events(net, ca):
    """Jumps no batch certified still skip their solve when the exact scheme's one-path bound
    allows (``skip_solves``, on by default above 5000 pores): the events stay the exact ones."""
    fl = Fluids()
    rate = _rate_for_ca(net, fl, ca)
    kw = dict(rate=rate, t_end=1e9, stop_at_breakthrough=True)
    ref = simulate_drainage(net, fl, scheme="exact", skip_solves="off", **kw)
    on = simulate_drainage(net, fl, scheme="adaptive", tie_tolerance=0.0, skip_solves="on", **kw)
    off = simulate_drainage(net, fl, scheme="adaptive", tie_tolerance=0.0, skip_solves="off", **kw)
    assert on.counters["n_skipped_solves"] > off.counters["n_skipped_solves"]  # the path is taken
    assert on.counters["n_solves"] < off.counters["n_solves"]
    for res in (on, off):
        _same_events(ref.invasion_time, res.invasion_time)
        assert res.breakthrough_time == pytest.approx(ref.breakthrough_time, rel=1e-7)


def test_adaptive_auto_solver_is_split_above_its_pore_count_and_an_explicit_solver_turns_it_off():
    ca = 1e-7
    auto = DrainageOptions(scheme="adaptive")
    assert auto.engine_options(ADAPTIVE_SPLIT_ABOVE + 1, ca)["solver"] == "lowrank_or_split"
    assert auto.engine_options(ADAPTIVE_SPLIT_ABOVE, ca)["solver"] == "auto"
    for solver in ("lowrank", "direct", "amg"):
        o = DrainageOptions(scheme="adaptive", solver=solver)
        assert o.engine_options(10 * ADAPTIVE_SPLIT_ABOVE, ca)["solver"] == solver
    assert DrainageOptions().engine_options(10 * ADAPTIVE_SPLIT_ABOVE, ca)["solver"] == "auto"  # exact scheme
    skip = DrainageOptions(scheme="adaptive", skip_solves="off").engine_options(10 * ADAPTIVE_SPLIT_ABOVE, ca)
    assert skip["skip_solves"] is False


def test_constant_inlet_pressure_adaptive_run_is_the_exact_run(net):
    """No batch at constant pressure (the fill time needs the flux): the adaptive scheme makes
    the exact scheme's events, with its defaults."""
    fl = Fluids()
    ip = invasion_percolation(net, fl, stop_at_breakthrough=True)
    p = 1.05 * float(ip.capillary_pressure[ip.breakthrough_step])
    kw = dict(inlet_pressure=p, t_end=1e9, stop_at_breakthrough=True)
    ref = simulate_drainage(net, fl, scheme="exact", **kw)
    res = simulate_drainage(net, fl, scheme="adaptive", **kw)
    assert res.counters["n_certified_fills"] == 0
    _same_events(ref.invasion_time, res.invasion_time)
    np.testing.assert_allclose(res.history["inlet_pressure_pa"], ref.history["inlet_pressure_pa"])
    assert res.breakthrough_time == pytest.approx(ref.breakthrough_time, rel=1e-9)


@pytest.mark.parametrize("scale", [0.8, 1.25])
def test_adaptive_run_carried_onto_a_deformed_network_keeps_the_exact_events(net, scale):
    """Half-way, throats narrow (or widen) by ``scale``: the certificate's non-wetting distances
    must be recomputed from the new conductances (stale ones under-estimate the resistance of
    narrowed throats and certify fills the exact scheme does not make alone)."""
    fl = Fluids()
    rate = _rate_for_ca(net, fl, 1e-7)
    bt = simulate_drainage(net, fl, rate=rate, t_end=1e9, stop_at_breakthrough=True).breakthrough_time
    cap = net.pore_radius[net.throat_conns].min(axis=1)  # a throat is no wider than its pores
    deformed = net.replace(throat_radius=np.minimum(net.throat_radius * scale, cap))
    runs = {}
    for scheme, kw in (("exact", {}), ("adaptive", dict(tie_tolerance=0.0))):
        sim = DrainageSimulator(net, fl, rate=rate, scheme=scheme, **kw)
        sim.advance_to(0.4 * bt)
        sim = sim.with_network(deformed)
        sim.advance_to(1.2 * bt)
        runs[scheme] = sim
    a, b = runs["exact"], runs["adaptive"]
    assert b.counters["n_certified_fills"] > 0
    _same_events(a.invasion_time(), b.invasion_time())
    assert b.breakthrough_time == pytest.approx(a.breakthrough_time, rel=1e-7)


@pytest.mark.parametrize("limit", [0.0, 1e9])
def test_lowrank_or_split_chooses_by_the_first_factors_fill_and_keeps_the_exact_events(net, monkeypatch, limit):
    """The adaptive scheme's solver above ADAPTIVE_SPLIT_ABOVE pores: 'split' where the first LU
    is dense (limit 0: always), else 'selinv' from that factor; either way the run is the exact
    scheme's to the solvers' tolerance (certified batches, tie tolerance 0)."""
    from porefsi.flow import _drainage_solver as ds

    monkeypatch.setattr(ds, "_SPLIT_FILL", limit)
    fl = Fluids()
    rate = _rate_for_ca(net, fl, 1e-6)
    kw = dict(rate=rate, t_end=1e9, stop_at_breakthrough=True)
    ref = simulate_drainage(net, fl, scheme="exact", **kw)
    sim = DrainageSimulator(net, fl, rate=rate, scheme="adaptive", tie_tolerance=0.0)
    sim._engine.solver.method = "lowrank_or_split"  # what 'auto' is above ADAPTIVE_SPLIT_ABOVE pores
    while np.isnan(sim.breakthrough_time):
        sim._engine.step(np.inf)
    so = sim._engine.solver
    assert so.method == ("split" if limit == 0.0 else "selinv") and so.fill > 1.0
    _same_events(ref.invasion_time, sim.invasion_time())
