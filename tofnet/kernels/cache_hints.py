"""CPU cache hints the event loops share (a numba ``@intrinsic``: LLVM's prefetch)."""
from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic


@intrinsic
def prefetch(typingctx, array, index):
    """Hint the CPU to fetch ``array[index]`` for writing (``llvm.prefetch``; no bounds check)."""
    if not isinstance(array, types.Array):
        return None

    def codegen(context, builder, signature, args):
        array_type = signature.args[0]
        view = context.make_array(array_type)(context, builder, args[0])
        pointer = cgutils.get_item_pointer(context, builder, array_type, view, [args[1]], wraparound=False)
        byte_pointer = ir.IntType(8).as_pointer()
        i32 = ir.IntType(32)
        fn = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(ir.VoidType(), [byte_pointer, i32, i32, i32]), "llvm.prefetch.p0i8")
        # write, keep in all cache levels, data
        builder.call(fn, [builder.bitcast(pointer, byte_pointer), i32(1), i32(3), i32(1)])
        return context.get_dummy_value()

    return types.void(array, index), codegen


#: Bytes per cache line on the CPUs tofnet runs on (x86-64, most ARM cores).
CACHE_LINE = 64


def line_aligned_full(size: int, value: int, dtype=np.int64) -> np.ndarray:
    """``np.full(size, value, dtype)`` starting on a cache line: numpy's large arrays start 16 bytes past one,
    so state rows of 32 or 64 bytes would straddle two lines in turn."""
    itemsize = np.dtype(dtype).itemsize
    spare = np.full(size + CACHE_LINE // itemsize, value, dtype)
    skip = (-spare.ctypes.data % CACHE_LINE) // itemsize
    return spare[skip:skip + size]
