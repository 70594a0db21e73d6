"""Sort-first scale-out on Dask: scaling from 1 to 2 single-threaded workers, overhead
against the local 2-thread render, and a projection to a 64-worker cluster.

On a LocalCluster of single-threaded worker processes (``splinecast.distributed.local_cluster``,
Dask's background polling turned down; ``bench_movie_overhead.py`` measures what that changes),
after warm-up (scene prepared on every
worker, kernels loaded), medians of repeated runs, interleaved (1 worker, 2 workers, local) so a
change in the machine's load hits all three alike:

* a movie: ``F`` frames of a turntable rendered as one batch (``render_many``, 8-bit images
  back, as ``splinecast movie`` does) on 1 and 2 workers (target >= 1.8x), and locally in this
  process on 2 Numba threads (``render_locally``; distributed/local target <= 1.25x);
* one large frame by tiles (``DistributedScene.render``, every buffer of the Frame back; only
  colour and depth with ``outputs=("rgba", "depth")``, what compositing needs; and with
  ``image_only=True`` just the 8-bit image) on 1 and 2 workers (target >= 1.6x), and
  ``Scene.render`` locally on 2 threads with the same outputs;
* the parameters of a simple cost model: per-task overhead (a batch of empty tasks), client
  transfer rate (gathering a 16 MiB result), single-thread render times, and the cost of one
  compositing step (an "over" of two full-size premultiplied RGBA float32 images with depth,
  in numpy: what sort-last will do per reduction level).

From these it projects 1..64 workers (table in the results): a movie costs
``F * t_frame / W + F * (t_task + bytes_frame / B)`` (the client handles every frame), a frame by
tiles ``t_frame / W + 4 W * t_task + bytes_frame / B`` (about four tiles per worker, every byte
reaches the client), and a sort-last frame ``t_frame / W + log2(W) * (t_over + bytes_image / B)``.

Sort-last part (``--part sort-last``; results in ``distributed_sort_last_quick.*`` or
``distributed_sort_last_SIZE_levelL_Npx.*``): a
pyramid of the Marschner-Lobb signal (``--sort-last-size`` voxels per axis, float32, bricks of 32;
built once into ``--pyramid-dir``) rendered at one level by ``SortLastScene`` on 2
single-threaded workers, per mode (iso, MIP, DVR): wall time against the in-memory render of the
same level on 2 local threads, time in the shares' traces, in the merges (``combine`` tasks) and
in the final task, bytes of the partial images merged, bytes actually moved between the workers
(their Dask transfer logs) and bytes sent to the client; plus one merge of two full-image states
timed in this process. The 64-worker table for sort-last uses these measured numbers:
``t_trace / W + log2(W) * (t_task + t_merge + bytes_partial / B) + t_finish + bytes_frame / B``
(full-image partial images at every level: an upper bound, since a share's image shrinks as
the shares get smaller).

Run ``python benchmarks/bench_distributed.py [--quick] [--part all|sort-first|sort-last]``;
results go to ``benchmarks/results/distributed[_quick].json`` and ``.md`` (sort-first) and
``distributed_sort_last_*`` (sort-last).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import time
from pathlib import Path

import numba
import numpy as np

import splinecast as sc
from splinecast.distributed import DistributedScene, orbit_path, render_locally

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _machine import describe  # noqa: E402

HERE = Path(__file__).resolve().parent
WORKER_COUNTS = (1, 2, 4, 8, 16, 32, 64)


def timed(fn) -> float:
    start = time.perf_counter()
    fn()
    return time.perf_counter() - start


def _noop(i: int) -> int:
    return i


def _payload(nbytes: int) -> np.ndarray:
    return np.ones(nbytes, np.uint8)


def task_overhead(client, count: int) -> float:
    """Seconds per task of a batch of empty tasks (scheduler, worker and client costs)."""
    client.gather(client.map(_noop, range(count), pure=False))  # warm
    return timed(lambda: client.gather(client.map(_noop, range(count), pure=False))) / count


def transfer_rate(client, nbytes: int = 16 << 20, repeats: int = 3) -> float:
    """Bytes per second from a worker to the client (the result is computed first, then
    fetched and timed)."""
    from distributed import wait

    times = []
    for _ in range(repeats):
        future = client.submit(_payload, nbytes, pure=False)
        wait(future)
        times.append(timed(future.result))
    return nbytes / statistics.median(times)


def over_step(width: int, height: int, repeats: int) -> float:
    """Seconds of one compositing step of two full-size partial images (premultiplied RGBA
    float32 plus depth): nearer one over farther one, per pixel."""
    rng = np.random.default_rng(0)
    a, b = (rng.random((height, width, 4), np.float32) for _ in range(2))
    da, db = (rng.random((height, width), np.float32) for _ in range(2))

    def step():
        front = (da <= db)[..., None]
        near, far = np.where(front, a, b), np.where(front, b, a)
        return near + far * (1.0 - near[..., 3:4]), np.minimum(da, db)

    step()
    return statistics.median(timed(step) for _ in range(repeats))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes, a few repeats")
    parser.add_argument("--part", choices=("all", "sort-first", "sort-last", "markdown"),
                        default="all",
                        help="markdown: rewrite distributed.md from the saved .json files")
    parser.add_argument("--sort-last-size", type=int, default=None,
                        help="voxels per axis of the sort-last pyramid (default 512; quick 129)")
    parser.add_argument("--sort-last-level", type=int, default=0)
    parser.add_argument("--sort-last-image", default=None,
                        help="image side, or WxH, of the sort-last renders (default 1024; "
                             "quick 256)")
    parser.add_argument("--sort-last-repeats", type=int, default=3)
    parser.add_argument("--sort-first-repeats", type=int, default=None,
                        help="interleaved runs of the sort-first part (default 5; quick 3)")
    parser.add_argument("--sort-last-modes", default="iso,mip,dvr",
                        help="comma-separated modes of the sort-last part")
    parser.add_argument("--pyramid-dir", default="/tmp/splinecast-bench-pyramids")
    args = parser.parse_args()
    if args.part in ("all", "sort-first"):
        sort_first(args)
    if args.part in ("all", "sort-last"):
        sort_last(args)
    if args.part == "markdown":
        out = HERE / "results"
        result = json.loads((out / "distributed.json").read_text())
        (out / "distributed.md").write_text(markdown(result))


def sort_first(args: argparse.Namespace) -> None:
    from distributed import Client

    from splinecast.distributed import local_cluster

    if args.quick:
        source, iso, frames, movie_size, big, repeats = (
            "demo:marschner-lobb?size=64", 0.5, 24, (256, 256), (1024, 1024), 3)
    else:
        source, iso, frames, movie_size, big, repeats = (
            "demo:marschner-lobb?size=128", 0.5, 120, (512, 512), (2048, 2048), 5)
    repeats = args.sort_first_repeats or repeats
    load_before = os.getloadavg()
    volume = sc.read(source)
    scene = sc.Scene(volume)
    path = orbit_path(volume, frames, size=movie_size)
    big_cam = sc.Camera.orbit(volume, azimuth=40, elevation=25, size=big)
    scene.render(big_cam, iso=iso)  # compile / load kernels before the workers start
    scene.render(big_cam, iso=iso, outputs=("rgba", "depth"))  # the variant without counters

    clusters = {n: local_cluster(n) for n in (1, 2)}
    clients = {n: Client(c) for n, c in clusters.items()}
    try:
        scenes = {n: DistributedScene(source, c) for n, c in clients.items()}
        for ds in scenes.values():  # warm-up: kernels loaded, tables built on every worker
            list(ds.render_many(path[:4], iso=iso, image_only=True))
            ds.render(big_cam, iso=iso)
            ds.render(big_cam, iso=iso, outputs=("rgba", "depth"))

        runs: dict[str, list[float]] = {k: [] for k in (
            "movie_1w", "movie_2w", "movie_local2", "frame_1w", "frame_2w", "frame_local2",
            "image_1w", "image_2w", "image_local2", "rgbd_1w", "rgbd_2w", "rgbd_local2",
            "frame_local1", "movie_frame_local1")}
        rgbd = ("rgba", "depth")
        threads = numba.get_num_threads()
        for _ in range(repeats):
            for n in (1, 2):
                runs[f"movie_{n}w"].append(timed(lambda n=n: list(
                    scenes[n].render_many(path, iso=iso, image_only=True))))
                runs[f"frame_{n}w"].append(timed(lambda n=n: scenes[n].render(big_cam,
                                                                              iso=iso)))
                runs[f"image_{n}w"].append(timed(lambda n=n: scenes[n].render(
                    big_cam, iso=iso, image_only=True)))
                runs[f"rgbd_{n}w"].append(timed(lambda n=n: scenes[n].render(
                    big_cam, iso=iso, outputs=rgbd)))
            runs["movie_local2"].append(timed(lambda: list(
                render_locally(scene, sc.distributed.as_shots(path, iso=iso),
                               image_only=True))))
            runs["frame_local2"].append(timed(lambda: scene.render(big_cam, iso=iso)))
            runs["image_local2"].append(timed(lambda: scene.render(
                big_cam, iso=iso, outputs=("rgba",)).to_uint8()))
            runs["rgbd_local2"].append(timed(lambda: scene.render(big_cam, iso=iso,
                                                                  outputs=rgbd)))
            numba.set_num_threads(1)
            runs["frame_local1"].append(timed(lambda: scene.render(big_cam, iso=iso)))
            runs["movie_frame_local1"].append(timed(lambda: scene.render(path[0], iso=iso)))
            numba.set_num_threads(threads)
        med = {k: statistics.median(v) for k, v in runs.items()}
        tiles_2w = scenes[2].render(big_cam, iso=iso).stats["tiles"]
        t_task = task_overhead(clients[2], 400)
        rate = transfer_rate(clients[2])
    finally:
        for c in clients.values():
            c.close()
        for c in clusters.values():
            c.close()
    t_over = over_step(*big, repeats)

    frame = scene.render(big_cam, iso=iso)
    frame_bytes = sum(getattr(frame, n).nbytes for n in (
        "rgba", "depth", "position", "normal", "face", "cells_visited", "cells_tested",
        "blocks_skipped"))
    movie_image_bytes = movie_size[0] * movie_size[1] * 4
    partial_bytes = big[0] * big[1] * (16 + 4)  # RGBA float32 + float32 depth
    t_frame1 = med["frame_local1"]
    t_movie_frame1 = med["movie_frame_local1"]
    projection = []
    for w in WORKER_COUNTS:
        movie = frames * t_movie_frame1 / w + frames * (t_task + movie_image_bytes / rate)
        tiles = t_frame1 / w + 4 * w * t_task + frame_bytes / rate
        sort_last = t_frame1 / w + math.log2(w) * (t_over + partial_bytes / rate)
        projection.append({
            "workers": w, "movie_s": movie, "movie_fps": frames / movie,
            "movie_speedup": (frames * (t_movie_frame1 + t_task + movie_image_bytes / rate))
            / movie, "tiles_frame_s": tiles, "tiles_speedup": (t_frame1 + frame_bytes / rate)
            / tiles, "sort_last_frame_s": sort_last, "sort_last_speedup": t_frame1 / sort_last,
        })
    result = {
        "machine": describe(),
        "load_average_before": load_before,
        "load_average_after": os.getloadavg(),
        "command": "python benchmarks/bench_distributed.py" + (" --quick" if args.quick else "")
                   + (f" --part {args.part}" if args.part != "all" else "")
                   + (f" --sort-first-repeats {repeats}" if args.sort_first_repeats else ""),
        "cluster": "splinecast.distributed.local_cluster",
        "source": source, "iso": iso, "frames": frames, "movie_size": movie_size,
        "frame_size": big, "repeats": repeats, "tiles_on_2_workers": tiles_2w,
        "runs_s": runs, "median_s": med,
        "movie_speedup_1_to_2": med["movie_1w"] / med["movie_2w"],
        "frame_speedup_1_to_2": med["frame_1w"] / med["frame_2w"],
        "image_speedup_1_to_2": med["image_1w"] / med["image_2w"],
        "image_overhead_vs_local": med["image_2w"] / med["image_local2"],
        "rgbd_speedup_1_to_2": med["rgbd_1w"] / med["rgbd_2w"],
        "rgbd_overhead_vs_local": med["rgbd_2w"] / med["rgbd_local2"],
        "movie_overhead_vs_local": med["movie_2w"] / med["movie_local2"],
        "frame_overhead_vs_local": med["frame_2w"] / med["frame_local2"],
        "model": {"task_overhead_s": t_task, "transfer_bytes_per_s": rate,
                  "over_step_s": t_over, "frame_bytes": frame_bytes,
                  "movie_image_bytes": movie_image_bytes, "partial_image_bytes": partial_bytes,
                  "frame_1thread_s": t_frame1, "movie_frame_1thread_s": t_movie_frame1},
        "projection": projection,
    }
    stem = "distributed_quick" if args.quick else "distributed"
    out = HERE / "results"
    out.mkdir(exist_ok=True)
    (out / f"{stem}.json").write_text(json.dumps(result, indent=1))
    (out / f"{stem}.md").write_text(markdown(result))
    print(markdown(result))


# --------------------------------------------------------------------------- sort-last
SORT_LAST_MODES = ("iso", "mip", "dvr")


def _moved_between_workers(dask_worker) -> int:
    """Bytes this worker received from other workers so far (its Dask transfer log)."""
    return int(sum(entry.get("total", 0) for entry in dask_worker.transfer_incoming_log))


def _pyramid(size: int, folder: Path) -> Path:
    """The Marschner-Lobb pyramid of ``size``^3 float32 voxels (built once)."""
    path = folder / f"marschner-lobb-{size}.zarr"
    if not path.exists():
        folder.mkdir(parents=True, exist_ok=True)
        start = time.perf_counter()
        volume = sc.demo("marschner-lobb", size=size)
        sc.build_pyramid(volume, path, brick=32, progress=True)
        print(f"built {path} in {time.perf_counter() - start:.0f} s", file=sys.stderr)
    return path


def _sort_last_options(mode: str) -> dict:
    tf = sc.TransferFunction([(0.3, 0.0), (0.5, 0.3), (0.8, 0.6)], domain=(0.0, 1.0))
    return {"iso": {"iso": 0.5}, "mip": {"mode": "mip", "window": (0.0, 1.0)},
            "dvr": {"mode": "dvr", "tf": tf, "dvr": sc.DVRSettings(step=0.5)}}[mode]


def merge_step(level_volume: sc.Volume, camera: sc.Camera, mode: str, repeats: int) -> dict:
    """One merge of two full-image partial states of ``mode``, in this process (1 thread)."""
    from splinecast.distributed.sort_last import prepare_request
    from splinecast.distributed.source import VolumeInfo
    from splinecast.render.segment import combine_states, new_state

    setup = prepare_request(VolumeInfo.of(level_volume), camera, _sort_last_options(mode)).setup
    front, back = new_state(setup, camera), new_state(setup, camera)
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        combine_states(setup, front, back)
        t = statistics.median(timed(lambda: combine_states(setup, front, back))
                              for _ in range(repeats))
    finally:
        numba.set_num_threads(threads)
    return {"merge_s": t, "state_bytes": int(sum(a.nbytes for a in front))}


def sort_last(args: argparse.Namespace) -> None:
    from distributed import Client

    from splinecast.distributed import DistributedScene, local_cluster

    size = args.sort_last_size or (129 if args.quick else 512)
    side = args.sort_last_image or str(256 if args.quick else 1024)
    w, _, h = side.lower().partition("x")
    image = (int(w), int(h or w))
    repeats = args.sort_last_repeats
    modes = [m for m in args.sort_last_modes.split(",") if m]
    if not set(modes) <= set(SORT_LAST_MODES):
        raise SystemExit(f"--sort-last-modes: choose from {', '.join(SORT_LAST_MODES)}")
    level = args.sort_last_level
    load_before = os.getloadavg()
    path = _pyramid(size, Path(args.pyramid_dir))
    store = sc.read(path)
    level_volume = store.level(level).to_volume()
    camera = sc.Camera.orbit(level_volume, azimuth=40, elevation=25, size=image)
    local = sc.Scene(level_volume)
    for mode in modes:  # compile / load the kernels before the workers start
        local.render(sc.Camera.orbit(level_volume, size=(16, 16)), **_sort_last_options(mode))
    merges = {mode: merge_step(level_volume, camera, mode, repeats) for mode in modes}
    cluster = local_cluster(2)
    client = Client(cluster)
    rows = {}
    try:
        start = time.perf_counter()
        scene = DistributedScene(path, client, strategy="sort-last", level=level)
        open_s = time.perf_counter() - start
        for mode in modes:
            options = _sort_last_options(mode)
            small = sc.Camera.orbit(level_volume, azimuth=40, elevation=25, size=(32, 32))
            scene.render(small, **options)  # warm-up: kernels loaded on the workers
            local.render(small, **options)
            runs: dict[str, list[float]] = {k: [] for k in (
                "sort_last_s", "local_2threads_s", "share_trace_max_s", "share_trace_sum_s",
                "merge_tasks_s", "finish_s", "moved_bytes", "dvr_depth_refine_s")}
            for _ in range(repeats):
                before = sum(client.run(_moved_between_workers).values())
                frame = None

                def render(options=options):
                    nonlocal frame
                    frame = scene.render(camera, **options)

                runs["sort_last_s"].append(timed(render))
                runs["moved_bytes"].append(sum(client.run(_moved_between_workers).values())
                                           - before)
                st = frame.stats
                runs["share_trace_max_s"].append(st["share_trace_ms_max"] / 1e3)
                runs["share_trace_sum_s"].append(st["share_trace_ms_sum"] / 1e3)
                runs["merge_tasks_s"].append(st["composite_ms"] / 1e3)
                runs["finish_s"].append(st["finish_ms"] / 1e3)
                runs["dvr_depth_refine_s"].append(st.get("depth_refine_ms", 0.0) / 1e3)
                runs["local_2threads_s"].append(timed(lambda options=options: local.render(
                    camera, **options)))
            rows[mode] = {"runs": runs,
                          "median": {k: statistics.median(v) for k, v in runs.items()},
                          "partial_bytes": frame.stats["partial_bytes"],
                          "frame_bytes": frame.stats["frame_bytes"],
                          "merge_in_process_s": merges[mode]["merge_s"],
                          "full_state_bytes": merges[mode]["state_bytes"]}
        t_task = task_overhead(client, 200)
        rate = transfer_rate(client)
        loads = scene.load_stats
        shares = [{"lo": s.lo, "hi": s.hi, "bricks": s.n_bricks} for s in scene.shares]
    finally:
        client.close()
        cluster.close()
    projection = []
    for w in WORKER_COUNTS:
        row = {"workers": w}
        for mode, r in rows.items():
            m = r["median"]
            merge = t_task + r["merge_in_process_s"] + r["full_state_bytes"] / rate
            t = (m["share_trace_sum_s"] / w + math.log2(w) * merge + m["finish_s"]
                 + r["frame_bytes"] / rate)
            row[f"{mode}_s"] = t
            row[f"{mode}_speedup"] = (m["share_trace_sum_s"] + m["finish_s"]
                                      + r["frame_bytes"] / rate) / t
            row[f"{mode}_merge_levels_s"] = math.log2(w) * merge
            row[f"{mode}_moved_bytes_max"] = (w - 1) * r["full_state_bytes"]
        projection.append(row)
    result = {
        "machine": describe(), "load_average_before": load_before,
        "load_average_after": os.getloadavg(),
        "command": "python benchmarks/bench_distributed.py --part sort-last"
                   + (" --quick" if args.quick else "")
                   + (f" --sort-last-size {size}" if args.sort_last_size else "")
                   + (f" --sort-last-level {level}" if level else "")
                   + (f" --sort-last-image {side}" if args.sort_last_image else "")
                   + (f" --sort-last-repeats {repeats}" if repeats != 3 else "")
                   + (f" --sort-last-modes {args.sort_last_modes}"
                      if modes != list(SORT_LAST_MODES) else ""),
        "pyramid": str(path), "size": size, "level": level,
        "level_shape": list(level_volume.shape), "image": image, "repeats": repeats,
        "open_s": open_s, "loads": loads, "shares": shares, "modes": rows,
        "model": {"task_overhead_s": t_task, "transfer_bytes_per_s": rate},
        "projection": projection,
    }
    stem = ("distributed_sort_last_quick" if args.quick else
            f"distributed_sort_last_{size}_level{level}_{side.lower()}px")
    if modes != list(SORT_LAST_MODES):
        stem += "_" + "-".join(modes)
    out = HERE / "results"
    out.mkdir(exist_ok=True)
    (out / f"{stem}.json").write_text(json.dumps(result, indent=1, default=str))
    (out / f"{stem}.md").write_text(markdown_sort_last(result))
    print(markdown_sort_last(result))


def markdown_sort_last(r: dict) -> str:
    m = r["machine"]
    w, h = r["image"]
    mib = 2 ** 20
    bytes_read = sum(x["bytes_read"] for x in r["loads"])
    lines = [
        "# Distributed benchmark: sort-last on Dask",
        "",
        f"Machine: {m['cpu']}, {m['cores']} cores, numba {m['versions']['numba']}, load "
        f"average {r['load_average_before'][0]:.1f} before / {r['load_average_after'][0]:.1f} "
        f"after (a shared machine: other jobs ran meanwhile, timings are noisy). Command: "
        f"`{r['command']}`. Pyramid of Marschner-Lobb {r['size']}^3 float32 (bricks of 32), "
        f"level {r['level']} ({'x'.join(map(str, r['level_shape']))}), trilinear, image {w}x{h}. "
        f"LocalCluster of 2 single-threaded worker processes, {len(r['shares'])} shares "
        f"({', '.join(str(s['bricks']) for s in r['shares'])} bricks); opening the scene (each "
        f"worker reads its bricks, {bytes_read / mib:.0f} MiB with ghosts in all) took "
        f"{r['open_s']:.1f} s. Medians of {r['repeats']} runs after warm-up.",
        "",
        "| mode | sort-last 2 workers s | local 2 threads s | shares' traces max / sum s | "
        "merge tasks s | final task s | one merge in process s | partial images in merges + "
        "final task MiB | moved between workers MiB | sent to client MiB |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for mode, row in r["modes"].items():
        md = row["median"]
        lines.append(
            f"| {mode} | {md['sort_last_s']:.2f} | {md['local_2threads_s']:.2f} | "
            f"{md['share_trace_max_s']:.2f} / {md['share_trace_sum_s']:.2f} | "
            f"{md['merge_tasks_s']:.3f} | {md['finish_s']:.3f} | "
            f"{row['merge_in_process_s']:.3f} | {row['partial_bytes'] / mib:.1f} | "
            f"{md['moved_bytes'] / mib:.1f} | {row['frame_bytes'] / mib:.1f} |")
    mo = r["model"]
    dvr = r["modes"].get("dvr", {}).get("median", {})
    if "dvr_depth_refine_s" in dvr:
        lines += ["", f"DVR depth: the shares' second trace of the pixels whose opacity passes "
                  f"1/2 behind another share took {dvr['dvr_depth_refine_s']:.2f} s in all "
                  f"(included in the sort-last time)."]
    lines += [
        "",
        f"Per-task overhead {mo['task_overhead_s'] * 1e3:.1f} ms (200 empty tasks), worker -> "
        f"client transfer {mo['transfer_bytes_per_s'] / mib:.0f} MiB/s. A full-image partial "
        f"state is " + ", ".join(f"{mode} {row['full_state_bytes'] / mib:.1f} MiB"
                                   for mode, row in r["modes"].items()) + ".",
        "",
        "Projection to W single-threaded workers (model in the module docstring: traces split "
        "W ways, log2 W merge levels of task overhead + one measured merge + one full-image "
        "partial state moved, then the final task and the frame to the client; 'moved' is the "
        "most the merges move in all, (W - 1) full-image states):",
        "",
        "| workers | " + " | ".join(f"{m_} frame s | {m_} speed-up | {m_} merge levels s | "
                                    f"{m_} moved MiB" for m_ in r["modes"]) + " |",
        "|---|" + "---|---|---|---|" * len(r["modes"]),
    ]
    for p in r["projection"]:
        lines.append(f"| {p['workers']} | " + " | ".join(
            f"{p[f'{m_}_s']:.3f} | {p[f'{m_}_speedup']:.1f}x | {p[f'{m_}_merge_levels_s']:.3f} | "
            f"{p[f'{m_}_moved_bytes_max'] / mib:.0f}" for m_ in r["modes"]) + " |")
    lines.append("")
    return "\n".join(lines)


def markdown(r: dict) -> str:
    m, med, mo = r["machine"], r["median_s"], r["model"]
    (mw, mh), (fw, fh) = r["movie_size"], r["frame_size"]
    lines = [
        "# Distributed benchmark: sort-first on Dask",
        "",
        f"Machine: {m['cpu']}, {m['cores']} cores, numba {m['versions']['numba']}, load "
        f"average {r['load_average_before'][0]:.1f} before / {r['load_average_after'][0]:.1f} "
        f"after (a shared machine: other jobs ran meanwhile). Command: `{r['command']}`. "
        f"Volume `{r['source']}`, iso {r['iso']}, trilinear. LocalCluster of single-threaded "
        f"worker processes; medians of {r['repeats']} interleaved runs after warm-up.",
        "",
        "| what | 1 worker s | 2 workers s | local 2 threads s | speed-up 1 -> 2 (target) | "
        "2 workers / local (target <= 1.25) |",
        "|---|---|---|---|---|---|",
        f"| movie, {r['frames']} frames {mw}x{mh} (8-bit images back) | {med['movie_1w']:.2f} "
        f"| {med['movie_2w']:.2f} | {med['movie_local2']:.2f} | "
        f"{r['movie_speedup_1_to_2']:.2f}x (>= 1.8) | {r['movie_overhead_vs_local']:.2f}x |",
        f"| one frame {fw}x{fh} by tiles ({r['tiles_on_2_workers']} tiles on 2 workers; "
        f"whole Frame back) | {med['frame_1w']:.2f} | {med['frame_2w']:.2f} | "
        f"{med['frame_local2']:.2f} | {r['frame_speedup_1_to_2']:.2f}x (>= 1.6) | "
        f"{r['frame_overhead_vs_local']:.2f}x |",
        f"| the same frame, 8-bit image only (`image_only=True`) | {med['image_1w']:.2f} | "
        f"{med['image_2w']:.2f} | {med['image_local2']:.2f} | "
        f"{r['image_speedup_1_to_2']:.2f}x (>= 1.6) | {r['image_overhead_vs_local']:.2f}x |",
        *([f"| the same frame, colour and depth only (`outputs=(\"rgba\", \"depth\")`) | "
           f"{med['rgbd_1w']:.2f} | {med['rgbd_2w']:.2f} | {med['rgbd_local2']:.2f} | "
           f"{r['rgbd_speedup_1_to_2']:.2f}x (>= 1.6) | {r['rgbd_overhead_vs_local']:.2f}x |"]
          if "rgbd_1w" in med else []),
        "",
        "Model parameters (measured in the same run): per-task overhead "
        f"{mo['task_overhead_s'] * 1e3:.2f} ms (400 empty tasks on 2 workers), worker -> "
        f"client transfer {mo['transfer_bytes_per_s'] / 2**20:.0f} MiB/s, one compositing "
        f"step of two {fw}x{fh} RGBA float32 + depth images {mo['over_step_s'] * 1e3:.0f} ms "
        f"(numpy), Frame buffers {mo['frame_bytes'] / 2**20:.0f} MiB, single-thread render "
        f"{mo['frame_1thread_s']:.2f} s ({fw}x{fh}) and {mo['movie_frame_1thread_s'] * 1e3:.0f}"
        f" ms ({mw}x{mh}).",
        "",
        "Projection to larger clusters (single-threaded workers, model in the module "
        "docstring; the sort-last column uses a numpy 'over' as the merge, the sort-last "
        "results files `distributed_sort_last_*.md` project from measured merges):",
        "",
        "| workers | movie s | movie frames/s | movie speed-up | tiled frame s | tiled "
        "speed-up | sort-last frame s | sort-last speed-up |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for p in r["projection"]:
        lines.append(
            f"| {p['workers']} | {p['movie_s']:.2f} | {p['movie_fps']:.1f} | "
            f"{p['movie_speedup']:.1f}x | {p['tiles_frame_s']:.3f} | {p['tiles_speedup']:.1f}x "
            f"| {p['sort_last_frame_s']:.3f} | {p['sort_last_speedup']:.1f}x |")
    lines.append("")
    if "cluster" not in r:  # measured before local_cluster existed
        lines[2:2] = [
            "These sort-first numbers were measured on a default `LocalCluster`, before "
            "`splinecast.distributed.local_cluster` (Dask's background polling turned down) "
            "existed; `distributed_movie_overhead.md` measures what that changes for the movie.",
            ""]
    lines += sort_last_section(HERE / "results", mo)
    return "\n".join(lines)


def sort_last_section(folder: Path, quiet_model: dict | None = None) -> list[str]:
    """The measured sort-last runs of the 1024^3 pyramid (``distributed_sort_last_1024_*``):
    cost and bytes per frame, and their projection to 64 workers, as markdown lines."""
    runs = [json.loads(p.read_text())
            for p in sorted(folder.glob("distributed_sort_last_1024_*.json"))]
    if not runs:
        return []
    mib = 2**20
    lines = ["## Sort-last, 1024^3 pyramid", ""]
    for r in runs:
        w, h = r["image"]
        lines += [
            f"Measured by `{r['command']}` (results "
            f"`distributed_sort_last_1024_level{r['level']}_*`): Marschner-Lobb 1024^3 float32 "
            f"pyramid, level {r['level']} ({'x'.join(map(str, r['level_shape']))}) rendered "
            f"at {w}x{h} by 2 single-threaded workers (load average "
            f"{r['load_average_before'][0]:.0f} before / {r['load_average_after'][0]:.0f} after: "
            "a heavily shared machine, so the traces' times are inflated; the merge and byte "
            "counts are not). Per frame:",
            "",
            "| mode | sort-last 2 workers s | shares' traces sum s | merge tasks s | final task "
            "s | one merge in process s | partial images merged MiB | moved between workers MiB "
            "| sent to client MiB |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for mode, row in r["modes"].items():
            md = row["median"]
            lines.append(
                f"| {mode} | {md['sort_last_s']:.2f} | {md['share_trace_sum_s']:.2f} | "
                f"{md['merge_tasks_s']:.3f} | {md['finish_s']:.3f} | "
                f"{row['merge_in_process_s']:.3f} | {row['partial_bytes'] / mib:.1f} | "
                f"{md['moved_bytes'] / mib:.1f} | {row['frame_bytes'] / mib:.1f} |")
        modes = list(r["modes"])
        lines += [
            "",
            "Projection to W workers (the sort-last model of the module docstring, from these "
            "measurements: traces split W ways, log2 W merge levels each of one task, one "
            "measured merge and one full-image partial state moved; 'moved' is the most all "
            "merges move, (W - 1) full-image states):",
            "",
            "| workers | " + " | ".join(f"{m} frame s | {m} speed-up | {m} moved MiB"
                                        for m in modes) + " |",
            "|---|" + "---|---|---|" * len(modes),
        ]
        for p in r["projection"]:
            lines.append(f"| {p['workers']} | " + " | ".join(
                f"{p[f'{m}_s']:.3f} | {p[f'{m}_speedup']:.1f}x | "
                f"{p[f'{m}_moved_bytes_max'] / mib:.0f}" for m in modes) + " |")
        lines.append("")
        if quiet_model:
            t_task, rate = quiet_model["task_overhead_s"], quiet_model["transfer_bytes_per_s"]
            lines += [
                f"The run above measured a per-task overhead of "
                f"{r['model']['task_overhead_s'] * 1e3:.0f} ms and a transfer rate of "
                f"{r['model']['transfer_bytes_per_s'] / mib:.0f} MiB/s, both inflated by the "
                f"load; with the quiet sort-first run's {t_task * 1e3:.2f} ms and "
                f"{rate / mib:.0f} MiB/s instead (same traces, merges and bytes):",
                "",
                "| workers | " + " | ".join(f"{m} frame s | {m} speed-up" for m in modes) + " |",
                "|---|" + "---|---|" * len(modes),
            ]
            for w in WORKER_COUNTS:
                cells = []
                for m in modes:
                    row, md = r["modes"][m], r["modes"][m]["median"]
                    merge = t_task + row["merge_in_process_s"] + row["full_state_bytes"] / rate
                    tail = md["finish_s"] + row["frame_bytes"] / rate
                    t = md["share_trace_sum_s"] / w + math.log2(w) * merge + tail
                    cells.append(f"{t:.3f} | {(md['share_trace_sum_s'] + tail) / t:.1f}x")
                lines.append(f"| {w} | " + " | ".join(cells) + " |")
            lines.append("")
    return lines


if __name__ == "__main__":
    main()
