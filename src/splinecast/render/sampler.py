"""The fixed-step loop: a ray sampled every ``step`` voxels, for the sampled modes.

The driver's cell walk (:mod:`.driver`) hands a mode every cell the ray crosses; a walk step
and a cell's set-up cost about 100 ns, whatever the mode does with the cell. A sampled mode
(DVR's ``sampling="ray"``, the reference VTK's and most viewers' ray casters use) only needs
the model's value every ``step`` voxels, and the stretch between two samples, which may span
several cells, is one segment: a table lookup. This loop gives it exactly that, for every
model (the value is the model's ``value_at``, inlined into the pair's kernel):

* samples at ``anchor + m * step`` (``anchor``: where the ray enters the rendered domain, the
  same for every grid), so bricks sample at the same places as the whole volume; a grid's
  first and last segments are cut at its interval's ends, so bricks traced one after another
  composite the same stretches as one grid (cut in two at each brick face);
* empty-space leaping: at each sample the mode's ``skip_size`` names the largest block around
  the sample's cell that cannot contribute (DVR: the transfer function is zero over its value
  range; sampled MIP: its maximum does not beat the running one); the loop moves to the
  last sample inside that block, without evaluating the ones in between, whose segments lie
  wholly in the block and add nothing. A block it answered 0 for (the mode's ``answer_shift``
  block) is not asked about again while the samples stay in it, unless the mode ``asks_again``;
* for a model whose value is a few loads, runs of samples in such blocks go through a loop of
  their own, which holds only the sample's
  value, the mode's segment, the termination test and the block test (the same segments, the
  same values): with a dense transfer function nearly every sample is in one, and the
  round's leap and end-of-interval bookkeeping left the loop too large for the processor to
  overlap one sample's voxel reads with the segment in front (trilinear DVR 1.06-1.08x with
  the float64 table of :mod:`.dvr`, measured together);
* early termination by the mode's ``done``;
* for a model whose value is a few loads (``look_ahead``, :mod:`splinecast.models.pieces`),
  each sample's value is taken one sample early, before the table reads of the segment in
  front of it, so the voxel reads of the one overlap the table reads of the other (both wait
  on memory); the value is the same, as its position is;
* in that run loop, the model's ``prefetch_at`` asks for the voxels of the sample seven beyond
  the look-ahead's (a software prefetch, which reads nothing into a register): reads that miss
  the second-level cache then overlap the samples in between (trilinear DVR with dense transfer
  functions 1.11-1.17x; three, eleven or fourteen samples ahead no better);
* a footprint interval (:mod:`.footprint`) is widened to the samples on either side of it,
  so a ray started or ended by it takes the segments of the whole ray.

A mode may instead sample on planes (``sample_planes``): where the ray crosses every
``step``-th plane of voxels across its dominant axis, as slice-based renderers do. The planes
are the level's, so bricks sample where the whole volume does; a model reads fewer voxels on
such a plane (:func:`splinecast.models.pieces.value_on_plane`: 4 instead of 8 for the trilinear).
Its loop (:func:`_plane_samples`) takes every sample, with no leaping: every way of leaping
tried (asking at every sample, at every 4th, at every 16th for the 64-cell blocks only) cost
more than it saved, as each question puts the running value and a branch on the path of
samples that otherwise overlap in the processor.

It returns the driver's three per-ray counters with this meaning: samples evaluated, segments
handed to the mode, blocks leapt.
"""

from __future__ import annotations

import math
from collections import namedtuple
from typing import Any

from .._jit import jit, rebound
from ..accel.traversal import axis_exit, clip_to_box
from ..models.pieces import look_ahead, prefetch_at, value_at, value_on_plane
from .mode_api import (
    answer_shift,
    asks_again,
    done,
    entry_left_out,
    finish,
    sample_planes,
    sample_step,
    segment,
    skip_size,
    state_load,
    state_new,
    state_store,
    wants,
)
from .rays import GEOM_OFFSET, GEOM_SHIFT, Stretch, grid_ray

