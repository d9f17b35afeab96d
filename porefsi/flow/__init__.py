"""Flow on a pore network: fluids, absolute permeability, dynamic drainage, invasion percolation."""

from porefsi._lazy import exports

#: Public name -> the module that defines it (imported on first use).
_EXPORTS = {
    "Fluids": "porefsi.flow.fluids",
    "PAPER_FLUIDS": "porefsi.flow.fluids",
    "absolute_permeability": "porefsi.flow.permeability",
    "PermeabilityResult": "porefsi.flow.permeability",
    "flow_field": "porefsi.flow.permeability",
    "simulate_drainage": "porefsi.flow.drainage",
    "DrainageSimulator": "porefsi.flow.drainage",
    "DrainageResult": "porefsi.flow.drainage",
    "DrainageOptions": "porefsi.flow.drainage",
    "RunControl": "porefsi.flow.drainage",
    "OUTLET_PRESSURE": "porefsi.flow.drainage",
    "PAPER_RATE": "porefsi.flow.drainage",
    "PAPER_T_END": "porefsi.flow.drainage",
    "FlowState": "porefsi.flow.state",
    "invasion_percolation": "porefsi.flow.invasion",
    "simulator_state": "porefsi.flow._drainage_checkpoint",
    "simulator_from_state": "porefsi.flow._drainage_checkpoint",
    "warn_injection_pressure": "porefsi.flow.plausible",
    "warn_pressure_reached": "porefsi.flow.plausible",
    "InvasionResult": "porefsi.flow.invasion",
}

__all__ = [
    "Fluids",
    "PAPER_FLUIDS",
    "absolute_permeability",
    "PermeabilityResult",
    "flow_field",
    "simulate_drainage",
    "DrainageSimulator",
    "DrainageResult",
    "DrainageOptions",
    "RunControl",
    "OUTLET_PRESSURE",
    "PAPER_RATE",
    "PAPER_T_END",
    "FlowState",
    "invasion_percolation",
    "simulator_state",
    "simulator_from_state",
    "warn_injection_pressure",
    "warn_pressure_reached",
    "InvasionResult",
]

__getattr__, __dir__ = exports(__name__, _EXPORTS)
