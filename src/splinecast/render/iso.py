"""First-hit isosurface mode for every model: the first piece whose polynomial reaches the iso.

Two methods share the driver, the model's pieces and the block hierarchy:

* ``exact`` (default): per piece whose range holds the isovalue, the first root of its polynomial
  (:func:`splinecast.roots.pieces.poly_first_root`: guaranteed solvers for every form) ends the
  ray; the normal is the gradient of the model's shading field at the hit (``normals``,
  :mod:`.shading`: by default a smooth field for the models that are only continuous, the
  model's own analytic gradient with ``normals="exact"`` and for the C1 and C2 models).
* ``sampled``: the reference "as common viewers do": samples every ``step`` voxels along the ray
  from its entry into the volume (plus the exit point), and the first sign change refined by
  bisection on the model's reconstruction. It exists to be compared with the exact method.

State per ray: the hit parameter and the world shading gradient there, and for the sampled method
the last sample, in whose place a hit keeps the model's own derivative along the ray (which side
the ray enters). Partial results of two segments of a ray combine by keeping the nearer hit.
"""

from __future__ import annotations

import math
from collections import namedtuple
from collections.abc import Hashable
from typing import Any

import numpy as np
from numba import prange

from .._jit import jit
from ..accel.minmax import PAIR_SHIFT, inactive_pair_size, packed_pair_flags
from ..errors import ParameterError, limits
from ..models.pieces import gradient, value_gradient_at
from ..roots.pieces import poly_first_root, poly_value
from .frame import Frame
from .mode_api import no_scratch, register, unchanged_begin
from .mode_host import ModeHost
from .outputs import ALL_OUTPUTS, buffer
from .pixels import store_hit, store_miss
from .shading import Shading, normals_code, smooth_gradient

__all__ = ["IsoMode", "Iso", "METHODS", "combine_iso"]

#: Method names accepted by ``Scene.render(..., method=...)``.
METHODS = {"exact": 0, "sampled": 1}

_BISECTION_STEPS = 60

#: Kernel parameters: isovalue, method code, sampling step (voxels), which side is inside,
#: packed shading (:meth:`Shading.as_array`), normals code (:data:`.shading.NORMALS`).
IsoMode = namedtuple("IsoMode", ["iso", "method", "step", "inside_high", "shading", "normals"])


@jit()
def _state_new(mode):
    return math.inf, math.nan, math.nan, math.nan, math.nan, math.nan


@jit()
def _state_load(mode, state, row, col):
    depth, grad, prev = state
    return (depth[row, col], grad[row, col, 0], grad[row, col, 1], grad[row, col, 2],
            prev[row, col, 0], prev[row, col, 1])


@jit()
def _state_store(mode, state, row, col, st):
    depth, grad, prev = state
    depth[row, col] = st[0]
    grad[row, col, 0] = st[1]
    grad[row, col, 1] = st[2]
    grad[row, col, 2] = st[3]
    prev[row, col, 0] = st[4]
    prev[row, col, 1] = st[5]


@jit()
def _skip_size(mode, blocks, i, j, k, st):
    return inactive_pair_size(blocks[0], blocks[1], blocks[2], blocks[3], i, j, k)


@jit()
def _answer_shift(mode):
    # A constant (LLVM folds it into the driver's shifts); the sampled method's blocks carry no
    # pair level (Iso.blocks), so its answers are the 4-cell blocks', only asked for more often.
    return PAIR_SHIFT


@jit()
def _wants(mode, st, lo, hi):
    return lo <= mode.iso <= hi


@jit()
def _done(mode, st):
    return st[0] < math.inf


@jit()
def _hit(mode, grid, scratch, ray, t):
    """State of a hit at ``t`` found by sampling: the shading gradient at that point."""
    x = ray.index_x + t * ray.index_dx
    y = ray.index_y + t * ray.index_dy
    z = ray.index_z + t * ray.index_dz
    _, gx, gy, gz = value_gradient_at(grid, scratch, x, y, z)
    return _hit_state(mode, grid, scratch, ray, t, x, y, z, gx, gy, gz)


