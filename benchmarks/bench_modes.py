"""Render-mode benchmark: MIP, DVR and the 3D pre-integration table.

For the MNI152 MRI (when present, see ``_machine.MRI``) and a 256^3 seeded noise volume at 1024x768,
measures after JIT warm-up (median of repeated runs):

* analytic MIP against sampled MIP at the coarsest step (halving from 2 voxels) whose image agrees
  with the analytic one to 1e-3 of the data range, with the time ratio in the same process;
* DVR (2D/3D pre-integration, 0.5-voxel step) with a constant step and with the opacity-adaptive
  step (h_max = 8 h_min, n = 3), each without and with early ray termination at 0.99
  (the layout of Carmona & Froehlich 2011, table 4), each walking every cell of the visible blocks
  (``leap=False``) and leaping over cells that hold no sample (``leap=True``), with the
  leap/walk time ratio measured in the same process;
* the time to build the 3D pre-integration table for n = 64..1024, building every diagonal
  directly ("naive") and with the reuse recurrences (Carmona & Froehlich 2011, table 5 layout):
  uniform lengths k = 1..8 (eq. 14) and exponential lengths 2^j, j = 0..K-1, for K = 4 (the same
  range 1..8) and K = 7 (eq. 13).

Run ``python benchmarks/bench_modes.py [--quick] [--parts mip,dvr,tables]``; results go to
``benchmarks/results/modes[_quick].json`` and ``.md``. Parts not run keep their previous results
from the JSON file.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path

import numpy as np

import splinecast as sc

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _machine import MRI, describe, median_ms  # noqa: E402

HERE = Path(__file__).resolve().parent


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
            row = {"step": "adaptive" if adaptive else "constant", "termination": term}
            frames = {}
            for leap in (False, True):
                settings = sc.DVRSettings(step=0.5, preintegration="3d" if adaptive else "2d",
                                          adaptive=adaptive, h_max=4.0, exponent=3.0,
                                          termination=term, leap=leap)
                frames[leap] = scene.render(cam, mode="dvr", tf=tf, dvr=settings)  # warm-up
                key = "leap" if leap else "walk"
                row[f"{key}_ms"] = median_ms(
                    lambda s=settings: scene.render(cam, mode="dvr", tf=tf, dvr=s), repeats)
                row[f"{key}_cells"] = frames[leap].stats["mean_cells_visited"]
            row["ms"] = row["leap_ms"]
            row["leap_over_walk"] = row["leap_ms"] / row["walk_ms"]
            row["mean_samples"] = frames[True].stats["mean_samples"]
            row["max_diff_leap_vs_walk"] = float(
                np.abs(frames[True].rgba - frames[False].rgba).max())
            rows.append(row)
    return rows


def bench_tables(tf: sc.TransferFunction, sizes: list[int]) -> list:
    layouts = [("uniform", 8), ("exponential", 4), ("exponential", 7)]
    for layout, _ in layouts[:2]:  # compile
        sc.preintegrate(tf, n=16, steps=4, layout=layout)
        sc.preintegrate(tf, n=16, steps=4, layout=layout, reuse=False)
    rows = []
    for layout, steps in layouts:
        for n in sizes:
            repeats = 3 if n <= 256 else 1
            naive = statistics.median(
                sc.preintegrate(tf, n=n, h0=1.0, steps=steps, reuse=False,
                                layout=layout).build_ms for _ in range(repeats))
            opts = [sc.preintegrate(tf, n=n, h0=1.0, steps=steps, reuse=True, layout=layout)
                    for _ in range(repeats)]
            opt_ms = statistics.median(t.build_ms for t in opts)
            rows.append({"layout": layout, "n": n, "steps": steps, "naive_s": naive / 1e3,
                         "reuse_s": opt_ms / 1e3,
                         "improvement_pct": 100 * (1 - opt_ms / naive),
                         "composited_pct": 100 * opts[0].composited_fraction})
            print(json.dumps(rows[-1]), flush=True)
    return rows


def markdown(results: dict) -> str:
    m = results["machine"]
    cmds = results.get("part_commands") or {"all": results["command"]}
    ran = "; ".join(f"{part}: `{cmd}`" for part, cmd in sorted(cmds.items()))
    lines = [f"# Render modes benchmark\n\nMachine: {m.get('cpu', '?')}, "
             f"{m.get('cores', '?')} logical cores. Commands per part: {ran}. "
             "The machine is shared (2 cores, other jobs running), so timings are noisy: "
             "medians of repeated runs after warm-up; compare ratios within one part.\n"]
    for vol in results["volumes"]:
        mip = vol["mip"]
        lines.append(f"## {vol['label']} at {vol['size']}\n")
        lines.append("| MIP | ms/frame |\n|---|---|")
        lines.append(f"| analytic | {mip['exact_ms']:.1f} |")
        if mip["agree_step"] is not None:
            lines.append(f"| sampled, step {mip['agree_step']:g} voxel (agrees to 1e-3 of range) "
                         f"| {mip['sampled_ms']:.1f} (x{mip['speedup']:.2f} of analytic) |")
        lines.append("\nDVR: constant step 0.5 voxel (2D table) or opacity-adaptive step "
                     "0.5..4 voxels, exponent 3 (uniform 3D table). \"leap\" walks 4^3 blocks "
                     "between samples more than a voxel apart, \"cell walk\" loads every cell "
                     "of the visible blocks; the leap/walk ratio is measured in the same "
                     "process. Max |leap - walk| is the largest RGBA difference: non-zero only "
                     "where a transparent cell inside a visible block is leapt over.\n")
        lines.append("| DVR step | early termination | ms/frame, leap | ms/frame, cell walk "
                     "| leap/walk | samples/ray | cells/ray leap (walk) | max abs(leap - walk) |")
        lines.append("|---|---|---|---|---|---|---|---|")
        for r in vol["dvr"]:
            if "walk_ms" not in r:  # results of an older run
                lines.append(f"| {r['step']} | {r['termination'] or 'off'} | {r['ms']:.1f} "
                             f"| | | {r['mean_samples']:.1f} | |")
                continue
            lines.append(f"| {r['step']} | {r['termination'] or 'off'} | {r['leap_ms']:.1f} | "
                         f"{r['walk_ms']:.1f} | {r['leap_over_walk']:.2f} | "
                         f"{r['mean_samples']:.1f} | {r['leap_cells']:.1f} "
                         f"({r['walk_cells']:.1f}) | {r['max_diff_leap_vs_walk']:.2g} |")
        lines.append("")
    lines.append("## 3D pre-integration table build\n")
    lines.append("Uniform layout: lengths k = 1..K (eq. 14 reuse). Exponential layout: lengths "
                 "2^j, j = 0..K-1 (eq. 13 reuse). Median of 3 builds for n <= 256, one above.\n")
    lines.append("| layout | n | K | naive (s) | reuse (s) | improvement % | composited % |")
    lines.append("|---|---|---|---|---|---|---|")
    for r in results["tables"]:
        lines.append(f"| {r.get('layout', 'uniform')} | {r['n']} | {r['steps']} | "
                     f"{r['naive_s']:.3f} | {r['reuse_s']:.3f} | "
                     f"{r['improvement_pct']:.1f} | {r['composited_pct']:.1f} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes, few repeats")
    parser.add_argument("--out", default=str(HERE / "results"), help="output folder")
    parser.add_argument("--parts", default="mip,dvr,tables",
                        help="comma-separated parts to run (mip, dvr, tables); the others keep "
                             "their previous results")
    args = parser.parse_args()
    parts = {p.strip() for p in args.parts.split(",") if p.strip()}
    out = Path(args.out)
    stem = "modes_quick" if args.quick else "modes"
    old = {}
    if (out / f"{stem}.json").exists():
        old = json.loads((out / f"{stem}.json").read_text())
    old_volumes = {v["label"]: v for v in old.get("volumes", [])}
    size = (256, 192) if args.quick else (1024, 768)
    repeats = 2 if args.quick else 5
    volumes = [("noise", sc.demo("noise", size=96 if args.quick else 256))]
    if MRI.exists() and not args.quick:
        volumes.insert(0, ("mni152_t1_1mm", sc.read(str(MRI))))
    results = {"machine": describe(),
               "command": "python benchmarks/bench_modes.py" + (" --quick" if args.quick else "")
               + (f" --parts {args.parts}" if parts != {"mip", "dvr", "tables"} else ""),
               "volumes": []}
    results["part_commands"] = dict(old.get("part_commands", {}))
    for part in parts:
        results["part_commands"][part] = results["command"]
    for label, vol in volumes:
        if not parts & {"mip", "dvr"}:
            if label in old_volumes:
                results["volumes"].append(old_volumes[label])
            continue
        scene = sc.Scene(vol)
        cam = sc.Camera.orbit(vol, azimuth=30, elevation=20, size=size)
        lo, hi = vol.value_range
        span = hi - lo
        tf = sc.TransferFunction([(lo + 0.3 * span, 0.0), (lo + 0.5 * span, 0.05),
                                  (lo + 0.7 * span, 0.6)], domain=(lo, hi), colormap="bone")
        prev = old_volumes.get(label, {})
        entry = {"label": label, "shape": list(vol.shape), "size": f"{size[0]}x{size[1]}",
                 "mip": bench_mip(scene, cam, repeats) if "mip" in parts else prev.get("mip"),
                 "dvr": (bench_dvr(scene, cam, tf, repeats) if "dvr" in parts
                         else prev.get("dvr"))}
        results["volumes"].append(entry)
        print(json.dumps(entry, indent=1), flush=True)
    tf = sc.TransferFunction([(0.2, 0.0), (0.3, 0.8), (0.5, 0.0), (0.7, 0.3)], domain=(0, 1))
    sizes = [64, 128] if args.quick else [64, 128, 256, 512, 1024]
    if "tables" in parts:
        results["tables"] = bench_tables(tf, sizes)
    else:
        results["tables"] = old.get("tables", [])
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{stem}.json").write_text(json.dumps(results, indent=1) + "\n")
    (out / f"{stem}.md").write_text(markdown(results))
    print(f"wrote {out / stem}.json and .md")


if __name__ == "__main__":
    main()
