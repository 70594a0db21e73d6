"""Loading one view's cut to completion from a pyramid store.

    python benchmarks/tools/bench_loader.py STORE.zarr [--budget 256MiB] [--src DIR]

A :class:`~splinecast.multires.cut.stream.BrickStream` at lod 1, 1024x768, zoom 2, load budget 64,
isosurface filter at 128 (the synthetic volume of ``bench_multires.py``): frames until the cut
is complete; prints wall and CPU seconds, frames, bricks loaded, cut bricks, and the decoded
and reused chunks. ``--src`` imports splinecast from another source tree (a baseline).
"""

from __future__ import annotations

import argparse
import json
import sys
import time


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("store")
    parser.add_argument("--budget", default="256MiB")
    parser.add_argument("--src", help="import splinecast from this source tree")
    args = parser.parse_args()
    if args.src:
        sys.path.insert(0, args.src)
    import splinecast as sc
    from splinecast.multires.cut.relevance import ValueFilter
    from splinecast.multires.cut.stream import BrickStream

    mv = sc.read(args.store)
    wall, cpu, frames = time.perf_counter(), time.process_time(), 0
    with BrickStream(mv, args.budget, lod=1.0, loads_per_frame=64) as stream:
        cam = sc.Camera.orbit(mv, azimuth=0, elevation=25, size=(1024, 768), zoom=2.0)
        for _ in range(2000):
            bricks = stream.frame(cam, ValueFilter.iso(128), timeout=30)
            frames += 1
            if bricks.complete:
                break
        stats = stream.cache.stats()
    print(json.dumps({"src": sc.__file__, "budget": args.budget,
                      "wall_s": time.perf_counter() - wall, "cpu_s": time.process_time() - cpu,
                      "frames": frames, "loaded": stats["loaded"], "cut_bricks": len(bricks.cut),
                      "complete": bricks.complete, "chunks_decoded": stats.get("chunks_decoded"),
                      "chunks_reused": stats.get("chunks_reused")}))


if __name__ == "__main__":
    main()
