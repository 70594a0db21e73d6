"""Fault injection for the Dask tests: hold one worker busy so that the other surely owns the
work that is lost when it is killed."""

from __future__ import annotations

import time
from typing import Any


def _wait_for_event(name: str) -> None:
    import distributed

    distributed.Event(name).wait()


def hold_worker(client: Any, address: str, name: str, timeout: float = 60.0) -> tuple[Any, Any]:
    """Occupy the single thread of worker ``address`` with a task that waits on the Dask Event
    ``name``; returns once the task runs, as ``(event, future)``: ``event.set()`` releases the
    worker, ``future.result()`` waits for the task's end."""
    import distributed

    event = distributed.Event(name, client=client)
    future = client.submit(_wait_for_event, name, workers=[address], pure=False)
    deadline = time.monotonic() + timeout
    while not client.processing(workers=[address])[address]:
        assert time.monotonic() < deadline, "the held worker never started the holding task"
        time.sleep(0.01)
    return event, future
