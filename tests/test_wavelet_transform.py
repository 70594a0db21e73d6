"""3D spline-wavelet decomposition: perfect reconstruction, streaming, boundaries, hulls.

References: the voxels themselves (perfect reconstruction), numpy's own ``np.pad`` mirror modes
and ``scipy.ndimage.correlate1d`` for the extension claims, ``BSplineModel``'s padded
coefficients, and dense evaluation with ``scipy.ndimage.map_coordinates`` for the hulls.
"""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
from scipy import ndimage

import splinecast as sc
from splinecast.models.bspline import BSpline1Model, BSpline2Model, BSpline3Model
from splinecast.multires.wavelet.filters import spline_wavelet
from splinecast.multires.wavelet.layout import WaveletLayout
from splinecast.multires.wavelet.transform import (
    MemmapSink,
    decompose,
    level0_window,
    reconstruct,
)

MODELS = {1: BSpline1Model, 2: BSpline2Model, 3: BSpline3Model}
SHAPES = [(17, 12, 9), (16, 19, 10)]  # odd and even sizes on every axis


@pytest.mark.parametrize("degree", (1, 2, 3))
@pytest.mark.parametrize("shape", SHAPES)
def test_perfect_reconstruction_float64(degree, shape):
    rng = np.random.default_rng(sum(shape) + degree)
    data = rng.standard_normal(shape)
    pyramid = decompose(data, degree, levels=3, chunk=4)
    window = level0_window(data, pyramid.layout)
    assert pyramid.layout.levels == 3
    np.testing.assert_allclose(reconstruct(pyramid), window, rtol=0, atol=1e-12)
    # Every intermediate level too: level j from level J equals the stored level j.
    np.testing.assert_allclose(reconstruct(pyramid, level=1), pyramid.coarse[1], atol=1e-12)
    # Non-expansive on the window: coarsest + details = window nodes.
    count = np.prod(pyramid.layout.length(3)) + sum(
        a.size for j in pyramid.details for a in pyramid.details[j].values())
    assert count == np.prod(pyramid.layout.window)


@pytest.mark.parametrize("degree", (1, 3))
def test_perfect_reconstruction_float32(degree):
    rng = np.random.default_rng(7)
    data = (rng.random((15, 14, 13)) * 1000).astype(np.float32)
    pyramid = decompose(data, degree, levels=3, chunk=4, dtype=np.float32)
    assert pyramid.coarse[3].dtype == np.float32
    window = level0_window(data, pyramid.layout)
    error = np.abs(reconstruct(pyramid) - window).max() / np.abs(window).max()
    assert error < 1e-5


@pytest.mark.parametrize("degree", (1, 2, 3))
def test_window_is_the_models_coefficients(degree):
    """The level-0 window holds the bspline model's padded coefficients (voxel -pad .. n-1+pad)."""
    vol = sc.demo("noise", size=11)
    layout = WaveletLayout.for_volume(vol.shape, degree, levels=2, chunk=4)
    pad = degree // 2
    # The window extended by its own rule (WS = numpy "reflect", HS = numpy "symmetric").
    window = np.pad(level0_window(vol.data, layout), pad,
                    mode="reflect" if layout.odd else "symmetric")
    model = MODELS[degree](vol).coefficients
    first = -int(layout.node_origin(0))  # index of voxel -pad in the extended window
    n = np.array(vol.shape) + 2 * pad
    np.testing.assert_array_equal(
        window[first:first + n[0], first:first + n[1], first:first + n[2]], model)


