"""Materials, forms, the numba fast path and its twin; tangent, patch test, rigid-body modes."""

import numpy as np
import pytest
import scipy.sparse as sp

from porefsi.errors import InputError, MeshError
from porefsi.solid import forms
from porefsi.solid.assembly import P1Assembler, p1_gradients
from porefsi.solid.bc import Affine, Fixed
from porefsi.solid.linsolve import rigid_body_modes
from porefsi.solid.materials import NeoHookean, StVenantKirchhoff, make_material
from porefsi.solid.model import SolidModel
from porefsi.solid.shapes import box_mesh
from porefsi.solid.static import solve_static
from tests.reference.solid_ref import assemble_p1_ref, first_pk_ref, lame_ref, moduli_ref, p1_gradients_ref

MATERIALS = [StVenantKirchhoff(E=20e9, nu=0.28), NeoHookean(E=20e9, nu=0.28)]
IDS = ["svk", "neo-hookean"]


def _distorted_box(rng, shape=(3, 3, 4), amp=0.15):
    """Box mesh with interior nodes moved randomly (irregular elements, same boundary)."""
    m = box_mesh(shape, (1e-4, 1e-4, 1.3e-4))
    p = m.points.copy()
    h = 1e-4 / max(shape)
    interior = np.all((p > p.min(axis=0) + 1e-12) & (p < p.max(axis=0) - 1e-12), axis=1)
    p[interior] += amp * h * rng.uniform(-1, 1, (interior.sum(), 3))
    return type(m)(p, m.tets, m.facets, m.facet_tags)


@pytest.mark.parametrize("mat", MATERIALS, ids=IDS)
def test_stress_and_moduli_are_derivatives(mat, rng):
    """P = dW/dF and A = dP/dF by central differences; A has major symmetry (hyperelastic)."""
    F = np.eye(3)[:, :, None] + 0.1 * rng.standard_normal((3, 3, 5))
    P, A = mat.first_pk(F), mat.moduli(F)
    h = 1e-6
    for k in range(3):
        for L in range(3):
            d = np.zeros((3, 3, 1))
            d[k, L] = h
            dW = (mat.energy(F + d) - mat.energy(F - d)) / (2 * h)
            dP = (mat.first_pk(F + d) - mat.first_pk(F - d)) / (2 * h)
            np.testing.assert_allclose(dW, P[k, L], rtol=1e-6, atol=1e-6 * mat.E * 1e-3)
            np.testing.assert_allclose(dP, A[:, :, k, L], rtol=1e-6, atol=1e-6 * mat.E * 1e-3)
    np.testing.assert_array_equal(A, A.transpose(2, 3, 0, 1, 4))


@pytest.mark.parametrize("mat", MATERIALS, ids=IDS)
def test_small_strain_limit_is_hooke(mat):
    """At F = I both materials reduce to isotropic linear elasticity with the textbook
    lambda = E nu / ((1 + nu)(1 - 2 nu)), mu = E / (2 (1 + nu)) (computed here from E, nu)."""
    A = mat.moduli(np.eye(3)[:, :, None])[..., 0]
    d = np.eye(3)
    lam, mu = lame_ref(mat.E, mat.nu)
    assert (mat.lam, mat.mu) == (pytest.approx(lam, rel=1e-15), pytest.approx(mu, rel=1e-15))
    C = lam * np.einsum("ij,kl->ijkl", d, d) + mu * (np.einsum("ik,jl->ijkl", d, d)
                                                     + np.einsum("il,jk->ijkl", d, d))
    np.testing.assert_allclose(A, C, rtol=1e-14, atol=1e-14 * mat.E)
    # E and nu back from uniaxial stress (the normal 3 x 3 block of the Voigt stiffness, inverted):
    # eps_11 = sigma_11 / E, eps_22 = -nu sigma_11 / E
    normal = np.linalg.inv(A[[0, 1, 2], [0, 1, 2]][:, [0, 1, 2], [0, 1, 2]])
    assert 1.0 / normal[0, 0] == pytest.approx(mat.E, rel=1e-12)
    assert -normal[1, 0] / normal[0, 0] == pytest.approx(mat.nu, rel=1e-12)


