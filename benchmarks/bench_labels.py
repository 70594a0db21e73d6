"""Label volumes: a frame of many labels against one isosurface of their union.

A 128^3 uint8 label volume of ``--labels`` random ellipsoids (ids 1..n, later ones overwriting
earlier ones where they overlap) is rendered at 512x512 as labels (``Scene(vol, labels=True)``:
each label's indicator in a sub-volume, traced in the window of the image its box projects to,
composited by depth) and, as the baseline measured in the same run, as the 0.5 isosurface of the
union's indicator (``label > 0`` as float32: one surface, the least any label render can trace).
Both with antialiasing (the default) and without, trilinear; medians of ``--repeats`` steady
frames after a warm-up (kernels compiled, sub-scenes prepared). Also: the scene's preparation
(label boxes) and its first frame (every label's sub-scene prepared).

Run: ``python benchmarks/bench_labels.py [--labels 29] [--repeats 5]``; results go to
``benchmarks/results/labels.{json,md}``. Nothing is asserted.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _machine import describe, median_ms, write_results  # noqa: E402

import splinecast as sc  # noqa: E402

SIZE = 128
IMAGE = (512, 512)


def ellipsoid_labels(count: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    index = np.indices((SIZE,) * 3, dtype=np.float32)
    labels = np.zeros((SIZE,) * 3, np.uint8)
    for value in range(1, count + 1):
        centre = rng.uniform(20, SIZE - 20, 3)
        radii = rng.uniform(6, 16, 3)
        inside = (((index - centre[:, None, None, None]) / radii[:, None, None, None]) ** 2
                  ).sum(axis=0) <= 1
        labels[inside] = value
    return labels


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--labels", type=int, default=29)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    data = ellipsoid_labels(args.labels)
    vol = sc.Volume(data)
    cam = sc.Camera.orbit(vol, azimuth=30, elevation=20, size=IMAGE)
    sc.Scene(vol, labels=True).render(cam)  # compiles the kernels (not timed)
    start = time.perf_counter()
    scene = sc.Scene(vol, labels=True)
    prepare_ms = (time.perf_counter() - start) * 1e3
    start = time.perf_counter()
    first = scene.render(cam)
    first_ms = (time.perf_counter() - start) * 1e3
    union = sc.Scene(sc.Volume((data > 0).astype(np.float32)))
    union.render(cam, iso=0.5)
    rows = []
    for samples in (None, 1):
        labels_ms = median_ms(lambda s=samples: scene.render(cam, samples=s), args.repeats)
        union_ms = median_ms(lambda s=samples: union.render(cam, iso=0.5, samples=s),
                             args.repeats)
        frame = scene.render(cam, samples=samples)
        rows.append({"labels": len(scene.labels), "samples": frame.stats["samples"],
                     "labels_ms": labels_ms, "union_ms": union_ms,
                     "ratio": labels_ms / union_ms,
                     "traced_pixel_share": frame.stats["traced_pixels"] / (IMAGE[0] * IMAGE[1]),
                     "labels_in_view": int(np.count_nonzero(np.unique(frame.label))),
                     "prepare_ms": prepare_ms, "first_frame_ms": first_ms})
        print(rows[-1], flush=True)
    assert first.stats["labels"] == len(scene.labels)

    def cells(r: dict) -> list[str]:
        return [str(r["labels"]), str(r["samples"]), f"{r['labels_ms']:.0f} ms",
                f"{r['union_ms']:.0f} ms", f"{r['ratio']:.1f}x",
                f"{r['traced_pixel_share']:.2f}", f"{r['prepare_ms']:.0f} ms",
                f"{r['first_frame_ms']:.0f} ms"]

    write_results(
        HERE / "results" / "labels",
        "A frame of many labels against one isosurface of their union",
        f"`python benchmarks/bench_labels.py --labels {args.labels} --repeats {args.repeats}`. "
        f"{SIZE}^3 uint8 labels (random ellipsoids), {IMAGE[0]}x{IMAGE[1]}, trilinear; medians "
        "of steady frames after warm-up, both scenes in the same run. Traced pixels: the "
        "labels' windows added up, as a share of the image. Prepare: label boxes; first "
        "frame: every label's sub-scene prepared, then traced.",
        ["labels", "rays per edge pixel", "labels frame", "union frame", "labels / union",
         "traced pixels / image", "prepare", "first frame"],
        rows, cells, machine=describe())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
