"""Antialiasing: adaptive supersampling of the pixels on edges, with exact sub-pixel rays.

A frame is traced once through the pixel centres. The pixels where its image has an edge
(:func:`edge_mask`: a colour channel differs from a side neighbour's by more than
:data:`CONTRAST`, or one of the two rays hits a surface and the other misses, or their depths
jump by more than :data:`DEPTH_JUMP` pixel widths) are traced again, only they, with
``samples - 1`` more rays spread over the pixel (:func:`sample_offsets`, through
:meth:`splinecast.Camera.shifted` cameras), each ray an exact hit of its own. The pixel's
colour is the mean of its ``samples`` colours (a box filter). Depth, position, normal and face
stay those of the centre ray, so a frame's geometry is the same with and without
antialiasing. Silhouettes, creases and the boundaries between front and back faces are
smoothed; smooth shading inside a surface is left alone.

Pixels on the border of a window of a larger image (:meth:`splinecast.Camera.tile`: the
viewer's stripes, distributed tiles) compare with their neighbours outside the window too:
those rays are traced (once, through their centres) for the comparison, so windows antialias
the same pixels as the whole image.

Cost: one extra ray per edge pixel and extra sample, plus a pass over the image for the edges;
with the default of :data:`DEFAULT_SAMPLES` samples an isosurface frame takes about 1.2 to 1.4
times as long (``docs/performance``).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numba import prange

from .._jit import jit
from ..errors import ParameterError

__all__ = ["DEFAULT_SAMPLES", "MAX_SAMPLES", "CONTRAST", "DEPTH_JUMP", "check_samples",
           "resolve_samples", "sample_offsets", "edge_mask", "antialias"]

#: Rays per edge pixel of an isosurface frame by default (the centre one included).
DEFAULT_SAMPLES = 5
#: The most rays per pixel ``samples`` may ask for.
MAX_SAMPLES = 64
#: A colour channel (0..1) differing by more than this from a side neighbour's marks an edge:
#: about 20 levels of an 8-bit image.
CONTRAST = 0.08
#: Depths of side neighbours differing by more than this many pixel widths (at the nearer
#: depth) mark an edge: an occluding contour over the same surface, a surface seen edge-on.
DEPTH_JUMP = 4.0


def check_samples(samples: Any) -> int:
    """Validate a sample count: an integer from 1 (no antialiasing) to :data:`MAX_SAMPLES`.

    Raises
    ------
    ParameterError
        For anything else.
    """
    if isinstance(samples, (bool, np.bool_)) or not isinstance(samples, (int, np.integer)) \
            or not 1 <= int(samples) <= MAX_SAMPLES:
        raise ParameterError(f"samples must be an integer from 1 (no antialiasing) to "
                             f"{MAX_SAMPLES}, got {samples!r}")
    return int(samples)


def sample_offsets(samples: int) -> np.ndarray:
    """Where in its pixel each of ``samples`` rays passes: ``(samples, 2)`` offsets ``(dx, dy)``
    in pixels, in ``[-1/2, 1/2)``, the first the centre ``(0, 0)``.

    The points are a rank-1 lattice, ``(i / n, i g / n)`` modulo 1, moved so that one point is
    the centre, with the generator ``g`` whose points lie farthest apart: well spread over the
    pixel for any ``n`` (5 gives the rotated grid of a centre and four points around it).
    """
    n = check_samples(samples)
    i = np.arange(n)
    best, best_g = -1.0, 1
    for g in range(1, max(n, 2)):
        pts = np.stack([i / n, (i * g % n) / n], axis=-1)
        d = np.abs(pts[1:] - pts[0]) if n > 1 else np.zeros((0, 2))
        d = np.minimum(d, 1.0 - d)  # toroidal: the lattice is a group, one point suffices
        spread = float(np.min(np.hypot(d[:, 0], d[:, 1]))) if n > 1 else 0.0
        if spread > best + 1e-12:
            best, best_g = spread, g
    pts = np.stack([i / n, (i * best_g % n) / n], axis=-1)
    return (pts + 0.5) % 1.0 - 0.5


@jit(parallel=True)
def _edges(rgba, depth, has_depth, contrast, jump, footprint, ortho, out):
    height, width = out.shape
    for row in prange(height):
        for col in range(width):
            edge = False
            for k in range(4):
                r = row + (1 if k == 0 else -1 if k == 1 else 0)
                c = col + (1 if k == 2 else -1 if k == 3 else 0)
                if r < 0 or r >= height or c < 0 or c >= width:
                    continue
                for ch in range(4):
                    if abs(np.float64(rgba[row, col, ch]) - np.float64(rgba[r, c, ch])) > contrast:
                        edge = True
                if has_depth:
                    a, b = depth[row, col], depth[r, c]
                    if (a == math.inf) != (b == math.inf):
                        edge = True
                    elif a < math.inf:
                        near = min(a, b)
                        pixel = footprint if ortho else footprint * max(near, 0.0)
                        if abs(a - b) > jump * pixel:
                            edge = True
                if edge:
                    break
            out[row, col] = edge


def edge_mask(rgba: np.ndarray, depth: np.ndarray | None, camera: Any,
              contrast: float = CONTRAST, jump: float = DEPTH_JUMP) -> np.ndarray:
    """The pixels of a frame that lie on an edge of its image (module docstring).

    Parameters
    ----------
    rgba : ndarray (height, width, 4)
        The colours traced through the pixel centres.
    depth : ndarray (height, width) or None
        Their depths (``inf``: no hit), or None to compare colours only.
    camera : Camera
        The camera of the frame (the width of a pixel at a depth).
    contrast, jump : float
        The thresholds (:data:`CONTRAST`, :data:`DEPTH_JUMP`).

    Returns
    -------
    ndarray of bool (height, width)
    """
    height, width = rgba.shape[:2]
    out = np.empty((height, width), np.bool_)
    basis = camera.pixel_basis()
    # The width of a pixel: world units (orthographic), or per unit of distance along the ray.
    footprint = 2.0 * float(basis[13]) / float(basis[19])
    d = np.zeros((0, 0)) if depth is None else np.ascontiguousarray(depth, np.float64)
    _edges(np.ascontiguousarray(rgba), d, depth is not None, float(contrast), float(jump),
           footprint, bool(camera.ortho), out)
    return out


def _with_margin(camera: Any) -> tuple[Any, int, int]:
    """The window of the full image one pixel larger on every side than ``camera``'s where the
    image goes on there, and where ``camera``'s pixels start in it (row, column)."""
    col0, row0, full_w, full_h = camera.region
    left, top = min(col0, 1), min(row0, 1)
    right = min(full_w - col0 - camera.width, 1)
    bottom = min(full_h - row0 - camera.height, 1)
    if left == top == right == bottom == 0:
        return camera, 0, 0
    full = copy.copy(camera)
    full.width, full.height = full_w, full_h
    full.region = (0, 0, full_w, full_h)
    big = full.tile(col0 - left, row0 - top, camera.width + left + right,
                    camera.height + top + bottom)
    return big, top, left


