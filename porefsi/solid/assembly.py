"""Fast P1 assembly (numba) of the total-Lagrangian residual and tangent into a fixed CSR pattern.

The node graph of the mesh fixes the sparsity once; every later assembly writes straight into
the CSR ``data`` array (no COO triplets, no sorting). Checked equal to :mod:`porefsi.solid.forms`.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from porefsi.errors import InputError, MeshError
from porefsi.solid import _kernels
from porefsi.solid.materials import Material
from porefsi.solid.mesh import SolidMesh

__all__ = ["P1Assembler", "p1_gradients", "submatrix_selector"]


def p1_gradients(mesh: SolidMesh) -> tuple[np.ndarray, np.ndarray]:
    """Shape-function gradients (Ne, 4, 3), 1/m, and volumes (Ne,), m^3, of a P1 mesh."""
    pts = np.ascontiguousarray(mesh.points, dtype=np.float64)
    tets = np.ascontiguousarray(mesh.tets, dtype=np.int64)
    dN = np.empty((len(tets), 4, 3))
    vol = np.empty(len(tets))
    _kernels._p1_gradients(pts, tets, dN, vol)
    return dN, vol


def submatrix_selector(indptr, indices, keep: np.ndarray):
    """Precompute the extraction of ``A[keep][:, keep]`` from a CSR pattern.

    Returns ``(sel, new_indptr, new_indices)``: ``A_sub.data = A.data[sel]``.
    """
    n = len(indptr) - 1
    mask = np.zeros(n, dtype=bool)
    mask[keep] = True
    remap = np.full(n, -1, dtype=np.int64)
    remap[keep] = np.arange(len(keep))
    counts = np.diff(indptr)
    rows = np.repeat(np.arange(n, dtype=np.int32 if n < 2**31 else np.int64), counts)
    ok = mask[rows] & mask[indices]
    sel = np.flatnonzero(ok)
    if len(indices) < 2**31:
        sel = sel.astype(np.int32)
    row_counts = np.bincount(rows[sel], minlength=n)[keep]
    new_indptr = np.concatenate([[0], np.cumsum(row_counts)]).astype(indices.dtype)
    new_indices = remap[indices[sel]].astype(indices.dtype)
    return sel, new_indptr, new_indices


class P1Assembler:
    r"""Residual and tangent of a P1 mesh and a material, assembled by a numba kernel.

    Parameters
    ----------
    mesh : SolidMesh
    material : Material

    Notes
    -----
    Dofs are interleaved (``3 n + c``), as in scikit-fem's vector basis. For each element the
    kernel forms :math:`F = I + \sum_a u_a \otimes \nabla N_a`, the stress P and moduli A, and adds
    :math:`V_e P \nabla N_a` and :math:`V_e \nabla N_a \cdot A \cdot \nabla N_b`.
    """

    def __init__(self, mesh: SolidMesh, material: Material):
        if material.kind not in (_kernels.SVK, _kernels.NEO_HOOKEAN):
            raise InputError(f"no P1 kernel for material {material!r}")
        self.mesh, self.material = mesh, material
        self.tets = np.ascontiguousarray(mesh.tets, dtype=np.int64)
        self.dN, self.vol = p1_gradients(mesh)
        nn = mesh.n_nodes
        self.n_dofs = 3 * nn
        key = (self.tets[:, :, None] * nn + self.tets[:, None, :]).reshape(-1)  # (e, a, b) -> (t[e,a], t[e,b])
        uniq, inv = np.unique(key, return_inverse=True)
        del key
        nrow, ncol = uniq // nn, uniq % nn
        del uniq
        nptr = np.searchsorted(nrow, np.arange(nn + 1)).astype(np.int64)
        deg = np.diff(nptr)
        self.nptr, self.deg = nptr, deg
        self.pos = (inv.reshape(-1, 4, 4) - nptr[self.tets][:, :, None]).astype(np.int32)
        del inv
        nb = len(nrow)
        idx_t = np.int32 if 9 * nb < 2**31 else np.int64
        p_in_row = np.arange(nb) - nptr[nrow]
        start = 9 * nptr[nrow] + 3 * p_in_row  # position of (i=0, k=0) entry of each block
        indices = np.empty(9 * nb, dtype=idx_t)
        for i in range(3):
            for k in range(3):
                indices[start + 3 * i * deg[nrow] + k] = 3 * ncol + k
        self.indices = indices
        row_starts = (9 * nptr[:-1, None] + 3 * np.arange(3)[None, :] * deg[:, None]).reshape(-1)
        self.indptr = np.concatenate([row_starts, [9 * nb]]).astype(idx_t)
        self.nnz = 9 * nb

    def assemble(self, u_nodes: np.ndarray, want_K: bool = True):
        """Internal force (3 Nn,), N, and (optionally) tangent CSR (3 Nn, 3 Nn), N/m, at ``u_nodes``.

        Parameters
        ----------
        u_nodes : ndarray of float, shape (Nn, 3)
            Nodal displacement, m.

        Raises
        ------
        MeshError
            If any element has J = det F <= 0 (inverted); the message names the count.
        """
        u = np.ascontiguousarray(u_nodes, dtype=np.float64)
        if u.shape != (self.mesh.n_nodes, 3):
            raise InputError(f"u_nodes must have shape ({self.mesh.n_nodes}, 3), got {u.shape}")
        fint = np.zeros(self.n_dofs)
        if not want_K and not u.any():  # the reference state is stress-free (every Material): f_int = 0
            return fint, None
        data = np.zeros(self.nnz if want_K else 0)
        m = self.material
        n_bad = _kernels._assemble_p1((self.tets, self.dN, self.vol), u, (int(m.kind), float(m.lam), float(m.mu)),
                                      want_K, fint, (data, self.nptr, self.deg, self.pos))
        if n_bad:
            raise MeshError(
                f"{n_bad} of {len(self.tets)} elements inverted (J <= 0) under the current displacement; "
                "take a smaller load or time step (or more load increments)"
            )
        if not want_K:
            return fint, None
        K = sp.csr_matrix((data, self.indices, self.indptr), shape=(self.n_dofs, self.n_dofs))
        return fint, K
