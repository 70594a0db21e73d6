"""Screen footprint of the blocks a mode can see: where and how deep a ray can find anything.

A first-hit isosurface can only lie in an active block. Projecting the active blocks' boxes
onto the screen gives, per tile of ``8 x 8`` pixels of the full image, the interval of ray
parameters inside which every ray of the tile that meets an active block meets it: from the
smallest distance of a covering block to the eye to the largest distance of one of its
corners. The driver
(:mod:`.driver`) writes the pixels of a tile that no active block covers without tracing
them (the rays of an object that fills a small part of the screen cost a ray set-up and a
box clip each, a third of a frame on a 128^3 sphere), and starts the others at the tile's
interval, past the empty space in front of the object.

The footprint is conservative, so the image is the one without it: a block's screen box is
the bounding box of its corners' projections widened by a pixel, the interval is widened by
a relative ``1e-9``, a block with a corner at or behind the eye's plane covers the whole
screen, and one wholly behind that plane covers nothing (rays start at the eye). A ray
starting at the interval's start begins in empty space (no covering block is nearer), and
the cell walk then crosses the same cell faces at the same parameters as a ray started at
the volume box; ``tests/test_footprint.py`` checks the images are identical.

Only modes whose result comes from the blocks they name use it: the exact isosurface
methods, DVR's cell-walk samplings ("grid", "pieces") with the visible blocks, and DVR's
fixed-step "ray" sampling with the blocks its segments can take colour from (a visible
block's neighbours, into which a segment from inside it reaches, and pairs of blocks whose
joint value range is visible; the loop widens the interval to the samples around it). Not
the sampled isosurface method, whose samples in front of a block take part in finding a
crossing.

MIP names the blocks holding a value above the grid's smallest: every value elsewhere is that
smallest one, which a ray meets first at its entry into the grid. Its rays are therefore still
traced where the grid's box projects but no named block does, from their entry only
(:data:`ENTRY_ONLY`, see :func:`fill_box`), and the mode's ``entry_left_out`` takes the value
at the entry of every ray whose entry the footprint leaves out, so the air around an object
is neither walked nor sampled. Rays that miss the box (most of the pixels of a view of the
whole volume) are not set up one by one.
"""

from __future__ import annotations

import math
from typing import Any

import numba
import numpy as np

from .._jit import jit
from .._jit.work_queue import run_on_threads, take
from ..camera import (
    BASIS_COL0,
    BASIS_EYE,
    BASIS_FORWARD,
    BASIS_FULL_HEIGHT,
    BASIS_FULL_WIDTH,
    BASIS_HALF_HEIGHT,
    BASIS_HALF_WIDTH,
    BASIS_ORTHO,
    BASIS_RIGHT,
    BASIS_ROW0,
    BASIS_UP,
)
from .rays import GEOM_OFFSET, GEOM_ORIGIN, GEOM_SHIFT, GEOM_SPACING

__all__ = ["FOOTPRINT_SHIFT", "NO_FOOTPRINT", "ENTRY_ONLY", "MAX_PROJECTED_BLOCKS",
           "MAX_PROJECTED_PAIRS", "block_footprint", "fill_box", "footprint_level"]

#: log2 of the edge in pixels of the footprint's tiles. Tiles of 4 pixels measured no better:
#: the finer intervals save little and the projection writes four times as many tiles.
FOOTPRINT_SHIFT = 3

#: The driver's ``footprint`` argument when there is none (every ray is traced whole).
NO_FOOTPRINT = np.zeros((0, 0, 2))

#: Both ends of the interval of a tile whose rays are traced from their entry only (an interval
#: that starts behind every ray's end, yet is not empty: the driver sets its rays up).
ENTRY_ONLY = math.inf

#: Above this many active blocks at a level, the next coarser level is projected instead
#: (its boxes are larger but fewer; projecting costs about 50 ns per block).
MAX_PROJECTED_BLOCKS = 1 << 17

#: A mode that names the 2-cell blocks (the exact isosurface) has them projected when at most
#: this many are active: their boxes hug the surface, so fewer rays that miss it are traced and
#: the rest start nearer to it. Projecting tens of thousands of them (a large or busy surface)
#: costs more than it saves, and the 4-cell blocks are projected instead.
MAX_PROJECTED_PAIRS = 1 << 14

#: Relative widening of a block's parameter interval (the walk's parameters are rounded).
_T_MARGIN = 1e-9


def footprint_level(flags: tuple, limits: tuple) -> int:
    """The finest level of ``flags`` (finest first) with at most ``limits[level]`` active blocks
    (the coarsest if none is); a level given as ``None`` is never chosen (the coarsest level
    must be given)."""
    for level, act in enumerate(flags):
        if act is None:
            continue
        if level == len(flags) - 1 or np.count_nonzero(act) <= limits[level]:
            return level
    return len(flags) - 1


