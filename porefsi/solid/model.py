r"""The assembled solid model: a :class:`~porefsi.integrators.system.SecondOrderSystem` on free dofs.

.. math::

    M_{ff}\, \ddot u_f + f_{int}(u_f + u_D(t))_f = f_{ext}(t)_f,
    \qquad u_D(t) = u_D^0 + \dot u_D\, t

Dirichlet dofs are condensed out (the free-free blocks keep K symmetric); because the prescribed
motion is affine in t, :math:`\ddot u_D = 0` and the mass couples no load from it.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence

import numpy as np
import scipy.sparse as sp

from porefsi.errors import InputError
from porefsi.solid import forms
from porefsi.solid.assembly import P1Assembler, p1_gradients, submatrix_selector
from porefsi.solid.bc import Constraints, Traction
from porefsi.solid.linsolve import (
    AdaptiveSolverFactory,
    AMGSolverFactory,
    direct_solver_factory,
    jacobi_solver_factory,
)
from porefsi.solid.materials import Material
from porefsi.solid.mesh import FACET_TAGS, SolidMesh

__all__ = ["SolidModel"]

#: Below this many free dofs "auto" factorises every matrix (a factorisation costs less than a
#: few CG solves there).
SMALL_DOFS = 3000


class SolidModel:
    """Nonlinear elastic solid on a :class:`SolidMesh`, condensed to its free dofs.

    Parameters
    ----------
    mesh : SolidMesh
    material : Material
    bcs : sequence of Fixed / Roller / Prescribed
        Dirichlet conditions (see :mod:`porefsi.solid.bc`).
    tractions : sequence of Traction, optional
        Dead surface loads on tagged facets (each scaled in time by its ``factor``, if any).
    nodal_forces : ndarray (Nn, 3) or callable ``t -> (Nn, 3)``, optional
        Forces (N) on the mesh vertices, e.g. pore-pressure forces from the coupling; for P2
        also shape (n_full / 3, 3), forces on every Lagrange node (vertices, then edge
        midpoints, as :attr:`dof_points`), which a consistent P2 surface load needs.
    order : {1, 2}
        P1 (lumped mass, numba fast path) or P2 (consistent mass, scikit-fem forms).
    backend : {"auto", "numba", "skfem"}
        Assembly route for P1 ("auto" = numba); P2 always uses scikit-fem.
    linear_solver : {"auto", "amg", "jacobi", "direct"}
        What :meth:`make_solver` returns (see there): "auto" picks per matrix; "amg" is AMG-CG
        always, "direct" a sparse LU per matrix, "jacobi" Jacobi-CG (cheapest for strongly
        mass-dominated M + c K, omega dt ~ 10).

    Attributes
    ----------
    horizon_steps : int
        Exchange steps of the run ahead (0: unknown; set by the coupled loop): a stepper that
        keeps its tangent frozen hints "auto" with the solves it expects from it.
    recycle : int
        Earlier solutions each AMG-CG matrix keeps to start later solves from
        (:class:`~porefsi.solid.linsolve.SolutionSpace`; default 0: none); set it before the first
        solve. Not part of a checkpoint: with it a resumed run agrees with the uninterrupted one to
        the CG tolerance, not bit for bit.
    amg_rotations : bool
        Near-null space of the AMG hierarchy: the six rigid-body modes (True, default) or the three
        translations (False: a hierarchy about half as costly to build and a V-cycle ~30 % cheaper,
        for ~25 % more CG iterations on the 120³ rocks' graded meshes, but ~10x more on a slender,
        bending-dominated body; docs/solid.md section 5); set it before the first solve.

    Notes
    -----
    :meth:`with_nodal_forces` returns a new model sharing every assembled structure, so a
    coupling can swap the load each exchange step at no cost.
    """

    def __init__(self, mesh: SolidMesh, material: Material, bcs: Sequence = (), *,
                 tractions: Sequence[Traction] = (), nodal_forces=None, order: int = 1, backend: str = "auto",
                 linear_solver: str = "auto"):
        if not isinstance(mesh, SolidMesh):
            raise InputError(f"mesh must be a SolidMesh, got {type(mesh).__name__}")
        if not isinstance(material, Material):
            raise InputError(f"material must be a Material, got {type(material).__name__}")
        if linear_solver not in ("auto", "amg", "jacobi", "direct"):
            raise InputError(f"linear_solver must be 'auto', 'amg', 'jacobi' or 'direct', got {linear_solver!r}")
        self.linear_solver = linear_solver
        self.recycle = 0
        self.amg_rotations = True
        self.horizon_steps = 0
        if backend not in ("auto", "numba", "skfem"):
            raise InputError(f"backend must be 'auto', 'numba' or 'skfem', got {backend!r}")
        if order == 2 and backend == "numba":
            raise InputError("the numba fast path is P1 only; use backend='skfem' (or 'auto') for P2")
        self.mesh, self.material, self.order = mesh, material, int(order)
        self.backend = "numba" if (backend == "auto" and order == 1) else ("skfem" if backend == "auto" else backend)
        self._feb = None
        if self.order == 1:  # no scikit-fem basis unless needed (it holds 12 gradient fields per element)
            self.dof_points, self.n_full = mesh.points, 3 * mesh.n_nodes
        else:
            self.dof_points, self.n_full = self.feb.dof_points, self.feb.n_dofs
        self.bcs = tuple(bcs)
        self.constraints = Constraints.build(mesh, self.dof_points, self.bcs)
        self.free = self.constraints.free
        self._p1 = P1Assembler(mesh, material) if self.backend == "numba" else None
        if self._p1 is not None:
            self._sel = submatrix_selector(self._p1.indptr, self._p1.indices, self.free)
        self._traction_vec = np.zeros(self.n_full)  # the constant tractions
        self._timed = []  # (factor, load) of the tractions that vary in time
        for tr in tractions:
            vec = forms.facet_load(self.feb, mesh.facets_tagged(FACET_TAGS[tr.tag]), traction=tr.traction,
                                   pressure=tr.pressure)
            if tr.factor is None:
                self._traction_vec += vec
            else:
                self._timed.append((tr.factor, vec))
        self.tractions = tuple(tractions)
        self._nodal = None
        self._set_nodal(nodal_forces)
        self._mass = None
        self._cache = None
        self._solver_factory = None
        self._adaptive = None

    # ---- loads -------------------------------------------------------------------------
    def _nodal_shapes(self) -> tuple:
        return ((self.mesh.n_nodes, 3), (self.n_full // 3, 3))

    def _set_nodal(self, F):
        if F is not None and not callable(F):
            F = np.asarray(F, dtype=float)
            if F.shape not in self._nodal_shapes():
                raise InputError(f"nodal forces must have shape ({self.mesh.n_nodes}, 3) (N, on the vertices) or "
                                 f"({self.n_full // 3}, 3) (on every Lagrange node), got {F.shape}")
        self._nodal = F

    def with_nodal_forces(self, F) -> SolidModel:
        """A model identical to this one but with nodal forces ``F`` ((Nn, 3) N, or ``t -> (Nn, 3)``)."""
        new = copy.copy(self)
        new._set_nodal(F)
        return new

    def full_external_force(self, t: float) -> np.ndarray:
        """External load on all dofs, N, shape (n_full,)."""
        f = 1.0 * self._traction_vec
        for factor, vec in self._timed:
            f = f + float(factor(t)) * vec
        if self._nodal is not None:
            F = self._nodal(t) if callable(self._nodal) else self._nodal
            F = np.asarray(F, dtype=float)
            if F.shape not in self._nodal_shapes():
                raise InputError(f"nodal force function returned shape {F.shape}, expected ({self.mesh.n_nodes}, 3) "
                                 f"or ({self.n_full // 3}, 3)")
            f = f.copy()
            f[: F.size] += F.reshape(-1)
        return f

    # ---- protocol ------------------------------------------------------------------------
    @property
    def n_dofs(self) -> int:
        """Number of free dofs."""
        return len(self.free)

    @property
    def feb(self) -> forms.FEBasis:
        """The scikit-fem basis (built on first use for P1)."""
        if self._feb is None:
            self._feb = forms.make_basis(self.mesh, self.order)
        return self._feb

    def vertex_gradients(self) -> np.ndarray:
        """Gradients of the P1 (vertex) shape functions of every tetrahedron, (Ne, 4, 3), 1/m.

        The fast path's assembler keeps them; otherwise they are computed from the mesh.
        """
        return self._p1.dN if self._p1 is not None else p1_gradients(self.mesh)[0]

    def full_displacement(self, u: np.ndarray, t: float) -> np.ndarray:
        """All dofs (n_full,) from the free dofs ``u`` (n,) and the prescribed motion at t."""
        u = np.asarray(u, dtype=float)
        if u.shape != (self.n_dofs,):
            raise InputError(f"u must have shape ({self.n_dofs},), got {u.shape}")
        full = np.zeros(self.n_full)
        full[self.free] = u
        full[self.constraints.dofs] = self.constraints.values(t)
        return full

    def expand(self, u: np.ndarray, t: float) -> np.ndarray:
        """Vertex displacement (Nn, 3), m, from the free dofs at time t."""
        return self.full_displacement(u, t)[: 3 * self.mesh.n_nodes].reshape(-1, 3)

    def _evaluate(self, u: np.ndarray, t: float, want_K: bool):
        c = self._cache
        if c is not None and c[0] == t and (c[3] is not None or not want_K) and np.array_equal(c[1], u):
            return c[2], c[3]
        full = self.full_displacement(u, t)
        if self._p1 is not None:
            f, K = self._p1.assemble(full.reshape(-1, 3), want_K)
        else:
            f = forms.internal_force(self.feb, self.material, full)
            K = forms.tangent(self.feb, self.material, full) if want_K else None
        self._cache = (float(t), np.array(u, dtype=float), f, K)
        return f, K

    def full_internal_force(self, u: np.ndarray, t: float) -> np.ndarray:
        """Internal force on all dofs (n_full,), N (reactions are read from it)."""
        return self._evaluate(u, t, False)[0]

    def internal_force(self, u: np.ndarray, t: float) -> np.ndarray:
        """f_int on the free dofs, N, shape (n,)."""
        return self._evaluate(u, t, False)[0][self.free]

    def full_tangent(self, u: np.ndarray, t: float) -> sp.csr_matrix:
        """Tangent on all dofs (n_full, n_full) at free dofs ``u`` and time t, N/m."""
        return self._evaluate(u, t, True)[1]

    def tangent(self, u: np.ndarray, t: float) -> sp.csr_matrix:
        """Tangent stiffness on the free dofs, N/m, CSR (n, n), symmetric."""
        _, K = self._evaluate(u, t, True)
        if self._p1 is not None:
            sel, ip, ix = self._sel
            return sp.csr_matrix((K.data[sel], ix, ip), shape=(self.n_dofs, self.n_dofs))
        return K[self.free][:, self.free].tocsr()

    def external_force(self, t: float) -> np.ndarray:
        """f_ext on the free dofs, N, shape (n,)."""
        return self.full_external_force(t)[self.free]

    def full_mass(self):
        """Mass on all dofs: lumped diagonal (n_full,) for P1, consistent CSR for P2; kg."""
        if self._mass is None:
            if self.order == 1:
                self._mass = forms.lumped_mass_p1(self.mesh, self.material.density)
            else:
                self._mass = forms.consistent_mass(self.feb, self.material.density)
        return self._mass

    def mass(self):
        """Mass on the free dofs: ndarray (n,) (P1, lumped) or CSR (n, n) (P2, consistent); kg."""
        M = self.full_mass()
        if self.order == 1:
            return M[self.free]
        return M[self.free][:, self.free].tocsr()

    # ---- solvers and post-processing ------------------------------------------------------
    def make_solver(self, A: sp.spmatrix, *, expected_solves: int | None = None):
        """``solve(b) -> x`` for an SPD free-dof matrix A (e.g. K or M + c K).

        ``expected_solves``: the caller's hint that A is frozen and will serve about that many
        solves ("auto" then chooses LU or AMG-CG at the first solve, from predicted costs; the
        other solvers ignore it).

        Per ``linear_solver``. "auto": below :data:`SMALL_DOFS` free dofs a sparse LU (factoring
        is cheap there); above, :class:`~porefsi.solid.linsolve.AdaptiveSolverFactory`: CG
        preconditioned by pyamg smoothed aggregation with rigid-body modes (the hierarchy shared
        and reused across matrices while CG converges within 40 iterations), so Newton tangents and
        per-step TDG tangents stay on AMG-CG; a matrix that keeps serving solves (a frozen TDG
        :math:`M^*`) is factorised once the AMG-CG work spent on it reaches its predicted
        factorisation cost (not before its 20th solve; when the caller announces the number of
        solves a frozen tangent will serve, ``make_solver(A, expected_solves=n)``, LU or AMG-CG is
        chosen at the first solve from the predicted costs), up to 1e5 dofs (measured on the 57k-tet
        sample: 0.12 s per TDG step with the factor vs 0.3-0.9 s with AMG-CG; docs/solid.md
        sections 5 and 8). Above 1e5 dofs it stays on AMG-CG (factor memory).
        """
        kind = self.linear_solver
        if kind == "auto" and self.n_dofs < SMALL_DOFS:
            kind = "direct"
        if kind == "direct":
            return direct_solver_factory()(A)
        if kind == "jacobi":
            return jacobi_solver_factory()(A)
        if kind == "auto":
            if self._adaptive is None:
                self._adaptive = AdaptiveSolverFactory(self.solver_factory)
            return self._adaptive(A, expected_solves)
        return self.solver_factory(A)

    @property
    def solver_factory(self) -> AMGSolverFactory:
        """The shared AMG factory (created on first use)."""
        if self._solver_factory is None:
            self._solver_factory = AMGSolverFactory(self.dof_points, self.free, rotations=bool(self.amg_rotations))
            self._solver_factory.recycle = self.recycle
        return self._solver_factory

    def reactions(self, u: np.ndarray, t: float) -> dict[str, np.ndarray]:
        r"""Net force (3,), N, that the supports exert on each constrained box face.

        Computed as :math:`\sum_{a \in face} (f_{int} - f_{ext})_a` over the Lagrange nodes on
        the facets tagged with the face (the residual vanishes at free dofs at equilibrium).
        """
        from porefsi.solid.bc import face_dofs

        r = (self.full_internal_force(u, t) - self.full_external_force(t)).reshape(-1, 3)
        out = {}
        faces = sorted({spec.face for spec in self.bcs})
        for face in faces:
            nodes = face_dofs(self.mesh, self.dof_points, face, 0) // 3
            out[face] = r[nodes].sum(axis=0)
        return out

    def __repr__(self) -> str:
        return (f"SolidModel(P{self.order}, {self.material.name}, n_dofs={self.n_dofs}, "
                f"n_full={self.n_full}, backend={self.backend})")
