"""The renderer of a cut: every box of a multiresolution cut traced from its own brick, front to
back per ray, through the segment entry point of the render driver.

Drawables
    A :class:`Drawable` is one box of a cut (level-0 index space) and the brick that reconstructs
    it: an array of one level's values with ghost layers (voxels, or B-spline coefficients for
    the B-spline models, whose coefficients are the voxels), the level index of its first
    element and a key naming its contents. A brick drawn in place of a missing descendant (a
    substitution) is a drawable whose level is coarser than the cut's brick; several drawables may
    share one array. Anything that produces drawables can be rendered: the brick stream of an
    OME-Zarr pyramid (:mod:`~splinecast.multires.scenes.multiscale`), spline-wavelet
    reconstructions, a
    distributed worker's share of the bricks.

Grids
    A drawable's array becomes the model's kernel grid (:func:`splinecast.render.segment.make_grid`)
    with the level's placement: index offset ``first + pad`` (``pad`` the model's border layers,
    so that the grid's cell ``c`` reads the same voxels as cell ``offset + c`` of the whole
    level), the level's origin and spacing and the rendered domain in the level's index space.
    The grid covers the whole brick; each ray is restricted to the drawable's box with a per-ray
    parameter interval (:func:`.draw.probe.box_ranges`, the driver's ``t_range``), so boxes that cut
    through cells (the even B-spline and the type-6 models, whose cells are centred on voxels,
    or an ancestor drawn over a descendant's box) need nothing special. Grids of unmodified
    bricks are kept between frames while their bricks are in the cut; grids of bricks changed at
    a seam are built when first traced and kept while the seam plan keeps its change
    (:mod:`.draw.seams`).

Tracing
    The drawables are put in front-to-back order (:mod:`.draw.order`) and traced in one compiled
    launch per frame (:func:`splinecast.render.cut_driver.trace_cut`): parallel over screen
    tiles, each tile walks the drawables whose screen rectangle (:func:`screen_rects`, the box's
    projection) overlaps it, in that order, and hands each pixel of the rectangle to the
    driver's per-ray unit with the ray's interval inside the drawable's box; the mode's per-pixel
    state stays in the full-image arrays. A ray thus crosses the boxes one after the other
    exactly as it crosses the bricks of one volume (``tests/test_bricks.py``), and a cut whose
    boxes all come from level 0 renders the in-memory image. The per-drawable path (one
    :func:`~splinecast.render.segment.trace_segment` call per drawable over a tile camera of its
    rectangle, the state copied out and back) is kept as the reference
    (:attr:`CutRenderer.batched` off; ``tests/test_cut_driver.py`` compares the two
    bit for bit): per drawable it costs a parallel launch and copies, milliseconds on a shared
    machine, which dominated frames of many small bricks. Boxes at the volume's border are
    extended to the model's domain (the type-6 splines render half a voxel beyond the outer
    voxel centres); see :meth:`CutRenderer.box`.
"""

from __future__ import annotations

import contextlib
import gc
import time
from collections.abc import Callable, Hashable, Iterable, Iterator, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numba
import numpy as np
from numba.typed import List

from ..._jit import jit, overload_jit
from ...camera import (
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
    Camera,
)
from ...render.clipping import NO_PLANES
from ...render.cut_driver import TILE, tile_lists, trace_cut
from ...render.driver import GEOM_SIZE, band_order, finalize, reset_state
from ...render.rays import GEOM_OFFSET
from ...render.segment import Grid, counters, make_grid, trace_segment
from .order import eye_index, front_to_back
from .probe import box_ranges, sample_grid
from .seam_parts import SHELL_SHARE_MAX, Parts, crop_range, part_order, split_box

__all__ = ["Drawable", "LevelGeometry", "CutRenderer", "screen_rect", "screen_rects",
           "SERIAL_PIXELS", "SERIAL_CELLS", "gc_paused"]

#: Tiles of fewer pixels are traced on one thread, and grids of bricks of fewer cells built on
#: one: waking the thread pool costs more than such work (tens of milliseconds per call on a busy
#: machine), and a cut of small bricks (spline-wavelet chunks of 8^3 nodes) has thousands.
SERIAL_PIXELS = 4096
SERIAL_CELLS = 32**3


# Numba's typed List builds and grows itself with functions compiled in every process (about a
# second per run, several on a busy machine); these two are cached on disk like the kernels.
@jit()
def _typed_list_of(item: Any) -> Any:
    """An empty typed List whose items have ``item``'s Numba type."""
    return _empty_list_like(item)


def _empty_list_like(item: Any) -> Any:
    """An empty typed List for items like ``item`` (compiled code only)."""
    raise NotImplementedError


@overload_jit(_empty_list_like)
def _empty_list_like_impl(item: Any) -> Any:
    # The item's type is known here, at compile time: the list is made empty of that type
    # directly, which compiles in half the time of appending an item and popping it again.
    item_type = item

    def empty(item: Any) -> Any:
        return List.empty_list(item_type)

    return empty


@jit()
def _append(items: Any, item: Any) -> None:
    """``items.append(item)`` for a typed List."""
    items.append(item)
#: Voxels per axis of the arrays behind the launch's type exemplars (:meth:`CutRenderer._pack`).
_EXEMPLAR = 8


@contextlib.contextmanager
def _threads(serial: bool) -> Iterator[None]:
    """Run the body's compiled parallel calls on one thread when ``serial``."""
    if not serial:
        yield
        return
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(before)


