r"""Pressure solves of the drainage model (private): a grounded weighted graph Laplacian, SPD.

Every event changes a few conductances, so the solver reuses work across events:

* ``'lowrank'`` (default above a few hundred unknowns): one sparse LU factorisation of a *base*
  matrix ``A0`` (symmetrically diagonal-scaled, SuperLU with the minimum-degree ordering of
  ``A + A^T``), and for the current matrix ``A = A0 + E_S D E_S^T`` (``S`` the nodes whose rows
  changed since the base, ``D`` the change restricted to them) the Sherman–Morrison–Woodbury
  identity

  .. math:: A^{-1} b = y - W D (I + W_{SS} D)^{-1} y_S,\qquad y = A_0^{-1} b,\quad W = A_0^{-1} E_S,

  with the columns of ``W`` cached per node (one base solve each, computed once per base). When
  ``|S|`` exceeds ``max_rank`` the current matrix becomes the new base. Columns are computed in
  batches (one triangular solve with several right-hand sides costs far less per column than
  single ones: 32-43 ms instead of 82 ms at 100k unknowns); with each batch that is needed anyway
  go the columns of rows the engine expects to change soon (``hint``: the pores being filled and
  the next pores to be invaded, with their neighbours), within a budget of unused slots and the
  slots left free. When to refactorise is decided from the asked-for columns alone, so
  prefetching neither forces nor delays a refactorisation (only the residual-check fallback
  below depends on round-off). Every solve is checked by its residual and refined (up to twice)
  if needed; a residual that stays large triggers a fresh factorisation, so the answer is a
  direct solve's to round-off (a fresh factorisation's own answer is taken as it is: on
  ill-conditioned systems, viscosity ratio 1e-3 at Ca 1e-2, it can stop above ``rtol``, and
  refactorising again would give the same answer). After eight consecutive failed updates the
  solver factorises each matrix directly for the next 64 solves, then tries updates again.
  Right-hand sides with many nonzeros (many active menisci at high Ca) are solved by one base
  solve instead of through cached columns. Batches of 8 or more columns are solved in two
  halves, on two threads when there are two CPUs (the same halves with one CPU, so the answer
  is machine independent). Pickled, the base travels as its recipe (its values and its column
  batches) and is rebuilt identically: a resumed run repeats the uninterrupted one bit for bit.
* ``'direct'``: a fresh sparse LU per solve (cheapest for a few hundred unknowns), refined like
  the low-rank solves when its residual misses ``rtol``.
* ``'amg'``: CG preconditioned by a pyamg smoothed-aggregation hierarchy that is reused across
  events and rebuilt when the iteration count doubles from its value right after the build,
  warm-started from the previous field. ``'jacobi'``: diagonal-scaled CG (tests only).

References
----------
.. [1] Hager, W. W. (1989). Updating the inverse of a matrix. SIAM Review 31, 221-239.
"""

from __future__ import annotations

import threading
import time

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from porefsi.errors import InputError
from porefsi.flow import _drainage_columns as cols
from porefsi.flow import _drainage_linalg as la
from porefsi.flow import _drainage_selinv as selinv

__all__ = ["PressureSolver"]

_METHODS = ("auto", "lowrank", "direct", "amg", "jacobi", "split", "hybrid", "lowrank_or_split", "selinv")
#: Fill of the first LU (entries of L and U per unknown) above which ``'lowrank_or_split'`` solves
#: ``'split'``: measured at the paper rate (adaptive scheme), 10k lattice 232 (low-rank 1.9 CPU s
#: against split 3.3), 400^3 Berea network 33 and 2x2x2-tiled 211 (low-rank ~4.7x the split's
#: progress: 66 CG iterations per split solve), 30k lattice 436 (split 35 s against 154 s), 100k
#: lattice 934 (split).
_SPLIT_FILL = 300.0


#: Consecutive failed low-rank updates after which the solver factorises directly, and for how
#: many solves (then it tries the low-rank path again).
_FAIL_STREAK = 8
_DIRECT_SOLVES = 64
#: Residual target of the split solves, relative to the scaled right-hand side: pressure errors
#: of ~1e-5 Pa on pressures of kPa (measured on 10k lattices; 1e-11 costs ~60 % more iterations).
_SPLIT_RTOL = 1e-9
#: Split solves rebuild their wetting hierarchy once CG needs this many times the iterations
#: of the first solve after the build (the cluster's growth cuts the wetting block).
_SPLIT_STALE = 1.5
#: Right-hand-side nonzeros without a cached column above which ``A0^-1 b`` is one base solve.
_MAX_RHS_COLUMNS = 16


