"""The one pixel loop: every model's ray pieces through every mode, on any grid.

:func:`trace` is the segment entry point of the renderer. It traces the rays of an image (or of
a tile of it, see :meth:`splinecast.Camera.tile`) through one *grid*: a model's kernel grid
(:mod:`splinecast.models.pieces`) covering the whole volume or one brick of it with its ghost
layers, placed in the volume by ``geom``, a float64 array of ``GEOM_SIZE`` read at the offsets
:mod:`.rays` names (three entries x, y, z from the offsets of vectors):

====================  ========================================================================
``GEOM_ORIGIN``       world position of voxel ``(0, 0, 0)`` of the grid's level
``GEOM_SPACING``      the level's voxel spacing (level 0's spacing times the level's scale)
``GEOM_SHIFT``        the model's shift: the traversal walks cells in ``voxel index + shift``
``GEOM_OFFSET``       the grid's index offset: its cell 0 is cell ``offset`` of the level
``GEOM_LO``           the rendered domain's low corner in the level's voxel index space
``GEOM_HI``           the rendered domain's high corner
``GEOM_CELLS``        the level's cells per axis (a grid that ends before them has neighbours)
====================  ========================================================================

Each ray is clipped by the clip ``planes``, the domain, when ``t_range`` is not empty, its
own parameter interval ``t_range[row, col]``, and when ``footprint`` is not empty, the interval
of its ``8 x 8`` pixel tile in which the blocks the mode can see lie (:mod:`.footprint`; the
pixels of a tile without one are finished without a ray, and a mode's ``entry_left_out``
sees a ray whose entry the footprint leaves out); the ray parameter is always the
world distance along the unit ray, so depths agree between grids and levels. The mode's
per-ray state comes in and goes out through the mode's state arrays (``load`` / ``store``), so
a ray can be traced through several grids in turn, front to back, exactly as through one: the
sample positions of the sampled methods and of DVR are anchored at the ray's entry into the
domain, not into the grid. With ``final`` the mode writes the pixel's outputs at the end.

Rendering a whole volume is one call (``load=False, store=False, final=True``). Rendering it
brick by brick: reset the state arrays (:func:`reset_state`), call :func:`trace` for the bricks
in front-to-back order per ray (``load=True, store=True``), then :func:`finalize`. Bricks traced
independently (on other workers) give partial states that the mode's ``combine`` merges in depth
order. Models and modes are resolved from the grid's and the mode's tuple classes: the one loop
written here is copied once per (model, mode) pair with the pair's hooks inlined into it at
Numba's IR level (no call, no reference counting per hook), compiled once and cached on disk
under its own name (:func:`pair_band`). The image loop around it takes the pair's band as a
first-class function (:func:`splinecast._jit.bind_first_class`), so it compiles without it.

Work is spread over threads in bands of ``band_rows`` rows: each thread
(:mod:`~splinecast._jit.work_queue`) takes the next band of the order ``bands`` (a permutation
that mixes busy and empty parts of the image) when it is free, and traverses it in tiles of
``tile`` columns so neighbouring rays reuse the model's per-thread caches. A model may hand out
several bands at once (``work_rows``) to the modes whose rays go through the volume: the item is
then traced a column of tiles at a time, the same tiles, so the same pixels.
"""

from __future__ import annotations

import functools
import math
from collections import namedtuple
from typing import Any

import numba
import numpy as np
from numba import types

from .._jit import bind_first_class, inlined, jit, rebound
from .._jit.work_queue import run_on_threads, take
from ..accel.traversal import walk_begin, walk_step_cached
from ..camera import BASIS_COL0, BASIS_ROW0
from ..models import pieces as model_api
from ..models.pieces import cell_count, cell_load, cell_pieces, new_scratch, piece_poly, piece_range
from . import mode_api
from .footprint import FOOTPRINT_SHIFT
from .mode_api import (
    answer_shift,
    asks_again,
    consume,
    done,
    entry_left_out,
    finish,
    mode_scratch,
    on_skip,
    ray_begin,
    ray_end,
    skip_size,
    state_load,
    state_new,
    state_store,
    tile_begin,
    wants,
    watches_skips,
)
from .outputs import copy_pixel
from .rays import GEOM_SIZE, Ray, RayPiece, grid_ray, pixel_ray
from .sampler import bound_sample_pixel