@contextlib.contextmanager
def gc_paused() -> Iterator[None]:
    """Hold Python's cyclic garbage collector for the body (it runs again after it).

    A frame with tens of thousands of drawables allocates a few small tuples per drawable while
    about a million objects (each drawable's cached grid, pair and box) stay alive; the
    allocations trigger full collections that traverse all of them: 0.66 s of a 3 s steady
    frame of a 512^3 wavelet store with 33 k drawables (cProfile, ``_pair``'s own time, which fell
    to nothing with the collector held). The body creates no reference cycles, so holding the
    collector only moves that work out of the frame; reference counting still frees memory.
    """
    if not gc.isenabled():
        yield
        return
    gc.disable()
    try:
        yield
    finally:
        gc.enable()


@dataclass(frozen=True, eq=False)
class Drawable:
    """One box of a cut and the brick array that reconstructs it.

    Attributes
    ----------
    cut_key : (level, i, j, k)
        The cut's brick whose box this is (orders the drawables front to back).
    key : hashable
        Names the array's contents (a brick's key): drawables with the same key share one grid.
    level : int
        Level of the array (coarser than ``cut_key[0]`` when an ancestor stands in).
    data : ndarray (nx, ny, nz)
        The level's values ``first .. first + shape - 1`` with ghost layers (at least the
        model's support on every side of the box).
    first : (3,) int
        Level index of ``data[0, 0, 0]``.
    box_lo, box_hi : ndarray (3,)
        The box drawn, in level-0 index space.
    substituted : bool
        An ancestor's array is drawn for the box (the cut's own brick is not resident).
    placed : bool
        ``box_lo``/``box_hi`` are already the box to trace, on the model's cell boundaries and
        inside its domain (spline-wavelet chunk regions): :meth:`CutRenderer.box` neither moves
        nor extends them.
    seam_part : {"", "core", "shell"}
        Part of a brick changed at a seam (:mod:`.draw.seam_parts`): the core is drawn from the
        brick's own grid (no seam change applies to it), a shell from ``data``, which is
        already the changed prepared array around it.
    """

    cut_key: tuple[int, int, int, int]
    key: Hashable
    level: int
    data: np.ndarray
    first: tuple[int, int, int]
    box_lo: np.ndarray
    box_hi: np.ndarray
    substituted: bool = False
    placed: bool = False
    seam_part: str = ""


@dataclass(frozen=True)
class LevelGeometry:
    """Placement of one level: ``level index = level-0 index * scale + offset``; voxel ``v`` of
    the level is at ``origin + v * spacing`` in the world."""

    shape: np.ndarray
    origin: np.ndarray
    spacing: np.ndarray
    scale: np.ndarray
    offset: np.ndarray

    def from_level0(self, index: np.ndarray) -> np.ndarray:
        """Level-0 index coordinates to this level's."""
        return np.asarray(index, dtype=np.float64) * self.scale + self.offset


def screen_rect(camera: Camera, lo: np.ndarray, hi: np.ndarray) -> tuple[int, int, int, int] | None:
    """Pixel rectangle ``(col0, row0, width, height)`` of ``camera``'s image that the world box
    ``[lo, hi]`` can project to (one pixel of margin), or ``None`` if it projects outside."""
    rects, seen = screen_rects(camera, np.asarray(lo, np.float64)[None],
                               np.asarray(hi, np.float64)[None])
    if not seen[0]:
        return None
    c0, r0, c1, r1 = (int(v) for v in rects[0])
    return c0, r0, c1 - c0, r1 - r0