def block_footprint(basis: np.ndarray, geom: np.ndarray, n_cells: Any, active: np.ndarray,
                    shift: int, width: int, height: int) -> np.ndarray:
    """Per-tile ray parameter interval covered by the active blocks of one level.

    Parameters
    ----------
    basis : ndarray
        :meth:`splinecast.Camera.pixel_basis` of the image (or tile) rendered.
    geom : ndarray, shape (19,)
        Placement of the grid (:mod:`.driver`).
    n_cells : 3 ints
        The grid's cells per axis.
    active : ndarray of uint8, shape (bx, by, bz)
        Non-zero for the blocks that can contribute; block ``b`` holds cells
        ``[b << shift, (b + 1) << shift)`` per axis.
    shift : int
        log2 of the block edge in cells.
    width, height : int
        The image's size in pixels.

    Returns
    -------
    ndarray, shape (tiles_y, tiles_x, 2)
        ``[t_start, t_end]`` per tile, empty (``t_start > t_end``) where no active block
        projects. The tiles are those of the full image (:meth:`splinecast.Camera.tile`) that
        the camera's pixels overlap: pixel ``(row, col)`` of the camera lies in tile
        ``((row + row0) >> 3 - (row0 >> 3), (col + col0) >> 3 - (col0 >> 3))``, so an image
        rendered in tiles (a distributed render) traces every ray as the whole image does.
    """
    ncx, ncy, ncz = (int(n) for n in n_cells)
    active = np.ascontiguousarray(active)
    col0, row0 = int(basis[BASIS_COL0]), int(basis[BASIS_ROW0])
    tiles_x = ((col0 + width - 1) >> FOOTPRINT_SHIFT) - (col0 >> FOOTPRINT_SHIFT) + 1
    tiles_y = ((row0 + height - 1) >> FOOTPRINT_SHIFT) - (row0 >> FOOTPRINT_SHIFT) + 1
    # The blocks are projected in ``parts`` slabs of block rows, one interval image each,
    # merged at the end (a frame of the fixed-step DVR projects some 30 000 blocks: 2.3 ms on
    # one core).
    parts = max(1, min(numba.get_num_threads(), active.shape[0]))
    slabs = np.empty((parts, tiles_y, tiles_x, 2))
    slabs[..., 0] = math.inf
    slabs[..., 1] = -math.inf
    next_part = np.zeros(1, np.int64)
    run_on_threads(lambda: _project(basis, geom, active, shift, ncx, ncy, ncz, width, height,
                                    slabs, next_part), parts)
    out = np.empty((tiles_y, tiles_x, 2))
    np.min(slabs[..., 0], axis=0, out=out[..., 0])
    np.max(slabs[..., 1], axis=0, out=out[..., 1])
    return out


def fill_box(tiles: np.ndarray, box: np.ndarray) -> np.ndarray:
    """``tiles`` with the tiles that ``box`` (the footprint of the grid's whole box) covers but
    ``tiles`` leaves empty marked :data:`ENTRY_ONLY` (in place; returned)."""
    entry_only = (tiles[..., 0] > tiles[..., 1]) & (box[..., 0] <= box[..., 1])
    tiles[entry_only] = ENTRY_ONLY
    return tiles


@jit()
def _project(basis, geom, active, shift, ncx, ncy, ncz, width, height, slabs, next_part):
    """One thread's share of :func:`block_footprint`: it takes the next slab of block rows
    (``next_part``: the counter the threads share, :mod:`~splinecast._jit.work_queue`) and
    covers its tiles in that slab's interval image."""
    parts = slabs.shape[0]
    edge = 1 << shift
    ortho = basis[BASIS_ORTHO] != 0.0
    cells = (ncx, ncy, ncz)
    nbx, nby, nbz = active.shape
    per_part = (nbx + parts - 1) // parts
    lo = np.empty(3)
    hi = np.empty(3)
    while True:
        part = take(next_part)
        if part >= parts:
            break
        slab = slabs[part]
        for bi in range(part * per_part, min(nbx, (part + 1) * per_part)):
            for bj in range(nby):
                for bk in range(nbz):
                    if active[bi, bj, bk] == 0:
                        continue
                    index = (bi, bj, bk)
                    for a in range(3):
                        # The block's cells in the traversal space, then in the world.
                        x0 = index[a] * edge
                        x1 = min(x0 + edge, cells[a])
                        origin, spacing = geom[GEOM_ORIGIN + a], geom[GEOM_SPACING + a]
                        model_shift, offset = geom[GEOM_SHIFT], geom[GEOM_OFFSET + a]
                        w0 = origin + (x0 - model_shift + offset) * spacing
                        w1 = origin + (x1 - model_shift + offset) * spacing
                        lo[a] = min(w0, w1)
                        hi[a] = max(w0, w1)
                    _cover(slab, basis, ortho, lo, hi, width, height)


