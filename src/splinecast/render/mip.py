"""Maximum (and minimum) intensity projection, exactly or sampled, for every model.

Exact MIP (Józsa et al. 2014, section 9): along a ray the reconstruction is, piece by piece, a
polynomial; its largest value on a piece is at an end or at a root of its derivative
(:func:`splinecast.roots.pieces.poly_max`), so the maximum along the whole ray is found with no
step size at all.

Empty-space skipping uses the block maxima of the min/max hierarchy: a block whose largest possible
value does not exceed the running maximum cannot change the result and is leapt over, which, once a
bright structure has been met, removes most of the ray. Before that walk, the exact method takes a
lower bound of the answer: blocks (cells, pieces) whose maximum lies strictly below it are left out
from the start, so a bright structure far behind dim ones is reached without testing the dim ones
first. Neighbouring rays of an image find their maxima at nearly the same depth, so the bound is the
model's value on this ray at the depth where the thread's previous ray found its maximum: a value
the ray does meet, usually close to its answer, and tighter than the block bound below. A thread's
first ray has no predecessor; it walks the 16-cell blocks instead, taking the largest block minimum
(every value the ray meets inside a block is at least the block's minimum) and the model's values at
a few points inside the block with the largest maximum. The bound only decides what is left out,
never the answer, which is therefore the same whatever the order of the rays. Minimum intensity
projection is the same computation on the negated field.

Two more prunings leave the answer bit-identical (``tests/test_mip.py``): a tested piece whose
Bernstein control points cannot beat the running maximum, or lie below the lower bound, is
dropped before the roots of its derivative are solved for, and after a tested cell the driver
asks for the skip size again (``asks_again``), so a ray whose maximum reached its block's
(plateaus of equal values, as in CT and MRI) leaps the rest of the block.

With a tolerance ``e`` (``Mip(tolerance=...)``, a fraction of the display window), the exact
method leaves out every block, cell and piece whose maximum does not beat the running maximum
by more than ``e``, and the lower bound's value becomes the running maximum itself. The running
maximum only grows, so everything left out lies at most ``e`` above the final answer: that
answer is a value the ray meets (at the depth reported) and at most ``e`` below the exact one,
for every pixel (``tests/test_mip.py``). Here the bound also decides which value within the
tolerance a pixel reports, so a ray may take it only from the previous ray of its own tile of the
image (the driver's ``tile_begin`` clears it at each tile): a window of the image on that grid of
tiles (:attr:`splinecast.Scene.tile_shape`: the viewer's stripes, Dask's tiles) shows the whole
image's pixels. The larger the tolerance, the more of each ray is left
out (``benchmarks/mip_tolerance.py`` measures the trade). The sampled methods have no such
bound: a thin bright structure between two samples is missed whole.

The sampled method (the reference common viewers use) runs the fixed-step loop of
:mod:`.sampler`, with no cell walk: the model's values at the ray's entry into the grid, every
``step`` voxels from the ray's entry into the volume, and at its exit. The loop leaps a block
whose maximum does not beat the running one, as the exact walk does. It can only report values
the field takes, so it never exceeds the exact MIP. A ray traced brick by brick also takes the
values where it crosses the brick faces, so its maximum may be larger than through the whole
volume (closer to the exact one, never above it; on 8^3 bricks of smooth noise, by up to 2% of
the volume's range at a 1.5-voxel step). It takes no cell walk: samples inside the exact
method's cell walk paid for every cell between them.

Both methods start and end rays at the blocks holding a value above the volume's smallest
(:meth:`Mip.footprint_flags`, :mod:`.footprint`): every other value equals the smallest, which a
ray meets first where it enters the volume, so that value is taken there and the air around
an object (78% of the MRI's voxels are 0) is neither walked nor sampled. The answer, its depth
and its position are the ones of the whole ray (``tests/test_footprint.py``).

Partial results of two segments of a ray combine by taking the larger value (the front one on a
tie, as the walk keeps the first position of a maximum).
"""

from __future__ import annotations

import math
from collections import namedtuple
from collections.abc import Hashable
from typing import Any

import numpy as np
from numba import prange

from .._jit import jit
from ..accel.traversal import clip_to_box, walk_begin, walk_step
from ..errors import ParameterError, limits
from ..models.pieces import value_at, value_gradient_at
from ..roots.pieces import poly_bounds, poly_max
from ..transfer import TransferFunction, apply_colormap, colormap_table
from .frame import Frame
from .mode_api import register, unchanged_end, unchanged_skip
from .mode_host import ModeHost
from .outputs import ALL_OUTPUTS, buffer

