"""CDF spline-wavelet filters (reference 000, Table 4.1) against independent references.

Exact checks use the filters' rational coefficients with sums written here (not the module's
helpers); the B-spline identities evaluate basis functions with scipy's ``BSpline``; the
cross-check uses PyWavelets' bior2.2 and bior3.1 tables.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
import pywt
from scipy.interpolate import BSpline

from splinecast.multires.wavelet.filters import spline_wavelet

DEGREES = (1, 2, 3)
# Table 4.1: (low taps, high taps, vanishing moments, pieces low, pieces high) of the
# *reconstruction* filters.
TABLE_4_1 = {1: (3, 5, 2, 2, 6), 2: (4, 4, 1, 3, 6), 3: (5, 7, 2, 4, 10)}


def correlate(a: dict, b: dict, shift: int) -> Fraction:
    """Σ_i a[i - shift] b[i] in exact arithmetic."""
    return sum((a.get(i - shift, Fraction(0)) * v for i, v in b.items()), Fraction(0))


@pytest.mark.parametrize("degree", DEGREES)
def test_biorthogonality(degree):
    w = spline_wavelet(degree)
    p, g = w.synthesis_low.as_dict(), w.synthesis_high.as_dict()
    pt, gt = w.analysis_low.as_dict(), w.analysis_high.as_dict()
    for m in range(-6, 7):
        delta = Fraction(int(m == 0))
        assert correlate(pt, p, 2 * m) == delta
        assert correlate(gt, g, 2 * m) == delta
        assert correlate(pt, g, 2 * m) == 0
        assert correlate(gt, p, 2 * m) == 0


@pytest.mark.parametrize("degree", DEGREES)
def test_perfect_reconstruction_exact(degree):
    """Analysis then synthesis of an integer sequence returns it exactly (Fractions)."""
    w = spline_wavelet(degree)
    p, g = w.synthesis_low.as_dict(), w.synthesis_high.as_dict()
    pt, gt = w.analysis_low.as_dict(), w.analysis_high.as_dict()
    rng = np.random.default_rng(degree)
    x = {i: Fraction(int(v)) for i, v in enumerate(rng.integers(-50, 50, 23))}
    s = {m: sum((pt.get(i - 2 * m, 0) * v for i, v in x.items()), Fraction(0))
         for m in range(-8, 20)}
    d = {m: sum((gt.get(i - 2 * m, 0) * v for i, v in x.items()), Fraction(0))
         for m in range(-8, 20)}
    for i in range(-3, 27):
        back = sum((p.get(i - 2 * m, 0) * s[m] + g.get(i - 2 * m, 0) * d[m] for m in s),
                   Fraction(0))
        assert back == x.get(i, 0)


@pytest.mark.parametrize("degree", DEGREES)
def test_table_4_1_taps_moments_support(degree):
    w = spline_wavelet(degree)
    low, high, moments, pieces_low, pieces_high = TABLE_4_1[degree]
    assert len(w.synthesis_low.taps) == low
    assert len(w.synthesis_high.taps) == high
    assert w.dual_moments == moments
    # Support in polynomial pieces (fine cells): taps span + the B-spline's d + 1 pieces.
    assert (w.synthesis_low.stop - w.synthesis_low.start) + degree + 1 == 2 * pieces_low
    assert (w.synthesis_high.stop - w.synthesis_high.start) + degree + 1 == pieces_high
    # Discrete moments: the synthesis wavelet kills exactly Ñ, the analysis one N = d + 1.
    g, gt = w.synthesis_high.as_dict(), w.analysis_high.as_dict()
    for filt, count in ((g, moments), (gt, degree + 1)):
        sums = [sum((v * Fraction(k) ** r for k, v in filt.items()), Fraction(0))
                for r in range(count + 1)]
        assert sums[:count] == [0] * count
        assert sums[count] != 0


def centred_bspline(degree: int) -> BSpline:
    """scipy's B-spline basis element of degree d on knots centred at 0."""
    return BSpline.basis_element(np.arange(degree + 2) - (degree + 1) / 2, extrapolate=False)


