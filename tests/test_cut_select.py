"""Issue 11, item 2: greedy and optimal cut selection.

References: the trace of the paper's Fig. 2 (every node's table of optimal cuts, N = 3), brute-force
enumeration of every cut on small random trees, hand-derived greedy runs on Fig. 2, the greedy
refinement replayed step by step from its definition (``cut_reference.reference_greedy``), and the
greedy's distance to the brute-force optimum over a fixed sample of random trees.
"""

from __future__ import annotations

import numpy as np
import pytest
from cut_reference import (
    all_cuts,
    block_monotone_errors,
    cuts_within,
    hierarchical_visibility,
    is_valid_cut,
    random_parents,
    reference_greedy,
)

from splinecast.multires.cut.metric import ArrayMetric
from splinecast.multires.cut.select import (
    greedy_cut,
    optimal_cut,
    optimal_cut_errors,
    optimal_update,
)
from splinecast.multires.cut.tree import BrickTree

# Fig. 2 of reference 002: a binary tree (G has a single child Q) with errors E at inner nodes.
FIG2_NAMES = "A B C D E F G H I J K L P Q".split()
FIG2_PARENT = {"B": "A", "C": "A", "D": "B", "E": "B", "H": "D", "I": "D", "J": "E", "K": "E",
               "F": "C", "G": "C", "L": "F", "P": "F", "Q": "G"}
FIG2_ERROR = {"A": 16, "B": 7, "C": 6, "D": 3, "E": 2, "F": 2, "G": 1}
# The black (optimal) tuples of the trace: node -> {m: E-bar} for N = 3.
FIG2_TABLES = {
    "H": {1: 0}, "I": {1: 0}, "D": {1: 3, 2: 0}, "J": {1: 0}, "K": {1: 0}, "E": {1: 2, 2: 0},
    "B": {1: 7, 2: 5, 3: 2}, "L": {1: 0}, "P": {1: 0}, "F": {1: 2, 2: 0}, "Q": {1: 0},
    "G": {1: 0}, "C": {1: 6, 2: 2, 3: 0}, "A": {1: 16, 2: 13, 3: 9},
}


def fig2():
    parent = [FIG2_NAMES.index(FIG2_PARENT[n]) if n in FIG2_PARENT else -1 for n in FIG2_NAMES]
    error = np.array([FIG2_ERROR.get(n, 0) for n in FIG2_NAMES], float)
    return BrickTree.from_parents(parent), error


def names(cut):
    return {FIG2_NAMES[i] for i in cut}


def test_fig2_optimum_is_bfq():
    tree, error = fig2()
    cut, total = optimal_cut(tree, error, None, 3)
    assert names(cut) == {"B", "F", "Q"} and len(cut) == 3 and total == 9


@pytest.mark.parametrize("node", list(FIG2_TABLES))
def test_fig2_every_node_table_matches_the_trace(node):
    tree, error = fig2()
    row = optimal_cut_errors(tree, error, None, 3, root=FIG2_NAMES.index(node))
    expected = np.full(4, np.inf)
    for m, e in FIG2_TABLES[node].items():
        expected[m] = e
    np.testing.assert_array_equal(row, expected)


def test_fig2_greedy_runs():
    """Hand-derived. Naive (P = E): split A (16) -> {B 7, C 6}; split B -> {D, E, C}; C's split
    needs 4 > 3 bricks: stop, sum 3 + 2 + 6 = 11. Improved (P = ER): ER(A) = (16 - 13)/2 = 1.5;
    then ER(B) = 1, ER(C) = 1.5: split C -> {B, F, G}; now B, F, G all have priority 1 (F and G
    capped by C's 1.5, unchanged), B ranks first (shallower) and needs 4 > 3: stop, sum 10."""
    tree, error = fig2()
    naive = greedy_cut(ArrayMetric(tree, error, improved=False), 3)
    improved = greedy_cut(ArrayMetric(tree, error, improved=True), 3)
    assert names(naive) == {"C", "D", "E"} and error[naive].sum() == 11
    assert names(improved) == {"B", "F", "G"} and error[improved].sum() == 10
    # Filling: B and F are set aside (4 bricks), G's single child fits: {B, F, Q}, the optimum.
    filled = greedy_cut(ArrayMetric(tree, error, improved=True), 3, fill=True)
    assert names(filled) == {"B", "F", "Q"} and error[filled].sum() == 9


