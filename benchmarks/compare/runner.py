"""Run the comparison: interleaved timings, quality metrics, per-method peak memory."""

from __future__ import annotations

import json
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

import splinecast as sc

from . import methods as M
from .metrics import surface_quality
from .reference import image_error, reference_dvr, reference_mip
from .scenes import SceneSpec

REPO = Path(__file__).resolve().parents[2]
# The floor kernel is imported as the top-level module ``floor_kernel`` everywhere (see its
# docstring): Numba's on-disk cache records the module name it was compiled under.
sys.path.insert(0, str(REPO / "benchmarks"))
from floor_kernel import floor_render  # noqa: E402

#: Azimuths of the steady-frame cameras: every timed frame follows a camera rotation.
ROTATIONS = (40.0, 50.0, 60.0, 70.0)
#: Sample steps (voxels) tried when matching MIP / DVR quality (coarsest first): a method whose
#: error allows a long step should be timed at the step a user would pick for that quality.
#: Pre-integrated segments meet the tolerance at four voxels on most of the suite's volumes, and
#: VTK's casters at three on the MRI (every method gets the same ladder). Four is the longest step
#: the fixed-step loop's screen footprint takes (a finest block's edge).
VOLUME_STEPS = (4.0, 3.0, 2.0, 1.0, 0.5, 0.25, 0.125)
#: Image size of the MIP / DVR quality match (the dense reference is costly at full size): the
#: timing camera at 1/16 of the pixels; the methods render this size directly for the match.
QUALITY_SIZE = (256, 192)


def _timed(fn) -> float:
    start = time.perf_counter()
    fn()
    return (time.perf_counter() - start) * 1e3


def _camera(volume: sc.Volume, size: tuple[int, int], azimuth: float = 30.0) -> sc.Camera:
    return sc.Camera.orbit(volume, azimuth=azimuth, elevation=20.0, size=size)


def _floor_ms(cam: sc.Camera, volume: sc.Volume) -> float:
    """The floor of a ray-cast frame (``benchmarks/floor_kernel.py``: the pixel's ray, clipped
    to the volume's box, one colour written), best of three calls: it takes a few ms, so one
    call is at the mercy of the scheduler."""
    return min(_timed(lambda: floor_render(cam, volume.bounds)) for _ in range(3))


def run_iso_scene(spec: SceneSpec, sizes: list[tuple[int, int]], keys: list[str], repeats: int,
                  quality_size: tuple[int, int] | None, log=print) -> dict[str, Any]:
    """Time and assess every isosurface method on one scene, methods interleaved.

    For each image size: one warm-up (compilation, first upload to OpenGL), then ``repeats``
    rounds in which every method in turn goes to a new isovalue and finishes an image (the
    isovalues cycle through ``spec.isos[1:]``), then ``repeats`` rounds of steady frames after a
    camera rotation at the isovalue of record. Quality (analytic scenes) is measured at
    ``quality_size`` with the isovalue of record.
    """
    volume = spec.make()
    iso = spec.isos[0]
    result: dict[str, Any] = {"scene": spec.label, "shape": list(volume.shape), "iso": iso,
                              "kind": spec.kind, "size": spec.size, "skipped": {}, "sizes": [],
                              "methods": {}}
    active: dict[str, M.IsoMethod] = {}
    for key in keys:
        reason = M.iso_requirements(key)
        if reason:
            result["skipped"][key] = reason
            continue
        active[key] = M.ISO_METHODS[key](volume, sizes[0])
    error_images: dict[str, np.ndarray] = {}
    for size in sizes:
        cam = _camera(volume, size)
        warm = {}
        for key, method in active.items():
            warm[key] = _timed(lambda m=method, c=cam: m.new_iso(iso, c))
            method.frame(_camera(volume, size, ROTATIONS[0]))
        # Very slow methods (mesh extraction of 512^3) get fewer rounds; all methods get the same.
        n = repeats if max(warm.values(), default=0) < 5000 else min(repeats, 3)
        first = {key: [] for key in active}
        steady = {key: [] for key in active}
        for r in range(n):
            value = spec.isos[1 + r % (len(spec.isos) - 1)]
            for key, method in active.items():
                first[key].append(_timed(lambda m=method, v=value, c=cam: m.new_iso(v, c)))
        for method in active.values():
            method.new_iso(iso, cam)
        floor = []
        floor_render(cam, volume.bounds)  # compilation
        for r in range(n):
            rotated = _camera(volume, size, ROTATIONS[r % len(ROTATIONS)])
            floor.append(_floor_ms(rotated, volume))
            for key, method in active.items():
                steady[key].append(_timed(lambda m=method, c=rotated: m.frame(c)))
        entry = {"width": size[0], "height": size[1], "repeats": n, "methods": {},
                 "floor_ms": statistics.median(floor), "floor_runs_ms": floor}
        for key in active:
            entry["methods"][key] = {
                "first_image_ms": statistics.median(first[key]),
                "first_image_runs_ms": first[key],
                "steady_frame_ms": statistics.median(steady[key]),
                "steady_frame_runs_ms": steady[key],
            }
        result["sizes"].append(entry)
        line = ", ".join(f"{k} {v['first_image_ms']:.0f}/{v['steady_frame_ms']:.0f}"
                         for k, v in entry["methods"].items())
        log(f"  {spec.label} {size[0]}x{size[1]} first image / steady frame ms: {line}")
    for key, method in active.items():
        result["methods"][key] = {"label": M.ISO_LABELS[key], **method.info(),
                                  "threads": method.threads()}
    if spec.truth is not None and quality_size is not None:
        cam = _camera(volume, quality_size)
        voxel = float(min(volume.spacing))
        for key, method in active.items():
            depth, normals = method.surface(cam)
            q = surface_quality(depth, normals, cam, spec.truth, iso, voxel)
            result["methods"][key]["quality"] = {"width": quality_size[0],
                                                 "height": quality_size[1], **q.summary()}
            error_images[key] = q.position_voxels
    for method in active.values():
        method.close()
    result["_error_images"] = error_images
    return result


