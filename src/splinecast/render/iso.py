"""First-hit isosurface ray casting on the trilinear reconstruction.

Two methods share the ray set-up, the min/max block hierarchy and the integer traversal of
:mod:`splinecast.accel.traversal`:

* ``exact`` (default): per active cell the exact cubic ray profile is built, cells whose profile
  cannot reach the isovalue are rejected from the extrema of the profile (the roots of its
  derivative), and the first root is solved with a safeguarded Newton/bisection iteration.
* ``sampled``: the reference "as common viewers do": samples every ``step`` voxels along the ray
  (from the entry point, plus the exit point) and refines the first sign change by bisection. It
  exists to be compared with the exact method.

Rays are generated per pixel in world space; each is mapped to index space once (``o_idx = (o -
origin) / spacing``, ``d_idx = u / spacing``), so the ray parameter stays the world distance
along the unit ray and is directly the depth.
"""

from __future__ import annotations

import math

import numpy as np
from numba import prange

from .._jit import jit
from ..accel.minmax import inactive_block_size
from ..accel.traversal import walk_begin, walk_step
from ..models.trilinear import cell_monomials, local_gradient, local_value, ray_cubic
from ..roots.cubic import cubic_first_root
from .clipping import clip_interval
from .pixels import store_hit, store_miss
from .rays import pixel_ray

__all__ = ["trace_trilinear", "METHODS"]

#: Method names accepted by ``Scene.render(..., method=...)``.
METHODS = {"exact": 0, "sampled": 1}

_BISECTION_STEPS = 60


@jit()
def _value_at(data: np.ndarray, px: float, py: float, pz: float) -> float:
    """Trilinear value at an index-space point (clamped into the grid)."""
    nx, ny, nz = data.shape[0] - 1, data.shape[1] - 1, data.shape[2] - 1
    px = min(max(px, 0.0), float(nx))
    py = min(max(py, 0.0), float(ny))
    pz = min(max(pz, 0.0), float(nz))
    i = min(int(px), nx - 1)
    j = min(int(py), ny - 1)
    k = min(int(pz), nz - 1)
    _, _, k0, k1, k2, k3, k4, k5, k6, k7 = cell_monomials(data, i, j, k)
    return local_value(k0, k1, k2, k3, k4, k5, k6, k7, px - i, py - j, pz - k)


@jit()
def _trace_ray(
    data, act0, act1, act2, iso, ox, oy, oz, dx, dy, dz, method, dt, t_min, t_max,
):
    """Trace one index-space ray. Returns (t_hit or inf, i, j, k, visited, tested, skipped)."""
    nx, ny, nz = data.shape[0] - 1, data.shape[1] - 1, data.shape[2] - 1
    visited = 0
    tested = 0
    skipped = 0
    inside, ci, cj, ck, t, t_far = walk_begin(ox, oy, oz, dx, dy, dz, nx, ny, nz, t_min, t_max)
    t_near = t
    # Sampled method state: the last sample's parameter and residual (NaN: no sample yet).
    prev_t = math.nan
    prev_g = math.nan
    while inside:
        size = inactive_block_size(act0, act1, act2, ci, cj, ck)
        t_end, inside, ni, nj, nk, t_next = walk_step(
            ox, oy, oz, dx, dy, dz, nx, ny, nz, ci, cj, ck, t, t_far, max(size, 1)
        )
        if size > 0:
            skipped += 1
            if method == 1 and t_end >= t:
                # The block lies strictly on one side of the isovalue, so one sample gives the
                # sign of all its samples; a change against the previous sample is refined.
                m = math.ceil((t - t_near) / dt)
                ts = t_near + m * dt
                if ts <= t_end:
                    g = _value_at(data, ox + ts * dx, oy + ts * dy, oz + ts * dz) - iso
                    if prev_g == prev_g and (prev_g < 0.0) != (g < 0.0):
                        return _bisect(data, iso, ox, oy, oz, dx, dy, dz, prev_t, prev_g,
                                       ts, g, visited, tested, skipped)
                    prev_t = t_near + math.floor((t_end - t_near) / dt) * dt
                    prev_g = g
        else:
            visited += 1
            vmin, vmax, k0, k1, k2, k3, k4, k5, k6, k7 = cell_monomials(data, ci, cj, ck)
            if vmin <= iso <= vmax and t_end >= t:
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
                    s = cubic_first_root(c3, c2, c1, c0 - iso, 0.0, 1.0)
                    if s == s:  # not NaN
                        return t + s * (t_end - t), ci, cj, ck, visited, tested, skipped
                else:
                    # Samples on the global grid t_near + m dt that fall in [t, t_end].
                    m = math.ceil((t - t_near) / dt)
                    ts = t_near + m * dt
                    while ts <= t_end:
                        s = (ts - t) / (t_end - t) if t_end > t else 0.0
                        g = local_value(k0, k1, k2, k3, k4, k5, k6, k7,
                                        ax + s * ex, ay + s * ey, az + s * ez) - iso
                        if prev_g == prev_g and ((prev_g < 0.0) != (g < 0.0) or g == 0.0):
                            return _bisect(data, iso, ox, oy, oz, dx, dy, dz, prev_t, prev_g,
                                           ts, g, visited, tested, skipped)
                        if prev_g != prev_g and g == 0.0:
                            return ts, ci, cj, ck, visited, tested, skipped
                        prev_t, prev_g = ts, g
                        m += 1
                        ts = t_near + m * dt
            elif method == 1 and t_end >= t:
                # A rejected cell lies strictly on one side: its samples all have the sign of
                # its corner range, so no value needs fetching unless the sign changed.
                m = math.ceil((t - t_near) / dt)
                ts = t_near + m * dt
                if ts <= t_end:
                    g_side = vmin - iso if vmin > iso else vmax - iso
                    if prev_g == prev_g and (prev_g < 0.0) != (g_side < 0.0):
                        g = _value_at(data, ox + ts * dx, oy + ts * dy, oz + ts * dz) - iso
                        return _bisect(data, iso, ox, oy, oz, dx, dy, dz, prev_t, prev_g,
                                       ts, g, visited, tested, skipped)
                    prev_t = t_near + math.floor((t_end - t_near) / dt) * dt
                    prev_g = g_side
        ci, cj, ck, t = ni, nj, nk, t_next
    if method == 1 and prev_g == prev_g and prev_t < t_far:
        # The sampled method also samples the exit point, so a crossing in the last partial
        # step is not lost.
        g = _value_at(data, ox + t_far * dx, oy + t_far * dy, oz + t_far * dz) - iso
        if (prev_g < 0.0) != (g < 0.0) or g == 0.0:
            return _bisect(data, iso, ox, oy, oz, dx, dy, dz, prev_t, prev_g, t_far, g,
                           visited, tested, skipped)
    return math.inf, -1, -1, -1, visited, tested, skipped