def test_fig2_download_aware_optimum():
    tree, error = fig2()
    resident = np.isin(np.arange(tree.size), [FIG2_NAMES.index("B"), FIG2_NAMES.index("C")])
    # From the resident cut {B, C}: one download cannot replace C by anything of its subtree
    # (every cut of it has two bricks, none resident); two downloads reach {B, F, Q} (F, Q new).
    one = optimal_update(tree, error, None, 3, 1, resident)
    two = optimal_update(tree, error, None, 3, 2, resident)
    assert names(one[0]) == {"B", "C"} and one[1] == 13
    assert names(two[0]) == {"B", "F", "Q"} and two[1] == 9  # F and Q: two downloads
    assert optimal_update(tree, error, None, 3, 0, np.zeros(tree.size, bool)) is None


def _random_case(rng, max_nodes, complete=False, max_children=8):
    parent = random_parents(rng, max_nodes, max_children=max_children, complete=complete,
                            depth=int(rng.integers(2, 5)))
    error = block_monotone_errors(rng, parent)
    visible = hierarchical_visibility(rng, parent, 0.75)
    visible[0] = True
    return parent, BrickTree.from_parents(parent), error, visible


@pytest.mark.parametrize("seed", range(12))
def test_optimum_never_worse_than_greedy_and_cuts_are_valid(seed):
    rng = np.random.default_rng(seed)
    parent, tree, error, visible = _random_case(rng, int(rng.integers(30, 400)),
                                                complete=seed % 3 == 0)
    budget = int(rng.integers(1, 80))
    cut, total = optimal_cut(tree, error, visible, budget)
    assert is_valid_cut(parent, visible, cut) and len(cut) <= budget
    assert total == pytest.approx(error[cut].sum())
    for improved in (False, True):
        metric = ArrayMetric(tree, error, visible, improved=improved)
        greedy = greedy_cut(metric, budget)
        filled = greedy_cut(metric, budget, fill=True)
        for cut_ in (greedy, filled):
            assert is_valid_cut(parent, visible, cut_) and len(cut_) <= budget
            assert total <= error[cut_].sum() + 1e-9
        # Filling only adds splits of positive priority, each lowering the error (block-
        # monotone errors), so it never does worse than stopping.
        assert error[filled].sum() <= error[greedy].sum() + 1e-9


@pytest.mark.parametrize("seed", range(25))
def test_optimum_equals_brute_force_on_small_trees(seed):
    rng = np.random.default_rng(100 + seed)
    parent, tree, error, visible = _random_case(rng, int(rng.integers(5, 22)),
                                                max_children=int(rng.integers(2, 5)))
    if seed % 2:
        error = rng.exponential(1.0, tree.size)  # arbitrary errors: no monotonicity assumed
    cuts = all_cuts(parent, visible)
    budget = int(rng.integers(1, 12))
    best = min(error[list(c)].sum() for c in cuts if len(c) <= budget)
    cut, total = optimal_cut(tree, error, visible, budget)
    assert total == pytest.approx(best, abs=1e-12)
    assert tuple(sorted(cut)) in {tuple(sorted(c)) for c in cuts}
    # The download-aware optimum against the same enumeration, from a random resident cut.
    previous = cuts[int(rng.integers(len(cuts)))]
    resident = np.isin(np.arange(tree.size), previous)
    load = int(rng.integers(0, 6))
    feasible = [c for c in cuts if len(c) <= budget and sum(not resident[b] for b in c) <= load]
    result = optimal_update(tree, error, visible, budget, load, resident)
    if not feasible:
        assert result is None
    else:
        assert result[1] == pytest.approx(min(error[list(c)].sum() for c in feasible), abs=1e-12)
        assert len(result[0]) <= budget and np.count_nonzero(~resident[result[0]]) <= load
        assert tuple(sorted(result[0])) in {tuple(sorted(c)) for c in cuts}


def test_download_aware_optimum_without_a_load_limit_is_the_optimum():
    rng = np.random.default_rng(7)
    parent, tree, error, visible = _random_case(rng, 120)
    cut, total = optimal_cut(tree, error, visible, 20)
    capped = optimal_update(tree, error, visible, 20, 20, np.zeros(tree.size, bool))
    assert capped[1] == pytest.approx(total)


