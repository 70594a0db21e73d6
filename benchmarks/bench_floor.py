"""Time per ray above the floor, and bytes written per pixel, of every mode.

The floor (:mod:`floor_kernel`) generates each pixel's ray, clips it to the volume's box and
writes one colour: what any ray caster pays before it does anything with the ray. For every mode
(iso, multi-iso, MIP, DVR) and a few models, at 1024x768 on Marschner-Lobb 256^3 and the MNI152 MRI
(when present, see ``_machine.MRI``), this measures after JIT warm-up the median frame time

* with every output (the default ``Scene.render``), and
* with colour only (``outputs=("rgba",)``: what the viewer and the movie writer ask for),

and reports ``(frame - floor) / rays`` in ns, the ratio frame / floor, and the bytes of output
buffers the render fills per pixel. The floor and the two renders take turns, so a change of
the machine's load hits all three alike.

    python benchmarks/bench_floor.py [--quick] [--repeats N] [--volumes ml,mri]
        [--only MODEL:MODE,...] [--json PATH] [--clock wall|cpu]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

import splinecast as sc

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _machine import MRI, describe  # noqa: E402
from floor_kernel import floor_render  # noqa: E402

COLOUR = ("rgba",)
BUFFERS = ("rgba", "depth", "position", "normal", "face", "cells_visited", "cells_tested",
           "blocks_skipped", "value")


def _volumes(quick: bool, which: set[str]) -> list[tuple[str, sc.Volume, float, float]]:
    """(label, volume, isovalue, multi-iso spread)."""
    out = []
    if "ml" in which:
        size = 64 if quick else 256
        out.append((f"ML {size}^3", sc.demo("marschner-lobb", size=size), 0.5, 0.1))
    if "mri" in which and MRI.exists() and not quick:
        out.append(("MRI", sc.read(MRI), 80.0, 30.0))
    return out


def _cases(iso: float, spread: float) -> list[tuple[str, str, dict]]:
    """(model, mode, render keyword arguments): every mode with trilinear, the isosurface of
    the higher-order models (their MIP and DVR take minutes per frame)."""
    cases = [("trilinear", "iso", {"iso": iso}),
             ("trilinear", "multi-iso", {"iso": [iso - spread, iso, iso + spread]}),
             ("trilinear", "mip", {"mode": "mip"}),
             ("trilinear", "dvr", {"mode": "dvr"})]
    for model in ("s31", "bspline3"):
        cases.append((model, "iso", {"iso": iso}))
    return cases


def _bytes_per_pixel(frame: sc.Frame, rays: int) -> dict[str, float]:
    """Bytes of each buffer the render filled, per pixel (the per-ray counters behind
    ``mean_samples`` / ``mean_layers`` are int32: 4 more with the statistics)."""
    sizes = {name: getattr(frame, name).nbytes / rays for name in BUFFERS
             if getattr(frame, name) is not None}
    if frame.cells_visited is not None and ("mean_samples" in frame.stats
                                            or "mean_layers" in frame.stats):
        sizes["samples_or_layers"] = 4.0
    return sizes


def _time(fn: Callable[[], object], clock: Callable[[], float], calls: int = 1) -> float:
    """Milliseconds per call of ``fn`` (the least of ``calls`` calls)."""
    best = float("inf")
    for _ in range(calls):
        start = clock()
        fn()
        best = min(best, (clock() - start) * 1e3)
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="ML 64^3 at 256x192")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--volumes", default="ml,mri")
    ap.add_argument("--only", help="comma-separated MODEL:MODE cases (default: all)")
    ap.add_argument("--json", help="output path (default results/floor[_quick].json)")
    ap.add_argument("--clock", choices=["wall", "cpu"], default="wall",
                    help="wall time, or this process's CPU time (steadier on a loaded machine; "
                         "use with NUMBA_NUM_THREADS=1)")
    args = ap.parse_args()
    clock = time.process_time if args.clock == "cpu" else time.perf_counter
    name = "floor_quick" if args.quick else "floor"
    path = Path(args.json) if args.json else HERE / "results" / f"{name}.json"
    size = (256, 192) if args.quick else (1024, 768)
    only = set(args.only.split(",")) if args.only else None
    rows = []
    for label, vol, iso, spread in _volumes(args.quick, set(args.volumes.split(","))):
        cam = sc.Camera.orbit(vol, azimuth=30, elevation=25, size=size)
        rays = cam.width * cam.height
        floor_render(cam, vol.bounds)  # compile
        scenes: dict[str, sc.Scene] = {}
        for model, mode, kwargs in _cases(iso, spread):
            if only is not None and f"{model}:{mode}" not in only:
                continue
            scene = scenes.setdefault(model, sc.Scene(vol, model=model))
            full = scene.render(cam, **kwargs)  # warm-up: compilation, classification
            colour = scene.render(cam, **kwargs, outputs=COLOUR)
            assert np.array_equal(full.rgba, colour.rgba)
            # The three take turns, so a change of the machine's load hits them alike.
            floors, fulls, colours = [], [], []
            for _ in range(args.repeats):
                floors.append(_time(lambda: floor_render(cam, vol.bounds), clock, 3))  # noqa: B023
                fulls.append(_time(lambda: scene.render(cam, **kwargs), clock))  # noqa: B023
                colours.append(_time(lambda: scene.render(cam, **kwargs, outputs=COLOUR),  # noqa: B023
                                     clock))
            floor, t_full, t_colour = (statistics.median(v) for v in (floors, fulls, colours))
            row = {
                "volume": label, "model": model, "mode": mode, "rays": rays,
                "floor_ms": floor, "all_ms": t_full, "rgba_ms": t_colour,
                "all_ns_above_floor": (t_full - floor) * 1e6 / rays,
                "rgba_ns_above_floor": (t_colour - floor) * 1e6 / rays,
                "all_over_floor": t_full / floor, "rgba_over_floor": t_colour / floor,
                "rgba_gain": t_full / t_colour,
                "bytes_all": _bytes_per_pixel(full, rays),
                "bytes_rgba": _bytes_per_pixel(colour, rays),
                "hit_fraction": float(np.isfinite(full.depth).mean()),
            }
            rows.append(row)
            print(json.dumps(row), flush=True)
    out = {"machine": describe(), "quick": args.quick, "repeats": args.repeats,
           "clock": args.clock,
           "image": list(size), "build": _revision(), "rows": rows}
    path.write_text(json.dumps(out, indent=1))
    path.with_suffix(".md").write_text(_markdown(out))


def _revision() -> str | None:
    import subprocess

    done = subprocess.run(["git", "-C", str(HERE), "rev-parse", "--short", "HEAD"],
                          capture_output=True, text=True)
    return done.stdout.strip() or None


def _markdown(out: dict) -> str:
    w, h = out["image"]
    lines = [f"# Time per ray above the floor ({'quick' if out['quick'] else 'full'})", "",
             f"Machine: {out['machine']}", "",
             f"Build {out['build']}, {w}x{h}, `Camera.orbit(azimuth=30, elevation=25)`, median "
             f"of {out['repeats']} renders after a warm-up, {out['clock']} clock; the floor, the "
             "default render and the colour-only render take turns (the floor: best of 3 calls "
             "per turn). The floor "
             "generates each pixel's ray, clips it to the volume box and writes one float32 "
             "RGBA colour (benchmarks/floor_kernel.py). "
             "\"all\": the default render (every output); \"rgba\": `outputs=(\"rgba\",)`. "
             "Bytes: output buffers filled per pixel.", "",
             "| volume | model | mode | floor ms | all ms | rgba ms | all / rgba | "
             "ns/ray above floor (all) | (rgba) | rgba / floor | bytes/px all | rgba |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in out["rows"]:
        lines.append(
            f"| {r['volume']} | {r['model']} | {r['mode']} | {r['floor_ms']:.1f} | "
            f"{r['all_ms']:.1f} | {r['rgba_ms']:.1f} | {r['rgba_gain']:.3f} | "
            f"{r['all_ns_above_floor']:.0f} | {r['rgba_ns_above_floor']:.0f} | "
            f"{r['rgba_over_floor']:.1f} | {sum(r['bytes_all'].values()):.0f} | "
            f"{sum(r['bytes_rgba'].values()):.0f} |")
    lines += ["", "Bytes per pixel by buffer (all outputs):", ""]
    seen = set()
    for r in out["rows"]:
        key = (r["mode"], tuple(sorted(r["bytes_all"].items())))
        if key in seen:
            continue
        seen.add(key)
        parts = ", ".join(f"{k} {v:g}" for k, v in r["bytes_all"].items())
        lines.append(f"- {r['mode']}: {parts}")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
