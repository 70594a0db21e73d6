"""One compiled launch for a whole cut: every drawable of it, front to back per ray, tile by tile.

A multiresolution frame is drawn from many grids (the bricks of a cut, each with its own kernel
grid, block flags, placement and box). Tracing them one driver call at a time costs a parallel
launch, a camera tile, and copies of the mode's per-pixel state per drawable -- milliseconds each,
far more than a small brick's rays on a shared machine. :func:`trace_cut` instead runs once
per frame: parallel over screen tiles, each tile walks the drawables overlapping it in the given
(front-to-back) order and calls the (model, mode) pair's compiled band of the driver
(:func:`.driver.pair_band`, the in-memory renderer's own loop) on the pixels of the drawable's
screen rectangle, with the ray's interval inside the drawable's box as its ``t_range``. The
mode's state stays in the full-image state arrays (``load`` and ``store`` per drawable, as the
segment entry point does), so a ray sees exactly the sequence of grids and intervals of one
:func:`.segment.trace_segment` call per drawable. A ray whose state is ``done`` (a first hit,
opaque) is left out of the drawables behind it, and a tile stops once all its rays are: the
driver would only load and store such a state. With ``fresh`` and ``final`` the launch
also resets the states and writes the outputs (the driver's ``reset_state`` and ``finalize``)
tile by tile, so a frame is one pass.

Grids come in typed lists of ``(kernel, blocks)`` pairs. All pairs of one list have one Numba
type; a cut may hold two (a pyramid's bricks in the store's dtype and the float64 copies of
bricks changed at a level seam), so the launch takes two lists, and ``which[p]`` says in which
list and where drawable ``p``'s pair is.

The first-hit isosurface's seam closure (:class:`splinecast.multires.draw.seams.IsoClosure`) runs
inside the launch too (``close``): per ray, where it left the last drawable without a hit, the
field there and that drawable's level; entering a drawable of another level at the same parameter
with the field on the other side of the isovalue is a hit on the face. Other modes compile the
closure away.
"""

from __future__ import annotations

import math
from collections import namedtuple
from typing import Any

import numba
import numpy as np

from .._jit import bind_first_classes, first_class, jit, overload_jit
from .._jit.work_queue import run_on_threads, take
from ..models.pieces import new_scratch, value_gradient_at
from .clipping import box_slab, clip_interval
from .driver import Buffers, Counters, Passes, Pixel, RaySetup, Rect, band_types, pair_band
from .iso import IsoMode
from .mode_api import done, finish, mode_scratch, state_load, state_new, state_store
from .rays import GEOM_SPACING, Ray, grid_point, index_axis, pixel_ray

__all__ = ["trace_cut", "tile_lists", "box_interval", "TILE", "Cut", "View", "Tiles",
           "FrameEnds", "Seam", "TileRays"]

# The launch's argument groups (numba passes a named tuple as its fields; :func:`trace_cut`
# describes each field).

Cut = namedtuple("Cut", ("grids_a", "grids_b", "which", "geoms", "boxes", "closed", "rects",
                         "levels", "origin0", "spacing0"))
Cut.__doc__ = """The drawables of a cut: their grids (two typed lists), placements, boxes and the
boxes' index space, screen rectangles and levels (:func:`trace_cut`' parameters of those
names)."""

View = namedtuple("View", ("basis", "planes", "t_range"))
View.__doc__ = """The image's rays: the camera's pixel basis, the clip planes, and each ray's
interval in the drawable being traced (work space, shape (height, width, 2))."""

Tiles = namedtuple("Tiles", ("order", "start", "drawables", "counter"))
Tiles.__doc__ = """The screen tiles: first row and column of each (``order``, in the order handed
out), the drawables overlapping each (``start``, ``drawables``: :func:`tile_lists`), and the shared
one-element int64 counter the threads take the next tile from
(:func:`~splinecast._jit.work_queue.take`)."""

FrameEnds = namedtuple("FrameEnds", ("fresh", "final"))
FrameEnds.__doc__ = """Whether the launch resets the states first (``fresh``) and writes the
outputs at the end (``final``), tile by tile (booleans)."""

