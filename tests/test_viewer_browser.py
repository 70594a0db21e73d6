"""The viewer's page in headless Chromium (Debian's `chromium`, driven by Playwright for Python).

What a person does: load the page, drag the image, move the isovalue slider, switch the mode,
edit the transfer function, take a screenshot. Each time the picture on the page's canvas is
compared with `Scene.render` for the state the page shows (camera and options rebuilt by hand
here), so the page, the protocol and the server are checked end to end.

Chromium comes from `scripts/install_browser.sh` (apt); the tests skip, saying so, only where it
is not installed. A screenshot of the page is kept as a test artifact (its path is printed).
"""

from __future__ import annotations

import base64
import io
import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PIL import Image

import splinecast as sc

CHROMIUM = os.environ.get("SPLINECAST_CHROMIUM") or shutil.which("chromium") or (
    "/usr/bin/chromium" if os.path.exists("/usr/bin/chromium") else None)
pytestmark = pytest.mark.skipif(
    CHROMIUM is None, reason="chromium is not installed (scripts/install_browser.sh installs it "
    "with apt; or set SPLINECAST_CHROMIUM to a Chromium executable)")

# Headless Chromium on a machine with no network and no GPU: no background traffic, no sandbox
# (tests often run as root), no first-run UI.
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run",
                 "--disable-dev-shm-usage"]
TIMEOUT_MS = 600_000  # first frames may include compiling kernels on an empty cache


@pytest.fixture(scope="module")
def vol() -> sc.Volume:
    return sc.demo("marschner-lobb", size=20)


@contextmanager
def viewer_page(handle: Any, profile: Path, viewport: dict, **options: Any) -> Iterator[Any]:
    """A headless Chromium page on the viewer ``handle`` serves, its first frame drawn, with
    ``page.problems`` collecting page errors and console errors; at the end the browser is
    closed and the server stopped. ``options`` go to Playwright's context."""
    from playwright.sync_api import sync_playwright

    problems: list[str] = []
    try:
        with sync_playwright() as pw:
            context = pw.chromium.launch_persistent_context(
                str(profile), executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS,
                viewport=viewport, **options)
            try:
                page = context.new_page()
                page.set_default_timeout(TIMEOUT_MS)
                page.on("pageerror", lambda exc: problems.append(f"page error: {exc}"))
                page.on("console", lambda m: problems.append(f"console: {m.text}")
                        if m.type == "error" else None)
                page.goto(handle.url)
                wait_final(page, 0)
                page.problems = problems
                yield page
            finally:
                context.close()
    finally:
        handle.stop()


@pytest.fixture(scope="module")
def page(vol, tmp_path_factory):
    handle = sc.view(vol, open_browser=False)
    with viewer_page(handle, tmp_path_factory.mktemp("chromium-profile"),
                     {"width": 760, "height": 420}, accept_downloads=True) as shown:
        yield shown


def wait_final(page, after: int) -> dict:
    """Wait for the page to show the final frame of its newest request, which must be newer
    than ``after``.

    A final frame of *some* request newer than ``after`` is not enough: when an earlier
    action's frame was still on its way, it would be taken for the frame of the action just
    made, and the canvas compared with a state it does not show."""
    page.wait_for_function(
        "(after) => { const v = window.splinecastViewer;"
        " return v && v.settled && v.lastFrame.id > after; }",
        arg=after, timeout=TIMEOUT_MS)
    return page.evaluate("window.splinecastViewer.lastFrame")


def last_id(page) -> int:
    return page.evaluate("window.splinecastViewer.lastFrame.id")


def canvas_pixels(page) -> np.ndarray:
    url = page.evaluate("document.getElementById('canvas').toDataURL('image/png')")
    data = base64.b64decode(url.split(",", 1)[1])
    return np.asarray(Image.open(io.BytesIO(data)).convert("RGBA"))


