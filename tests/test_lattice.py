"""Synthetic networks: geometry conventions the flow tests rely on."""

import numpy as np
import pytest

from porefsi.errors import InputError
from porefsi.network.geometry import resistance_factors
from porefsi.network.lattice import chain_network, lattice_network, parallel_paths_network, tube_network


def test_tube_tiles_the_cylinder():
    net = tube_network(10, 1e-5, 1e-3)
    assert net.pore_volume.sum() == pytest.approx(np.pi * 1e-10 * 1e-3, rel=1e-14, abs=0)
    # every conduit is a cylinder of the tube radius whose length is the spacing: 8 d / (pi r^4)
    np.testing.assert_allclose(resistance_factors(net).sum(axis=1), 8 * 1e-4 / (np.pi * 1e-20), rtol=1e-12)
    assert net.inlet("x").sum() == 1 and net.outlet("x").sum() == 1


def test_lattice_shapes_and_faces(rng):
    net = lattice_network((4, 3, 2), 1e-4, rng)
    assert net.n_pores == 24 and net.n_throats == 3 * 3 * 2 + 4 * 2 * 2 + 4 * 3 * 1
    assert net.inlet("x").sum() == 6 and net.outlet("z").sum() == 12
    assert np.all(net.throat_radius <= np.minimum(*net.pore_radius[net.throat_conns].T))
    d = np.linalg.norm(np.diff(net.pore_coords[net.throat_conns], axis=1)[:, 0], axis=1)
    np.testing.assert_allclose(net.throat_length + net.throat_pore_length.sum(axis=1), d, rtol=1e-12)
    flat = lattice_network((5, 5, 1), 1e-4, rng)
    assert flat.coordination.max() == 4


def test_builders_validate(rng):
    with pytest.raises(InputError):
        chain_network([1e-5, 1e-5], [1e-5, 1e-5], 1e-4)
    with pytest.raises(InputError):
        chain_network([6e-5, 1e-5], [1e-6], 1e-4)
    with pytest.raises(InputError):
        lattice_network((2, 2, 1), 1e-4, rng, pore_radius=(0.2, 0.6))
    net = parallel_paths_network(3e-5, [1e-5, 8e-6, 6e-6, 1e-5], 1e-4)
    assert net.inlet("x").tolist() == [True, False, False, False]
