"""The viewer's server on a real localhost socket: access checks, static files, the WebSocket
protocol, scheduling, and frames equal to Scene.render.

References: Scene.render with cameras built by hand (Camera.orbit), raw HTTP requests written
byte by byte (so no client library normalizes a path or fills in a header for us).
"""

from __future__ import annotations

import asyncio
import base64
import json
import os
import threading
from dataclasses import replace
from importlib import resources

import numpy as np
import pytest

import splinecast as sc
from splinecast.render.dvr import DEFAULT_SETTINGS
from splinecast.viewer.client import ServerError, ViewerClient
from splinecast.viewer.renderer import FrameRenderer
from splinecast.viewer.server import STATIC_FILES, ViewerServer
from splinecast.viewer.session import Session
from splinecast.viewer.state import default_state, parse_state

SIZE = (40, 30)


def run(coro):
    return asyncio.run(coro)


@pytest.fixture(scope="module")
def vol() -> sc.Volume:
    return sc.demo("marschner-lobb", size=16)


async def raw_request(port: int, target: str, host: str | None = None,
                      headers: dict[str, str] | None = None) -> tuple[int, bytes]:
    """Send one GET exactly as written and return (status, body)."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    lines = [f"GET {target} HTTP/1.1", f"Host: {host or f'127.0.0.1:{port}'}",
             "Connection: close"]
    lines += [f"{k}: {v}" for k, v in (headers or {}).items()]
    writer.write(("\r\n".join(lines) + "\r\n\r\n").encode())
    await writer.drain()
    status_line = await asyncio.wait_for(reader.readline(), 30)
    status = int(status_line.split()[1])
    body = b""
    if status != 101:
        body = await asyncio.wait_for(reader.read(), 30)
    writer.close()
    return status, body


def websocket_headers(origin: str | None = None) -> dict[str, str]:
    headers = {"Upgrade": "websocket", "Connection": "Upgrade",
               "Sec-WebSocket-Key": base64.b64encode(os.urandom(16)).decode(),
               "Sec-WebSocket-Version": "13"}
    if origin is not None:
        headers["Origin"] = origin
    return headers


def reference(vol, state_camera=None, size=SIZE, model="trilinear", **options) -> np.ndarray:
    cam = sc.Camera.orbit(vol, size=size, **(state_camera or {}))
    return sc.Scene(vol, model=model).render(cam, **options).to_uint8()


# ------------------------------------------------------------------------------ access
def test_page_and_websocket_refuse_missing_or_wrong_token_bad_host_and_foreign_origin(vol):
    async def check():
        async with ViewerServer(vol) as server:
            port, token = server.port, server.token
            ok = f"?token={token}"
            status, body = await raw_request(port, "/" + ok)
            assert status == 200 and b"<canvas" in body
            status, _ = await raw_request(port, "/" + ok, host=f"localhost:{port}")
            assert status == 200
            assert (await raw_request(port, "/"))[0] == 401
            assert (await raw_request(port, "/?token=wrong"))[0] == 403
            assert (await raw_request(port, "/viewer.js"))[0] == 401
            assert (await raw_request(port, "/viewer.js?token=" + token[:-1]))[0] == 403
            # DNS rebinding: a foreign name in Host, or the right name with another port.
            for host in (f"evil.example:{port}", f"127.0.0.1:{port + 1}", "localhost"):
                assert (await raw_request(port, "/" + ok, host=host))[0] == 403, host
            ws = "/ws" + ok
            assert (await raw_request(port, ws, headers=websocket_headers()))[0] == 101
            own = f"http://127.0.0.1:{port}"
            assert (await raw_request(port, ws, headers=websocket_headers(own)))[0] == 101
            assert (await raw_request(port, "/ws", headers=websocket_headers(own)))[0] == 401
            assert (await raw_request(port, "/ws?token=x", headers=websocket_headers(own)))[0] \
                == 403
            for origin in ("http://evil.example", f"http://evil.example:{port}",
                           f"https://127.0.0.1:{port}", "null", f"http://127.0.0.1:{port + 1}"):
                status, _ = await raw_request(port, ws, headers=websocket_headers(origin))
                assert status == 403, origin
            status, _ = await raw_request(port, ws, host="evil.example",
                                          headers=websocket_headers(own))
            assert status == 403
    run(check())


def test_only_the_fixed_files_are_served(vol):
    async def check():
        async with ViewerServer(vol) as server:
            port, token = server.port, server.token
            status, page = await raw_request(port, f"/?token={token}")
            assert status == 200
            # The page carries the token to its own scripts; nothing else is templated in.
            assert f"viewer.js?token={token}".encode() in page
            for path, (_, content_type) in STATIC_FILES.items():
                status, body = await raw_request(port, f"{path}?token={token}")
                assert status == 200 and f"Content-Type: {content_type}".encode() in body
            # Every file the page needs is in the list (and nothing in the folder is left out).
            folder = resources.files("splinecast.viewer").joinpath("static")
            assert {f.name for f in folder.iterdir()} == {n for n, _ in STATIC_FILES.values()}
            attempts = ["/../../../../etc/passwd", "/%2e%2e/%2e%2e/%2e%2e/etc/passwd",
                        "/..%2f..%2f..%2fetc%2fpasswd", "/%2E%2E%2F%2E%2E%2Fetc/passwd",
                        "/viewer.js/../../server.py", "/static/../server.py",
                        "/..\\..\\server.py", "//etc/passwd", "/etc/passwd",
                        "/%2fetc%2fpasswd", "/server.py", "/__init__.py", "/index.html",
                        "/static/viewer.js", "/viewer.js%00.png", "/./viewer.js/"]
            for path in attempts:
                status, body = await raw_request(port, f"{path}?token={token}")
                assert status == 404, path
                assert b"root:" not in body and b"import" not in body
    run(check())


def test_security_headers_on_the_page(vol):
    async def check():
        async with ViewerServer(vol) as server, ViewerClient(server.url) as client:
            assert client.hello["type"] == "hello"
            import aiohttp

            async with aiohttp.ClientSession() as http, http.get(server.url) as response:
                csp = response.headers["Content-Security-Policy"]
                assert "script-src 'self'" in csp and "connect-src 'self'" in csp
                assert response.headers["X-Content-Type-Options"] == "nosniff"
    run(check())


def test_refuses_other_arguments_and_ports(vol):
    with pytest.raises(sc.ParameterError, match="Volume or Scene"):
        ViewerServer(np.zeros((3, 3, 3)))
    with pytest.raises(sc.ParameterError, match="port"):
        ViewerServer(vol, port=70000)
    with pytest.raises(sc.ParameterError, match="outside the data range"):
        ViewerServer(vol, iso=5.0)

    async def taken():
        async with ViewerServer(vol) as server:
            with pytest.raises(sc.ParameterError, match="cannot listen"):
                await ViewerServer(vol, port=server.port).start()
    run(taken())


# ------------------------------------------------------------------------------ frames
def test_frames_equal_scene_render_for_every_mode(vol):
    camera = {"azimuth": 50.0, "elevation": 35.0, "zoom": 1.3}
    tf = {"domain": [-1.0, 1.0], "opacity": [[0.3, 0.0], [0.6, 0.2], [1.0, 0.5]],
          "colormap": "hot"}
    cases = [
        ({"iso": 0.4}, {"iso": 0.4}),
        ({"iso": [0.3, 0.6], "opacity": [0.4, 1.0]}, {"iso": [0.3, 0.6], "opacity": [0.4, 1.0]}),
        ({"mode": "mip", "window": [0.0, 0.9], "colormap": "viridis"},
         {"mode": "mip", "window": (0.0, 0.9), "colormap": "viridis"}),
        ({"mode": "minip"}, {"mode": "minip"}),
        # The dvr fields not sent are the library's default (DEFAULT_SETTINGS).
        ({"mode": "dvr", "tf": tf}, {"mode": "dvr", "tf": sc.TransferFunction.from_dict(tf)}),
        ({"mode": "dvr", "tf": tf, "dvr": {"step": 0.5, "shade": True},
          "lighting": {"ambient": 0.2, "diffuse": 0.6}},
         {"mode": "dvr", "tf": sc.TransferFunction.from_dict(tf),
          "dvr": replace(DEFAULT_SETTINGS, step=0.5, shade=True, ambient=0.2, diffuse=0.6)}),
        ({"mode": "dvr", "tf": tf, "dvr": {"step": 0.5, "shade": True, "sampling": "grid",
                                           "termination": 0.99},
          "lighting": {"ambient": 0.2, "diffuse": 0.6}},
         {"mode": "dvr", "tf": sc.TransferFunction.from_dict(tf),
          "dvr": sc.DVRSettings(step=0.5, shade=True, ambient=0.2, diffuse=0.6,
                                termination=0.99)}),
        ({"mode": "dvr", "tf": tf, "dvr": {"termination": None, "preintegration": "none",
                                           "step": 0.3, "sampling": "grid"}},
         {"mode": "dvr", "tf": sc.TransferFunction.from_dict(tf),
          "dvr": sc.DVRSettings(step=0.3, preintegration="none")}),
        ({"clip": [[1.0, 0.0, 0.0, 0.1]], "crop": [-1, 1, -0.8, 1, -1, 0.7],
          "lighting": {"specular": 0.0, "shininess": 10.0}},
         {"iso": 0.5, "clip": [(1, 0, 0, 0.1)], "crop": (-1, 1, -0.8, 1, -1, 0.7),
          "shading": sc.Shading(specular=0.0, shininess=10.0)}),
    ]

    async def check():
        async with ViewerServer(vol) as server, ViewerClient(server.url) as client:
            for state, options in cases:
                ident = await client.render({**state, "camera": camera, "size": list(SIZE)})
                frame = await client.frame(ident)
                assert frame.header["format"] == "png" and frame.header["pass"] == "full"
                expected = reference(vol, camera, **options)
                np.testing.assert_array_equal(frame.image, expected, err_msg=str(state))
    run(check())


def test_every_model_and_mode_gives_scene_render_or_its_error():
    """The page lists every model and mode; a combination the library refuses is answered
    with the library's own message, one it renders with the same image."""
    vol = sc.demo("sphere", size=10)

    async def check():
        async with ViewerServer(vol) as server, ViewerClient(server.url) as client:
            assert client.hello["models"] == list(sc.MODELS)
            assert client.hello["modes"] == list(sc.scene.MODES)
            for model in sc.MODELS:
                scene = sc.Scene(vol, model=model)
                cam = sc.Camera.orbit(vol, size=(24, 18))
                for mode in sc.scene.MODES:
                    options = {"mode": mode, "iso": 0.0}
                    if mode == "dvr":
                        tf = sc.TransferFunction([(-0.2, 0.3), (0.2, 0.0)], (-1, 1))
                        options.update(tf=tf)  # the viewer's default is the library's
                    try:
                        expected = scene.render(cam, **options).to_uint8()
                    except sc.ParameterError as exc:
                        expected = str(exc)
                    state = {"model": model, "mode": mode, "iso": 0.0, "size": [24, 18]}
                    if mode == "dvr":
                        state.update(tf=tf.to_dict())
                    ident = await client.render(state)
                    try:
                        got = (await client.frame(ident)).image
                    except ServerError as exc:
                        got = exc.message["message"]
                    if isinstance(expected, str):
                        assert got == expected, (model, mode)
                    else:
                        np.testing.assert_array_equal(got, expected, err_msg=f"{model} {mode}")
    run(check())


