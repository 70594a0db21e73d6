"""Direct volume rendering: emission-absorption compositing front to back, for every model.

Each ray piece (a cell, or a tetrahedron of a cell, see :mod:`splinecast.models.pieces`) is cut
into segments at the ray's samples, taken every ``step`` voxels from the ray's entry into the
volume; a segment from parameter ``t_a`` (value ``v_a``) to ``t_b`` (value ``v_b``, the piece's
polynomial evaluated there) of length ``L`` voxels is classified and composited with the "under"
operator, ``C += (1 - A) c``, ``A += (1 - A) a`` (premultiplied colours):

* plain classification: the back sample's transfer-function value, ``a = 1 - exp(-tau(v_b) L)``,
  ``c = C(v_b) a``;
* pre-integrated (:mod:`splinecast.preintegration`): the segment's exact integral for a value going
  linearly from ``v_a`` to ``v_b``, looked up bilinearly in a table. A 2D table is for one length;
  other lengths (segments cut short by a piece boundary) use the opacity correction
  ``a' = 1 - (1 - a)^(L / h)`` with the colour scaled by ``a' / a``. A 3D table holds the lengths
  ``k h0`` (uniform layout) or ``2^j h0`` (exponential layout) exactly, which is what the
  opacity-adaptive step uses: its step is rounded to the nearest length in the table (for the
  exponential layout, nearest in ``log2``).

With ``sampling="pieces"`` the segments are not anchored at the ray's entry: every piece is cut
into ``ceil(L / step)`` equal segments (``L`` its length in voxels), so a cell shorter than
``step`` along the ray is a single segment and a single table lookup, and segments of a length
the table does not hold take their opacity from the table's optical depth (a fifth channel,
``-ln(1 - alpha)``, scaled by the length ratio: one ``exp``). This is what ``mode="dvr"`` uses
without settings (:data:`DEFAULT_SETTINGS`, with early termination at ``1 - 2^-10``): the cost
of a cell walk is in the calls per cell (the walk's step and the consume call), not in the
samples inside a cell, so a per-piece integration and termination are what pay.

With ``sampling="ray"`` there is no cell walk: the fixed-step loop of :mod:`.sampler` takes
the model's value every ``step`` voxels from the ray's entry, and the stretch between two
samples, across however many cells, is one segment and one table lookup (the ray caster of VTK
and most viewers, with the segments pre-integrated rather than classified by one sample). Blocks
whose value range is transparent are leapt to the last sample inside them. Bricks sample at the
same places; a segment crossing a brick face is cut in two there, which changes it only by the
field's curvature along it (``tests/test_dvr_ray.py``).

Otherwise segments end at every piece boundary, so no segment spans two cells: a ray traced
brick by brick meets exactly the same segments as through the whole volume, and bricks traced
independently combine with "over" into the same image (fixed step; the adaptive step depends
on the opacity in front). Cells whose value range is fully transparent (the transfer function's
prefix-sum table, Carmona & Froehlich 2011, section 1.5) and blocks the hierarchy marks invisible
contribute nothing and are left out. A value range that only touches an end of the transfer
function beyond which its opacity is zero (``TransferFunction.clear_ends``: a background of
zeros under a ramp starting at 0) is transparent too, exactly, although it meets the closed
visible ranges and the prefix table's first bin; such blocks are leapt (the MRI's background,
with a ramp over the whole data range: 3.4x faster frames).

Opacity-adaptive step (Carmona & Froehlich 2011, eq. 10): ``h = h_min + (h_max - h_min) A^n`` with
``A`` the accumulated opacity, so the step grows where little of what follows can still be seen.
Early ray termination stops a ray once ``A`` reaches a threshold ``A_max``: what it leaves out is at
most ``(1 - A_max)`` per channel.

Optional gradient shading multiplies each segment's colour by ``ambient + diffuse |n . u|``
(headlight, ``n`` the normalized gradient of the model at the segment's back end).

``depth`` is where the accumulated opacity first reaches 1/2 (``inf`` if never).
"""

from __future__ import annotations

import json
import math
import time
from collections import namedtuple
from collections.abc import Hashable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import prange

from .._jit import jit
from ..accel.minmax import BLOCK_SHIFTS, neighbourhood
from ..errors import ParameterError, limits
from ..models.pieces import gradient, value_gradient_at
from ..preintegration import (
    PreintegrationTable,
    preint_lookup,
    preintegrate,
    table_cell,
    table_channel,
    table_rgba,
)
from ..roots.pieces import poly_value
from ..transfer import TransferFunction
from .frame import Frame
from .mode_api import (
    flagged_block_size,
    no_scratch,
    register,
    unchanged_begin,
    unchanged_end,
    unchanged_skip,
)
from .mode_host import ModeHost
from .outputs import ALL_OUTPUTS, buffer

__all__ = ["DVRSettings", "DEFAULT_SETTINGS", "PREINTEGRATION", "TABLE_LAYOUTS", "SAMPLINGS",
           "DvrMode", "DvrRayMode", "Dvr", "combine_dvr"]

#: Classification kinds accepted by :class:`DVRSettings`.
PREINTEGRATION = ("none", "2d", "3d")

#: Layouts of the 3D pre-integration table accepted by :class:`DVRSettings`.
TABLE_LAYOUTS = ("uniform", "exponential")

#: Where segments end, accepted by :class:`DVRSettings`: at samples every ``step`` voxels from
#: the ray's entry and at every piece boundary ("grid"), at equal divisions of every piece,
#: none longer than ``step`` ("pieces"), or only at the samples ("ray": a segment may span
#: several cells; the fixed-step loop of :mod:`.sampler`).
SAMPLINGS = ("grid", "pieces", "ray")


