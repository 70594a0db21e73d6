"""Issue 11, item 1: CIELUV colours, the brick histograms and D(b) from them.

D(b) from the sparse histograms must equal D(b) summed voxel by voxel (eq. 1-2) with an
independent trilinear evaluation (scipy's ``map_coordinates``); the CIELUV conversion is checked
against published values; the histograms of 2B bricks summed from B bricks against a direct build.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from cut_reference import smooth_volume, voxel_distortion

import splinecast as sc
from splinecast.multires.cut.colour import classified_luv, distortion_table, srgb_to_luv
from splinecast.multires.cut.histograms import (
    BrickHistograms,
    Quantizer,
    approximate,
    brick_histogram,
    coarsen_histograms,
    leaf_value_ranges,
    mean_pyramid_map,
    pyramid_histograms,
)
from splinecast.multires.cut.metric import histogram_distortion
from splinecast.multires.cut.tree import regular_brick_tree
from splinecast.multires.store.mean_pyramid import mean_downsample, mean_pyramid

MNI = Path(__file__).resolve().parents[2] / "shared" / "data" / "mni152_t1_1mm.nii.gz"
TF = sc.TransferFunction([(30, 0.0), (60, 0.05), (90, 0.1), (140, 0.6), (255, 0.9)],
                         domain=(0, 255), colormap="bone")


def test_srgb_to_luv_matches_published_values():
    # CIE L*u*v* (D65) of sRGB primaries and white, as tabulated e.g. by Bruce Lindbloom's
    # calculator: white (100, 0, 0); red (53.2408, 175.0151, 37.7564); blue (32.2970,
    # -9.4054, -130.3423); black (0, 0, 0).
    luv = srgb_to_luv(np.array([[1, 1, 1], [1, 0, 0], [0, 0, 1], [0, 0, 0]], float))
    np.testing.assert_allclose(luv[0], [100, 0, 0], atol=2e-3)
    np.testing.assert_allclose(luv[1], [53.2408, 175.0151, 37.7564], atol=2e-2)
    np.testing.assert_allclose(luv[2], [32.2970, -9.4054, -130.3423], atol=2e-2)
    np.testing.assert_allclose(luv[3], [0, 0, 0], atol=1e-12)


def test_distortion_table_is_a_distance_of_premultiplied_colours():
    values = np.array([0.0, 100.0, 200.0])
    table = distortion_table(TF, values)
    assert table.shape == (3, 3)
    np.testing.assert_allclose(np.diag(table), 0.0)
    np.testing.assert_allclose(table, table.T)
    # Value 0 is fully transparent: premultiplied black, whatever the colormap says.
    np.testing.assert_allclose(classified_luv(TF, values[:1]), [[0, 0, 0]], atol=1e-12)
    direct = np.linalg.norm(classified_luv(TF, [100.0])[0] - classified_luv(TF, [200.0])[0])
    assert table[1, 2] == pytest.approx(direct)


def test_quantizer_bins_are_the_values_for_8_bit_data():
    default = Quantizer.for_data(np.uint8, (3, 200))
    assert (default.lo, default.hi, default.bins) == (0.0, 255.0, 64)
    np.testing.assert_allclose(default.values[[0, 1, -1]], [0, 255 / 63, 255])
    q = Quantizer.for_data(np.uint8, (3, 200), bins=256)
    assert (q.lo, q.hi, q.bins) == (0.0, 255.0, 256)
    np.testing.assert_array_equal(q.bin_of(np.arange(256)), np.arange(256))
    np.testing.assert_array_equal(q.values, np.arange(256))
    assert q.bin_of(10.49) == 10 and q.bin_of(10.5) == 11 and q.bin_of(-3) == 0
    f = Quantizer.for_data(np.float32, (-1.0, 1.0), bins=5)
    np.testing.assert_allclose(f.values, [-1, -0.5, 0, 0.5, 1])


def test_mean_downsample_averages_the_voxels_that_exist():
    rng = np.random.default_rng(3)
    data = rng.integers(0, 256, (5, 4, 3)).astype(np.uint8)
    out = mean_downsample(data)
    assert out.shape == (3, 2, 2) and out.dtype == np.uint8
    for idx in np.ndindex(out.shape):
        block = data[2 * idx[0]:2 * idx[0] + 2, 2 * idx[1]:2 * idx[1] + 2,
                     2 * idx[2]:2 * idx[2] + 2]
        assert out[idx] == np.floor(block.mean() + 0.5)


def test_approximate_is_trilinear_with_the_centroid_convention():
    rng = np.random.default_rng(4)
    coarse = rng.random((4, 5, 3))
    a, c = mean_pyramid_map(1)
    np.testing.assert_allclose(a, 0.5)
    np.testing.assert_allclose(c, -0.25)
    # Source voxels 2I and 2I + 1 sit at coarse coordinates I - 1/4 and I + 1/4.
    got = approximate(coarse, (2, 2, 2), (4, 4, 4), a, c)
    x = np.array([0.75, 1.25])
    lo = np.floor(x).astype(int)
    w = x - lo
    ref = np.zeros((2, 2, 2))
    for p, q, r in np.ndindex(2, 2, 2):
        for dx, dy, dz in np.ndindex(2, 2, 2):
            wt = ((w[p] if dx else 1 - w[p]) * (w[q] if dy else 1 - w[q])
                  * (w[r] if dz else 1 - w[r]))
            ref[p, q, r] += wt * coarse[lo[p] + dx, lo[q] + dy, lo[r] + dz]
    np.testing.assert_allclose(got, ref)


@pytest.fixture(scope="module")
def small_pyramid():
    src = smooth_volume((37, 29, 45), seed=1)
    tree = regular_brick_tree(src.shape, 8)
    levels = mean_pyramid(src, tree.grid.levels)
    q = Quantizer.for_data(src.dtype, (0, 255))
    return src, tree, levels, q, pyramid_histograms(levels, 8, q)


def _footprint(tree, node):
    grid = tree.grid
    lv = int(tree.level[node])
    idx = np.unravel_index(node - grid.level_offsets[lv], grid.level_bricks[lv])
    return lv, grid.footprint(lv, np.array(idx))


def test_histograms_count_every_source_voxel_once(small_pyramid):
    src, tree, levels, q, hist = small_pyramid
    counts = np.add.reduceat(hist.counts.astype(np.int64), hist.offsets[:-1].clip(
        max=hist.counts.size - 1)) * (hist.offsets[1:] > hist.offsets[:-1])
    inner = ~tree.is_leaf
    np.testing.assert_array_equal(counts[inner], tree.voxels[inner])
    assert np.all(counts[tree.is_leaf] == 0)
    for lv in range(1, tree.grid.levels):  # each level covers the whole source
        ids = slice(tree.grid.level_offsets[lv], tree.grid.level_offsets[lv + 1])
        assert counts[ids].sum() == src.size


def test_d_from_histograms_equals_d_from_voxels(small_pyramid):
    src, tree, levels, q, hist = small_pyramid
    table = distortion_table(TF, q.values)
    luv = classified_luv(TF, q.values)
    got = histogram_distortion(hist, table)
    inner = np.flatnonzero(~tree.is_leaf)
    assert inner.size >= 20
    for node in inner:
        lv, (lo, hi) = _footprint(tree, node)
        ref = voxel_distortion(src, levels[lv], lv, lo, hi, q.bin_of, luv)
        assert got[node] == pytest.approx(ref, rel=1e-12, abs=1e-9)
    assert np.all(got[tree.is_leaf] == 0)
    # And the one-brick numpy path agrees with the compiled one.
    node = inner[len(inner) // 2]
    lv, (lo, hi) = _footprint(tree, node)
    keys, counts = brick_histogram(src[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]],
                                   approximate(levels[lv], lo, hi, *mean_pyramid_map(lv)), q)
    np.testing.assert_array_equal(keys, hist.keys[hist.offsets[node]:hist.offsets[node + 1]])
    np.testing.assert_array_equal(counts, hist.counts[hist.offsets[node]:hist.offsets[node + 1]])


def test_float_volume_histograms_match_voxels():
    src = smooth_volume((21, 18, 17), seed=2, dtype=np.float32) / 255.0
    tree = regular_brick_tree(src.shape, 6)
    levels = [src] + mean_pyramid(src, tree.grid.levels)[1:]
    q = Quantizer.for_data(src.dtype, (float(src.min()), float(src.max())), bins=64)
    hist = pyramid_histograms(levels, 6, q)
    tf = sc.TransferFunction([(0.2, 0.0), (0.6, 0.8)], domain=(0, 1), colormap="viridis")
    got = histogram_distortion(hist, distortion_table(tf, q.values))
    luv = classified_luv(tf, q.values)
    for node in np.flatnonzero(~tree.is_leaf):
        lv, (lo, hi) = _footprint(tree, node)
        ref = voxel_distortion(src, levels[lv], lv, lo, hi, q.bin_of, luv)
        assert got[node] == pytest.approx(ref, rel=1e-9, abs=1e-9)


def test_histograms_of_double_bricks_are_sums_of_single_bricks(small_pyramid):
    src, tree, levels, q, hist = small_pyramid
    tree16 = regular_brick_tree(src.shape, 16)
    direct = pyramid_histograms(levels[:tree16.grid.levels], 16, q)
    summed = coarsen_histograms(hist, tree.grid, tree16.grid)
    np.testing.assert_array_equal(summed.offsets, direct.offsets)
    np.testing.assert_array_equal(summed.keys, direct.keys)
    np.testing.assert_array_equal(summed.counts, direct.counts)


def test_histograms_round_trip_through_plain_arrays(small_pyramid):
    hist = small_pyramid[4]
    back = BrickHistograms.from_arrays(hist.to_arrays())
    assert back.quantizer == hist.quantizer
    np.testing.assert_array_equal(back.keys, hist.keys)
    assert hist.keys.dtype == np.uint16 and hist.counts.dtype == np.uint32
    assert hist.quantizer.bins == 64
    assert hist.nbytes == hist.offsets.nbytes + 6 * hist.keys.size


def test_leaf_value_ranges_include_one_ghost_voxel():
    rng = np.random.default_rng(5)
    src = rng.integers(0, 256, (11, 9, 10)).astype(np.uint8)
    vmin, vmax = leaf_value_ranges(src, 4)
    assert vmin.shape == (3, 3, 3)
    for a, b, c in np.ndindex(vmin.shape):
        block = src[max(4 * a - 1, 0):4 * a + 5, max(4 * b - 1, 0):4 * b + 5,
                    max(4 * c - 1, 0):4 * c + 5]
        assert (vmin[a, b, c], vmax[a, b, c]) == (block.min(), block.max())


@pytest.mark.skipif(not MNI.exists(), reason=f"real data not present: {MNI}")
def test_mri_d_from_histograms_equals_d_from_voxels():
    vol = sc.read(MNI)
    src = np.ascontiguousarray(vol.data[60:124, 70:134, 50:114])  # a 64^3 crop, 16^3 bricks
    tree = regular_brick_tree(src.shape, 16)
    levels = mean_pyramid(src, tree.grid.levels)
    q = Quantizer.for_data(src.dtype, (0, 255), bins=256)  # exact 8-bit bins
    hist = pyramid_histograms(levels, 16, q)
    tf = sc.TransferFunction.load(Path(__file__).resolve().parents[1] / "examples"
                                  / "tf-mri.json")
    got = histogram_distortion(hist, distortion_table(tf, q.values))
    luv = classified_luv(tf, q.values)
    rng = np.random.default_rng(0)
    inner = np.flatnonzero(~tree.is_leaf)
    for node in rng.choice(inner, 6, replace=False):
        lv, (lo, hi) = _footprint(tree, node)
        ref = voxel_distortion(src, levels[lv], lv, lo, hi, q.bin_of, luv)
        assert got[node] == pytest.approx(ref, rel=1e-12)
