"""The parts of an exchange step, each alone (issue 14: small parts with plain data in and out).

Relaxation against the fixed point of a known linear map; the extraction cache's bookkeeping; the
static solid stepper against a direct solve of the linear elastic problem and its checkpoint
round trip; the load transfer's output view. The loop that composes them is tested in
test_coupled.py, and docs/api.md redoes a first step by hand from these parts.
"""

from __future__ import annotations

import numpy as np
import pytest

from porefsi.coupling import (
    CoupledOptions,
    ExtractionCache,
    Relaxation,
    StaticStepper,
    TractionInterface,
    make_solid_stepper,
    transfer_loads,
)
from porefsi.coupling.solid_step import NEWTON_RTOL
from porefsi.solid import Fixed, SolidModel, box_mesh, make_material


def _iterate(relax: Relaxation, G, n: int) -> list[np.ndarray]:
    out, U = [], relax.start
    for _ in range(n):
        U = relax(G(U))
        out.append(U)
    return out


def test_aitken_finds_the_fixed_point_of_a_scalar_linear_map_in_two_iterations():
    """For G(U) = a U + b Aitken's factor is exact after one step: U_2 = b / (1 - a) to round-off
    (the plain iteration only contracts by |a| per step)."""
    a, b = -0.8, 1.5
    G = lambda U: a * U + b  # noqa: E731
    star = b / (1 - a)
    it = _iterate(Relaxation(np.zeros(1), aitken=True), G, 3)
    assert abs(it[1][0] - star) < 1e-14 * star
    plain = _iterate(Relaxation(np.zeros(1), aitken=False), G, 3)
    np.testing.assert_allclose([p[0] for p in plain], [b, a * b + b, a * (a * b + b) + b], rtol=1e-15)
    assert abs(plain[1][0] - star) > 0.1 * star


def test_relaxation_records_residuals_and_factors():
    r = Relaxation(np.zeros(3), aitken=False)
    U1 = np.array([3.0, 4.0, 0.0])
    np.testing.assert_array_equal(r(U1), U1)  # omega = 1: the solid's answer itself
    assert r.residuals == [1.0] and r.omegas == [1.0]  # |U1 - 0| / |U1|
    r(U1)
    assert r.residuals[-1] == 0.0  # a repeated answer: converged exactly


def test_extraction_cache_serves_by_image_and_counts():
    calls = []

    def make(tag):
        def extract():
            calls.append(tag)
            return tag
        return extract

    img_a, img_b = np.zeros((3, 3, 3), np.uint8), np.ones((3, 3, 3), np.uint8)
    c = ExtractionCache(size=1)
    c.seed(img_a, "seeded")
    assert c.get(img_a, make("a")) == "seeded" and (c.n_computed, c.n_reused) == (0, 1)
    assert c.get(img_b, make("b")) == "b" and c.get(img_b, make("b2")) == "b"
    assert (c.n_computed, c.n_reused, calls) == (1, 2, ["b"])
    assert c.get(img_a, make("a")) == "a"  # size 1: the seed was evicted by b
    off = ExtractionCache(enabled=False)
    off.seed(img_a, "seeded")
    assert off.get(img_a, make("again")) == "again" and off.n_reused == 0


def _model():
    mesh = box_mesh((2, 2, 2), (1e-4, 1e-4, 1e-4))
    return SolidModel(mesh, make_material("svk", E=20e9, nu=0.28), [Fixed("zmin")], linear_solver="direct")


def test_static_stepper_reaches_equilibrium_under_the_end_of_step_load():
    """u1 solves f_int(u1) = f_ext(t0 + dt) with the forces given for t0 + dt (not those of t0);
    v1 is the mean velocity over the step."""
    model = _model()
    F = np.zeros((model.mesh.n_nodes, 3))
    top = model.mesh.points[:, 2] > 0.99e-4
    F[top, 2] = -1e-3  # 1 mN down on each top node
    stepper = StaticStepper(model, rtol=1e-8)
    assert stepper.load_times(0.0, 0.5) == (0.5,)
    u0 = np.zeros(model.n_dofs)
    u1, v1 = stepper.step(u0, u0, 0.0, 0.5, {0.0: np.zeros_like(F), 0.5: F})
    loaded = model.with_nodal_forces(F)
    r = loaded.internal_force(u1, 0.5) - loaded.external_force(0.5)
    assert np.linalg.norm(r) <= 1e-8 * np.linalg.norm(loaded.external_force(0.5))
    assert model.expand(u1, 0.5)[top, 2].max() < 0
    np.testing.assert_array_equal(v1, (u1 - u0) / 0.5)


def test_newton_rtol_bounds_the_static_residual_and_reaches_the_stepper():
    """``newton_rtol`` is the static stepper's stopping rule: the relative residual of a step is below
    it, and a loose tolerance stops earlier (a larger residual) than a tight one."""
    model = _model()
    F = np.zeros((model.mesh.n_nodes, 3))
    F[model.mesh.points[:, 2] > 0.99e-4, 2] = -2e-2  # strains ~1e-3: the nonlinearity needs iterations
    loaded = model.with_nodal_forces(F)
    res = {}
    for rtol in (1e-3, 1e-11):
        stepper = make_solid_stepper(model, "static", newton_rtol=rtol)
        assert isinstance(stepper, StaticStepper) and stepper.rtol == rtol
        u1, _ = stepper.step(np.zeros(model.n_dofs), np.zeros(model.n_dofs), 0.0, 1.0, {1.0: F})
        r = loaded.internal_force(u1, 1.0) - loaded.external_force(1.0)
        res[rtol] = np.linalg.norm(r) / np.linalg.norm(loaded.external_force(1.0))
        assert res[rtol] <= rtol
    assert res[1e-3] > 100 * res[1e-11]
    assert StaticStepper(model).rtol == NEWTON_RTOL == CoupledOptions().solid.newton_rtol


