"""Recycled solutions of one matrix: the start of the next AMG-CG solve (:class:`SolutionSpace`)."""

from __future__ import annotations

import numpy as np

__all__ = ["SolutionSpace"]


class SolutionSpace:
    r"""The span of earlier solutions of :math:`A x = b`, A-orthonormal: a start for the next solve.

    For a right-hand side ``b`` the guess :math:`x_0 = W W^T b` (columns of ``W`` A-orthonormal) is the
    A-orthogonal projection of :math:`A^{-1} b` onto the span, so the initial error is A-orthogonal
    to every stored solution; a ``b`` that combines earlier right-hand sides is solved exactly by it
    (Fischer 1998, projection of successive right-hand sides). A run's modified Newton solves with
    one frozen tangent over all exchange steps, and their loads grow in few patterns.

    Parameters
    ----------
    A : sparse matrix, shape (n, n)
        The SPD matrix of every solve.
    capacity : int
        Most vectors kept (the oldest is dropped first; 0 keeps none).
    """

    def __init__(self, A, capacity: int):
        self.A, self.capacity = A, int(capacity)
        self.W: list[np.ndarray] = []  # A-orthonormal directions
        self.AW: list[np.ndarray] = []  # A @ W

    def guess(self, b: np.ndarray) -> np.ndarray | None:
        """``W W^T b`` (n,), or None while the space is empty."""
        if not self.W:
            return None
        W = np.column_stack(self.W)
        return W @ (W.T @ np.asarray(b, dtype=float))

    def add(self, x: np.ndarray) -> None:
        """Add the direction of solution ``x`` (n,), A-orthogonalised twice (no-op if already in the span)."""
        if self.capacity == 0:
            return
        v = np.array(x, dtype=float)
        xnorm = np.sqrt(abs(v @ (self.A @ v)))
        for _ in range(2):  # classical Gram-Schmidt, repeated: orthogonal to rounding
            for w, aw in zip(self.W, self.AW, strict=True):
                v -= (aw @ v) * w
        Av = self.A @ v
        nv2 = float(v @ Av)
        if not nv2 > (1e-10 * xnorm) ** 2:  # nothing new (or not SPD along v)
            return
        nv = np.sqrt(nv2)
        self.W.append(v / nv)
        self.AW.append(Av / nv)
        if len(self.W) > self.capacity:
            del self.W[0], self.AW[0]