def test_render_errors_reach_the_page_and_the_connection_stays_usable(vol):
    async def check():
        async with ViewerServer(vol) as server, ViewerClient(server.url) as client:
            ident = await client.render({"mode": "mip", "window": [1.0, 0.0]})
            with pytest.raises(ServerError, match="window must be two finite numbers"):
                await client.frame(ident)
            ident = await client.render({"iso": 9.0})
            with pytest.raises(ServerError, match="outside the data range"):
                await client.frame(ident)
            await client.ws.send_bytes(b"\x00\x01")
            error = await client.receive()
            assert error["type"] == "error" and "only JSON text" in error["message"]
            ident = await client.render({"size": list(SIZE)})
            frame = await client.frame(ident)
            np.testing.assert_array_equal(frame.image, reference(vol, iso=0.5))
    run(check())


def _fuzz_messages(rng: np.random.Generator, base: dict, count: int) -> tuple[list, int]:
    """Random and malformed messages; returns them and how many are certainly invalid."""
    junk_values = [None, True, -1, 0, 2**70, -1e308, 1e308, "", "x" * 300, "../../etc/passwd",
                   [], [1, 2, 3], [[1]], {}, {"a": {"b": [None]}}, 0.5, "NaN", [None, None]]
    fields = {"model": None, "mode": None, "camera": ["azimuth", "elevation", "zoom", "pan",
                                                      "fov", "ortho"],
              "size": None, "iso": None, "opacity": None, "window": None, "colormap": None,
              "tf": ["domain", "opacity", "colormap"], "dvr": ["step", "shade",
                                                                "preintegration", "termination",
                                                                "sampling"],
              "lighting": ["ambient", "diffuse", "specular", "shininess"], "clip": None,
              "crop": None, "bogus": None}
    messages, invalid = [], 0
    for i in range(count):
        kind = i % 8
        if kind == 0:
            messages.append(bytes(rng.integers(0, 256, int(rng.integers(0, 200)), np.uint8)))
            invalid += 1
        elif kind == 1:
            chars = rng.integers(32, 0x2FF, int(rng.integers(0, 120)))
            text = "".join(map(chr, chars))
            try:
                json.loads(text)
            except ValueError:
                invalid += 1
            messages.append(text)
        elif kind == 2:
            messages.append(json.dumps(junk_values[int(rng.integers(len(junk_values)))]))
            invalid += 1  # not an object
        elif kind == 3:
            depth = int(rng.integers(1, 3000))
            messages.append("[" * depth + "]" * depth)
            invalid += 1
        elif kind == 4:
            message = {"type": str(rng.choice(["render", "screenshot", "paint", "", "RENDER"])),
                       "id": junk_values[int(rng.integers(len(junk_values)))]}
            messages.append(json.dumps(message))
            invalid += message["type"] not in ("render", "screenshot") or not (
                isinstance(message["id"], int) and not isinstance(message["id"], bool)
                and 0 <= message["id"] < 2**53)
        else:
            state = json.loads(json.dumps(base))
            for _ in range(int(rng.integers(1, 4))):
                key = str(rng.choice(list(fields)))
                value = junk_values[int(rng.integers(len(junk_values)))]
                sub = fields[key]
                if sub and isinstance(state.get(key), dict) and rng.random() < 0.8:
                    state[key][str(rng.choice(sub))] = value
                else:
                    state[key] = value
            message = {"type": "render", "id": i, "state": state,
                       "interactive": bool(rng.random() < 0.5)}
            text = json.dumps(message)
            if rng.random() < 0.1:
                text = text[: int(rng.integers(1, len(text)))]  # cut short
                invalid += 1
            messages.append(text)
    return messages, invalid


