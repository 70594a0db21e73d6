"""Rendering of validated requests for the viewer: a scene per model, images at a reduced scale,
full images in horizontal stripes that a newer request can abandon.

Everything here runs on the viewer's one render thread (see :mod:`.session`): a :class:`Scene`
is not safe to use from two threads at once, and the compiled kernels already use every core, so
frames of several clients are rendered one after another.

Stripes are windows of the full image (:meth:`Camera.tile`): their rays are bit-identical to the
full image's, so a frame assembled from stripes equals ``Scene.render`` of the whole camera. They
exist so a slow frame can be given up between stripes when the user has already moved on.
Multiresolution scenes are rendered whole: their cut (and a wavelet store's ε) depends on the
camera's whole image, which a stripe's camera would change (the kind of data on display says
so, :attr:`.kinds.DataKind.stripes`; label volumes are rendered whole too).

A time series (``Shown.timepoints`` > 1) keys scenes by (model, time point). Another time point
is read and prepared aside (:meth:`FrameRenderer.load_timepoint`, on any thread) while the
current one goes on rendering; the first render of it makes it current and releases every scene
of the others. So at most two time points are held: the current one and the one being loaded.
"""

from __future__ import annotations

import math
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._jit import forbidding_compiles, reporting_compiles
from ..camera import Camera
from ..errors import ParameterError
from ..render.modes import modes_with_method
from ..scene import Scene
from ..volume import Volume
from .data import Shown, shown
from .state import RenderRequest, resized_camera

__all__ = ["FrameRenderer", "RenderedImage"]

#: Longest render time of a stripe: the longest a superseded frame keeps the render thread
#: busy. A frame expected to take longer is cut into as few even stripes as keep each below it;
#: each stripe adds a call's fixed cost and its antialiased border (a 1024x768 isosurface in two
#: stripes takes 8-17% longer than whole), so a frame that fits is rendered whole.
STRIPE_MS = 250.0
#: Stripe height when nothing is known yet about the cost of a frame.
_FIRST_STRIPE_ROWS = 128
_MIN_STRIPE_ROWS = 32
#: Two frames in a row whose pixel counts differ by this factor or more tell the cost model the
#: fixed part of a frame's time (the line through both); closer sizes only its per-pixel part.
_SIZES_APART = 1.5
#: The passes shown only until the full frame replaces them (a drag's reduced frames, the coarse
#: frame before a slow full one).
PREVIEW_PASSES = ("interactive", "coarse")
#: How MIP / minIP previews are rendered: samples on every second plane of voxels across the ray
#: (``method="slices"``), several times faster than the exact projection at a comparable mean
#: error (no cell walk, no root finding), so a drag shows more pixels in the same time. Full
#: frames and screenshots are the exact projection, within the state's ``tolerance``; a
#: preview's samples have no such bound, so it leaves the tolerance out.
PREVIEW_MIP = {"method": "slices", "step": 2.0, "tolerance": 0.0}


@dataclass
class RenderedImage:
    """An image rendered for a request.

    Attributes
    ----------
    rgba : ndarray, (height, width, 4) uint8
    stats : dict
        The frame's statistics (``Frame.stats``; per-stripe counts summed or averaged).
    render_ms : float
        Wall time of the render, including preparing a model's scene if that was needed.
    scale : float
        Image size relative to the request's full size.
    """

    rgba: np.ndarray
    stats: dict[str, Any] = field(default_factory=dict)
    render_ms: float = 0.0
    scale: float = 1.0


@dataclass
class _Cost:
    """Render time of one kind of frame (:meth:`FrameRenderer._cost_key`), modelled as
    ``fixed + per_pixel * pixels`` milliseconds, and the last frame it learned from.

    The fixed part (each call's set-up: the blocks' screen footprint, starting the threads)
    dominates small frames: a drag's frames at 1/8 scale take far more than 1/64 of a full
    one. A per-pixel cost alone, learned from them, overestimates every larger frame, and a drag
    that once fell to the smallest scale would stay there.
    """

    per_pixel: float
    fixed: float
    pixels: int
    ms: float

    def estimate(self, pixels: float) -> float:
        return self.fixed + self.per_pixel * pixels


