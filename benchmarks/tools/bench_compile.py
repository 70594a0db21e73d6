"""Compile time of one (model, mode) specialisation from an empty Numba cache, two builds.

Each run is a fresh process with its own empty ``NUMBA_CACHE_DIR`` and ``PYTHONPATH`` set to a
build's ``src``: it imports splinecast, makes the scene (Marschner-Lobb 64^3) and times the
first render at 128x128 (process CPU time: compilation of the pair's kernel, plus the model's
and the mode's preparation kernels, the same in both builds), then the median of 3 renders
after it (steady). The builds take turns, run by run, so both see the same machine load.

    NUMBA_NUM_THREADS=1 taskset -c 1 python benchmarks/tools/bench_compile.py --old /tmp/dvr-old2 \\
        --pairs trilinear:dvr --rounds 2
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]  # benchmarks/
REPO = HERE.parent


def _child(model: str, mode: str, settings: str) -> None:
    import numpy as np

    import splinecast as sc

    np.seterr(all="ignore")
    vol = sc.demo("marschner-lobb", size=64)
    scene = sc.Scene(vol, model=model)
    cam = sc.Camera.orbit(vol, azimuth=30.0, elevation=25.0, size=(128, 128))
    kw: dict = {"mode": mode, "outputs": ("rgba",)}
    if mode == "dvr":
        kw["tf"] = sc.TransferFunction([(0.3, 0.0), (0.5, 0.3), (0.8, 0.9)], (0.0, 1.0))
        if settings:
            kw["dvr"] = sc.DVRSettings(**json.loads(settings))
    elif mode == "iso":
        kw["iso"] = 0.5
    start = time.process_time()
    frame = scene.render(cam, **kw)
    first = time.process_time() - start
    steady = []
    for _ in range(3):
        start = time.process_time()
        scene.render(cam, **kw)
        steady.append((time.process_time() - start) * 1e3)
    print(json.dumps({"first_s": first, "steady_ms": statistics.median(steady),
                      "rgba_sum": float(np.asarray(frame.rgba, np.float64).sum()),
                      "where": sc.__file__}))


def _run(checkout: Path, model: str, mode: str, settings: str) -> dict:
    with tempfile.TemporaryDirectory(prefix="numba-cache-") as cache:
        env = dict(os.environ, PYTHONPATH=str(checkout / "src"), NUMBA_CACHE_DIR=cache)
        out = subprocess.run([sys.executable, __file__, "--child", model, mode, settings],
                             env=env, capture_output=True, text=True, cwd=str(REPO), check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _uptime() -> str:
    return subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    ap.add_argument("--old", help="checkout of the baseline build")
    ap.add_argument("--pairs", default="trilinear:dvr", help="model:mode[,model:mode...]")
    ap.add_argument("--settings", default="", help="DVRSettings as JSON (default: none given)")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--stem", default="dvr_compile")
    args = ap.parse_args()
    if args.child:
        _child(*args.child)
        return
    if not args.old:
        raise SystemExit("--old: the baseline checkout is required")
    sys.path.insert(0, str(HERE))
    from _machine import describe

    builds = {"old": Path(args.old).resolve(), "new": REPO}
    heads = {k: subprocess.run(["git", "-C", str(v), "rev-parse", "--short", "HEAD"],
                               capture_output=True, text=True).stdout.strip()
             for k, v in builds.items()}
    rows = []
    uptimes = [_uptime()]
    for pair in args.pairs.split(","):
        model, mode = pair.split(":")
        row: dict = {"model": model, "mode": mode, "settings": args.settings or None,
                     "runs": {"old": [], "new": []}}
        for _ in range(args.rounds):
            for key, checkout in builds.items():
                row["runs"][key].append(_run(checkout, model, mode, args.settings))
                uptimes.append(_uptime())
        row["first_s"] = {k: statistics.median(r["first_s"] for r in v)
                          for k, v in row["runs"].items()}
        row["steady_ms"] = {k: statistics.median(r["steady_ms"] for r in v)
                            for k, v in row["runs"].items()}
        rows.append(row)
        print(json.dumps({k: row[k] for k in ("model", "mode", "first_s", "steady_ms")}),
              flush=True)
    out = {"machine": describe(), "command": " ".join(sys.argv), "heads": heads,
           "uptime": uptimes, "rows": rows}
    path = HERE / "results" / f"{args.stem}.json"
    path.write_text(json.dumps(out, indent=1))
    lines = [f"# Compile time of one specialisation from an empty Numba cache ({args.stem})", "",
             f"Machine: {out['machine']}", "",
             f"Old: {heads['old']} (`{args.old}`); new: {heads['new']} (this checkout). ML 64^3, "
             "128x128, first render's process CPU time (fresh `NUMBA_CACHE_DIR` per run: the "
             "pair's kernel plus the preparation kernels, the same in both builds) and median "
             f"of 3 renders after it; {args.rounds} runs per build, taking turns, median shown.",
             "", f"Command: `{out['command']}`", "",
             "Load (uptime) before and after each run: "
             + "; ".join(u.split("load average:")[-1].strip() for u in uptimes), "",
             "| pair | old first s | new first s | new / old | old steady ms | new steady ms |",
             "|---|---|---|---|---|---|"]
    for r in rows:
        f, s = r["first_s"], r["steady_ms"]
        lines.append(f"| {r['model']} {r['mode']} | {f['old']:.1f} | {f['new']:.1f} | "
                     f"{f['new'] / f['old']:.2f} | {s['old']:.1f} | {s['new']:.1f} |")
    path.with_suffix(".md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