def antialias(rgba: np.ndarray, depth: np.ndarray | None, camera: Any, samples: int,
              trace: Callable[[Any, np.ndarray], tuple[np.ndarray, np.ndarray | None]],
              ) -> int:
    """Antialias a frame's colours in place; returns the number of pixels traced again.

    Parameters
    ----------
    rgba : ndarray (height, width, 4)
        The frame's colours, traced through the pixel centres of ``camera``; replaced by the
        mean over ``samples`` rays on the pixels of :func:`edge_mask`.
    depth : ndarray (height, width) or None
        The frame's depths (None: the edges are found from the colours alone).
    camera : Camera
        The frame's camera (a window of a larger image, :meth:`Camera.tile`, is compared with
        the pixels around it).
    samples : int
        Rays per edge pixel, the centre one included (1: nothing is done).
    trace : callable
        ``trace(camera, mask)`` traces the pixels of ``camera``'s image where ``mask`` is true
        and returns their colours and depths as ``(rgba, depth)`` full-image arrays (the other
        pixels' contents do not matter; ``depth`` may be None when ``depth`` is).
    """
    if samples <= 1:
        return 0
    height, width = rgba.shape[:2]
    big, r0, c0 = _with_margin(camera)
    if big is camera:
        colours, depths = rgba, depth
    else:
        ring = np.ones((big.height, big.width), np.bool_)
        ring[r0:r0 + height, c0:c0 + width] = False
        ring_rgba, ring_depth = trace(big, ring)
        colours = np.array(ring_rgba, dtype=rgba.dtype, copy=True)
        colours[r0:r0 + height, c0:c0 + width] = rgba
        depths = None
        if depth is not None and ring_depth is not None:
            depths = np.array(ring_depth, dtype=np.float64, copy=True)
            depths[r0:r0 + height, c0:c0 + width] = depth
    mask = edge_mask(colours, depths, big)
    if big is not camera:
        inner = np.zeros_like(mask)
        inner[r0:r0 + height, c0:c0 + width] = True
        mask &= inner
    count = int(np.count_nonzero(mask))
    if count == 0:
        return 0
    total = colours[mask].astype(np.float64)
    for dx, dy in sample_offsets(samples)[1:]:
        sub, _ = trace(big.shifted(float(dx), float(dy)), mask)
        total += sub[mask]
    colours[mask] = (total / samples).astype(colours.dtype)
    if big is not camera:
        rgba[...] = colours[r0:r0 + height, c0:c0 + width]
    return count


def resolve_samples(samples: Any, mode: str) -> int:
    """The sample count of a render: ``samples`` checked, or by default
    :data:`DEFAULT_SAMPLES` for isosurfaces and 1 (off) for the other modes."""
    if samples is None:
        return DEFAULT_SAMPLES if mode == "iso" else 1
    return check_samples(samples)
