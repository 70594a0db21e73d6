"""A model or mode whose kernels are not compiled yet never stops the viewer's frames.

The session renders views with ready kernels only; a view that needs new ones has them prepared
on another thread while the page goes on getting frames of the last state that renders, seen
from the new camera, with status messages saying what is prepared; then the newest view is
rendered, and a newer view for other new kernels is prepared next (the newest wins).

The session logic is checked with a renderer whose "new" models need a preparation the test
releases by hand (events, no sleeps); the renderer's own preparation is checked in a fresh
process with an empty kernel cache, where it really compiles.
"""

from __future__ import annotations

import asyncio
import importlib.util
import io
import json
import os
import subprocess
import sys
import textwrap
import threading

import numpy as np
import pytest
from PIL import Image

import splinecast as sc
from splinecast._jit import CompileNeeded, forbidding_compiles
from splinecast.viewer.protocol import unpack_frame
from splinecast.viewer.renderer import FrameRenderer, RenderedImage
from splinecast.viewer.session import Session
from splinecast.viewer.state import default_state, resized_camera

NEW_MODELS = ("s31", "bspline3")  # models whose kernels the fake renderer "compiles"
SIZE = [48, 36]


@pytest.fixture(scope="module")
def vol() -> sc.Volume:
    return sc.demo("marschner-lobb", size=16)


class _Renderer(FrameRenderer):
    """Renders trilinear views for real; a view of a model in :data:`NEW_MODELS` needs its
    preparation, which waits until the test releases it, and then renders one flat colour."""

    def __init__(self, vol):
        super().__init__(vol)
        self.release = {model: threading.Event() for model in NEW_MODELS}
        self.warming: list[str] = []
        self.prepared: set[str] = set()
        self.done = {model: threading.Event() for model in NEW_MODELS}

    def render(self, request, scale=1.0, abort=None, step="full", compile=True):
        if request.model in NEW_MODELS:
            if request.model not in self.prepared and not compile:
                raise CompileNeeded(f"{request.model} kernels")
            w = max(1, round(request.camera.width * scale))
            h = max(1, round(request.camera.height * scale))
            rgba = np.full((h, w, 4), (10, 200, 30, 255), np.uint8)
            return RenderedImage(rgba, {"model": request.model, "mode": request.mode},
                                 1.0, h / request.camera.height)
        return super().render(request, scale, abort, step, compile)

    def warm(self, request, on_compile=None):
        if request.model not in NEW_MODELS:  # real kernels (an empty cache compiles them)
            return super().warm(request, on_compile)
        self.warming.append(request.model)
        if on_compile is not None:
            on_compile()
        assert self.release[request.model].wait(timeout=600)
        self.prepared.add(request.model)
        self.done[request.model].set()


class _Page:
    """What the session sends, and a way to wait for a message that matches."""

    def __init__(self):
        self.texts: list[dict] = []
        self.frames: list[tuple[dict, bytes]] = []
        self.changed = asyncio.Event()

    async def send_text(self, message):
        self.texts.append(message)
        self.changed.set()

    async def send_bytes(self, data):
        self.frames.append(unpack_frame(data))
        self.changed.set()

    async def until(self, predicate, what):
        async def wait():
            while not predicate():
                self.changed.clear()
                await self.changed.wait()
        await asyncio.wait_for(wait(), timeout=600)
        return predicate()


def _frame(page, ident, final):
    for header, data in page.frames:
        if header["id"] == ident and header["final"] == final:
            return header, data
    return None


