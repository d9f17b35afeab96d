"""Where menisci are active: the flux-split predictor (``predict_fills``) and block pivots against the exact scheme.

Truth: the exact event scheme on the same lattice (itself checked against closed forms in
test_drainage_analytic.py). The predictor is off by default (measured to save nothing:
docs/drainage.md, "Several active menisci"); these tests turn it on and check that

* a batch the corrector rejects leaves no trace: with ``flux_tolerance=0`` every batch is
  rolled back and the run makes the exact scheme's events;
* accepted batches keep the volume balance exact and the histories within 1 % of the exact
  scheme at Ca = 1e-6 and 1e-5 (small lattices, event by event in the exact scheme);
* the options are validated and switched off with the exact scheme;
* block pivots (``block_pivots``, on by default) keep the exact scheme's events with fewer solves.
"""

import numpy as np
import pytest

from porefsi.errors import ConfigError, InputError
from porefsi.flow._drainage_options import DrainageOptions
from porefsi.flow._drainage_predictor import redistribute
from porefsi.flow.drainage import DrainageSimulator
from porefsi.flow.fluids import Fluids
from porefsi.network.lattice import lattice_network


def _rate_for_ca(net, fl, ca):
    ext = net.extent
    return ca * fl.sigma * float(ext[1] * ext[2]) / fl.mu_n


def _run(net, rate, **kw):
    sim = DrainageSimulator(net, Fluids(), rate=rate, **kw)
    sim.advance_to(1e12, stop_at_breakthrough=True)
    tb = sim.breakthrough_time
    sim.advance_to(1.25 * tb)
    return sim


def _sw_at(h, t):
    i = np.searchsorted(h["time_s"], t, side="right") - 1
    return h["sw"][np.clip(i, 0, None)]


def test_redistribute_hands_the_inflow_on_in_proportion():
    """The predicted split: the full pores' inflow goes to the others in proportion, summing to the rate."""
    q = np.array([1.0, 2.0, 0.0, 1.0])
    assert redistribute(q, np.array([1]), 4.0)
    np.testing.assert_allclose(q, [2.0, 0.0, 0.0, 2.0])
    assert not redistribute(q, np.array([0, 3]), 4.0)
    assert not q.any()


def test_rejected_batches_leave_the_exact_events():
    """``flux_tolerance = 0`` rejects every batch: after each rollback the run is the exact one."""
    net = lattice_network((12, 8, 6), 4e-5, np.random.default_rng(5))
    rate = _rate_for_ca(net, Fluids(), 1e-5)
    ref = _run(net, rate, scheme="exact", solver="direct")
    sim = _run(net, rate, scheme="adaptive", solver="direct", predict_fills=16, flux_tolerance=0.0)
    c = sim.counters
    assert c["n_predict_rollbacks"] > 0 and c["n_predicted_fills"] == 0  # the path was taken, all rejected
    ta, tb = ref.invasion_time(), sim.invasion_time()
    np.testing.assert_array_equal(np.isfinite(ta), np.isfinite(tb))
    np.testing.assert_allclose(tb[np.isfinite(tb)], ta[np.isfinite(ta)], rtol=1e-9)
    ha, hb = ref.history(), sim.history()
    assert hb["time_s"].size == ha["time_s"].size  # no event of a rolled-back batch is left in the history
    np.testing.assert_allclose(hb["sw"], ha["sw"], rtol=1e-9)


