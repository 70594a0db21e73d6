"""``render.work_queue``: compiled loops shared by threads through a counter.

References: a count per item kept by the test (every item taken exactly once), a barrier that
only opens when the copies run at the same time, and events that show the caller waits for a
copy still running before it reports a failure."""

from __future__ import annotations

import threading

import numba
import numpy as np
import pytest

from splinecast._jit import jit
from splinecast.render.work_queue import run_on_threads, take


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
def test_every_item_is_taken_exactly_once(threads):
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