@dataclass(frozen=True)
class DVRSettings:
    """How a direct volume rendering is sampled and composited.

    Parameters
    ----------
    step : float
        Sampling step in voxels (``h_min`` of the adaptive step).
    preintegration : {"none", "2d", "3d"}
        Plain classification of samples, a 2D pre-integration table for the fixed step, or a 3D
        table over several step lengths (needed for the adaptive step to be exact).
    table_layout : {"uniform", "exponential"}
        Lengths of the 3D table: ``k * step`` for ``k = 1 .. ceil(h_max / step)`` (uniform,
        eq. 14 reuse) or ``2**j * step`` up to ``h_max`` (exponential, eq. 13 reuse; the
        adaptive step is then rounded to a power of two times ``step``).
    adaptive : bool
        Opacity-adaptive step ``h = step + (h_max - step) * A^exponent``.
    h_max, exponent : float
        Largest step (voxels) and exponent of the adaptive step (Carmona & Froehlich 2011: 8 and
        3, with ``h_min = 1``).
    termination : float or None
        Stop a ray when its accumulated opacity reaches this value (``None``: never).
    shade : bool
        Gradient (headlight) shading of the samples.
    ambient, diffuse : float
        Weights of the gradient shading.
    table_size : int
        Values per axis of the pre-integration table.
    leap : bool
        Accepted for compatibility; has no effect (segments now end at every cell, so every
        visible cell is visited).
    sampling : {"grid", "pieces", "ray"}
        Where segments end. ``"grid"``: at samples every ``step`` voxels from the ray's entry
        into the volume, and at every piece (cell or tetrahedron) boundary. ``"pieces"``: every
        ray piece is cut into ``ceil(L / step)`` equal segments (``L`` its length in voxels), so
        a cell shorter than ``step`` along the ray is one segment and one table lookup; no
        segment is longer than ``step``, and the error stays second order in ``step``.
        (The adaptive step, in this sampling, is chosen once per piece.) ``"ray"``: only at
        the samples every ``step`` voxels from the entry (and at the ends of a brick's
        stretch of the ray): a segment may span several cells, and the model's value is taken
        at the samples only, the classic ray caster's loop (:mod:`.sampler`) with the
        segments pre-integrated; no cell walk, so it is the fastest, and the error is second
        order in ``step`` (the field is taken as linear between samples). Not with
        ``adaptive``.
    """

    step: float = 0.5
    preintegration: str = "2d"
    adaptive: bool = False
    h_max: float = 4.0
    exponent: float = 3.0
    termination: float | None = None
    shade: bool = False
    ambient: float = 0.3
    diffuse: float = 0.7
    table_size: int = 256
    table_layout: str = "uniform"
    leap: bool = True
    sampling: str = "grid"

    def __post_init__(self) -> None:
        # Bounds on work and memory (splinecast.errors.limits): the smallest step, finite
        # weights, and a table that fits in memory. The step against a volume's size is checked
        # at render.
        limits.check_finite_number(self.step, "step (voxels)", lo=limits.MIN_STEP)
        for name in ("ambient", "diffuse", "exponent"):
            limits.check_finite_number(getattr(self, name), name, lo=0)
        limits.check_count(self.table_size, "table_size", lo=2, hi=4096)
        if self.preintegration not in PREINTEGRATION:
            raise ParameterError(f"preintegration must be one of {', '.join(PREINTEGRATION)}, "
                                 f"got {self.preintegration!r}")
        if self.adaptive:
            limits.check_finite_number(self.h_max, f"h_max (>= step {self.step:g})",
                                       lo=self.step)
        if self.termination is not None:
            limits.check_finite_number(self.termination, "termination", lo=0, hi=1,
                                       lo_open=True)
        if not self.exponent > 0:
            raise ParameterError(f"exponent must be positive, got {self.exponent}")
        if self.sampling not in SAMPLINGS:
            raise ParameterError(f"sampling must be one of {', '.join(SAMPLINGS)}, "
                                 f"got {self.sampling!r}")
        if self.sampling == "ray" and self.adaptive:
            raise ParameterError("adaptive=True needs sampling 'grid' or 'pieces' (the 'ray' "
                                 "sampling takes samples at a fixed step)")
        if self.table_layout not in TABLE_LAYOUTS:
            raise ParameterError(f"table_layout must be one of {', '.join(TABLE_LAYOUTS)}, "
                                 f"got {self.table_layout!r}")
        if self.preintegration == "3d":
            n = int(self.table_size)
            # float32 RGBA entries, and as much again for the build's temporaries.
            limits.check_memory(limits.nbytes((self.table_steps, n, n, 4), 4) * 2,
                                f"a {self.table_steps}x{n}x{n} pre-integration table",
                                "DVRSettings (h_max / step, table_size)")

    @property
    def table_steps(self) -> int:
        """Lengths in the 3D table: ``k * step`` for ``k = 1 .. ceil(h_max / step)``
        (uniform), or ``2**j * step`` for ``j = 0 .. floor(log2(h_max / step))``."""
        if self.preintegration != "3d":
            return 1
        top = self.h_max if self.adaptive else self.step
        if self.table_layout == "exponential":
            return 1 + max(0, math.floor(math.log2(top / self.step) + 1e-9))
        return max(1, math.ceil(top / self.step - 1e-9))

    @property
    def pi_mode(self) -> int:
        """Classification code of the kernel: 0 plain, 1 2D, 2 uniform 3D, 3 exponential 3D."""
        if self.preintegration == "3d" and self.table_layout == "exponential":
            return 3
        return {"none": 0, "2d": 1, "3d": 2}[self.preintegration]