def run_volume_scene(spec: SceneSpec, mode: str, sizes: list[tuple[int, int]], keys: list[str],
                     repeats: int, log=print) -> dict[str, Any]:
    """MIP or DVR frame times at matched quality.

    Every image is compared with a dense reference at ``QUALITY_SIZE`` by mean absolute error:
    MIP against the trilinear maximum sampled every 1/16 voxel (normalized value), DVR against
    emission-absorption compositing of the same transfer function every 1/16 voxel on the
    trilinear field (premultiplied RGB over black; see ``reference_dvr``). The tolerance is the
    error of splinecast at its default settings, at least 1/255 (the 8-bit output of VTK).
    MIP: splinecast's is exact (no step); each VTK ray caster runs at the coarsest step of
    ``VOLUME_STEPS`` (or the method's own ladder, ``methods.VOLUME_METHOD_STEPS``) within the
    tolerance. DVR: splinecast and each VTK caster run at the
    coarsest step within the tolerance. A method that never reaches it runs at the finest step.
    """
    volume = spec.make()
    iso = spec.isos[0]
    result: dict[str, Any] = {"scene": spec.label, "mode": mode, "shape": list(volume.shape),
                              "skipped": {}, "steps": {}, "quality": {}, "sizes": []}
    qcam = _camera(volume, QUALITY_SIZE)
    if mode == "mip":
        reference = reference_mip(volume, qcam)
    else:
        reference = reference_dvr(volume, qcam, M.dvr_transfer(volume, iso))
    tolerance = 1.0 / 255.0
    active: dict[str, M.VolumeMethod] = {}
    for key in keys:
        reason = M.volume_requirements(key, mode)
        if reason:
            result["skipped"][key] = reason
            continue
        if key == "splinecast":
            method = M.VOLUME_METHODS[key](volume, sizes[0], mode, iso, 0.0)
            err = image_error(method.image(qcam), reference)
            tolerance = max(tolerance, err)
            if mode == "mip":
                result["quality"][key] = {"step": "exact", "mean_abs_error": err}
                active[key] = method
            else:
                from splinecast.render.dvr import DEFAULT_SETTINGS

                result["default_error"] = err
                result["default_step"] = DEFAULT_SETTINGS.step
    for key in keys:
        if key in result["skipped"] or key in active:
            continue
        ladder = M.VOLUME_METHOD_STEPS.get(key, VOLUME_STEPS)
        chosen, errors = ladder[-1], {}
        for step in ladder:
            probe = M.VOLUME_METHODS[key](volume, QUALITY_SIZE, mode, iso, step)
            errors[step] = image_error(probe.image(qcam), reference)
            probe.close()
            if errors[step] <= tolerance:
                chosen = step
                break
        result["steps"][key] = chosen
        result["quality"][key] = {"step": chosen, "mean_abs_error": errors.get(chosen),
                                  "errors_by_step": errors}
        active[key] = M.VOLUME_METHODS[key](volume, sizes[0], mode, iso, chosen)
    result["tolerance"] = tolerance
    for size in sizes:
        for method in active.values():
            method.frame(_camera(volume, size))  # warm-up
        floor_render(_camera(volume, size), volume.bounds)  # compilation
        times = {key: [] for key in active}
        floor = []
        for r in range(repeats):
            cam = _camera(volume, size, ROTATIONS[r % len(ROTATIONS)])
            floor.append(_floor_ms(cam, volume))
            for key, method in active.items():
                times[key].append(_timed(lambda m=method, c=cam: m.frame(c)))
        entry = {"width": size[0], "height": size[1], "floor_ms": statistics.median(floor),
                 "floor_runs_ms": floor, "methods": {
            key: {"frame_ms": statistics.median(t), "runs_ms": t} for key, t in times.items()}}
        result["sizes"].append(entry)
        log(f"  {spec.label} {mode} {size[0]}x{size[1]} ms/frame: " + ", ".join(
            f"{k} {v['frame_ms']:.0f}" for k, v in entry["methods"].items()))
    result["threads"] = {key: m.threads() for key, m in active.items()}
    for method in active.values():
        if hasattr(method, "close"):
            method.close()
    return result


