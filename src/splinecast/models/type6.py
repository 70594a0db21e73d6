"""Shared machinery of the splines on the type-6 partition (:mod:`.s31`, :mod:`.qss`).

A model of this family is defined by its coefficient rules only; this module turns the derived
tables (:mod:`.type6_geometry`) into compiled evaluation (de Casteljau value and gradient,
blossoming of the ray restriction) and prepares the volume:

Border
    The 27-neighbourhood of a border cube reaches one voxel outside the data. The data are
    extended by *clamp-to-edge* (each outside value copies the nearest border voxel), so every
    coefficient is still an average of real data values and nothing outside the data range
    appears (no garbage, no ringing at the box faces). Linear functions are therefore reproduced
    exactly only in cubes whose 27-neighbourhood lies inside the data; the outermost half cube
    flattens towards the border. The spline covers ``[-1/2, n - 1/2]`` in index space per axis,
    half a voxel more on each side than the trilinear box.
Storage
    The padded data are kept as float32 when that is exact (8/16-bit integers, float32) and as
    float64 otherwise, to keep the number of compiled variants small; the prefilter computes in
    float64 and stores its result in the same type (the voxels' precision).
Bounds
    Per cube, the exact range of its coefficients (float32, rounded outward and widened by the
    rounding tolerance), computed once per volume by the scheme's verified averaging chain
    (:func:`~.type6_geometry.derive_program`, about a third of the multiply-adds of the direct
    rules) vectorised over rows of cubes and parallel over slices. It bounds every patch of the
    cube (convex hull property), also for QSS-B's negative weights, and is iso-independent, so an
    isovalue change compares instead of computing. Memory: 8 bytes per cube.
"""

from __future__ import annotations

import math
from collections import namedtuple
from collections.abc import Callable
from functools import cached_property
from typing import Any

import numpy as np

from .._jit import jit
from .._jit.work_queue import run_items, take
from ..errors import ParameterError
from ..volume import Volume
from .base import ActiveCellClassifier, ReconstructionModel
from .storage import coefficient_dtype
from .type6_geometry import (
    Type6Program,
    Type6Tables,
    barycentric_matrices,
    decasteljau_tables,
    tet_of_point,
)
from .validation import require_renderable

__all__ = [
    "Type6Model",
    "S31Grid",
    "QSSGrid",
    "SCHEMES",
    "register_scheme",
    "ROOT_FINDERS",
    "gather27",
    "tet_coefficients",
    "stored_tet_coefficients",
    "decasteljau_step",
    "value_gradient",
    "ray_bernstein",
    "cube_bounds",
    "run_program",
    "barycentric",
    "ray_bernstein3",
    "ray_bernstein2",
    "ray_bernstein3_at",
    "ray_bernstein2_at",
    "bernstein3_value_at",
    "bernstein2_value_at",
    "gather27_lane",
    "rounding_tolerance",
    "RELATIVE_ROUNDING",
    "evaluate_in_tets",
    "evaluate_points",
]

_GRID_FIELDS = ["pad", "cube_lo", "cube_hi", "slot", "tet_mask", "coeffs", "tet_points",
                "bary", "steps", "newton", "scheme"]
#: Kernel grid of the S31 model (hooks in :mod:`.type6_ray`): the clamp-padded data (cube ``c``
#: needs ``pad[c .. c + 2]``), per-cube coefficient bounds, the optional isovalue classification
#: (``slot``, ``tet_mask``, precomputed ``coeffs``; empty arrays without), the scheme's tables,
#: the root finder choice and the number of the model's coefficient program among the grid
#: class's (:data:`SCHEMES`).
S31Grid = namedtuple("S31Grid", _GRID_FIELDS)
#: Kernel grid of the QSS model (same fields as :data:`S31Grid`).
QSSGrid = namedtuple("QSSGrid", _GRID_FIELDS)

#: Kernel grid class -> the coefficient programs of the schemes it renders, in the order of
#: their numbers (the grids' ``scheme``), each as a function that returns it (programs are
#: derived on first use). The ray hooks compile each program into straight-line code
#: (:mod:`.type6_ray`); the model modules add theirs with :func:`register_scheme`.
SCHEMES: dict[type, list[Callable[[], Type6Program]]] = {S31Grid: [], QSSGrid: []}


def register_scheme(grid_class: type, program: Callable[[], Type6Program]) -> int:
    """Add a coefficient scheme to the schemes a kernel grid class renders.

    Parameters
    ----------
    grid_class : type
        :data:`S31Grid` (cubic schemes) or :data:`QSSGrid` (quadratic ones).
    program : callable
        Returns the scheme's verified program (:func:`~.type6_geometry.derive_program`).

    Returns
    -------
    int
        The scheme's number: what a model of the scheme passes as ``scheme``.
    """
    SCHEMES[grid_class].append(program)
    return len(SCHEMES[grid_class]) - 1

#: Root finders of the ray–patch intersection (``root_finder=`` option): name -> code.
ROOT_FINDERS = {"bernstein": 0, "newton": 1}


# ----------------------------------------------------------------------------- compiled helpers
@jit(inline="always")
def gather27(pad: np.ndarray, i: int, j: int, k: int, out: np.ndarray) -> None:
    """The 27 data values around cube ``(i, j, k)`` into ``out[:27]`` (``pad`` has a one-voxel
    border)."""
    n = 0
    for a in range(3):
        for b in range(3):
            for c in range(3):
                out[n] = float(pad[i + a, j + b, k + c])
                n += 1


@jit(inline="always")
def tet_coefficients(
    v27: np.ndarray, tet: int, tet_points: np.ndarray, indptr: np.ndarray, cols: np.ndarray,
    vals: np.ndarray, out: np.ndarray,
) -> None:
    """Bernstein–Bézier coefficients of one tetrahedron from the 27 data values (sparse rules)."""
    for n in range(tet_points.shape[1]):
        p = tet_points[tet, n]
        s = 0.0
        for q in range(indptr[p], indptr[p + 1]):
            s += vals[q] * v27[cols[q]]
        out[n] = s


