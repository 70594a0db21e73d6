"""Multiresolution benchmark, build part: a synthetic volume streamed into an OME-Zarr pyramid.

Run ``python benchmarks/bench_multires.py [--quick] [--parts build,cache] [--workdir DIR]``;
results go to ``benchmarks/results/multires[_quick].json`` and ``.md``. Parts not run keep their
previous results (the render part joins when the renderer of a cut is wired; keep it separate).

- ``build``: a ``N^3`` uint8 volume (2048^3 = 8 GiB; ``--quick``: 192^3), smooth with structure at
  all scales (a sum of sine octaves with amplitude ``2^-0.7k``), written slice by slice as a raw
  file with a JSON sidecar (memory-mapped, never whole in RAM), then built into a pyramid in a
  fresh process: wall time, peak RSS (``ru_maxrss``, which counts the source's mapped pages the
  build touched) and peak anonymous memory (sampled ``RssAnon``: what the build itself holds).
  Baseline in the same run: one plain pass over the source (read and sum, in the same slabs).
- ``cache``: a :class:`~splinecast.multires.stream.BrickStream` with a byte budget renders the
  cut of several views to completion in a fresh process; the overhead is the peak anonymous
  memory above the process before the stream opened, minus the cache's own peak bytes.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _machine import describe  # noqa: E402

OCTAVES = 7


def make_source(path: Path, n: int) -> None:
    """Write the synthetic volume as ``path`` (raw, x fastest) + ``path.json``, slab by slab."""
    if path.exists() and path.stat().st_size == n**3:
        return
    out = np.memmap(path, dtype=np.uint8, mode="w+", shape=(n, n, n), order="F")
    x = np.arange(n, dtype=np.float32) / n
    rng = np.random.default_rng(7)
    phases = rng.uniform(0, 2 * np.pi, (OCTAVES, 3))
    norm = sum(2.0 ** (-0.7 * k) for k in range(OCTAVES))
    for z0 in range(0, n, 16):
        z = x[z0:z0 + 16]
        slab = np.zeros((n, n, len(z)), dtype=np.float32)
        for k in range(OCTAVES):
            w = 2 * np.pi * 2.0**k * 1.5
            a = np.sin(w * x + phases[k, 0])[:, None, None]
            b = np.sin(w * x + phases[k, 1])[None, :, None]
            c = np.sin(w * z + phases[k, 2])[None, None, :]
            slab += 2.0 ** (-0.7 * k) * a * b * c
        out[:, :, z0:z0 + len(z)] = np.clip(slab / norm * 127.5 + 128, 0, 255).astype(np.uint8)
    out.flush()
    del out
    Path(str(path)[:-4] + ".json").write_text(json.dumps({"shape": [n] * 3, "dtype": "uint8"}))


_CHILD = textwrap.dedent("""
    import json, resource, sys, threading, time
    def anon():
        for line in open("/proc/self/status"):
            if line.startswith("RssAnon"):
                return int(line.split()[1]) * 1024
    peak = [0]
    stop = threading.Event()
    def sample():
        while not stop.is_set():
            peak[0] = max(peak[0], anon()); time.sleep(0.02)
    job, args = sys.argv[1], json.loads(sys.argv[2])
    import numpy as np
    import splinecast as sc
    if job == "build":
        from splinecast.multires.pyramid import build_pyramid
        before = anon(); threading.Thread(target=sample, daemon=True).start()
        t = time.perf_counter()
        build_pyramid(args["source"], args["out"], overwrite=True, progress=False)
        result = {"seconds": time.perf_counter() - t}
    elif job == "baseline":
        before = anon(); threading.Thread(target=sample, daemon=True).start()
        vol = sc.read(args["source"]); t = time.perf_counter(); total = 0
        for z0 in range(0, vol.shape[2], 128):
            total += int(np.asarray(vol.data[:, :, z0:z0 + 128]).sum(dtype=np.int64))
        result = {"seconds": time.perf_counter() - t}
    else:
        from splinecast.multires.stream import BrickStream
        from splinecast.multires.relevance import ValueFilter
        mv = sc.read(args["out"])
        before = anon(); threading.Thread(target=sample, daemon=True).start()
        t = time.perf_counter(); frames = 0
        with BrickStream(mv, args["budget"], lod=args["lod"], loads_per_frame=64) as stream:
            for azimuth in (0, 60, 120, 240):
                cam = sc.Camera.orbit(mv, azimuth=azimuth, elevation=25, size=(1024, 768),
                                      zoom=2.0)
                for _ in range(400):
                    fb = stream.frame(cam, ValueFilter.iso(128), timeout=30); frames += 1
                    if fb.complete:
                        break
            stats = stream.cache.stats()
        result = {"seconds": time.perf_counter() - t, "frames": frames,
                  "cache_peak_bytes": stats["peak_bytes"], "budget": stats["budget"],
                  "loaded": stats["loaded"], "evicted": stats["evicted"]}
    stop.set()
    result["peak_anon_above_start"] = peak[0] - before
    result["maxrss"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    print(json.dumps(result))
""")


def child(job: str, **args) -> dict:
    done = subprocess.run([sys.executable, "-c", _CHILD, job, json.dumps(args)],
                          capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def mib(v: float) -> str:
    return f"{v / 2**20:.0f} MiB"


def markdown(results: dict) -> str:
    m = results["machine"]
    lines = [f"# Multiresolution benchmark ({'quick' if results['quick'] else 'full'})", "",
             f"Machine: {m['cpu']}, {m['cores']} cores; `{results['command']}`. "
             f"{results.get('note', '')}", ""]
    b = results.get("build")
    if b:
        lines += ["## Build (raw memory-mapped source -> OME-Zarr pyramid)", "",
                  "| volume | source | store | build (median) | one read pass | ratio | "
                  "peak RSS | peak anon above start |", "|---|---|---|---|---|---|---|---|",
                  f"| {b['n']}^3 uint8 | {mib(b['source_bytes'])} | {mib(b['store_bytes'])} | "
                  f"{b['build_s']:.2f} s | {b['baseline_s']:.2f} s | "
                  f"{b['build_s'] / b['baseline_s']:.1f}x | {mib(b['maxrss'])} | "
                  f"{mib(b['peak_anon'])} |", ""]
    c = results.get("cache")
    if c:
        lines += ["## Cache (views rendered to a complete cut within the budget)", "",
                  "| budget | cache peak | peak anon above start | overhead | frames | loaded | "
                  "evicted |", "|---|---|---|---|---|---|---|",
                  f"| {mib(c['budget'])} | {mib(c['cache_peak_bytes'])} | "
                  f"{mib(c['peak_anon_above_start'])} | {mib(c['overhead'])} | {c['frames']} | "
                  f"{c['loaded']} | {c['evicted']} |", ""]
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="192^3 instead of 2048^3")
    parser.add_argument("--parts", default="build,cache")
    parser.add_argument("--workdir", help="where the source and the store go (default: temp)")
    parser.add_argument("--repeats", type=int, help="build repeats (default 3 quick, 1 full)")
    parser.add_argument("--out", default=str(HERE / "results"))
    args = parser.parse_args()
    n = 192 if args.quick else 2048
    repeats = args.repeats or (3 if args.quick else 1)
    parts = set(args.parts.split(","))
    stem = "multires_quick" if args.quick else "multires"
    out = Path(args.out)
    old = json.loads((out / f"{stem}.json").read_text()) if (out / f"{stem}.json").exists() else {}
    command = "python benchmarks/bench_multires.py" + (" --quick" if args.quick else "")
    results = {"machine": describe(), "quick": args.quick, "command": command,
               "note": "Medians of fresh processes; the build includes zarr's and dask's "
                       "start-up inside the process but not the interpreter's."}
    work = Path(args.workdir or tempfile.mkdtemp(prefix="bench-multires-"))
    source, store = work / f"synthetic{n}.raw", work / f"synthetic{n}.zarr"
    print(f"source {source}", file=sys.stderr)
    make_source(source, n)
    if "build" in parts:
        builds = [child("build", source=str(source), out=str(store)) for _ in range(repeats)]
        bases = [child("baseline", source=str(source)) for _ in range(repeats)]
        size = sum(p.stat().st_size for p in store.rglob("*") if p.is_file())
        results["build"] = {
            "n": n, "source_bytes": n**3, "store_bytes": size, "repeats": repeats,
            "build_s": statistics.median(r["seconds"] for r in builds),
            "baseline_s": statistics.median(r["seconds"] for r in bases),
            "maxrss": max(r["maxrss"] for r in builds),
            "peak_anon": max(r["peak_anon_above_start"] for r in builds),
            "runs": builds, "baseline_runs": bases}
    else:
        results["build"] = old.get("build")
    if "cache" in parts:
        if not store.exists():
            child("build", source=str(source), out=str(store))
        budget = "64MiB" if args.quick else "1GiB"
        c = child("cache", out=str(store), budget=budget, lod=1.0)
        c["overhead"] = c["peak_anon_above_start"] - c["cache_peak_bytes"]
        results["cache"] = c
    else:
        results["cache"] = old.get("cache")
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{stem}.json").write_text(json.dumps(results, indent=1) + "\n")
    (out / f"{stem}.md").write_text(markdown(results))
    print(markdown(results))
    if not args.workdir:
        import shutil

        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    main()
