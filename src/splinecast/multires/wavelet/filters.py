"""CDF biorthogonal spline wavelets for B-spline degree 1, 2 and 3 (Steinberger 2010, §4.1).

The synthesis scaling function is the centred uniform B-spline of degree ``d`` — the basis the
``bspline1/2/3`` models render — so every approximation level is again a B-spline coefficient grid.
For each degree we take the member of the Cohen–Daubechies–Feauveau family (Cohen et al. 1992) with
the fewest vanishing moments of the synthesis wavelet, as the thesis does (Table 4.1): ψ2,2
(linear), ψ3,1 (quadratic), ψ4,2 (cubic); ``ψN,Ñ`` has B-spline order ``N = d + 1``.

Construction (exact, in rational arithmetic)
    With ``C(z) = (z^-1 + 2 + z) / 4`` (``cos²(ξ/2)``) and ``S(z) = (2 - z - z^-1) / 4``
    (``sin²(ξ/2)``), ``z = e^{-iξ}``:

    * synthesis low-pass ``P(z) = 2 ((1 + z) / 2)^N``, i.e. ``p_k = binom(N, k) / 2^(N-1)``: the
      B-spline two-scale mask ``B_d(x) = Σ_k p_k B_d(2x - k)`` (shifted so it is centred);
    * analysis low-pass ``P̃(z) = ((1 + z) / 2)^Ñ Σ_{k<ℓ} binom(ℓ-1+k, k) S(z)^k`` with
      ``ℓ = (N + Ñ) / 2`` — Daubechies' identity ``(1-y)^ℓ P_ℓ(y) + y^ℓ P_ℓ(1-y) = 1`` makes the
      pair biorthogonal (Daubechies, *Ten Lectures*, §8.3.4; Cohen et al. 1992, §6.A);
    * high-passes by the alternating flip ``g_k = (-1)^(k+1) p̃_(1-k)``,
      ``g̃_k = (-1)^(k+1) p_(1-k)``, which turns biorthogonality of the low-passes into perfect
      reconstruction of the two-channel bank.

Conventions (one level, fine sequence ``x``, coarse ``s``, detail ``w``)::

    s[m] = Σ_i p̃[i - 2m] x[i]          w[m] = Σ_i g̃[i - 2m] x[i]          (analysis)
    x[i] = Σ_m p[i - 2m] s[m] + Σ_m g[i - 2m] w[m]                       (synthesis)

Normalisation: ``Σ p = 2`` and ``Σ p̃ = 1`` (PyWavelets uses √2 for both), so a constant stays the
same constant on every level and coarse coefficients are in the data's units, like a downsampled
pyramid. The detail filter is ``g̃ = ±(-1)^k p``: for degree 1 the detail is exactly the linear
prediction residual ``x[2m+1] - (x[2m] + x[2m+2]) / 2``.

Node positions: for odd ``d`` the coarse node ``m`` sits on fine sample ``2m`` and the detail node
on ``2m + 1`` (filters symmetric about 0 and 1). For even ``d`` the B-spline's knots lie between
samples, so both the coarse and the detail node sit at ``2m + 1/2``; ``p``, ``p̃`` are symmetric and
``g``, ``g̃`` antisymmetric about ``1/2``.
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction
from functools import cache
from math import comb

import numpy as np

from ...errors import ParameterError

__all__ = ["Filter", "SplineWavelet", "spline_wavelet", "DUAL_MOMENTS"]

#: Vanishing moments Ñ of the synthesis wavelet per B-spline degree: the fewest the CDF family
#: allows (Ñ has the parity of N = d + 1), as chosen in Steinberger 2010, Table 4.1.
DUAL_MOMENTS = {1: 2, 2: 1, 3: 2}

Laurent = dict[int, Fraction]


@dataclass(frozen=True)
class Filter:
    """A finite filter: ``taps[t]`` is the coefficient at offset ``start + t``.

    ``exact`` holds the same coefficients as fractions (offset -> value).
    """

    start: int
    taps: np.ndarray
    exact: tuple[tuple[int, Fraction], ...]

    @classmethod
    def from_laurent(cls, coeffs: Laurent) -> Filter:
        items = sorted((k, v) for k, v in coeffs.items() if v != 0)
        start, stop = items[0][0], items[-1][0]
        taps = np.zeros(stop - start + 1)
        for k, v in items:
            taps[k - start] = float(v)
        return cls(start, taps, tuple(items))

    @property
    def stop(self) -> int:
        """Last offset with a (possibly zero) tap."""
        return self.start + len(self.taps) - 1

    def as_dict(self) -> Laurent:
        """Offset -> exact coefficient."""
        return dict(self.exact)


@dataclass(frozen=True)
class SplineWavelet:
    """The four filters of one CDF spline wavelet (see the module docstring for conventions).

    Attributes
    ----------
    degree : int
        B-spline degree d of the scaling function (1, 2 or 3).
    order, dual_moments : int
        N = d + 1 and Ñ of ψN,Ñ: the synthesis wavelet has Ñ vanishing moments, the analysis
        wavelet N (the details of a polynomial of degree <= d are zero).
    synthesis_low, synthesis_high, analysis_low, analysis_high : Filter
        p, g, p̃, g̃.
    node_offset : Fraction
        Position of coarse node 0 relative to fine sample 0 in fine samples: 0 (odd d) or 1/2.
    """

    degree: int
    order: int
    dual_moments: int
    synthesis_low: Filter
    synthesis_high: Filter
    analysis_low: Filter
    analysis_high: Filter
    node_offset: Fraction

    @property
    def name(self) -> str:
        """Thesis name, e.g. ``"psi4,2"``."""
        return f"psi{self.order},{self.dual_moments}"


def _mul(a: Laurent, b: Laurent) -> Laurent:
    out: Laurent = {}
    for i, x in a.items():
        for j, y in b.items():
            out[i + j] = out.get(i + j, Fraction(0)) + x * y
    return {k: v for k, v in out.items() if v != 0}


def _power(a: Laurent, n: int) -> Laurent:
    out: Laurent = {0: Fraction(1)}
    for _ in range(n):
        out = _mul(out, a)
    return out


def _add(a: Laurent, b: Laurent, scale: Fraction = Fraction(1)) -> Laurent:
    out = dict(a)
    for k, v in b.items():
        out[k] = out.get(k, Fraction(0)) + scale * v
    return {k: v for k, v in out.items() if v != 0}


def _shift(a: Laurent, by: int) -> Laurent:
    return {k + by: v for k, v in a.items()}


def _flip(a: Laurent) -> Laurent:
    """``g_k = (-1)^(k+1) a_(1-k)`` (alternating flip)."""
    return {1 - k: (v if (1 - k) % 2 else -v) for k, v in a.items()}


@cache
def spline_wavelet(degree: int) -> SplineWavelet:
    """The CDF spline wavelet ψ(d+1),Ñ with the fewest vanishing moments for B-spline degree d.

    Parameters
    ----------
    degree : int
        1, 2 or 3.

    Returns
    -------
    SplineWavelet
        Exact and floating-point filters.

    Raises
    ------
    ParameterError
        For another degree.
    """
    if degree not in DUAL_MOMENTS:
        raise ParameterError(f"spline wavelets exist here for degree 1, 2, 3, not {degree!r}")
    order = degree + 1
    dual = DUAL_MOMENTS[degree]
    ell = (order + dual) // 2
    half = Fraction(1, 2)
    # Centre of the filters: 0 for odd degree (even N), 1/2 for even degree (odd N).
    centre_shift = order // 2  # ((1+z)/2)^N is centred at N/2; shift it to 0 or 1/2
    low = _shift({k: Fraction(comb(order, k), 2 ** (order - 1)) for k in range(order + 1)},
                 -centre_shift)
    sine = {-1: -half / 2, 0: half, 1: -half / 2}  # S(z) = (2 - z - 1/z) / 4
    poly: Laurent = {}
    for k in range(ell):
        poly = _add(poly, _power(sine, k), Fraction(comb(ell - 1 + k, k)))
    dual_low = _shift(_mul(_power({0: half, 1: half}, dual), poly), -(dual // 2))
    # Guard against a wrong construction: biorthogonality Σ_i p̃[i - 2m] p[i] = δ_m.
    for m in range(-4, 5):
        dot = sum((dual_low.get(i - 2 * m, Fraction(0)) * v for i, v in low.items()), Fraction(0))
        if dot != (1 if m == 0 else 0):
            raise AssertionError(f"CDF construction is not biorthogonal (degree {degree}, m={m})")
    return SplineWavelet(
        degree=degree,
        order=order,
        dual_moments=dual,
        synthesis_low=Filter.from_laurent(low),
        synthesis_high=Filter.from_laurent(_flip(dual_low)),
        analysis_low=Filter.from_laurent(dual_low),
        analysis_high=Filter.from_laurent(_flip(low)),
        node_offset=Fraction(0) if degree % 2 else half,
    )
