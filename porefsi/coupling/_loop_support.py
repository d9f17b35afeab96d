"""Helpers of the coupled loop (private).

The solid model as the TDG stepper sees it, solver failures as typed errors, topology comparison,
stage clocks (wall and CPU seconds).
"""

from __future__ import annotations

import contextlib
import hashlib
import time

import numpy as np

from porefsi.errors import ConvergenceError
from porefsi.network.network import Network


class _TangentLog:
    """The solid model as the TDG stepper sees it, noting where its tangent was evaluated.

    ``last`` is the ``(u, t)`` of the latest :meth:`tangent` call (what the stepper factorised);
    a ``pin`` set by :meth:`CoupledRun.restore` makes the next call evaluate there instead, so
    the resumed stepper factorises the same matrix as the run that wrote the checkpoint.
    """

    def __init__(self, model):
        self.model = model
        self.last: tuple[np.ndarray, float] | None = None
        self.pin: tuple[np.ndarray, float] | None = None

    @property
    def n_dofs(self) -> int:
        """Free dofs of the model."""
        return self.model.n_dofs

    def mass(self):
        """The model's mass."""
        return self.model.mass()

    def internal_force(self, u, t):
        """The model's internal force."""
        return self.model.internal_force(u, t)

    def external_force(self, t):
        """The model's external force."""
        return self.model.external_force(t)

    def tangent(self, u, t):
        """The model's tangent at ``(u, t)`` (or at the pinned state, once)."""
        if self.pin is not None:
            u, t = self.pin
            self.pin = None
        self.last = (np.array(u, dtype=float), float(t))
        return self.model.tangent(*self.last)


#: Exceptions solver libraries raise for a singular or broken system (SuperLU: RuntimeError).
_SOLVER_FAILURES = (RuntimeError, ArithmeticError, np.linalg.LinAlgError)


def _solver_failure(exc: BaseException, t: float, part: str = "solid") -> ConvergenceError:
    """A solver library's exception (e.g. SuperLU's "Factor is exactly singular") as a typed error."""
    if part == "fluid":
        return ConvergenceError(
            f"the drainage pressure solve failed at t = {t:g} s ({type(exc).__name__}: {exc}); the network's "
            "conductance matrix is singular: check the network for pores cut off from inlet and outlet")
    return ConvergenceError(
        f"the solid's linear solver failed at t = {t:g} s ({type(exc).__name__}: {exc}); the tangent is "
        "singular or not positive definite: check for floating or inverted elements (solid.coarsen), "
        "reduce coupling.exchange_dt, or try solid.linear_solver = 'amg'")


def _digest(phases: np.ndarray) -> bytes:
    """SHA-1 of a voxel image's bytes (the key of the loop's extraction cache)."""
    return hashlib.sha1(memoryview(np.ascontiguousarray(phases)).cast("B")).digest()


def _same_topology(a: Network, b: Network) -> bool:
    return a.n_pores == b.n_pores and np.array_equal(a.throat_conns, b.throat_conns) and \
        np.array_equal(a.pore_faces, b.pore_faces)


class StageClock:
    """Wall (``time.perf_counter``) and CPU (``time.process_time``) seconds of named stages.

    ``with clock("fluid"): ...`` adds the block's wall seconds to ``clock.wall["fluid"]`` and its
    CPU seconds (this process, all threads) to ``clock.cpu["fluid"]``; the two dicts may be shared
    with the caller (they are updated in place).
    """

    def __init__(self, wall: dict | None = None, cpu: dict | None = None):
        self.wall = {} if wall is None else wall
        self.cpu = {} if cpu is None else cpu

    @contextlib.contextmanager
    def __call__(self, stage: str):
        """Time the block as ``stage`` (accumulated: the same stage may be timed several times)."""
        w0, c0 = time.perf_counter(), time.process_time()
        yield
        self.wall[stage] = self.wall.get(stage, 0.0) + time.perf_counter() - w0
        self.cpu[stage] = self.cpu.get(stage, 0.0) + time.process_time() - c0
