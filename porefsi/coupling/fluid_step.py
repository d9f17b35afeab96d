"""The fluid part of an exchange step and the load transfer: plain arrays in and out.

``advance_fluid``
    The drainage advanced through the times the solid needs loads at; the pore-wall pressure
    (Np,) at each.
``transfer_loads``
    Those pressures as nodal forces through an interface, per load time, plus the forces on the
    mesh vertices for outputs.
``carry_state``
    The drainage state carried onto a network the solid has deformed (same pores: new sizes;
    new pores after a re-extraction: a volume-keeping remap through the voxel labels).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from porefsi.coupling._loop_support import SOLVER_FAILURES, same_topology, solver_failure
from porefsi.coupling.interface import Interface
from porefsi.errors import NetworkError
from porefsi.flow.drainage import DrainageSimulator
from porefsi.flow.state import FlowState
from porefsi.network.network import Network

__all__ = ["pore_pressure", "fluid_times", "advance_fluid", "carry_state", "Loads", "transfer_loads"]


def pore_pressure(state: FlowState) -> np.ndarray:
    """Pore-wall loading pressure (Np,), Pa.

    The volume-averaged fluid pressure; 0 where a pore is not simulated.
    """
    return np.nan_to_num(np.asarray(state.fluid_pressure, float), nan=0.0)


def fluid_times(load_times, t0: float, t1: float) -> list[float]:
    """The times after ``t0`` the fluid must reach: the solid's load times and the step's end ``t1``."""
    return sorted((set(load_times) | {t1}) - {t0})


def advance_fluid(sim: DrainageSimulator, times, t0: float) -> dict[float, np.ndarray]:
    """Advance ``sim`` (in place) through ``times`` (ascending, s); ``{time: pore pressure (Np,) Pa}``.

    Raises
    ------
    ConvergenceError
        The drainage pressure solve failed (a solver library's exception, named with ``t0``).
    """
    try:
        return {s: pore_pressure(sim.advance_to(s)) for s in times}
    except SOLVER_FAILURES as exc:
        raise solver_failure(exc, t0, "fluid") from exc


@dataclasses.dataclass(frozen=True)
class Loads:
    """Nodal forces of one exchange step.

    Attributes
    ----------
    forces : dict
        ``{time: (Nn, 3) N}``: the forces the solid takes at each load time (and at the start).
    output : ndarray, shape (Nv, 3)
        The forces at the end of the step on the mesh vertices, N (outputs are drawn there: the
        P1 split of a P2 operator's load).
    """

    forces: dict
    output: np.ndarray


def transfer_loads(interface: Interface, pressures: dict, start_forces: np.ndarray, t0: float, t1: float) -> Loads:
    """The pore pressures of ``pressures`` (``{time: (Np,) Pa}``, ``t1`` among them) as nodal forces.

    ``start_forces`` are the forces the solid carried at ``t0`` (computed on the network and
    interface of ``t0``, even when a re-extraction changes the topology within the step).
    """
    forces = {t0: start_forces} | {s: interface.nodal_forces(P) for s, P in pressures.items()}
    output = forces[t1] if interface.vertex_operator is None else interface.vertex_forces(pressures[t1])
    return Loads(forces, output)


def carry_state(sim: DrainageSimulator, net: Network, labels_old=None, labels_new=None) -> DrainageSimulator:
    """The drainage state of ``sim`` on network ``net``.

    Same topology: sizes only. Otherwise a remap in which each new pore's non-wetting
    saturation is the voxel-weighted mean over the old pores its voxels belonged to (labels of
    ``sim.net`` and of ``net``), so the stored volume is kept.

    Raises
    ------
    NetworkError
        The topology changed and no voxel labels were given.
    """
    if net is sim.net:
        return sim
    if same_topology(net, sim.net):
        return sim.with_network(net)
    if labels_new is None or labels_old is None:
        raise NetworkError("the network topology changed but no voxel labels were given to remap the state")
    st = sim.state
    sat_old = np.concatenate([np.asarray(st.nw_saturation, float), [0.0]])  # index -1 -> solid: 0
    fill_old = np.concatenate([np.nan_to_num(sim.invasion_time(), nan=np.inf), [np.inf]])
    old = np.asarray(labels_old).ravel()
    new = np.asarray(labels_new).ravel()
    m = new >= 0
    n_new = net.n_pores
    count = np.bincount(new[m], minlength=n_new).astype(float)
    sat = np.bincount(new[m], weights=sat_old[old[m]], minlength=n_new) / np.maximum(count, 1.0)
    first = np.full(n_new, np.inf)
    np.minimum.at(first, new[m], fill_old[old[m]])
    return sim.remap(net, np.clip(sat, 0.0, 1.0), invasion_time=np.where(np.isfinite(first), first, np.nan))
