"""MIP with a tolerance against the exact and the sampled projections: speed and shortfall.

``scene.render(cam, mode="mip", tolerance=e)`` leaves out every block, cell and piece whose
maximum does not beat the running maximum by more than ``e`` of the window, so no pixel falls
more than ``e`` below the exact projection. The sampled methods have no such bound: a thin
bright structure between two samples is missed whole. This script renders the comparison
suite's MIP volumes at 1024x768 (four orbit views, azimuth 40-70, elevation 20; median of
``ROUNDS`` rounds after a warm-up, two threads as numba has them) with:

* the exact method (the baseline of every ratio);
* the exact method with tolerances of 0.5, 1, 4 and 10 levels of an 8-bit image (1/255 of the
  window each);
* ``method="slices"`` at steps of 2, 3 and 4 voxels (the fastest sampled method);

and reports each frame's time, its speed-up over the exact frame measured in the same run, and
the mean and largest shortfall below the exact projection over the pixels with a value, as
fractions of the window (the automatic one, :func:`splinecast.auto_window`). It writes
``results/mip_tolerance.{json,md,png}``.

    python benchmarks/mip_tolerance.py
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))
from _machine import write_results  # noqa: E402

import splinecast as sc  # noqa: E402
from benchmarks.compare.scenes import ml, mri, noise  # noqa: E402

ROUNDS = 3
AZIMUTHS = (40.0, 50.0, 60.0, 70.0)
LEVELS = (0.5, 1.0, 4.0, 10.0)  # tolerances, in 1/255 of the window
STEPS = (2.0, 3.0, 4.0)  # slices


def _frames(scene, cams, **options):
    """Median frame time (ms) over ROUNDS rounds of ``cams`` after a warm-up, and the values
    of the first camera's frame."""
    first = scene.render(cams[0], mode="mip", outputs=("value",), **options).value
    times = []
    for _ in range(ROUNDS):
        for cam in cams:
            t = time.perf_counter()
            scene.render(cam, mode="mip", outputs=("rgba",), **options)
            times.append(time.perf_counter() - t)
    return 1e3 * statistics.median(times), first


def measure(spec) -> list[dict]:
    vol = spec.make()
    scene = sc.Scene(vol)
    cams = [sc.Camera.orbit(vol, azimuth=a, elevation=20.0, size=(1024, 768)) for a in AZIMUTHS]
    window = sc.auto_window(vol)
    width = window[1] - window[0]
    exact_ms, exact = _frames(scene, cams)
    seen = np.isfinite(exact)
    rows = [{"scene": spec.label, "method": "exact", "setting": "-", "ms": exact_ms,
             "speedup": 1.0, "mean": 0.0, "max": 0.0}]
    cases = [("exact, tolerance", f"{level:g}/255", {"tolerance": level / 255.0})
             for level in LEVELS]
    cases += [("slices", f"step {step:g}", {"method": "slices", "step": step})
              for step in STEPS]
    for method, setting, options in cases:
        ms, value = _frames(scene, cams, **options)
        short = (exact[seen] - value[seen]) / width
        rows.append({"scene": spec.label, "method": method, "setting": setting, "ms": ms,
                     "speedup": exact_ms / ms, "mean": float(short.mean()),
                     "max": float(short.max())})
        print(rows[-1], flush=True)
    return rows


def plot(rows: list[dict], path: Path) -> bool:
    """Frame time against largest shortfall per scene; False without matplotlib."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        from matplotlib.ticker import NullFormatter
    except ImportError:
        return False
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    cols = 2
    nrows = (len(scenes) + cols - 1) // cols
    fig, axes = plt.subplots(nrows, cols, figsize=(5.2 * cols, 3.9 * nrows), squeeze=False)
    for ax in axes.flat[len(scenes):]:
        ax.set_visible(False)
    for ax, name in zip(axes.flat, scenes, strict=False):  # axes may outnumber scenes
        mine = [r for r in rows if r["scene"] == name]
        exact = mine[0]
        ax.axhline(exact["ms"], color="k", lw=0.8, ls=":", label="exact")
        for method, style in (("exact, tolerance", "o-"), ("slices", "s--")):
            pts = [r for r in mine if r["method"] == method]
            ax.plot([r["max"] for r in pts], [r["ms"] for r in pts], style, label=method)
            for r in pts:
                ax.annotate(r["setting"], (r["max"], r["ms"]), fontsize=7,
                            textcoords="offset points", xytext=(3, 3))
        ax.set_xscale("log")
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("largest shortfall below exact (of the window)")
        ax.set_ylabel("ms per 1024x768 frame")
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return True


def main() -> None:
    rows = [r for spec in (ml(128), ml(256), mri(), noise(256)) if spec is not None
            for r in measure(spec)]
    plotted = plot(rows, HERE / "results" / "mip_tolerance.png")
    write_results(
        HERE / "results" / "mip_tolerance",
        "MIP with a tolerance: frame time and shortfall below the exact projection",
        "Command: `python benchmarks/mip_tolerance.py`. 1024x768, colour only, four orbit "
        f"views (azimuth 40-70, elevation 20), medians of {ROUNDS} rounds after a warm-up; "
        "speed-up over the exact frame of the same run. Shortfall: (exact - value) / window "
        "width over the pixels with a value (first view), the window being `sc.auto_window`'s. "
        "A tolerance bounds the largest shortfall; the sampled methods' is unbounded.",
        ["scene", "method", "setting", "ms", "speed-up over exact", "mean shortfall",
         "largest shortfall"],
        rows, lambda r: [r["scene"], r["method"], r["setting"], f"{r['ms']:.1f}",
                         f"{r['speedup']:.2f}x", f"{r['mean']:.4f}", f"{r['max']:.4f}"],
        before_table=["![frame time against largest shortfall](mip_tolerance.png)"]
        if plotted else ())

if __name__ == "__main__":
    import argparse

    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args()
    main()
