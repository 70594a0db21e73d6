"""Servers on 127.0.0.1 for the remote-reading tests and benchmark: an aiohttp file server with
injected latency, bandwidth cap and faults, moto's S3 endpoint and a GCS emulator; and the one
render those tests compare between a remote store and its local copy.

The HTTP server serves a folder read-only with single byte ranges (``Range: bytes=a-b``,
``bytes=-n``) and HEAD. Faults are set per test through :class:`Faults`; each takes effect for
paths matching a substring, for a given number of requests. The server runs in its own thread
with its own event loop; :meth:`FileServer.start` returns once it listens (an event, no sleep).
"""

from __future__ import annotations

import asyncio
import os
import re
import socket
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from aiohttp import web

_RANGE = re.compile(r"^bytes=(\d*)-(\d*)$")


@dataclass
class Faults:
    """What the server does wrong. ``rules`` maps a path substring to ``[kind, count]``: the
    next ``count`` matching requests get ``kind``: ``404``, ``500``, ``403``, ``401``,
    ``"reset"`` (the connection closed before any answer), ``"short"`` (the body cut after
    half of its declared length), ``"truncate"`` (a whole answer of half the bytes asked, as
    from a file shorter than its index says), ``"slow"`` (a body that stalls for ``slow_seconds``),
    ``"big"`` (a body of ``big_bytes`` without a Range, announced), ``"redirect:<url>"``.

    ``hold``: requests whose path holds this substring wait, unanswered, until
    :meth:`FileServer.release` (or, with ``release_at``, until that many are held at once);
    ``held`` is set when one arrives and ``dropped`` when the client of one goes away (the
    server sees the connection closed: its handler is cancelled); ``hold_suffix`` false lets
    suffix ranges (shard indexes) through. ``watch``: requests whose path
    holds this substring are counted while answered, their most at once in ``watch_peak``.
    ``no_suffix``: how a suffix range (``bytes=-n``) is answered by a server that does not
    support them: ``416`` or ``"whole"`` (200 with the whole file); ``suffix_peak``: most suffix
    ranges answered at once."""

    latency: float = 0.0
    bandwidth: float | None = None  # bytes per second per response
    rules: dict[str, list[Any]] = field(default_factory=dict)
    slow_seconds: float = 5.0
    big_bytes: int = 64 << 20
    ignore_range: bool = False
    log: list[tuple[str, str, str]] = field(default_factory=list)  # (method, path, range)
    hold: str | None = None
    held: threading.Event = field(default_factory=threading.Event)
    dropped: threading.Event = field(default_factory=threading.Event)
    held_log: list[str] = field(default_factory=list)
    dropped_log: list[str] = field(default_factory=list)
    release_at: int = 0
    hold_suffix: bool = True  # whether suffix ranges (shard indexes) are held too
    held_now: int = 0
    watch: str | None = None
    watch_active: int = 0
    watch_peak: int = 0
    no_suffix: int | str | None = None
    suffix_active: int = 0  # suffix ranges being answered now
    suffix_peak: int = 0
    active: int = 0  # requests being answered now
    peak: int = 0  # most requests answered at once
    lock: threading.Lock = field(default_factory=threading.Lock)

    def add(self, pattern: str, kind: Any, count: int = 1) -> None:
        with self.lock:
            self.rules[pattern] = [kind, count]

    def take(self, path: str) -> Any:
        with self.lock:
            for pattern, rule in self.rules.items():
                if pattern in path and rule[1] > 0:
                    rule[1] -= 1
                    return rule[0]
        return None


