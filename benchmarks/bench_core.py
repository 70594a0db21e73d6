"""Core trilinear isosurface benchmark.

For Marschner–Lobb 128^3, the MNI152 MRI (when present, see ``_machine.MRI``) and a 256^3 seeded
noise volume, at 512x512 and 1024x768, measures after JIT warm-up:

* median ms per frame (wall time of ``Scene.render``) and rays per second;
* ms per isovalue change (block classification) and ms from a new isovalue to the finished image;
* mean cells visited / tested and blocks skipped per ray;
* the sampled reference renderer at decreasing steps, and the coarsest step whose image matches the
  exact one (no hit/miss disagreement, depth within 0.01 voxel), with the time ratio exact/sampled
  measured in the same process.

Run ``python benchmarks/bench_core.py [--quick]``; results go to ``benchmarks/results/core.json``
and ``core.md``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import splinecast as sc

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _machine import MRI, describe  # noqa: E402

HERE = Path(__file__).resolve().parent
STEPS = (2.0, 1.0, 0.5, 0.25, 0.125, 0.0625, 0.03125, 0.015625)


def median_ms(fn, repeats: int) -> tuple[float, list[float]]:
    """Median wall time of ``fn()`` in ms over ``repeats`` runs (the caller warms up first)."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append((time.perf_counter() - start) * 1e3)
    return statistics.median(times), times


