"""Cold starts: how long a user waits for the first picture of each command, from an empty
kernel cache.

Every run is a fresh process with a fresh, empty kernel cache folder (``NUMBA_CACHE_DIR``), so
what is measured is what a user meets on the first use of a model, mode and voxel type after
installing: Python and splinecast importing, the data read, the kernels compiled, the image
written. After each cold run the same command runs again on the cache it filled (the *warm*
time: every later use). Times are wall times of the whole process, the median of ``--repeats``
runs.

Parts (``--parts``, comma-separated):

``readme``
    The command of ``make demo`` and the README's first examples.
``table``
    A small volume (Marschner-Lobb 48^3, 128x96 image) and the MNI152 MRI (when present) in
    the default mode and model, then one further mode or model at a time: what trying the
    options of the README costs on first use.
``viewer``
    Every model x mode the viewer's selectors offer, each the first render of that pair in a
    fresh cache (what a switch in the viewer prepares before its first frame).

    python benchmarks/bench_cold_start.py [--parts readme,table,viewer] [--repeats 3]
        [--only TEXT] [--stem NAME]

Results go to ``benchmarks/results/cold_start.{md,json}`` (``--stem``) with the machine.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _machine import MRI, write_results  # noqa: E402

SMALL = "demo:marschner-lobb?size=48"
SMALL_OPTIONS = ["--iso", "0.5", "--size", "128x96", "--quiet"]

#: Models and modes of the viewer's selectors (``hello.models``, ``hello.modes``).
VIEWER_MODELS = ("trilinear", "bspline1", "bspline2", "bspline3", "s31", "qss")
VIEWER_MODES = ("iso", "mip", "minip", "dvr")

#: One render of a model and mode, as the viewer's first full frame of them: 128x96 of the small
#: volume with the viewer's defaults.
_VIEWER_FIRST_FRAME = """
import sys
import splinecast as sc
model, mode = sys.argv[1], sys.argv[2]
vol = sc.demo("marschner-lobb", size=48)
cam = sc.Camera.orbit(vol, size=(128, 96))
sc.Scene(vol, model=model).render(cam, mode=mode, outputs=("rgba",))
"""


def _cli(*args: str) -> list[str]:
    """The ``splinecast`` command a user types (the entry point installed beside Python)."""
    return [str(Path(sys.executable).with_name("splinecast")), *args]


def cases(parts: set[str], out: Path) -> list[tuple[str, str, list[str]]]:
    """(part, label, command) of every case of ``parts``; outputs go under ``out``."""
    png = str(out / "out.png")
    found: list[tuple[str, str, list[str]]] = []
    if "readme" in parts:
        found.append(("readme", "make demo's render (ML 128^3, 768x768)", _cli(
            "render", "demo:marschner-lobb?size=128", "--iso", "0.5", "--size", "768x768",
            "--azimuth", "30", "--elevation", "25", "--quiet", "-o", png)))
    if "table" in parts:
        small = [*SMALL_OPTIONS, "-o", png]
        found += [
            ("table", "ML 48^3 iso (trilinear)", _cli("render", SMALL, *small)),
            ("table", "ML 48^3 --mode mip", _cli("render", SMALL, "--mode", "mip", *small[2:])),
            ("table", "ML 48^3 --mode dvr", _cli("render", SMALL, "--mode", "dvr", *small[2:])),
            ("table", "ML 48^3 --model s31", _cli("render", SMALL, "--model", "s31", *small)),
            ("table", "ML 48^3 --model bspline3", _cli("render", SMALL, "--model", "bspline3",
                                                       *small)),
            ("table", "ML 48^3 --model s31 --mode dvr", _cli(
                "render", SMALL, "--model", "s31", "--mode", "dvr", *small[2:])),
        ]
        if MRI.exists():
            found.append(("table", "MNI T1 NIfTI, no options (uint8)", _cli(
                "render", str(MRI), "--size", "128x96", "--quiet", "-o", png)))
    if "viewer" in parts:
        for model in VIEWER_MODELS:
            for mode in VIEWER_MODES:
                found.append(("viewer", f"{model} / {mode}", [
                    sys.executable, "-c", _VIEWER_FIRST_FRAME, model, mode]))
    return found


def _run(command: list[str], cache: Path) -> tuple[float, str]:
    """Wall time of one process with ``cache`` as its kernel cache, and its error if it
    failed."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    start = time.perf_counter()
    proc = subprocess.run(command, env=env, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    error = "" if proc.returncode == 0 else (proc.stderr.strip().splitlines() or ["?"])[-1]
    return seconds, error


def measure(command: list[str], repeats: int) -> dict[str, object]:
    """Median cold and warm wall times of ``command`` over ``repeats`` fresh caches."""
    cold, warm, errors = [], [], []
    for _ in range(repeats):
        cache = Path(tempfile.mkdtemp(prefix="splinecast-cold-"))
        try:
            seconds, error = _run(command, cache)
            cold.append(seconds)
            errors.append(error)
            seconds, error = _run(command, cache)
            warm.append(seconds)
            errors.append(error)
        finally:
            shutil.rmtree(cache, ignore_errors=True)
    return {"cold_s": statistics.median(cold), "warm_s": statistics.median(warm),
            "cold_runs_s": cold, "warm_runs_s": warm,
            "error": next((e for e in errors if e), "")}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--parts", default="readme,table,viewer",
                        help="comma-separated: readme, table, viewer")
    parser.add_argument("--repeats", type=int, default=3, help="fresh caches per case")
    parser.add_argument("--only", help="keep the cases whose label contains this text")
    parser.add_argument("--stem", default="cold_start", help="result file name")
    args = parser.parse_args(argv)
    parts = {p.strip() for p in args.parts.split(",") if p.strip()}
    rows = []
    with tempfile.TemporaryDirectory() as out:
        for part, label, command in cases(parts, Path(out)):
            if args.only and args.only not in label:
                continue
            row = {"part": part, "case": label, **measure(command, args.repeats)}
            rows.append(row)
            print(f"{part:7s} {label:40s} cold {row['cold_s']:6.1f} s  warm "
                  f"{row['warm_s']:5.2f} s  {row['error']}", flush=True)
    path = HERE / "results" / args.stem
    write_results(
        path, "Cold starts",
        f"Wall time of each command in a fresh process with an empty kernel cache (cold) and "
        f"again on the cache it filled (warm), median of {args.repeats} runs "
        f"(`python benchmarks/bench_cold_start.py --parts {args.parts} --repeats "
        f"{args.repeats}`).",
        ["part", "case", "cold (s)", "warm (s)", "error"], rows,
        lambda r: [r["part"], r["case"], f"{r['cold_s']:.1f}", f"{r['warm_s']:.2f}",
                   r["error"] or ""])
    print(f"wrote {path}.md")
    return 0 if all(not r["error"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