class FrameRenderer:
    """Renders :class:`RenderRequest` objects of one volume, keeping recent scenes.

    Parameters
    ----------
    volume : Volume or Shown
        The data on display (:func:`.data.shown` describes multiresolution data).
    scene : Scene, optional
        An already prepared scene (``sc.view(scene)``); it is kept for its model.
    max_scenes : int
        How many prepared models to keep (each holds the model's arrays; s31 and qss are large;
        a pyramid keeps one, since each scene of it holds a brick cache).
    stripe_rows : int, optional
        Fixed stripe height; by default chosen from the cost of recent frames so a stripe takes
        about :data:`STRIPE_MS`.

    A model is chosen per time point: ``max_scenes`` scenes of the current time point are kept.
    """

    def __init__(self, volume: Volume | Shown, scene: Scene | None = None, max_scenes: int = 2,
                 stripe_rows: int | None = None) -> None:
        self.shown = volume if isinstance(volume, Shown) else shown(scene or volume)
        self.volume = self.shown.volume
        self._stripe_rows_fixed = stripe_rows
        self._pinned = self.shown.pinned
        # Scenes by (model, time point), of the current time point only.
        self._scenes: OrderedDict[tuple[str, int], Any] = OrderedDict()
        first = self.shown.timepoint
        if self.shown.initial is not None:
            self._scenes[(self.shown.initial.model_name, first)] = self.shown.initial
        # The current time point and its data; a time point loaded aside, waiting to be used:
        # (time point, data, {model: scene}) (the lock guards it and the current one).
        self._current: tuple[int, Any] = (first, self.shown.data)
        self._incoming: tuple[int, Any, dict[str, Any]] | None = None
        self._lock = threading.Lock()
        self._max_scenes = max(1, min(int(max_scenes), self.shown.kind.max_scenes))
        # Cost of recent renders, by (model, mode, several isovalues, preview options).
        self._cost: dict[tuple, _Cost] = {}

    # ------------------------------------------------------------------------------ scenes
    def _pinned_for(self, model: str, timepoint: int) -> bool:
        return (self._pinned is not None and self._pinned.model_name == model
                and timepoint == self.shown.timepoint)

    def has_scene(self, model: str, timepoint: int | None = None) -> bool:
        """Whether the model's scene of ``timepoint`` (default: the first one shown) is
        prepared (otherwise the next render prepares it)."""
        timepoint = self.shown.timepoint if timepoint is None else timepoint
        return self._pinned_for(model, timepoint) or (model, timepoint) in self._scenes

    def has_timepoint(self, timepoint: int) -> bool:
        """Whether ``timepoint`` is in memory: the current one, or one loaded aside (a render of
        another one reads it from the file first: see :meth:`load_timepoint`)."""
        with self._lock:
            incoming = self._incoming
            return self._current[0] == timepoint or (
                incoming is not None and incoming[0] == timepoint)

    def load_timepoint(self, timepoint: int, model: str) -> None:
        """Read ``timepoint`` and prepare its scene of ``model`` aside, touching nothing the
        render thread uses (safe on any thread); the next render of it makes it current.

        A time point loaded aside before and not used since is released first.
        """
        with self._lock:
            incoming, self._incoming = self._incoming, None
            if incoming is not None and incoming[0] == timepoint and model in incoming[2]:
                self._incoming = incoming
                return
        if incoming is not None and incoming[0] != timepoint:
            self._close_all(incoming[2].values())
            incoming = None
        if self.has_timepoint(timepoint):
            return
        data = incoming[1] if incoming is not None else self.shown.read_timepoint(timepoint)
        scenes = dict(incoming[2]) if incoming is not None else {}
        scenes[model] = self.shown.make_scene(model, data)
        with self._lock:
            replaced, self._incoming = self._incoming, (timepoint, data, scenes)
        if replaced is not None:
            self._close_all(replaced[2].values())

    def _close_all(self, scenes: Any) -> None:
        for scene in scenes:
            self.shown.close_scene(scene)

    def _timepoint_data(self, timepoint: int) -> Any:
        """The data of ``timepoint``, made current (render thread): loaded aside, or read now.
        Every scene of another time point is released."""
        with self._lock:
            if self._current[0] == timepoint:
                return self._current[1]
            incoming = self._incoming
            if incoming is not None and incoming[0] == timepoint:
                self._incoming = None
        if incoming is None or incoming[0] != timepoint:
            if timepoint == self.shown.timepoint:
                incoming = (timepoint, self.shown.data, {})
            else:
                incoming = (timepoint, self.shown.read_timepoint(timepoint), {})
        self._drop_scenes(0)
        for model, scene in incoming[2].items():
            self._scenes[(model, timepoint)] = scene
        with self._lock:
            self._current = (timepoint, incoming[1])
        return incoming[1]

    def scene(self, model: str, timepoint: int | None = None) -> Any:
        """The prepared scene of ``model`` at ``timepoint`` (default: the first one shown),
        building it if needed (least recent one dropped; a pyramid's scene is closed first, so
        one brick cache at a time holds its budget)."""
        timepoint = self.shown.timepoint if timepoint is None else timepoint
        if self._pinned_for(model, timepoint):
            return self._pinned
        key = (model, timepoint)
        scene = self._scenes.get(key)
        if scene is None:
            if model not in self.shown.models:  # before anything is dropped
                raise ParameterError(f"model must be one of {', '.join(self.shown.models)} for "
                                     f"{self.shown.geometry.name}, got {model!r}")
            data = self._timepoint_data(timepoint)
            scene = self._scenes.get(key)
        if scene is None:
            budget = max(self._max_scenes - (self._pinned is not None), 1)
            if self.shown.kind.close_before_open:  # e.g. one brick cache at a time
                self._drop_scenes(budget - 1)
                scene = self.shown.make_scene(model, data)
            else:  # made first: a model whose kernels are not ready drops nothing
                scene = self.shown.make_scene(model, data)
                self._drop_scenes(budget - 1)
            self._scenes[key] = scene
        self._scenes.move_to_end(key)
        return scene

    def _drop_scenes(self, keep: int) -> None:
        """Close the least recently used scenes until at most ``keep`` remain."""
        while self._scenes and len(self._scenes) > keep:
            self.shown.close_scene(self._scenes.popitem(last=False)[1])

    def bricks_loaded(self) -> dict[str, int]:
        """Bricks read so far by each pyramid scene held, by model (empty for other data); safe
        to call from any thread (the cache counts under its lock)."""
        out = {}
        scenes = list(self._scenes.items())
        if self._pinned is not None:
            scenes.append(((self._pinned.model_name,), self._pinned))
        for (model, *_), scene in scenes:
            loaded = scene.bricks_loaded()
            if loaded is not None:
                out[model] = loaded
        return out

    def close(self) -> None:
        """Release the scenes the viewer made (a pyramid's loader thread stops)."""
        while self._scenes:
            self.shown.close_scene(self._scenes.popitem(last=False)[1])
        with self._lock:
            incoming, self._incoming = self._incoming, None
        if incoming is not None:
            self._close_all(incoming[2].values())

    # ------------------------------------------------------------------------- cost model
    @staticmethod
    def _pass_options(request: RenderRequest, step: str) -> dict[str, Any]:
        """What a pass renders differently from the request: previews of MIP and minIP sample
        on planes (:data:`PREVIEW_MIP`); previews are not antialiased (the settled frames and
        screenshots are, as ``Scene.render`` does by default)."""
        if step in PREVIEW_PASSES and request.mode in modes_with_method(PREVIEW_MIP["method"]):
            return {**PREVIEW_MIP, "samples": 1}
        if step in PREVIEW_PASSES:
            return {"samples": 1}
        return {}

    def _cost_key(self, request: RenderRequest, step: str) -> tuple:
        return (request.model, request.mode, isinstance(request.options.get("iso"), list),
                bool(self._pass_options(request, step)))

    def estimate_ms(self, request: RenderRequest, scale: float = 1.0,
                    step: str = "full") -> float | None:
        """Expected render time of pass ``step`` at ``scale`` from recent renders of the same
        kind (None if there were none)."""
        cost = self._cost.get(self._cost_key(request, step))
        if cost is None:
            return None
        return cost.estimate(request.camera.width * request.camera.height * scale * scale)

    def _learn(self, request: RenderRequest, step: str, pixels: int, ms: float) -> None:
        """Update the cost of ``request``'s kind of frame with a frame of ``pixels`` that took
        ``ms``. Every frame teaches, whatever its size: the pass whose scale the model chooses
        must be able to correct it (a drag's smallest frames included)."""
        pixels = max(int(pixels), 1)
        key = self._cost_key(request, step)
        cost = self._cost.get(key)
        if cost is None:
            self._cost[key] = _Cost(ms / pixels, 0.0, pixels, ms)
            return
        (small, small_ms), (large, large_ms) = sorted(((cost.pixels, cost.ms), (pixels, ms)))
        if large >= _SIZES_APART * small and large_ms > small_ms:
            # The line through the last two frames (a drag changing its scale, a window
            # resized): how the time grows with the size, and what a frame costs anyway.
            slope = (large_ms - small_ms) / (large - small)
            fixed = min(max(0.0, small_ms - slope * small), 0.5 * ms)
            per_pixel = (ms - fixed) / pixels
        else:
            # A frame takes longer than its fixed part: at most half of it is taken as fixed
            # when the last change of size is old news.
            fixed = min(cost.fixed, 0.5 * ms)
            per_pixel = (ms - fixed) / pixels
            if per_pixel >= cost.per_pixel / 4:  # else the earlier frames included compiling
                per_pixel = 0.5 * (cost.per_pixel + per_pixel)
        self._cost[key] = _Cost(per_pixel, fixed, pixels, ms)

    # -------------------------------------------------------------------------- rendering
    def render(self, request: RenderRequest, scale: float = 1.0,
               abort: Callable[[], bool] | None = None, step: str = "full",
               compile: bool = True) -> RenderedImage | None:
        """Render ``request`` at ``scale`` times its size; ``None`` if ``abort()`` said stop.

        ``abort`` is asked between stripes. ``step`` names the pass (``interactive``,
        ``coarse``, ``full``, ``refresh``, ``screenshot``): how long a pyramid's frame waits for
        bricks (:meth:`.kinds.DataKind.render_options`), and for MIP / minIP whether it is a preview
        sampled on planes (:data:`PREVIEW_MIP`). Errors of the request (a combination of
        model and mode the library refuses, an isovalue outside the range) raise ParameterError.
        Without ``compile``, kernels come from memory or the disk cache only, and a render that
        would compile one raises :class:`splinecast._jit.CompileNeeded` instead (see
        :meth:`warm`); data whose kernels :meth:`warm` does not cover
        (:attr:`.kinds.DataKind.warm_covers`: pyramids, channels, labels) always may compile.
        """
        if compile or not self.shown.kind.warm_covers:
            return self._render(request, scale, abort, step)
        with forbidding_compiles():
            return self._render(request, scale, abort, step)

    def warm(self, request: RenderRequest, on_compile: Callable[[], None] | None = None) -> None:
        """Compile (or load) the kernels ``request`` needs, touching no scene in use: safe on
        any thread while the render thread goes on.

        A tiny volume of the same voxel type and value range is rendered with the request's
        model, mode and options, for a full frame and a drag's preview: the kernels depend on
        the types of the data and the mode's parameters, not on their sizes or values.
        ``on_compile`` is called when a kernel really compiles (not when it loads).
        """
        tiny = _tiny_volume(self.volume)
        scene = Scene(tiny, model=request.model)
        camera = Camera.orbit(tiny, size=(8, 8))
        # Clip planes and crop box are in the data's world coordinates; they change no kernel.
        # (Several channels: the channels' settings are values, not kernels; the tiny scene
        # is one volume, rendered as the mode's automatic choices make it.)
        options = {k: v for k, v in request.options.items()
                   if k not in ("clip", "crop", "channels")}
        started = (lambda name: on_compile()) if on_compile is not None else (lambda name: None)
        with reporting_compiles(started, lambda name, seconds: None):
            for step in ("full", "interactive"):
                scene.render(camera, **{"outputs": ("rgba",), **options,
                                        **self._pass_options(request, step)})

    def _render(self, request: RenderRequest, scale: float,
                abort: Callable[[], bool] | None, step: str) -> RenderedImage | None:
        start = time.perf_counter()
        scene = self.scene(request.model, request.timepoint)
        camera = request.camera
        if scale != 1.0:
            width = max(1, round(camera.width * scale))
            height = max(1, round(camera.height * scale))
            camera = resized_camera(camera, width, height)
        # Stripes start on the scene's grid of tiles, so they assemble into exactly the
        # whole image's pixels (Scene.tile_shape).
        align = scene.tile_shape[1]
        rows = self._stripe_rows(request, step, camera.width, camera.height, align)
        # The viewer shows colour only: no depth, position, normal or per-ray counters.
        options = {"outputs": ("rgba",), **request.options, **self._pass_options(request, step),
                   **self.shown.kind.render_options(step)}
        image = None
        parts: list[tuple[int, dict[str, Any]]] = []
        for row0 in range(0, camera.height, rows):
            if abort is not None and parts and abort():
                return None
            height = min(rows, camera.height - row0)
            if height == camera.height:  # whole: the frame's own pixels, no copy
                frame = scene.render(camera, **options)
                image = frame.to_uint8()
            else:
                frame = scene.render(camera.tile(0, row0, camera.width, height), **options)
                if image is None:
                    image = np.empty((camera.height, camera.width, 4), np.uint8)
                image[row0:row0 + height] = frame.to_uint8()
            parts.append((height, frame.stats))
        render_ms = (time.perf_counter() - start) * 1e3
        self._learn(request, step, camera.width * camera.height, render_ms)
        stats = _merge_stats(parts, camera.width, camera.height)
        return RenderedImage(image, stats, render_ms, camera.height / request.camera.height)

    def pick(self, request: RenderRequest, x: float, y: float) -> dict[str, Any]:
        """The label under pixel ``(x, y)`` of ``request``'s full-resolution image (render
        thread): that one pixel's ray, rendered as :meth:`Camera.tile` of a 1x1 window of the
        request's camera with one sample, through the label scene as every frame.

        Returns
        -------
        dict
            ``label`` (0: no label there), ``name`` (the label's, or None) and ``position``
            (the world point hit, or None).

        Raises
        ------
        ParameterError
            The data is not a label volume, or the pixel is outside the image.
        """
        if not self.shown.kind.picks_labels:
            raise ParameterError("pick: the data on display is not a label volume")
        camera = request.camera
        col, row = int(np.floor(x)), int(np.floor(y))
        if not (0 <= col < camera.width and 0 <= row < camera.height):
            raise ParameterError(f"pick: pixel ({x:g}, {y:g}) is outside the "
                                 f"{camera.width}x{camera.height} image")
        scene = self.scene(request.model, request.timepoint)
        options = {**request.options, "samples": 1, "outputs": ("position",)}  # label: always
        frame = scene.render(camera.tile(col, row, 1, 1), **options)
        label = int(frame.label[0, 0])
        position = frame.position[0, 0] if frame.position is not None else None
        hit = label != 0 and position is not None and bool(np.all(np.isfinite(position)))
        return {"label": label, "name": scene.style(label).name if label else None,
                "position": [float(v) for v in position] if hit else None}

    def _stripe_rows(self, request: RenderRequest, step: str, width: int, height: int,
                     align: int = 1) -> int:
        """Rows per stripe: the fewest even stripes of at most :data:`STRIPE_MS` of work each,
        a multiple of ``align`` rows."""
        if not self.shown.kind.stripes:  # rendered whole (.kinds.DataKind.stripes)
            return height
        if self._stripe_rows_fixed is not None:
            rows = self._stripe_rows_fixed
        else:
            cost = self._cost.get(self._cost_key(request, step))
            if cost is None:
                rows = _FIRST_STRIPE_ROWS
            else:
                stripes = max(1, math.ceil(cost.estimate(width * height) / STRIPE_MS))
                # Rounded up to the alignment, so the stripes are no more than that many.
                step_rows = max(1, int(align))
                rows = max(_MIN_STRIPE_ROWS,
                           math.ceil(height / stripes / step_rows) * step_rows)
        align = max(1, int(align))
        rows = max(align, rows - rows % align)
        return max(1, min(height, rows))


