"""The viewer's time slider: a file holding several time points (here a 4D NIfTI written by
nibabel) is shown one time point at a time; the state's ``timepoint`` chooses which.

Frames of another time point equal ``Scene(sc.read(path, timepoint=t)).render`` of the page's
state (with the first time point's automatic isovalue); while a time point is read, the page
goes on getting frames of the one it shows. Waits are on events, never sleeps.
"""

from __future__ import annotations

import asyncio
import json
import threading
from pathlib import Path

import numpy as np
import pytest

import splinecast as sc
from splinecast.viewer.client import ServerError, ViewerClient
from splinecast.viewer.protocol import PROTOCOL_MINOR, unpack_frame
from splinecast.viewer.renderer import FrameRenderer
from splinecast.viewer.server import ViewerServer
from splinecast.viewer.session import Session

nib = pytest.importorskip("nibabel")
pytest.importorskip("aiohttp")

SIZE = (32, 24)
CAMERA = {"azimuth": 40.0, "elevation": 25.0}


def _blobs(n_t: int, shape: tuple[int, int, int] = (14, 12, 10)) -> np.ndarray:
    """``n_t`` float32 volumes (x, y, z, t): a ball that moves and grows with t."""
    x, y, z = np.meshgrid(*(np.linspace(-1, 1, n) for n in shape), indexing="ij")
    vols = []
    for t in range(n_t):
        cx, r = -0.3 + 0.25 * t, 0.4 + 0.12 * t
        vols.append(np.exp(-((x - cx) ** 2 + y**2 + (z * 1.2) ** 2) / r**2))
    return np.stack(vols, axis=-1).astype(np.float32)


def _nifti(path: Path, data: np.ndarray) -> Path:
    nib.save(nib.Nifti1Image(data, np.eye(4)), str(path))
    return path


@pytest.fixture
def series(tmp_path) -> Path:
    return _nifti(tmp_path / "series.nii", _blobs(3))


def _reference(path: Path, timepoint: int, iso: float) -> np.ndarray:
    vol = sc.read(path, timepoint=timepoint)
    cam = sc.Camera.orbit(vol, size=SIZE, **CAMERA)
    return sc.Scene(vol).render(cam, iso=iso).to_uint8()


def test_a_time_point_renders_as_scene_render_of_that_time_point(series):
    first = sc.read(series, timepoint=0)

    async def check():
        async with ViewerServer(first) as server, ViewerClient(server.url) as client:
            hello = client.hello
            assert hello["timepoints"] == 3 and hello["v_minor"] == PROTOCOL_MINOR >= 4
            assert hello["defaults"]["timepoint"] == 0
            iso = hello["defaults"]["iso"]  # the first time point's, kept for the others
            state = {"size": list(SIZE), "camera": CAMERA}
            ident = await client.render({**state, "timepoint": 2})
            frame = await client.frame(ident)
            assert frame.header["timepoint"] == 2 and frame.header["pass"] == "full"
            np.testing.assert_array_equal(frame.image, _reference(series, 2, iso))
            # The time points differ (the comparison above means something), and back to the
            # first one gives its own picture again.
            assert not np.array_equal(frame.image, _reference(series, 0, iso))
            ident = await client.render({**state, "timepoint": 0})
            frame = await client.frame(ident)
            assert frame.header["timepoint"] == 0
            np.testing.assert_array_equal(frame.image, _reference(series, 0, iso))
            # Only the current time point's scenes are held.
            assert {t for _, t in server.renderer._scenes} == {0}
    asyncio.run(check())


def test_out_of_range_time_points_are_refused_and_the_server_keeps_answering(series):
    first = sc.read(series, timepoint=1)  # the viewer starts at the time point read

    async def check():
        async with ViewerServer(first) as server, ViewerClient(server.url) as client:
            assert client.hello["defaults"]["timepoint"] == 1
            iso = client.hello["defaults"]["iso"]
            for bad, message in ((3, "timepoint 3 is out of range"),
                                 (-1, "timepoint -1 is out of range"),
                                 (1.0, "timepoint must be an integer"),
                                 (True, "timepoint must be an integer"),
                                 ("2", "timepoint must be an integer")):
                ident = await client.render({"size": list(SIZE), "timepoint": bad})
                with pytest.raises(ServerError, match=message):
                    await client.frame(ident)
            ident = await client.render({"size": list(SIZE), "camera": CAMERA})
            frame = await client.frame(ident)
            assert frame.header["timepoint"] == 1
            np.testing.assert_array_equal(frame.image, _reference(series, 1, iso))
    asyncio.run(check())


def test_a_single_volume_has_one_time_point(tmp_path):
    path = _nifti(tmp_path / "one.nii", _blobs(1)[..., 0])
    vol = sc.read(path)

    async def check():
        async with ViewerServer(vol) as server, ViewerClient(server.url) as client:
            assert client.hello["timepoints"] == 1
            ident = await client.render({"size": list(SIZE), "timepoint": 1})
            with pytest.raises(ServerError, match="timepoint 1 is out of range"):
                await client.frame(ident)
            ident = await client.render({"size": list(SIZE), "timepoint": 0})
            assert (await client.frame(ident)).header["timepoint"] == 0
    asyncio.run(check())