#: What ``mode="dvr"`` uses when no :class:`DVRSettings` are given: the fixed-step loop
#: (``sampling="ray"``) with a sample every voxel and the segments between samples
#: pre-integrated, and rays stopped once what remains visible behind them is below 2^-10 per
#: channel (a quarter of the 8-bit step), which no 8-bit image can show. Against the comparison
#: suite's dense reference it stays well within that suite's tolerance (mean absolute error
#: 1/255; ``docs/accuracy.rst``), and it walks no cells, so it is faster than the per-piece
#: sampling (``sampling="pieces"``, whose error is about half); ``tests/test_dvr_pieces.py``
#: checks it. On small volumes whose field bends within a voxel the per-piece sampling is the
#: more accurate (``tests/test_dvr_pieces.py`` bounds both). Bricks rendered independently and
#: merged with "over" (sort-last) can differ from the whole-volume image by up to the same
#: 2^-10, because a back brick cannot know the opacity in front of it, and by a segment cut in
#: two at each brick face (second order in the step); pass ``DVRSettings(sampling="pieces")``
#: for the exact merge.
DEFAULT_SETTINGS = DVRSettings(step=1.0, sampling="ray", termination=1.0 - 2.0**-10)

#: Kernel parameters (see :class:`Dvr` for their meaning).
DvrMode = namedtuple("DvrMode", [
    "prefix", "p_lo", "p_scale", "pi_mode", "table", "h0", "t_lo", "t_scale", "lut",
    "l_scale", "adaptive", "h_max", "exponent", "term", "shade", "ambient", "diffuse",
    "bg_r", "bg_g", "bg_b", "bg_a", "pieces", "clear_below", "clear_above", "zero_below",
    "zero_above"])

#: The same parameters for ``sampling="ray"``: another class, so the driver runs the fixed-step
#: loop of :mod:`.sampler` for it.
DvrRayMode = namedtuple("DvrRayMode", DvrMode._fields)


@jit(inline="always")
def _shade_factor(shade, ambient, diffuse, gx, gy, gz, sx, sy, sz, ux, uy, uz):
    if not shade:
        return 1.0
    wx, wy, wz = gx / sx, gy / sy, gz / sz
    norm = math.sqrt(wx * wx + wy * wy + wz * wz)
    if norm == 0.0:
        return ambient + diffuse
    return ambient + diffuse * abs(wx * ux + wy * uy + wz * uz) / norm


@jit(inline="always")
def _table_entry(pi_mode, table, h0, t_lo, t_scale, va, vb, length):
    """Where a segment ``(va, vb, length)`` reads a pre-integration table: the front and back
    value coordinates, the length index ``k`` and the length that table row holds."""
    n = table.shape[1]
    steps = table.shape[0]
    uf = min(max((va - t_lo) * t_scale, 0.0), n - 1.0)
    ub = min(max((vb - t_lo) * t_scale, 0.0), n - 1.0)
    if pi_mode == 3:
        # Exponential layout: the table nearest in log2 of the length.
        j = 0
        if length > h0:
            j = min(int(math.log2(length / h0) + 0.5), steps - 1)
        return uf, ub, j, h0 * 2.0**j
    k = min(max(int(length / h0 + 0.5), 1), steps)
    return uf, ub, k - 1, k * h0


@jit(inline="always")
def _classify(pi_mode, table, h0, t_lo, t_scale, lut, l_lo, l_scale,
              va, vb, length):
    """Premultiplied RGBA of a segment of ``length`` voxels from value ``va`` to ``vb``."""
    if pi_mode == 0:
        n = lut.shape[0]
        u = min(max((vb - l_lo) * l_scale, 0.0), n - 1.0)
        i = min(int(u), n - 2)
        f = u - i
        tau = (1.0 - f) * lut[i, 3] + f * lut[i + 1, 3]
        a = -math.expm1(-tau * length)
        r = ((1.0 - f) * lut[i, 0] + f * lut[i + 1, 0]) * a
        g = ((1.0 - f) * lut[i, 1] + f * lut[i + 1, 1]) * a
        b = ((1.0 - f) * lut[i, 2] + f * lut[i + 1, 2]) * a
        return r, g, b, a
    uf, ub, k, held = _table_entry(pi_mode, table, h0, t_lo, t_scale, va, vb, length)
    r, g, b, a = preint_lookup(table, k, uf, ub)
    ratio = length / held
    if abs(ratio - 1.0) > 1e-9 and a > 0.0:
        # A length the table does not hold: correct the opacity for it (colour follows).
        a2 = -math.expm1(ratio * math.log1p(-min(a, 1.0 - 1e-12)))
        scale = a2 / a
        return r * scale, g * scale, b * scale, a2
    return r, g, b, a


@jit(inline="always")
def _classify_od(pi_mode, table, h0, t_lo, t_scale, lut, l_lo, l_scale,
                 va, vb, length):
    """:func:`_classify` for segments of any length, with the table's optical depth at hand.

    ``table[k, ..., 4] = -ln(1 - alpha)`` (the table's optical depth, a fifth channel the
    pieces sampling adds), interpolated bilinearly like the colours, so the
    opacity of a length the table does not hold is ``1 - exp(-(L / held) od)`` (one ``exp``
    instead of a ``log1p`` of the interpolated opacity and an ``expm1``). Optical depth is what
    adds up along a ray, so interpolating it is as accurate as interpolating the opacity.
    """
    if pi_mode == 0:
        return _classify(pi_mode, table, h0, t_lo, t_scale, lut, l_lo, l_scale,
                         va, vb, length)
    uf, ub, k, held = _table_entry(pi_mode, table, h0, t_lo, t_scale, va, vb, length)
    r, g, b, a = preint_lookup(table, k, uf, ub)
    ratio = length / held
    if abs(ratio - 1.0) <= 1e-9 or not a > 0.0:
        return r, g, b, a
    d = table_channel(table, k, table_cell(table, uf, ub), 4)
    a2 = 1.0 - math.exp(-ratio * d)  # not expm1: see _pieces_2d
    scale = a2 / a
    return r * scale, g * scale, b * scale, a2


