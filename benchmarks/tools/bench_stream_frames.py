"""Frames of a multiresolution scene until its cut is complete, and where each frame's time goes.

    python benchmarks/tools/bench_stream_frames.py STORE.zarr [--budget 256MiB] [--mode iso]
        [--frames N] [--src DIR] [--baseline DIR --save NAME]

``Scene(store, budget=..., lod=1)`` renders one view (the view and modes of
``bench_multires.py``: 1024x768, zoom 1.3, trilinear; iso 128 or DVR) frame after frame with
the default load budget until the cut is complete (or ``--frames``).
Prints one JSON line per frame (wall ms, and the frame's ``seam_plan_ms``, ``cut_ms``,
``trace_ms``, ``drawables_changed_at_seams``, bricks loaded) and a summary line. The first frame
compiles; compare runs from a warm Numba cache. ``--src`` imports splinecast from another source
tree; ``--baseline DIR`` runs this source and that one one after the other in fresh processes
and, with ``--save NAME``, writes ``benchmarks/results/NAME.{json,md}`` with the machine.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parents[1]  # benchmarks/


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("store")
    parser.add_argument("--budget", default="256MiB")
    parser.add_argument("--mode", default="iso", choices=("iso", "dvr"))
    parser.add_argument("--frames", type=int, default=2000)
    parser.add_argument("--src", help="import splinecast from this source tree")
    parser.add_argument("--quiet", action="store_true", help="only the summary line")
    parser.add_argument("--baseline", help="also run this source tree; compare")
    parser.add_argument("--save", help="results file stem (with --baseline)")
    args = parser.parse_args()
    if args.baseline:
        compare(args)
        return
    if args.src:
        sys.path.insert(0, args.src)
    import splinecast as sc

    mv = sc.read(args.store)
    if args.mode == "iso":
        options = {"mode": "iso", "iso": 128.0}
    else:
        tf = sc.TransferFunction([(140.0, 0.0), (170.0, 0.08), (255.0, 0.3)], domain=(0.0, 255.0))
        options = {"mode": "dvr", "tf": tf}
    cam = sc.Camera.orbit(mv, azimuth=30, elevation=25, size=(1024, 768), zoom=1.3)
    rows = []
    wall = time.perf_counter()
    with sc.Scene(mv, budget=args.budget, lod=1.0) as scene:
        for _ in range(args.frames):
            t = time.perf_counter()
            frame = scene.render(cam, complete=False, **options)
            st = frame.stats
            row = {"ms": (time.perf_counter() - t) * 1e3,
                   **{k: st.get(k) for k in ("seam_plan_ms", "cut_ms", "trace_ms",
                                             "drawables_changed_at_seams", "loaded_this_frame",
                                             "cut_bricks", "substituted", "complete")}}
            rows.append(row)
            if not args.quiet:
                print(json.dumps(row), flush=True)
            if st["complete"]:
                break
    later = rows[1:] or rows
    summary = {"src": sc.__file__, "budget": args.budget, "mode": args.mode,
               "frames": len(rows), "wall_s": time.perf_counter() - wall,
               "first_ms": rows[0]["ms"],
               "median_ms_after_first": float(np.median([r["ms"] for r in later])),
               "plan_ms_total": float(sum(r["seam_plan_ms"] or 0 for r in rows)),
               "cut_ms_total": float(sum(r["cut_ms"] or 0 for r in rows)),
               "trace_ms_total": float(sum(r["trace_ms"] or 0 for r in rows)),
               "complete": rows[-1]["complete"], "cut_bricks": rows[-1]["cut_bricks"]}
    print(json.dumps(summary), flush=True)


def compare(args: argparse.Namespace) -> None:
    """This source and ``--baseline``, each in a fresh process, and the ratios."""
    sys.path.insert(0, str(HERE))
    from _machine import describe

    runs = {}
    for name, src in (("new", args.src or str(HERE.parent / "src")), ("baseline", args.baseline)):
        done = subprocess.run([sys.executable, __file__, args.store, "--budget", args.budget,
                               "--mode", args.mode, "--frames", str(args.frames), "--src", src,
                               "--quiet"], capture_output=True, text=True, check=True)
        runs[name] = json.loads(done.stdout.strip().splitlines()[-1])
        print(name, json.dumps(runs[name]), flush=True)
    if not args.save:
        return
    result = {"machine": describe(), "store": args.store, "budget": args.budget,
              "mode": args.mode, "runs": runs}
    out = HERE / "results"
    (out / f"{args.save}.json").write_text(json.dumps(result, indent=1) + "\n")
    m = result["machine"]
    lines = [f"# Multiresolution frames until the cut is complete ({args.mode}, {args.budget})",
             "", f"Machine: {m['cpu']}, {m['cores']} cores. Store `{args.store}`. Command: "
             f"`python benchmarks/tools/bench_stream_frames.py STORE --budget {args.budget} --mode "
             f"{args.mode} --baseline OLD/src --save {args.save}` (one run each, one after the "
             "other, warm Numba cache).", "",
             "| source | frames | to complete s | first frame ms | median frame ms | "
             "seam plan ms (sum) | cut ms (sum) | trace ms (sum, incl. plan) |",
             "|---|---|---|---|---|---|---|---|"]
    for name, r in runs.items():
        lines.append(f"| {name} | {r['frames']} | {r['wall_s']:.1f} | {r['first_ms']:.0f} | "
                     f"{r['median_ms_after_first']:.0f} | {r['plan_ms_total']:.0f} | "
                     f"{r['cut_ms_total']:.0f} | {r['trace_ms_total']:.0f} |")
    new, old = runs["new"], runs["baseline"]
    lines += ["", f"Ratio baseline / new: to complete {old['wall_s'] / new['wall_s']:.2f}x, "
              f"median frame {old['median_ms_after_first'] / new['median_ms_after_first']:.2f}x, "
              f"seam plan {old['plan_ms_total'] / max(new['plan_ms_total'], 1e-9):.2f}x.", ""]
    (out / f"{args.save}.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
