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
from ..camera import (
    BASIS_COL0,
    BASIS_EYE,
    BASIS_FORWARD,
    BASIS_FULL_HEIGHT,
    BASIS_FULL_WIDTH,
    BASIS_HALF_HEIGHT,
    BASIS_HALF_WIDTH,
    BASIS_ORTHO,
    BASIS_RIGHT,
    BASIS_ROW0,
    BASIS_SUBPIXEL,
    BASIS_UP,
)
from .clipping import clip_interval

#: Below this, a direction component's reciprocal could overflow: the slab test divides.
_TINY = 1e-300

__all__ = ["Ray", "RayPiece", "Stretch", "pixel_ray", "index_axis", "grid_ray", "grid_point",
           "slab", "GEOM_ORIGIN", "GEOM_SPACING", "GEOM_SHIFT", "GEOM_OFFSET", "GEOM_LO", "GEOM_HI",
           "GEOM_CELLS", "GEOM_SIZE"]

# Where each quantity lies in the driver's ``geom`` array, which places a grid in the volume
# (:mod:`.driver` describes it): the vectors are x, y, z from their offset on.
GEOM_ORIGIN = 0  #: world position of voxel (0, 0, 0) of the grid's level (3)
GEOM_SPACING = 3  #: the level's voxel spacing (3)
GEOM_SHIFT = 6  #: the model's shift: the traversal walks cells in ``voxel index + shift``
GEOM_OFFSET = 7  #: the grid's index offset: its cell 0 is cell ``offset`` of the level (3)
GEOM_LO = 10  #: low corner of the rendered domain, in the level's voxel index space (3)
GEOM_HI = 13  #: high corner of the rendered domain (3)
GEOM_CELLS = 16  #: the level's cells per axis (3)
GEOM_SIZE = 19  #: length of the array

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


RayPiece = namedtuple("RayPiece", (
    "ctx", "i", "j", "k", "tag", "poly", "lo", "hi", "t0", "t1",
    "ax", "ay", "az", "bx", "by", "bz",
))
RayPiece.__doc__ = """One piece of a ray in one cell, as a model yields it and a mode consumes it
(:mod:`.mode_api`'s ``consume``).

Attributes
----------
ctx : tuple
    The model's context of the cell (``cell_load``; ``ctx[0], ctx[1]`` its value range).
i, j, k : int
    The cell, in the grid's traversal space.
tag : int
    Which piece of the cell (the model's ``cell_pieces``: a tetrahedron of a type-6 spline).
poly : tuple
    The model's reconstruction along the piece, a polynomial in ``s in [0, 1]``
    (``piece_poly``).
lo, hi : float
    A conservative range of the piece's values (``piece_range``).
t0, t1 : float
    The ray parameters of the piece's ends.
ax, ay, az : float
    Where the ray enters the piece, in the cell's local coordinates (``s = 0``).
bx, by, bz : float
    Where it leaves the piece (``s = 1``).
"""


Stretch = namedtuple("Stretch", ("ta", "tb", "va", "vb", "length", "x", "y", "z"))
Stretch.__doc__ = """The stretch of a ray between two samples of the fixed-step loop (or a sample
and an end of the grid's interval), as a sampled mode's ``segment`` takes it (:mod:`.mode_api`).

Attributes
----------
ta, tb : float
    The ray parameters of its ends.
va, vb : float
    The model's values there.
length : float
    Its length in voxels.
x, y, z : float
    The point at ``tb`` in the grid's traversal space (for a gradient).
"""