@jit(inline="always")
def _hit_state(mode, grid, scratch, ray, t, x, y, z, gx, gy, gz):
    """The state of a hit at ``t``, at traversal-space point ``(x, y, z)``, where the model's
    own index-space gradient is ``g``: the world shading gradient, and in place of the sampled
    method's last sample (done with once there is a hit), the model's own derivative along the
    ray, whose sign says which side the ray enters (:func:`.pixels.store_hit`)."""
    # = world gradient . unit ray
    slope = gx * ray.index_dx + gy * ray.index_dy + gz * ray.index_dz
    hx, hy, hz = smooth_gradient(mode.normals, grid, scratch, ray, x, y, z, gx / ray.spacing_x,
                                 gy / ray.spacing_y, gz / ray.spacing_z)
    return t, hx, hy, hz, math.nan, slope


@jit()
def _sample(grid, scratch, ray, t, iso):
    v, _, _, _ = value_gradient_at(grid, scratch, ray.index_x + t * ray.index_dx,
                                   ray.index_y + t * ray.index_dy, ray.index_z + t * ray.index_dz)
    return v - iso


@jit()
def _bisect(mode, grid, scratch, ray, ta, ga, tb, gb):
    """Refine a sign change of the sampled method between ``ta`` and ``tb``."""
    if gb != 0.0:
        for _ in range(_BISECTION_STEPS):
            tm = 0.5 * (ta + tb)
            gm = _sample(grid, scratch, ray, tm, mode.iso)
            if (gm < 0.0) == (ga < 0.0) and gm != 0.0:
                ta, ga = tm, gm
            else:
                tb, gb = tm, gm
    return _hit(mode, grid, scratch, ray, tb)


@jit()
def _dt(mode, ray):
    """The sampling step in world units along this ray."""
    dx, dy, dz = ray.index_dx, ray.index_dy, ray.index_dz
    return mode.step / math.sqrt(dx * dx + dy * dy + dz * dz)


# Only the sampled method watches what is skipped (``_watches_skips``); the exact method's
# path through ``_consume`` is kept short, the sampled method's work in separate functions.
@jit()
def _watches_skips(mode):
    return mode.method == 1


@jit()
def _on_skip(mode, grid, scratch, st, ray, t0, t1, lo, hi):
    if mode.method != 1:
        return st
    # A call, not inlined: the pixel loop has four places where a stretch is skipped, and the
    # sampled method's work copied into each made a tenth of every isosurface kernel's code.
    return _skip_sampled(mode, grid, scratch, st, ray, t0, t1, lo, hi)


@jit()
def _skip_sampled(mode, grid, scratch, st, ray, t0, t1, lo, hi):
    """:func:`_on_skip` of the sampled method."""
    # A stretch without the isovalue lies on one side of it: one sample gives the sign of all
    # its samples (the range gives it without a sample when known); a change against the
    # previous sample is refined.
    anchor = ray.anchor
    dt = _dt(mode, ray)
    ts = anchor + math.ceil((t0 - anchor) / dt) * dt
    if ts > t1:
        return st
    prev_t, prev_g = st[4], st[5]
    known = lo <= hi and (lo > mode.iso or hi < mode.iso)
    if known:
        g = lo - mode.iso if lo > mode.iso else hi - mode.iso
        if prev_g == prev_g and (prev_g < 0.0) != (g < 0.0):
            gs = _sample(grid, scratch, ray, ts, mode.iso)
            return _bisect(mode, grid, scratch, ray, prev_t, prev_g, ts, gs)
    else:
        g = _sample(grid, scratch, ray, ts, mode.iso)
        if prev_g == prev_g and ((prev_g < 0.0) != (g < 0.0) or g == 0.0):
            return _bisect(mode, grid, scratch, ray, prev_t, prev_g, ts, g)
        if prev_g != prev_g and g == 0.0:
            return _hit(mode, grid, scratch, ray, ts)
    last = anchor + math.floor((t1 - anchor) / dt) * dt
    return st[0], st[1], st[2], st[3], last, g


