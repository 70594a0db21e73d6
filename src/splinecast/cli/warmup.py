"""``splinecast warmup``: compile the kernels of chosen models, modes and voxel types ahead of use.

Every kernel is compiled on its first use and then cached on disk, so the first render of a new
model, mode or voxel type waits for a compile (seconds to a minute) and every later one starts at
once. ``warmup`` pays that wait now, for many combinations at once and on every core (one worker
process per core: Numba compiles on one thread), so that nobody waits later: run it once after
installing, when building a container image, or on a cluster's shared file system before the
Dask workers start. A combination already cached costs a fraction of a second.

Each combination is rendered on a tiny volume of the voxel type: the kernels depend on the types
of the data and of the mode's parameters, not on the sizes or values. ``--pyramids`` also renders
a small pyramid drawn from bricks (the kernels of OME-Zarr stores). Two processes compiling the
same kernel at once (another ``warmup``, a render) wait for each other instead of compiling it
twice.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

import splinecast as sc
from splinecast.errors import ParameterError
from splinecast.render.modes import MODE_NAMES, mode_class

__all__ = ["add_parser", "run", "Combination", "warm_combination", "combinations"]

#: The voxel types ``--dtypes`` accepts (what the readers produce).
DTYPES = ("float32", "float64", "uint8", "int8", "uint16", "int16", "int32", "uint32")


@dataclass(frozen=True)
class Combination:
    """One model, mode and voxel type to compile; ``pyramid`` for the bricks' kernels."""

    model: str
    mode: str
    dtype: str
    pyramid: str | None = None  # a small pyramid of this voxel type (its path)

    def __str__(self) -> str:
        where = ", pyramid" if self.pyramid else ""
        return f"{self.model} / {self.mode}, {self.dtype}{where}"


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    warm = sub.add_parser(
        "warmup", help="compile the kernels of models and modes now, so no later run waits",
        description=__doc__.splitlines()[0])
    warm.add_argument("--models", default="all",
                      help=f"comma-separated models, or all (default: {', '.join(sc.MODELS)})")
    warm.add_argument("--modes", default="all",
                      help=f"comma-separated modes, or all (default: {', '.join(MODE_NAMES)}; "
                           "iso includes several isovalues)")
    warm.add_argument("--dtypes", default="float32",
                      help="comma-separated voxel types of your data (default float32; 8- and "
                           "16-bit integers share the float32 kernels of trilinear and B-spline "
                           f"models); one of {', '.join(DTYPES)}")
    warm.add_argument("--pyramids", action="store_true",
                      help="also the kernels of pyramids drawn from bricks (OME-Zarr stores)")
    warm.add_argument("--jobs", type=int, default=os.cpu_count() or 1,
                      help="worker processes (default: one per core)")
    warm.add_argument("--quiet", action="store_true", help="print nothing")


def _names(text: str, known: tuple[str, ...] | list[str], option: str) -> list[str]:
    """The comma-separated names of ``text`` (``all``: every known name), checked."""
    if text.strip() == "all":
        return list(known)
    names = [t.strip() for t in text.split(",") if t.strip()]
    unknown = [n for n in names if n not in known]
    if unknown or not names:
        raise ParameterError(f"{option}: {', '.join(unknown) or 'nothing'} is not one of "
                             f"{', '.join(known)} (or all)")
    return list(dict.fromkeys(names))


def combinations(models: list[str], modes: list[str], dtypes: list[str],
                 pyramids: dict[str, str] | None = None) -> list[Combination]:
    """Every combination to warm, the in-memory ones first (what users meet first), each
    model's modes together."""
    out = [Combination(m, mode, d) for d in dtypes for m in models for mode in modes]
    if pyramids:
        out += [Combination(m, mode, d, pyramids[d]) for d in dtypes for m in models
                for mode in modes]
    return out


def tiny_volume(dtype: str, size: int = 6) -> sc.Volume:
    """A ``size``^3 volume of ``dtype`` spanning a typical range of values of that type."""
    kind = np.dtype(dtype)
    hi = 1.0 if kind.kind == "f" else float(min(np.iinfo(kind).max, 4095))
    values = np.linspace(0.0, hi, size ** 3).reshape(size, size, size)
    if kind.kind != "f":
        values = np.round(values)
    return sc.Volume(values.astype(kind), spacing=(1.0, 1.0, 1.0))


