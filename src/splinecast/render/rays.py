"""Per-pixel ray generation inside compiled kernels (same formula as :meth:`Camera.rays`).

Generating rays where they are used saves writing and reading two (height, width, 3) arrays per
frame, about a tenth of a frame's budget at 1024x768. ``tests/test_camera.py`` checks that both
paths give the same rays.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import jit

__all__ = ["pixel_ray"]


@jit(inline="always")
def pixel_ray(basis: np.ndarray, row: int, col: int, width: int, height: int) -> tuple:
    """World origin and unit direction ``(wx, wy, wz, ux, uy, uz)`` of pixel ``(row, col)``.

    ``width`` and ``height`` (the output's size) are not needed: the basis carries the full
    image's size and the tile's offset (:meth:`Camera.pixel_basis`).
    """
    # Offsets and full size from the basis: a tile camera's pixels are those of the full image.
    sx = ((col + basis[16] + 0.5) / basis[18] * 2.0 - 1.0) * basis[12]
    sy = (1.0 - (row + basis[17] + 0.5) / basis[19] * 2.0) * basis[13]
    if basis[14] != 0.0:
        wx = basis[0] + sx * basis[6] + sy * basis[9]
        wy = basis[1] + sx * basis[7] + sy * basis[10]
        wz = basis[2] + sx * basis[8] + sy * basis[11]
        return wx, wy, wz, basis[3], basis[4], basis[5]
    dx = basis[3] + sx * basis[6] + sy * basis[9]
    dy = basis[4] + sx * basis[7] + sy * basis[10]
    dz = basis[5] + sx * basis[8] + sy * basis[11]
    norm = math.sqrt(dx * dx + dy * dy + dz * dz)
    return basis[0], basis[1], basis[2], dx / norm, dy / norm, dz / norm
