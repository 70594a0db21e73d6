"""Frame time of two builds side by side, per model: interleaved worker processes.

The baseline is another checkout of the repository (``--old``, e.g. ``git worktree add --detach
/tmp/iso-old HEAD~1``); this checkout is the new build. Each build runs in its own worker process
(``PYTHONPATH=<checkout>/src``, one Numba thread unless ``--threads``) that loads the scenes
once; the parent asks them in turn to render the same frame and records the process CPU time of
each render (the wall clock with several threads, whose idle ones spin), so both
builds see the same machine load, round by round. Each worker also saves the frame's depth
(isosurfaces), value (MIP) or colour (DVR, the comparison suite's transfer function), and the
parent reports whether the two builds' are bit-identical
and their largest difference.

    python benchmarks/tools/bench_iso_builds.py --old /tmp/iso-old [--rounds 5] [--mode iso|mip|dvr]
        [--dvr-sampling OLD,NEW] [--dvr-step VOXELS] [--mip-step VOXELS] [--mip-method M]
        [--models trilinear,bspline1,bspline2,bspline3]
        [--scenes LABELS] [--view orbit|far|away|inside] [--stem iso_builds]

Results go to ``benchmarks/results/<stem>.md`` and ``.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parents[1]  # benchmarks/
REPO = HERE.parent
SIZE = (1024, 768)
#: The comparison suite's MRI (isovalue 80), read from the shared data folder.
sys.path.insert(0, str(HERE))
from _machine import MRI  # noqa: E402

#: (label, demo name or file, size): the comparison suite's scenes.
SCENES = (("marschner-lobb 128^3", "marschner-lobb", 128), ("sphere SDF 128^3", "sphere", 128),
          ("torus SDF 128^3", "torus", 128), ("marschner-lobb 256^3", "marschner-lobb", 256),
          ("noise 256^3", "noise", 256), ("MNI152 T1 MRI", str(MRI), 0),
          ("marschner-lobb 64^3", "marschner-lobb", 64))


def _worker(outdir: str) -> None:
    """Serve render requests on stdin (one JSON per line); answer on stdout."""
    import splinecast as sc

    scenes: dict[tuple[str, str], tuple] = {}
    print(json.dumps({"ready": sc.__file__}), flush=True)
    for line in sys.stdin:
        req = json.loads(line)
        key = (req["scene"], req["model"], req["mode"], req.get("sampling"), req.get("step"),
               req.get("view", "orbit"))
        if key not in scenes:
            _, name, size = next(s for s in SCENES if s[0] == req["scene"])
            if size:
                vol = sc.demo(name, size=size)
                iso = vol.metadata["default_iso"]
            else:
                vol, iso = sc.read(name), 80.0
            cam = _view(sc, vol, req.get("view", "orbit"))
            scene = sc.Scene(vol, model=req["model"])
            options = {"iso": iso} if req["mode"] == "iso" else {"mode": req["mode"]}
            if req["mode"] == "dvr":
                options.update(_dvr_options(vol, iso, req.get("sampling") or None,
                                            req.get("step")))
            if req["mode"] == "mip" and req.get("step"):
                options.update(method=req.get("method") or "sampled", step=float(req["step"]))
            scene.render(cam, **options, outputs=("rgba",))  # compile and prepare
            scenes[key] = (scene, cam, options)
        scene, cam, options = scenes[key]
        if req.get("depth"):
            kept = {"iso": "depth", "mip": "value", "dvr": "rgba"}[options.get("mode", "iso")]
            frame = scene.render(cam, **options, outputs=("rgba", kept))
            path = os.path.join(outdir, f"{os.getpid()}_{len(os.listdir(outdir))}.npy")
            np.save(path, getattr(frame, kept))
            print(json.dumps({"depth": path}), flush=True)
            continue
        # One thread: the process's CPU time (steadier than the wall clock on a shared machine).
        # More: the wall clock, as idle threads wait by spinning, which counts as CPU time.
        clock = time.process_time if os.environ["NUMBA_NUM_THREADS"] == "1" else time.perf_counter
        start = clock()
        scene.render(cam, **options, outputs=("rgba",))
        print(json.dumps({"ms": (clock() - start) * 1e3}), flush=True)


#: Cameras of ``--view``: the comparison's orbit; the same zoomed out (the volume a small
#: part of the screen); the orbit's eye turned round, looking away from the volume; an eye at
#: the volume's centre looking the orbit's way (a fly-through).
VIEWS = ("orbit", "far", "away", "inside")


def _view(sc, vol, view: str):
    orbit = sc.Camera.orbit(vol, azimuth=30, elevation=20, size=SIZE)
    if view == "orbit":
        return orbit
    if view == "far":
        return sc.Camera.orbit(vol, azimuth=30, elevation=20, size=SIZE, zoom=0.35)
    eye, centre = orbit.position, orbit.look_at
    if view == "away":
        return sc.Camera(eye, 2.0 * eye - centre, up=orbit.up, fov=orbit.fov, size=SIZE)
    return sc.Camera(centre, 2.0 * centre - eye, up=orbit.up, fov=60.0, size=SIZE)


def _dvr_options(vol, iso: float, sampling: str | None, step: float | None = None) -> dict:
    """The comparison suite's DVR: its transfer function over black, the build's default
    settings (with another ``sampling`` or ``step`` in voxels when given)."""
    import dataclasses

    import splinecast as sc
    from splinecast.render import dvr
    from splinecast.transfer import TransferFunction

    sys.path.insert(0, str(REPO))
    from benchmarks.compare.methods import dvr_transfer

    options = {"tf": TransferFunction(dvr_transfer(vol, iso), vol.value_range, "gray"),
               "shading": sc.Shading(background=(0.0, 0.0, 0.0, 1.0))}
    changes = {"sampling": sampling} if sampling else {}
    if step:
        changes["step"] = float(step)
    if changes:
        options["dvr"] = dataclasses.replace(dvr.DEFAULT_SETTINGS, **changes)
    return options


class _Build:
    """A worker process running one checkout's splinecast."""

    def __init__(self, checkout: Path, outdir: str, threads: int = 1) -> None:
        env = {**os.environ, "PYTHONPATH": str(checkout / "src"),
               "NUMBA_NUM_THREADS": str(threads)}
        self.proc = subprocess.Popen([sys.executable, __file__, "--worker", outdir], env=env,
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        self.source = self._read()["ready"]

    def _read(self) -> dict:
        line = self.proc.stdout.readline()
        if not line:
            raise SystemExit("a worker stopped; run it alone to see its error")
        return json.loads(line)

    def ask(self, **req) -> dict:
        self.proc.stdin.write(json.dumps(req) + "\n")
        self.proc.stdin.flush()
        return self._read()

    def close(self) -> None:
        self.proc.stdin.close()
        self.proc.wait(timeout=60)


def main() -> None:
    if len(sys.argv) > 2 and sys.argv[1] == "--worker":
        _worker(sys.argv[2])
        return
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old", required=True, help="checkout of the baseline build")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--models", default="trilinear,bspline1,bspline2,bspline3")
    ap.add_argument("--scenes", default=",".join(s[0] for s in SCENES[:2] + SCENES[3:6]),
                    help="comma-separated scene labels")
    ap.add_argument("--mode", default="iso", choices=("iso", "mip", "dvr"))
    ap.add_argument("--dvr-sampling", default=",",
                    help="DVR: the sampling of the old and the new build, 'OLD,NEW' (empty: the "
                         "build's default settings)")
    ap.add_argument("--dvr-step", type=float, default=0.0,
                    help="DVR: the sample step in voxels of both builds (0: the build's default)")
    ap.add_argument("--mip-step", type=float, default=0.0,
                    help="MIP: the sampled method at this step in voxels in both builds (0: the "
                         "exact method)")
    ap.add_argument("--mip-method", default="sampled", choices=("sampled", "slices"),
                    help="MIP with --mip-step: the sampled method of both builds")
    ap.add_argument("--threads", type=int, default=1,
                    help="Numba threads of each build (more than one: timed by the wall clock)")
    ap.add_argument("--view", default="orbit", choices=VIEWS,
                    help="camera: the comparison's orbit, zoomed out, the orbit's eye looking "
                         "away from the volume, or an eye inside it at its centre")
    ap.add_argument("--stem", default="iso_builds")
    args = ap.parse_args()
    os.environ["NUMBA_NUM_THREADS"] = str(args.threads)  # the workers', for the description
    sys.path.insert(0, str(HERE))
    from _machine import describe

    rows = []
    with tempfile.TemporaryDirectory() as outdir:
        builds = {"old": _Build(Path(args.old).resolve(), outdir, args.threads),
                  "new": _Build(REPO, outdir, args.threads)}
        for label in args.scenes.split(","):
            for model in args.models.split(","):
                req = {"scene": label, "model": model, "mode": args.mode,
                       "step": (args.mip_step if args.mode == "mip" else args.dvr_step) or None,
                       "view": args.view, "method": args.mip_method}
                samplings = dict(zip(builds, args.dvr_sampling.split(","), strict=True))
                depths = {k: np.load(b.ask(**req, depth=True, sampling=samplings[k])["depth"])
                          for k, b in builds.items()}
                times: dict[str, list[float]] = {k: [] for k in builds}
                for _ in range(args.rounds):
                    for k, b in builds.items():
                        times[k].append(b.ask(**req, sampling=samplings[k])["ms"])
                old, new = depths["old"], depths["new"]
                both = np.isfinite(old) & np.isfinite(new)
                row = {"scene": label, "model": model,
                       "old_ms": statistics.median(times["old"]),
                       "new_ms": statistics.median(times["new"]),
                       "identical": bool(np.array_equal(old, new, equal_nan=True)),
                       "max_depth_diff": float(np.max(np.abs(old[both] - new[both]),
                                                      initial=0.0)),
                       "hits_old": int(np.isfinite(old).sum()),
                       "hits_new": int(np.isfinite(new).sum()), "times": times}
                row["speedup"] = row["old_ms"] / row["new_ms"]
                rows.append(row)
                print(f"{label} {model}: {row['old_ms']:.1f} -> {row['new_ms']:.1f} ms "
                      f"({row['speedup']:.2f}x), identical {row['identical']}", flush=True)
        sources = {k: b.source for k, b in builds.items()}
        for b in builds.values():
            b.close()
    out = HERE / "results"
    out.mkdir(exist_ok=True)
    machine = describe()
    (out / f"{args.stem}.json").write_text(json.dumps(
        {"machine": machine, "builds": sources, "rounds": args.rounds, "rows": rows}, indent=1))
    what = {"iso": "Isosurface", "mip": "MIP", "dvr": "DVR"}[args.mode]
    kept = {"iso": "depths", "mip": "values", "dvr": "colours"}[args.mode]
    lines = [f"# {what} frames, two builds side by side ({args.stem})", "",
             f"Machine: {machine}. Command: `python benchmarks/tools/bench_iso_builds.py"
             " --old <checkout>"
             f" --rounds {args.rounds} --mode {args.mode}"
             + (f" --dvr-sampling {args.dvr_sampling}" if args.mode == "dvr" else "")
             + (f" --dvr-step {args.dvr_step:g}" if args.dvr_step else "")
             + (f" --mip-step {args.mip_step:g} --mip-method {args.mip_method}"
                if args.mip_step and args.mode == "mip" else "")
             + (f" --threads {args.threads}" if args.threads > 1 else "")
             + (f" --view {args.view}" if args.view != "orbit" else "")
             + f"`. Builds: old `{sources['old']}`, new "
             f"`{sources['new']}`. 1024x768, colour only, "
             + ("one Numba thread, process CPU time, " if args.threads == 1 else
                f"{args.threads} Numba threads, wall clock, ")
             + "median of the rounds after a warm-up, the builds alternating within every round; "
             f"{kept} compared on a frame with them.", "",
             f"| scene | model | old ms | new ms | speed-up | {kept} bit-identical | largest "
             "difference | pixels with a value |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['scene']} | {r['model']} | {r['old_ms']:.1f} | {r['new_ms']:.1f} | "
                     f"{r['speedup']:.2f}x | {'yes' if r['identical'] else 'no'} | "
                     f"{r['max_depth_diff']:.3g} | {r['hits_new']} |")
    (out / f"{args.stem}.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {out / (args.stem + '.md')}")


if __name__ == "__main__":
    main()
