"""Where a sampled ray's time goes, phase by phase: the fixed-step loop's cycle counts.

The fixed-step loop (:func:`splinecast.render.sampler.sample_pixel`, DVR's default
``sampling="ray"``) is what ``cycle_breakdown.py`` does not instrument. This tool copies it,
inserts reads of the CPU's time-stamp counter around one phase per pass, compiles the copy into
the scene's (model, DVR) band (not cached) and renders one frame; the band's three per-ray
counters then hold cycles (the phase's, the whole ray's, and the samples evaluated). Phases:

* ``skip``: from the top of a loop round to the value reads: the sample's cell, the block
  hierarchy's question (``skip_size``), leaps over blocks and the test of the segment between
  two leapt blocks;
* ``values``: the model's value reads of a round (the front sample's after a leap, the back
  sample's, the look-ahead);
* ``segment``: the mode's segment (classification: the table lookup; compositing) and its
  termination test.

One pass per phase, so a probe (two counter reads, about 20-40 cycles, which also order the
instructions around them) distorts only the phase it measures; each pass reports the whole ray
too, and the rest (ray set-up, the loop's own bookkeeping, what the probes cost the others) is
the whole less the three phases. The three passes share one compiled band (about 25 s of
compile each otherwise): every probe is guarded by a test of the pass's number, read once per
ray, so a probe of another pass costs a predicted branch. Counts are for comparing phases, not
for adding up to a frame time exactly. The events (segments, samples, leaps) come from a frame
of the real kernel.

    NUMBA_NUM_THREADS=1 python benchmarks/tools/sample_breakdown.py \\
        --scene "MNI152 T1 MRI 197x233x189" [--tf auto|suite] [--size 1024x768]
"""

from __future__ import annotations

import argparse
import functools
import inspect
import json
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
from cycle_breakdown import _counter_rate, _rdtsc_intrinsic, _read_cost  # noqa: E402

#: Probes of each pass: (anchor, text, where). ``_ph`` accumulates the phase's cycles; the
#: anchors span two lines where one would also match inside the run loop (deeper indentation).
_START = ("    t0, t1, ray = grid_ray(", "    _c0 = _rdtsc()\n    _ph = 0\n", "before")
_S16, _S20, _S24, _S28, _S32 = (" " * n for n in (16, 20, 24, 28, 32))
_PASSES: dict[str, tuple] = {
    "skip": (
        ("            open_i = open_j = open_k = -1\n            while True:\n",
         _S16 + "_cs = _rdtsc()\n", "after"),
        (_S32 + "ta = tb\n" + _S32 + "known = False\n" + _S32 + "m += 1.0\n" + _S32
         + "continue\n", _S32 + "_ph += _rdtsc() - _cs\n", "before"),
        (_S16 + "if not known:\n" + _S20 + "va = value_at(", _S16 + "_ph += _rdtsc() - _cs\n",
         "before"),
        # The run loop's block test (a run's last one, which ends it, is left out).
        (_S24 + "ci, cj, ck = _cells(ox, oy, oz, dx, dy, dz, ta, ncx, ncy, ncz)\n" + _S24
         + "if (ci >> shift) != open_i", _S24 + "_cs = _rdtsc()\n", "before"),
        (_S24 + "bx, by, bz = ox + tb * dx, oy + tb * dy, oz + tb * dz\n" + _S24
         + "if ahead_m == m:", _S24 + "_ph += _rdtsc() - _cs\n", "before"),
    ),
    "values": (
        (_S16 + "if not known:\n" + _S20 + "va = value_at(", _S16 + "_cv = _rdtsc()\n",
         "before"),
        (_S16 + "if _LOOK_AHEAD and size == 0 and cache and ahead_of_model and tb < t_far:\n",
         _S16 + "_ph += _rdtsc() - _cv\n",
         "before"),
        (_S20 + "stop = False\n", _S20 + "_cv = _rdtsc()\n", "before"),
        (_S20 + "while True:\n" + _S24 + "# The next sample's value first",
         _S20 + "_ph += _rdtsc() - _cv\n", "before"),
        (_S24 + "tc = anchor + (m + 1.0) * dt\n" + _S24 + "if tc < t_far:",
         _S24 + "_cv = _rdtsc()\n", "before"),
        (_S24 + "length = (tb - ta) * speed\n" + _S24 + "if length > 0.0:",
         _S24 + "_ph += _rdtsc() - _cv\n", "before"),
        (_S24 + "bx, by, bz = ox + tb * dx, oy + tb * dy, oz + tb * dz\n" + _S24
         + "if ahead_m == m:", _S24 + "_cv = _rdtsc()\n", "before"),
        (_S28 + "vb = value_at(grid, scr, bx, by, bz)\n" + _S28 + "evaluated += 1\n" + _S20
         + "if stop:", _S24 + "_ph += _rdtsc() - _cv\n", "before_last_line"),
        (_S16 + "end = tb >= t_far\n", _S16 + "_cv = _rdtsc()\n", "before"),
        (_S16 + "length = (tb - ta) * speed\n" + _S16 + "if length > 0.0:",
         _S16 + "_ph += _rdtsc() - _cv\n", "before"),
    ),
    "segment": (
        (_S24 + "length = (tb - ta) * speed\n" + _S24 + "if length > 0.0:",
         _S24 + "_cg = _rdtsc()\n", "before"),
        (_S24 + "if done(mode, st):\n" + _S28 + "stop = True", _S24 + "_ph += _rdtsc() - _cg\n",
         "before"),
        (_S16 + "length = (tb - ta) * speed\n" + _S16 + "if length > 0.0:",
         _S16 + "_cg = _rdtsc()\n", "before"),
        (_S16 + "if end or done(mode, st):\n", _S16 + "_ph += _rdtsc() - _cg\n", "before"),
    ),
}
_END = "    return evaluated, taken, leaps\n"
_NEW_END = "    return _ph, _rdtsc() - _c0, evaluated\n"


