"""Where DVR time goes: per-ray counts and CPU time of settings variants (issue 15, item 4).

For each scene (Marschner-Lobb 256^3, the MNI152 MRI) and transfer function (the comparison
suite's grey ramp, and the automatic one a user gets without ``tf``) this renders at 1024x768
(``Camera.orbit(azimuth=30, elevation=20)``, the suite's DVR camera) with settings variants and
reports, from the frame's per-ray counters: rays that enter the volume, cells walked one by
one, cells whose range is visible (their pieces are built and consumed), blocks leapt over,
samples per ray, rays whose opacity reaches 0.99 / 0.999 (what early termination could stop),
and the CPU time per ray, per visited cell and per sample.

"driver only" replaces the mode's ``consume`` with one that returns the state unchanged (the
same walk, leaps, cell loads, visibility tests and piece polynomials): what the walk and the
model cost without the mode's integration.

    NUMBA_NUM_THREADS=1 taskset -c 1 python benchmarks/bench_dvr_profile.py --clock cpu
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from collections import namedtuple
from pathlib import Path

import numpy as np

import splinecast as sc
from splinecast._jit import jit
from splinecast.render import dvr as D
from splinecast.render.mode_api import register
from splinecast.render.segment import render_grid

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))
from _machine import describe  # noqa: E402

from benchmarks.compare import methods as M  # noqa: E402
from benchmarks.compare.scenes import ml, mri  # noqa: E402

#: The DVR mode with a consume that does nothing (measures the walk and the model alone).
NullDvrMode = namedtuple("NullDvrMode", D.DvrMode._fields)


@jit()
def _null_consume(mode, mscratch, grid, scratch, ctx, i, j, k, tag, poly, lo, hi, t0, t1,
                  ax, ay, az, bx, by, bz, ray, st):
    # Touch the polynomial so its construction is not optimised away.
    return st[0] + poly.c0 * 1e-300, st[1], st[2], st[3], st[4], st[5], st[6]


register(NullDvrMode, state_new=D._state_new, state_load=D._state_load,
         state_store=D._state_store, mode_scratch=D.no_scratch, ray_begin=D.unchanged_begin,
         skip_size=D.flagged_block_size, wants=D._wants, on_skip=D.unchanged_skip,
         consume=_null_consume, done=D._done, ray_end=D.unchanged_end, finish=D._finish)


def variants() -> dict[str, object]:
    """Label -> DVRSettings (None: no settings given, the defaults a user gets)."""
    S = D.DVRSettings
    out = {"no settings": None, "step 0.5": S(), "step 1": S(step=1.0),
           "step 1, plain": S(step=1.0, preintegration="none"),
           "step 1, stop 0.999": S(step=1.0, termination=0.999),
           "step 1, stop 0.99": S(step=1.0, termination=0.99),
           "driver only": "null"}
    fields = getattr(S, "__dataclass_fields__", {})
    if "sampling" in fields:
        out["pieces 1"] = S(step=1.0, sampling="pieces")
        out["pieces 1, stop 0.999"] = S(step=1.0, sampling="pieces", termination=0.999)
    return out


def _render(scene, cam, tf, settings, black):
    if settings == "null":
        setup = D.Dvr(tf, D.DVRSettings(step=1.0), black.background)
        setup.params = NullDvrMode(*setup.params)
        start = time.process_time()
        out, counters = render_grid(scene.grid, setup, cam)
        ms = (time.process_time() - start) * 1e3
        return ms, None, counters
    start = time.process_time()
    frame = scene.render(cam, mode="dvr", tf=tf, dvr=settings, shading=black)
    ms = (time.process_time() - start) * 1e3
    return ms, frame, (frame.cells_visited, frame.cells_tested, frame.blocks_skipped)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--scenes", default="ml256,mri")
    ap.add_argument("--tfs", default="suite,auto")
    ap.add_argument("--only", default="", help="comma-separated variant labels")
    ap.add_argument("--size", default="1024x768")
    ap.add_argument("--json", default=str(HERE / "results" / "dvr_profile.json"))
    args = ap.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    specs = {"ml256": ml(256), "mri": mri()}
    black = sc.Shading(background=(0.0, 0.0, 0.0, 1.0))
    rows = []
    for name in args.scenes.split(","):
        spec = specs[name]
        volume = spec.make()
        scene = sc.Scene(volume)
        cam = sc.Camera.orbit(volume, azimuth=30.0, elevation=20.0, size=(width, height))
        tfs = {"suite": sc.TransferFunction(M.dvr_transfer(volume, spec.isos[0]),
                                            volume.value_range, "gray"),
               "auto": sc.auto_transfer_function(volume)}
        for tf_name in args.tfs.split(","):
            tf = tfs[tf_name]
            for label, settings in variants().items():
                if args.only and label not in args.only.split(","):
                    continue
                _render(scene, cam, tf, settings, black)  # warm-up (compilation, tables)
                times = []
                for _ in range(args.repeats):
                    ms, frame, counters = _render(scene, cam, tf, settings, black)
                    times.append(ms)
                visited, tested, skipped = (np.asarray(c, np.float64) for c in counters)
                entered = (visited + skipped) > 0
                n = max(int(entered.sum()), 1)
                ms = statistics.median(times)
                row = {"scene": spec.label, "tf": tf_name, "settings": label, "ms": ms,
                       "runs_ms": times, "rays": width * height, "rays_entering": n,
                       "cells_visited_per_ray": float(visited[entered].sum() / n),
                       "cells_visible_per_ray": float(tested[entered].sum() / n),
                       "blocks_leapt_per_ray": float(skipped[entered].sum() / n),
                       "ns_per_ray": ms * 1e6 / n,
                       "ns_per_visited_cell": ms * 1e6 / max(visited.sum(), 1)}
                if frame is not None:
                    samples = frame.stats.get("mean_samples", float("nan")) * width * height
                    row.update(samples_per_ray=samples / n,
                               ns_per_sample=ms * 1e6 / max(samples, 1))
                if frame is not None and label == "step 1":
                    acc = _volume_alpha(scene, cam, tf, settings)
                    row.update(rays_reaching_099=float((acc[entered] >= 0.99).mean()),
                               rays_reaching_0999=float((acc[entered] >= 0.999).mean()),
                               rays_visible=float((acc[entered] >= 1 / 255).mean()))
                rows.append(row)
                print(json.dumps({k: (round(v, 3) if isinstance(v, float) else v)
                                  for k, v in row.items() if k != "runs_ms"}), flush=True)
                _write(rows, args)


def _volume_alpha(scene, cam, tf, settings):
    """The volume's own accumulated opacity per ray (rendered over a transparent background)."""
    clear = sc.Shading(background=(0.0, 0.0, 0.0, 0.0))
    frame = scene.render(cam, mode="dvr", tf=tf, dvr=settings, shading=clear,
                         outputs=("rgba",))
    return np.asarray(frame.rgba[..., 3], np.float64)


