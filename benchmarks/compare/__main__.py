"""Command line of the comparison suite: ``python -m benchmarks.compare [--quick]``."""

from __future__ import annotations

import argparse
import json
import sys
import time
from importlib import metadata
from pathlib import Path
from typing import Any

from . import methods as M
from . import report, runner, scenes

HERE = Path(__file__).resolve().parent
RESULTS = HERE.parent / "results"
ISO_KEYS = list(M.ISO_METHODS)


def machine() -> dict[str, Any]:
    """CPU, cores and versions (the core benchmark's description plus VTK and scikit-image)."""
    sys.path.insert(0, str(HERE.parent))
    from _machine import describe

    info = describe()
    for package in ("vtk", "scikit-image", "matplotlib"):
        try:
            info["versions"][package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            info["versions"][package] = None
    return info


def run(quick: bool, repeats: int, out: Path, memory: bool = True, volume_modes: bool = True,
        log=print, only_volume: bool = False, scenes_only: list[str] | None = None,
        sizes_only: list[tuple[int, int]] | None = None, stem: str | None = None,
        only_dense: bool = False) -> dict[str, Any]:
    """Run the suite and write its results; returns the results dictionary.

    ``only_volume``: run only MIP/DVR and merge them into the stored results of ``out`` (the
    isosurface, quality and memory sections of the stored JSON are kept as they are);
    ``only_dense``: the DVR rows with dense transfer functions, merged the same way.
    ``scenes_only`` keeps the scenes whose label contains one of its strings, ``sizes_only``
    replaces the image sizes (a partial run on a busy machine; write it under another ``stem``).
    """
    start = time.perf_counter()
    vtk = M.vtk_status()
    notes: list[str] = []
    if not vtk["available"]:
        notes.append(f"VTK methods skipped: {vtk['reason']}")
    if not M.skimage_status()["available"]:
        notes.append(f"scikit-image skipped: {M.skimage_status()['reason']}")
    # splinecast's MIP/DVR are checked when they run (other work lands them); see mode_notes.
    if quick:
        suite, more = scenes.quick_suite()
        sizes = [(128, 128)]
        quality_size = (128, 128)
        volume_scenes = [scenes.ml(64)]
    else:
        suite, more = scenes.full_suite()
        sizes = [(512, 512), (1024, 768)]
        quality_size = (512, 512)
        volume_scenes = [s for s in suite if s.label in (
            "marschner-lobb 128^3", "marschner-lobb 256^3", "noise 256^3")
            or s.kind == "mri"]
    notes += more
    if scenes_only:
        def kept(spec) -> bool:
            return any(part in spec.label for part in scenes_only)

        suite = [spec for spec in suite if kept(spec)]
        volume_scenes = [spec for spec in volume_scenes if kept(spec)]
        notes.append("partial run: scenes " + ", ".join(spec.label for spec in suite))
    if sizes_only:
        sizes = list(sizes_only)
        notes.append("partial run: images " + ", ".join(f"{w}x{h}" for w, h in sizes))
    for note in notes:
        log(f"note: {note}")
    results: dict[str, Any] = {
        "command": "python -m benchmarks.compare" + (" --quick" if quick else ""),
        "machine": machine(), "vtk": vtk, "notes": notes, "iso": [], "volume": [],
        "memory": {}, "threads": {},
    }
    stem = stem or ("compare_quick" if quick else "compare")
    if only_dense:
        return run_only_dense(quick, repeats, out, stem, volume_scenes, log)
    if only_volume:
        return run_only_volume(quick, repeats, out, stem, volume_scenes, notes, log, start)
    error_images: dict[str, dict] = {}
    for spec in suite:
        log(f"iso: {spec.label}")
        r = runner.run_iso_scene(spec, sizes, ISO_KEYS, repeats, quality_size, log)
        error_images[spec.label] = r.pop("_error_images")
        results["iso"].append(r)
        for k, info in r["methods"].items():
            results["threads"][ISO_LABELS_SHORT.get(k, k)] = info["threads"]
    if volume_modes:
        run_volume(volume_scenes, sizes[-1], repeats, results, log)
        results["dense_dvr"] = run_dense(volume_scenes, quick, sizes[-1], repeats, log)
    results["notes"] += mode_notes(results["volume"], volume_modes)
    results["volume_quality_size"] = list(runner.QUALITY_SIZE)
    if memory:
        size = sizes[-1]
        for spec in suite:
            if quick or spec.label in ("marschner-lobb 256^3", "noise 256^3", "noise 512^3"):
                jobs = [("iso", k, "iso", 0.0) for k in ISO_KEYS if not M.iso_requirements(k)]
                for r in results["volume"]:
                    if r["scene"] == spec.label:
                        jobs += [("volume", k, r["mode"], r["steps"].get(k, 0.0))
                                 for k in M.volume_keys(r["mode"]) if k not in r["skipped"]]
                results["memory"][spec.label] = runner.measure_memory(spec, jobs, size, log)
    results["machine"] = machine()  # the threading layer is known after the first kernel ran
    results["elapsed_s"] = time.perf_counter() - start
    for path in report.write(results, error_images, out, stem):
        log(f"wrote {path}")
    return results


def run_volume(volume_scenes, size: tuple[int, int], repeats: int, results: dict[str, Any],
               log=print) -> None:
    """MIP and DVR of every volume scene into ``results["volume"]`` and ``results["threads"]``."""
    for spec in volume_scenes:
        for mode in ("mip", "dvr"):
            log(f"{mode}: {spec.label}")
            r = runner.run_volume_scene(spec, mode, [size], M.volume_keys(mode), repeats, log)
            results["volume"].append(r)
            for k, t in r["threads"].items():
                results["threads"][f"{k} {mode}"] = t


#: The scenes of the dense-DVR rows (full suite; the quick suite uses its one volume scene).
DENSE_SCENES = ("marschner-lobb 256^3", "MNI152")


def run_dense(volume_scenes, quick: bool, size: tuple[int, int], repeats: int,
              log=print) -> list[dict[str, Any]]:
    """The dense-DVR rows (:func:`runner.run_dense_dvr_scene`) of the scenes that have them."""
    rows = []
    for spec in volume_scenes:
        if quick or any(label in spec.label for label in DENSE_SCENES):
            log(f"dense dvr: {spec.label}")
            rows.append(runner.run_dense_dvr_scene(spec, size, repeats, log))
    return rows


def run_only_dense(quick: bool, repeats: int, out: Path, stem: str, volume_scenes,
                   log=print) -> dict[str, Any]:
    """Rerun the dense-DVR rows and merge them into the stored ``out/stem.json``."""
    path = out / f"{stem}.json"
    if not path.exists():
        raise SystemExit(f"--only-dense needs the stored results {path}; run the full suite")
    results = json.loads(path.read_text())
    size = (128, 128) if quick else (1024, 768)
    results["dense_dvr"] = run_dense(volume_scenes, quick, size, repeats, log)
    note = ("Dense-DVR rows rerun alone (`python -m benchmarks.compare"
            f"{' --quick' if quick else ''} --only-dense`) and merged into the stored results.")
    results["notes"] = [n for n in results.get("notes", [])
                        if not n.startswith("Dense-DVR rows rerun")] + [note]
    results["machine"] = machine()
    for written in report.write(results, None, out, stem):
        log(f"wrote {written}")
    return results


def run_only_volume(quick: bool, repeats: int, out: Path, stem: str, volume_scenes,
                    notes: list[str], log, start: float) -> dict[str, Any]:
    """Rerun MIP/DVR and merge them into the stored ``out/stem.json`` (kept: everything else)."""
    path = out / f"{stem}.json"
    if not path.exists():
        raise SystemExit(f"--only-volume needs the stored results {path}; run the full suite")
    results = json.loads(path.read_text())
    size = (128, 128) if quick else (1024, 768)
    old_notes = [n for n in results.get("notes", [])
                 if not n.startswith(("splinecast MIP", "splinecast DVR", "MIP/DVR rerun"))]
    results["volume"] = []
    results["threads"] = {k: v for k, v in results.get("threads", {}).items()
                          if not k.endswith((" mip", " dvr"))}
    run_volume(volume_scenes, size, repeats, results, log)
    results["notes"] = old_notes + [n for n in notes if n not in old_notes]
    results["notes"] += mode_notes(results["volume"], True)
    results["notes"].append(
        f"MIP/DVR rerun alone (`python -m benchmarks.compare{' --quick' if quick else ''} "
        "--only-volume`) and merged into the stored results; the isosurface, quality and memory "
        "sections are from the earlier full run (its MIP/DVR memory figures used the steps of "
        "that run).")
    command = results.get("command", "python -m benchmarks.compare")
    if "--only-volume" not in command:
        results["command"] = command + " (MIP/DVR: --only-volume)"
    results["volume_quality_size"] = list(runner.QUALITY_SIZE)
    results["machine"] = machine()
    results["volume_elapsed_s"] = time.perf_counter() - start
    for written in report.write(results, None, out, stem):
        log(f"wrote {written}")
    return results


def mode_notes(volume_results: list[dict[str, Any]], ran: bool) -> list[str]:
    """Say for MIP and DVR whether splinecast's own mode took part in this run."""
    notes = []
    for mode in ("mip", "dvr"):
        runs = [r for r in volume_results if r["mode"] == mode]
        if ran and runs and all("splinecast" in r["skipped"] for r in runs):
            notes.append(f"splinecast {mode.upper()} not available yet "
                         f"({runs[0]['skipped']['splinecast']}); VTK's {mode.upper()} timed alone")
    return notes


ISO_LABELS_SHORT = {"splinecast": "splinecast", "splinecast-s31": "splinecast s31",
                    "splinecast-bspline3": "splinecast bspline3",
                    "vtk-flying-edges-smoothed": "VTK flying edges + smoothing",
                    "vtk-flying-edges": "VTK flying edges",
                    "vtk-marching-cubes": "VTK marching cubes",
                    "skimage-mc": "skimage marching cubes + VTK"}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.compare",
        description="splinecast vs VTK and scikit-image: speed and image quality.")
    parser.add_argument("--quick", action="store_true",
                        help="64^3 volumes at 128x128 (the test suite's version)")
    parser.add_argument("--repeats", type=int, default=7, help="timed runs per measurement")
    parser.add_argument("--out", default=str(RESULTS), help="output folder")
    parser.add_argument("--no-memory", action="store_true", help="skip the per-method RSS runs")
    parser.add_argument("--no-volume", action="store_true", help="skip MIP/DVR")
    parser.add_argument("--only-volume", action="store_true",
                        help="run only MIP/DVR and merge them into the stored results")
    parser.add_argument("--only-dense", action="store_true",
                        help="run only the DVR rows with dense transfer functions (MRI, "
                        "Marschner-Lobb 256^3) and merge them into the stored results")
    parser.add_argument("--scenes", help="comma-separated parts of scene labels to keep "
                        "(e.g. 'marschner-lobb 256,MNI152')")
    parser.add_argument("--sizes", help="comma-separated image sizes, e.g. 1024x768")
    parser.add_argument("--stem", help="name of the result files (default compare[_quick])")
    parser.add_argument("--memory-worker", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.memory_worker:
        job = json.loads(args.memory_worker)
        M.vtk_status()  # picks the working offscreen window class for this process
        print(json.dumps(runner.memory_worker(
            job["data_path"], job["meta"], job["kind"], job["key"], tuple(job["size"]),
            job["mode"], job["step"])))
        return 0
    sizes = None
    if args.sizes:
        try:
            sizes = [tuple(int(v) for v in part.split("x")) for part in args.sizes.split(",")]
        except ValueError:
            parser.error(f"--sizes must look like 1024x768,512x512, got {args.sizes!r}")
    run(args.quick, args.repeats, Path(args.out), memory=not args.no_memory,
        volume_modes=not args.no_volume, only_volume=args.only_volume,
        scenes_only=args.scenes.split(",") if args.scenes else None, sizes_only=sizes,
        stem=args.stem, only_dense=args.only_dense)
    return 0


if __name__ == "__main__":
    sys.exit(main())
