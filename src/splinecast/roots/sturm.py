"""First root by a Sturm sequence and bisection (power form).

The Sturm chain of ``p`` is ``p_0 = p``, ``p_1 = p'``, ``p_{k+1} = -rem(p_{k-1}, p_k)``. With
``V(x)`` the number of sign changes of ``p_0(x), p_1(x), ...`` (zeros skipped), ``V(a) - V(b)`` is
the number of *distinct* real roots in ``(a, b]``. Bisection keeps the half whose left part still
holds a root, so after ``k`` steps the first root is known within ``2^-k`` (Steinberger 2010,
Listing A.4). Every chain element is rescaled to a largest coefficient of 1 (signs unchanged) to
keep the division well scaled, and a remainder whose coefficients are all below ``1e-13`` relative
to the dividend ends the chain (it is the rounding residue of an exact zero remainder, which is
what a multiple root produces).

Power-form arithmetic in float64 is the weak point the thesis names: near multiple or tightly
clustered roots the rounded chain can miscount. The result is then still deterministic.

Degenerate cases: ``p(0) == 0`` gives 0 (this includes the identically zero polynomial); a
constant non-zero polynomial has no root; a double root counts as one root and is found like a
simple one; a root exactly at 1 is found (the count is over ``(a, b]``).
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import jit
from .bernstein import power_eval

__all__ = ["sturm_chain", "sturm_first_root", "sturm_first_root_work", "STURM_ITERATIONS"]

#: Default number of bisection steps (2^-44 < 1e-13).
STURM_ITERATIONS = 44

_REMAINDER_EPS = 1e-13


@jit(inline="always")
def _normalize(chain: np.ndarray, row: int, deg: int) -> None:
    scale = 0.0
    for i in range(deg + 1):
        scale = max(scale, abs(chain[row, i]))
    if scale > 0.0:
        for i in range(deg + 1):
            chain[row, i] /= scale


@jit()
def sturm_chain(p: np.ndarray, n: int, chain: np.ndarray, degrees: np.ndarray) -> int:
    """Build the Sturm chain of ``p[:n+1]`` into ``chain`` (rows, ascending powers).

    ``chain`` needs shape at least ``(n + 1, n + 1)`` and ``degrees`` length ``n + 1``; returns
    the number of chain elements (0 for the zero polynomial).
    """
    deg = n
    while deg >= 0 and p[deg] == 0.0:
        deg -= 1
    if deg < 0:
        return 0
    for i in range(deg + 1):
        chain[0, i] = p[i]
    degrees[0] = deg
    _normalize(chain, 0, deg)
    if deg == 0:
        return 1
    for i in range(deg):
        chain[1, i] = (i + 1) * chain[0, i + 1]
    degrees[1] = deg - 1
    _normalize(chain, 1, deg - 1)
    count = 2
    while degrees[count - 1] > 0:
        num = count - 2
        den = count - 1
        dn = degrees[num]
        dd = degrees[den]
        # Remainder of chain[num] / chain[den], computed in the row that will hold it.
        out = count
        for i in range(dn + 1):
            chain[out, i] = chain[num, i]
        lead = chain[den, dd]
        for shift in range(dn - dd, -1, -1):
            q = chain[out, shift + dd] / lead
            for i in range(dd + 1):
                chain[out, shift + i] -= q * chain[den, i]
            chain[out, shift + dd] = 0.0
        # Degree of the remainder, dropping rounding residue.
        rdeg = dd - 1
        while rdeg >= 0 and abs(chain[out, rdeg]) <= _REMAINDER_EPS:
            rdeg -= 1
        if rdeg < 0:
            break  # exact division: the last element is the gcd (multiple roots)
        for i in range(rdeg + 1):
            chain[out, i] = -chain[out, i]
        degrees[out] = rdeg
        _normalize(chain, out, rdeg)
        count += 1
    return count


@jit(inline="always")
def _variations(chain: np.ndarray, degrees: np.ndarray, count: int, x: float) -> int:
    changes = 0
    last = 0.0
    for k in range(count):
        v = power_eval(chain[k], degrees[k], x)
        if v != 0.0:
            if last != 0.0 and (v < 0.0) != (last < 0.0):
                changes += 1
            last = v
    return changes


@jit()
def sturm_first_root_work(
    p: np.ndarray, n: int, iterations: int, tol: float, chain: np.ndarray, degrees: np.ndarray
) -> float:
    """First root in ``[0, 1]`` of ``sum_j p_j s^j`` (``j <= n``); NaN if none.

    ``chain`` (shape at least ``(n + 1, n + 1)``) and ``degrees`` (int, length ``n + 1``) are
    scratch space.
    """
    if p[0] == 0.0:
        return 0.0
    count = sturm_chain(p, n, chain, degrees)
    a = 0.0
    b = 1.0
    va = _variations(chain, degrees, count, a)
    if va - _variations(chain, degrees, count, b) <= 0:
        return math.nan
    for _ in range(iterations):
        if b - a <= tol:
            break
        m = 0.5 * (a + b)
        vm = _variations(chain, degrees, count, m)
        if va - vm >= 1:
            b = m
        else:
            a = m
            va = vm
    return 0.5 * (a + b)


@jit()
def sturm_first_root(
    p: np.ndarray, iterations: int = STURM_ITERATIONS, tol: float = 1e-12
) -> float:
    """First root in ``[0, 1]`` of a polynomial in power form, by Sturm sequence and bisection.

    Parameters
    ----------
    p : ndarray of float64
        Coefficients in ascending powers, ``p[j]`` multiplies ``s^j``.
    iterations : int
        Number of bisection steps (the result is within ``2^-iterations`` of the root when the
        rounded chain counts correctly).
    tol : float
        Bracket width at which bisection stops early.

    Returns
    -------
    float
        The first root, or NaN.
    """
    n = p.shape[0] - 1
    chain = np.empty((n + 1, n + 1))
    degrees = np.empty(n + 1, dtype=np.int64)
    return sturm_first_root_work(p.astype(np.float64), n, iterations, tol, chain, degrees)