class FileServer:
    """Serve ``root`` over HTTP on 127.0.0.1 (a free port) with :class:`Faults`."""

    def __init__(self, root: str | os.PathLike[str], faults: Faults | None = None) -> None:
        self.root = Path(root).resolve()
        self.faults = faults or Faults()
        self._ready = threading.Event()
        self._stop: asyncio.Event | None = None
        self._released: asyncio.Event | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None
        self.port = 0

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def start(self) -> FileServer:
        sock = socket.socket()
        sock.bind(("127.0.0.1", 0))
        self.port = sock.getsockname()[1]
        self._thread = threading.Thread(target=self._run, args=(sock,), daemon=True,
                                        name="test-file-server")
        self._thread.start()
        self._ready.wait(timeout=30)
        if self._error is not None:
            raise self._error
        return self

    def release(self) -> None:
        """Answer the requests held by ``faults.hold`` (and hold no more)."""
        if self._loop is not None and self._released is not None:
            self._loop.call_soon_threadsafe(self._released.set)

    def stop(self) -> None:
        self.release()
        if self._loop is not None and self._stop is not None:
            self._loop.call_soon_threadsafe(self._stop.set)
        if self._thread is not None:
            self._thread.join(timeout=30)

    def __enter__(self) -> FileServer:
        return self.start()

    def __exit__(self, *exc: Any) -> None:
        self.stop()

    def _run(self, sock: socket.socket) -> None:
        try:
            asyncio.run(self._serve(sock))
        except BaseException as exc:  # reported to start()
            self._error = exc
            self._ready.set()

    async def _serve(self, sock: socket.socket) -> None:
        self._loop = asyncio.get_running_loop()
        self._stop = asyncio.Event()
        self._released = asyncio.Event()
        app = web.Application()
        app.router.add_route("*", "/{tail:.*}", self._handle)
        # A client closing its connection cancels the handler answering it (seen by `hold`).
        runner = web.AppRunner(app, access_log=None, handle_signals=False,
                               handler_cancellation=True)
        await runner.setup()
        site = web.SockSite(runner, sock)
        await site.start()
        self._ready.set()
        await self._stop.wait()
        await runner.cleanup()

    async def _handle(self, request: web.Request) -> web.StreamResponse:
        faults = self.faults
        watched = faults.watch is not None and faults.watch in request.path
        suffix = request.headers.get("Range", "").startswith("bytes=-")
        faults.active += 1
        faults.peak = max(faults.peak, faults.active)
        if watched:
            faults.watch_active += 1
            faults.watch_peak = max(faults.watch_peak, faults.watch_active)
        if suffix:
            faults.suffix_active += 1
            faults.suffix_peak = max(faults.suffix_peak, faults.suffix_active)
        try:
            return await self._answer(request)
        finally:
            faults.active -= 1
            if watched:
                faults.watch_active -= 1
            if suffix:
                faults.suffix_active -= 1

    async def _answer(self, request: web.Request) -> web.StreamResponse:
        faults = self.faults
        path = request.path
        faults.log.append((request.method, path, request.headers.get("Range", "")))
        if faults.latency:
            await asyncio.sleep(faults.latency)
        released = self._released
        suffix = request.headers.get("Range", "").startswith("bytes=-")
        if (faults.hold and faults.hold in path and released and not released.is_set()
                and (faults.hold_suffix or not suffix)):
            faults.held_log.append(f"{request.method} {path}")
            faults.held.set()
            faults.held_now += 1
            if faults.release_at and faults.held_now >= faults.release_at:
                released.set()
            try:
                await released.wait()
            except asyncio.CancelledError:
                faults.dropped_log.append(f"{request.method} {path}")
                faults.dropped.set()
                raise
            finally:
                faults.held_now -= 1
        kind = faults.take(path)
        if kind in (404, 500, 403, 401, 503):
            return web.Response(status=kind, text="injected")
        if kind == "reset":
            assert request.transport is not None
            request.transport.close()
            raise asyncio.CancelledError  # nothing answered: the client sees a reset
        if isinstance(kind, str) and kind.startswith("redirect:"):
            raise web.HTTPFound(kind.split(":", 1)[1])
        if kind == "big" and request.method == "HEAD":
            faults.add(path, "big")  # (HEAD answers the truth; the next GET is big)
            kind = None
        if kind == "big":
            response = web.StreamResponse(status=200)
            response.content_length = faults.big_bytes
            await response.prepare(request)
            block = b"\0" * (1 << 20)
            for _ in range(faults.big_bytes >> 20):
                await response.write(block)
            return response
        if request.method not in ("GET", "HEAD"):
            return web.Response(status=405)
        target = (self.root / path.lstrip("/")).resolve()
        if self.root not in target.parents or not target.is_file():
            return web.Response(status=404)
        size = target.stat().st_size
        start, stop, status = 0, size, 200
        header = request.headers.get("Range")
        if header and faults.no_suffix is not None and header.strip().startswith("bytes=-"):
            if faults.no_suffix == 416:
                return web.Response(status=416)
            header = None  # the whole file
        if header and not faults.ignore_range:
            match = _RANGE.match(header.strip())
            if match is None:
                return web.Response(status=416)
            a, b = match.groups()
            if a == "":
                start, stop = max(0, size - int(b)), size
            else:
                start, stop = int(a), size if b == "" else min(int(b) + 1, size)
            if start >= size and size > 0 or start > stop:
                return web.Response(status=416, headers={"Content-Range": f"bytes */{size}"})
            status = 206
        headers = {"Accept-Ranges": "bytes"}
        if status == 206:
            headers["Content-Range"] = f"bytes {start}-{max(stop - 1, start)}/{size}"
        if kind == "truncate":
            stop = start + (stop - start) // 2
            if status == 206:
                headers["Content-Range"] = f"bytes {start}-{max(stop - 1, start)}/{size}"
        response = web.StreamResponse(status=status, headers=headers)
        response.content_length = stop - start
        await response.prepare(request)
        if request.method == "HEAD":
            return response
        with open(target, "rb") as fh:
            fh.seek(start)
            data = fh.read(stop - start)
        if kind == "short":
            await response.write(data[:len(data) // 2])
            assert request.transport is not None
            request.transport.close()
            return response
        if kind == "slow":
            await response.write(data[:1])
            await asyncio.sleep(faults.slow_seconds)
            data = data[1:]
        step = 1 << 16
        for at in range(0, len(data), step):
            piece = data[at:at + step]
            await response.write(piece)
            if faults.bandwidth:
                await asyncio.sleep(len(piece) / faults.bandwidth)
        await response.write_eof()
        return response


class S3Server:
    """moto's S3 endpoint on 127.0.0.1 (a free port), in a thread; ``start`` returns once it
    listens (moto's own ready event)."""

    def __init__(self) -> None:
        from moto.server import ThreadedMotoServer

        self._server = ThreadedMotoServer(ip_address="127.0.0.1", port=0, verbose=False)
        self.endpoint = ""

    def start(self) -> S3Server:
        self._server.start()
        host, port = self._server.get_host_and_port()
        self.endpoint = f"http://{host}:{port}"
        return self

    def stop(self) -> None:
        self._server.stop()

    def client(self) -> Any:
        import boto3

        return boto3.client("s3", endpoint_url=self.endpoint, region_name="us-east-1",
                            aws_access_key_id="testing", aws_secret_access_key="testing")

    def upload(self, bucket: str, folder: Path, prefix: str) -> None:
        """Put every file under ``folder`` at ``prefix/<relative path>`` in ``bucket``."""
        client = self.client()
        for path in sorted(folder.rglob("*")):
            if path.is_file():
                key = f"{prefix}/{path.relative_to(folder).as_posix()}"
                client.put_object(Bucket=bucket, Key=key, Body=path.read_bytes())


class GCSServer:
    """A Google Cloud Storage endpoint on 127.0.0.1 (a free port), in a thread: the pure-Python
    ``gcp-storage-emulator`` (JSON API, media downloads with ``Range``), objects in memory.
    ``start`` returns once it listens (the emulator's own ready event)."""

    def __init__(self, bucket: str) -> None:
        from gcp_storage_emulator.server import create_server

        self.bucket = bucket
        self._server = create_server("127.0.0.1", 0, in_memory=True, default_bucket=bucket)
        self.endpoint = ""

    def start(self) -> GCSServer:
        self._server.start()
        # Port 0 binds a free port; the emulator keeps the listening server on its API thread.
        port = self._server._api._httpd.server_address[1]
        self.endpoint = f"http://127.0.0.1:{port}"
        return self

    def stop(self) -> None:
        self._server.stop()

    def upload(self, folder: Path, prefix: str) -> None:
        """Put every file under ``folder`` at ``prefix/<relative path>`` in the bucket (the JSON
        API's media upload, through urllib: independent of the reader under test)."""
        import urllib.parse
        import urllib.request

        for path in sorted(folder.rglob("*")):
            if path.is_file():
                name = f"{prefix}/{path.relative_to(folder).as_posix()}"
                url = (f"{self.endpoint}/upload/storage/v1/b/{self.bucket}/o?uploadType=media"
                       f"&name={urllib.parse.quote(name, safe='')}")
                request = urllib.request.Request(url, data=path.read_bytes(), method="POST",
                                                 headers={"Content-Type":
                                                          "application/octet-stream"})
                with urllib.request.urlopen(request, timeout=60) as answer:
                    assert answer.status == 200, (name, answer.status)


def render_complete(volume: Any, size: tuple[int, int] = (32, 32), iso: float = 0.0,
                    after: Any = None) -> Any:
    """The isosurface of ``volume`` from one fixed camera, its pyramid's cut complete (the render
    every remote test compares with the same store read from disk); ``after(scene)`` is called
    on the scene once rendered, then the scene is closed."""
    import splinecast as sc

    scene = sc.Scene(volume)
    try:
        camera = sc.Camera.orbit(volume, azimuth=30, elevation=20, size=size)
        frame = scene.render(camera, iso=iso, complete=True)
        if after is not None:
            after(scene)
        return frame
    finally:
        scene.close()
