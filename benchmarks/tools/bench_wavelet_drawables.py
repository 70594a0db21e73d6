"""Per-brick Python overhead of a wavelet frame: the drawable list and a steady frame.

``wavelet_drawables`` turns a selection into the cut renderer's drawables (one per drawn brick or
octant). It runs every frame, so its cost per drawable adds to the renderer's own per-drawable cost.
This measures, on a Chmutov 64^3 degree-3 store (k = 8) from one orbit view, for ε = 0 (every
chunk, 512 drawables) and a small ε: the median time of the drawable list (per drawable) and
the median steady frame (bricks reused; 64x48 pixels, so the trace is small next to the overhead).

``--large``: a noise 512^3 degree-3 store seen whole (zoom 1) at 1024x768, ε = 5, 10 and 25
pixels (tens of thousands of drawables down to a few hundred): the median steady frame and its
trace.

Run ``python benchmarks/tools/bench_wavelet_drawables.py --label NAME --json OUT.json
[--large]`` once per code version, e.g. with ``PYTHONPATH=<old checkout>/src`` for the baseline
(the results file keeps every label's rows side by side).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

import splinecast as sc
from splinecast.multires.scenes.wavelet import wavelet_drawables
from splinecast.multires.wavelet.lod import select
from splinecast.multires.wavelet.store import build_wavelet_pyramid

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _machine import describe, median_ms  # noqa: E402


def _small(args) -> list[dict]:
    folder = Path(tempfile.mkdtemp())
    build_wavelet_pyramid(sc.demo("chmutov", size=64), folder / "w.zarr", degree=3, chunk=8,
                          dtype=np.float32)
    store = sc.read(folder / "w.zarr")
    camera = sc.Camera.orbit(store, azimuth=30, size=(64, 48))
    rows = []
    for eps in (0.0, 0.02):
        scene = sc.Scene(store, lod=eps)
        scene.render(camera, iso=0.0)  # compile, reconstruct, read
        selection = select(store.layout, store.ranges, camera.position, eps, 0.0, store.spacing,
                           store.origin)
        drawables = len(wavelet_drawables(selection, scene.reconstructor))
        drawables_ms = median_ms(lambda s=selection, r=scene.reconstructor: wavelet_drawables(s, r),
                                  args.repeats)
        frame_ms = median_ms(lambda s=scene: s.render(camera, iso=0.0), max(3, args.repeats // 3))
        rows.append({"label": args.label, "lod": eps, "drawables": drawables,
                     "drawables_ms": round(drawables_ms, 2),
                     "us_per_drawable": round(drawables_ms / drawables * 1e3, 1),
                     "steady_frame_ms": round(frame_ms, 1)})
        print(rows[-1], flush=True)
    return rows


def _large(args) -> list[dict]:
    folder = Path(tempfile.mkdtemp())
    vol = sc.demo("noise", size=512)
    build_wavelet_pyramid(vol, folder / "w.zarr", degree=3, chunk=8, dtype=np.float32)
    store = sc.read(folder / "w.zarr")
    camera = sc.Camera.orbit(vol, azimuth=30, elevation=20, size=(1024, 768), zoom=1.0)
    small = sc.Camera.orbit(vol, azimuth=30, elevation=20, size=(32, 24), zoom=1.0)
    pixel = math.radians(camera.fov) / camera.height
    rows = []
    for multiple in (5, 10, 25):
        scene = sc.Scene(store, lod=multiple * pixel)
        scene.render(small, iso=0.5)  # compile
        frame = scene.render(camera, iso=0.5)  # reconstruct, read
        traces: list[float] = []

        def steady(scene=scene, traces=traces):
            traces.append(scene.render(camera, iso=0.5).stats["trace_ms"])

        frame_ms = median_ms(steady, 5)
        rows.append({"label": args.label, "lod_pixels": multiple,
                     "drawables": frame.stats["drawables"], "steady_frame_ms": round(frame_ms, 1),
                     "steady_trace_ms": round(sorted(traces)[len(traces) // 2], 1)})
        print(rows[-1], flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--label", required=True)
    parser.add_argument("--json", required=True)
    parser.add_argument("--repeats", type=int, default=15)
    parser.add_argument("--large", action="store_true", help="the noise 512^3 store instead")
    args = parser.parse_args()
    rows = _large(args) if args.large else _small(args)
    out = Path(args.json)
    old = json.loads(out.read_text()) if out.exists() else {"machine": describe(), "rows": []}
    old["rows"] = [r for r in old["rows"] if r["label"] != args.label] + rows
    out.write_text(json.dumps(old, indent=1) + "\n")


if __name__ == "__main__":
    main()