@jit(inline="always")
def _adaptive_step(pi_mode, steps, h0, h_max, exponent, acc_a):
    """Opacity-adaptive step in voxels, rounded to a length the 3D table holds."""
    h = h0 + (h_max - h0) * acc_a**exponent
    if pi_mode == 2:
        h = max(1.0, math.floor(h / h0 + 0.5)) * h0
    elif pi_mode == 3:
        j = 0
        if h > h0:
            j = min(int(math.log2(h / h0) + 0.5), steps - 1)
        h = h0 * 2.0**j
    return h


@jit(inline="always")
def _composite(acc_r, acc_g, acc_b, acc_a, t_half, r, g, b, a, shade_factor, t):
    """Front-to-back "over" of a premultiplied segment colour; tracks where alpha passes 1/2."""
    w = (1.0 - acc_a) * shade_factor
    acc_r += w * r
    acc_g += w * g
    acc_b += w * b
    acc_a += (1.0 - acc_a) * a
    if acc_a >= 0.5 and t_half == math.inf:
        t_half = t
    return acc_r, acc_g, acc_b, acc_a, t_half


@jit(inline="always")
def _state_new(mode):
    # acc r, g, b, a; depth where a passes 1/2; samples taken; next sample (adaptive step).
    return 0.0, 0.0, 0.0, 0.0, math.inf, 0, math.nan


@jit()
def _state_load(mode, state, row, col):
    acc, t_half, t_next, samples = state
    return (acc[row, col, 0], acc[row, col, 1], acc[row, col, 2], acc[row, col, 3],
            t_half[row, col], np.int64(samples[row, col]), t_next[row, col])


@jit()
def _state_store(mode, state, row, col, st):
    acc, t_half, t_next, samples = state
    acc[row, col, 0] = st[0]
    acc[row, col, 1] = st[1]
    acc[row, col, 2] = st[2]
    acc[row, col, 3] = st[3]
    t_half[row, col] = st[4]
    samples[row, col] = st[5]
    t_next[row, col] = st[6]


@jit()
def _wants(mode, st, lo, hi):
    """Not fully transparent over ``[lo, hi]`` (prefix table; an empty range is transparent,
    and so is one at or beyond an end where the opacity is zero: the prefix table's first and
    last bins stand for more than that end)."""
    if not lo <= hi or hi <= mode.clear_below or lo >= mode.clear_above:
        return False
    nbins = mode.prefix.shape[0] - 1
    b0 = min(max(int((lo - mode.p_lo) * mode.p_scale), 0), nbins - 1)
    b1 = min(max(int((hi - mode.p_lo) * mode.p_scale), 0), nbins - 1)
    return mode.prefix[b1 + 1] != mode.prefix[b0]


@jit()
def _done(mode, st):
    return st[3] >= mode.term


@jit(inline="always")
def _shaded_over(mode, grid, scratch, piece, s, ray, acc, colour, t):
    """One segment's colour ``colour`` (premultiplied ``(r, g, b, a)``) composited behind the
    ray's, ``acc`` (``(acc_r, acc_g, acc_b, acc_a, t_half)``, returned updated), shaded (when
    asked) with the gradient at the point ``s`` of the piece (a :class:`.rays.RayPiece`)."""
    acc_r, acc_g, acc_b, acc_a, t_half = acc
    r, g, b, a = colour
    factor = 1.0
    if mode.shade:
        ax, ay, az, bx, by, bz = piece.ax, piece.ay, piece.az, piece.bx, piece.by, piece.bz
        gx, gy, gz = gradient(grid, scratch, piece.ctx, piece.i, piece.j, piece.k, piece.tag,
                              ax + s * (bx - ax), ay + s * (by - ay), az + s * (bz - az))
        factor = _shade_factor(True, mode.ambient, mode.diffuse, gx, gy, gz,
                               ray.spacing_x, ray.spacing_y, ray.spacing_z,
                               ray.world_dx, ray.world_dy, ray.world_dz)
    return _composite(acc_r, acc_g, acc_b, acc_a, t_half, r, g, b, a, factor, t)


@jit(inline="always")
def _pieces_2d(mode, grid, scratch, piece, ray, n, seg, va, st):
    """The pieces sampling with a 2D table: ``n`` segments of ``seg`` voxels of the piece (a
    :class:`.rays.RayPiece`) whose value at its start is ``va``, into the state ``st``.

    The same integral as :func:`_classify_od`, written out for the common case: the table's
    cell and weights are found once per segment, its opacity is read first (a transparent
    segment reads nothing else), and nothing is called that would not be inlined.
    """
    acc_r, acc_g, acc_b, acc_a, t_half, samples, t_next = st
    poly, t0 = piece.poly, piece.t0
    span = piece.t1 - piece.t0
    table = mode.table
    nt = table.shape[1]
    top = nt - 1.0
    lo = mode.t_lo
    scale_u = mode.t_scale
    ratio = seg / mode.h0
    held = abs(ratio - 1.0) <= 1e-9  # the table's own length: no correction
    uf = min(max((va - lo) * scale_u, 0.0), top)
    inv_n = 1.0 / n
    for m in range(1, n + 1):
        s = m * inv_n
        vb = poly_value(poly, s)
        ub = min(max((vb - lo) * scale_u, 0.0), top)
        samples += 1
        cell = table_cell(table, uf, ub)
        a = table_channel(table, 0, cell, 3)
        uf = ub
        if not a > 0.0:
            continue
        r = table_channel(table, 0, cell, 0)
        g = table_channel(table, 0, cell, 1)
        b = table_channel(table, 0, cell, 2)
        if not held:
            d = table_channel(table, 0, cell, 4)
            # ``1 - exp`` rather than ``-expm1``: libm's exp costs about half (5.9 against
            # 11.3 ns), and what expm1 keeps, the relative precision of a tiny opacity, does
            # not matter here: opacities and colours add up absolutely (the difference is
            # below 2^-52 of the pixel), and the table's entries are float32 anyway.
            a2 = 1.0 - math.exp(-ratio * d)
            f = a2 / a
            r, g, b, a = r * f, g * f, b * f, a2
        acc_r, acc_g, acc_b, acc_a, t_half = _shaded_over(
            mode, grid, scratch, piece, s, ray, (acc_r, acc_g, acc_b, acc_a, t_half),
            (r, g, b, a), t0 + s * span)
        if acc_a >= mode.term:
            break
    return acc_r, acc_g, acc_b, acc_a, t_half, samples, t_next


