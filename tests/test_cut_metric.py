"""Issue 11, items 1 and 4: importance, transparency, fix-up, ER and the lazily computed metric.

References: hand-computed distances for eqs. (5)-(6); the opacity of the transfer function sampled
densely over each node's value range for the transparency test; the whole-tree vectorized
computation (every node's E, then ER and the monotone clamp over arrays) for the per-node cached
one, including after a transfer-function edit (the hull-only update must give the same numbers).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from cut_reference import reference_priorities, smooth_volume

import splinecast as sc
from splinecast.multires.cut.histograms import Quantizer, leaf_value_ranges, pyramid_histograms
from splinecast.multires.cut.metric import (
    ArrayMetric,
    CutMetric,
    cut_error,
    histogram_distortion,
    importance,
    visible_nodes,
)
from splinecast.multires.cut.tree import BrickTree, regular_brick_tree
from splinecast.multires.store.mean_pyramid import mean_pyramid

UNIT = (np.zeros((1, 3)), np.ones((1, 3)))


def test_importance_of_a_point_and_an_eye():
    r_far = math.sqrt(3) / (math.sqrt(3) + 2)          # box [0,1]^3, PI 2 away along x
    assert importance(*UNIT, interest=(3, 0.5, 0.5))[0] == pytest.approx(r_far)
    assert importance(*UNIT, interest=(0.5, 0.2, 0.9))[0] == 1.0   # inside: d = 0
    both = importance(*UNIT, interest=(3, 0.5, 0.5), eye=(0.5, 0.5, 0.5))[0]
    assert both == pytest.approx(0.75 * r_far + 0.25 * 1.0)        # t = 1/4
    corner = importance(*UNIT, eye=(2, 2, 2))[0]                    # d = sqrt(3)
    assert corner == pytest.approx(0.5)
    assert importance(*UNIT)[0] == 1.0


def test_importance_of_a_region_averages_two_distances():
    region = ((2.0, 0.0, 0.0), (4.0, 1.0, 1.0))  # 1 away from the box, centre 2 away
    got = importance(*UNIT, region=region)[0]
    assert got == pytest.approx(math.sqrt(3) / (math.sqrt(3) + 1.5))


def test_importance_is_monotonic_down_a_pyramid_tree():
    tree = regular_brick_tree((40, 33, 27), 4)
    rng = np.random.default_rng(0)
    for _ in range(5):
        imp = importance(tree.box_min, tree.box_max, interest=rng.uniform(-10, 50, 3),
                         eye=rng.uniform(-60, 100, 3))
        child = np.flatnonzero(tree.parent >= 0)
        assert np.all(imp[child] <= imp[tree.parent[child]] + 1e-15)


def test_transparency_prefix_table_against_dense_opacity():
    tf = sc.TransferFunction([(30, 0.0), (60, 0.4), (90, 0.0), (200, 0.0), (230, 0.5)],
                             domain=(0, 255))
    rng = np.random.default_rng(1)
    parent = [-1] + [0] * 60
    lo = np.concatenate([[0.0], rng.uniform(0, 255, 60)])
    hi = np.concatenate([[255.0], lo[1:] + rng.exponential(20, 60)])
    tree = BrickTree.from_parents(parent, value_min=lo, value_max=hi)
    visible = visible_nodes(tree, tf)
    width = 255 / 1024  # one bin of the prefix table: the test's resolution
    for b in range(1, tree.size):
        dense = tf.opacity(np.linspace(lo[b], hi[b], 2000))
        inside = tf.opacity(np.linspace(lo[b] - width, hi[b] + width, 2000))
        if dense.max() > 0:
            assert visible[b]              # never hides something visible
        elif inside.max() == 0:
            assert not visible[b]          # transparent beyond a bin's slack
    assert visible[0]


def test_ranges_are_hierarchical_so_transparency_is():
    rng = np.random.default_rng(2)
    src = rng.integers(0, 256, (30, 20, 25)).astype(np.uint8)
    src[:16] //= 8  # a dark half: bricks there are transparent under the TF below
    vmin, vmax = leaf_value_ranges(src, 4)
    tree = regular_brick_tree(src.shape, 4, leaf_min=vmin, leaf_max=vmax)
    child = np.flatnonzero(tree.parent >= 0)
    assert np.all(tree.value_min[tree.parent[child]] <= tree.value_min[child])
    assert np.all(tree.value_max[tree.parent[child]] >= tree.value_max[child])
    visible = visible_nodes(tree, sc.TransferFunction([(40, 0.0), (60, 0.5)], domain=(0, 255)))
    assert np.all(visible[tree.parent[child[visible[child]]]])
    assert 0 < visible.sum() < tree.size


def test_error_reduction_and_monotone_clamp_by_hand():
    #      0 (E 10)
    #    1 (E 2)   2 (E 5)        3 is 1's child, 4 and 5 are 2's, 6 is 4's
    parent = [-1, 0, 0, 1, 2, 2, 4]
    tree = BrickTree.from_parents(parent)
    error = np.array([10, 2, 5, 0, 1, 0, 0], float)
    metric = ArrayMetric(tree, error)
    er = metric.error_reduction(np.arange(7))
    np.testing.assert_allclose(er[:3], [(10 - 7) / 2, 2.0, (5 - 1) / 2])
    assert er[4] == 1.0 and np.all(np.isneginf(er[[3, 5, 6]]))
    p = metric.priority(np.arange(7))
    np.testing.assert_allclose(p[:3], [1.5, 1.5, 1.5])  # children capped by the root's 1.5
    assert p[4] == 1.0
    naive = ArrayMetric(tree, error, improved=False).priority(np.arange(7))
    np.testing.assert_allclose(naive[:3], [10, 2, 5])
    # E(cut) divides by the voxels of the visible finest nodes (3, 5, 6 here: 1 voxel each).
    assert cut_error(tree, error, [1, 2], np.ones(7, bool)) == pytest.approx(7 / 3)


@pytest.mark.parametrize("seed", range(6))
def test_array_metric_matches_the_reference_on_random_trees(seed):
    from cut_reference import block_monotone_errors, hierarchical_visibility, random_parents

    rng = np.random.default_rng(seed)
    parent = random_parents(rng, 200)
    error = block_monotone_errors(rng, parent) if seed % 2 else rng.exponential(1, len(parent))
    visible = hierarchical_visibility(rng, parent)
    visible[0] = True
    tree = BrickTree.from_parents(parent)
    for improved in (False, True):
        er, prio = reference_priorities(parent, error, visible, improved)
        metric = ArrayMetric(tree, error, visible, improved)
        order = rng.permutation(tree.size)  # any query order: ancestors computed on demand
        np.testing.assert_allclose(metric.priority(order), prio[order])
        np.testing.assert_allclose(metric.error_reduction(order), er[order])


@pytest.fixture(scope="module")
def pyramid():
    src = smooth_volume((40, 36, 44), seed=3)
    vmin, vmax = leaf_value_ranges(src, 8)
    tree = regular_brick_tree(src.shape, 8, spacing=(1.0, 1.2, 0.8), leaf_min=vmin,
                              leaf_max=vmax)
    levels = mean_pyramid(src, tree.grid.levels)
    hist = pyramid_histograms(levels, 8, Quantizer.for_data(src.dtype, (0, 255)))
    return tree, hist


TF_A = sc.TransferFunction([(60, 0.0), (120, 0.3), (200, 0.9)], domain=(0, 255), colormap="hot")
TF_B = sc.TransferFunction([(90, 0.0), (110, 0.6), (150, 0.1)], domain=(0, 255),
                           colormap="viridis")


def _whole_tree_priorities(metric: CutMetric, improved: bool) -> tuple[np.ndarray, np.ndarray]:
    """Second code path: every node's D from the histograms at once (vectorized), the fix-up and
    E over whole arrays, then ER and the clamp node by node in Python (cut_reference)."""
    tree = metric.tree
    raw = histogram_distortion(metric.histograms, metric.table)
    kids_sum = np.zeros(tree.size)
    child = np.flatnonzero((tree.parent >= 0) & metric.visible)
    np.add.at(kids_sum, tree.parent[child], raw[child])
    fixed = np.maximum(raw, kids_sum)
    error = fixed * importance(tree.box_min, tree.box_max, metric.interest, metric.region,
                               metric.eye)
    _, prio = reference_priorities([int(p) for p in tree.parent], error, metric.visible, improved)
    return error, prio


@pytest.mark.parametrize("improved", [False, True])
def test_lazy_hull_priorities_equal_the_whole_tree_computation(pyramid, improved):
    tree, hist = pyramid
    metric = CutMetric(tree, hist, TF_A, interest=(10, 30, 5), eye=(-50, 20, 20),
                       improved=improved)
    hull = np.array([tree.root, *tree.children_of(tree.root)[:3]])
    lazy = metric.priority(hull)               # computed for these nodes (and ancestors) only
    state = metric._state  # noqa: SLF001 - checking laziness
    assert (state.raw_at == metric.tf_epoch).sum() < tree.size
    error, full = _whole_tree_priorities(CutMetric(tree, hist, TF_A, interest=(10, 30, 5),
                                                   eye=(-50, 20, 20), improved=improved),
                                         improved)
    np.testing.assert_allclose(lazy, full[hull], rtol=1e-12)
    # After a transfer-function edit and a view change, the cached values are refreshed.
    metric.set_transfer_function(TF_B)
    metric.set_view(region=((0, 0, 0), (10, 10, 10)), eye=(100, 0, 0))
    some = np.flatnonzero(metric.visible)[::7]
    reference = CutMetric(tree, hist, TF_B, region=((0, 0, 0), (10, 10, 10)), eye=(100, 0, 0),
                          improved=improved)
    error_b, full_b = _whole_tree_priorities(reference, improved)
    np.testing.assert_allclose(metric.priority(some), full_b[some], rtol=1e-12)
    np.testing.assert_allclose(metric.error(some), error_b[some], rtol=1e-12)


def test_fix_up_makes_parents_at_least_their_childrens_sum(pyramid):
    tree, hist = pyramid
    metric = CutMetric(tree, hist, TF_A)
    fixed = metric.update_all_distortions()
    raw = metric.raw_distortion(np.arange(tree.size))
    assert np.all(fixed >= raw)
    for b in np.flatnonzero(~tree.is_leaf & metric.visible):
        kids = tree.children_of(b)
        kids = kids[metric.visible[kids]]
        assert fixed[b] >= raw[kids].sum() - 1e-9
        if raw[b] >= raw[kids].sum():
            assert fixed[b] == raw[b]
    assert np.all(fixed[tree.is_leaf] == 0)
