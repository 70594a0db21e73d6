"""The viewer's state validation, message protocol and frame encoding (no server involved).

References: cameras built directly with Camera.orbit / Camera, projections computed by hand,
numpy's histogram, PIL round trips.
"""

from __future__ import annotations

import io
import json
import math

import numpy as np
import pytest
from PIL import Image

import splinecast as sc
from splinecast.render.modes import MODES
from splinecast.viewer import protocol
from splinecast.viewer.encoding import decode_image, encode_image
from splinecast.viewer.state import default_state, parse_state, resized_camera


@pytest.fixture(scope="module")
def vol() -> sc.Volume:
    return sc.demo("marschner-lobb", size=12)


@pytest.fixture(scope="module")
def defaults(vol) -> dict:
    return default_state(vol)


def parse(state, vol, defaults, **kw):
    return parse_state(state, vol, defaults, **kw)


def test_default_state_is_plain_json_and_renders_the_demo_isovalue(vol, defaults):
    assert json.loads(json.dumps(defaults)) == defaults
    assert defaults["iso"] == vol.metadata["default_iso"]
    request = parse({}, vol, defaults)
    assert request.options["iso"] == 0.5 and request.mode == "iso"
    assert request.model == "trilinear"


def test_defaults_without_metadata_are_those_of_splinecast_render():
    """The viewer opens on what ``splinecast render FILE`` shows: the automatic isovalue,
    window and transfer function of :mod:`splinecast.render.defaults`."""
    data = np.arange(27, dtype=np.uint8).reshape(3, 3, 3) * 4
    vol = sc.Volume(data)
    state = default_state(vol)
    assert state["iso"] == sc.auto_iso(vol)
    assert 0.0 < state["iso"] < 104.0
    # No window in the state: each projection takes its own automatic one, as Scene.render.
    assert state["window"] is None
    for mode in ("mip", "minip"):
        window = parse({"mode": mode}, vol, state).options["window"]
        assert tuple(window) == sc.auto_window(vol, mode)
    assert sc.auto_window(vol, "mip") != sc.auto_window(vol, "minip")
    hello = protocol.hello_message(vol, state, {"max_pixels": 10})
    assert {m: hello["auto_window"][m] for m in ("mip", "minip")} == {
        m: list(sc.auto_window(vol, m)) for m in ("mip", "minip")}
    # Every mode with a window has its automatic one there, and the page learns which
    # controls each mode reads from the registry.
    windowed = [m for m, cls in MODES.items() if "window" in cls.keywords]
    assert sorted(hello["auto_window"]) == sorted(windowed)
    for mode in windowed:
        window = parse({"mode": mode}, vol, state).options["window"]
        assert list(window) == hello["auto_window"][mode]
    assert hello["mode_keywords"] == {m: list(cls.keywords) for m, cls in MODES.items()}
    tf = sc.TransferFunction.from_dict(state["tf"])
    assert tf.to_dict() == sc.auto_transfer_function(vol).to_dict()
    assert 0.0 <= tf.domain[0] < tf.domain[1] <= 104.0  # within the data range
    assert state["colormap"] == sc.auto_colormap(vol) == "gray"


def test_signed_data_opens_with_the_diverging_map_and_any_catalog_name_renders():
    data = np.zeros((10, 10, 10), np.float32)
    data[2:5, 2:8, 2:8], data[5:8, 2:8, 2:8] = -2.0, 3.0
    vol = sc.Volume(data)
    state = default_state(vol, mode="mip")
    assert state["colormap"] == sc.transfer.DIVERGING
    lo, hi = parse({}, vol, state).options["window"]
    assert lo == -hi < 0
    hello = protocol.hello_message(vol, state, {"max_pixels": 10})
    assert sc.transfer.DIVERGING in hello["colormaps"]
    # A name outside the menu: what Scene.render takes, the viewer takes.
    request = parse({"colormap": "cmocean:thermal"}, vol, state)
    assert request.options["colormap"] == "cmocean:thermal"


