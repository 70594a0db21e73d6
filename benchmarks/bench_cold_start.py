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
``sequence``
    What a new user meets trying the README in order: ``make demo``'s render, then the MRI, MIP,
    DVR, ``s31`` and ``bspline3``, all on one kernel cache (emptied once per repeat), each
    command's time given the ones before it: the wait for each further model, mode and voxel
    type after the demo.
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
    if "sequence" in parts:
        mri = [str(MRI)] if MRI.exists() else [SMALL, "--iso", "0.5"]
        quiet = ["--size", "128x96", "--quiet", "-o", png]
        found += [
            ("sequence", "1. make demo's render", _cli(
                "render", "demo:marschner-lobb?size=128", "--iso", "0.5", "--size", "768x768",
                "--azimuth", "30", "--elevation", "25", "--quiet", "-o", png)),
            ("sequence", "2. then the MRI, no options", _cli("render", *mri, *quiet)),
            ("sequence", "3. then the MRI --mode mip", _cli("render", *mri[:1], "--mode", "mip",
                                                          *quiet)),
            ("sequence", "4. then the MRI --mode dvr", _cli("render", *mri[:1], "--mode", "dvr",
                                                          *quiet)),
            ("sequence", "5. then ML 48^3 --model s31", _cli("render", SMALL, "--model", "s31",
                                                           *SMALL_OPTIONS, "-o", png)),
            ("sequence", "6. then ML 48^3 --model bspline3", _cli(
                "render", SMALL, "--model", "bspline3", *SMALL_OPTIONS, "-o", png)),
        ]
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


def measure_sequence(commands: list[list[str]], repeats: int) -> list[dict[str, object]]:
    """Median wall and CPU time of each of ``commands`` run in order on one kernel cache (a
    fresh one per repeat): each command's cold time given the kernels of those before it."""
    runs = [{"cold_s": [], "cold_cpu_s": []} for _ in commands]
    errors: list[list[str]] = [[] for _ in commands]
    for _ in range(repeats):
        cache = Path(tempfile.mkdtemp(prefix="splinecast-cold-"))
        try:
            for i, command in enumerate(commands):
                seconds, cpu, error = _run(command, cache)
                runs[i]["cold_s"].append(seconds)
                runs[i]["cold_cpu_s"].append(cpu)
                errors[i].append(error)
        finally:
            shutil.rmtree(cache, ignore_errors=True)
    return [{**{key: statistics.median(values) for key, values in run.items()},
             **{key.replace("_s", "_runs_s"): values for key, values in run.items()},
             "warm_s": float("nan"), "warm_cpu_s": float("nan"),
             "error": next((e for e in errs if e), "")} for run, errs in zip(runs, errors,
                                                                             strict=True)]


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
    parser.add_argument("--parts", default="readme,table,sequence,viewer",
                        help="comma-separated: readme, table, sequence, viewer")
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
        # The sequence's commands run together, so each row knows the ones before it.
        in_order = [i for i, c in enumerate(ours) if c[0] == "sequence"]
        sequence: dict[int, dict] = {}
        if in_order:
            results = measure_sequence([ours[i][2] for i in in_order], args.repeats)
            base = (measure_sequence([theirs[i][2] for i in in_order], args.repeats)
                    if args.baseline else [None] * len(in_order))
            sequence = {i: {"ours": r, "base": b}
                        for i, r, b in zip(in_order, results, base, strict=True)}
        for n, ((part, label, command), other) in enumerate(zip(ours, theirs, strict=True)):
            if args.only and args.only not in label:
                continue
            ran = sequence.get(n)
            row = {"part": part, "case": label,
                   **(ran["ours"] if ran else measure(command, args.repeats))}
            line = (f"{part:7s} {label:40s} cold {row['cold_s']:6.1f} s ({row['cold_cpu_s']:5.1f}"
                    f" s CPU)  warm {row['warm_s']:5.2f} s")
            if other is not None:
                base = ran["base"] if ran else measure(other[2], args.repeats)
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
        + (" The baseline is the installation before the change, run in the same process: case"
           " by case, the sequence after this one's; the ratio is of the cold CPU times (this /"
           " baseline)."
           if args.baseline else ""),
        [*columns, "error"], rows, cells)
    print(f"wrote {path}.md")
    return 0 if all(not r["error"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