__all__ = ["sample_pixel", "bound_sample_pixel"]


#: Whether :func:`sample_pixel` compiles the look-ahead code (its model's ``look_ahead`` may be
#: true); :func:`bound_sample_pixel` binds the pair's constant in its copy.
_LOOK_AHEAD = True

#: How many samples beyond the look-ahead's the run loop prefetches the voxels of.
_PREFETCH = 7.0


@jit(inline="always")
def _cell(p: float, n: int) -> int:
    """The cell holding coordinate ``p``, clamped into ``[0, n - 1]``."""
    # Truncation, not floor: the two differ only below 0, where both clamp to cell 0 (and
    # truncation is one instruction where floor is two, at every sample).
    return min(max(int(p), 0), n - 1)


@jit(inline="always")
def _cells(ox, oy, oz, dx, dy, dz, t, ncx, ncy, ncz):
    """The cell holding the ray's point at ``t`` (clamped into the grid)."""
    return _cell(ox + t * dx, ncx), _cell(oy + t * dy, ncy), _cell(oz + t * dz, ncz)


#: Where a ray's samples lie (:func:`_sample_grid`).
SampleGrid = namedtuple("SampleGrid", ("anchor", "dt", "axis", "plane0", "plane_step"))


@jit(inline="always")
def _sample_grid(mode, geom, ray):
    """Where the ray's samples lie: a :class:`SampleGrid` ``(anchor, dt, axis, plane0,
    plane_step)``, sample ``m`` lying at ``t = anchor + m * dt``.

    Along the ray (``axis`` -1): every ``sample_step`` voxels from the ray's entry into the
    domain. On planes (the mode's ``sample_planes``): where the ray crosses the voxel planes
    ``m * step`` of the grid's level across its dominant axis ``axis``, at traversal coordinate
    ``plane0 + m * plane_step`` there."""
    dx, dy, dz = ray.index_dx, ray.index_dy, ray.index_dz
    step = sample_step(mode)
    if sample_planes(mode):
        axis = 0
        da, oa = dx, ray.index_x
        if abs(dy) > abs(da):
            axis, da, oa = 1, dy, ray.index_y
        if abs(dz) > abs(da):
            axis, da, oa = 2, dz, ray.index_z
        if da != 0.0:
            # Voxel plane 0 of the level, in the grid.
            plane0 = geom[GEOM_SHIFT] - geom[GEOM_OFFSET + axis]
            anchor = (plane0 - oa) / da
            return SampleGrid(anchor, step / abs(da), axis, plane0,
                              step if da > 0.0 else -step)
    speed = math.sqrt(dx * dx + dy * dy + dz * dz)
    return SampleGrid(ray.anchor, step / speed if speed > 0.0 else math.inf, -1, 0.0, 0.0)


@jit(inline="always")
def _on_plane(grid, scr, axis, lattice, p, a, b):
    """The model's value on plane ``p`` across ``axis`` at ``(a, b)`` on the two other axes:
    through the model's plane reads when the plane is one of voxels (``lattice``)."""
    if lattice:
        return value_on_plane(grid, scr, axis, p, a, b)
    if axis == 0:
        return value_at(grid, scr, p, a, b)
    if axis == 1:
        return value_at(grid, scr, a, p, b)
    return value_at(grid, scr, a, b, p)


