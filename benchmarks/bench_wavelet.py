"""Spline-wavelet multiresolution benchmark: Steinberger 2010's Table 6.4 on the CPU.

1. Decomposition: time and peak traced memory (``tracemalloc``: numpy's allocations) of the
   in-memory decomposition and of the block-streamed one (memory-mapped source and sink).
2. View-dependent LOD for several ε (multiples of one pixel's angle, ``fov / height``) from a
   close orbit view at 1024x768: selection ms, share of chunks, bricks drawn per level,
   reconstruction ms from scratch (every brick of the frame computed, as the thesis does per
   frame) and after a 2° orbit step with the cache of the previous frame (bricks reused / made).
3. Store and rendering: the decomposition written to a Zarr store
   (``sc.build_pyramid(..., kind="wavelet")``: time and peak traced memory), then
   ``Scene(store, lod=ε)`` frames at the render size for several ε (in pixels of a 1024x768
   image whatever the render size, so the rows match the LOD table's): the first frame
   (selection, reconstruction of every brick, grids) and the median steady frame (bricks and
   grids reused) in ms, the share of chunks reconstructed and refined, and the image MSE (RGB in
   [0, 1]) against the full-resolution render of the in-memory ``bspline<d>`` model, whose
   time is the baseline of the ratio column. The Chmutov stores are rendered from a close-up
   (zoom 2.5, nearly every ray hits within a few cells), the 512^3 store from a view of the
   whole volume (zoom 1), where rays cross many cells.

Run ``python benchmarks/bench_wavelet.py [--quick]``; results go to
``benchmarks/results/wavelet[_quick].json`` and ``.md``. Medians after warm-up.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

import splinecast as sc
from splinecast.multires.wavelet.lod import select
from splinecast.multires.wavelet.reconstruct import ChunkReconstructor
from splinecast.multires.wavelet.transform import MemmapSink, decompose

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _machine import describe, median_ms  # noqa: E402

HERE = Path(__file__).resolve().parent
PIXEL_MULTIPLES = (0, 25, 50, 100, 200, 400, 800)
THESIS_TABLE_6_4 = {"reconstruction_ms": [7.23, 8.72, 9.25, 6.11, 6.92, 3.58],
                    "chunks_percent": [100, 73, 40, 12, 6, 1.6]}


def peak_mib(fn) -> float:
    tracemalloc.start()
    fn()
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return peak / 2**20


def bench_decomposition(vol, degree: int, dtype, repeats: int) -> dict:
    data = vol.data
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "src.npy"
        np.save(src, data)
        mapped = np.load(src, mmap_mode="r")

        def streamed(i=[0]):  # noqa: B006 - a fresh sink folder per run
            i[0] += 1
            return decompose(mapped, degree, dtype=dtype, block=32,
                             sink=MemmapSink(Path(tmp) / f"pyr{i[0]}"))

        in_memory = lambda: decompose(data, degree, dtype=dtype)  # noqa: E731
        return {
            "in_memory_ms": median_ms(in_memory, repeats),
            "in_memory_peak_mib": peak_mib(in_memory),
            "streamed_ms": median_ms(streamed, repeats),
            "streamed_peak_mib": peak_mib(streamed),
            "volume_mib": data.nbytes / 2**20,
        }


def bench_lod(vol, pyramid, iso: float, size, repeats: int) -> list[dict]:
    lay = pyramid.layout
    cam = sc.Camera.orbit(vol, azimuth=30, elevation=20, size=size, zoom=2.5)
    step = sc.Camera.orbit(vol, azimuth=32, elevation=20, size=size, zoom=2.5)
    pixel = math.radians(cam.fov) / cam.size[1]
    rows = []
    for multiple in PIXEL_MULTIPLES:
        eps = multiple * pixel

        def choose(camera=cam, eps=eps):
            return select(lay, pyramid.ranges, camera.position, eps, iso=iso,
                          spacing=vol.spacing, origin=vol.origin)

        sel = choose()
        select_ms = median_ms(choose, repeats)

        def cold(sel=sel):
            ChunkReconstructor(pyramid).update(sel)

        cold_ms = median_ms(cold, repeats)
        warm = []
        for _ in range(repeats):
            rec = ChunkReconstructor(pyramid)
            rec.update(sel)
            moved = choose(step)
            stats = rec.update(moved)
            warm.append(stats)
        drawn = {}
        for level, _, _ in sel.drawn():
            drawn[level] = drawn.get(level, 0) + 1
        rows.append({
            "epsilon_pixels": multiple,
            "epsilon": eps,
            "select_ms": select_ms,
            "chunks": sel.chunk_count,
            "chunks_percent": 100.0 * sel.share,
            "drawn_bricks_per_level": [drawn.get(j, 0) for j in range(lay.levels + 1)],
            "reconstruct_cold_ms": cold_ms,
            "reconstruct_after_step_ms": statistics.median(s.milliseconds for s in warm),
            "after_step_computed": sum(warm[-1].computed),
            "after_step_reused": sum(warm[-1].reused),
        })
    return rows


RENDER_MULTIPLES = (0, 25, 50, 100, 200, 400)


def bench_store_render(vol, degree: int, dtype, iso: float, size, repeats: int,
                       multiples: tuple[int, ...], zoom: float = 2.5) -> dict:
    """Store build (time, peak memory) and frames of ``Scene(store, lod=ε)`` against the
    full-resolution in-memory render, from an orbit view at ``zoom``."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "w.zarr"
        source = sc.Volume(vol.data.astype(dtype), spacing=vol.spacing, origin=vol.origin)

        def build(n=[0]):  # noqa: B006 - a fresh store per run
            n[0] += 1
            return sc.build_pyramid(source, Path(tmp) / f"w{n[0]}.zarr", kind="wavelet",
                                    degree=degree, dtype=dtype, progress=False)

        start = time.perf_counter()
        sc.build_pyramid(source, path, kind="wavelet", degree=degree, dtype=dtype,
                         progress=False)
        build_ms = (time.perf_counter() - start) * 1e3
        build_peak = peak_mib(build)
        store = sc.read(path)
        cam = sc.Camera.orbit(vol, azimuth=30, elevation=20, size=size, zoom=zoom)
        pixel = math.radians(cam.fov) / 768  # ε in pixels of a 1024x768 image, as in bench_lod
        ref = sc.Scene(source, model=f"bspline{degree}")
        full = ref.render(cam, iso=iso)
        full_ms = median_ms(lambda: ref.render(cam, iso=iso), repeats)
        # Compile the cut launch for this store's model, mode and dtype outside the timings
        # (a small image at every ε): without it the first timed frame held the compilation
        # (70 s of the quick run's ε = 0 "first frame").
        small = sc.Camera.orbit(vol, azimuth=30, elevation=20, size=(32, 24), zoom=zoom)
        for multiple in multiples:
            sc.Scene(store, lod=multiple * pixel).render(small, iso=iso)
        rows = []
        for multiple in multiples:
            scene = sc.Scene(store, lod=multiple * pixel)
            start = time.perf_counter()
            first = scene.render(cam, iso=iso)
            first_ms = (time.perf_counter() - start) * 1e3
            frames = []

            def steady(scene=scene, frames=frames):
                frames.append(scene.render(cam, iso=iso))

            steady_ms = median_ms(steady, repeats)
            frame = frames[-1]
            mse = float(np.mean((frame.rgba[..., :3].astype(np.float64)
                                 - full.rgba[..., :3].astype(np.float64)) ** 2))
            hits = np.isfinite(full.depth)
            st = first.stats
            rows.append({
                "epsilon_pixels": multiple, "epsilon": multiple * pixel,
                "chunks_percent": 100.0 * st["chunk_share"],
                "active_percent": 100.0 * st["active_chunks"] / store.layout.chunk_total(),
                "drawables": st["drawables"],
                "first_frame_ms": first_ms, "first_reconstruct_ms": st["reconstruct_ms"],
                "select_ms": frame.stats["select_ms"],
                "steady_frame_ms": steady_ms, "steady_trace_ms": frame.stats["trace_ms"],
                "ratio_to_full_resolution": full_ms / steady_ms,
                "mse_rgb": mse,
                "hit_mismatch_percent": 100.0 * float(np.mean(hits != np.isfinite(frame.depth))),
                "details_read": st["details_read"],
            })
        return {"store_build_ms": build_ms, "store_build_peak_mib": build_peak,
                "full_resolution_ms": full_ms, "size": list(size), "zoom": zoom,
                "render": rows}


