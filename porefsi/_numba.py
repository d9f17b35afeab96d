"""The one place numba policy lives.

Kernels are compiled lazily (no eager signatures, so ``import porefsi`` compiles nothing),
cached on disk (``cache=True``) and never use ``fastmath`` (results must match their pure
Python twins to round-off). Setting ``NUMBA_DISABLE_JIT=1`` runs every kernel as plain
Python, which is how the ``nojit`` tox environment measures kernel coverage.
"""

from __future__ import annotations

import numba

__all__ = ["jit", "prange"]

prange = numba.prange


def jit(func=None, *, parallel: bool = False):
    """Compile ``func`` with porefsi's numba policy.

    Parameters
    ----------
    func : callable, optional
        The kernel; when omitted, returns a decorator.
    parallel : bool, default False
        Compile with ``parallel=True`` (use :data:`prange` in the kernel).
    """

    def wrap(f):
        return numba.njit(cache=True, fastmath=False, nogil=True, parallel=parallel)(f)

    return wrap if func is None else wrap(func)
