"""Issue 11, items 3 and 4: split-and-collapse updates, partial sorting, transfer-function repair.

References: a plain sorted list for the partial queue; leaf-by-leaf validity checks and budget
counts for every frame; the greedy selection from the root (an independent code path: a heap over
the whole tree) for the fixed point of the updates; hand traces on the paper's Fig. 2 tree for the
stop conditions.
"""

from __future__ import annotations

import numpy as np
import pytest
from cut_reference import (
    block_monotone_errors,
    hierarchical_visibility,
    is_valid_cut,
    random_parents,
    smooth_volume,
)
from test_cut_select import FIG2_NAMES, fig2, names

import splinecast as sc
from splinecast.multires.cut.histograms import Quantizer, leaf_value_ranges, pyramid_histograms
from splinecast.multires.cut.metric import ArrayMetric, CutMetric
from splinecast.multires.cut.partial_queue import PartialQueue
from splinecast.multires.cut.select import greedy_cut
from splinecast.multires.cut.tree import BrickTree, regular_brick_tree
from splinecast.multires.cut.update import CutUpdater
from splinecast.multires.store.mean_pyramid import mean_pyramid


def ids(*letters):
    return [FIG2_NAMES.index(x) for x in letters]


# ------------------------------------------------------------------------------- partial queue
@pytest.mark.parametrize("capacity", [1, 3, 8])
def test_partial_queue_pops_in_key_order(capacity):
    rng = np.random.default_rng(capacity)
    queue = PartialQueue(capacity, 1000)
    reference: dict[int, tuple[float, int]] = {}
    nodes = np.arange(40)
    keys = rng.integers(0, 6, 40).astype(float)  # many ties on the primary key
    queue.rebuild(nodes, keys, -nodes)
    reference.update({int(n): (float(k), int(-n)) for n, k in zip(nodes, keys, strict=True)})
    fresh = 40
    for _ in range(400):
        op = rng.integers(0, 3)
        if op == 0:
            key = (float(rng.integers(0, 6)), -fresh)
            queue.push(fresh, key)
            reference[fresh] = key
            fresh += 1
        elif op == 1 and reference:
            victim = int(rng.choice(list(reference)))
            queue.remove(victim)
            del reference[victim]
        elif reference:
            key, node = queue.pop()
            best = min(reference, key=lambda n: (reference[n], n))
            assert node == best and key == reference.pop(best)
        assert len(queue) == len(reference)
        assert len(queue._a) <= capacity  # noqa: SLF001 - the sorted part stays within M
    assert sorted(queue.nodes().tolist()) == sorted(reference)
    for node, key in reference.items():
        assert queue.key(node) == key


def test_a_frame_sorts_each_queue_once():
    """O(N + M log M) per re-prioritisation: one partial sort of S and one of C when the
    priorities change, none when nothing changed."""
    rng, parent, tree, visible = _case(3, max_nodes=400)
    error = block_monotone_errors(rng, parent)
    metric = ArrayMetric(tree, error, visible)
    updater = CutUpdater(metric, budget=60, load_budget=None)
    _run_until_stable(updater, [int(p) for p in tree.parent], visible, 60, None)
    before = (updater.split_queue.partial_sorts, updater.collapse_queue.partial_sorts)
    metric.set(error * 1.5, visible)  # new priorities (same order): re-prioritise, no operation
    frame = updater.update()
    after = (updater.split_queue.partial_sorts, updater.collapse_queue.partial_sorts)
    assert frame.splits == frame.collapses == 0
    assert after == (before[0] + 1, before[1] + 1)
    updater.update()  # nothing changed: no re-prioritisation at all
    assert (updater.split_queue.partial_sorts, updater.collapse_queue.partial_sorts) == after


# ------------------------------------------------------------------------- stop conditions
def test_zero_error_stops_first():
    tree, _ = fig2()
    updater = CutUpdater(ArrayMetric(tree, np.zeros(tree.size)), budget=10, load_budget=0)
    frame = updater.update()
    assert frame.stop == "zero error" and frame.splits == 0 and list(frame.cut) == [tree.root]


def test_load_budget_stops_a_split_that_needs_more_downloads():
    tree, error = fig2()
    frame = CutUpdater(ArrayMetric(tree, error), budget=10, load_budget=1).update()
    assert frame.stop == "load budget" and list(frame.cut) == [tree.root]
    assert frame.downloads.size == 0


def test_collapse_makes_room_for_a_better_split():
    """Fig. 2, improved priorities, N = 3, from the cut {D, E, C}: head C (1.5) needs a fourth
    brick; the lowest collapsible parent B (1) ranks below, so B is collapsed, C split, giving
    {B, F, G}; then B heads (1, shallowest of the ties), C (1.5) does not rank below: stop 3."""
    tree, error = fig2()
    updater = CutUpdater(ArrayMetric(tree, error), budget=3, cut=ids("D", "E", "C"))
    frame = updater.update()
    assert names(frame.cut) == {"B", "F", "G"}
    assert (frame.splits, frame.collapses, frame.stop) == (1, 1, "brick budget")
    assert set(frame.downloads) == set(ids("B", "F", "G"))
    assert set(frame.evicted) == set(ids("D", "E", "C"))


