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
    ip = _Invasion(g, trapping)
    if inlet_pores_filled:
        for e in np.flatnonzero(g.is_in_edge):
            x = int(g.b[e])
            if not ip.full[x]:
                ip.invade(x, -1, 0.0)
    else:
        ip.push_edges(np.flatnonzero(g.is_in_edge))
    ip.run(stop_at_breakthrough)
    return ip.result(net)


class _Invasion:
    """Invasion percolation state on a drainage graph: the cluster, trapped pores, the boundary heap."""

    def __init__(self, g, trapping: bool):
        n = g.n
        self.g, self.trapping = g, trapping
        self.full = np.zeros(n, dtype=bool)
        self.trapped = np.zeros(n, dtype=bool)
        self.work = (np.zeros(1, dtype=np.int64), np.zeros(n, dtype=np.int64))  # stamp, mark
        self.seq = np.full(n, -1, dtype=np.int64)
        self.entry = np.full(n, np.nan)
        self.via = np.full(g.n_edges, -1, dtype=np.int64)
        self.heap: list = []
        self.pcs: list = []
        self.sws: list = []
        self.vol_tot = float(g.vol.sum())
        self.stored = 0.0
        self.pc = -np.inf
        self.bt = -1
        self.k = 0

    def push_edges(self, edges):
        for e in edges:
            heapq.heappush(self.heap, (float(self.g.thr[e]), int(e)))

    def invade(self, x: int, e: int, thr: float) -> None:
        """Fill pore ``x`` (entered through edge ``e``, -1: none) at threshold ``thr``; trap what it cuts off."""
        g, full = self.g, self.full
        full[x] = True
        self.seq[x] = self.k
        self.entry[x] = thr
        if e >= 0:
            self.via[e] = self.k
        self.stored += g.vol[x]
        self.pc = max(self.pc, thr)
        self.pcs.append(self.pc)
        self.sws.append(1.0 - self.stored / self.vol_tot)
        self.k += 1
        for p in range(g.indptr[x], g.indptr[x + 1]):
            if not full[g.nbr[p]]:
                heapq.heappush(self.heap, (float(g.thr[g.nbr_edge[p]]), int(g.nbr_edge[p])))
        if self.trapping:
            seeds = g.nbr[g.indptr[x]:g.indptr[x + 1]]
            seeds = seeds[~full[seeds] & ~self.trapped[seeds]]
            if seeds.size:
                kern._trapped_from(seeds.astype(np.int64), (g.indptr, g.nbr, g.is_outlet, g.key),
                                   (full, self.trapped), self.work)

    def run(self, stop_at_breakthrough: bool) -> None:
        """Invade through the cheapest boundary throat until none is left (or at breakthrough)."""
        g, n = self.g, self.g.n
        while self.heap:
            thr, e = heapq.heappop(self.heap)
            a, b = int(g.a[e]), int(g.b[e])
            x = b if (a == n or self.full[a]) else a
            if self.full[x] or self.trapped[x]:
                continue
            self.invade(x, e, thr)
            if self.bt < 0 and g.is_outlet[x]:
                self.bt = self.k - 1
                if stop_at_breakthrough:
                    break

    def result(self, net: Network) -> InvasionResult:
        """The outcome on ``net``'s pores and throats (dropped ones: -1 / NaN / False)."""
        g = self.g
        n_p = net.n_pores
        ps = np.full(n_p, -1, dtype=np.int64)
        ps[g.keep] = self.seq
        pe = np.full(n_p, np.nan)
        pe[g.keep] = self.entry
        ts = np.full(net.n_throats, -1, dtype=np.int64)
        m = g.throat >= 0
        ts[g.throat[m]] = self.via[m]
        tr = np.zeros(n_p, dtype=bool)
        tr[g.keep] = self.trapped
        return InvasionResult(pore_sequence=ps, pore_entry_pressure=pe, throat_sequence=ts, trapped=tr,
                              capillary_pressure=np.asarray(self.pcs), sw=np.asarray(self.sws),
                              breakthrough_step=self.bt)
