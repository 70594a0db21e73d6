"""Compositing frames of the same camera: nearest hit, "over" in depth order, a background.

Frames rendered separately with one camera (one per label of a label volume, one per channel,
an isosurface beside other geometry) are put together per pixel here. Two rules:

* :func:`nearest_hit`: each pixel takes the frame whose ray hit first (smallest finite
  ``depth``), and reports which frame that was, so the picture can say what lies under the
  cursor. Ties go to the frame listed first.
* :func:`over_by_depth`: every frame's colour at a pixel, sorted front to back by its depth, is
  composited with the "over" operator. Opaque surfaces then give the nearest hit's colour;
  translucent ones let what lies behind show through; antialiased silhouettes (partial alpha,
  their centre ray's depth) blend with the surface behind them instead of a background.

The colours are read as **premultiplied** RGBA: a frame rendered on a transparent background
(``Shading(background=(0, 0, 0, 0))``) is premultiplied already (a hit is opaque, a miss is
zero, antialiasing averages both). :func:`over_background` composites the result once on a
background at the end and returns straight (unpremultiplied) RGBA, as :class:`Frame` holds.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..errors import ParameterError
from .frame import Frame

__all__ = ["nearest_hit", "gather", "over_by_depth", "over_background"]


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


def over_background(premultiplied: np.ndarray, background: Sequence[float]) -> np.ndarray:
    """Straight RGBA of premultiplied colours composited over a background colour.

    Parameters
    ----------
    premultiplied : ndarray (..., 4)
        Premultiplied RGBA (:func:`over_by_depth`).
    background : 4 floats in [0, 1]
        Straight RGBA of the background (``Shading.background``).

    Returns
    -------
    ndarray (..., 4), float32
        Straight RGBA; where the result is fully transparent its colour is 0.
    """
    bg = np.asarray(background, np.float32)
    alpha = premultiplied[..., 3:4]
    colour = premultiplied[..., :3] + bg[:3] * bg[3] * (1.0 - alpha)
    total = alpha + bg[3] * (1.0 - alpha)
    with np.errstate(invalid="ignore", divide="ignore"):
        straight = np.where(total > 0, colour / np.where(total > 0, total, 1), 0.0)
    return np.concatenate([np.clip(straight, 0, 1), total], axis=-1).astype(np.float32)