def test_no_collapse_when_the_split_it_enables_exceeds_the_load_budget():
    tree, error = fig2()
    # Collapsing B (1 download) and splitting C (F, G: 2 downloads) needs 3 > 2.
    updater = CutUpdater(ArrayMetric(tree, error), budget=3, load_budget=2,
                         cut=ids("D", "E", "C"))
    frame = updater.update()
    assert names(frame.cut) == {"D", "E", "C"} and frame.stop == "brick budget"
    assert frame.collapses == 0


# ------------------------------------------------------------------------------ random trees
def _case(seed, max_nodes=300):
    rng = np.random.default_rng(seed)
    parent = random_parents(rng, int(rng.integers(40, max_nodes)), complete=seed % 3 == 0,
                            depth=int(rng.integers(3, 5)))
    visible = hierarchical_visibility(rng, parent, 0.8)
    visible[0] = True
    return rng, parent, BrickTree.from_parents(parent), visible


def _run_until_stable(updater, parent, visible, budget, load, frames=300):
    for _ in range(frames):
        frame = updater.update()
        assert is_valid_cut(parent, visible, frame.cut)
        assert len(frame.cut) <= budget
        if load is not None:
            assert frame.downloads.size <= load
        if frame.splits == 0 and frame.collapses == 0:
            return frame
    raise AssertionError("the updates did not settle")


@pytest.mark.parametrize("seed", range(10))
@pytest.mark.parametrize("improved", [False, True])
def test_updates_converge_to_the_greedy_cut(seed, improved):
    rng, parent, tree, visible = _case(seed)
    error = block_monotone_errors(rng, parent)
    metric = ArrayMetric(tree, error, visible, improved=improved)
    budget = int(rng.integers(2, 60))
    target = greedy_cut(metric, budget)
    # From the root, from the finest possible cut collapsed to fit, and under a load budget.
    for start in (None, greedy_cut(ArrayMetric(tree, error[::-1].copy(), visible), budget)):
        updater = CutUpdater(metric, budget=budget, load_budget=None, cut=start)
        frame = _run_until_stable(updater, parent, visible, budget, None)
        np.testing.assert_array_equal(frame.cut, target)
    load = int(rng.integers(8, 20))  # at least the most children, so every split can happen
    updater = CutUpdater(metric, budget=budget, load_budget=load)
    frame = _run_until_stable(updater, parent, visible, budget, load)
    np.testing.assert_array_equal(frame.cut, target)


@pytest.mark.parametrize("seed", range(8))
def test_changing_priorities_and_visibility_keep_every_frame_within_budgets(seed):
    rng, parent, tree, visible = _case(100 + seed)
    error = block_monotone_errors(rng, parent)
    budget, load = int(rng.integers(8, 50)), int(rng.integers(8, 24))
    metric = ArrayMetric(tree, error, visible)
    updater = CutUpdater(metric, budget=budget, load_budget=load)
    for frame_no in range(60):
        if frame_no % 10 == 9:  # a "transfer-function edit": new visibility and new errors
            visible = hierarchical_visibility(rng, parent, rng.uniform(0.4, 0.95))
            visible[0] = True
        error = block_monotone_errors(rng, parent)  # a "view change": new errors
        metric.set(error, visible)
        frame = updater.update()
        assert is_valid_cut(parent, visible, frame.cut)
        if not frame.over_budget:
            assert len(frame.cut) <= budget and frame.downloads.size <= load
        resident_before = set(frame.cut) - set(frame.downloads)
        assert resident_before.isdisjoint(frame.evicted)
    # Once the inputs stop changing, the cut settles on the greedy cut (block-monotone errors:
    # positive priorities, so the fixed point is unique).
    frame = _run_until_stable(updater, parent, visible, budget, load)
    np.testing.assert_array_equal(frame.cut, greedy_cut(metric, budget))


def test_transfer_function_repair_follows_the_paper():
    """Fig. 2 with Q made transparent and then L: removal, mark, top-down insertion."""
    tree, error = fig2()
    metric = ArrayMetric(tree, error)
    updater = CutUpdater(metric, budget=5, cut=ids("D", "E", "F", "Q"))
    visible = np.ones(tree.size, bool)
    visible[ids("Q", "G")] = False  # G's only child goes transparent: G too
    metric.set(error, visible)
    frame = updater.update()
    assert frame.repaired and not set(frame.cut) & set(ids("Q", "G"))
    assert is_valid_cut([int(p) for p in tree.parent], visible, frame.cut)
    visible[:] = True
    visible[ids("D", "H", "I")] = False
    metric.set(error, visible)
    frame = updater.update()
    # D's region is gone; G and Q are back: G is the unmarked node met below marked C.
    assert not set(frame.cut) & set(ids("D", "H", "I"))
    assert is_valid_cut([int(p) for p in tree.parent], visible, frame.cut)


