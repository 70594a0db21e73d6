"""Ray pieces: a reconstruction along a piece of a ray, as a univariate polynomial in ``s``.

A model hands each piece of a ray (a cell, or a tetrahedron of a cell) to a render mode as a
polynomial ``p(s)``, ``s in [0, 1]`` from the piece's entry to its exit, in the model's natural
form. Each form is a small named tuple, so Numba compiles every generic operation below once per
form and keeps the coefficients of the small forms in registers:

=====================  =============================================  ==========================
type                   polynomial                                     model
=====================  =============================================  ==========================
:class:`PowerCubic`    ``c0 + c1 s + c2 s^2 + c3 s^3``                trilinear
:class:`Bernstein2`    ``sum_k b_k C(2, k) s^k (1 - s)^(2 - k)``      qss (per tetrahedron)
:class:`Bernstein3`    the same with degree 3                         s31 (per tetrahedron)
:class:`PolyN`         degree ``n <= 9``, power or Bernstein, in an   bspline1/2/3 (degree 3d)
                       array, with its model's first-root finder
=====================  =============================================  ==========================

Generic operations (compile-time dispatch on the type, :func:`numba.extending.overload`):

* :func:`poly_value` -- ``p(s)``;
* :func:`poly_first_root` -- the first ``s`` in ``[0, 1]`` with ``p(s) = v`` (NaN if none), with
  the form's guaranteed solver (or the model's chosen one for :class:`PolyN`);
* :func:`poly_roots` -- every such ``s``, increasing (several isosurfaces);
* :func:`poly_max` -- the largest value of ``sign * p`` on ``[0, 1]`` and where it is taken
  (first of ties), from the roots of the derivative (exact MIP / minIP);
* :func:`poly_bounds` -- a conservative range of ``p`` on ``[0, 1]`` for a few additions (the
  convex hull of the Bernstein coefficients of the fixed-degree forms; unbounded for
  :class:`PolyN`, whose control points cost about what its maximum does).

Tangency rule, as everywhere in :mod:`splinecast.roots`: a root without a sign change counts
when the polynomial is exactly the value there (or, for subdivision, when it is narrowed to
``2^-40`` without separating).
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from .._jit import jit, overload_jit
from .bernstein import bernstein_eval, power_eval, power_to_bernstein
from .bernstein_cubic import (
    bernstein3_value,
    bernstein_cubic_first_root,
    bernstein_quadratic_first_root,
    newton_cubic_first_root,
)
from .cubic import cubic_first_root, cubic_max, cubic_roots_in_unit, horner3
from .first_root import first_root_by_id

__all__ = [
    "PowerCubic", "Bernstein2", "Bernstein3", "PolyN", "polyn_workspace",
    "poly_value", "poly_first_root", "poly_roots", "poly_max", "poly_bounds",
    "bernstein_roots",
]

#: ``c0 + c1 s + c2 s^2 + c3 s^3``.
PowerCubic = namedtuple("PowerCubic", ["c0", "c1", "c2", "c3"])
#: Quadratic with Bernstein coefficients ``b0, b1, b2``.
Bernstein2 = namedtuple("Bernstein2", ["b0", "b1", "b2"])
#: Cubic with Bernstein coefficients ``b0..b3``; ``newton`` selects the references' Newton
#: iteration from three starts for the first root instead of guaranteed subdivision.
Bernstein3 = namedtuple("Bernstein3", ["b0", "b1", "b2", "b3", "newton"])
#: Degree ``n`` polynomial in ``coeffs[:n+1]`` (``power`` form or Bernstein control points) with
#: the first-root finder ``finder`` of :mod:`.first_root` and scratch space (see
#: :func:`polyn_workspace`).
PolyN = namedtuple("PolyN", ["coeffs", "n", "power", "finder", "iterations", "tol",
                             "tmp", "work", "degrees", "stack", "spans", "cand"])

_MAX_DEGREE = 9
#: A product instead of a division by 3 in the Bernstein coefficients of a power-form cubic:
#: LLVM keeps a division by a constant that is not a power of two, and its latency stood out
#: in isosurface profiles. The coefficients only bound the cubic,
#: with margins far above the one rounding this changes.
_THIRD = 1.0 / 3.0
_STACK = 48          # subdivision depth-first stack: depth + 2 entries suffice
_MIN_WIDTH = 2.0**-40  # narrower intervals that still hold several sign changes: a touch


@jit(inline="always")
def polyn_workspace() -> tuple:
    """Scratch arrays of a :class:`PolyN` up to degree 9:
    ``(coeffs, tmp, work, degrees, stack, spans, cand)``."""
    m = _MAX_DEGREE + 1
    return (np.empty(m), np.empty(m), np.empty((m, m)), np.empty(m, np.int64),
            np.empty((_STACK, m)), np.empty((_STACK, 2)), np.empty(2 * m))


def _is(typ, cls) -> bool:
    return getattr(typ, "instance_class", None) is cls


# ---------------------------------------------------------------------------- Bernstein arrays
@jit(inline="always")
def _changes(c: np.ndarray, n: int) -> int:
    count = 0
    last = 0.0
    for i in range(n + 1):
        v = c[i]
        if v != 0.0:
            if last != 0.0 and (v < 0.0) != (last < 0.0):
                count += 1
            last = v
    return count


@jit()
def _refine_single(b: np.ndarray, n: int, lo: float, hi: float, glo: float) -> float:
    """The one sign change of the control-point polynomial ``b`` inside ``(lo, hi)``
    (Illinois regula falsi, bisection-safeguarded)."""
    ghi = bernstein_eval(b, n, hi)
    for _ in range(200):
        s = (lo * ghi - hi * glo) / (ghi - glo) if ghi != glo else 0.5 * (lo + hi)
        if not (lo < s < hi) or hi - lo > 0.25:
            s = 0.5 * (lo + hi)
        g = bernstein_eval(b, n, s)
        if g == 0.0:
            return s
        if (g < 0.0) == (glo < 0.0):
            lo, glo = s, g
            ghi *= 0.5
        else:
            hi, ghi = s, g
            glo *= 0.5
        if hi - lo <= 4e-16 * max(1.0, abs(hi)):
            break
    return 0.5 * (lo + hi)


@jit()
def bernstein_roots(b: np.ndarray, n: int, out: np.ndarray, start: int, stack: np.ndarray,
                    spans: np.ndarray) -> int:
    """Every root in ``[0, 1]`` of the control-point polynomial ``b[:n+1]``, increasing.

    Roots are isolated by subdivision with the Bernstein form of Descartes' rule: an interval
    whose control polygon has no sign change holds no root, one with exactly one change and
    non-zero ends holds exactly one (refined by bracketing), others are halved depth first, left
    before right, so roots come out in order. An exact zero at an interval's left end is a root
    (a zero at a split point belongs to the right half; a zero at ``s = 1`` is reported last).
    Returns the number written to ``out[start:]``.
    """
    found = 0
    for i in range(n + 1):
        stack[0, i] = b[i]
    spans[0, 0] = 0.0
    spans[0, 1] = 1.0
    top = 1
    last = -1.0
    while top > 0:
        top -= 1
        lo = spans[top, 0]
        hi = spans[top, 1]
        c = stack[top]
        if c[0] == 0.0 and lo != last:
            out[start + found] = lo
            found += 1
            last = lo
        v = _changes(c, n)
        if v == 0:
            continue
        if v == 1 and c[0] != 0.0 and c[n] != 0.0:
            r = _refine_single(b, n, lo, hi, bernstein_eval(b, n, lo))
            if r != last:
                out[start + found] = r
                found += 1
                last = r
            continue
        if hi - lo <= _MIN_WIDTH or top + 2 > stack.shape[0]:
            # Several changes left in a tiny interval: a touch or a cluster, one root. (One
            # change next to an exact zero end is that end's root, reported on its own.)
            if v >= 2:
                r = 0.5 * (lo + hi)
                if r > last:
                    out[start + found] = r
                    found += 1
                    last = r
            continue
        # de Casteljau at 1/2: the right half goes in slot top, the left half above it.
        mid = 0.5 * (lo + hi)
        right = stack[top]
        left = stack[top + 1]
        left[0] = right[0]
        for r_ in range(1, n + 1):
            for i in range(n - r_ + 1):
                right[i] = 0.5 * (right[i] + right[i + 1])
            left[r_] = right[0]
        spans[top, 0] = mid
        spans[top, 1] = hi
        spans[top + 1, 0] = lo
        spans[top + 1, 1] = mid
        top += 2
    if b[n] == 0.0 and last != 1.0:
        out[start + found] = 1.0
        found += 1
    return found


@jit(inline="always")
def _to_control_points(p, value: float) -> None:
    """``p.tmp[:n+1]`` = control points of ``p - value``."""
    n = p.n
    if p.power:
        power_to_bernstein(p.coeffs, n, p.tmp)
    else:
        for i in range(n + 1):
            p.tmp[i] = p.coeffs[i]
    for i in range(n + 1):
        p.tmp[i] -= value


# ---------------------------------------------------------------------------- generic operations
def poly_value(p, s):
    """Value of the piece polynomial ``p`` at ``s`` (compiled code only)."""
    raise NotImplementedError


@overload_jit(poly_value)
def _poly_value(p, s):
    if _is(p, PowerCubic):
        return lambda p, s: horner3(p.c3, p.c2, p.c1, p.c0, s)
    if _is(p, Bernstein3):
        return lambda p, s: bernstein3_value(p.b0, p.b1, p.b2, p.b3, s)
    if _is(p, Bernstein2):
        def value2(p, s):
            r = 1.0 - s
            return r * (r * p.b0 + s * p.b1) + s * (r * p.b1 + s * p.b2)
        return value2
    if _is(p, PolyN):
        def value_n(p, s):
            if p.power:
                return power_eval(p.coeffs, p.n, s)
            return bernstein_eval(p.coeffs, p.n, s)
        return value_n
    return None


def poly_first_root(p, value):
    """First ``s`` in ``[0, 1]`` with ``p(s) == value``, NaN if none (compiled code only)."""
    raise NotImplementedError


@overload_jit(poly_first_root)
def _poly_first_root(p, value):
    if _is(p, PowerCubic):
        def first_power3(p, value):
            c0 = p.c0 - value
            # Convex hull of the Bernstein coefficients on [0, 1]: no root when they all lie on
            # one side of zero, decided with a few additions instead of the derivative's roots
            # and up to three evaluations (most pieces a ray tests hold the value in their
            # range but not on the ray). The margin, far above the rounding of these sums and of
            # the solver's evaluations, leaves every case the solver could decide otherwise to
            # the solver, so the result is the solver's.
            b1 = c0 + p.c1 * _THIRD
            b2 = b1 + (p.c1 + p.c2) * _THIRD
            b3 = c0 + p.c1 + p.c2 + p.c3
            margin = 1e-12 * (abs(c0) + abs(p.c1) + abs(p.c2) + abs(p.c3))
            if (c0 > margin and b1 > margin and b2 > margin and b3 > margin) or (
                    c0 < -margin and b1 < -margin and b2 < -margin and b3 < -margin):
                return math.nan
            return cubic_first_root(p.c3, p.c2, p.c1, c0, 0.0, 1.0)
        return first_power3
    if _is(p, Bernstein2):
        return lambda p, value: bernstein_quadratic_first_root(p.b0 - value, p.b1 - value,
                                                              p.b2 - value)
    if _is(p, Bernstein3):
        def first3(p, value):
            b0, b1, b2, b3 = p.b0 - value, p.b1 - value, p.b2 - value, p.b3 - value
            if (b0 > 0.0 and b1 > 0.0 and b2 > 0.0 and b3 > 0.0) or (
                    b0 < 0.0 and b1 < 0.0 and b2 < 0.0 and b3 < 0.0):
                return math.nan  # convex hull: no root
            if p.newton:
                return newton_cubic_first_root(b0, b1, b2, b3)
            return bernstein_cubic_first_root(b0, b1, b2, b3)
        return first3
    if _is(p, PolyN):
        def first_n(p, value):
            n = p.n
            for i in range(n + 1):
                p.tmp[i] = p.coeffs[i]
            if p.power:
                p.tmp[0] -= value
            else:
                for i in range(n + 1):
                    p.tmp[i] -= value
            return first_root_by_id(p.finder, p.tmp, n, p.iterations, p.tol, p.work, p.degrees)
        return first_n
    return None


def poly_roots(p, value, out, start):
    """Every ``s`` in ``[0, 1]`` with ``p(s) == value``, increasing, written to ``out[start:]``;
    returns the count (compiled code only)."""
    raise NotImplementedError


@overload_jit(poly_roots)
def _poly_roots(p, value, out, start):
    if _is(p, PowerCubic):
        return lambda p, value, out, start: cubic_roots_in_unit(p.c3, p.c2, p.c1, p.c0 - value,
                                                                out, start)
    if _is(p, Bernstein2):
        def roots2(p, value, out, start):
            b0, b1, b2 = p.b0 - value, p.b1 - value, p.b2 - value
            if (b0 > 0.0 and b1 > 0.0 and b2 > 0.0) or (b0 < 0.0 and b1 < 0.0 and b2 < 0.0):
                return 0
            return cubic_roots_in_unit(0.0, b0 - 2.0 * b1 + b2, 2.0 * (b1 - b0), b0, out, start)
        return roots2
    if _is(p, Bernstein3):
        def roots3(p, value, out, start):
            b0, b1, b2, b3 = p.b0 - value, p.b1 - value, p.b2 - value, p.b3 - value
            if (b0 > 0.0 and b1 > 0.0 and b2 > 0.0 and b3 > 0.0) or (
                    b0 < 0.0 and b1 < 0.0 and b2 < 0.0 and b3 < 0.0):
                return 0
            return cubic_roots_in_unit(b3 - 3.0 * b2 + 3.0 * b1 - b0,
                                       3.0 * (b2 - 2.0 * b1 + b0), 3.0 * (b1 - b0), b0,
                                       out, start)
        return roots3
    if _is(p, PolyN):
        def roots_n(p, value, out, start):
            _to_control_points(p, value)
            return bernstein_roots(p.tmp, p.n, out, start, p.stack, p.spans)
        return roots_n
    return None


def poly_max(p, sign):
    """Largest value of ``sign * p`` on ``[0, 1]`` and the first ``s`` where it is taken
    (compiled code only); ``sign`` is +1 (maximum) or -1 (minimum, returned negated)."""
    raise NotImplementedError


@overload_jit(poly_max)
def _poly_max(p, sign):
    if _is(p, PowerCubic):
        return lambda p, sign: cubic_max(sign * p.c3, sign * p.c2, sign * p.c1, sign * p.c0)
    if _is(p, Bernstein2):
        def max2(p, sign):
            b0, b1, b2 = sign * p.b0, sign * p.b1, sign * p.b2
            return cubic_max(0.0, b0 - 2.0 * b1 + b2, 2.0 * (b1 - b0), b0)
        return max2
    if _is(p, Bernstein3):
        def max3(p, sign):
            b0, b1, b2, b3 = sign * p.b0, sign * p.b1, sign * p.b2, sign * p.b3
            return cubic_max(b3 - 3.0 * b2 + 3.0 * b1 - b0, 3.0 * (b2 - 2.0 * b1 + b0),
                             3.0 * (b1 - b0), b0)
        return max3
    if _is(p, PolyN):
        def max_n(p, sign):
            n = p.n
            _to_control_points(p, 0.0)
            b = p.tmp
            for i in range(n + 1):
                b[i] *= sign
            best = b[0]
            s_best = 0.0
            if n >= 2:
                # Derivative control points n (b[i+1] - b[i]); its roots are the candidates.
                d = p.work[0]
                for i in range(n):
                    d[i] = b[i + 1] - b[i]
                m = bernstein_roots(d, n - 1, p.cand, 0, p.stack, p.spans)
                for q in range(m):
                    s = p.cand[q]
                    if 0.0 < s < 1.0:
                        v = bernstein_eval(b, n, s)
                        if v > best:
                            best, s_best = v, s
            if b[n] > best:
                best, s_best = b[n], 1.0
            return best, s_best
        return max_n
    return None


def poly_bounds(p):
    """Conservative ``(lo, hi)`` of ``p`` on ``[0, 1]``, cheap to take (compiled code only):
    the convex hull of the Bernstein coefficients of a cubic or quadratic, ``(-inf, inf)`` for
    :class:`PolyN` (converting its coefficients would double the work of :func:`poly_max`,
    which MIP calls after it, for a bound that rarely leaves a tensor-product piece out)."""
    raise NotImplementedError


@overload_jit(poly_bounds)
def _poly_bounds(p):
    if _is(p, PowerCubic):
        def bounds_pc(p):
            # Bernstein coefficients of the power form: the convex hull bounds the cubic.
            b1 = p.c0 + p.c1 * _THIRD
            b2 = p.c0 + (2.0 * p.c1 + p.c2) * _THIRD
            b3 = p.c0 + p.c1 + p.c2 + p.c3
            return min(min(p.c0, b1), min(b2, b3)), max(max(p.c0, b1), max(b2, b3))
        return bounds_pc
    if _is(p, Bernstein2):
        return lambda p: (min(p.b0, min(p.b1, p.b2)), max(p.b0, max(p.b1, p.b2)))
    if _is(p, Bernstein3):
        return lambda p: (min(min(p.b0, p.b1), min(p.b2, p.b3)),
                          max(max(p.b0, p.b1), max(p.b2, p.b3)))
    if _is(p, PolyN):
        return lambda p: (-math.inf, math.inf)
    return None