__all__ = ["trace", "pair_band", "pair_bindings", "finalize", "reset_state", "band_order",
           "scratch_types", "GEOM_SIZE", "RaySetup", "Rect", "Passes", "Counters", "Buffers",
           "Bands", "Pixel", "band_types"]

# The argument groups of the pixel loop (compiled code reads them by field name; numba passes a
# named tuple as its fields, so grouping costs nothing per call).

RaySetup = namedtuple("RaySetup", ("basis", "geom", "planes", "t_range", "footprint"))
RaySetup.__doc__ = """What sets up each pixel's ray through one grid and limits its interval.

Attributes
----------
basis : ndarray
    :meth:`Camera.pixel_basis` of the image (or tile).
geom : ndarray, shape (GEOM_SIZE,)
    Placement of the grid (module docstring).
planes : ndarray, shape (m, 4)
    Clip planes.
t_range : ndarray, shape (height, width, 2) or (0, 0, 2)
    Per-ray parameter interval, or none (empty: the ray is left alone).
footprint : ndarray, shape (tiles_y, tiles_x, 2) or (0, 0, 2)
    Per-tile parameter interval of the blocks the mode can see (:mod:`.footprint`), or none.
"""

Rect = namedtuple("Rect", ("r0", "r1", "c0", "c1", "tile", "rows"))
Rect.__doc__ = """Rows ``[r0, r1)`` x columns ``[c0, c1)`` of the image, traced in tiles of
``rows`` rows by ``tile`` columns (integers), a column of tiles after another, each column's
tiles from top to bottom."""

Passes = namedtuple("Passes", ("load", "store", "final", "count"))
Passes.__doc__ = """What a trace does besides tracing (booleans): read the state arrays at the
start (``load``), write them at the end (``store``), write the outputs (``final``), increment
the per-ray statistics (``count``)."""

Counters = namedtuple("Counters", ("visited", "tested", "skipped"))
Counters.__doc__ = """Per-ray statistics, int32 arrays of shape (height, width): cells walked,
cells whose pieces were built, blocks leapt (or a sampled mode's samples, segments and leaps).
Their shape is the image's."""

Buffers = namedtuple("Buffers", ("model", "mode", "cuts", "tags"))
Buffers.__doc__ = """One thread's scratch buffers for the pixel loop: the model's scratch
(:func:`splinecast.models.pieces.new_scratch`), the mode's (``mode_scratch``), and the piece
boundaries (float64) and tags (int64) of one cell."""

Bands = namedtuple("Bands", ("order", "rows", "tile", "counter", "group"))
Bands.__doc__ = """How the image loop hands out its work: groups of ``group`` bands of ``rows``
rows in the order ``order`` (int64 array), the next one taken from the shared one-element int64
array ``counter`` (:func:`~splinecast._jit.work_queue.take`). A group of one band is traced
``tile`` columns at a time; a larger group one column of tiles at a time, its bands' tiles top
to bottom."""

Pixel = namedtuple("Pixel", ("row", "col", "width", "height"))
Pixel.__doc__ = """Pixel ``(row, col)`` of an image (or tile) of ``width`` x ``height``
(integers)."""

#: (grid class, mode class) -> the pair's :func:`_trace_band`.
_KERNELS: dict[tuple[type, type], Any] = {}


def band_order(n_bands: int) -> np.ndarray:
    """A permutation of bands in which every contiguous run is spread over the whole image.

    Ordering bands by the fractional part of ``band * golden ratio`` gives a thread that takes
    a contiguous range of them (the brick renderer's parallel loop, :mod:`splinecast.multires`)
    a similar mix of busy and empty bands, and threads taking bands one at a time
    (:func:`trace`) busy bands from the start.
    """
    key = (np.arange(n_bands) * 0.6180339887498949) % 1.0
    return np.argsort(key, kind="stable").astype(np.int64)


