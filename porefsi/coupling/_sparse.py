"""Sparse helpers of the pressure -> force operators (private; shared by ``hull`` and ``traction``).

A nodal-force operator ``T`` has shape (3 Nn, m): row ``3 k + d`` is component ``d`` of the force
on node ``k``, column ``j`` one load source (a pore, or a throat) per unit pressure.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["assemble", "column_magnitudes", "throat_mean", "resultants"]


def assemble(rows: list, cols: list, vals: list, shape: tuple[int, int]) -> sp.csr_matrix:
    """CSR matrix of the COO triplets in the lists of arrays ``rows``, ``cols``, ``vals`` (duplicates add)."""
    if rows:
        ij = (np.concatenate(rows), np.concatenate(cols))
        return sp.csr_matrix((np.concatenate(vals), ij), shape=shape)
    return sp.csr_matrix(shape)


def throat_mean(conns: np.ndarray, n_pores: int) -> sp.csr_matrix:
    """``C`` (Nt, Np): row ``t`` takes the mean pressure of throat ``t``'s two pores."""
    n_t = len(conns)
    return sp.csr_matrix((np.full(2 * n_t, 0.5), (np.repeat(np.arange(n_t), 2), np.asarray(conns).ravel())),
                         shape=(n_t, n_pores))


def column_magnitudes(T: sp.spmatrix) -> np.ndarray:
    """``sum_k |(T[3k], T[3k+1], T[3k+2])|`` of every column of a (3 Nn, m) nodal-force operator."""
    sq = sp.csr_matrix(T).multiply(T).tocsr()
    n_nodes = T.shape[0] // 3
    group = sp.csr_matrix((np.ones(3 * n_nodes), (np.repeat(np.arange(n_nodes), 3), np.arange(3 * n_nodes))),
                          shape=(n_nodes, 3 * n_nodes))
    per_node = (group @ sq).tocsr()
    per_node.data = np.sqrt(per_node.data)
    return np.asarray(per_node.sum(axis=0)).ravel()


def resultants(T: sp.spmatrix) -> np.ndarray:
    """Resultant force (m, 3) of every column of a (3 Nn, m) nodal-force operator."""
    op = sp.csc_matrix(T)
    return np.stack([np.asarray(op[k::3].sum(axis=0)).ravel() for k in range(3)], axis=1)