@jit(inline="always")
def stored_tet_coefficients(
    coeffs: np.ndarray, slot: int, tet: int, tet_points: np.ndarray, out: np.ndarray
) -> None:
    """Coefficients of one tetrahedron from a cube's precomputed coefficient row."""
    for n in range(tet_points.shape[1]):
        out[n] = coeffs[slot, tet_points[tet, n]]


@jit(inline="always")
def decasteljau_step(
    src: np.ndarray, dst: np.ndarray, steps: np.ndarray, e: int,
    l0: float, l1: float, l2: float, l3: float,
) -> None:
    """One de Casteljau step from degree ``e`` to ``e - 1`` at barycentric ``(l0, l1, l2, l3)``."""
    n_out = e * (e + 1) * (e + 2) // 6
    for n in range(n_out):
        dst[n] = (l0 * src[steps[e - 1, n, 0]] + l1 * src[steps[e - 1, n, 1]]
                  + l2 * src[steps[e - 1, n, 2]] + l3 * src[steps[e - 1, n, 3]])


@jit(inline="always")
def _linear_part(
    c: np.ndarray, degree: int, steps: np.ndarray, l0: float, l1: float, l2: float, l3: float,
    b10: np.ndarray, b4: np.ndarray,
) -> None:
    """De Casteljau down to degree 1: the 4 coefficients left in ``b4``."""
    if degree == 3:
        decasteljau_step(c, b10, steps, 3, l0, l1, l2, l3)
        decasteljau_step(b10, b4, steps, 2, l0, l1, l2, l3)
    else:
        decasteljau_step(c, b4, steps, 2, l0, l1, l2, l3)


@jit(inline="always")
def value_gradient(
    c: np.ndarray, degree: int, steps: np.ndarray, bary: np.ndarray, tet: int,
    qx: float, qy: float, qz: float, b10: np.ndarray, b4: np.ndarray,
) -> tuple[float, float, float, float]:
    """Value and index-space gradient of the patch with coefficients ``c`` at local point ``q``.

    The last de Casteljau level ``b4`` holds the four directional building blocks: the
    derivative with respect to barycentric coordinate ``m`` is ``degree * b4[m]``, and the
    barycentric gradients are the constant rows of ``bary[tet]``.
    """
    a = bary[tet]
    l0 = a[0, 0] * qx + a[0, 1] * qy + a[0, 2] * qz + a[0, 3]
    l1 = a[1, 0] * qx + a[1, 1] * qy + a[1, 2] * qz + a[1, 3]
    l2 = a[2, 0] * qx + a[2, 1] * qy + a[2, 2] * qz + a[2, 3]
    l3 = a[3, 0] * qx + a[3, 1] * qy + a[3, 2] * qz + a[3, 3]
    _linear_part(c, degree, steps, l0, l1, l2, l3, b10, b4)
    value = l0 * b4[0] + l1 * b4[1] + l2 * b4[2] + l3 * b4[3]
    gx = degree * (a[0, 0] * b4[0] + a[1, 0] * b4[1] + a[2, 0] * b4[2] + a[3, 0] * b4[3])
    gy = degree * (a[0, 1] * b4[0] + a[1, 1] * b4[1] + a[2, 1] * b4[2] + a[3, 1] * b4[3])
    gz = degree * (a[0, 2] * b4[0] + a[1, 2] * b4[1] + a[2, 2] * b4[2] + a[3, 2] * b4[3])
    return value, gx, gy, gz


@jit(inline="always")
def ray_bernstein(
    c: np.ndarray, degree: int, steps: np.ndarray, bary: np.ndarray, tet: int, a: tuple,
    b: tuple, work: tuple,
) -> tuple[float, float, float, float]:
    """Univariate Bernstein coefficients of the patch on the segment from ``a`` to ``b`` (local
    points, ``(x, y, z)`` tuples); ``work`` holds the blossoms' buffers ``(b10a, b10b, b4a,
    b4b, b4c)``.

    The restriction of a degree-``d`` polynomial to a segment is a degree-``d`` polynomial in the
    segment parameter whose ``k``-th Bernstein coefficient is the blossom evaluated ``d - k``
    times at ``a`` and ``k`` times at ``b`` (barycentric coordinates of the end points). For a
    quadratic the fourth returned value is 0.
    """
    ax, ay, az = a
    bx, by, bz = b
    b10a, b10b, b4a, b4b, b4c = work
    t = bary[tet]
    a0 = t[0, 0] * ax + t[0, 1] * ay + t[0, 2] * az + t[0, 3]
    a1 = t[1, 0] * ax + t[1, 1] * ay + t[1, 2] * az + t[1, 3]
    a2 = t[2, 0] * ax + t[2, 1] * ay + t[2, 2] * az + t[2, 3]
    a3 = t[3, 0] * ax + t[3, 1] * ay + t[3, 2] * az + t[3, 3]
    e0 = t[0, 0] * bx + t[0, 1] * by + t[0, 2] * bz + t[0, 3]
    e1 = t[1, 0] * bx + t[1, 1] * by + t[1, 2] * bz + t[1, 3]
    e2 = t[2, 0] * bx + t[2, 1] * by + t[2, 2] * bz + t[2, 3]
    e3 = t[3, 0] * bx + t[3, 1] * by + t[3, 2] * bz + t[3, 3]
    if degree == 3:
        decasteljau_step(c, b10a, steps, 3, a0, a1, a2, a3)
        decasteljau_step(c, b10b, steps, 3, e0, e1, e2, e3)
        decasteljau_step(b10a, b4a, steps, 2, a0, a1, a2, a3)  # blossom (a, a, .)
        decasteljau_step(b10a, b4b, steps, 2, e0, e1, e2, e3)  # blossom (a, b, .)
        decasteljau_step(b10b, b4c, steps, 2, e0, e1, e2, e3)  # blossom (b, b, .)
        u0 = a0 * b4a[0] + a1 * b4a[1] + a2 * b4a[2] + a3 * b4a[3]
        u1 = e0 * b4a[0] + e1 * b4a[1] + e2 * b4a[2] + e3 * b4a[3]
        u2 = e0 * b4b[0] + e1 * b4b[1] + e2 * b4b[2] + e3 * b4b[3]
        u3 = e0 * b4c[0] + e1 * b4c[1] + e2 * b4c[2] + e3 * b4c[3]
        return u0, u1, u2, u3
    decasteljau_step(c, b4a, steps, 2, a0, a1, a2, a3)
    decasteljau_step(c, b4b, steps, 2, e0, e1, e2, e3)
    u0 = a0 * b4a[0] + a1 * b4a[1] + a2 * b4a[2] + a3 * b4a[3]
    u1 = e0 * b4a[0] + e1 * b4a[1] + e2 * b4a[2] + e3 * b4a[3]
    u2 = e0 * b4b[0] + e1 * b4b[1] + e2 * b4b[2] + e3 * b4b[3]
    return u0, u1, u2, 0.0


