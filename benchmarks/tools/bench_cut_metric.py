"""Per-node cost of the cut metric's lazy queries, side by side with an earlier build.

A cut is chosen by asking the metric for the priorities (or the errors, or the error reductions)
of tree nodes; after a transfer-function or view change every cached value is stale and the
whole tree is refilled. This tool builds the brick tree and histograms of a Marschner-Lobb
volume, then alternates the two worker processes (this checkout's ``src`` and ``--baseline
DIR/src``): each changes the transfer function and the view, asks one query for every node and
reports the CPU time per node, median over the repeats after a warm-up. Rounds alternate the
builds so both see the same machine load.

    python benchmarks/tools/bench_cut_metric.py --baseline /tmp/old/src [--rounds 3]
        [--size 160] [--brick 4]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]

WORKER = r'''
import json, statistics, sys, time
import numpy as np
import splinecast as sc
from splinecast.multires.cut.histograms import Quantizer, leaf_value_ranges, pyramid_histograms
from splinecast.multires.cut.metric import CutMetric
from splinecast.multires.cut.tree import regular_brick_tree
from splinecast.multires.store.mean_pyramid import mean_pyramid

size, brick, repeats = (int(a) for a in sys.argv[1:4])
src = np.asarray(sc.demo("marschner-lobb", size=size).data, np.float32) * 255.0
vmin, vmax = leaf_value_ranges(src, brick)
tree = regular_brick_tree(src.shape, brick, spacing=(1.0, 1.0, 1.0), leaf_min=vmin,
                          leaf_max=vmax)
hist = pyramid_histograms(mean_pyramid(src, tree.grid.levels), brick,
                          Quantizer.for_data(src.dtype, (0, 255)))
tfs = (sc.TransferFunction([(60, 0.0), (120, 0.3), (200, 0.9)], domain=(0, 255)),
       sc.TransferFunction([(90, 0.0), (110, 0.6), (150, 0.1)], domain=(0, 255)))
metric = CutMetric(tree, hist, tfs[0], interest=(10, 30, 5), eye=(-50, 20, 20), improved=True)
nodes = np.arange(tree.size)
out = {"nodes": int(tree.size)}
for query in ("priority", "error_reduction", "error"):
    getattr(metric, query)(nodes)  # compile and warm up
    times = []
    for r in range(repeats):
        metric.set_transfer_function(tfs[(r + 1) % 2])
        metric.set_view(interest=(10 + r, 30, 5), eye=(-50, 20, 20))
        start = time.process_time()
        getattr(metric, query)(nodes)
        times.append(time.process_time() - start)
    out[query] = statistics.median(times) / tree.size * 1e9
print(json.dumps(out))
'''


def run(src: str, args: argparse.Namespace) -> dict:
    """One worker run of the build whose package is in ``src``."""
    env = {**os.environ, "PYTHONPATH": src}
    done = subprocess.run([sys.executable, "-c", WORKER, str(args.size), str(args.brick),
                           str(args.repeats)], env=env, capture_output=True, text=True,
                          check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", required=True, help="src folder of the baseline build")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--size", type=int, default=160, help="volume side in voxels")
    ap.add_argument("--brick", type=int, default=4, help="brick side in voxels")
    args = ap.parse_args()
    runs: dict[str, list[dict]] = {"new": [], "baseline": []}
    for _ in range(args.rounds):
        runs["new"].append(run(str(REPO / "src"), args))
        runs["baseline"].append(run(args.baseline, args))
    nodes = runs["new"][0]["nodes"]
    print(f"# Cut metric, CPU ns per node ({nodes} nodes, {args.size}^3, bricks of "
          f"{args.brick}^3), median of {args.rounds} alternating rounds\n")
    print("| query | this build | baseline | new / baseline |")
    print("|---|---|---|---|")
    for query in ("priority", "error_reduction", "error"):
        new = statistics.median(r[query] for r in runs["new"])
        old = statistics.median(r[query] for r in runs["baseline"])
        print(f"| {query} | {new:.0f} | {old:.0f} | {new / old:.2f} |")


if __name__ == "__main__":
    main()
