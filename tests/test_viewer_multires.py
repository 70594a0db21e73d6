"""The viewer on multiresolution data: OME-Zarr pyramids (bricks loaded while the page looks) and
spline-wavelet stores; progressive refinement of slow frames.

References: ``MultiscaleScene.render(..., complete=True)`` and ``Scene(store, lod=eps).render``
of separately opened scenes, with cameras built by hand (``Camera.orbit`` of the full-resolution
volume); ``Scene.render`` of the in-memory volume for progressive frames. The brick loader is
held (``Level.read`` waits on an event the test sets) so frames arrive while bricks are still
missing.
"""

from __future__ import annotations

import asyncio
import json
import os
import signal
import subprocess
import sys
import threading
import time
import urllib.request

import numpy as np
import pytest

import splinecast as sc

pytest.importorskip("zarr")
pytest.importorskip("aiohttp")

from splinecast.io.omezarr import Level  # noqa: E402
from splinecast.multires.scenes.multiscale import MultiscaleScene  # noqa: E402
from splinecast.viewer.client import ServerError, ViewerClient  # noqa: E402
from splinecast.viewer.data import shown  # noqa: E402
from splinecast.viewer.renderer import FrameRenderer  # noqa: E402
from splinecast.viewer.server import ViewerServer  # noqa: E402
from splinecast.viewer.session import Session  # noqa: E402
from splinecast.viewer.state import default_state  # noqa: E402

SIZE = (160, 120)
LOD = 0.5  # pixels per voxel: at SIZE the view's cut needs level-0 and level-1 bricks


def run(coro):
    return asyncio.run(coro)


@pytest.fixture(scope="module")
def source() -> sc.Volume:
    return sc.demo("marschner-lobb", size=48)


@pytest.fixture(scope="module")
def pyramid(source, tmp_path_factory):
    path = tmp_path_factory.mktemp("pyramid") / "ml.zarr"
    sc.build_pyramid(source, path, brick=16, progress=False)
    return path


@pytest.fixture(scope="module")
def wavelet(source, tmp_path_factory):
    path = tmp_path_factory.mktemp("wavelet") / "w.zarr"
    sc.build_pyramid(source, path, kind="wavelet", degree=3, progress=False)
    return path


def camera(geometry, size=SIZE, **orbit) -> sc.Camera:
    """The camera of the default state (azimuth 30, elevation 20, fov 30) around the full
    volume."""
    args = {"azimuth": 30.0, "elevation": 20.0, "fov": 30.0, "zoom": 1.0, **orbit}
    return sc.Camera.orbit(geometry, size=size, **args)


@pytest.fixture
def gated_loader(monkeypatch):
    """Reads of the levels finer than the coarsest (13^3, read at once) wait while the returned
    gate is closed: frames are drawn while their bricks are missing, on any machine. Opened at
    the start and at the end (no loader thread is left waiting)."""
    gate = threading.Event()
    gate.set()
    original = Level.read

    def gated(self, lo, hi):
        if self.shape[0] > 16:
            gate.wait()
        return original(self, lo, hi)

    monkeypatch.setattr(Level, "read", gated)
    yield gate
    gate.set()


async def frames_until_complete(client, ident, limit_s=600.0, first_full=None):
    """Every frame of request ``ident`` until a full frame whose cut is complete;
    ``first_full()`` is called when the first full frame arrived."""
    frames = []
    deadline = time.perf_counter() + limit_s
    while True:
        got = await client.receive(deadline - time.perf_counter())
        if isinstance(got, dict):
            if got.get("type") == "error":
                raise ServerError(got)
            continue
        if got.header["id"] != ident:
            continue
        frames.append(got)
        if got.header["final"] and first_full is not None:
            first_full()
            first_full = None
        bricks = got.header.get("bricks")
        if got.header["final"] and bricks is not None and bricks["complete"]:
            return frames


# ------------------------------------------------------------------------------ pyramids
def test_pyramid_hello_reads_only_the_coarsest_level(pyramid, monkeypatch):
    mv = sc.read(pyramid)
    original = Level.read
    read_levels = []

    def watched(self, lo, hi):
        read_levels.append(self.index)
        return original(self, lo, hi)

    monkeypatch.setattr(Level, "read", watched)

    async def check():
        async with ViewerServer(mv) as server, ViewerClient(server.url) as client:
            hello = client.hello
            assert hello["v"] == 1 and hello["v_minor"] >= 1
            assert hello["models"] == list(sc.MODELS)  # every model renders a pyramid
            assert hello["defaults"]["model"] == "trilinear"
            assert hello["multires"]["kind"] == "multiscale"
            assert hello["multires"]["levels"] == len(mv.levels)
            assert hello["volume"]["shape"] == [48, 48, 48]
            coarsest = mv.levels[-1].shape
            # The histogram counts the coarsest level's voxels, not the finest level's.
            assert sum(hello["histogram"]["counts"]) == int(np.prod(coarsest))
            assert hello["volume"]["value_range"] == list(mv.value_range)
    run(check())
    assert set(read_levels) == {len(mv.levels) - 1}