@jit(inline="always")
def barycentric(bary: np.ndarray, tet: int, x: float, y: float, z: float
                ) -> tuple[float, float, float, float]:
    """Barycentric coordinates of local point ``(x, y, z)`` in tetrahedron ``tet``."""
    b = bary
    return (b[tet, 0, 0] * x + b[tet, 0, 1] * y + b[tet, 0, 2] * z + b[tet, 0, 3],
            b[tet, 1, 0] * x + b[tet, 1, 1] * y + b[tet, 1, 2] * z + b[tet, 1, 3],
            b[tet, 2, 0] * x + b[tet, 2, 1] * y + b[tet, 2, 2] * z + b[tet, 2, 3],
            b[tet, 3, 0] * x + b[tet, 3, 1] * y + b[tet, 3, 2] * z + b[tet, 3, 3])


#: Coefficient numbers of a tetrahedron in order: what :func:`ray_bernstein3` and
#: :func:`ray_bernstein2` read their coefficient array through.
_IDENTITY = np.arange(20, dtype=np.int64)


@jit(inline="always")
def ray_bernstein3(
    c: np.ndarray, a0: float, a1: float, a2: float, a3: float,
    e0: float, e1: float, e2: float, e3: float,
) -> tuple[float, float, float, float]:
    """:func:`ray_bernstein` for a cubic, unrolled (indices from ``decasteljau_tables(3)``).

    ``a`` and ``e`` are the barycentric coordinates of the segment's end points; the result
    is the blossom at ``(a, a, a)``, ``(a, a, e)``, ``(a, e, e)``, ``(e, e, e)``.
    """
    return ray_bernstein3_at(c, _IDENTITY, a0, a1, a2, a3, e0, e1, e2, e3)


@jit(inline="always")
def ray_bernstein3_at(
    row: np.ndarray, idx: np.ndarray, a0: float, a1: float, a2: float, a3: float,
    e0: float, e1: float, e2: float, e3: float,
) -> tuple[float, float, float, float]:
    """:func:`ray_bernstein3` of the tetrahedron whose coefficient ``n`` is ``row[idx[n]]``.

    Read in place from a cube's coefficient row (``idx`` the tetrahedron's row of the
    tables' ``tet_points``): copying the 20 coefficients first cost a store and a load each.
    Straight-line code keeps every intermediate in registers.
    """
    c0, c1, c2, c3, c4 = row[idx[0]], row[idx[1]], row[idx[2]], row[idx[3]], row[idx[4]]
    c5, c6, c7, c8, c9 = row[idx[5]], row[idx[6]], row[idx[7]], row[idx[8]], row[idx[9]]
    c10, c11, c12, c13 = row[idx[10]], row[idx[11]], row[idx[12]], row[idx[13]]
    c14, c15, c16, c17 = row[idx[14]], row[idx[15]], row[idx[16]], row[idx[17]]
    c18, c19 = row[idx[18]], row[idx[19]]
    pa0 = a0 * c0 + a1 * c1 + a2 * c2 + a3 * c3
    pa1 = a0 * c1 + a1 * c4 + a2 * c5 + a3 * c6
    pa2 = a0 * c2 + a1 * c5 + a2 * c7 + a3 * c8
    pa3 = a0 * c3 + a1 * c6 + a2 * c8 + a3 * c9
    pa4 = a0 * c4 + a1 * c10 + a2 * c11 + a3 * c12
    pa5 = a0 * c5 + a1 * c11 + a2 * c13 + a3 * c14
    pa6 = a0 * c6 + a1 * c12 + a2 * c14 + a3 * c15
    pa7 = a0 * c7 + a1 * c13 + a2 * c16 + a3 * c17
    pa8 = a0 * c8 + a1 * c14 + a2 * c17 + a3 * c18
    pa9 = a0 * c9 + a1 * c15 + a2 * c18 + a3 * c19
    pe0 = e0 * c0 + e1 * c1 + e2 * c2 + e3 * c3
    pe1 = e0 * c1 + e1 * c4 + e2 * c5 + e3 * c6
    pe2 = e0 * c2 + e1 * c5 + e2 * c7 + e3 * c8
    pe3 = e0 * c3 + e1 * c6 + e2 * c8 + e3 * c9
    pe4 = e0 * c4 + e1 * c10 + e2 * c11 + e3 * c12
    pe5 = e0 * c5 + e1 * c11 + e2 * c13 + e3 * c14
    pe6 = e0 * c6 + e1 * c12 + e2 * c14 + e3 * c15
    pe7 = e0 * c7 + e1 * c13 + e2 * c16 + e3 * c17
    pe8 = e0 * c8 + e1 * c14 + e2 * c17 + e3 * c18
    pe9 = e0 * c9 + e1 * c15 + e2 * c18 + e3 * c19
    aa0 = a0 * pa0 + a1 * pa1 + a2 * pa2 + a3 * pa3
    aa1 = a0 * pa1 + a1 * pa4 + a2 * pa5 + a3 * pa6
    aa2 = a0 * pa2 + a1 * pa5 + a2 * pa7 + a3 * pa8
    aa3 = a0 * pa3 + a1 * pa6 + a2 * pa8 + a3 * pa9
    ae0 = e0 * pa0 + e1 * pa1 + e2 * pa2 + e3 * pa3
    ae1 = e0 * pa1 + e1 * pa4 + e2 * pa5 + e3 * pa6
    ae2 = e0 * pa2 + e1 * pa5 + e2 * pa7 + e3 * pa8
    ae3 = e0 * pa3 + e1 * pa6 + e2 * pa8 + e3 * pa9
    ee0 = e0 * pe0 + e1 * pe1 + e2 * pe2 + e3 * pe3
    ee1 = e0 * pe1 + e1 * pe4 + e2 * pe5 + e3 * pe6
    ee2 = e0 * pe2 + e1 * pe5 + e2 * pe7 + e3 * pe8
    ee3 = e0 * pe3 + e1 * pe6 + e2 * pe8 + e3 * pe9
    u0 = a0 * aa0 + a1 * aa1 + a2 * aa2 + a3 * aa3
    u1 = e0 * aa0 + e1 * aa1 + e2 * aa2 + e3 * aa3
    u2 = e0 * ae0 + e1 * ae1 + e2 * ae2 + e3 * ae3
    u3 = e0 * ee0 + e1 * ee1 + e2 * ee2 + e3 * ee3
    return u0, u1, u2, u3


