"""Where a traced ray's time goes, phase by phase: cycle counts from an instrumented pixel loop.

The instruction-level profile (``profile_kernel.py``) says which machine code is hot, but the
band is one large function and its hot windows are hard to read against the source. This tool
asks the question in the source's own terms. It copies the driver's per-ray function
(:func:`splinecast.render.driver._trace_pixel`), inserts reads of the CPU's time-stamp counter
(LLVM's ``readcyclecounter``) around its phases, compiles that copy into the scene's (model,
mode) band in place of the real one (not cached) and renders one frame with the per-ray
counters. The three counter buffers then hold cycles instead of counts, in two passes:

* pass A: cycles in runs of leaps over blocks, in tested cells (building and consuming their
  pieces), and the whole ray;
* pass B: cycles in the ray's set-up (its generation, clipping and the mode's ``ray_begin``;
  for a ray that misses the grid, everything before its ``finish``), in the mode's
  ``finish``, and the whole ray.

The rest of a ray, whole minus the four phases, is the walk from cell to cell: each visited
cell's step, load and range test (a tested cell's as well), and the loop's own bookkeeping.
Rays are split into those that produced a result (a hit, a maximum, some opacity) and those
traced without one; the events per ray (cells visited, cells tested, blocks leapt) come from
a frame of the real kernel.

Each counter read costs about 20 cycles and orders the instructions around it, so the
instrumented frame is slower than the real one (both are reported); the counts are for
comparing phases, not for adding up to the frame time. The time-stamp counter's rate is
measured against the wall clock. Example (one thread: the counts are per ray anyway)::

    NUMBA_NUM_THREADS=1 python benchmarks/tools/cycle_breakdown.py \\
        --scene "sphere SDF 128^3" --mode iso
"""

from __future__ import annotations

import argparse
import functools
import inspect
import json
import re
import sys
import textwrap
import time
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))
sys.path.insert(0, str(REPO / "benchmarks" / "tools"))
from _kernel_args import MODE_CLASSES, add_scene_arguments  # noqa: E402

#: Text inserted into ``_trace_pixel``'s source: (anchor, text, where), ``where`` being
#: "before" or "after" the anchor. Each anchor must occur exactly once.
_PROBES = (
    ("    t0, t1, ray = grid_ray(",
     "    _c0 = _rdtsc()\n    _leap = 0\n    _test = 0\n    _setup = 0\n", "before"),
    ("        open_i = open_j = open_k = -1\n", "        _setup = _rdtsc() - _c0\n", "before"),
    ("                size = skip_size(mode, blocks, ci, cj, ck, st)\n                # Leaps",
     "                _ca = _rdtsc()\n", "before"),
    ("                if not inside:\n                    break\n                open_i, open_j",
     "                _leap += _rdtsc() - _ca\n", "before"),
    ("                    tested += 1\n", "                    _cb = _rdtsc()\n", "after"),
    ("                    if asks_again(mode):\n                        open_i = -1\n",
     "                    _test += _rdtsc() - _cb\n", "after"),
)

#: The function's end, replaced so it returns the pass's cycle counts.
_END = ("    if final:\n        finish(mode, out, row, col, st, ray)\n"
        "    return visited, tested, skipped\n")
_NEW_END = ("    _cf = _rdtsc()\n    if _setup == 0:\n        _setup = _cf - _c0\n"
            "    if final:\n        finish(mode, out, row, col, st, ray)\n"
            "    _finish = _rdtsc() - _cf\n    return {slots}\n")

#: What each pass's three counter buffers hold.
PASSES = {"A": ("leaps", "tests", "whole"), "B": ("setup", "finish", "whole")}
_SLOTS = {"A": "_leap, _test, _rdtsc() - _c0", "B": "_setup, _finish, _rdtsc() - _c0"}


def instrumented_source(source: str, pass_name: str) -> str:
    """``_trace_pixel``'s source with the counter reads of pass ``pass_name`` ("A" or "B").

    Raises ``ValueError`` naming the anchor when the driver's source no longer has it once.
    """
    for anchor, text, where in _PROBES:
        if source.count(anchor) != 1:
            raise ValueError(f"cycle_breakdown: anchor not found once in _trace_pixel: "
                             f"{anchor.strip()[:60]!r}")
        source = source.replace(anchor, text + anchor if where == "before" else anchor + text)
    if source.count(_END) != 1:
        raise ValueError("cycle_breakdown: _trace_pixel's end (finish, return) not found once")
    return source.replace(_END, _NEW_END.format(slots=_SLOTS[pass_name]))


