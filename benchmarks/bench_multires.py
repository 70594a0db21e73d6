"""Multiresolution benchmark: a synthetic volume streamed into an OME-Zarr pyramid and rendered.

Run ``python benchmarks/bench_multires.py [--quick] [--parts build,cache,render] [--workdir DIR]``;
results go to ``benchmarks/results/multires[_quick].json`` and ``.md``. Parts not run keep their
previous results.

- ``build``: a ``N^3`` uint8 volume (2048^3 = 8 GiB; ``--quick``: 192^3), smooth with structure at
  all scales (a sum of sine octaves with amplitude ``2^-0.7k``), written slice by slice as a raw
  file with a JSON sidecar (memory-mapped, never whole in RAM), then built into a pyramid in a
  fresh process: wall time, peak RSS (``ru_maxrss``, which counts the source's mapped pages the
  build touched) and peak anonymous memory (sampled ``RssAnon``: what the build itself holds).
  Baseline in the same run: one plain pass over the source (read and sum, in the same slabs).
- ``cache``: a :class:`~splinecast.multires.cut.stream.BrickStream` with a byte budget renders the
  cut of several views to completion in a fresh process; the overhead is the peak anonymous
  memory above the process before the stream opened, minus the cache's own peak bytes.
- ``render``: ``Scene(pyramid, budget=1GiB)`` (``--quick``: 4 MiB, so that level 0 does not fit
  either) renders one view at 1024x768 (``--quick``: 256x192), isosurface and DVR, each in a
  fresh process after a warm-up in that process that compiles the kernels (on another scene):
  time to open the scene, to the first (incomplete) image drawn at once from what is resident
  (``wait=False``, the viewer's first pass), to the first image that waited for up to the load
  budget (``scene.render``'s default), until the cut is complete; steady
  frame time (median of 5); bricks read per frame; peak RSS and peak anonymous memory above the
  process before the scene opened, against the cache's own peak (the overhead) and against the
  budget (above the budget; the seam copies count against the budget, so this is what the
  fixed overhead amounts to); the seam copies held at the end. Baseline in the same run: the
  in-memory ``Scene`` of the finest level that fits in the budget (2048^3: level 2, 513^3), same
  view, median of 5 after warm-up; and the image error of both against the finest level
  rendered in memory (``--quick``) or, when it does not fit in ``--reference-budget``, the
  multiresolution render at ``lod=0.5`` with that budget. ``--budgets 512MiB,2GiB`` renders the
  isosurface to completion at further budgets too: the memory above the budget at each, which
  shows whether the overhead is fixed.
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
    sys.path.insert(0, sys.argv[3])
    from bench_multires import render_job
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
        from splinecast.multires.store.pyramid import build_pyramid
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
    elif job in ("render", "memory"):
        result = render_job(job, args, anon, sample, stop, peak)
        before = result.pop("before")
    else:
        from splinecast.multires.cut.stream import BrickStream
        from splinecast.multires.cut.relevance import ValueFilter
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


# --------------------------------------------------------------------------- render part
def _view(mv, size):
    import splinecast as sc

    return sc.Camera.orbit(mv, azimuth=30, elevation=25, size=tuple(size), zoom=1.3)


def _modes():
    import splinecast as sc

    tf = sc.TransferFunction([(140.0, 0.0), (170.0, 0.08), (255.0, 0.3)], domain=(0.0, 255.0))
    return {"iso": {"mode": "iso", "iso": 128.0}, "dvr": {"mode": "dvr", "tf": tf}}


def render_job(job: str, args: dict, anon, sample, stop, peak) -> dict:
    """One mode in a fresh process: the multiresolution scene (``render``) or the in-memory
    scene of one level (``memory``); images go to ``args["image"]`` (.npz)."""
    import threading
    import time

    import splinecast as sc

    mv = sc.read(args["store"])
    options = _modes()[args["mode"]]
    cam = _view(mv, args["size"])
    if job == "memory":
        vol = mv.level(args["level"]).to_volume(max_bytes=2**40)
        scene = sc.Scene(vol)
        scene.render(cam, **options)  # compiles, classifies
        before = anon()
        threading.Thread(target=sample, daemon=True).start()
        times = []
        for _ in range(5):
            t = time.perf_counter()
            frame = scene.render(cam, **options)
            times.append(time.perf_counter() - t)
        np.savez(args["image"], depth=frame.depth, rgba=frame.rgba)
        return {"before": before, "steady_s": float(np.median(times)), "times": times,
                "level": args["level"], "shape": list(vol.shape)}
    # Warm-up on another scene and view: compile the kernels for the store's dtype and for the
    # float64 arrays of bricks changed at seams. A small image's cut can lie on one level and
    # have no seam, which left the seam bricks' kernels to be compiled in the measured first
    # frame (17 s of the quick run's "first image"); the same image size from another side
    # has the same mix of levels.
    # A few frames suffice: the kernels compile in the first ones (levels mixed by
    # substitution bring the seam bricks' kernels); refining a 1 GiB cut to completion here
    # took longer than the measurement itself.
    other = sc.Camera.orbit(mv, azimuth=210, elevation=-25, size=tuple(args["size"]), zoom=1.3)
    brick = args.get("brick")  # None: the scene's default render brick
    with sc.Scene(mv, budget=args["budget"], lod=args["lod"], brick=brick) as warm:
        for _ in range(4):
            if warm.render(other, **options).stats["complete"]:
                break
    before = anon()
    threading.Thread(target=sample, daemon=True).start()
    t0 = time.perf_counter()
    scene = sc.Scene(mv, budget=args["budget"], lod=args["lod"], brick=brick)
    open_s = time.perf_counter() - t0
    # The first image as the viewer shows it (its interactive and coarse passes draw what is
    # resident at once), then frames that wait for up to the load budget, as scene.render does.
    at_once = scene.render(cam, **options, wait=False)
    at_once_s = time.perf_counter() - t0
    frame = scene.render(cam, **options)
    first_s = time.perf_counter() - t0
    first = frame.stats
    loads, frames = [frame.stats["loaded_this_frame"]], 1
    while not frame.stats["complete"] and frames < 2000:
        frame = scene.render(cam, **options)
        loads.append(frame.stats["loaded_this_frame"])
        frames += 1
    complete_s = time.perf_counter() - t0
    times = []
    for _ in range(5):
        t = time.perf_counter()
        frame = scene.render(cam, **options)
        times.append(time.perf_counter() - t)
    st = frame.stats
    np.savez(args["image"], depth=frame.depth, rgba=frame.rgba)
    scene.close()
    keep = ("cut_bricks", "cut_levels", "drawables_traced", "drawables_changed_at_seams",
            "seam_parts", "seam_copy_bytes", "reserved_bytes", "resident_bytes", "peak_bytes",
            "budget", "loaded", "evicted", "trace_ms", "cut_ms")
    return {"before": before, "open_s": open_s, "at_once_s": at_once_s,
            "at_once_trace_ms": at_once.stats["trace_ms"], "first_s": first_s,
            "complete_s": complete_s,
            "frames_to_complete": frames, "steady_s": float(np.median(times)), "times": times,
            "loads_per_frame_mean": float(np.mean(loads)), "loads_per_frame_max": int(max(loads)),
            "first_frame": {k: first[k] for k in ("substituted", "cut_bricks", "trace_ms")},
            "final": {k: st[k] for k in keep if k in st}}


def _image_error(a: dict, b: dict, mode: str, voxel: float) -> dict:
    if mode == "dvr":
        return {"mean_abs_rgba": float(np.abs(a["rgba"] - b["rgba"]).mean()),
                "max_abs_rgba": float(np.abs(a["rgba"] - b["rgba"]).max())}
    ha, hb = np.isfinite(a["depth"]), np.isfinite(b["depth"])
    both = ha & hb
    diff = np.abs(a["depth"][both] - b["depth"][both]) / voxel
    return {"hit_mismatch": float((ha != hb).mean()),
            "mean_depth_voxels": float(diff.mean()) if diff.size else 0.0,
            "p99_depth_voxels": float(np.percentile(diff, 99)) if diff.size else 0.0}


def render_part(store: Path, budget: str, size: tuple[int, int], work: Path,
                reference_budget: int, keep_reference: bool = False,
                coarser: tuple[float, ...] = (), baseline_brick: int | None = None,
                other_budgets: tuple[str, ...] = ()) -> dict:
    """Both modes, the in-memory baseline and the image errors; the isosurface's memory
    above the budget at ``other_budgets``."""
    import splinecast as sc
    from splinecast.multires.store.budget import parse_bytes

    mv = sc.read(store)
    limit = parse_bytes(budget, "budget")
    fits = [lv.index for lv in mv.levels if lv.nbytes <= limit]
    level = fits[0]
    out: dict = {"budget": limit, "size": list(size), "memory_level": level,
                 "memory_shape": list(mv.level(level).shape), "modes": {}}
    for mode in ("iso", "dvr"):
        images = {name: work / f"{mode}_{name}.npz" for name in ("multi", "memory", "ref")}
        multi = child("render", store=str(store), mode=mode, size=list(size), budget=budget,
                      lod=1.0, image=str(images["multi"]))
        memory = child("memory", store=str(store), mode=mode, size=list(size), level=level,
                       image=str(images["memory"]))
        ref: dict | None = None
        if keep_reference:
            # The finer reference of an earlier run in this workdir (its render takes hours at
            # 2048^3); none yet: no error is measured for the mode.
            ref_what = f"{images['ref']} of an earlier run"
            if not images["ref"].exists():
                images.pop("ref")
                ref_what = "none (no reference image kept)"
        elif mv.levels[0].nbytes <= reference_budget:
            ref = child("memory", store=str(store), mode=mode, size=list(size), level=0,
                        image=str(images["ref"]))
            ref_what = "level 0 in memory"
        else:
            ref = child("render", store=str(store), mode=mode, size=list(size),
                        budget=reference_budget, lod=0.5, image=str(images["ref"]))
            ref_what = f"multiresolution, lod 0.5, budget {mib(reference_budget)}"
        # Coarser levels of detail (``--coarser-lod``): lod 2 draws voxels of up to 2 pixels,
        # about the in-memory level's resolution, so its ratio compares equal detail.
        extra = {}
        for lod in coarser:
            name = f"multi_lod{lod:g}"
            images[name] = work / f"{mode}_{name}.npz"
            extra[f"{lod:g}"] = child("render", store=str(store), mode=mode, size=list(size),
                                      budget=budget, lod=lod, image=str(images[name]))
        if baseline_brick and mode == "iso":
            # The same run with another render brick (``--baseline-brick``; the isosurface only:
            # a DVR run of 32^3 bricks takes most of ten minutes).
            name = f"multi_brick{baseline_brick}"
            images[name] = work / f"{mode}_{name}.npz"
            extra[f"1, bricks of {baseline_brick}"] = child(
                "render", store=str(store), mode=mode, size=list(size), budget=budget, lod=1.0,
                brick=baseline_brick, image=str(images[name]))
        loaded = {k: dict(np.load(v)) for k, v in images.items()}
        voxel = float(min(mv.spacing))
        for run in (multi, *extra.values()):
            run["overhead"] = run["peak_anon_above_start"] - run["final"]["peak_bytes"]
            run["above_budget"] = run["peak_anon_above_start"] - limit
        out["modes"][mode] = {
            "multires": multi, "memory": memory, "reference": ref_what, "reference_run": ref,
            "error_multires": (_image_error(loaded["multi"], loaded["ref"], mode, voxel)
                               if "ref" in loaded else {}),
            "error_memory": (_image_error(loaded["memory"], loaded["ref"], mode, voxel)
                             if "ref" in loaded else {}),
            "coarser": {lod: dict(run, error=(_image_error(loaded[name], loaded["ref"], mode,
                                                           voxel) if "ref" in loaded else {}))
                        for (lod, run), name in zip(extra.items(),
                                                    [k for k in images if k.startswith("multi_")],
                                                    strict=True)}}
    # The fixed overhead: the isosurface rendered to completion at other budgets (the same
    # view), peak anonymous memory above the process's start against each budget.
    out["budgets"] = {}
    for other in other_budgets:
        run = child("render", store=str(store), mode="iso", size=list(size), budget=other,
                    lod=1.0, image=str(work / f"iso_budget_{other}.npz"))
        other_limit = parse_bytes(other, "budget")
        run["above_budget"] = run["peak_anon_above_start"] - other_limit
        run["overhead"] = run["peak_anon_above_start"] - run["final"]["peak_bytes"]
        out["budgets"][str(other_limit)] = run
    return out


def budgets_markdown(r: dict) -> list[str]:
    """The table of the isosurface's memory at several budgets."""
    runs = dict(r.get("budgets") or {})
    if not runs:
        return []
    runs.setdefault(str(r["budget"]), r["modes"]["iso"]["multires"])
    lines = ["", "### Memory above the budget (iso, lod 1, rendered to completion)", "",
             "| budget | cut bricks | cache peak | seam copies (end) | peak anon above start | "
             "above the budget | complete | steady |", "|---|---|---|---|---|---|---|---|"]
    for limit, run in sorted(runs.items(), key=lambda kv: int(kv[0])):
        fin = run["final"]
        lines.append(
            f"| {mib(int(limit))} | {fin['cut_bricks']} | {mib(fin['peak_bytes'])} | "
            f"{mib(fin.get('seam_copy_bytes', 0))} | {mib(run['peak_anon_above_start'])} | "
            f"{mib(run['peak_anon_above_start'] - int(limit))} | {run['complete_s']:.1f} s | "
            f"{run['steady_s'] * 1e3:.0f} ms |")
    return lines