# Called, not inlined: this and the untraced-pixel helpers below serve tiles and pixels where no
# ray is traced (rare next to the rays), and as calls they compile once for every model instead
# of once per (model, mode) band, where their inlined copies made a large share of the code.
@jit(_nrt=False)
def _unseen(footprint, row_a, row_b, col_a, col_b, ty0, tx0):
    """Whether every footprint tile that full-image rows ``[row_a, row_b)`` x columns
    ``[col_a, col_b)`` overlap is empty (``ty0``, ``tx0``: the footprint's first tile)."""
    for ty in range((row_a >> FOOTPRINT_SHIFT) - ty0, ((row_b - 1) >> FOOTPRINT_SHIFT) - ty0 + 1):
        for tx in range((col_a >> FOOTPRINT_SHIFT) - tx0,
                        ((col_b - 1) >> FOOTPRINT_SHIFT) - tx0 + 1):
            if footprint[ty, tx, 0] <= footprint[ty, tx, 1]:
                return False
    return True


@jit(inline="always")
def _trace_pixel(grid, mode, blocks, state, out, setup, passes, buffers, pixel, window, cells):
    """Trace one pixel's ray inside ``window``, ``(t_lo, t_hi)``; ``cells`` is the grid's
    ``cell_count``. Returns (cells visited, cells tested, blocks skipped)."""
    basis, geom, planes, t_range = setup.basis, setup.geom, setup.planes, setup.t_range
    load, store, final = passes.load, passes.store, passes.final
    scr, mscr, cuts, tags = buffers.model, buffers.mode, buffers.cuts, buffers.tags
    row, col, width, height = pixel
    t_lo, t_hi = window
    ncx, ncy, ncz = cells
    t0, t1, ray = grid_ray(basis, geom, planes, t_range, row, col, width, height, ncx, ncy, ncz)
    st = state_load(mode, state, row, col) if load else state_new(mode)
    if (t_lo > t0 or t_hi < t0) and t0 <= t1 and not done(mode, st):
        st = entry_left_out(mode, grid, scr, st, ray, t0, t1, t_lo, t_hi, ncx, ncy, ncz)
    t0 = max(t0, t_lo)
    t1 = min(t1, t_hi)
    ox, oy, oz = ray.index_x, ray.index_y, ray.index_z
    dx, dy, dz = ray.index_dx, ray.index_dy, ray.index_dz
    visited = 0
    tested = 0
    skipped = 0
    if t0 <= t1 and not done(mode, st):
        inside, ci, cj, ck, t, t_far = walk_begin(ox, oy, oz, dx, dy, dz, ncx, ncy, ncz, t0, t1)
        if inside:
            st = ray_begin(mode, grid, scr, mscr, blocks, st, ray, ncx, ncy, ncz, t, t_far)
        # The smallest block the mode answers for (answer_shift) that it last asked to
        # process: its other cells are processed without asking again (skip_size's
        # contract), which saves the hierarchy's lookups for most cells near a surface; a
        # mode that ``asks_again`` is asked after each cell it tested.
        shift = answer_shift(mode)
        open_i = open_j = open_k = -1
        # Each axis's last plane and its crossing parameter (walk_step_cached): the walk
        # divides only for an axis whose plane changed.
        crossings = (-2, 0.0, -2, 0.0, -2, 0.0)
        while inside:
            if (ci >> shift) != open_i or (cj >> shift) != open_j or (
                    ck >> shift) != open_k:
                size = skip_size(mode, blocks, ci, cj, ck, st)
                # Leaps follow one another until a block must be entered: a loop of its own,
                # with only the walk's state live in it.
                while size > 0:
                    t_end, inside, ci, cj, ck, t_next, crossings = walk_step_cached(
                        (ox, oy, oz), (dx, dy, dz), cells, ci, cj, ck, t, t_far, size,
                        crossings)
                    skipped += 1
                    if watches_skips(mode):
                        st = on_skip(mode, grid, scr, st, ray, t, t_end, math.nan, math.nan)
                    t = t_next
                    if not inside:
                        break
                    size = skip_size(mode, blocks, ci, cj, ck, st)
                if not inside:
                    break
                open_i, open_j = ci >> shift, cj >> shift
                open_k = ck >> shift
            t_end, inside, ni, nj, nk, t_next, crossings = walk_step_cached(
                (ox, oy, oz), (dx, dy, dz), cells, ci, cj, ck, t, t_far, 1, crossings)
            if t_end >= t:
                visited += 1
                ctx = cell_load(grid, scr, ci, cj, ck)
                if wants(mode, st, ctx[0], ctx[1]):
                    tested += 1
                    ax = ox + t * dx - ci
                    ay = oy + t * dy - cj
                    az = oz + t * dz - ck
                    ex = ox + t_end * dx - ci - ax
                    ey = oy + t_end * dy - cj - ay
                    ez = oz + t_end * dz - ck - az
                    n = cell_pieces(grid, scr, ctx, (ci, cj, ck), (ax, ay, az), (ex, ey, ez),
                                    cuts, tags)
                    for p in range(n):
                        s0 = cuts[p]
                        s1 = cuts[p + 1]
                        tp0 = t + s0 * (t_end - t)
                        tp1 = t + s1 * (t_end - t)
                        tag = tags[p]
                        lo, hi = piece_range(grid, scr, ctx, ci, cj, ck, tag)
                        if not wants(mode, st, lo, hi):
                            if watches_skips(mode):
                                st = on_skip(mode, grid, scr, st, ray, tp0, tp1, lo, hi)
                            continue
                        pax, pay, paz = ax + s0 * ex, ay + s0 * ey, az + s0 * ez
                        pbx, pby, pbz = ax + s1 * ex, ay + s1 * ey, az + s1 * ez
                        poly = piece_poly(grid, scr, ctx, (ci, cj, ck), tag, (pax, pay, paz),
                                          (pbx, pby, pbz))
                        piece = RayPiece(ctx, ci, cj, ck, tag, poly, lo, hi, tp0, tp1, pax,
                                         pay, paz, pbx, pby, pbz)
                        st = consume(mode, mscr, grid, scr, piece, ray, st)
                        if done(mode, st):
                            break
                    if asks_again(mode):
                        open_i = -1
                elif watches_skips(mode):
                    st = on_skip(mode, grid, scr, st, ray, t, t_end, ctx[0], ctx[1])
                if done(mode, st):
                    break
            ci, cj, ck, t = ni, nj, nk, t_next
        if final and watches_skips(mode):
            st = ray_end(mode, grid, scr, st, ray, t_far)
    if store:
        state_store(mode, state, row, col, st)
    if final:
        finish(mode, out, row, col, st, ray)
    return visited, tested, skipped


