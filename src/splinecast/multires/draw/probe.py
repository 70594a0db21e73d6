"""Compiled helpers that look at rays and grids from outside the render driver.

- :func:`box_ranges`: each ray's parameter interval inside an axis-aligned box (the part of the
  ray a brick of a cut owns), clipped by the clip planes;
- :func:`sample_grid`: a kernel grid's reconstruction at points (seams, tests);
- :func:`grid_values_at`: the reconstruction at one parameter per ray (the isosurface's seam
  closure, :class:`.draw.seams.IsoClosure`).

They use the models' own compiled hooks (:func:`splinecast.models.pieces.value_gradient_at`) and
the driver's ray formula (:func:`splinecast.render.rays.pixel_ray`), so the values and ray
parameters are those the renderer sees.
"""

from __future__ import annotations

import numpy as np
from numba import prange

from ..._jit import jit
from ...models.pieces import new_scratch, value_gradient_at
from ...render.cut_driver import box_interval
from ...render.rays import GEOM_SPACING, grid_point

__all__ = ["box_ranges", "sample_grid", "grid_values_at"]


@jit(inline="always")
def _box_row(basis, origin, spacing, lo, hi, closed, planes, out, row) -> int:
    height, width = out.shape[0], out.shape[1]
    met = 0
    for col in range(width):
        t0, t1 = box_interval(basis, origin, spacing, lo, hi, closed, planes, row, col, width,
                              height)
        out[row, col, 0] = t0
        out[row, col, 1] = t1
        if t0 <= t1:
            met += 1
    return met


@jit()
def _box_ranges_serial(basis, origin, spacing, lo, hi, closed, planes, out) -> int:
    met = 0
    for row in range(out.shape[0]):
        met += _box_row(basis, origin, spacing, lo, hi, closed, planes, out, row)
    return met


@jit(parallel=True)
def _box_ranges_parallel(basis, origin, spacing, lo, hi, closed, planes, out) -> int:
    met = np.zeros(out.shape[0], np.int64)
    for row in prange(out.shape[0]):
        met[row] = _box_row(basis, origin, spacing, lo, hi, closed, planes, out, row)
    return int(met.sum())


#: Rays below which the helpers run on one thread (a parallel region costs more than it saves,
#: and far more on a busy machine, where waking the other threads waits for the scheduler).
PARALLEL_RAYS = 1 << 16


def box_ranges(basis: np.ndarray, origin: np.ndarray, spacing: np.ndarray, lo: np.ndarray,
               hi: np.ndarray, closed: np.ndarray, planes: np.ndarray, out: np.ndarray) -> int:
    """Write each ray's interval ``[t0, t1]`` inside the index box ``[lo, hi]`` into ``out``.

    Parameters
    ----------
    basis : ndarray
        :meth:`Camera.pixel_basis` of the (tile) camera whose rays are meant.
    origin, spacing : ndarray (3,)
        World position of index ``(0, 0, 0)`` and the index spacing of the box's index space.
    lo, hi : ndarray (3,)
        The box in that index space.
    closed : ndarray (3,) of bool
        Whether a ray lying in the box's upper face plane belongs to the box.
    planes : ndarray (m, 4)
        Clip planes (:func:`splinecast.render.clipping.make_planes`).
    out : ndarray (height, width, 2)
        Written; ``t0 > t1`` where the ray misses the box.

    Returns
    -------
    int
        Number of rays that meet the box.
    """
    run = _box_ranges_parallel if out.shape[0] * out.shape[1] >= PARALLEL_RAYS else (
        _box_ranges_serial)
    return run(basis, origin, spacing, lo, hi, closed, planes, out)


@jit()
def sample_grid(grid, points: np.ndarray, out: np.ndarray) -> None:
    """``out[n]`` = the grid's reconstruction at ``points[n]`` (the grid's traversal space)."""
    scratch = new_scratch(grid)
    for n in range(points.shape[0]):
        v, _, _, _ = value_gradient_at(grid, scratch, points[n, 0], points[n, 1], points[n, 2])
        out[n] = v


@jit()
def grid_values_at(grid, geom: np.ndarray, basis: np.ndarray, t: np.ndarray, want: np.ndarray,
                   value: np.ndarray, gradient: np.ndarray) -> None:
    """Value and world gradient of the grid's reconstruction at parameter ``t[row, col]`` of
    every ray where ``want[row, col]`` is set (written into ``value`` and ``gradient``)."""
    height, width = t.shape
    for row in range(height):
        scratch = new_scratch(grid)
        for col in range(width):
            if not want[row, col]:
                continue
            x, y, z = grid_point(geom, basis, row, col, width, height, t[row, col])
            v, gx, gy, gz = value_gradient_at(grid, scratch, x, y, z)
            value[row, col] = v
            gradient[row, col, 0] = gx / geom[GEOM_SPACING]
            gradient[row, col, 1] = gy / geom[GEOM_SPACING + 1]
            gradient[row, col, 2] = gz / geom[GEOM_SPACING + 2]
