"""Solid physics against closed forms: homogeneous finite strain, Lame shell, column frequency,
equilibrium of reactions and loads, the integrator protocol."""

import numpy as np
import pytest
import scipy.linalg as sl
from scipy.optimize import brentq

from porefsi.integrators.system import SecondOrderSystem
from porefsi.solid.bc import Affine, Fixed, Prescribed, Roller, Traction, face_nodes, uniaxial_bcs
from porefsi.solid.materials import NeoHookean, StVenantKirchhoff
from porefsi.solid.model import SolidModel
from porefsi.solid.shapes import box_mesh, shell_octant_mesh
from porefsi.solid.static import solve_static, uniaxial_compression
from porefsi.solid.stress import element_cauchy, nodal_average, von_mises

MAT = StVenantKirchhoff(E=20e9, nu=0.28)


def _uniaxial_stress_closed_form(mat, c):
    """Lateral stretch a and nominal stress P_zz for uniaxial stress with axial stretch c.

    SVK: E_xx = -nu E_zz, S_zz = E E_zz, P_zz = c S_zz. Neo-Hookean: P_xx = 0 solved for a.
    (Holzapfel 2000, sec. 6.5; Bonet & Wood 2008, sec. 6.4.3.)
    """
    if isinstance(mat, StVenantKirchhoff):
        Ez = 0.5 * (c**2 - 1)
        return np.sqrt(1 - 2 * mat.nu * Ez), c * mat.E * Ez
    lam, mu = mat.lam, mat.mu
    a = brentq(lambda a: mu * (a - 1 / a) + lam * np.log(a * a * c) / a, 0.2, 3.0, xtol=1e-15, rtol=1e-15)
    return a, mu * (c - 1 / c) + lam * np.log(a * a * c) / c


@pytest.mark.parametrize("mat", [StVenantKirchhoff(1e9, 0.3), NeoHookean(1e9, 0.3)], ids=["svk", "nh"])
@pytest.mark.parametrize("c", [1.3, 0.8])
def test_homogeneous_uniaxial_stress_finite_strain(mat, c):
    """30 % stretch / 20 % compression: P1 reproduces the homogeneous closed form to round-off."""
    L = 2e-4
    m = box_mesh((2, 2, 3), (1e-4, 1e-4, L))
    bcs = [Roller("xmin"), Roller("ymin"), Roller("zmin"), Prescribed("zmax", "z", 0.0, (c - 1) * L)]
    model = SolidModel(m, mat, bcs)
    u = np.zeros(model.n_dofs)
    for t in np.linspace(0.25, 1.0, 4):
        u, info = solve_static(model, t, u0=u, t_prev=t - 0.25, rtol=1e-12)
    a, Pzz = _uniaxial_stress_closed_form(mat, c)
    U = model.expand(u, 1.0)
    np.testing.assert_allclose(U[:, 0], (a - 1) * m.points[:, 0], atol=1e-12 * L)
    np.testing.assert_allclose(U[:, 2], (c - 1) * m.points[:, 2], atol=1e-12 * L)
    R = model.reactions(u, 1.0)
    assert R["zmax"][2] == pytest.approx(Pzz * 1e-8, rel=1e-9)
    assert R["zmin"][2] == pytest.approx(-Pzz * 1e-8, rel=1e-9)
    # Cauchy: sigma_zz = P_zz c / J with J = a^2 c, the rest zero; von Mises = |sigma_zz|
    sig = element_cauchy(model, u, 1.0)
    szz = Pzz * c / (a * a * c)
    np.testing.assert_allclose(sig[:, 2, 2], szz, rtol=1e-9)
    np.testing.assert_allclose(von_mises(sig), abs(szz), rtol=1e-9)
    np.testing.assert_allclose(nodal_average(m, von_mises(sig)), abs(szz), rtol=1e-9)


