"""Several processes compiling the same kernel at once, from one empty Numba cache, two builds.

The case of ``splinecast movie --workers N``, Dask workers on one machine or several viewers:
``--processes`` fresh processes share one empty ``NUMBA_CACHE_DIR`` and start together; each
imports splinecast, renders a trilinear isosurface of the demo sphere (32^3, 32x32 pixels) and
reports its first render's wall time. The result is the wall time until all have finished, per
build (``--old``: another checkout, e.g. ``git worktree add --detach /tmp/old <commit>``); the
builds run one after the other.

    python benchmarks/tools/bench_compile_processes.py --old /tmp/old --processes 4
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]

_CHILD = """
import time
import splinecast as sc
vol = sc.demo("sphere", size=32)
cam = sc.Camera.orbit(vol, azimuth=30.0, elevation=25.0, size=(32, 32))
t = time.perf_counter()
sc.Scene(vol, model="trilinear").render(cam, mode="iso", iso=0.0, outputs=("rgba",))
print(time.perf_counter() - t)
"""


def run(checkout: Path, processes: int) -> tuple[float, list[float]]:
    """Wall time for all processes and each one's first render (seconds)."""
    with tempfile.TemporaryDirectory(prefix="compile-processes-") as cache:
        env = dict(os.environ, PYTHONPATH=str(checkout / "src"), NUMBA_CACHE_DIR=cache)
        start = time.perf_counter()
        procs = [subprocess.Popen([sys.executable, "-c", _CHILD], env=env, text=True,
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE)
                 for _ in range(processes)]
        firsts = []
        for p in procs:
            out, err = p.communicate()
            if p.returncode != 0:
                raise SystemExit(f"a child process failed:\n{err[-2000:]}")
            firsts.append(float(out.strip().splitlines()[-1]))
        return time.perf_counter() - start, firsts


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--old", type=Path, help="another checkout to time first")
    parser.add_argument("--processes", type=int, default=4)
    args = parser.parse_args()
    builds = ([("old", args.old)] if args.old else []) + [("this", REPO)]
    for name, checkout in builds:
        wall, firsts = run(checkout, args.processes)
        print(f"{name:5s} {checkout}: {args.processes} processes, wall {wall:.1f} s, first "
              f"renders {', '.join(f'{f:.1f}' for f in firsts)} s")


if __name__ == "__main__":
    main()