@pytest.mark.parametrize("mat", MATERIALS, ids=IDS)
def test_stress_and_moduli_match_textbook_twin(mat, rng):
    """The library's P(F) and A(F) at finite strain equal the reference laws written from the
    textbooks (tests/reference/solid_ref.py: own formulas from E and nu, complex-step moduli)."""
    H = 0.1 * rng.standard_normal((3, 3, 4))
    F = np.eye(3)[:, :, None] + H
    P, A = mat.first_pk(F), mat.moduli(F)
    for q in range(H.shape[2]):
        P_ref = first_pk_ref(mat.name, mat.E, mat.nu, H[:, :, q])
        A_ref = moduli_ref(mat.name, mat.E, mat.nu, H[:, :, q])
        np.testing.assert_allclose(P[:, :, q], P_ref, rtol=0, atol=1e-12 * np.abs(P_ref).max())
        np.testing.assert_allclose(A[..., q], A_ref, rtol=0, atol=1e-12 * np.abs(A_ref).max())


def test_material_validation():
    for bad in [dict(E=0.0), dict(E=-1.0), dict(nu=0.5), dict(nu=0.6), dict(nu=-1.0), dict(density=0.0)]:
        with pytest.raises(InputError):
            StVenantKirchhoff(**bad)
    with pytest.raises(InputError, match="unknown material"):
        make_material("mooney")
    assert make_material("neo_hookean").kind == 1
    assert StVenantKirchhoff().density == 2650.0


def test_p1_gradients_match_twin(rng):
    m = _distorted_box(rng)
    dN, vol = p1_gradients(m)
    dN2, vol2 = p1_gradients_ref(m.points, m.tets)
    np.testing.assert_allclose(vol, vol2, rtol=1e-12)
    np.testing.assert_allclose(dN, dN2, rtol=1e-10, atol=1e-10 * np.abs(dN2).max())


@pytest.mark.parametrize("mat", MATERIALS, ids=IDS)
def test_numba_kernel_matches_twin_and_skfem(mat, rng):
    """The fast path equals the pure-Python twin and the scikit-fem forms to round-off."""
    m = _distorted_box(rng, shape=(2, 2, 3))
    u = 2e-6 * rng.standard_normal((m.n_nodes, 3))  # strains ~ 5 %
    f, K = P1Assembler(m, mat).assemble(u)
    f_ref, K_ref = assemble_p1_ref(m.points, m.tets, u, mat)
    feb = forms.make_basis(m, 1)
    f_sk = forms.internal_force(feb, mat, u.ravel())
    K_sk = forms.tangent(feb, mat, u.ravel())
    fs, ks = np.abs(f_ref).max(), np.abs(K_ref).max()
    assert np.abs(f - f_ref).max() <= 1e-12 * fs
    assert np.abs(K.toarray() - K_ref).max() <= 1e-12 * ks
    assert np.abs(f - f_sk).max() <= 1e-12 * fs
    assert abs(K - K_sk).max() <= 1e-12 * ks
    assert abs(K - K.T).max() <= 1e-13 * ks


@pytest.mark.parametrize("mat", MATERIALS, ids=IDS)
def test_zero_displacement_force_shortcut_is_exact(mat, rng):
    """The fast path skips the assembly of f_int at zero displacement (a quasi-static step's load
    scale evaluates it every step): the reference state of every material is stress-free, so the
    shortcut's zeros equal the kernel's f_int (computed along with K) and the twin's exactly; a
    displacement with a single nonzero entry still assembles."""
    m = _distorted_box(rng, shape=(2, 2, 3))
    asm = P1Assembler(m, mat)
    zero = np.zeros((m.n_nodes, 3))
    f_short, K_none = asm.assemble(zero, want_K=False)
    f_kernel, _ = asm.assemble(zero, want_K=True)
    assert K_none is None and not f_short.any() and not f_kernel.any()
    assert not assemble_p1_ref(m.points, m.tets, zero, mat)[0].any()
    one = zero.copy()
    one[5, 1] = 1e-9
    f1, _ = asm.assemble(one, want_K=False)
    np.testing.assert_allclose(f1, assemble_p1_ref(m.points, m.tets, one, mat)[0], rtol=0,
                               atol=1e-10 * np.abs(f1).max())
    assert np.abs(f1).max() > 0


