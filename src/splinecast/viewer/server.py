"""The viewer's HTTP and WebSocket server (aiohttp): one page, a fixed list of static files, and
a WebSocket per open page.

Requests pass three checks before anything else (:mod:`.security`): the ``Host`` header (403),
the token (401 missing, 403 wrong) and, for the WebSocket, the ``Origin`` (403). Static files are
looked up by exact path in :data:`STATIC_FILES`; every other path is 404, so no path from the
browser ever reaches the file system. Frames are rendered on one worker thread shared by all
clients (:mod:`.session`, :mod:`.renderer`) so the event loop keeps answering while a frame is
being traced.
"""

from __future__ import annotations

import asyncio
import contextlib
import html
import logging
import socket
from concurrent.futures import ThreadPoolExecutor
from importlib import resources
from typing import Any

from aiohttp import WSMsgType, web

from ..errors import ParameterError
from . import security
from .data import shown
from .protocol import MAX_MESSAGE_BYTES, PROTOCOL_VERSION, hello_message
from .renderer import FrameRenderer
from .session import Session
from .state import MAX_PIXELS, default_state

__all__ = ["ViewerServer", "STATIC_FILES"]

log = logging.getLogger("splinecast.viewer")

#: URL path -> (file in the package's ``static`` folder, content type). Nothing else is served.
STATIC_FILES = {
    "/": ("index.html", "text/html"),
    "/viewer.css": ("viewer.css", "text/css"),
    "/viewer.js": ("viewer.js", "text/javascript"),
    "/orbit.js": ("orbit.js", "text/javascript"),
    "/histogram.js": ("histogram.js", "text/javascript"),
    "/controls.js": ("controls.js", "text/javascript"),
}

# The page may be shown inside a Jupyter notebook served from another local port.
_FRAME_ANCESTORS = ("'self' http://localhost:* http://127.0.0.1:* "
                    "https://localhost:* https://127.0.0.1:*")
_SECURITY_HEADERS = {
    "Content-Security-Policy": (
        "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' blob: data:; "
        f"connect-src 'self'; base-uri 'none'; form-action 'none'; "
        f"frame-ancestors {_FRAME_ANCESTORS}"),
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
    "Cache-Control": "no-store",
}


def _read_static(name: str) -> bytes:
    return resources.files("splinecast.viewer").joinpath("static", name).read_bytes()


