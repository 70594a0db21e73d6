"""The viewer's label list in headless Chromium: a label volume of three spheres, a label
hidden with its box, the picture on the canvas compared with ``LabelScene.render`` of the
settings the page shows, and the label under the cursor read from the page.

Chromium comes from ``scripts/install_browser.sh``; the tests skip, saying so, where it is
not installed.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_labels import SPACING, first_sphere, sphere_labels
from test_viewer_browser import (
    CHROMIUM,
    TIMEOUT_MS,
    canvas_pixels,
    last_id,
    viewer_page,
    wait_final,
)

import splinecast as sc

pytestmark = pytest.mark.skipif(
    CHROMIUM is None, reason="chromium is not installed (scripts/install_browser.sh installs it "
    "with apt; or set SPLINECAST_CHROMIUM to a Chromium executable)")


@pytest.fixture(scope="module")
def vol() -> sc.Volume:
    return sphere_labels()  # spheres labelled 3, 5 and 12


@pytest.fixture(scope="module")
def page(vol, tmp_path_factory):
    handle = sc.view(vol, labels=True, open_browser=False)
    with viewer_page(handle, tmp_path_factory.mktemp("chromium-profile"),
                     {"width": 600, "height": 360}) as shown:
        yield shown


def page_camera(page, vol) -> sc.Camera:
    state = page.evaluate("window.splinecastViewer.state")
    width, height = page.evaluate("[document.getElementById('canvas').width, "
                                  "document.getElementById('canvas').height]")
    cam = state["camera"]
    return sc.Camera.orbit(vol, azimuth=cam["azimuth"], elevation=cam["elevation"],
                           size=(width, height), fov=cam["fov"], ortho=cam["ortho"],
                           zoom=cam["zoom"])


def assert_page_shows(page, vol) -> np.ndarray:
    labels = page.evaluate("window.splinecastViewer.state.labels")
    shown = canvas_pixels(page)
    expected = sc.Scene(vol, labels=True).render(page_camera(page, vol), show=labels["show"],
                                                 opacity=labels["opacity"])
    np.testing.assert_array_equal(shown, expected.to_uint8())
    return shown


def test_the_label_list_hides_labels_and_the_cursor_names_them(page, vol):
    rows = page.locator("#labels li")
    assert rows.count() == 3
    assert page.locator("#labels li .label").all_inner_texts() == ["label 3", "label 5",
                                                                    "label 12"]
    assert page.is_hidden("#iso-histogram")  # the isovalue gives way to the label list
    every = assert_page_shows(page, vol)
    # Hide label 5 with its box.
    after = last_id(page)
    page.get_by_label("show label 5").uncheck()
    wait_final(page, after)
    assert page.evaluate("window.splinecastViewer.state.labels.show") == [3, 12]
    hidden = assert_page_shows(page, vol)
    assert not np.array_equal(hidden, every)
    # Hover a pixel well inside sphere 12's silhouette (and one off every sphere): the page
    # names what the test's own ray-sphere intersections say is there (5 is hidden).
    camera = page_camera(page, vol)
    small, _ = first_sphere(camera, -2 * SPACING)
    large, _ = first_sphere(camera, 2 * SPACING)
    box = page.locator("#canvas").bounding_box()
    scale = camera.width / box["width"]
    for value in (12, 0):
        robust = (small == large) & (small == value)
        rows_, cols = np.nonzero(robust)
        assert rows_.size
        row, col = int(rows_[rows_.size // 2]), int(cols[rows_.size // 2])
        page.mouse.move(box["x"] + (col + 0.5) / scale, box["y"] + (row + 0.5) / scale)
        page.wait_for_function(
            "([x, y]) => { const p = window.splinecastViewer.lastPick;"
            " return p && Math.floor(p.x) === x && Math.floor(p.y) === y; }",
            arg=[col, row], timeout=TIMEOUT_MS)
        text = page.inner_text("#pick")
        assert text.startswith(f"label {value}" if value else "no label"), text
    assert not page.problems, page.problems
