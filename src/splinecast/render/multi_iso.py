"""Several translucent isosurfaces at once, composited front to back, for every model.

Along each ray every crossing of every isovalue is found exactly and in depth order: per piece,
the roots of its polynomial minus each isovalue inside the piece's range
(:func:`splinecast.roots.pieces.poly_roots`), sorted by ray parameter and composited with the
"under" operator, each surface with its own colour and opacity, so a translucent skin shows the
bone beneath (Koch 2009, "Blending kubischer C1-Splines"). A ray stops once its opacity
reaches ``1 - 1e-4``.

Front and back faces of a surface get the same colour (a translucent shell is seen from both
sides); lighting and effects are those of :func:`splinecast.render.effects.surface_rgb`, with
the normals of the model's shading field (``normals``, :mod:`.shading`) as for a single
isosurface. The first crossing gives the pixel's depth, position, normal and face.

Partial results of two segments of a ray combine with "over": the front colour plus the back
colour times the front's remaining transparency.
"""

from __future__ import annotations

import math
from collections import namedtuple
from collections.abc import Hashable
from typing import Any

import numpy as np
from numba import prange

from .._jit import jit
from ..errors import ParameterError
from ..models.pieces import gradient
from ..roots.pieces import poly_roots
from ..transfer import colormap_table
from .effects import NO_EFFECTS, SurfaceEffects, surface_rgb
from .frame import Frame
from .mode_api import flagged_block_size, register, unchanged_begin, unchanged_end, unchanged_skip
from .mode_host import ModeHost
from .outputs import ALL_OUTPUTS, buffer
from .shading import Shading, normals_code, smooth_gradient

__all__ = ["MultiIsoMode", "MultiIso", "combine_multi_iso"]

#: A ray stops compositing at this opacity.
OPAQUE = 1.0 - 1e-4

#: Kernel parameters: isovalues, one RGB and one opacity each, which side is inside, packed
#: shading and effects, normals code (:data:`.shading.NORMALS`).
MultiIsoMode = namedtuple("MultiIsoMode", ["isos", "colors", "opacity", "inside_high", "shading",
                                           "effects", "normals"])


@jit()
def _state_new(mode):
    # acc r, g, b, a; first crossing t, normal, face; layers; last crossing t and surface.
    return (0.0, 0.0, 0.0, 0.0, math.inf, math.nan, math.nan, math.nan, 0, 0, -math.inf, -1)


@jit()
def _state_load(mode, state, row, col):
    acc, first, normal, face, layers, last = state
    return (acc[row, col, 0], acc[row, col, 1], acc[row, col, 2], acc[row, col, 3],
            first[row, col], normal[row, col, 0], normal[row, col, 1], normal[row, col, 2],
            np.int64(face[row, col]), np.int64(layers[row, col]), last[row, col, 0],
            np.int64(last[row, col, 1]))


@jit()
def _state_store(mode, state, row, col, st):
    acc, first, normal, face, layers, last = state
    acc[row, col, 0] = st[0]
    acc[row, col, 1] = st[1]
    acc[row, col, 2] = st[2]
    acc[row, col, 3] = st[3]
    first[row, col] = st[4]
    normal[row, col, 0] = st[5]
    normal[row, col, 1] = st[6]
    normal[row, col, 2] = st[7]
    face[row, col] = st[8]
    layers[row, col] = st[9]
    last[row, col, 0] = st[10]
    last[row, col, 1] = st[11]


@jit()
def _mode_scratch(mode):
    # Degree <= 9 pieces: at most 9 crossings per isovalue and piece.
    m = mode.isos.shape[0]
    return np.empty(9 * m + 1), np.empty(9 * m + 1, np.int64)


@jit()
def _wants(mode, st, lo, hi):
    for q in range(mode.isos.shape[0]):
        if lo <= mode.isos[q] <= hi:
            return True
    return False


@jit()
def _done(mode, st):
    return st[3] >= OPAQUE