__all__ = ["MipMode", "MipRayMode", "Mip", "combine_mip", "SAMPLED_METHODS"]

_METHODS = {"exact": 0, "sampled": 1, "slices": 2}
#: The methods that run the fixed-step loop of :mod:`.sampler`.
SAMPLED_METHODS = ("sampled", "slices")

#: Kernel parameters of the exact method: +1 (MIP) or -1 (minIP), method code, sampling step
#: (voxels; the sampled method's), whether the lower bound starts from the previous ray's
#: maximum, whether it prunes pieces by their control points and leaps the rest of a block
#: once the running maximum has reached its maximum (1.0; 0.0 only to test the exact method
#: without them), and the shortfall allowed below the exact answer (in values; 0: exact).
MipMode = namedtuple("MipMode", ["sign", "method", "step", "coherent", "prune", "tolerance"])

#: The same parameters for the sampled method: another class, so the driver runs the
#: fixed-step loop of :mod:`.sampler` for it (no cell walk).
MipRayMode = namedtuple("MipRayMode", MipMode._fields)


@jit()
def _state_new(mode):
    return -math.inf, math.inf, -math.inf  # best (times sign), where, lower bound


@jit()
def _state_load(mode, state, row, col):
    best, where = state
    return best[row, col], where[row, col], -math.inf


@jit()
def _state_store(mode, state, row, col, st):
    best, where = state
    best[row, col] = st[0]
    where[row, col] = st[1]


#: Values of the model taken along the ray inside the 16-cell block with the largest maximum it
#: crosses, to raise the lower bound before the walk (see ``_ray_begin``).
SEED_SAMPLES = 4


@jit()
def _mode_scratch(mode):
    """The ray parameter where the thread's previous ray found its maximum (NaN: none yet)."""
    return np.full(1, np.nan)


@jit()
def _tile_begin(mode, mscratch):
    """A tile's first ray has no previous ray: it seeds its bound from the blocks."""
    mscratch[0] = np.nan


@jit()
def _ray_begin(mode, grid, scratch, mscratch, blocks, st, ray, ncx, ncy, ncz, t0, t1):
    """A lower bound of the ray's maximum before the walk (exact method only).

    The model's value at the depth where the thread's previous ray (a neighbouring pixel) found
    its maximum, clamped into ``[t0, t1]``, is a value this ray meets. Without a previous ray,
    a coarse walk over the 16-cell blocks takes the largest block minimum (every value the
    ray meets in a block is at least its minimum) and finds the block with the largest maximum;
    the model's values at ``SEED_SAMPLES`` points of the ray inside that block are values the
    ray does meet, so the largest of them bounds the answer from below as well. On an MRI the
    block minima are background and bound little; a value taken where the maximum may be lets
    the walk leap most blocks in front of it."""
    ox, oy, oz = ray.index_x, ray.index_y, ray.index_z
    dx, dy, dz = ray.index_dx, ray.index_dy, ray.index_dz
    lower = st[2]
    t_previous = mscratch[0]
    if mode.coherent != 0.0 and t_previous == t_previous:
        ts = min(max(t_previous, t0), t1)
        x, y, z = ox + ts * dx, oy + ts * dy, oz + ts * dz
        v = mode.sign * value_at(grid, scratch, x, y, z)
        # The walk tests cells against the bound with their conservative ranges; the margin
        # keeps a value evaluated on another code path than the pieces' from passing the
        # range of the cell that holds it by a rounding error. It scales with the values
        # around the point (a value near zero can be the sum of large ones).
        bi = np.uint64(min(max(math.floor(x), 0.0), ncx - 1.0)) >> np.uint64(4)
        bj = np.uint64(min(max(math.floor(y), 0.0), ncy - 1.0)) >> np.uint64(4)
        bk = np.uint64(min(max(math.floor(z), 0.0), ncz - 1.0)) >> np.uint64(4)
        scale = max(abs(blocks[1][bi, bj, bk]), abs(blocks[3][bi, bj, bk]), abs(v))
        lower = max(lower, v - 1e-6 * scale - 1e-12)
        if mode.tolerance > 0.0 and v > st[0]:
            return v, ts, lower  # a value the ray meets: an answer within the tolerance
        return st[0], st[1], lower
    g1_min, g1_max = blocks[3], blocks[1]
    top = -math.inf
    ta = tb = t0
    inside, ci, cj, ck, t, t_far = walk_begin(ox, oy, oz, dx, dy, dz, ncx, ncy, ncz, t0, t1)
    while inside:
        bi, bj, bk = np.uint64(ci >> 4), np.uint64(cj >> 4), np.uint64(ck >> 4)
        lower = max(lower, g1_min[bi, bj, bk])
        block_top = g1_max[bi, bj, bk]
        t_end, inside, ci, cj, ck, t_next = walk_step((ox, oy, oz), (dx, dy, dz),
                                                      (ncx, ncy, ncz), ci, cj, ck, t, t_far, 16)
        if block_top > top:
            top, ta, tb = block_top, t, t_end
        t = t_next
    best, where = st[0], st[1]
    if top > lower and tb > ta:
        for m in range(SEED_SAMPLES):
            ts = ta + (m + 0.5) * (tb - ta) / SEED_SAMPLES
            v, _, _, _ = value_gradient_at(grid, scratch, ox + ts * dx, oy + ts * dy,
                                           oz + ts * dz)
            v *= mode.sign
            lower = max(lower, v - 1e-6 * (abs(v) + abs(top)) - 1e-12)
            if mode.tolerance > 0.0 and v > best:
                best, where = v, ts
    return best, where, lower


