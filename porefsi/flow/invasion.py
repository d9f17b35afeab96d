"""Quasi-static drainage: invasion percolation with trapping, and its capillary pressure curve.

The low-capillary-number limit of the dynamic model (:mod:`porefsi.flow.drainage`), on the same
augmented graph and with the same thresholds: the non-wetting cluster grows, one pore at a time,
through the throat of lowest entry pressure ``max(P_e, P_c,b)`` on its boundary; wetting clusters
cut off from the outlet are trapped and never invaded (incompressible wetting fluid).

References
----------
.. [1] Wilkinson, D., Willemsen, J. F. (1983). Invasion percolation: a new form of percolation
   theory. J. Phys. A 16, 3365-3376.
"""

from __future__ import annotations

import dataclasses
import heapq

import numpy as np

from porefsi.flow import _kernels as kern
from porefsi.flow._drainage_graph import build_graph
from porefsi.flow.fluids import PAPER_FLUIDS, Fluids
from porefsi.image.voxel_image import axis_index
from porefsi.network.network import Network

__all__ = ["InvasionResult", "invasion_percolation"]


@dataclasses.dataclass(frozen=True, eq=False)
class InvasionResult:
    """Outcome of :func:`invasion_percolation` (arrays indexed like the network).

    Attributes
    ----------
    pore_sequence : ndarray of int, shape (Np,)
        Invasion rank of each pore (0 first), -1 if never invaded (trapped or dropped).
    pore_entry_pressure : ndarray of float, shape (Np,)
        Threshold pressure at which each pore was entered, Pa (NaN if never).
    throat_sequence : ndarray of int, shape (Nt,)
        Rank of the pore invaded through each throat, -1 for throats no pore was invaded through.
    trapped : ndarray of bool, shape (Np,)
        Pores in wetting clusters cut off from the outlet at the end.
    capillary_pressure : ndarray of float, shape (k,)
        Pc after each invasion step: the running maximum of entry pressures, Pa.
    sw : ndarray of float, shape (k,)
        Wetting saturation of the kept pore space after each step.
    breakthrough_step : int
        Index into the step arrays of the first outlet pore invaded (-1 if none).
    """

    pore_sequence: np.ndarray
    pore_entry_pressure: np.ndarray
    throat_sequence: np.ndarray
    trapped: np.ndarray
    capillary_pressure: np.ndarray
    sw: np.ndarray
    breakthrough_step: int

    def pc_curve(self, stop_at_breakthrough: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Quasi-static drainage curve as (Sw, Pc) arrays, Pa."""
        k = self.breakthrough_step + 1 if (stop_at_breakthrough and self.breakthrough_step >= 0) else None
        return self.sw[:k], self.capillary_pressure[:k]


def invasion_percolation(net: Network, fluids: Fluids = PAPER_FLUIDS, axis="x", trapping: bool = True,
                         stop_at_breakthrough: bool = False, inlet_pores_filled: bool = False) -> InvasionResult:
    """Invasion percolation with (optional) trapping from the low face of ``axis``.

    Parameters
    ----------
    net : Network
    fluids : Fluids
        Sets the thresholds: :meth:`Fluids.entry_pressure` of each throat and pore body under the
        network's conduit model (``2 sigma cos(theta) / r`` for ``"paper"``, Mayer-Stowe-Princen
        for ``"shape_factor"``).
    axis : {'x', 'y', 'z'}
    trapping : bool
        Never invade wetting clusters cut off from the outlet (default True).
    stop_at_breakthrough : bool
        Stop after the first outlet pore is invaded.
    inlet_pores_filled : bool
        Start with every inlet pore invaded (OpenPNM's convention); by default the inlet pores
        are entered from the inlet face at their pore-body capillary pressure, as in the dynamic
        model.

    Returns
    -------
    InvasionResult

    Raises
    ------
    NetworkError
        No inlet or outlet pores on the axis, or no connected path between them.
    """
    g = build_graph(net, fluids, axis_index(axis))
    n = g.n
    full = np.zeros(n, dtype=bool)
    trapped = np.zeros(n, dtype=bool)
    stamp = np.zeros(1, dtype=np.int64)
    mark = np.zeros(n, dtype=np.int64)
    seq = np.full(n, -1, dtype=np.int64)
    entry = np.full(n, np.nan)
    via = np.full(g.n_edges, -1, dtype=np.int64)
    heap: list = []
    in_edges = np.flatnonzero(g.is_in_edge)
    for e in in_edges:
        heapq.heappush(heap, (float(g.thr[e]), int(e)))
    pcs, sws = [], []
    vol_tot = float(g.vol.sum())
    stored = 0.0
    pc = -np.inf
    bt = -1
    k = 0

    def invade(x, e, thr):
        nonlocal stored, pc, k
        full[x] = True
        seq[x] = k
        entry[x] = thr
        if e >= 0:
            via[e] = k
        stored += g.vol[x]
        pc = max(pc, thr)
        pcs.append(pc)
        sws.append(1.0 - stored / vol_tot)
        k += 1
        for p in range(g.indptr[x], g.indptr[x + 1]):
            y = g.nbr[p]
            if not full[y]:
                heapq.heappush(heap, (float(g.thr[g.nbr_edge[p]]), int(g.nbr_edge[p])))
        if trapping:
            seeds = g.nbr[g.indptr[x]:g.indptr[x + 1]]
            seeds = seeds[~full[seeds] & ~trapped[seeds]]
            if seeds.size:
                kern._trapped_from(seeds.astype(np.int64), g.indptr, g.nbr, full, trapped, g.is_outlet, g.key,
                                stamp, mark)

    if inlet_pores_filled:
        heap = []
        for e in in_edges:
            x = int(g.b[e])
            if not full[x]:
                invade(x, -1, 0.0)
    while heap:
        thr, e = heapq.heappop(heap)
        a, b = int(g.a[e]), int(g.b[e])
        x = b if (a == n or full[a]) else a
        if full[x] or trapped[x]:
            continue
        invade(x, e, thr)
        if bt < 0 and g.is_outlet[x]:
            bt = k - 1
            if stop_at_breakthrough:
                break
    n_p = net.n_pores
    ps = np.full(n_p, -1, dtype=np.int64)
    ps[g.keep] = seq
    pe = np.full(n_p, np.nan)
    pe[g.keep] = entry
    ts = np.full(net.n_throats, -1, dtype=np.int64)
    m = g.throat >= 0
    ts[g.throat[m]] = via[m]
    tr = np.zeros(n_p, dtype=bool)
    tr[g.keep] = trapped
    return InvasionResult(pore_sequence=ps, pore_entry_pressure=pe, throat_sequence=ts, trapped=tr,
                          capillary_pressure=np.asarray(pcs), sw=np.asarray(sws), breakthrough_step=bt)