# Without Numba's reference counting (``_nrt=False``): the hooks inlined here take the grid,
# scratch, mode and state tuples, and Numba increments and decrements the count of every array
# in a tuple each time an inlined function with branches receives it; it could not prune those
# pairs, and their atomic operations took more than half of a qss iso frame. The band allocates
# nothing (its buffers come from the caller, which keeps every array alive), so it needs no
# counts. Functions it calls inherit that (numba passes ``nrt`` on to callees that do not set it),
# so one that allocates must be compiled with ``_nrt=True`` (none of the band's does).
@jit(_nrt=False)
def _trace_band(grid, mode, blocks, state, out, setup, rect, passes, counters, buffers):
    """Trace the pixels of ``rect`` (a :class:`Rect`; one thread's work item) with the rays of
    ``setup`` (:class:`RaySetup`); ``buffers`` are the thread's scratch buffers
    (:class:`Buffers`).

    This is also the one-launch cut renderer's per-drawable unit (:mod:`.cut_driver`), which
    calls the pair's compiled band instead of inlining its own copy of the pixel loop: both
    renderers then share one compiled loop per (model, mode, argument types). A pixel whose
    ``t_range`` is empty (``t0 > t1``) is left alone, state and outputs included: the cut
    renderer marks so the pixels a drawable does not cover (tracing them would load their state
    and store it unchanged), antialiasing the pixels it does not trace again
    (:mod:`.antialias`). A non-empty ``footprint`` (:mod:`.footprint`) limits the
    rays of each of its tiles to the tile's interval; the pixels of a tile it leaves empty are
    not traced (their states are passed on, and finished with ``final``).
    """
    basis, t_range, footprint = setup.basis, setup.t_range, setup.footprint
    r0, r1, c0, c1, tile, rows = rect
    load, store, final, count = passes
    visited, tested, skipped = counters
    height, width = visited.shape
    cells = cell_count(grid)
    ranged = t_range.shape[0] > 0
    footed = footprint.shape[0] > 0
    t_lo, t_hi = -math.inf, math.inf
    # The footprint's tiles are the full image's (a tile camera's pixels start at col0, row0).
    col0, row0 = int(basis[BASIS_COL0]), int(basis[BASIS_ROW0])
    tx0, ty0 = col0 >> FOOTPRINT_SHIFT, row0 >> FOOTPRINT_SHIFT
    # A whole image's fresh pixels where nothing projects get the outputs of one of them: the
    # mode finishes a fresh state there without a ray, and the pixel is copied over the run
    # of such tiles (a fresh state's outputs do not depend on the pixel; .outputs.copy_pixel).
    # Not when some pixels are to be left alone (``t_range``).
    fresh = footed and final and not load and not store and not ranged
    # A rectangle one tile tall: a run of tiles where nothing projects gets one finished
    # pixel copied over the whole run.
    one_row = r1 - r0 <= rows
    tc0 = c0
    while tc0 < c1:
        tc1 = min(c1, tc0 + tile)
        tr0 = r0
        while tr0 < r1:
            tr1 = min(r1, tr0 + rows)
            # Each tile's rays start from a fresh mode scratch (what a mode carries from one
            # ray to the next, such as MIP's depth of the previous maximum): a pixel's result
            # then depends only on the rays of its own tile, so any window of the image whose
            # edges lie on tile boundaries (Camera.tile, the viewer's stripes, Dask's tiles)
            # renders the same pixels as the whole image, whatever a mode does with its
            # scratch, and so does any order of the tiles.
            tile_begin(mode, buffers.mode)
            if fresh and _unseen(footprint, tr0 + row0, tr1 + row0, tc0 + col0, tc1 + col0,
                                 ty0, tx0):
                end = tc1
                while one_row and end < c1 and _unseen(footprint, r0 + row0, r1 + row0,
                                                       end + col0, min(c1, end + tile) + col0,
                                                       ty0, tx0):
                    end = min(c1, end + tile)
                _finish_fresh(mode, out, tr0, tc0)
                copy_pixel(out, tr0, tc0, tr0, tr1, tc0, end)
                tc1 = end  # only ever past the tile in a rectangle one tile tall
                tr0 = tr1
                continue
            for row in range(tr0, tr1):
                for col in range(tc0, tc1):
                    if ranged and t_range[row, col, 0] > t_range[row, col, 1]:
                        continue
                    if footed:
                        ty = ((row + row0) >> FOOTPRINT_SHIFT) - ty0
                        tx = ((col + col0) >> FOOTPRINT_SHIFT) - tx0
                        t_lo = footprint[ty, tx, 0]
                        t_hi = footprint[ty, tx, 1]
                        if t_lo > t_hi:
                            # Nothing the mode can see projects here: no ray to set up.
                            if store or final:
                                _pass_untraced(mode, state, out, basis, row, col, width,
                                               height, load, store, final)
                            continue
                    nv, nt, ns = _trace_pixel(
                        grid, mode, blocks, state, out, setup, passes, buffers,
                        Pixel(row, col, width, height), (t_lo, t_hi), cells,
                    )
                    if count:
                        visited[row, col] += nv
                        tested[row, col] += nt
                        skipped[row, col] += ns
            tr0 = tr1
        tc0 = tc1