def test_random_and_malformed_messages_leave_the_server_answering_correctly(vol):
    rng = np.random.default_rng(13)
    base = {"size": [24, 18], "iso": 0.5}
    messages, invalid = _fuzz_messages(rng, base, 1000)
    assert invalid > 400

    async def check():
        async with ViewerServer(vol, max_pixels=64 * 64) as server:
            async with ViewerClient(server.url) as client:
                for message in messages:
                    if isinstance(message, bytes):
                        await client.ws.send_bytes(message)
                    else:
                        await client.ws.send_str(message)
                ident = await client.render({"size": list(SIZE), "iso": 0.45})
                frame = await client.frame(ident)
                np.testing.assert_array_equal(frame.image, reference(vol, iso=0.45))
                errors = [m for m in client.messages if m.get("type") == "error"]
                assert len(errors) >= invalid
                # Every refusal is a validation message, none is a crash inside the server.
                assert not [m for m in errors if "internal error" in m["message"]]
            # A new page still connects and renders.
            async with ViewerClient(server.url) as again:
                ident = await again.render({"size": list(SIZE)})
                await again.frame(ident)
    run(check())


def test_oversized_message_closes_only_that_connection(vol):
    async def check():
        async with ViewerServer(vol) as server:
            async with ViewerClient(server.url) as client:
                await client.ws.send_str(json.dumps({"type": "render", "pad": "x" * 70_000}))
                with pytest.raises(ConnectionError):
                    while True:
                        await client.receive(timeout=30)
                assert client.ws.close_code == 1009  # message too big
            async with ViewerClient(server.url) as client:
                ident = await client.render({"size": list(SIZE)})
                await client.frame(ident)
    run(check())


