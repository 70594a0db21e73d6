"""Machine description saved with every benchmark result, the shared timing helper, and the
writer of a result's JSON and markdown table."""

from __future__ import annotations

import json
import os
import platform
import statistics
import time
from collections.abc import Callable, Sequence
from importlib import metadata
from pathlib import Path
from typing import Any

#: The real volume of the benchmarks' MRI rows: the MNI152 T1 1 mm template
#: (``mni152_t1_1mm.nii.gz``). ``SPLINECAST_BENCH_MRI`` names the file; without it, the
#: ``mni152_t1_1mm.nii.gz`` of the ``shared/data`` folder beside the checkout is used when it
#: exists. Benchmarks leave the MRI rows out when the file is missing.
MRI = Path(os.environ.get("SPLINECAST_BENCH_MRI")
           or Path(__file__).resolve().parents[2] / "shared" / "data" / "mni152_t1_1mm.nii.gz")


def describe() -> dict[str, Any]:
    """CPU model, core count and library versions of this run."""
    cpu = platform.processor() or "unknown"
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    import numba

    versions = {}
    for package in ("splinecast", "numpy", "numba", "llvmlite", "scipy"):
        try:
            versions[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            versions[package] = None
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "numba_threads": numba.get_num_threads(),
        "numba_threading_layer": _threading_layer(),
        "python": platform.python_version(),
        "platform": platform.platform(),
        "versions": versions,
    }


def _threading_layer() -> str | None:
    import numba

    try:
        return numba.threading_layer()
    except ValueError:  # no parallel kernel has run yet
        return None


def median_ms(fn: Callable[[], object], repeats: int) -> float:
    """Median wall time of ``repeats`` calls of ``fn``, in milliseconds (warm up before)."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append((time.perf_counter() - start) * 1e3)
    return statistics.median(times)


def write_results(path: Path, title: str, description: str, header: Sequence[str],
                  rows: list[dict[str, Any]], cells: Callable[[dict[str, Any]], Sequence[str]],
                  machine: dict[str, Any] | None = None, before_table: Sequence[str] = ()
                  ) -> None:
    """Write ``path.json`` (the machine and the rows) and ``path.md``: a title, the machine,
    the description and a table, one line per row.

    Parameters
    ----------
    path : Path
        The results' path without a suffix, e.g. ``results/mip_tolerance``.
    title, description : str
        The markdown's heading and the paragraph under it (how the numbers were taken, the
        command); the machine goes first in that paragraph.
    header : sequence of str
        The table's column titles.
    rows : list of dict
        One result per line, saved as they are in the JSON.
    cells : callable
        The formatted cells of one row, as many as ``header`` has titles.
    machine : dict, optional
        The machine description (default: :func:`describe` now).
    before_table : sequence of str
        Markdown paragraphs between the description and the table (a figure, say).
    """
    machine = describe() if machine is None else machine
    path.with_suffix(".json").write_text(json.dumps({"machine": machine, "rows": rows},
                                                    indent=1))
    lines = [f"# {title}", "", f"Machine: {machine}. {description}", ""]
    for paragraph in before_table:
        lines += [paragraph, ""]
    lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cells(row)) + " |" for row in rows]
    path.with_suffix(".md").write_text("\n".join(lines) + "\n")