def expected(vol, state: dict, size: tuple[int, int]) -> np.ndarray:
    """Scene.render of the page's state, for the fields these tests change."""
    cam_state = state["camera"]
    camera = sc.Camera.orbit(vol, azimuth=cam_state["azimuth"],
                             elevation=cam_state["elevation"], size=size,
                             fov=cam_state["fov"], ortho=cam_state["ortho"],
                             zoom=cam_state["zoom"])
    if any(cam_state["pan"]):
        # Pan moves eye and target sideways by pan x view height at the target.
        distance = np.linalg.norm(camera.look_at - camera.position)
        view_height = 2 * distance * np.tan(np.radians(camera.fov) / 2)
        shift = (cam_state["pan"][0] * camera.right + cam_state["pan"][1] * camera.up)
        shift = shift * view_height
        camera = sc.Camera(camera.position + shift, camera.look_at + shift, up=camera.up,
                           fov=camera.fov, size=size)
    mode = state["mode"]
    options = {"mode": mode, "clip": state["clip"] or None, "crop": state["crop"]}
    if mode == "iso":
        options["iso"] = state["iso"]
        if isinstance(state["iso"], list):
            options["opacity"] = state["opacity"]
    elif mode in ("mip", "minip"):
        options.update(window=state["window"], colormap=state["colormap"],
                       tolerance=state["tolerance"])
    else:
        dvr, light = state["dvr"], state["lighting"]
        options.update(tf=sc.TransferFunction.from_dict(state["tf"]),
                       dvr=sc.DVRSettings(step=dvr["step"], shade=dvr["shade"],
                                          preintegration=dvr["preintegration"],
                                          termination=dvr["termination"],
                                          sampling=dvr["sampling"],
                                          ambient=light["ambient"], diffuse=light["diffuse"]))
    return sc.Scene(vol, model=state["model"]).render(camera, **options).to_uint8()


def assert_page_shows(page, vol) -> np.ndarray:
    state = page.evaluate("window.splinecastViewer.state")
    shown = canvas_pixels(page)
    height, width = shown.shape[:2]
    np.testing.assert_array_equal(shown, expected(vol, state, (width, height)))
    return shown


def test_page_loads_and_shows_the_isosurface(page, vol, tmp_path_factory):
    hello = page.evaluate("window.splinecastViewer.hello")
    assert hello["models"] == list(sc.MODELS)
    options = page.eval_on_selector_all("#mode option", "els => els.map(e => e.value)")
    assert options == list(sc.scene.MODES)
    shown = assert_page_shows(page, vol)
    assert len(np.unique(shown.reshape(-1, 4), axis=0)) > 100  # a shaded surface, not a fill
    status = page.inner_text("#status")
    assert "PNG" in status and "frame" in status and "ms" in status
    path = tmp_path_factory.mktemp("artifacts") / "viewer-page.png"
    page.screenshot(path=str(path))
    print(f"\nscreenshot of the viewer page: {path}")
    picture = np.asarray(Image.open(path).convert("RGB")).astype(float)
    assert picture.std() > 10  # not blank
    assert not page.problems, page.problems


def test_dragging_orbits_the_camera(page, vol):
    before_state = page.evaluate("window.splinecastViewer.state.camera")
    before = canvas_pixels(page)
    box = page.locator("#canvas").bounding_box()
    x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    after_id = last_id(page)
    page.mouse.move(x, y)
    page.mouse.down()
    page.mouse.move(x + 60, y + 25, steps=8)
    page.mouse.up()
    wait_final(page, after_id)
    camera = page.evaluate("window.splinecastViewer.state.camera")
    # Dragging right turns the object right (camera azimuth decreases), down raises the camera.
    assert camera["azimuth"] == pytest.approx(before_state["azimuth"] - 60 * 0.4)
    assert camera["elevation"] == pytest.approx(before_state["elevation"] + 25 * 0.4)
    after = assert_page_shows(page, vol)
    assert np.mean(np.any(after != before, axis=-1)) > 0.05


def test_wheel_zooms_and_the_full_frame_follows_when_it_rests(page, vol):
    box = page.locator("#canvas").bounding_box()
    page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
    zoom = page.evaluate("window.splinecastViewer.state.camera.zoom")
    after_id = last_id(page)
    page.mouse.wheel(0, -200)
    wait_final(page, after_id)  # no release event: the server settles on its own
    assert page.evaluate("window.splinecastViewer.state.camera.zoom") > zoom
    assert_page_shows(page, vol)


def test_shift_drag_pans(page, vol):
    box = page.locator("#canvas").bounding_box()
    x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    height = page.evaluate("document.getElementById('canvas').clientHeight")
    after_id = last_id(page)
    page.keyboard.down("Shift")
    page.mouse.move(x, y)
    page.mouse.down()
    page.mouse.move(x + 40, y - 20, steps=5)
    page.mouse.up()
    page.keyboard.up("Shift")
    wait_final(page, after_id)
    pan = page.evaluate("window.splinecastViewer.state.camera.pan")
    # The data follows the pointer: the camera moves the other way.
    assert pan == pytest.approx([-40 / height, -20 / height])
    assert_page_shows(page, vol)


