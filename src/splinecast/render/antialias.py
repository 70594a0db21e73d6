"""Antialiasing: adaptive supersampling of the pixels on edges, with exact sub-pixel rays.

A frame is traced once through the pixel centres. The pixels on an edge of the image
(:func:`edge_mask`: where a side neighbour's ray misses while this one hits, or meets the
other face, or where the colour changes by more than :data:`CONTRAST` in a channel across a
bend of the normal of more than :data:`CREASE` degrees: silhouettes, occluding contours,
creases) are traced again, only they, with more rays inside the pixel, each an exact hit of
its own (:meth:`splinecast.Camera.shifted` cameras), and get the weighted mean of their
colours. Depth, position, normal and face stay those of the centre ray, so a frame's geometry
is the same with and without antialiasing. Changes of colour inside a smooth surface (its
shading, highlights) are left alone.

``samples`` is the number of rays an edge pixel's colour is made of, the centre one included:

* 5 (:data:`DEFAULT_SAMPLES`): the centre and the pixel's four corners, weighted 1/2 and 1/8
  (the quincunx pattern: a quadrature of the pixel's box exact for bilinear colours). A corner
  is shared by the four pixels around it and traced only where an edge passes between two of
  them (elsewhere the mean of their centres stands in), so an edge costs less than one new ray
  per pixel on it; rays along edges are the costly ones, though (they graze surfaces), and the
  default costs about 1.4 to 1.5 times a dense frame (the performance page).
* any other count ``n``: ``n`` rays spread evenly over the pixel (:func:`sample_offsets`),
  averaged (a box filter); ``n`` new rays per pixel on an edge.

Pixels on the border of a window of a larger image (:meth:`splinecast.Camera.tile`: the
viewer's stripes, distributed tiles) compare with their neighbours outside the window, and
share corners with them: those rays are traced too, so windows antialias the same pixels, with
the same colours, as the whole image. On the border of the whole image a missing corner takes
the centre's colour.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from typing import Any

import numpy as np

from .._jit import jit
from ..errors import ParameterError
from .modes import RenderMode, mode_class

__all__ = ["DEFAULT_SAMPLES", "MAX_SAMPLES", "CONTRAST", "CREASE", "check_samples",
           "resolve_samples", "sample_offsets", "edge_mask", "antialias"]

#: Rays per edge pixel of an isosurface frame by default (the centre and four shared corners).
DEFAULT_SAMPLES = 5
#: The most rays per pixel ``samples`` may ask for.
MAX_SAMPLES = 64
#: A colour channel (0..1) changing by more than this to a side neighbour's, across a crease
#: (:data:`CREASE`), marks an edge: about 20 levels of an 8-bit image.
CONTRAST = 0.08
#: Normals of side neighbours more than this many degrees apart make a crease or an occluding
#: contour (the smooth shading inside a surface turns far less from one pixel to the next).
CREASE = 30.0

#: Where a pixel's rays pass, by sample scheme: the quincunx's centre and corners.
_QUINCUNX = 5


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
    """Where in its pixel each of ``samples`` rays passes for the box filter (``samples`` other
    than :data:`DEFAULT_SAMPLES`): ``(samples, 2)`` offsets ``(dx, dy)`` in pixels, inside
    ``(-1/2, 1/2)``.

    A square count ``k * k`` is the regular ``k x k`` grid of sub-pixel centres; any other
    count ``n`` the centred rank-1 lattice ``((i + 1/2) / n, (i + 1/2) g / n mod 1)`` whose
    generator ``g`` spreads the points farthest apart: one point per column of ``n`` and well
    spread over the pixel.
    """
    n = check_samples(samples)
    k = math.isqrt(n)
    if k * k == n:
        centres = (np.arange(k) + 0.5) / k - 0.5
        dx, dy = np.meshgrid(centres, centres)
        return np.stack([dx.ravel(), dy.ravel()], axis=-1)
    i = np.arange(n) + 0.5
    best, best_g = -1.0, 1
    for g in range(1, n):
        pts = np.stack([i / n, (i * g / n) % 1.0], axis=-1)
        d = np.abs(pts[:, None, :] - pts[None, :, :])
        d = np.minimum(d, 1.0 - d)  # on the torus: the pattern repeats over the pixels
        dist = np.hypot(d[..., 0], d[..., 1]) + np.eye(n) * 2.0
        if dist.min() > best + 1e-12:
            best, best_g = float(dist.min()), g
    return np.stack([i / n, (i * best_g / n) % 1.0], axis=-1) - 0.5


@jit(inline="always")
def _differ(rgba, depth, normal, face, contrast, crease, r0, c0, r1, c1):
    """Whether side neighbours ``(r0, c0)`` and ``(r1, c1)`` lie across an edge."""
    if depth.shape[0] != 0 and (depth[r0, c0] == math.inf) != (depth[r1, c1] == math.inf):
        return True
    if face.shape[0] != 0 and face[r0, c0] != face[r1, c1]:
        return True
    changed = False
    for ch in range(4):
        if abs(np.float64(rgba[r0, c0, ch]) - np.float64(rgba[r1, c1, ch])) > contrast:
            changed = True
    if not changed or normal.shape[0] == 0:
        return changed
    cos = (np.float64(normal[r0, c0, 0]) * normal[r1, c1, 0]
           + np.float64(normal[r0, c0, 1]) * normal[r1, c1, 1]
           + np.float64(normal[r0, c0, 2]) * normal[r1, c1, 2])
    return not cos >= crease  # NaN normals (no hit) compare as a crease


# Without reference counting (``_nrt=False``, as the driver's band): the inlined comparison
# takes the arrays, and counting them at each of its calls took 200 ns a pixel.
# Serial: a light pass (a few loads a pixel, about 10 ms at 1024 x 768); a parallel one took
# twice as long on a loaded machine, waiting for its slowest thread.
@jit(_nrt=False)
def _edges(rgba, depth, normal, face, contrast, crease, right, down, out):
    """``right[r, c]``: pixels ``(r, c)`` and ``(r, c + 1)`` lie across an edge; ``down[r, c]``:
    ``(r, c)`` and ``(r + 1, c)`` do; ``out``: a pixel has an edge to a side neighbour."""
    height, width = out.shape
    for row in range(height):
        for col in range(width):
            across = col + 1 < width and _differ(rgba, depth, normal, face, contrast, crease,
                                                 row, col, row, col + 1)
            right[row, col] = across
            below = row + 1 < height and _differ(rgba, depth, normal, face, contrast, crease,
                                                 row, col, row + 1, col)
            down[row, col] = below
            out[row, col] = (across or below or (col > 0 and right[row, col - 1])
                             or (row > 0 and down[row - 1, col]))


def _or_empty(array: np.ndarray | None, ndim: int, dtype: Any) -> np.ndarray:
    if array is None:
        return np.zeros((0,) * ndim, dtype)
    return np.ascontiguousarray(array, dtype)


def edge_mask(rgba: np.ndarray, depth: np.ndarray | None = None,
              normal: np.ndarray | None = None, face: np.ndarray | None = None,
              contrast: float | None = None, crease: float | None = None) -> np.ndarray:
    """The pixels of a frame that lie on an edge of its image (module docstring).

    A pixel is on an edge when one of its four side neighbours differs from it: the one ray
    hits and the other misses (``depth``), they meet different faces (``face``), or a colour
    channel changes by more than ``contrast`` while the normals turn by more than ``crease``
    degrees (``normal``). Without normals every change of colour beyond ``contrast`` counts
    (MIP and DVR images).

    Parameters
    ----------
    rgba : ndarray (height, width, 4)
        The colours traced through the pixel centres.
    depth, normal, face : ndarray, optional
        The frame's depths (``inf``: no hit), unit normals and faces.
    contrast, crease : float, optional
        The thresholds (default :data:`CONTRAST`, :data:`CREASE` degrees).

    Returns
    -------
    ndarray of bool (height, width)
    """
    return _edge_pairs(rgba, depth, normal, face, contrast, crease)[0]


def _edge_pairs(rgba: np.ndarray, depth: np.ndarray | None, normal: np.ndarray | None,
                face: np.ndarray | None, contrast: float | None = None,
                crease: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`edge_mask`, and which pairs of side neighbours lie across an edge (``right``,
    ``down``: see :func:`_edges`)."""
    height, width = rgba.shape[:2]
    out = np.empty((height, width), np.bool_)
    right = np.empty((height, width), np.bool_)
    down = np.empty((height, width), np.bool_)
    limit = CONTRAST if contrast is None else float(contrast)
    angle = CREASE if crease is None else float(crease)
    _edges(np.ascontiguousarray(rgba, np.float32), _or_empty(depth, 2, np.float64),
           _or_empty(normal, 3, np.float32), _or_empty(face, 2, np.int8), limit,
           math.cos(math.radians(angle)), right, down, out)
    return out, right, down


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