@pytest.mark.parametrize("interactive", [False, True], ids=["click", "after-a-drag"])
def test_pyramid_frames_refine_as_bricks_arrive_and_end_in_scene_render(pyramid, gated_loader,
                                                                          interactive):
    # The reference first (it also compiles the kernels, so the viewer's frames are quick).
    # The viewer draws pyramids from bricks: the reference too (not level 0 held whole).
    with MultiscaleScene(sc.read(pyramid), lod=LOD, whole_level=False) as ref_scene:
        iso = default_state(ref_scene.preview)["iso"]
        ref_frame = ref_scene.render(camera(ref_scene.volume), iso=iso, complete=True)
    reference = ref_frame.to_uint8()
    assert ref_frame.stats["complete"] and set(ref_frame.stats["cut_levels"]) >= {0}

    async def check():
        gated_loader.clear()  # no brick finer than the coarsest level until the first full frame
        async with ViewerServer(sc.read(pyramid), lod=LOD) as server, \
                ViewerClient(server.url) as client:
            # After a drag the full frame follows by itself once input rests.
            ident = await client.render({"size": list(SIZE)}, interactive=interactive)
            return await frames_until_complete(client, ident, first_full=gated_loader.set)

    frames = run(check())
    full = [f for f in frames if f.header["final"]]
    assert all(f.header["pass"] == "full" for f in full)
    # Bricks arrived while frames were shown: the first full frame was drawn without them.
    assert not full[0].header["bricks"]["complete"] and len(full) >= 2
    seen = []
    for f in frames:
        b = f.header["bricks"]
        assert 0 <= b["cut_resident"] <= b["cut"] and b["resident"] >= b["cut_resident"]
        assert b["resident_bytes"] <= b["budget"] and b["loading"] >= 0
        assert b["progress"] == pytest.approx(b["cut_resident"] / b["cut"])
        if f.header["final"]:
            seen.append(b["cut_resident"])
    assert seen == sorted(seen)  # the same view: its resident bricks only grow
    last = full[-1].header["bricks"]
    assert last["complete"] and last["progress"] == 1.0 and last["cut"] == \
        ref_frame.stats["cut_bricks"]
    np.testing.assert_array_equal(full[-1].image, reference)
    assert not np.array_equal(full[0].image, reference)  # the refinement changed the image


def test_pyramid_screenshot_is_the_complete_cut_in_every_mode(pyramid):
    """A screenshot waits for the whole cut; MIP (with a tolerance) and DVR frames equal
    MultiscaleScene.render."""
    mv = sc.read(pyramid)
    size = (64, 48)
    tf = {"domain": [-1.0, 1.0], "opacity": [[0.3, 0.0], [0.6, 0.2], [1.0, 0.5]],
          "colormap": "hot"}
    states = {
        "mip": {"mode": "mip", "window": [0.0, 0.9], "colormap": "viridis",
                "tolerance": 4 / 255},
        "dvr": {"mode": "dvr", "tf": tf, "dvr": {"termination": None, "preintegration": "none",
                                                 "step": 0.5, "sampling": "grid"}},
    }
    # The viewer draws pyramids from bricks: the reference too (not level 0 held whole).
    with MultiscaleScene(sc.read(pyramid), lod=LOD, whole_level=False) as ref_scene:
        cam = camera(mv, size=size, azimuth=70.0)
        refs = {
            "mip": ref_scene.render(cam, mode="mip", window=(0.0, 0.9), colormap="viridis",
                                    tolerance=4 / 255, complete=True).to_uint8(),
            "dvr": ref_scene.render(cam, mode="dvr", tf=sc.TransferFunction.from_dict(tf),
                                    dvr=sc.DVRSettings(step=0.5, preintegration="none"),
                                    complete=True).to_uint8(),
        }

    async def check():
        async with ViewerServer(mv, lod=LOD) as server, ViewerClient(server.url) as client:
            out = {}
            for mode in refs:
                ident = await client.screenshot({**states[mode], "size": list(size),
                                                 "camera": {"azimuth": 70.0}})
                shot = await client.frame(ident)
                assert shot.header["pass"] == "screenshot" and shot.header["bricks"]["complete"]
                out[mode] = shot.image
            return out

    shots = run(check())
    for mode, ref in refs.items():
        np.testing.assert_array_equal(shots[mode], ref, err_msg=mode)