@jit()
def _consume(mode, mscratch, grid, scratch, piece, ray, st):
    ctx, i, j, k, tag, poly = piece.ctx, piece.i, piece.j, piece.k, piece.tag, piece.poly
    t0, t1 = piece.t0, piece.t1
    ax, ay, az, bx, by, bz = piece.ax, piece.ay, piece.az, piece.bx, piece.by, piece.bz
    if mode.method == 0:
        s = poly_first_root(poly, mode.iso)
        if s == s:  # not NaN
            px, py, pz = ax + s * (bx - ax), ay + s * (by - ay), az + s * (bz - az)
            gx, gy, gz = gradient(grid, scratch, ctx, i, j, k, tag, px, py, pz)
            return _hit_state(mode, grid, scratch, ray, t0 + s * (t1 - t0), i + px, j + py,
                              k + pz, gx, gy, gz)
        return st
    return _consume_sampled(mode, grid, scratch, poly, t0, t1, ray, st)


@jit()
def _consume_sampled(mode, grid, scratch, poly, t0, t1, ray, st):
    iso = mode.iso
    anchor = ray.anchor
    dt = _dt(mode, ray)
    m = math.ceil((t0 - anchor) / dt)
    ts = anchor + m * dt
    prev_t, prev_g = st[4], st[5]
    while ts <= t1:
        s = (ts - t0) / (t1 - t0) if t1 > t0 else 0.0
        g = poly_value(poly, s) - iso
        if prev_g == prev_g and ((prev_g < 0.0) != (g < 0.0) or g == 0.0):
            return _bisect(mode, grid, scratch, ray, prev_t, prev_g, ts, g)
        if prev_g != prev_g and g == 0.0:
            return _hit(mode, grid, scratch, ray, ts)
        prev_t, prev_g = ts, g
        m += 1
        ts = anchor + m * dt
    return st[0], st[1], st[2], st[3], prev_t, prev_g


@jit()
def _ray_end(mode, grid, scratch, st, ray, t_far):
    # The sampled method also samples the exit point, so a crossing in the last partial step
    # is not lost.
    prev_t, prev_g = st[4], st[5]
    if mode.method == 1 and st[0] == math.inf and prev_g == prev_g and prev_t < t_far:
        g = _sample(grid, scratch, ray, t_far, mode.iso)
        if (prev_g < 0.0) != (g < 0.0) or g == 0.0:
            return _bisect(mode, grid, scratch, ray, prev_t, prev_g, t_far, g)
    return st


@jit()
def _finish(mode, out, row, col, st, ray):
    rgba, depth, position, normal, face = out
    if st[0] == math.inf:
        store_miss(row, col, mode.shading, rgba, depth, position, normal, face)
    else:
        store_hit(row, col, st[0], ray, st[1], st[2], st[3], mode.inside_high, mode.shading,
                  out, st[5])


register(IsoMode,
         state_new=_state_new,
         state_load=_state_load,
         state_store=_state_store,
         mode_scratch=no_scratch,
         ray_begin=unchanged_begin,
         skip_size=_skip_size,
         answer_shift=_answer_shift,
         wants=_wants,
         on_skip=_on_skip,
         consume=_consume,
         done=_done,
         ray_end=_ray_end,
         finish=_finish,
         watches_skips=_watches_skips)


@jit(parallel=True)
def combine_iso(front: tuple, back: tuple, out: tuple) -> None:
    """``out`` = the nearer hit of two partial states of the same rays (``front`` first)."""
    fd, fg, fp = front
    bd, bg, bp = back
    od, og, op = out
    height, width = fd.shape
    for row in prange(height):
        for col in range(width):
            src_d, src_g = (fd, fg) if fd[row, col] <= bd[row, col] else (bd, bg)
            od[row, col] = src_d[row, col]
            for c in range(3):
                og[row, col, c] = src_g[row, col, c]
            # The back's last sample continues the ray; a hit's slope stays with its hit.
            src_p = fp if fd[row, col] < math.inf and fd[row, col] <= bd[row, col] else bp
            op[row, col, 0] = src_p[row, col, 0]
            op[row, col, 1] = src_p[row, col, 1]


