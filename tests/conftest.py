"""Suite-wide test order.

The short fuzzing run (``tests/fuzz``) renders hundreds of hostile inputs in fresh processes,
each loading the compiled kernels from the disk cache. Run first, it finds that cache empty and
its processes compile the kernels while the other worker compiles the same ones for its own
tests (535 s of one worker in a cold run, against 26 s when it ran last); run last, the rest of
the suite has compiled them. The order is kept otherwise (``--dist worksteal`` hands each
worker its half of the tests in this order).
"""

from __future__ import annotations

from pathlib import Path

import pytest

_LAST = Path(__file__).resolve().parent / "fuzz"


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Move the fuzzing tests to the end, keeping every other test's place."""
    late = [item for item in items if _LAST in Path(str(item.path)).resolve().parents]
    if late:
        early = [item for item in items if item not in late]
        items[:] = early + late