class ViewerServer:
    """A viewer for one volume (or prepared scene), served on a local port.

    Parameters
    ----------
    data : Volume, Scene, or multiresolution volume or scene
        What to show; a Scene's prepared model is kept, other models are prepared on demand.
        A pyramid (``MultiscaleVolume``) is opened as a ``MultiscaleScene`` (every model, one
        brick cache at a time); a wavelet store (``WaveletVolume``) as its ``WaveletScene``
        (model ``bspline<degree>`` only); a multiresolution scene passed in is shown with its
        own model only.
    model : str, optional
        Initial model (default: the scene's, a wavelet store's, or ``"trilinear"``).
    mode : str
        Initial render mode.
    iso : float or list of float, optional
        Initial isovalue(s) (default: the automatic isovalue of
        :func:`splinecast.auto_iso`, as ``splinecast render``).
    host : str
        Address to bind; anything but a loopback address must be asked for explicitly and is
        logged as a warning (the token is then the only protection).
    port : int
        Port to bind; 0 picks a free one.
    token : str, optional
        The access token (default: a fresh random one).
    max_pixels : int
        Largest image a client may ask for.
    budget : int or str, optional
        Brick cache of a pyramid (default ``"2GiB"``, as ``splinecast render``).
    lod : float, optional
        Level of detail of a pyramid (pixels per voxel, default 1) or a wavelet store (ε in
        radians, default one pixel's angle), as ``splinecast render --lod``.
    allow_external : bool, optional
        How other time points of a time series are read (``splinecast.read(allow_external=)``).
    labels : bool
        Show ``data`` as a label volume (:class:`~splinecast.multires.scenes.labels.LabelScene`):
        ``hello.labels`` lists its labels, the state's ``labels`` chooses and fades them, and
        ``pick`` requests name the label under a pixel. A ``LabelScene`` is shown so anyway.
    colors : path, mapping or list, optional
        With ``labels``: the labels' colour table.

    Data read from a file holding several time points (``metadata["timepoints"]`` and
    ``["source"]``, as :func:`splinecast.read` records them) gets a time slider: the page's
    state chooses a time point, which is read from the file on another thread while the page
    goes on showing the current one. The automatic isovalue, window and transfer function are
    those of the time point shown first, for every time point.
    """

    #: How often (s) the server looks for bricks a pyramid's loader brought in.
    brick_poll_s = 0.1

    def __init__(self, data: Any, model: str | None = None, mode: str = "iso",
                 iso: Any = None, host: str = "127.0.0.1", port: int = 0,
                 token: str | None = None, max_pixels: int = MAX_PIXELS,
                 budget: Any = None, lod: float | None = None,
                 allow_external: bool | None = None, labels: bool = False,
                 colors: Any = None) -> None:
        if not isinstance(port, int) or not 0 <= port <= 65535:
            raise ParameterError(f"port must be an integer in 0..65535, got {port!r}")
        self.shown = shown(data, model=model, budget=budget, lod=lod,
                           allow_external=allow_external, labels=labels, colors=colors)
        try:
            volume = self.shown.volume
            self.volume = volume
            self.defaults = default_state(volume, model=self.shown.default_model, mode=mode,
                                          iso=iso, geometry=self.shown.geometry,
                                          timepoint=self.shown.timepoint,
                                          channels=self.shown.channels,
                                          labels=self.shown.labels)
            self.renderer = FrameRenderer(self.shown)
        except BaseException:
            self.shown.close_scene(self.shown.initial)  # stop a pyramid's loader thread
            raise
        self.host = host
        self.port = port
        self.token = token or security.new_token()
        self.max_pixels = int(max_pixels)
        self._hello = hello_message(volume, self.defaults, {
            "max_pixels": self.max_pixels, "max_message_bytes": MAX_MESSAGE_BYTES,
            "settle_ms": round(Session.settle_s * 1e3)}, geometry=self.shown.geometry,
            models=self.shown.models, modes=self.shown.modes,
            multires=self.shown.description(), timepoints=self.shown.timepoints,
            channels=self.shown.channels, labels=self.shown.labels)
        self._watcher: asyncio.Task | None = None
        self._allowed: frozenset[str] = frozenset()
        self._sessions: set[Session] = set()
        self._sockets: set[web.WebSocketResponse] = set()
        self._executor: ThreadPoolExecutor | None = None
        self._runner: web.AppRunner | None = None
        self._loop: asyncio.AbstractEventLoop | None = None

    # ------------------------------------------------------------------------- lifecycle
    @property
    def url(self) -> str:
        """The page's address with its token (valid once :meth:`start` returned)."""
        host = self.host if self.host not in ("", "0.0.0.0", "::") else "127.0.0.1"
        if ":" in host:
            host = f"[{host}]"
        return f"http://{host}:{self.port}/?token={self.token}"

    def _bind(self) -> socket.socket:
        try:
            family, kind, proto, _, address = socket.getaddrinfo(
                self.host, self.port, type=socket.SOCK_STREAM)[0]
            sock = socket.socket(family, kind, proto)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            sock.bind(address)
        except OSError as exc:
            raise ParameterError(f"cannot listen on {self.host}:{self.port}: "
                                 f"{exc.strerror or exc}") from None
        return sock

    async def start(self) -> str:
        """Bind, start serving, and return :attr:`url`."""
        sock = self._bind()
        if not security.is_loopback(self.host):
            log.warning("splinecast: warning: the viewer listens on %s: other machines can "
                        "reach it, and its token is the only protection", self.host)
        self.port = sock.getsockname()[1]
        self._allowed = security.allowed_hosts(self.host, self.port)
        self._loop = asyncio.get_running_loop()
        self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="splinecast-render")
        app = web.Application(middlewares=[self._guard], client_max_size=MAX_MESSAGE_BYTES)
        app.router.add_get("/ws", self._websocket)
        app.router.add_get("/{path:.*}", self._static)
        app.on_shutdown.append(self._close_sockets)
        self._runner = web.AppRunner(app, access_log=None, handle_signals=False)
        await self._runner.setup()
        await web.SockSite(self._runner, sock).start()
        if self.shown.kind.refreshes_with_bricks:
            self._watcher = asyncio.create_task(self._watch_bricks())
        return self.url

    async def __aenter__(self) -> ViewerServer:
        """``async with ViewerServer(data) as server``: started on entry, stopped on exit."""
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    async def stop(self) -> None:
        """Close every connection and stop serving (a pyramid's loader thread stops too)."""
        if self._watcher is not None:
            self._watcher.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await self._watcher
            self._watcher = None
        if self._runner is not None:
            await self._runner.cleanup()
            self._runner = None
        if self._executor is not None:
            self._executor.shutdown(wait=False, cancel_futures=True)
            self._executor = None
        self.renderer.close()

    def refresh_all(self) -> None:
        """Ask every client's session to re-render its last full frame (from any thread): the
        hook for data that gets more detailed over time. A pyramid needs no call: the server
        watches its loader (:meth:`_watch_bricks`) and refreshes incomplete frames itself."""
        if self._loop is not None:
            for session in list(self._sessions):
                self._loop.call_soon_threadsafe(session.refresh)

    async def _watch_bricks(self) -> None:
        """Poll the pyramid's loader and let each session refresh its frame when bricks of its
        view arrived (the sessions decide, and rate-limit, in :meth:`Session.bricks_arrived`)."""
        while True:
            await asyncio.sleep(self.brick_poll_s)
            if not self._sessions:
                continue
            try:
                loaded = self.renderer.bricks_loaded()
            except Exception:  # a scene being replaced on the render thread; try again
                log.debug("brick poll failed", exc_info=True)
                continue
            for session in list(self._sessions):
                session.bricks_arrived(loaded)

    async def _close_sockets(self, app: web.Application) -> None:
        for ws in list(self._sockets):
            await ws.close(code=1001, message=b"server shutting down")

    # -------------------------------------------------------------------------- requests
    @web.middleware
    async def _guard(self, request: web.Request, handler: Any) -> web.StreamResponse:
        if not security.host_allowed(request.headers.get("Host"), self._allowed):
            return self._refuse(403, "this server answers local host names only")
        status = security.check_token(request.query.get("token"), self.token)
        if status is not None:
            return self._refuse(status, "missing token" if status == 401 else "wrong token")
        if request.path == "/ws" and not security.origin_allowed(
                request.headers.get("Origin"), self._allowed):
            return self._refuse(403, "cross-site WebSocket refused")
        response = await handler(request)
        response.headers.update(_SECURITY_HEADERS)
        return response

    @staticmethod
    def _refuse(status: int, reason: str) -> web.Response:
        return web.Response(status=status, text=f"{status}: {reason}\n",
                            headers=_SECURITY_HEADERS)

    async def _static(self, request: web.Request) -> web.Response:
        entry = STATIC_FILES.get(request.path)
        if entry is None:
            return self._refuse(404, "not found")
        name, content_type = entry
        body = _read_static(name)
        if name == "index.html":
            body = body.replace(b"{{token}}", html.escape(self.token).encode())
            body = body.replace(b"{{version}}", str(PROTOCOL_VERSION).encode())
        return web.Response(body=body, content_type=content_type, charset="utf-8")

    async def _websocket(self, request: web.Request) -> web.WebSocketResponse:
        ws = web.WebSocketResponse(max_msg_size=MAX_MESSAGE_BYTES, compress=False)
        await ws.prepare(request)
        loop = asyncio.get_running_loop()
        executor = self._executor

        async def run_in_thread(fn: Any) -> Any:
            return await loop.run_in_executor(executor, fn)

        async def send_text(message: dict[str, Any]) -> None:
            with contextlib.suppress(ConnectionError):
                if not ws.closed:
                    await ws.send_json(message)

        async def send_bytes(data: bytes) -> None:
            with contextlib.suppress(ConnectionError):
                if not ws.closed:
                    await ws.send_bytes(data)

        session = Session(self.renderer, run_in_thread, send_text, send_bytes, self.defaults,
                          self.max_pixels)
        self._sessions.add(session)
        self._sockets.add(ws)
        worker = asyncio.create_task(session.run())
        try:
            await send_text(self._hello)
            async for message in ws:
                if message.type in (WSMsgType.TEXT, WSMsgType.BINARY):
                    await session.handle_text(message.data)
                elif message.type == WSMsgType.ERROR:
                    break
        finally:
            session.close()
            worker.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await worker
            self._sessions.discard(session)
            self._sockets.discard(ws)
        return ws