@pytest.mark.parametrize("law", ["svk", "neo-hookean"])
@pytest.mark.parametrize("scale", [1e-7, 0.05])
def test_element_cauchy_fused_against_reference(law, scale, rng):
    """The fused P1 kernel's sigma = P F^T / J on a random displacement of a box: per element
    against the reference twin (its own gradients and first PK stress), at rock strains and at 5 %."""
    from tests.reference.solid_ref import first_pk_ref, p1_gradients_ref

    mat = StVenantKirchhoff(20e9, 0.28) if law == "svk" else NeoHookean(20e9, 0.28)
    m = box_mesh((2, 3, 2), (1e-4, 1.5e-4, 1e-4))
    model = SolidModel(m, mat)
    u = scale * 1e-4 * rng.standard_normal(model.n_dofs)
    sig = element_cauchy(model, u, 0.0)
    dN, _ = p1_gradients_ref(m.points, m.tets)
    disp = model.full_displacement(u, 0.0).reshape(-1, 3)
    for e, tet in enumerate(m.tets):
        H = disp[tet].T @ dN[e]  # H_iJ = sum_a u_ai dN_aJ
        F = np.eye(3) + H
        want = first_pk_ref(law, 20e9, 0.28, H) @ F.T / np.linalg.det(F)
        np.testing.assert_allclose(sig[e], want, rtol=1e-9, atol=1e-12 * np.abs(want).max())


def test_uniaxial_strain_modulus_and_equilibrium():
    """A pore-free box under the paper's BCs: E_eff -> lambda + 2 mu (uniaxial strain) as strain -> 0,
    and the reactions on the two platens balance."""
    m = box_mesh((3, 3, 3), (1e-4, 1e-4, 1e-4))
    res = uniaxial_compression(m, MAT, strain=1e-7)
    assert res.effective_modulus == pytest.approx(MAT.lam + 2 * MAT.mu, rel=1e-6)
    assert res.reaction[2] < 0  # the platen pushes down on the solid
    model = SolidModel(m, MAT, uniaxial_bcs("z", rate=-1e-3 * 1e-4))
    u, _ = solve_static(model, 1.0, rtol=1e-12)  # the imbalance is bounded by the Newton residual
    R = model.reactions(u, 1.0)
    assert abs(R["zmax"][2] + R["zmin"][2]) <= 1e-10 * abs(R["zmax"][2])


def test_nodal_forces_balance_reactions(rng):
    """Nodal (pore-pressure-like) forces on a body fixed at zmin: the support reaction is -sum F.
    with_nodal_forces swaps the load without reassembling anything."""
    m = box_mesh((2, 2, 2), (1e-4, 1e-4, 1e-4))
    base = SolidModel(m, MAT, [Fixed("zmin")])
    F = 1e-3 * rng.standard_normal((m.n_nodes, 3))
    model = base.with_nodal_forces(F)
    assert model._p1 is base._p1 and np.all(base.external_force(0.0) == 0)
    u, _ = solve_static(model, 0.0, rtol=1e-11)
    R = model.reactions(u, 0.0)["zmin"]
    # internal forces are self-equilibrated, so the support carries every applied force
    np.testing.assert_allclose(R, -F.sum(axis=0), atol=1e-9 * np.abs(F).sum())
    timed = base.with_nodal_forces(lambda t: t * F)
    np.testing.assert_allclose(timed.external_force(0.5), 0.5 * model.external_force(0.0))


def test_model_implements_the_integrator_protocol():
    m = box_mesh((2, 2, 2), (1e-4, 1e-4, 1e-4))
    model = SolidModel(m, MAT, uniaxial_bcs("z", rate=-1e-7))
    assert isinstance(model, SecondOrderSystem)
    n = model.n_dofs
    u = np.zeros(n)
    assert model.mass().shape == (n,) and np.all(model.mass() > 0)
    assert model.internal_force(u, 1.0).shape == (n,)
    K = model.tangent(u, 1.0)
    assert K.shape == (n, n) and abs(K - K.T).max() <= 1e-12 * abs(K).max()
    assert model.expand(u, 1.0)[m.points[:, 2] == m.points[:, 2].max(), 2] == pytest.approx(-1e-7)
    x = model.make_solver(K)(np.ones(n))
    np.testing.assert_allclose(K @ x, np.ones(n), rtol=1e-8)
    p2 = SolidModel(m, MAT, [Fixed("zmin")], order=2)
    assert p2.mass().shape == (p2.n_dofs, p2.n_dofs)