@pytest.mark.parametrize("degree", DEGREES)
def test_synthesis_low_is_bspline_two_scale_mask(degree):
    """B_d(x) = Σ_k p_k B_d(2x - k + c) with c the coarse node's position (0 or 1/2)."""
    w = spline_wavelet(degree)
    basis = centred_bspline(degree)
    c = float(w.node_offset)
    x = np.linspace(-(degree + 1) / 2 - 0.3, (degree + 1) / 2 + 0.3, 401)
    coarse = np.nan_to_num(basis(x))
    fine = sum(float(v) * np.nan_to_num(basis(2 * (x + c / 2) - k))
               for k, v in w.synthesis_low.as_dict().items())
    np.testing.assert_allclose(fine, coarse, atol=1e-14)


@pytest.mark.parametrize("degree", DEGREES)
def test_continuous_vanishing_moments(degree):
    """∫ x^r ψ(x) dx = 0 for r < Ñ and not for r = Ñ, ψ = Σ g_k B_d(2x - k), by exact quadrature."""
    w = spline_wavelet(degree)
    basis = centred_bspline(degree)
    g = w.synthesis_high.as_dict()
    lo, hi = w.synthesis_high.start - (degree + 1) / 2, w.synthesis_high.stop + (degree + 1) / 2
    # Gauss-Legendre on every half-integer piece of the fine grid is exact for these polynomials.
    nodes, weights = np.polynomial.legendre.leggauss(degree + w.dual_moments + 2)
    edges = np.arange(lo, hi + 0.5, 0.5) / 2
    xs = ((edges[:-1, None] + edges[1:, None]) + (edges[1:, None] - edges[:-1, None])
          * nodes[None, :]) / 2
    ws = (edges[1:, None] - edges[:-1, None]) / 2 * weights[None, :]
    psi = sum(float(v) * np.nan_to_num(basis(2 * xs - k)) for k, v in g.items())
    centre = (w.synthesis_high.start + w.synthesis_high.stop) / 4
    moments = [float(np.sum(ws * psi * (xs - centre) ** r)) for r in range(w.dual_moments + 1)]
    np.testing.assert_allclose(moments[:-1], 0.0, atol=1e-13)
    assert abs(moments[-1]) > 1e-3


def stripped(a) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    nz = np.nonzero(np.abs(a) > 1e-12)[0]
    return a[nz[0]:nz[-1] + 1]


@pytest.mark.parametrize(("name", "degree"), [("bior2.2", 1), ("bior3.1", 2)])
def test_pywavelets_cross_check(name, degree):
    """PyWavelets' tables equal ours up to its √2 normalisation and one detail sign σ.

    PyWavelets stores decomposition filters reversed (convolution form); our analysis filters
    are correlations. Its detail sign is the opposite of ours for bior2.2 (σ = -1) and the same
    for bior3.1 (σ = +1); σ multiplies both high-passes, so the bank is the same.
    """
    ref = pywt.Wavelet(name)
    w = spline_wavelet(degree)
    r2 = np.sqrt(2.0)
    np.testing.assert_allclose(stripped(ref.rec_lo), w.synthesis_low.taps / r2, atol=1e-12)
    np.testing.assert_allclose(stripped(ref.dec_lo)[::-1], w.analysis_low.taps * r2, atol=1e-12)
    sigma = np.sign(stripped(ref.rec_hi)[0] * w.synthesis_high.taps[0])
    np.testing.assert_allclose(stripped(ref.rec_hi), sigma * w.synthesis_high.taps * r2,
                               atol=1e-12)
    np.testing.assert_allclose(stripped(ref.dec_hi)[::-1], sigma * w.analysis_high.taps / r2,
                               atol=1e-12)


def test_cubic_is_not_pywavelets_bior44():
    """ψ4,2 (5/7 taps) is derived here; PyWavelets' bior4.4 (CDF 9/7) is a different wavelet."""
    w = spline_wavelet(3)
    assert len(stripped(pywt.Wavelet("bior4.4").rec_lo)) != len(w.synthesis_low.taps)
    assert [str(v) for _, v in w.analysis_low.exact] == [
        "3/32", "-3/8", "5/32", "5/4", "5/32", "-3/8", "3/32"]