def import_ms(repeats: int = 5) -> float:
    """Median wall time of ``python -c "import splinecast"`` in a fresh interpreter, in ms."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        subprocess.run([sys.executable, "-c", "import splinecast"], check=True)
        times.append((time.perf_counter() - start) * 1e3)
    baseline = []
    for _ in range(repeats):
        start = time.perf_counter()
        subprocess.run([sys.executable, "-c", "pass"], check=True)
        baseline.append((time.perf_counter() - start) * 1e3)
    return statistics.median(times) - statistics.median(baseline)


def voxel_depth_error(frame_a: sc.Frame, frame_b: sc.Frame, camera: sc.Camera,
                      volume: sc.Volume) -> tuple[int, float]:
    """Hit/miss disagreements and the largest depth difference in voxels between two frames."""
    disagree = int(np.count_nonzero(frame_a.hit != frame_b.hit))
    both = frame_a.hit & frame_b.hit
    if not both.any():
        return disagree, 0.0
    _, directions = camera.rays()
    # World distance along the ray -> index-space length (voxels).
    scale = np.linalg.norm(directions[both] / np.asarray(volume.spacing), axis=-1)
    err = np.abs(frame_a.depth[both] - frame_b.depth[both]) * scale
    return disagree, float(err.max())


def bench_volume(label: str, volume: sc.Volume, isos: list[float], sizes: list[tuple[int, int]],
                 repeats: int) -> dict:
    scene = sc.Scene(volume)
    result = {"volume": label, "shape": volume.shape, "dtype": str(volume.dtype),
              "prepare_ms": scene.prepare_ms, "iso": isos[0], "sizes": []}
    iso = isos[0]
    for size in sizes:
        cam = sc.Camera.orbit(volume, azimuth=30, elevation=20, size=size)
        scene.render(cam, iso=iso)  # warm-up: compilation and first touch of the data
        frame_ms, _ = median_ms(lambda cam=cam: scene.render(cam, iso=iso), repeats)
        exact = scene.render(cam, iso=iso)
        # New isovalue -> classification alone, and -> finished image (alternating isovalues).
        classify, change_total = [], []
        for k in range(repeats):
            value = isos[1 + k % (len(isos) - 1)]
            start = time.perf_counter()
            classify.append(scene.set_iso(value))
            scene.render(cam, iso=value)
            change_total.append((time.perf_counter() - start) * 1e3)
        scene.set_iso(iso)
        entry = {
            "width": size[0], "height": size[1],
            "frame_ms": frame_ms,
            "trace_ms": exact.stats["trace_ms"],
            "rays_per_s": size[0] * size[1] / (frame_ms / 1e3),
            "iso_change_classify_ms": statistics.median(classify),
            "iso_change_to_image_ms": statistics.median(change_total),
            "hits": exact.stats["hits"],
            "mean_cells_visited": exact.stats["mean_cells_visited"],
            "mean_cells_tested": exact.stats["mean_cells_tested"],
            "mean_blocks_skipped": exact.stats["mean_blocks_skipped"],
            "sampled": [],
        }
        matched = None
        for step in STEPS:
            scene.render(cam, iso=iso, method="sampled", step=step)
            ms, _ = median_ms(
                lambda cam=cam, step=step: scene.render(cam, iso=iso, method="sampled", step=step),
                max(1, repeats // 2),
            )
            sampled = scene.render(cam, iso=iso, method="sampled", step=step)
            disagree, depth_err = voxel_depth_error(exact, sampled, cam, volume)
            entry["sampled"].append({"step": step, "frame_ms": ms, "hit_miss_disagreements":
                                     disagree, "max_depth_error_voxels": depth_err})
            if matched is None and disagree == 0 and depth_err <= 0.01:
                matched = {"step": step, "frame_ms": ms, "exact_over_sampled": frame_ms / ms}
        entry["sampled_match"] = matched
        result["sizes"].append(entry)
        print(f"{label} {size[0]}x{size[1]}: {frame_ms:.1f} ms/frame, "
              f"iso change {entry['iso_change_classify_ms']:.2f} ms classify, "
              f"{entry['iso_change_to_image_ms']:.1f} ms to image, "
              f"{entry['mean_cells_visited']:.2f} cells/ray, match: {matched}", flush=True)
    return result


def markdown(results: dict) -> str:
    m = results["machine"]
    lines = [
        "# Core benchmark: exact trilinear isosurface",
        "",
        f"Machine: {m['cpu']}, {m['cores']} cores, numba {m['versions']['numba']} "
        f"({m['numba_threads']} threads, {m['numba_threading_layer']}), "
        f"numpy {m['versions']['numpy']}. Command: `{results['command']}`. "
        "Medians after warm-up.",
        "",
        f"`import splinecast`: {results['import_splinecast_ms']:.0f} ms (fresh interpreter, "
        "minus the interpreter's own start-up).",
        "",
        "| volume | image | ms/frame | Mrays/s | iso change: classify ms | iso change: to image ms "
        "| cells visited/ray | cells tested/ray | blocks skipped/ray | sampled step matching exact "
        "| sampled ms at that step | exact/sampled time |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for vol in results["volumes"]:
        for e in vol["sizes"]:
            match = e["sampled_match"]
            step = f"{match['step']:g}" if match else f"none <= {STEPS[-1]:g}"
            sms = f"{match['frame_ms']:.1f}" if match else "-"
            ratio = f"{match['exact_over_sampled']:.2f}" if match else "-"
            lines.append(
                f"| {vol['volume']} | {e['width']}x{e['height']} | {e['frame_ms']:.1f} | "
                f"{e['rays_per_s'] / 1e6:.2f} | {e['iso_change_classify_ms']:.2f} | "
                f"{e['iso_change_to_image_ms']:.1f} | {e['mean_cells_visited']:.2f} | "
                f"{e['mean_cells_tested']:.2f} | {e['mean_blocks_skipped']:.2f} | {step} | {sms} | "
                f"{ratio} |"
            )
    lines += ["", "Sampled reference per step (hit/miss disagreements, max depth error in voxels, "
              "ms/frame):", ""]
    for vol in results["volumes"]:
        for e in vol["sizes"]:
            cells = "; ".join(
                f"{s['step']:g}: {s['hit_miss_disagreements']} / {s['max_depth_error_voxels']:.3g}"
                f" / {s['frame_ms']:.0f} ms" for s in e["sampled"]
            )
            lines.append(f"- {vol['volume']} {e['width']}x{e['height']}: {cells}")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes, few repeats")
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--out", default=str(HERE / "results"), help="output folder")
    args = parser.parse_args()
    sizes = [(512, 512), (1024, 768)]
    repeats = args.repeats
    cases = [("marschner-lobb 128^3", lambda: sc.demo("marschner-lobb", size=128),
              [0.5, 0.3, 0.4, 0.6, 0.7])]
    if MRI.exists():
        cases.append(("MNI152 T1 MRI 197x233x189 uint8", lambda: sc.read(MRI),
                      [80.0, 40.0, 60.0, 100.0, 120.0]))
    else:
        print(f"skipping the MRI: {MRI} not found", flush=True)
    cases.append(("noise 256^3 (seed 0)", lambda: sc.demo("noise", size=256, seed=0),
                  [0.5, 0.4, 0.45, 0.55, 0.6]))
    if args.quick:
        sizes, repeats = [(256, 192)], 3
        cases = [(label.replace("128^3", "48^3").replace("256^3", "64^3"),
                  (lambda f=f, label=label: _shrink(f, label)), isos)
                 for label, f, isos in cases if "MRI" not in label]
    results = {"machine": describe(), "command": "python benchmarks/bench_core.py"
               + (" --quick" if args.quick else ""), "import_splinecast_ms": import_ms(),
               "volumes": []}
    for label, make, isos in cases:
        results["volumes"].append(bench_volume(label, make(), isos, sizes, repeats))
    results["machine"] = describe()  # threading layer is known after the first kernel ran
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    stem = "core_quick" if args.quick else "core"
    (out / f"{stem}.json").write_text(json.dumps(results, indent=2, default=float))
    (out / f"{stem}.md").write_text(markdown(results))
    print(markdown(results))


def _shrink(factory, label: str) -> sc.Volume:
    if "marschner" in label:
        return sc.demo("marschner-lobb", size=48)
    return sc.demo("noise", size=64, seed=0)


if __name__ == "__main__":
    main()
