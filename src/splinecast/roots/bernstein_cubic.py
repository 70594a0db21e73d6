"""First roots on [0, 1] of quadratics and cubics given by Bernstein coefficients.

These serve the type-6 splines, whose ray restrictions come out of blossoming directly in
Bernstein form ``sum_k b_k C(d, k) s^k (1 - s)^(d - k)``.

* :func:`bernstein_quadratic_first_root` -- closed form (the cancellation-free quadratic formula
  on the power form).
* :func:`bernstein_cubic_first_root` -- guaranteed first root by Bernstein subdivision: intervals
  are visited left to right; one whose control polygon has no sign change holds no root (convex
  hull property) and is dropped, one with exactly one sign change holds exactly one root (Descartes'
  rule for Bernstein polynomials), which Newton's iteration on the power form refines from the
  secant point, kept inside the interval (:func:`.cubic.refine_bracketed`), anything else is
  halved. The walk over the dyadic intervals needs no stack: an interval's coefficients are
  recomputed from the original ones by blossoming, which for a cubic costs a dozen operations.
* :func:`newton_cubic_first_root` -- the references' method: Newton's iteration from three starts
  (0, 1/2, 1), the smallest converged root in [0, 1]. Fast but not guaranteed (it can miss a
  root, or find the second one); kept for comparison.

Conventions: a coefficient exactly zero at the start of an interval is a root there; a tangential
touch (double root without a sign change) is reported when subdivision narrows it to 2^-48.
"""

from __future__ import annotations

import math

from .._jit import jit
from .cubic import quadratic_roots, refine_bracketed

__all__ = [
    "bernstein_quadratic_first_root",
    "bernstein_cubic_first_root",
    "newton_cubic_first_root",
    "bernstein3_value",
]

_MAX_LEVEL = 48
_EDGE_TOLERANCE = 1e-12


@jit(inline="always")
def bernstein3_value(b0: float, b1: float, b2: float, b3: float, s: float) -> float:
    """Value of the cubic with Bernstein coefficients ``b0..b3`` at ``s`` (de Casteljau)."""
    r = 1.0 - s
    p0 = r * b0 + s * b1
    p1 = r * b1 + s * b2
    p2 = r * b2 + s * b3
    q0 = r * p0 + s * p1
    q1 = r * p1 + s * p2
    return r * q0 + s * q1


@jit(inline="always")
def _bernstein3_slope(b0: float, b1: float, b2: float, b3: float, s: float) -> float:
    r = 1.0 - s
    d0, d1, d2 = b1 - b0, b2 - b1, b3 - b2
    return 3.0 * (r * (r * d0 + s * d1) + s * (r * d1 + s * d2))


@jit(inline="always")
def _blossom3(b0: float, b1: float, b2: float, b3: float, u: float, v: float, w: float) -> float:
    p0 = (1.0 - u) * b0 + u * b1
    p1 = (1.0 - u) * b1 + u * b2
    p2 = (1.0 - u) * b2 + u * b3
    q0 = (1.0 - v) * p0 + v * p1
    q1 = (1.0 - v) * p1 + v * p2
    return (1.0 - w) * q0 + w * q1


@jit()
def bernstein_quadratic_first_root(b0: float, b1: float, b2: float) -> float:
    """First root in [0, 1] of ``b0 (1-s)^2 + 2 b1 s (1-s) + b2 s^2``; NaN if there is none."""
    if b0 == 0.0:
        return 0.0
    if (b0 > 0.0 and b1 > 0.0 and b2 > 0.0) or (b0 < 0.0 and b1 < 0.0 and b2 < 0.0):
        return math.nan  # convex hull: no root
    n, r0, r1 = quadratic_roots(b0 - 2.0 * b1 + b2, 2.0 * (b1 - b0), b0)
    best = math.nan
    if n >= 1 and -_EDGE_TOLERANCE <= r0 <= 1.0 + _EDGE_TOLERANCE:
        best = r0
    elif n == 2 and -_EDGE_TOLERANCE <= r1 <= 1.0 + _EDGE_TOLERANCE:
        best = r1
    if best != best:
        if b2 == 0.0:
            return 1.0
        return math.nan
    return min(max(best, 0.0), 1.0)