@jit()
def _consume(mode, mscratch, grid, scratch, piece, ray, st):
    ctx, i, j, k, tag, poly = piece.ctx, piece.i, piece.j, piece.k, piece.tag, piece.poly
    lo, hi, t0, t1 = piece.lo, piece.hi, piece.t0, piece.t1
    ax, ay, az, bx, by, bz = piece.ax, piece.ay, piece.az, piece.bx, piece.by, piece.bz
    hit_s, hit_q = mscratch
    count = 0
    for q in range(mode.isos.shape[0]):
        if lo <= mode.isos[q] <= hi:
            found = poly_roots(poly, mode.isos[q], hit_s, count)
            for h in range(count, count + found):
                hit_q[h] = q
            count += found
    # Insertion sort of the (few) crossings of this piece by depth.
    for h in range(1, count):
        s_h, q_h = hit_s[h], hit_q[h]
        g = h - 1
        while g >= 0 and hit_s[g] > s_h:
            hit_s[g + 1] = hit_s[g]
            hit_q[g + 1] = hit_q[g]
            g -= 1
        hit_s[g + 1] = s_h
        hit_q[g + 1] = q_h
    acc_r, acc_g, acc_b, acc_a, t_first, fnx, fny, fnz, face, layers, last_t, last_q = st
    wx, wy, wz = ray.world_x, ray.world_y, ray.world_z
    ux, uy, uz = ray.world_dx, ray.world_dy, ray.world_dz
    for h in range(count):
        q = hit_q[h]
        s = hit_s[h]
        th = t0 + s * (t1 - t0)
        if q == last_q and th <= last_t + 1e-12 * (1.0 + abs(th)):
            continue  # the same crossing seen again on a shared face of two pieces
        last_t, last_q = th, q
        px, py, pz = ax + s * (bx - ax), ay + s * (by - ay), az + s * (bz - az)
        gx, gy, gz = gradient(grid, scratch, ctx, i, j, k, tag, px, py, pz)
        # Which side the ray enters: the model's own derivative along the ray.
        slope = gx * ray.index_dx + gy * ray.index_dy + gz * ray.index_dz
        gx, gy, gz = smooth_gradient(mode.normals, grid, scratch, ray, i + px, j + py, k + pz,
                                     gx / ray.spacing_x, gy / ray.spacing_y, gz / ray.spacing_z)
        norm = math.sqrt(gx * gx + gy * gy + gz * gz)
        if norm > 0.0:
            scale = (-1.0 if mode.inside_high else 1.0) / norm
            nxw, nyw, nzw = gx * scale, gy * scale, gz * scale
        else:
            nxw, nyw, nzw = -ux, -uy, -uz
        cr, cg, cb = surface_rgb(mode.shading, mode.effects,
                                 (mode.colors[q, 0], mode.colors[q, 1], mode.colors[q, 2]),
                                 (nxw, nyw, nzw), (ux, uy, uz),
                                 (wx + th * ux, wy + th * uy, wz + th * uz))
        w = (1.0 - acc_a) * mode.opacity[q]
        acc_r += w * cr
        acc_g += w * cg
        acc_b += w * cb
        acc_a += w
        layers += 1
        if t_first == math.inf:
            t_first, fnx, fny, fnz = th, nxw, nyw, nzw
            front = slope >= 0.0 if mode.inside_high else slope <= 0.0
            face = 1 if front else -1
        if acc_a >= OPAQUE:
            break
    return (acc_r, acc_g, acc_b, acc_a, t_first, fnx, fny, fnz, face, layers, last_t, last_q)


