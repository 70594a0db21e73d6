"""First-hit isosurface ray casting on tensor-product B-splines of degree 1, 2 and 3.

One kernel serves every degree and root finder; both come in through ``params`` (see
:attr:`splinecast.models.bspline.BSplineModel.params`). Per pixel, as in
:func:`splinecast.render.iso.trace_trilinear`:

1. the ray is generated, clipped by the clip planes and by the box spanned by the voxel centres
   (in voxel index space), then moved to spline index space ``s = x + h`` where cell ``c`` is
   ``[c, c + 1]`` (``h = 1/2`` for even degree, see :mod:`splinecast.models.bspline`);
2. the shared integer traversal walks the cells and leaps over blocks the min/max hierarchy
   marks inactive (bounds: the convex hull of the influence coefficients);
3. per cell, the (d+1)^3 influence coefficients are first checked against the isovalue (the same
   convex-hull bound, per cell); only then are they transformed to the cell's polynomial and
   composed with the ray segment into one polynomial of degree 3d (scaled Bernstein form for the
   Bernstein-form root finders, power form for Sturm and Newton);
4. the first root in the segment ends the walk; the normal is the analytic gradient of the
   spline at the hit, evaluated from the B-spline basis.

Only the ``exact`` method exists for B-splines (the model lists it in ``methods``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import prange

from .._jit import jit
from ..accel.minmax import inactive_block_size
from ..accel.traversal import clip_to_box, walk_begin, walk_step
from ..models.bspline import POWER_MATRIX, SB_MATRIX, SCALE, cell_transform, local_value_gradient
from ..models.bspline_ray import axis_basis_power, axis_basis_sb, compose
from ..roots.bernstein import binomial
from ..roots.first_root import first_root_by_id
from .clipping import clip_interval
from .pixels import store_hit, store_miss
from .rays import pixel_ray

__all__ = ["trace_bspline"]


@jit(inline="always")
def _ic_range(coeffs: np.ndarray, i: int, j: int, k: int, d: int) -> tuple[float, float]:
    """Smallest and largest influence coefficient of cell ``(i, j, k)``."""
    vmin = np.inf
    vmax = -np.inf
    for a in range(d + 1):
        for b in range(d + 1):
            for c in range(d + 1):
                v = float(coeffs[i + a, j + b, k + c])
                vmin = min(vmin, v)
                vmax = max(vmax, v)
    return vmin, vmax


@jit()
def _trace_row(
    coeffs, params, act0, act1, act2, iso, basis, vol_origin, spacing, planes, row,
    inside_high, shading, rgba, depth, position, normal, face, cells_visited, cells_tested,
    blocks_skipped,
):
    """Trace every pixel of one image row (scratch buffers are allocated once per row)."""
    height, width = depth.shape
    d = int(params[0])
    fid = int(params[1])
    iterations = int(params[2])
    tol = params[3]
    h = params[4]
    power = params[5] != 0.0
    n = 3 * d
    matrix = POWER_MATRIX[d] if power else SB_MATRIX[d]
    # The transformed coefficients are SCALE^3 times the true ones (integer matrices).
    scaled_iso = SCALE[d] ** 3 * iso
    inv_binom = np.empty(n + 1)
    for m in range(n + 1):
        inv_binom[m] = 1.0 / binomial(n, m)
    tensor = np.empty((4, 4, 4))
    tmp = np.empty((4, 4, 4))
    bx = np.empty((4, 4))
    by = np.empty((4, 4))
    bz = np.empty((4, 4))
    inner = np.empty(4)
    middle = np.empty(7)
    poly = np.empty(10)
    work = np.empty((10, 10))
    degrees = np.empty(10, dtype=np.int64)

    ncx, ncy, ncz = coeffs.shape[0] - d, coeffs.shape[1] - d, coeffs.shape[2] - d
    # Last voxel index per axis: the box spanned by the voxel centres is [0, n_voxels - 1].
    lastx = ncx - 1 if h > 0.0 else ncx
    lasty = ncy - 1 if h > 0.0 else ncy
    lastz = ncz - 1 if h > 0.0 else ncz
    sx, sy, sz = spacing[0], spacing[1], spacing[2]
    orx, ory, orz = vol_origin[0], vol_origin[1], vol_origin[2]
    for col in range(width):
        wx, wy, wz, ux, uy, uz = pixel_ray(basis, row, col, width, height)
        dx, dy, dz = ux / sx, uy / sy, uz / sz
        vx, vy, vz = (wx - orx) / sx, (wy - ory) / sy, (wz - orz) / sz
        t_min, t_max = clip_interval(planes, wx, wy, wz, ux, uy, uz)
        t0, t1 = clip_to_box(vx, vy, vz, dx, dy, dz, lastx, lasty, lastz, t_min, t_max)
        ox, oy, oz = vx + h, vy + h, vz + h
        visited = 0
        tested = 0
        skipped = 0
        t_hit = math.inf
        hi = hj = hk = -1
        inside = False
        ci = cj = ck = 0
        t = t_far = 0.0
        if t0 <= t1:
            inside, ci, cj, ck, t, t_far = walk_begin(ox, oy, oz, dx, dy, dz, ncx, ncy, ncz,
                                                      t0, t1)
        while inside:
            size = inactive_block_size(act0, act1, act2, ci, cj, ck)
            t_end, inside, ni, nj, nk, t_next = walk_step(
                ox, oy, oz, dx, dy, dz, ncx, ncy, ncz, ci, cj, ck, t, t_far, max(size, 1)
            )
            if size > 0:
                skipped += 1
            else:
                visited += 1
                vmin, vmax = _ic_range(coeffs, ci, cj, ck, d)
                if vmin <= iso <= vmax and t_end >= t:
                    tested += 1
                    cell_transform(coeffs, ci, cj, ck, d, matrix, tensor, tmp)
                    ax, ay, az = ox + t * dx - ci, oy + t * dy - cj, oz + t * dz - ck
                    ex, ey, ez = (ox + t_end * dx - ci, oy + t_end * dy - cj,
                                  oz + t_end * dz - ck)
                    if power:
                        axis_basis_power(ax, ex, d, bx)
                        axis_basis_power(ay, ey, d, by)
                        axis_basis_power(az, ez, d, bz)
                        compose(tensor, bx, by, bz, d, inner, middle, poly)
                        poly[0] -= scaled_iso
                    else:
                        axis_basis_sb(ax, ex, d, bx)
                        axis_basis_sb(ay, ey, d, by)
                        axis_basis_sb(az, ez, d, bz)
                        compose(tensor, bx, by, bz, d, inner, middle, poly)
                        # Scaled Bernstein -> control points; the isovalue is subtracted from
                        # every control point because the Bernstein basis sums to 1.
                        for m in range(n + 1):
                            poly[m] = poly[m] * inv_binom[m] - scaled_iso
                    s = first_root_by_id(fid, poly, n, iterations, tol, work, degrees)
                    if s == s:  # not NaN
                        t_hit = t + s * (t_end - t)
                        hi, hj, hk = ci, cj, ck
                        break
            ci, cj, ck, t = ni, nj, nk, t_next
        cells_visited[row, col] = visited
        cells_tested[row, col] = tested
        blocks_skipped[row, col] = skipped
        if t_hit == math.inf:
            store_miss(row, col, shading, rgba, depth, position, normal, face)
            continue
        _, gx, gy, gz = local_value_gradient(
            coeffs, d, hi, hj, hk, ox + t_hit * dx - hi, oy + t_hit * dy - hj,
            oz + t_hit * dz - hk,
        )
        # Index-space gradient to world space: d/dx_world = d/dx_index / spacing.
        store_hit(row, col, t_hit, wx, wy, wz, ux, uy, uz, gx / sx, gy / sy, gz / sz,
                  inside_high, shading, rgba, depth, position, normal, face)


@jit(parallel=True)
def trace_bspline(
    arrays: tuple,
    params: np.ndarray,
    act0: np.ndarray,
    act1: np.ndarray,
    act2: np.ndarray,
    iso: float,
    basis: np.ndarray,
    vol_origin: np.ndarray,
    spacing: np.ndarray,
    planes: np.ndarray,
    row_order: np.ndarray,
    method: int,
    step: float,
    inside_high: bool,
    shading: np.ndarray,
    rgba: np.ndarray,
    depth: np.ndarray,
    position: np.ndarray,
    normal: np.ndarray,
    face: np.ndarray,
    cells_visited: np.ndarray,
    cells_tested: np.ndarray,
    blocks_skipped: np.ndarray,
) -> None:
    """Trace and shade every pixel (the iso kernel interface of :mod:`splinecast.render.kernels`).

    ``arrays`` is ``(padded coefficients,)`` and ``params`` the model's numbers. ``method`` and
    ``step`` are part of the common signature; only the exact method is implemented.
    """
    coeffs = arrays[0]
    height = depth.shape[0]
    for r in prange(height):
        _trace_row(coeffs, params, act0, act1, act2, iso, basis, vol_origin, spacing, planes,
                   row_order[r], inside_high, shading, rgba, depth, position, normal, face,
                   cells_visited, cells_tested, blocks_skipped)