def trace(grid, mode, blocks, state, out, basis, geom, planes, t_range, footprint, bands,
          band_rows, tile, load, store, final, count, visited, tested, skipped, group=1):
    """Trace every pixel of the image (or tile) through ``grid`` with ``mode``.

    All parameters are prepared by the host side (:mod:`.segment`).

    Parameters
    ----------
    grid : named tuple
        The model's kernel grid.
    mode : named tuple
        The mode's parameters.
    blocks : tuple of arrays
        The mode's view of the grid's block hierarchy (flags or block maxima).
    state, out : tuples of arrays
        The mode's per-pixel state arrays and output buffers.
    basis : ndarray
        :meth:`Camera.pixel_basis`.
    geom : ndarray, shape (19,)
        Placement of the grid (module docstring).
    planes : ndarray, shape (m, 4)
        Clip planes.
    t_range : ndarray, shape (height, width, 2) or (0, 0, 2)
        Per-ray parameter interval, or none.
    footprint : ndarray, shape (tiles_y, tiles_x, 2) or (0, 0, 2)
        Per-tile parameter interval of the blocks the mode can see, over the tiles of the full
        image the camera's pixels overlap (:func:`.footprint.block_footprint`), or none; rays
        of a tile it leaves empty are not traced.
    bands : ndarray of int64
        Order of the groups of ``group`` bands of ``band_rows`` rows (one thread's work item);
        ``tile`` columns per tile.
    load, store, final : bool
        Read the state arrays at the start, write them at the end, write the outputs.
    count : bool
        Increment the per-ray statistics (a caller that does not want them passes False and
        arrays that are only read for the image's size).
    visited, tested, skipped : ndarray of int32, shape (height, width)
        Per-ray statistics, incremented.
    group : int
        Bands per work item, traced a column of ``tile`` columns at a time (tiles of
        ``band_rows`` x ``tile`` pixels, each traced as with one band: the same pixels).
    """
    args = (grid, mode, blocks, state, out, RaySetup(basis, geom, planes, t_range, footprint),
            Bands(bands, int(band_rows), int(tile), np.zeros(1, np.int64), max(1, int(group))),
            Passes(bool(load), bool(store), bool(final), bool(count)),
            Counters(visited, tested, skipped))
    work = bind_first_class(_trace_image, pair_band(type(grid), type(mode)), _image_band_types,
                            args)
    run_on_threads(work, max(1, min(numba.get_num_threads(), len(bands))))