#: The passes in the order of their numbers (what ``_phase`` holds in the shared band).
_ORDER = tuple(_PASSES)
#: The shared band's ray set-up: every probe's start defined, and the pass it measures read.
_SELECT = ("    t0, t1, ray = grid_ray(",
           "    _cs = _cv = _cg = 0\n    _phase = _selected()\n", "before")


def _insert(source: str, anchor: str, text: str, where: str) -> str:
    """``source`` with ``text`` inserted at ``anchor`` (which must occur once)."""
    if source.count(anchor) != 1:
        raise ValueError(f"sample_breakdown: anchor not found once in sample_pixel: "
                         f"{anchor.strip()[:60]!r}")
    if where == "before_last_line":  # after all but the anchor's last line
        head, _, last = anchor.rpartition("\n")
        return source.replace(anchor, head + "\n" + text + last)
    return source.replace(anchor, text + anchor if where == "before" else anchor + text)


def _guarded(text: str, number: int) -> str:
    """The one-line probe ``text`` run only in pass ``number``."""
    body = text.lstrip(" ")
    indent = text[:len(text) - len(body)]
    return f"{indent}if _phase == {number}:\n{indent}    {body}"


def instrumented_source(source: str, phase: str | None) -> str:
    """``sample_pixel``'s source with the probes of ``phase``; with ``None``, every phase's,
    each run only while ``_selected()`` (read once per ray) returns its number in
    :data:`_ORDER`."""
    if phase is None:
        source = _insert(source, *_SELECT)
        probes = [(anchor, _guarded(text, number), where)
                  for number, name in enumerate(_ORDER)
                  for anchor, text, where in _PASSES[name]]
    else:
        probes = list(_PASSES[phase])
    for anchor, text, where in (_START, *probes):
        source = _insert(source, anchor, text, where)
    if source.count(_END) != 1:
        raise ValueError("sample_breakdown: sample_pixel's return not found once")
    return source.replace(_END, _NEW_END)


#: The pass the shared band measures (its number in :data:`_ORDER`); the band reads it at each
#: ray's start, so choosing another pass needs no compile.
_PASS_NUMBER = np.zeros(1, dtype=np.int64)
#: The shared instrumented band of each (model, mode) pair built in this process.
_BANDS: dict[tuple[type, type], Any] = {}


def _selected_intrinsic() -> Any:
    """A Numba intrinsic returning :data:`_PASS_NUMBER`'s value at the time of the call (a
    global array would be frozen into the code as a constant)."""
    from llvmlite import ir
    from numba.core import types
    from numba.core.extending import intrinsic

    address = _PASS_NUMBER.ctypes.data

    @intrinsic
    def selected(typingctx):
        def codegen(context, builder, signature, args):
            i64 = ir.IntType(64)
            pointer = builder.inttoptr(ir.Constant(i64, address), i64.as_pointer())
            return builder.load(pointer)

        return types.int64(), codegen

    return selected


def install(grid_class: type, mode_class: type, phase: str) -> None:
    """Make the renderer use the pair's instrumented band, measuring ``phase``: the band with
    every phase's probes (:func:`instrumented_source`), compiled at the pair's first call."""
    from splinecast.render import driver

    _PASS_NUMBER[0] = _ORDER.index(phase)
    band = _BANDS.get((grid_class, mode_class))
    if band is None:
        band = _BANDS[(grid_class, mode_class)] = _build(grid_class, mode_class)
    driver._KERNELS[(grid_class, mode_class)] = band


