"""What limits the exact MIP: the best any order of visiting blocks could do, and threads.

Issue 15 asks exact MIP to skip better: never enter a block whose maximum cannot beat the
ray's running maximum, and visit blocks in an order that raises the running maximum early. The
walk already leaps every block whose maximum does not beat the running one, and starts each
ray from a lower bound (the value where the neighbouring ray found its maximum). How much can
a better order still gain? This script gives every ray the best possible start: its running
maximum set, before the walk, just below its own answer (taken from a first exact render), so
the walk leaps every block no order could avoid and visits only the cells that could hold the
answer. The gap between that frame and the ordinary one bounds what any visiting order, or any
better lower bound, can save. Both run through the same entry point
(:func:`splinecast.render.segment.trace_segment`, no screen footprint), and the answers must
be bit-identical.

It also times the ordinary frame on one thread and on all of them (the share lost to thread
imbalance) and the slices method at a step of 4 voxels (what sampling costs on the same
rays). 1024x768, the comparison suite's four orbit views (azimuth 40-70, elevation 20),
medians of ``ROUNDS`` rounds after a warm-up.

    python benchmarks/mip_exact_limits.py
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import numba
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))
from _machine import write_results  # noqa: E402

import splinecast as sc  # noqa: E402
from benchmarks.compare.scenes import ml, mri, noise  # noqa: E402
from splinecast.render.mip import Mip  # noqa: E402
from splinecast.render.segment import (  # noqa: E402
    counters,
    finish_state,
    new_state,
    trace_segment,
)

ROUNDS = 3
AZIMUTHS = (40.0, 50.0, 60.0, 70.0)
#: How far below its answer a ray's running maximum starts (times the data range): far above
#: the rounding of the answer, so the cell holding it is still tested and the answer is the
#: walk's own, far below any block maximum that decides a leap.
BELOW = 1e-9


def _median_ms(fn, cameras) -> float:
    for cam in cameras[:1]:
        fn(cam)
    times = []
    for _ in range(ROUNDS):
        for cam in cameras:
            t = time.perf_counter()
            fn(cam)
            times.append(time.perf_counter() - t)
    return 1e3 * statistics.median(times)


def _segment_frame(scene, setup, cam, answer, value_range):
    """The exact frame through ``trace_segment``, each ray's running maximum started just below
    ``answer`` (``None``: from nothing, as the renderer starts it). Returns (values, counters,
    seconds of the trace)."""
    state = new_state(setup, cam)
    if answer is not None:
        seen = np.isfinite(answer)
        state[0][seen] = answer[seen] - BELOW * (value_range[1] - value_range[0])
    stats = counters(cam.height, cam.width)
    t = time.perf_counter()
    trace_segment(scene.grid, setup, cam, state, stats)
    seconds = time.perf_counter() - t
    return finish_state(setup, state, cam)[0], stats, seconds


def measure(spec) -> dict:
    vol = spec.make()
    scene = sc.Scene(vol)
    cams = [sc.Camera.orbit(vol, azimuth=a, elevation=20.0, size=(1024, 768)) for a in AZIMUTHS]
    setup = Mip("mip", value_range=vol.value_range)
    row = {"scene": spec.label}
    threads = numba.get_num_threads()
    row["threads"] = threads

    def exact(cam):
        return scene.render(cam, mode="mip", outputs=("value",))

    row["exact_ms"] = _median_ms(exact, cams)
    numba.set_num_threads(1)
    row["exact_one_thread_ms"] = _median_ms(exact, cams)
    numba.set_num_threads(threads)
    row["slices4_ms"] = _median_ms(
        lambda c: scene.render(c, mode="mip", method="slices", step=4.0, outputs=("value",)),
        cams)

    answers = {id(c): _segment_frame(scene, setup, c, None, vol.value_range)[0] for c in cams}
    for key, seeded in (("segment", False), ("perfect_bound", True)):
        times, visited, tested, leapt, identical = [], [], [], [], True
        for r in range(ROUNDS + 1):
            for cam in cams:
                answer = answers[id(cam)]
                value, stats, seconds = _segment_frame(scene, setup, cam,
                                                       answer if seeded else None,
                                                       vol.value_range)
                if r == 0:  # warm-up round: the counters and the answers
                    traced = stats[0] > 0
                    visited.append(stats[0][traced].mean())
                    tested.append(stats[1][traced].mean())
                    leapt.append(stats[2][traced].mean())
                    # The ordinary walk against the renderer's frame (footprint and all); the
                    # perfect bound against the ordinary walk.
                    reference = exact(cam).value if not seeded else answer
                    identical &= np.array_equal(value, reference, equal_nan=True)
                else:
                    times.append(seconds)
        row[key] = {"ms": 1e3 * statistics.median(times),
                    "visited_per_ray": float(np.mean(visited)),
                    "tested_per_ray": float(np.mean(tested)),
                    "leapt_per_ray": float(np.mean(leapt)), "identical": bool(identical)}
    print(row, flush=True)
    return row


def main() -> None:
    rows = [measure(spec) for spec in (ml(128), ml(256), mri(), noise(256)) if spec is not None]
    def cells(r: dict) -> list[str]:
        a, b = r["segment"], r["perfect_bound"]
        return [r["scene"], f"{r['exact_ms']:.1f}", f"{r['exact_one_thread_ms']:.1f}",
                f"{r['exact_one_thread_ms'] / r['exact_ms']:.2f}x on {r['threads']}",
                f"{a['ms']:.1f}", f"{b['ms']:.1f}", f"{a['ms'] / b['ms']:.2f}x",
                f"{a['visited_per_ray']:.1f} / {a['tested_per_ray']:.1f} / "
                f"{a['leapt_per_ray']:.1f} -> {b['visited_per_ray']:.1f} / "
                f"{b['tested_per_ray']:.1f} / {b['leapt_per_ray']:.1f}",
                "yes" if a["identical"] and b["identical"] else "NO", f"{r['slices4_ms']:.1f}"]

    write_results(
        HERE / "results" / "mip_exact_limits",
        "Exact MIP: the most a better visiting order could gain, and thread scaling",
        "Command: `python benchmarks/mip_exact_limits.py`. 1024x768, four orbit views (azimuth "
        f"40-70, elevation 20), medians of {ROUNDS} rounds after a warm-up. *Ordinary* and "
        "*perfect bound* run the exact walk through `trace_segment` (no screen footprint): from "
        "nothing, and with each ray's running maximum started just below its own answer (the "
        "best start any visiting order or lower bound could give). Cells and leaps are means "
        "over the rays that visited a cell. *Frame* is `scene.render(mode=\"mip\")` as a user "
        "calls it (footprint included), on all threads and on one.",
        ["scene", "frame ms", "one thread ms", "thread scaling", "ordinary ms",
         "perfect bound ms", "most a better order gains",
         "cells visited / tested / leaps per ray, ordinary -> perfect", "answers identical",
         "slices step 4 ms"],
        rows, cells)

if __name__ == "__main__":
    main()