def _lame_error(order, n, a=1.0, b=2.0, p=1e-3):
    """Max radial-displacement error (relative to u_r(a)) on a pressurised shell octant.

    Lame (e.g. Timoshenko & Goodier 1951, sec. 136): u_r = A r + B / r^2,
    A = p a^3 (1 - 2 nu) / (E (b^3 - a^3)), B = p a^3 b^3 (1 + nu) / (2 E (b^3 - a^3)).
    Linear elasticity: the tangent at u = 0.
    """
    mat = StVenantKirchhoff(1.0, 0.3)
    E, nu = mat.E, mat.nu
    A = p * a**3 * (1 - 2 * nu) / (E * (b**3 - a**3))
    B = p * a**3 * b**3 * (1 + nu) / (2 * E * (b**3 - a**3))
    m = shell_octant_mesh(a, b, n)
    model = SolidModel(m, mat, [Roller("xmin"), Roller("ymin"), Roller("zmin")],
                       tractions=[Traction("pore_wall", pressure=p)], order=order)
    K = model.tangent(np.zeros(model.n_dofs), 0.0)
    u = model.make_solver(K)(model.external_force(0.0))
    full = model.full_displacement(u, 0.0).reshape(-1, 3)
    X = model.dof_points
    r = np.linalg.norm(X, axis=1)
    ur = np.einsum("ij,ij->i", full, X) / r
    return np.abs(ur - (A * r + B / r**2)).max() / (A * a + B / a**2)


def _order(ns, errs):
    """Fitted convergence order: slope of log(error) against log(h), h ~ 1/n."""
    return np.polyfit(np.log(1.0 / np.asarray(ns)), np.log(errs), 1)[0]


def test_lame_hollow_sphere_p1_p2():
    """P1 converges (pre-asymptotic max-norm slope ~1.4, -> 2 on finer meshes, see the slow sweep);
    P2 at slope 2 (limited by the flat-faceted boundary, an O(h^2) geometry error) and ~4x smaller
    error than P1 at the same mesh."""
    e1 = [_lame_error(1, n) for n in (6, 12)]
    e2 = [_lame_error(2, n) for n in (4, 8)]
    assert e1[1] < 0.1 and _order((6, 12), e1) > 1.3
    assert _order((4, 8), e2) > 1.8
    assert _lame_error(2, 6) < 0.5 * _lame_error(1, 6)


@pytest.mark.slow
def test_lame_hollow_sphere_convergence_sweep():
    """Sweep: P1 n = 6..48, pairwise slopes rising towards 2 (measured 1.42, 1.58, 1.67);
    P2 n = 4..12 (slope > 1.8, the flat-facet geometric limit is 2)."""
    ns1 = (6, 12, 24, 48)
    e1 = [_lame_error(1, n) for n in ns1]
    slopes = [_order(ns1[i:i + 2], e1[i:i + 2]) for i in range(3)]
    assert slopes[0] < slopes[1] < slopes[2] < 2.05
    assert slopes[2] > 1.6
    ns2 = (4, 6, 8, 12)
    e2 = [_lame_error(2, n) for n in ns2]
    assert _order(ns2, e2) > 1.8


