"""Grids placed in a volume, and the host side of the segment entry point.

A :class:`Grid` is a model's kernel grid (the whole volume, or one brick with the ghost layers
its support needs) with its own block hierarchy and its placement (:mod:`.driver`). Rendering:

* a whole volume: :func:`render_grid` -- one call of the driver, outputs written directly;
* a volume cut into bricks (the multiresolution renderer, a distributed worker):
  :func:`new_state`, then :func:`trace_segment` for each brick (front to back per ray, carrying
  the state), then :func:`finish_state`; or trace bricks into separate states and merge them in
  depth order with the mode's ``combine`` (:func:`combine_states`).

A brick of a model is a block of the model's ``prepared`` array: the brick owning cells
``[a, b)`` per axis (of the grid's traversal space) is ``prepared[a : b + support]`` placed at
``offset = a`` (:func:`brick_grid`). Every model reconstructs inside it without reading its
neighbours, and a ray traced through the bricks one after the other gives the same hits, values
and colours as through the whole volume.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._jit import jit, read_only
from ..accel.active_cells import CubeBoundHierarchy, block_ranges
from ..accel.minmax import BLOCK_SHIFTS, PAIR_SHIFT, MinMaxHierarchy
from ..errors import ParameterError
from ..models.shading_field import halo_box
from .clipping import NO_PLANES
from .driver import GEOM_SIZE, band_order, finalize, reset_state, trace
from .footprint import (
    MAX_PROJECTED_BLOCKS,
    MAX_PROJECTED_PAIRS,
    NO_FOOTPRINT,
    block_footprint,
    fill_box,
    footprint_level,
)
from .rays import GEOM_CELLS, GEOM_HI, GEOM_LO, GEOM_OFFSET, GEOM_ORIGIN, GEOM_SHIFT, GEOM_SPACING

__all__ = ["Grid", "make_grid", "brick_grid", "render_grid", "new_state", "trace_segment",
           "finish_state", "combine_states", "counters", "screen_footprint", "trace_pixels",
           "pixel_ranges"]

_NO_RANGE = np.zeros((0, 0, 2))


@dataclass
class Grid:
    """A model's kernel grid with its block hierarchy and its placement in the volume.

    Attributes
    ----------
    kernel : named tuple
        The model's kernel grid (:mod:`splinecast.models.pieces`).
    hierarchy : MinMaxHierarchy
        Block ranges of this grid's cells (for empty-space skipping).
    geom : ndarray, shape (19,)
        Placement (see :mod:`.driver`).
    n_cells : tuple of 3 int
        Cells of the grid per axis.
    band_rows, tile : int
        How the driver cuts the image into work (see :mod:`.driver`; ``tile = 0``: whole rows).
    work_rows : int
        Rows of a thread's work item, traced a column of tiles at a time (0: ``band_rows``).
    """

    kernel: tuple
    hierarchy: Any
    geom: np.ndarray
    n_cells: tuple[int, int, int]
    band_rows: int = 1
    tile: int = 0
    work_rows: int = 0

    def __post_init__(self) -> None:
        self.kernel = read_only_kernel(self.kernel)

    def with_kernel(self, kernel: tuple) -> Grid:
        """The same grid with another kernel tuple of the same cells (e.g. iso-classified)."""
        return Grid(kernel, self.hierarchy, self.geom, self.n_cells, self.band_rows, self.tile,
                    self.work_rows)

    def with_domain(self, lo: Any, hi: Any) -> Grid:
        """The same grid rendering only the part of its domain inside the box ``[lo, hi]``
        (the level's voxel index space): rays are clipped to it by the driver's slab test,
        which costs less per ray than clip planes."""
        geom = self.geom.copy()
        low, high = slice(GEOM_LO, GEOM_LO + 3), slice(GEOM_HI, GEOM_HI + 3)
        geom[low] = np.maximum(geom[low], np.asarray(lo, np.float64))
        geom[high] = np.minimum(geom[high], np.asarray(hi, np.float64))
        return Grid(self.kernel, self.hierarchy, geom, self.n_cells, self.band_rows, self.tile,
                    self.work_rows)


def read_only_kernel(kernel: tuple) -> tuple:
    """``kernel`` with every array replaced by a read-only view of it (no copy).

    Numba compiles a separate specialization for a read-only array (a memory-mapped file) and a
    writable one (an array in memory) of the same type. Kernels never write their grid, so
    handing them read-only views always makes one compiled kernel serve both, which halves the
    compilation a session (and the test suite) pays for mixing files and arrays.
    """
    return type(kernel)(*(read_only(field) for field in kernel))


def _hierarchy(model: Any, array: np.ndarray, n_cells: tuple[int, int, int]) -> Any:
    if model.cube_bounded:
        lo, hi = model.cube_bounds_of(array)
        return CubeBoundHierarchy(*block_ranges(lo, hi), n_cells)
    return MinMaxHierarchy(read_only(array), n_cells, model.support)


def make_grid(model: Any, array: np.ndarray | None = None, offset: Any = (0, 0, 0),
              level_origin: Any = None, level_spacing: Any = None, domain: Any = None,
              level_cells: Any = None, halo: tuple[np.ndarray, np.ndarray] | None = None) -> Grid:
    """A :class:`Grid` of ``model`` over ``array`` (default: its whole prepared array).

    Parameters
    ----------
    model : a model of :data:`splinecast.models.MODELS`
    array : ndarray, optional
        A block of ``model.prepared`` (or of the prepared array of another level of the same
        data), ghost layers included: cell ``c`` of the grid needs ``array[c .. c + support]``.
    offset : 3 ints
        The grid's cell 0 in the level's traversal grid.
    level_origin, level_spacing : 3 floats, optional
        World position of the level's voxel ``(0, 0, 0)`` and its spacing (default: the
        model's volume).
    domain : (lo, hi), optional
        The rendered box in the level's voxel index space (default: the model's
        ``domain()``); the same for every brick of a level.
    level_cells : 3 ints, optional
        The level's cells per axis (default: this grid's plus its offset).
    halo : (ndarray, ndarray), optional
        For a model with a shading field that reads beyond the cells' support
        (``model.shading_halo``, :mod:`splinecast.models.shading_field`): the halo array and
        its box. Default: ``array`` itself, real where it lies inside the level.
    """
    whole = array is None
    arr = model.prepared if whole else np.asarray(array)
    n_cells = tuple(int(s) - int(model.support) for s in arr.shape)
    if min(n_cells) < 1:
        raise ParameterError(f"a grid needs at least one cell per axis, got {n_cells} cells")
    vol = model.volume
    lo, hi = model.domain() if domain is None else domain
    geom = np.empty(GEOM_SIZE)
    geom[GEOM_ORIGIN:GEOM_ORIGIN + 3] = vol.origin if level_origin is None else level_origin
    geom[GEOM_SPACING:GEOM_SPACING + 3] = vol.spacing if level_spacing is None else level_spacing
    geom[GEOM_SHIFT] = model.shift
    geom[GEOM_OFFSET:GEOM_OFFSET + 3] = offset
    geom[GEOM_LO:GEOM_LO + 3] = lo
    geom[GEOM_HI:GEOM_HI + 3] = hi
    cells = (np.asarray(offset) + n_cells) if level_cells is None else level_cells
    geom[GEOM_CELLS:GEOM_CELLS + 3] = cells
    if whole:
        kernel = model.kernel_grid()
    elif model.shading_halo:
        if halo is None:
            # The array's elements are the level's prepared values from ``offset`` on; those
            # of the level itself are real (a pyramid brick's ghosts beyond its ends are not).
            last_cell = np.asarray(cells, np.int64) + int(model.support) - 1
            first = np.asarray(offset, np.int64)
            real_lo = np.clip(-first, 0, np.asarray(arr.shape) - 1)
            real_hi = np.clip(last_cell - first, 0, np.asarray(arr.shape) - 1)
            halo = (arr, halo_box((0, 0, 0), real_lo, real_hi))
        kernel = model.kernel_grid(arr, halo=halo)
    else:
        kernel = model.kernel_grid(arr)
    return Grid(kernel, _hierarchy(model, arr, n_cells), geom, n_cells,
                model.band_rows, model.tile, model.work_rows)


def brick_grid(model: Any, lo: Any, hi: Any) -> Grid:
    """The grid of the brick owning cells ``[lo, hi)`` (per axis) of ``model``'s whole grid,
    cut from ``model.prepared`` with its ghost layers (and, for a model whose shading field
    reads further, ``model.shading_halo``, the halo of that field around them)."""
    lo = [int(v) for v in lo]
    hi = [int(v) for v in hi]
    s = int(model.support)
    prepared = model.prepared
    block = prepared[lo[0]:hi[0] + s, lo[1]:hi[1] + s, lo[2]:hi[2] + s]
    whole = tuple(int(n) - s for n in prepared.shape)
    halo = None
    h = int(model.shading_halo)
    if h:
        a = [max(0, v - h) for v in lo]
        b = [min(n, v + s + h) for v, n in zip(hi, prepared.shape, strict=True)]
        first = np.asarray(lo) - np.asarray(a)
        halo = (np.ascontiguousarray(prepared[a[0]:b[0], a[1]:b[1], a[2]:b[2]]),
                halo_box(first, (0, 0, 0), np.asarray(b) - np.asarray(a) - 1))
    return make_grid(model, block, offset=lo, level_cells=whole, halo=halo)


def counters(height: int, width: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Zeroed per-ray statistics: cells visited, cells tested, blocks skipped."""
    return tuple(np.zeros((height, width), np.int32) for _ in range(3))  # type: ignore