@jit(inline="always")
def _index_speed(ray):
    """Voxels the ray crosses per world unit along it (the length of its index direction)."""
    dx, dy, dz = ray.index_dx, ray.index_dy, ray.index_dz
    return math.sqrt(dx * dx + dy * dy + dz * dz)


@jit(inline="always")
def _consume_pieces(mode, grid, scratch, piece, ray, st):
    """``sampling="pieces"``: the piece cut into ``ceil(L / h)`` equal segments."""
    acc_r, acc_g, acc_b, acc_a, t_half, samples, t_next = st
    poly, t0, t1 = piece.poly, piece.t0, piece.t1
    dnorm = _index_speed(ray)
    span = t1 - t0
    length = span * dnorm
    if not length > 0.0:
        return st
    h = mode.h0
    if mode.adaptive:
        h = _adaptive_step(mode.pi_mode, mode.table.shape[0], mode.h0, mode.h_max,
                           mode.exponent, acc_a)
    n = max(int(math.ceil(length / h - 1e-9)), 1)
    seg = length / n
    va = poly_value(poly, 0.0)
    if mode.pi_mode == 1:
        return _pieces_2d(mode, grid, scratch, piece, ray, n, seg, va, st)
    for m in range(1, n + 1):
        s = m / n
        vb = poly_value(poly, s)
        r, g, b, a = _classify_od(mode.pi_mode, mode.table, mode.h0, mode.t_lo,
                                  mode.t_scale, mode.lut, mode.t_lo,
                                  mode.l_scale, va, vb, seg)
        samples += 1
        if a > 0.0:
            acc_r, acc_g, acc_b, acc_a, t_half = _shaded_over(
                mode, grid, scratch, piece, s, ray, (acc_r, acc_g, acc_b, acc_a, t_half),
                (r, g, b, a), t0 + s * span)
            if acc_a >= mode.term:
                break
        va = vb
    return acc_r, acc_g, acc_b, acc_a, t_half, samples, t_next


@jit()
def _consume(mode, mscratch, grid, scratch, piece, ray, st):
    if mode.pieces:
        return _consume_pieces(mode, grid, scratch, piece, ray, st)
    acc_r, acc_g, acc_b, acc_a, t_half, samples, t_next = st
    poly, t0, t1 = piece.poly, piece.t0, piece.t1
    anchor = ray.anchor
    dnorm = _index_speed(ray)
    dt = mode.h0 / dnorm  # the base step in world units
    steps = mode.table.shape[0]
    span = t1 - t0
    # The next sample after t0: on the fixed grid anchor + m dt, or carried (adaptive step).
    if mode.adaptive and t_next == t_next:
        ts = t_next
        while ts <= t0:
            ts += _adaptive_step(mode.pi_mode, steps, mode.h0, mode.h_max, mode.exponent,
                                 acc_a) / dnorm
    else:
        ts = anchor + (math.floor((t0 - anchor) / dt) + 1.0) * dt
    ta = t0
    va = poly_value(poly, 0.0)
    while True:
        sample = ts < t1
        tb = ts if sample else t1
        s = (tb - t0) / span if span > 0.0 else 1.0
        vb = poly_value(poly, s)
        length = (tb - ta) * dnorm
        if length > 0.0:
            r, g, b, a = _classify(mode.pi_mode, mode.table, mode.h0, mode.t_lo, mode.t_scale,
                                   mode.lut, mode.t_lo, mode.l_scale, va, vb,
                                   length)
            if a > 0.0:
                acc_r, acc_g, acc_b, acc_a, t_half = _shaded_over(
                    mode, grid, scratch, piece, s, ray, (acc_r, acc_g, acc_b, acc_a, t_half),
                    (r, g, b, a), tb)
        if not sample or acc_a >= mode.term:
            break
        samples += 1
        ta, va = tb, vb
        if mode.adaptive:
            ts += _adaptive_step(mode.pi_mode, steps, mode.h0, mode.h_max, mode.exponent,
                                 acc_a) / dnorm
        else:
            ts = anchor + (math.floor((ts - anchor) / dt + 0.5) + 1.0) * dt
    return acc_r, acc_g, acc_b, acc_a, t_half, samples, ts


@jit()
def _finish(mode, out, row, col, st, ray):
    rgba, depth, position, samples = out
    # Buffers with no rows were not asked for (see .outputs).
    if rgba.shape[0] != 0:
        rest = 1.0 - st[3]
        rgba[row, col, 0] = min(st[0] + rest * mode.bg_r * mode.bg_a, 1.0)
        rgba[row, col, 1] = min(st[1] + rest * mode.bg_g * mode.bg_a, 1.0)
        rgba[row, col, 2] = min(st[2] + rest * mode.bg_b * mode.bg_a, 1.0)
        rgba[row, col, 3] = st[3] + rest * mode.bg_a
    t = st[4]
    if depth.shape[0] != 0:
        depth[row, col] = t
    if position.shape[0] != 0:
        hit = t < math.inf
        position[row, col, 0] = ray.world_x + t * ray.world_dx if hit else math.nan
        position[row, col, 1] = ray.world_y + t * ray.world_dy if hit else math.nan
        position[row, col, 2] = ray.world_z + t * ray.world_dz if hit else math.nan
    if samples.shape[0] != 0:
        samples[row, col] = st[5]