def test_two_finger_pinch_zooms(page, vol):
    """Real touch input through the DevTools protocol: two fingers moving apart."""
    cdp = page.context.new_cdp_session(page)
    cdp.send("Emulation.setTouchEmulationEnabled", {"enabled": True, "maxTouchPoints": 2})
    box = page.locator("#canvas").bounding_box()
    x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    zoom = page.evaluate("window.splinecastViewer.state.camera.zoom")
    pan = page.evaluate("window.splinecastViewer.state.camera.pan")
    after_id = last_id(page)

    def touch(kind, spread):
        points = [{"x": x - spread, "y": y, "id": 0}, {"x": x + spread, "y": y, "id": 1}]
        cdp.send("Input.dispatchTouchEvent",
                 {"type": kind, "touchPoints": points if kind != "touchEnd" else []})

    touch("touchStart", 20)
    for spread in range(25, 61, 5):
        touch("touchMove", spread)
    touch("touchEnd", 60)
    wait_final(page, after_id)
    camera = page.evaluate("window.splinecastViewer.state.camera")
    assert camera["zoom"] == pytest.approx(zoom * 3, rel=1e-6)  # fingers 40 -> 120 px apart
    assert camera["pan"] == pytest.approx(pan)  # the midpoint did not move
    cdp.send("Emulation.setTouchEmulationEnabled", {"enabled": False})
    assert_page_shows(page, vol)


def test_clip_plane_cuts_at_the_slider_position(page, vol):
    after_id = last_id(page)
    page.check("#clip-on")
    wait_final(page, after_id)
    # The position slider starts in the middle: the plane x = centre, keeping x >= centre.
    clip = page.evaluate("window.splinecastViewer.state.clip")
    assert clip == [[1, 0, 0, pytest.approx(-vol.center[0], abs=1e-12)]]
    assert_page_shows(page, vol)
    after_id = last_id(page)
    page.uncheck("#clip-on")
    wait_final(page, after_id)
    assert page.evaluate("window.splinecastViewer.state.clip") == []


def test_isovalue_slider_shows_the_new_isosurface(page, vol):
    slider = page.locator("#iso-slider").bounding_box()
    before = page.evaluate("window.splinecastViewer.state.iso")
    after_id = last_id(page)
    y = slider["y"] + slider["height"] / 2
    page.mouse.move(slider["x"] + slider["width"] * 0.5, y)
    page.mouse.down()
    page.mouse.move(slider["x"] + slider["width"] * 0.3, y, steps=6)
    page.mouse.up()
    wait_final(page, after_id)
    iso = page.evaluate("window.splinecastViewer.state.iso")
    lo, hi = vol.value_range
    assert iso < before and lo < iso < hi
    assert float(page.input_value("#iso-value")) == pytest.approx(iso, rel=1e-4)
    assert_page_shows(page, vol)


def test_adding_and_removing_isosurfaces(page, vol):
    after_id = last_id(page)
    page.click("#add-surface")
    wait_final(page, after_id)
    state = page.evaluate("window.splinecastViewer.state")
    assert isinstance(state["iso"], list) and len(state["iso"]) == 2
    assert state["opacity"][0] < 1 and state["opacity"][1] == 1
    assert page.locator("#surfaces li").count() == 2
    assert_page_shows(page, vol)
    after_id = last_id(page)
    page.locator("#surfaces li button").nth(1).click()
    wait_final(page, after_id)
    assert not isinstance(page.evaluate("window.splinecastViewer.state.iso"), list)
    assert_page_shows(page, vol)


@pytest.mark.parametrize("mode", ["mip", "dvr", "aip"])
def test_switching_the_mode(page, vol, mode):
    after_id = last_id(page)
    page.select_option("#mode", mode)
    header = wait_final(page, after_id)
    assert header["stats"]["mode"] == mode
    # The controls of the keywords the mode reads (the registry's answer, hello.mode_keywords):
    # AIP has a window and a colormap but no tolerance.
    assert page.is_visible("#section-mip") == (mode in ("mip", "aip"))
    assert page.is_visible("#mip-tolerance") == (mode == "mip")
    assert page.is_visible("#section-dvr") == (mode == "dvr")
    assert page.is_visible("#section-lighting") == (mode == "dvr")
    assert_page_shows(page, vol)