@pytest.mark.parametrize("ca, seed", [(1e-6, 3), (1e-5, 7)])
def test_accepted_batches_keep_the_histories_within_one_percent(ca, seed):
    """Predicted fills (accepted by the corrector) against the exact scheme: volume balance to round-off,
    breakthrough time and Sw history within 1 %, the same invaded pores but a few."""
    net = lattice_network((20, 10, 10), 4e-5, np.random.default_rng(seed))
    rate = _rate_for_ca(net, Fluids(), ca)
    ref = _run(net, rate, scheme="exact")
    sim = _run(net, rate, scheme="adaptive", tie_tolerance=0.0, predict_fills=16, flux_tolerance=0.05)
    assert sim.counters["n_predicted_fills"] > 0  # the predictor made fills the exact scheme solved for
    h = sim.history()
    assert np.nanmax(h["mass_balance_error"]) < 1e-9
    assert sim.breakthrough_time == pytest.approx(ref.breakthrough_time, rel=0.01)
    ts = np.linspace(0.0, 1.25 * ref.breakthrough_time, 400)
    sw_ref, sw = _sw_at(ref.history(), ts), _sw_at(h, ts)
    assert np.max(np.abs(sw - sw_ref) / sw_ref) < 0.01
    ta, tb = ref.invasion_time(), sim.invasion_time()
    assert np.count_nonzero(np.isfinite(ta) != np.isfinite(tb)) <= 0.01 * np.count_nonzero(np.isfinite(ta))


def test_predictor_options_are_validated_and_adaptive_only():
    """Off by default; bad values and the knobs with the exact scheme are one-line errors."""
    assert DrainageOptions().predict_fills == 0 and DrainageOptions().backoff == 32
    assert DrainageOptions().block_pivots == "on"
    with pytest.raises(ConfigError, match="block_pivots"):
        DrainageOptions(scheme="adaptive", block_pivots="maybe")
    with pytest.raises(ConfigError, match="predict_fills"):
        DrainageOptions(scheme="adaptive", predict_fills=-1)
    with pytest.raises(ConfigError, match="flux_tolerance"):
        DrainageOptions(scheme="adaptive", flux_tolerance=-0.1)
    with pytest.raises(ConfigError, match="scheme = 'adaptive' only"):
        DrainageOptions(predict_fills=8)
    with pytest.raises(ConfigError, match="backoff"):
        DrainageOptions(backoff=0)
    net = lattice_network((6, 4, 4), 4e-5, np.random.default_rng(0))
    with pytest.raises(InputError, match="flux_tolerance"):
        DrainageSimulator(net, rate=1e-12, scheme="adaptive", flux_tolerance=float("nan"))


@pytest.mark.parametrize("backoff", [0, 4])
def test_backoff_switch_changes_the_cost_only(backoff):
    """With the rigorous certificate the batch back-off decides only when a batch is attempted:
    with it off (0) or short, the events are the exact scheme's."""
    net = lattice_network((12, 8, 6), 4e-5, np.random.default_rng(5))
    rate = _rate_for_ca(net, Fluids(), 1e-6)
    ref = _run(net, rate, scheme="exact")
    sim = _run(net, rate, scheme="adaptive", tie_tolerance=0.0, backoff=backoff)
    ta, tb = ref.invasion_time(), sim.invasion_time()
    np.testing.assert_array_equal(np.isfinite(ta), np.isfinite(tb))
    np.testing.assert_allclose(tb[np.isfinite(tb)], ta[np.isfinite(ta)], rtol=1e-7)


@pytest.mark.parametrize("ca", [1e-6, 1e-5])
def test_block_closings_keep_the_exact_events(ca):
    """Block pivots (every pushed-back meniscus closed at once, checked by the next solve): the exact
    scheme's events, same pores, order and times, with fewer solves than one closing per solve."""
    net = lattice_network((20, 10, 10), 4e-5, np.random.default_rng(3))
    rate = _rate_for_ca(net, Fluids(), ca)
    ref = _run(net, rate, scheme="exact")
    kw = dict(scheme="adaptive", tie_tolerance=0.0)
    on = _run(net, rate, block_pivots="on", **kw)
    off = _run(net, rate, block_pivots="off", **kw)
    assert on.counters["n_block_pivots"] > 0 and off.counters["n_block_pivots"] == 0
    assert on.counters["n_solves"] < off.counters["n_solves"]
    ta = ref.invasion_time()
    for sim in (on, off):
        tb = sim.invasion_time()
        np.testing.assert_array_equal(np.isfinite(ta), np.isfinite(tb))
        np.testing.assert_allclose(tb[np.isfinite(tb)], ta[np.isfinite(ta)], rtol=1e-7)
        assert sim.breakthrough_time == pytest.approx(ref.breakthrough_time, rel=1e-9)
