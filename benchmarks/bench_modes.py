"""Render-mode benchmark (issue 5): MIP, DVR and the 3D pre-integration table.

For the MNI152 MRI in ../shared/data (when present) and a 256^3 seeded noise volume at 1024x768,
measures after JIT warm-up (median of repeated runs):

* analytic MIP against sampled MIP at the coarsest step (halving from 2 voxels) whose image agrees
  with the analytic one to 1e-3 of the data range, with the time ratio in the same process;
* DVR (2D/3D pre-integration, 0.5-voxel step) with a constant step and with the opacity-adaptive
  step (h_max = 8 h_min, n = 3), each without and with early ray termination at 0.99
  (the layout of reference 002, table 4);
* the time to build the 3D pre-integration table (uniform lengths k = 1..8) for n = 64..1024,
  building every diagonal directly ("naive") and with the reuse recurrence (reference 002,
  table 5 layout).

Run ``python benchmarks/bench_modes.py [--quick]``; results go to
``benchmarks/results/modes[_quick].json`` and ``.md``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

import splinecast as sc

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _machine import describe  # noqa: E402

HERE = Path(__file__).resolve().parent
MRI = HERE.parent.parent / "shared" / "data" / "mni152_t1_1mm.nii.gz"


def median_ms(fn, repeats: int) -> float:
    """Median wall time of ``fn()`` in ms (the caller warms up first)."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append((time.perf_counter() - start) * 1e3)
    return statistics.median(times)


def bench_mip(scene: sc.Scene, cam: sc.Camera, repeats: int) -> dict:
    lo, hi = scene.volume.value_range
    tol = 1e-3 * (hi - lo)
    exact = scene.render(cam, mode="mip")
    exact_ms = median_ms(lambda: scene.render(cam, mode="mip"), repeats)
    step, agreed = 2.0, None
    while step >= 1 / 64:
        frame = scene.render(cam, mode="mip", method="sampled", step=step)
        err = float(np.nanmax(np.abs(frame.value - exact.value)))
        if err <= tol:
            agreed = step
            break
        step /= 2
    row = {"exact_ms": exact_ms, "tolerance": tol, "agree_step": agreed}
    if agreed is not None:
        row["sampled_ms"] = median_ms(
            lambda: scene.render(cam, mode="mip", method="sampled", step=agreed), repeats)
        row["speedup"] = row["sampled_ms"] / exact_ms
    return row


def bench_dvr(scene: sc.Scene, cam: sc.Camera, tf: sc.TransferFunction, repeats: int) -> list:
    rows = []
    for adaptive in (False, True):
        for term in (None, 0.99):
            settings = sc.DVRSettings(step=0.5, preintegration="3d" if adaptive else "2d",
                                      adaptive=adaptive, h_max=4.0, exponent=3.0,
                                      termination=term)
            frame = scene.render(cam, mode="dvr", tf=tf, dvr=settings)  # warm-up + table
            ms = median_ms(lambda s=settings: scene.render(cam, mode="dvr", tf=tf, dvr=s),
                           repeats)
            rows.append({"step": "adaptive" if adaptive else "constant",
                         "termination": term, "ms": ms,
                         "mean_samples": frame.stats["mean_samples"]})
    return rows


def bench_tables(tf: sc.TransferFunction, sizes: list[int], steps: int) -> list:
    sc.preintegrate(tf, n=16, steps=4)  # compile
    sc.preintegrate(tf, n=16, steps=4, reuse=False)
    rows = []
    for n in sizes:
        naive = sc.preintegrate(tf, n=n, h0=1.0, steps=steps, reuse=False).build_ms
        opt = sc.preintegrate(tf, n=n, h0=1.0, steps=steps, reuse=True)
        rows.append({"n": n, "steps": steps, "naive_s": naive / 1e3,
                     "reuse_s": opt.build_ms / 1e3,
                     "improvement_pct": 100 * (1 - opt.build_ms / naive),
                     "composited_pct": 100 * opt.composited_fraction})
    return rows


def markdown(results: dict) -> str:
    m = results["machine"]
    lines = [f"# Render modes benchmark\n\nMachine: {m.get('cpu', '?')}, "
             f"{m.get('cores', '?')} logical cores. Command: `{results['command']}`. "
             "The machine is shared, so timings are noisy.\n"]
    for vol in results["volumes"]:
        mip = vol["mip"]
        lines.append(f"## {vol['label']} at {vol['size']}\n")
        lines.append("| MIP | ms/frame |\n|---|---|")
        lines.append(f"| analytic | {mip['exact_ms']:.1f} |")
        if mip["agree_step"] is not None:
            lines.append(f"| sampled, step {mip['agree_step']:g} voxel (agrees to 1e-3 of range) "
                         f"| {mip['sampled_ms']:.1f} (x{mip['speedup']:.2f} of analytic) |")
        lines.append("\n| DVR step | early termination | ms/frame | samples/ray |")
        lines.append("|---|---|---|---|")
        for r in vol["dvr"]:
            lines.append(f"| {r['step']} | {r['termination'] or 'off'} | {r['ms']:.1f} | "
                         f"{r['mean_samples']:.1f} |")
        lines.append("")
    lines.append("## 3D pre-integration table build (uniform lengths k = 1..K)\n")
    lines.append("| n | K | naive (s) | reuse (s) | improvement % | composited % |")
    lines.append("|---|---|---|---|---|---|")
    for r in results["tables"]:
        lines.append(f"| {r['n']} | {r['steps']} | {r['naive_s']:.3f} | {r['reuse_s']:.3f} | "
                     f"{r['improvement_pct']:.1f} | {r['composited_pct']:.1f} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes, few repeats")
    parser.add_argument("--out", default=str(HERE / "results"), help="output folder")
    args = parser.parse_args()
    size = (256, 192) if args.quick else (1024, 768)
    repeats = 2 if args.quick else 5
    volumes = [("noise", sc.demo("noise", size=96 if args.quick else 256))]
    if MRI.exists() and not args.quick:
        volumes.insert(0, ("mni152_t1_1mm", sc.read(str(MRI))))
    results = {"machine": describe(),
               "command": "python benchmarks/bench_modes.py" + (" --quick" if args.quick else ""),
               "volumes": []}
    for label, vol in volumes:
        scene = sc.Scene(vol)
        cam = sc.Camera.orbit(vol, azimuth=30, elevation=20, size=size)
        lo, hi = vol.value_range
        span = hi - lo
        tf = sc.TransferFunction([(lo + 0.3 * span, 0.0), (lo + 0.5 * span, 0.05),
                                  (lo + 0.7 * span, 0.6)], domain=(lo, hi), colormap="bone")
        entry = {"label": label, "shape": list(vol.shape), "size": f"{size[0]}x{size[1]}",
                 "mip": bench_mip(scene, cam, repeats), "dvr": bench_dvr(scene, cam, tf, repeats)}
        results["volumes"].append(entry)
        print(json.dumps(entry, indent=1), flush=True)
    tf = sc.TransferFunction([(0.2, 0.0), (0.3, 0.8), (0.5, 0.0), (0.7, 0.3)], domain=(0, 1))
    sizes = [64, 128] if args.quick else [64, 128, 256, 512, 1024]
    results["tables"] = bench_tables(tf, sizes, 8)
    print(json.dumps(results["tables"], indent=1))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    stem = "modes_quick" if args.quick else "modes"
    (out / f"{stem}.json").write_text(json.dumps(results, indent=1) + "\n")
    (out / f"{stem}.md").write_text(markdown(results))
    print(f"wrote {out / stem}.json and .md")


if __name__ == "__main__":
    main()
