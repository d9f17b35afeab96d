"""Peer cross-checks against OpenPNM (v3): StokesFlow permeability and the Statoil reader.

Run with the peers environment: ``python -m pytest -m peers tests/test_peers_permeability.py``.
OpenPNM is an independent implementation of the same network model: given porefsi's conduit size
factors, it combines the conduit segments itself (``generic_hydraulic``), assembles and solves its
own pressure system (``StokesFlow``) and measures the inlet rate itself (``rate``).

OpenPNM's usual set-up imposes the reservoir pressures at the face pores' centres: porefsi's
``boundary="centre"``. porefsi's default ``boundary="conduit"`` is checked against OpenPNM on a network
extended (``topotools.extend``) with two reservoir pores, each face pore joined to its reservoir by a
throat whose size factor is that of a cylinder of the pore radius from the centre to the face (computed
here from the coordinates, floored at R/4).
"""

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from porefsi.flow.permeability import absolute_permeability
from porefsi.network.convert import from_openpnm, save_network, to_openpnm, write_statoil
from porefsi.network.geometry import conduit_conductance

pytestmark = pytest.mark.peers
op = pytest.importorskip("openpnm")

from tests.test_permeability import lattice_network  # noqa: E402


def _spanning(net, axis):
    """Pores on clusters touching both faces of ``axis`` (computed here, independently of porefsi)."""
    c = net.throat_conns
    adj = sp.coo_matrix((np.ones(len(c)), (c[:, 0], c[:, 1])), shape=(net.n_pores,) * 2)
    _, lab = connected_components(adj, directed=False)
    good = np.intersect1d(lab[net.inlet(axis)], lab[net.outlet(axis)])
    return np.isin(lab, good)


def _openpnm_network(d, drop_pores):
    """An OpenPNM network loaded the way a user would: ``pn.update(dict(numpy.load('NET.npz')))``."""
    pn = op.network.Network(coords=d["pore.coords"], conns=d["throat.conns"])
    pn.update({k: v for k, v in d.items() if not k.startswith("porefsi.") and k not in ("pore.all", "throat.all")})
    if np.any(drop_pores):
        op.topotools.trim(network=pn, pores=np.flatnonzero(drop_pores))
    return pn


def _openpnm_k(net, d, axis, mu=1e-3, dp=1.0):
    keep = _spanning(net, axis)
    pn = _openpnm_network(d, ~keep)
    water = op.phase.Phase(network=pn)
    water["pore.viscosity"] = mu
    water.add_model(propname="throat.hydraulic_conductance",
                    model=op.models.physics.hydraulic_conductance.generic_hydraulic)
    sf = op.algorithms.StokesFlow(network=pn, phase=water)
    sf.set_value_BC(pores=pn.pores(f"{axis}min"), values=dp)
    sf.set_value_BC(pores=pn.pores(f"{axis}max"), values=0.0)
    sf.run()
    q = float(sf.rate(pores=pn.pores(f"{axis}min"), mode="group")[0])
    ext = net.extent
    ax = "xyz".index(axis)
    k = q * mu * ext[ax] / (np.prod(np.delete(ext, ax)) * dp)
    pressure = np.full(net.n_pores, np.nan)
    pressure[keep] = sf["pore.pressure"]
    g = water["throat.hydraulic_conductance"]
    return k, pressure, g, keep


def _compare(net, axis):
    d = to_openpnm(net)
    k_op, p_op, g_op, keep = _openpnm_k(net, d, axis)
    res = absolute_permeability(net, axis, boundary="centre")
    assert res.k_m2 == pytest.approx(k_op, rel=1e-10, abs=0)
    np.testing.assert_array_equal(np.isnan(res.pressure), ~keep)
    np.testing.assert_allclose(res.pressure[keep], p_op[keep], rtol=0, atol=1e-10)
    # OpenPNM's own series combination of the size factors equals porefsi's conductance.
    t_keep = keep[net.throat_conns[:, 0]]
    np.testing.assert_allclose(g_op, conduit_conductance(net, 1e-3)[t_keep], rtol=1e-13)
    return res.k_m2