def test_new_kernels_are_prepared_aside_while_frames_go_on(vol):
    renderer = _Renderer(vol)
    defaults = default_state(vol)

    async def check():
        page = _Page()
        render_thread = asyncio.Semaphore(1)

        async def run_in_thread(fn):
            async with render_thread:
                return await asyncio.to_thread(fn)

        session = Session(renderer, run_in_thread, page.send_text, page.send_bytes, defaults,
                          10**6)
        task = asyncio.create_task(session.run())

        async def send(ident, state, interactive=False):
            await session.handle_text(json.dumps({"type": "render", "id": ident,
                                                  "interactive": interactive, "state": state}))

        try:
            await send(1, {"size": SIZE})
            await page.until(lambda: _frame(page, 1, True), "the first view")
            # A new model: no final frame until its kernels are ready; meanwhile a frame of the
            # last view that renders (trilinear) from the new camera, and status messages.
            # (from above: Marschner-Lobb turned about its axis looks much the same)
            await send(2, {"size": SIZE, "model": "s31",
                           "camera": {"azimuth": 80.0, "elevation": 80.0}})
            await page.until(lambda: _frame(page, 2, False), "a frame while s31 is prepared")
            header, data = _frame(page, 2, False)
            assert header["pass"] == "preparing" and header["stats"]["model"] == "trilinear"
            assert header["preparing"]["model"] == "s31" and header["preparing"]["compiling"]
            shown = np.asarray(Image.open(io.BytesIO(data)).convert("RGBA"))
            cam = sc.Camera.orbit(vol, azimuth=80.0, elevation=80.0, size=tuple(SIZE))
            cam = resized_camera(cam, header["width"], header["height"])
            # (a preview: one ray a pixel)
            want = sc.Scene(vol).render(cam, iso=defaults["iso"], samples=1).to_uint8()
            # JPEG: the picture of the trilinear surface from the new camera, not the old one.
            near = np.abs(shown[..., :3].astype(int) - want[..., :3]).mean()
            old = sc.Scene(vol).render(resized_camera(sc.Camera.orbit(vol, size=tuple(SIZE)),
                                                      header["width"], header["height"]),
                                       iso=defaults["iso"], samples=1).to_uint8()
            far = np.abs(shown[..., :3].astype(int) - old[..., :3]).mean()
            assert near < 12 and far > 2 * near, (near, far)
            # The first status may come before the preparation knows it compiles (it says
            # "loading" then); one says "compiling" once it does.
            await page.until(lambda: any((t.get("preparing") or {}).get("compiling")
                                         for t in page.texts), "a status")
            status = next(t for t in page.texts if (t.get("preparing") or {}).get("compiling"))
            assert status["message"].startswith("preparing s31 / iso: compiling kernels")
            # A drag keeps getting frames while s31 compiles.
            await send(3, {"size": SIZE, "model": "s31", "camera": {"azimuth": 90.0}},
                       interactive=True)
            await page.until(lambda: _frame(page, 3, False), "a drag frame")
            # Another new model before s31 is ready: the newest wins.
            await send(4, {"size": SIZE, "model": "bspline3"})
            await page.until(lambda: _frame(page, 4, False), "a frame while bspline3 waits")
            renderer.release["s31"].set()
            await page.until(lambda: renderer.warming == ["s31", "bspline3"], "bspline3 next")
            renderer.release["bspline3"].set()
            await page.until(lambda: _frame(page, 4, True), "the newest view, final")
            header, data = _frame(page, 4, True)
            assert header["stats"]["model"] == "bspline3"
            image = np.asarray(Image.open(io.BytesIO(data)).convert("RGBA"))
            assert (image == (10, 200, 30, 255)).all()
            # s31's views were superseded: no final frame of them; the wait is over.
            assert _frame(page, 2, True) is None and _frame(page, 3, True) is None
            await page.until(lambda: [t["preparing"] for t in page.texts
                                      if "preparing" in t][-1] is None, "ready")
        finally:
            session.close()
            task.cancel()
            for event in renderer.release.values():
                event.set()

    asyncio.run(check())