@jit()
def _entry_left_out(mode, grid, scratch, st, ray, t0, t1, t_lo, t_hi, ncx, ncy, ncz):
    """The footprint keeps ``[t_lo, t_hi]`` of the ray: outside it, the ray crosses only
    blocks whose values all equal the grid's smallest (``Mip.footprint_flags``). When the ray's
    entry into the grid lies outside, the value there is the first of the largest values left
    out, the one the walk or the samples would have kept (they keep the first of equal
    values)."""
    ox, oy, oz = ray.index_x, ray.index_y, ray.index_z
    dx, dy, dz = ray.index_dx, ray.index_dy, ray.index_dz
    ta, tb = clip_to_box(ox, oy, oz, dx, dy, dz, ncx, ncy, ncz, t0, t1)
    if ta <= tb and (ta < t_lo or ta > t_hi):
        v = mode.sign * value_at(grid, scratch, ox + ta * dx, oy + ta * dy, oz + ta * dz)
        if v > st[0]:
            return v, ta, st[2]
    return st


@jit()
def _skip_size(mode, blocks, i, j, k, st):
    """Edge of the largest block around the cell that cannot hold the maximum (0 if none):
    its maximum does not beat the running one (ties keep the earlier position) by more than
    the tolerance, or lies strictly below the lower bound."""
    # Asking for the 2-cell blocks as well (their ranges as the isosurface keeps them,
    # quantized within the 4-cell block's) about halves the cells visited per ray but was
    # measured slower: a leap costs about what a visited cell does, and the driver then asks
    # once per 2-cell block instead of once per 4-cell block.
    best, lower = st[0] + mode.tolerance, st[2]
    ui, uj, uk = np.uint64(i), np.uint64(j), np.uint64(k)  # see inactive_block_size
    v = blocks[2][ui >> np.uint64(6), uj >> np.uint64(6), uk >> np.uint64(6)]
    if v <= best or v < lower:
        return 64
    v = blocks[1][ui >> np.uint64(4), uj >> np.uint64(4), uk >> np.uint64(4)]
    if v <= best or v < lower:
        return 16
    v = blocks[0][ui >> np.uint64(2), uj >> np.uint64(2), uk >> np.uint64(2)]
    if v <= best or v < lower:
        return 4
    return 0


@jit()
def _wants(mode, st, lo, hi):
    top = hi if mode.sign > 0.0 else -lo
    return top > st[0] + mode.tolerance and top >= st[2]