class PressureSolver:
    """Solve ``A x = b`` for a sequence of SPD matrices sharing one sparsity pattern.

    Parameters
    ----------
    n : int
        Number of unknowns.
    method : {'auto', 'lowrank', 'direct', 'amg', 'jacobi'}
        'auto' picks 'direct' up to ``direct_max`` unknowns, else 'lowrank'.
    rtol : float
        Relative residual target (scaled norm) of the iterative and low-rank solves.
    maxiter : int
        CG iteration cap; exceeding it raises :class:`ConvergenceError` with the residual history.
    max_rank : int
        Largest number of changed rows handled by the Woodbury update before refactorising.
    """

    def __init__(self, n: int, method: str = "auto", rtol: float = 1e-11, maxiter: int = 2000,
                 direct_max: int = 400, max_rank: int | None = None):
        if method not in _METHODS:
            raise InputError(f"unknown pressure solver {method!r}; choose one of "
                             f"{', '.join(repr(m) for m in _METHODS)} ('auto': 'direct' up to {direct_max} "
                             "unknowns, else 'lowrank')")
        if method == "auto":
            method = "direct" if n <= direct_max else "lowrank"
        self.method = method
        self.n = int(n)
        self.rtol = rtol
        self.maxiter = maxiter
        self.max_rank = int(max_rank) if max_rank else _default_rank(n)
        self._ml = None
        self._ml_iters = None
        self._base = None
        self.n_solves = 0
        self.n_setups = 0
        self.iterations = 0
        self.seconds_setup = 0.0
        self.prefetch = True
        self.n_columns = 0
        self.n_column_batches = 0
        self.n_prefetched = 0
        self._saved_base = None  # the low-rank base of an unpickled solver, rebuilt at the next solve
        self._fail_streak = 0  # consecutive low-rank updates that missed the residual target
        self._direct_left = 0  # solves left to factorise directly after such a streak
        self.split_rtol = _SPLIT_RTOL  # residual target of the split solves
        self._amg_data = None  # values of the (scaled) matrix the AMG hierarchy was built from
        self._amg_ref = None  # CG iterations of the first solve after the build (rebuild at twice)
        self.fill = None  # 'lowrank_or_split': entries of L + U per unknown of the first factorisation
        self.prefetch_fill = None  # fill of the first base, which decides whether to prefetch
        self._dpos = self._dpos_for = None  # positions of the diagonal in the (fixed) pattern, and its indices
        self._sel = self._sel_saved = None  # method 'selinv': the base (:mod:`_drainage_selinv`), or its recipe

    def __setstate__(self, d):  # solvers pickled before the prefetch counters existed
        d.setdefault("prefetch", True)
        d.setdefault("_fail_streak", 0)
        d.setdefault("_direct_left", 0)
        d.setdefault("_saved_base", None)
        d.setdefault("_amg_data", None)
        d.setdefault("_amg_ref", None)
        d.setdefault("split_rtol", _SPLIT_RTOL)
        d.setdefault("prefetch_fill", -1.0)  # pickled before the rule: prefetch as it was
        d.setdefault("_dpos", None)
        d.setdefault("_dpos_for", None)
        d.setdefault("_sel", None)
        d.setdefault("_sel_saved", None)
        for k in ("n_columns", "n_column_batches", "n_prefetched"):
            d.setdefault(k, 0)
        self.__dict__.update(d)

    def __getstate__(self):
        """Pickle without factorisations (not picklable); the low-rank base is kept as its recipe.

        The base matrix's values and the batches of cached columns are saved, so an unpickled
        solver refactorises the same base and recomputes the same columns in the same batches:
        a resumed run repeats the uninterrupted run's arithmetic exactly (checkpoints).
        """
        d = self.__dict__.copy()
        d["_ml"] = None
        d["_ml_iters"] = None
        d["_dpos"] = d["_dpos_for"] = None
        base = d.pop("_base")
        d["_base"] = None
        if base is not None:
            d["_saved_base"] = {k: base[k] for k in ("data", "batches", "pref", "n_pref")}
        sel = d.pop("_sel", None)
        d["_sel"] = None
        if sel is not None:  # 'selinv': the base's values and its nodes, batch by batch
            d["_sel_saved"] = (sel.data, [b.copy() for b in sel.batches])
        return d

    def _diagonal(self, A):
        """``A.diagonal()`` through cached positions while ``A`` keeps the same index array (the engine's pattern)."""
        key = (A.indices.__array_interface__["data"][0], A.indices.size, A.shape[0])
        cached = getattr(self, "_dpos_for", None)  # (solvers restored from a checkpoint lack it)
        if cached is None or cached[0] != key:
            rows = _rows(A)
            pos = np.flatnonzero(rows == A.indices)
            if pos.size != A.shape[0]:  # a row without a stored diagonal: no shortcut
                return A.diagonal()
            # the index array is held, so its memory cannot be reused by another pattern under the same key
            self._dpos, self._dpos_for = pos[np.argsort(rows[pos], kind="stable")], (key, A.indices)
        return A.data[self._dpos]

    def _restore_base(self, A):
        """Rebuild the base saved by :meth:`__getstate__` (pattern from ``A``); counters unchanged."""
        saved, self._saved_base = self._saved_base, None
        A0 = sp.csr_array((saved["data"], A.indices, A.indptr), shape=A.shape)
        n_setups, seconds = self.n_setups, self.seconds_setup
        self._factor(A0)
        self.n_setups, self.seconds_setup = n_setups, seconds
        base = self._base
        for nodes in saved["batches"]:
            _solve_columns(base, nodes)
        base["pref"][:] = saved["pref"]
        base["n_pref"] = saved["n_pref"]

    def solve(self, A: sp.csr_array, b: np.ndarray, x0: np.ndarray | None = None,
              hint: np.ndarray | None = None, nmask: np.ndarray | None = None, frequent: bool = True) -> np.ndarray:
        """Return x with ``A x = b`` (A symmetric positive definite, CSR with a fixed pattern).

        ``hint`` (a callable returning node indices, called only when a batch of base columns is
        computed anyway) names rows likely to change soon; the low-rank solver computes
        their base columns in the same batched triangular solve as the columns it needs now
        (a batch of k right-hand sides costs far less than k single solves). Hints change the
        cost only, never the answer. ``nmask`` (method ``'split'``, required there) marks the
        non-wetting rows, eliminated directly (:mod:`porefsi.flow._drainage_schur`). Method
        ``'hybrid'`` solves with ``'lowrank'`` when ``frequent`` (solves on consecutive events: its
        cached columns pay off) and with ``'split'`` otherwise (a rare solve after many changes,
        which would cost the low-rank solver a factorisation).
        """
        self.n_solves += 1
        lu0 = self._choose_by_fill(A) if self.method == "lowrank_or_split" else None
        if self.method == "lowrank" or (self.method == "hybrid" and frequent):
            return self._solve_lowrank(A, b, hint, lu0)
        if self.method == "selinv":
            return selinv.solve(self, A, b, lu0)
        d = self._diagonal(A)
        s = 1.0 / np.sqrt(d)
        As = _scaled(A, s)
        bs = b * s
        if self.method == "direct":
            lu = _lu(As)
            y = lu.solve(bs)
            bn = float(np.linalg.norm(bs))
            for _ in range(2):  # refined like the low-rank solves (ill-conditioned systems)
                r = bs - As @ y
                if bn == 0.0 or float(np.linalg.norm(r)) <= self.rtol * bn:
                    break
                y = y + lu.solve(r)
            return y * s
        y0 = np.zeros_like(b) if x0 is None else np.nan_to_num(x0 / s)
        if self.method in ("split", "hybrid"):
            return self._solve_split(As, bs, y0, nmask) * s
        if self.method == "amg":
            if self._ml is None:
                self._setup_amg(As)
            y, hist = _pcg(As, bs, y0, self._ml, self.rtol, self.maxiter)
            it = len(hist) - 1
            if self._amg_ref is None:
                self._amg_ref = max(it, 4)
            elif it > 2 * self._amg_ref:  # the hierarchy went stale: rebuild for next time
                self._ml = None
                self._amg_data = None
                self._amg_ref = None
        else:
            y, hist = _pcg(As, bs, y0, None, self.rtol, self.maxiter)
        self.iterations += len(hist) - 1
        return y * s

    # -- low-rank updated direct solver ------------------------------------------------------
    def _factor(self, A, lu=None):
        """Make ``A`` the low-rank base (``lu``: its scaled factor when already computed)."""
        t0 = time.perf_counter()
        s = 1.0 / np.sqrt(self._diagonal(A))
        lu = _lu(_scaled(A, s)) if lu is None else lu
        if getattr(self, "prefetch_fill", None) is None:  # the first factorisation decides (cost only)
            self.prefetch_fill = float(lu.L.nnz + lu.U.nnz) / A.shape[0]
            self.prefetch = self.prefetch and self.prefetch_fill >= _PREFETCH_FILL
            if self.max_rank == _default_rank(self.n):  # not set by the caller
                self.max_rank = _default_rank(self.n, self.prefetch_fill)
        budget = self.max_rank // 2 if self.prefetch else 0
        cap = self.max_rank + 64 + budget
        # columns A0^-1 e_v are stored as *rows* of WT (cap, n): a combination of a few of them
        # gathers contiguous rows instead of multiplying the whole (n, cap) block
        self._base = dict(data=A.data.copy(), s=s, lu=lu, rows=_rows(A),
                          col_of=np.full(A.shape[0], -1, dtype=np.int64), WT=np.empty((cap, A.shape[0])),
                          ncols=0, n_pref=0, budget=budget, pref=np.zeros(A.shape[0], dtype=bool), batches=[])
        self.n_setups += 1
        self.seconds_setup += time.perf_counter() - t0

    def _needs_new_base(self, T):
        """Whether caching the columns of ``T`` would exceed the slots of asked-for columns.

        Counted without the prefetched-but-unused columns (they have their own ``budget`` of
        slots), so prefetching neither forces nor delays a refactorisation. The ``64`` slots above
        ``max_rank`` in the cache hold the columns of the right-hand side's nonzeros and of rows
        that changed and changed back since the base (counted asked-for, not in ``S``).
        """
        base = self._base
        n_asked = base["ncols"] - base["n_pref"]
        n_new = np.count_nonzero(base["col_of"][T] < 0) + np.count_nonzero(base["pref"][T])
        return n_asked + n_new > base["WT"].shape[0] - base["budget"]

    def _columns(self, nodes, hint=None):
        """Cache ``A0^-1 e_v`` for the given nodes (one batched base solve for the missing ones).

        When some are missing, missing ``hint`` nodes join the same batch. Prefetched columns not
        (yet) asked for occupy at most ``budget`` extra slots of the cache, and never more than the
        slots left free after the columns asked for: the cache cannot overflow. The caller decides
        when to refactorise from the *asked-for* columns alone (:meth:`_needs_new_base`), so the
        sequence of base factorisations, hence every answer, is the same with and without
        prefetching.
        """
        base = self._base
        hit = nodes[base["pref"][nodes]]
        base["pref"][hit] = False
        base["n_pref"] -= hit.size
        new = nodes[base["col_of"][nodes] < 0]
        room = base["budget"] - base["n_pref"]
        if new.size and room > 0 and hint is not None:
            h = np.asarray(hint(), dtype=np.int64)
            extra = np.setdiff1d(h[base["col_of"][h] < 0], new)
            # the asked-for columns always fit (the caller refactorises otherwise); prefetched ones
            # take what remains of the budget *and* of the free slots after them
            fit = base["WT"].shape[0] - base["ncols"] - new.size
            if extra.size and fit > 0:
                extra = extra[:min(room, fit)]
                new = np.concatenate([new, extra])
                base["pref"][extra] = True
                base["n_pref"] += extra.size
                self.n_prefetched += extra.size
        if new.size:
            self.n_columns += new.size
            self.n_column_batches += 1
            _solve_columns(base, new)
        return base["col_of"][nodes]

    def _choose_by_fill(self, A):
        """Method ``'lowrank_or_split'``: factorise ``A`` once and choose by the factor's fill.

        ``'selinv'`` (returning the factor: the first base) when the fill is at most
        :data:`_SPLIT_FILL` entries per unknown, else ``'split'`` (returning None: that
        factorisation is the price of the choice). ``'selinv'`` rather than ``'lowrank'`` since
        2026-12-02 (tiled Berea at Ca 1e-5, the first 194 fills: 15-19 CPU s against 23.5;
        docs/drainage.md).
        """
        t0 = time.perf_counter()
        lu = _lu(_scaled(A, 1.0 / np.sqrt(self._diagonal(A))))
        self.fill = float(lu.L.nnz + lu.U.nnz) / A.shape[0]
        if self.fill <= _SPLIT_FILL:
            self.method = "selinv"
            return lu
        self.method = "split"
        self.n_setups += 1
        self.seconds_setup += time.perf_counter() - t0
        return None

    def _solve_lowrank(self, A, b, hint=None, lu0=None):
        fresh = False  # whether the base was factorised from this very matrix
        if self._base is None and self._saved_base is not None:  # unpickled: the same base again
            self._restore_base(A)
        if self._base is None or self._direct_left > 0:
            # the latter: after a run of failed low-rank updates (each a wasted attempt plus a
            # refactorisation), factorise each matrix directly for a while before trying again
            self._direct_left = max(0, self._direct_left - 1)
            self._factor(A, lu0)
            fresh = True
        for _attempt in range(2):
            status, got = self._lowrank_update(A, b, hint)
            if status != "ok":  # refactorised: too many changed rows, or a singular capacitance matrix
                fresh = fresh or status == "rank"
                continue
            x, upd, n_changed = got
            sc = 1.0 / np.sqrt(self._diagonal(A))
            bn = float(np.linalg.norm(b * sc))
            if bn == 0.0:
                return np.zeros_like(b)
            x, ok = self._refine(A, b, x, upd, sc, bn)
            if ok:
                if not fresh:
                    self._fail_streak = 0
                return x
            if fresh or n_changed == 0:
                # a direct solve of this matrix with two refinement steps: as accurate as a
                # factorisation gets (ill-conditioned systems, e.g. viscosity ratio 1e-3 at Ca 1e-2,
                # stop above rtol here); refactorising would give the same answer again
                return x
            self._fail_streak += 1
            if self._fail_streak >= _FAIL_STREAK:
                self._fail_streak = 0
                self._direct_left = _DIRECT_SOLVES
            self._factor(A)  # ill-conditioned update: start from a fresh base
            fresh = True
        return self._base["lu"].solve(b * self._base["s"]) * self._base["s"]

    def _lowrank_update(self, A, b, hint):
        """``A^-1 b`` from the base by a Woodbury update of the changed rows ``S``.

        Returns ``("ok", (x, update, |S|))``, or ``("rank", None)`` / ``("singular", None)``
        after refactorising the base from ``A`` (too many changed rows or cached columns; a
        singular capacitance matrix).
        """
        base = self._base
        s = base["s"]
        dd = A.data - base["data"]
        nz = np.flatnonzero(dd)
        S = np.unique(base["rows"][nz])
        bz = np.flatnonzero(b)
        # y = A0^-1 b from cached columns when b has few uncached nonzeros (the usual case:
        # inlet and a few menisci), else by one base solve (many active menisci at high Ca:
        # caching their columns would only crowd out the columns of changed rows)
        direct_y = np.count_nonzero(base["col_of"][bz] < 0) > _MAX_RHS_COLUMNS
        T = S if direct_y else np.union1d(S, bz)  # rows whose columns the solution needs
        if S.size > self.max_rank or self._needs_new_base(T):
            self._factor(A)
            return "rank", None
        cT = self._columns(T, hint)
        k = base["ncols"]
        WT = base["WT"][:k]
        # y = A0^-1 (s b) as a combination of cached columns (b is sparse): coefficients on T
        coef = np.zeros(k)
        if not direct_y:
            coef[cT] = (b * s)[T]
        cS = base["col_of"][S]
        loc = np.full(A.shape[0], -1, dtype=np.int64)
        loc[S] = np.arange(S.size)
        rr = base["rows"][nz]
        cc = A.indices[nz]
        # D: the scaled change restricted to S x S (sparse: a few entries per changed row)
        D = sp.csr_array((dd[nz] * s[rr] * s[cc], (loc[rr], loc[cc])), shape=(S.size, S.size))
        lu_m = None
        if S.size:
            WSS_T = WT[np.ix_(cS, S)]  # row j: W[S, cS_j], so this is W_SS^T
            M = np.eye(S.size) + (D.T @ WSS_T).T  # = I + W_SS D with D sparse
            try:
                lu_m = sla.lu_factor(M, check_finite=False)
            except (ValueError, np.linalg.LinAlgError):
                self._factor(A)
                return "singular", None
        upd = (lu_m, S, cS, D, WT)
        if direct_y:
            x = _woodbury(upd, base["lu"].solve(b * s)) * s
        else:
            if lu_m is not None:  # Woodbury correction on the coefficients of the cached columns
                z = sla.lu_solve(lu_m, coef @ WT[:, S], check_finite=False)
                coef[cS] -= D @ z
            x = (coef @ WT) * s
        return "ok", (x, upd, S.size)

    def _refine(self, A, b, x, upd, sc, bn):
        """Up to two refinement steps (one full base solve each); returns (x, converged to ``rtol``)."""
        base = self._base
        for _ in range(2):
            r = b - A @ x
            if float(np.linalg.norm(r * sc)) / bn <= self.rtol:
                return x, True
            x = x + _woodbury(upd, base["lu"].solve(r * base["s"])) * base["s"]  # refinement: one full base solve
            self.iterations += 1
        return x, False

    def _solve_split(self, As, bs, y0, nmask):
        """Non-wetting block direct, wetting block CG with a reused hierarchy (rebuilt when stale)."""
        from porefsi.flow import _drainage_schur as schur

        wm = ~nmask & schur.coupled_rows(As)
        if self._ml is None:
            self._setup_amg(schur.wetting_block(As, wm))
        y, it = schur.split_solve(As, bs, y0, nmask, self._ml, self.split_rtol, self.maxiter)
        self.iterations += it
        if self._amg_ref is None:
            self._amg_ref = max(it, 4)
        elif it > _SPLIT_STALE * self._amg_ref:  # the hierarchy went stale: rebuild for next time
            self._ml = None
            self._amg_data = None
            self._amg_ref = None
        return y

    def _setup_amg(self, As):
        """Build the smoothed-aggregation hierarchy of ``As``, or of the matrix it was built from.

        The hierarchy's recipe (the values of the matrix it was built from, ``_amg_data``) is kept,
        so a solver restored from a checkpoint rebuilds the very same hierarchy; pyamg's spectral
        radius estimate starts from a random vector, drawn here from a fixed seed.

        Why NumPy's global generator and not a local ``Generator``: pyamg 5.4 draws that vector with
        ``np.random.rand`` inside ``approximate_spectral_radius``, which
        ``smoothed_aggregation_solver`` calls on matrices it builds itself (the filtered
        ``D^-1 S`` of the prolongator smoother), with no ``rng``, seed or initial-guess parameter
        to pass through (checked in pyamg/aggregation/smooth.py and pyamg/util/linalg.py). So the
        global state is seeded and restored around the call, under a module lock, so that two
        threads of one process building hierarchies cannot interleave their seed and restore.
        """
        import pyamg

        if self._amg_data is None:
            self._amg_data = As.data.copy()
            self.n_setups += 1
        A0 = sp.csr_array((self._amg_data, As.indices, As.indptr), shape=As.shape)
        with _GLOBAL_RNG_LOCK:
            state = np.random.get_state()
            np.random.seed(0)
            try:
                self._ml = pyamg.smoothed_aggregation_solver(A0, max_coarse=500)
            finally:
                np.random.set_state(state)


