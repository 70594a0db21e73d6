"""Numba's IR inlining as splinecast patches it (``splinecast._jit``): the inlined function's
variable scope is copied once per copy of the function, not once per block, and the inlined code
still computes what the Python functions compute."""

from __future__ import annotations

import copy

import numba
import pytest
from numba.core import ir

import splinecast._jit.speedups as sc_speedups


@numba.njit(inline="always")
def _branchy(x):
    # Many blocks (each branch is one) over one scope: the case the patch is for.
    total = 0.0
    for k in range(4):
        if x > k:
            total += x * k
        elif x < -k:
            total -= x
        else:
            total += 1.0
        if total > 100.0:
            total = 100.0
    return total


def _caller(x):
    return _branchy(x) + 2.0 * _branchy(x - 1.5) - _branchy(-x)


@pytest.fixture
def scope_copies(monkeypatch):
    """Count deep copies of IR scopes (default deepcopy behaviour otherwise)."""
    count = [0]

    def counting_deepcopy(self, memo):
        count[0] += 1
        new = ir.Scope.__new__(ir.Scope)
        memo[id(self)] = new
        for name, value in self.__dict__.items():
            setattr(new, name, copy.deepcopy(value, memo))
        return new

    monkeypatch.setattr(ir.Scope, "__deepcopy__", counting_deepcopy, raising=False)
    return count


def test_the_patch_is_installed():
    from numba.core import inline_closurecall

    assert isinstance(inline_closurecall.copy, sc_speedups._CopyModuleSharingScopes)


def test_inlining_copies_each_scope_once_and_computes_the_same(scope_copies):
    blocks = len(numba.core.compiler.run_frontend(_branchy.py_func).blocks)
    assert blocks >= 8  # else the test would not tell the two behaviours apart
    compiled = numba.njit(_caller)
    values = [-3.0, -0.5, 0.0, 0.7, 2.5, 40.0]
    assert [compiled(x) for x in values] == [_python_caller(x) for x in values]
    # Three call sites; numba copies the callee's IR four times per site (two passes, each
    # keeping an unmutated copy): one scope copy per function copy. Unpatched numba copies the
    # scope once per block of each copy (132 here).
    assert 0 < scope_copies[0] <= 3 * 4 < 3 * blocks


def _python_caller(x):
    f = _branchy.py_func
    return f(x) + 2.0 * f(x - 1.5) - f(-x)