@jit()
def _bisect(data, iso, ox, oy, oz, dx, dy, dz, ta, ga, tb, gb, visited, tested, skipped):
    """Refine a sign change of the sampled method between ``ta`` and ``tb`` by bisection."""
    if gb == 0.0:
        t = tb
    else:
        for _ in range(_BISECTION_STEPS):
            tm = 0.5 * (ta + tb)
            gm = _value_at(data, ox + tm * dx, oy + tm * dy, oz + tm * dz) - iso
            if (gm < 0.0) == (ga < 0.0) and gm != 0.0:
                ta, ga = tm, gm
            else:
                tb, gb = tm, gm
        t = tb
    nx, ny, nz = data.shape[0] - 1, data.shape[1] - 1, data.shape[2] - 1
    ci = min(max(int(math.floor(ox + t * dx)), 0), nx - 1)
    cj = min(max(int(math.floor(oy + t * dy)), 0), ny - 1)
    ck = min(max(int(math.floor(oz + t * dz)), 0), nz - 1)
    return t, ci, cj, ck, visited, tested, skipped


@jit(parallel=True)
def trace_trilinear(
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
    """Trace and shade every pixel; results are written into the output arrays.

    This is the iso kernel interface every model implements (see
    :mod:`splinecast.render.kernels`): ``arrays`` and ``params`` are the model's prepared arrays
    and numbers (trilinear: ``(voxels,)``, unused params), ``act0..act2`` the block flags,
    ``basis`` is :meth:`Camera.pixel_basis` (rays are generated per pixel), ``planes`` the clip
    planes of :mod:`splinecast.render.clipping`.

    ``row_order`` is a permutation of the rows that spreads each thread's share over the whole
    image, so threads get similar amounts of work. ``step`` is in voxel (index) units and only
    used by the sampled method.
    """
    data = arrays[0]
    height, width = depth.shape
    sx, sy, sz = spacing[0], spacing[1], spacing[2]
    orx, ory, orz = vol_origin[0], vol_origin[1], vol_origin[2]
    for r in prange(height):
        row = row_order[r]
        for col in range(width):
            wx, wy, wz, ux, uy, uz = pixel_ray(basis, row, col, width, height)
            dx, dy, dz = ux / sx, uy / sy, uz / sz
            ox, oy, oz = (wx - orx) / sx, (wy - ory) / sy, (wz - orz) / sz
            # The sampled method's step, converted from voxels to world distance on this ray.
            dt = step / math.sqrt(dx * dx + dy * dy + dz * dz)
            t_min, t_max = clip_interval(planes, wx, wy, wz, ux, uy, uz)
            t, ci, cj, ck, nvis, ntest, nskip = _trace_ray(
                data, act0, act1, act2, iso, ox, oy, oz, dx, dy, dz, method, dt, t_min, t_max
            )
            cells_visited[row, col] = nvis
            cells_tested[row, col] = ntest
            blocks_skipped[row, col] = nskip
            if t == math.inf:
                store_miss(row, col, shading, rgba, depth, position, normal, face)
                continue
            _, _, k0, k1, k2, k3, k4, k5, k6, k7 = cell_monomials(data, ci, cj, ck)
            gx, gy, gz = local_gradient(k1, k2, k3, k4, k5, k6, k7,
                                        ox + t * dx - ci, oy + t * dy - cj, oz + t * dz - ck)
            # Index-space gradient to world space: d/dx_world = d/dx_index / spacing.
            store_hit(row, col, t, wx, wy, wz, ux, uy, uz, gx / sx, gy / sy, gz / sz,
                      inside_high, shading, rgba, depth, position, normal, face)
