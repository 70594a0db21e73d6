"""Compositing images of one camera rendered separately: labels, channels, layers.

Frames rendered separately with one camera (one per label of a label volume, one per channel of
a multichannel volume) are put together per pixel here. Every layer is read as
**premultiplied** RGBA rendered on a transparent background (``Shading(background=(0, 0, 0,
0))``: a hit is opaque, a miss is zero, antialiasing averages both); the scene's background goes
under the result once, at the end (:func:`on_background`), so it is not counted once per layer.

Surfaces, by depth:

* :func:`nearest_hit`: each pixel takes the frame whose ray hit first (smallest finite
  ``depth``) and reports which frame that was, so the picture can say what lies under the cursor
  (:func:`gather` then takes any buffer of that frame). Ties go to the frame listed first.
* :func:`over_by_depth`: every frame's colour at a pixel, sorted front to back by its depth,
  composited with "over": opaque surfaces give the nearest hit's colour, translucent ones let
  what lies behind show through, antialiased silhouettes blend with the surface behind them.
  It keeps only the pixels each frame drew, and frames may be windows of the image: the form
  for many small layers (the labels of a segmentation, each drawn in its own window).
* :func:`nearest_hit_over`: the same rule for a few whole-image layers (channels), compiled,
  returning the composite and the nearest layer at once.

Projections and volumes, order-independent:

* :func:`window_ramp`: one projected channel (MIP values) through its window onto a
  black-to-colour ramp.
* :func:`additive`: colours summed and clipped, opacities joined as independent coverages
  (``1 - prod(1 - a)``): napari's additive blending and Fiji's "Composite", where a pixel in
  two channels shows the sum of their colours (red + green = yellow).

Which of these a multichannel frame uses is the render mode's to say: every mode declares a
:class:`Compositing` rule (:attr:`splinecast.render.modes.RenderMode.compositing`), how the frames
it renders per channel combine into one image. :data:`ADDITIVE` (the default: projections,
volume rendering) and :data:`NEAREST_HIT` (surfaces) are the rules of the built-in modes; a mode
of one's own may declare another (a subclass of :class:`Compositing`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import prange

from .._jit import jit
from ..errors import ParameterError
from .frame import Frame

__all__ = ["nearest_hit", "gather", "over_by_depth", "nearest_hit_over", "window_ramp",
           "additive", "on_background", "Composite", "Compositing", "Additive", "NearestHit",
           "ADDITIVE", "NEAREST_HIT"]



Offsets = Sequence[tuple[int, int]] | None


def _layout(frames: Sequence[Frame], need: str, offsets: Offsets,
            size: tuple[int, int] | None) -> tuple[tuple[int, int], list[tuple[int, int]]]:
    """The composite's ``(height, width)`` and each frame's top-left pixel in it, checked."""
    if not frames and size is None:
        raise ParameterError("nothing to composite: no frames")
    shapes = []
    for frame in frames:
        array = getattr(frame, need)
        if array is None:
            raise ParameterError(f"compositing needs each frame's {need} buffer: render with "
                                 f"outputs including {need!r}")
        shapes.append(array.shape[:2])
    if offsets is None:
        if len(set(shapes)) > 1:
            raise ParameterError(f"frames of different sizes cannot be composited: "
                                 f"{sorted(set(shapes))}")
        offsets = [(0, 0)] * len(frames)
        size = size or shapes[0]
    elif len(offsets) != len(frames) or size is None:
        raise ParameterError("offsets need one (row, column) per frame and the size")
    height, width = size
    for (h, w), (r0, c0) in zip(shapes, offsets, strict=True):
        if r0 < 0 or c0 < 0 or r0 + h > height or c0 + w > width:
            raise ParameterError(f"a {w}x{h} frame at row {r0}, column {c0} does not fit in "
                                 f"the {width}x{height} image")
    return (int(height), int(width)), [(int(r), int(c)) for r, c in offsets]


def _window(array: np.ndarray, offset: tuple[int, int], frame_array: np.ndarray) -> np.ndarray:
    r0, c0 = offset
    return array[r0:r0 + frame_array.shape[0], c0:c0 + frame_array.shape[1]]


def nearest_hit(frames: Sequence[Frame], offsets: Offsets = None,
                size: tuple[int, int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel, the frame whose ray hit first.

    Parameters
    ----------
    frames : sequence of Frame
        Renders of one camera, each with a ``depth`` buffer: the whole image, or windows of it
        (:meth:`splinecast.Camera.tile`) placed by ``offsets``.
    offsets : sequence of (row, column), optional
        The top-left pixel of each frame in the image (default: every frame is the image).
    size : (height, width), optional
        The image's size (needed with ``offsets``).

    Returns
    -------
    depth : ndarray (height, width), float64
        The smallest depth over the frames (``inf`` where every ray missed).
    source : ndarray (height, width), int32
        Index into ``frames`` of the frame that gave it; ``-1`` where every ray missed. Ties go
        to the earlier frame.
    """
    (height, width), places = _layout(frames, "depth", offsets, size)
    depth = np.full((height, width), np.inf)
    source = np.full((height, width), -1, np.int32)
    for index, (frame, place) in enumerate(zip(frames, places, strict=True)):
        d, s = _window(depth, place, frame.depth), _window(source, place, frame.depth)
        nearer = frame.depth < d  # streaming: one frame in memory beside the result
        d[nearer] = frame.depth[nearer]
        s[nearer] = index
    return depth, source