def antialias(frame: Any, camera: Any, samples: int,
              trace: Callable[[Any, np.ndarray], Any], geometry: bool = True) -> int:
    """Antialias a frame's colours in place; returns the number of pixels on edges.

    Parameters
    ----------
    frame : Frame
        The frame traced through the pixel centres of ``camera``: its ``rgba`` is changed on
        the pixels of :func:`edge_mask`, found from its colours and, with ``geometry``, its
        ``depth``, ``normal`` and ``face`` (those that are not None).
    camera : Camera
        The frame's camera (a window of a larger image, :meth:`Camera.tile`, is compared with
        the pixels around it).
    samples : int
        Rays per edge pixel, the centre one included (module docstring; 1: nothing is done).
    trace : callable
        ``trace(camera, mask)`` traces the pixels of ``camera``'s image where ``mask`` is true
        and returns a Frame of them with the same buffers as ``frame`` (the other pixels'
        contents do not matter).
    geometry : bool
        Find edges from the geometry as well as the colours (isosurfaces).
    """
    if samples <= 1:
        return 0
    names = ("rgba", "depth", "normal", "face") if geometry else ("rgba",)
    height, width = frame.rgba.shape[:2]
    big, r0, c0 = _with_margin(camera)
    inner = (slice(r0, r0 + height), slice(c0, c0 + width))
    if big is camera:
        data = {name: getattr(frame, name) for name in names}
    else:
        # The pixels around the window, through their centres, for the comparison.
        ring = np.ones((big.height, big.width), np.bool_)
        ring[inner] = False
        around = trace(big, ring)
        data = {}
        for name in names:
            mine = getattr(frame, name)
            if mine is None or getattr(around, name) is None:
                data[name] = None
                continue
            data[name] = np.array(getattr(around, name), copy=True)
            data[name][inner] = mine
    mask, right, down = _edge_pairs(data["rgba"], data.get("depth"), data.get("normal"),
                                    data.get("face"))
    if big is not camera:
        keep = np.zeros_like(mask)
        keep[inner] = True
        mask &= keep
    count = int(np.count_nonzero(mask))
    if count == 0:
        return 0
    colours = data["rgba"]
    if samples == _QUINCUNX:
        _quincunx(colours, mask, right, down, big, trace)
    else:
        total = np.zeros((count, colours.shape[2]))
        for dx, dy in sample_offsets(samples):
            total += trace(big.shifted(float(dx), float(dy)), mask).rgba[mask]
        colours[mask] = (total / samples).astype(colours.dtype)
    if big is not camera:
        frame.rgba[...] = colours[inner]
    return count