def _rdtsc_intrinsic() -> Any:
    """A Numba intrinsic returning LLVM's ``readcyclecounter`` (the time-stamp counter)."""
    from llvmlite import ir
    from numba.core import cgutils, types
    from numba.core.extending import intrinsic

    @intrinsic
    def rdtsc(typingctx):
        def codegen(context, builder, signature, args):
            fnty = ir.FunctionType(ir.IntType(64), [])
            fn = cgutils.get_or_insert_function(builder.module, fnty, "llvm.readcyclecounter")
            return builder.call(fn, [])

        return types.int64(), codegen

    return rdtsc


def install_instrumented_band(grid_class: type, mode_class: type, pass_name: str) -> None:
    """Compile the (model, mode) band with pass ``pass_name``'s instrumented pixel loop and
    make the renderer use it (:func:`splinecast.render.driver.pair_band`'s table)."""
    from splinecast._jit import jit, rebound
    from splinecast.render import driver, mode_api

    if mode_api.sampled_of(mode_class):
        raise SystemExit("cycle_breakdown: sampled modes run the fixed-step loop, which this "
                         "tool does not instrument")
    source = textwrap.dedent(inspect.getsource(driver._trace_pixel.py_func))
    # Not cached: the copy's code has no source file, and it must never replace the real band.
    namespace = {**vars(driver), "_rdtsc": _rdtsc_intrinsic(),
                 "jit": functools.partial(jit, cache=False)}
    exec(compile(instrumented_source(source, pass_name), "<cycle_breakdown>", "exec"),
         namespace)
    bind = driver.pair_bindings(grid_class, mode_class)
    suffix = f"{grid_class.__name__}_{mode_class.__name__}_cycles{pass_name}"
    pixel = rebound(namespace["_trace_pixel"], bind, suffix, cache=False)
    band = rebound(driver._trace_band, {**bind, "_trace_pixel": pixel}, suffix, cache=False)
    driver._KERNELS[(grid_class, mode_class)] = band


def _produced(frame: Any, mode: str) -> np.ndarray:
    """Pixels whose ray produced a result: a hit, a maximum, some opacity."""
    if mode == "iso":
        return np.isfinite(frame.depth)
    if mode == "mip":
        return np.isfinite(frame.value)
    return frame.rgba[..., 3] > 0.0


def _counter_rate() -> float:
    """Time-stamp counter ticks per nanosecond, against the wall clock."""
    from numba import njit

    rdtsc = _rdtsc_intrinsic()

    @njit
    def read():
        return rdtsc()

    read()
    t0, c0 = time.perf_counter_ns(), read()
    time.sleep(0.2)
    t1, c1 = time.perf_counter_ns(), read()
    return (c1 - c0) / (t1 - t0)


def _read_cost() -> float:
    """Cycles between two consecutive counter reads (the cost of one probe)."""
    from numba import njit

    rdtsc = _rdtsc_intrinsic()

    @njit
    def pairs(n):
        total = 0
        for _ in range(n):
            a = rdtsc()
            total += rdtsc() - a
        return total

    pairs(10)
    return pairs(1_000_000) / 1_000_000


def summarize(counts: dict[str, np.ndarray], cycles: dict[str, dict[str, np.ndarray]],
              groups: dict[str, np.ndarray]) -> dict[str, dict[str, float]]:
    """Mean events and cycles per ray of each group of pixels.

    ``counts``: the real kernel's per-pixel ``visited``, ``tested``, ``leapt``; ``cycles``: per
    pass, its three buffers by :data:`PASSES` name; ``groups``: masks of the pixels to average.
    The ``rest`` is pass A's whole minus leaps and tests minus pass B's set-up and finish.
    """
    out = {}
    for name, mask in groups.items():
        n = int(mask.sum())
        if n == 0:
            continue
        mean = {k: float(v[mask].astype(np.float64).mean()) for k, v in counts.items()}
        for pass_name, buffers in cycles.items():
            for k, v in buffers.items():
                mean[f"{k}_{pass_name}" if k == "whole" else k] = float(
                    v[mask].astype(np.float64).mean())
        mean["rest"] = (mean["whole_A"] - mean["leaps"] - mean["tests"] - mean["setup"]
                        - mean["finish"])
        out[name] = {"rays": n, **mean}
    return out


