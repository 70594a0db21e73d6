"""The floor of a frame: per pixel, generate its ray, clip it to the volume's box, write a colour.

No traversal, no reconstruction: what is left is the cost every mode pays whatever it does with
the ray (the ray, the box clip, one float32 RGBA write and the thread scheduling). It is
compiled with splinecast's own options (:func:`splinecast._jit.jit`) and cuts the image into the
same row bands, handed out in the same order, as the renderer's driver, so the difference
between a mode's frame time and this one is the time the mode spends on its actual work.

Import it as the top-level module ``floor_kernel`` (``benchmarks/`` on ``sys.path``), as every
benchmark and test does: Numba's on-disk cache records the name of the module a kernel was
compiled in, and a cached kernel loaded under another name (``benchmarks.floor_kernel``) fails.
"""

from __future__ import annotations

import math

import numpy as np
from numba import prange

from splinecast._jit import jit
from splinecast.render.driver import band_order

# The driver's own ray and slab clip, so the floor clips each ray exactly as a render does.
from splinecast.render.rays import pixel_ray, slab

__all__ = ["floor_frame", "floor_render"]


@jit(parallel=True)
def floor_frame(basis: np.ndarray, box: np.ndarray, colour: np.ndarray, bands: np.ndarray,
                rgba: np.ndarray) -> None:
    """Write ``colour[0]`` where a pixel's ray crosses the world box ``box`` (lo xyz, hi xyz),
    ``colour[1]`` where it misses; one band of rows per work item, in the order ``bands``."""
    height, width = rgba.shape[0], rgba.shape[1]
    for b in prange(bands.shape[0]):
        row = bands[b]
        for col in range(width):
            wx, wy, wz, ux, uy, uz = pixel_ray(basis, row, col, width, height)
            t0, t1 = slab(wx, ux, box[0], box[3], 0.0, math.inf)
            t0, t1 = slab(wy, uy, box[1], box[4], t0, t1)
            t0, t1 = slab(wz, uz, box[2], box[5], t0, t1)
            c = 0 if t0 <= t1 else 1
            for k in range(4):
                rgba[row, col, k] = colour[c, k]


def floor_render(camera, bounds: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """The floor frame of ``camera`` for a volume whose world box is ``bounds`` (lo, hi)."""
    rgba = np.empty((camera.height, camera.width, 4), np.float32)
    box = np.concatenate([np.asarray(bounds[0], float), np.asarray(bounds[1], float)])
    colour = np.array([[1.0, 1.0, 1.0, 1.0], [0.0, 0.0, 0.0, 1.0]])
    floor_frame(camera.pixel_basis(), box, colour, band_order(camera.height), rgba)
    return rgba
