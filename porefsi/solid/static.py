r"""Quasi-static equilibrium (no inertia): Newton's method with load increments.

Solve :math:`f_{int}(u_f, t)_f = f_{ext}(t)_f` for the free dofs, t playing the role of a load
parameter (prescribed motions and load factors are functions of t).
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from porefsi.errors import ConvergenceError, InputError, MeshError
from porefsi.image.voxel_image import axis_index
from porefsi.solid.bc import check_load_path, uniaxial_bcs
from porefsi.solid.materials import Material
from porefsi.solid.mesh import FACE_NAMES, SolidMesh

__all__ = ["NewtonInfo", "solve_static", "UniaxialResult", "uniaxial_compression"]


@dataclasses.dataclass
class NewtonInfo:
    """Newton solve record.

    ``iterations`` counts linear solves (the predictor included); ``history`` holds the relative
    residual after each; ``linear_iterations`` the CG iterations of each (AMG-CG only).
    """

    iterations: int = 0
    history: list = dataclasses.field(default_factory=list)
    linear_iterations: list = dataclasses.field(default_factory=list)
    converged: bool = False


def solve_static(model, t: float, u0: np.ndarray | None = None, *, t_prev: float | None = None,
                 rtol: float = 1e-8, max_iter: int = 25, make_solver=None) -> tuple[np.ndarray, NewtonInfo]:
    r"""Newton solve of :math:`r(u) = f_{int}(u, t) - f_{ext}(t) = 0` on the free dofs.

    The first iterate is a linear predictor from the state ``u0`` at ``t_prev`` (default 0):

    .. math:: K_{ff}\,\Delta u = f_{ext}(t) - f_{int}(u_0, t_{prev}) - K_{fD}\,[u_D(t) - u_D(t_{prev})],

    so a prescribed boundary motion is spread over the body before any residual is evaluated at
    t (evaluating it with the interior still at ``u0`` would crush the elements next to a moving
    face). Converged when :math:`\|r\| \le rtol \cdot \max(\|f_{ext}\|, \|\text{predictor rhs}\|)`.

    Parameters
    ----------
    model : SolidModel (or any system with ``full_tangent``, ``constraints``, ``make_solver``)
    t : float
        Time / load parameter.
    u0 : ndarray, shape (n,), optional
        State at ``t_prev`` (default zero).
    t_prev : float, optional
        Time of ``u0`` (default 0).

    Raises
    ------
    ConvergenceError
        If the residual does not fall below tolerance in ``max_iter`` iterations (with history).
        Its subclass :class:`~porefsi.solid.linsolve.IndefiniteMatrixError` if CG finds the
        tangent indefinite: the message says why (e.g. St Venant-Kirchhoff compressed below a
        stretch of 1/sqrt(3)) and what to use instead.
    MeshError
        If an iterate inverts elements (take more load increments).
    """
    make_solver = model.make_solver if make_solver is None else make_solver
    u = np.zeros(model.n_dofs) if u0 is None else np.array(u0, dtype=float)
    t_prev = 0.0 if t_prev is None else float(t_prev)
    fext = model.external_force(t)
    info = NewtonInfo()
    # linear predictor from (u0, t_prev)
    c = model.constraints
    dD = np.zeros(model.n_full)
    dD[c.dofs] = c.values(t) - c.values(t_prev)
    Kfull = model.full_tangent(u, t_prev)
    rhs = fext - model.internal_force(u, t_prev) - (Kfull @ dD)[model.free]
    scale = max(np.linalg.norm(fext), np.linalg.norm(rhs), 1e-300)
    K = model.tangent(u, t_prev)
    u = u + _solve_checked(model, make_solver, K, rhs, u, t_prev)
    _record_linear(model, info)
    r = model.internal_force(u, t) - fext
    info.history.append(np.linalg.norm(r) / scale)
    for it in range(1, max_iter + 1):
        if info.history[-1] <= rtol:
            info.converged, info.iterations = True, it
            return u, info
        K = model.tangent(u, t)
        u = u + _solve_checked(model, make_solver, K, -r, u, t)
        _record_linear(model, info)
        r = model.internal_force(u, t) - fext
        info.history.append(np.linalg.norm(r) / scale)
    if info.history[-1] <= rtol:
        info.converged, info.iterations = True, max_iter + 1
        return u, info
    raise ConvergenceError(
        f"Newton did not converge in {max_iter} iterations at t={t:g} (relative residual "
        f"{info.history[-1]:.3g}); use more load increments", info.history)


#: St Venant-Kirchhoff's nominal stress in uniaxial stress or strain, P ~ c (c^2 - 1), peaks at
#: the stretch c = 1/sqrt(3) and softens below it: the material is unstable there.
SVK_CRITICAL_STRETCH = 1.0 / np.sqrt(3.0)


def _solve_checked(model, make_solver, K, rhs, u, t):
    """``make_solver(K)(rhs)``; an indefinite tangent is reported as the instability it is."""
    from porefsi.solid.linsolve import IndefiniteMatrixError

    try:
        return make_solver(K)(rhs)
    except IndefiniteMatrixError as exc:
        raise IndefiniteMatrixError(f"{exc}: {_instability_diagnosis(model, u, t)}", exc.history,
                                    curvature=exc.curvature) from None


def _instability_diagnosis(model, u, t) -> str:
    """Why the tangent at (u, t) is not positive definite, in words, with the smallest stretch."""
    from porefsi.solid.forms import deformation_gradient
    from porefsi.solid.materials import StVenantKirchhoff

    msg = ("the tangent stiffness at the current Newton iterate is not positive definite (the deformed "
           "state is unstable)")
    try:
        F = deformation_gradient(model.feb, model.full_displacement(u, t))  # (3, 3, Ne, nqp)
    except Exception:  # noqa: BLE001 - only a diagnosis; the solve error is the news
        return msg + "; use a smaller strain or more load increments"
    C = np.einsum("kiep,kjep->epij", F, F)
    stretch = np.sqrt(np.clip(np.linalg.eigvalsh(C)[..., 0], 0.0, None)).min(axis=1)  # per element
    smin = float(stretch.min())
    if isinstance(model.material, StVenantKirchhoff):
        n_soft = int(np.count_nonzero(stretch < SVK_CRITICAL_STRETCH))
        if n_soft:
            return (f"{msg}: St Venant-Kirchhoff is unstable in strong compression (its stress peaks at a "
                    f"principal stretch of 1/sqrt(3) = {SVK_CRITICAL_STRETCH:.3f} and softens below), and "
                    f"{n_soft} of {len(stretch)} elements are compressed beyond that (smallest stretch "
                    f"{smin:.3f}); use the neo-Hookean material (NeoHookean, --material neo-hookean: no material "
                    "instability in compression, though the porous frame can still buckle), a smaller strain or "
                    "more load increments")
    return (f"{msg}: smallest principal stretch {smin:.3f}; the frame may buckle or a material limit is passed; "
            "use a smaller strain, more load increments, or the neo-Hookean material")


def _record_linear(model, info):
    factory = getattr(model, "_solver_factory", None)
    if factory is not None:
        info.linear_iterations.append(factory.last.iterations)


@dataclasses.dataclass(frozen=True, eq=False)
class UniaxialResult:
    """Outcome of :func:`uniaxial_compression` (SI units).

    Attributes
    ----------
    u : ndarray (Nn, 3)
        Vertex displacement, m.
    sigma : ndarray (Ne, 3, 3)
        Cauchy stress per element, Pa.
    von_mises_element : ndarray (Ne,), Pa
    von_mises_nodal : ndarray (Nn,), Pa
    reaction : ndarray (3,)
        Force the platen exerts on the loaded face, N.
    effective_modulus : float
        |R_axis| / (A strain), Pa, A the area of the image box face (solid and pore).
    strain : float
    newton : list of NewtonInfo
        One per load increment.
    """

    u: np.ndarray
    sigma: np.ndarray
    von_mises_element: np.ndarray
    von_mises_nodal: np.ndarray
    reaction: np.ndarray
    effective_modulus: float
    strain: float
    newton: list
    seconds: float


def uniaxial_compression(mesh: SolidMesh, material: Material, strain: float = 1e-3, *, axis="z",
                         n_steps: int = 1, order: int = 1, lateral: str = "roller", rtol: float = 1e-8,
                         ) -> UniaxialResult:
    """Compress ``mesh`` along ``axis`` by nominal ``strain`` with the paper's boundary conditions.

    The faces are those of the image box (:attr:`SolidMesh.box`, found through the facet tags):
    the solid on the min face is fixed, the solid on the max face is displaced by
    ``-strain * L`` (bonded platen), the solid on the lateral faces is on rollers; L and the
    face area A behind the effective modulus are the box's, so pore space at the box faces
    counts as part of the sample. The load is applied in ``n_steps`` equal increments, each
    solved by Newton (t = 0..1 is the load parameter).

    Raises
    ------
    InputError
        strain <= 0 or >= 1, n_steps < 1.
    MeshError
        If no connected solid joins the min and max faces along ``axis`` (:func:`check_load_path`),
        or elements invert (use more increments).
    ConvergenceError
        If Newton fails (use more increments).
    """
    from porefsi.solid.linsolve import IndefiniteMatrixError
    from porefsi.solid.model import SolidModel
    from porefsi.solid.stress import effective_modulus, element_cauchy, nodal_average, von_mises

    if not (0 < strain < 1):
        raise InputError(f"strain must be in (0, 1) (compression, dimensionless), got {strain!r}")
    if int(n_steps) < 1:
        raise InputError(f"n_steps must be >= 1, got {n_steps!r}")
    t0 = time.perf_counter()
    ax = axis_index(axis)
    check_load_path(mesh, ax)
    box = mesh.box  # the image box, not the extent of the solid in it
    L = float(box[1, ax] - box[0, ax])
    model = SolidModel(mesh, material, uniaxial_bcs(ax, rate=-strain * L, lateral=lateral), order=order)
    u = np.zeros(model.n_dofs)
    infos = []
    for k in range(1, int(n_steps) + 1):
        t = k / int(n_steps)
        try:
            u, info = solve_static(model, t, u0=u, t_prev=(k - 1) / int(n_steps), rtol=rtol)
        except MeshError as exc:
            raise MeshError(f"{exc} (at load increment {k}/{n_steps}; try n_steps={2 * int(n_steps)})") from None
        except IndefiniteMatrixError as exc:
            raise IndefiniteMatrixError(f"{exc} (at load increment {k}/{n_steps}, strain {strain * t:g})",
                                        exc.history, curvature=exc.curvature) from None
        infos.append(info)
    R = model.reactions(u, 1.0)[FACE_NAMES[2 * ax + 1]]  # force of the platen on the solid
    area = float(np.prod(np.delete(box[1] - box[0], ax)))
    sigma = element_cauchy(model, u, 1.0)
    vm = von_mises(sigma)
    return UniaxialResult(
        u=model.expand(u, 1.0), sigma=sigma, von_mises_element=vm, von_mises_nodal=nodal_average(mesh, vm),
        reaction=R, effective_modulus=effective_modulus(R[ax], area, strain), strain=float(strain),
        newton=infos, seconds=time.perf_counter() - t0,
    )
