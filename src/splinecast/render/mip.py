"""Maximum (and minimum) intensity projection of the trilinear field, exactly or sampled.

Exact MIP (reference 001, section 9): along a ray the trilinear interpolant is, cell by cell, the
cubic ``c3 s^3 + c2 s^2 + c1 s + c0`` of :func:`splinecast.models.trilinear.ray_cubic`. Its largest
value on the cell's segment is at an end or at a root of the derivative (a quadratic), so the
maximum along the whole ray is found with no step size at all.

Empty-space skipping uses the per-block maxima of the min/max hierarchy: a block whose largest
possible value does not exceed the running maximum cannot change the result and is leapt over,
which, once a bright structure has been met, removes most of the ray. Before that walk, the exact
method takes a cheap lower bound of the answer from a coarse walk over 16-cell blocks: every
value the ray meets inside a block is at least the block's minimum, so the largest block minimum
along the ray bounds the MIP from below, and blocks whose maximum lies strictly below that bound
are leapt over from the start, even before anything bright has been met. Minimum intensity
projection is the same computation on the negated field (the block minima, negated, serve as
maxima).

The sampled method takes samples every ``step`` voxels from the ray's entry point (the reference
common viewers use); it can only report values the field takes, so it never exceeds the exact MIP.
"""

from __future__ import annotations

import math

import numpy as np
from numba import prange

from .._jit import jit
from ..accel.traversal import walk_begin, walk_step
from ..models.trilinear import cell_monomials, local_value, ray_cubic
from ..roots.cubic import horner3, quadratic_roots
from .clipping import clip_interval
from .rays import pixel_ray

__all__ = ["trace_mip"]


@jit(inline="always")
def _skip_size(h0: np.ndarray, h1: np.ndarray, h2: np.ndarray, i: int, j: int, k: int,
               best: float, lower: float) -> int:
    """Edge of the largest block around cell ``(i, j, k)`` that cannot hold the maximum.

    A block cannot when its maximum does not beat the running maximum ``best`` (ties keep the
    earlier position) or lies strictly below the known lower bound ``lower``; 0 if none.
    """
    v = h2[i >> 6, j >> 6, k >> 6]
    if v <= best or v < lower:
        return 64
    v = h1[i >> 4, j >> 4, k >> 4]
    if v <= best or v < lower:
        return 16
    v = h0[i >> 2, j >> 2, k >> 2]
    if v <= best or v < lower:
        return 4
    return 0


@jit(inline="always")
def _lower_bound(g1, ox, oy, oz, dx, dy, dz, nx, ny, nz, t_min, t_max):
    """Largest 16-cell block minimum along the ray: a lower bound of its maximum."""
    lower = -math.inf
    inside, ci, cj, ck, t, t_far = walk_begin(ox, oy, oz, dx, dy, dz, nx, ny, nz, t_min, t_max)
    while inside:
        lower = max(lower, g1[ci >> 4, cj >> 4, ck >> 4])
        _, inside, ci, cj, ck, t = walk_step(
            ox, oy, oz, dx, dy, dz, nx, ny, nz, ci, cj, ck, t, t_far, 16
        )
    return lower


@jit(inline="always")
def _cubic_max(c3: float, c2: float, c1: float, c0: float) -> tuple[float, float]:
    """Largest value of the cubic on ``[0, 1]`` and the ``s`` where it is taken (first of ties)."""
    best = c0
    s_best = 0.0
    count, e0, e1 = quadratic_roots(3.0 * c3, 2.0 * c2, c1)
    if count >= 1 and 0.0 < e0 < 1.0:
        v = horner3(c3, c2, c1, c0, e0)
        if v > best:
            best, s_best = v, e0
    if count >= 2 and 0.0 < e1 < 1.0:
        v = horner3(c3, c2, c1, c0, e1)
        if v > best:
            best, s_best = v, e1
    v = c3 + c2 + c1 + c0
    if v > best:
        best, s_best = v, 1.0
    return best, s_best


