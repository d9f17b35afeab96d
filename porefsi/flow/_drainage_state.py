"""Snapshot of the drainage engine as a :class:`~porefsi.flow.state.FlowState` (private)."""

from __future__ import annotations

import numpy as np

from porefsi.flow._drainage_engine import Engine
from porefsi.flow._drainage_graph import DrainageGraph
from porefsi.flow.state import (
    PORE_DROPPED,
    PORE_EMPTY,
    PORE_FILLING,
    PORE_FULL,
    PORE_TRAPPED,
    THROAT_DROPPED,
    THROAT_MENISCUS,
    THROAT_NONWETTING,
    THROAT_PINNED,
    THROAT_TRAPPED,
    THROAT_WETTING,
    FlowState,
)
from porefsi.network.network import Network

__all__ = ["make_state"]


def make_state(net: Network, g: DrainageGraph, e: Engine) -> FlowState:
    """The :class:`FlowState` of engine ``e`` on graph ``g`` of ``net`` (pressures as they stand).

    Per-pore arrays span all of ``net``'s pores: dropped pores get NaN pressures, zero
    saturation and :data:`PORE_DROPPED`; throats outside the graph :data:`THROAT_DROPPED`.
    """
    n_p, n = net.n_pores, g.n
    keep = g.keep
    sat_k = e.vn / g.vol
    P = np.full(n_p, np.nan)
    P[keep] = e.P[:n]
    sat = np.zeros(n_p)
    sat[keep] = sat_k
    fp = np.full(n_p, np.nan)
    filling_k = (sat_k > 0) & ~e.full
    fp[keep] = e.P[:n] + np.where(filling_k, sat_k * g.pcb[:n], 0.0)
    ps = np.full(n_p, PORE_DROPPED, dtype=np.int8)
    pk = np.where(e.full, PORE_FULL, np.where(sat_k > 0, PORE_FILLING, PORE_EMPTY)).astype(np.int8)
    pk[e.trapped] = PORE_TRAPPED
    ps[keep] = pk
    cond, men, fa = e.conductances()
    fx = e._node_full()
    fb = fx[g.b]
    tx = np.concatenate([e.trapped, [False, False]])
    kind = np.where(fa & fb, THROAT_NONWETTING, np.where(men, THROAT_MENISCUS,
                    np.where(fa ^ fb, THROAT_PINNED, THROAT_WETTING)))
    kind[tx[g.a] | tx[g.b]] = THROAT_TRAPPED
    ts = np.full(net.n_throats, THROAT_DROPPED, dtype=np.int8)
    inv = np.zeros(net.n_throats, dtype=bool)
    m = g.throat >= 0
    ts[g.throat[m]] = kind[m]
    inv[g.throat[m]] = e.inv[m]
    return FlowState(
        t=e.t, pressure=P, fluid_pressure=fp, nw_saturation=sat, pore_state=ps, throat_state=ts,
        throat_invaded=inv, inlet_pressure=e.inlet_pressure(), injected_volume=e.injected,
        nw_outflow_volume=e.out_n, w_outflow_volume=e.out_w, deformation_volume=e.deformation,
        breakthrough_time=e.t_breakthrough, pore_volume_total=float(g.vol.sum()),
        stored_nw_volume=float(e.vn.sum()),
    )
