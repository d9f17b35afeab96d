r"""The linear-response solid: superposed unit responses instead of Newton at every exchange step.

At the coupled run's loads (displacements ~1e-11 m, strains ~1e-7) the solid is linear to ~1e-7,
so it is linearised once about the reference state :math:`u = 0`, :math:`t = 0`:

.. math::

    f_{lin}(u, t) = f_0 + K_0\,u + t\,k_D, \qquad
    u(t) = K_0^{-1}\bigl(f_{ext}(t) - f_0 - t\,k_D\bigr)

(:math:`K_0` the tangent on the free dofs, :math:`f_0` the internal force of the initial
prescribed motion, :math:`k_D = K_{fD}\,\dot u_D` the load of the prescribed boundary motion
per unit time). The pore loads are linear in the pore pressures through the interface operator
(``F = T P`` on the reference configuration, total Lagrangian), so

.. math:: u(t) = a + t\,b + U\,P(t), \qquad U = K_0^{-1} T_f

with one column of unit responses per loaded pore: every step is a matrix-vector product.
:class:`LinearResponse` holds :math:`K_0`'s factorisation and, once it has served enough solves to
pay for them (:data:`BLOCK_SOLVE_RATIO`) and they fit :data:`RESPONSE_BUDGET_BYTES`, the unit
responses; it is cached in the process (:func:`linear_response`), so every member of a rate sweep
run in one process reuses it. Without stored responses a step is one back-substitution.

:class:`LinearStepper` wraps the nonlinear stepper of the run (static or TDG) and monitors the
linearisation: the nonlinear defect :math:`d = f_{int}(u) - f_{lin}(u)` at the linear solution,
turned into a displacement error :math:`\delta = K_0^{-1} d` (static; for TDG the step's
:math:`M^{*-1}\alpha^2\Delta t^2 d`), :math:`e = \|\delta\|_\infty / \|u\|_\infty`. With
``response = "auto"`` the run falls back to the nonlinear stepper for good when ``e`` times
:data:`CHECK_GROWTH` (what it may grow by before the next check) exceeds ``solid.response_tol``,
or when a re-extraction rebuilt the interface (the responses are those of the reference pores),
redoing that step nonlinearly; each fallback and check is recorded (:meth:`LinearStepper.summary`,
``summary.json`` key ``solid_response``). ``"linear"`` monitors and records but never falls back
(studies of where the linearisation stops holding).
"""

from __future__ import annotations

import collections
import hashlib

import numpy as np
import scipy.sparse as sp

from porefsi.coupling._loop_support import SOLVER_FAILURES, solver_failure
from porefsi.coupling.solid_step import StaticStepper, TDGStepper, _ModelView, make_solid_stepper
from porefsi.errors import InputError
from porefsi.integrators.tdg import ALPHA
from porefsi.solid.model import SMALL_DOFS, SolidModel

__all__ = ["RESPONSES", "LinearResponse", "LinearStepper", "linear_response", "clear_response_cache", "make_stepper",
           "max_green_lagrange", "with_response"]

#: ``solid.response`` choices.
RESPONSES = ("nonlinear", "linear", "auto")
#: Largest stored unit-response matrix (n_dofs x loaded pores x 8 bytes); above it every step is a
#: back-substitution (at 120³ / coarsen 5: 39,871 dofs x 262 pores = 84 MB).
RESPONSE_BUDGET_BYTES = 512 * 2**20
#: Cost of one column of a block solve relative to one single solve (measured on the 120³ sample
#: at coarsen 5: 262 columns in 4.3 CPU-s, one solve 0.037 s: 0.44). Ski rental: the responses are
#: built once the factorisation has served ``BLOCK_SOLVE_RATIO x columns`` solves (or the run
#: ahead needs that many).
BLOCK_SOLVE_RATIO = 0.5
#: Monitor: a check at least every this many linear steps ...
CHECK_EVERY = 5
#: ... and whenever max |u| has grown by this factor since the last check (the error grows with it).
CHECK_GROWTH = 1.25
#: Linear responses kept in the process (each holds a factorisation: ~0.3 GB at 40k dofs).
CACHE_SIZE = 1

_CACHE: collections.OrderedDict = collections.OrderedDict()


def _digest(*parts) -> str:
    h = hashlib.sha1()
    for p in parts:
        h.update(memoryview(np.ascontiguousarray(p)).cast("B") if isinstance(p, np.ndarray) else repr(p).encode())
    return h.hexdigest()