def _column_error(order, n):
    """Lowest eigenfrequency of a column (fixed base, free top, lateral rollers) vs the exact
    uniaxial-strain rod value omega_1 = pi / (2 L) sqrt((lambda + 2 mu) / rho) (e.g. Graff 1975,
    Wave Motion in Elastic Solids, sec. 2.1, with the P-wave modulus since lateral strain is zero)."""
    a, L = 1e-4, 8e-4
    w_ex = np.pi / (2 * L) * np.sqrt((MAT.lam + 2 * MAT.mu) / MAT.density)
    m = box_mesh((2, 2, n), (a, a, L))
    model = SolidModel(m, MAT, [Fixed("zmin")] + [Roller(f) for f in ("xmin", "xmax", "ymin", "ymax")],
                       order=order)
    K = model.tangent(np.zeros(model.n_dofs), 0.0).toarray()
    M = model.mass()
    M = np.diag(M) if np.ndim(M) == 1 else M.toarray()
    ev, V = sl.eigh(K, M, subset_by_index=[0, 1])
    U = model.expand(V[:, 0], 0.0)
    assert np.abs(U[:, :2]).max() <= 1e-8 * np.abs(U[:, 2]).max()  # an axial mode
    return (np.sqrt(ev[0]) - w_ex) / w_ex, np.sqrt(ev[1] / ev[0])


def test_column_eigenfrequency():
    """P1 lumped mass: below the exact frequency, O(h^2); P2 consistent mass: above it (Rayleigh-Ritz
    upper bound), O(h^4); second mode = 3x the first (odd quarter-wave harmonics)."""
    (e4, _), (e8, r8) = _column_error(1, 4), _column_error(1, 8)
    assert e8 < 0 and e4 < e8
    assert np.log2(e4 / e8) > 1.7
    assert r8 == pytest.approx(3.0, rel=0.03)
    (f4, _), (f8, s8) = _column_error(2, 4), _column_error(2, 8)
    assert 0 < f8 < f4
    assert np.log2(f4 / f8) > 3.5
    assert s8 == pytest.approx(3.0, rel=1e-3)


def test_inverting_load_step_raises_mesh_error():
    """A 30 % compression of the porous rock in one increment inverts elements: MeshError names the
    count and suggests more increments; 1e-3 in one increment is fine (2 linear solves: the
    predictor and one Newton correction)."""
    from pathlib import Path

    from porefsi.errors import MeshError
    from porefsi.image.voxel_image import VoxelImage
    from porefsi.solid.mesh import mesh_solid

    d = np.load(Path(__file__).resolve().parents[1] / "porefsi" / "data" / "berea_icl_120_paper.npz")
    mesh = mesh_solid(VoxelImage(d["image"], float(d["voxel_size_m"])), coarsen=12).mesh
    with pytest.raises(MeshError, match=r"\d+ of \d+ elements inverted.*n_steps=2"):
        uniaxial_compression(mesh, MAT, strain=0.3)
    res = uniaxial_compression(mesh, MAT, strain=1e-3)
    assert res.newton[0].converged and res.newton[0].iterations == 2


def _layers_image(solid_layers, shape=(6, 6, 8), h=1e-6):
    """VoxelImage with solid (0) in the z layers ``solid_layers``, pore (1) elsewhere."""
    from porefsi.image.voxel_image import VoxelImage

    ph = np.ones(shape, np.uint8)
    ph[:, :, list(solid_layers)] = 0
    return VoxelImage(ph, h)


def test_load_frame_needs_solid_on_the_image_box_faces():
    """Solid in the bottom 3 of 8 voxel layers: the image box's zmax face has no solid, so there is
    no platen contact; the frame must not grab the slab's top (pore wall) instead (it used to, and
    reported E_eff = 25.5 GPa). Two slabs, one on each face, with pore between: no load path."""
    from porefsi.errors import MeshError
    from porefsi.solid.mesh import mesh_solid

    slab = mesh_solid(_layers_image(range(3)), coarsen=1).mesh
    np.testing.assert_allclose(slab.box, [[0, 0, 0], [6e-6, 6e-6, 8e-6]])
    assert slab.bounds[1, 2] == pytest.approx(3e-6)
    with pytest.raises(MeshError, match=r"no solid reaches the zmax face of the image box.*\[0, 8e-06\]"):
        uniaxial_compression(slab, MAT, strain=1e-3)
    # the bare model too: a prescribed motion on a face without solid is an error, not a no-op ...
    with pytest.raises(MeshError, match="no solid reaches the zmax face"):
        SolidModel(slab, MAT, uniaxial_bcs("z", rate=-1e-9))
    # ... while loading along x (solid on both x faces) works, the box area being 6 x 8 voxels
    res = uniaxial_compression(slab, MAT, strain=1e-6, axis="x")
    assert np.isfinite(res.effective_modulus) and res.effective_modulus > 0
    apart = mesh_solid(_layers_image([0, 1, 2, 5, 6, 7]), coarsen=1).mesh
    with pytest.raises(MeshError, match="no connected solid joins the zmin and zmax faces"):
        uniaxial_compression(apart, MAT, strain=1e-3)


