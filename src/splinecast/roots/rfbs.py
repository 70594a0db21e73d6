"""First root by de Casteljau isolation, then alternating regula falsi and bisection ("aRFBS").

Steinberger 2010 (section 3.3: the fastest root finder on average), made exact about *first*:

1. **Isolation.** While the control points on the current interval ``[lo, hi]`` have more than
   one sign change (or end in an exact zero after a sign change), split by de Casteljau halfway
   between the polygon's first crossing and its second one (or the interval's end); keep the left
   piece if it can hold a root, else the right one, else go on with ``[hi, 1]`` of the input.
   Exactly one sign change of the control points means exactly one simple root (variation
   diminishing), with opposite signs at the interval's ends: a bracket.
2. **Refinement.** Regula falsi on odd steps and bisection on even steps inside the bracket, the
   polynomial evaluated with the scaled Bernstein Horner scheme; bisection every second step
   halves the bracket at least every two steps, regula falsi gives the speed on smooth profiles.

``iterations`` bounds each phase separately. The result is the final bracket's regula falsi point;
it stops early when the bracket is narrower than ``tol`` or the polynomial is exactly 0.

Degenerate cases are those of :mod:`splinecast.roots.subdivision` ("zero" meaning within the
rounding level ``8 eps max |b_i|``): a zero at the start of the current interval is returned, a
lone zero at ``s = 1`` is returned, the identically zero polynomial gives 0. A double root keeps
two sign changes in the control polygon until rounding separates it; if the isolation budget runs
out first, the refinement runs on the first crossing of the polygon and returns a point of the
double root's rounding neighbourhood if the signs at the bracket ends differ, otherwise the
polygon's first crossing (a documented false hit of an exhausted budget).
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import jit
from .bernstein import bernstein_eval, restrict_right, sign_changes, split, zero_tolerance

__all__ = ["rfbs_first_root", "rfbs_first_root_work", "RFBS_ITERATIONS"]

#: Default budget per phase; the refinement halves the bracket at least every two steps.
RFBS_ITERATIONS = 96


@jit(inline="always")
def _crossings(c: np.ndarray, n: int, ztol: float) -> tuple[float, float]:
    """Fractions where the control polygon first and second crosses zero (1.0 if absent)."""
    first = 1.0
    last = 0.0
    found = 0
    for i in range(n + 1):
        v = c[i]
        if abs(v) <= ztol:
            continue
        if last != 0.0 and (v < 0.0) != (last < 0.0):
            # The crossing lies between the previous non-zero point (index j) and i.
            j = i - 1
            while abs(c[j]) <= ztol:
                j -= 1
            pos = (j + (i - j) * c[j] / (c[j] - v)) / n
            if found == 0:
                first = pos
            else:
                return first, pos
            found += 1
        last = v
    return first, 1.0


@jit()
def rfbs_first_root_work(
    b: np.ndarray, n: int, iterations: int, tol: float, cur: np.ndarray, other: np.ndarray
) -> float:
    """First root in ``[0, 1]`` of the control points ``b`` (degree ``n``); NaN if none.

    ``cur`` and ``other`` are scratch arrays of at least ``n + 1`` floats.
    """
    for i in range(n + 1):
        cur[i] = b[i]
    ztol = zero_tolerance(b, n)
    lo = 0.0
    hi = 1.0
    isolated = False
    for _ in range(iterations):
        if abs(cur[0]) <= ztol:
            return lo
        changes = sign_changes(cur, n, ztol)
        if changes == 0:
            if abs(cur[n]) <= ztol:
                return hi
            if hi >= 1.0:
                return math.nan
            lo = hi
            hi = 1.0
            for i in range(n + 1):
                cur[i] = b[i]
            restrict_right(cur, n, lo)
            continue
        if changes == 1 and abs(cur[n]) > ztol:
            isolated = True
            break
        first, second = _crossings(cur, n, ztol)
        x = 0.5 * (first + second)
        mid = lo + x * (hi - lo)
        if not lo < mid < hi:
            isolated = True  # the interval cannot be split further in float64
            break
        split(cur, n, x, other)
        if abs(other[0]) <= ztol:
            return lo
        if sign_changes(other, n, ztol) > 0 or abs(other[n]) <= ztol:
            cur, other = other, cur
            hi = mid
        else:
            lo = mid
    if not isolated:
        # Isolation budget spent: refine on the polygon's first crossing if it brackets a root.
        if abs(cur[0]) <= ztol:
            return lo
        if sign_changes(cur, n, ztol) == 0:
            return hi if abs(cur[n]) <= ztol else math.nan
    fa = cur[0]
    fb = cur[n]
    if abs(fb) <= ztol or (fa < 0.0) == (fb < 0.0):
        # No end-to-end sign change (only reachable with an exhausted isolation budget): the
        # first polygon crossing is the best estimate the budget allows.
        first, _ = _crossings(cur, n, ztol)
        return lo + first * (hi - lo)
    a = lo
    c_b = hi
    for it in range(iterations):
        if c_b - a <= tol:
            break
        if it % 2 == 0:
            c = (a * fb - c_b * fa) / (fb - fa)
            if not a < c < c_b:
                c = 0.5 * (a + c_b)
        else:
            c = 0.5 * (a + c_b)
        fc = bernstein_eval(b, n, c)
        if fc == 0.0:
            return c
        if (fc < 0.0) == (fa < 0.0):
            a, fa = c, fc
        else:
            c_b, fb = c, fc
    c = (a * fb - c_b * fa) / (fb - fa)
    if not a <= c <= c_b:
        c = 0.5 * (a + c_b)
    return c


@jit()
def rfbs_first_root(b: np.ndarray, iterations: int = RFBS_ITERATIONS, tol: float = 1e-12) -> float:
    """First root in ``[0, 1]`` of a polynomial in Bernstein form (isolation + RF/bisection).

    Parameters
    ----------
    b : ndarray of float64
        Control points (degree ``len(b) - 1``).
    iterations : int
        Budget of each phase (isolating subdivisions; refinement steps).
    tol : float
        Bracket width at which the refinement stops.

    Returns
    -------
    float
        The first root, or NaN.
    """
    n = b.shape[0] - 1
    cur = np.empty(n + 1)
    other = np.empty(n + 1)
    return rfbs_first_root_work(b.astype(np.float64), n, iterations, tol, cur, other)