def _run(grid: Grid, mode: Any, camera: Any, blocks: tuple, state: tuple, out: tuple,
         planes: np.ndarray, t_range: np.ndarray, load: bool, store: bool, final: bool,
         stats: tuple, count: bool = True, footprint: np.ndarray = NO_FOOTPRINT) -> None:
    h, w = camera.height, camera.width
    band_rows = max(1, grid.band_rows)
    tile = grid.tile if grid.tile > 0 else w
    # Bands per work item (traced a column of tiles at a time): only with tiles narrower than
    # the image, for modes whose rays go deep into the volume.
    deep = bool(mode.deep_rays)
    group = max(1, grid.work_rows // band_rows) if tile < w and deep else 1
    n_bands = (h + band_rows - 1) // band_rows
    bands = band_order((n_bands + group - 1) // group)
    trace(grid.kernel, mode.params, blocks, state, out, camera.pixel_basis(), grid.geom,
          np.ascontiguousarray(planes, np.float64), t_range, footprint, bands, band_rows, tile,
          load, store, final, count, *stats, group=group)


def screen_footprint(grid: Grid, mode: Any, camera: Any, blocks: tuple) -> np.ndarray:
    """The per-tile footprint of the blocks ``mode`` can see (:mod:`.footprint`), or
    :data:`~.footprint.NO_FOOTPRINT` for a mode that does not name them.

    A mode's ``footprint_flags`` are the hierarchy's levels, finest first, or one more before
    them, its 2-cell blocks (:data:`~splinecast.accel.minmax.PAIR_SHIFT`): the finest level
    with few enough active blocks is projected. A mode with ``footprint_fills_box`` has the
    rays of the tiles that the grid's box covers, and those blocks do not, traced from their
    entry only (:func:`~.footprint.fill_box`)."""
    flags_of = getattr(mode, "footprint_flags", None)
    flags = flags_of(blocks) if flags_of is not None else None
    if flags is None:
        return NO_FOOTPRINT
    shifts, limits = BLOCK_SHIFTS, (MAX_PROJECTED_BLOCKS,) * len(BLOCK_SHIFTS)
    if len(flags) > len(BLOCK_SHIFTS):  # the 2-cell blocks first
        # Every active 4-cell block holds an active pair: more blocks than the pairs' limit
        # need not count the pairs.
        if np.count_nonzero(flags[1]) > MAX_PROJECTED_PAIRS:
            flags = flags[1:]
        else:
            shifts, limits = (PAIR_SHIFT, *shifts), (MAX_PROJECTED_PAIRS, *limits)
    level = footprint_level(flags, limits)
    basis = camera.pixel_basis()
    tiles = block_footprint(basis, grid.geom, grid.n_cells, flags[level], shifts[level],
                            camera.width, camera.height)
    coarsest = level == len(flags) - 1
    if getattr(mode, "footprint_fills_box", False) and not (coarsest and flags[level].all()):
        # Rays crossing the box outside the named blocks still have a value (MIP's floor).
        whole = np.ones(flags[-1].shape, np.uint8)
        box = block_footprint(basis, grid.geom, grid.n_cells, whole, shifts[-1],
                              camera.width, camera.height)
        fill_box(tiles, box)
    return tiles


def render_grid(grid: Grid, mode: Any, camera: Any, planes: np.ndarray = NO_PLANES,
                flags: tuple | None = None, count: bool = True,
                footprint: Any = True) -> tuple[tuple, tuple]:
    """Trace a whole image through one grid; returns ``(outputs, counters)``.

    ``flags`` replaces the hierarchy's own classification for the iso mode. Without ``count``
    the per-ray statistics are not gathered: the counters returned are one uninitialised array
    (never written, so never paged in) standing for all three. With ``footprint``, rays are
    traced only where and as deep as the blocks the mode can see project
    (:func:`screen_footprint`; the image is the same, the frame faster); ``footprint`` may
    also be that footprint, computed before.
    """
    h, w = camera.height, camera.width
    out = mode.output(h, w)
    if count:
        stats = counters(h, w)
    else:
        unused = np.empty((h, w), np.int32)
        stats = (unused, unused, unused)
    blocks = mode.blocks(grid.hierarchy, flags)
    if isinstance(footprint, np.ndarray):
        tiles = footprint
    else:
        tiles = screen_footprint(grid, mode, camera, blocks) if footprint else NO_FOOTPRINT
    _run(grid, mode, camera, blocks, mode.state(0, 0), out, planes, _NO_RANGE, False, False, True,
         stats, count, tiles)
    return out, stats


def pixel_ranges(mask: np.ndarray) -> np.ndarray:
    """The ``t_range`` (:mod:`.driver`) that traces the pixels where ``mask`` is true and leaves
    the others alone, for :func:`trace_pixels` (one for every pass over the same pixels)."""
    out = np.empty((*mask.shape, 2))
    _fill_ranges(np.ascontiguousarray(mask, np.bool_), out)
    return out


@jit()
def _fill_ranges(mask, out):
    # Serial: a light pass (parallel ones wait for their slowest thread on a loaded machine).
    for row in range(mask.shape[0]):
        for col in range(mask.shape[1]):
            if mask[row, col]:
                out[row, col, 0] = -np.inf
                out[row, col, 1] = np.inf
            else:
                out[row, col, 0] = np.inf
                out[row, col, 1] = -np.inf


def trace_pixels(grid: Grid, mode: Any, camera: Any, ranges: np.ndarray,
                 planes: np.ndarray = NO_PLANES, flags: tuple | None = None,
                 footprint: np.ndarray = NO_FOOTPRINT) -> tuple:
    """Trace only the pixels of ``camera``'s image that ``ranges`` (:func:`pixel_ranges`)
    names, as :func:`render_grid` traces them; returns ``mode``'s outputs, whose other pixels
    are left as allocated (undefined).

    ``footprint`` is the screen footprint of the grid's blocks for ``camera``'s window
    (:func:`screen_footprint`, as :func:`render_grid` computed it for the frame), or none. A
    camera shifted inside its pixels (:meth:`~splinecast.Camera.shifted`) may use its
    unshifted camera's: a footprint is widened by a pixel. This is how antialiasing traces its
    extra rays (:mod:`.antialias`).
    """
    h, w = camera.height, camera.width
    out = mode.output(h, w)
    unused = np.empty((h, w), np.int32)
    blocks = mode.blocks(grid.hierarchy, flags)
    _run(grid, mode, camera, blocks, mode.state(0, 0), out, planes, ranges, False, False, True,
         (unused, unused, unused), False, footprint)
    return out


def new_state(mode: Any, camera: Any) -> tuple:
    """Fresh per-pixel state arrays of ``mode`` for ``camera``'s image."""
    state = mode.state(camera.height, camera.width)
    reset_state(mode.params, state, camera.height, camera.width)
    return state


def trace_segment(grid: Grid, mode: Any, camera: Any, state: tuple, stats: tuple,
                  planes: np.ndarray = NO_PLANES, t_range: np.ndarray | None = None) -> None:
    """Trace the image's rays through one grid, continuing from ``state`` (updated in place).

    ``t_range`` (shape ``(height, width, 2)``) restricts each ray further; ``stats`` are the
    per-ray counters (:func:`counters`), incremented.
    """
    rng = _NO_RANGE if t_range is None else np.ascontiguousarray(t_range, np.float64)
    _run(grid, mode, camera, mode.blocks(grid.hierarchy), state,
         mode.output(0, 0), planes, rng, True, True, False, stats)


def finish_state(mode: Any, state: tuple, camera: Any) -> tuple:
    """The outputs of the final per-pixel states (after the last segment)."""
    out = mode.output(camera.height, camera.width)
    finalize(mode.params, state, out, camera.pixel_basis())
    return out


def combine_states(mode: Any, front: tuple, back: tuple) -> tuple:
    """Merge the partial states of the same rays from a front and a back segment."""
    out = tuple(np.empty_like(a) for a in front)
    mode.combine(front, back, out)
    return out
