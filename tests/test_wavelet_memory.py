"""Bounded memory of a wavelet scene: bricks and detail blocks stay under the scene's budget.

A camera flies along a long tube (a store whose details span several blocks along the flight),
refining only near the eye. Reference: the same flight with an unlimited budget (nothing is ever
evicted), whose frames must be pixel for pixel the same.
"""

from __future__ import annotations

import numpy as np
import pytest

import splinecast as sc
from splinecast.multires.wavelet.memory import Budget, SlotPool
from splinecast.multires.wavelet.store import build_wavelet_pyramid

pytest.importorskip("zarr")


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    x, y, z = np.meshgrid(np.arange(200.0), np.arange(20.0), np.arange(20.0), indexing="ij")
    tube = np.sqrt((y - 9.5) ** 2 + (z - 9.5) ** 2) - (5 + 2 * np.sin(x / 6))
    path = tmp_path_factory.mktemp("w") / "tube.zarr"
    build_wavelet_pyramid(sc.Volume(tube.astype(np.float32)), path, degree=3, chunk=8)
    return path


def _flight():
    return [sc.Camera(position=(px, -6.0, 9.5), look_at=(px + 10.0, 9.5, 9.5), size=(16, 16),
                      fov=60) for px in range(0, 200, 20)]


def test_a_flight_under_a_small_budget_stays_under_it_and_renders_the_same(store):
    unlimited = sc.Scene(sc.read(store), lod=0.2, budget=None)
    reference = [unlimited.render(cam, iso=0.0) for cam in _flight()]
    grown = max(f.stats["resident_bytes"] for f in reference)
    read_unlimited = sum(f.stats["details_read"] for f in reference)
    assert sum(f.stats["hits"] for f in reference) > 0
    budget = int(0.3 * grown)
    small = sc.Scene(sc.read(store), lod=0.2, budget=budget)
    read_small = 0
    for cam, ref in zip(_flight(), reference, strict=True):
        frame = small.render(cam, iso=0.0)
        resident = small.reconstructor.resident_bytes
        assert frame.stats["resident_bytes"] == resident <= budget
        read_small += frame.stats["details_read"]
        np.testing.assert_array_equal(frame.rgba, ref.rgba)
        np.testing.assert_array_equal(frame.depth, ref.depth)
    # The budget did bite: details were dropped and read again.
    assert grown > budget and read_small > read_unlimited


def test_a_selection_larger_than_the_budget_still_renders(store):
    """Nothing the current frame uses is evicted: the budget is exceeded, not the image."""
    cam = _flight()[5]
    ref = sc.Scene(sc.read(store), lod=0.2, budget=None).render(cam, iso=0.0)
    tiny = sc.Scene(sc.read(store), lod=0.2, budget=1)
    frame = tiny.render(cam, iso=0.0)
    np.testing.assert_array_equal(frame.rgba, ref.rgba)


def test_slot_pools_evict_least_recently_used_and_compact():
    released = []
    pool = SlotPool((2,), np.float64, lambda lv, fl: released.append((lv.tolist(), fl.tolist())))
    other = SlotPool((4,), np.float64, lambda lv, fl: None)
    moves = []
    budget = Budget(10 * 16 + 2 * 32, lambda p, remap: moves.append((p, remap.tolist())))
    budget.pools = [pool, other]
    budget.make_room(other, 2, frame=1)
    other.take(0, np.array([7, 8]), frame=1)
    budget.make_room(pool, 4, frame=1)
    slots = pool.take(1, np.arange(4), frame=1)
    pool.touch(slots[:2], 2)  # frame 2 uses owners 0 and 1; 2 and 3 were last used in frame 1
    pool.array[slots] = np.arange(8.0).reshape(4, 2)
    # 10 more: the two of frame 1 go first (their slots are reused), then one item of the other
    # pool (32 bytes), which is compacted, leaves room for the last 8 of 16 bytes.
    budget.make_room(pool, 10, frame=2)
    assert released[0] == ([1, 1], [2, 3])
    assert pool.free == 10 and budget.nbytes == budget.limit
    assert other.capacity == 1 and moves == [(other, [-1, 0])] and other.flat.tolist() == [8]
    np.testing.assert_array_equal(pool.array[slots[:2]], [[0, 1], [2, 3]])