def _default_rank(n: int, fill: float | None = None) -> int:
    """Rank cap of the low-rank solver: ``2 sqrt(n)`` (40..600), lowered where the factor is sparse.

    A sparse factor is cheap to refactorise, so fewer cached columns (less dense algebra per
    solve) pay off: the cap is scaled by ``sqrt(fill / 200)`` below 200 entries of L + U per
    unknown. Measured on the 2x2x2-tiled Berea network at Ca 1e-6 (fill 57; CPU s per fill over
    the first ~60 CPU s): cap 500 0.161, 250 0.140, 200 0.142, 100 0.177.
    """
    scale = 1.0 if fill is None else min(1.0, float(np.sqrt(max(fill, 1.0) / 200.0)))
    return int(np.clip(2.0 * np.sqrt(n) * scale, 40, 600))


#: Prefetching base columns (cost only) is kept where the first factor has at least this many
#: entries of L + U per unknown. Batched columns pay off only with dense supernodes: 8 single
#: base solves over one batch of 8, measured 2026-12-02 (thread time): 10k lattice (fill 232)
#: 1.8-2.2, 30k lattice (436) 1.7-2.1, 400^3 Berea network (21) 1.2-1.5, 2x2x2-tiled Berea (57)
#: 1.2-1.3; on the tiled Berea at Ca 1e-6 prefetching cost more than it saved (60 CPU s: 347
#: fills with it, 400 without). A rule on the fill, not a timing, so that every run of the same
#: input computes the same column batches (round-off included).
_PREFETCH_FILL = 100.0


#: Held while pyamg draws from NumPy's global generator (see :meth:`PressureSolver._setup_amg`).
_GLOBAL_RNG_LOCK = threading.Lock()


_lu, _scaled, _rows, _pcg = la.lu, la.scaled, la.rows, la.pcg  # the shared linear algebra (module _drainage_linalg)
_solve_columns, _woodbury = cols.solve_columns, cols.woodbury  # the base columns (module _drainage_columns)