# ------------------------------------------------------------------------------ scheduling
def test_interactive_frames_are_reduced_jpeg_then_full_png_after_settling(vol):
    async def check():
        async with ViewerServer(vol) as server, ViewerClient(server.url) as client:
            state = {"size": [64, 48], "camera": {"azimuth": 80.0}}
            ident = await client.render(state, interactive=True)
            first = await client.frame(ident, final=False)
            assert first.header["pass"] == "interactive" and first.header["format"] == "jpeg"
            assert first.header["scale"] <= 1.0 and not first.header["final"]
            assert first.image.shape[:2] == (first.header["height"], first.header["width"])
            # No further message: the full frame follows by itself after the settle time.
            full = await client.frame(ident, final=True)
            assert full.header["format"] == "png" and full.header["pass"] == "full"
            assert full.received - client.sent_at(ident) >= Session.settle_s
            np.testing.assert_array_equal(full.image, reference(
                vol, {"azimuth": 80.0}, size=(64, 48), iso=0.5))
    run(check())


def test_newest_interactive_request_wins(vol):
    async def check():
        async with ViewerServer(vol) as server, ViewerClient(server.url) as client:
            ids = [await client.render({"size": list(SIZE), "camera": {"azimuth": float(a)}},
                                       interactive=True) for a in range(0, 60, 2)]
            frames = []
            while True:
                frame = await client.frame(ids[-1], final=False)
                frames.append(frame)
                if frame.header["final"]:
                    break
            # Only the last request settles into a full frame; earlier ones were superseded.
            assert [f.header["id"] for f in frames if f.header["final"]] == [ids[-1]]
            np.testing.assert_array_equal(frames[-1].image, reference(
                vol, {"azimuth": 58.0}, iso=0.5))
    run(check())


