"""The state of a two-phase drainage on a pore network at one instant."""

from __future__ import annotations

import dataclasses

import numpy as np

__all__ = ["FlowState", "DrainageResult", "PORE_EMPTY", "PORE_FILLING", "PORE_FULL", "PORE_TRAPPED", "PORE_DROPPED",
           "THROAT_WETTING", "THROAT_MENISCUS", "THROAT_PINNED", "THROAT_NONWETTING", "THROAT_TRAPPED",
           "THROAT_DROPPED"]

#: Pore states (:attr:`FlowState.pore_state`).
PORE_EMPTY, PORE_FILLING, PORE_FULL, PORE_TRAPPED, PORE_DROPPED = 0, 1, 2, 3, -1
#: Throat states (:attr:`FlowState.throat_state`).
THROAT_WETTING, THROAT_MENISCUS, THROAT_PINNED, THROAT_NONWETTING, THROAT_TRAPPED, THROAT_DROPPED = (
    0, 1, 2, 3, 4, -1)


@dataclasses.dataclass(frozen=True, eq=False)
class FlowState:
    """Snapshot of a drainage (SI units; arrays indexed like the network's pores and throats).

    Parameters
    ----------
    t : float
        Time since the injection started, s.
    pressure : ndarray of float, shape (Np,)
        The scheme's single pore pressure, Pa (gauge, outlet = 0): the **non-wetting** pressure in
        full pores and the **wetting** pressure in filling and empty pores; trapped pores keep the
        pressure they had when their cluster was cut off; pores dropped as disconnected are NaN.
    fluid_pressure : ndarray of float, shape (Np,)
        Volume-averaged fluid pressure of each pore body, Pa: ``s P_n + (1 - s) P_w`` with
        ``P_n = P_w + Pc_b`` (the meniscus in a filling pore is at the pore-body capillary
        pressure). This is the pressure that loads the pore walls; it equals ``pressure`` in empty
        and full pores.
    nw_saturation : ndarray of float, shape (Np,)
        Non-wetting saturation of each pore body, in [0, 1] (0 for dropped pores).
    pore_state : ndarray of int8, shape (Np,)
        ``PORE_EMPTY`` (0), ``PORE_FILLING`` (1), ``PORE_FULL`` (2), ``PORE_TRAPPED`` (3, wetting
        cluster cut off from the outlet; keeps its saturation), ``PORE_DROPPED`` (-1).
    throat_state : ndarray of int8, shape (Nt,)
        ``THROAT_WETTING`` (0), ``THROAT_MENISCUS`` (1, non-wetting flowing into a filling pore),
        ``THROAT_PINNED`` (2, meniscus held below its threshold), ``THROAT_NONWETTING`` (3),
        ``THROAT_TRAPPED`` (4, touches a trapped pore), ``THROAT_DROPPED`` (-1).
    throat_invaded : ndarray of bool, shape (Nt,)
        Whether non-wetting fluid has passed the throat's constriction.
    inlet_pressure : float
        Pressure of the virtual inlet node, Pa (NaN when not computed, see ``pressure_current``).
    injected_volume, nw_outflow_volume, w_outflow_volume : float
        Cumulative volumes, m³. At constant rate ``injected_volume`` is ``Q t`` (prescribed); at
        constant inlet pressure it is the time integral of the computed non-wetting inflow.
    deformation_volume : float
        Non-wetting volume created by carrying the state onto deformed networks, m³ (saturations
        are kept, so a pore that grows holds more non-wetting fluid).
    breakthrough_time : float
        Time the first outlet pore became full, s (NaN before breakthrough).
    pore_volume_total : float
        Total volume of the kept (spanning) pores, m³.
    """

    t: float
    pressure: np.ndarray
    fluid_pressure: np.ndarray
    nw_saturation: np.ndarray
    pore_state: np.ndarray
    throat_state: np.ndarray
    throat_invaded: np.ndarray
    inlet_pressure: float
    injected_volume: float
    nw_outflow_volume: float
    w_outflow_volume: float
    deformation_volume: float
    breakthrough_time: float
    pore_volume_total: float
    stored_nw_volume: float

    def __post_init__(self):
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if isinstance(v, np.ndarray):
                v.setflags(write=False)

    @property
    def wetting_saturation(self) -> np.ndarray:
        """Wetting saturation of each pore body, ``1 - nw_saturation``, shape (Np,)."""
        return 1.0 - self.nw_saturation

    @property
    def sw(self) -> float:
        """Wetting saturation of the kept pore space (volume-weighted)."""
        return 1.0 - self.stored_nw_volume / self.pore_volume_total

    @property
    def mass_balance_error(self) -> float:
        """``|injected + deformation - stored - nw outflow| / (injected + |deformation|)``, 0 at t = 0.

        At constant rate ``injected`` is the prescribed ``Q t``, so this measures how well the
        fluxes of the pressure solves (rescaled to sum to Q) integrate to the injected volume. At
        constant inlet pressure ``injected`` is the integrated computed inflow, so this checks the
        volume bookkeeping only.
        """
        den = self.injected_volume + abs(self.deformation_volume)
        if den <= 0:
            return 0.0
        num = self.injected_volume + self.deformation_volume - self.stored_nw_volume - self.nw_outflow_volume
        return abs(num) / den


@dataclasses.dataclass(frozen=True, eq=False)
class DrainageResult:
    """Outcome of :func:`porefsi.flow.drainage.simulate_drainage`.

    Attributes
    ----------
    history : dict of str to ndarray
        Time series, one row per event (:data:`porefsi.flow.drainage.HISTORY_COLUMNS`): time s,
        injected volume m³, wetting saturation, inlet pressure Pa (NaN for events whose solve was skipped), capillary
        pressure Pa (``capillary_pressure_pa``: inlet minus outlet node pressure; the outlet is at
        :data:`porefsi.flow.drainage.OUTLET_PRESSURE` = 0 by construction, so it equals the inlet pressure), wetting and
        non-wetting outflow rates m³/s, cumulative events and solves, relative mass balance error,
        number of full pores. Plotted against ``sw`` it is the dynamic Pc–S curve (viscous pressure
        drops included), next to the quasi-static one of
        :func:`~porefsi.flow.invasion.invasion_percolation`.
        ``mass_balance_error`` is ``|V_in + V_def - V_stored - V_out,n| / (V_in + |V_def|)`` after
        the event, with ``V_in`` the prescribed ``Q t`` at constant rate (the integrated computed
        inflow at constant inlet pressure, where it checks the bookkeeping only) and ``V_def`` the
        volume booked by :meth:`porefsi.flow.drainage.DrainageSimulator.with_network` / ``remap``;
        ``injected_m3`` is ``V_in``.
    snapshots : list of FlowState
        States at the requested ``times`` (and at the end).
    invasion_time : ndarray, shape (Np,)
        Time each pore became fully non-wetting, s (NaN if never).
    breakthrough_time, breakthrough_sw : float
        Breakthrough time s and wetting saturation then (NaN if no breakthrough).
    final : FlowState
    counters : dict
        Events, solves, jumps, skipped solves, active-set statistics.
    n_dropped : int
        Pores dropped as not connecting the two faces.
    seconds : float
        Wall time of the run, s.
    """

    history: dict
    snapshots: list
    invasion_time: np.ndarray
    breakthrough_time: float
    breakthrough_sw: float
    final: FlowState
    counters: dict
    n_dropped: int
    seconds: float

    @property
    def mass_balance_error(self) -> float:
        """Largest relative mass balance error over all events (see ``history``; against Q t at constant rate)."""
        m = self.history["mass_balance_error"]
        return float(m.max()) if m.size else 0.0
