"""The millidarcy constant, by its literal value and by the darcy's definition."""

import importlib

import numpy as np
import pytest

from porefsi.flow.permeability import absolute_permeability
from porefsi.network.lattice import lattice_network


def _millidarcy_constants():
    """Every place porefsi defines it (the constant may move to porefsi.units; test whichever exist)."""
    found = {}
    for module in ("porefsi.units", "porefsi.flow.permeability"):
        try:
            mod = importlib.import_module(module)
        except ImportError:
            continue
        if hasattr(mod, "MILLIDARCY"):
            found[module] = mod.MILLIDARCY
    assert found, "no MILLIDARCY constant found"
    return found


def test_millidarcy_is_the_literal_value():
    for module, md in _millidarcy_constants().items():
        assert md == 9.869233e-16, module


def test_millidarcy_from_the_darcy_definition():
    """1 D passes 1 cm^3/s of a 1 cP fluid through 1 cm^2 under 1 atm/cm (atm = 101325 Pa exactly):
    k = mu q / (A dp/dx) = 1e-3 * 1e-6 / (1e-4 * 101325 / 1e-2) m^2 = 9.8692327e-13 m^2."""
    darcy = 1e-3 * 1e-6 / (1e-4 * 101325.0 / 1e-2)
    for module, md in _millidarcy_constants().items():
        assert md == pytest.approx(darcy / 1000.0, rel=1e-7, abs=0), module


def test_permeability_result_reports_millidarcy_with_that_value():
    net = lattice_network((5, 4, 3), 1e-4, np.random.default_rng(3))
    res = absolute_permeability(net, axis="x")
    assert res.k_mD == pytest.approx(res.k_m2 / 9.869233e-16, rel=1e-15, abs=0)