def test_camera_equals_camera_orbit(vol, defaults):
    state = {"camera": {"azimuth": 75.0, "elevation": -10.0, "zoom": 1.7, "fov": 40.0},
             "size": [33, 17]}
    cam = parse(state, vol, defaults).camera
    ref = sc.Camera.orbit(vol, azimuth=75, elevation=-10, size=(33, 17), fov=40, zoom=1.7)
    np.testing.assert_array_equal(cam.pixel_basis(), ref.pixel_basis())


@pytest.mark.parametrize("ortho", [False, True])
def test_pan_moves_the_centre_by_view_heights(vol, defaults, ortho):
    """pan = [0.25, -0.1] puts the volume centre 0.25 view heights left of the image centre and
    0.1 below it (projection computed by hand)."""
    state = {"camera": {"pan": [0.25, -0.1], "ortho": ortho}, "size": [40, 30]}
    cam = parse(state, vol, defaults).camera
    rel = vol.center - cam.position
    if ortho:
        view_height = cam.ortho_height
        x, y = rel @ cam.right / view_height, rel @ cam.up / view_height
    else:
        depth = rel @ cam.forward
        view_height = 2 * math.tan(math.radians(cam.fov) / 2)
        x, y = rel @ cam.right / depth / view_height, rel @ cam.up / depth / view_height
    assert x == pytest.approx(-0.25, abs=1e-12)
    assert y == pytest.approx(0.1, abs=1e-12)


def test_resized_camera_keeps_the_view(vol):
    """A pixel of the 4x smaller image looks at the centre of the 4x4 block of full pixels it
    replaces (rays compared on the image plane, where pixel centres average linearly)."""
    cam = sc.Camera.orbit(vol, azimuth=10, size=(64, 48))
    small = resized_camera(cam, 16, 12)
    assert small.size == (16, 12)
    _, d_full = cam.rays()
    _, d_small = small.rays()
    plane_full = d_full / (d_full @ cam.forward)[..., None]
    plane_small = d_small / (d_small @ cam.forward)[..., None]
    block_centres = plane_full.reshape(12, 4, 16, 4, 3).mean(axis=(1, 3))
    np.testing.assert_allclose(block_centres, plane_small, atol=1e-12)


