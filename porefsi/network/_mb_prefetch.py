"""A software prefetch for numba kernels (private): ``_prefetch(a, n)`` hints that ``a.flat[n]`` is needed soon.

The extraction's sequential kernels (ball hierarchy, label flood) are bound by the latency of
reads scattered over arrays of gigabytes; a prefetch issued a few steps ahead overlaps it.
A hint only: it reads nothing into the kernel, so results cannot change. Under
``NUMBA_DISABLE_JIT=1`` it is a no-op Python function.
"""

from __future__ import annotations

import numba
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

__all__ = ["_prefetch"]


def _codegen(context, builder, signature, args):
    aryty = signature.args[0]
    ary = context.make_array(aryty)(context, builder, args[0])
    ptr = builder.gep(ary.data, [args[1]])
    i8p = ir.IntType(8).as_pointer()
    i32 = ir.IntType(32)
    fnty = ir.FunctionType(ir.VoidType(), [i8p, i32, i32, i32])
    fn = cgutils.get_or_insert_function(builder.module, fnty, "llvm.prefetch.p0i8")
    # read (0), high temporal locality (3), data cache (1)
    builder.call(fn, [builder.bitcast(ptr, i8p), ir.Constant(i32, 0), ir.Constant(i32, 3), ir.Constant(i32, 1)])
    return context.get_dummy_value()


@intrinsic
def _prefetch_intrinsic(typingctx, arr, idx):
    """``llvm.prefetch`` of ``arr``'s element ``idx`` in its flat (C-order) buffer; no bounds check needed."""
    if not isinstance(arr, types.Array) or not isinstance(idx, types.Integer):
        return None
    return types.void(arr, idx), _codegen


def _prefetch_python(arr, idx):
    """No-op twin used when numba's compiler is disabled."""


_prefetch = _prefetch_python if numba.config.DISABLE_JIT else _prefetch_intrinsic
