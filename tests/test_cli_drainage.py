"""`porefsi drainage` through main(argv)."""

import json

import numpy as np
import pytest

from porefsi.cli import main
from porefsi.network.lattice import lattice_network

convert = pytest.importorskip("porefsi.network.convert")


@pytest.fixture
def net_file(tmp_path, rng):
    net = lattice_network((6, 5, 3), 1e-4, rng)
    return net, convert.save_network(net, tmp_path / "net.npz")


def test_cli_drainage_writes_outputs_and_json(net_file, tmp_path, capsys):
    net, path = net_file
    out = tmp_path / "out"
    rate = 1e-12
    code = main(["drainage", str(path), "--rate", str(rate), "--t-end", "20", "-o", str(out), "--json",
                 "--snapshots", "2"])
    assert code == 0
    s = json.loads(capsys.readouterr().out)
    for k in ("breakthrough_time_s", "final_sw", "n_events", "n_solves", "mass_balance_error", "seconds"):
        assert k in s
    assert s["mass_balance_error"] <= 1e-12
    assert 0 <= s["final_sw"] <= 1
    hist = np.genfromtxt(out / "drainage.csv", delimiter=",", names=True)
    assert hist["time_s"][-1] == pytest.approx(20.0)
    # volume bookkeeping in the file: injected = rate * t (constant rate)
    np.testing.assert_allclose(hist["injected_m3"], rate * hist["time_s"], rtol=1e-10, atol=1e-30)
    # capillary pressure = inlet minus outlet node pressure, the outlet at 0 by construction
    assert "capillary_pressure_pa" in hist.dtype.names
    np.testing.assert_array_equal(hist["capillary_pressure_pa"], hist["inlet_pressure_pa"])
    assert np.nanmax(hist["capillary_pressure_pa"]) > 0
    # the Pc-S figure: a PNG
    assert (out / "pc_s.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    lines = (out / "invasion.csv").read_text().splitlines()
    assert lines[0] == "pore,time_s" and len(lines) == net.n_pores + 1
    assert any(line.endswith(",") for line in lines[1:]) or s["final_sw"] == 0
    snaps = sorted(out.glob("snapshot_*.csv"))
    assert len(snaps) == 2
    for k, t_snap in enumerate((10.0, 20.0)):  # --snapshots 2 over 20 s: evenly spaced, ending at t_end
        snap = np.genfromtxt(out / f"snapshot_{k}.csv", delimiter=",", names=True)
        np.testing.assert_array_equal(snap["time_s"], t_snap)
        np.testing.assert_array_equal(snap["pore"], np.arange(net.n_pores))
        assert np.all((snap["nw_saturation"] >= 0) & (snap["nw_saturation"] <= 1))


@pytest.mark.parametrize("argv, msg", [
    (["--rate", "0"], "positive"),
    (["--rate=-1e-12"], "positive"),
    (["--theta", "95"], "contact angle"),
    (["--sigma", "0"], "positive"),
    (["--axis", "z", "--mu-n=-1"], "positive"),
    (["--scheme", "adaptive", "--tie-tolerance=-1"], ">= 0"),
    (["--scheme", "adaptive", "--tie-tolerance", "nan"], ">= 0"),
    (["--scheme", "adaptive", "--predict-fills", "2.5"], "integer"),
    (["--scheme", "adaptive", "--flux-tolerance", "3"], "at most 2"),
    (["--tie-tolerance", "0.5"], "--scheme adaptive only"),
    (["--block-pivots", "off"], "--scheme adaptive only"),
])
def test_cli_drainage_bad_input_is_a_one_line_error(net_file, capsys, argv, msg):
    _, path = net_file
    code = main(["drainage", str(path), *argv])
    err = capsys.readouterr().err
    assert code == 2 and msg in err


def test_cli_drainage_adaptive_knobs_reach_the_options(net_file, capsys, monkeypatch):
    """--tie-tolerance, --predict-fills, --flux-tolerance, --block-pivots and --backoff set the adaptive
    scheme's options; left out, the options keep their defaults."""
    import porefsi.flow.drainage as drainage

    seen = []
    real = drainage.simulate_drainage

    def spy(net, fluids, options, **kw):
        seen.append(options)
        return real(net, fluids, options, **kw)

    monkeypatch.setattr(drainage, "simulate_drainage", spy)
    _, path = net_file
    base = ["drainage", str(path), "--scheme", "adaptive", "--t-end", "2", "--snapshots", "0", "--json"]
    assert main([*base, "--tie-tolerance", "0", "--predict-fills", "4", "--flux-tolerance", "0.1",
                 "--block-pivots", "off", "--backoff", "0"]) == 0
    assert main(base) == 0
    capsys.readouterr()
    o, d = seen
    assert (o.tie_tolerance, o.predict_fills, o.flux_tolerance, o.block_pivots, o.backoff) == (0.0, 4, 0.1, "off", 0)
    assert d == drainage.DrainageOptions(rate=d.rate, t_end=2.0, scheme="adaptive")
