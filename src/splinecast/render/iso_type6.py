"""First-hit isosurface ray casting on the type-6 splines (models ``s31`` and ``qss``).

The kernel has the common signature of :mod:`splinecast.render.kernels` and follows the trilinear
kernel's structure; what is particular to the type-6 splines:

* **Dual grid.** Cube ``(i, j, k)`` is centred on voxel ``(i, j, k)``. Shifting the index-space ray
  origin by +1/2 makes cube ``i`` span ``[i, i + 1]``, so the shared integer traversal walks cubes
  unchanged (``n_cells`` = voxels per axis).
* **Work lists.** The model's isovalue change (:mod:`splinecast.accel.active_cells`) supplies the
  cube -> slot lookup, a 24-bit mask of active tetrahedra per active cube and its own block flags;
  the ``act0..act2`` arguments from the scene's generic hierarchy are not used (the model's flags
  are exact for QSS-B's negative weights and tighter for every scheme).
* **Tetrahedra in order.** Inside a cube the ray segment is cut where it crosses the six planes
  ``x = +-y``, ``x = +-z``, ``y = +-z`` (through the cube centre) that bound the 24 tetrahedra;
  each piece lies in one tetrahedron, found from its midpoint, and pieces are visited front to
  back.
* **Ray restriction.** On a piece, the patch is a univariate Bernstein polynomial of the patch's
  degree obtained by blossoming at the piece's end points (:func:`~splinecast.models.type6.
  ray_bernstein3`); if its coefficients all have one sign the piece is skipped (convex hull),
  otherwise the first root is found in closed form (quadratic) or by Bernstein subdivision /
  Newton from three starts (cubic, ``root_finder``).
* **Coefficients on demand.** Only when a ray crosses an active tetrahedron of a cube are the
  cube's coefficients computed (the model's verified averaging chain from the 27 data values)
  into a small per-thread cache keyed by the cube's slot, so the neighbouring pixels of a row
  that cross the same cube reuse them; a tetrahedron's 20 (10) coefficients are then read from
  the cache (or from the stored coefficients with ``precompute=True``). The ray restriction is
  unrolled straight-line blossoming (:func:`~splinecast.models.type6.ray_bernstein3`), and a
  piece whose Bernstein coefficients have one sign is rejected before any root finding.
* **Normals** come from the de Casteljau directional derivatives of the hit tetrahedron's patch
  at the hit point (continuous across all faces for S31), from the coefficients already at hand.

``method`` and ``step`` are ignored: the type-6 kernels are always exact.
"""

from __future__ import annotations

import math

import numpy as np
from numba import prange

from .._jit import jit
from ..accel.minmax import inactive_block_size
from ..accel.traversal import walk_begin, walk_step
from ..models.type6 import (
    barycentric,
    gather27,
    ray_bernstein2,
    ray_bernstein3,
    run_program1,
    value_gradient,
)
from ..models.type6_geometry import tet_of_point
from ..roots.bernstein_cubic import (
    bernstein_cubic_first_root,
    bernstein_quadratic_first_root,
    newton_cubic_first_root,
)
from .clipping import clip_interval
from .pixels import store_hit, store_miss
from .rays import pixel_ray

__all__ = ["trace_type6", "split_cube_segment"]


@jit(inline="always")
def _plane_cut(a_u: float, a_v: float, e_u: float, e_v: float, sign: float,
               cuts: np.ndarray, n: int) -> int:
    """Append the segment parameter where ``u = sign * v`` is crossed, if inside (0, 1)."""
    g0 = a_u - sign * a_v
    ge = e_u - sign * e_v
    if ge != 0.0:
        s = -g0 / ge
        if 0.0 < s < 1.0:
            cuts[n] = s
            return n + 1
    return n


@jit(inline="always")
def split_cube_segment(ax: float, ay: float, az: float, ex: float, ey: float, ez: float,
                       cuts: np.ndarray) -> int:
    """Sorted break points of the segment ``a + s e`` (``s`` in [0, 1]) at tetrahedron faces.

    Fills ``cuts[0..n]`` with ``0, s_1, ..., 1`` (increasing) and returns ``n``, the number of
    pieces. ``a`` and ``e`` are in local cube coordinates.
    """
    cuts[0] = 0.0
    n = 1
    n = _plane_cut(ax, ay, ex, ey, 1.0, cuts, n)
    n = _plane_cut(ax, ay, ex, ey, -1.0, cuts, n)
    n = _plane_cut(ax, az, ex, ez, 1.0, cuts, n)
    n = _plane_cut(ax, az, ex, ez, -1.0, cuts, n)
    n = _plane_cut(ay, az, ey, ez, 1.0, cuts, n)
    n = _plane_cut(ay, az, ey, ez, -1.0, cuts, n)
    # Insertion sort of at most six values.
    for a in range(2, n):
        v = cuts[a]
        b = a - 1
        while b >= 1 and cuts[b] > v:
            cuts[b + 1] = cuts[b]
            b -= 1
        cuts[b + 1] = v
    cuts[n] = 1.0
    return n


