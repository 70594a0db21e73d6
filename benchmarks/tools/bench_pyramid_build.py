"""Pyramid build speed: ``build_pyramid`` of a raw memory-mapped uint8 volume, vs a baseline.

The source is the smooth synthetic volume of ``bench_multires.py`` (sine octaves, ``N^3`` uint8,
raw, x fastest), written once into ``--workdir``. Each build runs in a fresh interpreter
(``splinecast`` imported from this tree's ``src`` or from a ``git archive`` of ``--baseline``),
builds the whole pyramid with the default shard and threads, and reports wall time, the process's
CPU time (all threads: the build's tasks and zarr's codec threads), the CPU time spent inside the
build's tasks (a wrapper around ``_copy_task`` / ``_downsample_task`` per level), and peak RSS.
Current and baseline builds alternate; medians of ``--repeats``. On a machine shared with other
jobs wall times move with the load; CPU time is the steadier number.

Usage::

    python benchmarks/tools/bench_pyramid_build.py --sizes 512,1024 --baseline main --workdir /tmp/b
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tarfile
import tempfile
import textwrap
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]  # benchmarks/
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
from _machine import describe  # noqa: E402
from bench_multires import make_source  # noqa: E402

_CHILD = textwrap.dedent("""
    import collections, json, resource, shutil, sys, threading, time
    sys.path.insert(0, sys.argv[1])
    start_cpu, start = time.process_time(), time.perf_counter()
    import splinecast
    from splinecast.multires.store import pyramid as P
    imported = time.process_time() - start_cpu
    tasks = collections.defaultdict(float)
    lock = threading.Lock()

    def timed(fn, level):
        def run(*args):
            t = time.thread_time()
            out = fn(*args)
            with lock:
                tasks[level(args)] += time.thread_time() - t
            return out
        return run

    P._copy_task = timed(P._copy_task, lambda a: "0")
    P._downsample_task = timed(P._downsample_task, lambda a: "x".join(map(str, a[2])))
    out = sys.argv[3]
    shutil.rmtree(out, ignore_errors=True)
    t0, c0 = time.perf_counter(), time.process_time()
    P.build_pyramid(sys.argv[2], out, progress=False)
    result = {"build_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0,
              "import_cpu_s": imported, "task_cpu_s": dict(tasks),
              "maxrss": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024}
    shutil.rmtree(out, ignore_errors=True)
    print(json.dumps(result))
