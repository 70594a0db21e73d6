"""Clip planes applied analytically to each ray's parameter interval.

A plane is four numbers ``(nx, ny, nz, d)`` in world coordinates; it keeps the half-space
``nx*x + ny*y + nz*z + d >= 0`` and removes the rest. Intersecting the ray with every kept
half-space gives one interval ``[t_min, t_max]`` per ray, which the traversal starts and ends at:
the surface behind a cut is seen through it, with no sampling artefacts at the cut. An
axis-aligned crop box is six such planes.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .._jit import jit
from ..errors import ParameterError

__all__ = ["clip_interval", "box_slab", "NO_PLANES", "make_planes"]

#: An empty plane list, shape (0, 4).
NO_PLANES = np.zeros((0, 4), dtype=np.float64)


@jit(inline="always")
def box_slab(v: float, d: float, lo: float, hi: float, closed: bool, t0: float,
             t1: float) -> tuple[float, float]:
    """``[t0, t1]`` clipped to the slab ``lo <= v + t d <= hi`` of one axis of a box.

    A ray lying in a face plane (``d == 0``) belongs to the box above it, as the traversal gives
    a cell's faces to the next cell; the last box of the volume (``closed``) keeps its far face.
    An empty result is ``(inf, -inf)``.
    """
    if d == 0.0:
        if v < lo or v > hi or (v == hi and not closed):
            return math.inf, -math.inf
        return t0, t1
    ta = (lo - v) / d
    tb = (hi - v) / d
    if ta > tb:
        ta, tb = tb, ta
    return max(t0, ta), min(t1, tb)


@jit(inline="always")
def clip_interval(
    planes: np.ndarray, wx: float, wy: float, wz: float, ux: float, uy: float, uz: float,
) -> tuple[float, float]:
    """Interval ``[t_min, t_max]`` of ``w + t u`` (``t >= 0``) kept by all ``planes``."""
    t_min = 0.0
    t_max = math.inf
    for p in range(planes.shape[0]):
        a, b, c, d = planes[p, 0], planes[p, 1], planes[p, 2], planes[p, 3]
        at_origin = a * wx + b * wy + c * wz + d
        rate = a * ux + b * uy + c * uz
        if rate == 0.0:
            if at_origin < 0.0:
                return math.inf, -math.inf
            continue
        t_cross = -at_origin / rate
        if rate > 0.0:
            t_min = max(t_min, t_cross)
        else:
            t_max = min(t_max, t_cross)
    return t_min, t_max


def make_planes(clip: Any = None, crop: Any = None) -> np.ndarray:
    """Validated planes, shape (m, 4), from clip planes and an axis-aligned crop box.

    Parameters
    ----------
    clip : sequence of (nx, ny, nz, d), optional
        Planes in world coordinates; each keeps ``nx*x + ny*y + nz*z + d >= 0``.
    crop : (x0, x1, y0, y1, z0, z1), optional
        World-space box to keep; it becomes six planes.

    Raises
    ------
    ParameterError
        A plane is not four finite numbers or has a zero normal; the crop box is not six finite
        numbers with ``x0 < x1``, ``y0 < y1``, ``z0 < z1``.
    """
    rows: list[list[float]] = []
    if clip is not None:
        try:
            arr = np.asarray(clip, dtype=np.float64)
        except (TypeError, ValueError):
            raise ParameterError(f"clip must be a list of (nx, ny, nz, d), got {clip!r}") from None
        if arr.ndim == 1 and arr.size == 4:
            arr = arr.reshape(1, 4)
        if arr.size and (arr.ndim != 2 or arr.shape[1] != 4):
            raise ParameterError(f"clip must be a list of (nx, ny, nz, d), got {clip!r}")
        for plane in arr.reshape(-1, 4):
            if not np.all(np.isfinite(plane)) or not np.any(plane[:3] != 0):
                raise ParameterError(
                    f"clip plane {tuple(plane.tolist())} needs finite numbers and a non-zero normal"
                )
            rows.append(plane.tolist())
    if crop is not None:
        try:
            box = np.asarray(crop, dtype=np.float64).reshape(6)
        except (TypeError, ValueError):
            raise ParameterError(f"crop must be (x0, x1, y0, y1, z0, z1), got {crop!r}") from None
        if not np.all(np.isfinite(box)) or np.any(box[1::2] <= box[0::2]):
            raise ParameterError(
                f"crop must be six finite numbers with x0 < x1, y0 < y1, z0 < z1, got {crop!r}"
            )
        for axis in range(3):
            lo, hi = box[2 * axis], box[2 * axis + 1]
            normal = [0.0, 0.0, 0.0]
            normal[axis] = 1.0
            rows.append([*normal, -lo])         # x_axis - lo >= 0
            normal[axis] = -1.0
            rows.append([*normal, hi])          # hi - x_axis >= 0
    if not rows:
        return NO_PLANES
    return np.ascontiguousarray(np.array(rows, dtype=np.float64))
