"""What is left of calls and reference counting in a (model, mode) pair's compiled band.

The driver's band (:func:`splinecast.render.driver._trace_band`, copied per pair with the hooks
inlined at Numba's IR level) compiles with ``_nrt=False``. This renders one small frame for each
pair asked for, takes the LLVM IR of the pair's band and counts, per callee, the calls left in it
(after LLVM's own inlining): NRT reference-count operations, Numba-compiled functions that were
not inlined (their mangled names), and math intrinsics. A mode hook that is a real call shows up
as a callee named after it.

    python benchmarks/band_ir.py --models trilinear --modes dvr
"""

from __future__ import annotations

import argparse
import os
import re
import tempfile
from collections import Counter

# Numba keeps no IR for functions loaded from its on-disk cache: compile into an empty one.
os.environ["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(prefix="band-ir-cache-")

import numpy as np  # noqa: E402

import splinecast as sc  # noqa: E402
from splinecast.render import driver  # noqa: E402
from splinecast.render.dvr import DvrMode  # noqa: E402
from splinecast.render.iso import IsoMode  # noqa: E402
from splinecast.render.mip import MipMode  # noqa: E402

_MODE_CLASSES = {"dvr": DvrMode, "iso": IsoMode, "mip": MipMode, "minip": MipMode}

_CALL = re.compile(r"(?:call|invoke)\b[^@]*@\"?([A-Za-z0-9_.$]+)")


def band_ir(model: str, mode: str, settings: object = None) -> str:
    """LLVM IR of the band of ``(model, mode)`` after one 16x12 render of a 12^3 demo."""
    vol = sc.demo("marschner-lobb", size=12)
    scene = sc.Scene(vol, model=model)
    cam = sc.Camera.orbit(vol, size=(16, 12))
    kw: dict = {"mode": mode}
    if mode == "dvr":
        kw["tf"] = sc.TransferFunction([(0.3, 0.0), (0.7, 0.6)], vol.value_range)
        if settings is not None:
            kw["dvr"] = settings
    elif mode == "iso":
        kw["iso"] = 0.5
    scene.render(cam, **kw)
    band = driver.pair_band(type(scene.model.kernel_grid()), _MODE_CLASSES[mode])
    return "\n".join(band.inspect_llvm().values())


def census(ir: str) -> Counter:
    """Callee name -> number of call sites in the IR's function bodies."""
    calls: Counter = Counter()
    for line in ir.splitlines():
        line = line.strip()
        if line.startswith("declare") or line.startswith(";"):
            continue
        m = _CALL.search(line)
        if m:
            calls[m.group(1)] += 1
    return calls


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", default="trilinear")
    ap.add_argument("--modes", default="dvr")
    ap.add_argument("--dump", help="write the IR of the last pair to this file")
    args = ap.parse_args()
    np.seterr(all="ignore")
    for model in args.models.split(","):
        for mode in args.modes.split(","):
            ir = band_ir(model, mode)
            calls = census(ir)
            nrt = sum(n for name, n in calls.items() if "NRT" in name)
            print(f"{model} {mode}: {len(ir.splitlines())} IR lines, NRT calls {nrt}")
            for name, n in calls.most_common():
                print(f"  {n:5d}  {name[:160]}")
            if args.dump:
                with open(args.dump, "w") as f:
                    f.write(ir)


if __name__ == "__main__":
    main()
