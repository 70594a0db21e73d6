"""Integer-state ray traversal of a cell grid (Józsa et al. 2014, section 7).

A ray ``p(t) = o + t d`` is given in *index space* (cell ``(i, j, k)`` spans ``[i, i+1] x [j, j+1] x
[k, k+1]``; voxel centres sit at integer coordinates). The only state carried from step to step is
the integer cell index. Each step recomputes, from those integers and the fixed ray parameters, the
distance to the next grid plane on every axis, ``t_a = (plane_a - o_a) / d_a``, and moves along the
axes whose plane is nearest (several at once when the ray passes exactly through an edge or a
corner). No floating-point quantity is updated incrementally, so rounding errors never accumulate:
a ray crossing a thousand cells is exactly as accurate at the end as at the start.

The step divides by ``d_a`` rather than multiplying by ``1 / d_a``, although divisions are a
tenth of a small volume's isosurface frame: the product rounds twice, the point ``o + t d`` of a
plane crossing then lands further from the plane, and crossings lying exactly on a grid plane
were lost (``tests/test_multi_iso.py``'s nested spheres, whose surfaces pass through voxels).
Clipping to the grid's box (:func:`clip_to_box`) multiplies: it decides where a ray starts, not
where a cell ends. The renderer's walk (:func:`walk_step_cached`) keeps each axis's last plane
and its parameter, so it divides only for the axes whose plane changed: the same divisions of
the same numbers, one instead of three on most cell steps.

The same step also works for aligned blocks of ``size`` cells (a power of two), which is how the
renderer leaps over empty space: leaving a block, the cell index on the crossed axes is exact and
on the other axes is the floor of the exit point, clamped into the block so the walk stays
consistent with the block it just left.

Conventions: a ray lying exactly in a cell face belongs to the cell on the face's positive side
(``floor``), except on the upper face of the grid, which belongs to the last cell. A ray that
starts (or leaves a block) exactly on a grid plane while moving towards the plane's negative side
belongs to the cell below the plane, which it actually enters.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import jit

__all__ = [
    "clip_to_box", "start_cell", "axis_exit", "axis_advance", "walk_begin", "walk_step",
    "walk_cells", "walk_step_cached",
]


#: Below this, a direction component's reciprocal could overflow: the slab tests divide.
_TINY = 1e-300


@jit(inline="always")
def _slab(o: float, d: float, hi: float, t0: float, t1: float) -> tuple[float, float]:
    if d == 0.0:
        if o < 0.0 or o > hi:
            return math.inf, -math.inf
        return t0, t1
    if abs(d) < _TINY:  # 1 / d would overflow
        ta = (0.0 - o) / d
        tb = (hi - o) / d
    else:  # one division and two products (see splinecast.render.rays)
        inv = 1.0 / d
        ta = (0.0 - o) * inv
        tb = (hi - o) * inv
    if ta > tb:
        ta, tb = tb, ta
    return max(t0, ta), min(t1, tb)


@jit()
def clip_to_box(
    ox: float, oy: float, oz: float, dx: float, dy: float, dz: float,
    nx: int, ny: int, nz: int, t_min: float = 0.0, t_max: float = math.inf,
) -> tuple[float, float]:
    """Parameter interval ``[t_near, t_far]`` of the ray inside ``[0, n_a]`` on every axis.

    ``nx, ny, nz`` are the numbers of cells. Only ``t_min <= t <= t_max`` is kept (by default
    ``t >= 0``: the ray starts at ``o``). An empty interval has ``t_near > t_far``.
    """
    t0, t1 = t_min, t_max
    t0, t1 = _slab(ox, dx, float(nx), t0, t1)
    t0, t1 = _slab(oy, dy, float(ny), t0, t1)
    t0, t1 = _slab(oz, dz, float(nz), t0, t1)
    return t0, t1


@jit(inline="always")
def _cell_index(p: float, d: float) -> float:
    """Cell holding coordinate ``p`` for a ray moving with slope ``d`` on this axis.

    On a grid plane a ray moving down belongs to the cell below it (it never enters the one
    above); otherwise, and for rays parallel to the axis, the cell above (``floor``).
    """
    if d < 0.0:
        return math.ceil(p) - 1.0
    return math.floor(p)


@jit(inline="always")
def _start_index(o: float, d: float, t: float, n: int) -> int:
    v = _cell_index(o + t * d, d)
    if v < 0:
        return 0
    if v > n - 1:
        return n - 1
    return int(v)


@jit()
def start_cell(
    ox: float, oy: float, oz: float, dx: float, dy: float, dz: float, t: float,
    nx: int, ny: int, nz: int,
) -> tuple[int, int, int]:
    """Cell containing the ray point at ``t`` (the entry point), clamped into the grid."""
    return (_start_index(ox, dx, t, nx), _start_index(oy, dy, t, ny), _start_index(oz, dz, t, nz))


@jit(inline="always")
def axis_exit(c: int, o: float, d: float, size: int) -> tuple[int, float]:
    """Next grid plane on one axis when leaving the aligned block of ``size`` cells holding ``c``.

    Returns the plane's integer coordinate and the ray parameter where it is crossed
    (``inf`` when the ray is parallel to the axis).
    """
    plane = _axis_plane(c, d, size)
    if not (d > 0.0 or d < 0.0):  # parallel to the axis (or NaN): never crossed
        return plane, math.inf
    return plane, (plane - o) / d


@jit(inline="always")
def _axis_plane(c: int, d: float, size: int) -> int:
    """The plane a ray moving with slope ``d`` leaves the block of ``size`` cells around ``c``
    through (the block's lower plane when ``d`` is 0)."""
    start = c & -size  # size is a power of two and c >= 0: clear the low bits
    return start + size if d > 0.0 else start


@jit(inline="always")
def axis_advance(
    c: int, plane: int, t_axis: float, t_exit: float, o: float, d: float, size: int, n: int
) -> int:
    """Cell index on one axis after leaving the current block at ``t_exit``.

    Axes whose plane is crossed at ``t_exit`` step exactly to the neighbouring cell; on the other
    axes a cell step keeps the index and a block step takes the floor of the exit point, clamped
    into the block that was just left. The result may be ``-1`` or ``n`` (the ray left the grid).
    """
    if t_axis <= t_exit:
        return plane if d > 0.0 else plane - 1
    if size == 1:
        return c
    start = c & -size  # size is a power of two and c >= 0: clear the low bits
    end = min(start + size - 1, n - 1)
    v = _cell_index(o + t_exit * d, d)
    if v < start:
        return start
    if v > end:
        return end
    return int(v)


@jit(inline="always")
def walk_begin(
    ox: float, oy: float, oz: float, dx: float, dy: float, dz: float, nx: int, ny: int, nz: int,
    t_min: float = 0.0, t_max: float = math.inf,
) -> tuple[bool, int, int, int, float, float]:
    """Start a walk: ``(inside, i, j, k, t_near, t_far)`` for the ray's entry into the grid.

    ``[t_min, t_max]`` restricts the ray further (clip planes, a crop box).
    """
    t_near, t_far = clip_to_box(ox, oy, oz, dx, dy, dz, nx, ny, nz, t_min, t_max)
    if not t_near <= t_far:
        return False, -1, -1, -1, t_near, t_far
    ci, cj, ck = start_cell(ox, oy, oz, dx, dy, dz, t_near, nx, ny, nz)
    return True, ci, cj, ck, t_near, t_far


@jit(inline="always")
def walk_step(
    origin: tuple, direction: tuple, cells: tuple, ci: int, cj: int, ck: int, t: float,
    t_far: float, size: int,
) -> tuple[float, bool, int, int, int, float]:
    """Leave the aligned block of ``size`` cells around cell ``(ci, cj, ck)``, entered at ``t``,
    of the ray ``origin + t direction`` (``(x, y, z)`` tuples) through a grid of ``cells``
    (``(nx, ny, nz)``).

    Returns ``(t_end, more, i, j, k, t_next)``: the block's segment is ``[t, t_end]`` (clipped to
    the grid), ``more`` tells whether the ray goes on into cell ``(i, j, k)`` at ``t_next``.
    Every model's kernel walks its rays with :func:`walk_begin` and this function::

        inside, i, j, k, t, t_far = walk_begin(...)
        while inside:
            size = <1 for a cell to process, or the edge of an empty block to leap over>
            t_end, inside, ni, nj, nk, t_next = walk_step(o, d, n, i, j, k, t, t_far, size)
            <process the segment [t, t_end] of cell or block (i, j, k)>
            i, j, k, t = ni, nj, nk, t_next
    """
    return walk_step_cached(origin, direction, cells, ci, cj, ck, t, t_far, size,
                            _NO_CROSSINGS)[:6]


#: The cached step's ``crossings`` before a walk's first step: planes no walk produces.
_NO_CROSSINGS = (-2, 0.0, -2, 0.0, -2, 0.0)


@jit(inline="always")
def _axis_exit_cached(c: int, o: float, d: float, size: int, plane_c: int,
                      t_c: float) -> tuple[int, float]:
    """:func:`axis_exit`, reusing ``t_c`` when the plane is ``plane_c`` (the same division)."""
    plane = _axis_plane(c, d, size)
    if not (d > 0.0 or d < 0.0):  # parallel to the axis (or NaN): never crossed
        return plane, math.inf
    if plane == plane_c:
        return plane, t_c
    return plane, (plane - o) / d


@jit(inline="always")
def walk_step_cached(
    origin: tuple, direction: tuple, cells: tuple, ci: int, cj: int, ck: int, t: float,
    t_far: float, size: int, crossings: tuple,
) -> tuple:
    """:func:`walk_step` with each axis's last plane and its parameter carried from step to
    step (``crossings``: ``(px, tx, py, ty, pz, tz)``; a walk starts with planes that never
    occur, ``-2``): an axis the ray did not cross keeps its plane, and its division is not
    repeated. The parameters are the same divisions of the same numbers, so the walk is
    identical (``tests/test_walk_cached.py``). Returns :func:`walk_step`'s tuple and the
    updated ``crossings``."""
    ox, oy, oz = origin
    dx, dy, dz = direction
    nx, ny, nz = cells
    px, tx = _axis_exit_cached(ci, ox, dx, size, crossings[0], crossings[1])
    py, ty = _axis_exit_cached(cj, oy, dy, size, crossings[2], crossings[3])
    pz, tz = _axis_exit_cached(ck, oz, dz, size, crossings[4], crossings[5])
    crossings = (px, tx, py, ty, pz, tz)
    t_exit = min(tx, ty, tz)
    t_end = min(t_exit, t_far)
    if t_exit >= t_far:
        return t_end, False, ci, cj, ck, t, crossings
    ni = axis_advance(ci, px, tx, t_exit, ox, dx, size, nx)
    nj = axis_advance(cj, py, ty, t_exit, oy, dy, size, ny)
    nk = axis_advance(ck, pz, tz, t_exit, oz, dz, size, nz)
    if ni < 0 or ni >= nx or nj < 0 or nj >= ny or nk < 0 or nk >= nz:
        return t_end, False, ci, cj, ck, t, crossings
    # A block exit can lie a rounding error before t on a non-crossing axis; never go back.
    return t_end, True, ni, nj, nk, max(t, t_exit), crossings


@jit()
def walk_cells(
    origin: np.ndarray, direction: np.ndarray, n_cells: np.ndarray, max_cells: int = 100000
) -> np.ndarray:
    """Cells a ray visits, in order, with the renderer's traversal (no empty-space skipping).

    Parameters
    ----------
    origin, direction : ndarray, shape (3,)
        The ray in index space (``direction`` need not be unit length).
    n_cells : ndarray of int, shape (3,)
        Number of cells per axis (number of voxels minus one).
    max_cells : int
        Safety bound on the output length.

    Returns
    -------
    ndarray of int64, shape (m, 3)
        The visited cells. A cell the ray only touches in an edge or corner is not listed.
    """
    ox, oy, oz = origin[0], origin[1], origin[2]
    dx, dy, dz = direction[0], direction[1], direction[2]
    nx, ny, nz = n_cells[0], n_cells[1], n_cells[2]
    out = np.empty((max_cells, 3), dtype=np.int64)
    inside, ci, cj, ck, t, t_far = walk_begin(ox, oy, oz, dx, dy, dz, nx, ny, nz)
    if not t < t_far:
        return out[:0]
    count = 0
    crossings = _NO_CROSSINGS
    while inside and count < max_cells:
        out[count, 0] = ci
        out[count, 1] = cj
        out[count, 2] = ck
        count += 1
        # The renderer's step (tests/test_traversal.py checks it against exact crossings).
        _, inside, ci, cj, ck, t, crossings = walk_step_cached(
            (ox, oy, oz), (dx, dy, dz), (nx, ny, nz), ci, cj, ck, t, t_far, 1, crossings
        )
    return out[:count]
