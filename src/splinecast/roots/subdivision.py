"""First root by Bernstein subdivision at the control polygon's zero crossing (after Lane &
Riesenfeld 1981).

The recommended root finder of Steinberger 2010 (section 3.3), written iteratively with constant
memory. The state is an interval ``[lo, hi]`` of ``[0, 1]`` and the control points of the
polynomial restricted to it; everything left of ``lo`` is proven root-free. One *iteration* is one
de Casteljau subdivision:

1. if the control points have one strict sign, ``[lo, hi]`` has no root: continue with the rest of
   the segment, ``[hi, 1]`` (its control points are recomputed from the input; this backtracking
   is what makes the result the *first* root, where the thesis' version can lose a root once it
   has discarded a right half);
2. otherwise split where the control polygon first crosses zero (a quadratically convergent
   estimate of the first root) and keep the left piece if its polygon still reaches zero, else the
   right piece.

The search stops with the crossing estimate when the interval or the change of the estimate falls
below ``tol`` (converged), or when the iteration budget is spent. Bounds on the result:

* everything before the returned value was proven root-free, so it is never past the first root;
* a budget too small to separate a control polygon from zero can return a *false* hit where the
  polygon crosses but the polynomial does not (Steinberger 2010 notes the same risk).

Degenerate cases, deterministically:

* "zero" means within :func:`~splinecast.roots.bernstein.zero_tolerance` (``8 eps max |b_i|``,
  the rounding level of subdivision);
* a control point zero at the start of the current interval is a root there; in particular
  the identically zero polynomial (a constant equal to the isovalue) has its first root at 0;
* a root at ``s = 1`` with no earlier root is returned as 1;
* a double root (a tangential ray) is reported (to about ``sqrt(eps)``): near it the control
  polygon comes within rounding of zero; a tangency whose minimum exceeds the rounding level is
  rejected.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import jit
from .bernstein import restrict_right, split, zero_tolerance

__all__ = ["subdivision_first_root", "subdivision_first_root_work", "SUBDIVISION_ITERATIONS"]

#: Default iteration budget (subdivisions); convergence to 1e-12 usually takes 4 to 10.
SUBDIVISION_ITERATIONS = 40


@jit(inline="always")
def _first_crossing(c: np.ndarray, n: int, ztol: float) -> int:
    """Index ``m >= 1`` of the first control point that is (within ``ztol`` of) 0 or of the other
    sign than ``c[0]`` (``c[0]`` must be non-zero); -1 if there is none."""
    negative = c[0] < 0.0
    for m in range(1, n + 1):
        v = c[m]
        if abs(v) <= ztol or (v < 0.0) != negative:
            return m
    return -1


@jit(inline="always")
def _crossing_fraction(c: np.ndarray, n: int, m: int) -> float:
    """Where the polygon's segment ``m-1 .. m`` meets zero, as a fraction of the interval."""
    a = c[m - 1]
    return ((m - 1) + a / (a - c[m])) / n


@jit()
def subdivision_first_root_work(
    b: np.ndarray, n: int, iterations: int, tol: float, cur: np.ndarray, other: np.ndarray
) -> float:
    """First root in ``[0, 1]`` of the degree-``n`` polynomial with control points ``b``.

    ``cur`` and ``other`` are scratch arrays of at least ``n + 1`` floats (kernels allocate them
    once per image row). Returns NaN when there is no root (or none was found within the budget).
    """
    for i in range(n + 1):
        cur[i] = b[i]
    ztol = zero_tolerance(b, n)
    lo = 0.0
    hi = 1.0
    estimate = math.nan
    for _ in range(iterations):
        if abs(cur[0]) <= ztol:
            return lo
        m = _first_crossing(cur, n, ztol)
        if m < 0:
            # One strict sign on [lo, hi]: no root there; go on with [hi, 1].
            if hi >= 1.0:
                return math.nan
            lo = hi
            hi = 1.0
            for i in range(n + 1):
                cur[i] = b[i]
            restrict_right(cur, n, lo)
            continue
        if m == n and abs(cur[n]) <= ztol:
            return hi  # all earlier control points share one strict sign: hi is the only root
        x = lo + _crossing_fraction(cur, n, m) * (hi - lo)
        if hi - lo <= tol or abs(x - estimate) <= tol or x <= lo or x >= hi:
            return x
        estimate = x
        split(cur, n, (x - lo) / (hi - lo), other)
        # Keep the left piece [lo, x] if its polygon reaches zero, else the right piece [x, hi].
        if abs(other[0]) <= ztol:
            return lo
        if _first_crossing(other, n, ztol) > 0:
            cur, other = other, cur
            hi = x
        else:
            lo = x
    # Budget spent: the crossing estimate of the current interval, or of [hi, 1] when the
    # current one has just been found empty (NaN if that has no crossing either).
    if abs(cur[0]) <= ztol:
        return lo
    m = _first_crossing(cur, n, ztol)
    if m < 0:
        if hi >= 1.0:
            return math.nan
        lo = hi
        hi = 1.0
        for i in range(n + 1):
            cur[i] = b[i]
        restrict_right(cur, n, lo)
        if abs(cur[0]) <= ztol:
            return lo
        m = _first_crossing(cur, n, ztol)
        if m < 0:
            return math.nan
    return lo + _crossing_fraction(cur, n, m) * (hi - lo)


@jit()
def subdivision_first_root(
    b: np.ndarray, iterations: int = SUBDIVISION_ITERATIONS, tol: float = 1e-12
) -> float:
    """First root in ``[0, 1]`` of a polynomial in Bernstein form, by subdivision.

    Parameters
    ----------
    b : ndarray of float64
        Control points (degree ``len(b) - 1``).
    iterations : int
        Budget of de Casteljau subdivisions (see the module docstring for what a small budget
        gives).
    tol : float
        Convergence tolerance in the parameter ``s``.

    Returns
    -------
    float
        The first root, or NaN.

    Examples
    --------
    >>> import numpy as np
    >>> round(subdivision_first_root(np.array([-1.0, 1.0])), 12)  # f(s) = 2 s - 1
    0.5
    """
    n = b.shape[0] - 1
    cur = np.empty(n + 1)
    other = np.empty(n + 1)
    return subdivision_first_root_work(b.astype(np.float64), n, iterations, tol, cur, other)
