"""Frame times of every model in every mode, side by side with an earlier build.

Two worker processes, one importing this checkout's splinecast and one importing a baseline
source tree (``--baseline DIR/src``, e.g. a ``git worktree`` of an earlier commit), prepare the
same scenes; the driver asks them in turn for the same renders, so both measure under the same
machine conditions, and reports medians after JIT warm-up and the ratio new / baseline. Cases
the baseline cannot render (modes it did not support for a model) are measured for the new
build only.

    python benchmarks/tools/bench_kernels.py --baseline /tmp/old/src [--quick] [--json PATH]
        [--only MODEL:MODE,...] [--volumes ml,mri] [--combo-repeats N] [--resume LOG]
        [--clock wall|cpu] [--kwargs JSON] [--baseline-kwargs JSON]

``--kwargs`` adds render options to every case of this build only (``'{"samples": 1}'``: the
same frame without antialiasing, options the baseline may not know), ``--baseline-kwargs`` to
the baseline's; so one build can also be measured against itself with other options
(``--baseline`` the same ``src``).

``--resume LOG`` takes the rows already printed by an interrupted run (one JSON object per line)
instead of measuring those cases again; the slow combinations (B-spline and type-6 MIP and DVR
take seconds to minutes per 1024x768 frame on one core) can run with fewer repeats
(``--combo-repeats``). Every case is asked of both builds; one the baseline cannot render is
reported with its error.

Volumes: Marschner-Lobb 256^3 (iso 0.5) and the MNI152 MRI (``_machine.MRI``; iso 80) when
present; images 1024x768 (``--quick``: 64^3 and 256x192).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]  # benchmarks/
sys.path.insert(0, str(HERE))
from _machine import MRI, describe  # noqa: E402

# The worker: reads one JSON request per line, answers with the times in ms. It uses only the
# public API that both builds share.
WORKER = r'''
import json, sys, time
import numpy as np
import splinecast as sc

volumes, scenes = {}, {}

def volume(name, size):
    if name not in volumes:
        volumes[name] = sc.demo("marschner-lobb", size=size) if name == "ml" else sc.read(name)
    return volumes[name]

for line in sys.stdin:
    req = json.loads(line)
    vol = volume(req["volume"], req["size"])
    key = (req["volume"], req["model"])
    if key not in scenes:
        scenes[key] = sc.Scene(vol, model=req["model"])
    scene = scenes[key]
    cam = sc.Camera.orbit(vol, azimuth=30, elevation=25, size=tuple(req["image"]))
    kwargs = dict(req["kwargs"])
    if "tf" in kwargs:
        kwargs["tf"] = sc.TransferFunction.from_dict(kwargs["tf"])
    try:
        scene.render(cam, **kwargs)  # warm-up (compilation, isovalue classification)
        times = []
        clock = time.process_time if req.get("clock") == "cpu" else time.perf_counter
        for _ in range(req["repeats"]):
            start = clock()
            scene.render(cam, **kwargs)
            times.append((clock() - start) * 1e3)
        print(json.dumps({"ms": times}), flush=True)
    except Exception as exc:  # a mode the build does not support
        print(json.dumps({"error": f"{type(exc).__name__}: {exc}"}), flush=True)
'''


class Worker:
    """One splinecast build in a subprocess."""

    def __init__(self, src: str | None) -> None:
        env = dict(os.environ)
        if src:
            env["PYTHONPATH"] = src
        self.proc = subprocess.Popen([sys.executable, "-c", WORKER], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, text=True, env=env)

    def ask(self, request: dict) -> dict:
        self.proc.stdin.write(json.dumps(request) + "\n")
        self.proc.stdin.flush()
        return json.loads(self.proc.stdout.readline())

    def close(self) -> None:
        self.proc.stdin.close()
        self.proc.wait()


def _cases(quick: bool) -> list[dict]:
    ml = {"volume": "ml", "size": 64 if quick else 256, "iso": 0.5, "tf": {
        "opacity": [[0.3, 0.0], [0.5, 0.4], [0.7, 0.0]], "domain": [0.0, 1.0],
        "colormap": "viridis"}}
    vols = [ml]
    if MRI.exists() and not quick:
        vols.append({"volume": str(MRI), "size": 0, "iso": 80.0, "tf": {
            "opacity": [[40.0, 0.0], [90.0, 0.05], [140.0, 0.3]], "domain": [0.0, 255.0],
            "colormap": "bone"}})
    image = [256, 192] if quick else [1024, 768]
    cases = []
    for v in vols:
        iso, tf = v["iso"], v["tf"]
        spread = 0.1 if v["volume"] == "ml" else 30.0
        for model in ("trilinear", "bspline1", "bspline2", "bspline3", "qss", "s31"):
            cases.append({**v, "model": model, "mode": "iso", "kwargs": {"iso": iso}})
        for model in ("trilinear", "bspline3", "s31"):
            cases.append({**v, "model": model, "mode": "mip", "kwargs": {"mode": "mip"}})
            cases.append({**v, "model": model, "mode": "dvr", "kwargs": {"mode": "dvr", "tf": tf}})
            cases.append({**v, "model": model, "mode": "multi-iso",
                          "kwargs": {"iso": [iso - spread, iso, iso + spread]}})
        for c in cases:
            c["image"] = image
    return cases


def _revision(folder: str | None) -> str | None:
    """The git commit of a source folder, if it is in a git checkout."""
    if not folder:
        return None
    done = subprocess.run(["git", "-C", folder, "rev-parse", "--short", "HEAD"],
                          capture_output=True, text=True)
    return done.stdout.strip() or None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", help="src folder of the baseline build")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--combo-repeats", type=int,
                    help="repeats of the slow cases (smooth models in MIP, DVR, multi-iso)")
    ap.add_argument("--only", help="comma-separated MODEL:MODE cases (default: all)")
    ap.add_argument("--volumes", default="ml,mri", help="comma-separated: ml, mri")
    ap.add_argument("--resume", help="rows printed by an earlier run, not measured again")
    ap.add_argument("--json", help="output path (default results/kernels[_quick].json)")
    ap.add_argument("--kwargs", default="{}",
                    help="JSON object of render options added for this build")
    ap.add_argument("--baseline-kwargs", default="{}",
                    help="JSON object of render options added for the baseline")
    ap.add_argument("--clock", choices=["wall", "cpu"], default="wall",
                    help="wall time, or the worker's CPU time (steadier on a machine other "
                         "processes load; use with NUMBA_NUM_THREADS=1)")
    args = ap.parse_args()
    if args.json is None:
        args.json = str(HERE / "results" / ("kernels_quick.json" if args.quick else "kernels.json"))
    repeats = 3 if args.quick else args.repeats
    new = Worker(None)
    old = Worker(args.baseline) if args.baseline else None
    done: dict[tuple, dict] = {}
    if args.resume:
        for line in Path(args.resume).read_text().splitlines():
            if line.startswith("{"):
                row = json.loads(line)
                done[(row["volume"], row["model"], row["mode"])] = row
    only = set(args.only.split(",")) if args.only else None
    volumes = set(args.volumes.split(","))
    rows = []
    for case in _cases(args.quick):
        label = f"ML {case['size']}^3" if case["volume"] == "ml" else "MRI"
        if ("ml" if case["volume"] == "ml" else "mri") not in volumes:
            continue
        if only is not None and f"{case['model']}:{case['mode']}" not in only:
            continue
        if (label, case["model"], case["mode"]) in done:
            rows.append(done[(label, case["model"], case["mode"])])
            continue
        req = {k: case[k] for k in ("volume", "size", "model", "image", "kwargs")}
        req["clock"] = args.clock
        # Every case is asked of the baseline (a mode it lacks answers with its error); the
        # slow combinations (smooth models outside the isosurface) may take fewer repeats.
        slow = case["mode"] != "iso" and case["model"] != "trilinear"
        req["repeats"] = args.combo_repeats if slow and args.combo_repeats else repeats
        # Interleave: the builds take turns, so both see the same machine.
        a = new.ask({**req, "kwargs": {**req["kwargs"], **json.loads(args.kwargs)}})
        b = (old.ask({**req, "kwargs": {**req["kwargs"], **json.loads(args.baseline_kwargs)}})
             if old else {"error": "no baseline"})
        row = {"volume": label, "repeats": req["repeats"], "model": case["model"],
               "mode": case["mode"], "new_ms": statistics.median(a["ms"]) if "ms" in a else None,
               "new_error": a.get("error"),
               "base_ms": statistics.median(b["ms"]) if "ms" in b else None,
               "base_error": b.get("error")}
        if row["new_ms"] and row["base_ms"]:
            row["ratio"] = row["new_ms"] / row["base_ms"]
        rows.append(row)
        print(json.dumps(row), flush=True)
    new.close()
    if old:
        old.close()
    out = {"machine": describe(), "quick": args.quick, "repeats": repeats, "clock": args.clock,
           "baseline": _revision(args.baseline), "build": _revision(str(HERE.parent)),
           "kwargs": json.loads(args.kwargs), "baseline_kwargs": json.loads(args.baseline_kwargs),
           "rows": rows}
    path = Path(args.json)
    path.write_text(json.dumps(out, indent=1))
    lines = [f"# Frame times, this build vs baseline ({'quick' if args.quick else 'full'})", "",
             f"Machine: {out['machine']}", "",
             f"This build: {out['build']}; baseline: {out['baseline']}. Median of {repeats} "
             "renders after a warm-up render, the builds taking turns; "
             f"{'CPU' if args.clock == 'cpu' else 'wall'} time. Options added: this build "
             f"{args.kwargs}, baseline {args.baseline_kwargs}.", "",
             "| volume | model | mode | new ms | baseline ms | new / baseline |",
             "|---|---|---|---|---|---|"]
    for r in rows:
        base = f"{r['base_ms']:.1f}" if r["base_ms"] else "n/a"
        ratio = f"{r['ratio']:.3f}" if r.get("ratio") else "-"
        newv = f"{r['new_ms']:.1f}" if r["new_ms"] else r["new_error"]
        lines.append(f"| {r['volume']} | {r['model']} | {r['mode']} | {newv} | {base} | {ratio} |")
    path.with_suffix(".md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