def _write(rows: list[dict], args: argparse.Namespace) -> None:
    out = {"machine": describe(), "uptime": subprocess.run(["uptime"], capture_output=True,
                                                          text=True).stdout.strip(),
           "command": " ".join(sys.argv), "clock": "cpu (process_time)",
           "repeats": args.repeats, "rows": rows}
    path = Path(args.json)
    path.write_text(json.dumps(out, indent=1))
    lines = ["# Where DVR time goes (issue 15, item 4)", "", f"Machine: {out['machine']}", "",
             f"Load: `{out['uptime']}`. Command: `{out['command']}`. CPU time of the process "
             f"(one Numba thread), median of {args.repeats} after a warm-up, 1024x768, per ray "
             "entering the volume.", "",
             "| scene | tf | settings | ms | cells walked / ray | visible cells / ray | "
             "blocks leapt / ray | samples / ray | ns / ray | ns / walked cell | ns / sample | "
             "rays >= 0.99 | rays >= 0.999 |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        def f(key, fmt="{:.1f}", r=r):
            v = r.get(key)
            return "-" if v is None else fmt.format(v)
        lines.append(f"| {r['scene']} | {r['tf']} | {r['settings']} | {r['ms']:.0f} | "
                     f"{f('cells_visited_per_ray')} | {f('cells_visible_per_ray')} | "
                     f"{f('blocks_leapt_per_ray')} | {f('samples_per_ray')} | "
                     f"{f('ns_per_ray', '{:.0f}')} | {f('ns_per_visited_cell')} | "
                     f"{f('ns_per_sample')} | {f('rays_reaching_099', '{:.2f}')} | "
                     f"{f('rays_reaching_0999', '{:.2f}')} |")
    path.with_suffix(".md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