def test_a_scene_given_to_the_viewer_offers_only_its_model(pyramid):
    with MultiscaleScene(sc.read(pyramid), lod=LOD) as scene:
        async def check():
            async with ViewerServer(scene) as server, ViewerClient(server.url) as client:
                assert client.hello["models"] == ["trilinear"]
                ident = await client.render({"model": "bspline1", "size": [8, 6]})
                with pytest.raises(ServerError, match="model must be one of trilinear"):
                    await client.frame(ident)
        run(check())
        assert scene.stream.cache.running  # the caller's scene stays open
    with pytest.raises(sc.ParameterError, match="model must be trilinear"):
        ViewerServer(scene, model="s31")
    with pytest.raises(sc.ParameterError, match="budget"):
        ViewerServer(sc.demo("sphere", size=8), budget="1GiB")


def test_pyramid_model_switch_closes_the_previous_brick_cache(pyramid):
    renderer = FrameRenderer(shown(sc.read(pyramid), lod=LOD))
    first = renderer.scene("trilinear")
    second = renderer.scene("bspline1")
    assert second is not first and not first.stream.cache.running  # one cache at a time
    assert second.stream.cache.running
    renderer.close()
    assert not second.stream.cache.running


# ------------------------------------------------------------------------------ wavelets
def test_wavelet_store_frames_equal_scene_render(wavelet):
    eps = 0.01
    store = sc.read(wavelet)
    ref_scene = sc.Scene(sc.read(wavelet), lod=eps)
    iso = default_state(ref_scene.preview)["iso"]
    size = (80, 60)
    reference = ref_scene.render(camera(store, size=size), iso=iso).to_uint8()

    async def check():
        async with ViewerServer(store, lod=eps) as server, ViewerClient(server.url) as client:
            hello = client.hello
            assert hello["models"] == ["bspline3"] and hello["defaults"]["model"] == "bspline3"
            assert hello["multires"]["kind"] == "wavelet"
            # From the coarsest level's coefficients (those beyond the voxels' range fall out).
            assert 0 < sum(hello["histogram"]["counts"]) <= ref_scene.preview.data.size
            ident = await client.render({"size": list(size)})
            frame = await client.frame(ident)
            assert "bricks" not in frame.header and frame.header["stats"]["chunks"] > 0
            bad = await client.render({"size": list(size), "model": "trilinear"})
            with pytest.raises(ServerError, match="model must be one of bspline3"):
                await client.frame(bad)
            return frame.image

    np.testing.assert_array_equal(run(check()), reference)


# ------------------------------------------------------------------------ progressive
def test_progressive_coarse_first_then_full_equal_to_scene_render(source, monkeypatch):
    """After a state change whose frame is expected to be slow, the first frame is the coarse
    one (reduced size) and the last the full frame, equal to Scene.render."""
    vol = sc.demo("marschner-lobb", size=24)
    size = (96, 72)

    async def check():
        async with ViewerServer(vol) as server, ViewerClient(server.url) as client:
            first = await client.render({"size": list(size)})
            await client.frame(first)
            # Every frame now counts as slow (the previous frame time is the estimate).
            monkeypatch.setattr(Session, "progressive_ms", 0.0)
            ident = await client.render({"size": list(size), "camera": {"azimuth": 75.0}})
            frames = []
            while not frames or not frames[-1].header["final"]:
                got = await client.receive()
                if not isinstance(got, dict) and got.header["id"] == ident:
                    frames.append(got)
            return frames

    frames = run(check())
    coarse, full = frames[0], frames[-1]
    assert [f.header["pass"] for f in frames] == ["coarse", "full"]
    assert coarse.header["scale"] <= 0.5 and coarse.header["format"] == "jpeg"
    k = round(1 / coarse.header["scale"])
    assert coarse.image.shape[:2] == (round(size[1] / k), round(size[0] / k))
    reference = sc.Scene(vol).render(camera(vol, size=size, azimuth=75.0), iso=0.5).to_uint8()
    np.testing.assert_array_equal(full.image, reference)