def test_effective_modulus_uses_the_image_box_area():
    """A 2 x 2-voxel column through a 6 x 6 x 8 image, nu = 0: the column is in uniaxial stress
    sigma = E eps whatever the end conditions (no lateral expansion to restrain), so the apparent
    modulus of the sample is E A_column / A_box = E / 9 (the old mesh-bounding-box area gave E).
    The lateral rollers touch no solid and hold nothing."""
    from porefsi.image.voxel_image import VoxelImage
    from porefsi.solid.mesh import mesh_solid

    ph = np.ones((6, 6, 8), np.uint8)
    ph[2:4, 2:4, :] = 0
    mesh = mesh_solid(VoxelImage(ph, 1e-6), coarsen=1).mesh
    mat = StVenantKirchhoff(E=20e9, nu=0.0)
    strain = 1e-7
    res = uniaxial_compression(mesh, mat, strain=strain)
    # SVK in uniaxial stress: P_zz = c E (c^2 - 1) / 2 = -E eps (1 - 3 eps / 2 + O(eps^2))
    assert res.effective_modulus == pytest.approx(mat.E * (2 * 2) / (6 * 6), rel=3 * strain)
    np.testing.assert_allclose(res.u[:, 2], -strain * mesh.points[:, 2], atol=1e-9 * strain * 8e-6)


def test_p2_face_nodes_are_the_tagged_facets_nodes():
    """P2: the Dirichlet nodes of a box face are the vertices and edge midpoints of its tagged
    facets, which on a full box are exactly the Lagrange nodes on the face's plane."""
    from porefsi.solid.bc import face_nodes

    m = box_mesh((2, 3, 2), (1e-4, 2e-4, 1e-4))
    model = SolidModel(m, MAT, [Fixed("zmin")], order=2)
    for k, face in enumerate(("xmin", "xmax", "ymin", "ymax", "zmin", "zmax")):
        ax, side = divmod(k, 2)
        plane = np.flatnonzero(np.isclose(model.dof_points[:, ax], m.box[side, ax], rtol=0, atol=1e-15))
        np.testing.assert_array_equal(face_nodes(m, model.dof_points, face), plane)
    assert len(model.constraints.dofs) == 3 * int(np.sum(np.isclose(model.dof_points[:, 2], 0.0)))


@pytest.mark.parametrize("order", [1, 2])
def test_traction_vector_total_load_and_reaction(order):
    """A uniform traction vector t with shear components on the zmax face of a box fixed at zmin:
    the consistent nodal loads add up to t A (A = 1e-4 x 2e-4 m^2, the zmax face), and at
    equilibrium the support reaction on zmin is -t A (global force balance: the internal forces are
    self-equilibrated). Also on a lateral face (xmax, A = 2e-4 x 3e-4 m^2)."""
    m = box_mesh((2, 2, 3), (1e-4, 2e-4, 3e-4))
    t = np.array([3e5, -2e5, 1e5])  # Pa: small strains (t / E ~ 1e-5), linear regime
    for face, area in (("zmax", 1e-4 * 2e-4), ("xmax", 2e-4 * 3e-4)):
        model = SolidModel(m, MAT, [Fixed("zmin")], tractions=[Traction(face, traction=tuple(t))], order=order)
        f = model.full_external_force(0.0).reshape(-1, 3)
        np.testing.assert_allclose(f.sum(axis=0), t * area, rtol=1e-12)
        # only the nodes of the loaded face carry load
        loaded = np.zeros(len(f), bool)
        loaded[face_nodes(m, model.dof_points, face)] = True
        assert np.all(f[~loaded] == 0) and np.any(f[loaded] != 0)
        u, _ = solve_static(model, 0.0, rtol=1e-12)
        np.testing.assert_allclose(model.reactions(u, 0.0)["zmin"], -t * area, rtol=1e-9)


