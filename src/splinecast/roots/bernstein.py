"""Bernstein form of a univariate polynomial on ``[0, 1]``: evaluation, subdivision, conversion.

A polynomial of degree ``n`` in Bernstein form is ``f(s) = sum_i b_i C(n, i) s^i (1 - s)^(n - i)``;
the ``b_i`` are its *control points*. In *scaled* Bernstein form the binomials are folded into the
coefficients, ``f(s) = sum_i c_i s^i (1 - s)^(n - i)`` with ``c_i = C(n, i) b_i``, which makes the
product of two polynomials a plain convolution of their coefficient sequences (this is how the
B-spline renderer composes a voxel's polynomial with a ray, see
:mod:`splinecast.models.bspline_ray`). The power form is ``f(s) = sum_j p_j s^j``.

Two facts the root finders rely on:

* convex hull: ``f`` lies between the smallest and the largest control point on ``[0, 1]``, so a
  sequence of one strict sign has no root;
* variation diminishing: ``f`` has at most as many roots in ``(0, 1)`` as the control points have
  sign changes (zeros skipped), and the same number modulo 2.

All coefficient arrays are float64 and only their first ``n + 1`` entries are read, so kernels can
reuse fixed-size scratch buffers for every degree.
"""

from __future__ import annotations

import numpy as np

from .._jit import jit

__all__ = [
    "binomial",
    "bernstein_eval",
    "power_eval",
    "split",
    "restrict_right",
    "sign_changes",
    "zero_tolerance",
    "power_to_bernstein",
    "bernstein_to_power",
    "scaled_to_bernstein",
]


@jit(inline="always")
def binomial(n: int, k: int) -> float:
    """Binomial coefficient ``C(n, k)`` as a float (exact for the small degrees used here)."""
    if k < 0 or k > n:
        return 0.0
    k = min(k, n - k)
    value = 1.0
    for i in range(k):
        value = value * (n - i) / (i + 1)
    return value


@jit()
def bernstein_eval(b: np.ndarray, n: int, s: float) -> float:
    """Value at ``s`` of the degree-``n`` polynomial with control points ``b``.

    Horner's scheme in the scaled basis, ``(1 - s)^n sum_i C(n, i) b_i (s / (1 - s))^i`` for
    ``s <= 1/2`` and the mirrored form for ``s > 1/2``, so the ratio never exceeds 1. This costs
    ``O(n)`` instead of de Casteljau's ``O(n^2)``; its error bound is comparable for the degrees
    used here (<= 9).
    """
    if s <= 0.5:
        r = s / (1.0 - s)
        acc = b[n]
        coef = 1.0  # C(n, i) for the current i, built downwards from C(n, n) = 1
        for i in range(n - 1, -1, -1):
            coef = coef * (i + 1) / (n - i)
            acc = acc * r + coef * b[i]
        return acc * (1.0 - s) ** n
    r = (1.0 - s) / s
    acc = b[0]
    coef = 1.0
    for i in range(1, n + 1):
        coef = coef * (n - i + 1) / i
        acc = acc * r + coef * b[i]
    return acc * s**n


@jit(inline="always")
def power_eval(p: np.ndarray, n: int, s: float) -> float:
    """Value at ``s`` of ``sum_j p_j s^j`` (Horner)."""
    acc = p[n]
    for j in range(n - 1, -1, -1):
        acc = acc * s + p[j]
    return acc


@jit()
def split(b: np.ndarray, n: int, x: float, left: np.ndarray) -> None:
    """Subdivide at ``x`` by de Casteljau's algorithm.

    On return ``left[:n+1]`` holds the control points of the piece on ``[0, x]`` and ``b[:n+1]``
    (overwritten in place) those of the piece on ``[x, 1]``, each reparameterised to ``[0, 1]``.
    """
    y = 1.0 - x
    left[0] = b[0]
    for r in range(1, n + 1):
        for i in range(n - r + 1):
            b[i] = y * b[i] + x * b[i + 1]
        left[r] = b[0]


@jit()
def restrict_right(b: np.ndarray, n: int, x: float) -> None:
    """Replace ``b`` in place by the control points of its piece on ``[x, 1]``."""
    y = 1.0 - x
    for r in range(1, n + 1):
        for i in range(n - r + 1):
            b[i] = y * b[i] + x * b[i + 1]


@jit(inline="always")
def sign_changes(b: np.ndarray, n: int, ztol: float = 0.0) -> int:
    """Number of strict sign changes in ``b[:n+1]``, zeros (``|b_i| <= ztol``) skipped."""
    count = 0
    last = 0.0
    for i in range(n + 1):
        v = b[i]
        if abs(v) > ztol:
            if last != 0.0 and (v < 0.0) != (last < 0.0):
                count += 1
            last = v
    return count


@jit(inline="always")
def zero_tolerance(b: np.ndarray, n: int) -> float:
    """Magnitude below which a control point counts as zero: ``8 eps max |b_i|``.

    Subdivision computes control points with a rounding error of a few ``eps max |b_i|``; a
    polygon that comes that close to zero cannot be told apart from one that touches it, so the
    root finders treat it as touching (a tangential ray is reported as a hit).
    """
    scale = 0.0
    for i in range(n + 1):
        scale = max(scale, abs(b[i]))
    return 8.0 * 2.220446049250313e-16 * scale


@jit()
def power_to_bernstein(p: np.ndarray, n: int, out: np.ndarray) -> None:
    """Control points of ``sum_j p_j s^j``: ``b_k = sum_{j<=k} C(k, j) / C(n, j) p_j``."""
    for k in range(n + 1):
        acc = 0.0
        for j in range(k + 1):
            acc += binomial(k, j) / binomial(n, j) * p[j]
        out[k] = acc


@jit()
def bernstein_to_power(b: np.ndarray, n: int, out: np.ndarray) -> None:
    """Power coefficients: ``p_j = C(n, j) sum_{i<=j} (-1)^(j-i) C(j, i) b_i``."""
    for j in range(n + 1):
        acc = 0.0
        for i in range(j + 1):
            term = binomial(j, i) * b[i]
            acc += term if (j - i) % 2 == 0 else -term
        out[j] = binomial(n, j) * acc


@jit()
def scaled_to_bernstein(c: np.ndarray, n: int, out: np.ndarray) -> None:
    """Control points from scaled Bernstein coefficients: ``b_i = c_i / C(n, i)``."""
    for i in range(n + 1):
        out[i] = c[i] / binomial(n, i)