def scratch_types(grid_kind: Any, mode_kind: Any) -> tuple[Any, Any]:
    """The Numba types of the band's per-thread scratch buffers (the model's and the mode's)
    for a grid and a mode of the Numba types ``grid_kind`` and ``mode_kind``."""
    key = (grid_kind, mode_kind)
    scratch = _scratch_probe.overloads.get(key)
    if scratch is None:
        _scratch_probe.compile(key)
        scratch = _scratch_probe.overloads[key]
    return tuple(scratch.signature.return_type)


def band_types(grid_kind: Any, mode_kind: Any, blocks_kind: Any, state_kind: Any,
               out_kind: Any, setup_kind: Any, passes_kind: Any, counters_kind: Any) -> tuple:
    """The argument types of a (model, mode) pair's band (:func:`_trace_band`) from the Numba
    types of its grid, mode, block hierarchy, state arrays, outputs, :class:`RaySetup`,
    :class:`Passes` and :class:`Counters`: its :class:`Rect` of int64 and its :class:`Buffers`
    are made by the caller."""
    scr, mscr = scratch_types(grid_kind, mode_kind)
    index = numba.int64  # the rectangle's rows and columns, computed in the loop
    rect = types.BaseTuple.from_types((index,) * len(Rect._fields), Rect)
    buffers = types.BaseTuple.from_types((scr, mscr, numba.float64[::1], numba.int64[::1]),
                                         Buffers)
    return (grid_kind, mode_kind, blocks_kind, state_kind, out_kind, setup_kind, rect,
            passes_kind, counters_kind, buffers)


