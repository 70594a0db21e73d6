"""Issue 11, item 5: the extended cut S+ that orders the paging loader's work.

References: a greedy refinement written here from the definition (a heap over the tree, a split
costing its visible children in a cache that holds the cut and all its ancestors), leaf-by-leaf
validity, and direct checks of the pinning rule on every plan.
"""

from __future__ import annotations

import heapq

import numpy as np
import pytest
from cut_reference import (
    block_monotone_errors,
    hierarchical_visibility,
    is_valid_cut,
    random_parents,
)

from splinecast.multires.cut.metric import ArrayMetric
from splinecast.multires.cut.paging import ExtendedCut
from splinecast.multires.cut.tree import BrickTree
from splinecast.multires.cut.update import CutUpdater


def _case(seed):
    rng = np.random.default_rng(seed)
    parent = random_parents(rng, int(rng.integers(60, 400)), complete=seed % 2 == 0,
                            depth=int(rng.integers(3, 5)))
    visible = hierarchical_visibility(rng, parent, 0.85)
    visible[0] = True
    error = block_monotone_errors(rng, parent)
    return rng, parent, BrickTree.from_parents(parent), visible, error


def greedy_with_ancestors(parent, visible, priority, rank, capacity):
    """Greedy refinement where the cut and every ancestor occupy the cache."""
    kids = [[] for _ in parent]
    for node, p in enumerate(parent):
        if p >= 0 and visible[node]:
            kids[p].append(node)
    heap = [(-priority[0], rank[0], 0)]
    cached = 1
    while heap:
        neg, _, node = heap[0]
        if not -neg > 0 or cached + len(kids[node]) > capacity:
            break
        heapq.heappop(heap)
        cached += len(kids[node])
        for k in kids[node]:
            heapq.heappush(heap, (-priority[k], rank[k], k))
    return sorted(n for _, _, n in heap)


@pytest.mark.parametrize("seed", range(8))
def test_first_plan_from_the_root_is_the_greedy_extended_cut(seed):
    rng, parent, tree, visible, error = _case(seed)
    metric = ArrayMetric(tree, error, visible)
    capacity = int(rng.integers(5, 120))
    ext = ExtendedCut(metric, capacity, render_cut=[tree.root])
    plan = ext.plan()
    expected = greedy_with_ancestors(parent, visible, metric.priority(np.arange(tree.size)),
                                     metric.rank, capacity)
    assert sorted(ext.cut) == expected
    assert is_valid_cut(parent, visible, sorted(ext.cut))
    assert ext.cached.sum() <= capacity
    np.testing.assert_array_equal(np.sort(plan.downloads), np.flatnonzero(ext.cached)[1:])
    # Loads come in split order: their parents' priorities never increase.
    p = metric.priority(tree.parent[plan.downloads])
    assert np.all(np.diff(p) <= 1e-12)


@pytest.mark.parametrize("seed", range(8))
def test_loader_and_renderer_together_never_evict_the_rendering_cut(seed):
    rng, parent, tree, visible, error = _case(100 + seed)
    metric = ArrayMetric(tree, error, visible)
    loader_metric = ArrayMetric(tree, error, visible)  # the loader's own instance
    budget = int(rng.integers(4, 40))
    capacity = budget + int(rng.integers(budget // 2 + 8, 3 * budget + 10))
    renderer = CutUpdater(metric, budget=budget, load_budget=int(rng.integers(8, 16)))
    ext = ExtendedCut(loader_metric, capacity, render_cut=[tree.root], loads_per_plan=10)
    in_ram = ext.cached.copy()
    for frame_no in range(40):
        if frame_no % 8 == 7:
            error = block_monotone_errors(rng, parent)
            metric.set(error, visible)
            loader_metric.set(error, visible)
        frame = renderer.update(in_ram=in_ram)
        assert in_ram[frame.cut].all()                 # splits only into RAM
        ext.set_render_cut(frame.cut)
        plan = ext.plan()
        assert plan.downloads.size <= 10
        pinned = np.zeros(tree.size, bool)
        pinned[frame.cut] = True
        pinned[tree.ancestors_of(frame.cut)] = True
        assert not pinned[plan.evicted].any()          # S and its ancestors stay in RAM
        assert ext.cached[pinned].all()
        assert is_valid_cut(parent, visible, sorted(ext.cut))
        if plan.stop == "brick budget":
            assert ext.cached.sum() <= capacity
        in_ram = ext.cached.copy()                     # the loader carried the plan out


def test_prefetch_order_respects_the_limit():
    rng, parent, tree, visible, error = _case(3)
    ext = ExtendedCut(ArrayMetric(tree, error, visible), 200, render_cut=[tree.root])
    first = ext.prefetch_order(5)
    assert 0 < first.size <= 5
    second = ext.prefetch_order(5)
    assert not set(first) & set(second)
