"""First root of a cubic on an interval, computed stably.

The cubic ``g(s) = c3 s^3 + c2 s^2 + c1 s + c0`` is split at the real roots of its derivative
(a quadratic, solved with the cancellation-free formula) into monotone pieces. Walking those pieces
in order, the first one whose end values bracket zero holds the first root, which is then refined by
Newton's method safeguarded with bisection, so it always stays inside a shrinking bracket. No bare
closed-form cubic formula is used: Cardano's formula loses digits near double roots and near
degenerate (almost quadratic) cubics, which are common on ray profiles.

Degenerate cases, deterministically:

* a value exactly zero at an interval end or at an extremum counts as a root there (a tangential
  touch is a hit only when the touching value is exactly the isovalue);
* a polynomial that is identically zero on the interval has its first root at the start;
* a double root without a sign change is reported only if the extremum evaluates to exactly 0.
"""

from __future__ import annotations

import math

from .._jit import jit

__all__ = ["cubic_first_root", "quadratic_roots", "horner3", "cubic_roots_in_unit", "cubic_max",
           "refine_bracketed"]

_NEWTON_MAX_ITERATIONS = 80


@jit(inline="always")
def horner3(c3: float, c2: float, c1: float, c0: float, s: float) -> float:
    """Value of ``c3 s^3 + c2 s^2 + c1 s + c0`` by Horner's scheme."""
    return ((c3 * s + c2) * s + c1) * s + c0


@jit()
def quadratic_roots(a: float, b: float, c: float) -> tuple[int, float, float]:
    """Real roots of ``a s^2 + b s + c``, sorted, without catastrophic cancellation.

    Returns
    -------
    count : int
        0, 1 or 2 (a double root is returned once; a linear equation gives at most 1).
    r0, r1 : float
        The roots in increasing order (unused slots are NaN).
    """
    nan = math.nan
    if a == 0.0:
        if b == 0.0:
            return 0, nan, nan
        return 1, -c / b, nan
    disc = b * b - 4.0 * a * c
    if disc < 0.0:
        return 0, nan, nan
    if disc == 0.0:
        return 1, -b / (2.0 * a), nan
    # q has the sign of b so that b + sign(b) sqrt(disc) never cancels.
    q = -0.5 * (b + math.copysign(math.sqrt(disc), b))
    r0 = q / a
    if q == 0.0:
        return 1, r0, nan
    r1 = c / q
    if r0 > r1:
        r0, r1 = r1, r0
    return 2, r0, r1


@jit()
def refine_bracketed(
    c3: float, c2: float, c1: float, c0: float, lo: float, hi: float, glo: float, ghi: float
) -> float:
    """The root of a cubic in ``[lo, hi]``, given its values ``glo`` and ``ghi`` of opposite
    signs at the ends, where it has exactly one (it is monotone there, or the interval is
    isolated otherwise): Newton's method from the secant point, kept inside the bracket."""
    # Start from the secant (regula falsi) point: on a monotone piece it is already close.
    s = lo - glo * (hi - lo) / (ghi - glo)
    if not (lo < s < hi):
        s = 0.5 * (lo + hi)
    tol = 4e-16 * max(1.0, abs(lo), abs(hi))
    for _ in range(_NEWTON_MAX_ITERATIONS):
        gs = horner3(c3, c2, c1, c0, s)
        if gs == 0.0:
            return s
        if (gs < 0.0) == (glo < 0.0):
            lo, glo = s, gs
        else:
            hi, ghi = s, gs
        if hi - lo <= tol:
            break
        slope = (3.0 * c3 * s + 2.0 * c2) * s + c1
        nxt = s - gs / slope if slope != 0.0 else 0.5 * (lo + hi)
        if not (lo < nxt < hi):
            nxt = 0.5 * (lo + hi)  # Newton left the bracket: bisect instead.
        if abs(nxt - s) <= tol:
            s = nxt
            break
        s = nxt
    # Return the bracket end with the smaller residual when the iteration stops on width.
    gs = horner3(c3, c2, c1, c0, s)
    if abs(glo) < abs(gs) and abs(glo) <= abs(ghi):
        return lo
    if abs(ghi) < abs(gs):
        return hi
    return s


@jit()
def cubic_first_root(c3: float, c2: float, c1: float, c0: float, lo: float, hi: float) -> float:
    """Smallest ``s`` in ``[lo, hi]`` with ``c3 s^3 + c2 s^2 + c1 s + c0 == 0``.

    Parameters
    ----------
    c3, c2, c1, c0 : float
        Power-form coefficients.
    lo, hi : float
        The interval, ``lo <= hi``.

    Returns
    -------
    float
        The first root, or NaN when the cubic has no root in the interval.
    """
    g_lo = horner3(c3, c2, c1, c0, lo)
    if g_lo == 0.0:
        return lo
    # Split points: the derivative's roots inside (lo, hi).
    count, e0, e1 = quadratic_roots(3.0 * c3, 2.0 * c2, c1)
    a = lo
    ga = g_lo
    for piece in range(3):
        if piece == 0:
            if count < 1 or not (lo < e0 < hi):
                continue
            b = e0
        elif piece == 1:
            if count < 2 or not (lo < e1 < hi):
                continue
            b = e1
        else:
            b = hi
        gb = horner3(c3, c2, c1, c0, b)
        if gb == 0.0:
            return b
        if (ga < 0.0) != (gb < 0.0):
            return refine_bracketed(c3, c2, c1, c0, a, b, ga, gb)
        a, ga = b, gb
    return math.nan


@jit(inline="always")
def cubic_roots_in_unit(c3: float, c2: float, c1: float, c0: float, out, start: int) -> int:
    """Write the roots in ``[0, 1]`` of the cubic, increasing, to ``out[start:]``; return count.

    The cubic is split at the roots of its derivative into monotone pieces, each holding at most
    one root (found by :func:`cubic_first_root`). A double root without a sign change counts only
    when the cubic is exactly 0 there (the tangency rule above).
    """
    count, e0, e1 = quadratic_roots(3.0 * c3, 2.0 * c2, c1)
    found = 0
    a = 0.0
    last = -1.0
    for piece in range(3):
        if piece == 0:
            if count < 1 or not (0.0 < e0 < 1.0):
                continue
            b = e0
        elif piece == 1:
            if count < 2 or not (0.0 < e1 < 1.0):
                continue
            b = e1
        else:
            b = 1.0
        s = cubic_first_root(c3, c2, c1, c0, a, b)
        if s == s and s != last:
            out[start + found] = s
            found += 1
            last = s
        a = b
    return found


@jit(inline="always")
def cubic_max(c3: float, c2: float, c1: float, c0: float) -> tuple[float, float]:
    """Largest value of the cubic on ``[0, 1]`` and the ``s`` where it is taken (first of ties).

    The maximum is at an end or at a root of the derivative (a quadratic).
    """
    best = c0
    s_best = 0.0
    count, e0, e1 = quadratic_roots(3.0 * c3, 2.0 * c2, c1)
    if count >= 1 and 0.0 < e0 < 1.0:
        v = horner3(c3, c2, c1, c0, e0)
        if v > best:
            best, s_best = v, e0
    if count >= 2 and 0.0 < e1 < 1.0:
        v = horner3(c3, c2, c1, c0, e1)
        if v > best:
            best, s_best = v, e1
    v = c3 + c2 + c1 + c0
    if v > best:
        best, s_best = v, 1.0
    return best, s_best