@jit()
def bernstein_cubic_first_root(b0: float, b1: float, b2: float, b3: float) -> float:
    """First root in [0, 1] of the cubic with Bernstein coefficients ``b0..b3``; NaN if none."""
    if b0 == 0.0:
        return 0.0
    level = 0
    idx = 0
    while True:
        scale = 1.0 / (1 << level)
        lo = idx * scale
        hi = (idx + 1) * scale
        if level == 0:
            c0, c1, c2, c3 = b0, b1, b2, b3
        else:
            c0 = _blossom3(b0, b1, b2, b3, lo, lo, lo)
            c1 = _blossom3(b0, b1, b2, b3, lo, lo, hi)
            c2 = _blossom3(b0, b1, b2, b3, lo, hi, hi)
            c3 = _blossom3(b0, b1, b2, b3, hi, hi, hi)
        if c0 == 0.0:
            return lo
        pos = c0 > 0.0
        same012 = (c1 > 0.0) == pos and c1 != 0.0 and (c2 > 0.0) == pos and c2 != 0.0
        drop = False
        if same012 and c3 != 0.0 and (c3 > 0.0) == pos:
            drop = True
        elif same012 and c3 == 0.0:
            if idx == (1 << level) - 1:
                return 1.0  # exact zero at the end of [0, 1]
            drop = True  # the next interval starts with this zero and reports it
        else:
            changes = 0
            prev = c0
            for c in (c1, c2, c3):
                if c != 0.0:
                    if (c > 0.0) != (prev > 0.0):
                        changes += 1
                    prev = c
            if changes == 1 and c3 != 0.0 and (c3 > 0.0) != pos:
                # Exactly one root, and the cubic's values at both ends (c0, c3): bracketed
                # Newton on the power form from the secant point, as for the power cubics.
                return refine_bracketed(b3 - 3.0 * b2 + 3.0 * b1 - b0,
                                         3.0 * (b2 - 2.0 * b1 + b0), 3.0 * (b1 - b0), b0,
                                         lo, hi, c0, c3)
            if level >= _MAX_LEVEL:
                return 0.5 * (lo + hi)  # a tangential touch narrowed to 2^-48
            level += 1
            idx *= 2
            continue
        if drop:
            # Next dyadic interval to the right: climb while we are a right child.
            while idx & 1:
                idx >>= 1
                level -= 1
            if level == 0:
                return math.nan
            idx += 1


@jit()
def newton_cubic_first_root(b0: float, b1: float, b2: float, b3: float) -> float:
    """Smallest root in [0, 1] found by Newton's iteration from the starts 0, 1/2 and 1.

    Each start runs at most 12 steps; a start converges when the step falls below 1e-12. NaN when
    the control polygon excludes a root or no start converges inside [0, 1].
    """
    if b0 == 0.0:
        return 0.0
    if (b0 > 0.0 and b1 > 0.0 and b2 > 0.0 and b3 > 0.0) or (
        b0 < 0.0 and b1 < 0.0 and b2 < 0.0 and b3 < 0.0
    ):
        return math.nan
    best = math.nan
    for start in (0.0, 0.5, 1.0):
        s = start
        for _ in range(12):
            slope = _bernstein3_slope(b0, b1, b2, b3, s)
            if slope == 0.0:
                break
            step = bernstein3_value(b0, b1, b2, b3, s) / slope
            s -= step
            if abs(step) < 1e-12:
                if -_EDGE_TOLERANCE <= s <= 1.0 + _EDGE_TOLERANCE:
                    s = min(max(s, 0.0), 1.0)
                    if not (best <= s):
                        best = s
                break
    return best
