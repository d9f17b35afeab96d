"""Numba kernels of the drainage model against their naive twins (tests/reference/drainage_ref.py)."""

import numpy as np
import pytest

from porefsi.flow import _kernels as kern
from porefsi.flow._drainage_graph import build_graph
from porefsi.flow.fluids import Fluids
from porefsi.network.lattice import lattice_network
from tests.reference import drainage_ref as ref


def _graph(rng, shape=(6, 5, 3)):
    return build_graph(lattice_network(shape, 1e-4, rng), Fluids(), "x")


def test_filling_step_and_apply_match_twin(rng):
    for _ in range(20):
        n = 30
        vol = rng.uniform(1, 2, n)
        vn = vol * rng.uniform(0, 1, n)
        q = np.where(rng.random(n) < 0.5, rng.uniform(0, 1, n), 0.0)
        filling = np.flatnonzero(rng.random(n) < 0.7)
        dt, k = kern._filling_step(vn, vol, q, filling)
        dt_r, k_r = ref.filling_step(vn, vol, q, filling)
        assert k == k_r and dt == dt_r
        if k >= 0:
            v = vn.copy()
            kern._apply_filling(v, vol, q, filling, dt, k)
            np.testing.assert_array_equal(v, ref.apply_filling(vn, vol, q, filling, dt, k))
            assert v[k] == vol[k] and np.all(v <= vol)


def test_most_violated_matches_twin(rng):
    g = _graph(rng)
    n, E = g.n, g.n_edges
    for _ in range(20):
        full = rng.random(n) < 0.4
        trapped = ~full & (rng.random(n) < 0.1)
        inv = rng.random(E) < 0.5
        closed = rng.random(E) < 0.2
        blocked = rng.random(E) < 0.2
        P = rng.uniform(0, 2e4, n + 1)
        got = kern._most_violated((g.a, g.b, n), (full, trapped, inv, closed, blocked), P, (g.thr, g.pcb))
        want = ref.most_violated(g.a, g.b, n, full, trapped, inv, closed, blocked, P, g.thr, g.pcb)
        assert got[0] == want[0] and got[2] == want[2]
        assert got[1] == want[1]


def test_trapping_search_matches_connected_components(rng):
    g = _graph(rng, (7, 7, 1))
    n = g.n
    for _ in range(30):
        full = rng.random(n) < 0.45
        trapped = np.zeros(n, dtype=bool)
        seeds = np.flatnonzero(~full)
        got = trapped.copy()
        kern._trapped_from(seeds, (g.indptr, g.nbr, g.is_outlet, g.key), (full, got),
                           (np.zeros(1, np.int64), np.zeros(n, np.int64)))
        np.testing.assert_array_equal(got, ref.trapped_after(g.indptr, g.nbr, full, trapped, g.is_outlet))


def test_dijkstra_and_path_check_match_twin(rng):
    g = _graph(rng)
    n = g.n
    res = 1.0 / g.gw[g.nbr_edge]
    for _ in range(5):
        usable = rng.random(n) < 0.8
        dist, pred = kern._dijkstra_to_outlet(g.indptr, g.nbr, res, usable, g.out_res_w)
        want = ref.dijkstra_to_outlet(g.indptr, g.nbr, res, usable, g.out_res_w)
        np.testing.assert_allclose(dist, want, rtol=1e-12)
        for x in np.flatnonzero(np.isfinite(dist))[:10]:
            assert kern._path_usable(x, pred, usable, n)
            # walking the chain adds up the distance
            v, tot = x, 0.0
            while pred[v] != -1:
                w = pred[v]
                p = g.indptr[v] + np.flatnonzero(g.nbr[g.indptr[v]:g.indptr[v + 1]] == w)[0]
                tot += res[p]
                v = w
            assert tot + g.out_res_w[v] == np.float64(dist[x]) or abs(tot + g.out_res_w[v] - dist[x]) <= 1e-12 * dist[x]
            blocked = usable.copy()
            blocked[x] = False
            assert not kern._path_usable(x, pred, blocked, n)


def test_non_wetting_distances_match_twin_and_the_incremental_update(rng):
    # d_N bounds the cluster's resistance from the inlet (Rayleigh): Dijkstra over full pores from
    # the inlet node; adding a pore updates the distances to what a fresh computation gives
    g = _graph(rng, (7, 6, 4))
    n = g.n
    nres = 1.0 / g.gn[g.nbr_edge]
    in_res = np.full(n, np.inf)
    ie = np.flatnonzero(g.is_in_edge)
    in_res[g.b[ie]] = 1.0 / g.gn[ie]
    for _ in range(4):
        full = rng.random(n) < 0.5
        dist = kern._n_distance(g.indptr, g.nbr, nres, full, in_res)
        np.testing.assert_allclose(dist, ref.n_distance(g.indptr, g.nbr, nres, full, in_res), rtol=1e-12)
        assert np.isfinite(dist).any() and np.isinf(dist[~full]).all()
        for x in rng.permutation(np.flatnonzero(~full))[:15]:
            full[x] = True
            kern._n_distance_add(int(x), dist, g.indptr, g.nbr, nres, full, in_res)
            np.testing.assert_allclose(dist, ref.n_distance(g.indptr, g.nbr, nres, full, in_res), rtol=1e-12)


def test_ball_matches_twin(rng):
    g = _graph(rng, (7, 6, 4))
    for hops in (0, 1, 2, 5):
        allowed = rng.random(g.n) < 0.7
        seeds = rng.choice(g.n, 4, replace=False)
        got = kern._ball(seeds, g.indptr, g.nbr, allowed, hops)
        np.testing.assert_array_equal(got, ref.ball(seeds, g.indptr, g.nbr, allowed, hops))
        assert got.sum() >= np.count_nonzero(allowed[seeds])