def test_a_waiting_request_is_replaced_by_a_newer_one(vol):
    """Deterministic: the render thread is held while three requests arrive; only the first
    (already started) and the newest are rendered."""
    rendered = []

    async def check():
        release, waiting, done = asyncio.Event(), asyncio.Event(), asyncio.Event()
        sent = []
        defaults = default_state(vol)
        renderer = FrameRenderer(vol)

        async def run_in_thread(fn):
            waiting.set()
            await release.wait()
            rendered.append(fn.args[0].state["camera"]["azimuth"])
            return fn()

        def record(item):
            sent.append(item)
            if rendered and rendered[-1] == 40.0 and len(sent) >= 3:
                done.set()

        async def send_text(message):
            record(message)

        async def send_bytes(data):
            record(data)

        session = Session(renderer, run_in_thread, send_text, send_bytes, defaults, 10**6)
        task = asyncio.create_task(session.run())
        for azimuth in (10.0, 20.0, 30.0, 40.0):
            message = {"type": "render", "id": int(azimuth), "state": {
                "size": [16, 12], "camera": {"azimuth": azimuth}}}
            await session.handle_text(json.dumps(message))
            if azimuth == 10.0:  # 10 waits for the render thread before the others arrive
                await asyncio.wait_for(waiting.wait(), 60)
        release.set()
        await asyncio.wait_for(done.wait(), 60)
        session.close()
        task.cancel()
        return sent

    run(check())
    # 10 started before the others arrived (its passes stop once it is stale); 20 and 30 were
    # replaced while waiting; 40 is rendered in full.
    assert 20.0 not in rendered and 30.0 not in rendered
    assert rendered[0] == 10.0 and rendered[-1] == 40.0


def test_progressive_coarse_frame_before_a_slow_full_frame(vol):
    async def check():
        async with ViewerServer(vol) as server, ViewerClient(server.url) as client:
            ident = await client.render({"size": list(SIZE)})
            coarse = await client.frame(ident, final=False)
            full = await client.frame(ident, final=True)
            # Nothing is known about the cost of the first frame: it is treated as slow.
            assert coarse.header["pass"] == "coarse" and coarse.header["scale"] < 1
            assert coarse.image.shape[1] < SIZE[0]
            assert full.header["pass"] == "full" and full.image.shape[:2] == SIZE[::-1]
    run(check())


def test_striped_render_equals_whole_render_and_can_be_abandoned(vol):
    defaults = default_state(vol)
    request = parse_state({"size": [37, 29], "camera": {"elevation": 60.0}}, vol, defaults)
    renderer = FrameRenderer(vol, stripe_rows=8)
    image = renderer.render(request)
    assert image.stats["stripes"] == 4
    np.testing.assert_array_equal(image.rgba, reference(vol, {"elevation": 60.0},
                                                        size=(37, 29), iso=0.5))
    calls = []
    assert renderer.render(request, abort=lambda: calls.append(1) or True) is None
    assert len(calls) == 1  # asked after the first stripe, then stopped


