"""Per-drawable overhead of the cut renderer: one launch per frame against one call per drawable.

A multiresolution frame is traced through many bricks (drawables), pyramid or wavelet. The cut
renderer used to call the segment entry point once per drawable (screen rectangle, tile camera,
state copied out and back, a parallel launch); it now traces all drawables in one compiled launch
(:mod:`splinecast.render.cut_driver`). Both paths are still in the code
(``CutRenderer.batched``), so this runs them side by side in one process, interleaved, on the
same cut, after warm-up:

- ``plain``: the synthetic volume of ``bench_multires.py`` (n^3 uint8) as an OME-Zarr pyramid,
  trilinear, iso and DVR, budget as given, ``lod=1``; against the in-memory renderer of level 0
  (the same data the cut mostly draws) and of the finest level that fits in the budget (the
  baseline of ``bench_multires.py``);
- ``wavelet``: the Chmutov distance field (n^3) as a degree-3 spline-wavelet store (float32),
  iso 0, for several ε (pixels of a 1024x768 image, as ``bench_wavelet.py``); against the
  full-resolution in-memory ``bspline3`` render.

Medians of wall time and of process CPU time (all threads; on a shared machine the CPU time is
the steadier of the two, and a parallel region's idle threads count in it).

    python benchmarks/tools/bench_cut_launch.py plain --n 192 --size 256x192 --budget 4MiB
    python benchmarks/tools/bench_cut_launch.py wavelet --n 128 --size 1024x768 --eps 100,200
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parents[1]  # benchmarks/
sys.path.insert(0, str(HERE))
from _machine import describe  # noqa: E402


def timed(fn, repeats: int) -> dict:
    """Median wall and CPU milliseconds of ``fn()`` (after one untimed call)."""
    fn()
    wall, cpu = [], []
    for _ in range(repeats):
        w, c = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - w)
        cpu.append(time.process_time() - c)
    return {"wall_ms": 1e3 * float(np.median(wall)), "cpu_ms": 1e3 * float(np.median(cpu)),
            "repeats": repeats}


def both_paths(scene, render, repeats: int) -> dict:
    """The steady frame per drawable and in one launch, interleaved (two rounds each)."""
    out: dict = {"per_drawable": [], "one_launch": []}
    for _ in range(2):
        for batched, name in ((False, "per_drawable"), (True, "one_launch")):
            scene.renderer.batched = batched
            out[name].append(timed(render, repeats))
    stats = scene.renderer.stats
    result = {}
    for name, runs in out.items():
        result[name] = {k: float(np.median([r[k] for r in runs])) for k in ("wall_ms", "cpu_ms")}
    result["drawables"] = int(stats["drawables"])
    return result


def run_plain(args) -> dict:
    import bench_multires as bm

    import splinecast as sc
    from splinecast.multires.store.budget import parse_bytes
    from splinecast.multires.store.pyramid import build_pyramid

    work = Path(args.workdir or tempfile.mkdtemp())
    work.mkdir(parents=True, exist_ok=True)
    src, store = work / f"src{args.n}.raw", work / f"p{args.n}.zarr"
    bm.make_source(src, args.n)
    if not store.exists():
        build_pyramid(str(src), str(store), progress=False)
    mv = sc.read(str(store))
    size = sc.camera.parse_size(args.size)
    cam = bm._view(mv, size)
    limit = parse_bytes(args.budget, "--budget")
    fits = next(p for p, lv in enumerate(mv.levels) if lv.nbytes <= limit)
    rows = []
    for mode, options in bm._modes().items():
        if mode not in args.modes.split(","):
            continue
        row: dict = {"mode": mode}
        for label, level in (("memory_level0", 0), ("memory_fits", fits)):
            vol = mv.level(level).to_volume(max_bytes=2**40)
            ref = sc.Scene(vol)
            row[label] = {"level": level, "shape": list(vol.shape),
                          **timed(lambda r=ref, o=options: r.render(cam, **o), args.repeats)}
        with sc.Scene(mv, budget=args.budget, lod=1.0) as scene:
            frame = scene.render(cam, complete=True, **options)
            row["cut_levels"] = {str(k): v for k, v in frame.stats["cut_levels"].items()}
            row.update(both_paths(scene, lambda s=scene, o=options: s.render(cam, **o),
                                  args.repeats))
        rows.append(row)
        print(json.dumps(row), flush=True)
    return {"kind": "plain", "n": args.n, "size": list(size), "budget": args.budget,
            "model": "trilinear", "lod": 1.0, "rows": rows}


def run_wavelet(args) -> dict:
    import splinecast as sc

    size = sc.camera.parse_size(args.size)
    vol = sc.demo("chmutov", size=args.n)
    source = sc.Volume(vol.data.astype(np.float32), spacing=vol.spacing, origin=vol.origin)
    folder = Path(tempfile.mkdtemp())
    sc.build_pyramid(source, folder / "w.zarr", kind="wavelet", degree=3, dtype=np.float32,
                     progress=False)
    store = sc.read(folder / "w.zarr")
    cam = sc.Camera.orbit(vol, azimuth=30, elevation=20, size=size, zoom=2.5)
    pixel = math.radians(cam.fov) / 768  # ε in pixels of a 1024x768 image (bench_wavelet.py)
    ref = sc.Scene(source, model="bspline3")
    full = timed(lambda: ref.render(cam, iso=0.0), args.repeats)
    rows = []
    for multiple in (float(v) for v in args.eps.split(",")):
        scene = sc.Scene(store, lod=multiple * pixel)
        scene.render(cam, iso=0.0)
        row = {"epsilon_pixels": multiple,
               **both_paths(scene, lambda s=scene: s.render(cam, iso=0.0), args.repeats)}
        rows.append(row)
        print(json.dumps(row), flush=True)
    return {"kind": "wavelet", "n": args.n, "size": list(size), "degree": 3,
            "dtype": "float32", "full_resolution": full, "rows": rows}


def markdown(result: dict, command: str, note: str) -> str:
    w, h = result["size"]
    lines = [f"# Cut renderer: one launch per frame vs one call per drawable "
             f"({result['kind']})", "",
             f"`{command}` — {note}", "",
             f"Machine: {result['machine']['cpu']}, {result['machine']['cores']} cores, "
             f"{result['machine']['numba_threads']} Numba threads. Medians of "
             f"{result['repeats']} steady frames after warm-up, both paths interleaved in one "
             "process (two rounds each). CPU = process "
             "time of all threads.", ""]
    if "load_average" in result:
        la = result["load_average"]
        lines += ["Load average (1, 5, 15 min) before: "
                  + ", ".join(f"{v:.2f}" for v in la["before"]) + "; after: "
                  + ", ".join(f"{v:.2f}" for v in la["after"]) + ".", ""]
    if result["kind"] == "plain":
        lines += [f"{result['n']}^3 uint8 pyramid, {w}x{h}, trilinear, budget "
                  f"{result['budget']}, lod 1.", "",
                  "| mode | drawables (levels) | per drawable wall / CPU ms "
                  "| one launch wall / CPU ms "
                  "| in-memory level 0 wall / CPU ms | in-memory fitting level wall / CPU ms "
                  "| one launch / level 0 (CPU) | one launch / fitting level (CPU) |",
                  "|---|---|---|---|---|---|---|---|"]
        for r in result["rows"]:
            a, b = r["per_drawable"], r["one_launch"]
            m0, mf = r["memory_level0"], r["memory_fits"]
            lines.append(
                f"| {r['mode']} | {r['drawables']} ({r['cut_levels']}) | {a['wall_ms']:.0f} / "
                f"{a['cpu_ms']:.0f} | {b['wall_ms']:.0f} / {b['cpu_ms']:.0f} | "
                f"{m0['wall_ms']:.0f} / {m0['cpu_ms']:.0f} | level {mf['level']}: "
                f"{mf['wall_ms']:.0f} / {mf['cpu_ms']:.0f} | {b['cpu_ms'] / m0['cpu_ms']:.2f}x |"
                f" {b['cpu_ms'] / mf['cpu_ms']:.2f}x |")
    else:
        f = result["full_resolution"]
        lines += [f"Chmutov {result['n']}^3, degree 3, float32 wavelet store, iso 0, {w}x{h}. "
                  f"Full-resolution in-memory bspline3: {f['wall_ms']:.0f} ms wall, "
                  f"{f['cpu_ms']:.0f} ms CPU.", "",
                  "| ε (pixels) | drawables | per drawable wall / CPU ms "
                  "| one launch wall / CPU ms | "
                  "speed-up (CPU) | full-res / one launch (CPU) |", "|---|---|---|---|---|---|"]
        for r in result["rows"]:
            a, b = r["per_drawable"], r["one_launch"]
            lines.append(f"| {r['epsilon_pixels']:g} | {r['drawables']} | {a['wall_ms']:.0f} / "
                         f"{a['cpu_ms']:.0f} | {b['wall_ms']:.0f} / {b['cpu_ms']:.0f} | "
                         f"{a['cpu_ms'] / b['cpu_ms']:.2f}x | {f['cpu_ms'] / b['cpu_ms']:.2f}x |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("kind", choices=["plain", "wavelet"])
    parser.add_argument("--n", type=int, default=192)
    parser.add_argument("--size", default="256x192")
    parser.add_argument("--budget", default="4MiB", help="plain: cache budget")
    parser.add_argument("--eps", default="100,200", help="wavelet: ε multiples (pixels)")
    parser.add_argument("--modes", default="iso,dvr", help="plain: modes to run")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--workdir", default=None, help="plain: where source and store go")
    parser.add_argument("--out", required=True, help="results stem (writes .md and .json)")
    parser.add_argument("--note", default="machine shared with other agents' jobs (noisy)")
    args = parser.parse_args()
    load_before = os.getloadavg()
    result = run_plain(args) if args.kind == "plain" else run_wavelet(args)
    result["load_average"] = {"before": list(load_before), "after": list(os.getloadavg())}
    result.update({"machine": describe(), "repeats": args.repeats, "note": args.note,
                   "command": ("python benchmarks/tools/bench_cut_launch.py "
                               + " ".join(sys.argv[1:]))})
    out = Path(args.out)
    out.with_suffix(".json").write_text(json.dumps(result, indent=1) + "\n")
    out.with_suffix(".md").write_text(markdown(result, result["command"], args.note))
    print(markdown(result, result["command"], args.note))


if __name__ == "__main__":
    main()
