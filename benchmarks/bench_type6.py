"""Type-6 spline benchmark: isovalue change and frame times of s31 and qss.

For Marschner–Lobb 64^3/128^3/256^3, the MNI152 MRI (when present, see ``_machine.MRI``) and a 256^3
noise volume, measures after JIT warm-up (medians):

* isovalue change split into cube classification, tetrahedron classification, compaction and (for
  the precomputed variant) coefficient storage; active cubes, tetrahedra, tetrahedra per cube;
* preparation time (includes the iso-independent exact per-cube coefficient ranges) and memory of
  the on-the-fly and precomputed variants (and of the per-cube ranges);
* ms per frame at 1280x1024 and 1024x768 for trilinear (baseline, same process), qss and s31
  (on the fly and precomputed), and the ratio to trilinear;
* on Marschner–Lobb, the mean and 95th-percentile angle between rendered and analytic normals.

Run ``python benchmarks/bench_type6.py [--quick]``; results go to ``benchmarks/results/type6*.json``
and ``.md``. The machine is described in the JSON; timings on a shared 2-core machine are noisy.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numba
import numpy as np

import splinecast as sc
from splinecast.io.synthetic import marschner_lobb_gradient

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _machine import MRI, describe, median_ms  # noqa: E402

HERE = Path(__file__).resolve().parent
VARIANTS = [("trilinear", {}), ("qss", {}), ("s31", {}), ("s31", {"precompute": True})]


def normal_angles(frame: sc.Frame, volume: sc.Volume) -> tuple[float, float]:
    """Mean and 95th percentile angle (degrees) to the analytic Marschner–Lobb normal."""
    pos = frame.position[frame.hit]
    g = marschner_lobb_gradient(pos[:, 0], pos[:, 1], pos[:, 2])
    sign = 1.0 if volume.metadata.get("inside", "high") == "high" else -1.0
    expected = -sign * g / np.linalg.norm(g, axis=1, keepdims=True)
    cos = np.clip(np.sum(frame.normal[frame.hit] * expected, axis=1), -1.0, 1.0)
    ang = np.degrees(np.arccos(cos))
    return float(ang.mean()), float(np.percentile(ang, 95))


def bench_volume(label: str, volume: sc.Volume, isos: list[float], sizes, repeats: int,
                 analytic: bool) -> dict:
    result = {"volume": label, "shape": volume.shape, "dtype": str(volume.dtype), "iso": isos[0],
              "models": []}
    baseline: dict = {}
    for name, opts in VARIANTS:
        tag = name + ("+precompute" if opts.get("precompute") else "")
        start = time.perf_counter()
        scene = sc.Scene(volume, model=name, **opts)
        entry = {"model": tag, "prepare_ms": (time.perf_counter() - start) * 1e3, "sizes": []}
        if hasattr(scene.model, "cube_lo"):
            # Iso-independent precomputation: exact per-cube coefficient ranges (float32 pair).
            entry["cube_bounds_bytes"] = int(scene.model.cube_lo.nbytes
                                             + scene.model.cube_hi.nbytes)
        if hasattr(scene.model, "classify"):
            scene.set_iso(isos[1])  # warm-up
            stats = []
            for k in range(repeats):
                scene.set_iso(isos[k % len(isos)] if k % 2 else isos[0])
                stats.append(dict(scene.iso_stats))
            scene.set_iso(isos[0])
            at_iso = dict(scene.iso_stats)
            for key in ("cube_classify_ms", "tet_classify_ms", "compact_ms", "precompute_ms",
                        "iso_change_ms"):
                entry[key] = statistics.median(s[key] for s in stats)
            for key in ("cubes_candidate", "cubes_active", "tets_active", "tets_per_active_cube",
                        "memory_on_the_fly_bytes", "memory_precomputed_bytes"):
                entry[key] = at_iso[key]
        else:
            scene.set_iso(isos[0])
            entry["iso_change_ms"] = median_ms(lambda s=scene: (s.set_iso(isos[1]),
                                                                s.set_iso(isos[0])), repeats) / 2
        for size in sizes:
            cam = sc.Camera.orbit(volume, azimuth=30, elevation=20, size=size)
            frame = scene.render(cam, iso=isos[0])  # warm-up
            ms = median_ms(lambda cam=cam, s=scene: s.render(cam, iso=isos[0]), repeats)
            e = {"width": size[0], "height": size[1], "frame_ms": ms, "hits": frame.stats["hits"],
                 "mean_cubes_visited": frame.stats["mean_cells_visited"],
                 "mean_tested": frame.stats["mean_cells_tested"]}
            if name == "trilinear":
                baseline[size] = ms
            else:
                e["over_trilinear"] = ms / baseline[size]
            if analytic:
                e["normal_angle_mean_deg"], e["normal_angle_p95_deg"] = normal_angles(frame, volume)
            entry["sizes"].append(e)
            print(f"{label} {tag} {size[0]}x{size[1]}: {ms:.0f} ms/frame"
                  + (f", iso change {entry['iso_change_ms']:.0f} ms" if "iso_change_ms" in entry
                     else "")
                  + (f", normals {e['normal_angle_mean_deg']:.2f}/{e['normal_angle_p95_deg']:.2f}"
                     " deg" if analytic else ""), flush=True)
        result["models"].append(entry)
        del scene
    return result


def markdown(results: dict) -> str:
    m = results["machine"]
    lines = [f"# Type-6 splines benchmark ({results['command']})", "",
             f"Machine: {m.get('cpu', '?')}, {m.get('cores', '?')} cores; timings are medians "
             "after warm-up on a shared machine (noisy).", ""]
    lines.append("| volume | model | prepare ms | iso change ms (cubes / tets / compact / store)"
                 " | active cubes | tets/cube | memory on-the-fly / precomputed MB (cube bounds)"
                 " | frame ms per size (x trilinear) | normal angle mean/p95 deg |")
    lines.append("|---|---|---|---|---|---|---|---|---|")
    for v in results["volumes"]:
        for e in v["models"]:
            if "cube_classify_ms" in e:
                change = (f"{e['iso_change_ms']:.0f} ({e['cube_classify_ms']:.0f} / "
                          f"{e['tet_classify_ms']:.0f} / {e['compact_ms']:.0f} / "
                          f"{e['precompute_ms']:.0f})")
                act = f"{e['cubes_active']}"
                tpc = f"{e['tets_per_active_cube']:.1f}"
                mem = (f"{e['memory_on_the_fly_bytes'] / 2**20:.0f} / "
                       f"{e['memory_precomputed_bytes'] / 2**20:.0f}"
                       f" ({e.get('cube_bounds_bytes', 0) / 2**20:.0f})")
            else:
                change, act, tpc, mem = f"{e['iso_change_ms']:.1f}", "-", "-", "-"
            frames = ", ".join(
                f"{s['width']}x{s['height']}: {s['frame_ms']:.0f}"
                + (f" ({s['over_trilinear']:.1f}x)" if "over_trilinear" in s else "")
                for s in e["sizes"])
            normals = ", ".join(f"{s['normal_angle_mean_deg']:.2f}/{s['normal_angle_p95_deg']:.1f}"
                                for s in e["sizes"] if "normal_angle_mean_deg" in s) or "-"
            lines.append(f"| {v['volume']} | {e['model']} | {e['prepare_ms']:.0f} | {change} | "
                         f"{act} | {tpc} | {mem} | {frames} | {normals} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help="Marschner-Lobb 64^3/128^3 and the MRI only, 2 repeats")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", default=str(HERE / "results"), help="output folder")
    args = parser.parse_args()
    numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))  # the 2-core target
    sizes = [(1280, 1024), (1024, 768)]
    ml_isos = [0.5, 0.3, 0.4, 0.6, 0.7]
    cases = [(f"marschner-lobb {n}^3", lambda n=n: sc.demo("marschner-lobb", size=n), ml_isos,
              True) for n in (64, 128, 256)]
    if MRI.exists():
        cases.append(("MNI152 T1 MRI 197x233x189 uint8", lambda: sc.read(MRI),
                      [80.0, 40.0, 60.0, 100.0, 120.0], False))
    else:
        print(f"skipping the MRI: {MRI} not found", flush=True)
    cases.append(("noise 256^3 (seed 0)", lambda: sc.demo("noise", size=256, seed=0),
                  [0.5, 0.4, 0.45, 0.55, 0.6], False))
    repeats = args.repeats
    if args.quick:
        cases = [c for c in cases if "256" not in c[0]]
        repeats = 2
    results = {"machine": describe(), "command": "python benchmarks/bench_type6.py"
               + (" --quick" if args.quick else ""), "volumes": []}
    for label, make, isos, analytic in cases:
        results["volumes"].append(bench_volume(label, make(), isos, sizes, repeats, analytic))
    results["machine"] = describe()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    stem = "type6_quick" if args.quick else "type6"
    (out / f"{stem}.json").write_text(json.dumps(results, indent=2, default=float))
    (out / f"{stem}.md").write_text(markdown(results))
    print(markdown(results))


if __name__ == "__main__":
    main()