@jit()
def _mip_ray(data, h0, h1, h2, g1, sign, ox, oy, oz, dx, dy, dz, method, dt, t_min, t_max):
    """One index-space ray. Returns ``(best, t_best, visited, tested, skipped)`` in sign space."""
    nx, ny, nz = data.shape[0] - 1, data.shape[1] - 1, data.shape[2] - 1
    best = -math.inf
    t_best = math.inf
    visited = 0
    tested = 0
    skipped = 0
    inside, ci, cj, ck, t, t_far = walk_begin(ox, oy, oz, dx, dy, dz, nx, ny, nz, t_min, t_max)
    t_near = t
    # Only the exact maximum is bounded by the block minima (samples may miss a block).
    lower = -math.inf
    if method == 0 and inside:
        lower = _lower_bound(g1, ox, oy, oz, dx, dy, dz, nx, ny, nz, t_min, t_max)
    while inside:
        size = _skip_size(h0, h1, h2, ci, cj, ck, best, lower)
        t_end, inside, ni, nj, nk, t_next = walk_step(
            ox, oy, oz, dx, dy, dz, nx, ny, nz, ci, cj, ck, t, t_far, max(size, 1)
        )
        if size > 0:
            skipped += 1
        elif t_end >= t:
            visited += 1
            vmin, vmax, k0, k1, k2, k3, k4, k5, k6, k7 = cell_monomials(data, ci, cj, ck)
            # The corner range bounds the cell (convexity of trilinear interpolation).
            cell_max = vmax if sign > 0.0 else -vmin
            if cell_max > best and cell_max >= lower:
                tested += 1
                ax = ox + t * dx - ci
                ay = oy + t * dy - cj
                az = oz + t * dz - ck
                ex = ox + t_end * dx - ci - ax
                ey = oy + t_end * dy - cj - ay
                ez = oz + t_end * dz - ck - az
                if method == 0:
                    c3, c2, c1, c0 = ray_cubic(k0, k1, k2, k3, k4, k5, k6, k7,
                                               ax, ay, az, ex, ey, ez)
                    v, s = _cubic_max(sign * c3, sign * c2, sign * c1, sign * c0)
                    if v > best:
                        best = v
                        t_best = t + s * (t_end - t)
                else:
                    m = math.ceil((t - t_near) / dt)
                    ts = t_near + m * dt
                    while ts <= t_end:
                        s = (ts - t) / (t_end - t) if t_end > t else 0.0
                        v = sign * local_value(k0, k1, k2, k3, k4, k5, k6, k7,
                                               ax + s * ex, ay + s * ey, az + s * ez)
                        if v > best:
                            best = v
                            t_best = ts
                        m += 1
                        ts = t_near + m * dt
        ci, cj, ck, t = ni, nj, nk, t_next
    return best, t_best, visited, tested, skipped


@jit(parallel=True)
def trace_mip(
    data: np.ndarray,
    h0: np.ndarray,
    h1: np.ndarray,
    h2: np.ndarray,
    g1: np.ndarray,
    sign: float,
    basis: np.ndarray,
    vol_origin: np.ndarray,
    spacing: np.ndarray,
    planes: np.ndarray,
    row_order: np.ndarray,
    method: int,
    step: float,
    value: np.ndarray,
    depth: np.ndarray,
    position: np.ndarray,
    cells_visited: np.ndarray,
    cells_tested: np.ndarray,
    blocks_skipped: np.ndarray,
) -> None:
    """Maximum (``sign=+1``) or minimum (``sign=-1``) of the trilinear field along every ray.

    ``h0..h2`` are the per-block maxima of the field times ``sign`` (the hierarchy's ``highs``
    for MIP, its negated ``lows`` for minIP), finest level first; ``g1`` the per-block minima
    times ``sign`` of the 16-cell level (``lows[1]`` for MIP, ``-highs[1]`` for minIP).
    ``method`` is 0 (exact) or 1 (sampled every ``step`` voxels). Writes ``value`` (NaN when the
    ray misses the volume), ``depth`` (world distance to the extremum, ``inf`` on a miss) and
    ``position``.
    """
    height, width = depth.shape
    sx, sy, sz = spacing[0], spacing[1], spacing[2]
    orx, ory, orz = vol_origin[0], vol_origin[1], vol_origin[2]
    for r in prange(height):
        row = row_order[r]
        for col in range(width):
            wx, wy, wz, ux, uy, uz = pixel_ray(basis, row, col, width, height)
            dx, dy, dz = ux / sx, uy / sy, uz / sz
            ox, oy, oz = (wx - orx) / sx, (wy - ory) / sy, (wz - orz) / sz
            dt = step / math.sqrt(dx * dx + dy * dy + dz * dz)
            t_min, t_max = clip_interval(planes, wx, wy, wz, ux, uy, uz)
            best, t, nvis, ntest, nskip = _mip_ray(
                data, h0, h1, h2, g1, sign, ox, oy, oz, dx, dy, dz, method, dt, t_min, t_max
            )
            cells_visited[row, col] = nvis
            cells_tested[row, col] = ntest
            blocks_skipped[row, col] = nskip
            if t == math.inf:
                value[row, col] = math.nan
                depth[row, col] = math.inf
                for c in range(3):
                    position[row, col, c] = math.nan
            else:
                value[row, col] = sign * best
                depth[row, col] = t
                position[row, col, 0] = wx + t * ux
                position[row, col, 1] = wy + t * uy
                position[row, col, 2] = wz + t * uz