@pytest.mark.parametrize(("state", "words"), [
    ({"colour": 1}, "state has no field 'colour'"),
    ({"camera": {"azimut": 3}}, "camera has no field 'azimut'"),
    ({"camera": {"azimuth": "30"}}, "camera.azimuth must be a number"),
    ({"camera": {"azimuth": True}}, "camera.azimuth must be a number"),
    ({"camera": {"zoom": 0}}, "camera.zoom must be in"),
    ({"camera": {"fov": 200}}, "camera.fov must be between 0 and 180"),
    ({"camera": {"pan": [1]}}, "camera.pan must hold 2 numbers"),
    ({"camera": {"pan": [1e9, 0]}}, "camera.pan must be within"),
    ({"camera": {"ortho": 1}}, "camera.ortho must be true or false"),
    ({"size": [0, 10]}, "size must be positive"),
    ({"size": [10.5, 10]}, "size must be two integers"),
    ({"size": [5000, 5000]}, "larger than this server's limit"),
    ({"model": "cubic"}, "model must be one of trilinear"),
    ({"mode": "xray"}, "mode must be one of iso"),
    ({"iso": 7}, "outside the data range"),
    ({"iso": "a"}, "iso must be a number"),
    ({"iso": []}, "iso must hold 1 to"),
    ({"iso": [0.2, 0.4], "opacity": [1]}, "opacity must hold 2 numbers"),
    ({"mode": "mip", "window": [1]}, "window must hold 2 numbers"),
    ({"mode": "mip", "colormap": "jett"}, "colormap 'jett' is not a known colormap; did you "
                                          "mean jet?"),
    ({"mode": "mip", "colormap": 3}, "colormap must be a colormap name"),
    ({"mode": "mip", "tolerance": "1/255"}, "tolerance must be a number"),
    ({"mode": "minip", "tolerance": True}, "tolerance must be a number"),
    ({"mode": "mip", "tolerance": 1.5}, "tolerance must be a fraction of the window in [0, 1]"),
    ({"mode": "mip", "tolerance": -0.01}, "tolerance must be a fraction of the window"),
    ({"mode": "dvr", "tf": {"domain": [0, 1]}}, "tf needs 'domain' and 'opacity'"),
    ({"mode": "dvr", "tf": {"domain": [0, 1], "opacity": [[0.5, 2]]}}, "opacity values"),
    ({"mode": "dvr", "tf": {"domain": [1, 0], "opacity": [[0.5, 1]]}}, "lo < hi"),
    ({"mode": "dvr", "tf": {"domain": [0, 1], "opacity": [[0.6, 1], [0.5, 1]]}},
     "increasing order"),
    ({"mode": "dvr", "dvr": {"step": -1}}, "step (voxels) must be a finite number >= 0.001"),
    ({"mode": "dvr", "dvr": {"preintegration": "4d"}}, "preintegration must be one of"),
    ({"mode": "dvr", "dvr": {"sampling": "cells"}}, "sampling must be one of"),
    ({"mode": "dvr", "dvr": {"sampling": 1}}, "dvr.sampling must be a name"),
    ({"lighting": {"ambient": -1}}, "ambient must be >= 0"),
    ({"clip": [[0, 0, 0, 1]]}, "non-zero normal"),
    ({"clip": [[1, 0, 0]]}, "clip[0] must hold 4 numbers"),
    ({"crop": [0, 1, 0, 1, 1, 0]}, "crop"),
])
def test_bad_fields_are_refused_with_the_field_named(vol, defaults, state, words):
    with pytest.raises(sc.ParameterError, match=None) as info:
        parse(state, vol, defaults, max_pixels=4096 * 4096 // 2)
    assert words in str(info.value)
    assert "\n" not in str(info.value)


def test_mode_options_are_what_scene_render_takes(vol, defaults):
    tf = {"domain": [-1, 1], "opacity": [[0.2, 0.0], [0.6, 0.3]], "colormap": "hot"}
    request = parse({"mode": "dvr", "tf": tf, "dvr": {"step": 0.25, "shade": True},
                     "clip": [[1, 0, 0, 0.1]], "crop": [-1, 1, -1, 1, -0.5, 0.5]},
                    vol, defaults)
    opts = request.options
    assert opts["tf"].to_dict() == sc.TransferFunction(
        [(0.2, 0.0), (0.6, 0.3)], (-1, 1), "hot").to_dict()
    assert opts["dvr"].step == 0.25 and opts["dvr"].shade
    assert opts["clip"] == [[1.0, 0.0, 0.0, 0.1]]
    assert opts["crop"] == [-1.0, 1.0, -1.0, 1.0, -0.5, 0.5]
    multi = parse({"iso": [0.2, 0.6], "opacity": [0.3, 1.0]}, vol, defaults).options
    assert multi["iso"] == [0.2, 0.6] and multi["opacity"] == [0.3, 1.0]
    # Omitted fields are the defaults: the complete state is the same either way.
    assert parse({}, vol, defaults).state == parse({"mode": "iso"}, vol, defaults).state == defaults


def test_mip_tolerance_is_passed_to_scene_render_and_left_out_of_other_modes(vol, defaults):
    """Untouched, MIP is the exact projection (tolerance 0, as Scene.render without
    tolerance=); a client's tolerance reaches Scene.render, whose frame it changes; modes
    without one never see it (a client keeps the field when it switches modes)."""
    assert defaults["tolerance"] == 0.0
    assert parse({"mode": "mip"}, vol, defaults).options["tolerance"] == 0.0
    state = {"mode": "mip", "tolerance": 8 / 255, "size": [48, 36]}
    request = parse(state, vol, defaults)
    assert request.options["tolerance"] == 8 / 255
    scene = sc.Scene(vol)
    within = scene.render(request.camera, **request.options)
    exact = scene.render(request.camera, **parse({**state, "tolerance": 0}, vol,
                                                   defaults).options)
    lo, hi = within.stats["window"]
    shortfall = (exact.value - within.value)[np.isfinite(exact.value)] / (hi - lo)
    assert 0.0 < shortfall.max() <= 8 / 255 + 1e-12 and shortfall.min() >= -1e-12
    for mode in ("iso", "dvr"):
        assert "tolerance" not in parse({**state, "mode": mode}, vol, defaults).options


def test_default_dvr_state_is_the_library_default_and_fields_change_one_thing(vol, defaults):
    """Untouched, the viewer renders DVR as Scene.render(mode="dvr") without dvr= does
    (DEFAULT_SETTINGS); a field the client sets changes that field only."""
    from dataclasses import replace

    from splinecast.render.dvr import DEFAULT_SETTINGS

    def drawn(settings):  # what the image depends on: every field but the unused weights
        return replace(settings, ambient=0.0, diffuse=0.0)

    request = parse({"mode": "dvr"}, vol, defaults)
    assert not request.options["dvr"].shade
    assert drawn(request.options["dvr"]) == drawn(DEFAULT_SETTINGS)
    tf = sc.TransferFunction([(0.3, 0.0), (0.6, 0.4)], (0, 1), "hot")
    cam = sc.Camera.orbit(vol, size=(24, 18))
    scene = sc.Scene(vol)
    np.testing.assert_array_equal(
        scene.render(cam, mode="dvr", tf=tf, dvr=request.options["dvr"]).rgba,
        scene.render(cam, mode="dvr", tf=tf).rgba)
    step = parse({"mode": "dvr", "dvr": {"step": 0.25}}, vol, defaults).options["dvr"]
    assert drawn(step) == drawn(replace(DEFAULT_SETTINGS, step=0.25))
    grid = parse({"mode": "dvr", "dvr": {"sampling": "grid", "termination": None, "step": 0.5}},
                 vol, defaults).options["dvr"]
    assert drawn(grid) == drawn(sc.DVRSettings())


# ------------------------------------------------------------------------------ protocol
@pytest.mark.parametrize(("text", "words"), [
    (b"{}", "only JSON text"),
    ("{", "not valid JSON"),
    ("[" * 100_000, "longer than"),
    ("[" * 50_000 + "]" * 50_000, "longer than"),
    ("[" * 20_000 + "]" * 20_000, "not valid JSON"),
    ("[1]", "must be a JSON object"),
    ('{"type": "render", "id": NaN}', "not a number JSON allows"),
    ('{"type": "paint"}', "type must be one of"),
    ('{"type": "render", "id": -1}', "id must be an integer"),
    ('{"type": "render", "id": 1.5}', "id must be an integer"),
    ('{"type": "render", "v": 2}', "protocol version 2"),
    ('{"type": "render", "interactive": "yes"}', "interactive must be"),
    ('{"type": "render", "state": []}', "state must be an object"),
    ('{"type": "render", "path": "/etc/passwd"}', "no field 'path'"),
])
def test_malformed_messages_are_refused(text, words):
    with pytest.raises(sc.ParameterError) as info:
        protocol.decode_request(text)
    assert words in str(info.value)


def test_frame_messages_round_trip():
    header = {"type": "frame", "id": 7, "stats": {"mode": "iso", "trace_ms": 1.5}}
    image = bytes(range(256)) * 3
    back, data = protocol.unpack_frame(protocol.pack_frame(header, image))
    assert back == header and data == image


def test_json_safe_stats_keeps_scalars_only():
    stats = {"a": np.float64(2.5), "b": np.int32(3), "c": "x", "d": math.inf, "e": [1, 2.0],
             "f": np.zeros(3), "g": {"x": 1}, "h": None, "i": True}
    assert protocol.json_safe_stats(stats) == {"a": 2.5, "b": 3, "c": "x", "d": None,
                                               "e": [1, 2.0], "h": None, "i": True}


def test_histogram_matches_numpy(vol):
    hist = protocol.histogram(vol, bins=32)
    lo, hi = vol.value_range
    ref, _ = np.histogram(vol.data, bins=32, range=(lo, hi))
    assert hist["counts"] == ref.tolist() and (hist["lo"], hist["hi"]) == (lo, hi)


def test_hello_lists_the_library_models_modes_and_colormaps(vol, defaults):
    hello = protocol.hello_message(vol, defaults, {"max_pixels": 10})
    assert hello["models"] == list(sc.MODELS)
    assert hello["modes"] == list(sc.scene.MODES)
    assert set(hello["colormaps"]) == set(sc.transfer.COLORMAPS)
    assert hello["v"] == protocol.PROTOCOL_VERSION
    json.dumps(hello)  # plain JSON


def test_png_is_lossless_and_jpeg_is_close():
    rng = np.random.default_rng(0)
    smooth = np.clip(np.linspace(0, 255, 48)[None, :, None] + rng.normal(0, 2, (32, 48, 4)),
                     0, 255).astype(np.uint8)
    # Translucent pixels: all four channels kept.
    np.testing.assert_array_equal(decode_image(encode_image(smooth, "png")), smooth)
    # Opaque images go without alpha (a quarter less to compress) and come back the same.
    smooth[..., 3] = 255
    opaque = encode_image(smooth, "png")
    assert Image.open(io.BytesIO(opaque)).mode == "RGB"
    np.testing.assert_array_equal(decode_image(opaque), smooth)
    jpeg = decode_image(encode_image(smooth, "jpeg"))
    assert jpeg.shape == (32, 48, 4) and np.all(jpeg[..., 3] == 255)
    assert np.abs(jpeg[..., :3].astype(int) - smooth[..., :3]).mean() < 4



# ------------------------------------------------------------------------------ security
def test_host_and_origin_rules():
    from splinecast.viewer import security

    allowed = security.allowed_hosts("127.0.0.1", 8765)
    assert allowed == {"127.0.0.1:8765", "localhost:8765", "[::1]:8765"}
    assert security.host_allowed("LOCALHOST:8765", allowed)
    for host in (None, "", "localhost", "127.0.0.1:8766", "evil.example:8765",
                 "127.0.0.1.evil.example:8765", "127.0.0.1:8765@evil.example"):
        assert not security.host_allowed(host, allowed), host
    assert security.origin_allowed(None, allowed)  # not a browser
    assert security.origin_allowed("http://localhost:8765", allowed)
    for origin in ("null", "", "http://localhost:8766", "https://localhost:8765",
                   "http://evil.example", "http://user@localhost:8765",
                   "http://localhost:8765/page", "file://", "http://[::1"):
        assert not security.origin_allowed(origin, allowed), origin
    # An explicitly bound name is allowed too; a wildcard address adds no name.
    assert "myhost:80" in security.allowed_hosts("myhost", 80)
    assert security.allowed_hosts("0.0.0.0", 80) == security.allowed_hosts("127.0.0.1", 80)
    assert security.is_loopback("127.0.0.2") and security.is_loopback("::1")
    assert not security.is_loopback("0.0.0.0") and not security.is_loopback("example.org")
    assert security.check_token(None, "abc") == 401 and security.check_token("", "abc") == 401
    assert security.check_token("abd", "abc") == 403 and security.check_token("abc", "abc") is None
    assert len({security.new_token() for _ in range(50)}) == 50
