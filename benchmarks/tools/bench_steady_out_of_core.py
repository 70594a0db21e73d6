"""The out-of-core steady frame against the in-memory render of the level the budget holds.

    python benchmarks/tools/bench_steady_out_of_core.py STORE.zarr [--budgets 256MiB,1GiB]
        [--modes iso,dvr] [--repeats 7] [--settle 12] [--save NAME]

For each budget and mode, in one process: ``Scene(store, budget=B, lod=1)`` renders the view
of ``bench_multires.py`` (1024x768, zoom 1.3, trilinear; iso 128, or its DVR transfer function)
until its cut is complete, then until the cut is reused (``cut_reused``: nothing changed since
the last frame; at most ``--settle`` frames, each counted); the in-memory ``Scene`` of the
finest level that fits in the budget (``bench_multires.py``'s baseline) renders the same view
after a warm-up. Then the two render in turn, ``--repeats`` times each: their medians and ratio
are taken side by side, on the same loaded machine. One JSON line per budget and mode; with
``--save NAME`` also ``benchmarks/results/NAME.{json,md}``. The kernels compile in the first
frames: run once before measuring.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]  # benchmarks/


def measure(store: str, budget: str, mode: str, repeats: int, settle: int) -> dict:
    import splinecast as sc
    from splinecast.multires.store.budget import parse_bytes

    mv = sc.read(store)
    if mode == "iso":
        options = {"mode": "iso", "iso": 128.0}
    else:
        tf = sc.TransferFunction([(140.0, 0.0), (170.0, 0.08), (255.0, 0.3)], domain=(0.0, 255.0))
        options = {"mode": "dvr", "tf": tf}
    cam = sc.Camera.orbit(mv, azimuth=30, elevation=25, size=(1024, 768), zoom=1.3)
    limit = parse_bytes(budget, "budget")
    level = [lv.index for lv in mv.levels if lv.nbytes <= limit][0]
    scene = sc.Scene(mv, budget=budget, lod=1.0)
    t0 = time.perf_counter()
    frames = 0
    while True:
        frame = scene.render(cam, **options)
        frames += 1
        if frame.stats["complete"]:
            break
    complete_s = time.perf_counter() - t0
    settling = []
    for _ in range(settle):
        t = time.perf_counter()
        frame = scene.render(cam, **options)
        settling.append((time.perf_counter() - t) * 1e3)
        if frame.stats["cut_reused"] and len(settling) > 1:
            break
    memory = sc.Scene(mv.level(level).to_volume(max_bytes=2**40))
    memory.render(cam, **options)
    memory.render(cam, **options)
    multi_ms, memory_ms = [], []
    for _ in range(repeats):
        t = time.perf_counter()
        frame = scene.render(cam, **options)
        multi_ms.append((time.perf_counter() - t) * 1e3)
        t = time.perf_counter()
        memory.render(cam, **options)
        memory_ms.append((time.perf_counter() - t) * 1e3)
    st = frame.stats
    scene.close()
    keep = ("cut_bricks", "cut_levels", "drawables", "drawables_traced",
            "drawables_changed_at_seams",
            "seam_copy_bytes", "trace_ms", "cut_ms", "seam_plan_ms", "cut_reused",
            "resident_bytes", "reserved_bytes", "whole_level")
    return {"src": sc.__file__, "budget": budget, "mode": mode, "memory_level": level,
            "frames_to_complete": frames, "complete_s": complete_s, "settling_ms": settling,
            "multi_ms": statistics.median(multi_ms), "memory_ms": statistics.median(memory_ms),
            "ratio": statistics.median(multi_ms) / statistics.median(memory_ms),
            "multi_times": multi_ms, "memory_times": memory_ms,
            "final": {k: st.get(k) for k in keep}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("store")
    parser.add_argument("--budgets", default="256MiB,1GiB")
    parser.add_argument("--modes", default="iso")
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--settle", type=int, default=12)
    parser.add_argument("--save", help="results file stem")
    args = parser.parse_args()
    rows = []
    for budget in args.budgets.split(","):
        for mode in args.modes.split(","):
            row = measure(args.store, budget, mode, args.repeats, args.settle)
            print(json.dumps(row, default=str), flush=True)
            rows.append(row)
    if not args.save:
        return
    sys.path.insert(0, str(HERE))
    from _machine import write_results

    def cells(r: dict) -> list[str]:
        fin = r["final"]
        return [r["budget"], r["mode"], f"{r['complete_s']:.1f} s ({r['frames_to_complete']})",
                ", ".join(f"{v:.0f}" for v in r["settling_ms"]), f"{r['multi_ms']:.0f} ms",
                f"level {r['memory_level']}: {r['memory_ms']:.0f} ms", f"{r['ratio']:.2f}x",
                str(fin["cut_bricks"]), json.dumps(fin["cut_levels"]),
                str(fin["drawables_changed_at_seams"])]

    write_results(
        HERE / "results" / args.save,
        "Out-of-core steady frame against the in-memory level the budget holds",
        f"`python benchmarks/tools/bench_steady_out_of_core.py {args.store} --budgets "
        f"{args.budgets} --modes {args.modes} --repeats {args.repeats} --save {args.save}`. "
        "1024x768, zoom 1.3, trilinear, lod 1. The multiresolution scene is rendered until "
        "complete, then until its cut is reused (the settling frames, listed); then it and the "
        "in-memory scene of the finest level within the budget render in turn: medians of "
        "the repeats, side by side in one process.",
        ["budget", "mode", "to complete (frames)", "settling frames ms", "steady out of core",
         "in memory", "ratio", "cut bricks", "cut levels", "drawables changed at seams"],
        rows, cells)


if __name__ == "__main__":
    main()