""")


def export_src(ref: str, into: Path) -> Path:
    """``src`` of git ``ref`` as a plain folder (its compiled-code cache starts empty)."""
    archive = into / "src.tar"
    with open(archive, "wb") as f:
        subprocess.run(["git", "-C", str(ROOT), "archive", "--format=tar", ref, "src"],
                       stdout=f, check=True)
    with tarfile.open(archive) as tar:
        tar.extractall(into, filter="data")
    return into / "src"


def build(src: Path, raw: Path, out: Path) -> dict:
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    done = subprocess.run([sys.executable, "-c", _CHILD, str(src), str(raw), str(out)],
                          capture_output=True, text=True, env=env, check=False)
    if done.returncode:
        raise SystemExit(f"build failed: {done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def markdown(r: dict) -> str:
    m = r["machine"]
    mib = 2**20
    lines = [
        "# Pyramid build: raw memory-mapped uint8 -> OME-Zarr pyramid",
        "",
        f"Machine: {m['cpu']}, {m['cores']} cores; shared with other jobs (load average "
        f"{r['load_before'][0]:.1f} before / {r['load_after'][0]:.1f} after), so wall times are "
        f"noisy and CPU times are the steadier measure. Command: `{r['command']}`. Baseline: "
        f"`{r['baseline']}`. Fresh interpreter per build, default shard (128) and threads; "
        "medians of alternating runs (count per row; one warm-up build of each first, so "
        "compiled code is cached). CPU = the process's CPU time after the imports (every "
        "thread, zarr's codec threads included); tasks = CPU inside the build's tasks.",
        "",
        "| volume (runs) | code | build wall s | CPU s | tasks CPU s (level 0 / 1 / rest) | "
        "peak RSS MiB | wall speed-up | CPU speed-up |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for n, row in r["sizes"].items():
        base = row["baseline"]
        for code in ("baseline", "current"):
            s = row[code]
            levels = s["task_cpu_s"]
            names = list(levels)
            rest = sum(levels[k] for k in names[2:])
            first = [levels[k] for k in names[:2]] + [0.0] * (2 - len(names[:2]))
            lines.append(
                f"| {n}^3 ({row.get('repeats', '?')}) | {code} | {s['build_s']:.1f} | "
                f"{s['cpu_s']:.1f} | "
                f"{first[0]:.1f} / {first[1]:.1f} / {rest:.1f} | {s['maxrss'] / mib:.0f} | "
                f"{base['build_s'] / s['build_s']:.2f}x | {base['cpu_s'] / s['cpu_s']:.2f}x |")
    lines.append("")
    return "\n".join(lines)


def _median(runs: list[dict]) -> dict:
    keys = ("build_s", "cpu_s", "import_cpu_s", "maxrss")
    out = {k: statistics.median(r[k] for r in runs) for k in keys}
    out["maxrss"] = max(r["maxrss"] for r in runs)
    levels = runs[0]["task_cpu_s"]
    out["task_cpu_s"] = {k: statistics.median(r["task_cpu_s"][k] for r in runs) for k in levels}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="512", help="comma-separated N (N^3 uint8 sources)")
    parser.add_argument("--baseline", default="main", help="git ref to compare against")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--workdir", help="where the sources and stores go (default: temp)")
    parser.add_argument("--out", default=str(HERE / "results"))
    args = parser.parse_args()
    sizes = [int(s) for s in args.sizes.split(",")]
    work = Path(args.workdir or tempfile.mkdtemp(prefix="bench-pyramid-"))
    work.mkdir(parents=True, exist_ok=True)
    baseline_dir = Path(tempfile.mkdtemp(prefix="baseline-", dir=work))
    codes = {"baseline": export_src(args.baseline, baseline_dir), "current": ROOT / "src"}
    load_before = os.getloadavg()
    out = Path(args.out)
    previous = out / "pyramid_build.json"
    # Sizes measured by earlier runs (e.g. a large one with fewer repeats) are kept.
    kept = json.loads(previous.read_text())["sizes"] if previous.exists() else {}
    results: dict = {"machine": describe(), "baseline": args.baseline,
                     "command": "python benchmarks/tools/bench_pyramid_build.py --sizes "
                                f"{args.sizes} --baseline {args.baseline} --repeats "
                                f"{args.repeats}", "sizes": kept}
    try:
        for n in sizes:
            raw = work / f"synthetic{n}.raw"
            make_source(raw, n)
            store = work / f"build{n}.zarr"
            warm = work / "synthetic64.raw"
            make_source(warm, 64)
            for src in codes.values():  # warm-up: compile and cache each tree's kernels
                build(src, warm, store)
            runs: dict[str, list[dict]] = {k: [] for k in codes}
            for i in range(args.repeats):
                for code, src in codes.items():
                    runs[code].append(build(src, raw, store))
                    print(f"{n}^3 {code} run {i + 1}: {runs[code][-1]}", file=sys.stderr)
            results["sizes"][str(n)] = {code: {**_median(r), "runs": r}
                                        for code, r in runs.items()}
            results["sizes"][str(n)]["repeats"] = args.repeats
            results["sizes"][str(n)]["load"] = os.getloadavg()
    finally:
        shutil.rmtree(baseline_dir, ignore_errors=True)
    results["load_before"], results["load_after"] = load_before, os.getloadavg()
    out.mkdir(parents=True, exist_ok=True)
    (out / "pyramid_build.json").write_text(json.dumps(results, indent=1) + "\n")
    (out / "pyramid_build.md").write_text(markdown(results))
    print(markdown(results))
    if not args.workdir:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
