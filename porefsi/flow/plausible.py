"""Warnings for physical inputs of a drainage that are allowed but probably a mistake.

Each warning is a :class:`porefsi.image.io.PlausibilityWarning` naming the likely cause; the
command line prints it as one ``porefsi: warning: ...`` line and goes on.
"""

from __future__ import annotations

import math
import warnings

from porefsi.image.io import PlausibilityWarning

__all__ = ["MAX_PLAUSIBLE_PRESSURE", "warn_injection_pressure", "warn_pressure_reached"]

#: Inlet pressures above this (Pa) are warned about: rock fractures and pumps stop long before.
MAX_PLAUSIBLE_PRESSURE = 100e6


def warn_injection_pressure(net, axis, rate: float, mu_n: float) -> float:
    """Warn, before a drainage runs, when pushing ``rate`` through ``net`` needs more than 100 MPa.

    The estimate is the viscous pressure drop of the non-wetting fluid alone at ``rate``
    through the network's single-phase conductance, ``Q mu_n L / (k A)`` (capillary entry
    pressures come on top). Returns the estimate, Pa (NaN if it cannot be made).
    """
    from porefsi.errors import PorefsiError
    from porefsi.flow.permeability import absolute_permeability

    try:
        res = absolute_permeability(net, axis)
        dp = rate * mu_n * res.length / (res.k_m2 * res.area)
    except (PorefsiError, ArithmeticError, ValueError):
        return float("nan")
    if math.isfinite(dp) and dp > MAX_PLAUSIBLE_PRESSURE:
        warnings.warn(f"injecting {rate:g} m^3/s through this network needs an inlet pressure of about "
                      f"{dp / 1e6:.3g} MPa (> {MAX_PLAUSIBLE_PRESSURE / 1e6:g} MPa) from viscous flow alone: the "
                      "rate is probably in the wrong unit (m^3/s; the paper's is 1.25e-13)", PlausibilityWarning,
                      stacklevel=2)
    return dp


def warn_pressure_reached(p_max: float) -> None:
    """Warn after a run whose inlet pressure exceeded :data:`MAX_PLAUSIBLE_PRESSURE`."""
    if math.isfinite(p_max) and p_max > MAX_PLAUSIBLE_PRESSURE:
        warnings.warn(f"the inlet pressure reached {p_max / 1e6:.3g} MPa (> {MAX_PLAUSIBLE_PRESSURE / 1e6:g} MPa): "
                      "check the injection rate and the fluids' units (m^3/s, Pa s, N/m)", PlausibilityWarning,
                      stacklevel=2)
