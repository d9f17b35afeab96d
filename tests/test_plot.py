"""Figures are written as real PNGs (off-screen) with the content asked for."""

import numpy as np
import pytest

from porefsi import plot


def _png_size(path):
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")


def test_timeseries_psd_and_pcs(tmp_path):
    t = np.linspace(0, 20, 21)
    ts = {"time_s": t, "sw": 1 - t / 40, "max_displacement_m": t * 1e-10, "permeability_m2": 2e-13 + 0 * t}
    assert _png_size(plot.plot_timeseries(ts, tmp_path / "ts.png", title="x")) == (1200, 624)
    rng = np.random.default_rng(0)
    plot.plot_psd([(0.0, rng.uniform(1e-6, 2e-5, 100)), (10.0, rng.uniform(1e-6, 2e-5, 100))], tmp_path / "psd.png")
    plot.plot_pc_s({"dynamic": (1 - t / 20, t * 1e3)}, tmp_path / "pcs.png")
    assert (tmp_path / "psd.png").stat().st_size > 5000 and (tmp_path / "pcs.png").stat().st_size > 5000


def test_offscreen_renders(tmp_path):
    pytest.importorskip("pyvista")
    rng = np.random.default_rng(1)
    c = rng.uniform(0, 1e-4, (10, 3))
    out = plot.render_network(c, np.full(10, 5e-6), [[0, 1], [1, 2]], rng.random(10), tmp_path / "n.png",
                              label="Sw", window_size=(320, 240))
    assert _png_size(out) == (320, 240)
    for sw in (np.r_[np.zeros(3), np.ones(7)], np.ones(10)):  # some pores invaded / none yet
        out = plot.render_network(c, np.full(10, 5e-6), [[0, 1]], sw, tmp_path / "f.png", label="Sw",
                                  clim=(0, 1), window_size=(320, 240), fade_above=0.999)
        assert _png_size(out) == (320, 240)
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]]) * 1e-5
    out = plot.render_solid(pts, [[0, 1, 2, 3]], np.arange(4.0), tmp_path / "s.png", label="u",
                            displacement=pts, scale=0.1, window_size=(320, 240))
    assert _png_size(out) == (320, 240)


@pytest.mark.parametrize("values, unit, scale, label", [
    ([6.9e-12, 1e-13], "m", 1e12, "pm"),        # a coupled run's displacements
    ([2734.6], "Pa", 1e-3, "kPa"),
    ([1.74e-4, 0.0], "N", 1e6, "µN"),
    ([999.0], "Pa", 1.0, "Pa"),
    ([1000.0], "Pa", 1e-3, "kPa"),             # the boundary goes up
    ([-3e-9, 1e-9], "m", 1e9, "nm"),           # magnitude, not sign
    ([0.0, np.nan, np.inf], "m", 1.0, "m"),    # nothing finite and non-zero: the base unit
    ([], "Pa", 1.0, "Pa"),
])
def test_si_scale_puts_the_largest_magnitude_between_1_and_1000(values, unit, scale, label):
    got_scale, got_label = plot.si_scale(values, unit)
    assert got_label == label and got_scale == pytest.approx(scale, rel=1e-12)


def test_permeability_panel_is_a_relative_change():
    k = np.array([2299.606324, 2299.606323, 2299.606350])
    y, label = plot._relative_change(k)
    assert label == "permeability change (ppm of 2300 mD)"
    assert y == pytest.approx((k / k[0] - 1) * 1e6) and y[-1] == pytest.approx(0.01131, rel=1e-3)
    y, label = plot._relative_change(np.array([500.0, 490.0, 481.5]))
    assert label.startswith("permeability change (%") and y[-1] == pytest.approx(-3.7)