@jit()
def _sample_step(mode):
    return mode.h0


@jit()
def _segment(mode, grid, scratch, st, ray, stretch):
    """``sampling="ray"``: the stretch between two samples, composited behind the ray's colour
    (shaded with the model's gradient at its back end, ``(x, y, z)``)."""
    tb, va, vb, length = stretch.tb, stretch.va, stretch.vb, stretch.length
    x, y, z = stretch.x, stretch.y, stretch.z
    acc_r, acc_g, acc_b, acc_a, t_half, samples, t_next = st
    samples += 1
    if mode.pi_mode == 1 and abs(length - mode.h0) <= 1e-9 * mode.h0:
        # The common case, a whole step with a 2D table: the table's own length, so no
        # correction; its opacity is read first and a transparent segment reads nothing else.
        table = mode.table
        top = table.shape[1] - 1.0
        uf = min(max((va - mode.t_lo) * mode.t_scale, 0.0), top)
        ub = min(max((vb - mode.t_lo) * mode.t_scale, 0.0), top)
        if (uf < mode.zero_below and ub < mode.zero_below) or (
                uf >= mode.zero_above and ub >= mode.zero_above):
            # All four entries the lookup would read have opacity 0 (_zero_corners): the
            # segment is transparent, as the lookup would find, without reading the table.
            return acc_r, acc_g, acc_b, acc_a, t_half, samples, t_next
        r, g, b, a = table_rgba(table, 0, table_cell(table, uf, ub))
        if not a > 0.0:
            return acc_r, acc_g, acc_b, acc_a, t_half, samples, t_next
    else:
        r, g, b, a = _classify(mode.pi_mode, mode.table, mode.h0, mode.t_lo, mode.t_scale,
                               mode.lut, mode.t_lo, mode.l_scale, va, vb, length)
    if a > 0.0:
        factor = 1.0
        if mode.shade:
            _, gx, gy, gz = value_gradient_at(grid, scratch, x, y, z)
            factor = _shade_factor(True, mode.ambient, mode.diffuse, gx, gy, gz, ray.spacing_x,
                                   ray.spacing_y, ray.spacing_z, ray.world_dx, ray.world_dy,
                                   ray.world_dz)
        acc_r, acc_g, acc_b, acc_a, t_half = _composite(acc_r, acc_g, acc_b, acc_a, t_half, r,
                                                        g, b, a, factor, tb)
    return acc_r, acc_g, acc_b, acc_a, t_half, samples, t_next


_HOOKS = dict(state_new=_state_new, state_load=_state_load, state_store=_state_store,
              mode_scratch=no_scratch, ray_begin=unchanged_begin, skip_size=flagged_block_size,
              wants=_wants, on_skip=unchanged_skip, consume=_consume, done=_done,
              ray_end=unchanged_end, finish=_finish)
register(DvrMode, **_HOOKS)
register(DvrRayMode, sample_step=_sample_step, segment=_segment, **_HOOKS)


#: Key of the "ray" sampling's footprint flags in the render cache (see Dvr.footprint_flags).
_SEGMENT_BLOCKS = "segment blocks"

#: Key of the table's transparent corners in the render cache (see _zero_corners).
_ZERO_CORNERS = "zero corners"


def _segment_blocks(mode: Any, visible: np.ndarray, lows: np.ndarray,
                    highs: np.ndarray) -> np.ndarray:
    """Finest blocks a taken segment of the fixed-step loop can touch: a visible block and its
    26 neighbours, and a block whose value range joined with its neighbours' is one the mode
    wants (the loop's test for a segment between two leapt blocks takes two of them, so this is
    conservative). Whole-array operations, once per transfer function: about 5 ms for a 256^3
    volume (64^3 blocks), 80 ms for 512^3."""
    near = neighbourhood(visible, np.maximum)
    lo, hi = neighbourhood(lows, np.minimum), neighbourhood(highs, np.maximum)
    # The kernel's test (``_wants``): the opacity prefix differs over the bins of [lo, hi].
    nbins = mode.prefix.shape[0] - 1
    b0 = np.clip((lo - mode.p_lo) * mode.p_scale, 0, nbins - 1).astype(np.int64)
    b1 = np.clip((hi - mode.p_lo) * mode.p_scale, 0, nbins - 1).astype(np.int64)
    wanted = ((lo <= hi) & (mode.prefix[b1 + 1] != mode.prefix[b0]) & (hi > mode.clear_below)
              & (lo < mode.clear_above))
    return ((near != 0) | wanted).view(np.uint8)


def _visible_flags(hierarchy: Any, tf: TransferFunction) -> tuple:
    """Flags of the blocks (every level, finest first) whose value range holds a value of
    non-zero opacity: those meeting a visible range, less those that only touch a transparent
    end (:meth:`TransferFunction.clear_ends`): a background of zeros under a ramp that starts
    at 0 is left out, as its values are all transparent."""
    below, above = tf.clear_ends()
    flags = hierarchy.flags_for(tf.visible_ranges())
    return tuple((f.view(bool) & (hi > below) & (lo < above)).view(np.uint8)
                 for f, lo, hi in zip(flags, hierarchy.lows, hierarchy.highs, strict=True))


def _any_in_blocks(flags: np.ndarray, factor: int, shape: tuple) -> np.ndarray:
    """Flags of blocks of ``factor`` finer blocks per axis: set where any finer one is."""
    padded = np.zeros(tuple(n * factor for n in shape), np.uint8)
    padded[:flags.shape[0], :flags.shape[1], :flags.shape[2]] = flags
    grouped = padded.reshape(shape[0], factor, shape[1], factor, shape[2], factor)
    return grouped.any(axis=(1, 3, 5)).view(np.uint8)