def screen_rects(camera: Camera, lo: np.ndarray,
                 hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`screen_rect` of many world boxes ``[lo[n], hi[n]]`` at once.

    Returns
    -------
    rects : ndarray (n, 4) of int64
        ``(col0, row0, col1, row1)`` (end exclusive) of each box.
    seen : ndarray (n,) of bool
        Whether the box can project into the image (``rects`` is meaningless where not).
    """
    basis = camera.pixel_basis()
    eye, fwd = basis[BASIS_EYE:BASIS_EYE + 3], basis[BASIS_FORWARD:BASIS_FORWARD + 3]
    right, up = basis[BASIS_RIGHT:BASIS_RIGHT + 3], basis[BASIS_UP:BASIS_UP + 3]
    half_w, half_h = basis[BASIS_HALF_WIDTH], basis[BASIS_HALF_HEIGHT]
    ortho = basis[BASIS_ORTHO] != 0.0
    col0, row0 = basis[BASIS_COL0], basis[BASIS_ROW0]
    full_w, full_h = basis[BASIS_FULL_WIDTH], basis[BASIS_FULL_HEIGHT]
    n = len(lo)
    pick = np.array([[(b >> a) & 1 for a in range(3)] for b in range(8)], dtype=bool)
    corners = np.where(pick[None], np.asarray(hi, np.float64)[:, None, :],
                       np.asarray(lo, np.float64)[:, None, :]) - eye  # (n, 8, 3)
    sx, sy = corners @ right, corners @ up
    seen = np.ones(n, dtype=bool)
    whole = np.zeros(n, dtype=bool)
    if not ortho:
        depth = corners @ fwd
        seen = ~np.all(depth <= 0, axis=1)
        whole = np.any(depth <= 1e-9 * (np.abs(sx) + np.abs(sy) + 1.0), axis=1)  # at the eye
        with np.errstate(divide="ignore", invalid="ignore"):
            sx, sy = sx / depth, sy / depth
    cols = (sx / half_w + 1.0) * 0.5 * full_w - 0.5 - col0
    rows = (1.0 - sy / half_h) * 0.5 * full_h - 0.5 - row0
    with np.errstate(invalid="ignore"):
        bounds = np.stack([np.floor(cols.min(axis=1)) - 1, np.floor(rows.min(axis=1)) - 1,
                           np.ceil(cols.max(axis=1)) + 2, np.ceil(rows.max(axis=1)) + 2], axis=1)
    bounds[whole] = (0, 0, camera.width, camera.height)
    bounds = np.nan_to_num(bounds, nan=0.0, posinf=0.0, neginf=0.0)
    lim = np.array([camera.width, camera.height], dtype=np.float64)
    bounds[:, :2] = np.maximum(bounds[:, :2], 0.0)
    bounds[:, 2:] = np.minimum(bounds[:, 2:], lim)
    rects = bounds.astype(np.int64)
    seen &= (rects[:, 0] < rects[:, 2]) & (rects[:, 1] < rects[:, 3])
    return rects, seen


class CutRenderer:
    """Traces the drawables of a cut with one model, front to back per ray.

    Parameters
    ----------
    model : a model of :data:`splinecast.models.MODELS`
        Prepared once (from any level: only its kind, options and tables are used); drawables'
        arrays become its kernel grids.
    tree : BrickOctree
        The levels' geometry and the bricks' nesting (for the front-to-back order).
    seams : optional
        Seam treatment with ``plan(drawables, renderer)`` and ``closure``
        (:class:`.draw.seams.Seams`); ``None`` draws every brick as it is.
    """

    def __init__(self, model: Any, tree: Any, seams: Any = None) -> None:
        self.model = model
        self.tree = tree
        self.seams = seams
        #: Border layers of the model's prepared array: cell ``c`` reads voxels ``c - pad ..``.
        self.pad = (int(model.prepared.shape[0]) - int(model.volume.shape[0])) // 2
        lo, _ = model.domain()
        #: The model renders this far (voxels) beyond the outer voxel centres (type-6: 1/2).
        self.margin = -float(lo[0])
        n0 = np.asarray(tree.n0, dtype=np.float64)
        self.domain0 = (np.full(3, -self.margin), n0 - 1.0 + self.margin)
        self.levels = {int(level): self._geometry(int(level)) for level in tree.levels}
        g0 = self.levels[int(tree.levels[0])]
        #: World placement of the level-0 index space the boxes are given in (the finest
        #: level's own index space unless its map has an offset, as spline-wavelet levels do).
        self.origin0 = g0.origin + g0.offset * g0.spacing
        self.spacing0 = g0.scale * g0.spacing
        self._grids: dict[Hashable, Grid] = {}
        self._prepared: dict[Hashable, tuple[np.ndarray, np.ndarray]] = {}
        #: Grids of arrays changed at a seam, kept with their change while the seam plan
        #: (which keeps its ``Change`` objects while the cut stays) hands out the same one.
        self._changed: dict[Hashable, tuple[Any, Grid, int]] = {}
        #: Per (brick key, box) changed at a seam: the change and the parts it is drawn as
        #: (:mod:`.draw.seam_parts`: shells, then the core last), or ``None`` for a whole copy.
        self._split: dict[tuple, tuple[Any, list[Drawable] | None, Any]] = {}
        #: Draw bricks changed at a seam as shells around their unchanged core (else each from
        #: a float64 copy of its whole array, the reference the parts are tested against).
        self.split_seams = True
        self._serial = 0
        #: Per brick: its grid's (kernel, blocks) pair for the launch (see :meth:`_pair`).
        self._pairs: dict[Hashable, tuple] = {}
        #: Per mode type: the (kernel, blocks) pair type of a grid changed at a seam.
        self._seam_pairs: dict[Hashable, tuple[tuple, Hashable]] = {}
        #: The last frame's typed lists of pairs (see :meth:`_pack`).
        self._packed: tuple | None = None
        #: The last frame's drawables, seam changes, view, order and launch arrays (see
        #: :meth:`_trace`).
        self._last: _LastDraw | None = None
        #: Trace all drawables of a frame in one compiled launch (else one call per drawable).
        self.batched = True
        self.stats: dict[str, Any] = {}

    def _geometry(self, level: int) -> LevelGeometry:
        lv = self.tree.volume.level(level)
        scale, offset = self.tree.level_map(level)
        return LevelGeometry(np.asarray(lv.shape, dtype=np.int64),
                             np.asarray(lv.origin, dtype=np.float64),
                             np.asarray(lv.spacing, dtype=np.float64),
                             np.asarray(scale, dtype=np.float64),
                             np.asarray(offset, dtype=np.float64))

    # ------------------------------------------------------------------ arrays and grids
    def prepared(self, drawable: Drawable) -> tuple[np.ndarray, np.ndarray]:
        """The array the model's kernels read for a drawable, and the level index of its first
        element (the brick's voxels; the type-6 prefilter applied when the model has it)."""
        if drawable.seam_part == "shell":
            return drawable.data, np.asarray(drawable.first, dtype=np.int64)
        cached = self._prepared.get(drawable.key)
        if cached is not None:
            return cached
        first = np.asarray(drawable.first, dtype=np.int64)
        data = drawable.data
        data, first = self.model.prefilter_brick(data, first, self.levels[drawable.level].shape)
        self._prepared[drawable.key] = (data, first)
        return data, first

    def grid(self, level: int, array: np.ndarray, first: np.ndarray) -> Grid:
        """The model's grid over ``array`` (values of ``level`` from index ``first`` on)."""
        g = self.levels[level]
        lo, hi = g.from_level0(self.domain0[0]), g.from_level0(self.domain0[1])
        cells = g.shape + 2 * self.pad - int(self.model.support)
        return make_grid(self.model, array, offset=np.asarray(first) + self.pad,
                         level_origin=g.origin, level_spacing=g.spacing, domain=(lo, hi),
                         level_cells=cells)

    def _drawable_grid(self, drawable: Drawable, changes: dict) -> tuple[Grid, bool]:
        """The grid to trace for a drawable: cached, or built from the array changed at a seam.
        Builds of small bricks run their compiled calls on one thread (thread start-up costs
        more than they do); a cached grid costs a dictionary lookup only, which matters at tens
        of thousands of drawables per frame (switching the thread count for every drawable took
        0.44 s of a profiled 32 k-drawable wavelet frame)."""
        change = None if drawable.seam_part else changes.get(drawable.key)
        if change is None:
            grid = self._grids.get(drawable.key)
            if grid is None:
                with _threads(drawable.data.size < SERIAL_CELLS):
                    array, first = self.prepared(drawable)
                    grid = self._grids[drawable.key] = self.grid(drawable.level, array, first)
            return grid, False
        kept = self._changed.get(drawable.key)
        if kept is not None and kept[0] is change:
            return kept[1], False
        with _threads(drawable.data.size < SERIAL_CELLS):
            array, first = self.prepared(drawable)
            copy = change.apply(array)
            grid = self.grid(drawable.level, copy, first)
        self._changed[drawable.key] = (change, grid, copy.nbytes)
        return grid, True

    def evaluate(self, drawable: Drawable, points: np.ndarray,
                 changes: dict | None = None) -> np.ndarray:
        """The reconstruction a drawable draws (with its seam ``changes``, if any) at level-0 index
        points (n, 3)."""
        array, first = self.prepared(drawable)
        change = (changes or {}).get(drawable.key)
        if change is not None:
            array = change.apply(array)
        grid = self.grid(drawable.level, array, first)
        local = (self.levels[drawable.level].from_level0(points) + self.model.shift
                 - grid.geom[GEOM_OFFSET:GEOM_OFFSET + 3])
        out = np.empty(len(local))
        sample_grid(grid.kernel, np.ascontiguousarray(local), out)
        return out

    def forget(self, keep: Iterable[Hashable]) -> None:
        """Drop the grids and arrays of bricks not in ``keep`` (the cache may evict them)."""
        keep = set(keep)
        for key in [k for k in self._split if k[0] not in keep]:
            self._drop_split(key)
        keep.update(shell.key for entry in self._split.values() for shell in (entry[1] or [])[:-1])
        for store in (self._grids, self._prepared, self._changed, self._pairs):
            for key in [k for k in store if k not in keep]:
                del store[key]

    # ------------------------------------------------------------------ rendering
    def box(self, drawable: Drawable) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The level-0 box a drawable draws, and which of its upper faces are the domain's (closed
        to rays lying in them).

        The cut's box moved by ``-shift`` level-0 voxels, so that boxes of level 0 end on cell
        boundaries also for the models whose cells are centred on voxels (even B-splines,
        type-6): a ray then meets the same cells, cut at the same places, as in the whole
        volume (DVR's segments end at every cell boundary). Moving every box alike keeps them a
        partition. At the volume's border the box reaches the model's domain.
        """
        lo = np.asarray(drawable.box_lo, dtype=np.float64)
        hi = np.asarray(drawable.box_hi, dtype=np.float64)
        d_lo, d_hi = self.domain0
        if drawable.placed:
            return lo, hi, hi >= d_hi
        shift = float(self.model.shift)
        first, last = lo <= 0.0, hi >= d_hi - self.margin
        lo = np.where(first, d_lo, lo - shift)
        hi = np.where(last, d_hi, hi - shift)
        return lo, hi, last

    def render(self, drawables: Sequence[Drawable], setup: Any, camera: Camera,
               planes: np.ndarray = NO_PLANES) -> tuple[tuple, tuple]:
        """Trace an image through the drawables of a cut; returns ``(outputs, counters)``."""
        h, w = camera.height, camera.width
        stats = counters(h, w)
        out = setup.output(h, w)
        # The states are reset and the outputs written inside the one launch (no separate
        # passes over the image), or around the per-drawable path.
        self._trace(drawables, setup, camera, setup.state(h, w), stats, planes, out)
        return out, stats

    def trace(self, drawables: Sequence[Drawable], setup: Any, camera: Camera, state: tuple,
              stats: tuple, planes: np.ndarray = NO_PLANES) -> None:
        """Carry the per-pixel ``state`` of ``setup`` through the drawables, front to back.

        ``state`` and ``stats`` are full-image arrays
        (:func:`~splinecast.render.segment.new_state`,
        :func:`~splinecast.render.segment.counters`), updated in place; a renderer
        that splits a cut (a distributed worker) traces its share into its own state and
        merges the states with the mode's ``combine`` in depth order.

        One compiled launch traces all drawables
        (:func:`~splinecast.render.cut_driver.trace_cut`); with :attr:`batched` off, or for a
        cut whose grids have more than two Numba types, each drawable is traced by its own call of
        the segment entry point (the reference the batched launch is tested against).
        """
        self._trace(drawables, setup, camera, state, stats, planes, None)

    def _trace(self, drawables: Sequence[Drawable], setup: Any, camera: Camera, state: tuple,
               stats: tuple, planes: np.ndarray, out: tuple | None) -> None:
        """:meth:`trace`; with ``out``, from uninitialised ``state`` arrays (reset here) to the
        finished outputs written into ``out``."""
        start = time.perf_counter()
        planes = np.ascontiguousarray(planes, dtype=np.float64).reshape(-1, 4)
        # The same drawables (the scene hands out the same list while the cut and what is
        # resident stay) seen the same way: the seam plan, the order and the launch's arrays
        # of the last frame are still right (tens of microseconds per drawable to redo).
        view = (camera.pixel_basis().tobytes(), planes.tobytes(), _blocks_key(setup),
                type(setup.params))
        last = self._last
        steady = last is not None and last.drawables is drawables and view[2] is not None
        if steady:
            assert last is not None
            changes = last.changes
        else:
            changes = self.seams.plan(drawables, self) if self.seams is not None else {}
            # Grids built for a change an array no longer has go: kept while the array stayed
            # in the cut, such float64 copies (8 bytes per voxel) grew to several times the
            # brick budget while a large cut refined.
            for key in [k for k, (change, *_) in self._changed.items()
                        if changes.get(k) is not change]:
                del self._changed[key]
            for key in [k for k, entry in self._split.items()
                        if changes.get(k[0]) is not entry[0]]:
                self._drop_split(key)
        plan_s = time.perf_counter() - start
        closure = self.seams.closure(setup, camera) if self.seams is not None else None
        if steady and last is not None and last.view == view:
            drawn, drawn_changes, launch = last.drawn, last.drawn_changes, last.launch
        else:
            keys = np.array([p.cut_key for p in drawables], dtype=np.int64).reshape(-1, 4)
            drawn, drawn_changes = self._drawn(drawables, front_to_back(keys, camera, self.tree),
                                                  changes, camera)
            launch = None
        order = np.arange(len(drawn))
        self._last = None
        done = None
        if self.batched:
            done, launch = self._trace_batched(drawn, order, drawn_changes, closure, setup,
                                               camera, state, stats, planes, out, launch)
            if done is not None and view[2] is not None:
                self._last = _LastDraw(drawables, changes, view, drawn, drawn_changes, launch)
        if done is None:
            if out is not None:
                reset_state(setup.params, state, camera.height, camera.width)
            done = self._trace_each(drawn, order, drawn_changes, closure, setup, camera, state,
                                    stats, planes)
            if out is not None:
                finalize(setup.params, state, out, camera.pixel_basis())
        traced, rebuilt = done
        self.stats = {"drawables": len(drawables), "drawables_traced": traced,
                      "launch_reused": steady,
                      "one_launch": self._last is not None,
                      "drawables_changed_at_seams": len(changes), "grids_built_at_seams": rebuilt,
                      "seam_plan_ms": plan_s * 1e3, "seam_parts": len(drawn) - len(drawables),
                      "seam_copy_bytes": self.seam_copy_bytes()}
        if closure is not None:
            self.stats["seam_closure_hits"] = closure.hits

    # ------------------------------------------------------------------ seams drawn in parts
    def seam_copy_bytes(self) -> int:
        """Bytes of changed values held for seams: the shells' arrays, the whole copies of
        bricks not split, and the changes they were made from (the changed elements' indices
        and values, kept to tell whether the next frame's changes are the same); the scene holds
        them inside its budget with :meth:`~.store.cache.BrickCache.reserve`."""
        shells = sum(shell.data.nbytes for _, parts, _ in self._split.values() if parts
                     for shell in parts[:-1])
        held = {id(entry[0]): entry[0] for entry in (*self._split.values(),
                                                      *self._changed.values())}
        changes = sum(c.index.nbytes + c.values.nbytes for c in held.values())
        return shells + changes + sum(nbytes for _, _, nbytes in self._changed.values())

    def _drawn(self, drawables: Sequence[Drawable], order: np.ndarray, changes: dict,
               camera: Camera) -> tuple[list[Drawable], dict]:
        """The drawables to trace, front to back, and the seam changes still to apply to them:
        each drawable changed at a seam is replaced by its parts (:mod:`.draw.seam_parts`) in the
        order seen from ``camera``, where it splits."""
        ordered = [drawables[int(n)] for n in order]
        if not changes or not self.split_seams:
            return ordered, changes
        point, eye = eye_index(camera, self.tree)
        drawn: list[Drawable] = []
        used: set[tuple] = set()
        for drawable in ordered:
            change = changes.get(drawable.key)
            if change is None:
                drawn.append(drawable)
                continue
            lo, hi, _ = self.box(drawable)
            key = (drawable.key, lo.tobytes(), hi.tobytes())
            entry = self._split.get(key)
            if entry is None or entry[0] is not change:
                if entry is not None:
                    self._drop_split(key)
                entry = self._split[key] = (change, *self._parts(drawable, change, lo, hi))
            used.add(key)
            parts, split = entry[1], entry[2]
            if parts is None:
                drawn.append(drawable)
            elif split is None:  # no changed element reaches the box: the brick's own grid
                drawn.extend(parts)
            else:
                lv = self.levels[drawable.level]
                if eye is None:
                    at = part_order(split, point * lv.scale, perspective=False)
                else:
                    at = part_order(split, lv.from_level0(eye), perspective=True)
                drawn.extend(parts[int(p)] for p in at)
        # Only what this frame draws is kept: parts of boxes no longer drawn, and whole copies
        # of bricks now drawn in parts (or from an ancestor's box that splits) go.
        for key in [k for k in self._split if k not in used]:
            self._drop_split(key)
        whole = {drawable.key for drawable in drawn if not drawable.seam_part}
        for key in [k for k in self._changed if k not in whole]:
            del self._changed[key]
        return drawn, {k: c for k, c in changes.items() if k in whole}

    def _parts(self, drawable: Drawable, change: Any, lo: np.ndarray,
               hi: np.ndarray) -> tuple[list[Drawable] | None, Parts | None]:
        """A changed drawable's parts (shells, then the core) and their split, or ``(None,
        None)`` when it is drawn from a whole copy."""
        array, first = self.prepared(drawable)
        lv = self.levels[drawable.level]
        lo_b, hi_b = lv.from_level0(lo), lv.from_level0(hi)
        radius = float(self.seams.radius) if self.seams is not None else 0.0
        elements = np.stack(np.unravel_index(change.index, array.shape), axis=1) + first
        # Only elements a point of the box can read matter (an ancestor standing in for a
        # missing brick carries the changes of its whole array).
        reach = np.all((elements >= lo_b - radius - 1.0) & (elements <= hi_b + radius + 1.0),
                       axis=1)
        if not reach.any():
            return [replace(drawable, seam_part="core")], None
        split = split_box(lo_b, hi_b, elements[reach], radius)
        if split is None:
            return None, None
        crops = [crop_range(box_lo, box_hi, first, array.shape, radius)
                 for box_lo, box_hi in split.boxes[:-1]]
        if sum(int(np.prod(stop - start)) for start, stop in crops) > (
                SHELL_SHARE_MAX * array.size):
            return None, None
        changed = change.apply(array)  # transient: only the shells' elements are kept
        parts: list[Drawable] = []
        for p, (box_lo, box_hi) in enumerate(split.boxes):
            # Back to level 0, exactly where a part's face is the brick's.
            lo0 = np.where(box_lo == lo_b, lo, (box_lo - lv.offset) / lv.scale)
            hi0 = np.where(box_hi == hi_b, hi, (box_hi - lv.offset) / lv.scale)
            if p == len(split.boxes) - 1:
                parts.append(replace(drawable, box_lo=lo0, box_hi=hi0, placed=True,
                                     seam_part="core"))
                continue
            start, stop = crops[p]
            data = np.ascontiguousarray(changed[start[0]:stop[0], start[1]:stop[1],
                                                start[2]:stop[2]])
            self._serial += 1
            parts.append(replace(drawable, key=("seam shell", self._serial), data=data,
                                 first=tuple(int(v) for v in first + start), box_lo=lo0,
                                 box_hi=hi0, placed=True, seam_part="shell"))
        return parts, split

    def _drop_split(self, key: tuple) -> None:
        """Forget a changed drawable's parts and the grids built for its shells."""
        _, parts, _ = self._split.pop(key)
        for shell in (parts or [])[:-1]:
            for store in (self._grids, self._pairs):
                store.pop(shell.key, None)

    def boxes(self, drawables: Sequence[Drawable]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`box` of many drawables at once: ``lo``, ``hi`` (n, 3) and ``closed`` (n, 3)."""
        n = len(drawables)
        lo = np.array([p.box_lo for p in drawables], dtype=np.float64).reshape(n, 3)
        hi = np.array([p.box_hi for p in drawables], dtype=np.float64).reshape(n, 3)
        placed = np.array([p.placed for p in drawables], dtype=bool)[:, None]
        d_lo, d_hi = self.domain0
        shift = float(self.model.shift)
        first, last = lo <= 0.0, hi >= d_hi - self.margin
        out_lo = np.where(placed, lo, np.where(first, d_lo, lo - shift))
        out_hi = np.where(placed, hi, np.where(last, d_hi, hi - shift))
        closed = np.where(placed, hi >= d_hi, last)
        return out_lo, out_hi, closed

    def _trace_batched(self, drawables: Sequence[Drawable], order: np.ndarray, changes: dict,
                       closure: Any, setup: Any, camera: Camera, state: tuple, stats: tuple,
                       planes: np.ndarray, out: tuple | None,
                       launch: _Launch | None = None) -> tuple[tuple[int, int] | None, Any]:
        """All drawables in one compiled launch (with ``out``: the states reset and the outputs
        written in it too); ``None``, before anything is traced, if their grids have too many
        types. Returns that and the launch's arrays (``launch``: those of the last frame, for
        the same drawables, seam changes, view and mode)."""
        if launch is None:
            launch = self._launch(drawables, order, changes, setup, camera)
        if launch is None:
            return None, None
        h, w = camera.height, camera.width
        if not len(launch.which):
            if out is not None:
                reset_state(setup.params, state, h, w)
                finalize(setup.params, state, out, camera.pixel_basis())
            return (0, launch.rebuilt), launch
        if closure is not None:
            exits = (closure.exit_t, np.zeros((h, w), dtype=np.int64), closure.exit_level)
        else:
            exits = (np.empty((0, 0)), np.empty((0, 0), dtype=np.int64),
                     np.empty((0, 0), dtype=np.int64))
        final = out is not None
        hits = trace_cut(launch.grids[0], launch.grids[1], launch.which, setup.params, state,
                         out if final else setup.output(0, 0), camera.pixel_basis(),
                         launch.geoms, launch.boxes, launch.closed, launch.rects,
                         launch.levels, self.origin0, self.spacing0, planes,
                         np.empty((h, w, 2)), _tiles(h, w), *launch.tile_lists, final, final,
                         closure is not None, *exits, *stats)
        if closure is not None:
            closure.hits += int(hits)
        rebuilt, launch.rebuilt = launch.rebuilt, 0  # built once, for the first frame
        return (len(launch.which), rebuilt), launch

    def _launch(self, drawables: Sequence[Drawable], order: np.ndarray, changes: dict, setup: Any,
                camera: Camera) -> _Launch | None:
        """The arrays :func:`trace_cut` takes for the drawables seen by ``camera`` (grids built
        where missing); ``None`` if their grids have more than two Numba types."""
        ordered = [drawables[int(n)] for n in order]
        if not ordered:
            return None
        lo, hi, closed = self.boxes(ordered)
        world_lo = self.origin0 + lo * self.spacing0
        world_hi = self.origin0 + hi * self.spacing0
        rects, seen = screen_rects(camera, np.minimum(world_lo, world_hi),
                                   np.maximum(world_lo, world_hi))
        keep = np.flatnonzero(seen)
        rebuilt = 0
        blocks_key = _blocks_key(setup)
        pairs: list[tuple[tuple, Hashable]] = []  # distinct grids' (kernel, blocks), signature
        index: dict[int, int] = {}  # id(grid) -> position in pairs
        per_drawable = np.empty(len(keep), dtype=np.int64)
        geoms = np.empty((len(keep), GEOM_SIZE))
        for m, n in enumerate(keep):
            drawable = ordered[int(n)]
            grid, changed = self._drawable_grid(drawable, changes)
            rebuilt += changed
            geoms[m] = grid.geom
            at = index.get(id(grid))
            if at is None:
                at = index[id(grid)] = len(pairs)
                pairs.append(self._pair(drawable.key, grid, setup, blocks_key))
            per_drawable[m] = at
        if not len(keep):
            return _Launch((), np.zeros((0, 2), np.int64), geoms, np.zeros((0, 2, 3)),
                           np.zeros((0, 3), bool), np.zeros((0, 4), np.int64),
                           np.zeros(0, np.int64), rebuilt, ())
        packed = self._pack(pairs, lambda: self._seam_pair(ordered[int(keep[0])], setup),
                            lambda: self._float32_pair(ordered[int(keep[0])], setup))
        if packed is None:
            return None
        grids, slot = packed
        rects = np.ascontiguousarray(rects[keep])
        return _Launch(tuple(grids), np.ascontiguousarray(slot[per_drawable]), geoms,
                       np.ascontiguousarray(np.stack([lo[keep], hi[keep]], axis=1)),
                       np.ascontiguousarray(closed[keep]), rects,
                       np.array([ordered[int(n)].level for n in keep], dtype=np.int64), rebuilt,
                       tile_lists(rects, camera.height, camera.width))

    def _pack(self, pairs: list[tuple[tuple, Hashable]],
              seam_pair: Callable[[], tuple[tuple, Hashable]],
              float32_pair: Callable[[], tuple]) -> tuple[list, np.ndarray] | None:
        """The launch's two typed lists of ``(kernel, blocks)`` and each pair's ``(list,
        index)``; ``None`` for more than two Numba types. Kept while the pairs are the same
        objects (a steady view): filling typed lists costs tens of microseconds per item.

        The second list always has the type of grids changed at a seam (``seam_pair``, a
        float64 copy), empty or not, so a view with seams and one without use the same compiled
        launch: otherwise the first seam of a session (and every test with another mix) would
        compile the launch again (tens of seconds) for the same store. When every grid has that
        type (a float64 store, spline-wavelet bricks) the first list is an empty one of the
        type a float32 store's grids have (``float32_pair``), so the launch compiled for
        float32 stores serves them too (for the same reason)."""
        key = [pair for pair, _ in pairs]
        kept = self._packed
        if kept is not None and len(kept[0]) == len(key) and all(
                a is b for a, b in zip(kept[0], key, strict=True)):
            return kept[1], kept[2]
        members: dict[Hashable, list[int]] = {}
        for at, (_, signature) in enumerate(pairs):
            members.setdefault(signature, []).append(at)
        seam, seam_signature = seam_pair()
        stored = [signature for signature in members if signature != seam_signature]
        if len(stored) > 1:
            return None
        order = [stored[0] if stored else None, seam_signature]
        slot = np.empty((len(pairs), 2), dtype=np.int64)
        grids: list[Any] = []
        for number, signature in enumerate(order):
            if signature is None:  # only float64 grids
                grids.append(_typed_list_of(float32_pair()))
                continue
            ats = members.get(signature, [])
            items = _typed_list_of(pairs[ats[0]][0] if ats else seam)
            for k, at in enumerate(ats):
                _append(items, pairs[at][0])
                slot[at] = number, k
            grids.append(items)
        # The pairs themselves are kept (compared by identity: the lists hold copies).
        self._packed = (key, grids, slot)
        return grids, slot

    def _seam_pair(self, drawable: Drawable, setup: Any) -> tuple[tuple, Hashable]:
        """A ``(kernel, blocks)`` pair of the type a grid changed at a seam has (built from a
        float64 copy of ``drawable``'s array, as :meth:`~.draw.seams.Change.apply` makes), and its
        signature; one per mode type."""
        key = _signature(setup.params)
        kept = self._seam_pairs.get(key)
        if kept is None:
            # Only its type matters: a corner of the array, not a float64 copy of the whole
            # brick kept beside the budget for the session.
            array, first = self.prepared(drawable)
            corner = np.array(array[:_EXEMPLAR, :_EXEMPLAR, :_EXEMPLAR], dtype=np.float64,
                              order="C")
            grid = self.grid(drawable.level, corner, first)
            pair = (grid.kernel, setup.blocks(grid.hierarchy))
            kept = self._seam_pairs[key] = (pair, _signature(pair))
        return kept

    def _float32_pair(self, drawable: Drawable, setup: Any) -> tuple:
        """A ``(kernel, blocks)`` pair of the type a float32 store's grids have (the type-6
        models convert every array to their own dtype: there it is the seam pair's type)."""
        key = ("float32", _signature(setup.params))
        kept = self._seam_pairs.get(key)
        if kept is None:
            array, first = self.prepared(drawable)
            corner = array[:_EXEMPLAR, :_EXEMPLAR, :_EXEMPLAR]
            grid = self.grid(drawable.level, np.array(corner, dtype=np.float32, order="C"), first)
            kept = self._seam_pairs[key] = ((grid.kernel, setup.blocks(grid.hierarchy)), None)
        return kept[0]

    def _pair(self, key: Hashable, grid: Grid, setup: Any,
              blocks_key: Any) -> tuple[tuple, Hashable]:
        """A grid's ``(kernel, blocks)`` for the launch and the signature of its Numba type;
        kept between frames while the grid and the mode's block selection stay the same (block
        flags and Numba's typing cost a millisecond or more per drawable)."""
        kept = self._pairs.get(key)
        if kept is not None and kept[0] is grid and blocks_key is not None and (
                kept[1] == blocks_key):
            return kept[2], kept[3]
        pair = (grid.kernel, setup.blocks(grid.hierarchy))
        signature = _signature(pair)
        self._pairs[key] = (grid, blocks_key, pair, signature)
        return pair, signature

    def _trace_each(self, drawables: Sequence[Drawable], order: np.ndarray, changes: dict,
                    closure: Any, setup: Any, camera: Camera, state: tuple, stats: tuple,
                    planes: np.ndarray) -> tuple[int, int]:
        """One segment-entry-point call per drawable, over the screen rectangle of its box."""
        origin0, spacing0 = self.origin0, self.spacing0
        traced = rebuilt = 0
        for n in order:
            drawable = drawables[int(n)]
            lo, hi, closed = self.box(drawable)
            world_lo = origin0 + lo * spacing0
            world_hi = origin0 + hi * spacing0
            rect = screen_rect(camera, np.minimum(world_lo, world_hi),
                               np.maximum(world_lo, world_hi))
            if rect is None:
                continue
            tile = camera if rect == (0, 0, camera.width, camera.height) else camera.tile(*rect)
            t_range = np.empty((tile.height, tile.width, 2))
            if box_ranges(tile.pixel_basis(), origin0, spacing0, lo, hi, closed, planes,
                          t_range) == 0:
                continue
            grid, changed = self._drawable_grid(drawable, changes)
            rebuilt += changed
            traced += 1
            local = _gather(state, rect, tile is camera)
            local_stats = counters(tile.height, tile.width)
            if closure is not None:
                closure.enter(drawable, grid, tile, t_range, local, rect)
            with _threads(tile.width * tile.height < SERIAL_PIXELS):
                trace_segment(grid, setup, tile, local, local_stats, planes, t_range)
            if closure is not None:
                closure.leave(drawable, grid, tile, t_range, local, rect)
            if tile is not camera:
                _scatter(state, local, rect)
            for total, part in zip(stats, local_stats, strict=True):
                c0, r0, w, h = rect
                total[r0:r0 + h, c0:c0 + w] += part
        return traced, rebuilt


@dataclass
class _LastDraw:
    """What the last frame drew: its drawables (the list object), their seam changes, the view
    (camera basis, clip planes, block selection, mode type), the drawables as traced and the
    launch's arrays."""

    drawables: Sequence[Drawable]
    changes: dict
    view: tuple
    #: The drawables as traced (changed ones in parts), front to back, and their changes.
    drawn: list[Drawable]
    drawn_changes: dict
    launch: Any


@dataclass
class _Launch:
    """What :func:`trace_cut` takes for one frame's drawables, besides the mode's arrays."""

    grids: tuple
    which: np.ndarray
    geoms: np.ndarray
    boxes: np.ndarray
    closed: np.ndarray
    rects: np.ndarray
    levels: np.ndarray
    #: Grids built at seams for it (reported by the first frame that traces it).
    rebuilt: int
    #: :func:`~splinecast.render.cut_driver.tile_lists` of ``rects``.
    tile_lists: tuple


def _blocks_key(setup: Any) -> Hashable:
    """What a mode's block selection (``setup.blocks``) depends on besides the grid, or None
    when unknown (then it is recomputed every frame)."""
    try:
        return setup.blocks_key()
    except (TypeError, ValueError):
        return None


def _signature(value: Any) -> Hashable:
    """A cheap stand-in for ``numba.typeof(value)`` of tuples of arrays and numbers: equal
    signatures, equal Numba types."""
    if isinstance(value, np.ndarray):
        f = value.flags
        # Numba's layout: an array both C- and F-contiguous (a thin shell's coarsest block
        # level, (3, 1, 1)) is typed "C"; telling the two apart split one type in two and sent
        # every frame with seam shells to the per-drawable path.
        layout = "C" if f.c_contiguous else "F" if f.f_contiguous else "A"
        return (value.dtype.str, value.ndim, layout, f.writeable, f.aligned)
    if isinstance(value, tuple):
        return (type(value), tuple(_signature(v) for v in value))
    if isinstance(value, np.generic):
        return (type(value), value.dtype.str)
    return type(value)


def _tiles(height: int, width: int) -> np.ndarray:
    """First row and column of the launch's tiles, in an order that spreads every contiguous
    run of tiles (one thread's share) over the image."""
    rows = np.arange(0, height, TILE)
    cols = np.arange(0, width, TILE)
    grid = np.stack(np.meshgrid(rows, cols, indexing="ij"), axis=-1).reshape(-1, 2)
    return np.ascontiguousarray(grid[band_order(len(grid))], dtype=np.int64)


def _gather(state: tuple, rect: tuple[int, int, int, int], whole: bool) -> tuple:
    if whole:
        return state
    c0, r0, w, h = rect
    return tuple(np.ascontiguousarray(a[r0:r0 + h, c0:c0 + w]) for a in state)


def _scatter(state: tuple, local: tuple, rect: tuple[int, int, int, int]) -> None:
    c0, r0, w, h = rect
    for full, part in zip(state, local, strict=True):
        full[r0:r0 + h, c0:c0 + w] = part
