"""Steady isosurface frames: rays clipped to the active blocks' box as a domain or as planes.

Run ``python benchmarks/bench_iso_clip.py [--rounds N]``; results go to
``benchmarks/results/iso_clip.md`` and ``.json``.

``Scene.render`` clips every isosurface ray to the box around the blocks that can hold the
isovalue. It did so with six clip planes per ray; it now narrows the grid's domain, which the
driver clips with its slab test anyway (``Grid.with_domain``). The baseline, in the same
process and the same rounds, adds the same box as a six-plane ``crop`` (what the old code paid
on top). Also timed: the floor kernel (ray, box clip, one colour write; ``floor_kernel.py``).
1024x768, colour only, default orbit camera; process CPU time of one Numba thread
(``NUMBA_NUM_THREADS=1`` is set before Numba loads), median of the rounds after a warm-up, the
variants alternating within every round.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _machine import describe  # noqa: E402
from floor_kernel import floor_render  # noqa: E402

import splinecast as sc  # noqa: E402

SCENES = (("sphere", 128), ("torus", 128), ("marschner-lobb", 256))


def measure(name: str, size: int, rounds: int) -> dict:
    vol = sc.demo(name, size=size)
    iso = vol.metadata["default_iso"]
    cam = sc.Camera.orbit(vol, azimuth=30, elevation=20, size=(1024, 768))
    scene = sc.Scene(vol)
    scene.render(cam, iso=iso, outputs=("rgba",))
    lo, hi = scene._active_box(scene._iso_flags())
    origin, spacing = np.asarray(vol.origin), np.asarray(vol.spacing)
    wlo, whi = origin + lo * spacing, origin + hi * spacing
    crop = tuple(float(v) for pair in zip(wlo, whi, strict=True) for v in pair)
    variants = {
        "domain (now)": lambda: scene.render(cam, iso=iso, outputs=("rgba",)),
        "domain + six planes (before)": lambda: scene.render(cam, iso=iso, outputs=("rgba",),
                                                             crop=crop),
        "floor": lambda: floor_render(cam, vol.bounds),
    }
    times: dict[str, list[float]] = {k: [] for k in variants}
    for run in variants.values():
        run()
    for _ in range(rounds):
        for key, run in variants.items():
            start = time.process_time()
            run()
            times[key].append(time.process_time() - start)
    return {"scene": f"{name} {size}^3", "ms": {k: float(np.median(v)) * 1e3
                                                 for k, v in times.items()},
            "rounds": rounds}


def markdown(results: dict) -> str:
    m = results["machine"]
    lines = ["# Isosurface rays clipped to the active box: domain vs six planes", "",
             f"Machine: {m['cpu']}, {m['cores']} cores, {m.get('numba_threads', '?')} Numba "
             f"thread(s). Command: `{results['command']}`. " + __doc__.split("\n\n")[2]
             .replace("\n", " "), "",
             "| scene | domain (now) ms | six planes (before) ms | saved | floor ms | "
             "now / floor |", "|---|---|---|---|---|---|"]
    for r in results["scenes"]:
        ms = r["ms"]
        now, before, floor = (ms["domain (now)"], ms["domain + six planes (before)"],
                              ms["floor"])
        lines.append(f"| {r['scene']} | {now:.1f} | {before:.1f} | "
                     f"{100 * (1 - now / before):.0f}% | {floor:.1f} | {now / floor:.1f}x |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--out", default=str(HERE / "results"))
    args = parser.parse_args()
    results = {"machine": describe(),
               "command": " ".join(["python benchmarks/bench_iso_clip.py", *sys.argv[1:]]),
               "scenes": [measure(n, s, args.rounds) for n, s in SCENES]}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "iso_clip.json").write_text(json.dumps(results, indent=1) + "\n")
    (out / "iso_clip.md").write_text(markdown(results))
    print(markdown(results))


if __name__ == "__main__":
    main()
