"""A shared counter that threads take work items from: dynamic scheduling for parallel loops.

Numba's parallel loop hands each thread one contiguous range of iterations fixed in advance.
When the items cost very different amounts (bands of an image where a small object covers a
few of them), a thread that drew the cheap ones waits at the end for the other. With
:func:`take`, a loop over the threads instead lets each take the next item as it becomes free::

    counter = np.zeros(1, np.int64)
    for _ in prange(threads):
        while True:
            item = take(counter)
            if item >= n_items:
                break
            ...

Numba has no atomic operations on the CPU; :func:`take` is LLVM's ``atomicrmw add``.
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.extending import intrinsic

__all__ = ["take"]


@intrinsic
def take(typingctx, counter):
    """Add one to ``counter[0]`` (a one-element int64 array) atomically; return its value
    before the addition."""
    if not (isinstance(counter, types.Array) and counter.dtype == types.int64
            and counter.ndim == 1):
        return None

    def codegen(context, builder, signature, args):
        array = context.make_array(signature.args[0])(context, builder, args[0])
        # Monotonic order: the counter only hands out distinct numbers; the items' data is
        # published by the parallel loop's own barrier.
        return builder.atomic_rmw("add", array.data, ir.Constant(ir.IntType(64), 1),
                                  "monotonic")

    return types.int64(counter), codegen
