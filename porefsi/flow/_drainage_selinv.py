r"""Low-rank pressure solves from selected inverse entries (private; solver method ``'selinv'``).

The ``'lowrank'`` solver (:mod:`porefsi.flow._drainage_solver`) updates a factorised base matrix
``A0`` by the Sherman–Morrison–Woodbury identity with *full* columns ``W = A0^-1 E_S`` of the
changed rows ``S``: one dense triangular solve per changed row, and a dense combination of all
cached columns per solve. Measured on the 2x2x2-tiled Berea network at Ca 1e-5 (cProfile, 2026-12-02):
the columns 39 % of the run, the combination 19 %.

Here the same identity is evaluated without full columns. With ``A0 = Pr^T L U Pc^T`` (SuperLU,
diagonal pivots: ``perm_r == perm_c`` on these SPD matrices, not assumed) every entry of the
inverse is a dot product of two *sparse* vectors,

.. math:: (A_0^{-1})_{ij} = h_i \cdot g_j,\qquad g_j = L^{-1} e_{\pi_r(j)},\quad h_i = U^{-T} e_{\pi_c(i)},

whose nonzeros are the elimination-tree ancestors of the node (~1200 of 62 470 on the tiled
Berea). So ``W_SS`` (the capacitance matrix's block) is kept entry by entry as rows join ``S``,
and a solve is

.. math:: x = A_0^{-1}(b - E_S D z),\quad (I + W_{SS} D) z = (A_0^{-1} b)_S,\quad
          (A_0^{-1} b)_S = h_S \cdot (L^{-1} P_r b),

i.e. one forward solve, ``|S|`` sparse dots, a dense ``|S| x |S|`` LU, ``|S|`` sparse updates of
the forward vector and one backward solve: about one base solve per pressure solve, whatever
``|S|``. The answer is the Woodbury answer of the ``'lowrank'`` solver to round-off (the same
base and the same ``S``), checked by its residual and refined by the caller.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from porefsi._numba import jit

__all__ = ["SelectedInverse", "forward_unit_lower", "backward_upper", "forward_upper_transposed"]


@jit
def forward_unit_lower(Lp, Li, Lx, y, start, end):
    """Eliminate columns ``start..end-1`` of ``L y = y`` in place (``L`` unit lower triangular, CSC).

    ``y`` is zero below ``start``; with ``end = n`` this solves ``L y := y``, with ``end < n`` the
    trailing block is left to a dense solve. Columns with a zero entry are skipped, so a sparse
    right-hand side costs the work of its elimination-tree ancestors only.
    """
    for j in range(start, end):
        yj = y[j]
        if yj != 0.0:
            for p in range(Lp[j], Lp[j + 1]):
                i = Li[p]
                if i > j:
                    y[i] -= Lx[p] * yj


@jit
def backward_upper(Rp, Ri, Rx, Ud, y, j0):
    """Solve ``U w = y`` in place (``U`` upper triangular by rows, CSR, diagonal ``Ud``) above a solved trailing block.

    ``Rp, Ri, Rx`` hold the entries strictly above the diagonal. ``y[j0:]`` already holds the
    solution of the trailing block (``j0 = n``: no block). Row form:
    row ``j`` of ``U`` reads the solution at ``j``'s elimination-tree ancestors, which stay in
    cache (the column form scatters into descendants all over ``y``: 2.7x slower, measured).
    """
    for j in range(j0 - 1, -1, -1):
        a0 = 0.0  # two partial sums: half the latency of one add chain (the order is fixed: deterministic)
        a1 = 0.0
        p = Rp[j]
        end = Rp[j + 1]
        while p + 1 < end:
            a0 += Rx[p] * y[Ri[p]]
            a1 += Rx[p + 1] * y[Ri[p + 1]]
            p += 2
        if p < end:
            a0 += Rx[p] * y[Ri[p]]
        y[j] = (y[j] - (a0 + a1)) / Ud[j]


@jit
def forward_upper_transposed(Rp, Ri, Rx, Ud, y, start, end):
    """Rows ``start..end-1`` of ``U^T h = y`` in place (``U`` by rows, CSR, strictly upper; diagonal ``Ud``).

    ``y`` is zero below ``start``; ``end = n`` solves the whole system (sparse-aware, as
    :func:`forward_unit_lower`).
    """
    for j in range(start, end):
        if y[j] != 0.0:
            hj = y[j] / Ud[j]
            y[j] = hj
            for p in range(Rp[j], Rp[j + 1]):
                k = Ri[p]
                if k > j:
                    y[k] -= Rx[p] * hj


@jit
def _dots(work, ptr, idx, val, slots, out):
    """``out[k] = sum(val * work[idx])`` over the entries of sparse vector ``slots[k]`` of a pool."""
    for k in range(slots.shape[0]):
        t = slots[k]
        acc = 0.0
        for p in range(ptr[t], ptr[t + 1]):
            acc += val[p] * work[idx[p]]
        out[k] = acc


@jit
def _subtract(y, ptr, idx, val, slots, coef):
    """``y -= sum_k coef[k] * v_{slots[k]}`` for sparse vectors ``v`` of a pool."""
    for k in range(slots.shape[0]):
        t = slots[k]
        c = coef[k]
        if c != 0.0:
            for p in range(ptr[t], ptr[t + 1]):
                y[idx[p]] -= c * val[p]


@jit
def _take_nonzeros(y, start, end):
    """Indices and values of the nonzeros of ``y[start:end]`` (ascending), which are zeroed in ``y``."""
    m = 0
    for i in range(start, end):
        if y[i] != 0.0:
            m += 1
    idx = np.empty(m, dtype=np.int32)
    val = np.empty(m)
    m = 0
    for i in range(start, end):
        if y[i] != 0.0:
            idx[m] = i
            val[m] = y[i]
            y[i] = 0.0
            m += 1
    return idx, val


@jit
def _changed_rows(data, base, rows):
    """Positions where ``data != base`` and the distinct rows holding them (``rows`` nondecreasing: CSR order)."""
    m = 0
    for p in range(data.shape[0]):
        if data[p] != base[p]:
            m += 1
    nz = np.empty(m, dtype=np.int64)
    S = np.empty(m, dtype=np.int64)
    m = 0
    k = 0
    for p in range(data.shape[0]):
        if data[p] != base[p]:
            nz[m] = p
            m += 1
            r = rows[p]
            if k == 0 or S[k - 1] != r:
                S[k] = r
                k += 1
    return nz, S[:k]


@jit
def _capacitance_matrix(W, cS, Dp, Di, Dx):
    """``I + W_SS D`` with ``W_SS = W[cS][:, cS]`` and ``D`` sparse (CSR ``Dp, Di, Dx``), shape (m, m).

    Sums in the order of SciPy's ``(D.T @ W_SS.T).T`` (rows of ``D`` ascending, each row's entries
    in stored order), so the matrix is the same to the last bit.
    """
    m = cS.shape[0]
    WT = np.empty((m, m))  # WT[j, c] = W_SS[c, j]: the inner loop below reads rows
    for c in range(m):
        for j in range(m):
            WT[j, c] = W[cS[c], cS[j]]
    Y = np.zeros((m, m))  # Y[i, c] = sum_j D[j, i] W_SS[c, j]
    for j in range(m):
        for p in range(Dp[j], Dp[j + 1]):
            i = Di[p]
            v = Dx[p]
            for c in range(m):
                Y[i, c] += v * WT[j, c]
    M = np.empty((m, m))
    for c in range(m):
        for i in range(m):
            M[c, i] = Y[i, c] + (1.0 if c == i else 0.0)
    return M


#: Least density of the trailing block of the factors kept dense (see :meth:`SelectedInverse._split_block`).
_BLOCK_DENSITY = 0.9


class _Pool:
    """Sparse vectors appended one by one (CSR-like ``ptr``, ``idx``, ``val``, growing by doubling)."""

    def __init__(self, n_vec: int):
        self.ptr = np.zeros(n_vec + 1, dtype=np.int64)
        self.idx = np.empty(1024, dtype=np.int32)
        self.val = np.empty(1024)
        self.k = 0

    def append(self, idx: np.ndarray, val: np.ndarray) -> None:
        end = self.ptr[self.k] + idx.size
        if end > self.idx.size:
            size = max(2 * self.idx.size, int(end))
            self.idx = np.resize(self.idx, size)
            self.val = np.resize(self.val, size)
        self.idx[self.ptr[self.k]:end] = idx
        self.val[self.ptr[self.k]:end] = val
        self.k += 1
        self.ptr[self.k] = end


class SelectedInverse:
    """A factorised base ``A0`` (scaled) with the entries ``(A0^-1)_ij`` among the nodes added so far.

    Parameters
    ----------
    lu : scipy.sparse.linalg.SuperLU
        Factor of the scaled base matrix (``Pr A0 Pc = L U``), shape (n, n).
    cap : int
        Most nodes whose vectors are kept (the caller refactorises before exceeding it).
    """

    def __init__(self, lu, cap: int):
        L = sp.csc_array(lu.L)
        U = sp.csc_array(lu.U)
        R = U.tocsr()
        n = L.shape[0]
        self.n = n
        self.lu = lu
        # 32-bit row/column indices (pointers stay 64-bit): the solves stream the factors from
        # memory, and 4-byte indices cut the bytes read per entry from 16 to 12
        self.Lp, self.Li, self.Lx = L.indptr.astype(np.int64), L.indices.astype(np.int32), L.data
        self.Up, self.Ui, self.Ux = U.indptr.astype(np.int64), U.indices.astype(np.int32), U.data
        R = sp.csr_array(sp.triu(R, k=1))  # strictly above the diagonal (the diagonal is Ud)
        R.sort_indices()
        self.Rp, self.Ri, self.Rx = R.indptr.astype(np.int64), R.indices.astype(np.int32), R.data
        self.Ud = U.diagonal()
        self.pr = np.asarray(lu.perm_r, dtype=np.int64)
        self.pc = np.asarray(lu.perm_c, dtype=np.int64)
        self.slot_of = np.full(n, -1, dtype=np.int64)
        self.nodes = np.empty(cap, dtype=np.int64)
        self.W = np.empty((cap, cap))  # W[slot_i, slot_j] = (A0^-1)_{node_i, node_j}
        self.g = _Pool(cap)
        self.h = _Pool(cap)
        self.k = 0
        self.batches: list[np.ndarray] = []  # the nodes added, batch by batch (a restored base repeats them)
        self.work = np.zeros(n)
        self.work_loc = np.full(n, -1, dtype=np.int64)  # position in S of a node (-1: not in S), between uses
        self._split_block(L, U)
        self.L3 = (self.Lp, self.Li, self.Lx)
        self.R4 = (self.Rp, self.Ri, self.Rx, self.Ud)
        self.GT = np.zeros((cap, n - self.j0))  # trailing-block parts of g and h, one row per slot
        self.HT = np.zeros((cap, n - self.j0))

    def _split_block(self, L, U) -> None:
        """The largest trailing block of the factors that is :data:`_BLOCK_DENSITY` full, kept dense.

        On the tiled Berea network the last ~1000 of 62 470 columns (the top separators of the
        minimum-degree ordering) are 94 % full and hold 28 % of the entries of ``L``; dense
        triangular solves do them several times faster than the column loop (a half-full block of
        2060 columns was slower: 34 MB read per solve). ``j0 = n`` (no block) below 64 columns.
        """
        n = self.n
        cnt = np.diff(L.indptr) - 1  # entries below the diagonal per column: all in the block from their column on
        m = np.arange(1, n + 1)
        inside = np.cumsum(cnt[::-1])  # entries of the trailing m x m block, m = 1..n
        dense = np.flatnonzero(inside >= 0.5 * _BLOCK_DENSITY * m * (m - 1))
        mb = int(m[dense[-1]]) if dense.size else 0
        self.j0 = j0 = n - mb if mb >= 64 else n
        self.LTT = L[j0:, j0:].toarray()
        self.UTT = U[j0:, j0:].toarray()

    @property
    def cap(self) -> int:
        return self.nodes.size

    def _sparse(self, y, start, end):
        return _take_nonzeros(y, start, end)

    def add(self, nodes: np.ndarray) -> None:
        """Keep ``g``, ``h`` and the entries of ``A0^-1`` against all kept nodes for the new ones among ``nodes``.

        Each vector is kept in two parts: its entries above the trailing block (sparse, in the
        pools) and its trailing-block part (dense columns of ``GT``, ``HT``), solved for all new
        nodes at once by LAPACK. ``W[i, j] = h_i . g_j`` is the sum of the two parts' products.
        """
        new = np.unique(nodes[self.slot_of[nodes] < 0])  # sorted: the same slots whatever the order asked
        if new.size == 0:
            return
        self.batches.append(new)
        y, j0, n = self.work, self.j0, self.n
        k0 = self.k
        for v in new.tolist():
            k = self.k
            for pool, block, start, kernel, lin in ((self.g, self.GT, int(self.pr[v]), forward_unit_lower, self.L3),
                                                    (self.h, self.HT, int(self.pc[v]), forward_upper_transposed,
                                                     self.R4)):
                y[start] = 1.0
                kernel(*lin, y, start, j0)
                pool.append(*self._sparse(y, start, j0))
                block[k] = y[j0:]
                y[j0:] = 0.0
            self.slot_of[v] = k
            self.nodes[k] = v
            self.k = k + 1
        k1 = self.k
        if j0 < n:
            self.GT[k0:k1] = sla.solve_triangular(self.LTT, self.GT[k0:k1].T, lower=True, unit_diagonal=True,
                                                  check_finite=False).T
            self.HT[k0:k1] = sla.solve_triangular(self.UTT, self.HT[k0:k1].T, trans="T", lower=False,
                                                  check_finite=False).T
        W = self.W
        W[:k1, k0:k1] = self.HT[:k1] @ self.GT[k0:k1].T  # trailing-block parts
        W[k0:k1, :k0] = self.HT[k0:k1] @ self.GT[:k0].T
        slots = np.arange(k1, dtype=np.int64)
        col = np.empty(k1)
        for k in range(k0, k1):  # the sparse parts above the block
            gi, gv = self.g.idx[self.g.ptr[k]:self.g.ptr[k + 1]], self.g.val[self.g.ptr[k]:self.g.ptr[k + 1]]
            y[gi] = gv  # column: W[t, k] += h_t . g_k
            _dots(y, self.h.ptr, self.h.idx, self.h.val, slots, col)
            W[:k1, k] += col
            y[gi] = 0.0
            hi, hv = self.h.idx[self.h.ptr[k]:self.h.ptr[k + 1]], self.h.val[self.h.ptr[k]:self.h.ptr[k + 1]]
            y[hi] = hv  # row: W[k, t] += h_k . g_t (t < k0: the new columns got theirs above)
            _dots(y, self.g.ptr, self.g.idx, self.g.val, slots[:k0], col[:k0])
            W[k, :k0] += col[:k0]
            y[hi] = 0.0

    def solve(self, bs: np.ndarray, S: np.ndarray, D, lu_m) -> np.ndarray:
        """``(A0 + E_S D E_S^T)^-1 bs`` (scaled system) given the LU ``lu_m`` of ``I + W_SS D`` (None: ``S`` empty)."""
        y = np.zeros(self.n)
        y[self.pr] = bs
        start = int(np.argmax(y != 0.0)) if y.any() else self.n
        j0 = self.j0
        forward_unit_lower(self.Lp, self.Li, self.Lx, y, min(start, j0), j0)
        if j0 < self.n:  # the dense trailing block (top separators) by LAPACK
            y[j0:] = sla.solve_triangular(self.LTT, y[j0:], lower=True, unit_diagonal=True, check_finite=False)
        if lu_m is not None:
            cS = self.slot_of[S]
            yS = np.empty(S.size)
            _dots(y, self.h.ptr, self.h.idx, self.h.val, cS, yS)  # (A0^-1 bs)_S: parts above the block
            k = self.k
            yS += (self.HT[:k] @ y[j0:])[cS]  # and in it (all kept rows: contiguous, no gather)
            z = sla.lu_solve(lu_m, yS, check_finite=False)
            c = np.asarray(D @ z, dtype=float)
            _subtract(y, self.g.ptr, self.g.idx, self.g.val, cS, c)
            coef = np.zeros(k)
            coef[cS] = c
            y[j0:] -= coef @ self.GT[:k]
        if j0 < self.n:
            y[j0:] = sla.solve_triangular(self.UTT, y[j0:], lower=False, check_finite=False)
        backward_upper(self.Rp, self.Ri, self.Rx, self.Ud, y, j0)
        return y[self.pc]

    def capacitance(self, S: np.ndarray, D):
        """LU of ``I + W_SS D`` (``D`` sparse, |S| x |S|), or None for an empty ``S``."""
        if S.size == 0:
            return None
        D = sp.csr_array(D)
        M = _capacitance_matrix(self.W, self.slot_of[S], D.indptr, D.indices, D.data)
        return sla.lu_factor(M, overwrite_a=True, check_finite=False)


def solve(ps, A, b: np.ndarray, lu0=None) -> np.ndarray:
    """``A^-1 b`` for solver ``ps`` (a :class:`~porefsi.flow._drainage_solver.PressureSolver`, method ``'selinv'``).

    The base is refactorised from ``A`` when more than ``ps.max_rank`` rows changed since it was
    made, when the capacitance matrix is singular, or when an update misses the residual target
    after two refinement steps (a fresh base's answer is taken as it is, as in ``'lowrank'``).
    ``lu0``: the factor of ``A`` when already computed (the first base of ``'lowrank_or_split'``).
    """
    fresh = False
    if ps._sel is None and getattr(ps, "_sel_saved", None) is not None:  # unpickled: the same base again
        data, batches = ps._sel_saved
        ps._sel_saved = None
        n_setups, seconds = ps.n_setups, ps.seconds_setup
        _new_base(ps, sp.csr_array((data, A.indices, A.indptr), shape=A.shape))
        ps.n_setups, ps.seconds_setup = n_setups, seconds
        for nodes in batches:  # the same batches: the same arithmetic as the uninterrupted run
            ps._sel.add(nodes)
    if ps._sel is None:
        _new_base(ps, A, lu0)
        fresh = True
    while True:
        got = _update(ps, A, b)
        if got is None:  # too many changed rows, or a singular capacitance matrix
            _new_base(ps, A)
            fresh = True
            continue
        x, ok, n_changed = got
        if ok or fresh or n_changed == 0:
            return x
        _new_base(ps, A)  # an ill-conditioned update: start from a fresh base
        fresh = True


def _new_base(ps, A, lu=None) -> None:
    import time

    from porefsi.flow import _drainage_linalg as la

    t0 = time.perf_counter()
    s = 1.0 / np.sqrt(ps._diagonal(A))
    lu = la.lu(la.scaled(A, s)) if lu is None else lu
    base = SelectedInverse(lu, ps.max_rank + 64)
    base.data, base.s, base.rows = A.data.copy(), s, la.rows(A)
    ps._sel = base
    ps.n_setups += 1
    ps.seconds_setup += time.perf_counter() - t0


def _update(ps, A, b):
    """Woodbury solve from the base with refinement: ``(x, converged, |S|)``, or None to refactorise."""
    base = ps._sel
    s = base.s
    nz, S = _changed_rows(A.data, base.data, base.rows)
    if S.size > ps.max_rank or base.k + np.count_nonzero(base.slot_of[S] < 0) > base.cap:
        return None
    base.add(S)
    loc = base.work_loc  # -1 outside S (restored below)
    loc[S] = np.arange(S.size)
    rr, cc = base.rows[nz], A.indices[nz]
    D = sp.csr_array(((A.data[nz] - base.data[nz]) * s[rr] * s[cc], (loc[rr], loc[cc])), shape=(S.size, S.size))
    loc[S] = -1
    try:
        lu_m = base.capacitance(S, D)
    except (ValueError, np.linalg.LinAlgError):
        return None
    sc = 1.0 / np.sqrt(ps._diagonal(A))  # residuals scaled by the current diagonal, as in 'lowrank'
    bn = float(np.linalg.norm(b * sc))
    if bn == 0.0:
        return np.zeros_like(b), True, S.size
    x = base.solve(b * s, S, D, lu_m) * s
    for _ in range(2):
        r = b - A @ x
        if float(np.linalg.norm(r * sc)) / bn <= ps.rtol:
            return x, True, S.size
        x = x + base.solve(r * s, S, D, lu_m) * s  # refinement: one more forward and backward solve
        ps.iterations += 1
    r = b - A @ x
    return x, float(np.linalg.norm(r * sc)) / bn <= ps.rtol, S.size