@pytest.mark.parametrize(("expected_ms", "stripes"), [(240.0, 1), (700.0, 3)])
def test_a_frame_is_cut_into_the_fewest_stripes_of_stripe_ms(vol, expected_ms, stripes):
    """A frame expected to take STRIPE_MS or less is rendered whole (each stripe costs a call's
    fixed part and its antialiased border); a longer one in the fewest even stripes of at most
    STRIPE_MS each. Either way the image is Scene.render's."""
    from splinecast.viewer.renderer import STRIPE_MS

    assert expected_ms / stripes <= STRIPE_MS < expected_ms / (stripes - 1 or 0.5)
    request = parse_state({"size": [64, 80], "camera": {"elevation": 50.0}}, vol,
                          default_state(vol))
    renderer = FrameRenderer(vol)
    renderer._learn(request, "full", 64 * 80, expected_ms)  # as if such a frame had been seen
    image = renderer.render(request)
    assert image.stats["stripes"] == stripes
    np.testing.assert_array_equal(image.rgba, reference(vol, {"elevation": 50.0},
                                                        size=(64, 80), iso=0.5))


@pytest.mark.parametrize(("fixed_ms", "per_pixel_ms"), [(6.0, 1.1e-4), (15.0, 1.3e-4),
                                                        (2.0, 4e-4)])
def test_drag_scale_recovers_from_a_slow_first_frame(vol, fixed_ms, per_pixel_ms):
    """The drag's scale follows the frames it renders, at any size: after a first reduced frame
    slowed by loading kernels (the smallest scale then looks necessary), the frames at that
    scale, and each one after, teach the cost model until the drag settles at the largest scale
    whose frames take Session.interactive_ms at most. A frame's time has a fixed part per call
    and a part per pixel; the reference is the smallest divisor whose frame fits, by that
    formula."""
    session = Session(FrameRenderer(vol), None, None, None, default_state(vol), 10**8)
    request = parse_state({"size": [1024, 768]}, vol, default_state(vol))

    def pixels(divisor):
        return round(1024 / divisor) * round(768 / divisor)

    def frame_ms(divisor):
        return fixed_ms + per_pixel_ms * pixels(divisor)

    fits = [k for k in range(1, 9) if frame_ms(k) <= session.interactive_ms]
    assert fits and fits[0] > 1  # the reference: full frames would not fit
    session.renderer._learn(request, "interactive", pixels(2), 3000.0)  # kernels loading
    chosen = []
    for _ in range(12):
        divisor = session._divisor(request, session.interactive_ms, 2, "interactive")
        chosen.append(divisor)
        session.renderer._learn(request, "interactive", pixels(divisor), frame_ms(divisor))
    assert chosen[0] == 8
    assert chosen[-6:] == [fits[0]] * 6, chosen


@pytest.mark.parametrize("rows", [5, 12, 37])
def test_striped_mip_with_a_tolerance_equals_the_whole_render(vol, rows):
    """A MIP with a tolerance reports, per pixel, one of the values within it, chosen by what
    the earlier rays of the pixel's tile found: stripes must start on the scene's grid of
    tiles, whatever height the cost model asks for, or the page shows another image than
    ``Scene.render`` (and than the screenshot)."""
    defaults = default_state(vol)
    request = parse_state({"mode": "mip", "tolerance": 16 / 255, "size": [96, 90]}, vol,
                          defaults)
    image = FrameRenderer(vol, stripe_rows=rows).render(request)
    assert image.stats["stripes"] > 1
    expected = sc.Scene(vol).render(request.camera, **request.options)
    np.testing.assert_array_equal(image.rgba, expected.to_uint8())


