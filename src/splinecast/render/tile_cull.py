"""Which tiles of the image see nothing of a box: their rays can skip the clipping and the walk.

A tile's pixel rays all lie inside the wedge bounded by the four planes through its corner
pixels' rays (adjacent corners pairwise): for a perspective camera the planes pass through the
eye, for an orthographic one they are parallel to the viewing direction. When the eight corners
of a box all lie strictly outside one of those planes, no ray of the tile meets the box, so the
driver (:mod:`.driver`) traces none of them: each pixel gets its state and outputs as a ray that
misses the grid's domain would (the slab test would find an empty interval for every one).

The plane through corner rays ``P`` and ``Q`` (origins ``w``, directions ``u``) has the normal
``u_P x (w_Q + u_Q - w_P)``, which is ``u_P x u_Q`` for a shared origin and ``u_P x (w_Q - w_P)``
for a shared direction; its outside is the side away from the tile's other corners. A box
within rounding of a plane is never culled: a corner must be outside by ``1e-9`` of the scene's
extent, far above the rounding of the rays and of the slab test.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import jit
from .rays import pixel_ray

__all__ = ["tile_misses_box"]

#: How far outside a plane (relative to the scene's extent) a box must lie to be culled.
_MARGIN = 1e-9


@jit(inline="always")
def _outside(wx, wy, wz, nx, ny, nz, sx, sy, sz, box, margin):
    """Do the eight corners of ``box`` lie strictly outside the plane through ``w`` with normal
    ``n``, where the point ``s`` is inside?"""
    side = nx * (sx - wx) + ny * (sy - wy) + nz * (sz - wz)
    if side == 0.0:
        return False  # degenerate plane (a one-pixel-wide tile): no verdict
    if side > 0.0:
        nx, ny, nz = -nx, -ny, -nz
    tol = margin * math.sqrt(nx * nx + ny * ny + nz * nz)
    for c in range(8):
        x = box[0] if c & 1 == 0 else box[3]
        y = box[1] if c & 2 == 0 else box[4]
        z = box[2] if c & 4 == 0 else box[5]
        if nx * (x - wx) + ny * (y - wy) + nz * (z - wz) <= tol:
            return False
    return True


@jit(inline="always")
def _plane_culls(wp, pp, wq, pq, ps, pt, box, margin):
    """The side plane through corner rays P and Q (origin ``w``, point at unit distance ``p``),
    with the points ``ps``, ``pt`` of the two other corner rays inside: does it cull ``box``?"""
    # u_P x (w_Q + u_Q - w_P), with u = p - w.
    ax, ay, az = pp[0] - wp[0], pp[1] - wp[1], pp[2] - wp[2]
    bx, by, bz = pq[0] - wp[0], pq[1] - wp[1], pq[2] - wp[2]
    nx, ny, nz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
    # The midpoint of the other two corners' points, so a corner on the plane does not decide.
    sx, sy, sz = 0.5 * (ps[0] + pt[0]), 0.5 * (ps[1] + pt[1]), 0.5 * (ps[2] + pt[2])
    return _outside(wp[0], wp[1], wp[2], nx, ny, nz, sx, sy, sz, box, margin)


@jit(inline="always")
def _corner(basis, row, col, width, height):
    wx, wy, wz, ux, uy, uz = pixel_ray(basis, row, col, width, height)
    return (wx, wy, wz), (wx + ux, wy + uy, wz + uz)


@jit(inline="always")
def tile_misses_box(basis: np.ndarray, r0: int, r1: int, c0: int, c1: int, width: int,
                    height: int, box: np.ndarray) -> bool:
    """True when no pixel ray of rows ``r0 .. r1 - 1`` and columns ``c0 .. c1 - 1`` can meet the
    world box ``box`` (lo xyz, hi xyz); False when it may (also for degenerate tiles).

    Allocates nothing (the driver's band runs without reference counting)."""
    # Corner rays in cyclic order: origin and the point at unit distance.
    wa, pa = _corner(basis, r0, c0, width, height)
    wb, pb = _corner(basis, r0, c1 - 1, width, height)
    wc, pc = _corner(basis, r1 - 1, c1 - 1, width, height)
    wd, pd = _corner(basis, r1 - 1, c0, width, height)
    extent = max(box[3] - box[0], box[4] - box[1], box[5] - box[2])
    for a in range(3):
        extent = max(extent, abs(box[a]), abs(box[a + 3]), abs(wa[a]), abs(pa[a]))
    margin = _MARGIN * extent
    return (_plane_culls(wa, pa, wb, pb, pc, pd, box, margin)
            or _plane_culls(wb, pb, wc, pc, pd, pa, box, margin)
            or _plane_culls(wc, pc, wd, pd, pa, pb, box, margin)
            or _plane_culls(wd, pd, wa, pa, pb, pc, box, margin))