@jit(parallel=True)
def combine_dvr(front: tuple, back: tuple, out: tuple) -> None:
    """``out`` = ``front`` over ``back`` (premultiplied colour and opacity).

    The depth where the opacity passes 1/2 is the front's when it got there, else the back's
    (exact when the front is transparent; otherwise where the back alone passes 1/2, a bound).
    """
    fa, fh, fn, fs = front
    ba, bh, bn, bs = back
    oa, oh, on, os_ = out
    height, width = fh.shape
    for row in prange(height):
        for col in range(width):
            rest = 1.0 - fa[row, col, 3]
            for c in range(4):
                oa[row, col, c] = fa[row, col, c] + rest * ba[row, col, c]
            oh[row, col] = fh[row, col] if fh[row, col] < math.inf else bh[row, col]
            on[row, col] = bn[row, col]
            os_[row, col] = fs[row, col] + bs[row, col]


class Dvr(ModeHost):
    """Host side of direct volume rendering: the transfer function's tables and the Frame.

    Parameters
    ----------
    tf : TransferFunction
        The transfer function.
    settings : DVRSettings, optional
        Step, classification, adaptive step, early termination, shading (default
        :data:`DEFAULT_SETTINGS`, not ``DVRSettings()``).
    background : 4 floats
        What the rays composite over.
    cache : dict, optional
        Keeps the last pre-integration table between renders (tables take milliseconds to
        seconds to build).
    outputs : set of str, optional
        The Frame's buffers to fill (:mod:`.outputs`; default all; ``"stats"`` includes the
        per-ray sample counts).
    """

    name = "dvr"
    #: Rays composite through the volume (ModeHost.deep_rays).
    deep_rays = True
    #: The depth of a sort-last pixel is where the opacity in front crosses the threshold,
    #: which only the composited shares in front of a share know.
    refines_depth_after_compositing = True

    def blocks_key(self) -> Hashable:
        """The transfer function's visible value ranges and its transparent ends."""
        return ("tf", tuple(tuple(float(v) for v in r) for r in self.tf.visible_ranges()),
                self.tf.clear_ends())

    def visible_transfer(self) -> TransferFunction:
        """The transfer function: a brick it makes transparent shows nothing."""
        return self.tf

    def cut_transfer(self) -> TransferFunction:
        """The transfer function."""
        return self.tf

    def __init__(self, tf: TransferFunction, settings: DVRSettings | None = None,
                 background: Any = (0.0, 0.0, 0.0, 1.0), cache: dict | None = None,
                 outputs: frozenset[str] = ALL_OUTPUTS) -> None:
        self.outputs = outputs
        if not isinstance(tf, TransferFunction):
            raise ParameterError("mode 'dvr' needs tf=TransferFunction(...)")
        settings = settings or DEFAULT_SETTINGS
        if not isinstance(settings, DVRSettings):
            raise ParameterError(f"dvr must be a DVRSettings, got {type(settings).__name__}")
        self.tf = tf
        self.settings = settings
        cache = {} if cache is None else cache
        self._cache = cache
        start = time.perf_counter()
        pi_mode = settings.pi_mode
        if pi_mode:
            table = _table(tf, settings, cache)
        else:
            table = np.zeros((1, 2, 2, 4), np.float32)
        self.table_ms = (time.perf_counter() - start) * 1e3
        _, lut_rgb, lut_tau = tf.sample(4096)
        # One array for the plain classification's colour and extinction, scalars for the
        # background: every array in the mode's tuple costs a reference count increment and
        # decrement on each call of the (not inlined) consume hook, that is on every cell.
        lut = np.empty((lut_tau.shape[0], 4))
        lut[:, :3] = lut_rgb
        lut[:, 3] = lut_tau
        prefix = tf.transparency_prefix(1024)
        lo, hi = (float(v) for v in tf.domain)
        term = 2.0 if settings.termination is None else float(settings.termination)
        bg = np.asarray(background, np.float64).reshape(4)
        params_class = DvrRayMode if settings.sampling == "ray" else DvrMode
        # Computed once per table (a millisecond or two): kept with the table it is for.
        found = cache.get(_ZERO_CORNERS)
        if found is None or found[0] is not table:
            found = (table, _zero_corners(table[0, :, :, 3]))
            cache[_ZERO_CORNERS] = found
        zero_below, zero_above = found[1]
        self.params = params_class(
            prefix, lo, (prefix.shape[0] - 1) / (hi - lo), pi_mode, table, float(settings.step),
            lo, (table.shape[1] - 1) / (hi - lo), lut, (lut.shape[0] - 1) / (hi - lo),
            bool(settings.adaptive), float(settings.h_max), float(settings.exponent), term,
            bool(settings.shade), float(settings.ambient), float(settings.diffuse),
            float(bg[0]), float(bg[1]), float(bg[2]), float(bg[3]),
            settings.sampling == "pieces", *tf.clear_ends(), zero_below, zero_above)

    def blocks(self, hierarchy: Any, flags: tuple | None = None) -> tuple:
        """Flags of the blocks whose value range meets a visible part of the transfer function,
        and the ranges of the finest blocks (the fixed-step loop's test between two leaps)."""
        return (*_visible_flags(hierarchy, self.tf), hierarchy.lows[0],
                hierarchy.highs[0])

    def footprint_flags(self, blocks: tuple) -> tuple | None:
        """Flags of the blocks whose screen footprint bounds where a ray can gather colour
        (:mod:`.footprint`).

        The cell walk's samplings ("grid", "pieces") skip every cell of an invisible block:
        the visible blocks' flags. The fixed-step "ray" sampling takes a segment between two
        samples, in neighbouring finest blocks when the step is at most their edge; it takes
        one whose samples lie in two invisible blocks when the two blocks' joint value range
        is visible (:mod:`.sampler`). Its flags are therefore the finest blocks next to a
        visible one (or visible) and those whose range joined with their neighbours' ranges
        is visible (a superset of the pairs), and the coarser levels' flags hold any such
        block (:func:`_segment_blocks`). None for a step longer than the finest blocks' edge.
        """
        if self.settings.sampling != "ray":
            return blocks[:3]
        if self.settings.step > 1 << BLOCK_SHIFTS[0]:
            return None
        prefix = self.params.prefix
        found = self._cache.get(_SEGMENT_BLOCKS)
        if found is not None and found[0] is blocks[3] and np.array_equal(found[1], prefix):
            return found[2]
        finest = _segment_blocks(self.params, blocks[0], blocks[3], blocks[4])
        flags = [finest]
        for level in range(1, 3):
            factor = 1 << (BLOCK_SHIFTS[level] - BLOCK_SHIFTS[0])
            flags.append(_any_in_blocks(finest, factor, blocks[level].shape))
        self._cache[_SEGMENT_BLOCKS] = (blocks[3], prefix, tuple(flags))
        return tuple(flags)

    @staticmethod
    def state(height: int, width: int) -> tuple:
        """Per-pixel state arrays."""
        return (np.empty((height, width, 4)), np.empty((height, width)),
                np.empty((height, width)), np.empty((height, width), np.int32))

    def output(self, height: int, width: int) -> tuple:
        """Output buffers: rgba, depth, position, samples (zero rows: not requested)."""
        o = self.outputs
        return (buffer("rgba" in o, (height, width, 4), np.float32),
                buffer("depth" in o, (height, width)),
                buffer("position" in o, (height, width, 3)),
                buffer("stats" in o, (height, width), np.int32))

    def frame(self, out: tuple, counters: tuple, stats: dict) -> Frame:
        """The Frame (``depth``: where the opacity passes 1/2)."""
        rgba, depth, position, samples = out
        o = self.outputs
        h, w = counters[0].shape
        s = self.settings
        stats.update(step=s.step, preintegration=s.preintegration, adaptive=s.adaptive,
                     table_layout=s.table_layout, termination=s.termination,
                     sampling=s.sampling, table_ms=self.table_ms)
        if samples.shape[0]:
            stats["mean_samples"] = float(samples.mean())
        return Frame(*(a if a.shape[0] else None for a in (rgba, depth, position)),
                     np.full((h, w, 3), np.nan, np.float32) if "normal" in o else None,
                     np.zeros((h, w), np.int8) if "face" in o else None, *counters, stats)

    combine = staticmethod(combine_dvr)


