"""Direct volume rendering: emission-absorption compositing front to back along each ray.

Each ray is sampled from its entry point; consecutive samples ``(t_a, v_a)`` and ``(t_b, v_b)``
bound a segment of length ``L`` (voxels) that is classified and composited with the "under"
operator, ``C += (1 - A) c``, ``A += (1 - A) a`` (premultiplied colours):

* plain classification: the sample's transfer-function value, ``a = 1 - exp(-tau(v_b) L)``,
  ``c = C(v_b) a``;
* pre-integrated (:mod:`splinecast.preintegration`): the segment's exact integral for a value going
  linearly from ``v_a`` to ``v_b``, looked up bilinearly in a table. A 2D table is for one length;
  other lengths (the last, partial step before an exit) use the opacity correction
  ``a' = 1 - (1 - a)^(L / h)`` with the colour scaled by ``a' / a``. A 3D table holds the lengths
  ``k h0`` (uniform layout) or ``2^j h0`` (exponential layout) exactly, which is what the
  opacity-adaptive step uses: its step is rounded to the nearest length in the table (for the
  exponential layout, nearest in ``log2``); other lengths use the opacity correction from the
  nearest table.

Opacity-adaptive step (reference 002, eq. 10): ``h = h_min + (h_max - h_min) A^n`` with ``A`` the
accumulated opacity, so the step grows where little of what follows can still be seen. Early ray
termination stops a ray once ``A`` reaches a threshold ``A_max``: what it leaves out is at most
``(1 - A_max)`` per channel.

Empty space: blocks whose value range meets no visible (non-zero opacity) range of the transfer
function are leapt over with the min/max hierarchy, and single cells are tested against the
transfer function's prefix-sum table. The sampling restarts at the exit of a skipped region; a
pending segment is closed at its entry with the value there.

Leaping between samples (``leap``): when the next sample lies more than a voxel ahead, the ray
walks the visible 4^3 blocks of the hierarchy's finest level instead of single cells and, once
the block holding the next sample is reached, restarts the cell walk at the sample (as
``walk_begin`` does at a ray's entry). Cells without a sample are then neither loaded nor tested
against the prefix table; the sample positions and values are those of the cell-by-cell walk
unless a cell leapt over is transparent on its own inside a visible block (the cell walk closes
the segment there and restarts the sampling at the cell's exit, the leap composites across it).

Optional gradient shading multiplies each segment's colour by ``ambient + diffuse |n . u|``
(headlight, ``n`` the normalized field gradient at the segment's back sample).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import prange

from .. import limits
from .._jit import jit
from ..accel.minmax import inactive_block_size
from ..accel.traversal import start_cell, walk_begin, walk_step
from ..errors import ParameterError
from ..models.trilinear import cell_monomials, local_gradient, local_value
from ..preintegration import preint_lookup
from .clipping import clip_interval
from .rays import pixel_ray

__all__ = ["DVRSettings", "PREINTEGRATION", "TABLE_LAYOUTS", "trace_dvr"]

#: Classification kinds accepted by :class:`DVRSettings`.
PREINTEGRATION = ("none", "2d", "3d")

#: Layouts of the 3D pre-integration table accepted by :class:`DVRSettings`.
TABLE_LAYOUTS = ("uniform", "exponential")


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
        Largest step (voxels) and exponent of the adaptive step (reference 002: 8 and 3, with
        ``h_min = 1``).
    termination : float or None
        Stop a ray when its accumulated opacity reaches this value (``None``: never).
    shade : bool
        Gradient (headlight) shading of the samples.
    ambient, diffuse : float
        Weights of the gradient shading.
    table_size : int
        Values per axis of the pre-integration table.
    leap : bool
        Leap over cells that hold no sample (see the module notes); ``False`` walks and tests
        every cell of the visible blocks.
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

    def __post_init__(self) -> None:
        # Bounds on work and memory (splinecast.limits): the smallest step, finite weights, and
        # a table that fits in memory. The step against a volume's size is checked at render.
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
        if self.termination is not None and not 0 < self.termination <= 1:
            raise ParameterError(f"termination must be in (0, 1], got {self.termination}")
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


@jit(inline="always")
def _cell_value_grad(data, ci, cj, ck, x, y, z):
    """Value and index-space gradient at local coordinates of cell ``(ci, cj, ck)``."""
    _, _, k0, k1, k2, k3, k4, k5, k6, k7 = cell_monomials(data, ci, cj, ck)
    v = local_value(k0, k1, k2, k3, k4, k5, k6, k7, x, y, z)
    gx, gy, gz = local_gradient(k1, k2, k3, k4, k5, k6, k7, x, y, z)
    return v, gx, gy, gz


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
def _classify(pi_mode, table, h0, t_lo, t_scale, lut_rgb, lut_tau, l_lo, l_scale,
              va, vb, length):
    """Premultiplied RGBA of a segment of ``length`` voxels from value ``va`` to ``vb``."""
    if pi_mode == 0:
        n = lut_tau.shape[0]
        u = min(max((vb - l_lo) * l_scale, 0.0), n - 1.0)
        i = min(int(u), n - 2)
        f = u - i
        tau = (1.0 - f) * lut_tau[i] + f * lut_tau[i + 1]
        a = -math.expm1(-tau * length)
        r = ((1.0 - f) * lut_rgb[i, 0] + f * lut_rgb[i + 1, 0]) * a
        g = ((1.0 - f) * lut_rgb[i, 1] + f * lut_rgb[i + 1, 1]) * a
        b = ((1.0 - f) * lut_rgb[i, 2] + f * lut_rgb[i + 1, 2]) * a
        return r, g, b, a
    n = table.shape[1]
    steps = table.shape[0]
    uf = min(max((va - t_lo) * t_scale, 0.0), n - 1.0)
    ub = min(max((vb - t_lo) * t_scale, 0.0), n - 1.0)
    if pi_mode == 3:
        # Exponential layout: the table nearest in log2 of the length.
        j = 0
        if length > h0:
            j = min(int(math.log2(length / h0) + 0.5), steps - 1)
        k = j + 1
        held = h0 * 2.0**j
    else:
        k = min(max(int(length / h0 + 0.5), 1), steps)
        held = k * h0
    r, g, b, a = preint_lookup(table, k - 1, uf, ub)
    ratio = length / held
    if abs(ratio - 1.0) > 1e-9 and a > 0.0:
        # A length the table does not hold: correct the opacity for it (colour follows).
        a2 = -math.expm1(ratio * math.log1p(-min(a, 1.0 - 1e-12)))
        scale = a2 / a
        return r * scale, g * scale, b * scale, a2
    return r, g, b, a


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
def _clamp_into_block(c, c_old, n):
    """``c`` clamped into the aligned 4-cell block holding ``c_old`` and into ``[0, n-1]``."""
    start = (c_old >> 2) << 2
    end = min(start + 3, n - 1)
    return min(max(c, start), end)


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


@jit()
def _dvr_ray(data, act0, act1, act2, prefix, p_lo, p_scale, pi_mode, table, h0, t_lo, t_scale,
             lut_rgb, lut_tau, l_lo, l_scale, adaptive, h_max, exponent, term,
             shade, ambient, diffuse, sx, sy, sz, ux, uy, uz,
             ox, oy, oz, dx, dy, dz, t_min, t_max, leap):
    """One ray. Returns ``(r, g, b, A, t_half, samples, visited, skipped)``."""
    nx, ny, nz = data.shape[0] - 1, data.shape[1] - 1, data.shape[2] - 1
    nbins = prefix.shape[0] - 1
    dnorm = math.sqrt(dx * dx + dy * dy + dz * dz)  # voxels per world unit along the ray
    acc_r = 0.0
    acc_g = 0.0
    acc_b = 0.0
    acc_a = 0.0
    t_half = math.inf
    samples = 0
    visited = 0
    skipped = 0
    have_prev = False
    t_prev = 0.0
    v_prev = 0.0
    inside, ci, cj, ck, t, t_far = walk_begin(ox, oy, oz, dx, dy, dz, nx, ny, nz, t_min, t_max)
    t_s = t
    last_i, last_j, last_k = ci, cj, ck
    done = False
    fresh = True  # the walk (re)started in this cell: process it, never leap from it
    steps = table.shape[0]
    while inside and not done:
        size = inactive_block_size(act0, act1, act2, ci, cj, ck)
        if leap and size == 0 and not fresh and (t_s - t) * dnorm > 1.0:
            # The next sample is over a voxel ahead: walk the visible 4^3 block instead.
            b_end, b_more, bi, bj, bk, b_next = walk_step(
                ox, oy, oz, dx, dy, dz, nx, ny, nz, ci, cj, ck, t, t_far, 4
            )
            skipped += 1
            if t_s > b_end:
                if b_more:
                    ci, cj, ck, t = bi, bj, bk, b_next
                else:
                    inside = False
                    last_i, last_j, last_k = start_cell(ox, oy, oz, dx, dy, dz, t_far,
                                                        nx, ny, nz)
                continue
            # Restart the cell walk at the next sample, which lies in this block.
            si, sj, sk = start_cell(ox, oy, oz, dx, dy, dz, t_s, nx, ny, nz)
            ci = _clamp_into_block(si, ci, nx)
            cj = _clamp_into_block(sj, cj, ny)
            ck = _clamp_into_block(sk, ck, nz)
            t = t_s
            fresh = True
            continue
        fresh = False
        t_end, inside, ni, nj, nk, t_next = walk_step(
            ox, oy, oz, dx, dy, dz, nx, ny, nz, ci, cj, ck, t, t_far, max(size, 1)
        )
        transparent = size > 0
        if size > 0:
            skipped += 1
        else:
            visited += 1
            vmin, vmax, k0, k1, k2, k3, k4, k5, k6, k7 = cell_monomials(data, ci, cj, ck)
            b0 = min(max(int((vmin - p_lo) * p_scale), 0), nbins - 1)
            b1 = min(max(int((vmax - p_lo) * p_scale), 0), nbins - 1)
            transparent = prefix[b1 + 1] == prefix[b0]
        if transparent:
            if have_prev and t > t_prev:
                # Close the pending segment at the region's entry, then restart after it.
                v, gx, gy, gz = _cell_value_grad(data, ci, cj, ck, ox + t * dx - ci,
                                                 oy + t * dy - cj, oz + t * dz - ck)
                r, g, b, a = _classify(pi_mode, table, h0, t_lo, t_scale, lut_rgb, lut_tau,
                                       l_lo, l_scale, v_prev, v, (t - t_prev) * dnorm)
                acc_r, acc_g, acc_b, acc_a, t_half = _composite(
                    acc_r, acc_g, acc_b, acc_a, t_half, r, g, b, a,
                    _shade_factor(shade, ambient, diffuse, gx, gy, gz, sx, sy, sz, ux, uy, uz), t,
                )
            have_prev = False
            t_s = t_next
        elif t_end >= t:
            last_i, last_j, last_k = ci, cj, ck
            while t_s <= t_end:
                x = ox + t_s * dx - ci
                y = oy + t_s * dy - cj
                z = oz + t_s * dz - ck
                v = local_value(k0, k1, k2, k3, k4, k5, k6, k7, x, y, z)
                samples += 1
                if have_prev:
                    r, g, b, a = _classify(pi_mode, table, h0, t_lo, t_scale, lut_rgb, lut_tau,
                                           l_lo, l_scale, v_prev, v, (t_s - t_prev) * dnorm)
                    if a > 0.0:
                        gx, gy, gz = local_gradient(k1, k2, k3, k4, k5, k6, k7, x, y, z)
                        acc_r, acc_g, acc_b, acc_a, t_half = _composite(
                            acc_r, acc_g, acc_b, acc_a, t_half, r, g, b, a,
                            _shade_factor(shade, ambient, diffuse, gx, gy, gz,
                                          sx, sy, sz, ux, uy, uz), t_s,
                        )
                        if acc_a >= term:
                            done = True
                            break
                have_prev = True
                t_prev = t_s
                v_prev = v
                h = h0
                if adaptive:
                    h = _adaptive_step(pi_mode, steps, h0, h_max, exponent, acc_a)
                t_s += h / dnorm
        ci, cj, ck, t = ni, nj, nk, t_next
    if not done and have_prev and t_prev < t_far:
        # The last, partial step ends at the exit point.
        v, gx, gy, gz = _cell_value_grad(data, last_i, last_j, last_k, ox + t_far * dx - last_i,
                                         oy + t_far * dy - last_j, oz + t_far * dz - last_k)
        r, g, b, a = _classify(pi_mode, table, h0, t_lo, t_scale, lut_rgb, lut_tau,
                               l_lo, l_scale, v_prev, v, (t_far - t_prev) * dnorm)
        acc_r, acc_g, acc_b, acc_a, t_half = _composite(
            acc_r, acc_g, acc_b, acc_a, t_half, r, g, b, a,
            _shade_factor(shade, ambient, diffuse, gx, gy, gz, sx, sy, sz, ux, uy, uz), t_far,
        )
    return acc_r, acc_g, acc_b, acc_a, t_half, samples, visited, skipped


@jit(parallel=True)
def trace_dvr(
    data: np.ndarray,
    act0: np.ndarray,
    act1: np.ndarray,
    act2: np.ndarray,
    prefix: np.ndarray,
    prefix_range: np.ndarray,
    pi_mode: int,
    table: np.ndarray,
    table_range: np.ndarray,
    h0: float,
    lut_rgb: np.ndarray,
    lut_tau: np.ndarray,
    adaptive: bool,
    h_max: float,
    exponent: float,
    term: float,
    shade: bool,
    ambient: float,
    diffuse: float,
    leap: bool,
    background: np.ndarray,
    basis: np.ndarray,
    vol_origin: np.ndarray,
    spacing: np.ndarray,
    planes: np.ndarray,
    row_order: np.ndarray,
    rgba: np.ndarray,
    depth: np.ndarray,
    position: np.ndarray,
    samples: np.ndarray,
    cells_visited: np.ndarray,
    blocks_skipped: np.ndarray,
) -> None:
    """Composite every pixel front to back over ``background``.

    ``act0..act2``: block flags, non-zero where the transfer function is visible. ``prefix``:
    the transparency prefix table over ``prefix_range = (lo, hi)``. ``pi_mode``: 0 plain, 1 2D
    table, 2 3D table (``table`` over ``table_range``, lengths ``k * h0``), 3 exponential 3D
    table (lengths ``2**j * h0``). ``leap``: leap over cells holding no sample. ``lut_rgb``,
    ``lut_tau``: the transfer function sampled evenly over ``table_range`` for plain
    classification. ``h0`` is the (minimum) step in voxels; ``term`` the early-termination
    opacity (> 1 disables it). ``depth`` and ``position`` get the distance and point where the
    opacity first reaches 0.5 (``inf`` and NaN if it never does).
    """
    height, width = depth.shape
    sx, sy, sz = spacing[0], spacing[1], spacing[2]
    orx, ory, orz = vol_origin[0], vol_origin[1], vol_origin[2]
    p_lo = prefix_range[0]
    p_scale = (prefix.shape[0] - 1) / (prefix_range[1] - prefix_range[0])
    t_lo = table_range[0]
    t_scale = (table.shape[1] - 1) / (table_range[1] - table_range[0])
    l_scale = (lut_tau.shape[0] - 1) / (table_range[1] - table_range[0])
    for r in prange(height):
        row = row_order[r]
        for col in range(width):
            wx, wy, wz, ux, uy, uz = pixel_ray(basis, row, col, width, height)
            dx, dy, dz = ux / sx, uy / sy, uz / sz
            ox, oy, oz = (wx - orx) / sx, (wy - ory) / sy, (wz - orz) / sz
            t_min, t_max = clip_interval(planes, wx, wy, wz, ux, uy, uz)
            cr, cg, cb, ca, t_half, ns, nvis, nskip = _dvr_ray(
                data, act0, act1, act2, prefix, p_lo, p_scale, pi_mode, table, h0, t_lo,
                t_scale, lut_rgb, lut_tau, t_lo, l_scale, adaptive, h_max, exponent, term,
                shade, ambient, diffuse, sx, sy, sz, ux, uy, uz,
                ox, oy, oz, dx, dy, dz, t_min, t_max, leap,
            )
            rest = 1.0 - ca
            rgba[row, col, 0] = min(cr + rest * background[0] * background[3], 1.0)
            rgba[row, col, 1] = min(cg + rest * background[1] * background[3], 1.0)
            rgba[row, col, 2] = min(cb + rest * background[2] * background[3], 1.0)
            rgba[row, col, 3] = ca + rest * background[3]
            depth[row, col] = t_half
            position[row, col, 0] = wx + t_half * ux if t_half < math.inf else math.nan
            position[row, col, 1] = wy + t_half * uy if t_half < math.inf else math.nan
            position[row, col, 2] = wz + t_half * uz if t_half < math.inf else math.nan
            samples[row, col] = ns
            cells_visited[row, col] = nvis
            blocks_skipped[row, col] = nskip
