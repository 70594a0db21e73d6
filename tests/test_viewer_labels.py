"""The viewer's label volumes: every label its own surface, a label list, and picking.

The page's state chooses the labels drawn and their opacity (``state.labels``, listed in
``hello.labels``); every frame must equal ``LabelScene.render`` of those settings, which
``tests/test_labels.py`` checks against analytic spheres and single renders of each label. A
``pick`` names the label under a pixel: checked against the test's own ray-sphere
intersections of the spheres the labels were made from. Driven through the protocol by the
Python client; waits are on the server's messages, never sleeps.
"""

from __future__ import annotations

import asyncio
import os
import signal
import subprocess
import sys

import numpy as np
import pytest
from test_labels import SPACING, first_sphere, sphere_labels

import splinecast as sc
from splinecast.cli import main
from splinecast.viewer.client import ServerError, ViewerClient
from splinecast.viewer.protocol import PROTOCOL_MINOR, decode_request
from splinecast.viewer.server import ViewerServer
from splinecast.viewer.state import default_state, parse_state

pytest.importorskip("aiohttp")

SIZE = (64, 48)
CAMERA = {"azimuth": 60.0, "elevation": -20.0}


@pytest.fixture(scope="module")
def vol() -> sc.Volume:
    return sphere_labels()  # spheres labelled 3, 5 and 12


def _camera(vol: sc.Volume) -> sc.Camera:
    return sc.Camera.orbit(vol, size=SIZE, **CAMERA)


def _reference(vol, **labels) -> np.ndarray:
    return sc.Scene(vol, labels=True).render(_camera(vol), **labels).to_uint8()


def test_frames_are_the_label_scene_of_the_page_s_settings(vol):
    async def check():
        async with ViewerServer(vol, labels=True) as server, \
                ViewerClient(server.url) as client:
            hello = client.hello
            assert hello["v_minor"] == PROTOCOL_MINOR >= 7
            assert [entry["value"] for entry in hello["labels"]] == [3, 5, 12]
            scene = sc.Scene(vol, labels=True)
            for entry in hello["labels"]:
                rgb = scene.style(entry["value"]).rgba[:3]
                assert entry["color"] == "#" + "".join(f"{round(255 * c):02x}" for c in rgb)
            assert hello["modes"] == ["iso"]
            assert hello["defaults"]["labels"] == {"show": None, "opacity": 1.0}
            state = {"size": list(SIZE), "camera": CAMERA}
            every = await client.frame(await client.render(state))
            np.testing.assert_array_equal(every.image, _reference(vol))
            # Hiding label 5 draws the others only.
            hidden = await client.frame(await client.render(
                {**state, "labels": {"show": [3, 12]}}))
            np.testing.assert_array_equal(hidden.image, _reference(vol, show=[3, 12]))
            assert not np.array_equal(hidden.image, every.image)
            # Translucent labels, one opacity per label (JSON keys are strings).
            faded = await client.frame(await client.render(
                {**state, "labels": {"show": None, "opacity": {"5": 0.4, "12": 0.7}}}))
            np.testing.assert_array_equal(faded.image,
                                          _reference(vol, opacity={5: 0.4, 12: 0.7}))

    asyncio.run(check())


def test_a_pick_names_the_sphere_the_ray_meets_first(vol):
    camera = _camera(vol)
    # Pixels well inside a silhouette or well off every sphere: the same first sphere for
    # the spheres shrunk and grown by two voxels (the surface lies within one of the sphere).
    small, _ = first_sphere(camera, -2 * SPACING)
    large, _ = first_sphere(camera, 2 * SPACING)
    robust = small == large
    rng = np.random.default_rng(7)
    picks = []
    for value in (0, 3, 5, 12):
        rows, cols = np.nonzero(robust & (small == value))
        assert rows.size, f"no robust pixel of label {value}"
        for i in rng.choice(rows.size, size=min(3, rows.size), replace=False):
            picks.append((int(cols[i]), int(rows[i]), value))
    scene = sc.Scene(vol, labels=True, colors={"5": {"rgba": [200, 40, 40, 255],
                                                     "name": "kidney"}})

    async def check():
        async with ViewerServer(vol, labels=True, colors={"5": {"rgba": [200, 40, 40, 255],
                                                                "name": "kidney"}}) as server, \
                ViewerClient(server.url) as client:
            assert [e["name"] for e in client.hello["labels"]] == [None, "kidney", None]
            state = {"size": list(SIZE), "camera": CAMERA}
            origins, dirs = camera.rays()
            for x, y, value in picks:
                got = await client.pick(state, x + 0.5, y + 0.5)
                assert got["label"] == value, (x, y)
                assert got["name"] == (scene.style(value).name if value else None)
                if value:
                    # The point hit lies on the pixel's ray, between the grown and the shrunk
                    # sphere's entry points.
                    _, near_small = first_sphere(camera, -2 * SPACING)
                    _, near_large = first_sphere(camera, 2 * SPACING)
                    t = float(np.dot(np.asarray(got["position"]) - origins[y, x], dirs[y, x]))
                    assert near_large[y, x] - 1e-6 <= t <= near_small[y, x] + 1e-6
                else:
                    assert got["position"] is None
            # A label hidden is not picked: the ray goes on to what is drawn behind it.
            x, y, value = next(p for p in picks if p[2] == 3)
            got = await client.pick({**state, "labels": {"show": [5, 12]}}, x, y)
            assert got["label"] != 3

    asyncio.run(check())


