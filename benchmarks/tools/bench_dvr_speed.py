"""DVR frame time before/after, side by side: two builds in two worker processes, interleaved.

The baseline is another checkout of the repository (``--old``, e.g. ``git worktree add --detach
/tmp/dvr-old lead-23``); this checkout is the new build. Each build runs in its own long-lived
worker process (``PYTHONPATH=<checkout>/src``) that loads the scenes once; the parent asks them in
turn to render the same frame (same scene, camera, transfer function, settings) and records the
process CPU time of each render, so both builds see the same machine load, round by round.

Quality: each worker also renders the suite's quality camera (256x192) and reports the mean
absolute error against the comparison suite's dense emission-absorption reference
(``benchmarks.compare.reference.reference_dvr``, suite transfer function only), the number the
suite matches quality by (tolerance 1/255).

    NUMBA_NUM_THREADS=1 taskset -c 1 python benchmarks/tools/bench_dvr_speed.py \\
        --old /tmp/dvr-old --rounds 3
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parents[1]  # benchmarks/
REPO = HERE.parent

#: (label, old build's settings, new build's settings); a settings spec is a dict of
#: DVRSettings arguments or None (no settings: the defaults a user gets).
CASES = [
    ("no settings (the default)", None, None),
    ("step 1 (what the suite picks)", {"step": 1.0}, {"step": 1.0}),
    # The per-piece default against the fixed-step ("ray") default, both at two voxels (the
    # comparison suite tries).
    ("pieces against ray, step 2, termination",
     {"step": 2.0, "sampling": "pieces", "termination": 1.0 - 2.0**-10},
     {"step": 2.0, "sampling": "ray", "termination": 1.0 - 2.0**-10}),
]


def _worker() -> None:
    """Serve render requests on stdin (one JSON per line); answer on stdout."""
    import splinecast as sc

    sys.path.insert(0, str(REPO))
    from benchmarks.compare import methods as M
    from benchmarks.compare.reference import image_error, reference_dvr
    from benchmarks.compare.scenes import ml, mri, noise

    specs = {"ml128": ml(128), "ml256": ml(256), "mri": mri(), "noise256": noise(256)}
    loaded: dict[str, tuple] = {}
    refs: dict[str, np.ndarray] = {}
    black = sc.Shading(background=(0.0, 0.0, 0.0, 1.0))
    print(json.dumps({"ready": sc.__file__}), flush=True)
    for line in sys.stdin:
        req = json.loads(line)
        name = req["scene"]
        if name not in loaded:
            spec = specs[name]
            volume = spec.make()
            loaded[name] = (spec, volume, sc.Scene(volume))
        spec, volume, scene = loaded[name]
        if req["tf"] == "suite":
            tf = sc.TransferFunction(M.dvr_transfer(volume, spec.isos[0]), volume.value_range,
                                     "gray")
        elif req["tf"] == "every":
            # The comparison suite's dense "every voxel" opacity (M.dense_transfers).
            tf = sc.TransferFunction(M.dense_transfers(volume)["every voxel"],
                                     volume.value_range, "gray")
        else:
            tf = sc.auto_transfer_function(volume)
        dvr = None if req["settings"] is None else sc.DVRSettings(**req["settings"])
        cam = sc.Camera.orbit(volume, azimuth=30.0, elevation=20.0, size=tuple(req["size"]))
        kwargs = dict(mode="dvr", tf=tf, dvr=dvr, shading=black, outputs=("rgba",))
        reply: dict = {}
        if req.get("quality") and req["tf"] == "suite":
            qcam = sc.Camera.orbit(volume, azimuth=30.0, elevation=20.0, size=(256, 192))
            if name not in refs:
                refs[name] = reference_dvr(volume, qcam, M.dvr_transfer(volume, spec.isos[0]))
            img = np.asarray(scene.render(qcam, **kwargs).rgba, np.float64)[..., :3]
            reply["error"] = image_error(img, refs[name])
        if req.get("warm"):
            scene.render(cam, **kwargs)
        start = time.process_time()
        frame = scene.render(cam, **kwargs)
        reply["ms"] = (time.process_time() - start) * 1e3
        reply["label"] = scene.model.name
        reply["stats"] = {k: v for k, v in frame.stats.items()
                          if isinstance(v, (int, float, str, bool)) or v is None}
        print(json.dumps(reply), flush=True)


class Worker:
    """One build's worker process."""

    def __init__(self, checkout: Path) -> None:
        env = dict(os.environ, PYTHONPATH=str(checkout / "src"))
        self.proc = subprocess.Popen([sys.executable, __file__, "--worker"], env=env,
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                                     cwd=str(REPO))
        self.where = json.loads(self.proc.stdout.readline())["ready"]

    def ask(self, **req) -> dict:
        self.proc.stdin.write(json.dumps(req) + "\n")
        self.proc.stdin.flush()
        return json.loads(self.proc.stdout.readline())

    def close(self) -> None:
        self.proc.stdin.close()
        self.proc.wait()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--old", help="checkout of the baseline build")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--scenes", default="ml256,mri")
    ap.add_argument("--tfs", default="suite,auto",
                    help="transfer functions: suite, auto (the automatic one), every (the "
                    "suite's dense ramp over the whole range)")
    ap.add_argument("--size", default="1024x768")
    ap.add_argument("--stem", default="dvr_speed")
    ap.add_argument("--cases", default="",
                    help="comma-separated indices into CASES (default: all)")
    args = ap.parse_args()
    if args.worker:
        _worker()
        return
    if not args.old:
        raise SystemExit("--old: the baseline checkout is required")
    size = [int(v) for v in args.size.split("x")]
    builds = {"old": Worker(Path(args.old).resolve()), "new": Worker(REPO)}
    rows = []
    uptimes = [_uptime()]
    for scene in args.scenes.split(","):
        for tf in args.tfs.split(","):
            picked = ([CASES[int(i)] for i in args.cases.split(",")] if args.cases else CASES)
            for label, old_settings, new_settings in picked:
                settings = {"old": old_settings, "new": new_settings}
                row = {"scene": scene, "tf": tf, "case": label, "settings": settings,
                       "ms": {"old": [], "new": []}, "error": {}, "stats": {}}
                for key, w in builds.items():  # warm-up and quality, one frame each
                    r = w.ask(scene=scene, tf=tf, settings=settings[key], size=size,
                              warm=True, quality=True)
                    row["error"][key] = r.get("error")
                    row["stats"][key] = r["stats"]
                for _ in range(args.rounds):
                    for key, w in builds.items():
                        row["ms"][key].append(
                            w.ask(scene=scene, tf=tf, settings=settings[key], size=size)["ms"])
                row["median_ms"] = {k: statistics.median(v) for k, v in row["ms"].items()}
                row["speedup"] = row["median_ms"]["old"] / row["median_ms"]["new"]
                rows.append(row)
                uptimes.append(_uptime())
                print(json.dumps({k: row[k] for k in ("scene", "tf", "case", "median_ms",
                                                      "speedup", "error")}), flush=True)
                _write(rows, args, builds, uptimes)
    for w in builds.values():
        w.close()