def _model_key(model: SolidModel) -> str:
    c = model.constraints
    return _digest(model.mesh.points, model.mesh.tets, model.free, c.dofs, c.value, c.rate, repr(model.material),
                   model.order, model.linear_solver, model.backend, repr(model.tractions))


def clear_response_cache() -> None:
    """Forget the cached linear responses (their factorisations are freed)."""
    _CACHE.clear()


def linear_response(model: SolidModel) -> LinearResponse:
    """The :class:`LinearResponse` of ``model``, from the process cache when one was made before.

    Two models share an entry when their mesh, constraints, material, order and solver agree
    (a rate sweep's members).
    """
    key = _model_key(model)
    if key in _CACHE:
        _CACHE.move_to_end(key)
        return _CACHE[key]
    resp = LinearResponse(model)
    _CACHE[key] = resp
    while len(_CACHE) > CACHE_SIZE:
        _CACHE.popitem(last=False)
    return resp


def max_green_lagrange(model: SolidModel, U: np.ndarray) -> float:
    """Largest |principal Green-Lagrange strain| of any element for vertex displacements ``U`` (Nv, 3).

    From the P1 (vertex) gradients: exact for P1, the vertex part of a P2 field.
    """
    dN = model.vertex_gradients()  # (Ne, 4, 3), 1/m
    H = np.einsum("eai,eaj->eij", np.asarray(U, float)[model.mesh.tets], dN)
    E = 0.5 * (H + H.transpose(0, 2, 1) + np.einsum("eki,ekj->eij", H, H))
    return float(np.abs(np.linalg.eigvalsh(E)).max(initial=0.0))


class LinearResponse:
    """The solid linearised about its reference state, factorised once.

    Parameters
    ----------
    model : SolidModel
        Without nodal forces (the pore loads come per step).

    Attributes
    ----------
    K : scipy.sparse.csr_matrix, shape (n, n)
        Tangent at ``u = 0``, ``t = 0`` on the free dofs, N/m.
    f0 : ndarray, shape (n,)
        Internal force at ``u = 0``, ``t = 0`` (zero unless the prescribed motion starts nonzero), N.
    k_rate : ndarray, shape (n,)
        ``K_fD @ rate_D``: the load of the prescribed motion per unit time, N/s.
    n_solves : int
        Back-substitutions served (all runs that shared it).
    """

    def __init__(self, model: SolidModel):
        self.model = model
        u0 = np.zeros(model.n_dofs)
        self.K = model.tangent(u0, 0.0)
        self.f0 = np.array(model.internal_force(u0, 0.0))
        c = model.constraints
        rate = np.zeros(model.n_full)
        rate[c.dofs] = c.rate
        self.k_rate = (model.full_tangent(u0, 0.0) @ rate)[model.free]
        self.affine_load = not any(tr.factor is not None for tr in model.tractions)
        self._solve = None
        self.n_solves = 0
        self._responses: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = {}

    def solve(self, b: np.ndarray, t: float = 0.0) -> np.ndarray:
        """``K0^{-1} b`` (factorised on first use); a solver-library failure is a ConvergenceError."""
        try:
            if self._solve is None:
                self._solve = self.model.make_solver(self.K)
            x = self._solve(b)
        except SOLVER_FAILURES as exc:
            raise solver_failure(exc, t) from exc
        self.n_solves += 1 if np.ndim(b) == 1 else np.shape(b)[1]
        return x

    def linear_force(self, u: np.ndarray, t: float) -> np.ndarray:
        """``f_lin(u, t) = f0 + K0 u + t k_rate`` on the free dofs, N."""
        return self.f0 + self.K @ u + t * self.k_rate

    def static(self, fext: np.ndarray, t: float) -> np.ndarray:
        """The linear equilibrium at ``t`` under the free-dof load ``fext`` (one back-substitution), m."""
        return self.solve(fext - self.f0 - t * self.k_rate, t)

    def free_operator(self, interface) -> sp.csc_matrix:
        """The interface operator on the free dofs (rows padded to all dofs first), m²."""
        T = sp.csr_matrix(interface.operator)
        n_full = self.model.n_full
        if T.shape[0] < n_full:  # forces on the vertices of a P2 model
            T = sp.vstack([T, sp.csr_matrix((n_full - T.shape[0], T.shape[1]))]).tocsr()
        return T[self.model.free].tocsc()

    def loaded_columns(self, interface) -> int:
        """Number of pores of ``interface`` whose load reaches a free dof (the columns of ``U``)."""
        return int(np.count_nonzero(np.diff(self.free_operator(interface).indptr)))

    def has_responses(self, interface) -> bool:
        """Whether the unit responses of ``interface`` are stored."""
        return _operator_key(interface) in self._responses

    def responses(self, interface) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(cols, U, a, b)``: loaded pores, unit responses (n, len(cols)) m/Pa, and ``u = a + t b`` without pore load.

        Built by a block solve on first request (and kept with this response).
        """
        key = _operator_key(interface)
        if key not in self._responses:
            if not self.affine_load:
                raise InputError("unit responses need loads affine in time (no time-varying tractions)")
            Tf = self.free_operator(interface)
            cols = np.flatnonzero(np.diff(Tf.indptr))
            B = Tf[:, cols].toarray()
            m = self.model
            direct = m.linear_solver == "direct" or (m.linear_solver == "auto" and m.n_dofs < SMALL_DOFS)
            if direct:  # SuperLU solves all columns at once (0.44 of the cost of single solves)
                U = np.asarray(self.solve(np.asfortranarray(B)))
            else:
                U = np.column_stack([self.solve(B[:, j]) for j in range(B.shape[1])]) if len(cols) else B
            a = self.solve(m.with_nodal_forces(None).external_force(0.0) - self.f0)  # the pore loads come in U
            b = self.solve(-self.k_rate)
            self._responses = {key: (cols, U, a, b)}  # one interface at a time
        return self._responses[key]


def _operator_key(interface) -> str:
    T = sp.csr_matrix(interface.operator)
    return _digest(T.indptr, T.indices, T.data, T.shape)


class _LinearisedModel(_ModelView):
    """A :class:`SolidModel` seen through its linearisation (for the TDG stepper): ``f_int = f_lin``.

    The tangent is always the same ``K0`` object, so the TDG stepper factorises ``M*`` once per
    ``dt`` and never refreshes it; the last solver built is kept for the monitor.
    """

    def __init__(self, model: SolidModel, resp: LinearResponse, solvers: dict):
        self.model, self.resp, self.solvers = model, resp, solvers

    def internal_force(self, u, t):
        """The linearised internal force, N."""
        return self.resp.linear_force(u, t)

    def tangent(self, u, t):
        """``K0`` (the same object at every call)."""
        return self.resp.K

    def with_nodal_forces(self, F) -> _LinearisedModel:
        """The same linearisation under nodal forces ``F``."""
        return _LinearisedModel(self.model.with_nodal_forces(F), self.resp, self.solvers)

    def make_solver(self, A):
        """The model's solver for ``A`` (kept as ``solvers["last"]``)."""
        solve = self.model.make_solver(A)
        self.solvers["last"] = solve
        return solve