@jit(inline="always")
def bernstein3_value_at(row: np.ndarray, idx: np.ndarray, l0: float, l1: float, l2: float,
                        l3: float) -> float:
    """The cubic patch whose coefficient ``n`` is ``row[idx[n]]`` at barycentric ``l``:
    :func:`ray_bernstein3_at`'s first value with ``e = a`` (the same products and sums in the
    same order, so the same number as :func:`value_gradient`'s value), written out alone.

    The fixed-step loop inlines the value at several places; the blossom's other three
    values, which the compiler drops anyway, doubled the time its kernel took to compile."""
    c0, c1, c2, c3, c4 = row[idx[0]], row[idx[1]], row[idx[2]], row[idx[3]], row[idx[4]]
    c5, c6, c7, c8, c9 = row[idx[5]], row[idx[6]], row[idx[7]], row[idx[8]], row[idx[9]]
    c10, c11, c12, c13 = row[idx[10]], row[idx[11]], row[idx[12]], row[idx[13]]
    c14, c15, c16, c17 = row[idx[14]], row[idx[15]], row[idx[16]], row[idx[17]]
    c18, c19 = row[idx[18]], row[idx[19]]
    p0 = l0 * c0 + l1 * c1 + l2 * c2 + l3 * c3
    p1 = l0 * c1 + l1 * c4 + l2 * c5 + l3 * c6
    p2 = l0 * c2 + l1 * c5 + l2 * c7 + l3 * c8
    p3 = l0 * c3 + l1 * c6 + l2 * c8 + l3 * c9
    p4 = l0 * c4 + l1 * c10 + l2 * c11 + l3 * c12
    p5 = l0 * c5 + l1 * c11 + l2 * c13 + l3 * c14
    p6 = l0 * c6 + l1 * c12 + l2 * c14 + l3 * c15
    p7 = l0 * c7 + l1 * c13 + l2 * c16 + l3 * c17
    p8 = l0 * c8 + l1 * c14 + l2 * c17 + l3 * c18
    p9 = l0 * c9 + l1 * c15 + l2 * c18 + l3 * c19
    q0 = l0 * p0 + l1 * p1 + l2 * p2 + l3 * p3
    q1 = l0 * p1 + l1 * p4 + l2 * p5 + l3 * p6
    q2 = l0 * p2 + l1 * p5 + l2 * p7 + l3 * p8
    q3 = l0 * p3 + l1 * p6 + l2 * p8 + l3 * p9
    return l0 * q0 + l1 * q1 + l2 * q2 + l3 * q3


@jit(inline="always")
def bernstein2_value_at(row: np.ndarray, idx: np.ndarray, l0: float, l1: float, l2: float,
                        l3: float) -> float:
    """:func:`bernstein3_value_at` for a quadratic patch (:func:`ray_bernstein2_at`'s first
    value with ``e = a``)."""
    c0, c1, c2, c3, c4 = row[idx[0]], row[idx[1]], row[idx[2]], row[idx[3]], row[idx[4]]
    c5, c6, c7, c8, c9 = row[idx[5]], row[idx[6]], row[idx[7]], row[idx[8]], row[idx[9]]
    p0 = l0 * c0 + l1 * c1 + l2 * c2 + l3 * c3
    p1 = l0 * c1 + l1 * c4 + l2 * c5 + l3 * c6
    p2 = l0 * c2 + l1 * c5 + l2 * c7 + l3 * c8
    p3 = l0 * c3 + l1 * c6 + l2 * c8 + l3 * c9
    return l0 * p0 + l1 * p1 + l2 * p2 + l3 * p3


@jit(inline="always")
def ray_bernstein2(
    c: np.ndarray, a0: float, a1: float, a2: float, a3: float,
    e0: float, e1: float, e2: float, e3: float,
) -> tuple[float, float, float]:
    """:func:`ray_bernstein` for a quadratic, unrolled (indices from ``decasteljau_tables(2)``)."""
    return ray_bernstein2_at(c, _IDENTITY, a0, a1, a2, a3, e0, e1, e2, e3)


@jit(inline="always")
def ray_bernstein2_at(
    row: np.ndarray, idx: np.ndarray, a0: float, a1: float, a2: float, a3: float,
    e0: float, e1: float, e2: float, e3: float,
) -> tuple[float, float, float]:
    """:func:`ray_bernstein2` of the tetrahedron whose coefficient ``n`` is ``row[idx[n]]``
    (as :func:`ray_bernstein3_at`)."""
    c0, c1, c2, c3, c4 = row[idx[0]], row[idx[1]], row[idx[2]], row[idx[3]], row[idx[4]]
    c5, c6, c7, c8, c9 = row[idx[5]], row[idx[6]], row[idx[7]], row[idx[8]], row[idx[9]]
    pa0 = a0 * c0 + a1 * c1 + a2 * c2 + a3 * c3
    pa1 = a0 * c1 + a1 * c4 + a2 * c5 + a3 * c6
    pa2 = a0 * c2 + a1 * c5 + a2 * c7 + a3 * c8
    pa3 = a0 * c3 + a1 * c6 + a2 * c8 + a3 * c9
    pe0 = e0 * c0 + e1 * c1 + e2 * c2 + e3 * c3
    pe1 = e0 * c1 + e1 * c4 + e2 * c5 + e3 * c6
    pe2 = e0 * c2 + e1 * c5 + e2 * c7 + e3 * c8
    pe3 = e0 * c3 + e1 * c6 + e2 * c8 + e3 * c9
    u0 = a0 * pa0 + a1 * pa1 + a2 * pa2 + a3 * pa3
    u1 = e0 * pa0 + e1 * pa1 + e2 * pa2 + e3 * pa3
    u2 = e0 * pe0 + e1 * pe1 + e2 * pe2 + e3 * pe3
    return u0, u1, u2


