"""Ray pieces of the type-6 splines (models ``s31`` and ``qss``): cubes cut into tetrahedra.

What is particular to these models (the interface is :mod:`splinecast.models.pieces`):

* **Dual grid.** Cube ``(i, j, k)`` is centred on voxel ``(i, j, k)``. The traversal space is
  voxel index + 1/2, where cube ``i`` spans ``[i, i + 1]``, so the shared integer traversal walks
  cubes unchanged; local cube coordinates relative to the cube centre are local cell coordinates
  minus 1/2.
* **Tetrahedra in order.** Inside a cube the ray segment is cut where it crosses the six planes
  ``x = +-y``, ``x = +-z``, ``y = +-z`` through the cube centre that bound the 24 tetrahedra; each
  piece lies in one tetrahedron (found from its midpoint), and pieces come front to back.
* **Ray restriction.** On a piece, the patch is a univariate Bernstein polynomial of the patch's
  degree, obtained by blossoming at the piece's end points (:func:`.type6.ray_bernstein3`).
* **Coefficients on demand.** A cube's coefficients are computed from its 27 data values by the
  model's verified averaging chain, written out as straight-line code (:func:`fill_cube`),
  into a small per-thread cache the first time a ray needs them,
  so the neighbouring pixels of a tile that cross the same cube reuse them; with
  ``precompute=True`` and an isovalue classification they are read from the stored rows.
* **Ranges.** Without a classification a cube's range is its exact coefficient range (computed
  once per volume) and a tetrahedron's the range of its own coefficients; with the isovalue
  classification of :mod:`splinecast.accel.active_cells` (iso mode) a cube's slot and 24-bit
  tetrahedron mask replace both (inactive cubes and tetrahedra are empty, active ones unbounded:
  the classification already tested them against the isovalue).
* **Polynomials on demand.** ``cell_pieces`` only cuts the segment, finds each piece's
  tetrahedron and its range (from the mask, or the tetrahedron's coefficients without a
  classification); ``piece_poly`` builds one piece's Bernstein coefficients when a mode asks for
  it. A first-hit ray therefore builds no piece behind its hit (the old hand-written kernels'
  order of work), and nothing of a piece whose range a mode refuses. Everything but the cube's
  coefficient computation on a cache miss (:func:`fill_cube`'s code, a call taking only the
  arrays it needs) is inlined into the driver's loop, which keeps no reference counts
  (:mod:`splinecast.render.driver`); a hook called out of line would still increment and
  decrement the count of every array of the grid and the scratch tuple (about 19 here).
* **In place.** Ranges, ray polynomials and values read a tetrahedron's 20 (10) coefficients
  from the cube's row through the tables' ``tet_points``, without copying them first; the
  fixed-step loop's ``value_at`` evaluates the value alone (:func:`.type6.bernstein3_value_at`,
  the same number as the value of ``value_gradient_at``).
* **Normals** come from the de Casteljau directional derivatives of the piece's patch.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba.core import cgutils, types
from numba.extending import intrinsic

from .._jit import jit, overload_jit
from ..roots.pieces import Bernstein2, Bernstein3
from .pieces import register
from .type6 import (
    SCHEMES,
    QSSGrid,
    S31Grid,
    barycentric,
    bernstein2_value_at,
    bernstein3_value_at,
    ray_bernstein2_at,
    ray_bernstein3_at,
    value_gradient,
)
from .type6_geometry import Type6Program, tet_of_point

__all__ = ["split_cube_segment", "CACHE_ENTRIES", "fill_cube"]

#: Cubes a thread keeps computed (512 x 175 float64 = 717 KB for S31: fits L2). Mapped by
#: 8 x 8 x 8 cubes: the neighbouring rays of a tile meet a cube again after about one ray of
#: 60-100 cubes, which 4 x 4 x 8 cubes mapped onto the same entries along a ray (hits: 35% of
#: the fixed-step samples of a Marschner-Lobb frame; 51% now).
CACHE_ENTRIES = 512


@jit(inline="always")
def _plane_cut(a_u: float, a_v: float, e_u: float, e_v: float, sign: float) -> float:
    """The segment parameter where ``u = sign * v`` is crossed if inside (0, 1), else 2.

    A segment parallel to the plane divides by zero: inf or NaN, neither inside (0, 1).
    """
    s = -(a_u - sign * a_v) / (e_u - sign * e_v)
    return s if (s > 0.0) & (s < 1.0) else 2.0


@jit(inline="always")
def _order(a: float, b: float) -> tuple[float, float]:
    return min(a, b), max(a, b)


@jit(inline="always")
def split_cube_segment(ax: float, ay: float, az: float, ex: float, ey: float, ez: float,
                       cuts: np.ndarray) -> int:
    """Sorted break points of the segment ``a + s e`` (``s`` in [0, 1]) at tetrahedron faces.

    Fills ``cuts[0..n]`` with ``0, s_1, ..., 1`` (increasing) and returns ``n``, the number of
    pieces (``cuts`` holds at least 8 values). ``a`` and ``e`` are in local cube coordinates
    (relative to the cube centre).

    Without a branch on the data: a plane not crossed inside the segment gives 2, and a sorting
    network of min/max pairs puts those last. Branches on where a ray crosses the planes (and
    an insertion sort's) were mispredicted so often that cutting a cube cost about 270 cycles,
    more than building a piece's polynomial; now about 50.
    """
    s0 = _plane_cut(ax, ay, ex, ey, 1.0)
    s1 = _plane_cut(ax, ay, ex, ey, -1.0)
    s2 = _plane_cut(ax, az, ex, ez, 1.0)
    s3 = _plane_cut(ax, az, ex, ez, -1.0)
    s4 = _plane_cut(ay, az, ey, ez, 1.0)
    s5 = _plane_cut(ay, az, ey, ez, -1.0)
    n = 1 + ((s0 < 2.0) + (s1 < 2.0) + (s2 < 2.0) + (s3 < 2.0) + (s4 < 2.0)
             + (s5 < 2.0))
    # The optimal 12-comparator sorting network of six values, layer by layer.
    s0, s5 = _order(s0, s5)
    s1, s3 = _order(s1, s3)
    s2, s4 = _order(s2, s4)
    s1, s2 = _order(s1, s2)
    s3, s4 = _order(s3, s4)
    s0, s3 = _order(s0, s3)
    s2, s5 = _order(s2, s5)
    s0, s1 = _order(s0, s1)
    s2, s3 = _order(s2, s3)
    s4, s5 = _order(s4, s5)
    s1, s2 = _order(s1, s2)
    s3, s4 = _order(s3, s4)
    cuts[0] = 0.0
    cuts[1] = s0
    cuts[2] = s1
    cuts[3] = s2
    cuts[4] = s3
    cuts[5] = s4
    cuts[6] = s5
    cuts[n] = 1.0
    return n


@jit()
def _cell_count(grid):
    p = grid.pad
    return p.shape[0] - 2, p.shape[1] - 2, p.shape[2] - 2


@jit()
def _new_scratch(grid):
    keys = np.full(CACHE_ENTRIES, -1, np.int64)
    cache = np.empty((CACHE_ENTRIES, grid.coeffs.shape[1]))
    return (keys, cache, np.empty(grid.tet_points.shape[1]), np.empty(10), np.empty(4),
            np.empty((8, 2)))


@jit()
def _cell_load(grid, scratch, i, j, k):
    """``(lo, hi, slot, tetrahedron mask)`` of cube ``(i, j, k)``."""
    i, j, k = np.uint64(i), np.uint64(j), np.uint64(k)  # see trilinear.cell_monomials
    if grid.slot.shape[0] > 0:
        s = np.int64(grid.slot[i, j, k])
        if s < 0:
            return math.inf, -math.inf, s, np.int64(0)
        return -math.inf, math.inf, s, np.int64(grid.tet_mask[s])
    return (np.float64(grid.cube_lo[i, j, k]), np.float64(grid.cube_hi[i, j, k]), np.int64(-1),
            np.int64(0xFFFFFF))


def _program_intrinsic(program: Type6Program) -> Any:
    """``fill(pad, i, j, k, row)``: ``program`` for cube ``(i, j, k)`` of ``pad`` as
    straight-line machine code, coefficient ``p`` into ``row[p]`` (compiled code only).

    The function reads the 27 data values around the cube (``pad[i .. i + 2, j .. j + 2,
    k .. k + 2]``), evaluates the program's rows in order with the weights as constants and
    writes the coefficients. Each row's sum is formed in the order of its terms, as
    :func:`~.type6.run_program` forms it (plain IEEE multiplies and adds, nothing reordered),
    so the coefficients are the same numbers. The loop over the rows of
    :class:`~.type6_geometry.Type6Program` cost about 2000 cycles per cube (its rows' varying
    lengths defeat branch prediction and every sum is one dependency chain); written out,
    about 270. Emitted as LLVM instructions directly: the same code written as Python took
    numba 1.7 s of typing and lowering to compile.
    """
    targets, ptr, sources, weights = program.arrays
    rows = [(int(targets[r]), [(float(weights[q]), int(sources[q]))
                                for q in range(ptr[r], ptr[r + 1])])
            for r in range(targets.shape[0])]
    n_points = program.n_points

    @intrinsic
    def fill(typingctx, pad, i, j, k, row):
        sig = types.void(pad, i, j, k, row)

        def codegen(context, builder, signature, args):
            pad_t, i_t, j_t, k_t, row_t = signature.args
            pad_v, i_v, j_v, k_v, row_v = args
            data = context.make_array(pad_t)(context, builder, pad_v)
            shape = cgutils.unpack_tuple(builder, data.shape, 3)
            strides = cgutils.unpack_tuple(builder, data.strides, 3)
            first = [context.cast(builder, v, t, types.intp)
                     for v, t in ((i_v, i_t), (j_v, j_t), (k_v, k_t))]
            slots = {}
            n = 0
            for a in range(3):
                for b in range(3):
                    for c in range(3):
                        inds = [builder.add(v, context.get_constant(types.intp, d))
                                for v, d in zip(first, (a, b, c), strict=True)]
                        at = cgutils.get_item_pointer2(context, builder, data.data, shape,
                                                       strides, pad_t.layout, inds)
                        slots[n] = context.cast(builder, builder.load(at), pad_t.dtype,
                                                types.float64)
                        n += 1
            for target, terms in rows:
                acc = None
                for w, src in terms:
                    term = builder.fmul(context.get_constant(types.float64, w), slots[src])
                    acc = term if acc is None else builder.fadd(acc, term)
                slots[target] = acc
            out = context.make_array(row_t)(context, builder, row_v)
            out_shape = cgutils.unpack_tuple(builder, out.shape, 1)
            out_strides = cgutils.unpack_tuple(builder, out.strides, 1)
            for p in range(n_points):
                at = cgutils.get_item_pointer2(context, builder, out.data, out_shape,
                                               out_strides, row_t.layout,
                                               [context.get_constant(types.intp, p)])
                builder.store(slots[27 + p], at)
            return context.get_dummy_value()

        return sig, codegen

    return fill


def fill_cube(grid, i, j, k, row):
    """All coefficients of cube ``(i, j, k)`` of ``grid`` into ``row[:n_points]``, by the
    straight-line code of the grid's scheme (compiled code only)."""
    raise NotImplementedError


#: (grid class, scheme number) -> the :func:`_program_intrinsic` of the scheme's program.
_STRAIGHT: dict[tuple[type, int], Any] = {}


def _straight_line(grid_class: type, scheme: int) -> Any:
    key = (grid_class, scheme)
    fill = _STRAIGHT.get(key)
    if fill is None:
        fill = _STRAIGHT[key] = _program_intrinsic(SCHEMES[grid_class][scheme]())
    return fill


# A call (cache misses only), not inlined: the generated body inlined at Numba's IR level
# corrupted the band's own variables (the pixel's colour was written from garbage; numba 0.6x),
# whereas generated code called out of line, as ``.render.outputs.copy_pixel``, compiles right.
# Generated code has no file for numba's disk cache; the bands that call it are cached with
# its code inside (and recompiled whenever a module of the package changes).
@overload_jit(fill_cube, inline="never")
def _fill_cube(grid, i, j, k, row):
    cls = getattr(grid, "instance_class", None)
    if cls not in SCHEMES or not SCHEMES[cls]:
        return None
    scope = {f"fill{n}": _straight_line(cls, n) for n in range(len(SCHEMES[cls]))}
    body = ""
    for n in range(len(SCHEMES[cls]) - 1):
        body += (f"    {'if' if n == 0 else 'elif'} grid.scheme == {n}:\n"
                 f"        fill{n}(grid.pad, i, j, k, row)\n        return\n")
    body += f"    fill{len(SCHEMES[cls]) - 1}(grid.pad, i, j, k, row)\n"
    exec(f"def fill(grid, i, j, k, row):\n{body}", scope)  # noqa: S102 - from the tables
    return scope["fill"]


@jit(inline="always")
def _cube_row(grid, scratch, slot, i, j, k):
    """The coefficients of cube ``(i, j, k)``: its stored row (``slot``, with a classification
    that stored them), else its entry of the thread's cache, computed there on a miss."""
    if slot >= 0 and grid.coeffs.shape[0] > 0:
        return grid.coeffs[slot]
    keys, cache = scratch[0], scratch[1]
    # Direct-mapped by the low bits of the cube index: distinct within any 8 x 8 x 8 cubes.
    entry = ((i & 7) << 6) | ((j & 7) << 3) | (k & 7)
    ny, nz = grid.pad.shape[1] - 2, grid.pad.shape[2] - 2
    lin = (np.int64(i) * ny + j) * nz + k
    buf = cache[entry]
    if keys[entry] != lin:
        fill_cube(grid, i, j, k, buf)
        keys[entry] = lin
    return buf


@jit(inline="always")
def _load_tet(grid, scratch, slot, i, j, k, tet):
    """The coefficients of tetrahedron ``tet`` of cube ``(i, j, k)`` into ``scratch[2]`` (for
    the de Casteljau gradient; the rest reads them in place, :func:`_cube_row`)."""
    c = scratch[2]
    row = _cube_row(grid, scratch, slot, i, j, k)
    for n in range(grid.tet_points.shape[1]):
        c[n] = row[grid.tet_points[tet, n]]
    return c


@jit(inline="always")
def _hull(row, idx):
    """``(min, max)`` of ``row[idx[n]]`` over the tetrahedron's coefficients (20 or 10).

    Four independent chains, joined at the end: one chain of 20 dependent ``min``/``max``
    waited about 80 cycles per piece on their latency. Min and max are exact, so the order
    changes nothing."""
    n = idx.shape[0]
    v0, v1, v2, v3 = row[idx[0]], row[idx[1]], row[idx[2]], row[idx[3]]
    lo0, hi0, lo1, hi1, lo2, hi2, lo3, hi3 = v0, v0, v1, v1, v2, v2, v3, v3
    m = 4
    while m + 4 <= n:
        v0, v1, v2, v3 = row[idx[m]], row[idx[m + 1]], row[idx[m + 2]], row[idx[m + 3]]
        lo0, hi0 = min(lo0, v0), max(hi0, v0)
        lo1, hi1 = min(lo1, v1), max(hi1, v1)
        lo2, hi2 = min(lo2, v2), max(hi2, v2)
        lo3, hi3 = min(lo3, v3), max(hi3, v3)
        m += 4
    while m < n:
        v0 = row[idx[m]]
        lo0, hi0 = min(lo0, v0), max(hi0, v0)
        m += 1
    return min(min(lo0, lo1), min(lo2, lo3)), max(max(hi0, hi1), max(hi2, hi3))


@jit(inline="always")
def _cell_pieces(grid, scratch, ctx, cell, a, e, cuts, tags):
    """Cut the cube's segment into tetrahedron pieces and give each its range
    (``scratch[5][piece]``); the polynomials are built only for the pieces a mode asks for
    (``piece_poly``), so a ray that ends early never pays for the pieces behind its hit."""
    i, j, k = cell
    ax, ay, az = a
    ex, ey, ez = e
    n = split_cube_segment(ax - 0.5, ay - 0.5, az - 0.5, ex, ey, ez, cuts)
    ranges = scratch[5]
    if ctx[2] < 0 and ctx[3] == 0xFFFFFF:
        # No classification: each piece's range is the convex hull of its tetrahedron's
        # coefficients, read in place from the cube's row (looked up once per cube).
        row = _cube_row(grid, scratch, ctx[2], i, j, k)
        for p in range(n):
            sm = 0.5 * (cuts[p] + cuts[p + 1])
            tet = tet_of_point(ax - 0.5 + sm * ex, ay - 0.5 + sm * ey, az - 0.5 + sm * ez)
            tags[p] = tet + 32 * p
            lo, hi = _hull(row, grid.tet_points[tet])
            ranges[p, 0] = lo
            ranges[p, 1] = hi
        return n
    for p in range(n):
        sm = 0.5 * (cuts[p] + cuts[p + 1])
        tet = tet_of_point(ax - 0.5 + sm * ex, ay - 0.5 + sm * ey, az - 0.5 + sm * ez)
        tags[p] = tet + 32 * p
        if (ctx[3] >> tet) & 1 == 0:
            ranges[p, 0] = math.inf  # not in the mask: the piece cannot contribute
            ranges[p, 1] = -math.inf
        else:
            ranges[p, 0] = -math.inf  # classified active for the isovalue
            ranges[p, 1] = math.inf
    return n


@jit()
def _piece_range(grid, scratch, ctx, i, j, k, tag):
    # From cell_pieces: empty outside the cube's mask, unbounded when classified active for
    # the isovalue, else the convex hull of the tetrahedron's coefficients.
    p = tag >> 5
    return scratch[5][p, 0], scratch[5][p, 1]


@jit()
def _piece_poly3(grid, scratch, ctx, cell, tag, a, b):
    i, j, k = cell
    ax, ay, az = a
    bx, by, bz = b
    tet = tag & 31
    row = _cube_row(grid, scratch, ctx[2], i, j, k)
    a0, a1, a2, a3 = barycentric(grid.bary, tet, ax - 0.5, ay - 0.5, az - 0.5)
    e0, e1, e2, e3 = barycentric(grid.bary, tet, bx - 0.5, by - 0.5, bz - 0.5)
    u0, u1, u2, u3 = ray_bernstein3_at(row, grid.tet_points[tet], a0, a1, a2, a3, e0, e1, e2, e3)
    return Bernstein3(u0, u1, u2, u3, grid.newton)


@jit()
def _piece_poly2(grid, scratch, ctx, cell, tag, a, b):
    i, j, k = cell
    ax, ay, az = a
    bx, by, bz = b
    tet = tag & 31
    row = _cube_row(grid, scratch, ctx[2], i, j, k)
    a0, a1, a2, a3 = barycentric(grid.bary, tet, ax - 0.5, ay - 0.5, az - 0.5)
    e0, e1, e2, e3 = barycentric(grid.bary, tet, bx - 0.5, by - 0.5, bz - 0.5)
    u0, u1, u2 = ray_bernstein2_at(row, grid.tet_points[tet], a0, a1, a2, a3, e0, e1, e2, e3)
    return Bernstein2(u0, u1, u2)


@jit()
def _gradient_deg(grid, scratch, slot, i, j, k, tag, x, y, z, degree):
    c = _load_tet(grid, scratch, slot, i, j, k, tag)
    _, gx, gy, gz = value_gradient(c, degree, grid.steps, grid.bary, tag, x - 0.5, y - 0.5,
                                   z - 0.5, scratch[3], scratch[4])
    return gx, gy, gz


@jit()
def _gradient3(grid, scratch, ctx, i, j, k, tag, x, y, z):
    return _gradient_deg(grid, scratch, ctx[2], i, j, k, tag & 31, x, y, z, 3)


@jit()
def _gradient2(grid, scratch, ctx, i, j, k, tag, x, y, z):
    return _gradient_deg(grid, scratch, ctx[2], i, j, k, tag & 31, x, y, z, 2)


@jit()
def _value_gradient_deg(grid, scratch, x, y, z, degree):
    i, j, k, tet, qx, qy, qz = _locate(grid, x, y, z)
    c = _load_tet(grid, scratch, np.int64(-1), i, j, k, tet)
    return value_gradient(c, degree, grid.steps, grid.bary, tet, qx, qy, qz, scratch[3],
                          scratch[4])


@jit(inline="always")
def _locate(grid, x, y, z):
    """Cube, tetrahedron and local point (relative to the cube's centre) of a point of the
    traversal space, clamped into the spline's box."""
    nx, ny, nz = _cell_count(grid)
    x = min(max(x, 0.0), float(nx))
    y = min(max(y, 0.0), float(ny))
    z = min(max(z, 0.0), float(nz))
    i = min(int(math.floor(x)), nx - 1)
    j = min(int(math.floor(y)), ny - 1)
    k = min(int(math.floor(z)), nz - 1)
    qx, qy, qz = x - i - 0.5, y - j - 0.5, z - k - 0.5
    return i, j, k, tet_of_point(qx, qy, qz), qx, qy, qz


@jit()
def _value_at3(grid, scratch, x, y, z):
    # The value alone (the fixed-step loop takes one per sample), read in place: the same
    # number value_gradient_at returns, without copying the coefficients or the gradient.
    i, j, k, tet, qx, qy, qz = _locate(grid, x, y, z)
    row = _cube_row(grid, scratch, np.int64(-1), i, j, k)
    l0, l1, l2, l3 = barycentric(grid.bary, tet, qx, qy, qz)
    return bernstein3_value_at(row, grid.tet_points[tet], l0, l1, l2, l3)


@jit()
def _value_at2(grid, scratch, x, y, z):
    i, j, k, tet, qx, qy, qz = _locate(grid, x, y, z)
    row = _cube_row(grid, scratch, np.int64(-1), i, j, k)
    l0, l1, l2, l3 = barycentric(grid.bary, tet, qx, qy, qz)
    return bernstein2_value_at(row, grid.tet_points[tet], l0, l1, l2, l3)


@jit()
def _value_gradient_at3(grid, scratch, x, y, z):
    return _value_gradient_deg(grid, scratch, x, y, z, 3)


@jit()
def _value_gradient_at2(grid, scratch, x, y, z):
    return _value_gradient_deg(grid, scratch, x, y, z, 2)


# Every hook but value_at is inlined into the per-pair loop (the cache-miss path stays a call
# inside them). The fixed-step loop reads values at several places: value_at inlined at each
# made s31 DVR frames about 1.2x faster than this call but took its kernel from 17 to 28 s of
# compile; called, it compiles in about the time the value_gradient_at it replaces did.
_CALLED = ("value_at",)

register(S31Grid, called=_CALLED, cell_count=_cell_count, new_scratch=_new_scratch,
         cell_load=_cell_load, cell_pieces=_cell_pieces, piece_range=_piece_range,
         piece_poly=_piece_poly3, gradient=_gradient3, value_gradient_at=_value_gradient_at3,
         value_at=_value_at3)
register(QSSGrid, called=_CALLED, cell_count=_cell_count, new_scratch=_new_scratch,
         cell_load=_cell_load, cell_pieces=_cell_pieces, piece_range=_piece_range,
         piece_poly=_piece_poly2, gradient=_gradient2, value_gradient_at=_value_gradient_at2,
         value_at=_value_at2)