def test_a_newer_state_cancels_the_refinement():
    """Deterministic: the coarse pass of request 1 is held until request 2 arrives; request 1
    then gets its coarse frame but no full frame."""
    vol = sc.demo("sphere", size=12)
    frames = []

    async def check():
        release, waiting, done = asyncio.Event(), asyncio.Event(), asyncio.Event()

        async def run_in_thread(fn):
            waiting.set()
            await release.wait()
            return fn()

        async def send_text(message):
            pass

        async def send_bytes(data):
            from splinecast.viewer.protocol import unpack_frame
            header = unpack_frame(data)[0]
            frames.append(header)
            if header["id"] == 2 and header["final"]:
                done.set()

        session = Session(FrameRenderer(vol), run_in_thread, send_text, send_bytes,
                          default_state(vol), 10**6)
        task = asyncio.create_task(session.run())
        await session.handle_text(json.dumps({"type": "render", "id": 1,
                                              "state": {"size": [40, 32]}}))
        await asyncio.wait_for(waiting.wait(), 60)  # request 1's coarse pass waits to render
        await session.handle_text(json.dumps({"type": "render", "id": 2, "state": {
            "size": [40, 32], "camera": {"azimuth": 90.0}}}))
        release.set()
        await asyncio.wait_for(done.wait(), 120)
        session.close()
        task.cancel()

    run(check())
    passes = [(f["id"], f["pass"]) for f in frames]
    # Nothing was known of the cost, so request 1 counted as slow (coarse first); its full
    # frame was cancelled. Request 2 skips the coarse pass: the page shows a reduced frame.
    assert passes == [(1, "coarse"), (2, "full")]


# ------------------------------------------------------------------------------ command
def test_view_of_a_pyramid_prints_its_url_and_stops_on_sigint(pyramid):
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "splinecast.cli", "view", str(pyramid), "--no-browser",
         "--budget", "64MiB"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        url = proc.stdout.readline().strip()
        assert url.startswith("http://127.0.0.1:") and "/?token=" in url, url
        with urllib.request.urlopen(url, timeout=60) as response:
            assert response.status == 200 and b"splinecast" in response.read()

        async def hello():
            async with ViewerClient(url) as client:
                return client.hello
        info = run(hello())
        assert info["multires"]["kind"] == "multiscale"
        assert info["multires"]["budget"] == 64 * 2**20
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err
    assert out == ""
    assert "Traceback" not in err and "levels" in err


@pytest.mark.parametrize(("which", "args", "words"), [
    ("demo", ["--budget", "1GiB"], "--budget applies to multiscale"),
    ("demo", ["--lod", "2"], "--lod applies to multiscale"),
    ("pyramid", ["--lod", "0"], "--lod must be a positive number of pixels"),
    ("pyramid", ["--budget", "lots"], "--budget"),
    ("wavelet", ["--budget", "1GiB"], "--budget does not apply to the wavelet store"),
    ("wavelet", ["--lod", "-1"], "--lod must be an angle >= 0"),
    ("wavelet", ["--model", "trilinear"], "model must be bspline3"),
])
def test_view_multires_mistakes_are_one_line(which, args, words, pyramid, wavelet, capsys):
    from splinecast.cli import main

    file = {"demo": "demo:sphere?size=8", "pyramid": str(pyramid), "wavelet": str(wavelet)}
    code = main(["view", file[which], *args, "--no-browser"])
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and words in err, err


def test_view_of_a_url_shows_what_the_local_store_shows(pyramid):
    """`splinecast view URL` (the store served over HTTP by a real aiohttp server on 127.0.0.1)
    and `splinecast view PATH` of the same store: equal screenshots (the whole cut)."""
    pytest.importorskip("fsspec", reason="remote reading needs the remote extra")
    from remote_servers import Faults, FileServer

    state = {"size": [64, 48], "camera": {"azimuth": 50.0}}

    def screenshot(location: str) -> np.ndarray:
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        proc = subprocess.Popen(
            [sys.executable, "-m", "splinecast.cli", "view", location, "--no-browser",
             "--budget", "64MiB", "--lod", str(LOD)],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
        try:
            url = proc.stdout.readline().strip()
            assert url.startswith("http://127.0.0.1:"), proc.stderr.read() if not url else url

            async def shoot():
                async with ViewerClient(url) as client:
                    assert client.hello["multires"]["kind"] == "multiscale"
                    shot = await client.frame(await client.screenshot(state))
                    assert shot.header["bricks"]["complete"]
                    return shot.image
            image = run(shoot())
            proc.send_signal(signal.SIGINT)
            _, err = proc.communicate(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.communicate()
        assert proc.returncode == 0 and "Traceback" not in err, err
        return image

    local = screenshot(str(pyramid))
    with FileServer(pyramid.parent, Faults(latency=0.005)) as server:
        remote = screenshot(f"{server.url}/{pyramid.name}")
        assert any(path.endswith("zarr.json") for _, path, _ in server.faults.log)
    np.testing.assert_array_equal(remote, local)