def render_markdown(r: dict) -> list[str]:
    w, h = r["size"]
    shape = "x".join(str(v) for v in r["memory_shape"])
    lines = [f"## Render ({w}x{h}, budget {mib(r['budget'])}, trilinear, lod 1)", "",
             f"In-memory baseline: level {r['memory_level']} ({shape}), the finest that fits in "
             "the budget. Errors against the finest level "
             f"({r['modes']['iso']['reference']}).", "",
             "| mode | open | first image at once | first waited image | complete (frames) | "
             "steady | in-memory | ratio | "
             "bricks read / frame (mean, max) | cut bricks | peak RSS | peak anon above start | "
             "cache peak | seam copies | overhead | above the budget |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    rows = []
    for mode, m in r["modes"].items():
        rows.append((mode, m["multires"], m["memory"]))
        rows += [(f"{mode}, lod {lod}", run, m["memory"])
                 for lod, run in m.get("coarser", {}).items()]
    for mode, a, b in rows:
        lines.append(
            f"| {mode} | {a['open_s']:.2f} s | {a.get('at_once_s', float('nan')):.2f} s | "
            f"{a['first_s']:.2f} s | {a['complete_s']:.2f} s "
            f"({a['frames_to_complete']}) | {a['steady_s'] * 1e3:.0f} ms | "
            f"{b['steady_s'] * 1e3:.0f} ms | {a['steady_s'] / b['steady_s']:.2f}x | "
            f"{a['loads_per_frame_mean']:.0f}, {a['loads_per_frame_max']} | "
            f"{a['final']['cut_bricks']} | {mib(a['maxrss'])} | "
            f"{mib(a['peak_anon_above_start'])} | {mib(a['final']['peak_bytes'])} | "
            f"{mib(a['final'].get('seam_copy_bytes', 0))} | {mib(a['overhead'])} | "
            f"{mib(a.get('above_budget', 0))} |")
    lines += ["", "| mode | error of the multiresolution image | error of the in-memory level |",
              "|---|---|---|"]
    for mode, m in r["modes"].items():
        def fmt(e):
            return ", ".join(f"{k} {v:.4g}" for k, v in e.items()) or "not measured"
        lines.append(f"| {mode} | {fmt(m['error_multires'])} | {fmt(m['error_memory'])} |")
        for lod, run in m.get("coarser", {}).items():
            lines.append(f"| {mode}, lod {lod} | {fmt(run['error'])} | |")
    return lines + budgets_markdown(r) + [""]


def child(job: str, **args) -> dict:
    done = subprocess.run([sys.executable, "-c", _CHILD, job, json.dumps(args), str(HERE)],
                          capture_output=True, text=True, check=True)
    result = json.loads(done.stdout.strip().splitlines()[-1])
    # Each child's result as soon as it is known (a full run takes hours; the files are written
    # only at the end).
    print(f"{job} {json.dumps(args)}: {json.dumps(result)}", file=sys.stderr, flush=True)
    return result


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
    if results.get("render"):
        lines += render_markdown(results["render"])
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="192^3 instead of 2048^3")
    parser.add_argument("--parts", default="build,cache,render")
    parser.add_argument("--reference-budget", default="4GiB",
                        help="largest level 0 rendered in memory as the error reference")
    parser.add_argument("--workdir", help="where the source and the store go (default: temp)")
    parser.add_argument("--coarser-lod", default="",
                        help="comma-separated further lod values rendered (e.g. 2)")
    parser.add_argument("--baseline-brick", type=int,
                        help="also render the isosurface with this render brick (e.g. 32)")
    parser.add_argument("--budgets", default="",
                        help="comma-separated further budgets the isosurface is rendered with "
                             "(memory above the budget; e.g. 512MiB,2GiB)")
    parser.add_argument("--keep-reference", action="store_true",
                        help="reuse the reference images of an earlier run in --workdir")
    parser.add_argument("--repeats", type=int, help="build repeats (default 3 quick, 1 full)")
    parser.add_argument("--out", default=str(HERE / "results"))
    args = parser.parse_args()
    n = 192 if args.quick else 2048
    repeats = args.repeats or (3 if args.quick else 1)
    parts = set(args.parts.split(","))
    stem = "multires_quick" if args.quick else "multires"
    out = Path(args.out)
    old = json.loads((out / f"{stem}.json").read_text()) if (out / f"{stem}.json").exists() else {}
    command = " ".join(["python benchmarks/bench_multires.py", *sys.argv[1:]])
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
    if "render" in parts:
        from splinecast.multires.store.budget import parse_bytes

        if not store.exists():
            child("build", source=str(source), out=str(store))
        size = (256, 192) if args.quick else (1024, 768)
        results["render"] = render_part(store, "4MiB" if args.quick else "1GiB", size, work,
                                        parse_bytes(args.reference_budget, "--reference-budget"),
                                        args.keep_reference,
                                        tuple(float(v) for v in args.coarser_lod.split(",") if v),
                                        args.baseline_brick,
                                        tuple(v for v in args.budgets.split(",") if v))
    else:
        results["render"] = old.get("render")
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