@pytest.mark.parametrize("mat", MATERIALS, ids=IDS)
@pytest.mark.parametrize("order", [1, 2])
def test_internal_force_keeps_precision_at_pore_pressure_strains(mat, order, rng):
    """At strains of 1e-11 the internal force is the linear-elastic K(0) u up to O(strain):
    forming the stress from F^T F - I (or det F - 1) instead of H would lose ~11 digits here and
    stall Newton's residual (P2 static solves used to stop at 1.5e-7 relative)."""
    m = _distorted_box(rng, shape=(2, 2, 2))
    model = SolidModel(m, mat, [Fixed("zmin")], order=order)
    u = 1e-15 * rng.standard_normal(model.n_dofs)
    K0 = model.tangent(np.zeros(model.n_dofs), 0.0)
    f = model.internal_force(u, 0.0)
    assert np.linalg.norm(f - K0 @ u) <= 1e-9 * np.linalg.norm(K0 @ u)
    if order == 1:  # the numba fast path, its twin and the scikit-fem forms agree as well
        uf = model.expand(u, 0.0)
        f_fast, _ = P1Assembler(m, mat).assemble(uf)
        f_ref, _ = assemble_p1_ref(m.points, m.tets, uf, mat)
        f_sk = forms.internal_force(forms.make_basis(m, 1), mat, uf.ravel())
        for g in (f_ref, f_sk):
            assert np.linalg.norm(f_fast - g) <= 1e-9 * np.linalg.norm(f_fast)


@pytest.mark.parametrize("mat", MATERIALS, ids=IDS)
@pytest.mark.parametrize("order", [1, 2])
def test_tangent_matches_central_differences(mat, order, rng):
    """K(u) v = (f(u + h v) - f(u - h v)) / 2h + O(h^2), on the condensed free dofs."""
    m = box_mesh((2, 2, 2), (1e-4, 1e-4, 1e-4))
    model = SolidModel(m, mat, [Fixed("zmin")], order=order)
    u = 3e-6 * rng.standard_normal(model.n_dofs)
    v = rng.standard_normal(model.n_dofs) * 1e-6
    K = model.tangent(u, 0.0)
    h = 1e-3
    fd = (model.internal_force(u + h * v, 0.0) - model.internal_force(u - h * v, 0.0)) / (2 * h)
    assert np.linalg.norm(K @ v - fd) <= 1e-7 * np.linalg.norm(fd)


@pytest.mark.parametrize("order", [1, 2])
def test_rigid_body_modes_in_null_space(order):
    """Unconstrained tangent at u = 0: all six rigid modes are zero-energy (K B = 0)."""
    m = box_mesh((2, 3, 2), (1e-4, 1.5e-4, 1e-4))
    model = SolidModel(m, MATERIALS[0], [], order=order)
    K = model.tangent(np.zeros(model.n_dofs), 0.0)
    B = rigid_body_modes(model.dof_points)
    scale = abs(K).max() * np.abs(B).max()
    assert np.abs(K @ B).max() <= 1e-12 * scale
    # with the zmin face fixed the free tangent is SPD: no zero-energy mode remains
    fixed = SolidModel(m, MATERIALS[0], [Fixed("zmin")], order=order)
    ev = np.linalg.eigvalsh(fixed.tangent(np.zeros(fixed.n_dofs), 0.0).toarray())
    assert ev.min() > 1e-8 * ev.max()


