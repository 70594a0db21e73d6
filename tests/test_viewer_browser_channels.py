"""The viewer's channel list in headless Chromium: several channels shown together, a channel
hidden with its box, a colour and a window typed in; each time the picture on the canvas is
compared with ``ChannelScene.render`` of the settings the page shows.

Chromium comes from ``scripts/install_browser.sh``; the tests skip, saying so, where it is
not installed.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_viewer_browser import (
    CHROMIUM,
    canvas_pixels,
    last_id,
    viewer_page,
    wait_final,
)

import splinecast as sc

pytestmark = pytest.mark.skipif(
    CHROMIUM is None, reason="chromium is not installed (scripts/install_browser.sh installs it "
    "with apt; or set SPLINECAST_CHROMIUM to a Chromium executable)")


def _blob(centre: tuple[float, float, float], radius: float, scale: float) -> sc.Volume:
    x, y, z = np.meshgrid(*(np.linspace(-1, 1, n) for n in (16, 14, 12)), indexing="ij")
    cx, cy, cz = centre
    data = scale * np.exp(-((x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2) / radius**2)
    return sc.Volume(data.astype(np.float32))


@pytest.fixture(scope="module")
def pair() -> list[sc.Volume]:
    return [_blob((-0.25, 0.0, 0.0), 0.5, 1.0), _blob((0.3, 0.1, 0.0), 0.4, 2.0)]


@pytest.fixture(scope="module")
def page(pair, tmp_path_factory):
    handle = sc.view(pair, mode="mip", open_browser=False)
    with viewer_page(handle, tmp_path_factory.mktemp("chromium-profile"),
                     {"width": 760, "height": 420}) as shown:
        yield shown


def assert_page_shows(page, pair) -> np.ndarray:
    state = page.evaluate("window.splinecastViewer.state")
    shown = canvas_pixels(page)
    height, width = shown.shape[:2]
    cam = state["camera"]
    camera = sc.Camera.orbit(pair[0], azimuth=cam["azimuth"], elevation=cam["elevation"],
                             size=(width, height), fov=cam["fov"], ortho=cam["ortho"],
                             zoom=cam["zoom"])
    expected = sc.Scene(pair).render(camera, state["mode"], channels=state["channels"])
    np.testing.assert_array_equal(shown, expected.to_uint8())
    return shown


def test_the_channel_list_shows_and_sets_each_channel(page, pair):
    rows = page.locator("#channels li")
    assert rows.count() == 2
    assert page.locator("#channels li .label").all_inner_texts() == ["channel 0", "channel 1"]
    assert page.is_hidden("#window-histogram")  # the single volume's window gives way
    both = assert_page_shows(page, pair)
    # Hide the second channel with its box.
    after = last_id(page)
    page.get_by_label("show channel 1").uncheck()
    wait_final(page, after)
    assert page.evaluate("window.splinecastViewer.state.channels[1].visible") is False
    alone = assert_page_shows(page, pair)
    assert not np.array_equal(alone, both)
    # A colour and a window for the first channel.
    after = last_id(page)
    page.get_by_label("colour of channel 0").fill("#ffaa00")
    wait_final(page, after)
    after = last_id(page)
    page.get_by_label("window low of channel 0").fill("0.1")
    page.get_by_label("window high of channel 0").fill("0.6")
    page.get_by_label("window high of channel 0").press("Enter")
    wait_final(page, after)
    channel = page.evaluate("window.splinecastViewer.state.channels[0]")
    assert channel["color"] == "#ffaa00" and channel["window"] == [0.1, 0.6]
    assert_page_shows(page, pair)
    assert not page.problems, page.problems