def _quincunx(colours: np.ndarray, mask: np.ndarray, right: np.ndarray, down: np.ndarray,
              camera: Any, trace: Callable[[Any, np.ndarray], Any]) -> None:
    """Half the centre's colour and an eighth of each corner's, on the pixels of ``mask``.

    A corner is traced (once, for the four pixels around it) where an edge passes between two
    of those pixels; elsewhere its colour is the mean of their centres' (bilinear: no edge
    there), as past the image's last row and column, where no ray is traced. A corner is the
    top-left one of the pixel below and to the right of it: one pass of the camera shifted
    half a pixel up and to the left traces them all."""
    corners = np.empty_like(mask)
    _corners_to_trace(mask, right, down, corners)
    centres = colours.copy()
    at = trace(camera.shifted(-0.5, -0.5), corners).rgba if corners.any() else centres
    _blend_corners(centres, mask, corners, at, colours)


@jit(_nrt=False)
def _corners_to_trace(mask, right, down, out):
    """``out[r, c]``: the top-left corner of pixel ``(r, c)`` is a corner of a pixel of
    ``mask`` with an edge between two of the pixels around it."""
    h, w = mask.shape
    for r in range(h):
        for c in range(w):
            used = mask[r, c] or (r > 0 and mask[r - 1, c]) or (c > 0 and mask[r, c - 1]) or (
                r > 0 and c > 0 and mask[r - 1, c - 1])
            crossed = (r > 0 and c > 0 and (right[r - 1, c - 1] or down[r - 1, c - 1])) or (
                c > 0 and right[r, c - 1]) or (r > 0 and down[r - 1, c])
            out[r, c] = used and crossed


@jit(inline="always")
def _corner(colours, traced, at, r, c, ch):
    """The colour at the top-left corner of pixel ``(r, c)`` (``r``, ``c`` up to the image's
    size): traced, or the mean of the centres around it."""
    h, w = traced.shape
    if r < h and c < w and traced[r, c]:
        return np.float64(at[r, c, ch])
    total = 0.0
    n = 0
    for rr in range(max(r - 1, 0), min(r + 1, h)):
        for cc in range(max(c - 1, 0), min(c + 1, w)):
            total += np.float64(colours[rr, cc, ch])
            n += 1
    return total / n


@jit(_nrt=False)
def _blend_corners(centres, mask, traced, at, out):
    """``out`` on the pixels of ``mask``: half the centre's colour and an eighth of each
    corner's (``centres``: the colours through the centres, unchanged)."""
    h, w = mask.shape
    for row in range(h):
        for col in range(w):
            if not mask[row, col]:
                continue
            for ch in range(centres.shape[2]):
                corners = (_corner(centres, traced, at, row, col, ch)
                           + _corner(centres, traced, at, row, col + 1, ch)
                           + _corner(centres, traced, at, row + 1, col, ch)
                           + _corner(centres, traced, at, row + 1, col + 1, ch))
                out[row, col, ch] = 0.5 * np.float64(centres[row, col, ch]) + 0.125 * corners


def resolve_samples(samples: Any, mode: str | RenderMode | type[RenderMode]) -> int:
    """The sample count of a render: ``samples`` checked, or by default
    :data:`DEFAULT_SAMPLES` for a mode drawing surfaces (:attr:`RenderMode.surfaces`: the
    isosurfaces) and 1 (off) for the other modes; ``mode`` is a name of the registry, a mode
    object or its class."""
    if samples is None:
        kind = mode if isinstance(mode, type) else mode_class(mode)
        return DEFAULT_SAMPLES if kind.surfaces else 1
    return check_samples(samples)
