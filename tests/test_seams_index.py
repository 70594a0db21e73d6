"""The seam plan's broad phase (:class:`splinecast.multires.seams.BoxIndex`) against testing
every box: the boxes it returns for a query include every box that meets it."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("zarr", reason="the multires extra (zarr) is not installed")

from splinecast.multires.seams import BoxIndex  # noqa: E402


def _octree_partition(rng: np.random.Generator, n: int = 64, leaf: int = 4) -> tuple:
    """A random partition of [0, n]^3 into octree boxes of sizes leaf .. n/2."""
    boxes = [(np.zeros(3), np.full(3, float(n)))]
    out = []
    while boxes:
        lo, hi = boxes.pop()
        size = hi[0] - lo[0]
        if size > leaf and (size > n / 2 or rng.random() < 0.6):
            half = size / 2
            for corner in np.indices((2, 2, 2)).reshape(3, -1).T:
                c = lo + corner * half
                boxes.append((c, c + half))
        else:
            out.append((lo, hi))
    return np.array([b[0] for b in out]), np.array([b[1] for b in out])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_box_index_returns_every_box_that_meets_the_query(seed):
    rng = np.random.default_rng(seed)
    lo, hi = _octree_partition(rng)
    # Shifted and clipped like the renderer's boxes (cells centred on voxels, domain ends).
    lo, hi = lo - 0.5 * (lo > 0), np.minimum(hi - 0.5, 63.5)
    index = BoxIndex(lo, hi)
    assert index.cells is not None and len(lo) >= 64  # the grid is in use
    for _ in range(300):
        q_lo = rng.uniform(-3, 66, 3)
        q_hi = q_lo + rng.uniform(0, 12, 3)
        meets = np.flatnonzero(np.all((lo <= q_hi) & (hi >= q_lo), axis=1))
        found = index.query(q_lo, q_hi)
        assert np.all(np.diff(found) > 0)  # ascending, no repeats
        assert set(meets) <= set(found.tolist())
        assert len(found) <= len(meets) + 64  # a broad phase, not every box
    # A query touching a box only at its face still finds it.
    face = index.query(hi[0] + np.array([0.0, -1e-9, -1e-9]), hi[0] + 1.0)
    assert 0 in face.tolist()


def test_small_sets_are_returned_whole():
    lo = np.zeros((5, 3))
    hi = np.ones((5, 3))
    assert BoxIndex(lo, hi).query(np.full(3, 10.0), np.full(3, 11.0)).tolist() == [0, 1, 2, 3, 4]
