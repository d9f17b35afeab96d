"""The augmented graph the drainage model works on (private).

Pores connected to both faces of the flow axis are kept and renumbered ``0..n-1``; node ``n`` is
the virtual inlet (a reservoir of injected non-wetting fluid) and node ``n + 1`` the virtual
outlet (P = 0). Edges are the network's throats between kept pores plus one boundary edge per
inlet pore ``(n, i)`` and per outlet pore ``(i, n + 1)``.

Boundary edges are the boundary conduits of single-phase flow
(:func:`porefsi.network.geometry.boundary_resistance`: from the pore centre to the face, floored at
a quarter of the pore radius so that a centre on the face keeps a finite conductance; a cylinder of
the pore radius in the paper's model, the pore's duct and the face cut's duct in the shape-factor
model). An inlet edge's entry pressure is the pore-body capillary pressure, or with the
shape-factor model and the face cuts' sections (:attr:`Network.has_face_sections`) the larger of
that and the face cut's entry pressure (the non-wetting fluid enters the pore through the section
the face cuts).

Conductances and entry pressures follow the network's conduit model
(:attr:`Network.conduit_model`): with ``"shape_factor"`` the throat entry pressures and pore-body
capillary pressures are the Mayer–Stowe–Princen values of the measured sections
(:meth:`Fluids.entry_pressure`), with ``"paper"`` ``2 sigma cos(theta) / r``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from porefsi.errors import NetworkError
from porefsi.flow.fluids import Fluids
from porefsi.image.voxel_image import axis_index
from porefsi.network.geometry import boundary_resistance, resistance_factors
from porefsi.network.network import Network

__all__ = ["DrainageGraph", "build_graph", "spanning_pores"]


def spanning_pores(net: Network, axis) -> np.ndarray:
    """Boolean mask (Np,) of pores whose connected component touches both faces of ``axis``.

    The search is :meth:`porefsi.network.network.Network.spanning_clusters`.

    Raises
    ------
    NetworkError
        No pores on a face, or no component joins the two faces.
    """
    net.require_inlet_outlet(axis)
    ax = axis_index(axis)
    mask, _, n_spanning = net.spanning_clusters(ax)
    if n_spanning == 0:
        raise NetworkError(
            f"no connected group of pores joins the {'xyz'[ax]}min and {'xyz'[ax]}max faces: the network "
            "does not percolate along this axis; choose another axis or a larger image"
        )
    return mask


@dataclasses.dataclass(frozen=True, eq=False)
class DrainageGraph:
    """Arrays of the augmented graph (see module docstring). All arrays read-only by convention."""

    n: int
    keep: np.ndarray  # (n,) original pore index of each kept pore
    a: np.ndarray  # (E,)
    b: np.ndarray  # (E,)
    throat: np.ndarray  # (E,) original throat index, -1 for boundary edges
    gn: np.ndarray  # (E,) conductance with non-wetting fluid in all segments, m³/(Pa s)
    gw: np.ndarray  # (E,) conductance with wetting fluid in all segments
    thr: np.ndarray  # (E,) entry threshold, Pa
    pcb: np.ndarray  # (n + 2,) pore-body capillary pressure (0 for the virtual nodes), Pa
    vol: np.ndarray  # (n,) pore volumes, m³
    is_outlet: np.ndarray  # (n,) bool
    key: np.ndarray  # (n,) coordinate along the axis (search priority), m
    indptr: np.ndarray  # (n + 1,) pore adjacency over internal edges
    nbr: np.ndarray
    nbr_edge: np.ndarray
    out_res_w: np.ndarray  # (n,) wetting resistance pore -> outlet node (inf if not an outlet pore)
    # fixed CSR pattern of the (n + 1) x (n + 1) pressure matrix
    indices: np.ndarray
    pattern_indptr: np.ndarray
    pos_diag: np.ndarray
    pos_ab: np.ndarray  # (E,) data position of (a, b), -1 for outlet edges
    pos_ba: np.ndarray
    row_of: np.ndarray  # (nnz,) row of every stored entry
    inner: np.ndarray  # (E,) bool: edge has both ends among the unknowns (not an outlet edge)
    is_in_edge: np.ndarray  # (E,) bool

    @property
    def n_edges(self) -> int:
        """Number of augmented edges E."""
        return int(self.a.shape[0])


def build_graph(net: Network, fluids: Fluids, axis, keep: np.ndarray | None = None) -> DrainageGraph:
    """Build the augmented graph of ``net`` for a drainage along ``axis``.

    ``keep`` (original pore indices) fixes the kept pores, e.g. when carrying a state onto a
    deformed copy of the same network; by default, the pores spanning the two faces.
    """
    ax = axis_index(axis)
    if keep is None:
        keep = np.flatnonzero(spanning_pores(net, ax))
    keep = np.asarray(keep, dtype=np.int64)
    n = keep.size
    new_id = np.full(net.n_pores, -1, dtype=np.int64)
    new_id[keep] = np.arange(n)
    c = net.throat_conns
    tmask = (new_id[c[:, 0]] >= 0) & (new_id[c[:, 1]] >= 0)
    tid = np.flatnonzero(tmask)
    h = resistance_factors(net)[tid].sum(axis=1)
    R = net.pore_radius[keep]
    h_lo, h_hi = boundary_resistance(net, ax)  # the boundary conduits of single-phase flow too
    inl = np.flatnonzero(net.inlet(ax)[keep])
    out = np.flatnonzero(net.outlet(ax)[keep])
    h_in = h_lo[keep[inl]]
    h_out = h_hi[keep[out]]
    ai = new_id[c[tid, 0]]
    bi = new_id[c[tid, 1]]
    a = np.concatenate([ai, np.full(inl.size, n), out]).astype(np.int64)
    b = np.concatenate([bi, inl, np.full(out.size, n + 1)]).astype(np.int64)
    throat = np.concatenate([tid, np.full(inl.size + out.size, -1)]).astype(np.int64)
    hs = np.concatenate([h, h_in, h_out])
    pcb = np.zeros(n + 2)
    shaped = net.conduit_model == "shape_factor"
    pcb[:n] = fluids.entry_pressure(R, net.pore_shape_factor[keep] if shaped else None)
    pe_t = fluids.entry_pressure(net.throat_radius[tid], net.throat_shape_factor[tid] if shaped else None)
    pe_int = np.maximum(pe_t, np.maximum(pcb[ai], pcb[bi]))
    pe_in = pcb[inl]
    if shaped and net.has_face_sections:
        p_in, col = keep[inl], 2 * ax
        r_face = np.minimum(net.pore_face_radius[p_in, col], net.pore_radius[p_in])
        pe_in = np.maximum(pe_in, fluids.entry_pressure(r_face, net.pore_face_shape_factor[p_in, col]))
    thr = np.concatenate([pe_int, pe_in, np.full(out.size, np.inf)])
    # adjacency over internal edges
    m = ai.size
    src = np.concatenate([ai, bi])
    dst = np.concatenate([bi, ai])
    eid = np.concatenate([np.arange(m), np.arange(m)])
    order = np.argsort(src, kind="stable")
    indptr = np.concatenate([[0], np.cumsum(np.bincount(src, minlength=n))]).astype(np.int64)
    is_outlet = np.zeros(n, dtype=bool)
    is_outlet[out] = True
    out_res = np.full(n, np.inf)
    out_res[out] = fluids.mu_w * h_out
    # pressure matrix pattern over unknowns 0..n (outlet eliminated)
    inner = b <= n
    rows = np.concatenate([np.arange(n + 1), a[inner], b[inner]])
    cols = np.concatenate([np.arange(n + 1), b[inner], a[inner]])
    perm = np.lexsort((cols, rows))
    pos = np.empty(rows.size, dtype=np.int64)
    pos[perm] = np.arange(rows.size)
    p_indptr = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=n + 1))]).astype(np.int64)
    n_in = int(inner.sum())
    pos_ab = np.full(a.size, -1, dtype=np.int64)
    pos_ba = np.full(a.size, -1, dtype=np.int64)
    pos_ab[inner] = pos[n + 1:n + 1 + n_in]
    pos_ba[inner] = pos[n + 1 + n_in:]
    is_in_edge = np.zeros(a.size, dtype=bool)
    is_in_edge[m:m + inl.size] = True
    return DrainageGraph(
        n=n, keep=keep, a=a, b=b, throat=throat,
        gn=1.0 / (fluids.mu_n * hs), gw=1.0 / (fluids.mu_w * hs), thr=thr, pcb=pcb,
        vol=net.pore_volume[keep].copy(), is_outlet=is_outlet,
        key=net.pore_coords[keep, ax].copy(),
        indptr=indptr, nbr=dst[order].astype(np.int64), nbr_edge=eid[order].astype(np.int64),
        out_res_w=out_res, indices=cols[perm].astype(np.int32), pattern_indptr=p_indptr,
        pos_diag=pos[:n + 1], pos_ab=pos_ab, pos_ba=pos_ba, row_of=rows[perm], inner=inner,
        is_in_edge=is_in_edge,
    )