def gather(frames: Sequence[Frame], source: np.ndarray, name: str, offsets: Offsets = None,
           ) -> np.ndarray | None:
    """Buffer ``name`` of the frame ``source`` names at each pixel (:func:`nearest_hit`, with
    the same ``offsets``); ``None`` if a frame lacks it. Pixels without a source hold the
    buffer's miss value (NaN for floats, 0 for integers)."""
    arrays = [getattr(f, name) for f in frames]
    if not arrays or any(a is None for a in arrays):
        return None
    places = offsets if offsets is not None else [(0, 0)] * len(frames)
    first = arrays[0]
    fill = np.nan if first.dtype.kind == "f" else 0
    out = np.full(source.shape + first.shape[2:], fill, first.dtype)
    for index, (array, place) in enumerate(zip(arrays, places, strict=True)):
        window = _window(out, place, array)
        mask = _window(source, place, array) == index
        window[mask] = array[mask]
    return out


def over_by_depth(frames: Sequence[Frame], offsets: Offsets = None,
                  size: tuple[int, int] | None = None) -> np.ndarray:
    """Composite premultiplied colours front to back by depth with the "over" operator.

    Each frame contributes, at each pixel where its alpha is positive, one fragment at that
    pixel's depth (a pixel with colour but a missed centre ray, on an antialiased silhouette,
    sorts last). Fragments at one pixel are sorted by depth (ties: the earlier frame first)
    and composited: ``C += T * c``, ``T *= 1 - a``.

    Parameters
    ----------
    frames : sequence of Frame
        Renders of one camera with ``rgba`` (premultiplied) and ``depth``.
    offsets, size : optional
        Windows of the image, as for :func:`nearest_hit`.

    Returns
    -------
    ndarray (height, width, 4), float32
        Premultiplied RGBA of the composite (alpha 0 where nothing was drawn).
    """
    (height, width), places = _layout(frames, "rgba", offsets, size)
    _layout(frames, "depth", offsets, (height, width))
    # Only the pixels a frame drew are kept (a label covers a small part of the image), so the
    # memory is that of the fragments, not of a stack of whole frames.
    pixels, depths, order, colours = [], [], [], []
    for index, (frame, (r0, c0)) in enumerate(zip(frames, places, strict=True)):
        rows, cols = np.nonzero(frame.rgba[..., 3] > 0)
        pixels.append((rows + r0).astype(np.int64) * width + (cols + c0))
        depths.append(frame.depth[rows, cols])
        order.append(np.full(rows.size, index, np.int32))
        colours.append(frame.rgba[rows, cols].astype(np.float32))
    if not pixels:
        return np.zeros((height, width, 4), np.float32)
    pixel = np.concatenate(pixels)
    depth = np.concatenate(depths)
    colour = np.concatenate(colours)
    sort = np.lexsort((np.concatenate(order), depth, pixel))
    pixel, colour = pixel[sort], colour[sort]
    # The rank of each fragment among its pixel's (0: the front one).
    starts = np.r_[0, np.flatnonzero(np.diff(pixel)) + 1] if pixel.size else np.zeros(0, int)
    run = np.diff(np.r_[starts, pixel.size])
    rank = np.arange(pixel.size) - np.repeat(starts, run)
    out = np.zeros((height * width, 4), np.float32)
    transmit = np.ones(height * width, np.float32)
    for layer in range(int(rank.max()) + 1 if rank.size else 0):  # at most one per frame
        at = rank == layer
        where, c = pixel[at], colour[at]
        out[where] += transmit[where, None] * c
        transmit[where] *= 1.0 - c[:, 3]
    return out.reshape(height, width, 4)




