"""Cost of Numba's reference counting when an inlined hook receives a tuple of arrays (issue 9).

A loop calls an ``inline="always"`` function that takes a named tuple of ten arrays, as the
render driver's loop calls the model and mode hooks with the grid and scratch tuples. Numba
increments and decrements the count of every array of the tuple at each such call unless its
refcount pruning removes the pair, which it does only when the inlined body is straight-line
code. The same loops compiled with ``_nrt=False`` (no reference counting, as the driver's band
now is) show what the work itself costs.

    python benchmarks/bench_refcount_hooks.py
"""

from __future__ import annotations

import re
import time
from collections import namedtuple

import numpy as np
from numba import njit

G = namedtuple("G", list("abcdefghij"))


@njit(inline="always", error_model="numpy")
def straight(g, i):
    return g.a[i] + g.b[i]


@njit(inline="always", error_model="numpy")
def one_branch(g, i):
    if i > 1:
        r = g.a[i]
    else:
        r = g.c[i]
    return r


@njit(inline="always", error_model="numpy")
def loop_and_returns(g, i):
    if i > 2:
        return g.a[i]
    for q in range(i):
        if g.b[q] > 5:
            return 1.0
    return g.c[i]


def _loop(hook, nrt):
    @njit(error_model="numpy", _nrt=nrt)
    def run(g, n):
        acc = 0.0
        for i in range(n):
            acc += hook(g, i % 3)
        return acc
    return run


def main() -> None:
    g = G(*[np.ones(3) for _ in range(10)])
    n = 10_000_000
    print("| hook body | reference counting | ns per call | NRT_incref calls in IR |")
    print("|---|---|---|---|")
    for name, hook in (("straight", straight), ("one if/else", one_branch),
                       ("loop and returns", loop_and_returns)):
        for nrt in (True, False):
            run = _loop(hook, nrt)
            run(g, 10)
            best = min(_timed(run, g, n) for _ in range(3))
            ir = run.inspect_llvm(run.signatures[0])
            incs = len(re.findall(r"call void @NRT_incref", ir))
            print(f"| {name} | {'on' if nrt else 'off (_nrt=False)'} | {best * 1e9 / n:.1f} | "
                  f"{incs} |")


def _timed(run, g, n) -> float:
    start = time.process_time()
    run(g, n)
    return time.process_time() - start


if __name__ == "__main__":
    main()