def test_mip_previews_sample_on_planes_and_full_frames_are_exact(vol):
    """A drag's reduced MIP / minIP frames and the coarse frame before a slow full one sample on
    every second voxel plane (``method="slices"``, faster); full frames, refreshes and
    screenshots are the exact projection. Reference: ``Scene.render`` with the request's
    options and that method. The cost model keeps the two kinds apart."""
    defaults = default_state(vol)
    renderer = FrameRenderer(vol)
    for mode in ("mip", "minip"):
        request = parse_state({"mode": mode, "size": [256, 160]}, vol, defaults)
        images = {}
        for step in ("interactive", "coarse", "full", "refresh", "screenshot"):
            image = renderer.render(request, step=step)
            preview = step in ("interactive", "coarse")
            assert image.stats["method"] == ("slices" if preview else "exact"), step
            extra = {"method": "slices", "step": 2.0} if preview else {}
            expected = sc.Scene(vol).render(request.camera, **request.options, **extra)
            np.testing.assert_array_equal(image.rgba, expected.to_uint8(), err_msg=step)
            images[step] = image.rgba
        assert not np.array_equal(images["interactive"], images["full"])
        assert renderer.estimate_ms(request, step="interactive") is not None
        assert renderer.estimate_ms(request, step="full") is not None
    # With a tolerance, full frames are the exact projection within it; previews still
    # sample (without the tolerance, which the samples could not honour).
    request = parse_state({"mode": "mip", "size": [256, 160], "tolerance": 6 / 255}, vol,
                          defaults)
    for step in ("interactive", "full", "screenshot"):
        preview = step == "interactive"
        extra = {"method": "slices", "step": 2.0, "tolerance": 0.0} if preview else {}
        expected = sc.Scene(vol).render(request.camera, **{**request.options, **extra})
        np.testing.assert_array_equal(renderer.render(request, step=step).rgba,
                                      expected.to_uint8(), err_msg=step)
    # An isosurface's previews are the request's own method.
    request = parse_state({"iso": 0.4, "size": [40, 30]}, vol, defaults)
    assert renderer.render(request, step="interactive").stats["method"] == "exact"
    fresh = FrameRenderer(vol)
    fresh.render(parse_state({"mode": "mip", "size": [256, 160]}, vol, defaults),
                 step="interactive")
    mip = parse_state({"mode": "mip", "size": [256, 160]}, vol, defaults)
    assert fresh.estimate_ms(mip, step="coarse") is not None
    assert fresh.estimate_ms(mip, step="full") is None


def test_screenshot_is_full_png_and_not_superseded(vol):
    async def check():
        async with ViewerServer(vol) as server, ViewerClient(server.url) as client:
            shot = await client.screenshot({"size": [50, 40], "mode": "mip"})
            later = await client.render({"size": list(SIZE)})
            frames = {}
            while len(frames) < 2:
                got = await client.receive()
                if not isinstance(got, dict) and got.header["final"]:
                    frames[got.header["id"]] = got
            assert frames[shot].header["pass"] == "screenshot"
            np.testing.assert_array_equal(frames[shot].image,
                                          reference(vol, size=(50, 40), mode="mip"))
            assert frames[later].header["pass"] == "full"
    run(check())


def test_refresh_renders_the_settled_state_again(vol):
    async def check():
        async with ViewerServer(vol) as server, ViewerClient(server.url) as client:
            ident = await client.render({"size": list(SIZE), "iso": 0.3})
            first = await client.frame(ident)
            server.refresh_all()  # what a brick loader does when more detail arrived
            again = await client.frame(ident)
            assert again.header["pass"] == "full"
            np.testing.assert_array_equal(again.image, first.image)
    run(check())


def test_view_of_a_scene_keeps_its_model(vol):
    scene = sc.Scene(vol, model="trilinear")

    async def check():
        async with ViewerServer(scene) as server, ViewerClient(server.url) as client:
            assert client.hello["defaults"]["model"] == "trilinear"
            assert server.renderer.scene("trilinear") is scene
            ident = await client.render({"size": list(SIZE)})
            frame = await client.frame(ident)
            np.testing.assert_array_equal(frame.image, reference(vol, iso=0.5))
            assert not [m for m in client.messages if m.get("type") == "status"]
    run(check())


def test_frames_are_rendered_off_the_event_loop(vol, monkeypatch):
    """While a frame is being traced the server still answers HTTP requests: the trace is held
    on the render thread until the page was served (events, not timing)."""
    tracing, release, left = threading.Event(), threading.Event(), threading.Event()
    original = FrameRenderer.render

    def held(self, *args, **kwargs):
        tracing.set()
        release.wait(60)  # a trace on the event loop would block it here: let it go at last
        left.set()
        return original(self, *args, **kwargs)

    monkeypatch.setattr(FrameRenderer, "render", held)

    async def check():
        async with ViewerServer(vol) as server, ViewerClient(server.url) as client:
            try:
                ident = await client.render({"size": list(SIZE)})
                assert await asyncio.to_thread(tracing.wait, 60)
                # The render thread is inside a trace it cannot finish: the loop answers.
                status, _ = await raw_request(server.port, f"/viewer.css?token={server.token}")
                assert status == 200 and not left.is_set()
            finally:
                release.set()
            frame = await client.frame(ident)
            np.testing.assert_array_equal(frame.image, reference(vol, iso=0.5))
    run(check())