@jit(inline="always")
def _plane_samples(grid, mode, st, scr, ray, ta, t_far, speed, samples):
    """The samples on planes (``samples``, a :class:`SampleGrid`) of one ray's interval
    ``[ta, t_far]``, every one taken (see the module's docstring). Returns ``(st, evaluated,
    taken, leaps)``."""
    anchor, dt, axis, plane0, plane_step = samples
    ox, oy, oz = ray.index_x, ray.index_y, ray.index_z
    dx, dy, dz = ray.index_dx, ray.index_dy, ray.index_dz
    # The two other axes, in order, and whether the planes are planes of voxels.
    oa, da = (oy, dy) if axis == 0 else (ox, dx)
    ob, db = (oy, dy) if axis == 2 else (oz, dz)
    lattice = plane0 == math.floor(plane0) and plane_step == math.floor(plane_step)
    m = math.floor((ta - anchor) / dt) + 1.0  # the first sample after ta
    va = value_at(grid, scr, ox + ta * dx, oy + ta * dy, oz + ta * dz)
    evaluated = 1
    taken = 0
    while True:
        tb = anchor + m * dt
        if tb >= t_far:
            break
        vb = _on_plane(grid, scr, axis, lattice, plane0 + m * plane_step, oa + tb * da,
                       ob + tb * db)
        evaluated += 1
        st = segment(mode, grid, scr, st, ray, Stretch(ta, tb, va, vb, (tb - ta) * speed,
                                                       ox + tb * dx, oy + tb * dy, oz + tb * dz))
        taken += 1
        if done(mode, st):
            return st, evaluated, taken, 0
        ta = tb
        va = vb
        m += 1.0
    # The last stretch, from the last sample to the end of the interval.
    if t_far > ta:
        bx, by, bz = ox + t_far * dx, oy + t_far * dy, oz + t_far * dz
        vb = value_at(grid, scr, bx, by, bz)
        evaluated += 1
        st = segment(mode, grid, scr, st, ray,
                     Stretch(ta, t_far, va, vb, (t_far - ta) * speed, bx, by, bz))
        taken += 1
    return st, evaluated, taken, 0