@pytest.mark.parametrize("axis", ["x", "y", "z"])
def test_stokesflow_random_lattice(rng, axis):
    net = lattice_network((7, 6, 5), rng=rng, drop=0.3)
    _compare(net, axis)


def test_stokesflow_extracted_berea_sample():
    from porefsi.image import load_sample
    from porefsi.network.extract import extract_network

    net = extract_network(load_sample()).network
    ks = [_compare(net, ax) for ax in "xyz"]
    assert min(ks) > 0


def _openpnm_k_reservoirs(net, axis, mu=1e-3, dp=1.0):
    """OpenPNM StokesFlow with two reservoir pores joined to the face pores by boundary-conduit throats."""
    keep = _spanning(net, axis)
    pn = _openpnm_network(to_openpnm(net), ~keep)
    ax = "xyz".index(axis)
    lo = net.origin[ax]
    hi = lo + net.extent[ax]
    x, R = pn["pore.coords"][:, ax], pn["pore.diameter"] / 2
    new_throats, factors = [], []
    for k, (face, dist) in enumerate(((f"{axis}min", x - lo), (f"{axis}max", hi - x))):
        ps = pn.pores(face)
        new_throats.append(np.column_stack([ps, np.full(ps.size, pn.Np + k)]))
        factors.append(np.pi * R[ps] ** 4 / (8 * np.maximum(dist[ps], R[ps] / 4)))  # Hagen-Poiseuille
    centre = pn["pore.coords"].mean(axis=0)
    res_coords = np.array([centre, centre])
    res_coords[:, ax] = lo, hi
    nt0 = pn.Nt
    op.topotools.extend(network=pn, coords=res_coords, conns=np.concatenate(new_throats))
    sf_all = pn["throat.hydraulic_size_factors"]
    sf_all[nt0:] = np.column_stack([np.full(sf_all.shape[0] - nt0, np.inf), np.concatenate(factors),
                                    np.full(sf_all.shape[0] - nt0, np.inf)])
    pn["throat.hydraulic_size_factors"] = sf_all
    water = op.phase.Phase(network=pn)
    water["pore.viscosity"] = mu
    water.add_model(propname="throat.hydraulic_conductance",
                    model=op.models.physics.hydraulic_conductance.generic_hydraulic)
    sf = op.algorithms.StokesFlow(network=pn, phase=water)
    sf.set_value_BC(pores=[pn.Np - 2], values=dp)
    sf.set_value_BC(pores=[pn.Np - 1], values=0.0)
    sf.run()
    q = float(sf.rate(pores=[pn.Np - 2], mode="group")[0])
    pressure = np.full(net.n_pores, np.nan)
    pressure[keep] = sf["pore.pressure"][:-2]
    return q, pressure


@pytest.mark.parametrize("axis", ["x", "y", "z"])
def test_conduit_boundary_against_openpnm_reservoir_pores(rng, axis):
    net = lattice_network((7, 6, 5), rng=rng, drop=0.3)
    # Move the face pores about so the boundary conduits differ (some floored at R/4).
    ax = "xyz".index(axis)
    coords = net.pore_coords.copy()
    lo, hi = net.origin[ax], net.origin[ax] + net.extent[ax]
    inl, out = net.inlet(axis), net.outlet(axis)
    coords[inl, ax] = lo + rng.uniform(0.0, 5e-6, inl.sum())
    coords[out, ax] = hi - rng.uniform(0.0, 5e-6, out.sum())
    net = net.replace(pore_coords=coords)
    q_op, p_op = _openpnm_k_reservoirs(net, axis)
    res = absolute_permeability(net, axis)
    assert res.flow_rate == pytest.approx(q_op, rel=1e-10, abs=0)
    np.testing.assert_array_equal(np.isnan(res.pressure), np.isnan(p_op))
    ok = np.isfinite(p_op)
    np.testing.assert_allclose(res.pressure[ok], p_op[ok], rtol=0, atol=1e-10)


