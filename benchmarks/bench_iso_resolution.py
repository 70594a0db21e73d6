"""Does a coarser grid make an exact isosurface frame cheaper? The same view of one function
sampled at several resolutions.

Run ``python benchmarks/bench_iso_resolution.py [--model bspline1] [--rounds N]``; results go
to ``benchmarks/results/iso_resolution.md`` and ``.json``.

The Chmutov function (the wavelet benchmark's volume) is sampled at 128^3, 64^3, 32^3 and 16^3
over the same world box, and each is rendered in memory with the same camera as
``bench_wavelet.py``'s store renders (orbit 30/20, zoom 2.5, 1024x768, iso 0). A wavelet frame
draws bricks of such coarser levels, so if the full-resolution frame costs about what the 16^3
one does, the level of detail has no traversal left to save at this view: the cost is the first
root and the normal of every pixel whose ray hits. Wall time on all threads, median of the
rounds after a warm-up frame.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _machine import describe  # noqa: E402

import splinecast as sc  # noqa: E402

SIZES = (128, 64, 32, 16)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default="bspline1")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--out", default=str(HERE / "results"))
    args = parser.parse_args()
    finest = sc.demo("chmutov", size=SIZES[0])
    cam = sc.Camera.orbit(finest, azimuth=30, elevation=20, size=(1024, 768), zoom=2.5)
    rows = []
    for n in SIZES:
        data = sc.demo("chmutov", size=n).data
        # The same world box as the finest sampling.
        spacing = np.asarray(finest.spacing) * (SIZES[0] - 1) / (n - 1)
        scene = sc.Scene(sc.Volume(data, spacing=spacing, origin=finest.origin), model=args.model)
        frame = scene.render(cam, iso=0.0)
        times = []
        for _ in range(args.rounds):
            start = time.perf_counter()
            frame = scene.render(cam, iso=0.0)
            times.append(time.perf_counter() - start)
        st = frame.stats
        rows.append({"size": n, "ms": float(np.median(times)) * 1e3, "hits": int(st["hits"]),
                     "rays": int(st["rays"]), "cells_visited": float(st["mean_cells_visited"]),
                     "cells_tested": float(st["mean_cells_tested"]),
                     "blocks_skipped": float(st["mean_blocks_skipped"])})
        print(rows[-1], flush=True)
    results = {"machine": describe(), "model": args.model, "rounds": args.rounds,
               "command": " ".join(["python benchmarks/bench_iso_resolution.py", *sys.argv[1:]]),
               "rows": rows}
    m = results["machine"]
    lines = [f"# Exact isosurface frame vs grid resolution ({args.model}, Chmutov, 1024x768)", "",
             f"Machine: {m['cpu']}, {m['cores']} cores, {m.get('numba_threads', '?')} Numba "
             f"threads. Command: `{results['command']}`. "
             + " ".join(__doc__.split("\n\n")[2].split()), "",
             "| samples | frame ms | rays that hit | cells visited / ray | cells tested / ray | "
             "blocks skipped / ray |", "|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['size']}^3 | {r['ms']:.0f} | {100 * r['hits'] / r['rays']:.1f}% | "
                     f"{r['cells_visited']:.2f} | {r['cells_tested']:.2f} | "
                     f"{r['blocks_skipped']:.2f} |")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "iso_resolution.json").write_text(json.dumps(results, indent=1) + "\n")
    (out / "iso_resolution.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