def _image_band_types(kinds: tuple) -> tuple:
    """The argument types of the band :func:`_trace_image` calls, from the Numba types ``kinds``
    of its own arguments (after the band)."""
    grid, mode, blocks, state, out, setup, _, passes, counters = kinds
    return band_types(grid, mode, blocks, state, out, setup, passes, counters)


@jit(no_cpython_wrapper=True)
def _scratch_probe(grid, mode):
    """Never called: compiled only for the types of the band's per-thread scratch buffers."""
    return new_scratch(grid), mode_scratch(mode)


@jit()
def _trace_image(band, grid, mode, blocks, state, out, setup, bands, passes, counters):
    """One thread's share of :func:`trace`: ``band`` is the pair's :func:`_trace_band` as a
    first-class function (:func:`splinecast._jit.bind_first_class`), so this function compiles
    without the band's code (its caller's library would link and optimize it again).

    Each thread that runs it (:func:`~splinecast._jit.work_queue.run_on_threads`) takes the
    next band in the order ``bands.order`` when it is free (``bands.counter``: the shared counter; a
    :class:`Bands`): bands differ in cost by orders of magnitude, and a split fixed in advance
    left one thread waiting for the other.

    A work item of several bands (``bands.group``) is one call of the band over all their
    rows, which traces it one column of tiles at a time, each column's tiles from top to
    bottom: rays close on the screen, which read the same voxels, are then traced close in
    time, while those voxels are still in the core's cache (a band traced tile by tile across
    the whole image had let the voxels its neighbours share fall out of it before the band
    below needed them). The tiles are the bands' (the mode's scratch reset at the start of
    each), so the pixels are the same."""
    height, width = counters.visited.shape
    # The first column as a variable: a constant argument is typed as a literal, which would
    # compile a band of its own instead of the one the cut renderer shares (.cut_driver).
    first = width - width
    rows, tile, group = bands.rows, bands.tile, bands.group
    while True:
        b = take(bands.counter)
        if b >= bands.order.shape[0]:
            break
        r0 = bands.order[b] * rows * group
        band(grid, mode, blocks, state, out, setup,
             Rect(r0, min(height, r0 + rows * group), first, width, tile, rows), passes,
             counters,
             Buffers(new_scratch(grid), mode_scratch(mode), np.empty(8), np.empty(8, np.int64)))


def finalize(mode, state, out, basis):
    """Write every pixel's outputs from the state left by the last segment."""
    rows = out[0].shape[0]
    counter = np.zeros(1, np.int64)
    run_on_threads(functools.partial(_finalize_rows, mode, state, out, basis, counter),
                   max(1, min(numba.get_num_threads(), rows)))


# Rows taken from a shared counter on ordinary threads (splinecast._jit.work_queue), not a
# parallel loop: Numba's parallel loop compiles a second library for its body, a second or two
# per mode and output types, for a pass that costs a few milliseconds per frame. Without reference
# counting (nothing here allocates): counted, every call of the mode's hooks would increment
# and decrement each array of the state and output tuples, per pixel.
@jit(_nrt=False)
def _finalize_rows(mode, state, out, basis, counter):
    """One thread's share of :func:`finalize`: the rows it takes from ``counter``."""
    height = out[0].shape[0]
    width = out[0].shape[1]
    while True:
        row = take(counter)
        if row >= height:
            break
        for col in range(width):
            finish(mode, out, row, col, state_load(mode, state, row, col),
                   _bare_ray(basis, row, col, width, height))


#: The ray passed to ``finish`` for a pixel never traced whose state is fresh.
_NO_RAY = Ray(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 0.0)