def _zero_corners(alpha: np.ndarray) -> tuple[float, float]:
    """Where a bilinear lookup of the 2D table ``alpha`` (opacity, ``(n, n)``) at value indices
    ``(uf, ub)`` reads only entries of opacity 0: ``(below, above)`` such that it does when
    both indices are below ``below`` or both at least ``above`` (the corners of
    :func:`~splinecast.preintegration.table_cell` are ``int(u)`` and ``int(u) + 1``, with
    ``int(u)`` at most ``n - 2``). A transfer function that is transparent below or above some
    value (the automatic one, below its isovalue) has such corners: segments there need no
    lookup. ``(-inf, inf)`` where there are none."""
    n = alpha.shape[0]
    rows, cols = np.nonzero(alpha)
    if rows.size == 0:
        return math.inf, math.inf
    # Entries with both indices below the smallest max(i, j) of a non-zero entry are zero; a
    # lookup's corners are when int(u) + 1 is below it, which u < smallest - 1 gives.
    below = float(np.min(np.maximum(rows, cols))) - 1.0
    # Entries with both indices above the largest min(i, j) of a non-zero entry are zero;
    # a lookup's corners are when int(u) is above it, which u >= largest + 1 gives unless
    # int(u) is clamped to n - 2 below that.
    top = int(np.max(np.minimum(rows, cols))) + 1
    above = float(top) if top <= n - 2 else math.inf
    return below, above


def _table(tf: TransferFunction, settings: DVRSettings, cache: dict) -> np.ndarray:
    """The kernel's table: the pre-integration table's RGBA (float32, ``(K, n, n, 4)``), and
    for the pieces sampling a fifth channel ``-ln(1 - alpha)`` (cached with it).

    The fixed-step ("ray") sampling reads the same values widened to float64 (exactly: every
    float32 is a float64; the lookup computes in float64 either way): its loop reads sixteen
    entries per segment, and leaving out their conversions made it faster (twice the table's
    memory, 2 MiB at the default size, of which a segment reads near the diagonal)."""
    base = _preintegration(tf, settings, cache)
    if settings.sampling == "ray":
        key = ("float64", id(base))
        table = cache.get(key)
        if table is None:
            table = base.table.astype(np.float64)
            cache[key] = table
        return table
    if settings.sampling != "pieces":
        return base.table
    key = ("optical depth", id(base))
    table = cache.get(key)
    if table is None:
        alpha = np.minimum(base.table[..., 3].astype(np.float64), 1.0 - 1e-12)
        table = np.empty((*base.table.shape[:3], 5), np.float32)
        table[..., :4] = base.table
        table[..., 4] = -np.log1p(-alpha)
        cache[key] = table
    return table


def _preintegration(tf: TransferFunction, settings: DVRSettings,
                    cache: dict) -> PreintegrationTable:
    """The pre-integration table for ``tf`` and ``settings``, built once and cached."""
    key = (json.dumps(tf.to_dict()), settings.table_size, settings.step, settings.table_steps,
           settings.table_layout)
    table = cache.get(key)
    if table is None:
        cache.clear()  # one table at a time: they can be large
        table = preintegrate(tf, n=settings.table_size, h0=settings.step,
                             steps=settings.table_steps, layout=settings.table_layout)
        cache[key] = table
    return table