@jit()
def _finish(mode, out, row, col, st, ray):
    rgba, depth, position, normal, face, layers = out
    # Buffers with no rows were not asked for (see .outputs).
    if rgba.shape[0] != 0:
        sh = mode.shading
        rest = 1.0 - st[3]
        bg_a = sh[9]
        rgba[row, col, 0] = min(st[0] + rest * sh[6] * bg_a, 1.0)
        rgba[row, col, 1] = min(st[1] + rest * sh[7] * bg_a, 1.0)
        rgba[row, col, 2] = min(st[2] + rest * sh[8] * bg_a, 1.0)
        rgba[row, col, 3] = st[3] + rest * bg_a
    t = st[4]
    if depth.shape[0] != 0:
        depth[row, col] = t
    if face.shape[0] != 0:
        face[row, col] = st[8]
    if layers.shape[0] != 0:
        layers[row, col] = st[9]
    if position.shape[0] != 0:
        hit = t < math.inf
        position[row, col, 0] = ray.world_x + t * ray.world_dx if hit else math.nan
        position[row, col, 1] = ray.world_y + t * ray.world_dy if hit else math.nan
        position[row, col, 2] = ray.world_z + t * ray.world_dz if hit else math.nan
    if normal.shape[0] != 0:
        normal[row, col, 0] = st[5]
        normal[row, col, 1] = st[6]
        normal[row, col, 2] = st[7]


register(MultiIsoMode,
         state_new=_state_new,
         state_load=_state_load,
         state_store=_state_store,
         mode_scratch=_mode_scratch,
         ray_begin=unchanged_begin,
         skip_size=flagged_block_size,
         wants=_wants,
         on_skip=unchanged_skip,
         consume=_consume,
         done=_done,
         ray_end=unchanged_end,
         finish=_finish)


@jit(parallel=True)
def combine_multi_iso(front: tuple, back: tuple, out: tuple) -> None:
    """``out`` = ``front`` over ``back``: composited colour, the front's first crossing if any.

    A front that reached :data:`OPAQUE` hides the back entirely, as the single-pass ray stops
    there. A back segment that crosses that opacity only after the front's remaining
    transparency is applied cannot stop where the single pass would (it did not know the front's
    opacity), so such a pixel may differ from the single-pass one by less than ``1 - OPAQUE``.
    """
    fa, ff, fn, fface, fl, flast = front
    ba, bf, bn, bface, bl, blast = back
    oa, of, on, oface, ol, olast = out
    height, width = ff.shape
    for row in prange(height):
        for col in range(width):
            if fa[row, col, 3] >= OPAQUE:
                for c in range(4):
                    oa[row, col, c] = fa[row, col, c]
                of[row, col] = ff[row, col]
                oface[row, col] = fface[row, col]
                for c in range(3):
                    on[row, col, c] = fn[row, col, c]
                ol[row, col] = fl[row, col]
                olast[row, col, 0] = flast[row, col, 0]
                olast[row, col, 1] = flast[row, col, 1]
                continue
            rest = 1.0 - fa[row, col, 3]
            for c in range(4):
                oa[row, col, c] = fa[row, col, c] + rest * ba[row, col, c]
            use_front = ff[row, col] < math.inf
            of[row, col] = ff[row, col] if use_front else bf[row, col]
            oface[row, col] = fface[row, col] if use_front else bface[row, col]
            for c in range(3):
                on[row, col, c] = fn[row, col, c] if use_front else bn[row, col, c]
            ol[row, col] = fl[row, col] + bl[row, col]
            olast[row, col, 0] = blast[row, col, 0]
            olast[row, col, 1] = blast[row, col, 1]


def _per_surface(values: Any, count: int, width: int, name: str) -> np.ndarray:
    arr = np.asarray(values, dtype=np.float64)
    if width > 1 and arr.ndim == 1 and arr.size == width:
        arr = arr.reshape(1, width)  # one colour for all surfaces
    try:
        arr = np.broadcast_to(arr.reshape(-1, width) if width > 1 else arr.reshape(-1),
                              (count, width) if width > 1 else (count,))
    except ValueError:
        raise ParameterError(f"{name} must give one value per isovalue ({count})") from None
    if not np.all((arr >= 0) & (arr <= 1)):
        raise ParameterError(f"{name} must be in [0, 1]")
    return np.ascontiguousarray(arr, dtype=np.float64)