def _cauchy_closed_form(mat, F):
    """Cauchy stress of a homogeneous deformation F (3, 3), written independently of the code.

    SVK: sigma = J^-1 F S F^T, S = lambda tr(E) I + 2 mu E, E = (F^T F - I)/2 (Holzapfel 2000,
    sec. 6.5). Neo-Hookean: sigma = (mu / J)(F F^T - I) + (lambda ln J / J) I (Bonet & Wood 2008,
    eq. 6.29)."""
    J = np.linalg.det(F)
    if isinstance(mat, StVenantKirchhoff):
        E = 0.5 * (F.T @ F - np.eye(3))
        S = mat.lam * np.trace(E) * np.eye(3) + 2 * mat.mu * E
        return F @ S @ F.T / J
    return mat.mu / J * (F @ F.T - np.eye(3)) + mat.lam * np.log(J) / J * np.eye(3)


@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("mat", [StVenantKirchhoff(20e9, 0.28), NeoHookean(20e9, 0.28)], ids=["svk", "nh"])
def test_cauchy_shear_components_on_a_general_affine_field(mat, order):
    """A general affine field u = G X (every component of G nonzero: shear, stretch, rotation, a
    few per cent) imposed on the whole boundary: every element carries the closed-form Cauchy
    stress, all nine components (shear ones of the order of the normal ones), symmetric, and the
    von Mises value of the closed form."""
    G = np.array([[0.02, 0.03, -0.02], [0.01, -0.01, 0.025], [-0.015, 0.02, 0.005]])
    m = box_mesh((2, 2, 2), (1e-4, 1e-4, 1e-4))
    model = SolidModel(m, mat, [Affine(f, G) for f in ("xmin", "xmax", "ymin", "ymax", "zmin", "zmax")],
                       order=order)
    u, info = solve_static(model, 0.0, rtol=1e-13)
    sig = element_cauchy(model, u, 0.0)
    exact = _cauchy_closed_form(mat, np.eye(3) + G)
    off = ~np.eye(3, dtype=bool)
    assert np.abs(exact[off]).min() > 0.2 * np.abs(exact).max()  # shear of the order of the normal stresses
    np.testing.assert_allclose(sig, np.broadcast_to(exact, sig.shape), rtol=0, atol=1e-9 * np.abs(exact).max())
    np.testing.assert_allclose(sig, sig.transpose(0, 2, 1), rtol=0, atol=1e-9 * np.abs(exact).max())
    s = exact - np.trace(exact) / 3 * np.eye(3)
    np.testing.assert_allclose(von_mises(sig), np.sqrt(1.5 * np.sum(s * s)), rtol=1e-9)


def test_nodal_von_mises_is_volume_weighted():
    """Nodal von Mises on a graded mesh (the Lame shell octant, element volumes vary ~9x) from a
    non-uniform field (pressurised shell: von Mises falls like r^-3): equal to a naive volume-
    weighted twin, sum_e V_e s_e / sum_e V_e over the elements at each node, and measurably
    different from the unweighted mean (so a dropped weight would fail)."""
    from porefsi.solid.mesh import tet_volumes

    m = shell_octant_mesh(1.0, 2.0, 6)
    mat = StVenantKirchhoff(1.0, 0.3)
    model = SolidModel(m, mat, [Roller("xmin"), Roller("ymin"), Roller("zmin")],
                       tractions=[Traction("pore_wall", pressure=1e-3)])
    u = model.make_solver(model.tangent(np.zeros(model.n_dofs), 0.0))(model.external_force(0.0))
    vm = von_mises(element_cauchy(model, u, 0.0))
    V = tet_volumes(m.points, m.tets)
    assert V.max() / V.min() > 5 and vm.max() / vm.min() > 3
    twin = np.zeros(m.n_nodes)
    plain = np.zeros(m.n_nodes)
    for a in range(m.n_nodes):
        els = np.flatnonzero(np.any(m.tets == a, axis=1))
        twin[a] = np.sum(V[els] * vm[els]) / np.sum(V[els])
        plain[a] = vm[els].mean()
    nodal = nodal_average(m, vm)
    np.testing.assert_allclose(nodal, twin, rtol=1e-12)
    assert np.abs(plain - twin).max() > 1e-3 * vm.max()
    # trailing dimensions: the (Ne, 3, 3) stress averages component by component
    sig = element_cauchy(model, u, 0.0)
    np.testing.assert_allclose(nodal_average(m, sig)[:, 0, 1], nodal_average(m, sig[:, 0, 1]), rtol=1e-12)