#: Cubes whose coefficients a thread keeps (direct-mapped by slot; 128 x 214 float64 = 219 KB
#: for S31, fits L2): neighbouring pixels of a tile cross the same cubes, so most cubes are
#: computed once per tile instead of once per ray and tetrahedron.
_CACHE = 128
#: Rows per work item and columns per tile (see trace_type6).
_BAND = 8
_TILE = 8


@jit(inline="always")
def _same_sign(b0: float, b1: float, b2: float, b3: float) -> bool:
    return (b0 > 0.0 and b1 > 0.0 and b2 > 0.0 and b3 > 0.0) or (
        b0 < 0.0 and b1 < 0.0 and b2 < 0.0 and b3 < 0.0)


@jit(inline="always")
def _trace_ray(
    pad, slot, tet_mask, coeffs, act0, act1, act2, tet_points, targets, ptr, sources, weights,
    bary, degree, root_mode, precomputed, iso, ox, oy, oz, dx, dy, dz, t_min, t_max,
    keys, cache, c, cuts,
):
    """Trace one (shifted) index-space ray.

    Returns ``(t_hit or inf, i, j, k, tet, visited, tested, skipped)``; ``tested`` counts the
    tetrahedron pieces whose ray polynomial was built. On a hit, ``c`` holds the coefficients
    of the hit tetrahedron. ``keys``/``cache`` are the thread's cube cache (on-the-fly mode):
    entry ``s % _CACHE`` holds the program buffer (data, coefficients, auxiliaries) of the cube
    in slot ``keys[s % _CACHE]``.
    """
    nx, ny, nz = pad.shape[0] - 2, pad.shape[1] - 2, pad.shape[2] - 2
    n_local = tet_points.shape[1]
    visited = 0
    tested = 0
    skipped = 0
    inside, ci, cj, ck, t, t_far = walk_begin(ox, oy, oz, dx, dy, dz, nx, ny, nz, t_min, t_max)
    while inside:
        size = inactive_block_size(act0, act1, act2, ci, cj, ck)
        t_end, inside, ni, nj, nk, t_next = walk_step(
            ox, oy, oz, dx, dy, dz, nx, ny, nz, ci, cj, ck, t, t_far, max(size, 1)
        )
        if size > 0:
            skipped += 1
        else:
            visited += 1
            s_slot = slot[ci, cj, ck]
            if s_slot >= 0 and t_end >= t:
                mask = tet_mask[s_slot]
                # Local coordinates relative to the cube centre (at ci + 1/2 in shifted space).
                ax = ox + t * dx - ci - 0.5
                ay = oy + t * dy - cj - 0.5
                az = oz + t * dz - ck - 0.5
                ex = ox + t_end * dx - ci - 0.5 - ax
                ey = oy + t_end * dy - cj - 0.5 - ay
                ez = oz + t_end * dz - ck - 0.5 - az
                n_pieces = split_cube_segment(ax, ay, az, ex, ey, ez, cuts)
                loaded = False
                entry = s_slot % _CACHE
                for piece in range(n_pieces):
                    s0 = cuts[piece]
                    s1 = cuts[piece + 1]
                    sm = 0.5 * (s0 + s1)
                    tet = tet_of_point(ax + sm * ex, ay + sm * ey, az + sm * ez)
                    if (mask >> tet) & 1 == 0:
                        continue
                    tested += 1
                    if precomputed:
                        for n in range(n_local):
                            c[n] = coeffs[s_slot, tet_points[tet, n]]
                    else:
                        if not loaded:
                            if keys[entry] != s_slot:
                                buf = cache[entry]
                                gather27(pad, ci, cj, ck, buf)
                                run_program1(buf, targets, ptr, sources, weights)
                                keys[entry] = s_slot
                            loaded = True
                        for n in range(n_local):
                            c[n] = cache[entry, 27 + tet_points[tet, n]]
                    a0, a1, a2, a3 = barycentric(bary, tet, ax + s0 * ex, ay + s0 * ey,
                                                 az + s0 * ez)
                    e0, e1, e2, e3 = barycentric(bary, tet, ax + s1 * ex, ay + s1 * ey,
                                                 az + s1 * ez)
                    if degree == 2:
                        u0, u1, u2 = ray_bernstein2(c, a0, a1, a2, a3, e0, e1, e2, e3)
                        u0 -= iso
                        u1 -= iso
                        u2 -= iso
                        if _same_sign(u0, u1, u2, u2):
                            continue
                        r = bernstein_quadratic_first_root(u0, u1, u2)
                    else:
                        u0, u1, u2, u3 = ray_bernstein3(c, a0, a1, a2, a3, e0, e1, e2, e3)
                        u0 -= iso
                        u1 -= iso
                        u2 -= iso
                        u3 -= iso
                        if _same_sign(u0, u1, u2, u3):
                            continue  # convex hull: no root on this piece
                        if root_mode == 1:
                            r = newton_cubic_first_root(u0, u1, u2, u3)
                        else:
                            r = bernstein_cubic_first_root(u0, u1, u2, u3)
                    if r == r:
                        s = s0 + r * (s1 - s0)
                        return t + s * (t_end - t), ci, cj, ck, tet, visited, tested, skipped
        ci, cj, ck, t = ni, nj, nk, t_next
    return math.inf, -1, -1, -1, -1, visited, tested, skipped


