r"""Time integrators for :math:`M\ddot u + f_{int}(u,t) = f_{ext}(t)`, free of porefsi physics.

The production scheme is :class:`TDGStepper` (piecewise-linear time-discontinuous Galerkin with
the Nørsett predictor-corrector, third order, L-stable limit). The others are references:
:class:`TDGExactStepper` (the coupled TDG solve, an oracle), :class:`NewmarkStepper`,
:class:`GeneralizedAlphaStepper`, :class:`CentralDifferenceStepper` and the quasi-static
:func:`solve_static`. Every stepper has ``dt`` and ``step(u, v, t) -> (u, v, StepInfo)``;
:func:`integrate` turns one into a generator of ``(t, u, v)``.
"""

from porefsi.integrators._common import StepInfo, default_solver, integrate
from porefsi.integrators.central_difference import CentralDifferenceStepper, critical_time_step, max_frequency
from porefsi.integrators.generalized_alpha import GeneralizedAlphaStepper, generalized_alpha_parameters
from porefsi.integrators.newmark import NewmarkStepper
from porefsi.integrators.quasistatic import QuasiStaticStepper, quasistatic, solve_static
from porefsi.integrators.spectral import amplification_matrix, spectral_radius
from porefsi.integrators.system import LinearSystem, SecondOrderSystem, SolverFactory
from porefsi.integrators.tdg import ALPHA, LAMBDA, TDGStepper, effective_loads
from porefsi.integrators.tdg_exact import TDGExactStepper

__all__ = [
    "ALPHA",
    "LAMBDA",
    "CentralDifferenceStepper",
    "GeneralizedAlphaStepper",
    "LinearSystem",
    "NewmarkStepper",
    "QuasiStaticStepper",
    "SecondOrderSystem",
    "SolverFactory",
    "StepInfo",
    "TDGExactStepper",
    "TDGStepper",
    "amplification_matrix",
    "critical_time_step",
    "default_solver",
    "effective_loads",
    "generalized_alpha_parameters",
    "integrate",
    "max_frequency",
    "quasistatic",
    "solve_static",
    "spectral_radius",
]
