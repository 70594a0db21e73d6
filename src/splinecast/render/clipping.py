"""Clip planes applied analytically to each ray's parameter interval.

A plane is four numbers ``(nx, ny, nz, d)`` in world coordinates; it keeps the half-space
``nx*x + ny*y + nz*z + d >= 0`` and removes the rest. Intersecting the ray with every kept
half-space gives one interval ``[t_min, t_max]`` per ray, which the traversal starts and ends at:
the surface behind a cut is seen through it, with no sampling artefacts at the cut. An
axis-aligned crop box is six such planes.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import jit

__all__ = ["clip_interval", "NO_PLANES"]

#: An empty plane list, shape (0, 4).
NO_PLANES = np.zeros((0, 4), dtype=np.float64)


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
