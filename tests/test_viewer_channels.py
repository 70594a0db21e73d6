"""The viewer's channel list: several channels on one grid shown together.

The page's state carries each channel's visibility, colour, window and isovalue
(``state.channels``, listed in ``hello.channels``); every frame must equal
``ChannelScene.render`` of those settings, which ``tests/test_channels.py`` checks against the
composition of single-channel renders. Driven through the protocol by the Python client; waits
are on the server's messages, never sleeps.
"""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

import splinecast as sc
from splinecast.viewer.client import ServerError, ViewerClient
from splinecast.viewer.protocol import PROTOCOL_MINOR
from splinecast.viewer.server import ViewerServer
from splinecast.viewer.state import default_state, parse_state

pytest.importorskip("aiohttp")

SIZE = (32, 24)
CAMERA = {"azimuth": 40.0, "elevation": 25.0}


def _blob(centre: tuple[float, float, float], radius: float, scale: float) -> sc.Volume:
    x, y, z = np.meshgrid(*(np.linspace(-1, 1, n) for n in (16, 14, 12)), indexing="ij")
    cx, cy, cz = centre
    data = scale * np.exp(-((x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2) / radius**2)
    return sc.Volume(data.astype(np.float32))


@pytest.fixture(scope="module")
def pair() -> list[sc.Volume]:
    return [_blob((-0.25, 0.0, 0.0), 0.5, 1.0), _blob((0.3, 0.1, 0.0), 0.4, 2.0)]


def _reference(pair, mode: str, settings: list[dict]) -> np.ndarray:
    camera = sc.Camera.orbit(pair[0], size=SIZE, **CAMERA)
    return sc.Scene(pair).render(camera, mode, channels=settings).to_uint8()


def test_frames_are_the_channel_scene_of_the_page_s_settings(pair):
    settings = [{"color": "#ff0000", "window": [0.1, 0.9]},
                {"color": "#00ff00", "window": [0.2, 1.6], "visible": True}]

    async def check():
        async with ViewerServer(pair, mode="mip") as server, \
                ViewerClient(server.url) as client:
            hello = client.hello
            assert hello["v_minor"] == PROTOCOL_MINOR >= 5
            assert [c["label"] for c in hello["channels"]] == ["channel 0", "channel 1"]
            assert [c["color"] for c in hello["channels"]] == ["#ff00ff", "#00ff00"]
            assert hello["defaults"]["channels"][0] == {"visible": True, "color": "#ff00ff",
                                                        "window": None, "iso": None}
            state = {"size": list(SIZE), "camera": CAMERA, "mode": "mip"}
            frame = await client.frame(await client.render({**state, "channels": settings}))
            np.testing.assert_array_equal(frame.image, _reference(pair, "mip", settings))
            # Hiding the second channel changes the picture to the first one's alone.
            hidden = [settings[0], {**settings[1], "visible": False}]
            frame = await client.frame(await client.render({**state, "channels": hidden}))
            np.testing.assert_array_equal(frame.image, _reference(pair, "mip", hidden))
            assert not np.array_equal(frame.image, _reference(pair, "mip", settings))
            # Isosurfaces, an isovalue per channel (null: the channel's automatic one).
            isos = [{"iso": 0.5}, {"iso": None, "color": [0.2, 0.4, 1.0]}]
            frame = await client.frame(await client.render(
                {**state, "mode": "iso", "channels": isos}))
            np.testing.assert_array_equal(frame.image, _reference(pair, "iso", isos))

    asyncio.run(check())


def test_bad_channel_states_are_one_error_naming_the_field(pair):
    async def check():
        async with ViewerServer(pair, mode="mip") as server, \
                ViewerClient(server.url) as client:
            state = {"size": list(SIZE), "mode": "mip"}
            for channels, message in (
                ([{}], r"channels must be a list of 2 objects"),
                ([{"colour": "red"}, {}], r"channels\[0\] has no field 'colour'"),
                ([{"window": [2, 1]}, {}], r"window must be two finite numbers with lo < hi"),
                ([{}, {"color": "nope"}], r"color 'nope' is not a colour"),
                ([{}, {"visible": 1}], r"channels\[1\]\.visible must be true or false"),
            ):
                with pytest.raises(ServerError, match=message):
                    await client.frame(await client.render({**state, "channels": channels}))

    asyncio.run(check())


def test_a_single_volume_refuses_channels(pair):
    volume = pair[0]
    defaults = default_state(volume)
    with pytest.raises(sc.ParameterError, match="channels: the data on display has one "
                                                "channel"):
        parse_state({"channels": [{}]}, volume, defaults)
    assert "channels" not in parse_state({}, volume, defaults).options
