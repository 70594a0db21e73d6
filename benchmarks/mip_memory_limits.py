"""What the exact MIP walk's memory reads cost: a measurement by elimination.

This machine's VM exposes no hardware counters (``perf stat`` reports every event as "not
supported"), so cache misses cannot be counted. They can be timed instead: the lean stand-alone
walk of ``mip_dda_feasibility.py`` (as fast as the renderer, same leaps, same cells) runs with
the range test of each visited cell reading a precomputed largest corner, so its path through
the volume is fixed, and the eight corners every visited cell would read are then

* not read at all ("no corner reads");
* read from the volume, as the renderer does ("corners from the volume");
* read with the same instructions at indices masked to the volume's first 16^3 cells, a few
  kilobytes that stay in the L1 cache ("corners from L1").

"corners from the volume" minus "corners from L1" is what the cache misses of those reads cost;
"corners from L1" minus "no corner reads" is what the reads cost when they hit. A tested cell's
cubic reads its corners in every variant (where the range test read them just before in the
renderer), so the difference covers the cells visited but not tested, and the per-cell figure
divides by those. The plain walk (the eight corners as its range test) is timed beside them.

    python benchmarks/mip_memory_limits.py
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))
from _machine import write_results  # noqa: E402
from mip_dda_feasibility import dda_mip, walk_inputs  # noqa: E402

from benchmarks.compare.scenes import ml, mri, noise  # noqa: E402

#: (label, ``loads`` argument of dda_mip); -1 is the plain walk.
VARIANTS = (("plain walk", -1), ("no corner reads", 0), ("corners from the volume", 1),
            ("corners from L1", 2))
ROUNDS = 7
SIZE = (1024, 768)
#: The time-stamp counter's rate on this machine (results/cycles_mip_*.md), to express the
#: per-cell times in cycles.
GHZ = 2.6


def _cell_maxima(data: np.ndarray) -> np.ndarray:
    """Largest of each cell's eight corners, in the data's dtype."""
    top = data[:-1, :-1, :-1].copy()
    for di in (0, 1):
        for dj in (0, 1):
            for dk in (0, 1):
                np.maximum(top, data[di:data.shape[0] - 1 + di, dj:data.shape[1] - 1 + dj,
                                     dk:data.shape[2] - 1 + dk], out=top)
    return top


def measure(spec) -> dict:
    """Median frame time of each variant on one scene, the variants interleaved per round."""
    import numba

    vol, scene, cam, data, (h0, h1, h2), o_index, d_index = walk_inputs(spec, SIZE)
    cellmax = _cell_maxima(data)
    shape = SIZE[::-1]
    outs = {loads: np.empty(shape) for _, loads in VARIANTS}
    visits = {loads: np.zeros(shape, np.int64) for _, loads in VARIANTS}
    sink = np.zeros(shape)
    times: dict[int, list[float]] = {loads: [] for _, loads in VARIANTS}
    for round_ in range(ROUNDS + 1):  # round 0 compiles and warms up
        for _, loads in VARIANTS:
            start = time.perf_counter()
            dda_mip(data, h0, h1, h2, o_index, d_index, outs[loads],
                    visits[loads], cellmax, loads, sink)
            if round_ > 0:
                times[loads].append((time.perf_counter() - start) * 1e3)
    # The variants take the same path: same answers, same cells.
    for _, loads in VARIANTS:
        np.testing.assert_array_equal(outs[loads], outs[-1])
        np.testing.assert_array_equal(visits[loads], visits[-1])
    ms = {label: statistics.median(times[loads]) for label, loads in VARIANTS}
    traced = np.isfinite(outs[-1])
    visited = int(visits[-1][traced].sum())
    tested = _tested_cells(scene, cam)
    threads = numba.get_num_threads()
    untested = max(visited - tested, 1)
    miss_ms = ms["corners from the volume"] - ms["corners from L1"]
    hit_ms = ms["corners from L1"] - ms["no corner reads"]
    per_cell = {name: value * 1e6 * threads / untested
                for name, value in (("miss_ns", miss_ms), ("hit_ns", hit_ms))}
    return {"scene": spec.label, "ms": ms, "traced_rays": int(traced.sum()),
            "visited_per_ray": visited / traced.sum(), "tested_per_ray": tested / traced.sum(),
            "miss_ms": miss_ms, "hit_ms": hit_ms, **per_cell, "threads": threads,
            "bytes_per_voxel": data.dtype.itemsize, "volume_mb": data.nbytes / 2**20}


def _tested_cells(scene, cam) -> int:
    """Cells the renderer tests (forms a piece for) over the frame, from its counters."""
    frame = scene.render(cam, mode="mip", outputs=("value", "stats"))
    return int(np.nansum(frame.cells_tested))


def main() -> None:
    rows = []
    for spec in (ml(128), ml(256), mri(), noise(256)):
        if spec is None:
            continue
        row = measure(spec)
        rows.append(row)
        print(row, flush=True)
    labels = [label for label, _ in VARIANTS]

    def cells(r: dict) -> list[str]:
        return [r["scene"], f"{r['volume_mb']:.0f} MB, {r['bytes_per_voxel']} B/voxel",
                *(f"{r['ms'][label]:.1f}" for label in labels),
                f"{r['miss_ms']:.1f} ({r['miss_ns']:.1f} ns, {r['miss_ns'] * GHZ:.0f})",
                f"{r['hit_ms']:.1f} ({r['hit_ns']:.1f} ns)",
                f"{r['visited_per_ray']:.1f} / {r['tested_per_ray']:.1f}"]

    write_results(
        HERE / "results" / "mip_memory_limits",
        "Exact MIP: what the walk's corner reads cost (cache misses by elimination)",
        f"Command: `python benchmarks/mip_memory_limits.py`. {SIZE[0]}x{SIZE[1]}, the "
        f"comparison's orbit camera at azimuth 40, numba's default threads, median of {ROUNDS} "
        "rounds after a warm-up, the variants interleaved in each round. All variants return "
        "the same values and visit the same cells (checked).",
        ["scene", "volume", *(f"{label} ms" for label in labels),
         f"misses: ms per frame (ns, cycles at {GHZ} GHz per untested visited cell)",
         "hits: ms per frame (ns per cell)", "cells visited / tested per traced ray"],
        rows, cells)

if __name__ == "__main__":
    main()
