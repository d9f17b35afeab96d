"""Cost-only machinery of the drainage solver: prefetched base columns change the cost, never the answer."""

import pickle

import numpy as np
import pytest

from porefsi.flow.drainage import DrainageSimulator
from porefsi.flow.fluids import Fluids
from porefsi.flow.invasion import invasion_percolation
from porefsi.network.lattice import lattice_network

SPACING = 1e-4


def _rate_for_ca(net, fl, ca):
    ext = net.extent
    return ca * fl.sigma * float(ext[1] * ext[2]) / fl.mu_n


def _run(net, fl, rate, prefetch, max_rank=None):
    sim = DrainageSimulator(net, fl, rate=rate, solver="lowrank")
    so = sim._engine.solver
    so.prefetch = prefetch
    so.prefetch_fill = np.inf  # decided: the first factorisation keeps the setting
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


@pytest.mark.parametrize("limit", [1.0, 1e6])
def test_prefetch_is_kept_only_where_the_factor_is_dense(rng, monkeypatch, limit):
    # the first factorisation switches prefetching off where the factor is sparse (batched columns
    # cost about as much as single solves there; cost only: the answers are those of the test above)
    from porefsi.flow import _drainage_solver as ds

    monkeypatch.setattr(ds, "_PREFETCH_FILL", limit)
    net = lattice_network((8, 6, 5), SPACING, rng)
    fl = Fluids()
    sim = DrainageSimulator(net, fl, rate=_rate_for_ca(net, fl, 1e-6), solver="lowrank")
    sim.advance_to(1e9, stop_at_breakthrough=True)
    so = sim._engine.solver
    assert so.prefetch_fill > 1.0 and so.prefetch == (so.prefetch_fill >= limit)
    assert (so.n_prefetched > 0) == so.prefetch


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


def _same_drainage(runs, rtol_direct=1e-10):
    """Every run of ``runs`` has the first one's events, solves, states and invasion times.

    The first run is the fresh-LU one; ``rtol_direct`` bounds its invasion times against the
    low-rank runs, which must agree with each other to 1e-10 (prefetching changes no answer).
    """
    ref = runs[0]
    for i, sim in enumerate(runs[1:]):
        for k in ("n_events", "n_fills", "n_jumps", "n_solves", "n_active_set_changes"):
            assert sim.counters[k] == ref.counters[k], k
        np.testing.assert_array_equal(np.isnan(sim.invasion_time()), np.isnan(ref.invasion_time()))
        np.testing.assert_allclose(sim.invasion_time(), ref.invasion_time(), rtol=rtol_direct)
        np.testing.assert_array_equal(sim.state.pore_state, ref.state.pore_state)
        assert sim.breakthrough_time == pytest.approx(ref.breakthrough_time, rel=rtol_direct)
        if i:
            np.testing.assert_allclose(sim.invasion_time(), runs[1].invasion_time(), rtol=1e-10)


def _three_solvers(net, fl, **kw):
    """The same drainage with a fresh LU per solve, and low-rank without and with prefetching."""
    runs = []
    for solver, prefetch in (("direct", False), ("lowrank", False), ("lowrank", True)):
        sim = DrainageSimulator(net, fl, solver=solver, **kw)
        sim._engine.solver.prefetch = prefetch
        sim._engine.solver.prefetch_fill = np.inf  # forced: the first factorisation keeps the setting
        sim.advance_to(1e9, stop_at_breakthrough=True)
        runs.append(sim)
    assert runs[2]._engine.solver.n_prefetched > 0
    return runs


