"""Compositing the images of several layers (channels) of one view into one frame.

Every layer is an RGBA image with **premultiplied** colour, rendered on a transparent
background; the background is put under the result once, at the end
(:func:`on_background`), so it is not counted once per layer.

- :func:`additive`: colours summed and clipped, opacities joined as independent coverages
  (``1 - prod(1 - a)``). The composite of fluorescence channels in napari (``blending=
  "additive"``) and Fiji ("Composite"): it does not depend on the order of the layers, and a
  pixel where two channels overlap shows the sum of their colours (red + green = yellow).
- :func:`window_ramp`: one projected channel (MIP values) through its window onto a
  black-to-colour ramp, the layer :func:`additive` sums.
- :func:`nearest_hit_over`: surfaces of several layers, each pixel showing the layer hit
  nearest to the camera (the others behind it, composited "over" in depth order where the
  nearest is not opaque: antialiased edges).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numba import prange

from .._jit import jit
from ..errors import ParameterError

__all__ = ["additive", "nearest_hit_over", "on_background", "window_ramp"]


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
