"""Per-pixel ray generation inside compiled kernels (same formula as :meth:`Camera.rays`).

Generating rays where they are used saves writing and reading two (height, width, 3) arrays per
frame, about a tenth of a frame's budget at 1024x768. ``tests/test_camera.py`` checks that both
paths give the same rays.

A ray's set-up divides once per quantity and multiplies after: the direction by the reciprocal
of its length, coordinates by the reciprocal of the spacing, slab bounds by the reciprocal of
the direction (up to fifteen divisions per pixel otherwise, a large share of a trilinear
isosurface frame on a small volume).
The results differ from the divisions' by rounding only. The cell walk keeps dividing
(:mod:`splinecast.accel.traversal` says why).
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from .._jit import jit
from .clipping import clip_interval

#: Below this, a direction component's reciprocal could overflow: the slab test divides.
_TINY = 1e-300

__all__ = ["Ray", "pixel_ray", "index_axis", "grid_ray", "grid_point", "slab"]

Ray = namedtuple("Ray", (
    "world_x", "world_y", "world_z", "world_dx", "world_dy", "world_dz",
    "index_x", "index_y", "index_z", "index_dx", "index_dy", "index_dz",
    "spacing_x", "spacing_y", "spacing_z", "anchor",
))
Ray.__doc__ = """The ray the driver hands a mode's hooks (:mod:`.mode_api`), for one pixel and grid.

Sixteen floats. Numba types it as a tuple of one type, the machine layout of a plain tuple, so
the names cost nothing per ray; compiled code builds one by calling the class.

Attributes
----------
world_x, world_y, world_z : float
    World origin of the ray (the camera's eye, or the pixel's point for a parallel camera).
world_dx, world_dy, world_dz : float
    Unit world direction: the ray parameter ``t`` is the world distance from the origin.
index_x, index_y, index_z : float
    The origin in the grid's traversal space (voxel index of the grid's level plus the model's
    shift, minus the grid's offset): the point at ``t`` is ``index + t * index_d``.
index_dx, index_dy, index_dz : float
    The direction in that space: the world direction divided by the spacing.
spacing_x, spacing_y, spacing_z : float
    The voxel spacing of the grid's level: an index-space gradient divided by it is in world
    units.
anchor : float
    The parameter where the ray enters the rendered domain, the same for every grid: the
    sampled methods and DVR start their samples there, so every brick samples at the same
    places.