@jit(inline="always")
def _bare_ray(basis, row, col, width, height):
    """The mode API's :class:`~.rays.Ray` with only the world ray set: what ``finish`` reads."""
    wx, wy, wz, ux, uy, uz = pixel_ray(basis, row, col, width, height)
    return Ray(wx, wy, wz, ux, uy, uz, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 0.0)


@jit(_nrt=False)
def _finish_fresh(mode, out, row, col):
    """Write pixel ``(row, col)``'s outputs from a fresh state (no ray: the mode API's contract
    for ``finish`` of a fresh state)."""
    finish(mode, out, row, col, state_new(mode), _NO_RAY)


@jit(_nrt=False)
def _pass_untraced(mode, state, out, basis, row, col, width, height, load, store, final):
    """A pixel whose ray meets nothing the mode can see: its state passed on (``store``) and
    its outputs written from it (``final``) without tracing."""
    st = state_load(mode, state, row, col) if load else state_new(mode)
    if store:
        state_store(mode, state, row, col, st)
    if final:
        # A state from an earlier grid may need the ray; a fresh one does not.
        ray = _bare_ray(basis, row, col, width, height) if load else _NO_RAY
        finish(mode, out, row, col, st, ray)


def reset_state(mode, state, height, width):
    """Fill the state arrays with fresh states (no segment traced yet)."""
    counter = np.zeros(1, np.int64)
    run_on_threads(functools.partial(_reset_rows, mode, state, int(height), int(width), counter),
                   max(1, min(numba.get_num_threads(), int(height))))


@jit(_nrt=False)
def _reset_rows(mode, state, height, width, counter):
    """One thread's share of :func:`reset_state` (rows as :func:`_finalize_rows`)."""
    while True:
        row = take(counter)
        if row >= height:
            break
        for col in range(width):
            state_store(mode, state, row, col, state_new(mode))


def pair_bindings(grid_class: type, mode_class: type) -> dict[str, Any] | None:
    """The hook names of the pixel loop bound to the pair's registered functions, inlined
    unless the model keeps them as calls (None: a model or mode the registries do not know);
    what :func:`pair_band` compiles its copies of the loop with."""
    model_hooks = model_api.hooks_of(grid_class)
    mode_hooks = mode_api.hooks_of(mode_class)
    if model_hooks is None or mode_hooks is None:
        return None
    called = model_api.called_of(grid_class)
    return {name: f if name in called else inlined(f)
            for name, f in {**model_hooks, **mode_hooks}.items()}


def pair_band(grid_class: type, mode_class: type) -> Any:
    """:func:`_trace_band` for one (model, mode) pair, its hooks inlined (made once per pair):
    the unit the in-memory renderer's image loop calls per band of rows and the one-launch cut
    renderer per drawable and tile.

    The generic loop calls each hook through an overload: a real call that LLVM does not inline
    (its tuple arguments expand to a hundred values or more) and that increments and decrements
    the reference count of every array of the grid and state tuples. Here the loop's functions
    are copied with the hook names bound to the pair's registered implementations, inlined at
    Numba's IR level, so the pair compiles into one function per band; the copies are cached
    on disk under their own names (:func:`splinecast._jit.rebound`). A model may keep hooks
    whose work dwarfs a call as calls (``register(..., called=...)``; none does at present:
    the band keeps no reference counts, so inlined hooks cost no counting, while a call still
    counts every array of the tuples it is passed). Pairs the registries do not know (no such
    model or mode) keep the generic loop and its error.
    """
    key = (grid_class, mode_class)
    band = _KERNELS.get(key)
    if band is None:
        bind = pair_bindings(grid_class, mode_class)
        if bind is None:
            band = _trace_band
        else:
            suffix = f"{grid_class.__name__}_{mode_class.__name__}"
            if mode_api.sampled_of(mode_class):
                pixel = bound_sample_pixel(bind, suffix)
            else:
                pixel = rebound(_trace_pixel, bind, suffix)
            band = rebound(_trace_band, {**bind, "_trace_pixel": pixel}, suffix)
        _KERNELS[key] = band
    return band