def test_a_view_of_ready_kernels_ends_the_wait(vol):
    """Back to a model that renders before the new one is ready: its final frame comes at once
    and the preparation's end renders nothing more."""
    renderer = _Renderer(vol)
    defaults = default_state(vol)

    async def check():
        page = _Page()

        async def run_in_thread(fn):
            return await asyncio.to_thread(fn)

        session = Session(renderer, run_in_thread, page.send_text, page.send_bytes, defaults,
                          10**6)
        task = asyncio.create_task(session.run())

        async def send(ident, state):
            await session.handle_text(json.dumps({"type": "render", "id": ident,
                                                  "interactive": False, "state": state}))

        try:
            await send(1, {"size": SIZE})
            await page.until(lambda: _frame(page, 1, True), "the first view")
            await send(2, {"size": SIZE, "model": "s31"})
            await page.until(lambda: _frame(page, 2, False), "a preparing frame")
            await send(3, {"size": SIZE, "model": "trilinear", "camera": {"azimuth": 10.0}})
            await page.until(lambda: _frame(page, 3, True), "the ready view, final")
            renderer.release["s31"].set()
            # Nothing is sent when it ends (no view waits for it): wait on the renderer and
            # the preparing task themselves.
            assert await asyncio.to_thread(renderer.done["s31"].wait, 600)
            await asyncio.wait_for(asyncio.shield(session._preparing), timeout=600)
            assert _frame(page, 2, True) is None
        finally:
            session.close()
            task.cancel()
            for event in renderer.release.values():
                event.set()

    asyncio.run(check())


def _import(path, name):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_forbidding_compiles_refuses_only_what_must_compile(tmp_path):
    """Under ``forbidding_compiles`` a kernel in memory runs and one in the disk cache loads;
    one that must compile raises before any work; other threads are not affected."""
    source = tmp_path / "kernels_under_test.py"
    source.write_text("from splinecast._jit import jit\n\n\n@jit\ndef double(x):\n"
                      "    return 2 * x\n")
    first = _import(source, "kernels_under_test_a")
    with forbidding_compiles(), pytest.raises(CompileNeeded, match="double"):
        first.double(1.5)
    assert first.double(1.5) == 3.0  # compiled here, saved to the disk cache
    with forbidding_compiles():
        assert first.double(2.5) == 5.0  # in memory
    second = _import(source, "kernels_under_test_b")  # a new dispatcher: nothing in memory
    with forbidding_compiles():
        assert second.double(4.0) == 8.0  # loaded from the disk cache
    done = []
    with forbidding_compiles():  # another thread may compile
        thread = threading.Thread(target=lambda: done.append(first.double(np.int64(3))))
        thread.start()
        thread.join()
    assert done == [6]


_CHILD = textwrap.dedent("""
    import numpy as np
    import splinecast as sc
    from splinecast._jit import CompileNeeded
    from splinecast.viewer.renderer import FrameRenderer
    from splinecast.viewer.state import default_state, parse_state

    vol = sc.Volume((sc.demo("sphere", size=20).data * 1000 + 2000).astype(np.uint16))
    renderer = FrameRenderer(vol)
    request = parse_state({"mode": "mip", "size": [40, 30]}, vol, default_state(vol))
    try:
        renderer.render(request, compile=False)
    except CompileNeeded:
        print("needed")
    compiled = []
    renderer.warm(request, on_compile=lambda: compiled.append(1))
    print("compiled" if compiled else "loaded")
    for step in ("full", "interactive"):
        image = renderer.render(request, step=step, compile=False)
    expected = sc.Scene(vol).render(request.camera, **request.options).to_uint8()
    print("same" if np.array_equal(renderer.render(request, compile=False).rgba, expected)
          else "different")
""")


def test_warming_prepares_what_a_view_then_renders_without_compiling(tmp_path):
    """In a process with an empty kernel cache: a view needs compiling; the renderer's
    preparation (a tiny volume of the same voxel type) compiles what the real view then
    renders with, in both passes, loading nothing new."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    out = subprocess.run([sys.executable, "-c", _CHILD], capture_output=True, text=True,
                         env=env, timeout=1800)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["needed", "compiled", "same"], out.stdout + out.stderr
