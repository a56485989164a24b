"""``prefetch(array, index)``: a cache prefetch hint (LLVM's ``llvm.prefetch``) for a compiled loop.

Why: the A* kernels pop cells whose state and cost were written long before (when they were
pushed); on a large grid those lines have left the caches, and the loop stalls on them. Hinting
the next entry of the bucket while the current cell expands overlaps that miss with useful work.
A hint only: it never changes what the loop computes.
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic


@intrinsic
def prefetch(typingctx, array, index):
    """Prefetch ``array[index]`` (1-d, no bounds check: ``index`` must be valid) for reading."""
    sig = types.void(array, index)

    def codegen(context, builder, signature, args):
        aryty = signature.args[0]
        ary = context.make_array(aryty)(context, builder, args[0])
        ptr = cgutils.get_item_pointer(context, builder, aryty, ary, [args[1]], wraparound=False)
        i8p = ir.IntType(8).as_pointer()
        i32 = ir.IntType(32)
        fn = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(ir.VoidType(), [i8p, i32, i32, i32]), "llvm.prefetch.p0"
        )
        # read, keep in all cache levels (locality 3), data cache
        builder.call(fn, [builder.bitcast(ptr, i8p), i32(0), i32(3), i32(1)])
        return context.get_dummy_value()

    return sig, codegen
