r"""Time integrators for :math:`M\ddot u + f_{int}(u,t) = f_{ext}(t)`, free of porefsi physics.

The production scheme is :class:`TDGStepper` (piecewise-linear time-discontinuous Galerkin with
the Nørsett predictor-corrector, third order, L-stable limit). The others are references:
:class:`TDGExactStepper` (the coupled TDG solve, an oracle), :class:`NewmarkStepper`,
:class:`GeneralizedAlphaStepper`, :class:`CentralDifferenceStepper` and the quasi-static
:func:`solve_static`. Every stepper has ``dt`` and ``step(u, v, t) -> (u, v, StepInfo)``;
:func:`integrate` turns one into a generator of ``(t, u, v)``.
"""

from porefsi._lazy import exports

#: Public name -> the module that defines it (imported on first use).
_EXPORTS = {
    "StepInfo": "porefsi.integrators._common",
    "default_solver": "porefsi.integrators._common",
    "integrate": "porefsi.integrators._common",
    "CentralDifferenceStepper": "porefsi.integrators.central_difference",
    "critical_time_step": "porefsi.integrators.central_difference",
    "max_frequency": "porefsi.integrators.central_difference",
    "GeneralizedAlphaStepper": "porefsi.integrators.generalized_alpha",
    "generalized_alpha_parameters": "porefsi.integrators.generalized_alpha",
    "NewmarkStepper": "porefsi.integrators.newmark",
    "QuasiStaticStepper": "porefsi.integrators.quasistatic",
    "quasistatic": "porefsi.integrators.quasistatic",
    "solve_static": "porefsi.integrators.quasistatic",
    "amplification_matrix": "porefsi.integrators.spectral",
    "spectral_radius": "porefsi.integrators.spectral",
    "LinearSystem": "porefsi.integrators.system",
    "SecondOrderSystem": "porefsi.integrators.system",
    "SolverFactory": "porefsi.integrators.system",
    "ALPHA": "porefsi.integrators.tdg",
    "LAMBDA": "porefsi.integrators.tdg",
    "TDGStepper": "porefsi.integrators.tdg",
    "effective_loads": "porefsi.integrators.tdg",
    "TDGExactStepper": "porefsi.integrators.tdg_exact",
}

__all__ = [
    "StepInfo",
    "default_solver",
    "integrate",
    "CentralDifferenceStepper",
    "critical_time_step",
    "max_frequency",
    "GeneralizedAlphaStepper",
    "generalized_alpha_parameters",
    "NewmarkStepper",
    "QuasiStaticStepper",
    "quasistatic",
    "solve_static",
    "amplification_matrix",
    "spectral_radius",
    "LinearSystem",
    "SecondOrderSystem",
    "SolverFactory",
    "ALPHA",
    "LAMBDA",
    "TDGStepper",
    "effective_loads",
    "TDGExactStepper",
]

__getattr__, __dir__ = exports(__name__, _EXPORTS)

# ``quasistatic`` names a module and its function: bind the function now (a lazily resolved name
# would be shadowed by the submodule as soon as anything imports it)
from porefsi.integrators.quasistatic import quasistatic  # noqa: E402
