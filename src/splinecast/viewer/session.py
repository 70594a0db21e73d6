"""One client of the viewer: which frames to render for it, in which order and at what size.

Scheduling rules (the interaction model of the issue):

* **One frame in flight, the newest request wins.** A request waiting for the render thread is
  replaced by a newer one; a frame being rendered is abandoned at its next stripe boundary when a
  newer request arrives (:mod:`.renderer`). A superseded request gets no frame.
* **Dragging:** ``"interactive": true`` requests are rendered at scale ``1/k``, the largest
  whose frame is expected to take :attr:`Session.interactive_ms` (40 ms, since a request may
  also wait for the frame in flight) at most, and sent as JPEG. The expectation comes from the
  drag's own recent frames (a fixed part per frame and a part per pixel,
  :meth:`.renderer.FrameRenderer.estimate_ms`), so the scale follows the view's cost both ways.
* **Settling:** :attr:`Session.settle_s` (0.3 s) after the last interactive request, the same state
  is rendered at full resolution and sent as PNG (lossless). A request with
  ``"interactive": false`` (a click, a typed value) skips the wait.
* **Progressive refinement:** a full-resolution frame expected to take longer than
  :attr:`Session.progressive_ms` is preceded by a coarse one, unless the client already shows a
  reduced frame (it comes from a drag).
* **Screenshots** are rendered at full resolution as PNG and are never superseded.
* **New kernels never stop the frames:** views render with the kernels that are ready (in
  memory or in the disk cache). A request whose model or mode needs kernels compiled first
  (their first use) has them prepared on a thread of their own
  (:meth:`~.renderer.FrameRenderer.warm`) while the page goes on showing the last picture that
  could be rendered, seen from the request's camera (pass ``preparing``, with a ``preparing``
  field saying what is being prepared and for how long), and ``status`` messages say so every
  second. When they are ready, the newest request is rendered; a newer request for kernels
  that are ready ends the wait, one for other new kernels is prepared next (the newest wins).
* **Another time point** of a time series is read and prepared the same way: on a thread of its
  own (:meth:`~.renderer.FrameRenderer.load_timepoint`), while the page goes on getting
  ``preparing`` frames of the time point it shows, seen from the request's camera; the
  ``preparing`` field names the ``timepoint`` being loaded.
* **More detail later:** :meth:`Session.refresh` re-renders the last settled state at full
  resolution. For a pyramid the server calls :meth:`Session.bricks_arrived` a few times a second
  with the loader's count of bricks read; the session re-renders (pass ``full``, drawing what is
  resident) when bricks landed since its last full frame, that frame was not complete, the page
  shows it (no drag, no newer request waiting, nothing rendering) and at least
  :attr:`Session.refresh_s` passed since the last refresh. It stops once a frame is complete.

The session knows nothing of sockets: the server gives it two coroutines that send a text and a
binary message, and a function that runs a callable on the render thread.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import threading
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, replace
from functools import partial
from typing import Any

from .._jit import CompileNeeded
from ..errors import SplinecastError
from ..volume import Volume
from .data import bricks_header
from .encoding import encode_image
from .protocol import decode_request, json_safe_stats, pack_frame
from .renderer import FrameRenderer, RenderedImage
from .state import RenderRequest, parse_state

__all__ = ["Session"]

log = logging.getLogger("splinecast.viewer")

SendText = Callable[[dict[str, Any]], Awaitable[None]]
SendBytes = Callable[[bytes], Awaitable[None]]
RunInThread = Callable[[Callable[[], Any]], Awaitable[Any]]

_MAX_DIVISOR = 8


@dataclass(frozen=True)
class _Job:
    kind: str  # "interactive", "final", "refresh" or "screenshot"
    ident: int
    request: RenderRequest


@dataclass(frozen=True)
class _Pass:
    name: str  # "interactive", "coarse", "full" or "screenshot" (the frame header's "pass")
    scale: float
    fmt: str
    final: bool


class Session:
    """The frames of one connected client.

    Parameters
    ----------
    renderer : FrameRenderer
        Shared by every session of a server (it owns the prepared scenes).
    run_in_thread : callable
        ``await run_in_thread(fn)`` runs ``fn()`` on the render thread and returns its result.
    send_text, send_bytes : coroutine functions
        Send a JSON message / a binary frame message to the client.
    defaults : dict
        The complete default state (:func:`~splinecast.viewer.state.default_state`).
    max_pixels : int
        Largest image a request may ask for.
    prepare_in_thread : coroutine function, optional
        ``await prepare_in_thread(fn)`` runs ``fn()`` on a thread other than the render
        thread (kernels being compiled); by default a new daemon thread each time.
    """

    #: Seconds without interactive requests after which the full-resolution frame follows.
    settle_s = 0.3
    #: Render time aimed at for reduced frames while dragging (ms).
    interactive_ms = 40.0
    #: Full frames expected to take longer than this (ms) are preceded by a coarse one.
    progressive_ms = 250.0
    #: Shortest time between two refreshes for arriving bricks (s).
    refresh_s = 0.25
    #: Time between two status messages while kernels are prepared (s).
    preparing_status_s = 1.0

    def __init__(self, renderer: FrameRenderer, run_in_thread: RunInThread,
                 send_text: SendText, send_bytes: SendBytes, defaults: dict[str, Any],
                 max_pixels: int, prepare_in_thread: RunInThread | None = None) -> None:
        self.renderer = renderer
        self._run = run_in_thread
        self._prepare_run = prepare_in_thread or _in_daemon_thread
        # What the page can be shown while other kernels are prepared: the last request
        # rendered and the pass it was rendered for (its kernels are loaded).
        self._ready: tuple[RenderRequest, str] | None = None
        self._wanted: _Job | None = None  # the newest view waiting for its kernels
        self._preparing: asyncio.Task | None = None
        self._preparing_since = 0.0
        self._compiling = False  # the kernels being prepared are compiling (not loading)
        self._loading: int | None = None  # the time point being read, if one is
        # (model, mode) prepared once: if a view of it still needs a kernel (a combination the
        # preparation did not cover), it compiles on the render thread as before.
        self._prepared: set[tuple[str, str]] = set()
        self._send_text = send_text
        self._send_bytes = send_bytes
        self._defaults = defaults
        self._max_pixels = max_pixels
        self._view: _Job | None = None
        self._shot: _Job | None = None
        self._generation = 0  # counts view requests; a render compares it to know it is stale
        self._wake = asyncio.Event()
        self._settle: asyncio.TimerHandle | None = None
        self._settled: _Job | None = None  # the last full-resolution view request
        self._shown_final = True  # whether the last view frame sent was a full one (or none)
        self._closed = False
        self._busy = False  # a job is being served
        # The last full frame of a pyramid: (model, bricks read when its cut was resolved,
        # whether its cut was complete); None for other data or before the first one.
        self._bricks_seen: tuple[str, int, bool] | None = None
        self._last_refresh = -math.inf

    @property
    def volume(self) -> Volume:
        """The data on display."""
        return self.renderer.volume

    # --------------------------------------------------------------------------- requests
    async def handle_text(self, text: Any) -> None:
        """Handle one message from the client; a mistake is answered with an ``error``."""
        ident = None
        try:
            message = decode_request(text)
            ident = message["id"]
            shown = self.renderer.shown
            request = parse_state(message["state"], self.volume, self._defaults,
                                  self._max_pixels, geometry=shown.geometry,
                                  models=shown.models, modes=shown.modes,
                                  timepoints=shown.timepoints,
                                  channels=len(shown.channels or ()),
                                  labels=None if shown.labels is None
                                  else [entry["value"] for entry in shown.labels])
        except SplinecastError as exc:
            await self._error(ident, str(exc))
            return
        if message["type"] == "pick":
            await self._pick(ident, request, message["x"], message["y"])
            return
        if message["type"] == "screenshot":
            self._shot = _Job("screenshot", ident, request)
            self._wake.set()
            return
        self._cancel_settle()
        if message["interactive"]:
            job = _Job("interactive", ident, request)
            loop = asyncio.get_running_loop()
            self._settle = loop.call_later(self.settle_s, self._settled_now,
                                           _Job("final", ident, request))
        else:
            job = _Job("final", ident, request)
        self._submit_view(job)

    async def _pick(self, ident: int, request: RenderRequest, x: float, y: float) -> None:
        """Answer a ``pick`` request: the label under pixel (x, y) of the request's image,
        rendered on the render thread (one ray; between frames, never during one)."""
        try:
            found = await self._run(partial(self.renderer.pick, request, x, y))
        except SplinecastError as exc:
            await self._error(ident, str(exc))
            return
        await self._send_text({"type": "pick", "id": ident, "x": x, "y": y, **found})

    def refresh(self) -> None:
        """Render the last full-resolution state again (call on the event loop's thread, e.g.
        via ``loop.call_soon_threadsafe``): for data that got more detailed since."""
        if self._settled is not None and self._view is None:
            job = self._settled
            self._submit_view(_Job("refresh", job.ident, job.request))

    def bricks_arrived(self, loaded: dict[str, int]) -> bool:
        """Refresh the shown full frame if bricks of its model landed since it was rendered and
        it was incomplete (see the module docstring); returns whether a refresh was queued.

        Parameters
        ----------
        loaded : dict
            Bricks read so far by each pyramid scene, by model
            (:meth:`.renderer.FrameRenderer.bricks_loaded`).
        """
        seen = self._bricks_seen
        if (seen is None or seen[2] or self._closed or self._busy or self._view is not None
                or self._settle is not None or not self._shown_final or self._settled is None
                or self._settled.request.model != seen[0]):
            return False
        if loaded.get(seen[0], seen[1]) <= seen[1]:
            return False
        now = time.perf_counter()
        if now - self._last_refresh < self.refresh_s:
            return False
        self._last_refresh = now
        self.refresh()
        return True

    def close(self) -> None:
        """Stop: waiting requests are dropped and :meth:`run` returns."""
        self._closed = True
        self._wanted = None
        if self._preparing is not None:
            self._preparing.cancel()  # a compile under way finishes on its own thread
        self._cancel_settle()
        self._generation += 1
        self._wake.set()

    def _cancel_settle(self) -> None:
        if self._settle is not None:
            self._settle.cancel()
            self._settle = None

    def _settled_now(self, job: _Job) -> None:
        """The settle timer fired: no drag in progress any more; render the full frame."""
        self._settle = None
        self._submit_view(job)

    def _submit_view(self, job: _Job) -> None:
        self._view = job
        self._generation += 1
        self._wake.set()

    # ---------------------------------------------------------------------------- the loop
    async def run(self) -> None:
        """Render waiting requests until :meth:`close` (one at a time, newest first)."""
        while not self._closed:
            await self._wake.wait()
            self._wake.clear()
            while not self._closed:
                if self._shot is not None:
                    job, self._shot = self._shot, None
                elif self._view is not None:
                    job, self._view = self._view, None
                else:
                    break
                self._busy = True
                try:
                    await self._serve(job)
                finally:
                    self._busy = False

    def _passes(self, job: _Job) -> list[_Pass]:
        if job.kind == "screenshot":
            return [_Pass("screenshot", 1.0, "png", True)]
        if job.kind == "interactive":
            divisor = self._divisor(job.request, self.interactive_ms, 2, "interactive")
            return [_Pass("interactive", 1.0 / divisor, "jpeg", False)]
        passes = []
        estimate = self.renderer.estimate_ms(job.request)
        slow = estimate is None or estimate > self.progressive_ms
        # A coarse frame helps after a jump (a new mode, a click); coming from a drag, the
        # client already shows a reduced frame close to this state.
        if job.kind == "final" and slow and self._shown_final:
            divisor = self._divisor(job.request, self.interactive_ms, 4, "coarse")
            passes.append(_Pass("coarse", 1.0 / max(divisor, 2), "jpeg", False))
        passes.append(_Pass("full", 1.0, "png", True))
        return passes

    def _divisor(self, request: RenderRequest, target_ms: float, default: int,
                 step: str) -> int:
        """The smallest ``k`` (at most 8) such that pass ``step`` at ``1/k`` of the full size is
        expected to take ``target_ms`` at most; ``default`` before any frame of its kind."""
        if self.renderer.estimate_ms(request, step=step) is None:
            return default
        for divisor in range(1, _MAX_DIVISOR):
            if self.renderer.estimate_ms(request, 1.0 / divisor, step) <= target_ms:
                return divisor
        return _MAX_DIVISOR

    async def _serve(self, job: _Job) -> None:
        generation = self._generation
        stale = None if job.kind == "screenshot" else (lambda: self._generation != generation)
        request = job.request
        if job.kind != "screenshot" and not self.renderer.has_timepoint(request.timepoint):
            await self._wait_for_kernels(job, stale)  # read aside; the page keeps its picture
            return
        if not self.renderer.has_scene(request.model, request.timepoint):
            await self._send_text({"type": "status", "id": job.ident,
                                   "message": f"preparing model {request.model}"})
        # Screenshots, and views of a model and mode prepared already, compile on the render
        # thread if they must; other views render with ready kernels only.
        may_compile = job.kind == "screenshot" or (request.model, request.mode) in self._prepared
        for step in self._passes(job):
            if stale is not None and stale():
                return
            name = "refresh" if job.kind == "refresh" else step.name
            work = partial(self._render_and_encode, request, step, stale, name, may_compile)
            try:
                result = await self._run(work)
            except CompileNeeded:
                await self._wait_for_kernels(job, stale)
                return
            except SplinecastError as exc:
                await self._error(job.ident, str(exc))
                return
            except Exception as exc:  # a bug must not end the server: log it, tell the page
                log.exception("rendering failed")
                await self._error(job.ident, f"internal error: {type(exc).__name__}: {exc}")
                return
            if result is None:
                return
            image, data, encode_ms = result
            await self._send_bytes(pack_frame(self._header(job, step, image, encode_ms,
                                                           request.timepoint), data))
            if job.kind != "screenshot":
                self._ready = (request, name)
                if self._wanted is not None and self._wanted.ident <= job.ident:
                    self._wanted = None  # a newer view rendered: nothing to wait for
                self._shown_final = step.final
                if step.final:
                    self._settled = job
                    bricks = bricks_header(image.stats)
                    self._bricks_seen = None if bricks is None else (
                        job.request.model, bricks["loaded"], bricks["complete"])

    def _render_and_encode(self, request: RenderRequest, step: _Pass,
                           stale: Callable[[], bool] | None, name: str, compile: bool = True
                           ) -> tuple[RenderedImage, bytes, float] | None:
        """On the render thread: the image of one pass and its encoded bytes."""
        image = self.renderer.render(request, step.scale, stale, name, compile=compile)
        if image is None:
            return None
        start = time.perf_counter()
        data = encode_image(image.rgba, step.fmt)
        return image, data, (time.perf_counter() - start) * 1e3

    @staticmethod
    def _header(job: _Job, step: _Pass, image: RenderedImage, encode_ms: float,
                timepoint: int) -> dict:
        height, width = image.rgba.shape[:2]
        header = {
            "type": "frame",
            "id": job.ident,
            "pass": step.name,
            "final": step.final,
            "format": step.fmt,
            "width": width,
            "height": height,
            "scale": image.scale,
            "render_ms": round(image.render_ms, 2),
            "encode_ms": round(encode_ms, 2),
            "stats": json_safe_stats(image.stats),
            "timepoint": timepoint,  # the time point shown (a preparing frame's: the old one)
        }
        bricks = bricks_header(image.stats)
        if bricks is not None:
            header["bricks"] = bricks
        return header

    # ------------------------------------------------------------------ new kernels
    async def _wait_for_kernels(self, job: _Job, stale: Callable[[], bool] | None) -> None:
        """``job`` needs kernels not compiled yet, or a time point not in memory: prepare them
        on another thread (the newest such job wins) and meanwhile show the last picture that
        renders, from ``job``'s camera."""
        wanted = self._wanted
        if wanted is None or (wanted.request.model, wanted.request.mode,
                              wanted.request.timepoint) != (
                job.request.model, job.request.mode, job.request.timepoint):
            self._preparing_since = time.perf_counter()
        self._wanted = job
        if self._preparing is None or self._preparing.done():
            self._compiling = False
            self._preparing = asyncio.create_task(self._prepare_wanted())
        await self._send_preparing_status()
        if self._ready is None or (stale is not None and stale()):
            return
        shown, name = self._ready
        if not self.renderer.has_timepoint(shown.timepoint):
            return  # released meanwhile (another page moved on): the page keeps its picture
        fallback = replace(shown, camera=job.request.camera)
        divisor = self._divisor(fallback, self.interactive_ms, 2, "interactive")
        step = _Pass("preparing", 1.0 / divisor, "jpeg", False)
        # Rendered with the options of pass ``name`` (the pass its kernels were loaded for),
        # at this pass's scale, ready kernels only.
        work = partial(self._render_and_encode, fallback, step, stale, name, False)
        try:
            result = await self._run(work)
        except (CompileNeeded, SplinecastError):
            return  # nothing ready renders this view: the page keeps its picture
        if result is None:
            return
        image, data, encode_ms = result
        header = self._header(job, step, image, encode_ms, fallback.timepoint)
        header["preparing"] = self._preparing_field()
        await self._send_bytes(pack_frame(header, data))
        self._shown_final = False

    async def _prepare_wanted(self) -> None:
        """Prepare the kernels of the newest waiting view, then render it; repeat while a
        newer view waits for other kernels."""
        ticker = asyncio.create_task(self._tick_preparing())
        try:
            while self._wanted is not None and not self._closed:
                job = self._wanted
                key = (job.request.model, job.request.mode)
                timepoint = job.request.timepoint
                try:
                    if not self.renderer.has_timepoint(timepoint):
                        self._loading = timepoint
                        await self._send_preparing_status()
                        await self._prepare_run(partial(self.renderer.load_timepoint, timepoint,
                                                        job.request.model))
                        self._loading = None
                    await self._prepare_run(partial(self.renderer.warm, job.request,
                                                    self._compiled_now))
                except SplinecastError as exc:
                    self._loading = None
                    if self._wanted is job:
                        self._wanted = None
                    await self._error(job.ident, str(exc))
                    continue
                except Exception as exc:  # a bug must not end the server: log it, tell the page
                    log.exception("preparing kernels failed")
                    self._loading = None
                    if self._wanted is job:
                        self._wanted = None
                    await self._error(job.ident, f"internal error: {type(exc).__name__}: {exc}")
                    continue
                self._prepared.add(key)
                self._compiling = False
                if self._wanted is job:
                    self._wanted = None
                    await self._send_preparing_status()
                    self._submit_view(_Job("final", job.ident, job.request))
        finally:
            ticker.cancel()

    def _compiled_now(self) -> None:
        """Called on the preparing thread when a kernel compiles (not only loads)."""
        self._compiling = True

    async def _tick_preparing(self) -> None:
        while True:
            await asyncio.sleep(self.preparing_status_s)
            if self._wanted is None:
                return
            await self._send_preparing_status()

    def _preparing_field(self) -> dict[str, Any] | None:
        """What is being prepared (the ``preparing`` field of frames and status messages)."""
        job = self._wanted
        if job is None:
            return None
        return {"model": job.request.model, "mode": job.request.mode,
                "compiling": self._compiling, "timepoint": self._loading,
                "seconds": round(time.perf_counter() - self._preparing_since, 1)}

    async def _send_preparing_status(self) -> None:
        field = self._preparing_field()
        if field is None:
            await self._send_text({"type": "status", "id": None, "preparing": None,
                                   "message": "ready"})
            return
        what = "compiling kernels (first use)" if field["compiling"] else "loading kernels"
        if field["timepoint"] is not None:
            what = f"reading time point {field['timepoint']}"
        await self._send_text({
            "type": "status", "id": self._wanted.ident if self._wanted else None,
            "preparing": field,
            "message": f"preparing {field['model']} / {field['mode']}: {what}, "
                       f"{field['seconds']:.0f} s"})

    async def _error(self, ident: int | None, message: str) -> None:
        await self._send_text({"type": "error", "id": ident, "message": message})


async def _in_daemon_thread(fn: Callable[[], Any]) -> Any:
    """``await`` ``fn()`` run on a new daemon thread: a compile cannot be interrupted, and a
    server that stops must not wait for one to end."""
    loop = asyncio.get_running_loop()
    future = loop.create_future()

    def settle(outcome: str, value: Any) -> None:
        if not future.done():
            (future.set_result if outcome == "result" else future.set_exception)(value)

    def target() -> None:
        try:
            outcome = ("result", fn())
        except BaseException as exc:  # handed to the awaiting coroutine
            outcome = ("exception", exc)
        with contextlib.suppress(RuntimeError):  # the server stopped (its loop is closed)
            loop.call_soon_threadsafe(settle, *outcome)

    threading.Thread(target=target, name="splinecast-prepare", daemon=True).start()
    return await future
