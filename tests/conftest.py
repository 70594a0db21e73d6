"""Suite-wide test order and threads.

The short fuzzing run (``tests/fuzz``) renders hundreds of hostile inputs in fresh processes,
each loading the compiled kernels from the disk cache. Run first, it finds that cache empty and
its processes compile the kernels while the other worker compiles the same ones for its own
tests (535 s of one worker in a cold run, against 26 s when it ran last); run last, the rest of
the suite has compiled them. The order is kept otherwise (``--dist worksteal`` hands each
worker its half of the tests in this order).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

# The test run's workers share the cores (one per core), so a thread that waits for work must
# sleep, not spin: OpenMP's threads (Numba's parallel loops outside the frame loops) otherwise
# spin after every parallel region and take the CPU the other worker compiles on. Set before
# any parallel region runs (OpenMP reads it when it starts); a value given outside is kept.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

_LAST = Path(__file__).resolve().parent / "fuzz"


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Move the fuzzing tests to the end, keeping every other test's place."""
    late = [item for item in items if _LAST in Path(str(item.path)).resolve().parents]
    if late:
        early = [item for item in items if item not in late]
        items[:] = early + late
