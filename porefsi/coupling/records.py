"""What a coupled run reports after every exchange step: the record and its time-series row."""

from __future__ import annotations

import dataclasses

import numpy as np

from porefsi.flow.state import FlowState
from porefsi.network.network import Network

__all__ = ["ExchangeRecord", "IterationStats", "Iterate", "TIMESERIES_COLUMNS", "TIMESERIES_DOCS"]

#: Columns of the per-exchange-step time series (``timeseries.csv``).
TIMESERIES_COLUMNS = (
    "step", "time_s", "sw", "inlet_pressure_Pa", "capillary_pressure_Pa", "max_pore_pressure_Pa",
    "total_pore_force_N", "max_displacement_m", "max_von_mises_Pa", "permeability_m2", "mean_pore_radius_m",
    "n_events", "n_solves", "mass_balance_error", "load_balance_error", "subiterations", "coupling_residual",
    "precoupling_iterations", "precoupling_Ea", "wall_s",
)

#: What each column of :data:`TIMESERIES_COLUMNS` holds (SI units, as in the names).
TIMESERIES_DOCS = {
    "step": "exchange step (0 = the initial state)",
    "time_s": "time at the end of the step, s",
    "sw": "wetting saturation of the spanning pore space",
    "inlet_pressure_Pa": "pressure of the virtual inlet node (gauge: outlet at 0), Pa",
    "capillary_pressure_Pa": "P_in - P_out, inlet minus outlet node pressure (the drainage's definition); "
                             "equal to inlet_pressure_Pa because the outlet is held at P_out = 0, Pa",
    "max_pore_pressure_Pa": "largest pore-wall (volume-averaged fluid) pressure, Pa",
    "total_pore_force_N": "sum over nodes of the magnitude of the pore-pressure nodal force, N",
    "max_displacement_m": "largest nodal displacement magnitude, m",
    "max_von_mises_Pa": "largest nodal (volume-averaged) von Mises stress, Pa",
    "permeability_m2": "absolute permeability of the current (deformed) network along the flow axis, m^2",
    "mean_pore_radius_m": "mean pore radius of the current network, m",
    "n_events": "cumulative drainage filling events",
    "n_solves": "cumulative drainage pressure solves",
    "mass_balance_error": "relative non-wetting volume balance of the drainage against the prescribed Q t (round-off)",
    "load_balance_error": "relative mismatch between the load the interface hands over and the pores carry",
    "subiterations": "fluid-solid sub-iterations of the step (0 at step 0)",
    "coupling_residual": "last relative displacement change of the sub-iterations (0 without)",
    "precoupling_iterations": "re-extractions of the step (re-extraction mode)",
    "precoupling_Ea": "last mean-pore-size change E_a (paper eq. 3.3; empty without re-extraction)",
    "wall_s": "wall time of the step, s",
}


@dataclasses.dataclass(frozen=True)
class IterationStats:
    """How the fixed-point iteration of one exchange step went.

    Attributes
    ----------
    iterations : int
        Fluid-solid iterations (1 with explicit staggering; 0 for the initial state).
    residual_history : tuple of float
        Relative displacement change ``|r_k| / |U|`` of each sub-iteration (empty without).
    relaxation_history : tuple of float
        The relaxation factor ``omega_k`` used after each sub-iteration (Aitken or 1).
    precoupling_history : tuple of float
        ``E_a`` (paper eq. 3.3) after each re-extraction (empty unless re-extracting).
    """

    iterations: int = 0
    residual_history: tuple = ()
    relaxation_history: tuple = ()
    precoupling_history: tuple = ()

    @property
    def residual(self) -> float:
        """The last sub-iteration residual (0 without sub-iterations)."""
        return self.residual_history[-1] if self.residual_history else 0.0

    @property
    def precoupling_ea(self) -> float:
        """The last ``E_a`` (NaN without re-extraction)."""
        return self.precoupling_history[-1] if self.precoupling_history else float("nan")


@dataclasses.dataclass(frozen=True, eq=False)
class Iterate:
    """One fluid-solid iteration within an exchange step.

    For studies of the fixed point (``on_iteration`` of :class:`~porefsi.coupling.loop.CoupledRun`).

    Attributes
    ----------
    index : int
        1 for the first iteration of the step.
    network : NetworkState
        The network (and interface) the drainage ran on in this iteration.
    flow : FlowState
        The drainage state at the end of the step.
    pressures : dict
        ``{time: (Np,) Pa}``: pore pressures the drainage gave at the solid's load times (before
        any ``load_map``).
    displacement : ndarray, shape (Nn, 3)
        The solid's answer to them, m.
    relaxed : ndarray, shape (Nn, 3)
        The iterate handed to the network update (``displacement`` without sub-iterations), m.
    residual : float or None
        ``|U1 - U_k| / |U1|`` of this sub-iteration (None without sub-iterations).
    omega : float or None
        The relaxation factor used (None without sub-iterations).
    """

    index: int
    network: object
    flow: FlowState
    pressures: dict
    displacement: np.ndarray
    relaxed: np.ndarray
    residual: float | None = None
    omega: float | None = None


@dataclasses.dataclass(frozen=True, eq=False)
class ExchangeRecord:
    """What one exchange step produced.

    Attributes
    ----------
    step : int
        Exchange step index (0 = the initial state at t = 0).
    t : float
        Time at the end of the step, s.
    flow : FlowState
        Drainage state at ``t``.
    network : Network
        Network at ``t`` (deformed).
    displacement : ndarray, shape (Nn, 3)
        Nodal displacement, m.
    von_mises : ndarray, shape (Nn,)
        Nodal (volume-averaged) von Mises stress, Pa.
    nodal_force : ndarray, shape (Nn, 3)
        Pore-pressure forces on the nodes at ``t``, N.
    row : dict
        The time-series row (:data:`TIMESERIES_COLUMNS`).
    seconds : dict
        Wall time of the step by stage: fluid, interface, solid, update, stress, permeability, s.
    residual_history : tuple of float
        Fluid-solid sub-iterations: relative displacement change ``|r_k| / |U|`` of each (empty
        without sub-iterations).
    relaxation_history : tuple of float
        The relaxation factor ``omega_k`` used after each sub-iteration (Aitken or 1).
    precoupling_history : tuple of float
        Pre-coupling re-extractions: ``E_a`` (paper eq. 3.3) after each (empty unless re-extracting).
    cpu_seconds : dict
        CPU time (``time.process_time``: this process, all threads) of the step by the stages of
        ``seconds``, s.
    """

    step: int
    t: float
    flow: FlowState
    network: Network
    displacement: np.ndarray
    von_mises: np.ndarray
    nodal_force: np.ndarray
    row: dict
    seconds: dict
    residual_history: tuple = ()
    relaxation_history: tuple = ()
    precoupling_history: tuple = ()
    cpu_seconds: dict = dataclasses.field(default_factory=dict)
