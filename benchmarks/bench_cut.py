"""Cut-selection benchmark (Carmona & Froehlich 2011 tables 1-3): no rendering involved.

For the MNI152 MRI (when present, see ``_machine.MRI``) and synthetic 512^3 and 1024^3 uint8
volumes, with bricks of 16^3 and 32^3, on a 2x2x2 mean pyramid computed here slab by slab (the
1024^3 source lives in a temporary memory-mapped file, not an OME-Zarr store):

* **Table 1**: pyramid and histogram build times, histogram bytes and their overhead over the
  source bytes (paper: 4-5%);
* the paper's protocol: 100 frames moving the interest point (a random walk, 3% of the volume
  diagonal per frame, seeded), then 100 frames editing the transfer function (one random control
  point moves per frame: 2% of the domain in value, 0.05 in opacity);
* **Table 2** (selection from scratch, no load limit), on every ``--sample``-th frame: E(cut) of
  the naive greedy (P = E), the improved greedy (P = ER) and the optimum (Algorithm 1), their
  percentage differences, and the DP time;
* **Table 3** (one update under M), on the same frames, with budgets small enough for the
  download-aware optimum (O(K N^2 M^2)): from the cut the improved updater had when the phase
  began, one naive and one improved frame against the optimal update; reduction as a % of the
  optimal reduction;
* greedy update time per frame (both priorities, every frame, the paper's N = 2560 and M = 164 for
  16^3 bricks, M = 85 for 32^3, where the tree is big enough), split into re-prioritisation and
  split-and-collapse;
* the distortion update after a transfer-function edit: the whole octree against the hull (the
  cut, its ancestors and children, and the grandchildren the fix-up reads).

Run ``python benchmarks/bench_cut.py [--quick] [--json PATH] [--volumes mri,512,1024]``; results
go to ``benchmarks/results/cut[_quick].json`` and ``.md``. The machine is described in the output.

**Images** (the paper's Fig. 9), ``python benchmarks/bench_cut.py --images [--quick]``: the MRI
and a synthetic volume are written as OME-Zarr pyramids (16^3 bricks) and rendered in DVR by the
multiresolution renderer with the error-metric cut (``cut="error"``, improved priority, importance
from the eye) and with the screen-space level-of-detail cut (``cut="lod"``, ``lod=0.5``: as fine
as the budget allows, largest voxels on screen refined first) under the *same* byte budget (a
share of the finest level's bricks), against the in-memory render of the full-resolution volume.
Per pixel: the CIELUV distance (ΔE*uv, the paper's measure) and CIEDE2000 (scikit-image
``rgb2lab`` / ``deltaE_ciede2000``); mean and 95th percentile over the pixels the full-resolution
image covers (alpha > 1%). Results go to ``cut_images[_quick].json``/``.md`` and a PNG of the
images and ΔE maps.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import splinecast as sc
from splinecast.multires.cut.histograms import (
    Quantizer,
    coarsen_histograms,
    leaf_value_ranges,
    pyramid_histograms,
)
from splinecast.multires.cut.metric import CutMetric, cut_error
from splinecast.multires.cut.select import greedy_cut, optimal_cut, optimal_update
from splinecast.multires.cut.tree import regular_brick_tree
from splinecast.multires.cut.update import CutUpdater
from splinecast.multires.store.mean_pyramid import mean_downsample

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _machine import MRI, describe  # noqa: E402

HERE = Path(__file__).resolve().parent
MRI_TF = HERE.parent / "examples" / "tf-mri.json"
SYNTH_TF = sc.TransferFunction([(70, 0.0), (110, 0.25), (150, 0.02), (190, 0.7), (255, 0.9)],
                               domain=(0, 255), colormap="viridis")


# ---------------------------------------------------------------------------------- volumes
def _interp_matrix(points: np.ndarray, m: int) -> np.ndarray:
    """Linear interpolation weights from an m-point lattice over [-1, 1] to ``points``."""
    u = (points + 1.0) / 2.0 * (m - 1)
    i0 = np.clip(np.floor(u).astype(int), 0, m - 2)
    w = u - i0
    mat = np.zeros((points.size, m))
    mat[np.arange(points.size), i0] = 1.0 - w
    mat[np.arange(points.size), i0 + 1] = w
    return mat


def synthetic(n: int, out: np.ndarray, seed: int = 0) -> np.ndarray:
    """A field with detail at several scales that varies across the volume, written slab by
    slab into ``out`` (uint8), in the spirit of the paper's IE volume.

    On ``[-1, 1]^3``: a damped radial wave ``0.25 cos(6 pi r) exp(-2 r^2)``; a high-frequency
    product of sines (wavelength ~ n/13 voxels) whose amplitude varies smoothly in space; and
    value noise (random lattices of 17^3 and 65^3 points, interpolated linearly): some regions
    are smooth, some need fine bricks. Outside a lumpy ellipsoid the field drops to near 0,
    "air" the transfer function makes transparent, so the brick tree is incomplete along that
    boundary, as for a scanned body: the cut selection has real choices to make.
    """
    rng = np.random.default_rng(seed)
    axis = np.linspace(-1.0, 1.0, n)
    lattices = [(rng.random((m, m, m)) - 0.5, m, a) for m, a in ((17, 0.16), (65, 0.10))]
    wy = {m: _interp_matrix(axis, m) for _, m, _ in lattices}
    y, z = np.meshgrid(axis, axis, indexing="ij")
    slab = max(1, (1 << 22) // (n * n))
    for x0 in range(0, n, slab):
        xs = axis[x0:x0 + slab]
        x = xs[:, None, None]
        r = np.sqrt(x * x + y * y + z * z)
        amp = 0.5 * (1.0 + np.sin(2.0 * x + 3.0 * y - z))
        f = (0.5 + 0.25 * np.cos(6 * np.pi * r) * np.exp(-2 * r * r)
             + 0.12 * amp * np.sin(40 * x + 3) * np.sin(37 * y + 1) * np.sin(43 * z + 2))
        noise = []
        for lattice, m, a in lattices:
            t = (_interp_matrix(xs, m) @ lattice.reshape(m, m * m)).reshape(-1, m, m)
            t = np.einsum("jb,ibc->ijc", wy[m], t)
            noise.append(t @ wy[m].T)
            f += a * noise[-1]
        body = (x / 0.85) ** 2 + (y / 0.7) ** 2 + (z / 0.95) ** 2 + 0.8 * noise[0] < 1.0
        f = np.where(body, f, 0.03 + 0.02 * noise[1])
        out[x0:x0 + slab] = np.clip(f * 255, 0, 255).astype(np.uint8)
    return out


def load_volume(name: str, tmp: Path) -> tuple[np.ndarray, sc.TransferFunction]:
    if name == "mri":
        return np.ascontiguousarray(sc.read(MRI).data), sc.TransferFunction.load(MRI_TF)
    n = int(name)
    if n >= 1024:  # 1 GiB: a memory-mapped file, generated and read slab by slab
        out = np.lib.format.open_memmap(tmp / f"synthetic{n}.npy", mode="w+", dtype=np.uint8,
                                        shape=(n, n, n))
    else:
        out = np.empty((n, n, n), np.uint8)
    return synthetic(n, out), SYNTH_TF


# ----------------------------------------------------------------------------- one tree setup
def budgets(visible_leaves: int, brick: int) -> tuple[int, int]:
    """The paper's N = 2560 (M = 164 for 16^3 bricks, 85 for 32^3) when the tree is big enough;
    otherwise 10% of the visible finest bricks, but at least 256 (or a third of them) so that
    the granularity of a split (7 bricks) stays small against N; M scaled like the paper's."""
    n = min(2560, max(visible_leaves // 10, min(256, visible_leaves // 3)))
    m = (164 if brick == 16 else 85) if n == 2560 else max(16, round(n * 164 / 2560))
    return n, m


def small_budgets(n: int) -> tuple[int, int]:
    """Budgets of Table 3, where the download-aware optimum costs O(K N^2 M^2)."""
    n_small = min(256, n)
    return n_small, max(8, round(n_small * 164 / 2560))


def walk(rng: np.random.Generator, point: np.ndarray, lo: np.ndarray, hi: np.ndarray,
         step: float) -> np.ndarray:
    return np.clip(point + rng.normal(0.0, step / np.sqrt(3), 3), lo, hi)


def edit(rng: np.random.Generator, tf: sc.TransferFunction) -> sc.TransferFunction:
    """Move one opacity control point: 2% of the domain in value, 0.05 in opacity."""
    pts = tf.opacity_points.copy()
    k = int(rng.integers(len(pts)))
    lo, hi = tf.domain
    pts[k, 0] = np.clip(pts[k, 0] + rng.normal(0, 0.02 * (hi - lo)), lo, hi)
    pts[k, 1] = np.clip(pts[k, 1] + rng.normal(0, 0.05), 0.0, 1.0)
    pts = pts[np.argsort(pts[:, 0], kind="stable")]
    return sc.TransferFunction(pts, domain=tf.domain, colormap=tf.colormap)


def summary(values: list[float]) -> dict:
    if not values:
        return {}
    return {"mean": statistics.fmean(values), "median": statistics.median(values),
            "max": max(values), "n": len(values)}


#: The download-aware optimum (O(K N^2 M^2)) runs only on trees up to this many nodes.
UPDATE_OPTIMUM_NODES = 40_000


def run_tree(name, brick, tree, hist, tf0, frames, sample, seed) -> dict:
    rng = np.random.default_rng(seed)
    with_update_optimum = tree.size <= UPDATE_OPTIMUM_NODES
    lo = tree.box_min.min(axis=0)
    hi = tree.box_max.max(axis=0)
    diag = float(np.linalg.norm(hi - lo))
    eye = (lo + hi) / 2 - 1.5 * diag * np.array([1.0, 0.5, 0.3]) / np.linalg.norm([1, 0.5, 0.3])
    point = (lo + hi) / 2
    metrics = {imp: CutMetric(tree, hist, tf0, interest=point, eye=eye, improved=imp)
               for imp in (False, True)}
    visible_leaves = int((tree.is_leaf & metrics[True].visible).sum())
    n_big, m_big = budgets(visible_leaves, brick)
    n_small, m_small = small_budgets(n_big)
    updaters = {imp: CutUpdater(metrics[imp], n_big, m_big,
                                cut=greedy_cut(metrics[imp], n_big)) for imp in (False, True)}
    small = CutUpdater(metrics[True], n_small, m_small, cut=greedy_cut(metrics[True], n_small))
    start = np.sort(np.fromiter(small.cut, np.int64, len(small.cut)))
    tf = tf0
    rows = {"pi": [], "tf": []}
    update_ms = {(imp, ph): [] for imp in (False, True) for ph in ("pi", "tf")}   # wall
    update_cpu_ms = {key: [] for key in update_ms}  # this thread's CPU time: robust when busy
    phase_ms = {"prioritize_ms": [], "refine_ms": []}
    d_full, d_hull, hull_sizes = [], [], []
    for frame in range(2 * frames):
        phase = "pi" if frame < frames else "tf"
        if phase == "pi":
            point = walk(rng, point, lo, hi, 0.03 * diag)
            for m in metrics.values():
                m.set_view(interest=point, eye=eye)
        else:
            tf = edit(rng, tf)
            for m in metrics.values():
                m.set_transfer_function(tf)
        sampled = frame % sample == sample - 1
        for imp, upd in updaters.items():
            t0, c0 = time.perf_counter(), time.thread_time()
            result = upd.update()
            update_ms[imp, phase].append((time.perf_counter() - t0) * 1e3)
            update_cpu_ms[imp, phase].append((time.thread_time() - c0) * 1e3)
            if imp:
                for key in phase_ms:
                    phase_ms[key].append(result.timings[key])
        if phase == "tf":  # distortion after an edit: whole octree vs hull (timed on a copy)
            probe = CutMetric(tree, hist, tf, interest=point, eye=eye)
            cut = np.fromiter(updaters[True].cut, np.int64, len(updaters[True].cut))
            kids = tree.children_of_many(cut)
            hull = np.unique(np.concatenate([cut, tree.ancestors_of(cut), kids]))
            t0, c0 = time.perf_counter(), time.process_time()
            probe.distortion(hull)
            d_hull.append(((time.perf_counter() - t0) * 1e3, (time.process_time() - c0) * 1e3))
            t0, c0 = time.perf_counter(), time.process_time()
            probe.update_all_distortions()  # parallel: CPU time counts both threads
            d_full.append(((time.perf_counter() - t0) * 1e3, (time.process_time() - c0) * 1e3))
            hull_sizes.append(int(hull.size))
        if sampled:
            rows[phase].append(compare(tree, metrics, n_big, start, n_small, m_small,
                                       with_update_optimum))
        small.update()
        if frame == frames - 1:
            # Table 3 starts from the cut the improved updater had when the phase began (the
            # interest point has wandered, or the transfer function has been edited, since),
            # so one update has ground to recover, as after a jump or a bigger edit (the
            # paper's inputs are well above its converged errors).
            start = np.sort(np.fromiter(small.cut, np.int64, len(small.cut)))
    return {
        "volume": name, "brick": brick, "nodes": tree.size, "visible_leaves": visible_leaves,
        "N": n_big, "M": m_big, "N_small": n_small, "M_small": m_small,
        "frames": 2 * frames, "sample_every": sample, "samples": rows,
        "update_ms": {f"{'improved' if imp else 'naive'}_{ph}": summary(v)
                      for (imp, ph), v in update_ms.items()},
        "update_cpu_ms": {f"{'improved' if imp else 'naive'}_{ph}": summary(v)
                          for (imp, ph), v in update_cpu_ms.items()},
        "update_phases_ms": {k: summary(v) for k, v in phase_ms.items()},
        "d_update_ms": {"full": summary([w for w, _ in d_full]),
                        "hull": summary([w for w, _ in d_hull]),
                        "full_cpu": summary([c for _, c in d_full]),
                        "hull_cpu": summary([c for _, c in d_hull]),
                        "hull_nodes": summary(hull_sizes)},
    }


def compare(tree, metrics, n_big, start, n_small, m_small, with_update_optimum) -> dict:
    """Table 2 (from scratch, N) and Table 3 (one update from ``start`` under N_small, M)."""
    metric = metrics[True]
    error = metric.all_errors()
    visible = metric.visible
    row = {}
    for label, imp in (("naive", False), ("improved", True)):
        row[label] = cut_error(tree, error, greedy_cut(metrics[imp], n_big), visible)
    row["improved_fill"] = cut_error(tree, error, greedy_cut(metric, n_big, fill=True), visible)
    t0 = time.perf_counter()
    cut, _ = optimal_cut(tree, error, visible, n_big)
    row["dp_ms"] = (time.perf_counter() - t0) * 1e3
    row["optimal"] = cut_error(tree, error, cut, visible)
    # Table 3: the same start cut for the three algorithms.
    one = {}
    within = {}
    for label, imp, fill in (("naive", False, False), ("improved", True, False),
                             ("improved_fill", True, True)):
        upd = CutUpdater(metrics[imp], n_small, m_small, cut=start, fill=fill)
        begin = np.sort(np.fromiter(upd.cut, np.int64, len(upd.cut)))
        one["input"] = cut_error(tree, error, begin, visible)
        frame = upd.update()
        one[label] = cut_error(tree, error, frame.cut, visible)
        within[label] = not frame.over_budget
    one["optimal"] = None
    if with_update_optimum:
        resident = np.zeros(tree.size, bool)
        resident[start] = True
        t0 = time.perf_counter()
        best = optimal_update(tree, error, visible, n_small, m_small, resident)
        one["dp_ms"] = (time.perf_counter() - t0) * 1e3
        if best is not None:
            one["optimal"] = cut_error(tree, error, best[0], visible)
            # The optimum can never lose to a greedy frame that kept within N and M.
            one["optimum_check"] = all(one["optimal"] <= one[k] * (1 + 1e-12) + 1e-15
                                       for k in within if within[k])
    row["update"] = one
    return row


# ------------------------------------------------------------------------------- aggregation
def pct(a: float, b: float) -> float:
    """How much lower b is than a, in % of a."""
    return 100.0 * (a - b) / a if a > 0 else 0.0


def aggregate(result: dict) -> dict:
    out = {}
    for phase, rows in result["samples"].items():
        if not rows:
            continue
        e = {k: statistics.fmean(r[k] for r in rows) for k in ("naive", "improved", "optimal")}
        e["b_vs_a_pct"] = statistics.fmean(pct(r["naive"], r["improved"]) for r in rows)
        e["c_vs_a_pct"] = statistics.fmean(pct(r["naive"], r["optimal"]) for r in rows)
        e["c_vs_b_pct"] = statistics.fmean(pct(r["improved"], r["optimal"]) for r in rows)
        e["c_vs_b_max_pct"] = max(pct(r["improved"], r["optimal"]) for r in rows)
        e["improved_fill"] = statistics.fmean(r["improved_fill"] for r in rows)
        e["c_vs_bfill_pct"] = statistics.fmean(pct(r["improved_fill"], r["optimal"])
                                               for r in rows)
        e["dp_ms"] = statistics.median(r["dp_ms"] for r in rows)
        ups = [r["update"] for r in rows if r["update"]["optimal"] is not None
               and r["update"]["input"] - r["update"]["optimal"] > 1e-9 * r["update"]["input"]]
        if ups:
            kinds = ("naive", "improved") + (("improved_fill",) if all(
                "improved_fill" in u for u in ups) else ())
            red = {k: [(u["input"] - u[k]) / (u["input"] - u["optimal"]) * 100 for u in ups]
                   for k in kinds}
            e["update"] = {
                "input": statistics.fmean(u["input"] for u in ups),
                "naive": statistics.fmean(u["naive"] for u in ups),
                "improved": statistics.fmean(u["improved"] for u in ups),
                "optimal": statistics.fmean(u["optimal"] for u in ups),
                "naive_pct_of_optimal": statistics.fmean(red["naive"]),
                "improved_pct_of_optimal": statistics.fmean(red["improved"]),
                "improved_fill_pct_of_optimal": (statistics.fmean(red["improved_fill"])
                                                 if "improved_fill" in red else None),
                "frames": len(ups), "sampled": len(rows),
                "optimum_check_failures": sum(not u.get("optimum_check", True) for u in ups),
                "dp_ms": statistics.median(u["dp_ms"] for u in ups)}
        out[phase] = e
    return out


# --------------------------------------------------------------------------------- the runs
def prepare(name: str, tmp: Path) -> dict:
    """Pyramid, leaf ranges and histograms for 16^3 and 32^3 bricks (Table 1)."""
    t0 = time.perf_counter()
    source, tf = load_volume(name, tmp)
    t_load = time.perf_counter() - t0
    t0 = time.perf_counter()
    levels = [source]
    while any(n > 1 for n in levels[-1].shape) and len(levels) < 12:
        levels.append(mean_downsample(levels[-1]))
    t_pyr = time.perf_counter() - t0
    q = Quantizer.for_data(source.dtype, (0, 255))  # 64 bins (DEFAULT_BINS)
    out = {"name": name, "shape": list(source.shape), "source_bytes": int(source.nbytes),
           "load_s": t_load, "pyramid_s": t_pyr, "tf": tf, "trees": {}}
    t0 = time.perf_counter()
    tree16 = regular_brick_tree(source.shape, 16, leaf_min=None, leaf_max=None)
    hist16 = pyramid_histograms(levels[:tree16.grid.levels], 16, q)
    t_hist = time.perf_counter() - t0
    if source.size <= 512**3:  # what 256 bins (exact for 8 bits) would cost, for comparison
        t0 = time.perf_counter()
        exact = pyramid_histograms(levels[:tree16.grid.levels], 16,
                                   Quantizer.for_data(source.dtype, (0, 255), bins=256))
        out["hist256_16"] = {"hist_bytes": exact.nbytes, "hist_s": time.perf_counter() - t0,
                             "hist_overhead_pct": 100.0 * exact.nbytes / source.nbytes}
    for brick in (16, 32):
        t0 = time.perf_counter()
        vmin, vmax = leaf_value_ranges(source, brick)
        tree = regular_brick_tree(source.shape, brick, leaf_min=vmin, leaf_max=vmax)
        t_ranges = time.perf_counter() - t0
        if brick == 16:
            hist, t_h = hist16, t_hist
        else:
            t0 = time.perf_counter()
            hist = coarsen_histograms(hist16, tree16.grid, tree.grid)
            t_h = time.perf_counter() - t0
        bricks_bytes = int(tree.size) * brick ** 3 * source.dtype.itemsize
        out["trees"][brick] = {
            "tree": tree, "hist": hist,
            "table1": {"nodes": tree.size, "levels": tree.grid.levels,
                       "octree_bytes": bricks_bytes, "hist_bytes": hist.nbytes,
                       "hist_entries": int(hist.keys.size),
                       "hist_overhead_pct": 100.0 * hist.nbytes / source.nbytes,
                       "hist_s": t_h, "ranges_s": t_ranges}}
    return out


def markdown(results: dict) -> str:
    m = results["machine"]
    lines = [
        "# Cut selection and updates (Carmona & Froehlich 2011)", "",
        f"Machine: {m['cpu']}, {m['cores']} logical cores (shared with other jobs: timings are "
        f"noisy). Command: `{results['command']}`. {results['frames']} frames per tree "
        f"(half moving the interest point, half editing the transfer function); Table 2 and 3 "
        f"on every {results['sample']}th frame.", "",
        "## Table 1: histograms", "",
        "| volume | brick | nodes | histogram entries | histogram MB | overhead vs source | "
        "build s |", "|---|---|---|---|---|---|---|"]
    for v in results["volumes"]:
        for brick, t in v["trees"].items():
            t1 = t["table1"]
            lines.append(f"| {v['name']} {tuple(v['shape'])} | {brick}^3 | {t1['nodes']} | "
                         f"{t1['hist_entries']} | {t1['hist_bytes'] / 2**20:.1f} | "
                         f"{t1['hist_overhead_pct']:.1f}% | {t1['hist_s']:.1f} |")
    lines += ["", "64 bins per value axis, 6 bytes per entry (uint16 key, uint32 count), raw "
              "(a store compresses them further). Build: 16^3 histograms from the pyramid (one "
              "pass over the source per level); 32^3 summed from them. With 256 bins (exact "
              "for 8-bit data), 16^3 bricks:", ""]
    for v in results["volumes"]:
        if "hist256_16" in v:
            h = v["hist256_16"]
            lines.append(f"- {v['name']}: {h['hist_bytes'] / 2**20:.1f} MB, "
                         f"{h['hist_overhead_pct']:.1f}% of the source")
    lines += ["",
              "## Table 2: E(cut), selection from scratch under N (mean over sampled frames)", "",
              "| volume | brick | N | phase | (a) naive | (b) improved | (c) optimal | b vs a | "
              "c vs a | c vs b (max) | (b') improved, fill | c vs b' | DP ms |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for v in results["volumes"]:
        for brick, t in v["trees"].items():
            r = t["run"]
            for phase, e in r["aggregate"].items():
                lines.append(
                    f"| {v['name']} | {brick}^3 | {r['N']} | {phase.upper()} | {e['naive']:.4f} | "
                    f"{e['improved']:.4f} | {e['optimal']:.4f} | {e['b_vs_a_pct']:.2f}% | "
                    f"{e['c_vs_a_pct']:.2f}% | {e['c_vs_b_pct']:.3f}% "
                    f"({e['c_vs_b_max_pct']:.2f}%) | {e['improved_fill']:.4f} | "
                    f"{e['c_vs_bfill_pct']:.3f}% | {e['dp_ms']:.0f} |")
    lines += ["", "(b') is the improved greedy that sets a split that does not fit aside and goes "
              "on (`greedy_cut(..., fill=True)`); (b) stops there, as the paper's rule and the "
              "updates' fixed point do.", ""]
    lines += ["", "## Table 3: one update under M, error reduction as % of the optimal one", "",
              "From the cut the improved updater had when the phase began, one naive and one "
              "improved update against the download-aware optimum (frames where the optimum "
              "reduces the error; trees up to "
              f"{UPDATE_OPTIMUM_NODES} nodes). *fill %*: the improved update with "
              "`fill=True` (a split that does not fit N or M is set aside for the frame and the "
              "next one tried, instead of ending the frame: with M = 8 or 16 against the 8 "
              "downloads of a full octree split, the paper's rule can make one split per frame "
              "at most, and none paired with a collapse when M = 8).", "",
              "| volume | brick | N, M | phase | input E | naive | improved | optimal | naive % | "
              "improved % | improved, fill % | frames (of sampled) | DP ms |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for v in results["volumes"]:
        for brick, t in v["trees"].items():
            r = t["run"]
            for phase, e in r["aggregate"].items():
                u = e.get("update")
                if not u:
                    continue
                fill_pct = ("-" if u.get("improved_fill_pct_of_optimal") is None
                            else f"{u['improved_fill_pct_of_optimal']:.1f}%")
                lines.append(
                    f"| {v['name']} | {brick}^3 | {r['N_small']}, {r['M_small']} | "
                    f"{phase.upper()} | {u['input']:.4f} | {u['naive']:.4f} | "
                    f"{u['improved']:.4f} | {u['optimal']:.4f} | "
                    f"{u['naive_pct_of_optimal']:.1f}% | {u['improved_pct_of_optimal']:.1f}% | "
                    f"{fill_pct} | {u['frames']} ({u['sampled']}) | {u['dp_ms']:.0f} |")
    lines += ["", "## Update and distortion times", "",
              "Greedy update per frame (re-prioritisation of S and C plus split-and-collapse), "
              "separately for the frames that move the interest point (PI) and those that edit "
              "the transfer function (TF: these include the repair and the hull's distortion "
              "from the histograms): median CPU time of the updating thread (robust on a loaded "
              "machine) and wall time. Distortion after a transfer-function edit on its own: the "
              "whole octree (parallel histogram sums; CPU time of both threads) against the "
              "hull.", "",
              "| volume | brick | nodes | N, M | PI update CPU ms naive / improved | PI wall "
              "(median / max) | TF update CPU ms naive / improved | D whole octree ms (wall / "
              "CPU) | D hull ms (wall / CPU, nodes) |", "|---|---|---|---|---|---|---|---|---|"]
    for v in results["volumes"]:
        for brick, t in v["trees"].items():
            r = t["run"]
            c, w = r["update_cpu_ms"], r["update_ms"]["improved_pi"]
            d = r["d_update_ms"]
            nan = {"median": float("nan")}
            df, dfc = d.get("full") or nan, d.get("full_cpu") or nan
            dh, dhc = d.get("hull") or nan, d.get("hull_cpu") or nan
            hn = d.get("hull_nodes") or {"median": 0}
            lines.append(
                f"| {v['name']} | {brick}^3 | {r['nodes']} | {r['N']}, {r['M']} | "
                f"{c['naive_pi']['median']:.2f} / {c['improved_pi']['median']:.2f} | "
                f"{w['median']:.2f} / {w['max']:.1f} | {c['naive_tf']['median']:.2f} / "
                f"{c['improved_tf']['median']:.2f} | {df['median']:.1f} / {dfc['median']:.1f} | "
                f"{dh['median']:.1f} / {dhc['median']:.1f} ({hn['median']:.0f}) |")
    lines += ["", "Targets from the paper: improved within 0.2% of optimal on average; improved "
              "88-94% of the optimal reduction per update; greedy update <= 4 ms per frame with "
              "N = 2560, M = 164; hull update < 40 ms.", ""]
    return "\n".join(lines)


def plot(results: dict, path: Path) -> bool:
    """E(cut) of the greedy cuts over the optimum per sampled frame (left) and the update CPU
    time per frame (right); False when matplotlib (the ``bench`` extra) is missing."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 4.5))
    labels, pi, tf = [], [], []
    for v in results["volumes"]:
        for brick, t in v["trees"].items():
            run = t["run"]
            name = f"{v['name']} {brick}^3 (N={run['N']})"
            rows = run["samples"]["pi"] + run["samples"]["tf"]
            if rows:
                colour = f"C{len(labels)}"
                for key, style in (("naive", ":"), ("improved", "-"), ("improved_fill", "--")):
                    if key not in rows[0]:
                        continue
                    ratio = [100 * (r[key] / r["optimal"] - 1) for r in rows]
                    left.plot(ratio, style, color=colour,
                              label=name if key == "improved" else None)
            labels.append(name)
            pi.append(run["update_cpu_ms"]["improved_pi"]["median"])
            tf.append(run["update_cpu_ms"]["improved_tf"]["median"])
    left.set_xlabel("sampled frame (interest point moves, then transfer-function edits)")
    left.set_ylabel("E(cut) above the optimum, %")
    left.set_title("Greedy selection vs optimum (dotted naive, solid improved, dashed fill)")
    left.legend(fontsize=7)
    x = np.arange(len(labels))
    right.bar(x - 0.2, pi, 0.4, label="interest point moves")
    right.bar(x + 0.2, tf, 0.4, label="transfer-function edits (repair + hull D)")
    right.axhline(4.0, color="k", lw=0.8, ls="--", label="paper: 4 ms")
    right.set_xticks(x, labels, rotation=30, ha="right", fontsize=7)
    right.set_ylabel("update CPU ms per frame (median)")
    right.set_title("Greedy split-and-collapse update (improved)")
    right.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help="MRI and 512^3 only, 20 + 20 frames, Table 2/3 every 10th frame")
    parser.add_argument("--json", type=Path, default=None, help="where to write the JSON")
    parser.add_argument("--volumes", default=None, help="comma list of mri, 512, 1024")
    parser.add_argument("--frames", type=int, default=None, help="frames per phase")
    parser.add_argument("--sample", type=int, default=None, help="Table 2/3 every n-th frame")
    parser.add_argument("--images", action="store_true",
                        help="only the image comparison (Fig. 9): error cut vs LOD cut")
    parser.add_argument("--replot", type=Path, default=None,
                        help="only redraw the plot from an existing JSON result")
    args = parser.parse_args(argv)
    if args.replot:
        results = json.loads(args.replot.read_text())
        print(plot(results, args.replot.with_name(args.replot.stem + "_frames.png")))
        return 0
    if args.images:
        return images_main(args, argv)
    names = (args.volumes.split(",") if args.volumes else
             (["mri", "512"] if args.quick else ["mri", "512", "1024"]))
    if "mri" in names and not MRI.exists():
        print(f"skipping the MRI: {MRI} not found", file=sys.stderr)
        names.remove("mri")
    frames = args.frames or (20 if args.quick else 100)
    sample = args.sample or 10
    stem = "cut_quick" if args.quick else "cut"
    json_path = args.json or HERE / "results" / f"{stem}.json"
    results = {"machine": describe(), "command": "python benchmarks/bench_cut.py "
               + " ".join(argv if argv is not None else sys.argv[1:]),
               "frames": 2 * frames, "sample": sample, "volumes": []}
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            print(f"[{name}] pyramid and histograms ...", file=sys.stderr, flush=True)
            vol = prepare(name, Path(tmp))
            entry = {k: vol[k] for k in ("name", "shape", "source_bytes", "load_s",
                                         "pyramid_s", "hist256_16") if k in vol}
            entry["trees"] = {}
            for brick, t in vol["trees"].items():
                print(f"[{name}] {brick}^3 bricks: {2 * frames} frames ...", file=sys.stderr,
                      flush=True)
                run = run_tree(name, brick, t["tree"], t["hist"], vol["tf"], frames, sample,
                               seed=brick)
                run["aggregate"] = aggregate(run)
                entry["trees"][brick] = {"table1": t["table1"], "run": run}
            results["volumes"].append(entry)
            del vol
    json_path.parent.mkdir(parents=True, exist_ok=True)
    json_path.write_text(json.dumps(results, indent=1, default=float) + "\n")
    md = markdown(results)
    png = json_path.with_name(json_path.stem + "_frames.png")
    if plot(results, png):
        md += f"\n![E(cut) over the optimum and update times]({png.name})\n"
    json_path.with_suffix(".md").write_text(md)
    print(md)
    return 0


# ------------------------------------------------------------------ Fig. 9: image comparison
#: Shares of the finest level's bricks that the cut's byte budget holds.
IMAGE_SHARES = (0.05, 0.15)


#: Cuts compared by ``--images``: the error cut with each priority, and the LOD cut.
IMAGE_POLICIES = ("naive", "improved", "lod")


def delta_e(reference: np.ndarray, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel ΔE*uv (CIELUV distance) and CIEDE2000 between two sRGB images (..., 3)."""
    from skimage.color import deltaE_ciede2000, rgb2lab

    from splinecast.multires.cut.colour import srgb_to_luv

    a = np.clip(reference, 0.0, 1.0)
    b = np.clip(image, 0.0, 1.0)
    luv = np.linalg.norm(srgb_to_luv(a) - srgb_to_luv(b), axis=-1)
    return luv, deltaE_ciede2000(rgb2lab(a), rgb2lab(b))


def _stats(values: np.ndarray) -> dict:
    return {"mean": float(values.mean()), "p95": float(np.percentile(values, 95)),
            "max": float(values.max())}


def image_volume(name: str, quick: bool, tmp: Path) -> tuple[sc.Volume, sc.TransferFunction]:
    if name == "mri":
        vol = sc.read(MRI)
        return vol, sc.TransferFunction.load(MRI_TF)
    n = int(name)
    data = synthetic(n, np.empty((n, n, n), np.uint8))
    return sc.Volume(data), SYNTH_TF


def compare_images(name: str, quick: bool, tmp: Path, png: Path | None) -> dict:
    """Full resolution, error cut and LOD cut at each budget share; ΔE statistics."""
    vol, tf = image_volume(name, quick, tmp)
    path = tmp / f"{name}.zarr"
    t0 = time.perf_counter()
    sc.build_pyramid(vol, path, brick=16, progress=False, histograms=True)
    build_s = time.perf_counter() - t0
    size = (256, 256) if quick else (512, 512)
    cam = sc.Camera.orbit(vol, azimuth=30, elevation=20, size=size)
    dvr = sc.DVRSettings(step=0.5)
    reference = sc.Scene(vol).render(cam, mode="dvr", tf=tf, dvr=dvr)  # compile
    t0 = time.perf_counter()
    reference = sc.Scene(vol).render(cam, mode="dvr", tf=tf, dvr=dvr)
    full_s = time.perf_counter() - t0
    covered = reference.rgba[..., 3] > 0.01
    mv = sc.read(path)
    from splinecast.multires.cut.octree import BrickOctree

    octree = BrickOctree(mv)
    finest = int(np.prod(octree.counts[0]))
    out = {"name": name, "shape": list(vol.shape), "size": list(size), "pyramid_s": build_s,
           "full_render_s": full_s, "finest_bricks": finest, "covered_pixels": int(covered.sum()),
           "budgets": []}
    panels = []
    for share in IMAGE_SHARES:
        row = {"share": share}
        # N full bricks (what ErrorCut.budget_bricks counts) in the cut's share of the budget.
        brick_bytes = int(max(octree.brick_bytes(level, np.zeros((1, 3), np.int64)).max()
                              for level in octree.levels))
        budget = int(max(1, round(share * finest)) * brick_bytes / 0.8)
        row["budget_bytes"] = budget
        for policy in IMAGE_POLICIES:
            t0 = time.perf_counter()
            options = ({"cut": "lod"} if policy == "lod" else
                       {"cut": "error", "cut_priority": policy})
            with sc.Scene(mv, budget=budget, lod=0.5, **options) as scene:
                open_s = time.perf_counter() - t0
                if scene.error_cut is not None:
                    row["histogram_build_ms"] = scene.error_cut.build_ms
                t0 = time.perf_counter()
                frame = scene.render(cam, mode="dvr", tf=tf, dvr=dvr, complete=True)
                render_s = time.perf_counter() - t0
                frames = 1
                # The error cut takes M bricks per frame: render until it is final.
                while not frame.stats.get("cut_final", True) and frames < 200:
                    frame = scene.render(cam, mode="dvr", tf=tf, dvr=dvr, complete=True)
                    frames += 1
            luv, de2000 = delta_e(reference.rgba[..., :3], frame.rgba[..., :3])
            st = frame.stats
            row[policy] = {"open_s": open_s, "render_complete_s": render_s, "frames": frames,
                           "cut_bricks": st["cut_bricks"], "cut_bytes": st["cut_bytes"],
                           "cut_levels": {str(k): v for k, v in st["cut_levels"].items()},
                           "complete": st["complete"],
                           "delta_e_uv": _stats(luv[covered]),
                           "delta_e_2000": _stats(de2000[covered])}
            if "cut_error" in st:
                row[policy]["cut_error"] = st["cut_error"]
            panels.append((share, policy, frame.rgba[..., :3], luv, float(luv[covered].mean())))
        out["budgets"].append(row)
        print(f"[{name}] share {share}: ΔE*uv " + ", ".join(
            f"{p} {row[p]['delta_e_uv']['mean']:.2f}" for p in IMAGE_POLICIES),
            file=sys.stderr, flush=True)
    if png is not None:
        _image_figure(name, reference.rgba[..., :3], panels, png)
        out["figure"] = png.name
    return out


def _image_figure(name: str, reference: np.ndarray, panels: list, png: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    shares = sorted({p[0] for p in panels})
    top = max(float(np.percentile(p[3], 99.5)) for p in panels) or 1.0
    cols = 1 + 2 * len(IMAGE_POLICIES)
    fig, axes = plt.subplots(len(shares), cols, figsize=(3 * cols, 3.2 * len(shares)),
                             squeeze=False)
    for r, share in enumerate(shares):
        row = {p[1]: p for p in panels if p[0] == share}
        images = [(reference, "full resolution")]
        images += [(row[p][2], f"{p} cut, {share:.0%} of finest bricks") for p in IMAGE_POLICIES]
        images += [(row[p][3], f"ΔE*uv {p} (mean {row[p][4]:.2f})") for p in IMAGE_POLICIES]
        for c, (img, title) in enumerate(images):
            ax = axes[r, c]
            if img.ndim == 3:
                ax.imshow(np.clip(img, 0, 1))
            else:
                shown = ax.imshow(img, cmap="magma", vmin=0, vmax=top)
                if c == cols - 1:
                    fig.colorbar(shown, ax=ax, fraction=0.046)
            ax.set_title(title, fontsize=9)
            ax.axis("off")
    fig.suptitle(f"{name}: DVR at the same memory budget (ΔE*uv per pixel, CIELUV; means over "
                 "the pixels the full-resolution image covers)")
    fig.tight_layout()
    fig.savefig(png, dpi=80)
    plt.close(fig)


def images_markdown(results: dict) -> str:
    m = results["machine"]
    lines = ["# Images at the same memory budget: naive and improved error cuts vs the "
             "level-of-detail cut (Carmona & Froehlich 2011, Fig. 9)", "",
             f"Machine: {m['cpu']}, {m['cores']} logical cores (shared with other jobs: times "
             f"are noisy). Command: `{results['command']}`.", "",
             "DVR (trilinear, step 0.5 voxel) of the multiresolution renderer, 16^3 bricks, "
             "the cut's budget a share of the finest level's bricks (full bricks with ghosts; "
             "the cache's budget is 1/0.8 of it), against the in-memory full-resolution image. "
             "ΔE over the pixels the full-resolution image covers (alpha > 1%). Error cuts: "
             "*naive* (P = E) and *improved* (P = ER) priority (`Scene(..., cut=\"error\", "
             "cut_priority=...)`), importance from the eye, no point of interest, frustum "
             "culling, histograms stored with the pyramid. The paper's Fig. 9 (Angio, one "
             "update): naive 9.834, improved 7.975 mean ΔE. "
             "LOD cut: lod = 0.5 pixel, refined largest-on-screen first while the budget "
             "allows.", "",
             "| volume | image | share | budget MiB | cut | bricks | levels | ΔE*uv mean | "
             "ΔE*uv p95 | ΔE2000 mean | ΔE2000 p95 | complete render s |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for v in results["volumes"]:
        for row in v["budgets"]:
            for policy in IMAGE_POLICIES:
                r = row[policy]
                levels = ", ".join(f"{k}: {n}" for k, n in sorted(r["cut_levels"].items()))
                lines.append(
                    f"| {v['name']} {tuple(v['shape'])} | {v['size'][0]}x{v['size'][1]} | "
                    f"{row['share']:.0%} | {row['budget_bytes'] / 2**20:.1f} | {policy} | "
                    f"{r['cut_bricks']} | {levels} | {r['delta_e_uv']['mean']:.2f} | "
                    f"{r['delta_e_uv']['p95']:.2f} | {r['delta_e_2000']['mean']:.2f} | "
                    f"{r['delta_e_2000']['p95']:.2f} | {r['render_complete_s']:.1f} |")
    lines.append("")
    for v in results["volumes"]:
        if "figure" in v:
            lines += [f"![{v['name']}: images and ΔE maps]({v['figure']})", ""]
    lines.append("Error cut set-up when the scene opens (histograms read from the store): "
                 + ", ".join(f"{v['name']} {v['budgets'][0]['histogram_build_ms'] / 1e3:.2f} s"
                             for v in results["volumes"]) + ".")
    lines += ["", "Mean ΔE*uv, naive vs improved (same budget): " + "; ".join(
        f"{v['name']} {row['share']:.0%}: {row['naive']['delta_e_uv']['mean']:.2f} vs "
        f"{row['improved']['delta_e_uv']['mean']:.2f}"
        for v in results["volumes"] for row in v["budgets"]) + "."]
    return "\n".join(lines) + "\n"


def images_main(args: argparse.Namespace, argv: list[str] | None) -> int:
    names = (args.volumes.split(",") if args.volumes else ["mri", "128" if args.quick else "256"])
    if "mri" in names and not MRI.exists():
        print(f"skipping the MRI: {MRI} not found", file=sys.stderr)
        names.remove("mri")
    stem = "cut_images_quick" if args.quick else "cut_images"
    json_path = args.json or HERE / "results" / f"{stem}.json"
    json_path.parent.mkdir(parents=True, exist_ok=True)
    results = {"machine": describe(), "command": "python benchmarks/bench_cut.py "
               + " ".join(argv if argv is not None else sys.argv[1:]), "volumes": []}
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            png = json_path.with_name(f"{stem}_{name}.png")
            results["volumes"].append(compare_images(name, args.quick, Path(tmp), png))
    json_path.write_text(json.dumps(results, indent=1, default=float) + "\n")
    md = images_markdown(results)
    json_path.with_suffix(".md").write_text(md)
    print(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