def _stack(layers: Sequence[np.ndarray], what: str) -> np.ndarray:
    if len(layers) == 0:
        raise ParameterError(f"{what}: no layers to composite")
    shapes = {np.shape(a) for a in layers}
    if len(shapes) != 1:
        raise ParameterError(f"{what}: layers of different shapes {sorted(shapes)}")
    stacked = np.stack([np.asarray(a, np.float64) for a in layers])
    if stacked.ndim != 4 or stacked.shape[-1] != 4:
        raise ParameterError(f"{what}: layers must be (height, width, 4) RGBA images, got "
                             f"{stacked.shape[1:]}")
    return stacked


def window_ramp(value: np.ndarray, window: tuple[float, float], color: Sequence[float],
                empty: np.ndarray | None = None) -> np.ndarray:
    """A projected channel as a premultiplied RGBA layer: ``value`` through ``window`` onto
    the ramp from black to ``color``.

    Parameters
    ----------
    value : ndarray (height, width)
        Projected values (``Frame.value`` of a MIP); NaN where the ray missed the volume.
    window : (lo, hi)
        Values at or below ``lo`` are black, at or above ``hi`` the full colour (linear in
        between, not quantized).
    color : 3 floats in [0, 1]
    empty : ndarray (height, width) of bool, optional
        Pixels whose ray met only background: transparent, as misses are.

    Returns
    -------
    ndarray (height, width, 4), float64
        Opaque (alpha 1) wherever the ray met the volume, transparent elsewhere.
    """
    lo, hi = float(window[0]), float(window[1])
    span = hi - lo if hi > lo else 1.0
    value = np.asarray(value, np.float64)
    met = np.isfinite(value)
    if empty is not None:
        met &= ~np.asarray(empty, bool)
    t = np.clip((np.where(met, value, lo) - lo) / span, 0.0, 1.0)
    out = np.zeros((*value.shape, 4))
    out[..., :3] = t[..., None] * np.asarray(color, np.float64)[:3]
    out[..., 3] = met
    return out


def additive(layers: Sequence[np.ndarray]) -> np.ndarray:
    """The additive composite of premultiplied RGBA layers.

    Colour: the sum of the layers' colours, clipped to 1. Opacity: ``1 - prod(1 - a_i)``, the
    coverage of independent layers (1 where any layer is opaque; a single layer's own). The
    result does not depend on the layers' order.

    Its limit, for volume renderings: each layer was integrated alone, so a channel in front
    does not hide (absorb) another behind it along the ray; both glow through each other, as
    in napari's additive blending of volume layers.
    """
    stacked = _stack(layers, "additive")
    out = np.empty(stacked.shape[1:])
    out[..., :3] = np.minimum(stacked[..., :3].sum(axis=0), 1.0)
    out[..., 3] = 1.0 - np.prod(1.0 - np.clip(stacked[..., 3], 0.0, 1.0), axis=0)
    return out