@jit(parallel=True)
def trace_type6(
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
    """Trace and shade every pixel on an S31 or QSS model (common iso kernel signature).

    ``arrays`` is :attr:`Type6Model.arrays` = ``(pad, slot, tet_mask, coeffs, act0, act1, act2,
    tet_points, targets, ptr, sources, weights, bary, steps)`` (the program arrays are the
    model's :class:`~splinecast.models.type6_geometry.Type6Program`); ``params`` = ``[degree,
    root finder code, precomputed, program slots]``. ``cells_tested`` counts tetrahedron pieces
    whose ray polynomial was built. ``row_order`` is not used: the kernel balances its own
    bands of rows (see the comment in the body).
    """
    (pad, slot, tet_mask, coeffs, m_act0, m_act1, m_act2, tet_points, targets, ptr, sources,
     weights, bary, steps) = arrays
    degree = int(params[0])
    root_mode = int(params[1])
    precomputed = params[2] != 0.0
    n_slots = int(params[3])
    n_local = tet_points.shape[1]
    height, width = depth.shape
    sx, sy, sz = spacing[0], spacing[1], spacing[2]
    orx, ory, orz = vol_origin[0], vol_origin[1], vol_origin[2]
    # Work items are bands of _BAND rows, traversed in tiles of _BAND x _TILE pixels so that
    # the cube cache serves neighbouring pixels of both directions; bands are taken in a
    # strided order (stride coprime to their number, near the golden ratio) so every thread
    # gets a mix of busy and empty bands, like the scene's row_order.
    n_bands = (height + _BAND - 1) // _BAND
    stride = max(int(0.6180339887498949 * n_bands), 1)
    while math.gcd(stride, n_bands) != 1:
        stride += 1
    for band_idx in prange(n_bands):
        band = (band_idx * stride) % n_bands
        keys = np.full(_CACHE, -1, np.int64)
        cache = np.empty((_CACHE, n_slots))
        c = np.empty(n_local)
        b10 = np.empty(10)
        b4 = np.empty(4)
        cuts = np.empty(8)
        for tile in range(0, width, _TILE):
            for row in range(band * _BAND, min(height, band * _BAND + _BAND)):
                for col in range(tile, min(width, tile + _TILE)):
                    wx, wy, wz, ux, uy, uz = pixel_ray(basis, row, col, width, height)
                    dx, dy, dz = ux / sx, uy / sy, uz / sz
                    # +1/2: cube i of the dual grid spans [i, i + 1] in the traversal's coordinates.
                    ox = (wx - orx) / sx + 0.5
                    oy = (wy - ory) / sy + 0.5
                    oz = (wz - orz) / sz + 0.5
                    t_min, t_max = clip_interval(planes, wx, wy, wz, ux, uy, uz)
                    t, ci, cj, ck, tet, nvis, ntest, nskip = _trace_ray(
                        pad, slot, tet_mask, coeffs, m_act0, m_act1, m_act2, tet_points, targets,
                        ptr, sources, weights, bary, degree, root_mode, precomputed, iso,
                        ox, oy, oz, dx, dy, dz, t_min, t_max, keys, cache, c, cuts,
                    )
                    cells_visited[row, col] = nvis
                    cells_tested[row, col] = ntest
                    blocks_skipped[row, col] = nskip
                    if t == math.inf:
                        store_miss(row, col, shading, rgba, depth, position, normal, face)
                        continue
                    # ``c`` holds the hit tetrahedron's coefficients.
                    _, gx, gy, gz = value_gradient(
                        c, degree, steps, bary, tet,
                        ox + t * dx - ci - 0.5, oy + t * dy - cj - 0.5, oz + t * dz - ck - 0.5,
                        b10, b4,
                    )
                    # Index-space gradient to world space: d/dx_world = d/dx_index / spacing.
                    store_hit(row, col, t, wx, wy, wz, ux, uy, uz, gx / sx, gy / sy, gz / sz,
                              inside_high, shading, rgba, depth, position, normal, face)
