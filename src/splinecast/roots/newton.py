"""Newton's method from the segment start (power form): the fast baseline.

Starting at ``s = 0`` (where the ray enters the cell), ``s <- s - p(s) / p'(s)`` is iterated with
Horner's scheme for value and derivative. It stops when a step is below ``tol`` or ``p(s) == 0``.
The result is accepted only if it converged and lies in ``[0, 1]`` (a last iterate within ``tol``
outside is clamped onto the end).

This is *not* a first-root method and gives no guarantee: Newton converges to whichever root's
basin holds ``s = 0``, which may lie outside the segment (then the cell is reported empty) or past
an earlier root. It exists as the cheap baseline the other finders are measured against. A double
root is approached linearly (the step halves), so it needs about 45 iterations for ``tol=1e-12``.

Degenerate cases: ``p(0) == 0`` (including the zero polynomial) gives 0; a vanishing derivative
before convergence gives NaN; an exhausted budget gives NaN.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import jit

__all__ = ["newton_root", "newton_root_work", "NEWTON_ITERATIONS"]

#: Default iteration budget.
NEWTON_ITERATIONS = 60


@jit()
def newton_root_work(p: np.ndarray, n: int, iterations: int, tol: float) -> float:
    """Newton root of ``sum_j p_j s^j`` (``j <= n``) from ``s = 0``; NaN unless it converged in
    ``[0, 1]``."""
    if p[0] == 0.0:
        return 0.0
    s = 0.0
    for _ in range(iterations):
        f = p[n]
        df = 0.0
        for j in range(n - 1, -1, -1):
            df = df * s + f
            f = f * s + p[j]
        if f == 0.0:
            break
        if df == 0.0 or not math.isfinite(df):
            return math.nan
        step = f / df
        s -= step
        if abs(step) <= tol:
            break
        if abs(s) > 1e6:
            return math.nan  # diverging
    else:
        return math.nan
    if -tol <= s < 0.0:
        s = 0.0
    elif 1.0 < s <= 1.0 + tol:
        s = 1.0
    if 0.0 <= s <= 1.0:
        return s
    return math.nan


@jit()
def newton_root(p: np.ndarray, iterations: int = NEWTON_ITERATIONS, tol: float = 1e-12) -> float:
    """Newton's method from ``s = 0`` on a polynomial in power form (ascending coefficients).

    Parameters
    ----------
    p : ndarray of float64
        ``p[j]`` multiplies ``s^j``.
    iterations : int
        Maximum number of Newton steps.
    tol : float
        Step size at which the iteration has converged.

    Returns
    -------
    float
        A root in ``[0, 1]`` (not necessarily the first; see the module docstring), or NaN.
    """
    return newton_root_work(p.astype(np.float64), p.shape[0] - 1, iterations, tol)