def test_splits_wait_for_children_in_ram():
    tree, error = fig2()
    in_ram = np.zeros(tree.size, bool)
    in_ram[ids("A", "B", "C")] = True
    updater = CutUpdater(ArrayMetric(tree, error), budget=10)
    frame = updater.update(in_ram=in_ram)
    assert names(frame.cut) == {"B", "C"}   # D, E, F, G not in RAM: no further split
    in_ram[:] = True
    frame = updater.update(in_ram=in_ram)
    assert names(frame.cut) == {"H", "I", "J", "K", "L", "P", "Q"}


# ---------------------------------------------------------------------- a real brick pyramid
def test_frames_on_a_pyramid_with_moving_interest_and_tf_edits():
    src = smooth_volume((64, 48, 56), seed=7)
    vmin, vmax = leaf_value_ranges(src, 8)
    tree = regular_brick_tree(src.shape, 8, leaf_min=vmin, leaf_max=vmax)
    levels = mean_pyramid(src, tree.grid.levels)
    hist = pyramid_histograms(levels, 8, Quantizer.for_data(src.dtype, (0, 255)))
    parent = [int(p) for p in tree.parent]
    points = [[60.0, 0.0], [120.0, 0.5], [200.0, 0.9]]  # (value, alpha)
    tf = sc.TransferFunction(points, domain=(0, 255), colormap="bone")
    metric = CutMetric(tree, hist, tf, interest=(32, 24, 28), eye=(-100, 24, 28))
    budget, load = 120, 24
    updater = CutUpdater(metric, budget=budget, load_budget=load)
    rng = np.random.default_rng(0)
    interest = np.array([32.0, 24.0, 28.0])
    for frame_no in range(40):
        if frame_no < 20:
            interest = np.clip(interest + rng.normal(0, 4, 3), 0, [63, 47, 55])
            metric.set_view(interest=interest, eye=(-100, 24, 28))
        else:
            k = int(rng.integers(0, 3))
            points[k][0] = float(np.clip(points[k][0] + rng.normal(0, 8), 1, 254))
            points[k][1] = float(np.clip(points[k][1] + rng.normal(0, 0.2), 0, 1))
            pts = sorted(points, key=lambda p: p[0])
            metric.set_transfer_function(sc.TransferFunction(pts, domain=(0, 255),
                                                             colormap="bone"))
        frame = updater.update()
        assert is_valid_cut(parent, metric.visible, frame.cut)
        if not frame.over_budget:
            assert len(frame.cut) <= budget and frame.downloads.size <= load
    frame = _run_until_stable(updater, parent, metric.visible, budget, load)
    np.testing.assert_array_equal(frame.cut, greedy_cut(metric, budget))


# ----------------------------------------------------------------------------------- fill
def test_fill_sets_a_large_split_aside_and_takes_a_smaller_one():
    """Root with A (8 children) and B (2 children), N = 4: the paper's rule stops at A (it needs
    7 more bricks); with ``fill`` A is set aside and B, which fits, is split."""
    parent = [-1, 0, 0] + [1] * 8 + [2] * 2
    tree = BrickTree.from_parents(parent)
    error = np.zeros(tree.size)
    error[0], error[1], error[2] = 100.0, 50.0, 10.0  # ER(A) = 50/8 > ER(B) = 10/2 > 0
    paper = CutUpdater(ArrayMetric(tree, error), budget=4).update()
    assert sorted(paper.cut.tolist()) == [1, 2] and paper.stop == "brick budget"
    filled = CutUpdater(ArrayMetric(tree, error), budget=4, fill=True).update()
    assert sorted(filled.cut.tolist()) == [1, 11, 12] and filled.stop == "brick budget"
    # Under a load budget too: A's 8 downloads exceed M = 3, B's 2 do not.
    loads = CutUpdater(ArrayMetric(tree, error), budget=20, load_budget=3, cut=[1, 2],
                       fill=True).update()
    assert sorted(loads.cut.tolist()) == [1, 11, 12] and loads.stop == "load budget"


@pytest.mark.parametrize("seed", range(10))
def test_fill_frames_respect_the_budgets_and_settle_no_worse_than_the_paper_rule(seed):
    """Every frame valid within N and M; the settled cut is never worse than the paper rule's
    fixed point (the greedy cut) and never better than the optimum."""
    from splinecast.multires.cut.select import optimal_cut

    rng, parent, tree, visible = _case(300 + seed)
    error = block_monotone_errors(rng, parent)
    metric = ArrayMetric(tree, error, visible)
    budget = int(rng.integers(2, 60))
    load = int(rng.integers(8, 20))  # at least the most children, so every split can happen
    for m in (None, load):
        updater = CutUpdater(metric, budget=budget, load_budget=m, fill=True)
        frame = _run_until_stable(updater, parent, visible, budget, m)
        total = error[frame.cut].sum()
        assert total <= error[greedy_cut(metric, budget)].sum() * (1 + 1e-12) + 1e-12
        assert total >= optimal_cut(tree, error, visible, budget)[1] * (1 - 1e-12) - 1e-12
