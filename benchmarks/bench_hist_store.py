"""Cost of storing the error cut's brick histograms with the pyramid.

For the MNI152 MRI (when present, see ``_machine.MRI``) and a synthetic 256^3 uint8 volume (the one
of ``bench_cut.py``), builds the 16^3-brick pyramid without and with ``histograms=True`` side by
side (alternating, after a warm-up build that compiles the kernels), ``--repeat`` times each, and
reports the median build times, their ratio, the histogram bytes (raw and on disk) against the
source and against the pyramid's level files, and the time ``ErrorCut`` takes to open the store
with stored histograms against building them from the levels (a store without the group).

Run ``python benchmarks/bench_hist_store.py [--quick] [--json PATH]``; results go to
``benchmarks/results/hist_store[_quick].{md,json}``. The machine is shared: times are noisy.
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from _machine import describe  # noqa: E402
from bench_cut import MRI, synthetic  # noqa: E402

import splinecast as sc  # noqa: E402
from splinecast.multires.cut.octree import BrickOctree  # noqa: E402
from splinecast.multires.cut.policy import ErrorCut  # noqa: E402
from splinecast.multires.store.hist_store import histogram_info  # noqa: E402

BRICK = 16


def _disk(path: Path, skip: str | None = None) -> int:
    return sum(f.stat().st_size for f in path.rglob("*")
               if f.is_file() and (skip is None or skip not in f.parts))


def measure(name: str, volume: sc.Volume, repeat: int, tmp: Path) -> dict:
    plain, with_hist = tmp / f"{name}.zarr", tmp / f"{name}_h.zarr"
    sc.build_pyramid(volume, plain, brick=BRICK, progress=False, overwrite=True,
                     histograms=True)  # warm-up: compiles every kernel
    t_plain, t_hist = [], []
    for _ in range(repeat):
        start = time.perf_counter()
        sc.build_pyramid(volume, plain, brick=BRICK, progress=False, overwrite=True)
        t_plain.append(time.perf_counter() - start)
        start = time.perf_counter()
        sc.build_pyramid(volume, with_hist, brick=BRICK, progress=False, overwrite=True,
                         histograms=True)
        t_hist.append(time.perf_counter() - start)
    info = histogram_info(sc.read(with_hist))
    open_stored, open_built = [], []
    for _ in range(repeat):
        start = time.perf_counter()
        cut = ErrorCut(BrickOctree(sc.read(with_hist)))
        open_stored.append(time.perf_counter() - start)
        assert cut.histogram_source == "store"
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            start = time.perf_counter()
            cut = ErrorCut(BrickOctree(sc.read(plain)))
            open_built.append(time.perf_counter() - start)
        assert cut.histogram_source == "built"
    med = statistics.median
    return {
        "volume": name, "shape": list(volume.shape), "dtype": str(volume.dtype),
        "brick": BRICK, "bins": info["bins"], "repeat": repeat,
        "build_s": med(t_plain), "build_hist_s": med(t_hist),
        "build_overhead": med(t_hist) / med(t_plain) - 1.0,
        "build_s_all": t_plain, "build_hist_s_all": t_hist,
        "hist_bytes": info["nbytes"], "hist_disk_bytes": info["disk_bytes"],
        "source_bytes": info["source_nbytes"],
        "pyramid_disk_bytes": _disk(plain),
        "overhead_raw": info["nbytes"] / info["source_nbytes"],
        "overhead_disk": info["disk_bytes"] / max(_disk(plain), 1),
        "open_stored_s": med(open_stored), "open_built_s": med(open_built),
    }


def table(rows: list[dict]) -> str:
    out = ["| volume | build (s) | build + histograms (s) | overhead | histograms (raw) | "
           "% of source | on disk | % of pyramid files | open error cut: stored / built (s) |",
           "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(
            f"| {r['volume']} {'x'.join(map(str, r['shape']))} {r['dtype']} | "
            f"{r['build_s']:.2f} | {r['build_hist_s']:.2f} | {100 * r['build_overhead']:+.0f}% | "
            f"{r['hist_bytes'] / 2**20:.2f} MiB | {100 * r['overhead_raw']:.1f}% | "
            f"{r['hist_disk_bytes'] / 2**20:.2f} MiB | {100 * r['overhead_disk']:.1f}% | "
            f"{r['open_stored_s']:.2f} / {r['open_built_s']:.2f} |")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="128^3 synthetic, 1 repeat")
    parser.add_argument("--repeat", type=int, default=None)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)
    repeat = args.repeat or (1 if args.quick else 3)
    n = 128 if args.quick else 256
    rows = []
    tmp = Path(tempfile.mkdtemp(prefix="bench_hist_"))
    try:
        if MRI.exists():
            rows.append(measure("mri", sc.read(MRI), repeat, tmp))
            print(table(rows), flush=True)
        data = synthetic(n, np.empty((n, n, n), np.uint8))
        rows.append(measure(f"synthetic{n}", sc.Volume(data), repeat, tmp))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    text = table(rows)
    print(text)
    stem = "hist_store_quick" if args.quick else "hist_store"
    results = HERE / "results"
    machine = describe()
    md = [f"# Brick histograms stored with the pyramid ({'quick' if args.quick else 'full'})",
          "", f"`python benchmarks/bench_hist_store.py{' --quick' if args.quick else ''}`; "
          f"16^3 bricks, median of {repeat} builds each (plain and with histograms alternating, "
          "after a warm-up build). Machine: "
          f"{machine['cpu']}, {machine['cores']} cores, **shared with other jobs (noisy)**.", "",
          text, "",
          "Histogram bytes: raw = offsets + keys + counts arrays (what the renderer holds); "
          "on disk = the zstd-compressed `splinecast/hist2d` group. The paper's Table 1 reports "
          "4.4-5% of the (uncompressed) source.", ""]
    (results / f"{stem}.md").write_text("\n".join(md))
    payload = {"machine": machine, "rows": rows}
    (args.json or results / f"{stem}.json").write_text(json.dumps(payload, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