#: Points per item of :func:`evaluate_in_tets` on threads.
_POINT_CHUNK = 1024


def evaluate_in_tets(
    pad: np.ndarray, tet_points: np.ndarray, indptr: np.ndarray, cols: np.ndarray,
    vals: np.ndarray, bary: np.ndarray, steps: np.ndarray, degree: int,
    cubes: np.ndarray, tets: np.ndarray, q: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Value and index-space gradient of given patches at local points.

    Point ``m`` is evaluated with the polynomial of tetrahedron ``tets[m]`` of cube ``cubes[m]``
    at local coordinates ``q[m]`` (also outside that tetrahedron: the polynomial extends), which
    is what continuity tests across shared faces need. Chunks of points are spread over threads
    (:func:`~splinecast._jit.work_queue.run_items`).
    """
    m_pts = q.shape[0]
    values = np.empty(m_pts)
    grads = np.empty((m_pts, 3))
    run_items(_evaluate_chunks, -(-m_pts // _POINT_CHUNK), pad, tet_points, indptr, cols, vals,
              bary, steps, int(degree), cubes, tets, q, values, grads)
    return values, grads


@jit
def _evaluate_chunks(pad, tet_points, indptr, cols, vals, bary, steps, degree, cubes, tets, q,
                     values, grads, counter):
    """One thread's share of :func:`evaluate_in_tets`: the chunks of points it takes."""
    m_pts = q.shape[0]
    v27 = np.empty(27)
    c = np.empty(tet_points.shape[1])
    b10 = np.empty(10)
    b4 = np.empty(4)
    while True:
        start = take(counter) * _POINT_CHUNK
        if start >= m_pts:
            break
        for m in range(start, min(start + _POINT_CHUNK, m_pts)):
            gather27(pad, cubes[m, 0], cubes[m, 1], cubes[m, 2], v27)
            tet_coefficients(v27, tets[m], tet_points, indptr, cols, vals, c)
            v, gx, gy, gz = value_gradient(c, degree, steps, bary, tets[m],
                                           q[m, 0], q[m, 1], q[m, 2], b10, b4)
            values[m] = v
            grads[m, 0] = gx
            grads[m, 1] = gy
            grads[m, 2] = gz


@jit()
def locate(points: np.ndarray, shape: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cube, tetrahedron and local coordinates of index-space points (clamped into the domain)."""
    m_pts = points.shape[0]
    cubes = np.empty((m_pts, 3), np.int64)
    tets = np.empty(m_pts, np.int64)
    q = np.empty((m_pts, 3))
    for m in range(m_pts):
        for a in range(3):
            p = min(max(points[m, a], -0.5), shape[a] - 0.5)
            c = min(max(int(math.floor(p + 0.5)), 0), shape[a] - 1)
            cubes[m, a] = c
            q[m, a] = p - c
        tets[m] = tet_of_point(q[m, 0], q[m, 1], q[m, 2])
    return cubes, tets, q


def evaluate_points(model: Type6Model, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Value and index-space gradient of ``model``'s spline at index-space points (m, 3)."""
    pts = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
    cubes, tets, q = locate(pts, np.asarray(model.n_cells, np.int64))
    return evaluate_in_tets(model.pad, *model.tables_arrays, model.degree, cubes, tets, q)


# ----------------------------------------------------------------------------- preparation
_LANES = 64  # cubes evaluated side by side (structure of arrays) by the program kernels


@jit(inline="always")
def run_program(
    buf: np.ndarray, n: int, targets: np.ndarray, ptr: np.ndarray, sources: np.ndarray,
    weights: np.ndarray,
) -> None:
    """Evaluate a :class:`~.type6_geometry.Type6Program` for ``n`` cubes side by side.

    ``buf`` has shape ``(n_slots, _LANES)``: slot ``s`` of cube ``l`` is ``buf[s, l]``; slots
    ``0..26`` hold the data. The inner loops run over cubes, so they vectorise.
    """
    for r in range(targets.shape[0]):
        d = targets[r]
        q0 = ptr[r]
        w0 = weights[q0]
        s0 = sources[q0]
        for m in range(n):
            buf[d, m] = w0 * buf[s0, m]
        for q in range(q0 + 1, ptr[r + 1]):
            w = weights[q]
            sq = sources[q]
            for m in range(n):
                buf[d, m] += w * buf[sq, m]


@jit(inline="always")
def gather27_lane(pad: np.ndarray, i: int, j: int, k: int, buf: np.ndarray, m: int) -> None:
    """The 27 data values around cube ``(i, j, k)`` into lane ``m`` of a program buffer."""
    n = 0
    for a in range(3):
        for b in range(3):
            for c in range(3):
                buf[n, m] = float(pad[i + a, j + b, k + c])
                n += 1


@jit(inline="always")
def _round_down32(x: float) -> np.float32:
    f = np.float32(x)
    if f > x:
        f = np.nextafter(f, np.float32(-np.inf))
    return f


@jit(inline="always")
def _round_up32(x: float) -> np.float32:
    f = np.float32(x)
    if f < x:
        f = np.nextafter(f, np.float32(np.inf))
    return f


def cube_bounds(
    pad: np.ndarray, targets: np.ndarray, ptr: np.ndarray, sources: np.ndarray,
    weights: np.ndarray, n_slots: int, n_points: int, tol: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Exact per-cube range of all Bernstein–Bézier coefficients, as float32 bounds.

    Every cube's coefficients are computed once (by the model's program, parallel over slices,
    vectorised along rows); the range is widened by ``tol`` times the largest magnitude of the
    cube's 27 data points (the rounding error of the coefficient sums, which are sums of
    products of those points: see :data:`RELATIVE_ROUNDING`) and rounded outward to float32,
    so it stays conservative. By the convex hull property the cube's patches lie in this
    range, which is iso-independent: an isovalue change then only compares. A cube of equal
    data points has the exact range of that value (a MIP over a constant background then leaps
    it as soon as it has met the value, as over the trilinear model's). Slices along the first
    axis are spread over threads (:func:`~splinecast._jit.work_queue.run_items`).
    """
    shape = (pad.shape[0] - 2, pad.shape[1] - 2, pad.shape[2] - 2)
    lo = np.empty(shape, np.float32)
    hi = np.empty(shape, np.float32)
    run_items(_cube_bound_slices, shape[0], pad, targets, ptr, sources, weights, int(n_slots),
              int(n_points), float(tol), lo, hi)
    return lo, hi


@jit
def _cube_bound_slices(pad, targets, ptr, sources, weights, n_slots, n_points, tol, lo, hi,
                       counter):
    """One thread's share of :func:`cube_bounds`: the slices of cubes it takes."""
    nx, ny, nz = lo.shape
    buf = np.empty((n_slots, _LANES))
    size = np.empty(_LANES)
    while True:
        i = take(counter)
        if i >= nx:
            break
        for j in range(ny):
            for k0 in range(0, nz, _LANES):
                n = min(_LANES, nz - k0)
                size[:] = 0.0
                for a in range(3):
                    for b in range(3):
                        for c in range(3):
                            row = buf[9 * a + 3 * b + c]
                            for m in range(n):
                                row[m] = float(pad[i + a, j + b, k0 + m + c])
                                size[m] = max(size[m], abs(row[m]))
                run_program(buf, n, targets, ptr, sources, weights)
                vmin = buf[27].copy()
                vmax = buf[27].copy()
                for p in range(28, 27 + n_points):
                    row = buf[p]
                    for m in range(n):
                        vmin[m] = min(vmin[m], row[m])
                        vmax[m] = max(vmax[m], row[m])
                for m in range(n):
                    lo[i, j, k0 + m] = _round_down32(vmin[m] - tol * size[m])
                    hi[i, j, k0 + m] = _round_up32(vmax[m] + tol * size[m])


@jit(inline="always")
def _gather_lanes(pad, cubes, start, n, ny, nz, buf):
    for m in range(n):
        lin = cubes[start + m]
        gather27_lane(pad, lin // (ny * nz), (lin // nz) % ny, lin % nz, buf, m)


def classify_tets(
    pad: np.ndarray, cubes: np.ndarray, shape: np.ndarray, tet_points: np.ndarray,
    targets: np.ndarray, ptr: np.ndarray, sources: np.ndarray, weights: np.ndarray,
    n_slots: int, iso: float, tol: float,
) -> np.ndarray:
    """24-bit masks of the tetrahedra whose coefficient range contains ``iso``, per cube.

    The coefficients come from the model's program, ``_LANES`` cubes side by side; a range is
    widened by ``tol`` (rounding) so the test stays conservative for the renderer's sums.
    Groups of ``_LANES`` cubes are spread over threads.
    """
    masks = np.zeros(cubes.shape[0], np.uint32)
    run_items(_classify_chunks, -(-cubes.shape[0] // _LANES), pad, cubes, shape, tet_points,
              targets, ptr, sources, weights, int(n_slots), float(iso) - tol, float(iso) + tol,
              masks)
    return masks


@jit
def _classify_chunks(pad, cubes, shape, tet_points, targets, ptr, sources, weights, n_slots,
                     lo_iso, hi_iso, masks, counter):
    """One thread's share of :func:`classify_tets`: the groups of cubes it takes."""
    n = cubes.shape[0]
    ny, nz = shape[1], shape[2]
    n_local = tet_points.shape[1]
    buf = np.empty((n_slots, _LANES))
    vmin = np.empty(_LANES)
    vmax = np.empty(_LANES)
    mask = np.zeros(_LANES, np.uint32)
    while True:
        start = take(counter) * _LANES
        if start >= n:
            break
        mask[:] = 0
        cnt = min(_LANES, n - start)
        _gather_lanes(pad, cubes, start, cnt, ny, nz, buf)
        run_program(buf, cnt, targets, ptr, sources, weights)
        for t in range(24):
            row = buf[27 + tet_points[t, 0]]
            for m in range(cnt):
                vmin[m] = row[m]
                vmax[m] = row[m]
            for q in range(1, n_local):
                row = buf[27 + tet_points[t, q]]
                for m in range(cnt):
                    vmin[m] = min(vmin[m], row[m])
                    vmax[m] = max(vmax[m], row[m])
            bit = np.uint32(1 << t)
            for m in range(cnt):
                if vmin[m] <= hi_iso and vmax[m] >= lo_iso:
                    mask[m] |= bit
        for m in range(cnt):
            masks[start + m] = mask[m]


def store_coefficients(
    pad: np.ndarray, cubes: np.ndarray, shape: np.ndarray, targets: np.ndarray, ptr: np.ndarray,
    sources: np.ndarray, weights: np.ndarray, n_slots: int, n_points: int,
) -> np.ndarray:
    """All coefficients of the given cubes, shape (n, n_points) float64 (groups of ``_LANES``
    cubes on threads)."""
    out = np.empty((cubes.shape[0], int(n_points)))
    run_items(_store_chunks, -(-cubes.shape[0] // _LANES), pad, cubes, shape, targets, ptr,
              sources, weights, int(n_slots), out)
    return out


@jit
def _store_chunks(pad, cubes, shape, targets, ptr, sources, weights, n_slots, out, counter):
    """One thread's share of :func:`store_coefficients`: the groups of cubes it takes."""
    n, n_points = out.shape
    ny, nz = shape[1], shape[2]
    buf = np.empty((n_slots, _LANES))
    while True:
        start = take(counter) * _LANES
        if start >= n:
            break
        cnt = min(_LANES, n - start)
        _gather_lanes(pad, cubes, start, cnt, ny, nz, buf)
        run_program(buf, cnt, targets, ptr, sources, weights)
        for m in range(cnt):
            for p in range(n_points):
                out[start + m, p] = buf[27 + p, m]


#: Bound on the difference between two ways of rounding a coefficient's sum, relative to the
#: largest magnitude of the data points it is made of: each coefficient is a sum of at most a
#: few hundred products of those points and weights whose absolute row sums are at most 9/8
#: (the schemes here); 1e-12 is far above that error and far below anything visible.
RELATIVE_ROUNDING = 1e-12


def rounding_tolerance(pad: np.ndarray, program) -> float:
    """:data:`RELATIVE_ROUNDING` of the largest magnitude of ``pad``: a bound for every cube."""
    scale = max(abs(float(pad.min())), abs(float(pad.max()))) if pad.size else 0.0
    return RELATIVE_ROUNDING * max(scale, 1e-300)


def laplacian_prefilter(pad: np.ndarray) -> np.ndarray:
    """``f - (1/8) Delta_h f`` with the 7-point Laplacian in index units, on the padded grid.

    Makes the S31 scheme exact on quadratics (it removes the ``Delta q / 8`` term). The input is the
    clamp-padded data; the output is re-padded by clamping so the border rule stays the same.
    """
    f = pad.astype(np.float64)
    core = f[1:-1, 1:-1, 1:-1]
    lap = (f[2:, 1:-1, 1:-1] + f[:-2, 1:-1, 1:-1] + f[1:-1, 2:, 1:-1] + f[1:-1, :-2, 1:-1]
           + f[1:-1, 1:-1, 2:] + f[1:-1, 1:-1, :-2] - 6.0 * core)
    return np.pad(core - lap / 8.0, 1, mode="edge")


def laplacian_prefilter_brick(data: np.ndarray, first: np.ndarray,
                              shape: Any) -> tuple[np.ndarray, np.ndarray]:
    """:func:`laplacian_prefilter` of a brick of a pyramid level, with the whole level's border
    rule: beyond the level's ends the prefiltered values repeat the outer voxel's (re-clamped,
    not prefiltered ghosts). One ghost layer is used up.

    Parameters
    ----------
    data : ndarray
        The brick's voxels with their ghost layers (at least one).
    first : ndarray of 3 ints
        The level index of ``data[0, 0, 0]``.
    shape : 3 ints
        The level's shape.

    Returns
    -------
    (ndarray, ndarray)
        The prefiltered values (in :func:`~.storage.coefficient_dtype` of the brick's type, as
        the whole volume's) and the level index of their first element.
    """
    f = data.astype(np.float64)
    core = f[1:-1, 1:-1, 1:-1]
    lap = (f[2:, 1:-1, 1:-1] + f[:-2, 1:-1, 1:-1] + f[1:-1, 2:, 1:-1] + f[1:-1, :-2, 1:-1]
           + f[1:-1, 1:-1, 2:] + f[1:-1, 1:-1, :-2] - 6.0 * core)
    out = core - lap / 8.0
    first = first + 1
    index = [np.clip(first[a] + np.arange(out.shape[a]), 0, shape[a] - 1) - first[a]
             for a in range(3)]
    return (np.ascontiguousarray(out[np.ix_(*index)], dtype=coefficient_dtype(data.dtype)),
            first)


class Type6Model(ReconstructionModel):
    """Base of the spline models on the type-6 partition (use :class:`S31Model`/:class:`QSSModel`).

    Parameters
    ----------
    volume : Volume
        The data (at least 1 voxel per axis, no NaN or inf).
    tables : Type6Tables
        The scheme's derived coefficient tables.
    scheme : int
        The number of the scheme among those of the model's kernel grid class
        (:func:`register_scheme`, whose program must be derived from ``tables``).
    prefilter : bool
        Replace the data by ``f - Delta_h f / 8`` first (see :func:`laplacian_prefilter`).
    precompute : bool
        Keep the coefficients of the active cubes after an isovalue change (the thesis' "high
        frame rate" variant; memory ``n_active * n_points * 8`` bytes) instead of computing a
        cube's coefficients from its 27 data values (into a small per-thread cache) when a ray
        first crosses one of its active tetrahedra.
    root_finder : str
        ``"bernstein"`` (guaranteed first root by Bernstein subdivision, default) or ``"newton"``
        (the references' Newton iteration from three starts; cubic models only).
    """

    name = "type6"
    #: Cube ``c`` depends on padded voxels ``c .. c + 2`` per axis.
    support = 2
    degree = 3

    def __init__(
        self, volume: Volume, tables: Type6Tables, prefilter: bool = False,
        precompute: bool = False, root_finder: str = "bernstein", scheme: int = 0,
    ) -> None:
        if not isinstance(volume, Volume):
            raise ParameterError(f"volume must be a splinecast.Volume, got {type(volume)}")
        if root_finder not in ROOT_FINDERS:
            raise ParameterError(
                f"root_finder must be one of {', '.join(ROOT_FINDERS)}, got {root_finder!r}"
            )
        require_renderable(volume)
        self.volume = volume
        self.tables = tables
        self.prefilter = bool(prefilter)
        self.precompute = bool(precompute)
        self.root_finder = root_finder
        pad = np.pad(np.asarray(volume.data), 1, mode="edge")
        stored = coefficient_dtype(pad.dtype)  # the voxels' precision, also when prefiltered
        if self.prefilter:
            pad = laplacian_prefilter(pad)
        self.pad = np.ascontiguousarray(pad, dtype=stored)
        self.n_cells = tuple(int(n) for n in volume.shape)
        self.tables_arrays = (
            np.ascontiguousarray(tables.tet_points),
            *tables.sparse(),
            barycentric_matrices(),
            decasteljau_tables(tables.degree),
        )
        self.scheme = int(scheme)
        self.program = SCHEMES[self.grid_class][self.scheme]()
        self.tolerance = rounding_tolerance(self.pad, self.program)
        self.cube_lo, self.cube_hi = cube_bounds(
            self.pad, *self.program.arrays, self.program.n_slots, tables.n_points,
            RELATIVE_ROUNDING,
        )

    # --------------------------------------------------------------------- model interface
    #: The traversal walks cubes in ``voxel index + shift`` (cube ``c`` is ``[c, c + 1]``).
    shift = 0.5
    #: The per-cell bounds of the block hierarchy are per-cube coefficient ranges.
    cube_bounded = True
    #: Rays are traced in tiles of 8 x 8 pixels so the per-thread cube cache serves neighbours.
    band_rows = 8
    tile = 8

    @property
    def value_overshoot(self) -> float:
        """Type-6 coefficients are affine combinations of the data with weights up to 9/8 in
        absolute sum (1/16 of the range beyond it); the Laplacian prefilter reaches up to 6/8 of
        the range beyond it (counted as a whole range)."""
        return 1.0 if self.prefilter else 1.0 / 16.0

    @property
    def grid_copy_dtype(self) -> np.dtype:
        """The padded data's dtype: ``kernel_grid`` converts a block into it."""
        return self.pad.dtype

    def prefilter_brick(self, data: np.ndarray, first: np.ndarray,
                        level_shape: Any) -> tuple[np.ndarray, np.ndarray]:
        """With ``prefilter=True``, :func:`laplacian_prefilter_brick` of the brick; otherwise
        the brick as it is."""
        if not self.prefilter:
            return data, first
        return laplacian_prefilter_brick(data, first, level_shape)

    def active_cell_classifier(self) -> ActiveCellClassifier:
        """The model itself: it classifies cubes and tetrahedra by isovalue
        (:meth:`tet_masks`, :meth:`coefficient_rows`)."""
        return self

    @property
    def prepared(self) -> np.ndarray:
        """The clamp-padded data: cube ``c`` depends on ``prepared[c .. c + 2]``."""
        return self.pad

    @property
    def coefficients(self) -> np.ndarray:
        """The values that bound the reconstruction cube by cube (here: the padded data)."""
        return self.pad

    def domain(self) -> tuple[np.ndarray, np.ndarray]:
        """The box rendered, in voxel index space: ``[-1/2, n - 1/2]`` per axis."""
        return np.full(3, -0.5), np.asarray(self.volume.shape, np.float64) - 0.5

    def cube_bounds_of(self, pad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Exact per-cube coefficient ranges of a block of :attr:`prepared` (see
        :func:`cube_bounds`); the model's own for its whole padded data."""
        if pad is self.pad:
            return self.cube_lo, self.cube_hi
        return cube_bounds(np.ascontiguousarray(pad, dtype=self.pad.dtype), *self.program.arrays,
                           self.program.n_slots, self.tables.n_points, RELATIVE_ROUNDING)

    def kernel_grid(self, array: np.ndarray | None = None, active: Any = None) -> tuple:
        """The kernel grid (:data:`~.type6_ray.S31Grid` or :data:`~.type6_ray.QSSGrid`) of
        ``array`` (a block of :attr:`prepared` with its ghost layers; default: the whole volume).

        ``active`` is an isovalue classification of the whole volume
        (:class:`splinecast.accel.active_cells.ActiveCells`): its cube slots, tetrahedron masks
        and (with ``precompute=True``) stored coefficients then replace the bounds.
        """
        pad = self.pad if array is None else np.ascontiguousarray(array, dtype=self.pad.dtype)
        lo, hi = self.cube_bounds_of(pad)
        if active is not None and array is None:
            slot, mask, coeffs = active.slot, active.tet_mask, active.coeffs
        else:
            slot = np.zeros((0, 0, 0), np.int32)
            mask = np.zeros(0, np.uint32)
            coeffs = np.zeros((0, self.n_points))
        tet_points, _, _, _, bary, steps = self.tables_arrays
        return self.grid_class(pad, lo, hi, slot, mask, coeffs, tet_points, bary, steps,
                               self.root_finder == "newton", self.scheme)

    @property
    def grid_class(self) -> type:
        """:data:`S31Grid` for a cubic scheme, :data:`QSSGrid` for a quadratic one."""
        return S31Grid if self.tables.degree == 3 else QSSGrid

    @property
    def n_points(self) -> int:
        """Distinct Bernstein–Bézier coefficients per cube."""
        return self.tables.n_points

    # ------------------------------------------------------------- isovalue classification
    def tet_masks(self, cubes: np.ndarray, iso: float) -> np.ndarray:
        """24-bit masks of the tetrahedra of ``cubes`` (linear indices) whose coefficient range
        holds ``iso`` (conservative; see :func:`classify_tets`)."""
        prog = self.program
        return classify_tets(self.pad, cubes, np.asarray(self.n_cells, np.int64),
                             self.tables_arrays[0], *prog.arrays, prog.n_slots, float(iso),
                             self.tolerance)

    def coefficient_rows(self, cubes: np.ndarray) -> np.ndarray:
        """All coefficients of ``cubes`` (linear indices), shape ``(len(cubes), n_points)``."""
        prog = self.program
        return store_coefficients(self.pad, cubes, np.asarray(self.n_cells, np.int64),
                                  *prog.arrays, prog.n_slots, self.n_points)

    @cached_property
    def static_nbytes(self) -> int:
        """Memory held independently of the isovalue: padded data, cube bounds, tables."""
        return int(self.pad.nbytes + self.cube_lo.nbytes + self.cube_hi.nbytes
                   + sum(a.nbytes for a in self.tables_arrays))

    @property
    def nbytes(self) -> int:
        """Memory held by the model: padded data, cube bounds and tables."""
        return self.static_nbytes

    def evaluate(self, points: np.ndarray) -> np.ndarray:
        """Spline values at index-space points, shape (..., 3) -> (...) (clamped into the
        domain)."""
        lead = np.shape(points)[:-1]
        return evaluate_points(self, points)[0].reshape(lead)

    def gradient(self, points: np.ndarray) -> np.ndarray:
        """Index-space gradient at index-space points, shape (..., 3) -> (..., 3) (divide by
        spacing for world units)."""
        lead = np.shape(points)[:-1]
        return evaluate_points(self, points)[1].reshape(*lead, 3)

    def cube_coefficients(self, i: int, j: int, k: int) -> np.ndarray:
        """All distinct coefficients of cube ``(i, j, k)`` (float64, in the tables' point order)."""
        v27 = self.pad[i:i + 3, j:j + 3, k:k + 3].astype(np.float64).reshape(27)
        return self.tables.weight_matrix() @ v27