def test_static_stepper_checkpoint_rebuilds_the_same_factorisation():
    """A stepper restored from state() takes the next step bit for bit like the original."""
    model = _model()
    F = np.zeros((model.mesh.n_nodes, 3))
    F[model.mesh.points[:, 2] > 0.99e-4, 0] = 1e-3  # small strain: the reused tangent holds
    a = StaticStepper(model)
    u1, v1 = a.step(np.zeros(model.n_dofs), np.zeros(model.n_dofs), 0.0, 1.0, {1.0: F})
    arrays, meta = a.state()
    assert set(arrays) == {"static_lu_u"} and set(meta) == {"static_lu_t"}
    b = StaticStepper(model)
    b.restore(arrays, meta)
    for s in (a, b):
        s.result = s.step(u1, v1, 1.0, 1.0, {2.0: 1.5 * F})
    np.testing.assert_array_equal(a.result[0], b.result[0])


def test_transfer_loads_draws_outputs_on_the_vertices():
    """With a P2 operator the solid takes the Lagrange-node load, the outputs the vertex split."""
    import scipy.sparse as sp

    T = sp.csr_matrix(np.arange(1.0, 19.0).reshape(18, 1))  # 6 Lagrange nodes, 1 pore
    V = sp.csr_matrix(np.ones((12, 1)))  # 4 vertices
    itf = TractionInterface(T, np.ones(1), (np.arange(4),), 0, 0.0, vertex_operator=V)
    loads = transfer_loads(itf, {1.0: np.array([2.0])}, np.zeros((6, 3)), 0.0, 1.0)
    np.testing.assert_array_equal(loads.forces[1.0], (2.0 * np.arange(1.0, 19.0)).reshape(6, 3))
    np.testing.assert_array_equal(loads.output, np.full((4, 3), 2.0))
    with pytest.raises(Exception, match="pressure must have shape"):
        itf.nodal_forces(np.zeros(2))


def test_carry_state_remaps_by_voxel_overlap():
    """A new topology: each new pore's saturation is the voxel-weighted mean of the old pores its
    voxels belonged to, its fill time the earliest of theirs (plain arrays handed to ``remap``)."""
    from types import SimpleNamespace

    from porefsi.coupling import carry_state

    old_net = SimpleNamespace(n_pores=2, throat_conns=np.array([[0, 1]]), pore_faces=np.zeros((2, 6), bool))
    new_net = SimpleNamespace(n_pores=2, throat_conns=np.zeros((0, 2), int), pore_faces=np.zeros((2, 6), bool))
    got = {}

    class Sim:
        net = old_net
        state = SimpleNamespace(nw_saturation=np.array([1.0, 0.2]))

        def invasion_time(self):
            return np.array([2.0, np.nan])

        def remap(self, net, sat, invasion_time=None):
            got.update(net=net, sat=sat, time=invasion_time)
            return "remapped"

    labels_old = np.array([0, 0, 0, 1, 1, -1])
    labels_new = np.array([0, 1, 1, 1, 1, -1])  # new pore 1: two voxels of old pore 0, two of old pore 1
    assert carry_state(Sim(), new_net, labels_old, labels_new) == "remapped" and got["net"] is new_net
    np.testing.assert_allclose(got["sat"], [1.0, (2 * 1.0 + 2 * 0.2) / 4], rtol=1e-15)
    np.testing.assert_array_equal(got["time"], [2.0, 2.0])
    new_only = np.array([-1, -1, -1, -1, -1, 0])  # a new pore in old solid: empty, never filled
    carry_state(Sim(), new_net, labels_old, new_only)
    assert got["sat"][0] == 0.0 and np.isnan(got["time"][0])


def test_geometric_update_always_maps_the_reference_network():
    """No drift: the network of a total displacement U does not depend on the network it starts
    from, and a uniform dilation scales every pore volume by det F."""
    import porefsi
    from porefsi.coupling import GeometricUpdate, NetworkState
    from porefsi.image import sphere_lattice

    image = sphere_lattice(n=(3, 2, 2), spacing=12, pore_radius=5, throat_radius=2, voxel_size=5e-6).image
    p = porefsi.build_problem(image, porefsi.CoupledOptions(solid=porefsi.SolidOptions(coarsen=3)))
    upd = GeometricUpdate(p.network, p.mesh.points, p.node_spacing)
    start = NetworkState(p.network, p.interface, p.extraction.labels)
    e = 1e-3
    U = e * (p.mesh.points - p.mesh.points.mean(axis=0))  # uniform dilation, F = (1 + e) I
    once = upd.update(U, start)
    twice = upd.update(U, once)
    np.testing.assert_array_equal(twice.network.pore_volume, once.network.pore_volume)
    np.testing.assert_allclose(once.network.pore_volume, p.network.pore_volume * (1 + e) ** 3, rtol=1e-9)