# ----------------------------------------------------------------- the greedy against brute force
@pytest.mark.parametrize("seed", range(12))
def test_greedy_cut_follows_its_definition_step_by_step(seed):
    """:func:`greedy_cut` equals the refinement replayed from the definition (priorities of eq. 9
    clamped down the tree, ties by depth then id, the paper's stop rule or ``fill``)."""
    rng = np.random.default_rng(500 + seed)
    parent, tree, error, visible = _random_case(rng, int(rng.integers(30, 300)),
                                                complete=seed % 3 == 0)
    budget = int(rng.integers(1, 60))
    for improved in (False, True):
        metric = ArrayMetric(tree, error, visible, improved=improved)
        for fill in (False, True):
            expected = reference_greedy(parent, error, visible, budget, improved, fill)
            assert greedy_cut(metric, budget, fill=fill).tolist() == expected


def _gap_sample(count: int = 300, seed: int = 2024):
    """The fixed sample of the gap test: trees of 10..80 nodes with 1..8 children (30% complete),
    block-monotone errors, 80% visible leaves, budgets of 1..23 bricks."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        parent = random_parents(rng, int(rng.integers(10, 80)),
                                max_children=int(rng.integers(2, 9)),
                                complete=bool(rng.random() < 0.3), depth=int(rng.integers(2, 5)))
        error = block_monotone_errors(rng, parent)
        visible = hierarchical_visibility(rng, parent, 0.8)
        visible[0] = True
        yield parent, error, visible, int(rng.integers(1, 24))


# (improved, fill) -> (largest mean missed share, smallest share of trees at the optimum).
# Measured on this sample: mean missed share 0.0363 / 0.0064 / 0.0280 / 0.0107 and at the
# optimum 75.3% / 90.7% / 79.3% / 91.0% (naive, naive + fill, improved, improved + fill); on
# 2000 other trees 0.0305 / 0.0042 / 0.0205 / 0.0092 and 79% / 94% / 83% / 92%. Bounds: 1.2x the
# mean, the share at the optimum less 5 points.
GAP_BOUNDS = {(False, False): (0.044, 0.70), (False, True): (0.0077, 0.85),
              (True, False): (0.034, 0.74), (True, True): (0.013, 0.86)}


def test_greedy_cut_is_near_the_brute_force_optimum():
    """How far the greedy cut (the oracle of the update and render tests) is from the optimum.

    The gap is the share of the best possible error reduction the greedy misses,
    ``(E_greedy - E_opt) / (E_root - E_opt)`` (Table 3 of Carmona & Froehlich 2011 reports its
    complement: 88.6-94.2% of the optimal reduction for the improved priority). The optimum
    comes from enumerating every cut within the budget (:func:`cut_reference.cuts_within`), not
    from :func:`optimal_cut`. The greedy has no worst-case guarantee (one large split that does
    not fit stops it, or with ``fill`` blocks the smaller splits below it): single trees of the
    sample miss up to 73% of the reduction, so the bounds are on the sample's mean and on how many
    trees reach the optimum exactly (see ``GAP_BOUNDS``)."""
    missed: dict[tuple[bool, bool], list[float]] = {key: [] for key in GAP_BOUNDS}
    for parent, error, visible, budget in _gap_sample():
        tree = BrickTree.from_parents(parent)
        best = min(error[list(c)].sum() for c in cuts_within(parent, visible, budget))
        for improved, fill in GAP_BOUNDS:
            cut = greedy_cut(ArrayMetric(tree, error, visible, improved=improved), budget,
                             fill=fill)
            total = error[cut].sum()
            assert is_valid_cut(parent, visible, cut) and len(cut) <= budget
            assert best <= total + 1e-9
            missed[improved, fill].append((total - best) / (error[0] - best)
                                          if error[0] > best else 0.0)
    for key, (mean_bound, exact_bound) in GAP_BOUNDS.items():
        share = np.asarray(missed[key])
        assert share.mean() <= mean_bound, (key, share.mean())
        assert np.mean(share <= 1e-12) >= exact_bound, (key, np.mean(share <= 1e-12))