class LinearStepper:
    """Linear-response solid steps with a validity monitor and a fallback to ``nonlinear``.

    Parameters
    ----------
    nonlinear : StaticStepper or TDGStepper
        The run's nonlinear stepper (used after a fallback; its kind sets the linear one's).
    mode : {"linear", "auto"}
        ``auto`` falls back when the estimated error exceeds ``tol`` or the interface is rebuilt;
        ``linear`` records the estimates and never falls back.
    tol : float
        Tolerance on the estimated relative displacement error of the linearisation.
    interface : Interface, optional
        The reference interface the unit responses are built from (none: back-substitutions only).
    n_steps : int, default 0
        Exchange steps the run will take (lets a long run build the unit responses at once).
    """

    def __init__(self, nonlinear: StaticStepper | TDGStepper, mode: str = "auto", tol: float = 1e-3,
                 interface=None, n_steps: int = 0):
        if mode not in ("linear", "auto"):
            raise InputError(f"mode must be 'linear' or 'auto', got {mode!r}")
        self.inner, self.mode, self.tol = nonlinear, mode, float(tol)
        self.model = nonlinear.model
        self.interface, self.n_steps = interface, int(n_steps)
        self.resp = linear_response(self.model)
        self.dynamic = isinstance(nonlinear, TDGStepper)
        self._solvers: dict = {}
        self._tdg = TDGStepper(_LinearisedModel(self.model, self.resp, self._solvers), nonlinear.iterations,
                               nonlinear.load_rule) if self.dynamic else None
        self.fallen: dict | None = None  # the fallback event, once it happened
        self.events: list[dict] = []
        self.n_linear = self.n_checks = 0
        self.max_estimate = self.max_strain = 0.0
        self._since_check, self._u_checked = CHECK_EVERY, 0.0
        self._use_responses: bool | None = None
        self._seen, self._key = None, None  # an interface object found equal to the reference, its digest
        self._n_cols: int | None = None  # loaded pores of the reference interface

    # ---- the stepper protocol -------------------------------------------------------------
    def load_times(self, t0: float, dt: float) -> tuple[float, ...]:
        """The times within the step at which the solid takes the load (those of the nonlinear stepper)."""
        return self.inner.load_times(t0, dt)

    def step(self, u, v, t0: float, dt: float, forces: dict, pressures: dict | None = None, interface=None):
        """``(u1, v1)`` at ``t0 + dt``: linear while it holds, else the nonlinear stepper's.

        ``pressures`` (``{time: (Np,) Pa}``) and the ``interface`` that made ``forces`` let the
        static path use the stored unit responses; without them it back-substitutes ``forces``.
        """
        if self.fallen is not None:
            return self.inner.step(u, v, t0, dt, forces)
        t1 = t0 + dt
        if interface is not None and self.interface is not None and not self._same_interface(interface):
            return self._fall_back(u, v, t0, dt, forces, "re-extraction rebuilt the interface (new pores)", None)
        if self.dynamic:
            u1, v1 = self._tdg.step(u, v, t0, dt, forces)
        else:
            u1 = self._static(t1, forces[t1], None if pressures is None else pressures.get(t1), interface)
            v1 = (u1 - u) / dt
        self.n_linear += 1
        est = self._monitor(u1, t1, dt)
        # the error may grow by CHECK_GROWTH before the next check: fall back before it can pass tol
        if est is not None and est * CHECK_GROWTH > self.tol and self.mode == "auto":
            why = f"estimated linearisation error {est:.3g} (x {CHECK_GROWTH:g}) > {self.tol:g}"
            return self._fall_back(u, v, t0, dt, forces, why, est)
        return u1, v1

    def _same_interface(self, interface) -> bool:
        """Whether ``interface`` has the reference operator (the same object, or one restored from a checkpoint)."""
        if interface is self.interface or interface is self._seen:
            return True
        if self._key is None:
            self._key = _operator_key(self.interface)
        same = _operator_key(interface) == self._key
        if same:
            self._seen = interface
        return same

    def _static(self, t1: float, F1: np.ndarray, P1, interface) -> np.ndarray:
        if P1 is not None and interface is not None and self.interface is not None and self._responses_pay():
            cols, U, a, b = self.resp.responses(self.interface)
            return a + t1 * b + U @ np.asarray(P1, float)[cols]
        return self.resp.static(self.model.with_nodal_forces(F1).external_force(t1), t1)

    def _responses_pay(self) -> bool:
        """Ski rental: use (and build) the unit responses once their block solve is paid for."""
        if not self._use_responses:  # decided again until it pays
            r = self.resp
            if r.has_responses(self.interface):
                self._use_responses = True
            else:
                if self._n_cols is None:
                    self._n_cols = r.loaded_columns(self.interface)
                fits = 8 * self.model.n_dofs * self._n_cols <= RESPONSE_BUDGET_BYTES
                ahead = max(0, self.n_steps - self.n_linear)
                self._use_responses = r.affine_load and fits and r.n_solves + ahead >= BLOCK_SOLVE_RATIO * self._n_cols
        return self._use_responses

    # ---- validity monitor ---------------------------------------------------------------
    def _monitor(self, u1: np.ndarray, t1: float, dt: float) -> float | None:
        """The estimated relative error of ``u1`` when a check is due (None otherwise)."""
        umax = float(np.max(np.abs(u1), initial=0.0))
        self._since_check += 1
        if umax == 0.0 or (self._since_check < CHECK_EVERY and umax <= CHECK_GROWTH * self._u_checked):
            return None
        est = self.estimate(u1, t1, dt)
        self._since_check, self._u_checked = 0, umax
        self.n_checks += 1
        self.max_estimate = max(self.max_estimate, est)
        strain = max_green_lagrange(self.model, self.model.expand(u1, t1))
        self.max_strain = max(self.max_strain, strain)
        self.events.append({"kind": "check", "t": t1, "estimate": est, "max_u": umax, "max_strain": strain})
        return est

    def estimate(self, u: np.ndarray, t: float, dt: float | None = None) -> float:
        r"""Estimated relative error of the linear solution ``u`` at ``t``: ``|δ|_∞ / |u|_∞``.

        ``δ = K0^{-1} (f_int(u, t) - f_lin(u, t))`` (static) or the TDG step's
        ``M*^{-1} α² Δt² (f_int - f_lin)``: one Newton correction of the linear solution.
        """
        umax = float(np.max(np.abs(u), initial=0.0))
        if umax == 0.0:
            return 0.0
        d = self.model.internal_force(u, t) - self.resp.linear_force(u, t)
        if self.dynamic and "last" in self._solvers and dt is not None:
            delta = self._solvers["last"](ALPHA**2 * dt**2 * d)
        else:
            delta = self.resp.solve(d, t)
        return float(np.max(np.abs(delta))) / umax

    def _fall_back(self, u, v, t0, dt, forces, reason: str, est):
        self.fallen = {"kind": "fallback", "t": t0 + dt, "step_start": t0, "reason": reason, "estimate": est}
        self.events.append(self.fallen)
        return self.inner.step(u, v, t0, dt, forces)

    # ---- records and checkpoints --------------------------------------------------------------
    @property
    def path(self) -> str:
        """What is running now: ``"linear (unit responses)"``, ``"linear (back-substitution)"`` or ``"nonlinear"``."""
        if self.fallen is not None:
            return "nonlinear"
        if self.dynamic:
            return "linear (TDG)"
        return "linear (unit responses)" if self._use_responses else "linear (back-substitution)"

    def summary(self) -> dict:
        """What ran: mode, path, checks, largest estimate, fallback (``summary.json`` ``solid_response``)."""
        return {"requested": self.mode, "path": self.path, "tolerance": self.tol, "linear_steps": self.n_linear,
                "checks": self.n_checks, "max_estimated_error": self.max_estimate,
                "max_strain_at_checks": self.max_strain, "fallback": self.fallen,
                "events": [e for e in self.events if e["kind"] != "check"][-20:]}

    def state(self) -> tuple[dict, dict]:
        """(arrays, metadata): the nonlinear stepper's, and whether and when the run fell back."""
        arrays, meta = self.inner.state()
        meta = dict(meta, linear_fallen=self.fallen is not None, linear_steps=self.n_linear,
                    linear_responses=bool(self._use_responses), linear_since_check=self._since_check,
                    linear_u_checked=self._u_checked)
        return arrays, meta

    def restore(self, arrays: dict, meta: dict) -> None:
        """Continue as the checkpointed stepper did (fallen back or not, same path)."""
        self.inner.restore(arrays, meta)
        if meta.get("linear_fallen"):
            self.fallen = {"kind": "fallback", "t": None, "reason": "before the checkpoint", "estimate": None}
        self.n_linear = int(meta.get("linear_steps", 0))
        self._use_responses = True if meta.get("linear_responses") else None
        self._since_check = int(meta.get("linear_since_check", CHECK_EVERY))
        self._u_checked = float(meta.get("linear_u_checked", 0.0))


