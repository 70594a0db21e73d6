"""Viewer benchmark: interaction latency of `splinecast view`, driven like a user.

For each scene the server runs as its own process (`splinecast view FILE --no-browser`) and a
WebSocket client (`splinecast.viewer.client.ViewerClient`) drives it:

* **dragging:** an interactive request every 16 ms (a 60 Hz pointer) turning the camera by 1.5
  degrees; for every reduced frame received, the latency from the request it shows to its arrival;
  frames per second received while dragging; the reduced scales the server chose;
* **release:** after a short drag, the request of the final state (``interactive: false``, as the
  page sends on pointer-up); latency to the full-resolution PNG frame.

Baseline, interleaved with the releases (once before each, while the server is idle, so both
see the same load of a shared machine): ``Scene.render`` of the full-size frame in this process
(median; compiled and warmed up first) with the options the viewer derives from the same state
(``splinecast.viewer.state.parse_state``: its DVR settings, its normals, colour output only, as
the viewer renders), so ``release / direct`` is the viewer's overhead
(waiting for the drag's frame in flight, stripes, protocol, PNG encoding, transfer,
scheduling). The release frame's header splits the server's part: render (stripes and the 8-bit
conversion included) and PNG encoding. Once, the same is measured through the real page
in headless Chromium (Playwright), from the page's own frame log.

Scenes: Marschner-Lobb 256^3 (trilinear and s31 isosurfaces) and the MNI152 MRI from
``_machine.MRI`` in DVR (``examples/tf-mri.json``), at 1024x768. ``--quick``: Marschner-Lobb 64^3,
512x384, shorter drags (what to run on a busy machine).

Pyramid case (``--only pyramid`` runs just this one): Marschner-Lobb (256^3; ``--quick``
128^3) written as an OME-Zarr pyramid of 32^3 bricks and served by ``splinecast view x.zarr
--lod 3``. Each repetition starts a fresh server (cold brick cache; Numba's disk cache warmed by
a first, unmeasured server) and asks for the default view at full size: latency from the request
to the first frame (any pass), to the first full-resolution frame, and to the full frame whose
cut is complete (the header's ``bricks.complete``; refreshes while bricks land come between),
with the number of frames received; then the same for the view zoomed 3x, which needs finer
bricks. Baseline in the same run: ``MultiscaleScene.render(...,
complete=True)`` of the same view in this process on a fresh scene (cold cache, warm JIT).
Results: ``benchmarks/results/viewer_pyramid[_quick].json`` and ``.md``.

Run ``python benchmarks/bench_viewer.py [--quick] [--no-browser] [--only pyramid|volumes]``;
results go to ``benchmarks/results/viewer[_quick].json`` and ``.md``.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

import splinecast as sc
from splinecast.viewer.client import ViewerClient
from splinecast.viewer.state import default_state, parse_state

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _machine import MRI, describe  # noqa: E402

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
TF_MRI = ROOT / "examples" / "tf-mri.json"
POINTER_HZ = 60.0
DEGREES_PER_EVENT = 1.5
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run"]


def percentiles(values: list[float]) -> dict:
    if not values:
        return {"p50": None, "p95": None, "n": 0}
    return {"p50": float(np.percentile(values, 50)), "p95": float(np.percentile(values, 95)),
            "n": len(values)}


def scenes(quick: bool) -> list[dict]:
    ml = "demo:marschner-lobb?size=64" if quick else "demo:marschner-lobb?size=256"
    out = [
        {"name": "ml-trilinear-iso", "source": ml, "model": "trilinear", "mode": "iso",
         "state": {"iso": 0.5}},
        {"name": "ml-s31-iso", "source": ml, "model": "s31", "mode": "iso",
         "state": {"iso": 0.5}},
    ]
    if MRI.exists():
        tf = json.loads(TF_MRI.read_text())
        out.append({"name": "mri-trilinear-dvr", "source": str(MRI), "model": "trilinear",
                    "mode": "dvr", "state": {"tf": tf}})
    else:
        print(f"skipping the MRI: {MRI} not found", file=sys.stderr)
    return out


def direct_renderer(scene_spec: dict, size: tuple[int, int]) -> Callable[[], float]:
    """A function timing one ``Scene.render`` (ms) of the first viewer frame's state, in this
    process (compiled and warmed up first)."""
    vol = sc.read(scene_spec["source"])
    scene = sc.Scene(vol, model=scene_spec["model"])
    defaults = default_state(vol, model=scene_spec["model"], mode=scene_spec["mode"])
    request = parse_state({**scene_spec["state"], "size": list(size)}, vol, defaults)
    options = {"outputs": ("rgba",), **request.options}
    scene.render(request.camera, **options)  # compile and warm up
    scene.render(request.camera, **options)

    def once() -> float:
        start = time.perf_counter()
        scene.render(request.camera, **options)
        return (time.perf_counter() - start) * 1e3

    return once


class Server:
    """`splinecast view` in a subprocess; the URL is the first line it prints."""

    def __init__(self, spec: dict) -> None:
        cmd = [sys.executable, "-m", "splinecast.cli", "view", spec["source"], "--model",
               spec["model"], "--mode", spec["mode"], "--no-browser", "--quiet",
               *spec.get("extra", [])]
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True, env=env)
        self.url = self.proc.stdout.readline().strip()
        if not self.url.startswith("http://"):
            self.stop()
            raise RuntimeError(f"splinecast view did not print its URL: {self.url!r}")

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(60)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


async def drag(client: ViewerClient, state: dict, seconds: float, azimuth: float
               ) -> tuple[list, float, float]:
    """Interactive requests at the pointer rate for ``seconds``; returns the reduced frames
    received meanwhile, the final azimuth and the drag's duration.

    Between two requests the client waits for messages (so arrival times are exact) rather
    than running a second task: no receive is ever cancelled from outside.
    """
    frames: list = []
    start = time.perf_counter()
    period = 1.0 / POINTER_HZ
    sent = 0
    while (now := time.perf_counter()) < start + seconds:
        due = start + sent * period
        if now >= due:
            azimuth += DEGREES_PER_EVENT
            await client.render({**state, "camera": {"azimuth": azimuth}}, interactive=True)
            sent += 1
            continue
        try:
            got = await client.receive(timeout=due - now)
        except TimeoutError:
            continue
        if not isinstance(got, dict) and got.header["pass"] == "interactive":
            frames.append(got)
    return frames, azimuth, time.perf_counter() - start


async def measure(url: str, state: dict, drag_s: float, releases: int,
                  direct: Callable[[], float]) -> dict:
    """Drag and release through the server at ``url``; before each release's drag, one direct
    render in this process (``direct``), so both see the same load of a shared machine."""
    async with ViewerClient(url) as client:
        ident = await client.render(state)  # warm-up: scene preparation, compilation
        await client.frame(ident)
        _, azimuth, _ = await drag(client, state, min(1.0, drag_s), 0.0)  # warm-up
        release_ms, drag_latency, drag_render, fps, scales = [], [], [], [], []
        frames, azimuth, duration = await drag(client, state, drag_s, azimuth)
        drag_latency += [(f.received - client.sent_at(f.header["id"])) * 1e3 for f in frames]
        drag_render += [f.header["render_ms"] for f in frames]
        fps.append(len(frames) / duration)
        scales += [f.header["scale"] for f in frames]
        release_render, render_only, encode_only, stripes, direct_ms = [], [], [], [], []
        for _ in range(releases):
            direct_ms.append(direct())  # the server is idle: its last frame has arrived
            frames, azimuth, duration = await drag(client, state, 0.4, azimuth)
            ident = await client.render({**state, "camera": {"azimuth": azimuth}})
            final = await client.frame(ident)
            release_ms.append((final.received - client.sent_at(ident)) * 1e3)
            release_render.append(final.header["render_ms"] + final.header["encode_ms"])
            render_only.append(final.header["render_ms"])
            encode_only.append(final.header["encode_ms"])
            stripes.append(final.header["stats"].get("stripes"))
        return {"drag_latency_ms": percentiles(drag_latency),
                "drag_render_ms": percentiles(drag_render), "drag_fps": statistics.mean(fps),
                "drag_scales": sorted(set(scales)),
                "drag_scale_shares": {str(s): scales.count(s) / len(scales)
                                      for s in sorted(set(scales))},
                "release_ms": percentiles(release_ms),
                "release_samples_ms": release_ms,
                "release_render_encode_ms": percentiles(release_render),
                "release_server_render_ms": percentiles(render_only),
                "release_encode_ms": percentiles(encode_only), "release_stripes": stripes,
                "direct_ms": statistics.median(direct_ms), "direct_samples_ms": direct_ms}


def browser_once(spec: dict, size: tuple[int, int], drag_s: float, releases: int) -> dict:
    """The same measurements through the page in headless Chromium (page-side timings)."""
    from playwright.sync_api import sync_playwright

    chromium = os.environ.get("SPLINECAST_CHROMIUM") or shutil.which("chromium")
    if chromium is None:
        return {"skipped": "chromium is not installed (scripts/install_browser.sh)"}
    server = Server(spec)
    panel = 300  # the control panel's width in CSS pixels (viewer.css)
    try:
        with sync_playwright() as pw, tempfile.TemporaryDirectory() as profile:
            context = pw.chromium.launch_persistent_context(
                profile, executable_path=chromium, headless=True, args=CHROMIUM_ARGS,
                viewport={"width": size[0] + panel, "height": size[1]})
            page = context.new_page()
            page.set_default_timeout(600_000)
            page.goto(server.url)
            wait = ("(n) => { const v = window.splinecastViewer; return v && v.lastFrame &&"
                    " v.lastFrame.final && v.lastFrame.id > n; }")
            page.wait_for_function(wait, arg=0, timeout=600_000)
            canvas = page.evaluate("[document.getElementById('canvas').width,"
                                   " document.getElementById('canvas').height]")
            box = page.locator("#canvas").bounding_box()
            x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
            drag_latency, fps, release_ms = [], [], []
            for i in range(releases + 1):
                seconds = drag_s if i == 0 else 0.4
                page.evaluate("window.splinecastViewer.frameLog = []")
                page.mouse.move(x, y)
                page.mouse.down()
                start = time.perf_counter()
                step = 0
                while time.perf_counter() - start < seconds:
                    step += 1
                    page.mouse.move(x + 2 * (step % 100), y)
                    page.wait_for_timeout(1000 / POINTER_HZ)
                duration = time.perf_counter() - start
                before = page.evaluate("window.splinecastViewer.lastFrame.id")
                page.mouse.up()
                page.wait_for_function(wait, arg=before, timeout=600_000)
                log = page.evaluate("window.splinecastViewer.frameLog")
                moving = [f for f in log if f["pass"] == "interactive"]
                if i == 0:
                    drag_latency = [f["latency_ms"] for f in moving if f["latency_ms"]]
                    fps.append(len(moving) / duration)
                else:
                    release_ms += [f["latency_ms"] for f in log
                                   if f["final"] and f["id"] > before and f["latency_ms"]]
            context.close()
    finally:
        server.stop()
    return {"canvas": canvas, "drag_latency_ms": percentiles(drag_latency),
            "drag_fps": statistics.mean(fps) if fps else None,
            "release_ms": percentiles(release_ms)}


# ------------------------------------------------------------------------------ pyramid
ZOOM = 3.0  # the second view of a run: closer, so its cut needs bricks not read yet
#: Pixels per voxel before a brick is refined: the default view then stops at level 1, the
#: zoomed one needs level 0.
PYRAMID_LOD = 3.0


async def pyramid_view(url: str, size: tuple[int, int]) -> dict:
    """A fresh server: the default view (cold bricks, first frames of the process), then a
    zoomed view (warm process, new bricks) on the same connection."""
    async with ViewerClient(url) as client:
        first = await one_view(client, {"size": list(size)})
        zoomed = await one_view(client, {"size": list(size), "camera": {"zoom": ZOOM}})
    zoomed["new_bricks"] = zoomed["loaded"] - first["loaded"]
    return {**first, "zoomed": zoomed}


async def one_view(client: ViewerClient, state: dict) -> dict:
    """Latencies of one request to its first, first full and complete frames."""
    ident = await client.render(state)
    sent = client.sent_at(ident)
    first = first_full = first_progress = None
    frames = 0
    while True:
        got = await client.receive(timeout=600)
        if isinstance(got, dict) or got.header["id"] != ident:
            continue
        frames += 1
        ms = (got.received - sent) * 1e3
        first = ms if first is None else first
        if got.header["final"]:
            bricks = got.header["bricks"]
            if first_full is None:
                first_full, first_progress = ms, bricks["progress"]
            if bricks["complete"]:
                return {"first_ms": first, "first_full_ms": first_full, "complete_ms": ms,
                        "frames": frames, "cut": bricks["cut"], "loaded": bricks["loaded"],
                        "first_full_progress": first_progress}


def pyramid_case(quick: bool, size: tuple[int, int], repeats: int) -> dict:
    n = 128 if quick else 256
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"ml{n}.zarr"
        sc.build_pyramid(sc.demo("marschner-lobb", size=n), path, brick=32, progress=False)
        spec = {"source": str(path), "model": "trilinear", "mode": "iso",
                "extra": ["--lod", str(PYRAMID_LOD)]}
        # Direct baseline: a fresh scene per repetition (cold brick cache), JIT warmed first.
        mv = sc.read(path)
        cam = sc.Camera.orbit(mv, azimuth=30, elevation=20, size=size)
        with sc.Scene(mv, lod=PYRAMID_LOD) as scene:
            iso = float(sc.auto_iso(scene.preview))
            scene.render(cam, iso=iso, complete=True)
        direct = []
        for _ in range(repeats):
            with sc.Scene(sc.read(path), lod=PYRAMID_LOD) as scene:
                start = time.perf_counter()
                scene.render(cam, iso=iso, complete=True)
                direct.append((time.perf_counter() - start) * 1e3)
        warm = Server(spec)  # fills Numba's disk cache for the server processes
        try:
            asyncio.run(pyramid_view(warm.url, size))
        finally:
            warm.stop()
        runs = []
        for _ in range(repeats):
            server = Server(spec)
            try:
                runs.append(asyncio.run(pyramid_view(server.url, size)))
            finally:
                server.stop()
            print(json.dumps(runs[-1]), file=sys.stderr, flush=True)
    return {"name": f"ml{n}-pyramid-trilinear-iso", "levels": len(mv.levels), "brick": 32,
            "size": list(size), "runs": runs,
            "first_ms": percentiles([r["first_ms"] for r in runs]),
            "first_full_ms": percentiles([r["first_full_ms"] for r in runs]),
            "complete_ms": percentiles([r["complete_ms"] for r in runs]),
            "frames": [r["frames"] for r in runs], "cut": runs[0]["cut"],
            "zoomed": {key: percentiles([r["zoomed"][key] for r in runs])
                       for key in ("first_ms", "first_full_ms", "complete_ms")},
            "zoomed_frames": [r["zoomed"]["frames"] for r in runs],
            "zoomed_cut": runs[0]["zoomed"]["cut"],
            "zoomed_new_bricks": [r["zoomed"]["new_bricks"] for r in runs],
            "zoomed_first_full_progress": [round(r["zoomed"]["first_full_progress"], 3)
                                           for r in runs],
            "direct_complete_ms": statistics.median(direct), "direct_samples_ms": direct}


def write_pyramid_markdown(result: dict, path: Path) -> None:
    m, row = result["machine"], result["pyramid"]
    w, h = row["size"]
    lines = [
        "# Viewer benchmark: an OME-Zarr pyramid",
        "",
        f"Machine: {m['cpu']}, {m['cores']} logical cores. Command: `{result['command']}`. "
        f"{result['note']}",
        "",
        f"{row['name']}: {row['levels']} levels of {row['brick']}^3 bricks, `--lod "
        f"{PYRAMID_LOD:g}`, image {w}x{h}, "
        f"the default view's cut has {row['cut']} bricks. Each run starts a fresh "
        "`splinecast view x.zarr` (cold brick cache, Numba's disk cache warm: the process's "
        "first frames include loading the compiled kernels) and requests the default view: "
        "latency to the first frame (a coarse one), to the first full frame, and to the full "
        "frame with the complete cut (`bricks.complete`). Then, on the same connection, the "
        f"view zoomed {ZOOM:g}x (a cut of {row['zoomed_cut']} bricks, of which "
        f"{row['zoomed_new_bricks']} per run were read while it was shown (prefetch included); "
        "until they land, frames draw "
        "their resident ancestors). Direct: "
        "`MultiscaleScene.render(complete=True)` of the same view on a fresh scene in one "
        f"process (median of {len(row['direct_samples_ms'])}).",
        "",
        "| | p50 ms | p95 ms | runs |",
        "|---|---|---|---|",
    ]
    for key, label in (("first_ms", "first frame"), ("first_full_ms", "first full frame"),
                       ("complete_ms", "complete frame")):
        for view, values in (("default view", row), (f"zoomed {ZOOM:g}x", row["zoomed"])):
            p = values[key]
            lines.append(f"| {view}: {label} | {p['p50']:.0f} | {p['p95']:.0f} | {p['n']} |")
    progress = [round(r["first_full_progress"], 2) for r in row["runs"]]
    lines += ["", f"Frames received per run (coarse, full, refreshes): {row['frames']}; share "
              f"of the cut resident in the first full frame: {progress}. Zoomed view: frames "
              f"{row['zoomed_frames']}, share resident in its first full frame "
              f"{row['zoomed_first_full_progress']}. "
              f"Direct complete render: {row['direct_complete_ms']:.0f} ms; complete frame / "
              f"direct = {row['complete_ms']['p50'] / row['direct_complete_ms']:.2f}."]
    path.write_text("\n".join(lines) + "\n")


def write_markdown(result: dict, path: Path) -> None:
    m = result["machine"]
    w, h = result["size"]
    lines = [
        "# Viewer benchmark",
        "",
        f"Machine: {m['cpu']}, {m['cores']} logical cores, Numba threading layer "
        f"{m.get('numba_threading_layer')}. Command: `{result['command']}`. "
        f"{result['note']}",
        "",
        f"Image {w}x{h}. Dragging: interactive requests at {POINTER_HZ:g} Hz; latency from a "
        "request to the reduced JPEG frame showing it; fps = reduced frames received per "
        "second; reduced scales: the share of the drag's frames at each scale. Release: latency "
        "from the final request (sent after a 0.4 s drag, so a drag frame may still be in "
        "flight) to the full-resolution PNG frame; the server's render (stripes and the 8-bit "
        "conversion included) and PNG encoding of it. Direct: `Scene.render` of the full frame "
        "in the benchmark's process with the options the viewer derives from the same state, "
        "colour only, once before each release (median), so both see the same load. Load: the "
        "machine's 1-minute load average before and after the scene's run.",
        "",
        "| scene | drag p50 ms | drag p95 ms | server render p50 ms (drag) | drag fps | "
        "reduced scales | release p50 ms | release p95 ms | server render p50 ms (release) | "
        "PNG encode p50 ms | direct ms | release / direct | load |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in result["scenes"]:
        d, r = row["drag_latency_ms"], row["release_ms"]
        shares = row.get("drag_scale_shares") or {}
        scales = ", ".join(
            f"1/{round(1 / s)}" + (f" ({max(shares[str(s)], 0.01):.0%})" if str(s) in shares
                                   else "")
            for s in sorted(row["drag_scales"], reverse=True))
        lines.append(
            f"| {row['name']} | {d['p50']:.0f} | {d['p95']:.0f} | "
            f"{row['drag_render_ms']['p50']:.0f} | {row['drag_fps']:.1f} | {scales} | "
            f"{r['p50']:.0f} | {r['p95']:.0f} | {row['release_server_render_ms']['p50']:.0f} | "
            f"{row['release_encode_ms']['p50']:.0f} | "
            f"{row['direct_ms']:.0f} | {r['p50'] / row['direct_ms']:.2f} | "
            f"{', '.join(f'{v:g}' for v in row.get('load', []))} |")
    b = result.get("browser")
    if b:
        lines += ["", f"Through the page in headless Chromium ({result['browser_scene']}):", ""]
        if "skipped" in b:
            lines.append(f"skipped: {b['skipped']}")
        else:
            d, r = b["drag_latency_ms"], b["release_ms"]
            lines += [
                "| canvas | drag p50 ms | drag p95 ms | drag fps | release p50 ms | "
                "release p95 ms |",
                "|---|---|---|---|---|---|",
                f"| {b['canvas'][0]}x{b['canvas'][1]} | {d['p50']:.0f} | {d['p95']:.0f} | "
                f"{b['drag_fps']:.1f} | {r['p50']:.0f} | {r['p95']:.0f} |",
            ]
    path.write_text("\n".join(lines) + "\n")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small volume and image, short")
    parser.add_argument("--no-browser", action="store_true", help="skip the Chromium run")
    parser.add_argument("--only", choices=("volumes", "pyramid"),
                        help="run only the in-memory volumes or only the pyramid case")
    args = parser.parse_args()
    size = (512, 384) if args.quick else (1024, 768)
    drag_s = 1.5 if args.quick else 8.0
    releases = 3 if args.quick else 10
    repeats = 3 if args.quick else 7  # the pyramid case's fresh servers
    command = "python benchmarks/bench_viewer.py" + (" --quick" if args.quick else "")
    note = ("Percentiles over one run; on a shared machine (other jobs running) the timings are "
            "noisy.")
    out = HERE / "results"
    if args.only != "volumes":
        print("pyramid ...", file=sys.stderr, flush=True)
        result = {"command": command + " --only pyramid", "note": note, "machine": describe(),
                  "pyramid": pyramid_case(args.quick, size, repeats)}
        stem = "viewer_pyramid_quick" if args.quick else "viewer_pyramid"
        (out / f"{stem}.json").write_text(json.dumps(result, indent=2) + "\n")
        write_pyramid_markdown(result, out / f"{stem}.md")
        print(out / f"{stem}.md")
        if args.only == "pyramid":
            return
    rows = []
    specs = scenes(args.quick)
    for spec in specs:
        print(f"{spec['name']}: direct render ...", file=sys.stderr, flush=True)
        direct = direct_renderer(spec, size)
        print(f"{spec['name']}: viewer ...", file=sys.stderr, flush=True)
        load = os.getloadavg()[0]
        server = Server(spec)
        try:
            state = {**spec["state"], "size": list(size)}
            row = asyncio.run(measure(server.url, state, drag_s, releases, direct))
        finally:
            server.stop()
        row.update(name=spec["name"], source=spec["source"], model=spec["model"],
                   mode=spec["mode"], load=[round(load, 1), round(os.getloadavg()[0], 1)])
        rows.append(row)
        print(json.dumps(row), file=sys.stderr, flush=True)
    result = {"command": command, "note": note, "machine": describe(), "size": list(size),
              "scenes": rows}
    if not args.no_browser:
        result["browser_scene"] = specs[0]["name"]
        print("browser ...", file=sys.stderr, flush=True)
        result["browser"] = browser_once(specs[0], size, drag_s, min(releases, 3))
    stem = "viewer_quick" if args.quick else "viewer"
    (out / f"{stem}.json").write_text(json.dumps(result, indent=2) + "\n")
    write_markdown(result, out / f"{stem}.md")
    print(out / f"{stem}.md")


if __name__ == "__main__":
    main()
