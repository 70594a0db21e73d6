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


def _check_same_size(frames: Sequence[Frame], need: str) -> tuple[int, int]:
    if not frames:
        raise ParameterError("nothing to composite: no frames")
    shapes = set()
    for frame in frames:
        array = getattr(frame, need)
        if array is None:
            raise ParameterError(f"compositing needs each frame's {need} buffer: render with "
                                 f"outputs including {need!r}")
        shapes.add(array.shape[:2])
    if len(shapes) != 1:
        raise ParameterError(f"frames of different sizes cannot be composited: {sorted(shapes)}")
    return shapes.pop()


def nearest_hit(frames: Sequence[Frame]) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel, the frame whose ray hit first.

    Parameters
    ----------
    frames : sequence of Frame
        Renders of one camera, each with a ``depth`` buffer.

    Returns
    -------
    depth : ndarray (height, width), float64
        The smallest depth over the frames (``inf`` where every ray missed).
    source : ndarray (height, width), int32
        Index into ``frames`` of the frame that gave it; ``-1`` where every ray missed. Ties go
        to the earlier frame.
    """
    height, width = _check_same_size(frames, "depth")
    depth = np.full((height, width), np.inf)
    source = np.full((height, width), -1, np.int32)
    for index, frame in enumerate(frames):  # streaming: one frame in memory beside the result
        nearer = frame.depth < depth
        depth[nearer] = frame.depth[nearer]
        source[nearer] = index
    return depth, source


def gather(frames: Sequence[Frame], source: np.ndarray, name: str) -> np.ndarray | None:
    """Buffer ``name`` of the frame ``source`` names at each pixel (:func:`nearest_hit`);
    ``None`` if a frame lacks it. Pixels without a source hold the buffer's miss value (NaN for
    floats, 0 for integers)."""
    arrays = [getattr(f, name) for f in frames]
    if any(a is None for a in arrays):
        return None
    first = arrays[0]
    fill = np.nan if first.dtype.kind == "f" else 0
    out = np.full(first.shape, fill, first.dtype)
    for index, array in enumerate(arrays):
        mask = source == index
        out[mask] = array[mask]
    return out


def over_by_depth(frames: Sequence[Frame]) -> np.ndarray:
    """Composite premultiplied colours front to back by depth with the "over" operator.

    Each frame contributes, at each pixel where its alpha is positive, one fragment at that
    pixel's depth (a pixel with colour but a missed centre ray, on an antialiased silhouette,
    sorts last). Fragments at one pixel are sorted by depth (ties: the earlier frame first)
    and composited: ``C += T * c``, ``T *= 1 - a``.

    Parameters
    ----------
    frames : sequence of Frame
        Renders of one camera with ``rgba`` (premultiplied) and ``depth``.

    Returns
    -------
    ndarray (height, width, 4), float32
        Premultiplied RGBA of the composite (alpha 0 where nothing was drawn).
    """
    height, width = _check_same_size(frames, "rgba")
    _check_same_size(frames, "depth")
    # Only the pixels a frame drew are kept (a label covers a small part of the image), so the
    # memory is that of the fragments, not of a stack of whole frames.
    pixels, depths, order, colours = [], [], [], []
    for index, frame in enumerate(frames):
        drawn = np.flatnonzero(frame.rgba[..., 3].reshape(-1) > 0)
        pixels.append(drawn)
        depths.append(frame.depth.reshape(-1)[drawn])
        order.append(np.full(drawn.size, index, np.int32))
        colours.append(frame.rgba.reshape(-1, 4)[drawn].astype(np.float32))
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
