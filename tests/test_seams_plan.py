"""The seam plan's fast parts against direct computations.

- :func:`splinecast.multires.draw.seams._within_reach` (a k-d tree per class of box sizes) against
the
  gap of every pair of boxes;
- :func:`splinecast.multires.draw.seams._subdivided` (composed per-axis subdivision matrices)
against
  the chain of 3D :func:`~splinecast.multires.draw.seams.refine` steps it replaces;
- the incremental plan (changes reused while what they were computed from is the same) against a
  plan from scratch, frame by frame while bricks arrive (the scene test is in
  ``test_multires_render.py``).
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from splinecast.multires.draw.seams import _subdivided, _within_reach, refine


def _brute_force_pairs(q_lo, q_hi, lo, hi, radius):
    gap = np.maximum(np.maximum(lo[None] - q_hi[:, None], q_lo[:, None] - hi[None]), 0.0)
    which, box = np.nonzero(gap.max(axis=2) < radius)
    return set(zip(which.tolist(), box.tolist(), strict=True))


@pytest.mark.parametrize("seed", range(4))
def test_within_reach_finds_exactly_the_pairs_closer_than_the_radius(seed):
    rng = np.random.default_rng(seed)
    # Boxes of very different sizes (as a cut's levels), on half-voxel positions.
    sizes = 2.0 ** rng.integers(0, 6, size=300)
    lo = np.round(rng.uniform(0, 100, size=(300, 3)) * 2) / 2
    hi = lo + sizes[:, None] * rng.uniform(0.5, 1.0, size=(300, 3))
    q_lo = np.round(rng.uniform(0, 100, size=(120, 3)))
    q_hi = q_lo + rng.integers(1, 12, size=(120, 3))
    for radius in (1.0, 1.5, 2.0):
        which, box = _within_reach(q_lo, q_hi, lo, hi, radius)
        found = list(zip(which.tolist(), box.tolist(), strict=True))
        assert len(found) == len(set(found))
        expected = _brute_force_pairs(q_lo, q_hi, lo, hi, radius)
        assert set(found) == expected and len(expected) > 50


def test_within_reach_of_nothing_is_empty():
    which, box = _within_reach(np.zeros((2, 3)), np.ones((2, 3)), np.full((3, 3), 10.0),
                               np.full((3, 3), 11.0), 1.5)
    assert len(which) == len(box) == 0


def _tree(factors):
    """The two things of an octree :func:`_subdivided` reads: level positions and factors."""
    factors = np.array(factors, dtype=np.int64)
    return SimpleNamespace(factors=factors, position=lambda level: level)


@pytest.mark.parametrize("degree", [1, 3])
@pytest.mark.parametrize("factors", [[(1, 1, 1), (2, 2, 2), (4, 4, 4)],
                                     [(1, 1, 1), (2, 2, 1), (4, 4, 2), (8, 8, 4)]])
def test_subdivided_box_equals_the_chain_of_refinements(degree, factors):
    rng = np.random.default_rng(degree)
    tree = _tree(factors)
    coarse = len(factors) - 1
    array = rng.standard_normal((9, 8, 10))
    first = np.array([3, 5, 2])
    for fine in range(coarse):
        # The reference: the whole array refined level by level.
        block, start = array, first
        for p in range(coarse, fine, -1):
            block, start = refine(block, start, tree.factors[p] // tree.factors[p - 1], degree)
        end = start + np.array(block.shape) - 1
        for _ in range(5):
            box_lo = rng.integers(start, end + 1)
            box_hi = np.minimum(box_lo + rng.integers(0, 6, size=3), end)
            got = _subdivided(array, first, box_lo, box_hi, coarse, fine, tree, degree)
            if got is None:  # near the array's edges the masks may not fit
                continue
            want = block[tuple(slice(a - s, b - s + 1)
                               for a, b, s in zip(box_lo, box_hi, start, strict=True))]
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
        # The box's middle always fits.
        mid = (start + end) // 2
        got = _subdivided(array, first, mid, mid + 1, coarse, fine, tree, degree)
        assert got is not None and got.shape == (2, 2, 2)
        np.testing.assert_allclose(got, block[tuple(slice(m - s, m - s + 2)
                                                    for m, s in zip(mid, start, strict=True))],
                                   rtol=0, atol=1e-12)


def test_subdivided_refuses_a_box_the_array_does_not_reach():
    tree = _tree([(1, 1, 1), (2, 2, 2)])
    array = np.ones((6, 6, 6))
    assert _subdivided(array, np.zeros(3, np.int64), np.array([-4, 0, 0]), np.array([2, 2, 2]),
                       1, 0, tree, 3) is None