@jit(inline="always")
def sample_pixel(grid, mode, blocks, state, out, setup, passes, buffers, pixel, window, cells):
    """Sample one pixel's ray through ``grid`` (the driver's per-ray unit for sampled modes;
    same arguments as :func:`.driver._trace_pixel`). Returns (samples evaluated, segments
    taken, blocks leapt)."""
    basis, geom, planes, t_range = setup.basis, setup.geom, setup.planes, setup.t_range
    load, store, final = passes.load, passes.store, passes.final
    scr = buffers.model
    row, col, width, height = pixel
    t_lo, t_hi = window
    ncx, ncy, ncz = cells
    t0, t1, ray = grid_ray(basis, geom, planes, t_range, row, col, width, height, ncx, ncy, ncz)
    ox, oy, oz = ray.index_x, ray.index_y, ray.index_z
    dx, dy, dz = ray.index_dx, ray.index_dy, ray.index_dz
    samples = _sample_grid(mode, geom, ray)
    anchor, dt, axis, plane0, plane_step = samples
    st = state_load(mode, state, row, col) if load else state_new(mode)
    if (t_lo > t0 or t_hi < t0) and t0 <= t1 and not done(mode, st):
        st = entry_left_out(mode, grid, scr, st, ray, t0, t1, t_lo, t_hi, ncx, ncy, ncz)
    if t_lo > t1:
        t0 = t_lo  # nothing of the ray in the footprint (its interval may be infinite)
    elif t_lo > t0 or t_hi < t1:
        # The footprint's interval, widened to the samples around it (the loop's own sample
        # positions): the segments are then the whole ray's, and none outside the interval
        # is one the loop would take (the footprint's blocks hold both ends of every such).
        if t_lo > t0:
            t0 = max(t0, anchor + math.floor((t_lo - anchor) / dt) * dt)
        if t_hi < t1:
            t1 = min(t1, anchor + math.ceil((t_hi - anchor) / dt) * dt)
    evaluated = 0
    taken = 0
    leaps = 0
    if t0 <= t1 and not done(mode, st):
        ta, t_far = clip_to_box(ox, oy, oz, dx, dy, dz, ncx, ncy, ncz, t0, t1)
        speed = math.sqrt(dx * dx + dy * dy + dz * dz)
        if ta <= t_far and speed > 0.0 and axis >= 0:
            st, evaluated, taken, leaps = _plane_samples(
                grid, mode, st, scr, ray, ta, t_far, speed, samples)
        elif ta <= t_far and speed > 0.0:
            m = math.floor((ta - anchor) / dt) + 1.0
            va = 0.0
            known = False  # whether va holds the value at ta (taken when first needed)
            # A constant of the pair's loop (bound_sample_pixel): for a model that does not
            # look ahead, the run loop below and the early values are not compiled at all (a
            # fifth of the s31 DVR kernel's code).
            ahead_of_model = look_ahead(grid) if _LOOK_AHEAD else False
            ahead = 0.0  # the value at sample number ahead_m (taken early; see below)
            ahead_m = -1.0
            lows, highs = blocks[3], blocks[4]
            # The block skip_size last answered 0 for (its smallest, answer_shift): samples
            # inside it are taken without asking again (skip_size's contract; a mode that
            # asks_again is asked at every sample).
            shift = answer_shift(mode)
            cache = not asks_again(mode)
            open_i = open_j = open_k = -1
            while True:
                ci, cj, ck = _cells(ox, oy, oz, dx, dy, dz, ta, ncx, ncy, ncz)
                if (ci >> shift) == open_i and (cj >> shift) == open_j and (
                        ck >> shift) == open_k:
                    size = 0
                else:
                    size = skip_size(mode, blocks, ci, cj, ck, st)
                    if size == 0 and cache:
                        open_i, open_j, open_k = ci >> shift, cj >> shift, ck >> shift
                tb = anchor + m * dt
                if size > 0:
                    # The block cannot contribute: go to the last sample inside it (segments
                    # between samples inside it add nothing), or end the ray if it reaches
                    # the end of the interval.
                    _, tx = axis_exit(ci, ox, dx, size)
                    _, ty = axis_exit(cj, oy, dy, size)
                    _, tz = axis_exit(ck, oz, dz, size)
                    t_exit = min(tx, ty, tz)
                    if t_exit >= t_far:
                        leaps += 1
                        break
                    last = math.floor((t_exit - anchor) / dt)
                    if last >= m:
                        leaps += 1
                        m = last
                        ta = anchor + m * dt
                        known = False
                        m += 1.0
                        tb = anchor + m * dt
                        ci, cj, ck = _cells(ox, oy, oz, dx, dy, dz, ta, ncx, ncy, ncz)
                    # The next sample lies beyond the block. When it lies in a block that cannot
                    # contribute either, and the mode refuses every value between the two
                    # blocks' ranges (the segment's values, taken as linear between its ends,
                    # lie there), the segment adds nothing: go on from that sample without
                    # taking a value. Rays crossing background cross it block to block so.
                    if tb < t_far:
                        bi, bj, bk = _cells(ox, oy, oz, dx, dy, dz, tb, ncx, ncy, ncz)
                        if skip_size(mode, blocks, bi, bj, bk, st) > 0:
                            lo = min(lows[ci >> 2, cj >> 2, ck >> 2],
                                     lows[bi >> 2, bj >> 2, bk >> 2])
                            hi = max(highs[ci >> 2, cj >> 2, ck >> 2],
                                     highs[bi >> 2, bj >> 2, bk >> 2])
                            if not wants(mode, st, lo, hi):
                                ta = tb
                                known = False
                                m += 1.0
                                continue
                if not known:
                    va = value_at(grid, scr, ox + ta * dx, oy + ta * dy, oz + ta * dz)
                    evaluated += 1
                if _LOOK_AHEAD and size == 0 and cache and ahead_of_model and tb < t_far:
                    # A run of samples in blocks the mode asked for: a loop of its own, with
                    # only the sample's value, the segment and the block test in it (the same
                    # segments as the rounds below, without their leaps and bookkeeping). Only
                    # for a model whose value is cheap: a costly value inlined at the loop's
                    # extra call sites made s31 DVR 1.08-1.16x slower.
                    stop = False
                    bx, by, bz = ox + tb * dx, oy + tb * dy, oz + tb * dz
                    if ahead_m == m:
                        vb = ahead
                    else:
                        vb = value_at(grid, scr, bx, by, bz)
                        evaluated += 1
                    while True:
                        # The next sample's value first (as below); the same expression as its
                        # tb below, so the same value.
                        tc = anchor + (m + 1.0) * dt
                        if tc < t_far:
                            ahead = value_at(grid, scr, ox + tc * dx, oy + tc * dy, oz + tc * dz)
                            ahead_m = m + 1.0
                            evaluated += 1
                            tp = tc + _PREFETCH * dt
                            prefetch_at(grid, scr, ox + tp * dx, oy + tp * dy, oz + tp * dz)
                        length = (tb - ta) * speed
                        if length > 0.0:
                            st = segment(mode, grid, scr, st, ray,
                                         Stretch(ta, tb, va, vb, length, bx, by, bz))
                            taken += 1
                        if done(mode, st):
                            stop = True
                            break
                        ta = tb
                        va = vb
                        m += 1.0
                        tb = tc
                        if tb >= t_far:
                            break
                        ci, cj, ck = _cells(ox, oy, oz, dx, dy, dz, ta, ncx, ncy, ncz)
                        if (ci >> shift) != open_i or (cj >> shift) != open_j or (
                                ck >> shift) != open_k:
                            if skip_size(mode, blocks, ci, cj, ck, st) != 0:
                                break
                            open_i, open_j, open_k = ci >> shift, cj >> shift, ck >> shift
                        bx, by, bz = ox + tb * dx, oy + tb * dy, oz + tb * dz
                        if ahead_m == m:
                            vb = ahead
                        else:
                            vb = value_at(grid, scr, bx, by, bz)
                            evaluated += 1
                    if stop:
                        break
                    known = True
                    continue
                end = tb >= t_far
                if end:
                    tb = t_far
                bx, by, bz = ox + tb * dx, oy + tb * dy, oz + tb * dz
                if ahead_m == m and not end:
                    vb = ahead
                else:
                    vb = value_at(grid, scr, bx, by, bz)
                    evaluated += 1
                # The next sample's value, before this segment's table reads, for a model
                # whose value is cheap: its voxel loads then overlap them (both wait on memory).
                # The same expression as its tb on the next round, so the same value.
                tc = anchor + (m + 1.0) * dt
                if _LOOK_AHEAD and ahead_of_model and not end and tc < t_far:
                    ahead = value_at(grid, scr, ox + tc * dx, oy + tc * dy, oz + tc * dz)
                    ahead_m = m + 1.0
                    evaluated += 1
                length = (tb - ta) * speed
                if length > 0.0:
                    st = segment(mode, grid, scr, st, ray,
                                 Stretch(ta, tb, va, vb, length, bx, by, bz))
                    taken += 1
                if end or done(mode, st):
                    break
                ta = tb
                va = vb
                known = True
                m += 1.0
    if store:
        state_store(mode, state, row, col, st)
    if final:
        finish(mode, out, row, col, st, ray)
    return evaluated, taken, leaps


def bound_sample_pixel(bindings: dict, suffix: str) -> Any:
    """:func:`sample_pixel` for one (model, mode) pair: a copy with the pair's hooks bound in it
    and in its helpers that call hooks (:func:`splinecast._jit.rebound` binds the names of one
    function only; a helper left unbound would call each hook through its stub, a real call
    rather than inlined code)."""
    # The model's look_ahead is a constant (models.pieces): known here, the code of the other
    # case is left out of the pair's kernel when it compiles.
    hook = bindings.get("look_ahead")
    bindings = {**bindings, "_LOOK_AHEAD": hook is not None and bool(hook.py_func(None))}
    where = rebound(_sample_grid, bindings, suffix)
    on_plane = rebound(_on_plane, bindings, suffix)
    planes = rebound(_plane_samples, {**bindings, "_on_plane": on_plane}, suffix)
    return rebound(sample_pixel, {**bindings, "_sample_grid": where, "_plane_samples": planes},
                   suffix)
