"""The viewer's time slider in headless Chromium: a 4D NIfTI (written by nibabel) shows a
slider; moving it shows that time point as ``Scene.render`` of it (helpers and Chromium as in
``test_viewer_browser.py``)."""

from __future__ import annotations

import numpy as np
import pytest
from test_viewer_browser import (
    CHROMIUM,
    CHROMIUM_ARGS,
    TIMEOUT_MS,
    canvas_pixels,
    expected,
    last_id,
    wait_final,
)

import splinecast as sc

pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed "
                                "(scripts/install_browser.sh installs it with apt)")


def test_the_time_slider_shows_another_time_point(tmp_path):
    """A 4D NIfTI: the slider appears; moving it shows that time point as Scene.render of it
    (the first time point's isovalue kept)."""
    nib = pytest.importorskip("nibabel")
    from playwright.sync_api import sync_playwright

    x, y, z = np.meshgrid(*(np.linspace(-1, 1, n) for n in (14, 12, 10)), indexing="ij")
    data = np.stack([np.exp(-((x + 0.3 - 0.3 * t) ** 2 + y**2 + z**2) / (0.4 + 0.15 * t) ** 2)
                     for t in range(3)], axis=-1).astype(np.float32)
    path = tmp_path / "series.nii"
    nib.save(nib.Nifti1Image(data, np.eye(4)), str(path))
    handle = sc.view(sc.read(path, timepoint=0), open_browser=False)
    problems: list[str] = []
    try:
        with sync_playwright() as pw:
            context = pw.chromium.launch_persistent_context(
                str(tmp_path / "profile"), executable_path=CHROMIUM, headless=True,
                args=CHROMIUM_ARGS, viewport={"width": 520, "height": 320})
            try:
                page = context.new_page()
                page.set_default_timeout(TIMEOUT_MS)
                page.on("pageerror", lambda exc: problems.append(f"page error: {exc}"))
                page.goto(handle.url)
                wait_final(page, 0)
                assert page.locator("#section-time").is_visible()
                assert page.inner_text("#time-label") == "0 of 0–2"
                after_id = last_id(page)
                page.focus("#time-slider")
                page.keyboard.press("End")  # to the last time point: input and change events
                frame = wait_final(page, after_id)
                state = page.evaluate("window.splinecastViewer.state")
                assert state["timepoint"] == 2 and frame["timepoint"] == 2
                assert page.inner_text("#time-label") == "2 of 0–2"
                shown = canvas_pixels(page)
                height, width = shown.shape[:2]
                later = sc.read(path, timepoint=2)
                np.testing.assert_array_equal(shown, expected(later, state, (width, height)))
                assert "time point 2" in page.inner_text("#status")
                assert not problems, problems
            finally:
                context.close()
    finally:
        handle.stop()