def _build(grid_class: type, mode_class: type) -> Any:
    """The pair's band with the instrumented loop (not cached: the copy's code has no source
    file, and it must never replace the real band)."""
    from splinecast._jit import jit, rebound
    from splinecast.render import driver, sampler

    source = textwrap.dedent(inspect.getsource(sampler.sample_pixel.py_func))
    namespace = {**vars(sampler), "_rdtsc": _rdtsc_intrinsic(),
                 "_selected": _selected_intrinsic(), "jit": functools.partial(jit, cache=False)}
    exec(compile(instrumented_source(source, None), "<sample_breakdown>", "exec"), namespace)
    bind = driver.pair_bindings(grid_class, mode_class)
    suffix = f"{grid_class.__name__}_{mode_class.__name__}_phases"
    where = rebound(sampler._sample_grid, bind, suffix, cache=False)
    on_plane = rebound(sampler._on_plane, bind, suffix, cache=False)
    planes = rebound(sampler._plane_samples, {**bind, "_on_plane": on_plane}, suffix, cache=False)
    pixel = rebound(namespace["sample_pixel"],
                    {**bind, "_sample_grid": where, "_plane_samples": planes}, suffix,
                    cache=False)
    return rebound(driver._trace_band, {**bind, "_trace_pixel": pixel}, suffix, cache=False)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", default="MNI152 T1 MRI 197x233x189")
    parser.add_argument("--tf", choices=("auto", "suite"), default="auto",
                        help="the automatic transfer function (dense) or the suite's")
    parser.add_argument("--size", default="1024x768")
    parser.add_argument("--dvr", default="{}", help="JSON of DVRSettings arguments "
                        "(default: none, the settings mode='dvr' uses)")
    parser.add_argument("--out", default=None, help="output stem (default: print only)")
    args = parser.parse_args()

    import numba

    import splinecast as sc
    from benchmarks._machine import describe
    from benchmarks.compare import methods as M
    from benchmarks.compare.runner import _camera
    from benchmarks.compare.scenes import by_label
    from splinecast.render import driver

    spec = by_label(args.scene)
    vol = spec.make()
    scene = sc.Scene(vol)
    tf = (sc.auto_transfer_function(vol) if args.tf == "auto" else
          sc.TransferFunction(M.dvr_transfer(vol, spec.isos[0]), vol.value_range, "gray"))
    settings = json.loads(args.dvr)
    kwargs: dict[str, Any] = {"mode": "dvr", "tf": tf,
                              "shading": sc.Shading(background=(0.0, 0.0, 0.0, 1.0))}
    if settings:
        kwargs["dvr"] = sc.DVRSettings(**settings)
    size = tuple(int(v) for v in args.size.split("x"))
    cam = _camera(vol, size, 40.0)

    def timed() -> tuple[Any, float]:
        scene.render(cam, **kwargs)
        start = time.perf_counter()
        frame = scene.render(cam, **kwargs)
        return frame, (time.perf_counter() - start) * 1e3

    real, frame_ms = timed()
    key = next(k for k in driver._KERNELS if k[1].__name__ == "DvrRayMode")
    events = {"evaluated": real.cells_visited, "segments": real.cells_tested,
              "leaps": real.blocks_skipped}
    traced = (real.cells_visited.astype(np.int64) + real.blocks_skipped) > 0
    out: dict[str, float] = {k: float(v[traced].mean()) for k, v in events.items()}
    phase_ms = {}
    for phase in _PASSES:
        install(*key, phase)
        frame, phase_ms[phase] = timed()
        out[phase] = float(frame.cells_visited[traced].astype(np.float64).mean())
        out[f"whole ({phase} pass)"] = float(frame.cells_tested[traced].astype(np.float64).mean())
    whole = min(out[f"whole ({p} pass)"] for p in _PASSES)
    out["rest"] = whole - sum(out[p] for p in _PASSES)
    info = {"scene": args.scene, "tf": args.tf, "size": args.size, "dvr": settings,
            "machine": describe()["cpu"], "threads": numba.get_num_threads(),
            "ghz": _counter_rate(), "probe": _read_cost(), "frame_ms": frame_ms,
            "instrumented_ms": phase_ms, "rays": int(traced.sum())}
    lines = [f"# Cycles per sampled ray by phase: {args.scene}, DVR ({args.tf} transfer "
             f"function)", "",
             f"Command: `python benchmarks/tools/sample_breakdown.py --scene \"{args.scene}\" "
             f"--tf {args.tf} --size {args.size}" + (f" --dvr '{args.dvr}'" if settings else "")
             + f"`. {info['machine']}; {info['threads']} Numba thread(s). Time-stamp counter "
             f"{info['ghz']:.2f} GHz; a probe costs {info['probe']:.0f} cycles. Frame "
             f"{frame_ms:.0f} ms with the real kernel; instrumented: "
             + ", ".join(f"{k} {v:.0f} ms" for k, v in phase_ms.items()) + ".", "",
             f"Means over the {info['rays']} traced rays (rays with a sample or a leap).", "",
             "| quantity | per ray | per segment |", "|---|---|---|"]
    for k, v in out.items():
        per = v / out["segments"] if out["segments"] else float("nan")
        lines.append(f"| {k} | {v:.1f} | {per:.1f} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        Path(f"{args.out}.md").write_text(text)
        Path(f"{args.out}.json").write_text(json.dumps({"info": info, "per_ray": out}, indent=1))


if __name__ == "__main__":
    main()
