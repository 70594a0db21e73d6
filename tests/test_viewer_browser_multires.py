"""The viewer's page in headless Chromium on an OME-Zarr pyramid: the status line counts the
view's bricks while they arrive and the page ends with the complete cut's image.

A module of its own: Playwright's sync API runs one instance per thread, and the page fixture of
``test_viewer_browser.py`` keeps its instance for that whole module. Chromium as there
(``scripts/install_browser.sh``); the test skips, saying so, where it is not installed.
"""

from __future__ import annotations

import re
import time

import numpy as np
import pytest
from test_viewer_browser import CHROMIUM, CHROMIUM_ARGS, TIMEOUT_MS, canvas_pixels

import splinecast as sc

pytestmark = pytest.mark.skipif(
    CHROMIUM is None, reason="chromium is not installed (scripts/install_browser.sh installs it "
    "with apt; or set SPLINECAST_CHROMIUM to a Chromium executable)")


def test_a_pyramid_shows_its_bricks_in_the_status_line(tmp_path, monkeypatch):
    """An OME-Zarr pyramid with a slowed-down loader: the status line counts the view's bricks
    while they arrive, the page refines by itself, and ends with the complete cut's image."""
    pytest.importorskip("zarr")
    from playwright.sync_api import sync_playwright

    from splinecast.io.omezarr import Level
    from splinecast.multires.scenes.multiscale import MultiscaleScene

    path = tmp_path / "ml.zarr"
    sc.build_pyramid(sc.demo("marschner-lobb", size=48), path, brick=16, progress=False)
    original = Level.read

    def slow(self, lo, hi):
        if self.shape[0] > 16:  # every level but the 13^3 coarsest
            time.sleep(0.4)
        return original(self, lo, hi)

    monkeypatch.setattr(Level, "read", slow)
    handle = sc.view(sc.read(path), lod=0.5, open_browser=False)
    statuses: list[str] = []
    try:
        with sync_playwright() as pw:
            context = pw.chromium.launch_persistent_context(
                str(tmp_path / "profile"), executable_path=CHROMIUM, headless=True,
                args=CHROMIUM_ARGS, viewport={"width": 560, "height": 360})
            try:
                page = context.new_page()
                page.set_default_timeout(TIMEOUT_MS)
                page.goto(handle.url)
                page.wait_for_function(
                    "() => { const v = window.splinecastViewer;"
                    " return v && v.lastFrame && v.lastFrame.bricks; }", timeout=TIMEOUT_MS)
                statuses.append(page.inner_text("#status"))
                page.wait_for_function(
                    "() => { const f = window.splinecastViewer.lastFrame;"
                    " return f.final && f.bricks && f.bricks.complete; }", timeout=TIMEOUT_MS)
                statuses.append(page.inner_text("#status"))
                models = page.eval_on_selector_all("#model option", "els => els.map(e => e.value)")
                state = page.evaluate("window.splinecastViewer.state")
                last = page.evaluate("window.splinecastViewer.lastFrame")
                shown = canvas_pixels(page)
            finally:
                context.close()
    finally:
        handle.stop()
    assert models == list(sc.MODELS)
    assert all(re.search(r"bricks \d+/\d+ resident", s) for s in statuses), statuses
    b = last["bricks"]
    assert f"bricks {b['cut']}/{b['cut']} resident" in statuses[-1] and "complete" in statuses[-1]
    height, width = shown.shape[:2]
    cam = state["camera"]
    # The viewer draws pyramids from bricks: the reference too (not level 0 held whole).
    with MultiscaleScene(sc.read(path), lod=0.5, whole_level=False) as scene:
        camera = sc.Camera.orbit(scene.volume, azimuth=cam["azimuth"],
                                 elevation=cam["elevation"], size=(width, height),
                                 fov=cam["fov"], ortho=cam["ortho"], zoom=cam["zoom"])
        reference = scene.render(camera, iso=state["iso"], complete=True).to_uint8()
    np.testing.assert_array_equal(shown, reference)
