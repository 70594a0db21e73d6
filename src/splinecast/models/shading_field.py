"""The smooth field that shades the isosurfaces of the models that are only continuous.

The trilinear interpolant (and the linear B-spline, the same function) is continuous, but its
gradient jumps from cell to cell: shaded with it, an isosurface shows every voxel as a facet, a
fine hatching on real data. Shading instead uses the gradient of the *cubic B-spline of the
voxels* (the voxels taken as its coefficients, without prefilter), evaluated at the hit found
on the model's own surface: a C2 field, a low-pass of the data with positive weights, so the
shading is smooth and never rings. The hit positions stay those of the model. (On
Marschner–Lobb 256^3 its normals are within half a degree of the analytic gradient on average,
where the trilinear gradient's are 4 to 5 degrees off; an interpolating cubic, Catmull–Rom or a
prefiltered B-spline, does a little better there but rings on the noise of real scans, which
then shows as dark pits.)

The gradient at a point of cell ``c`` reads the voxels ``c - 1 .. c + 2`` per axis: one voxel
beyond the cell's support on each side. A kernel grid therefore carries a *halo*: an array that
holds the grid's voxels and, where there are any, the neighbouring voxels, with a box of nine
integers (:func:`halo_box`):

* ``box[0:3]``: the halo's index of the grid array's element ``(0, 0, 0)``;
* ``box[3:6]``, ``box[6:9]``: the first and the last halo index that holds real data (a
  multiresolution brick's ghost layers beyond the level's ends repeat the border and are not
  real).

Beyond the real data the voxels are continued linearly (``v[-1] = 2 v[0] - v[1]``), so the
shading field reproduces linear functions up to the volume's faces, and every kind of grid (the
whole volume, a brick with its ghost layers, a level of a pyramid) gives the same gradient at
the same point.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._jit import jit

__all__ = ["halo_box", "whole_halo", "cubic_weights", "halo_gradient", "shading_gradients",
           "SHADING_HALO"]

#: Voxels the shading field reads beyond a cell's support on each side.
SHADING_HALO = 1


def halo_box(offset: Any, first: Any, last: Any) -> np.ndarray:
    """The nine integers of a halo (module docstring): the halo index of the grid array's first
    element, and the first and last halo indices of real data, per axis."""
    box = np.empty(9, np.int64)
    box[0:3] = np.asarray(offset, np.int64)
    box[3:6] = np.asarray(first, np.int64)
    box[6:9] = np.asarray(last, np.int64)
    return box


def whole_halo(array: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The halo of a grid that is a whole volume: the array itself, all of it real."""
    return array, halo_box((0, 0, 0), (0, 0, 0), np.asarray(array.shape) - 1)


@jit(inline="always")
def cubic_weights(t: float) -> tuple:
    """Weights and derivative weights of the cubic B-spline's four coefficients acting at local
    coordinate ``t`` in ``[0, 1]`` of a cell (coefficients ``c - 1 .. c + 2``)."""
    s = 1.0 - t
    t2 = t * t
    w = (s * s * s / 6.0, (3.0 * t2 * t - 6.0 * t2 + 4.0) / 6.0,
         (-3.0 * t2 * t + 3.0 * t2 + 3.0 * t + 1.0) / 6.0, t2 * t / 6.0)
    d = (-0.5 * s * s, 1.5 * t2 - 2.0 * t, -1.5 * t2 + t + 0.5, 0.5 * t2)
    return w, d


@jit(inline="always")
def _axis(p: float, offset: int, first: int, last: int) -> tuple:
    """One axis of the stencil at grid coordinate ``p``: the halo indices of the four
    coefficients (clamped to the real data), their weights and derivative weights, the ones
    beyond the real data folded into the two inside (linear continuation)."""
    c = int(np.floor(p))
    h = c + offset
    # The point lies in a cell of real data: ``h`` and ``h + 1`` are real (clamped for safety).
    if h < first:
        h = first
    elif h > last - 1:
        h = last - 1
    t = p - (h - offset)
    w, d = cubic_weights(t)
    w0, w1, w2, w3 = w
    d0, d1, d2, d3 = d
    i0, i3 = h - 1, h + 2
    if i0 < first:  # v[h - 1] = 2 v[h] - v[h + 1]
        w1 += 2.0 * w0
        w2 -= w0
        d1 += 2.0 * d0
        d2 -= d0
        w0 = 0.0
        d0 = 0.0
        i0 = h
    if i3 > last:  # v[h + 2] = 2 v[h + 1] - v[h]
        w2 += 2.0 * w3
        w1 -= w3
        d2 += 2.0 * d3
        d1 -= d3
        w3 = 0.0
        d3 = 0.0
        i3 = h + 1
    return (i0, h, h + 1, i3), (w0, w1, w2, w3), (d0, d1, d2, d3)


@jit(inline="always")
def halo_gradient(halo: np.ndarray, box: np.ndarray, x: float, y: float,
                  z: float) -> tuple[float, float, float]:
    """Gradient of the cubic B-spline of the voxels at grid coordinates ``(x, y, z)`` (the
    grid array's index space), per unit of that space."""
    ix, wx, dx = _axis(x, box[0], box[3], box[6])
    iy, wy, dy = _axis(y, box[1], box[4], box[7])
    iz, wz, dz = _axis(z, box[2], box[5], box[8])
    gx = 0.0
    gy = 0.0
    gz = 0.0
    for a in range(4):
        ua = np.uint64(ix[a])
        # Contractions along z, then y, then x: 64 reads, about 130 multiply-adds.
        row_w = 0.0  # sum_b wy sum_c wz v
        row_dy = 0.0  # sum_b dy sum_c wz v
        row_dz = 0.0  # sum_b wy sum_c dz v
        for b in range(4):
            ub = np.uint64(iy[b])
            sw = 0.0
            sd = 0.0
            for c in range(4):
                v = np.float64(halo[ua, ub, np.uint64(iz[c])])
                sw += wz[c] * v
                sd += dz[c] * v
            row_w += wy[b] * sw
            row_dy += dy[b] * sw
            row_dz += wy[b] * sd
        gx += dx[a] * row_w
        gy += wx[a] * row_dy
        gz += wx[a] * row_dz
    return gx, gy, gz


@jit()
def _gradients(halo: np.ndarray, box: np.ndarray, points: np.ndarray, out: np.ndarray) -> None:
    for m in range(points.shape[0]):
        out[m, 0], out[m, 1], out[m, 2] = halo_gradient(halo, box, points[m, 0], points[m, 1],
                                                        points[m, 2])


def shading_gradients(data: np.ndarray, points: np.ndarray) -> np.ndarray:
    """The shading field's gradient at voxel-index points of a whole volume's ``data``, shape
    (..., 3) -> (..., 3), per unit of index (divide by the spacing for world units); points
    are clamped into the volume's box."""
    arr = np.ascontiguousarray(data)
    pts = np.asarray(points, np.float64)
    lead = pts.shape[:-1]
    flat = np.ascontiguousarray(pts.reshape(-1, 3))
    flat = np.clip(flat, 0.0, np.asarray(arr.shape, np.float64) - 1.0)
    halo, box = whole_halo(arr)
    out = np.empty((flat.shape[0], 3))
    _gradients(halo, box, flat, out)
    return out.reshape(*lead, 3)
