"""Writing one pixel's results into the Frame buffers (shared by every model's kernel)."""

from __future__ import annotations

import math

import numpy as np

from .._jit import jit
from .shading import shade_pixel

__all__ = ["store_hit", "store_miss"]


@jit(inline="always")
def store_miss(
    row: int, col: int, shading: np.ndarray, rgba: np.ndarray, depth: np.ndarray,
    position: np.ndarray, normal: np.ndarray, face: np.ndarray,
) -> None:
    """Background colour, ``inf`` depth, NaN position and normal, face 0.

    A buffer with no rows was not asked for (:mod:`.outputs`) and is left alone.
    """
    if depth.shape[0] != 0:
        depth[row, col] = math.inf
    if position.shape[0] != 0:
        for c in range(3):
            position[row, col, c] = math.nan
    if normal.shape[0] != 0:
        for c in range(3):
            normal[row, col, c] = math.nan
    if rgba.shape[0] != 0:
        for c in range(3):
            rgba[row, col, c] = shading[6 + c]
        rgba[row, col, 3] = shading[9]
    if face.shape[0] != 0:
        face[row, col] = 0


@jit(inline="always")
def store_hit(
    row: int, col: int, t: float, ray: tuple, gx: float, gy: float, gz: float,
    inside_high: bool, shading: np.ndarray, out: tuple, slope: float = math.nan,
) -> None:
    """Store a hit at parameter ``t`` of ``ray`` (a :class:`.rays.Ray`; its world origin and
    direction are read) with world-space shading gradient ``g`` into ``out``, the buffers
    ``(rgba, depth, position, normal, face)``.

    The stored normal is the unit *outward* normal: ``-g/|g|`` when the object is where values
    are high, ``+g/|g|`` when it is where they are low. A zero gradient gets a normal facing the
    viewer. A face is front-facing when the ray enters the object through it: where the field
    rises along the ray (``slope``, the model's own derivative along the unit ray at the hit)
    when the object is where values are high, where it falls otherwise; without a slope (NaN),
    where the normal faces the ray. Buffers with no rows were not asked for and are left alone.
    """
    wx, wy, wz = ray.world_x, ray.world_y, ray.world_z
    ux, uy, uz = ray.world_dx, ray.world_dy, ray.world_dz
    rgba, depth, position, normal, face = out
    if depth.shape[0] != 0:
        depth[row, col] = t
    if position.shape[0] != 0:
        position[row, col, 0] = wx + t * ux
        position[row, col, 1] = wy + t * uy
        position[row, col, 2] = wz + t * uz
    norm = math.sqrt(gx * gx + gy * gy + gz * gz)
    if norm > 0.0:
        scale = (-1.0 if inside_high else 1.0) / norm
        nx, ny, nz = gx * scale, gy * scale, gz * scale
    else:
        nx, ny, nz = -ux, -uy, -uz
    if normal.shape[0] != 0:
        normal[row, col, 0] = nx
        normal[row, col, 1] = ny
        normal[row, col, 2] = nz
    if slope == slope:
        front = slope >= 0.0 if inside_high else slope <= 0.0
    else:
        front = nx * ux + ny * uy + nz * uz <= 0.0
    if face.shape[0] != 0:
        face[row, col] = 1 if front else -1
    if rgba.shape[0] != 0:
        r, g, b = shade_pixel(shading, front, nx, ny, nz, ux, uy, uz)
        rgba[row, col, 0] = r
        rgba[row, col, 1] = g
        rgba[row, col, 2] = b
        rgba[row, col, 3] = 1.0