def make_stepper(model: SolidModel, integrator: str = "static", iterations: int = 2, load_rule: str = "right",
                 response: str = "nonlinear", response_tol: float = 1e-3, interface=None,
                 n_steps: int = 0) -> StaticStepper | TDGStepper | LinearStepper:
    """The coupled run's solid stepper, nonlinear or linear.

    :func:`~porefsi.coupling.solid_step.make_solid_stepper`'s stepper, or for ``response`` =
    ``"linear"`` / ``"auto"`` (:attr:`SolidOptions.response`) a :class:`LinearStepper` around it
    (unit responses of ``interface``'s pores, tolerance ``response_tol``, ``n_steps`` ahead).
    """
    return with_response(make_solid_stepper(model, integrator, iterations, load_rule), response, response_tol,
                         interface, n_steps)


def with_response(inner: StaticStepper | TDGStepper, response: str = "nonlinear", response_tol: float = 1e-3,
                  interface=None, n_steps: int = 0) -> StaticStepper | TDGStepper | LinearStepper:
    """``inner`` itself for ``response = "nonlinear"``, else a :class:`LinearStepper` around it.

    ``response``, ``response_tol``, ``interface`` and ``n_steps`` as for :func:`make_stepper`.
    """
    if response not in RESPONSES:
        raise InputError(f"response must be one of {RESPONSES}, got {response!r}")
    if response == "nonlinear":
        return inner
    return LinearStepper(inner, response, response_tol, interface=interface, n_steps=n_steps)
