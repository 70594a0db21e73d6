"""Suite-wide pytest hooks: the order in which test files are handed to the xdist workers.

The suite runs with ``--dist loadfile``: each file goes whole to one of the (two, on CI) workers,
which take the next file from a queue when they run out. Most of a file's time on an empty Numba
cache is compiling the kernels it is the first to use, and a few files take minutes. Queued last,
one of those leaves a worker alone with it for minutes at the end (xdist's default queue orders
files by their number of tests, so a file's place changed whenever tests were added or removed:
the whole suite took 1375 s in one run and 1544 s after a change that removed work). Here the
costly files are queued first, longest first, so the short ones fill the gaps at the end; the
rest keep their collection order. ``pyproject.toml`` passes ``--no-loadscope-reorder`` so xdist
keeps this order.
"""

from __future__ import annotations

import pytest

#: Test files by cost, most costly first: seconds on one worker of the 2-core CI machine from
#: an empty Numba cache (``pytest --durations=0``, summed per file; re-measure when a file's
#: cost changes much). Files not listed take under 30 s each and follow in collection order.
COSTLY_FILES = (
    "tests/test_multires_render.py",  # 500 s (every mode and model in the one-launch renderer)
    "tests/test_cli_options.py",  # 295 s
    "tests/test_wavelet_render.py",  # 192 s
    "tests/test_clipping.py",  # 176 s
    "tests/test_wavelet_hostile.py",  # 169 s
    "tests/test_bricks.py",  # 134 s
    "tests/test_distributed_sort_last.py",  # 124 s
    "tests/fuzz/test_short_run.py",  # 71 s
    "tests/test_cut_render.py",  # 57 s
    "tests/test_pieces_driver.py",  # 56 s
    "tests/test_render_iso.py",  # 51 s
    "tests/test_pairs.py",  # 45 s
    "tests/test_packaging.py",  # 38 s
    "tests/test_type6_analytic.py",  # 38 s
)


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Put the tests of :data:`COSTLY_FILES` first, in that order (a stable sort: the order of
    tests within a file and of the other files is kept)."""
    rank = {path: n for n, path in enumerate(COSTLY_FILES)}
    items.sort(key=lambda item: rank.get(item.nodeid.split("::")[0], len(rank)))