# --------------------------------------------------------------------------- peak memory

def peak_rss_mib() -> float:
    """This process's peak resident set size (VmHWM) in MiB.

    Not ``ru_maxrss``: Linux carries the parent's high-water mark into a forked child across
    ``exec``, so every worker would report at least the (large) parent's peak.
    """
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def memory_worker(data_path: str, meta: dict[str, Any], kind: str, key: str,
                  size: tuple[int, int], mode: str, step: float) -> dict[str, Any]:
    """Peak RSS of one method in this fresh process (run via ``--memory-worker``).

    The volume is loaded from a ``.npy`` first; its peak is the baseline, and the method's
    figure is the peak after one new-isovalue image and one rotated frame (or two MIP/DVR frames),
    including the libraries the method imports (VTK, scikit-image).
    """
    data = np.load(data_path)
    volume = sc.Volume(data, spacing=meta["spacing"], origin=meta["origin"],
                       metadata=meta["metadata"])
    baseline = peak_rss_mib()
    cam = _camera(volume, size)
    if kind == "iso":
        method = M.ISO_METHODS[key](volume, size)
        method.new_iso(meta["iso"], cam)
        method.frame(_camera(volume, size, ROTATIONS[0]))
    else:
        method = M.VOLUME_METHODS[key](volume, size, mode, meta["iso"], step)
        method.frame(cam)
        method.frame(_camera(volume, size, ROTATIONS[0]))
    peak = peak_rss_mib()
    return {"baseline_mib": baseline, "peak_mib": peak, "increase_mib": peak - baseline}


def measure_memory(spec: SceneSpec, jobs: list[tuple[str, str, str, float]],
                   size: tuple[int, int], log=print) -> dict[str, Any]:
    """Run each ``(kind, key, mode, step)`` job's memory worker in a fresh subprocess."""
    volume = spec.make()
    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "volume.npy"
        np.save(path, np.asarray(volume.data))
        meta = {"spacing": volume.spacing, "origin": volume.origin, "iso": spec.isos[0],
                "metadata": {k: v for k, v in volume.metadata.items()
                             if isinstance(v, str | int | float)}}
        del volume
        for kind, key, mode, step in jobs:
            args = json.dumps({"data_path": str(path), "meta": meta, "kind": kind, "key": key,
                               "size": list(size), "mode": mode, "step": step})
            run = subprocess.run([sys.executable, "-m", "benchmarks.compare", "--memory-worker",
                                  args], cwd=REPO, capture_output=True, text=True)
            lines = [x for x in run.stdout.splitlines() if x.startswith("{")]
            name = key if kind == "iso" else f"{key} {mode}"
            if run.returncode == 0 and lines:
                out[name] = json.loads(lines[-1])
                log(f"  memory {spec.label} {name}: peak {out[name]['peak_mib']:.0f} MiB "
                    f"(+{out[name]['increase_mib']:.0f} over the loaded volume)")
            else:
                out[name] = {"error": (run.stderr.strip().splitlines() or ["?"])[-1][-300:]}
    return out