@jit()
def _consume(mode, mscratch, grid, scratch, piece, ray, st):
    poly, t0, t1 = piece.poly, piece.t0, piece.t1
    best, where = st[0], st[1]
    # The convex hull of the piece's control points bounds it: a piece that cannot beat the
    # running maximum needs no roots of its derivative (most tested cells of a bright volume).
    # The margin, far above the rounding of the hull and of poly_max's values, leaves every
    # piece poly_max could find better to poly_max, so the answer is its.
    # Below the lower bound (a value the ray meets, less a margin) the piece cannot hold the
    # answer either, although it could still raise the running maximum on the way.
    if mode.prune != 0.0:
        lo_p, hi_p = poly_bounds(poly)
        top = hi_p if mode.sign > 0.0 else -lo_p
        top += 1e-11 * max(abs(lo_p), abs(hi_p))
        if top <= best + mode.tolerance or top < st[2]:
            return st
    v, s = poly_max(poly, mode.sign)
    if v > best:
        where = t0 + s * (t1 - t0)
        mscratch[0] = where  # for the thread's next ray (_ray_begin)
        return v, where, st[2]
    return st


@jit()
def _done(mode, st):
    return False


@jit()
def _asks_again(mode):
    # A tested cell may raise the running maximum to its block's maximum (the ray meets the
    # block's brightest value, common on plateaus of equal values): the rest of the block is
    # then leapt over, which saves cells on data with plateaus (CT, MRI).
    return mode.prune != 0.0


@jit()
def _finish(mode, out, row, col, st, ray):
    value, depth, position = out
    t = st[1]
    # Buffers with no rows were not asked for (see .outputs).
    if t == math.inf:
        if value.shape[0] != 0:
            value[row, col] = math.nan
        if depth.shape[0] != 0:
            depth[row, col] = math.inf
        if position.shape[0] != 0:
            for c in range(3):
                position[row, col, c] = math.nan
    else:
        if value.shape[0] != 0:
            value[row, col] = mode.sign * st[0]
        if depth.shape[0] != 0:
            depth[row, col] = t
        if position.shape[0] != 0:
            position[row, col, 0] = ray.world_x + t * ray.world_dx
            position[row, col, 1] = ray.world_y + t * ray.world_dy
            position[row, col, 2] = ray.world_z + t * ray.world_dz


@jit()
def _sample_step(mode):
    return mode.step


@jit()
def _sample_planes(mode):
    return mode.method == 2  # "slices"


@jit()
def _segment(mode, grid, scratch, st, ray, stretch):
    """The sampled method: the stretch between two samples; its values there."""
    ta, tb, va, vb = stretch.ta, stretch.tb, stretch.va, stretch.vb
    best, where = st[0], st[1]
    a = mode.sign * va
    if a > best:
        best, where = a, ta
    b = mode.sign * vb
    if b > best:
        best, where = b, tb
    return best, where, st[2]


_HOOKS = dict(state_new=_state_new, state_load=_state_load, state_store=_state_store,
              mode_scratch=_mode_scratch, tile_begin=_tile_begin, ray_begin=_ray_begin,
              skip_size=_skip_size, wants=_wants, on_skip=unchanged_skip, consume=_consume,
              done=_done,
              ray_end=unchanged_end, asks_again=_asks_again, finish=_finish,
              entry_left_out=_entry_left_out)
register(MipMode, **_HOOKS)
register(MipRayMode, sample_step=_sample_step, sample_planes=_sample_planes, segment=_segment,
         **_HOOKS)


@jit(parallel=True)
def combine_mip(front: tuple, back: tuple, out: tuple) -> None:
    """``out`` = the larger of two partial maxima of the same rays (the front one on a tie)."""
    fb, fw = front
    bb, bw = back
    ob, ow = out
    height, width = fb.shape
    for row in prange(height):
        for col in range(width):
            if bb[row, col] > fb[row, col]:
                ob[row, col], ow[row, col] = bb[row, col], bw[row, col]
            else:
                ob[row, col], ow[row, col] = fb[row, col], fw[row, col]