@jit(inline="always")
def pixel_ray(basis: np.ndarray, row: int, col: int, width: int, height: int) -> tuple:
    """World origin and unit direction ``(wx, wy, wz, ux, uy, uz)`` of pixel ``(row, col)``.

    ``width`` and ``height`` (the output's size) are not needed: the basis carries the full
    image's size and the tile's offset (:meth:`Camera.pixel_basis`).
    """
    # Offsets and full size from the basis: a tile camera's pixels are those of the full image;
    # a shifted camera's rays pass off their pixels' centres (adding a zero shift is exact).
    x = col + basis[BASIS_COL0] + 0.5 + basis[BASIS_SUBPIXEL]
    y = row + basis[BASIS_ROW0] + 0.5 + basis[BASIS_SUBPIXEL + 1]
    sx = (x / basis[BASIS_FULL_WIDTH] * 2.0 - 1.0) * basis[BASIS_HALF_WIDTH]
    sy = (1.0 - y / basis[BASIS_FULL_HEIGHT] * 2.0) * basis[BASIS_HALF_HEIGHT]
    e, f, r, u = BASIS_EYE, BASIS_FORWARD, BASIS_RIGHT, BASIS_UP
    if basis[BASIS_ORTHO] != 0.0:
        wx = basis[e] + sx * basis[r] + sy * basis[u]
        wy = basis[e + 1] + sx * basis[r + 1] + sy * basis[u + 1]
        wz = basis[e + 2] + sx * basis[r + 2] + sy * basis[u + 2]
        return wx, wy, wz, basis[f], basis[f + 1], basis[f + 2]
    dx = basis[f] + sx * basis[r] + sy * basis[u]
    dy = basis[f + 1] + sx * basis[r + 1] + sy * basis[u + 1]
    dz = basis[f + 2] + sx * basis[r + 2] + sy * basis[u + 2]
    inv = 1.0 / math.sqrt(dx * dx + dy * dy + dz * dz)
    return basis[e], basis[e + 1], basis[e + 2], dx * inv, dy * inv, dz * inv


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
    sx, sy, sz = geom[GEOM_SPACING], geom[GEOM_SPACING + 1], geom[GEOM_SPACING + 2]
    vx, dx = index_axis(wx, ux, geom[GEOM_ORIGIN], sx)
    vy, dy = index_axis(wy, uy, geom[GEOM_ORIGIN + 1], sy)
    vz, dz = index_axis(wz, uz, geom[GEOM_ORIGIN + 2], sz)
    t0, t1 = clip_interval(planes, wx, wy, wz, ux, uy, uz)
    t0, t1 = slab(vx, dx, geom[GEOM_LO], geom[GEOM_HI], t0, t1)
    t0, t1 = slab(vy, dy, geom[GEOM_LO + 1], geom[GEOM_HI + 1], t0, t1)
    t0, t1 = slab(vz, dz, geom[GEOM_LO + 2], geom[GEOM_HI + 2], t0, t1)
    anchor = t0  # where the ray enters the rendered domain: the same for every grid
    if t_range.shape[0] > 0:
        t0 = max(t0, t_range[row, col, 0])
        t1 = min(t1, t_range[row, col, 1])
    ox = vx + geom[GEOM_SHIFT] - geom[GEOM_OFFSET]
    oy = vy + geom[GEOM_SHIFT] - geom[GEOM_OFFSET + 1]
    oz = vz + geom[GEOM_SHIFT] - geom[GEOM_OFFSET + 2]
    # A ray lying in the plane between this grid and the next one belongs to the next one (the
    # traversal's rule for cell faces), so bricks never trace the same stretch twice.
    off, cells = GEOM_OFFSET, GEOM_CELLS
    if ((dx == 0.0 and ox == ncx and geom[off] + ncx < geom[cells])
            or (dy == 0.0 and oy == ncy and geom[off + 1] + ncy < geom[cells + 1])
            or (dz == 0.0 and oz == ncz and geom[off + 2] + ncz < geom[cells + 2])):
        t1 = -math.inf
    return t0, t1, Ray(wx, wy, wz, ux, uy, uz, ox, oy, oz, dx, dy, dz, sx, sy, sz, anchor)


@jit(inline="always")
def grid_point(geom: np.ndarray, basis: np.ndarray, row: int, col: int, width: int, height: int,
               t: float) -> tuple[float, float, float]:
    """The point at parameter ``t`` of pixel ``(row, col)``'s ray, in the traversal space of the
    grid placed by ``geom``, computed as :func:`grid_ray` and the walk compute it."""
    wx, wy, wz, ux, uy, uz = pixel_ray(basis, row, col, width, height)
    vx, dx = index_axis(wx, ux, geom[GEOM_ORIGIN], geom[GEOM_SPACING])
    vy, dy = index_axis(wy, uy, geom[GEOM_ORIGIN + 1], geom[GEOM_SPACING + 1])
    vz, dz = index_axis(wz, uz, geom[GEOM_ORIGIN + 2], geom[GEOM_SPACING + 2])
    shift, off = geom[GEOM_SHIFT], GEOM_OFFSET
    return (vx + shift - geom[off] + t * dx, vy + shift - geom[off + 1] + t * dy,
            vz + shift - geom[off + 2] + t * dz)