def markdown(results: dict) -> str:
    m = results["machine"]
    lines = [
        "# Spline-wavelet LOD (Steinberger 2010 Table 6.4)",
        "",
        f"`{results['command']}` — {m['cpu']}, {m['cores']} cores, numba "
        f"{m['versions']['numba']}, {m['numba_threads']} threads. {results['note']}",
        "",
    ]
    for v in results["volumes"]:
        dec = v["decomposition"]
        lines += [
            f"## {v['label']} {v['shape'][0]}^3, degree {v['degree']}, iso {v['iso']}, "
            f"{v['dtype']}, {v['levels']} levels, {v['chunk_total']} chunks (k = {v['chunk']})",
            "",
            f"Decomposition: in memory {dec['in_memory_ms']:.0f} ms, peak "
            f"{dec['in_memory_peak_mib']:.0f} MiB; streamed (memmap in/out, 32^3 blocks) "
            f"{dec['streamed_ms']:.0f} ms, peak {dec['streamed_peak_mib']:.0f} MiB; "
            f"volume {dec['volume_mib']:.0f} MiB.",
            "",
            "| ε (pixels) | chunks | chunks % | bricks drawn per level (0..J) | select ms "
            "| reconstruct ms | after 2° step ms (made / reused) |",
            "|---|---|---|---|---|---|---|",
        ]
        for r in v["lod"]:
            lines.append(
                f"| {r['epsilon_pixels']} | {r['chunks']} | {r['chunks_percent']:.1f} | "
                f"{' / '.join(map(str, r['drawn_bricks_per_level']))} | {r['select_ms']:.2f} | "
                f"{r['reconstruct_cold_ms']:.1f} | {r['reconstruct_after_step_ms']:.1f} "
                f"({r['after_step_computed']} / {r['after_step_reused']}) |")
        lines.append("")
        st = v.get("store")
        if st:
            w, h = st["size"]
            lines += [
                f"Zarr store (`build_pyramid(kind=\"wavelet\")`): {st['store_build_ms']:.0f} ms, "
                f"peak {st['store_build_peak_mib']:.0f} MiB. Rendering {w}x{h}, iso "
                f"{v['iso']}, zoom {st.get('zoom', 2.5)}: full-resolution in-memory "
                f"`bspline{v['degree']}` "
                f"{st['full_resolution_ms']:.0f} ms per frame.",
                "",
                "| ε (pixels) | chunks % | refined % | drawables | first frame ms (reconstruct) "
                "| steady frame ms (trace) | full-res time / frame time | MSE (RGB) "
                "| hit mismatch % |",
                "|---|---|---|---|---|---|---|---|---|",
            ]
            for r in st["render"]:
                lines.append(
                    f"| {r['epsilon_pixels']} | {r['chunks_percent']:.1f} | "
                    f"{r['active_percent']:.1f} | {r['drawables']} | {r['first_frame_ms']:.0f} "
                    f"({r['first_reconstruct_ms']:.0f}) | {r['steady_frame_ms']:.0f} "
                    f"({r['steady_trace_ms']:.0f}) | {r['ratio_to_full_resolution']:.2f} | "
                    f"{r['mse_rgb']:.2e} | {r['hit_mismatch_percent']:.2f} |")
            lines.append("")
    lines += [
        "Thesis (GTX 285, Dragon 128^3, tri-cubic): reconstruction 7.23 / 8.72 / 9.25 / 6.11 / "
        "6.92 / 3.58 ms at 100 / 73 / 40 / 12 / 6 / 1.6 % of 4681 chunks.",
        "",
    ]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes, few repeats")
    parser.add_argument("--out", default=str(HERE / "results"), help="output folder")
    parser.add_argument("--render-size", default=None,
                        help="image size of the store rendering part (default 1024x768, "
                             "256x192 with --quick)")
    args = parser.parse_args()
    size = (1024, 768)
    render_size = sc.camera.parse_size(args.render_size or ("256x192" if args.quick
                                                            else "1024x768"))
    repeats = 2 if args.quick else 5
    if args.quick:
        cases = [("chmutov", 64, 0.0, 3, np.float64), ("noise", 96, 0.5, 3, np.float32)]
        render_cases = {("chmutov", 64, 3): (2.5, (0, 50, 100, 200, 400, 800))}
    else:
        cases = [("chmutov", 128, 0.0, d, np.float64) for d in (1, 2, 3)]
        cases.append(("noise", 512, 0.5, 3, np.float32))
        # (zoom, ε in pixels): the Chmutov views are close-ups where nearly every ray hits
        # within a few cells; the 512^3 view shows the whole volume (zoom 1, about one voxel
        # per pixel), where rays cross many cells and coarser levels can save traversal.
        render_cases = {("chmutov", 128, 1): (2.5, RENDER_MULTIPLES),
                        ("chmutov", 128, 3): (2.5, RENDER_MULTIPLES),
                        ("noise", 512, 3): (1.0, (0, 5, 10, 25, 50, 100, 200))}
    # Warm-up: compile every kernel once outside the timings.
    warm = sc.demo("chmutov", size=12)
    for dtype in {np.dtype(c[4]) for c in cases}:
        warm_pyr = decompose(warm.data, 3, chunk=4, dtype=dtype)
        ChunkReconstructor(warm_pyr).update(select(warm_pyr.layout, warm_pyr.ranges, (0, 0, 0),
                                                   0.0))
    results = {
        "machine": describe(),
        "command": "python benchmarks/bench_wavelet.py" + (" --quick" if args.quick else ""),
        "note": "Run on a machine shared with other jobs unless stated otherwise.",
        "thesis_table_6_4": THESIS_TABLE_6_4,
        "volumes": [],
    }
    for label, n, iso, degree, dtype in cases:
        vol = sc.demo(label, size=n)
        pyramid = decompose(vol.data, degree, dtype=dtype)
        lay = pyramid.layout
        entry = {
            "label": label, "shape": list(vol.shape), "degree": degree, "iso": iso,
            "dtype": np.dtype(dtype).name, "levels": lay.levels, "chunk": lay.chunk,
            "chunk_total": lay.chunk_total(), "window": list(lay.window),
            "decomposition": bench_decomposition(vol, degree, dtype, 1 if args.quick else 3),
            "lod": bench_lod(vol, pyramid, iso, size, repeats),
        }
        if (label, n, degree) in render_cases:
            zoom, multiples = render_cases[label, n, degree]
            entry["store"] = bench_store_render(vol, degree, dtype, iso, render_size, repeats,
                                                multiples, zoom)
        results["volumes"].append(entry)
        print(f"{label} {n}^3 degree {degree}: done", flush=True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    stem = "wavelet_quick" if args.quick else "wavelet"
    (out / f"{stem}.json").write_text(json.dumps(results, indent=2) + "\n")
    (out / f"{stem}.md").write_text(markdown(results))
    print(markdown(results))


if __name__ == "__main__":
    main()