def check_window(window: Any, value_range: tuple[float, float]) -> tuple[float, float]:
    """A validated display window ``(lo, hi)``; ``None`` means the data range."""
    if window is None:
        lo, hi = value_range
        return (float(lo), float(hi) if hi > lo else float(lo) + 1.0)
    try:
        lo, hi = (float(v) for v in window)
    except (TypeError, ValueError):
        raise ParameterError(f"window must be two numbers (lo, hi), got {window!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
        raise ParameterError(f"window must be two finite numbers with lo < hi, got {window!r}")
    return lo, hi


def check_tolerance(tolerance: Any, method: str) -> float:
    """A validated MIP tolerance (a fraction of the window, in ``[0, 1]``), for ``method``."""
    try:
        value = float(tolerance)
    except (TypeError, ValueError):
        raise ParameterError(f"tolerance must be a number, got {tolerance!r}") from None
    if not (0.0 <= value <= 1.0):
        raise ParameterError(f"tolerance must be a fraction of the window in [0, 1], "
                             f"got {tolerance!r}")
    if value > 0.0 and method != "exact":
        raise ParameterError(f"tolerance bounds the exact method's shortfall; the {method} "
                             "method has no bound (use method='exact')")
    return value



def projection_buffers(outputs: frozenset[str], height: int, width: int) -> tuple:
    """The output buffers of a projection through a window (MIP, minIP, AIP): value, depth,
    position (zero rows where not requested; the value also for the colour)."""
    return (buffer("value" in outputs or "rgba" in outputs, (height, width)),
            buffer("depth" in outputs, (height, width)),
            buffer("position" in outputs, (height, width, 3)))


def projection_frame(host: Any, out: tuple, counters: tuple, stats: dict) -> Frame:
    """The Frame of a projection through a window: the values colormapped through
    ``host.window`` and ``host.colormap``, rays that met only background (``host.empty``) in
    the background colour, ``Frame.value`` the projected values."""
    value, depth, position = out
    o = host.outputs
    h, w = counters[0].shape
    rgba = apply_colormap(value, host.window, host.colormap, host.background) if "rgba" in o \
        else None
    if rgba is not None and host.empty is not None:
        # Rays that meet only background: the background colour (their value is the
        # background's up to rounding of a spline's partition of unity).
        span = float(host.value_range[1]) - float(host.value_range[0])
        rgba[np.abs(value - host.empty) <= 1e-9 * max(span, 1e-300)] = np.asarray(
            host.background, np.float32)
    normal = np.full((h, w, 3), np.nan, np.float32) if "normal" in o else None
    face = np.zeros((h, w), np.int8) if "face" in o else None
    stats.update(window=host.window)
    return Frame(rgba, depth if "depth" in o else None, position if "position" in o else None,
                 normal, face, *counters, stats, value if "value" in o else None)

class Mip(ModeHost):
    """Host side of MIP (``kind="mip"``) and minIP (``"minip"``).

    Parameters
    ----------
    kind : {"mip", "minip"}
    method : {"exact", "sampled", "slices"}
        ``"exact"``: the largest value of the model along the ray. ``"sampled"``: the largest
        of its values every ``step`` voxels along the ray (and at the ray's ends).
        ``"slices"``: the largest of its values where the ray crosses every ``step``-th plane
        of voxels across its dominant axis (and at its ends), as slice-based renderers
        sample; the samples lie ``step`` to ``step * sqrt(3)`` voxels apart, and on the
        trilinear model each reads 4 voxels instead of 8 when ``step`` is a whole number.
    step : float
        Sampling step of the sampled methods, in voxels.
    tolerance : float
        Exact method only: how far a pixel's value may fall short of the exact projection
        (below it for MIP, above it for minIP), as a fraction of the window's width
        (``1 / 255``: one level of an 8-bit image). 0, the default, is the exact projection.
        The value is still one the ray meets, at the depth reported, and the bound holds for
        every pixel.
    window : (lo, hi), optional
        Values mapped to the ends of the colormap (default: the data range).
    colormap : str or control points
        Colormap of :mod:`splinecast.transfer`.
    background : 4 floats
        Colour of rays that miss the volume.
    value_range : (lo, hi)
        The data range (the default window).
    empty : float, optional
        The background value (:func:`splinecast.background_value`): pixels whose projected
        value is this one (their ray meets only background) get ``background`` as rays that
        miss the volume do, so the volume's box is not drawn. ``None``: every pixel whose ray
        meets the volume is colormapped.
    outputs : set of str, optional
        The Frame's buffers to fill (:mod:`.outputs`; default all). The colour is mapped from
        the projected values, so ``"rgba"`` computes them even when ``"value"`` is not kept.
    """

    #: Rays go through the volume (ModeHost.deep_rays).
    deep_rays = True

    def blocks_key(self) -> Hashable:
        """Which extremum: the blocks depend on the grid's ranges alone."""
        return ("mip", float(self.params.sign))

    def cut_transfer(self) -> TransferFunction:
        """The classification of the image: the window's colormap at full opacity."""
        lo, hi = (float(v) for v in self.window)
        return TransferFunction([(lo, 1.0), (hi, 1.0)], domain=(lo, hi), colormap=self.colormap)

    def __init__(self, kind: str = "mip", method: str = "exact", step: float = 0.25,
                 window: Any = None, colormap: Any = "gray",
                 background: Any = (0.0, 0.0, 0.0, 1.0),
                 value_range: tuple[float, float] = (0.0, 1.0),
                 outputs: frozenset[str] = ALL_OUTPUTS, tolerance: float = 0.0,
                 empty: float | None = None) -> None:
        self.outputs = outputs
        self.empty = empty
        self.value_range = value_range
        if method not in _METHODS:
            raise ParameterError(f"method must be one of {', '.join(_METHODS)}, got {method!r}")
        if method in SAMPLED_METHODS:  # against the volume's size too: limits.check_render
            limits.check_finite_number(step, "step", lo=limits.MIN_STEP)
        tolerance = check_tolerance(tolerance, method)
        self.name = kind
        self.method = method
        self.window = check_window(window, value_range)
        colormap_table(colormap, 2)  # validates the name before any work
        self.colormap = colormap
        self.background = background
        params_class = MipRayMode if method in SAMPLED_METHODS else MipMode
        self.tolerance = tolerance
        self.params = params_class(1.0 if kind == "mip" else -1.0, _METHODS[method],
                                   float(step), 1.0, 1.0,
                                   tolerance * (self.window[1] - self.window[0]))

    def blocks(self, hierarchy: Any, flags: tuple | None = None) -> tuple:
        """Block maxima (times the sign) per level, then the 16-cell block minima (exact
        method) or the finest blocks' plain minima and maxima (sampled: :mod:`.sampler` reads
        them at ``blocks[3]`` and ``blocks[4]``)."""
        if self.method in SAMPLED_METHODS:
            signed = hierarchy.highs if self.params.sign > 0 else [-a for a in hierarchy.lows]
            return (*signed, hierarchy.lows[0], hierarchy.highs[0])
        if self.params.sign > 0:
            return (*hierarchy.highs, hierarchy.lows[1])
        return (*(-a for a in hierarchy.lows), -hierarchy.highs[1])

    #: Rays that cross the grid's box outside the footprint of the blocks named by
    #: :meth:`footprint_flags` are still traced, from their entry only (:mod:`.footprint`):
    #: their value is the grid's smallest, not a miss.
    footprint_fills_box = True

    def footprint_flags(self, blocks: tuple) -> tuple:
        """The blocks holding a value above the grid's smallest (the largest, for minIP), per
        level (:mod:`.footprint`).

        Every value in another block equals the grid's smallest, so a ray's answer comes from
        these blocks unless it crosses none of them; then it is that smallest value, first met
        at the ray's entry into the grid, where ``_entry_left_out`` takes it. Air around a
        head (78% of the MRI's voxels are 0) is so never sampled or walked. Without a 16-cell
        block of that value (smooth fields), every block is named, at the coarsest level only:
        the volume's box, a few blocks to project, and the pixels whose rays miss it are
        written without a ray."""
        highs = blocks[:3]
        if self.method in SAMPLED_METHODS:
            lows, top = blocks[3], blocks[4]  # the 4-cell blocks' plain ranges
            floor = lows.min() if self.params.sign > 0 else -top.max()
        else:
            floor = blocks[3].min()  # the 16-cell blocks' minima, times the sign
        if not np.any(highs[1] <= floor):
            return (None, None, np.ones(highs[2].shape, np.uint8))
        return tuple((h > floor).view(np.uint8) for h in highs)

    @staticmethod
    def state(height: int, width: int) -> tuple:
        """Per-pixel state arrays: best value (times the sign) and where."""
        return np.empty((height, width)), np.empty((height, width))

    def output(self, height: int, width: int) -> tuple:
        """Output buffers: value, depth, position (zero rows: not requested)."""
        return projection_buffers(self.outputs, height, width)

    def frame(self, out: tuple, counters: tuple, stats: dict) -> Frame:
        """The Frame: colormapped values; ``Frame.value`` holds the projected values."""
        if self.tolerance > 0.0:
            stats["tolerance"] = self.tolerance
        if self.method in SAMPLED_METHODS:
            stats["step"] = self.params.step
        return projection_frame(self, out, counters, stats)

    combine = staticmethod(combine_mip)