def test_conduit_boundary_extracted_berea_sample_against_openpnm():
    from porefsi.image import load_sample
    from porefsi.network.extract import extract_network

    net = extract_network(load_sample()).network
    for axis in "xyz":
        q_op, p_op = _openpnm_k_reservoirs(net, axis)
        res = absolute_permeability(net, axis)
        assert res.flow_rate == pytest.approx(q_op, rel=1e-10, abs=0)
        ok = np.isfinite(p_op)
        np.testing.assert_allclose(res.pressure[ok], p_op[ok], rtol=0, atol=1e-10)


def test_npz_loads_into_openpnm(rng, tmp_path):
    net = lattice_network((4, 3, 3), rng=rng)
    p = save_network(net, tmp_path / "net.npz")
    pn = _openpnm_network(dict(np.load(p)), np.zeros(net.n_pores, bool))
    assert pn.Np == net.n_pores and pn.Nt == net.n_throats
    np.testing.assert_array_equal(pn["pore.coords"], net.pore_coords)
    np.testing.assert_array_equal(pn.pores("xmin"), np.flatnonzero(net.inlet("x")))


@pytest.mark.parametrize("axis", ["x", "z"])
def test_statoil_files_read_by_openpnm(rng, tmp_path, axis):
    net = lattice_network((4, 3, 3), rng=rng, drop=0.2, offset=(1e-4, 2e-4, 3e-4))
    write_statoil(net, tmp_path / "pn", axis)
    pn = op.io.network_from_statoil(path=tmp_path, prefix="pn")
    perm = {"x": [0, 1, 2], "z": [2, 0, 1]}[axis]
    assert pn.Np == net.n_pores and pn.Nt == net.n_throats
    np.testing.assert_allclose(pn["pore.coords"], (net.pore_coords - net.origin)[:, perm], rtol=1e-15)
    np.testing.assert_array_equal(np.sort(pn["throat.conns"], axis=1), net.throat_conns)
    np.testing.assert_array_equal(pn["throat.radius"], net.throat_radius)
    np.testing.assert_array_equal(pn["pore.radius"], net.pore_radius)
    np.testing.assert_array_equal(pn["throat.conduit_lengths.pore1"], net.throat_pore_length[:, 0])
    np.testing.assert_array_equal(pn["throat.length"], net.throat_length)
    np.testing.assert_array_equal(pn.pores("inlets"), np.flatnonzero(net.inlet(axis)))
    np.testing.assert_array_equal(pn.pores("outlets"), np.flatnonzero(net.outlet(axis)))


@pytest.mark.parametrize("axis", ["x", "z"])
def test_openpnm_cubic_with_openpnm_geometry(axis):
    """An OpenPNM-built network (Cubic + its spheres_and_cylinders geometry, random sizes) read by
    from_openpnm: porefsi's conduit closed forms and solve against OpenPNM's own size factors and StokesFlow."""
    pn = op.network.Cubic(shape=[6, 5, 4], spacing=1e-4)
    pn.add_model_collection(op.models.collections.geometry.spheres_and_cylinders)
    pn.regenerate_models()
    pn["throat.conduit_lengths"] = op.models.geometry.conduit_lengths.spheres_and_cylinders(pn)
    net = from_openpnm(pn, voxel_size=1e-5, shape=(60, 50, 40))
    water = op.phase.Phase(network=pn)
    water["pore.viscosity"] = 1e-3
    water.add_model(propname="throat.hydraulic_conductance",
                    model=op.models.physics.hydraulic_conductance.generic_hydraulic)
    np.testing.assert_allclose(conduit_conductance(net, 1e-3), water["throat.hydraulic_conductance"], rtol=1e-12)
    sf = op.algorithms.StokesFlow(network=pn, phase=water)
    sf.set_value_BC(pores=pn.pores(f"{axis}min"), values=1.0)
    sf.set_value_BC(pores=pn.pores(f"{axis}max"), values=0.0)
    sf.run()
    q = float(sf.rate(pores=pn.pores(f"{axis}min"), mode="group")[0])
    res = absolute_permeability(net, axis, boundary="centre")
    assert res.flow_rate == pytest.approx(q, rel=1e-10, abs=0)
    np.testing.assert_allclose(res.pressure, sf["pore.pressure"], rtol=0, atol=1e-10)
