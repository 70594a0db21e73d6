"""Where a 2-worker movie loses time against 1 worker: Dask's background work, with and without
``splinecast.distributed.local_cluster``'s quiet settings (issue 14).

For each cluster configuration (``dask-defaults``: a plain ``LocalCluster``; ``quiet``:
:func:`splinecast.distributed.local_cluster`) and 1 and 2 single-threaded worker processes:

* idle: CPU time per second of the client process (which also runs the scheduler and the
  nannies) and of each worker process while no task runs (``--idle`` seconds);
* movie: ``--frames`` frames of a 512x512 turntable of ``demo:marschner-lobb?size=128`` (iso 0.5,
  8-bit images back, ``render_many``), after a warm-up batch: wall time, and CPU time per frame
  of the client process and of the worker processes.

Only one cluster exists at a time (an idle second cluster would add its own background). Runs
alternate between the configurations; medians of ``--repeats``. On a machine shared with other
jobs the wall times and their 1 -> 2 ratio move with the load; the CPU times per frame are the
steadier numbers: with ``W`` workers on ``W`` cores, the client's CPU and the workers' own
background come out of the renders' share, so the scaling they allow is
``2 * t_worker(1) / (t_worker(2) + t_client(2))`` per frame (``t`` CPU per frame), printed as
"CPU-bound speed-up".
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _machine import describe  # noqa: E402

SOURCE, ISO = "demo:marschner-lobb?size=128", 0.5


def _cpu(proc) -> float:
    t = proc.cpu_times()
    return t.user + t.system


def measure(config: str, workers: int, frames: int, idle_s: float) -> dict:
    """One cluster: idle background, then one warm movie, CPU per process."""
    import psutil
    from distributed import Client, LocalCluster

    import splinecast as sc
    from splinecast.distributed import DistributedScene, local_cluster, orbit_path

    if config == "quiet":
        cluster = local_cluster(workers)
    else:
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               dashboard_address=":0", silence_logs=40)
    client = Client(cluster)
    try:
        path = orbit_path(sc.read(SOURCE), frames, size=(512, 512))
        scene = DistributedScene(SOURCE, client)
        list(scene.render_many(path[:2 * workers], iso=ISO, image_only=True))  # warm-up
        me = psutil.Process()
        pids = set(client.run(os.getpid).values())
        procs = [p for p in me.children(recursive=True) if p.pid in pids]

        def snap() -> tuple[float, float]:
            return _cpu(me), sum(_cpu(p) for p in procs)

        time.sleep(1.0)
        a = snap()
        time.sleep(idle_s)
        b = snap()
        idle = {"client_ms_per_s": 1e3 * (b[0] - a[0]) / idle_s,
                "worker_ms_per_s": 1e3 * (b[1] - a[1]) / idle_s / workers}
        a, start = snap(), time.perf_counter()
        images = list(scene.render_many(path, iso=ISO, image_only=True))
        wall = time.perf_counter() - start
        b = snap()
        assert len(images) == frames
        return {"idle": idle, "wall_s": wall,
                "client_cpu_ms_per_frame": 1e3 * (b[0] - a[0]) / frames,
                "worker_cpu_ms_per_frame": 1e3 * (b[1] - a[1]) / frames}
    finally:
        client.close()
        cluster.close()


def markdown(r: dict) -> str:
    m = r["machine"]
    lines = [
        "# Movie on 1 and 2 Dask workers: background overhead (issue 14)",
        "",
        f"Machine: {m['cpu']}, {m['cores']} cores; shared with other jobs (load average "
        f"{r['load_before'][0]:.1f} before / {r['load_after'][0]:.1f} after): wall times and "
        f"their ratios are noisy, CPU times are the steadier numbers. Command: "
        f"`{r['command']}`. {r['frames']} frames 512x512 of `{SOURCE}`, iso {ISO}, 8-bit "
        f"images back; medians of {r['repeats']} alternating runs, one cluster at a time.",
        "",
        "| cluster | idle: client+scheduler ms/s | idle: per worker ms/s | movie 1 worker s | "
        "movie 2 workers s | wall speed-up | client CPU ms/frame (2 w) | worker CPU ms/frame "
        "(1 w / 2 w) | CPU-bound speed-up |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for config, row in r["configs"].items():
        one, two = row["1"], row["2"]
        lines.append(
            f"| {config} | {two['idle']['client_ms_per_s']:.0f} | "
            f"{two['idle']['worker_ms_per_s']:.0f} | {one['wall_s']:.2f} | {two['wall_s']:.2f} "
            f"| {one['wall_s'] / two['wall_s']:.2f}x | {two['client_cpu_ms_per_frame']:.1f} | "
            f"{one['worker_cpu_ms_per_frame']:.0f} / {two['worker_cpu_ms_per_frame']:.0f} | "
            f"{row['cpu_bound_speedup']:.2f}x |")
    lines.append("")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=120)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--idle", type=float, default=5.0, help="seconds of idle measurement")
    parser.add_argument("--out", default=str(HERE / "results"))
    args = parser.parse_args()
    configs = ("dask-defaults", "quiet")
    load_before = os.getloadavg()
    runs: dict = {c: {"1": [], "2": []} for c in configs}
    for i in range(args.repeats):
        for config in configs:
            for w in (1, 2):
                runs[config][str(w)].append(measure(config, w, args.frames, args.idle))
                print(f"run {i + 1} {config} {w} worker(s): {runs[config][str(w)][-1]}",
                      file=sys.stderr)

    def med(rs: list[dict]) -> dict:
        return {"wall_s": statistics.median(x["wall_s"] for x in rs),
                "client_cpu_ms_per_frame": statistics.median(x["client_cpu_ms_per_frame"]
                                                             for x in rs),
                "worker_cpu_ms_per_frame": statistics.median(x["worker_cpu_ms_per_frame"]
                                                             for x in rs),
                "idle": {k: statistics.median(x["idle"][k] for x in rs)
                         for k in rs[0]["idle"]}}

    result = {"machine": describe(), "frames": args.frames, "repeats": args.repeats,
              "command": f"python benchmarks/bench_movie_overhead.py --frames {args.frames} "
                         f"--repeats {args.repeats}",
              "load_before": load_before, "load_after": os.getloadavg(), "configs": {},
              "runs": runs}
    for config in configs:
        one, two = med(runs[config]["1"]), med(runs[config]["2"])
        speedup = (2 * one["worker_cpu_ms_per_frame"]
                   / (two["worker_cpu_ms_per_frame"] + two["client_cpu_ms_per_frame"]))
        result["configs"][config] = {"1": one, "2": two, "cpu_bound_speedup": speedup}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "distributed_movie_overhead.json").write_text(json.dumps(result, indent=1) + "\n")
    (out / "distributed_movie_overhead.md").write_text(markdown(result))
    print(markdown(result))


if __name__ == "__main__":
    main()
