"""The software prefetch intrinsic: it compiles for arrays of any rank and element type, emits
a prefetch instruction, and leaves the values a loop computes unchanged."""

from __future__ import annotations

import numba
import numpy as np
import pytest

from splinecast._jit.prefetch import prefetch


@numba.njit
def _sum_with_prefetch3(a):
    total = 0.0
    n0, n1, n2 = a.shape
    for i in range(n0):
        for j in range(n1):
            for k in range(n2):
                # The element one row on, clamped into the array, as the callers clamp.
                prefetch(a, (np.uint64(min(i + 1, n0 - 1)), np.uint64(j), np.uint64(k)))
                total += a[i, j, k]
    return total


@numba.njit
def _sum_with_prefetch4(a):
    total = 0.0
    for i in range(a.shape[1]):
        prefetch(a, (0, i, min(i + 1, a.shape[2] - 1), 0))
        total += a[0, i, i, 3]
    return total


@pytest.mark.parametrize("dtype", [np.float32, np.float64, np.uint8, np.uint16])
def test_prefetch_leaves_values_unchanged(dtype):
    rng = np.random.default_rng(3)
    a = rng.integers(0, 200, size=(7, 5, 9)).astype(dtype)
    assert _sum_with_prefetch3(a) == pytest.approx(float(a.astype(np.float64).sum()), rel=1e-12)
    t = rng.uniform(0.0, 1.0, size=(1, 6, 6, 4))
    assert _sum_with_prefetch4(t) == pytest.approx(float(np.trace(t[0, :, :, 3])), rel=1e-12)


def test_prefetch_emits_a_prefetch_instruction():
    a = np.zeros((2, 2, 2))
    _sum_with_prefetch3(a)
    asm = _sum_with_prefetch3.inspect_asm(_sum_with_prefetch3.signatures[0])
    assert "prefetch" in asm


def test_prefetch_refuses_a_wrong_index():
    @numba.njit
    def wrong_rank(a):
        prefetch(a, (0, 0))

    with pytest.raises(numba.core.errors.TypingError):
        wrong_rank(np.zeros((2, 2, 2)))