@jit(inline="always")
def _cover(out, basis, ortho, lo, hi, width, height):
    """Widen the intervals of the tiles box ``[lo, hi]`` (world) projects onto (pixels and
    tiles counted in the full image, the camera's window of it kept)."""
    ex, ey, ez = basis[BASIS_EYE], basis[BASIS_EYE + 1], basis[BASIS_EYE + 2]
    sx_lo = sy_lo = math.inf
    sx_hi = sy_hi = -math.inf
    t_near = math.inf
    t_far = -math.inf
    whole_screen = False
    behind = 0
    for c in range(8):
        qx = (hi[0] if c & 1 else lo[0]) - ex
        qy = (hi[1] if c & 2 else lo[1]) - ey
        qz = (hi[2] if c & 4 else lo[2]) - ez
        f, r, u = BASIS_FORWARD, BASIS_RIGHT, BASIS_UP
        depth = qx * basis[f] + qy * basis[f + 1] + qz * basis[f + 2]
        across = qx * basis[r] + qy * basis[r + 1] + qz * basis[r + 2]
        above = qx * basis[u] + qy * basis[u + 1] + qz * basis[u + 2]
        if depth < 0.0:
            behind += 1
        if ortho:
            # Parallel rays: the parameter is the depth below the image plane.
            sx, sy = across, above
            t_near = min(t_near, depth)
            t_far = max(t_far, depth)
        else:
            # The ray parameter is the distance to the eye; a corner at or behind the eye's
            # plane has no projection (the block may then cover any pixel).
            t_far = max(t_far, math.sqrt(qx * qx + qy * qy + qz * qz))
            if depth <= 0.0:
                whole_screen = True
                continue
            sx, sy = across / depth, above / depth
        sx_lo, sx_hi = min(sx_lo, sx), max(sx_hi, sx)
        sy_lo, sy_hi = min(sy_lo, sy), max(sy_hi, sy)
    if behind == 8:
        # The box lies wholly behind the eye's plane (the image plane of parallel rays): rays
        # start there (t >= 0) and move away from it, so none meets the box. Such boxes would
        # otherwise cover the whole screen: a camera looking away from the volume, or inside
        # it, traced every ray, and projecting 16 000 of them over every tile took 50 ms.
        return
    if not ortho:
        # Distance from the eye to the nearest point of the box.
        gx = max(lo[0] - ex, 0.0, ex - hi[0])
        gy = max(lo[1] - ey, 0.0, ey - hi[1])
        gz = max(lo[2] - ez, 0.0, ez - hi[2])
        t_near = math.sqrt(gx * gx + gy * gy + gz * gz)
    # The full image's tiles the camera's window overlaps. A block widens every one of them
    # its screen box meets, also where the box misses the window's own pixels, so a tile
    # camera gets the full image's intervals.
    col0, row0 = int(basis[BASIS_COL0]), int(basis[BASIS_ROW0])
    tx0, tx1 = col0 >> FOOTPRINT_SHIFT, (col0 + width - 1) >> FOOTPRINT_SHIFT
    ty0, ty1 = row0 >> FOOTPRINT_SHIFT, (row0 + height - 1) >> FOOTPRINT_SHIFT
    if not whole_screen:
        # Screen coordinates to pixel columns and rows of the full image (Camera.pixel_basis's
        # formula inverted), widened by a pixel, then to tiles.
        half_w, half_h = basis[BASIS_HALF_WIDTH], basis[BASIS_HALF_HEIGHT]
        full_w, full_h = basis[BASIS_FULL_WIDTH], basis[BASIS_FULL_HEIGHT]
        col_lo = (sx_lo / half_w + 1.0) * 0.5 * full_w - 0.5 - 1.0
        col_hi = (sx_hi / half_w + 1.0) * 0.5 * full_w - 0.5 + 1.0
        row_lo = (1.0 - sy_hi / half_h) * 0.5 * full_h - 0.5 - 1.0
        row_hi = (1.0 - sy_lo / half_h) * 0.5 * full_h - 0.5 + 1.0
        if col_hi < 0.0 or row_hi < 0.0 or col_lo > full_w or row_lo > full_h:
            return
        tx0 = max(tx0, int(math.floor(max(col_lo, 0.0))) >> FOOTPRINT_SHIFT)
        tx1 = min(tx1, int(math.ceil(min(col_hi, full_w))) >> FOOTPRINT_SHIFT)
        ty0 = max(ty0, int(math.floor(max(row_lo, 0.0))) >> FOOTPRINT_SHIFT)
        ty1 = min(ty1, int(math.ceil(min(row_hi, full_h))) >> FOOTPRINT_SHIFT)
    t_start = t_near - _T_MARGIN * (1.0 + abs(t_near))
    t_end = t_far + _T_MARGIN * (1.0 + abs(t_far))
    first_tx, first_ty = col0 >> FOOTPRINT_SHIFT, row0 >> FOOTPRINT_SHIFT
    for ty in range(ty0, ty1 + 1):
        for tx in range(tx0, tx1 + 1):
            a, b = ty - first_ty, tx - first_tx
            out[a, b, 0] = min(out[a, b, 0], t_start)
            out[a, b, 1] = max(out[a, b, 1], t_end)