class Iso(ModeHost):
    """Host side of the first-hit isosurface mode: parameters, buffers, the Frame.

    Parameters
    ----------
    iso : float
        Isovalue in data units (already checked against the data range).
    method : {"exact", "sampled"}
        Exact first root per piece, or fixed-step sampling plus bisection.
    step : float
        Sampling step of the sampled method, in voxels.
    inside : {"high", "low"}
        Which side of the isovalue is the object's inside.
    shading : Shading, optional
        Colours and lighting.
    outputs : set of str, optional
        The Frame's buffers to fill (:mod:`.outputs`; default all).
    normals : {"smooth", "exact"}
        Shade with the model's shading field or its own gradient (:mod:`.shading`).
    """

    name = "iso"
    effects_after_tracing = True

    def blocks_key(self) -> Hashable:
        """The isovalue."""
        return ("iso", float(self.params.iso))

    def surface_values(self) -> float:
        """The isovalue."""
        return self.params.iso

    def first_hit_iso(self) -> float:
        """The isovalue: a first-hit isosurface's gaps at level boundaries are closed."""
        return self.params.iso

    def __init__(self, iso: float, method: str = "exact", step: float = 0.25,
                 inside: str = "high", shading: Shading | None = None,
                 outputs: frozenset[str] = ALL_OUTPUTS, normals: str = "smooth") -> None:
        self.outputs = outputs
        if method not in METHODS:
            raise ParameterError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
        if method == "sampled":  # against the volume's size too: limits.check_render
            limits.check_finite_number(step, "step", lo=limits.MIN_STEP)
        self.method = method
        self.shading = shading or Shading()
        self.normals = normals
        self.params = IsoMode(float(iso), METHODS[method], float(step), inside == "high",
                              self.shading.as_array(), normals_code(normals))

    def blocks(self, hierarchy: Any, flags: tuple | None = None) -> tuple:
        """Block flags for the isovalue (``flags`` overrides, e.g. a model's own), and, for
        the exact method, the 2-cell blocks' flags when ``flags`` has them (the sampled
        method leaps the 4-cell blocks only, so its samples stay where they were): packed per
        4-cell block for the walk (``blocks[3]``; ``flags[4]`` when ``flags`` brings them
        packed), and one byte each for the footprint (``blocks[4]``)."""
        if flags is None:
            flags = hierarchy.classify(self.params.iso)
        no_pairs = np.zeros((0, 0, 0), np.uint8)
        pairs = flags[3] if len(flags) > 3 and self.method == "exact" else no_pairs
        if pairs.shape[0] == 0:
            return (*flags[:3], no_pairs, no_pairs)
        # The kernel reads the pairs packed per 4-cell block; the footprint projects them.
        pack = getattr(hierarchy, "packed_pairs", None)
        if len(flags) > 4:
            packed = flags[4]
        elif pack is not None:
            packed = pack(pairs, flags[0])
        else:
            packed = packed_pair_flags(pairs, np.asarray(flags[0].shape, np.int64))
        return (*flags[:3], packed, pairs)

    def footprint_flags(self, blocks: tuple) -> tuple | None:
        """The block flags whose screen footprint bounds where rays can hit (:mod:`.footprint`):
        the exact method's, its 2-cell blocks' first when it has them (a hit lies in a cell
        whose range holds the isovalue, so in a flagged pair); none for the sampled method,
        whose samples in front of an active block take part in finding a crossing."""
        if self.method != "exact":
            return None
        return (blocks[4], *blocks[:3]) if blocks[4].shape[0] else blocks[:3]

    @staticmethod
    def state(height: int, width: int) -> tuple:
        """Per-pixel state arrays (contents undefined until reset)."""
        return (np.empty((height, width)), np.empty((height, width, 3)),
                np.empty((height, width, 2)))

    def output(self, height: int, width: int) -> tuple:
        """Output buffers: rgba, depth, position, normal, face (zero rows: not requested)."""
        o = self.outputs
        return (buffer("rgba" in o, (height, width, 4), np.float32),
                buffer("depth" in o, (height, width)),
                buffer("position" in o, (height, width, 3)),
                buffer("normal" in o, (height, width, 3), np.float32),
                buffer("face" in o, (height, width), np.int8))

    def frame(self, out: tuple, counters: tuple, stats: dict) -> Frame:
        """The Frame of finished outputs (``None`` for those not requested)."""
        return Frame(*(a if a.shape[0] else None for a in out), *counters, stats)

    combine = staticmethod(combine_iso)
