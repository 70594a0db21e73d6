"""Write the comparison's JSON, markdown table and plots."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from .methods import ISO_LABELS, VOLUME_LABELS


def _fmt(value: Any, digits: int = 0) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    return f"{value:.{digits}f}"


def dense_dvr_lines(rows: list[dict[str, Any]]) -> list[str]:
    """The section of the DVR rows with dense transfer functions
    (``runner.run_dense_dvr_scene``)."""
    if not rows:
        return []
    from .runner import DENSE_METHODS

    labels = dict(DENSE_METHODS)
    lines = ["", "## DVR with dense transfer functions, same step (ms per frame)", "",
             "Not matched by quality: every method samples every voxel (splinecast's default "
             "step), the opacity makes most of the volume partly visible, so rays end by "
             "opacity (\"automatic\": the opacity of splinecast.auto_transfer_function, what "
             "mode=\"dvr\" shows without a transfer function; \"every voxel\": a ramp from the "
             "lowest value to 0.1 per voxel at the highest), with the suite's grey colour ramp. "
             "splinecast runs with no settings (DEFAULT_SETTINGS: pre-integrated segments, early "
             "termination at an opacity of 1 - 2^-10) and with the same settings but VTK's "
             "termination; VTK's fixed-point caster stops a ray once its remaining transparency "
             "falls below 255/32768 (an opacity of 0.9922, built in). Error: mean absolute error "
             "against the dense reference at 256x192 (as above). Ratio: VTK's frame time over "
             "the method's (above 1: faster than VTK).", "",
             "| scene | transfer function | image | method | termination | error vs reference "
             "| ms/frame | VTK ms / ms |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        for t in r["transfers"]:
            for k, e in t["methods"].items():
                lines.append(
                    f"| {r['scene']} | {t['transfer']} | {t['width']}x{t['height']} | "
                    f"{labels.get(k, k)} | {_fmt(r['termination'].get(k), 4)} | "
                    f"{_fmt(e['mean_abs_error'], 4)} | {_fmt(e['frame_ms'])} | "
                    f"{_fmt(e.get('vtk_ms_over_ms'), 2)} |")
        for k, why in r["skipped"].items():
            lines.append(f"| {r['scene']} | - | - | {labels.get(k, k)} | - | - | skipped: {why} "
                         "| - |")
    return lines


def markdown(results: dict[str, Any]) -> str:
    """The human-readable summary: machine, iso table, quality table, MIP/DVR table, notes."""
    m = results["machine"]
    v = m["versions"]
    lines = [
        "# How splinecast compares",
        "",
        f"Machine: {m['cpu']}, {m['cores']} cores; splinecast {v.get('splinecast')}, "
        f"numba {v.get('numba')}, VTK {v.get('vtk')}, scikit-image {v.get('scikit-image')}; "
        f"OpenGL: {results['vtk'].get('renderer', 'unavailable')} via "
        f"{results['vtk'].get('window', '-')}. Command: `{results['command']}`. "
        "Medians after warm-up; methods interleaved in one process.",
        "",
    ]
    lines += [f"- {note}" for note in results["notes"]]
    lines += ["", "## Isosurface: new isovalue to first image / steady frame after a rotation (ms)",
              ""]
    keys = [k for k in ISO_LABELS if any(k in s["methods"] for r in results["iso"]
                                         for s in r["sizes"])]
    header = "| scene | image | " + " | ".join(ISO_LABELS[k] for k in keys) + \
        " | speed-up vs flying edges (first / steady) |"
    lines += [header, "|" + "---|" * (len(keys) + 3)]
    for r in results["iso"]:
        for s in r["sizes"]:
            cells = []
            for k in keys:
                e = s["methods"].get(k)
                cells.append(f"{_fmt(e['first_image_ms'])} / {_fmt(e['steady_frame_ms'])}"
                             if e else "skipped")
            sc_, fe = s["methods"].get("splinecast"), s["methods"].get("vtk-flying-edges")
            ratio = (f"{fe['first_image_ms'] / sc_['first_image_ms']:.1f}x / "
                     f"{fe['steady_frame_ms'] / sc_['steady_frame_ms']:.2f}x"
                     if sc_ and fe else "-")
            lines.append(f"| {r['scene']} | {s['width']}x{s['height']} | "
                         + " | ".join(cells) + f" | {ratio} |")
    if any("floor_ms" in s for r in results["iso"] for s in r["sizes"]):
        lines += ["", "### Ratio to the floor (steady frame / floor)", "",
                  "The floor (benchmarks/floor_kernel.py) is the least any ray caster pays per "
                  "frame: each pixel's ray generated, clipped to the volume's box, one colour "
                  "written, no traversal; it is timed in the same rounds as the steady frames "
                  "(median of the rounds, best of 3 calls per round). A ratio of 1 would be a "
                  "renderer that does nothing but reach every pixel; the meshes' ratio shows how "
                  "far a rasterizer is from that bound.", "",
                  "| scene | image | floor ms | " + " | ".join(ISO_LABELS[k] for k in keys)
                  + " |", "|" + "---|" * (len(keys) + 3)]
        for r in results["iso"]:
            for s in r["sizes"]:
                floor = s.get("floor_ms")
                if floor is None:
                    continue
                cells = [_fmt(s["methods"][k]["steady_frame_ms"] / floor, 1)
                         if k in s["methods"] else "-" for k in keys]
                lines.append(f"| {r['scene']} | {s['width']}x{s['height']} | {_fmt(floor, 1)} | "
                             + " | ".join(cells) + " |")
    lines += ["", "## Isosurface quality against the analytic function",
              "",
              "Position error: distance of each rendered hit point to the exact isosurface, in "
              "voxels (mean / 95th percentile / max). Normal error: angle to the exact gradient in "
              "degrees (mean / p95 / max). Meshes: depth from VTK's z-buffer, normals = the "
              "mesh's per-vertex normals interpolated at the hit point (what the rasterizer "
              "shades with).", "",
              "| scene | method | hits | position error (voxels) | normal error (degrees) | "
              "triangles |", "|---|---|---|---|---|---|"]
    for r in results["iso"]:
        for k, info in r["methods"].items():
            q = info.get("quality")
            if not q:
                continue
            lines.append(
                f"| {r['scene']} | {ISO_LABELS[k]} | {q['hits']} | "
                f"{_fmt(q['position_voxels_mean'], 4)} / {_fmt(q['position_voxels_p95'], 4)} / "
                f"{_fmt(q['position_voxels_max'], 4)} | {_fmt(q['normal_degrees_mean'], 3)} / "
                f"{_fmt(q['normal_degrees_p95'], 3)} / {_fmt(q['normal_degrees_max'], 3)} | "
                f"{info.get('triangles', '-')} |")
    if results.get("volume"):
        qsize = "x".join(str(n) for n in results.get("volume_quality_size", (256, 192)))
        lines += ["", "## MIP and DVR frame times (ms) at matched quality", "",
                  "Quality matched for both modes by mean absolute error against a dense "
                  f"reference image, computed for the timing camera at {qsize} (1/16 of the "
                  "pixels of 1024x768; the methods render that size directly for the match, the "
                  "timed frames are full size). MIP: reference = trilinear maximum along each "
                  "ray sampled every 1/16 voxel, normalized to the data range; splinecast's MIP "
                  "is exact (no step), and its sampled methods (method=\"sampled\", the "
                  "fixed-step loop; method=\"slices\", samples on every step-th voxel plane "
                  "across the ray) are matched like VTK's casters, as is its exact method with a "
                  "tolerance of k/255 of the window (k in the step column: the largest of 16, "
                  "12, 8, 6, 4, 3, 2, 1, 1/2 within the tolerance; its largest error per pixel "
                  "is k/255 of the window). DVR: reference = "
                  "emission-absorption compositing of the "
                  "same grey transfer function on the trilinear field every 1/16 voxel, opacity "
                  "per one-voxel slab corrected as 1 - (1 - a)^h for a step of h voxels "
                  "(splinecast's convention; VTK gets ScalarOpacityUnitDistance = one voxel), "
                  "premultiplied RGB over black, error averaged over pixels and RGB. Tolerance: "
                  "the error of splinecast at its default settings (DVR: "
                  "splinecast.render.dvr.DEFAULT_SETTINGS), at least 1/255. Each method (VTK's "
                  "casters; for DVR also splinecast, its other settings the defaults) runs at "
                  "the coarsest step of 4, 3, 2, 1, 1/2, 1/4, 1/8 voxel within the tolerance; one "
                  "that never reaches it runs at 1/8 (\"finest step tried\"). Timed frames: "
                  "the colour image (splinecast: outputs=(\"rgba\",)).",
                  "",
                  "| scene | mode | image | method | step (voxels) | error vs reference "
                  "| ms/frame | ratio to the floor |", "|---|---|---|---|---|---|---|---|"]
        for r in results["volume"]:
            for s in r["sizes"]:
                for k, e in s["methods"].items():
                    q = r["quality"].get(k, {})
                    err = q.get("mean_abs_error")
                    flag = (" (finest step tried; above the tolerance "
                            f"{r['tolerance']:.4f})") if err is not None \
                        and q.get("step") != "exact" and err > r["tolerance"] else ""
                    floor = s.get("floor_ms")
                    ratio = _fmt(e["frame_ms"] / floor, 1) if floor else "-"
                    lines.append(
                        f"| {r['scene']} | {r['mode']} | {s['width']}x{s['height']} | "
                        f"{VOLUME_LABELS[k]} | {q.get('step', '-')} | "
                        f"{_fmt(err, 4)}{flag} | {_fmt(e['frame_ms'])} | {ratio} |")
            if r.get("default_error") is not None:
                lines.append(f"| {r['scene']} | {r['mode']} | {qsize} | splinecast defaults "
                             f"(quality only; sets the tolerance {r['tolerance']:.4f}) | "
                             f"{r.get('default_step', '-')} | "
                             f"{_fmt(r['default_error'], 4)} | - | - |")
            for k, why in r["skipped"].items():
                lines.append(f"| {r['scene']} | {r['mode']} | - | {VOLUME_LABELS[k]} | - | - | "
                             f"skipped: {why} | - |")
    lines += dense_dvr_lines(results.get("dense_dvr", []))
    lines += ["", "## Peak resident memory (MiB, fresh process per method, 1024x768)", "",
              "| scene | method | peak | increase over the loaded volume |", "|---|---|---|---|"]
    for label, per in results.get("memory", {}).items():
        for name, e in per.items():
            if "error" in e:
                lines.append(f"| {label} | {name} | failed: {e['error']} | |")
            else:
                lines.append(f"| {label} | {name} | {_fmt(e['peak_mib'])} | "
                             f"{_fmt(e['increase_mib'])} |")
    lines += ["", "## Threads", ""]
    for k, t in results.get("threads", {}).items():
        lines.append(f"- {k}: " + ", ".join(f"{a}={b}" for a, b in t.items()))
    skipped = {k: why for r in results["iso"] for k, why in r["skipped"].items()}
    if skipped:
        lines += ["", "## Skipped methods", ""]
        lines += [f"- {ISO_LABELS.get(k, k)}: {why}" for k, why in skipped.items()]
    return "\n".join(lines) + "\n"


def plots(results: dict[str, Any], error_images: dict[str, dict[str, np.ndarray]],
          out: Path, stem: str) -> list[str]:
    """Time vs volume size per method, and position-error images side by side."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return []
    written = []
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, metric, title in ((axes[0], "first_image_ms", "new isovalue -> first image"),
                              (axes[1], "steady_frame_ms", "steady frame after rotation")):
        for kind, marker in (("ml", "o-"), ("noise", "s--")):
            for k in ISO_LABELS:
                xs, ys = [], []
                for r in results["iso"]:
                    if r["kind"] != kind:
                        continue
                    for s in r["sizes"]:
                        if (s["width"], s["height"]) == (1024, 768) or len(r["sizes"]) == 1:
                            if k in s["methods"]:
                                xs.append(r["size"])
                                ys.append(s["methods"][k][metric])
                if xs:
                    ax.plot(xs, ys, marker, label=f"{ISO_LABELS[k]} ({kind})")
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        ax.set_xlabel("volume size (samples per axis)")
        ax.set_ylabel("ms")
        ax.set_title(title)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=6)
    fig.tight_layout()
    path = out / f"{stem}_time_vs_size.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    written.append(path.name)
    for scene, images in error_images.items():
        if not images:
            continue
        fig, axes = plt.subplots(1, len(images), figsize=(3.2 * len(images), 3.2))
        axes = np.atleast_1d(axes)
        vmax = max(float(np.nanpercentile(img, 99)) for img in images.values()
                   if np.isfinite(img).any())
        for ax, (k, img) in zip(axes, images.items(), strict=True):
            shown = ax.imshow(img, cmap="magma", vmin=0, vmax=vmax)
            ax.set_title(ISO_LABELS[k], fontsize=7)
            ax.axis("off")
        fig.colorbar(shown, ax=list(axes), shrink=0.8, label="position error (voxels)")
        fig.suptitle(f"{scene}: distance to the exact surface", fontsize=9)
        slug = scene.replace(" ", "_").replace("^", "").replace("/", "")
        path = out / f"{stem}_error_{slug}.png"
        fig.savefig(path, dpi=100)
        plt.close(fig)
        written.append(path.name)
    return written


def write(results: dict[str, Any], error_images: dict[str, dict[str, np.ndarray]] | None,
          out: Path, stem: str) -> list[Path]:
    """JSON + markdown + plots into ``out``; returns the written paths."""
    out.mkdir(parents=True, exist_ok=True)
    if error_images is not None:  # None: keep the plots of the stored run (volume-only rerun)
        results["plots"] = plots(results, error_images, out, stem)
    results.setdefault("plots", [])
    (out / f"{stem}.json").write_text(json.dumps(results, indent=2, default=float))
    (out / f"{stem}.md").write_text(markdown(results))
    return [out / f"{stem}.json", out / f"{stem}.md", *(out / p for p in results["plots"])]
