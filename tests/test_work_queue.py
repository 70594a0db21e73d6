"""The shared counter of render/work_queue.py: every item is taken exactly once, whichever
thread takes it, and the images of the dynamic band schedule are those of one thread."""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

import splinecast as sc
from splinecast.render.work_queue import take


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