@pytest.mark.parametrize("shape, seed, m", [((24, 24, 1), 1, 1e-3), ((10, 8, 6), 0, 1e3)])
def test_prefetch_cannot_overflow_the_cache_at_high_ca(shape, seed, m):
    # 576 and 480 pores (above the 400-unknown switch to the low-rank solver) at Ca = 1e-2, at both
    # ends of the viscosity-ratio range: many menisci move at once, so a single solve asks for many
    # new columns while prefetched ones fill the cache; prefetched columns used to be capped by
    # their budget only and overflowed the cache (ValueError "could not broadcast ... (139,577)
    # into shape (136,577)" for the 2-D case, "(4,481) into shape (2,481)" for the 3-D one)
    net = lattice_network(shape, SPACING, np.random.default_rng(seed))
    fl = Fluids(mu_w=1e-3, mu_n=1e-3 * m)
    # At M = 1e-3 a fresh LU of these systems stops near a relative residual of 4e-11, above
    # rtol = 1e-11, whichever path refines it; the fresh-LU and low-rank runs then differ in the
    # last ~10 digits of the invasion times (measured 5.6e-10): the conditioning floor. The low-rank
    # runs with and without prefetching still agree to 1e-10.
    _same_drainage(_three_solvers(net, fl, rate=_rate_for_ca(net, fl, 1e-2)),
                   rtol_direct=1e-8 if m < 1 else 1e-10)


def test_prefetch_cannot_overflow_the_cache_at_constant_pressure():
    # constant inlet pressure 5 % above the quasi-static breakthrough pressure on 960 pores: every
    # inlet meniscus above its threshold opens in the first event (a large first batch of columns)
    net = lattice_network((12, 10, 8), SPACING, np.random.default_rng(3))
    fl = Fluids()
    ip = invasion_percolation(net, fl, stop_at_breakthrough=True)
    p_bt = float(ip.capillary_pressure[ip.breakthrough_step])
    runs = _three_solvers(net, fl, inlet_pressure=1.05 * p_bt)
    _same_drainage(runs)
    # without refactorisations forced by round-off, prefetching leaves the factorisation schedule alone
    assert runs[1].counters["n_solver_setups"] == runs[2].counters["n_solver_setups"] > 1


def test_two_thread_column_batches_give_the_one_cpu_answer(rng, monkeypatch):
    # large batches of base columns are split in halves (two threads when there are two CPUs);
    # the split is the same with one CPU, so the answer does not depend on the machine
    from porefsi.flow import _drainage_columns as dc
    from porefsi.flow import _drainage_solver as ds

    net = lattice_network((14, 10, 8), SPACING, rng)
    fl = Fluids()
    rate = _rate_for_ca(net, fl, 1e-6)
    sizes = []
    solve_columns = ds._solve_columns

    def spy(base, nodes):
        sizes.append(nodes.size)
        return solve_columns(base, nodes)

    monkeypatch.setattr(ds, "_solve_columns", spy)
    runs = []
    import os

    for pool in (dc.pool_(), None):
        monkeypatch.setattr(dc, "POOL", {os.getpid(): pool})
        runs.append(_run(net, fl, rate, prefetch=True))
    assert max(sizes) >= dc.SPLIT_COLUMNS  # split batches were exercised
    h0, h1 = runs[0].history(), runs[1].history()
    for k in h0:
        np.testing.assert_array_equal(h0[k], h1[k], err_msg=k)


@pytest.mark.filterwarnings("ignore:This process .* is multi-threaded:DeprecationWarning")  # the point here
def test_a_forked_child_gets_its_own_column_worker(rng):
    # the parent's worker thread does not exist in a forked child: the child builds its own
    # (a child using the parent's executor would wait forever on its first large batch)
    import multiprocessing as mp
    import os

    from porefsi.flow import _drainage_columns as dc

    if "fork" not in mp.get_all_start_methods():
        pytest.skip("no fork on this platform")
    parent = dc.pool_()
    if parent is None:
        pytest.skip("one CPU: no worker thread")
    net = lattice_network((10, 8, 6), SPACING, rng)
    fl = Fluids()
    rate = _rate_for_ca(net, fl, 1e-6)
    with mp.get_context("fork").Pool(1) as pool:
        child = pool.apply_async(_child_run, (net, fl, rate))
        n_events, child_pid_pool = child.get(timeout=120)
    assert n_events == _run(net, fl, rate, prefetch=True).counters["n_events"]
    assert child_pid_pool != os.getpid()


def _child_run(net, fl, rate):
    import os

    from porefsi.flow import _drainage_columns as dc

    sim = _run(net, fl, rate, prefetch=True)
    return sim.counters["n_events"], next(iter(dc.POOL)) if dc.POOL else os.getpid()
