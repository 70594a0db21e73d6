"""Several translucent isosurfaces at once, composited front to back.

Along each ray every crossing of every isovalue is found exactly and in depth order: per cell, the
cubic ray profile minus each isovalue inside the cell's range is split at the roots of its
derivative into monotone pieces, and each piece with a sign change holds exactly one root (solved
by :func:`splinecast.roots.cubic.cubic_first_root`). The cell's crossings are sorted by ray
parameter and composited with the "under" operator, each surface with its own colour and opacity,
so a translucent skin shows the bone beneath. A ray stops once its opacity reaches ``1 - 1e-4``.

Front and back faces of a surface get the same colour (a translucent shell is seen from both
sides); lighting and effects are those of :func:`splinecast.render.effects.surface_rgb`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import prange

from .._jit import jit
from ..accel.minmax import inactive_block_size
from ..accel.traversal import walk_begin, walk_step
from ..models.trilinear import cell_monomials, local_gradient, ray_cubic
from ..roots.cubic import cubic_first_root, quadratic_roots
from .clipping import clip_interval
from .effects import surface_rgb
from .rays import pixel_ray

__all__ = ["trace_multi_iso", "cubic_roots_in_unit"]

_OPAQUE = 1.0 - 1e-4


@jit(inline="always")
def cubic_roots_in_unit(c3: float, c2: float, c1: float, c0: float, out: np.ndarray,
                        start: int) -> int:
    """Write the roots in ``[0, 1]`` of the cubic, increasing, to ``out[start:]``; return count.

    A double root without a sign change counts only when the cubic is exactly 0 there (the
    tangency rule of :mod:`splinecast.roots.cubic`).
    """
    count, e0, e1 = quadratic_roots(3.0 * c3, 2.0 * c2, c1)
    found = 0
    a = 0.0
    last = -1.0
    for piece in range(3):
        if piece == 0:
            if count < 1 or not (0.0 < e0 < 1.0):
                continue
            b = e0
        elif piece == 1:
            if count < 2 or not (0.0 < e1 < 1.0):
                continue
            b = e1
        else:
            b = 1.0
        s = cubic_first_root(c3, c2, c1, c0, a, b)
        if s == s and s != last:
            out[start + found] = s
            found += 1
            last = s
        a = b
    return found


@jit(parallel=True)
def trace_multi_iso(
    data: np.ndarray,
    act0: np.ndarray,
    act1: np.ndarray,
    act2: np.ndarray,
    isos: np.ndarray,
    colors: np.ndarray,
    opacity: np.ndarray,
    basis: np.ndarray,
    vol_origin: np.ndarray,
    spacing: np.ndarray,
    planes: np.ndarray,
    row_order: np.ndarray,
    inside_high: bool,
    shading: np.ndarray,
    effects: np.ndarray,
    rgba: np.ndarray,
    depth: np.ndarray,
    position: np.ndarray,
    normal: np.ndarray,
    face: np.ndarray,
    layers: np.ndarray,
    cells_visited: np.ndarray,
    cells_tested: np.ndarray,
    blocks_skipped: np.ndarray,
) -> None:
    """Composite all crossings of ``isos`` (colours ``colors``, opacities ``opacity``).

    ``act0..act2`` flag the blocks that can hold any of the isovalues. ``depth``, ``position``,
    ``normal`` and ``face`` describe the first crossing; ``layers`` counts the crossings
    composited per pixel. ``shading`` is :meth:`Shading.as_array` (background, lighting),
    ``effects`` :meth:`SurfaceEffects.as_array`.
    """
    height, width = depth.shape
    m = isos.shape[0]
    sx, sy, sz = spacing[0], spacing[1], spacing[2]
    orx, ory, orz = vol_origin[0], vol_origin[1], vol_origin[2]
    nx, ny, nz = data.shape[0] - 1, data.shape[1] - 1, data.shape[2] - 1
    for r in prange(height):
        row = row_order[r]
        hit_s = np.empty(3 * m)
        hit_q = np.empty(3 * m, dtype=np.int64)
        for col in range(width):
            wx, wy, wz, ux, uy, uz = pixel_ray(basis, row, col, width, height)
            dx, dy, dz = ux / sx, uy / sy, uz / sz
            ox, oy, oz = (wx - orx) / sx, (wy - ory) / sy, (wz - orz) / sz
            t_min, t_max = clip_interval(planes, wx, wy, wz, ux, uy, uz)
            acc_r = 0.0
            acc_g = 0.0
            acc_b = 0.0
            acc_a = 0.0
            t_first = math.inf
            n_layers = 0
            visited = 0
            tested = 0
            skipped = 0
            last_t = -math.inf
            last_q = -1
            depth[row, col] = math.inf
            face[row, col] = 0
            for c in range(3):
                position[row, col, c] = math.nan
                normal[row, col, c] = math.nan
            inside, ci, cj, ck, t, t_far = walk_begin(ox, oy, oz, dx, dy, dz, nx, ny, nz,
                                                      t_min, t_max)
            while inside and acc_a < _OPAQUE:
                size = inactive_block_size(act0, act1, act2, ci, cj, ck)
                t_end, inside, ni, nj, nk, t_next = walk_step(
                    ox, oy, oz, dx, dy, dz, nx, ny, nz, ci, cj, ck, t, t_far, max(size, 1)
                )
                if size > 0:
                    skipped += 1
                elif t_end >= t:
                    visited += 1
                    vmin, vmax, k0, k1, k2, k3, k4, k5, k6, k7 = cell_monomials(data, ci, cj, ck)
                    ax = ox + t * dx - ci
                    ay = oy + t * dy - cj
                    az = oz + t * dz - ck
                    ex = ox + t_end * dx - ci - ax
                    ey = oy + t_end * dy - cj - ay
                    ez = oz + t_end * dz - ck - az
                    count = 0
                    built = False
                    c3 = c2 = c1 = c0 = 0.0
                    for q in range(m):
                        if not vmin <= isos[q] <= vmax:
                            continue
                        if not built:
                            c3, c2, c1, c0 = ray_cubic(k0, k1, k2, k3, k4, k5, k6, k7,
                                                       ax, ay, az, ex, ey, ez)
                            built = True
                            tested += 1
                        found = cubic_roots_in_unit(c3, c2, c1, c0 - isos[q], hit_s, count)
                        for h in range(count, count + found):
                            hit_q[h] = q
                        count += found
                    # Insertion sort of the (few) crossings of this cell by depth.
                    for h in range(1, count):
                        s_h, q_h = hit_s[h], hit_q[h]
                        g = h - 1
                        while g >= 0 and hit_s[g] > s_h:
                            hit_s[g + 1] = hit_s[g]
                            hit_q[g + 1] = hit_q[g]
                            g -= 1
                        hit_s[g + 1] = s_h
                        hit_q[g + 1] = q_h
                    for h in range(count):
                        q = hit_q[h]
                        th = t + hit_s[h] * (t_end - t)
                        if q == last_q and th <= last_t + 1e-12 * (1.0 + abs(th)):
                            continue  # the same crossing seen again on a shared cell face
                        last_t, last_q = th, q
                        x = ox + th * dx - ci
                        y = oy + th * dy - cj
                        z = oz + th * dz - ck
                        gx, gy, gz = local_gradient(k1, k2, k3, k4, k5, k6, k7, x, y, z)
                        gx, gy, gz = gx / sx, gy / sy, gz / sz
                        norm = math.sqrt(gx * gx + gy * gy + gz * gz)
                        if norm > 0.0:
                            scale = (-1.0 if inside_high else 1.0) / norm
                            nxw, nyw, nzw = gx * scale, gy * scale, gz * scale
                        else:
                            nxw, nyw, nzw = -ux, -uy, -uz
                        px, py, pz = wx + th * ux, wy + th * uy, wz + th * uz
                        cr, cg, cb = surface_rgb(shading, effects, colors[q, 0], colors[q, 1],
                                                 colors[q, 2], nxw, nyw, nzw, ux, uy, uz,
                                                 px, py, pz)
                        w = (1.0 - acc_a) * opacity[q]
                        acc_r += w * cr
                        acc_g += w * cg
                        acc_b += w * cb
                        acc_a += w
                        n_layers += 1
                        if t_first == math.inf:
                            t_first = th
                            depth[row, col] = th
                            position[row, col, 0] = px
                            position[row, col, 1] = py
                            position[row, col, 2] = pz
                            normal[row, col, 0] = nxw
                            normal[row, col, 1] = nyw
                            normal[row, col, 2] = nzw
                            face[row, col] = 1 if nxw * ux + nyw * uy + nzw * uz <= 0.0 else -1
                        if acc_a >= _OPAQUE:
                            break
                ci, cj, ck, t = ni, nj, nk, t_next
            rest = 1.0 - acc_a
            bg_a = shading[9]
            rgba[row, col, 0] = min(acc_r + rest * shading[6] * bg_a, 1.0)
            rgba[row, col, 1] = min(acc_g + rest * shading[7] * bg_a, 1.0)
            rgba[row, col, 2] = min(acc_b + rest * shading[8] * bg_a, 1.0)
            rgba[row, col, 3] = acc_a + rest * bg_a
            layers[row, col] = n_layers
            cells_visited[row, col] = visited
            cells_tested[row, col] = tested
            blocks_skipped[row, col] = skipped