class _SlowReads(FrameRenderer):
    """Reads another time point only once the test releases it."""

    def __init__(self, shown):
        super().__init__(shown)
        self.release = threading.Event()
        self.reading = threading.Event()

    def load_timepoint(self, timepoint, model):
        self.reading.set()
        assert self.release.wait(timeout=600)
        super().load_timepoint(timepoint, model)


def test_the_page_keeps_its_time_point_while_the_next_one_is_read(series):
    server = ViewerServer(sc.read(series, timepoint=0))
    renderer = _SlowReads(server.shown)
    defaults = server.defaults

    async def check():
        texts: list[dict] = []
        frames: list[tuple[dict, bytes]] = []
        changed = asyncio.Event()

        async def send_text(message):
            texts.append(message)
            changed.set()

        async def send_bytes(data):
            frames.append(unpack_frame(data))
            changed.set()

        async def until(predicate):
            async def wait():
                while not predicate():
                    changed.clear()
                    await changed.wait()
            await asyncio.wait_for(wait(), timeout=600)

        def frame(ident, final):
            return next((h for h, _ in frames if h["id"] == ident and h["final"] == final), None)

        async def run_in_thread(fn):
            return await asyncio.to_thread(fn)

        session = Session(renderer, run_in_thread, send_text, send_bytes, defaults, 10**6)
        task = asyncio.create_task(session.run())

        async def send(ident, state):
            await session.handle_text(json.dumps({"type": "render", "id": ident,
                                                  "state": {"size": list(SIZE), **state}}))

        try:
            await send(1, {})
            await until(lambda: frame(1, True))
            await send(2, {"timepoint": 2, "camera": {"azimuth": 80.0}})
            await until(lambda: frame(2, False))
            header = frame(2, False)
            # The time point shown, seen from the new camera, while time point 2 is read.
            assert header["pass"] == "preparing" and header["timepoint"] == 0
            assert header["preparing"]["timepoint"] == 2
            assert renderer.reading.is_set() and not renderer.has_timepoint(2)
            await until(lambda: any((t.get("preparing") or {}).get("timepoint") == 2
                                    for t in texts))
            status = next(t for t in texts if (t.get("preparing") or {}).get("timepoint") == 2)
            assert "reading time point 2" in status["message"]
            # Turning the view still gets frames of time point 0.
            await send(3, {"timepoint": 2, "camera": {"azimuth": 120.0}})
            await until(lambda: frame(3, False))
            assert frame(3, False)["timepoint"] == 0
            renderer.release.set()
            await until(lambda: frame(3, True))
            assert frame(3, True)["timepoint"] == 2 and frame(2, True) is None
            assert renderer.has_timepoint(2) and not renderer.has_timepoint(0)
            await until(lambda: [t["preparing"] for t in texts if "preparing" in t][-1] is None)
        finally:
            session.close()
            task.cancel()
            renderer.release.set()
            renderer.close()

    asyncio.run(check())


def test_an_omezarr_time_axis_gets_the_slider_too(tmp_path):
    """An OME-Zarr image with a ``t`` axis (a one-level pyramid): another time point is opened
    as its own pyramid, and its screenshot equals that time point's complete render."""
    zarr = pytest.importorskip("zarr")
    from splinecast.multires.scenes.multiscale import MultiscaleScene

    values = np.moveaxis(_blobs(3), -1, 0).transpose(0, 3, 2, 1)  # t, z, y, x
    path = tmp_path / "series.zarr"
    group = zarr.open_group(str(path), mode="w")
    group.create_array("0", shape=values.shape, dtype="f4")[...] = values
    group.attrs["ome"] = {"version": "0.5", "multiscales": [{
        "axes": [{"name": "t", "type": "time"}] + [{"name": a, "type": "space"} for a in "zyx"],
        "datasets": [{"path": "0", "coordinateTransformations": [
            {"type": "scale", "scale": [1, 1, 1, 1]}]}]}]}
    first = sc.read(path, timepoint=0)

    async def check():
        async with ViewerServer(first) as server, ViewerClient(server.url) as client:
            assert client.hello["timepoints"] == 3
            iso = client.hello["defaults"]["iso"]
            state = {"size": list(SIZE), "camera": CAMERA, "timepoint": 2}
            frame = await client.frame(await client.render(state))
            assert frame.header["timepoint"] == 2
            shot = await client.frame(await client.screenshot(state))
            assert shot.header["timepoint"] == 2 and shot.header["bricks"]["complete"]
            return iso, shot.image

    iso, image = asyncio.run(check())
    later = sc.read(path, timepoint=2)
    with MultiscaleScene(later, whole_level=False) as scene:  # the viewer draws bricks
        cam = sc.Camera.orbit(later, size=SIZE, **CAMERA)
        reference = scene.render(cam, iso=iso, complete=True).to_uint8()
    np.testing.assert_array_equal(image, reference)
