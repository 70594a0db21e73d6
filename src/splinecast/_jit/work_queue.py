"""Work shared by threads: a counter they take items from, and the threads that run it.

Compiled loops (the renderer's image loops, the acceleration structures' scans over the volume)
run on ordinary threads (:func:`run_on_threads`): each runs the same
compiled function, which takes the next item from a shared counter (:func:`take`) until none is
left. The compiled code releases the GIL, so the threads run at once::

    counter = np.zeros(1, np.int64)
    while True:                 # inside the compiled function
        item = take(counter)
        if item >= n_items:
            break
        ...

Why not Numba's parallel loop: it compiles a second library for the loop's body for every
argument type (a second or two per model, mode and data type, on the first render of each:
about half the compile of a volume's block ranges), and it hands each thread a range of
iterations fixed in advance, so a thread that drew the cheap bands of an image waited at the
end for the other. Taking items as each thread becomes free balances that, and a function
without a parallel loop compiles in a fraction of the time. :func:`run_items` runs such a
function over a number of items.

Numba has no atomic operations on the CPU; :func:`take` is LLVM's ``atomicrmw add``.
"""

from __future__ import annotations

import concurrent.futures
import functools
import threading
from collections.abc import Callable
from typing import TypeVar

import numba
import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic

__all__ = ["take", "run_on_threads", "run_items"]

T = TypeVar("T")

_pool: concurrent.futures.ThreadPoolExecutor | None = None
_pool_lock = threading.Lock()


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
        # published when the threads are joined (:func:`run_on_threads`).
        return builder.atomic_rmw("add", array.data, ir.Constant(ir.IntType(64), 1),
                                  "monotonic")

    return types.int64(counter), codegen


def _shared_pool() -> concurrent.futures.ThreadPoolExecutor:
    global _pool
    with _pool_lock:
        if _pool is None:
            # As many helpers as Numba may use threads, less the caller's own.
            _pool = concurrent.futures.ThreadPoolExecutor(
                max_workers=max(1, numba.config.NUMBA_NUM_THREADS - 1),
                thread_name_prefix="splinecast-trace")
        return _pool


def run_on_threads(work: Callable[[], T], threads: int) -> list[T]:
    """Run ``work`` on ``threads`` threads at once and return each one's result.

    ``work`` is a compiled function that releases the GIL and takes its items from a shared
    counter (:func:`take`); one copy runs on the calling thread, the others on a pool shared by
    every caller. A copy that starts after the items are all taken returns at once, so a busy
    pool only costs time, never a wait on another caller's work: copies still queued when the
    caller's own copy ends are cancelled.

    Parameters
    ----------
    work : callable
        The call to run (no arguments).
    threads : int
        How many copies to run (1: only the caller's).

    Returns
    -------
    list
        The results of the copies that ran, the caller's first.
    """
    if threads <= 1:
        return [work()]
    futures = [_shared_pool().submit(work) for _ in range(threads - 1)]
    try:
        results = [work()]
    finally:
        # Every copy still running must end before the caller reads what they wrote.
        for future in futures:
            future.cancel()
        concurrent.futures.wait(futures)
    results.extend(f.result() for f in futures if not f.cancelled())
    return results


def run_items(kernel: Callable[..., object], n_items: int, *args: object) -> None:
    """Run the compiled ``kernel(*args, counter)`` on as many threads as are useful for
    ``n_items`` items.

    ``kernel`` takes item numbers from ``counter`` (:func:`take`) until it draws one at or past
    its own count of items (which must be ``n_items``) and writes its results into arrays among
    ``args``; each item must write places no other item writes. With no item, it is not called.

    Parameters
    ----------
    kernel : callable
        A compiled function (``nogil``) whose last argument is the counter.
    n_items : int
        How many items there are: at most this many threads run.
    *args
        The kernel's other arguments.
    """
    n_items = int(n_items)
    if n_items <= 0:
        return
    counter = np.zeros(1, np.int64)
    run_on_threads(functools.partial(kernel, *args, counter),
                   max(1, min(numba.get_num_threads(), n_items)))
