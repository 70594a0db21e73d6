"""A store that fits its budget against the same volume read into memory.

For each ``--sizes`` N, the Marschner-Lobb demo volume (N^3 float32) is written as a NIfTI file
and as an OME-Zarr pyramid (``sc.build_pyramid``, 32^3 bricks), then measured side by side in
the same run:

- ``CLI``: wall time of ``splinecast render FILE -o OUT.png --quiet`` (a fresh process each; one
  warm-up run of each first, so the Numba cache is warm), median of ``--repeats``, store and
  NIfTI alternated;
- ``steady frame``: in one process, the same view (``Camera.orbit``, 512x512, iso 0.5, no
  antialiasing) rendered again and again after a warm-up: ``Scene(store, budget=...)`` (the
  level held whole when the cut is level 0 everywhere), the same with ``whole_level=False``
  (every frame drawn from bricks, what a store always did before) and the in-memory ``Scene`` of
  the volume; median of ``--repeats`` frames each.

Run: ``python benchmarks/bench_small_store.py [--sizes 128,256] [--repeats 5]``; results go to
``benchmarks/results/small_store.{json,md}``. Nothing is asserted: the numbers depend on the
machine (and on what else runs on it: the ratios, taken in the same run, are what to read).
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _machine import describe, median_ms, write_results  # noqa: E402

import splinecast as sc  # noqa: E402
from splinecast.multires.scenes.multiscale import MultiscaleScene  # noqa: E402

ISO = 0.5
IMAGE = (512, 512)


def make_inputs(folder: Path, n: int) -> tuple[Path, Path]:
    """The demo volume as ``ml{n}.nii.gz`` and ``ml{n}.zarr`` in ``folder`` (kept if present)."""
    import nibabel as nib

    nii, zarr = folder / f"ml{n}.nii.gz", folder / f"ml{n}.zarr"
    if not nii.exists() or not zarr.exists():
        vol = sc.demo("marschner-lobb", size=n)
        data = np.asarray(vol.data, dtype=np.float32)
        nib.save(nib.Nifti1Image(data, np.eye(4)), str(nii))
        sc.build_pyramid(sc.Volume(data), zarr, brick=32, progress=False, overwrite=True)
    return nii, zarr


def cli_times(files: list[Path], out: Path, repeats: int) -> list[float]:
    """Median wall seconds of ``splinecast render`` per file (one warm-up each, alternated)."""
    exe = Path(sys.executable).with_name("splinecast")

    def run(path: Path) -> float:
        start = time.perf_counter()
        subprocess.run([str(exe), "render", str(path), "-o", str(out), "--quiet"], check=True,
                       stdout=subprocess.DEVNULL)
        return time.perf_counter() - start

    for path in files:
        run(path)
    times: list[list[float]] = [[] for _ in files]
    for _ in range(repeats):
        for k, path in enumerate(files):
            times[k].append(run(path))
    return [statistics.median(t) for t in times]


def steady_frames(nii: Path, zarr: Path, budget: str, repeats: int) -> dict[str, float]:
    """Median ms of a steady frame: store (whole level), store (bricks only), in memory."""
    mv = sc.read(zarr)
    vol = sc.read(nii)
    cam = sc.Camera.orbit(mv, azimuth=30, elevation=20, size=IMAGE)
    out: dict[str, float] = {}
    images = {}
    for name, whole in (("store", True), ("bricks", False)):
        with MultiscaleScene(mv, budget=budget, whole_level=whole) as scene:
            frame = scene.render(cam, iso=ISO, complete=True)  # reads, compiles
            assert frame.stats["complete"] and frame.stats["whole_level"] == whole
            scene.render(cam, iso=ISO, complete=True)
            out[name] = median_ms(lambda s=scene: s.render(cam, iso=ISO, complete=True), repeats)
            images[name] = frame.rgba
    memory = sc.Scene(vol)
    memory.render(cam, iso=ISO, samples=1)
    out["memory"] = median_ms(lambda: memory.render(cam, iso=ISO, samples=1), repeats)
    out["max_rgba_difference_store_vs_bricks"] = float(
        np.abs(images["store"] - images["bricks"]).max())
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="128,256", help="volume sides (default 128,256)")
    parser.add_argument("--budget", default="2GiB", help="the scene's budget (default 2GiB, "
                        "the command line's)")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--workdir", help="keep the inputs here (default: a temporary folder)")
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(args.workdir or tmp)
        folder.mkdir(parents=True, exist_ok=True)
        for n in (int(s) for s in args.sizes.split(",")):
            nii, zarr = make_inputs(folder, n)
            store_s, nii_s = cli_times([zarr, nii], folder / "out.png", args.repeats)
            steady = steady_frames(nii, zarr, args.budget, args.repeats)
            row = {"size": n, "cli_store_s": store_s, "cli_nifti_s": nii_s, **steady}
            print(row, flush=True)
            rows.append(row)

    def cells(r: dict) -> list[str]:
        return [f"{r['size']}^3 float32", f"{r['cli_store_s']:.2f} s", f"{r['cli_nifti_s']:.2f} s",
                f"{r['cli_store_s'] / r['cli_nifti_s']:.2f}x", f"{r['store']:.0f} ms",
                f"{r['bricks']:.0f} ms", f"{r['memory']:.0f} ms",
                f"{r['store'] / r['memory']:.2f}x", f"{r['bricks'] / r['memory']:.2f}x",
                f"{r['max_rgba_difference_store_vs_bricks']:.1e}"]

    write_results(
        HERE / "results" / "small_store",
        "A store that fits its budget against the same volume in memory",
        f"`python benchmarks/bench_small_store.py --sizes {args.sizes} --budget {args.budget} "
        f"--repeats {args.repeats}`. Marschner-Lobb, 512x512, iso {ISO}, trilinear; medians "
        "after warm-up, store and NIfTI measured side by side in the same run. CLI: "
        "`splinecast render FILE -o OUT.png --quiet`, a fresh process each (import and "
        "reading included). Steady frame: the same view rendered again in one process; "
        "`bricks`: the store drawn from bricks every frame (`whole_level=False`, what every "
        "store did before).",
        ["volume", "CLI store", "CLI NIfTI", "ratio", "steady store", "steady bricks",
         "steady in memory", "store / memory", "bricks / memory",
         "max rgba difference, store vs bricks"],
        rows, cells, machine=describe())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