@pytest.mark.parametrize("degree", (1, 2, 3))
@pytest.mark.parametrize("n", (13, 16))
def test_coefficients_outside_the_window_follow_the_rule(degree, n):
    """Analysing the far-extended window gives, outside the window, mirror images of the inside.

    The reference extends the level-0 window with numpy's own modes (WS = ``reflect`` for odd,
    HS = ``symmetric`` for even degree), filters it and subsamples; the claim (symmetric
    extension is preserved, so ghosts are reflections) is that those out-of-window coarse and
    detail values equal the stored ones reflected WS/HS (odd degree) or HS/antisymmetric HS.
    """
    rng = np.random.default_rng(n + degree)
    x = rng.standard_normal(n)
    data = np.repeat(np.repeat(x[:, None, None], 3, 1), 3, 2)  # 1D along axis 0
    pyramid = decompose(data, degree, levels=1, chunk=4)
    lay = pyramid.layout
    w = spline_wavelet(degree)
    margin = 40
    window = level0_window(data, lay)[:, 1, 1]
    ext = np.pad(window, margin, mode="reflect" if lay.odd else "symmetric")

    def analyse(filt):  # value at coarse node m: Σ_k f[k] window[2m + k]
        ms = np.arange(-12, 12 + n // 2)
        return ms, np.array([sum(filt.taps[t] * ext[margin + 2 * m + filt.start + t]
                                 for t in range(len(filt.taps))) for m in ms])

    ms, coarse = analyse(w.analysis_low)
    _, detail = analyse(w.analysis_high)
    stored_c = pyramid.coarse[1][:, 1, 1]
    stored_d = pyramid.details[1]["HLL"][:, 1, 1]
    if lay.odd:  # coarse WS, details HS
        ref_c = np.pad(stored_c, 30, mode="reflect")
        ref_d = np.pad(stored_d, 30, mode="symmetric")
    else:  # coarse HS, details antisymmetric HS
        ref_c = np.pad(stored_c, 30, mode="symmetric")
        periodic = np.concatenate([stored_d, -stored_d[::-1]])
        ref_d = np.concatenate([periodic] * 8)[len(periodic) * 4 - 30:]
        ref_d = ref_d[: len(stored_d) + 60]
    np.testing.assert_allclose(coarse, ref_c[ms + 30], atol=1e-12)
    np.testing.assert_allclose(detail, ref_d[ms + 30], atol=1e-12)


def test_streamed_equals_in_memory_with_bounded_memory(tmp_path):
    """Block-streamed from a memory map into memory maps: same numbers, small peak memory."""
    rng = np.random.default_rng(3)
    shape = (41, 38, 36)
    src = np.lib.format.open_memmap(tmp_path / "src.npy", mode="w+", dtype=np.float32,
                                    shape=shape)
    src[:] = rng.standard_normal(shape).astype(np.float32)
    src.flush()
    reference = decompose(np.asarray(src), 3, chunk=4)
    tracemalloc.start()
    streamed = decompose(np.load(tmp_path / "src.npy", mmap_mode="r"), 3, chunk=4,
                         sink=MemmapSink(tmp_path / "pyr"), block=4)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    volume_bytes = np.prod(reference.layout.window) * 8
    assert peak < volume_bytes / 4, (peak, volume_bytes)
    for j in reference.coarse:
        np.testing.assert_array_equal(np.asarray(streamed.coarse[j]), reference.coarse[j])
        for band, array in reference.details[j].items():
            np.testing.assert_array_equal(np.asarray(streamed.details[j][band]), array)
    for a, b in zip(reference.hull_lo + reference.hull_hi, streamed.hull_lo + streamed.hull_hi,
                    strict=True):
        np.testing.assert_array_equal(a, b)


def pure_level_values(pyramid, level, points_voxel):
    """The pure level-j spline at voxel points, evaluated by scipy (independent of splinecast)."""
    lay = pyramid.layout
    coeffs = (level0_window_cache[id(pyramid)] if level == 0
              else np.asarray(pyramid.coarse[level], dtype=float))
    mode = "mirror" if lay.odd else "reflect"  # scipy names: WS = mirror, HS = reflect
    index = (points_voxel - lay.node_origin(level)) / 2**level
    return ndimage.map_coordinates(coeffs, index.T, order=lay.degree, mode=mode,
                                   prefilter=False)


level0_window_cache: dict[int, np.ndarray] = {}


@pytest.mark.parametrize("degree", (1, 2, 3))
def test_hulls_bound_each_pure_level(degree):
    """Every chunk's hull contains the pure level's spline sampled densely on its region."""
    vol = sc.demo("marschner-lobb", size=21)
    pyramid = decompose(vol.data, degree, levels=2, chunk=4)
    level0_window_cache[id(pyramid)] = level0_window(vol.data, pyramid.layout)
    lay = pyramid.layout
    rng = np.random.default_rng(degree)
    for j in range(lay.levels + 1):
        lo_t, hi_t = pyramid.hull_lo[j], pyramid.hull_hi[j]
        assert np.all(np.isfinite(lo_t)) and np.all(lo_t <= hi_t)
        for idx in np.ndindex(*lay.chunks(j)):
            box = [lay.region(j, a, idx[a]) for a in range(3)]
            pts = np.stack([rng.uniform(float(b[0]), float(b[1]), 300) for b in box], axis=1)
            values = pure_level_values(pyramid, j, pts)
            assert values.min() >= lo_t[idx] - 1e-12
            assert values.max() <= hi_t[idx] + 1e-12
