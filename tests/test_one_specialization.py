"""Compiled functions that only read an array are compiled once for it, whatever its flags.

Numba compiles a function again for a read-only array (a memory-mapped file, a cached or
broadcast array) and for another memory order of the same type. The block ranges of the
isosurface's hierarchy, the histograms of a cut's bricks and the importance of boxes are handed
one form of their arrays, so an array from a file, a view in Fortran order or a writable copy
uses the code compiled for the first: the number of compiled signatures does not grow, and the
answers are the same (and checked against numpy).
"""

from __future__ import annotations

import numpy as np

from splinecast.accel import minmax
from splinecast.multires.cut import histograms, metric

RNG = np.random.default_rng(11)


def _read_only_copy(a: np.ndarray) -> np.ndarray:
    b = a.copy()
    b.flags.writeable = False
    return b


def test_block_ranges_compile_once_for_arrays_of_files_and_of_memory():
    data = RNG.standard_normal((13, 11, 9)).astype(np.float32)
    n_cells = tuple(s - 1 for s in data.shape)
    first = minmax.MinMaxHierarchy(data, n_cells, 1)
    compiled = len(minmax._finest_range_slabs.overloads)
    second = minmax.MinMaxHierarchy(_read_only_copy(data), n_cells, 1)
    assert len(minmax._finest_range_slabs.overloads) == compiled
    for a, b in zip(first.lows + first.highs, second.lows + second.highs, strict=True):
        np.testing.assert_array_equal(a, b)
    # The finest blocks (4 cells: values 0..4 along each axis) against numpy.
    block = 1 << minmax.BLOCK_SHIFTS[0]
    for bi in range(first.lows[0].shape[0]):
        window = data[bi * block:bi * block + block + 1, :block + 1, :block + 1]
        assert first.lows[0][bi, 0, 0] == window.min()
        assert first.highs[0][bi, 0, 0] == window.max()


def test_brick_histograms_compile_once_for_any_order_and_flags():
    source = RNG.integers(0, 256, (16, 16, 16)).astype(np.uint8)
    coarse = source[::2, ::2, ::2].copy()
    lo = np.array([[0, 0, 0], [8, 0, 0], [0, 8, 8]])
    hi = lo + 8
    quantizer = histograms.Quantizer.for_data(np.uint8, (0, 255))
    first = histograms.box_histograms(source, coarse, lo, hi, 0.5, -0.25, quantizer)
    compiled = len(histograms._brick_batch_chunks.overloads)
    second = histograms.box_histograms(_read_only_copy(source), _read_only_copy(coarse),
                                       np.asfortranarray(lo), np.asfortranarray(hi),
                                       (0.5, 0.5, 0.5), np.full(3, -0.25), quantizer)
    assert len(histograms._brick_batch_chunks.overloads) == compiled
    for name in ("offsets", "keys", "counts"):
        np.testing.assert_array_equal(getattr(first, name), getattr(second, name))
    # Every brick counts each of its source voxels once.
    counts = np.add.reduceat(first.counts, first.offsets[:-1]) if len(first.counts) else []
    np.testing.assert_array_equal(counts, [8**3] * 3)


def test_importance_compiles_once_for_read_only_boxes():
    box_min = RNG.uniform(-5.0, 5.0, (20, 3))
    box_max = box_min + RNG.uniform(0.1, 2.0, (20, 3))
    first = metric.importance(box_min, box_max, interest=(1.0, 2.0, 3.0), eye=(9.0, 0.0, 0.0))
    compiled = len(metric._importance_boxes.overloads)
    second = metric.importance(_read_only_copy(box_min), _read_only_copy(box_max),
                               interest=(1.0, 2.0, 3.0), eye=(9.0, 0.0, 0.0))
    assert len(metric._importance_boxes.overloads) == compiled
    np.testing.assert_array_equal(first, second)
    assert np.all((first > 0.0) & (first <= 1.0))