def test_bad_label_states_are_one_error_naming_the_field(vol):
    async def check():
        async with ViewerServer(vol, labels=True) as server, \
                ViewerClient(server.url) as client:
            state = {"size": list(SIZE)}
            for labels, message in (
                ({"show": [3, 4]}, r"labels\.show\[1\]: label 4 does not occur"),
                ({"show": 3}, r"labels\.show must be a list of label values or null"),
                ({"opacity": 1.5}, r"labels\.opacity must be in \[0, 1\], got 1\.5"),
                ({"opacity": {"12": -0.1}}, r"labels\.opacity\['12'\] must be in \[0, 1\]"),
                ({"opacity": {"7": 0.5}}, r"labels\.opacity key '7': label 7 does not occur"),
                ({"hide": [3]}, r"labels has no field 'hide'"),
            ):
                with pytest.raises(ServerError, match=message):
                    await client.frame(await client.render({**state, "labels": labels}))
            with pytest.raises(ServerError, match=r"pick: pixel \(64, 0\) is outside the "
                                                  r"64x48 image"):
                await client.pick(state, 64, 0)
            with pytest.raises(ServerError, match="mode must be one of iso"):
                await client.frame(await client.render({**state, "mode": "mip"}))

    asyncio.run(check())


def test_other_data_refuses_labels_and_picks(vol):
    volume = sc.Volume(vol.data.astype(np.float32))
    defaults = default_state(volume)
    with pytest.raises(sc.ParameterError, match="labels: the data on display is not a label "
                                                "volume"):
        parse_state({"labels": {"show": None}}, volume, defaults)
    assert "show" not in parse_state({}, volume, defaults).options
    # A pick needs its pixel (the message is refused before it has an id to answer).
    with pytest.raises(sc.ParameterError, match=r"pick: y must be a pixel coordinate"):
        decode_request('{"type": "pick", "id": 1, "x": 3, "y": "top"}')
    with pytest.raises(sc.ParameterError, match=r"x and y belong to pick requests"):
        decode_request('{"type": "render", "id": 1, "x": 3}')

    async def check():
        async with ViewerServer(volume) as server, ViewerClient(server.url) as client:
            assert client.hello["labels"] is None
            with pytest.raises(ServerError, match="pick: the data on display is not a label "
                                                  "volume"):
                await client.pick({"size": list(SIZE)}, 1, 1)

    asyncio.run(check())


def test_splinecast_view_labels_serves_the_label_scene(vol, tmp_path):
    path = tmp_path / "spheres.nrrd"
    sc.write(vol, path)
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "splinecast.cli", "view", str(path), "--labels", "--no-browser"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        url = proc.stdout.readline().strip()
        assert "/?token=" in url, url

        async def check():
            async with ViewerClient(url) as client:
                assert [e["value"] for e in client.hello["labels"]] == [3, 5, 12]
                got = await client.pick({"size": list(SIZE), "camera": CAMERA}, 1, 1)
                assert got["label"] == 0

        asyncio.run(check())
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err
    assert "3 labels" in err and "Traceback" not in err


@pytest.mark.parametrize(("args", "words"), [
    (["--label-colors", "t.json"], "--label-colors applies to --labels only"),
    (["--labels", "--mode", "mip"], "--mode mip does not apply to --labels"),
    (["--labels", "--iso", "0.5"], "--iso does not apply to --labels"),
])
def test_view_label_mistakes_are_one_line_and_status_2(vol, tmp_path, args, words, capsys):
    path = tmp_path / "spheres.nrrd"
    sc.write(vol, path)
    code = main(["view", str(path), *args, "--no-browser"])
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and words in err, err