Seam = namedtuple("Seam", ("close", "exit_t", "exit_drawable", "exit_level"))
Seam.__doc__ = """The isosurface's seam closure: whether it runs (``close``), and per pixel where
the ray left the last drawable without a hit, that drawable and its level (work arrays)."""

TileRays = namedtuple("TileRays", ("row0", "col0", "ended"))
TileRays.__doc__ = """One tile of :data:`TILE` pixels: its first row and column, and which of its
rays ended (``done``) in a drawable already traced (bool array (TILE, TILE))."""

#: Edge in pixels of the square screen tiles the launch hands out to threads: small enough for
#: a balanced split of a 256x192 image over a few threads, large enough that a tile's pixels
#: reuse a drawable's cells and the per-(tile, drawable) set-up is small next to its rays.
TILE = 16


def tile_lists(rects: np.ndarray, height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """The drawables overlapping each tile of :data:`TILE` pixels, in the order of ``rects``.

    Parameters
    ----------
    rects : ndarray (n, 4) of int64
        ``(col0, row0, col1, row1)`` of each drawable (end exclusive), inside the image.
    height, width : int
        The image's size.

    Returns
    -------
    tile_start, tile_drawables : ndarray of int64
        Tile ``t`` (row-major over the tile grid) has drawables
        ``tile_drawables[tile_start[t]:tile_start[t + 1]]``, ascending. A tile walking every
        drawable's rectangle instead cost tens of milliseconds per frame for cuts of ten
        thousand drawables.
    """
    rects = np.asarray(rects, dtype=np.int64).reshape(-1, 4)
    ncol = (width + TILE - 1) // TILE
    nrow = (height + TILE - 1) // TILE
    empty = (rects[:, 2] <= rects[:, 0]) | (rects[:, 3] <= rects[:, 1])
    c0, r0 = rects[:, 0] // TILE, rects[:, 1] // TILE
    c1 = np.where(empty, c0, (rects[:, 2] - 1) // TILE + 1)
    r1 = np.where(empty, r0, (rects[:, 3] - 1) // TILE + 1)
    nc, nr = c1 - c0, r1 - r0
    count = nc * nr
    drawable = np.repeat(np.arange(len(rects), dtype=np.int64), count)
    # Position of each pair inside its drawable's block of tiles, then its tile's number.
    k = np.arange(int(count.sum()), dtype=np.int64) - np.repeat(np.cumsum(count) - count, count)
    width_p = np.repeat(nc, count)
    tile = (np.repeat(r0, count) + k // np.maximum(width_p, 1)) * ncol + np.repeat(c0, count) \
        + k % np.maximum(width_p, 1)
    order = np.argsort(tile, kind="stable")  # stable: drawables stay in order within a tile
    tile_start = np.zeros(nrow * ncol + 1, dtype=np.int64)
    np.cumsum(np.bincount(tile, minlength=nrow * ncol), out=tile_start[1:])
    return tile_start, np.ascontiguousarray(drawable[order])


@jit(inline="always")
def box_interval(basis, origin, spacing, lo, hi, closed, planes, row, col, width, height):
    """Parameter interval ``(t0, t1)`` of pixel ``(row, col)``'s ray inside the index box
    ``[lo, hi]`` (index ``v`` at ``origin + v * spacing``), clipped by ``planes``; ``t0 > t1``
    when the ray misses it (also what :func:`splinecast.multires.draw.probe.box_ranges`
    computes)."""
    wx, wy, wz, ux, uy, uz = pixel_ray(basis, row, col, width, height)
    t0, t1 = clip_interval(planes, wx, wy, wz, ux, uy, uz)
    vx, dx = index_axis(wx, ux, origin[0], spacing[0])  # the index ray as grid_ray makes it
    vy, dy = index_axis(wy, uy, origin[1], spacing[1])
    vz, dz = index_axis(wz, uz, origin[2], spacing[2])
    t0, t1 = box_slab(vx, dx, lo[0], hi[0], closed[0], t0, t1)
    t0, t1 = box_slab(vy, dy, lo[1], hi[1], closed[1], t0, t1)
    t0, t1 = box_slab(vz, dz, lo[2], hi[2], closed[2], t0, t1)
    return t0, t1


@jit(inline="always")
def _field_at(kernel, scr, geom, basis, row, col, width, height, t):
    """Value and world gradient of the grid's reconstruction at parameter ``t`` of the ray
    (the point as :func:`.rays.grid_point` computes it)."""
    x, y, z = grid_point(geom, basis, row, col, width, height, t)
    v, gx, gy, gz = value_gradient_at(kernel, scr, x, y, z)
    return v, gx / geom[GEOM_SPACING], gy / geom[GEOM_SPACING + 1], gz / geom[GEOM_SPACING + 2]


# The closure reads and writes the isosurface mode's state (depth, world gradient): it is
# compiled for IsoMode only, every other mode gets the no-op. Where a ray left a drawable is noted
# for every drawable; the field there is evaluated only when the ray enters a drawable of another
# level at that parameter (few rays: the seams), from the drawable it left.

def closure_enter(mode, state, basis, pixel, t_in, t_out, drawable, kernel, scr, cut, seam):
    """Before drawable number ``drawable`` of ``cut``, whose grid is ``kernel`` (scratch ``scr``):
    a hit on its entry face if the field jumps across the isovalue there (compiled code only);
    returns 1 for a hit, else 0."""
    raise NotImplementedError


def closure_leave(mode, state, row, col, t_in, t_out, level, drawable, exit_t, exit_drawable,
                  exit_level):
    """After a drawable: where a ray without a hit left it (compiled code only)."""
    raise NotImplementedError


# Reference counting on (``_nrt=True``) although its caller runs without: it allocates the
# scratch of the other drawable's grid (see :func:`_drawable_pixels`).
@jit(_nrt=True)
def _exit_value(grids_a, grids_b, which, geoms, q, basis, row, col, width, height, t):
    """The field of drawable ``q`` (as drawn) at parameter ``t`` of the ray."""
    if which[q, 0] == 0:
        pair_a = grids_a[which[q, 1]]
        v, _, _, _ = _field_at(pair_a[0], new_scratch(pair_a[0]), geoms[q], basis, row, col,
                               width, height, t)
        return v
    pair_b = grids_b[which[q, 1]]
    v, _, _, _ = _field_at(pair_b[0], new_scratch(pair_b[0]), geoms[q], basis, row, col, width,
                           height, t)
    return v


@jit()
def _iso_enter(mode, state, basis, pixel, t_in, t_out, drawable, kernel, scr, cut, seam):
    # The caller checked that the ray left a drawable of another level at t_in.
    row, col, width, height = pixel
    geom = cut.geoms[drawable]
    depth, gradient = state[0], state[1]
    if not (t_in <= t_out and depth[row, col] == math.inf):
        return 0
    before = _exit_value(cut.grids_a, cut.grids_b, cut.which, cut.geoms,
                         seam.exit_drawable[row, col], basis, row, col, width, height,
                         t_in) - mode.iso
    v, gx, gy, gz = _field_at(kernel, scr, geom, basis, row, col, width, height, t_in)
    g = v - mode.iso
    if g == 0.0 or (g < 0.0) != (before < 0.0):
        depth[row, col] = t_in
        gradient[row, col, 0] = gx
        gradient[row, col, 1] = gy
        gradient[row, col, 2] = gz
        return 1
    return 0


@jit()
def _iso_leave(mode, state, row, col, t_in, t_out, level, drawable, exit_t, exit_drawable,
               exit_level):
    if t_in <= t_out and state[0][row, col] == math.inf:
        exit_t[row, col] = t_out
        exit_drawable[row, col] = drawable
        exit_level[row, col] = level
    return 0


@jit()
def _no_enter(mode, state, basis, pixel, t_in, t_out, drawable, kernel, scr, cut, seam):
    return 0


@jit()
def _no_leave(mode, state, row, col, t_in, t_out, level, drawable, exit_t, exit_drawable,
              exit_level):
    return 0


def _is_iso(mode) -> bool:
    return getattr(mode, "instance_class", None) is IsoMode


@overload_jit(closure_enter, inline="never")
def _closure_enter(mode, state, basis, pixel, t_in, t_out, drawable, kernel, scr, cut, seam):
    return (_iso_enter if _is_iso(mode) else _no_enter).py_func


@overload_jit(closure_leave, inline="always")
def _closure_leave(mode, state, row, col, t_in, t_out, level, drawable, exit_t, exit_drawable,
                   exit_level):
    return (_iso_leave if _is_iso(mode) else _no_leave).py_func


@jit()
def _box_intervals(view, origin0, spacing0, box_lo, box_hi, closed, tile, rect, width, height):
    """Each ray's interval in a drawable's box ``[box_lo, box_hi]`` (in the index space placed by
    ``origin0`` and ``spacing0``) over the rectangle ``rect``, into ``view.t_range`` (empty for
    a ray that ended in a drawable in front, ``tile.ended``, or misses the box); returns how many
    rays have one. A function of its own, called per drawable: the same for every model and mode,
    it compiles once instead of once in each pair's tile function."""
    basis, planes, t_range = view
    tr0, tc0, ended = tile
    r0, r1, c0, c1 = rect.r0, rect.r1, rect.c0, rect.c1
    traced = 0
    for row in range(r0, r1):
        for col in range(c0, c1):
            if ended[row - tr0, col - tc0]:
                # The ray ended in a drawable in front (a first hit, opaque): the driver would
                # load its state, see it done and store it unchanged.
                t_range[row, col, 0] = math.inf
                t_range[row, col, 1] = -math.inf
                continue
            t0, t1 = box_interval(basis, origin0, spacing0, box_lo, box_hi, closed, planes, row,
                                  col, width, height)
            t_range[row, col, 0] = t0
            t_range[row, col, 1] = t1
            if t0 <= t1:  # else the ray misses the box: the driver would leave its state alone
                traced += 1
    return traced


# Without Numba's reference counting, as the driver's band (:func:`.driver._trace_band`): the
# closure's hooks take the mode's state tuple and would count every array in it at each call.
# Nothing here allocates; the closure's evaluation of another drawable's grid, which does, is
# compiled with counting (:func:`_exit_value`). No Python entry: unboxing the typed lists of
# its arguments needs counting.
@jit(_nrt=False, no_cpython_wrapper=True)
def _drawable_pixels(band, pair, mode, state, out, cut, view, drawable, rect, tile, seam, counters,
                     buffers):
    """Trace the pixels of ``rect`` (a :class:`.driver.Rect` inside ``tile``) through drawable
    number ``drawable`` of ``cut``, whose ``(kernel, blocks)`` is ``pair``; returns the closure's
    hits and the number of rays that ended in it (marked in ``tile.ended``). ``buffers``: the
    band's, allocated by the caller (:func:`_trace_tile`).

    Three passes over the rectangle: each ray's interval in the drawable's box
    (:func:`_box_intervals`) and the closure's test on entry; the
    pair's compiled band over the rectangle, which traces exactly the rays with an interval
    (the driver's per-pixel unit, compiled once per model, mode and types and shared with the
    in-memory renderer); then the closure's note on exit and which rays ended here."""
    kernel, blocks = pair[0], pair[1]
    basis, t_range = view.basis, view.t_range
    r0, r1, c0, c1 = rect.r0, rect.r1, rect.c0, rect.c1
    tr0, tc0, ended = tile
    close, exit_t, exit_drawable, exit_level = seam
    level = cut.levels[drawable]
    height, width = counters.visited.shape
    traced = _box_intervals(view, cut.origin0, cut.spacing0, cut.boxes[drawable, 0],
                            cut.boxes[drawable, 1], cut.closed[drawable], tile, rect, width, height)
    if traced == 0:
        return 0, 0
    hits = 0
    if close:
        for row in range(r0, r1):
            for col in range(c0, c1):
                t0 = t_range[row, col, 0]
                t1 = t_range[row, col, 1]
                # The closure's cheap test first (a ray leaving a drawable of another level right
                # here): calls with this many arguments cost more than the rest of a short ray.
                if t0 <= t1 and exit_t[row, col] == t0 and exit_level[row, col] != level:
                    hits += closure_enter(mode, state, basis, Pixel(row, col, width, height),
                                          t0, t1, drawable, kernel, buffers.model, cut, seam)
    # Flags as values of the launch's own arguments, not constants: a constant argument would
    # be typed as a literal and compile the band again instead of sharing the in-memory one.
    yes = tr0 >= 0
    # No footprint (an empty view of t_range: a C array like the in-memory renderer's, so the
    # band compiled for it serves here too).
    band(kernel, mode, blocks, state, out,
         RaySetup(basis, cut.geoms[drawable], view.planes, t_range, t_range[:0]), rect,
         Passes(yes, yes, not yes, yes), counters, buffers)
    n_ended = 0
    for row in range(r0, r1):
        for col in range(c0, c1):
            t0 = t_range[row, col, 0]
            t1 = t_range[row, col, 1]
            if t0 > t1:
                continue
            if close:
                closure_leave(mode, state, row, col, t0, t1, level, drawable, exit_t, exit_drawable,
                              exit_level)
            if done(mode, state_load(mode, state, row, col)):
                ended[row - tr0, col - tc0] = True
                n_ended += 1
    return hits, n_ended


# No Python entry: called only through its address (:func:`_launch_functions`), and the entry's
# unboxing of these arguments is a sizeable share of the function's compile.
@jit(no_cpython_wrapper=True)
def _trace_tile(band_a, band_b, mode, state, out, cut, view, tiles, n, ends, seam, counters):
    """One thread's work item: the drawables overlapping tile number ``n`` of ``tiles``, in order
    (the tile's states reset first when ``ends.fresh``, its outputs written at the end when
    ``ends.final``)."""
    tr0, tc0 = tiles.order[n, 0], tiles.order[n, 1]
    fresh, final = ends
    rects, which = cut.rects, cut.which
    basis = view.basis
    height, width = counters.visited.shape
    tr1 = min(tr0 + TILE, height)
    tc1 = min(tc0 + TILE, width)
    mscr = mode_scratch(mode)
    # The band's buffers, and below a model scratch per drawable (some models cache cells of their
    # grid in it): allocated here, with reference counting; the pixels run without it
    # (:func:`_drawable_pixels`).
    cuts = np.empty(8)
    tags = np.empty(8, np.int64)
    # Rays of the tile that ended (``done``) are left out of the drawables behind, and the tile
    # stops when all have: a first hit near the front otherwise still pays every drawable's
    # interval and state round trip behind it.
    ended = np.zeros((TILE, TILE), np.bool_)
    tile_rays = TileRays(tr0, tc0, ended)
    alive = 0
    for row in range(tr0, tr1):
        for col in range(tc0, tc1):
            if fresh:
                state_store(mode, state, row, col, state_new(mode))
            if done(mode, state_load(mode, state, row, col)):
                ended[row - tr0, col - tc0] = True
            else:
                alive += 1
    hits = 0
    tile = (tr0 // TILE) * ((width + TILE - 1) // TILE) + tc0 // TILE
    for q in range(tiles.start[tile], tiles.start[tile + 1]):
        if alive == 0:
            break
        p = tiles.drawables[q]
        c0 = max(rects[p, 0], tc0)
        r0 = max(rects[p, 1], tr0)
        c1 = min(rects[p, 2], tc1)
        r1 = min(rects[p, 3], tr1)
        if c0 >= c1 or r0 >= r1:
            continue
        rect = Rect(r0, r1, c0, c1, c1 - c0, r1 - r0)
        if which[p, 0] == 0:
            pair_a = cut.grids_a[which[p, 1]]
            h, e = _drawable_pixels(band_a, pair_a, mode, state, out, cut, view, p, rect,
                                    tile_rays, seam, counters,
                                    Buffers(new_scratch(pair_a[0]), mscr, cuts, tags))
        else:
            # Another name than above: the two lists may hold different types.
            pair_b = cut.grids_b[which[p, 1]]
            h, e = _drawable_pixels(band_b, pair_b, mode, state, out, cut, view, p, rect,
                                    tile_rays, seam, counters,
                                    Buffers(new_scratch(pair_b[0]), mscr, cuts, tags))
        hits += h
        alive -= e
    if final:
        # As the driver's ``finalize``, while the tile's states are still in the cache.
        for row in range(tr0, tr1):
            for col in range(tc0, tc1):
                wx, wy, wz, ux, uy, uz = pixel_ray(basis, row, col, width, height)
                ray = Ray(wx, wy, wz, ux, uy, uz, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 0.0)
                finish(mode, out, row, col, state_load(mode, state, row, col), ray)
    return hits


@jit()
def _launch(tile_fn, band_a, band_b, mode, state, out, cut, view, tiles, ends, seam, counters):
    """One thread's share of :func:`trace_cut`: it takes the next tile (``tiles.counter``:
    the counter the threads share, :mod:`~splinecast._jit.work_queue`) until none is left and
    returns the closure's hits. ``tile_fn`` is the pair's :func:`_trace_tile` as a first-class
    function, so this function compiles without the tile's code."""
    hits = 0
    while True:
        n = take(tiles.counter)
        if n >= tiles.order.shape[0]:
            break
        hits += tile_fn(band_a, band_b, mode, state, out, cut, view, tiles, n, ends, seam,
                        counters)
    return hits


def trace_cut(grids_a, grids_b, which, mode, state, out, basis, geoms, boxes, closed, rects,
              levels, origin0, spacing0, planes, t_range, tiles, tile_start, tile_drawables,
              fresh, final, close, exit_t, exit_drawable, exit_level, visited, tested, skipped):
    """Trace every pixel through the drawables of a cut, front to back, in one launch.

    All parameters are prepared by :class:`splinecast.multires.draw.cut_renderer.CutRenderer`.

    Parameters
    ----------
    grids_a, grids_b : typed List of (kernel, blocks)
        The drawables' kernel grids and the mode's view of their block hierarchies, one Numba
        type per list.
    which : ndarray (n, 2) of int64
        Drawable ``p``'s list (0: ``grids_a``, 1: ``grids_b``) and index in it; drawables in the
        order they are traced (front to back).
    mode : named tuple
        The mode's parameters.
    state, out : tuples of arrays
        The mode's full-image state arrays (updated in place) and output buffers (written
        only with ``final``).
    basis : ndarray (20,)
        :meth:`Camera.pixel_basis` of the image.
    geoms : ndarray (n, 19)
        The drawables' grid placements (:mod:`.driver`).
    boxes : ndarray (n, 2, 3)
        The drawables' boxes (lo, hi) in the index space placed by ``origin0``/``spacing0``.
    closed : ndarray (n, 3) of bool
        Whether a ray lying in a box's upper face plane belongs to the box.
    rects : ndarray (n, 4) of int64
        Screen rectangle ``(col0, row0, col1, row1)`` the drawable's box can project to.
    levels : ndarray (n,) of int64
        The drawables' levels (for the closure).
    origin0, spacing0 : ndarray (3,)
        World placement of the boxes' index space.
    planes : ndarray (m, 4)
        Clip planes.
    t_range : ndarray (height, width, 2)
        Work space: each ray's interval in the drawable being traced.
    tiles : ndarray (k, 2) of int64
        First row and column of each tile of :data:`TILE` pixels, in the order handed out
        (they cover the image).
    tile_start, tile_drawables : ndarray of int64
        The drawables whose rectangle overlaps each tile, in order: those of the tile in tile row
        ``r``, column ``c`` (``r * ceil(width / TILE) + c``) are
        ``tile_drawables[tile_start[t]:tile_start[t + 1]]`` (:func:`tile_lists`).
    fresh, final : bool
        Start from fresh states (the state arrays' contents are ignored) as the driver's
        ``reset_state`` does, and write the outputs at the end as its ``finalize`` does: a
        whole frame in one launch, each tile's states touched while in the cache.
    close : bool
        Run the isosurface's seam closure (``exit_t``, ``exit_drawable``, ``exit_level``:
        per-pixel work arrays, NaN, any and -1 at the start).
    visited, tested, skipped : ndarray of int32, shape (height, width)
        Per-ray statistics, incremented.

    Returns
    -------
    int
        Rays the closure ended on a face.
    """
    args = (mode, state, out,
            Cut(grids_a, grids_b, which, geoms, boxes, closed, rects, levels, origin0, spacing0),
            View(basis, planes, t_range), Tiles(tiles, tile_start, tile_drawables,
                                                np.zeros(1, np.int64)),
            FrameEnds(bool(fresh), bool(final)),
            Seam(bool(close), exit_t, exit_drawable, exit_level),
            Counters(visited, tested, skipped))
    # A list of grids that is empty (the float64 copies at level seams in most frames; the
    # float32 list of a float64 store) calls no band: a stub of the band's signature stands in
    # for it, compiled in a moment where the band would take as long as the other's.
    if _length(grids_b) == 0:
        functions = _launch_functions_a
    elif _length(grids_a) == 0:
        functions = _launch_functions_b
    else:
        functions = _launch_functions
    work = bind_first_classes(_launch, functions, args)
    return sum(run_on_threads(work, max(1, min(numba.get_num_threads(), len(tiles)))))


@jit()
def _length(items: Any) -> int:
    """``len`` of a typed List, compiled once and cached (``len`` from Python compiles numba's
    own helper in every process)."""
    return len(items)


def _launch_functions_a(kinds: tuple) -> tuple:
    """:func:`_launch_functions` for a cut whose second list of grids is empty."""
    return _launch_functions(kinds, stub_b=True)


def _launch_functions_b(kinds: tuple) -> tuple:
    """:func:`_launch_functions` for a cut whose first list of grids is empty."""
    return _launch_functions(kinds, stub_a=True)


@jit()
def _no_band(kernel, mode, blocks, state, out, setup, rect, passes, counters, buffers):
    """Stands for the band of an empty list of grids (never called)."""
    return None


def _launch_functions(kinds: tuple, stub_a: bool = False, stub_b: bool = False) -> tuple:
    """The functions :func:`_launch` calls, as first-class values, from the Numba types
    ``kinds`` of :func:`trace_cut`' arguments: the tile function, then the pair's band
    (:func:`.driver.pair_band`) for the kernel grids of each of the two lists.

    Passed as values, neither is linked into its caller: the band is the in-memory renderer's
    compiled code, called once per drawable and tile, and the tile function compiles without it
    (linked in, its library was optimized and translated again with the whole band in it, for
    every pair and grid type: the costliest compiles of a pyramid's first frame). One tile
    function serves every pair; its compiled code differs by the argument types only."""
    mode, cut = kinds[0], kinds[3]
    grids_a, grids_b = cut.types[0], cut.types[1]
    grid_class = grids_a.item_type[0].instance_class
    band = pair_band(grid_class, mode.instance_class)
    bands = (first_class(_no_band if stub_a else band, _band_types(grids_a.item_type, kinds)),
             first_class(_no_band if stub_b else band, _band_types(grids_b.item_type, kinds)))
    tile_types = (*(numba.typeof(b) for b in bands), *kinds[:6], numba.int64, *kinds[6:])
    return (first_class(_trace_tile, tile_types), *bands)


def _band_types(pair: Any, kinds: tuple) -> tuple:
    """The argument types of the band :func:`_drawable_pixels` calls for the grids of a list
    whose items (``(kernel, blocks)``) have the Numba type ``pair``, from the types ``kinds``
    of :func:`_launch`'s arguments after the functions."""
    mode, state, out, cut, view, _, _, _, counters = kinds
    geoms = cut.types[cut.fields.index("geoms")]
    basis, planes, t_range = view.types
    geom = geoms.copy(ndim=1, layout="C")  # a row of the drawables' placements
    setup = numba.types.BaseTuple.from_types((basis, geom, planes, t_range, t_range), RaySetup)
    passes = numba.types.BaseTuple.from_types((numba.boolean,) * len(Passes._fields), Passes)
    return band_types(pair[0], mode, pair[1], state, out, setup, passes, counters)