@pytest.mark.parametrize("mat", MATERIALS, ids=IDS)
def test_objectivity_under_finite_rotation(mat, rng):
    """f_int(Q(X + u) - X) = Q f_int(u) node by node for a rotation Q (frame indifference)."""
    m = box_mesh((2, 2, 2), (1e-4, 1e-4, 1e-4))
    a = P1Assembler(m, mat)
    u = 2e-6 * rng.standard_normal((m.n_nodes, 3))
    th = 0.7
    Q = np.array([[np.cos(th), -np.sin(th), 0], [np.sin(th), np.cos(th), 0], [0, 0, 1.0]])
    Q = Q @ np.array([[1, 0, 0], [0, np.cos(1.1), -np.sin(1.1)], [0, np.sin(1.1), np.cos(1.1)]])
    x = m.points + u
    f1, _ = a.assemble(u, want_K=False)
    f2, _ = a.assemble(x @ Q.T - m.points, want_K=False)
    np.testing.assert_allclose(f2.reshape(-1, 3), f1.reshape(-1, 3) @ Q.T, atol=1e-11 * np.abs(f1).max())


@pytest.mark.parametrize("mat", MATERIALS, ids=IDS)
def test_patch_test_affine_field(mat, rng):
    """Affine displacement on the whole boundary: interior nodes of an irregular mesh reproduce it.

    Linear patch test (tangent at 0) and nonlinear one (Newton, finite strain); 1e-12 relative.
    """
    m = _distorted_box(rng)
    G = np.array([[0.02, 0.01, -0.005], [0.0, -0.01, 0.015], [0.004, 0.0, 0.01]])
    c = np.array([1e-7, -2e-7, 3e-7])
    specs = [Affine(face, G, c) for face in ("xmin", "xmax", "ymin", "ymax", "zmin", "zmax")]
    model = SolidModel(m, mat, specs)
    exact = (m.points @ G.T + c)
    # nonlinear
    u, info = solve_static(model, 0.0, rtol=1e-13)
    assert info.converged
    err = np.abs(model.expand(u, 0.0) - exact).max()
    assert err <= 1e-12 * np.abs(exact).max()
    # linear (small-strain) patch test: K_ff u_f = -K_fD u_D with the unconstrained K(0)
    K = SolidModel(m, mat, []).tangent(np.zeros(3 * m.n_nodes), 0.0).tocsr()
    D, f = model.constraints.dofs, model.free
    uD = exact.ravel()[D]
    uf = sp.linalg.spsolve(sp.csc_matrix(K[f][:, f]), -(K[f][:, D] @ uD))
    assert np.abs(uf - exact.ravel()[f]).max() <= 1e-12 * np.abs(exact).max()


def test_inverted_elements_raise_mesh_error():
    m = box_mesh((1, 1, 1), (1.0, 1.0, 1.0))
    a = P1Assembler(m, MATERIALS[0])
    u = np.zeros((m.n_nodes, 3))
    top = m.points[:, 2] == 1.0
    u[top, 2] = -1.5  # push the top through the bottom
    with pytest.raises(MeshError, match=r"\d+ of 5 elements inverted .*smaller load"):
        a.assemble(u)
    with pytest.raises(MeshError, match="inverted"):
        forms.internal_force(forms.make_basis(m, 1), MATERIALS[1], u.ravel())


def test_masses_conserve_total_mass():
    """P1 lumped and P2 consistent masses both sum to rho V per direction; P2 row-sum lumping
    has negative vertex entries (why P2 keeps the consistent mass)."""
    m = box_mesh((2, 2, 2), (1e-4, 2e-4, 1e-4))
    rho = 2650.0
    total = rho * m.volume
    ml = forms.lumped_mass_p1(m, rho)
    assert np.all(ml > 0)
    assert ml.reshape(-1, 3).sum(axis=0) == pytest.approx([total] * 3, rel=1e-13)
    feb = forms.make_basis(m, 2)
    M2 = forms.consistent_mass(feb, rho)
    ones_x = np.zeros(feb.n_dofs)
    ones_x[0::3] = 1.0
    assert ones_x @ (M2 @ ones_x) == pytest.approx(total, rel=1e-13)
    rowsum = np.asarray(M2.sum(axis=1)).ravel()
    assert rowsum[: 3 * m.n_nodes].min() < 0
