"""Remote against local: the same OME-Zarr pyramid read from its folder and over HTTP from a
server on 127.0.0.1 that adds latency to every request and caps each response's bandwidth.

Measured (median of ``--repeats`` runs after one warm-up, each run with a fresh store object so
nothing is cached in memory; the disk cache is off):

- ``open``: metadata, tables and the coarsest level (what the first image draws from);
- ``level 0``: every chunk of the finest level;
- ``render``: a complete iso render (``complete=True``) at ``--size`` from a fresh scene.

Run: ``python benchmarks/bench_remote.py --size-volume 256 --latency 0.05 --bandwidth 100e6``.
Nothing here is asserted: the numbers depend on the machine.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import splinecast as sc

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from remote_servers import Faults, FileServer  # noqa: E402


def _timed(fn, repeats: int) -> float:
    fn()  # warm-up (kernels compiled, connections open)
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size-volume", type=int, default=256, help="volume side (default 256)")
    parser.add_argument("--brick", type=int, default=32)
    parser.add_argument("--latency", type=float, default=0.05, help="seconds added per request")
    parser.add_argument("--bandwidth", type=float, default=100e6, help="bytes/s per response")
    parser.add_argument("--size", default="256x192", help="image WIDTHxHEIGHT")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    with tempfile.TemporaryDirectory() as folder:
        root = Path(folder)
        vol = sc.demo("marschner-lobb", size=args.size_volume)
        vol = sc.Volume(vol.data.astype(np.float32), spacing=vol.spacing, origin=vol.origin)
        sc.build_pyramid(vol, root / "vol.zarr", brick=args.brick, progress=False)
        faults = Faults(latency=args.latency, bandwidth=args.bandwidth)
        with FileServer(root, faults) as server:
            sources = {"local": str(root / "vol.zarr"), "remote": f"{server.url}/vol.zarr"}
            rows = []
            for label, source in sources.items():
                def opened(source=source):
                    return sc.read(source).levels[-1].read((0, 0, 0), (1 << 20,) * 3)

                def level0(source=source):
                    level = sc.read(source).levels[0]
                    return level.read((0, 0, 0), level.shape)

                def render(source=source):
                    mv = sc.read(source)
                    scene = sc.Scene(mv)
                    try:
                        camera = sc.Camera.orbit(mv, size=(width, height))
                        return scene.render(camera, iso=0.5, complete=True)
                    finally:
                        scene.close()

                before = len(faults.log)
                times = [_timed(fn, args.repeats) for fn in (opened, level0, render)]
                rows.append((label, *times, len(faults.log) - before))
            print(f"volume {args.size_volume}^3 float32, bricks {args.brick}^3 (sharded), image "
                  f"{width}x{height}; server: +{args.latency * 1e3:.0f} ms per request, "
                  f"{args.bandwidth / 1e6:.0f} MB/s per response; median of {args.repeats} "
                  "after a warm-up")
            print(f"{'':8}{'open (s)':>10}{'level 0 (s)':>13}{'render (s)':>12}{'requests':>10}")
            for label, a, b, c, n in rows:
                print(f"{label:8}{a:10.3f}{b:13.3f}{c:12.3f}{n:10d}")
            local, remote = rows
            print(f"{'ratio':8}{remote[1] / local[1]:10.1f}{remote[2] / local[2]:13.1f}"
                  f"{remote[3] / local[3]:12.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
