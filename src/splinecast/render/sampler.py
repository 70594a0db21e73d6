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
  wholly in the block and add nothing. It asks at every sample: remembering the last 4-cell
  block found visible and not asking again inside it measured 0.94-1.04x;
* early termination by the mode's ``done``;
* for a model whose value is a few loads (``look_ahead``, :mod:`splinecast.models.pieces`),
  each sample's value is taken one sample early, before the table reads of the segment in
  front of it, so the voxel reads of the one overlap the table reads of the other (both wait
  on memory; 1.1-1.4x on the trilinear DVR); the value is the same, as its position is;
* a footprint interval (:mod:`.footprint`) is widened to the samples on either side of it,
  so a ray started or ended by it takes the segments of the whole ray.

It returns the driver's three per-ray counters with this meaning: samples evaluated, segments
handed to the mode, blocks leapt.
"""

from __future__ import annotations

import math

from .._jit import jit
from ..accel.traversal import axis_exit, clip_to_box
from ..models.pieces import look_ahead, value_at
from .mode_api import (
    done,
    finish,
    sample_step,
    segment,
    skip_size,
    state_load,
    state_new,
    state_store,
    wants,
)
from .rays import grid_ray

__all__ = ["sample_pixel"]


@jit(inline="always")
def _cell(p: float, n: int) -> int:
    """The cell holding coordinate ``p``, clamped into ``[0, n - 1]``."""
    c = int(math.floor(p))
    return min(max(c, 0), n - 1)


@jit(inline="always")
def _cells(ox, oy, oz, dx, dy, dz, t, ncx, ncy, ncz):
    """The cell holding the ray's point at ``t`` (clamped into the grid)."""
    return _cell(ox + t * dx, ncx), _cell(oy + t * dy, ncy), _cell(oz + t * dz, ncz)


@jit(inline="always")
def sample_pixel(grid, mode, blocks, state, out, basis, geom, planes, t_range, t_lo, t_hi, load,
                 store, final, scr, mscr, cuts, tags, row, col, width, height, ncx, ncy, ncz):
    """Sample one pixel's ray through ``grid`` (the driver's per-ray unit for sampled modes;
    same arguments as :func:`.driver._trace_pixel`). Returns (samples evaluated, segments
    taken, blocks leapt)."""
    t0, t1, ray = grid_ray(basis, geom, planes, t_range, row, col, width, height, ncx, ncy, ncz)
    ox, oy, oz, dx, dy, dz = ray[6], ray[7], ray[8], ray[9], ray[10], ray[11]
    if t_lo > t0 or t_hi < t1:
        # The footprint's interval, widened to the samples around it (the loop's own sample
        # positions): the segments are then the whole ray's, and none outside the interval
        # is one the loop would take (the footprint's blocks hold both ends of every such).
        dt = sample_step(mode) / math.sqrt(dx * dx + dy * dy + dz * dz)
        anchor = ray[15]
        if t_lo > t0:
            t0 = max(t0, anchor + math.floor((t_lo - anchor) / dt) * dt)
        if t_hi < t1:
            t1 = min(t1, anchor + math.ceil((t_hi - anchor) / dt) * dt)
    st = state_load(mode, state, row, col) if load else state_new(mode)
    evaluated = 0
    taken = 0
    leaps = 0
    if t0 <= t1 and not done(mode, st):
        ta, t_far = clip_to_box(ox, oy, oz, dx, dy, dz, ncx, ncy, ncz, t0, t1)
        speed = math.sqrt(dx * dx + dy * dy + dz * dz)
        if ta <= t_far and speed > 0.0:
            anchor = ray[15]
            dt = sample_step(mode) / speed
            m = math.floor((ta - anchor) / dt) + 1.0
            va = 0.0
            known = False  # whether va holds the value at ta (taken when first needed)
            ahead_of_model = look_ahead(grid)
            ahead = 0.0  # the value at sample number ahead_m (taken early; see below)
            ahead_m = -1.0
            lows, highs = blocks[3], blocks[4]
            while True:
                ci, cj, ck = _cells(ox, oy, oz, dx, dy, dz, ta, ncx, ncy, ncz)
                size = skip_size(mode, blocks, ci, cj, ck, st)
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
                if ahead_of_model and not end and tc < t_far:
                    ahead = value_at(grid, scr, ox + tc * dx, oy + tc * dy, oz + tc * dz)
                    ahead_m = m + 1.0
                    evaluated += 1
                length = (tb - ta) * speed
                if length > 0.0:
                    st = segment(mode, grid, scr, st, ray, ta, tb, va, vb, length, bx, by, bz)
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
