"""Remote against local: the same OME-Zarr pyramid read from its folder and over HTTP from a
server on 127.0.0.1 that adds latency to every request and caps each response's bandwidth.

Measured (median of ``--repeats`` runs after one warm-up, each run with a fresh store object so
nothing is cached in memory; the disk cache is off):

- ``open``: metadata, tables and the coarsest level (what the first image draws from);
- ``level 0``: every chunk of the finest level;
- ``render``: a complete iso render (``complete=True``) at ``--size`` from a fresh scene;
- ``view`` (``--parts view``): from a fresh store object and scene, the first image (drawn at
  once from what is resident, ``wait=False``, as the viewer's first pass) and the complete view
  (frames that wait for their load budget until the cut is complete), both timed from the
  store's opening. ``requests`` is what the server saw, ``counted`` the frame's
  ``stats["remote_requests"]`` (the reader's own count, retries included), ``reads`` the most
  loader reads in flight at once (``stats["reads_peak"]``). ``--baseline-reads 1`` times the
  remote store a second time in the same run with ``SPLINECAST_REMOTE_READS=1`` (one loader
  read at a time), alternated with the others.

Run: ``python benchmarks/bench_remote.py --size-volume 256 --latency 0.05 --bandwidth 100e6``;
an existing pyramid: ``--store P.zarr --iso 128 --size 1024x768 --parts view --budget 256MiB``.
Nothing here is asserted: the numbers depend on the machine.
"""

from __future__ import annotations

import argparse
import os
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
    parser.add_argument("--store", help="serve this pyramid instead of building one")
    parser.add_argument("--iso", type=float, default=0.5)
    parser.add_argument("--budget", default="2GiB", help="the scenes' budget (default 2GiB)")
    parser.add_argument("--parts", default="open,level0,render", help="of open, level0, "
                        "render, view")
    parser.add_argument("--baseline-reads", type=int, default=0, help="with --parts view: "
                        "also time the remote store with SPLINECAST_REMOTE_READS set to this")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    if "view" in args.parts:
        return view_part(args, width, height)
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
                    scene = sc.Scene(mv, budget=args.budget)
                    try:
                        camera = sc.Camera.orbit(mv, size=(width, height))
                        return scene.render(camera, iso=args.iso, complete=True)
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


def _kinds(root: Path, log: list[tuple[str, str, str]]) -> dict[str, int]:
    """The server's requests by kind: HEAD (a shard's size), metadata, shard index (a range
    ending at the file's end) and chunk data (any other range)."""
    out = {"HEAD": 0, "metadata": 0, "index": 0, "chunk data": 0}  # an index: bytes=-n too
    sizes: dict[str, int] = {}
    for method, path, header in log:
        if method == "HEAD":
            out["HEAD"] += 1
        elif (path.endswith(("zarr.json", ".zattrs", ".zarray", ".zgroup", ".zmetadata"))
              or "/splinecast/" in path or not (root / path.lstrip("/")).is_file()):
            out["metadata"] += 1  # (with splinecast's tables, and names looked for, absent)
        else:
            if path not in sizes:
                sizes[path] = (root / path.lstrip("/")).stat().st_size
            end = header.rsplit("-", 1)[-1]
            tail = header.startswith("bytes=-") or (
                end.isdigit() and int(end) == sizes[path] - 1
                and not header.startswith("bytes=0-"))
            out["index" if tail else "chunk data"] += 1
    return out


def view_part(args: argparse.Namespace, width: int, height: int) -> int:
    """First image and complete view, local and remote side by side (one warm-up each, then
    ``--repeats`` runs alternated; medians)."""
    store = Path(args.store).resolve() if args.store else None
    if store is None:
        raise SystemExit("--parts view needs --store")
    faults = Faults(latency=args.latency, bandwidth=args.bandwidth)
    kinds: dict[str, int] = {}
    with FileServer(store.parent, faults) as server:
        sources = {"local": str(store), "remote": f"{server.url}/{store.name}"}
        if args.baseline_reads:
            sources[f"remote, {args.baseline_reads} read"] = sources["remote"]

        def view(label: str) -> tuple[float, float, int, int, int, int]:
            source = sources[label]
            start = time.perf_counter()
            before = len(faults.log)
            kept = os.environ.get("SPLINECAST_REMOTE_READS")
            if label.startswith("remote, "):
                os.environ["SPLINECAST_REMOTE_READS"] = str(args.baseline_reads)
            try:
                mv = sc.read(source)  # (the remote settings are read here)
            finally:
                if kept is None:
                    os.environ.pop("SPLINECAST_REMOTE_READS", None)
                else:
                    os.environ["SPLINECAST_REMOTE_READS"] = kept
            with sc.Scene(mv, budget=args.budget) as scene:
                camera = sc.Camera.orbit(mv, azimuth=30, elevation=25, size=(width, height),
                                         zoom=1.3)
                scene.render(camera, iso=args.iso, wait=False)
                first = time.perf_counter() - start
                frame = scene.render(camera, iso=args.iso, complete=True)
                assert frame.stats["complete"]
                if label == "remote":
                    kinds.clear()
                    kinds.update(_kinds(store.parent, faults.log[before:]))
                return (first, time.perf_counter() - start, int(frame.stats["cut_bricks"]),
                        len(faults.log) - before, int(frame.stats.get("remote_requests", 0)),
                        int(frame.stats.get("reads_peak", 1)))

        for label in sources:
            view(label)  # warm-up: kernels compiled, connections open
        runs: dict[str, list[tuple[float, float, int, int, int, int]]] = {k: [] for k in sources}
        for _ in range(args.repeats):
            for label in sources:
                runs[label].append(view(label))
    print(f"store {store.name} ({sc.read(store).levels[0].shape}), image {width}x{height}, "
          f"budget {args.budget}; server: +{args.latency * 1e3:.0f} ms per request, "
          f"{args.bandwidth / 1e6:.0f} MB/s per response; median of {args.repeats} after a "
          "warm-up, local and remote alternated")
    print(f"{'':16}{'first image (s)':>16}{'complete view (s)':>19}{'cut bricks':>12}"
          f"{'requests':>10}{'counted':>9}{'reads':>7}")
    med = {label: [statistics.median(r[i] for r in rows) for i in range(6)]
           for label, rows in runs.items()}
    for label, (first, complete, bricks, requests, counted, reads) in med.items():
        print(f"{label:16}{first:16.2f}{complete:19.2f}{bricks:12.0f}{requests:10.0f}"
              f"{counted:9.0f}{reads:7.0f}")
    print("requests of the last remote run by kind: "
          + ", ".join(f"{n} {kind}" for kind, n in kinds.items()))
    if args.repeats > 1:
        for label, rows in runs.items():
            print(f"{label} runs, complete view (s): "
                  + ", ".join(f"{r[1]:.2f}" for r in rows))
    for label in med:
        if label != "local":
            print(f"{'ratio' + label[6:]:16}{med[label][0] / med['local'][0]:16.1f}"
                  f"{med[label][1] / med['local'][1]:19.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