def _uptime() -> str:
    return subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()


def _write(rows, args, builds, uptimes) -> None:
    sys.path.insert(0, str(HERE))
    from _machine import describe

    head = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"],
                          capture_output=True, text=True).stdout.strip()
    old_head = subprocess.run(["git", "-C", str(args.old), "rev-parse", "--short", "HEAD"],
                              capture_output=True, text=True).stdout.strip()
    out = {"machine": describe(), "command": " ".join(sys.argv), "new": head, "old": old_head,
           "uptime": uptimes, "rounds": args.rounds, "size": args.size, "rows": rows,
           "clock": "process CPU time (one Numba thread when NUMBA_NUM_THREADS=1)"}
    path = HERE / "results" / f"{args.stem}.json"
    path.write_text(json.dumps(out, indent=1))
    lines = [f"# DVR before/after, side by side ({args.stem})", "",
             f"Machine: {out['machine']}", "",
             f"Old: {old_head} (`{args.old}`); new: {head} (this checkout, uncommitted changes "
             f"included if any). {args.size}, `Camera.orbit(azimuth=30, elevation=20)`, colour "
             f"only. {out['clock']}; median of {args.rounds} rounds, old and new alternating in "
             "every round after one warm-up frame each. Error: mean absolute error at 256x192 "
             "against the comparison suite's dense reference (suite transfer function only; "
             "the suite's tolerance is 1/255 = 0.0039).", "",
             f"Command: `{out['command']}`", "", "Load (uptime) before and after each row: " +
             "; ".join(u.split("load average:")[-1].strip() for u in uptimes), "",
             "| scene | tf | settings | old ms | new ms | speed-up | old error | new error |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        def e(k, r=r):
            v = r["error"].get(k)
            return "-" if v is None else f"{v:.5f}"
        lines.append(f"| {r['scene']} | {r['tf']} | {r['case']} | {r['median_ms']['old']:.0f} | "
                     f"{r['median_ms']['new']:.0f} | {r['speedup']:.2f}x | {e('old')} | "
                     f"{e('new')} |")
    path.with_suffix(".md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
