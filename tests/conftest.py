"""Suite-wide settings of the test run."""

from __future__ import annotations

import os
from collections import Counter
from pathlib import Path

# The test run's workers share the cores (one per core), so a thread that waits for work must
# sleep, not spin: OpenMP's threads (Numba's parallel loops outside the frame loops) otherwise
# spin after every parallel region and take the CPU the other worker compiles on. Set before
# any parallel region runs (OpenMP reads it when it starts); a value given outside is kept.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

#: Test files that take longest in all (from an empty kernel cache on two cores), longest
#: first. The workers take whole files (``--dist loadfile``) in the order the collection gives
#: them, so these go first and short files fill the end: a long file started last would leave
#: the other worker idle until it ends. (Left to itself, pytest-xdist orders files by their
#: number of tests, which put a fuzzing run, a wheel build and the docs build, one test each,
#: last.) Files not listed follow by number of tests, most first.
LONGEST_FILES = (
    "test_cli_options.py",
    "test_multires_render.py",
    "test_mip.py",
    "test_hostile_input.py",
    "test_wavelet_render.py",
    "test_bricks.py",
    "fuzz/test_short_run.py",
    "test_packaging.py",
    "test_viewer_server.py",
    "test_docs.py",
    "test_sample_breakdown.py",
    "test_cli_warmup.py",
    "test_zarr_bounded.py",
    "test_viewer_prepare.py",
    "test_labels.py",
    "test_pair_kernels.py",
    "test_cycle_breakdown.py",
    "test_notebook.py",
    "test_floor_kernel.py",
    "test_viewer_browser_channels.py",
    "test_viewer_browser_labels.py",
    "test_viewer_browser_multires.py",
    "test_viewer_browser_time.py",
)


def pytest_collection_modifyitems(config, items):  # noqa: ANN001, ANN201 - a pytest hook
    """Order the test files as :data:`LONGEST_FILES` says (tests keep their order in a file)."""
    tests = Path(__file__).parent
    count = Counter(item.path for item in items)
    rank = {tests / name: n for n, name in enumerate(LONGEST_FILES)}

    def key(item):  # noqa: ANN001, ANN202
        return (rank.get(item.path, len(rank)), -count[item.path], str(item.path))

    items.sort(key=key)