"""


@jit(inline="always")
def pixel_ray(basis: np.ndarray, row: int, col: int, width: int, height: int) -> tuple:
    """World origin and unit direction ``(wx, wy, wz, ux, uy, uz)`` of pixel ``(row, col)``.

    ``width`` and ``height`` (the output's size) are not needed: the basis carries the full
    image's size and the tile's offset (:meth:`Camera.pixel_basis`).
    """
    # Offsets and full size from the basis: a tile camera's pixels are those of the full image;
    # a shifted camera's rays pass off their pixels' centres (adding a zero shift is exact).
    sx = ((col + basis[16] + 0.5 + basis[20]) / basis[18] * 2.0 - 1.0) * basis[12]
    sy = (1.0 - (row + basis[17] + 0.5 + basis[21]) / basis[19] * 2.0) * basis[13]
    if basis[14] != 0.0:
        wx = basis[0] + sx * basis[6] + sy * basis[9]
        wy = basis[1] + sx * basis[7] + sy * basis[10]
        wz = basis[2] + sx * basis[8] + sy * basis[11]
        return wx, wy, wz, basis[3], basis[4], basis[5]
    dx = basis[3] + sx * basis[6] + sy * basis[9]
    dy = basis[4] + sx * basis[7] + sy * basis[10]
    dz = basis[5] + sx * basis[8] + sy * basis[11]
    inv = 1.0 / math.sqrt(dx * dx + dy * dy + dz * dz)
    return basis[0], basis[1], basis[2], dx * inv, dy * inv, dz * inv


@jit(inline="always")
def slab(o: float, d: float, lo: float, hi: float, t0: float, t1: float) -> tuple:
    """``[t0, t1]`` cut to where ``o + t d`` lies in ``[lo, hi]`` (empty: ``t0 > t1``)."""
    if d == 0.0:
        if o < lo or o > hi:
            return math.inf, -math.inf
        return t0, t1
    if abs(d) < _TINY:  # 1 / d would overflow
        ta = (lo - o) / d
        tb = (hi - o) / d
    else:
        inv = 1.0 / d
        ta = (lo - o) * inv
        tb = (hi - o) * inv
    if ta > tb:
        ta, tb = tb, ta
    return max(t0, ta), min(t1, tb)


@jit(inline="always")
def index_axis(w: float, u: float, origin: float, spacing: float) -> tuple:
    """One axis of the world ray ``w + t u`` in an index space (index 0 at ``origin``, index
    spacing ``spacing``): ``(v, d)``, the index being ``v + t d``. Every kernel that needs a
    ray's index coordinates computes them with this, so they agree to the last bit."""
    inv = 1.0 / spacing
    return (w - origin) * inv, u * inv


@jit(inline="always")
def grid_ray(basis, geom, planes, t_range, row, col, width, height, ncx, ncy, ncz):
    """Pixel ``(row, col)``'s ray set up for one grid of the driver (:mod:`.driver`'s ``geom``).

    Returns ``(t0, t1, ray)``: the interval of the ray kept by the clip ``planes``, the rendered
    domain and the pixel's ``t_range`` (when not empty), empty (``t0 > t1``) when nothing is
    left, and the mode API's :class:`Ray`, whose ``anchor`` (where the sample grids start) is
    where the ray enters the domain: the same for every grid.
    """
    wx, wy, wz, ux, uy, uz = pixel_ray(basis, row, col, width, height)
    sx, sy, sz = geom[3], geom[4], geom[5]
    vx, dx = index_axis(wx, ux, geom[0], sx)
    vy, dy = index_axis(wy, uy, geom[1], sy)
    vz, dz = index_axis(wz, uz, geom[2], sz)
    t0, t1 = clip_interval(planes, wx, wy, wz, ux, uy, uz)
    t0, t1 = slab(vx, dx, geom[10], geom[13], t0, t1)
    t0, t1 = slab(vy, dy, geom[11], geom[14], t0, t1)
    t0, t1 = slab(vz, dz, geom[12], geom[15], t0, t1)
    anchor = t0  # where the ray enters the rendered domain: the same for every grid
    if t_range.shape[0] > 0:
        t0 = max(t0, t_range[row, col, 0])
        t1 = min(t1, t_range[row, col, 1])
    ox = vx + geom[6] - geom[7]
    oy = vy + geom[6] - geom[8]
    oz = vz + geom[6] - geom[9]
    # A ray lying in the plane between this grid and the next one belongs to the next one (the
    # traversal's rule for cell faces), so bricks never trace the same stretch twice.
    if ((dx == 0.0 and ox == ncx and geom[7] + ncx < geom[16])
            or (dy == 0.0 and oy == ncy and geom[8] + ncy < geom[17])
            or (dz == 0.0 and oz == ncz and geom[9] + ncz < geom[18])):
        t1 = -math.inf
    return t0, t1, Ray(wx, wy, wz, ux, uy, uz, ox, oy, oz, dx, dy, dz, sx, sy, sz, anchor)


@jit(inline="always")
def grid_point(geom: np.ndarray, basis: np.ndarray, row: int, col: int, width: int, height: int,
               t: float) -> tuple[float, float, float]:
    """The point at parameter ``t`` of pixel ``(row, col)``'s ray, in the traversal space of the
    grid placed by ``geom``, computed as :func:`grid_ray` and the walk compute it."""
    wx, wy, wz, ux, uy, uz = pixel_ray(basis, row, col, width, height)
    vx, dx = index_axis(wx, ux, geom[0], geom[3])
    vy, dy = index_axis(wy, uy, geom[1], geom[4])
    vz, dz = index_axis(wz, uz, geom[2], geom[5])
    return (vx + geom[6] - geom[7] + t * dx, vy + geom[6] - geom[8] + t * dy,
            vz + geom[6] - geom[9] + t * dz)
