"""A software prefetch of one array element's cache line, for compiled code.

The fixed-step loop's voxel reads wait on memory whenever a sample reaches voxels not yet in the
core's caches (a volume larger than the second-level cache, a ray across its rows); asking for
those lines a few samples early lets the reads of the samples in between overlap the wait
(:mod:`splinecast.render.sampler`). A prefetch is a hint: it reads nothing into a register,
cannot fault, and an address outside the array is harmless (it is never one here: callers
clamp the indices as the reads do).
"""

from __future__ import annotations

from typing import Any

from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

__all__ = ["prefetch"]


@intrinsic
def prefetch(typingctx: Any, array: Any, index: Any) -> Any:
    """Prefetch ``array[index]`` (``index`` a tuple of one non-negative integer per axis, in
    range) into every level of the cache (``llvm.prefetch``: read, high locality, data)."""
    if not (isinstance(array, types.Array) and isinstance(index, types.BaseTuple)
            and len(index) == array.ndim
            and all(isinstance(t, types.Integer) for t in index)):
        return None

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        arrty, idxty = signature.args
        arr = context.make_array(arrty)(context, builder, args[0])
        values = cgutils.unpack_tuple(builder, args[1], len(idxty))
        index = [context.cast(builder, v, t, types.intp)
                 for v, t in zip(values, idxty, strict=True)]
        ptr = cgutils.get_item_pointer(context, builder, arrty, arr, index, wraparound=False)
        byte_ptr = ir.IntType(8).as_pointer()
        i32 = ir.IntType(32)
        fnty = ir.FunctionType(ir.VoidType(), [byte_ptr, i32, i32, i32])
        fn = cgutils.get_or_insert_function(builder.module, fnty, "llvm.prefetch.p0")
        builder.call(fn, [builder.bitcast(ptr, byte_ptr), i32(0), i32(3), i32(1)])
        return context.get_dummy_value()

    return types.void(array, index), codegen