def nearest_hit_over(layers: Sequence[np.ndarray], depths: Sequence[np.ndarray]
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Premultiplied RGBA layers of surfaces composited in depth order, nearest first.

    Each pixel's layers are sorted by their ``depth`` (``inf`` or NaN, a miss, last; ties keep
    the layers' order) and composited front to back with "over". Where the nearest hit is
    opaque that is simply its colour: the nearest surface hides the others, as in a
    depth-buffered scene; where it is not (an antialiased edge, a translucent surface) the
    next ones show through.

    Returns
    -------
    rgba : ndarray (height, width, 4), float64
        The composite (premultiplied).
    nearest : ndarray (height, width), int64
        The layer hit nearest to the camera, -1 where no layer has a finite depth.
    """
    stacked = _stack(layers, "nearest_hit_over").astype(np.float32)
    depth = np.stack([np.asarray(d, np.float64) for d in depths])
    if depth.shape != stacked.shape[:3]:
        raise ParameterError(f"nearest_hit_over: depths of shape {depth.shape[1:]} for layers "
                             f"of {stacked.shape[1:3]}")
    out = np.empty(stacked.shape[1:])
    nearest = np.empty(depth.shape[1:], np.int64)
    _nearest_over(stacked, depth, out, nearest)
    return out, nearest


@jit(parallel=True)
def _nearest_over(layers, depth, out, nearest):  # pragma: no cover - compiled
    """Per pixel: the layers in increasing depth (insertion sort: a handful of layers),
    composited front to back; the first one's index if it was hit."""
    n, height, width = depth.shape
    for row in prange(height):
        order = np.empty(n, np.int64)
        keys = np.empty(n)
        for col in range(width):
            for k in range(n):
                d = depth[k, row, col]
                key = d if d == d else math.inf  # NaN: a miss
                at = k
                while at > 0 and keys[at - 1] > key:  # strict: ties keep the layers' order
                    keys[at] = keys[at - 1]
                    order[at] = order[at - 1]
                    at -= 1
                keys[at] = key
                order[at] = k
            nearest[row, col] = order[0] if keys[0] < math.inf else -1
            r = g = b = a = 0.0
            for k in range(n):
                rest = 1.0 - a
                if rest <= 0.0:
                    break
                layer = order[k]
                r += rest * layers[layer, row, col, 0]
                g += rest * layers[layer, row, col, 1]
                b += rest * layers[layer, row, col, 2]
                a += rest * layers[layer, row, col, 3]
            out[row, col, 0] = r
            out[row, col, 1] = g
            out[row, col, 2] = b
            out[row, col, 3] = a


def on_background(rgba: np.ndarray, background: Any) -> np.ndarray:
    """A premultiplied composite put over ``background`` (RGBA, straight alpha), as the
    render modes put a ray's colour over it: ``C + (1 - A) * bg_rgb * bg_a``,
    ``A + (1 - A) * bg_a``. Returns float32, clipped to [0, 1]."""
    bg = np.asarray(background, np.float64).reshape(4)
    rgba = np.asarray(rgba, np.float64)
    rest = 1.0 - rgba[..., 3:4]
    out = np.empty(rgba.shape, np.float32)
    out[..., :3] = np.clip(rgba[..., :3] + rest * bg[:3] * bg[3], 0.0, 1.0)
    out[..., 3:] = np.clip(rgba[..., 3:] + rest * bg[3], 0.0, 1.0)
    return out


# --------------------------------------------------------------------------- a mode's rule
@dataclass
class Composite:
    """What a :class:`Compositing` rule makes of the channels' frames.

    Attributes
    ----------
    rgba : ndarray (height, width, 4)
        The premultiplied composite, without the background (:func:`on_background` puts it
        under once).
    depth : ndarray (height, width)
        The composite's depth (``inf`` where nothing was drawn).
    position, normal, face : ndarray, optional
        Buffers of the frame that the rule chooses per pixel (a surface's), else None.
    """

    rgba: np.ndarray
    depth: np.ndarray
    position: np.ndarray | None = None
    normal: np.ndarray | None = None
    face: np.ndarray | None = None


class Compositing:
    """How the frames of one camera rendered separately, one per channel, combine into one
    image: a render mode's declared capability
    (:attr:`splinecast.render.modes.RenderMode.compositing`), which the multichannel scene
    (:class:`~splinecast.multires.scenes.channels.ChannelScene`) asks instead of testing which
    mode it renders.

    Each channel is rendered alone on a transparent background and turned into a premultiplied
    RGBA *layer* in its colour (a projection's values through the channel's window; the others'
    colours as rendered); the rule gets the layers and the frames, in the channels' order.
    """

    #: The rule's name, reported in ``Frame.stats["compositing"]``.
    name: str = ""
    #: What the composite shows, in a few words (the command line's help and the viewer's
    #: note on several channels say it of each mode).
    summary: str = ""

    def reads(self, wanted: frozenset[str]) -> frozenset[str]:
        """Buffers of every channel's frame the rule reads besides its layer and ``depth``,
        when the composite's buffers ``wanted`` are asked for (default: none)."""
        return frozenset()

    def combine(self, layers: Sequence[np.ndarray], frames: Sequence[Frame],
                wanted: frozenset[str]) -> Composite:
        """The composite of the channels' ``layers`` (premultiplied RGBA, one per frame, at
        least one) and their ``frames`` (with ``depth`` and the buffers of :meth:`reads`)."""
        raise NotImplementedError

    def __repr__(self) -> str:
        return f"<compositing {self.name!r}>"


class Additive(Compositing):
    """Colours summed and clipped (:func:`additive`), the depth the nearest of the channels':
    napari's additive blending, whatever the channels' order."""

    name = "additive"
    summary = "the sum of the channels' colours"

    def combine(self, layers: Sequence[np.ndarray], frames: Sequence[Frame],
                wanted: frozenset[str]) -> Composite:
        """:func:`additive` of the layers."""
        return Composite(additive(layers), np.min([f.depth for f in frames], axis=0))


class NearestHit(Compositing):
    """A depth test (:func:`nearest_hit_over`): each pixel shows the channel hit nearest, and
    the position, normal and face are that channel's, as opaque objects hide one another."""

    name = "nearest hit"
    summary = "the nearest channel's surface"

    def reads(self, wanted: frozenset[str]) -> frozenset[str]:
        """The surface buffers asked for: they are taken from the nearest channel."""
        return frozenset({"position", "normal", "face"} & wanted)

    def combine(self, layers: Sequence[np.ndarray], frames: Sequence[Frame],
                wanted: frozenset[str]) -> Composite:
        """:func:`nearest_hit_over` of the layers by the frames' depths."""
        rgba, nearest = nearest_hit_over(layers, [f.depth for f in frames])
        hit = nearest >= 0

        def chosen(name: str) -> np.ndarray | None:
            """The buffer of the channel hit nearest (a miss's: the first channel's)."""
            if name not in wanted:
                return None
            buffers = [getattr(f, name) for f in frames]
            picked = buffers[0].copy()
            for k, buffer in enumerate(buffers[1:], start=1):
                mine = hit & (nearest == k)
                picked[mine] = buffer[mine]
            return picked

        return Composite(rgba, np.min([f.depth for f in frames], axis=0), chosen("position"),
                         chosen("normal"), chosen("face"))


#: The rule of projections and volume rendering (:class:`Additive`).
ADDITIVE = Additive()
#: The rule of surfaces (:class:`NearestHit`).
NEAREST_HIT = NearestHit()