def test_the_mip_tolerance_slider_renders_within_it(page, vol):
    """The slider sets the tolerance in levels of 255 on release; the settled frame is
    Scene.render with it (and differs from the exact one)."""
    if page.evaluate("window.splinecastViewer.state.mode") != "mip":
        after_id = last_id(page)
        page.select_option("#mode", "mip")
        wait_final(page, after_id)
    exact = assert_page_shows(page, vol)
    after_id = last_id(page)
    page.eval_on_selector("#mip-tolerance", "(e) => { e.value = '16';"
                          " e.dispatchEvent(new Event('input'));"
                          " e.dispatchEvent(new Event('change')); }")
    wait_final(page, after_id)
    assert page.evaluate("window.splinecastViewer.state.tolerance") == 16 / 255
    assert "16/255" in page.inner_text("#tolerance-label")
    assert not np.array_equal(assert_page_shows(page, vol), exact)
    after_id = last_id(page)
    page.eval_on_selector("#mip-tolerance", "(e) => { e.value = '0';"
                          " e.dispatchEvent(new Event('change')); }")
    wait_final(page, after_id)
    assert page.inner_text("#tolerance-label") == "exact projection"
    np.testing.assert_array_equal(assert_page_shows(page, vol), exact)


def test_transfer_function_editor_adds_a_point(page, vol):
    if page.evaluate("window.splinecastViewer.state.mode") != "dvr":
        after_id = last_id(page)
        page.select_option("#mode", "dvr")
        wait_final(page, after_id)
    points = page.evaluate("window.splinecastViewer.state.tf.opacity")
    editor = page.locator("#tf-editor").bounding_box()
    after_id = last_id(page)
    # A click where there is no point adds one there (value 85% across, opacity near 0.36).
    page.mouse.click(editor["x"] + 0.85 * editor["width"], editor["y"] + 0.4 * editor["height"])
    wait_final(page, after_id)
    new_points = page.evaluate("window.splinecastViewer.state.tf.opacity")
    assert len(new_points) == len(points) + 1
    assert_page_shows(page, vol)


def test_a_combination_the_library_refuses_shows_its_message(page, vol):
    """Whatever the library supports: the page shows either the frame or the library's error."""
    after_id = last_id(page)
    page.select_option("#mode", "mip")
    wait_final(page, after_id)
    scene = sc.Scene(vol, model="qss")
    try:
        scene.render(sc.Camera.orbit(vol, size=(8, 8)), mode="mip")
        refused = None
    except sc.ParameterError as exc:
        refused = str(exc)
    after_id = last_id(page)
    page.select_option("#model", "qss")
    if refused is None:
        wait_final(page, after_id)
        assert_page_shows(page, vol)
    else:
        page.wait_for_selector("#error:not([hidden])", timeout=TIMEOUT_MS)
        assert page.inner_text("#error") == refused
    page.select_option("#model", "trilinear")  # back to a combination that renders
    wait_final(page, after_id)
    assert page.is_hidden("#error")


def test_screenshot_downloads_the_full_resolution_png(page, vol, tmp_path):
    with page.expect_download(timeout=TIMEOUT_MS) as info:
        page.click("#screenshot")
    path = tmp_path / info.value.suggested_filename
    info.value.save_as(path)
    assert path.suffix == ".png"
    saved = np.asarray(Image.open(path).convert("RGBA"))  # opaque images are saved as RGB
    state = page.evaluate("window.splinecastViewer.state")
    size = page.evaluate("[document.getElementById('canvas').width,"
                         " document.getElementById('canvas').height]")
    np.testing.assert_array_equal(saved, expected(vol, state, tuple(size)))


def test_keyboard_reset_returns_to_the_default_camera(page, vol):
    page.locator("#view").focus()
    after_id = last_id(page)
    page.keyboard.press("ArrowLeft")
    wait_final(page, after_id)
    after_id = last_id(page)
    page.keyboard.press("r")
    wait_final(page, after_id)
    camera = page.evaluate("window.splinecastViewer.state.camera")
    defaults = page.evaluate("window.splinecastViewer.hello.defaults.camera")
    assert camera == defaults
    assert_page_shows(page, vol)
    assert not page.problems, page.problems



def test_a_single_volume_has_no_time_slider(page):
    assert page.evaluate("window.splinecastViewer.hello.timepoints") == 1
    assert page.locator("#section-time").is_hidden()