def _render_options(mode: str, volume: Any) -> list[dict[str, Any]]:
    """The renders that compile a mode's kernels: the defaults, and for isosurfaces also
    several isovalues (a kernel of its own)."""
    if "iso" not in mode_class(mode).keywords:
        return [{"mode": mode}]
    lo, hi = volume.value_range
    return [{"mode": mode}, {"mode": mode, "iso": [lo + (hi - lo) / 3, lo + 2 * (hi - lo) / 3]}]


def warm_combination(combination: Combination) -> tuple[Combination, float, float]:
    """Render ``combination`` once (compiling or loading its kernels); returns it with the
    seconds spent compiling and in all. Runs in a worker process."""
    from splinecast._jit import reporting_compiles

    compiled = [0.0]
    start = time.perf_counter()
    with reporting_compiles(lambda name: None,
                            lambda name, seconds: compiled.__setitem__(0, compiled[0] + seconds)):
        if combination.pyramid is None:
            volume: Any = tiny_volume(combination.dtype)
            scene: Any = sc.Scene(volume, model=combination.model)
            extra: dict[str, Any] = {}
        else:
            volume = sc.read(combination.pyramid)
            # Drawn from bricks of two levels (the kernels of seams between levels too).
            scene = sc.Scene(volume, model=combination.model, whole_level=False, lod=0.5)
            extra = {"complete": True}
        try:
            camera = sc.Camera.orbit(volume, size=(8, 8))
            for options in _render_options(combination.mode, volume):
                scene.render(camera, outputs=("rgba",), **options, **extra)
        finally:
            scene.close()
    return combination, compiled[0], time.perf_counter() - start


def _build_pyramids(dtypes: list[str], folder: Path) -> dict[str, str]:
    """A small pyramid of each voxel type (three levels of 8^3 bricks)."""
    out = {}
    for dtype in dtypes:
        path = folder / f"{dtype}.zarr"
        sc.build_pyramid(tiny_volume(dtype, size=33), path, brick=8, shard=16, progress=False)
        out[dtype] = str(path)
    return out


def run(args: argparse.Namespace) -> int:
    """Compile (or load) the kernels of every chosen combination."""
    models = _names(args.models, list(sc.MODELS), "--models")
    modes = _names(args.modes, MODE_NAMES, "--modes")
    dtypes = _names(args.dtypes, DTYPES, "--dtypes")
    if args.jobs < 1:
        raise ParameterError(f"--jobs must be at least 1, got {args.jobs}")
    say = (lambda text: None) if args.quiet else (lambda text: print(text, file=args.stderr,
                                                                        flush=True))
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="splinecast-warmup-") as folder:
        pyramids = _build_pyramids(dtypes, Path(folder)) if args.pyramids else None
        todo = combinations(models, modes, dtypes, pyramids)
        say(f"warming {len(todo)} combinations on {args.jobs} process"
            f"{'es' if args.jobs > 1 else ''} (each compiled once; cached ones load at once)")
        compiled_total = 0.0
        # Worker processes are started afresh ("spawn"): a fork of a process whose Numba
        # threading layer is running is not safe.
        context = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(max_workers=min(args.jobs, len(todo)),
                                 mp_context=context) as pool:
            futures = [pool.submit(warm_combination, c) for c in todo]
            for done, future in enumerate(as_completed(futures), 1):
                try:
                    combination, compiled, took = future.result()
                except sc.SplinecastError as exc:  # a combination the library refuses
                    say(f"[{done}/{len(todo)}] {todo[futures.index(future)]}: not available "
                        f"({exc})")
                    continue
                compiled_total += compiled
                state = f"compiled in {compiled:.0f} s" if compiled else "cached"
                say(f"[{done}/{len(todo)}] {combination}: {state} ({took:.1f} s)")
    say(f"warm: {len(todo)} combinations in {time.perf_counter() - start:.0f} s "
        f"({compiled_total:.0f} s of compiling)")
    return 0
