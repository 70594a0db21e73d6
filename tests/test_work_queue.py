"""``_jit.work_queue``: the shared counter and the threads that run compiled loops on it.

References: a count per item kept by the test (every item taken exactly once, whichever thread
takes it), the images of one thread (the frames of every thread must equal them), a barrier
that only opens when the copies run at the same time, and events that show the caller waits
for a copy still running before it reports a failure."""

from __future__ import annotations

import threading

import numba
import numpy as np
import pytest
from numba import njit, prange

import splinecast as sc
from splinecast._jit import jit
from splinecast._jit.work_queue import run_items, run_on_threads, take


@njit(parallel=True)
def _take_all(n_items, taken_by):
    counter = np.zeros(1, np.int64)
    for worker in prange(taken_by.shape[0]):
        while True:
            item = take(counter)
            if item >= n_items:
                break
            # A little work: the threads run side by side and contend for the counter all the
            # time (a counter that is not atomic then hands out some numbers twice).
            x = 0.0
            for i in range(5 + item % 7):
                x += np.sin(i * 0.001 + item)
            taken_by[worker, item] += 1 + (x > 1e300)


def test_every_item_is_taken_exactly_once():
    n, workers = 200_000, max(2, numba.get_num_threads())
    taken_by = np.zeros((workers, n), np.int64)  # a row per worker: no shared writes
    _take_all(n, taken_by)
    assert np.all(taken_by.sum(axis=0) == 1)
    if numba.get_num_threads() > 1:
        assert np.count_nonzero(taken_by.sum(axis=1)) > 1, "one worker took every item"


def test_frames_with_every_thread_equal_frames_with_one():
    vol = sc.demo("torus", size=40)
    cam = sc.Camera.orbit(vol, azimuth=25, elevation=15, size=(96, 72))
    scene = sc.Scene(vol)
    threads = numba.get_num_threads()
    many = scene.render(cam, iso=vol.metadata["default_iso"])
    numba.set_num_threads(1)
    try:
        one = scene.render(cam, iso=vol.metadata["default_iso"])
    finally:
        numba.set_num_threads(threads)
    assert np.isfinite(one.depth).sum() > 100
    for name in ("rgba", "depth", "normal", "cells_visited"):
        assert np.array_equal(getattr(one, name), getattr(many, name), equal_nan=True), name


def test_pyramid_frames_with_every_thread_equal_frames_with_one(tmp_path):
    """The cut's tiles are taken by the threads as they become free: the image is the one a
    single thread draws, also where pieces of several levels meet (a small budget)."""
    pytest.importorskip("zarr")
    vol = sc.demo("marschner-lobb", size=48)
    sc.build_pyramid(vol, tmp_path / "p.zarr", brick=16, progress=False)
    cam = sc.Camera.orbit(vol, azimuth=35, elevation=20, size=(96, 72))
    threads = numba.get_num_threads()
    frames = []
    for n in (threads, 1):
        numba.set_num_threads(n)
        try:
            with sc.Scene(sc.read(tmp_path / "p.zarr"), budget="300KiB") as scene:
                frames.append(scene.render(cam, iso=0.5))
        finally:
            numba.set_num_threads(threads)
    many, one = frames
    assert len(one.stats["cut_levels"]) > 1  # levels meet in the cut
    assert np.isfinite(one.depth).sum() > 100
    for name in ("rgba", "depth", "normal"):
        assert np.array_equal(getattr(one, name), getattr(many, name), equal_nan=True), name


@jit()
def _count_items(counter, seen):
    taken = 0
    while True:
        item = take(counter)
        if item >= seen.shape[0]:
            break
        seen[item] += 1
        taken += 1
    return taken


@pytest.mark.parametrize("threads", [1, 2, 4])
def test_run_on_threads_takes_every_item_exactly_once(threads):
    seen = np.zeros(20000, np.int64)
    counter = np.zeros(1, np.int64)
    results = run_on_threads(lambda: _count_items(counter, seen), threads)
    np.testing.assert_array_equal(seen, 1)
    assert sum(results) == seen.size
    assert 1 <= len(results) <= threads


def test_the_copies_run_at_the_same_time():
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("the pool has no thread to run a second copy on (NUMBA_NUM_THREADS=1)")
    barrier = threading.Barrier(2, timeout=60)  # broken (an error) if the copies ran in turn

    def work() -> int:
        return barrier.wait()

    assert sorted(run_on_threads(work, 2)) == [0, 1]


def test_a_failure_is_reported_after_the_other_copies_end():
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("the pool has no thread to run a second copy on (NUMBA_NUM_THREADS=1)")
    caller = threading.get_ident()
    started, release, finished = threading.Event(), threading.Event(), threading.Event()

    def work() -> None:
        if threading.get_ident() == caller:
            assert started.wait(60)
            release.set()
            raise ValueError("the caller's copy failed")
        started.set()
        assert release.wait(60)
        finished.set()

    with pytest.raises(ValueError, match="caller's copy"):
        run_on_threads(work, 2)
    assert finished.is_set()  # the pool's copy had ended before the error reached the caller


@jit
def _mark_items(n_items, marks, counter):
    while True:
        item = take(counter)
        if item >= n_items:
            break
        marks[item] += 1


def test_run_items_takes_every_item_once_and_calls_nothing_for_none():
    for n in (1, 2, 3, 1000, 100_003):
        marks = np.zeros(n, np.int64)
        run_items(_mark_items, n, n, marks)
        assert np.all(marks == 1), n
    # No item: the kernel is not called (it would fail on these arguments).
    run_items(_mark_items, 0, "not an array", None)


def test_results_of_threaded_scans_equal_one_thread():
    """The scans that ``run_items`` spreads over threads give what one thread gives."""
    vol = sc.demo("marschner-lobb", size=33)
    cam = sc.Camera.orbit(vol, azimuth=25, elevation=15, size=(48, 40))
    threads = numba.get_num_threads()
    many = sc.Scene(vol, model="s31").render(cam, iso=0.45)
    numba.set_num_threads(1)
    try:
        one = sc.Scene(vol, model="s31").render(cam, iso=0.45)
    finally:
        numba.set_num_threads(threads)
    assert np.isfinite(one.depth).sum() > 100
    for name in ("rgba", "depth", "normal", "cells_visited"):
        assert np.array_equal(getattr(one, name), getattr(many, name), equal_nan=True), name