class MultiIso(ModeHost):
    """Host side of several translucent isosurfaces.

    Parameters
    ----------
    isos : list of float
        Isovalues (already checked against the data range).
    colors : optional
        One RGB per isovalue (default: evenly spaced on the ``bone`` colormap, in increasing
        isovalue order).
    opacity : optional
        One opacity per isovalue (default 0.5, and 1 for the last).
    inside : {"high", "low"}
    shading : Shading, optional
    effects : SurfaceEffects, optional
    outputs : set of str, optional
        The Frame's buffers to fill (:mod:`.outputs`; default all; ``"stats"`` includes the
        per-ray layer counts).
    normals : {"smooth", "exact"}
        Shade with the model's shading field or its own gradient (:mod:`.shading`).
    """

    name = "iso"

    def blocks_key(self) -> Hashable:
        """The isovalues."""
        return ("isos", tuple(float(v) for v in self.isos))

    def surface_values(self) -> list[float]:
        """The isovalues."""
        return list(self.isos)

    def __init__(self, isos: list[float], colors: Any = None, opacity: Any = None,
                 inside: str = "high", shading: Shading | None = None,
                 effects: SurfaceEffects | None = None,
                 outputs: frozenset[str] = ALL_OUTPUTS, normals: str = "smooth") -> None:
        self.outputs = outputs
        self.normals = normals
        count = len(isos)
        if colors is None:
            order = np.argsort(np.argsort(isos))
            palette = colormap_table("bone", 256)
            colors = palette[(64 + order * 191 // max(count - 1, 1)).clip(0, 255)]
        if opacity is None:
            opacity = [0.5] * (count - 1) + [1.0]
        self.isos = [float(v) for v in isos]
        self.shading = shading or Shading()
        self.params = MultiIsoMode(
            np.asarray(self.isos, np.float64), _per_surface(colors, count, 3, "colors"),
            _per_surface(opacity, count, 1, "opacity"), inside == "high",
            self.shading.as_array(), effects.as_array() if effects else NO_EFFECTS,
            normals_code(normals))

    def blocks(self, hierarchy: Any, flags: tuple | None = None) -> tuple:
        """Flags of the blocks that can hold any of the isovalues."""
        return (*hierarchy.flags_for([(v, v) for v in self.isos]), np.zeros(0))

    @staticmethod
    def footprint_flags(blocks: tuple) -> tuple:
        """The block flags whose screen footprint bounds where rays can meet a surface
        (:mod:`.footprint`)."""
        return blocks[:3]

    @staticmethod
    def state(height: int, width: int) -> tuple:
        """Per-pixel state arrays."""
        return (np.empty((height, width, 4)), np.empty((height, width)),
                np.empty((height, width, 3)), np.empty((height, width), np.int8),
                np.empty((height, width), np.int32), np.empty((height, width, 2)))

    def output(self, height: int, width: int) -> tuple:
        """Output buffers: rgba, depth, position, normal, face, layers (zero rows: not
        requested)."""
        o = self.outputs
        return (buffer("rgba" in o, (height, width, 4), np.float32),
                buffer("depth" in o, (height, width)),
                buffer("position" in o, (height, width, 3)),
                buffer("normal" in o, (height, width, 3), np.float32),
                buffer("face" in o, (height, width), np.int8),
                buffer("stats" in o, (height, width), np.int32))

    def frame(self, out: tuple, counters: tuple, stats: dict) -> Frame:
        """The Frame; ``stats["mean_layers"]`` counts the crossings composited per pixel."""
        layers = out[5]
        stats.update(iso=list(self.isos))
        if layers.shape[0]:
            stats["mean_layers"] = float(layers.mean())
        return Frame(*(a if a.shape[0] else None for a in out[:5]), *counters, stats)

    combine = staticmethod(combine_multi_iso)
