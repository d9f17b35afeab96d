"""Checkpoints hold plain arrays only (issue 13, section 3): the codec round-trips exactly."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from porefsi.io import plain


def test_every_supported_value_round_trips_bit_for_bit():
    values = {"none": None, "yes": True, "n": np.int64(7), "x": float("nan"), "inf": -np.inf, "tiny": 5e-324,
              "s": "lowrank", "a": np.arange(5.0), "b": np.array([True, False]), "shape": (3, 4, 5),
              "csr": sp.csr_array(np.eye(3)), "csrm": sp.csr_matrix(np.eye(2)),
              "parts": (np.array([1, 2], np.int64), np.array([], np.int64), np.array([5], np.int64)),
              "zero_d": np.float64(0.1)}
    arrays, meta = {}, {}
    plain.put_fields("p", values, arrays, meta)
    assert all(a.dtype != object for a in arrays.values())
    back = plain.get_fields("p", arrays, meta)
    assert back["none"] is None and back["yes"] is True and back["n"] == 7 and np.isnan(back["x"])
    assert back["inf"] == -np.inf and back["tiny"] == 5e-324 and back["s"] == "lowrank" and back["shape"] == (3, 4, 5)
    assert isinstance(back["csr"], sp.csr_array) and isinstance(back["csrm"], sp.csr_matrix)
    assert (back["csr"] != values["csr"]).nnz == 0
    assert [p.tolist() for p in back["parts"]] == [[1, 2], [], [5]] and isinstance(back["parts"], tuple)
    np.testing.assert_array_equal(back["a"], values["a"])
    assert back["zero_d"] == 0.1


@pytest.mark.parametrize("bad", [{1: 2}, [1, 2], object(), np.array([None], dtype=object), sp.coo_array(np.eye(2))])
def test_values_it_cannot_store_are_a_type_error_not_dropped(bad):
    with pytest.raises(TypeError):
        plain.put("p", "v", bad, {}, {})


def test_the_drainage_checkpoint_loads_without_pickles(tmp_path):
    from porefsi.flow import _drainage_checkpoint as ckpt
    from porefsi.flow.drainage import DrainageSimulator
    from porefsi.network.lattice import lattice_network

    sim = DrainageSimulator(lattice_network((6, 5, 3), 1e-4, np.random.default_rng(0)), rate=1e-12, solver="lowrank")
    sim.advance_to(5.0)
    ckpt.save(tmp_path / "c.npz", "k", {"sim": sim, "snaps": [sim.state], "k": 1, "seconds": 1.0})
    with np.load(tmp_path / "c.npz", allow_pickle=False) as z:
        assert all(z[k].dtype != object for k in z.files)
    back = ckpt.load(tmp_path / "c.npz", "k")
    e0, e1 = sim._engine, back["sim"]._engine
    for k, v in vars(e0).items():
        if isinstance(v, np.ndarray):
            np.testing.assert_array_equal(getattr(e1, k), v, err_msg=k)
    assert e1.rows == [tuple(float(x) for x in r) for r in e0.rows]
    np.testing.assert_array_equal(back["snaps"][0].pressure, sim.state.pressure)