def _wetting_twin(x, indptr, nbr, res, usable, out_res):
    """min(out_res[x], min_y res[x, y] + d(y)) with d a fresh (scipy) search over ``usable``."""
    d = ref.dijkstra_to_outlet(indptr, nbr, res, usable, out_res)
    best = out_res[x]
    for p in range(indptr[x], indptr[x + 1]):
        if usable[nbr[p]]:
            best = min(best, res[p] + d[nbr[p]])
    return best


def test_wetting_bound_from_a_cached_search_is_the_fresh_one_or_says_it_is_not(rng):
    # the adaptive batches reuse the last d_W search while the region shrinks: where the kernel
    # says "exact" its value is the fresh search's; otherwise it is still an upper bound's input
    g = _graph(rng, (8, 6, 5))
    n = g.n
    res = 1.0 / g.gw[g.nbr_edge]
    adj = (g.indptr, g.nbr, res)
    n_exact = n_stale = 0
    for _ in range(4):
        region = rng.random(n) < 0.9
        search = kern._dijkstra_to_outlet(g.indptr, g.nbr, res, region, g.out_res_w)
        for _ in range(6):
            region = region & (rng.random(n) < 0.93)  # the wetting region only shrinks
            for x in rng.choice(n, 12, replace=False):
                want = _wetting_twin(x, g.indptr, g.nbr, res, region, g.out_res_w)
                got, exact = kern._wetting_bound(x, adj, search, region, g.out_res_w[x])
                if exact:
                    n_exact += 1
                    assert got == pytest.approx(want, rel=1e-12) or got == want == np.inf
                else:
                    n_stale += 1
                    assert got >= want * (1 - 1e-12)
                fresh = kern._dijkstra_to_outlet(g.indptr, g.nbr, res, region, g.out_res_w)
                got, exact = kern._wetting_bound(x, adj, fresh, region, g.out_res_w[x])
                assert exact and (got == pytest.approx(want, rel=1e-12) or got == want == np.inf)
    assert n_exact > 50 and n_stale > 5  # both branches taken


@pytest.mark.parametrize("bc", ["rate", "pressure"])
def test_edge_states_and_assembly_match_twin_to_the_bit(rng, bc):
    g = _graph(rng, (7, 5, 4))
    n, E = g.n, g.n_edges
    diag_ref = (np.bincount(g.a, g.gw, minlength=n + 2) + np.bincount(g.b, g.gw, minlength=n + 2))[:n + 1]
    rate, p_fixed = (3e-12, None) if bc == "rate" else (None, 2.5e4)
    for _ in range(20):
        full = rng.random(n) < 0.4
        trapped = ~full & (rng.random(n) < 0.15)
        inv = rng.random(E) < 0.6
        closed = rng.random(E) < 0.2
        got = kern._edge_states((g.a, g.b, n), g.inner, g.gn, g.gw, (full, trapped, inv, closed))
        want = ref.edge_states(g, full, trapped, inv, closed)
        for x, y in zip(got, want, strict=True):
            np.testing.assert_array_equal(x, y)
        cond, men, fa = want
        assert men.any() and (cond == 0).any() and (cond == g.gw).any() and (cond == g.gn).any()
        bcs = (rate or 0.0, p_fixed or 0.0, rate is not None)
        got = kern._assemble((g.a, g.b, n), (g.inner, g.is_in_edge, men, fa), cond, g.pcb,
                             (g.pos_diag, g.pos_ab, g.pos_ba, g.indices.size), diag_ref, bcs)
        want = ref.assemble(g, cond, men, fa, rate, p_fixed, diag_ref)
        for x, y in zip(got, want, strict=True):
            np.testing.assert_array_equal(x, y)
            assert np.array_equal(np.signbit(x), np.signbit(y))  # -0.0 where the twin has it


def test_open_path_matches_the_edge_states_twin(rng):
    """``_open_path`` is ``men.any() or (fa & ~inner).any()`` of the NumPy edge-state twin.

    Random states, and states with a single invaded edge (every edge in turn) and no non-wetting
    outlet conduit, so that each edge kind decides the answer alone (trapped ends included).
    """
    g = _graph(rng)
    n, E = g.n, g.n_edges

    def check(full, trapped, inv, closed):
        _, men, fa = ref.edge_states(g, full, trapped, inv, closed)
        want = bool(men.any() or (fa & ~g.inner).any())
        assert kern._open_path((g.a, g.b, n), g.inner, (full, trapped, inv, closed)) == want
        return want

    seen = set()
    for i in range(30):
        full = rng.random(n) < (0.02 if i % 3 == 0 else 0.4)
        trapped = ~full & (rng.random(n) < 0.1)
        seen.add(check(full, trapped, rng.random(E) < (0.05 if i % 2 else 0.5), rng.random(E) < 0.2))
    outlet_pore = np.zeros(n, dtype=bool)
    outlet_pore[g.a[~g.inner & (g.a < n)]] = True
    for _ in range(4):
        full = (rng.random(n) < 0.4) & ~outlet_pore
        trapped = ~full & (rng.random(n) < 0.3)
        for e in range(E):
            inv = np.zeros(E, dtype=bool)
            inv[e] = True
            seen.add(check(full, trapped, inv, np.zeros(E, dtype=bool)))
    assert seen == {True, False}  # both answers exercised
