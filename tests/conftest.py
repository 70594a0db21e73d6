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

#: The 30 test files that took longest in all (one run from an empty kernel cache on two cores),
#: longest first. The workers take whole files (``--dist loadfile``) in the order the collection
#: gives them, so these go first and short files fill the end: a long file started last would
#: leave the other worker idle until it ends. (Left to itself, pytest-xdist orders files by
#: their number of tests, which put a fuzzing run, a wheel build and the docs build, one test
#: each, last.) Files not listed follow by number of tests, most first. Their times shift with
#: the order (the first test to need a kernel compiles it); remeasure with
#: ``pytest --durations=0`` when the suite changes much.
LONGEST_FILES = (
    "test_multires_render.py",
    "test_cli_options.py",
    "test_hostile_zarr_vtk.py",
    "test_wavelet_hostile.py",
    "test_wavelet_render.py",
    "test_viewer_server.py",
    "test_sample_breakdown.py",
    "test_seam_parts.py",
    "fuzz/test_short_run.py",
    "test_labels.py",
    "test_toy_model.py",
    "test_aip.py",
    "test_packaging.py",
    "test_mip.py",
    "test_hostile_input.py",
    "test_remote_http.py",
    "test_dvr_ray.py",
    "test_viewer_prepare.py",
    "test_docs.py",
    "test_cli_warmup.py",
    "test_movie.py",
    "test_cli.py",
    "test_cut_driver.py",
    "test_cut_render.py",
    "test_timepoints.py",
    "test_type6_analytic.py",
    "test_bricks.py",
    "test_viewer_multires.py",
    "test_cli_habits.py",
    "test_compare.py",
)


def pytest_collection_modifyitems(config, items):  # noqa: ANN001, ANN201 - a pytest hook
    """Order the test files as :data:`LONGEST_FILES` says (tests keep their order in a file)."""
    tests = Path(__file__).parent
    count = Counter(item.path for item in items)
    rank = {tests / name: n for n, name in enumerate(LONGEST_FILES)}

    def key(item):  # noqa: ANN001, ANN202
        return (rank.get(item.path, len(rank)), -count[item.path], str(item.path))

    items.sort(key=key)