# --------------------------------------------------------------------------- dense DVR

#: The dense DVR rows' methods: (key, label). splinecast with no settings (its defaults), the
#: same with VTK's early-termination opacity, and VTK's fixed-point caster at splinecast's
#: default step.
DENSE_METHODS = (
    ("splinecast", "splinecast, default settings"),
    ("splinecast-vtk-termination", "splinecast, default settings but VTK's termination"),
    ("vtk-fixed-point", "VTK fixed-point CPU ray caster"),
)


def run_dense_dvr_scene(spec: SceneSpec, size: tuple[int, int], repeats: int,
                        log=print) -> dict[str, Any]:
    """DVR with dense transfer functions (:func:`methods.dense_transfers`) at one step.

    Not matched by quality: every method samples every ``DEFAULT_SETTINGS.step`` voxels (one),
    splinecast with its default settings (pre-integrated segments, early termination at
    ``1 - 2^-10``) and once more with VTK's termination, VTK's fixed-point caster with early
    termination built in (:data:`methods.VTK_FIXED_POINT_TERMINATION`). The error of each
    against the dense reference (:func:`reference_dvr`, same opacity, grey ramp) is reported
    beside the times. Frames follow camera rotations, methods interleaved.
    """
    from splinecast.render.dvr import DEFAULT_SETTINGS

    volume = spec.make()
    iso = spec.isos[0]
    step = float(DEFAULT_SETTINGS.step)
    qcam = _camera(volume, QUALITY_SIZE)
    result: dict[str, Any] = {"scene": spec.label, "mode": "dvr", "step": step,
                              "termination": {"splinecast": DEFAULT_SETTINGS.termination,
                                              "splinecast-vtk-termination":
                                                  M.VTK_FIXED_POINT_TERMINATION,
                                              "vtk-fixed-point":
                                                  M.VTK_FIXED_POINT_TERMINATION},
                              "skipped": {}, "transfers": []}
    vtk_reason = M.volume_requirements("vtk-fixed-point", "dvr")
    if vtk_reason:
        result["skipped"]["vtk-fixed-point"] = vtk_reason
    for name, transfer in M.dense_transfers(volume).items():
        def make(key: str, at: tuple[int, int], transfer=transfer) -> M.VolumeMethod:
            if key == "vtk-fixed-point":
                return M.VtkVolume(volume, at, "dvr", iso, step, "fixed-point", transfer=transfer)
            termination = M.VTK_FIXED_POINT_TERMINATION if key != "splinecast" else None
            return M.SplinecastVolume(volume, at, "dvr", iso, 0.0, transfer=transfer,
                                      termination=termination)

        keys = [k for k, _ in DENSE_METHODS if k not in result["skipped"]]
        reference = reference_dvr(volume, qcam, transfer)
        errors = {}
        for key in keys:
            probe = make(key, QUALITY_SIZE)
            errors[key] = image_error(probe.image(qcam), reference)
            probe.close()
        active = {key: make(key, size) for key in keys}
        for method in active.values():
            method.frame(_camera(volume, size))  # warm-up
        times: dict[str, list[float]] = {key: [] for key in active}
        for r in range(repeats):
            cam = _camera(volume, size, ROTATIONS[r % len(ROTATIONS)])
            for key, method in active.items():
                times[key].append(_timed(lambda m=method, c=cam: m.frame(c)))
        threads = {key: m.threads() for key, m in active.items()}
        for method in active.values():
            method.close()
        entry = {"transfer": name, "opacity": transfer, "width": size[0], "height": size[1],
                 "methods": {key: {"frame_ms": statistics.median(t), "runs_ms": t,
                                   "mean_abs_error": errors[key]} for key, t in times.items()},
                 "threads": threads}
        vtk = entry["methods"].get("vtk-fixed-point")
        if vtk:
            for e in entry["methods"].values():
                e["vtk_ms_over_ms"] = vtk["frame_ms"] / e["frame_ms"]
        result["transfers"].append(entry)
        log(f"  {spec.label} dense DVR ({name}) {size[0]}x{size[1]} ms/frame: " + ", ".join(
            f"{k} {v['frame_ms']:.0f}" for k, v in entry["methods"].items()))
    return result
