"""Cold starts: how long a user waits for the first picture of each command, from an empty
kernel cache.

Every run is a fresh process with a fresh, empty kernel cache folder (``NUMBA_CACHE_DIR``), so
what is measured is what a user meets on the first use of a model, mode and voxel type after
installing: Python and splinecast importing, the data read, the kernels compiled, the image
written. After each cold run the same command runs again on the cache it filled (the *warm*
time: every later use). Times are wall times of the whole process, the median of ``--repeats``
runs, and the CPU time (user + system) the process and its children used: on a machine shared
with other work the wall time grows with the load, the CPU time much less.

``--baseline PYTHON`` runs every case also with another installation's Python (for example a
virtual environment of the main before a change), alternating with this one case by case, and
reports the ratio of the cold CPU times (this / baseline) beside the two.

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
        [--only TEXT] [--stem NAME] [--baseline OTHER/.venv/bin/python]

Results go to ``benchmarks/results/cold_start.{md,json}`` (``--stem``) with the machine.
"""

from __future__ import annotations

import argparse
import os
import resource
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


def cases(parts: set[str], out: Path, python: str = sys.executable
          ) -> list[tuple[str, str, list[str]]]:
    """(part, label, command) of every case of ``parts`` run by the installation of ``python``;
    outputs go under ``out``."""
    png = str(out / "out.png")

    def _cli(*args: str) -> list[str]:
        """The ``splinecast`` command a user types (the entry point installed beside Python)."""
        return [str(Path(python).with_name("splinecast")), *args]

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
                    python, "-c", _VIEWER_FIRST_FRAME, model, mode]))
    return found


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _run(command: list[str], cache: Path) -> tuple[float, float, str]:
    """Wall and CPU time of one process with ``cache`` as its kernel cache, and its error if
    it failed."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    cpu = _children_cpu()
    start = time.perf_counter()
    proc = subprocess.run(command, env=env, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    cpu = _children_cpu() - cpu
    error = "" if proc.returncode == 0 else (proc.stderr.strip().splitlines() or ["?"])[-1]
    return seconds, cpu, error


def measure(command: list[str], repeats: int) -> dict[str, object]:
    """Median cold and warm wall and CPU times of ``command`` over ``repeats`` fresh caches."""
    runs: dict[str, list[float]] = {"cold_s": [], "cold_cpu_s": [], "warm_s": [],
                                    "warm_cpu_s": []}
    errors = []
    for _ in range(repeats):
        cache = Path(tempfile.mkdtemp(prefix="splinecast-cold-"))
        try:
            for kind in ("cold", "warm"):  # warm: the same command on the cache just filled
                seconds, cpu, error = _run(command, cache)
                runs[f"{kind}_s"].append(seconds)
                runs[f"{kind}_cpu_s"].append(cpu)
                errors.append(error)
        finally:
            shutil.rmtree(cache, ignore_errors=True)
    return {**{key: statistics.median(values) for key, values in runs.items()},
            **{key.replace("_s", "_runs_s"): values for key, values in runs.items()},
            "error": next((e for e in errors if e), "")}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--parts", default="readme,table,viewer",
                        help="comma-separated: readme, table, viewer")
    parser.add_argument("--repeats", type=int, default=3, help="fresh caches per case")
    parser.add_argument("--only", help="keep the cases whose label contains this text")
    parser.add_argument("--stem", default="cold_start", help="result file name")
    parser.add_argument("--baseline", help="another installation's Python, run side by side")
    args = parser.parse_args(argv)
    parts = {p.strip() for p in args.parts.split(",") if p.strip()}
    rows = []
    with tempfile.TemporaryDirectory() as out:
        ours = cases(parts, Path(out))
        theirs = cases(parts, Path(out), args.baseline) if args.baseline else [None] * len(ours)
        for (part, label, command), other in zip(ours, theirs, strict=True):
            if args.only and args.only not in label:
                continue
            row = {"part": part, "case": label, **measure(command, args.repeats)}
            line = (f"{part:7s} {label:40s} cold {row['cold_s']:6.1f} s ({row['cold_cpu_s']:5.1f}"
                    f" s CPU)  warm {row['warm_s']:5.2f} s")
            if other is not None:
                base = measure(other[2], args.repeats)
                row["baseline"] = base
                row["cpu_ratio"] = row["cold_cpu_s"] / base["cold_cpu_s"]
                line += (f"  baseline cold {base['cold_s']:6.1f} s ({base['cold_cpu_s']:5.1f} s"
                         f" CPU)  ratio {row['cpu_ratio']:.2f}")
            rows.append(row)
            print(f"{line}  {row['error']}", flush=True)
    path = HERE / "results" / args.stem
    columns = ["part", "case", "cold (s)", "cold CPU (s)", "warm (s)", "warm CPU (s)"]
    if args.baseline:
        columns += ["baseline cold (s)", "baseline cold CPU (s)", "cold CPU ratio"]

    def cells(r: dict) -> list[str]:
        found = [r["part"], r["case"], f"{r['cold_s']:.1f}", f"{r['cold_cpu_s']:.1f}",
                 f"{r['warm_s']:.2f}", f"{r['warm_cpu_s']:.2f}"]
        if args.baseline:
            found += [f"{r['baseline']['cold_s']:.1f}", f"{r['baseline']['cold_cpu_s']:.1f}",
                      f"{r['cpu_ratio']:.2f}"]
        return [*found, r["error"] or ""]

    write_results(
        path, "Cold starts",
        f"Wall and CPU time of each command in a fresh process with an empty kernel cache "
        f"(cold) and again on the cache it filled (warm), median of {args.repeats} runs "
        f"(`python benchmarks/bench_cold_start.py --parts {args.parts} --repeats "
        f"{args.repeats}" + (" --baseline BASELINE_PYTHON" if args.baseline else "") + "`)."
        + (" The baseline is the installation before the change, run alternately with this one"
           " case by case; the ratio is of the cold CPU times (this / baseline)."
           if args.baseline else ""),
        [*columns, "error"], rows, cells)
    print(f"wrote {path}.md")
    return 0 if all(not r["error"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