def _tiny_volume(volume: Volume) -> Volume:
    """A 6^3 volume of ``volume``'s voxel type and value range (its smallest and largest values
    both occur), for compiling kernels without the real data."""
    lo, hi = volume.value_range
    values = np.linspace(lo, hi, 6 ** 3).reshape(6, 6, 6)
    data = np.clip(np.round(values) if np.issubdtype(volume.dtype, np.integer) else values,
                   lo, hi).astype(volume.dtype)
    data.flat[0], data.flat[-1] = lo, hi
    return Volume(data, spacing=volume.spacing, origin=volume.origin)


def _merge_stats(parts: list[tuple[int, dict[str, Any]]], width: int,
                 height: int) -> dict[str, Any]:
    """One frame's statistics from its stripes': times and hits summed, means weighted by rows."""
    if not parts:
        raise ParameterError("nothing was rendered")
    stats = dict(parts[-1][1])
    for key in ("trace_ms", "hits"):
        if all(key in s for _, s in parts):
            stats[key] = sum(s[key] for _, s in parts)
    for key in stats:
        if key.startswith("mean_") and all(key in s for _, s in parts):
            stats[key] = sum(rows * s[key] for rows, s in parts) / height
    stats.update(width=width, height=height, rays=width * height, stripes=len(parts))
    return stats
