"""Cost-only machinery of the drainage solver: prefetched base columns change the cost, never the answer."""

import pickle

import numpy as np

from porefsi.flow.drainage import DrainageSimulator
from porefsi.flow.fluids import Fluids
from porefsi.network.lattice import lattice_network

SPACING = 1e-4


def _rate_for_ca(net, fl, ca):
    ext = net.extent
    return ca * fl.sigma * float(ext[1] * ext[2]) / fl.mu_n


def _run(net, fl, rate, prefetch, max_rank=None):
    sim = DrainageSimulator(net, fl, rate=rate, solver="lowrank")
    so = sim._engine.solver
    so.prefetch = prefetch
    if max_rank:
        so.max_rank = max_rank
    sim.advance_to(1e9, stop_at_breakthrough=True)
    return sim


def test_prefetch_changes_cost_not_answer(rng):
    # the same drainage with and without prefetching: identical events, solves, factorisations and
    # invasion order; times equal to round-off (a batched triangular solve may round differently);
    # prefetching computes the base columns in fewer, larger batches
    net = lattice_network((10, 7, 6), SPACING, rng)
    fl = Fluids()
    rate = _rate_for_ca(net, fl, 1e-6)
    a = _run(net, fl, rate, prefetch=False, max_rank=40)
    b = _run(net, fl, rate, prefetch=True, max_rank=40)
    ca, cb = a.counters, b.counters
    for k in ("n_events", "n_fills", "n_solves", "n_skipped_solves", "n_solver_setups"):
        assert ca[k] == cb[k], k
    assert ca["n_solver_setups"] > 2  # the rank cap was reached several times
    np.testing.assert_array_equal(np.isnan(a.invasion_time()), np.isnan(b.invasion_time()))
    np.testing.assert_allclose(a.invasion_time(), b.invasion_time(), rtol=1e-10)
    np.testing.assert_array_equal(a.state.pore_state, b.state.pore_state)
    sa, sb = a._engine.solver, b._engine.solver
    assert sa.n_prefetched == 0 < sb.n_prefetched
    assert sb.n_column_batches < sa.n_column_batches


def test_hint_covers_every_row_a_fill_changes(rng):
    # the rows whose matrix entries change when a filling pore becomes full are all in the hint
    net = lattice_network((9, 7, 3), SPACING, rng)
    fl = Fluids()
    sim = DrainageSimulator(net, fl, rate=_rate_for_ca(net, fl, 1e-6), solver="lowrank")
    e = sim._engine
    g = e.g
    checked = 0
    for _ in range(60):
        e.step(np.inf)
        if not np.isnan(e.t_breakthrough):
            break
        if not e.flux_valid:
            e._resolve()  # what the next event starts with
        for x in np.flatnonzero(e.q > 0):
            cond0 = e.conductances()[0]
            e.full[x] = True
            cond1 = e.conductances()[0]
            e.full[x] = False
            ch = np.flatnonzero(cond0 != cond1)
            rows = np.unique(np.concatenate([g.a[ch], g.b[ch]]))
            rows = rows[rows < g.n]  # the inlet row is cached from the start (right-hand side)
            assert set(rows) <= set(e._hint(np.array([x]), n_pinned=0).tolist())
            checked += 1
    assert checked > 5


def test_solver_pickled_without_prefetch_fields_still_runs(rng):
    # checkpoints written before the prefetch counters existed load and continue
    net = lattice_network((8, 6, 5), SPACING, rng)
    fl = Fluids()
    sim = DrainageSimulator(net, fl, rate=_rate_for_ca(net, fl, 1e-6), solver="lowrank")
    sim.advance_to(1e-3)
    so = sim._engine.solver
    for k in ("prefetch", "n_columns", "n_column_batches", "n_prefetched"):
        del so.__dict__[k]
    sim2 = pickle.loads(pickle.dumps(sim))
    sim2.advance_to(1e9, stop_at_breakthrough=True)
    assert sim2._engine.solver.prefetch and not np.isnan(sim2.breakthrough_time)
