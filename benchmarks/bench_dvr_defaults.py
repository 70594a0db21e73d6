"""Which DVR settings could be the default: error against the suite's tolerance, and frame time.

The comparison suite (``benchmarks/compare``) matches DVR quality by the mean absolute error of
the image against a dense reference (emission-absorption of a grey transfer function on the
trilinear field, every 1/16 voxel, ``compare.reference.reference_dvr``) at 256x192, with the
tolerance max(1/255, error of splinecast's default settings). This script renders candidate
settings (coarser steps, early termination, the opacity-adaptive step) on the suite's DVR scenes,
reports their error against that reference and their frame time at 1024x768 with the suite's
transfer function and with the automatic one (``mode="dvr"`` without ``tf``, what a user gets;
its error is measured against splinecast's own render at a 1/8-voxel step, no independent
reference exists for a coloured transfer function).

    NUMBA_NUM_THREADS=1 python benchmarks/bench_dvr_defaults.py [--repeats N] [--clock cpu]
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
from splinecast.render.dvr import DVRSettings

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))
from _machine import describe  # noqa: E402

from benchmarks.compare import methods as M  # noqa: E402
from benchmarks.compare.reference import image_error, reference_dvr  # noqa: E402
from benchmarks.compare.runner import QUALITY_SIZE  # noqa: E402
from benchmarks.compare.scenes import ml, mri  # noqa: E402

CANDIDATES = {
    "default (0.5, 2d)": DVRSettings(),
    "step 1": DVRSettings(step=1.0),
    "step 0.5, stop at 0.99": DVRSettings(termination=0.99),
    "step 1, stop at 0.99": DVRSettings(step=1.0, termination=0.99),
    "adaptive 1..4 (3d), stop at 0.99": DVRSettings(step=1.0, preintegration="3d",
                                                     adaptive=True, h_max=4.0,
                                                     termination=0.99),
}
FINE = DVRSettings(step=0.125)


def _camera(volume: sc.Volume, size: tuple[int, int]) -> sc.Camera:
    # The suite's DVR camera (compare.runner._camera).
    return sc.Camera.orbit(volume, azimuth=30.0, elevation=20.0, size=size)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--clock", choices=["wall", "cpu"], default="wall")
    ap.add_argument("--scenes", default="mri,ml256")
    ap.add_argument("--json", default=str(HERE / "results" / "dvr_defaults.json"))
    args = ap.parse_args()
    clock = time.process_time if args.clock == "cpu" else time.perf_counter
    specs = {"ml256": ml(256), "mri": mri()}
    rows = []
    for name in args.scenes.split(","):
        spec = specs[name]
        if spec is None:
            continue
        volume = spec.make()
        scene = sc.Scene(volume)
        iso = spec.isos[0]
        black = sc.Shading(background=(0.0, 0.0, 0.0, 1.0))
        suite_tf = sc.TransferFunction(M.dvr_transfer(volume, iso), volume.value_range, "gray")
        qcam = _camera(volume, QUALITY_SIZE)
        reference = reference_dvr(volume, qcam, M.dvr_transfer(volume, iso))
        auto_fine = scene.render(qcam, mode="dvr", dvr=FINE, shading=black,
                                 outputs=("rgba",)).rgba[..., :3]
        cam = _camera(volume, (1024, 768))
        for label, settings in CANDIDATES.items():
            suite = dict(mode="dvr", tf=suite_tf, dvr=settings, shading=black,
                         outputs=("rgba",))
            auto = dict(mode="dvr", dvr=settings, shading=black, outputs=("rgba",))
            err = image_error(scene.render(qcam, **suite).rgba[..., :3], reference)
            err_auto = image_error(scene.render(qcam, **auto).rgba[..., :3], auto_fine)
            times = {"suite": [], "auto": []}
            for _ in range(args.repeats):
                for key, kwargs in (("suite", suite), ("auto", auto)):
                    start = clock()
                    scene.render(cam, **kwargs)
                    times[key].append((clock() - start) * 1e3)
            row = {"scene": spec.label, "settings": label, "error": err,
                   "error_auto_vs_fine": err_auto,
                   "suite_tf_ms": statistics.median(times["suite"]),
                   "auto_tf_ms": statistics.median(times["auto"]), "runs_ms": times}
            rows.append(row)
            print(json.dumps(row), flush=True)
            _write(rows, args)  # after every row: a long run stopped early keeps its rows


def _write(rows: list[dict], args: argparse.Namespace) -> None:
    out = {"machine": describe(), "clock": args.clock, "repeats": args.repeats,
           "tolerance": 1.0 / 255.0, "rows": rows}
    path = Path(args.json)
    path.write_text(json.dumps(out, indent=1))
    lines = ["# DVR settings against the comparison suite's tolerance", "",
             f"Machine: {out['machine']}", "",
             f"Median of {args.repeats} frames at 1024x768 after a warm-up, {args.clock} clock, "
             "colour only (`outputs=(\"rgba\",)`). Error: mean absolute difference at "
             f"{QUALITY_SIZE[0]}x{QUALITY_SIZE[1]} against the suite's dense reference (suite "
             "transfer function); the suite's tolerance is max(1/255 = 0.0039, error of the "
             "defaults). \"auto tf\": `mode=\"dvr\"` without `tf`; its error is against "
             "splinecast at a 1/8-voxel step.", "",
             "| scene | settings | error (suite tf) | within 1/255 | ms (suite tf) | "
             "error (auto tf vs 1/8 step) | ms (auto tf) |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['scene']} | {r['settings']} | {r['error']:.5f} | "
                     f"{'yes' if r['error'] <= out['tolerance'] else 'no'} | "
                     f"{r['suite_tf_ms']:.0f} | {r['error_auto_vs_fine']:.5f} | "
                     f"{r['auto_tf_ms']:.0f} |")
    path.with_suffix(".md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