def report(summary: dict[str, dict[str, float]], info: dict[str, Any]) -> str:
    """Markdown table of :func:`summarize`'s result."""
    lines = [f"# Cycles per ray by phase: {info['scene']}, {info['mode']}, {info['model']}", "",
             f"Command: `{info['command']}`. {info['machine']}; {info['threads']} Numba "
             f"thread(s); {info['size']}. Time-stamp counter: {info['ghz']:.2f} GHz; one probe "
             f"(two counter reads) costs {info['probe']:.0f} cycles and is included in the "
             f"phases. Frame: {info['frame_ms']:.1f} ms with the real kernel, "
             f"{info['frame_a_ms']:.1f} / {info['frame_b_ms']:.1f} ms instrumented (passes A / "
             "B).", "",
             "| rays | count | visited | tested | leapt | set-up | leaps | tests | finish | "
             "rest (cell steps and loads, loop) | whole (A / B) | per leap | per test | "
             "rest per cell visited |", "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]

    def per(a: float, b: float) -> str:
        return f"{a / b:.0f}" if b > 0.05 else "-"

    for name, m in summary.items():
        lines.append(
            f"| {name} | {m['rays']} | {m['visited']:.2f} | {m['tested']:.2f} | "
            f"{m['leapt']:.2f} | {m['setup']:.0f} | {m['leaps']:.0f} | {m['tests']:.0f} | "
            f"{m['finish']:.0f} | {m['rest']:.0f} | {m['whole_A']:.0f} / {m['whole_B']:.0f} | "
            f"{per(m['leaps'], m['leapt'])} | {per(m['tests'], m['tested'])} | "
            f"{per(m['rest'], m['visited'])} |")
    lines += ["", "Cycles are means over the rays of the row; events (visited, tested, leapt) "
              "are means of the real kernel's counters over the same rays. The rest holds each "
              "visited cell's walk step, load and range test (a tested cell's too: the tests "
              "column starts after them), so it is divided by all cells visited."]
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_scene_arguments(parser)
    parser.add_argument("--dvr-sampling", default="grid",
                        help="DVR's sampling ('grid' or 'pieces': the cell walk; 'ray' is "
                             "not instrumented)")
    parser.add_argument("--out", default=None,
                        help="output stem (default: benchmarks/results/cycles_<mode>_<scene>)")
    args = parser.parse_args()

    import numba

    import splinecast as sc
    from benchmarks._machine import describe
    from benchmarks.compare.runner import _camera
    from benchmarks.compare.scenes import by_label
    from splinecast.render import driver

    spec = by_label(args.scene)
    vol = spec.make()
    scene = sc.Scene(vol, model=args.model)
    if args.mode == "iso":
        kwargs: dict[str, Any] = {"iso": spec.isos[0]}
    elif args.mode == "dvr":
        kwargs = {"mode": "dvr", "dvr": sc.DVRSettings(sampling=args.dvr_sampling)}
    else:
        kwargs = {"mode": args.mode}
    size = tuple(int(v) for v in args.size.split("x"))
    cam = _camera(vol, size, 40.0)

    def timed() -> tuple[Any, float]:
        scene.render(cam, **kwargs)
        start = time.perf_counter()
        frame = scene.render(cam, **kwargs)
        return frame, (time.perf_counter() - start) * 1e3

    real, frame_ms = timed()
    counts = {"visited": real.cells_visited, "tested": real.cells_tested,
              "leapt": real.blocks_skipped}
    wanted = MODE_CLASSES[args.mode]
    key = next(k for k in driver._KERNELS if k[1].__name__ == wanted)
    cycles, frame_pass_ms = {}, {}
    for pass_name, names in PASSES.items():
        install_instrumented_band(*key, pass_name)
        frame, frame_pass_ms[pass_name] = timed()
        cycles[pass_name] = dict(zip(names, (frame.cells_visited, frame.cells_tested,
                                             frame.blocks_skipped), strict=True))
    traced = cycles["A"]["whole"] > 0
    produced = _produced(real, args.mode)
    summary = summarize(counts, cycles, {"with a result": traced & produced,
                                         "without": traced & ~produced, "all traced": traced})
    slug = re.sub(r"[^a-z0-9]+", "_", args.scene.lower()).strip("_")
    out = Path(args.out or REPO / "benchmarks" / "results" / f"cycles_{args.mode}_{slug}")
    command = " ".join(["python benchmarks/tools/cycle_breakdown.py", f'--scene "{args.scene}"',
                        f"--mode {args.mode}", f"--model {args.model}", f"--size {args.size}"])
    info = {"scene": args.scene, "mode": args.mode, "model": args.model, "size": args.size,
            "command": command, "machine": describe()["cpu"], "threads": numba.get_num_threads(),
            "ghz": _counter_rate(), "probe": _read_cost(), "frame_ms": frame_ms,
            "frame_a_ms": frame_pass_ms["A"], "frame_b_ms": frame_pass_ms["B"]}
    out.parent.mkdir(parents=True, exist_ok=True)
    Path(f"{out}.md").write_text(report(summary, info))
    Path(f"{out}.json").write_text(json.dumps({"info": info, "summary": summary}, indent=1))
    print(report(summary, info))
    print(f"wrote {out}.md and {out}.json")


if __name__ == "__main__":
    main()
