"""Linear solvers for the (condensed, SPD) elasticity systems: AMG-CG, Jacobi-CG, direct.

Each factory ``make(A) -> solve(b) -> x`` follows
:data:`porefsi.integrators.system.SolverFactory`; ``solve(b, rtol=...)`` overrides an iterative
solve's relative tolerance for one call (an inexact Newton step asks only for what it needs; a
direct solve ignores it). Unconverged solves raise
:class:`~porefsi.errors.ConvergenceError` carrying the residual history.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from porefsi.errors import ConvergenceError, InputError
from porefsi.solid._recycle import SolutionSpace
from porefsi.solid._vcycle import VCycle, relax_candidates
from porefsi.solid.footprint import (
    AMG_SECONDS_PER_WORK,
    LU_SECONDS_PER_FLOP,
    amg_iteration_work,
    lu_factor_flops,
    predict_solver_costs,
)

__all__ = ["pcg", "rigid_body_modes", "AMGSolverFactory", "jacobi_solver_factory", "direct_solver_factory",
           "AdaptiveSolverFactory", "SolveInfo", "SolutionSpace", "single_thread_blas", "IndefiniteMatrixError"]

#: BLAS threads inside the solves (their dot products are on vectors of 1e4-1e6 entries).
SOLVE_BLAS_THREADS = 1
_CONTROLLER = None


def single_thread_blas():
    """Context manager pinning every loaded BLAS to :data:`SOLVE_BLAS_THREADS` (1) thread.

    The solves' vector operations are too small for threads to pay: with the second core busy,
    Jacobi-CG on the sample at coarsen 5 (39,871 dofs, 190 iterations) took 0.45 s with
    2 OpenBLAS threads and 0.14 s with 1 (DESIGN.md section 5 measured 10-30x on CG). The
    threadpoolctl controller is built once (the first call, when numpy's and scipy's BLAS are
    loaded); entering the limit then costs ~6 us.
    """
    global _CONTROLLER
    if _CONTROLLER is None:
        import scipy.linalg  # noqa: F401  (load scipy's BLAS before the controller looks)
        from threadpoolctl import ThreadpoolController

        _CONTROLLER = ThreadpoolController()
    return _CONTROLLER.limit(limits=SOLVE_BLAS_THREADS, user_api="blas")


class IndefiniteMatrixError(ConvergenceError):
    """CG met a direction p with p.Ap <= 0: a certificate that A is not positive definite.

    No preconditioner or rebuild can fix this; for a tangent stiffness it means the deformed
    state is unstable (material softening, buckling) or the constraints leave a free motion.

    Attributes
    ----------
    curvature : float
        p.Ap / p.p of the offending direction (units of A).
    """

    def __init__(self, message: str, history=None, curvature: float = float("nan")):
        super().__init__(message, history)
        self.curvature = float(curvature)


@dataclasses.dataclass
class SolveInfo:
    """Statistics of the last solve: iterations, relative residual history, converged flag."""

    iterations: int = 0
    history: list = dataclasses.field(default_factory=list)
    converged: bool = False


def pcg(A, b: np.ndarray, M=None, x0: np.ndarray | None = None, rtol: float = 1e-8,
        maxiter: int | None = None, what: str = "CG") -> tuple[np.ndarray, SolveInfo]:
    r"""Preconditioned conjugate gradients for SPD ``A``; stop when :math:`\|r\|_2 \le rtol \|b\|_2`.

    Parameters
    ----------
    A : sparse matrix or LinearOperator, shape (n, n)
    b : ndarray, shape (n,)
    M : callable or LinearOperator, optional
        Preconditioner application ``z = M r`` (SPD).
    rtol : float
        Relative tolerance on the 2-norm of the residual.

    Raises
    ------
    ConvergenceError
        After ``maxiter`` iterations (default ``max(100, n)``), with the history.
    IndefiniteMatrixError
        On a breakdown (a direction with p.Ap <= 0: A is not positive definite).

    Notes
    -----
    Runs with BLAS pinned to one thread (:func:`single_thread_blas`).
    """
    with single_thread_blas():
        return _pcg(A, b, M, x0, rtol, maxiter, what)


def _pcg(A, b, M, x0, rtol, maxiter, what):
    b = np.asarray(b, dtype=float)
    n = b.shape[0]
    maxiter = max(100, n) if maxiter is None else int(maxiter)
    apply_M = (lambda r: r) if M is None else (M if callable(M) else M.matvec)
    bnorm = np.linalg.norm(b)
    info = SolveInfo()
    if bnorm == 0:
        info.converged = True
        return np.zeros(n), info
    x = np.zeros(n) if x0 is None else np.array(x0, dtype=float)
    r = b - A @ x
    z = apply_M(r)
    p = z.copy()
    rz = r @ z
    hist = [np.linalg.norm(r) / bnorm]
    for it in range(1, maxiter + 1):
        if hist[-1] <= rtol:
            info.iterations, info.history, info.converged = it - 1, hist, True
            return x, info
        Ap = A @ p
        pAp = p @ Ap
        if not pAp > 0:
            raise IndefiniteMatrixError(
                f"{what} breakdown: p.Ap = {pAp:.3g} <= 0, so the matrix is not positive definite", hist,
                curvature=pAp / float(p @ p))
        alpha = rz / pAp
        x += alpha * p
        r -= alpha * Ap
        hist.append(np.linalg.norm(r) / bnorm)
        z = apply_M(r)
        rz_new = r @ z
        p *= rz_new / rz
        p += z
        rz = rz_new
    if hist[-1] <= rtol:
        info.iterations, info.history, info.converged = maxiter, hist, True
        return x, info
    raise ConvergenceError(
        f"{what} did not reach rtol={rtol:g} in {maxiter} iterations (last relative residual "
        f"{hist[-1]:.3g}); check the constraints remove all rigid-body modes, or use a direct solve",
        hist,
    )


def rigid_body_modes(points: np.ndarray) -> np.ndarray:
    """The six rigid-body modes of interleaved 3-D dofs at ``points`` (N, 3): shape (3N, 6).

    Columns: translations x, y, z, then rotations about x, y, z (about the centroid).
    """
    x = np.asarray(points, dtype=float) - np.mean(points, axis=0)
    n = len(x)
    B = np.zeros((n, 3, 6))
    for c in range(3):
        B[:, c, c] = 1.0
    # omega x r for omega = e_x, e_y, e_z
    B[:, 1, 3], B[:, 2, 3] = -x[:, 2], x[:, 1]
    B[:, 0, 4], B[:, 2, 4] = x[:, 2], -x[:, 0]
    B[:, 0, 5], B[:, 1, 5] = -x[:, 1], x[:, 0]
    return B.reshape(3 * n, 6)


#: Strength-of-connection threshold of the AMG aggregation. Measured on the 120³ Berea crop's graded
#: mesh (coarsen 2-8, 41,911 dofs; a smooth load, CG to 1e-8): 19 iterations at theta 0 (every
#: connection strong), 14 at 0.02 and 0.05, 29 at 0.1 (operator complexity 2.08, 2.15, 2.25, 3.55);
#: docs/solid.md section 5.
STRENGTH_THETA = 0.02
#: Previous solutions :class:`AMGSolverFactory` keeps per matrix by default (:class:`SolutionSpace`).
#: 0 (off): a run restored from a checkpoint starts with an empty space, so with recycling its AMG
#: solves would agree with the uninterrupted run's only to the CG tolerance, not bit for bit
#: (tests/test_solver_footprint.py). Measured with 24 on the graded 3_12 meshes with ligaments (the
#: static coupled run of the speed-accuracy study, 10 steps, 16 solves with one tangent): 84 instead
#: of 103 CG iterations on the 120³ Berea crop (35,779 dofs), 75 instead of 90 on the sample
#: (31,438); docs/solid.md section 5.
RECYCLE_VECTORS = 0


class AMGSolverFactory:
    """CG preconditioned by pyamg smoothed aggregation with rigid-body modes, with reuse.

    The hierarchy is built on the full-size block (3 x 3 BSR) matrix in which the constrained
    dofs are eliminated symmetrically (unit diagonal), so aggregation works on nodes; it is
    applied to the free system by padding with zeros. A hierarchy is reused for later matrices
    (tangents change little between steps) while CG needs at most ``rebuild_iterations``;
    otherwise it is rebuilt for the current matrix and the solve repeated.

    Parameters
    ----------
    dof_points : ndarray, shape (n_full // 3, 3)
        Positions of the Lagrange nodes (interleaved dofs), m.
    free : ndarray of int, shape (n,)
        Indices of the free dofs in the full numbering.
    rtol : float
        CG relative residual tolerance.
    rebuild_iterations : int
        Reuse a hierarchy while CG converges within this many iterations.
    maxiter : int
        CG iteration cap for one solve.
    max_coarse : int
        Largest coarsest-level size (dofs) before pyamg stops coarsening.
    rotations : bool, default True
        Near-null space = the six rigid-body modes (True) or the three translations only (False,
        for comparison: on a slender cantilever CG needs ~10x more iterations without the
        rotations, on the porous rock ~25 % more; see tests/test_solid_linsolve.py).

    Attributes
    ----------
    recycle : int
        Previous solutions kept per matrix, :data:`RECYCLE_VECTORS` unless set (0: none; a
        negative or fractional value raises :class:`~porefsi.errors.InputError`). A solve with a matrix that
        served earlier solves starts from the A-orthogonal projection of its right-hand side onto
        their span (:class:`SolutionSpace`), so a load that repeats or combines earlier ones costs
        few or no CG iterations; the stopping test is unchanged (the residual is recomputed from
        the start).
    theta : float
        Strength-of-connection threshold of the aggregation (pyamg's symmetric measure), read at
        each hierarchy build; :data:`STRENGTH_THETA` unless changed.
    """

    def __init__(self, dof_points: np.ndarray, free: np.ndarray, *, rtol: float = 1e-8,
                 rebuild_iterations: int = 40, maxiter: int = 1000, max_coarse: int = 300,
                 rotations: bool = True):
        self.n_full = 3 * len(dof_points)
        self.free = np.asarray(free, dtype=np.int64)
        self.B_full = rigid_body_modes(dof_points)
        if not rotations:
            self.B_full = np.ascontiguousarray(self.B_full[:, :3])
        self.rtol, self.rebuild_iterations, self.maxiter = float(rtol), int(rebuild_iterations), int(maxiter)
        self.max_coarse = int(max_coarse)
        self.theta = STRENGTH_THETA
        self.recycle = RECYCLE_VECTORS
        self.ml = None
        self.n_setups = 0
        self.last = SolveInfo()
        self._pad = np.zeros(self.n_full)

    @property
    def recycle(self) -> int:
        """Previous solutions kept per matrix (see the class's Attributes)."""
        return self._recycle

    @recycle.setter
    def recycle(self, k: int) -> None:
        if int(k) != k or k < 0:
            raise InputError(f"recycle must be an integer >= 0 (solutions kept per matrix), got {k!r}")
        self._recycle = int(k)

    def _padded(self, A: sp.spmatrix) -> sp.bsr_matrix:
        """The full-size BSR matrix: ``A`` on the free rows and columns, the mean diagonal at the constrained.

        Built row by row in CSR order (``free`` is sorted, so each free row keeps its sorted
        columns): about two copies of ``A`` at the peak, where a COO detour would take five.
        """
        A = sp.csr_matrix(A)
        A.sort_indices()
        n_full, free = self.n_full, self.free
        cons = np.setdiff1d(np.arange(n_full), free)
        row_len = np.diff(A.indptr)
        counts = np.ones(n_full, dtype=np.int64)
        counts[free] = row_len
        indptr = np.zeros(n_full + 1, dtype=np.int64)
        np.cumsum(counts, out=indptr[1:])
        idx_t = np.int32 if n_full < 2**31 and indptr[-1] < 2**31 else np.int64
        data = np.empty(indptr[-1])
        indices = np.empty(indptr[-1], dtype=idx_t)
        dest = np.repeat(indptr[free] - A.indptr[:-1], row_len)
        dest += np.arange(A.nnz, dtype=np.int64)
        data[dest] = A.data
        indices[dest] = free[A.indices]
        del dest
        data[indptr[cons]] = A.diagonal().mean() if A.nnz else 1.0
        indices[indptr[cons]] = cons
        Af = sp.csr_matrix((data, indices, indptr.astype(idx_t)), shape=(n_full, n_full))
        Af.has_sorted_indices = True
        return Af.tobsr(blocksize=(3, 3))

    def setup(self, A: sp.spmatrix) -> None:
        """Build the smoothed-aggregation hierarchy for ``A`` (free-dof matrix), BLAS single-threaded."""
        with single_thread_blas():
            self._setup(A)

    def _setup(self, A):
        import pyamg

        Ab = self._padded(A)
        B = self.B_full.copy()
        cons = np.setdiff1d(np.arange(self.n_full), self.free)
        B[cons] = 0.0  # constrained dofs carry no near-null-space component
        # smoothers and coarse solve are VCycle's (pointwise Gauss-Seidel on CSR levels, forward
        # down and backward up: symmetric, as CG needs); pyamg builds the hierarchy only
        B = relax_candidates(Ab, B)  # pyamg's improve_candidates, with VCycle's cheaper sweeps
        self.ml = pyamg.smoothed_aggregation_solver(
            Ab, B=B, symmetry="symmetric", strength=("symmetric", {"theta": self.theta}),
            smooth=("jacobi", {"omega": 4.0 / 3.0}), max_coarse=self.max_coarse, coarse_solver="splu",
            improve_candidates=None, presmoother=None, postsmoother=None,
        )
        self._M = VCycle(self.ml.levels, self.ml.coarse_solver)
        self.n_setups += 1

    def precondition(self, r: np.ndarray) -> np.ndarray:
        """Apply the AMG V-cycle to a free-dof residual ``r`` (n,)."""
        pad = np.zeros(self.n_full)
        pad[self.free] = r
        return self._M(pad)[self.free]

    def __call__(self, A: sp.spmatrix):
        """Return ``solve(b) -> x`` for the free-dof SPD matrix ``A``."""
        A = sp.csr_matrix(A)
        if A.shape != (len(self.free), len(self.free)):
            raise InputError(f"matrix shape {A.shape} does not match {len(self.free)} free dofs")
        state = {"fresh": self.ml is None}
        space = SolutionSpace(A, self.recycle)
        if self.ml is None:
            self.setup(A)

        def solve(b: np.ndarray, rtol: float | None = None) -> np.ndarray:
            # a reused hierarchy gets at most rebuild_iterations before it is replaced
            cap = self.maxiter if state["fresh"] else self.rebuild_iterations
            tol = self.rtol if rtol is None else float(rtol)
            x0 = space.guess(b)
            try:
                x, info = pcg(A, b, self.precondition, x0=x0, rtol=tol, maxiter=cap, what="AMG-CG")
                ok = True
            except IndefiniteMatrixError:
                raise  # a property of A: no hierarchy can help
            except ConvergenceError:
                if state["fresh"]:
                    raise
                ok = False
            if not ok:  # stale hierarchy: rebuild for this matrix and solve again
                self.setup(A)
                state["fresh"] = True
                x, info = pcg(A, b, self.precondition, x0=x0, rtol=tol, maxiter=self.maxiter, what="AMG-CG")
            self.last = info
            space.add(x)
            return x

        solve.space = space  # what a checkpoint would have to carry for a bit-for-bit resume
        return solve

    def __repr__(self) -> str:
        lv = "none" if self.ml is None else f"{len(self.ml.levels)} levels"
        return f"AMGSolverFactory(n={len(self.free)}, hierarchy={lv}, setups={self.n_setups})"


def jacobi_solver_factory(rtol: float = 1e-8, maxiter: int | None = None):
    """Factory of Jacobi-preconditioned CG solves (cheap setup; fine at small size)."""
    default_rtol = rtol

    def make(A):
        A = sp.csr_matrix(A)
        d = A.diagonal()
        if np.any(d <= 0):
            raise InputError("Jacobi-CG needs a positive diagonal; the matrix is not SPD")
        inv = 1.0 / d
        def solve(b, rtol: float | None = None):
            tol = default_rtol if rtol is None else float(rtol)
            return pcg(A, b, lambda r: inv * r, rtol=tol, maxiter=maxiter, what="Jacobi-CG")[0]

        return solve

    return make


def direct_solver_factory(symmetric: bool = True):
    """Factory of sparse LU solves (SuperLU); exact, for systems up to ~1e5 dofs.

    For SPD matrices (``symmetric=True``) the minimum-degree ordering on A^T + A with diagonal
    pivoting is used: measured on the 57k-tet rock (39,871 dofs) it factors in 7.6 s with
    2.6e7 nonzeros in L + U and solves in 0.07 s, against 36 s, 6.0e7 and 0.17 s with SuperLU's
    default COLAMD ordering. A factorisation pays off when one matrix serves many solves
    (a time loop with a frozen tangent).
    """

    def make(A):
        A = sp.csc_matrix(A)
        with single_thread_blas():
            if symmetric:
                lu = spla.splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                               options={"SymmetricMode": True})
            else:
                lu = spla.splu(A)

        def solve(b, rtol: float | None = None):  # exact: a tolerance has nothing to loosen
            with single_thread_blas():
                return lu.solve(np.asarray(b, dtype=float))

        return solve

    return make


#: "auto" considers factorising a matrix only once it has served this many AMG-CG solves (and then
#: when the AMG-CG work spent on it reaches the predicted factorisation: AdaptiveSolverFactory). So a
#: matrix solved fewer times (a 10-s quasi-static coupled run's frozen tangent: 17 solves) never pays
#: for the prediction. Was the whole rule until 2026-12-02 (measured then at 40k dofs: factor 4.3 s,
#: pyamg's AMG-CG solve 0.22 s; docs/solid.md section 5).
FACTOR_AFTER_SOLVES = 20
#: Largest system "auto" factorises: measured 77,174 dofs factor in 11-13 s with 2.1 GiB process
#: peak (two factors alive); fill grows like n^(4/3), so ~1.8e5 dofs (coarsen 3) would need ~4+ GiB.
DIRECT_MAX_DOFS = 100_000
#: The frozen-matrix hint (``expected_solves``) is used: the switch (False: "auto" ignores hints and
#: decides by counting alone, as before 2026-12-02 night).
USE_HINTS = True
#: AMG-CG iterations per announced solve of a hinted matrix. The static coupled stepper announces 2 per
#: exchange step (an upper bound: its warm start skips many); measured over the 10-s run (CG iterations /
#: 20) on uniform 6, graded 3_12 and graded 3_12 with ligaments of the Berea crop, the sample and the
#: blobs (2026-12-02): 5.4, 6.4, 6.6; 4.7, 5.6, 5.8; 1.5, 1.5, 1.6 (mean 4.6); docs/solid.md section 5.
HINT_ITERATIONS_PER_SOLVE = 5.0


class AdaptiveSolverFactory:
    r"""The "auto" policy: AMG-CG for a matrix's first solves, a sparse LU once its predicted cost is repaid.

    A matrix that changes every time (Newton tangents, a TDG stepper refreshing its tangent each
    step) is solved by AMG-CG with the shared, reused hierarchy. A matrix that keeps serving
    solves (the frozen :math:`M^* = M + \alpha^{*2}\Delta t^2 K` of a TDG loop, a frozen static
    tangent) is factorised once the AMG-CG work spent on it has reached the predicted cost of its
    factorisation (ski rental: never more than twice the cheaper choice in hindsight), but not
    before :data:`FACTOR_AFTER_SOLVES` solves, and only up to :data:`DIRECT_MAX_DOFS` dofs. The
    factorisation's cost is predicted before it is made, from a node-level analysis of the
    matrix's fill (:func:`~porefsi.solid.footprint.lu_factor_flops`, made once, at the
    :data:`FACTOR_AFTER_SOLVES`-th solve: a run that solves fewer times never pays for it); the
    AMG-CG work is counted (iterations times the hierarchy's nonzeros), not timed, so runs are
    reproducible. Measured on the 120³ meshes (2026-12-02): the Berea crop's graded mesh
    (37,379 dofs, 699 factor nonzeros per dof) repays its factor after ~40 of its coupled
    run's solves, the sample's graded mesh (31,438 dofs, 471 per dof) after ~24, so the 17 solves
    of a 10-s quasi-static run stay on AMG-CG on both.

    A caller that knows a matrix is frozen passes ``expected_solves`` (the hint: the static coupled
    stepper's tangent serves ~2 solves per exchange step): then the choice is made at the matrix's
    first solve, from predicted costs of that many solves either way
    (:func:`~porefsi.solid.footprint.predict_solver_costs`, :data:`HINT_ITERATIONS_PER_SOLVE`);
    a matrix left on AMG-CG still falls back to the counting rule if it serves more solves than
    expected. ``use_hints = False`` (default :data:`USE_HINTS`) ignores hints.

    Parameters
    ----------
    amg : AMGSolverFactory
        The shared AMG factory.
    factor_after : int
        Fewest solves on one matrix before it may be factorised.
    direct_max_dofs : int
        No factorisation above this many dofs (memory).

    Attributes
    ----------
    n_factorizations : int
        Factorisations made so far.
    predicted : dict
        Of the last matrix assessed: ``factor_s`` (predicted factorisation, s) and ``amg_s``
        (AMG-CG work spent on it when assessed, s).
    """

    def __init__(self, amg: AMGSolverFactory, *, factor_after: int = FACTOR_AFTER_SOLVES,
                 direct_max_dofs: int = DIRECT_MAX_DOFS):
        if int(factor_after) < 0 or int(direct_max_dofs) < 0:
            raise InputError(f"factor_after and direct_max_dofs must be >= 0, got {factor_after}, {direct_max_dofs}")
        self.amg = amg
        self.factor_after, self.direct_max_dofs = int(factor_after), int(direct_max_dofs)
        self.n_factorizations = 0
        self.predicted: dict = {}
        self.use_hints = USE_HINTS

    def _hinted_choice(self, A, solves: int) -> bool:
        """Factorise a frozen matrix expected to serve ``solves`` solves (at its first)? Records ``predicted``."""
        built = self.amg.ml is not None
        cost = predict_solver_costs(A, self.amg.free, [lv.A.nnz for lv in self.amg.ml.levels] if built else None)
        direct, amg = cost.direct_s(solves), cost.amg_s(solves, HINT_ITERATIONS_PER_SOLVE, setup=not built)
        self.predicted = {"factor_s": cost.factor_s, "expected_solves": solves, "direct_s": direct, "amg_s": amg,
                          "choice": "direct" if direct < amg else "amg"}
        return direct < amg

    def _amg_seconds(self, A, iterations: int) -> float:
        """Predicted seconds of ``iterations`` AMG-CG iterations on ``A`` with the current hierarchy."""
        levels = [lv.A.nnz for lv in self.amg.ml.levels]
        return AMG_SECONDS_PER_WORK * iterations * amg_iteration_work(levels, A.nnz)

    def __call__(self, A: sp.spmatrix, expected_solves: int | None = None):
        """Return ``solve(b) -> x`` for the free-dof SPD matrix ``A`` (expected to serve ``expected_solves``)."""
        A = sp.csr_matrix(A)
        can_factor = A.shape[0] <= self.direct_max_dofs
        hint = int(expected_solves) if self.use_hints and expected_solves else None
        state = {"solves": 0, "lu": None, "amg": None, "iterations": 0, "factor_s": None}

        def factor_now() -> bool:
            if state["lu"] is not None or not can_factor:
                return False
            if hint is not None and state["solves"] == 0:
                choice = self._hinted_choice(A, hint)
                state["factor_s"] = self.predicted["factor_s"]
                return choice
            if state["solves"] < self.factor_after:
                return False
            if state["amg"] is None:  # factor_after = 0: no AMG-CG tried, factorise at once
                return True
            if state["factor_s"] is None:
                state["factor_s"] = LU_SECONDS_PER_FLOP * lu_factor_flops(A, self.amg.free)
            spent = self._amg_seconds(A, state["iterations"])
            self.predicted = {"factor_s": state["factor_s"], "amg_s": spent}
            return spent >= state["factor_s"]

        def solve(b: np.ndarray, rtol: float | None = None) -> np.ndarray:
            if factor_now():
                state["lu"] = direct_solver_factory()(A)
                self.n_factorizations += 1
            state["solves"] += 1
            if state["lu"] is not None:
                return state["lu"](b)
            if state["amg"] is None:
                state["amg"] = self.amg(A)
            x = state["amg"](b, rtol)
            state["iterations"] += self.amg.last.iterations
            return x

        return solve

    def __repr__(self) -> str:
        return (f"AdaptiveSolverFactory(factor_after={self.factor_after}, direct_max_dofs={self.direct_max_dofs}, "
                f"factorizations={self.n_factorizations}, amg={self.amg!r})")