def test_svk_instability_in_compression_is_named():
    """Uniaxial-stress compression of a box, AMG-CG solves, increments of 10 %: St Venant-Kirchhoff's
    nominal stress c E (c^2 - 1) / 2 peaks at c = 1/sqrt(3) = 0.577 and its tangent turns
    indefinite below; CG's breakdown is then reported as that instability (it used to say only
    'AMG-CG breakdown ... not SPD?'), naming the stretch and the neo-Hookean remedy. Neo-Hookean
    compresses to c = 0.5 (the same increments) without trouble."""
    from porefsi.solid.linsolve import IndefiniteMatrixError
    from porefsi.solid.static import SVK_CRITICAL_STRETCH

    L = 4e-4
    m = box_mesh((2, 2, 4), (2e-4, 2e-4, L))
    bcs = [Roller("xmin"), Roller("ymin"), Roller("zmin"), Prescribed("zmax", "z", 0.0, -0.5 * L)]
    ts = np.linspace(0.1, 1.0, 10)
    for mat in (StVenantKirchhoff(1e9, 0.3), NeoHookean(1e9, 0.3)):
        model = SolidModel(m, mat, bcs, linear_solver="amg")
        u, t_prev, reached = np.zeros(model.n_dofs), 0.0, 0.0
        try:
            for t in ts:
                u, _ = solve_static(model, t, u0=u, t_prev=t_prev)
                t_prev = reached = t
        except IndefiniteMatrixError as exc:
            assert isinstance(mat, StVenantKirchhoff)
            msg = str(exc)
            assert "not positive definite" in msg and "St Venant-Kirchhoff is unstable in strong compression" in msg
            assert "1/sqrt(3) = 0.577" in msg and "neo-Hookean" in msg and exc.curvature < 0
            # the last converged state is above the critical stretch, the failing increment below
            assert 1 - 0.5 * reached > SVK_CRITICAL_STRETCH > 1 - 0.5 * (reached + 0.1)
        else:
            assert isinstance(mat, NeoHookean) and reached == 1.0


def test_traction_factor_scales_that_traction_in_time():
    """A Traction's ``factor(t)`` scales its own load only; constant tractions add unscaled."""
    m = box_mesh((2, 2, 2), (1e-4, 1e-4, 1e-4))
    const = Traction("zmax", traction=(0.0, 0.0, -1e3))
    ramp = Traction("xmax", pressure=5e2, factor=lambda t: 3.0 * t)
    f_const = SolidModel(m, MAT, [Fixed("zmin")], tractions=[const]).full_external_force(0.0)
    f_ramp1 = SolidModel(m, MAT, [Fixed("zmin")], tractions=[Traction("xmax", pressure=5e2)]).full_external_force(0.0)
    both = SolidModel(m, MAT, [Fixed("zmin")], tractions=[const, ramp])
    for t in (0.0, 0.5, 2.0):
        np.testing.assert_allclose(both.full_external_force(t), f_const + 3.0 * t * f_ramp1, rtol=1e-14, atol=1e-20)
    assert np.abs(f_ramp1).max() > 0 and np.abs(f_const).max() > 0
