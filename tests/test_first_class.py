"""``_jit.call_with_first_class``: a compiled caller takes the function it calls as a value.

The caller is compiled once for every callee of one signature, each call reaches the callee it
was given (the cache of types and entry points is keyed by the callee too), and arguments numba
has no fingerprint for (a typed list, a string) still find their compiled code.
"""

from __future__ import annotations

import numpy as np
from numba.typed import List

from splinecast._jit import call_with_first_class, jit


@jit
def _add(x, values, out, label):
    for i in range(values.shape[0]):
        out[i] = values[i] + x[0][0] + len(label)


@jit
def _scale(x, values, out, label):
    for i in range(values.shape[0]):
        out[i] = values[i] * x[0][0] + len(label)


@jit
def _caller(fn, x, values, out, label):
    fn(x, values, out, label)


def _same_types(kinds: tuple) -> tuple:
    return kinds


def _run(callee, x, values, label: str) -> np.ndarray:
    out = np.empty_like(values)
    call_with_first_class(_caller, callee, _same_types, (x, values, out, label))
    return out


def test_each_call_reaches_its_callee_through_one_compiled_caller():
    x = List()
    x.append(np.array([3.0]))
    values = np.arange(4.0)
    np.testing.assert_array_equal(_run(_add, x, values, "ab"), values + 3.0 + 2)
    np.testing.assert_array_equal(_run(_scale, x, values, "ab"), values * 3.0 + 2)
    np.testing.assert_array_equal(_run(_add, x, values, "abc"), values + 3.0 + 3)
    assert len(_caller.overloads) == 1  # one caller for both callees of the signature
    # Other argument types: a new compile of the caller, and still the right callee.
    ints = np.arange(4, dtype=np.int64)
    np.testing.assert_array_equal(_run(_scale, x, ints, "ab"), ints * 3 + 2)
    assert len(_caller.overloads) == 2
