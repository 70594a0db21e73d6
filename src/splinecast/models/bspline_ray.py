"""A B-spline cell's polynomial restricted to a ray segment: one univariate polynomial of degree 3d.

On the segment from local point ``a`` (entry) to ``b`` (exit) of a cell, ``u(s) = a + s (b - a)``
with ``s in [0, 1]``. The cell polynomial ``F(u) = sum_{pqr} T_pqr X_p(u_x) Y_q(u_y) Z_r(u_z)``
(tensor coefficients ``T`` from :func:`splinecast.models.bspline.cell_transform`) becomes

    ``g(s) = sum_p X_p(s) * ( sum_q Y_q(s) * ( sum_r T_pqr Z_r(s) ) )``

where ``*`` is polynomial multiplication, evaluated inside out so only one inner sum of degree
``d`` and one middle sum of degree ``2d`` are live (Steinberger 2010, section 3.3.2):

* **scaled Bernstein** (the stable default): ``X_p(u) = u^p (1 - u)^(d - p)``; along the segment
  ``u`` and ``1 - u`` are linear with scaled Bernstein coefficients ``(a, b)`` and
  ``(1 - a, 1 - b)``, and in the scaled Bernstein basis multiplication *is* convolution of the
  coefficient sequences, so ``g`` comes out in scaled Bernstein form of degree 3d without any
  change of basis. All intermediate quantities are convex-like combinations of values in
  ``[0, 1]``, which is why the rounding error stays at the level of the coefficients.
* **power form**: ``X_p(u) = u^p`` and ``u = a + s (b - a)``; convolution of power coefficients.
* **naive** (benchmark baseline only): every one of the (d+1)^3 terms expanded on its own.

Every result is scaled by ``E = SCALE[d]^3`` like the tensor coefficients;
:func:`segment_polynomial` divides it out for callers outside the kernels.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import jit
from ..roots.bernstein import binomial
from ..roots.pieces import PolyN, polyn_workspace
from .bspline import (
    POWER_MATRIX,
    SB_MATRIX,
    SCALE,
    BSplineGrid,
    cell_transform,
    local_value_gradient,
)
from .pieces import register
from .shading_field import halo_gradient

__all__ = [
    "axis_basis_sb",
    "axis_basis_power",
    "compose",
    "compose_naive",
    "segment_polynomial",
    "FORMS",
]

#: Composition forms by name.
FORMS = {"bernstein": 0, "power": 1, "naive": 2}


@jit(inline="always")
def axis_basis_sb(a: float, b: float, d: int, out: np.ndarray) -> None:
    """``out[p, :d+1]``: scaled Bernstein coefficients in ``s`` of ``u^p (1 - u)^(d - p)`` for
    ``u = a + s (b - a)``."""
    qa = 1.0 - a
    qb = 1.0 - b
    for p in range(d + 1):
        # Start from the constant 1 and multiply by (a, b) p times and (1-a, 1-b) d-p times;
        # multiplying by a linear (x0, x1) in scaled Bernstein form: c'_k = x0 c_k + x1 c_{k-1}.
        out[p, 0] = 1.0
        length = 1
        for m in range(d):
            x0, x1 = (a, b) if m < p else (qa, qb)
            out[p, length] = x1 * out[p, length - 1]
            for k in range(length - 1, 0, -1):
                out[p, k] = x0 * out[p, k] + x1 * out[p, k - 1]
            out[p, 0] = x0 * out[p, 0]
            length += 1


@jit(inline="always")
def axis_basis_power(a: float, b: float, d: int, out: np.ndarray) -> None:
    """``out[p, :d+1]``: power coefficients in ``s`` of ``u^p`` for ``u = a + s (b - a)``
    (zero above degree ``p``)."""
    e = b - a
    for k in range(d + 1):
        out[0, k] = 0.0
    out[0, 0] = 1.0
    for p in range(1, d + 1):
        out[p, 0] = a * out[p - 1, 0]
        for k in range(1, d + 1):
            out[p, k] = a * out[p - 1, k] + e * out[p - 1, k - 1]


@jit()
def compose(
    tensor: np.ndarray, bx: np.ndarray, by: np.ndarray, bz: np.ndarray, d: int,
    inner: np.ndarray, middle: np.ndarray, out: np.ndarray,
) -> None:
    """``out[:3d+1]`` = ``sum_p bx[p] * (sum_q by[q] * (sum_r tensor[p,q,r] bz[r]))``.

    ``bx, by, bz`` are per-axis basis polynomials (rows, from :func:`axis_basis_sb` or
    :func:`axis_basis_power`); the form of the result is theirs. ``inner`` (>= d+1) and ``middle``
    (>= 2d+1) are scratch.
    """
    n = d + 1
    for k in range(3 * d + 1):
        out[k] = 0.0
    for p in range(n):
        for k in range(2 * d + 1):
            middle[k] = 0.0
        for q in range(n):
            for k in range(n):
                acc = 0.0
                for r in range(n):
                    acc += tensor[p, q, r] * bz[r, k]
                inner[k] = acc
            for i in range(n):
                y = by[q, i]
                for k in range(n):
                    middle[i + k] += y * inner[k]
        for i in range(n):
            x = bx[p, i]
            for k in range(2 * d + 1):
                out[i + k] += x * middle[k]


@jit()
def compose_naive(
    tensor: np.ndarray, ax: float, ay: float, az: float, bx: float, by: float, bz: float, d: int,
    term: np.ndarray, out: np.ndarray,
) -> None:
    """Power form of the segment polynomial with each term ``T_pqr u_x^p u_y^q u_z^r`` expanded
    separately (the "naive" baseline of Steinberger 2010; ``tensor`` in power form)."""
    ex, ey, ez = bx - ax, by - ay, bz - az
    for k in range(3 * d + 1):
        out[k] = 0.0
    for p in range(d + 1):
        for q in range(d + 1):
            for r in range(d + 1):
                term[0] = tensor[p, q, r]
                length = 1
                for m in range(p + q + r):
                    if m < p:
                        c0, c1 = ax, ex
                    elif m < p + q:
                        c0, c1 = ay, ey
                    else:
                        c0, c1 = az, ez
                    term[length] = c1 * term[length - 1]
                    for k in range(length - 1, 0, -1):
                        term[k] = c0 * term[k] + c1 * term[k - 1]
                    term[0] = c0 * term[0]
                    length += 1
                for k in range(length):
                    out[k] += term[k]


@jit()
def _segment(
    coeffs: np.ndarray, d: int, cell: tuple, a: tuple, b: tuple, form: int, out: np.ndarray,
) -> None:
    """:func:`segment_polynomial` into ``out`` (``cell``: ``(i, j, k)``; ``a``, ``b``: the
    local end points as ``(x, y, z)`` tuples; ``form``: an entry of :data:`FORMS`)."""
    i, j, k = cell
    ax, ay, az = a
    bx, by, bz = b
    tensor = np.empty((4, 4, 4))
    tmp = np.empty((4, 4, 4))
    matrix = SB_MATRIX[d] if form == 0 else POWER_MATRIX[d]
    cell_transform(coeffs, i, j, k, d, matrix, tensor, tmp)
    if form == 2:
        compose_naive(tensor, ax, ay, az, bx, by, bz, d, np.empty(3 * d + 1), out)
    else:
        basis = np.empty((3, 4, 4))
        if form == 0:
            axis_basis_sb(ax, bx, d, basis[0])
            axis_basis_sb(ay, by, d, basis[1])
            axis_basis_sb(az, bz, d, basis[2])
        else:
            axis_basis_power(ax, bx, d, basis[0])
            axis_basis_power(ay, by, d, basis[1])
            axis_basis_power(az, bz, d, basis[2])
        compose(tensor, basis[0], basis[1], basis[2], d, np.empty(4), np.empty(7), out)
    scale = SCALE[d] ** 3
    n = 3 * d
    for m in range(n + 1):
        out[m] /= scale
        if form == 0:
            out[m] /= binomial(n, m)  # scaled Bernstein -> control points


def segment_polynomial(
    coeffs: np.ndarray, degree: int, cell: tuple[int, int, int], entry: np.ndarray,
    exit: np.ndarray, form: str = "bernstein",
) -> np.ndarray:
    """The spline along a segment inside one cell as a univariate polynomial in ``s in [0, 1]``.

    Parameters
    ----------
    coeffs : ndarray
        A model's padded coefficients (:attr:`BSplineModel.coefficients`).
    degree : int
        1, 2 or 3.
    cell : 3 ints
        The cell index (spline index space, see :mod:`splinecast.models.bspline`).
    entry, exit : 3 floats
        Segment end points in the cell's local coordinates (``[0, 1]^3``).
    form : str
        ``"bernstein"`` (control points), ``"power"`` or ``"naive"`` (power form, computed term
        by term).

    Returns
    -------
    ndarray, shape (3 * degree + 1,)
        The coefficients (true scale, ``SCALE^3`` divided out).
    """
    out = np.empty(3 * int(degree) + 1)
    a = np.asarray(entry, dtype=np.float64)
    b = np.asarray(exit, dtype=np.float64)
    i, j, k = (int(c) for c in cell)
    _segment(coeffs, int(degree), (i, j, k), (float(a[0]), float(a[1]), float(a[2])),
             (float(b[0]), float(b[1]), float(b[2])), FORMS[form], out)
    return out


# ----------------------------------------------------------------------------- ray pieces
@jit()
def _cell_count(grid):
    c, d = grid.coeffs, grid.degree
    return c.shape[0] - d, c.shape[1] - d, c.shape[2] - d


#: Entries of the per-thread cell cache (:func:`_cached_cell`): direct-mapped by the low bits of
#: the cell index, so the cells of any 4 x 4 x 8 box have distinct entries.
CACHE_ENTRIES = 128

#: Relative widening of a cell's Bernstein range (:func:`_cached_cell`): far above the rounding
#: of the transform and of a segment's composition (tens of ``eps``), so a segment polynomial's
#: control points, as computed, never leave the widened range.
_RANGE_SLACK = 1e-10

#: ``_CONTROL_WEIGHTS[d, p] = 1 / (SCALE[d] C(d, p))``: per axis, what turns a cell's scaled
#: Bernstein coefficient (times ``SCALE[d]``) into a Bernstein control point.
_CONTROL_WEIGHTS = np.array([[1.0 / (SCALE[d] * math.comb(d, p)) if p <= d else 0.0
                              for p in range(4)] for d in range(4)])


@jit()
def _new_scratch(grid):
    n = 3 * grid.degree
    inv = np.empty(n + 1)
    scale = SCALE[grid.degree] ** 3
    for m in range(n + 1):
        # True-scale coefficients: the matrices carry SCALE^3, the Bernstein form C(n, m).
        inv[m] = 1.0 / scale if grid.power else 1.0 / (scale * binomial(n, m))
    coeffs, tmp, work, degrees, stack, spans, cand = polyn_workspace()
    keys = np.full(CACHE_ENTRIES, -1, np.int64)
    return (np.empty((4, 4, 4)), np.empty((4, 4, 4)), np.empty((3, 4, 4)), np.empty(4),
            np.empty(7), inv, coeffs, tmp, work, degrees, stack, spans, cand,
            keys, np.empty((CACHE_ENTRIES, 4, 4, 4)), np.empty((CACHE_ENTRIES, 2)))


@jit(inline="always")
def _ic_range(coeffs, i, j, k, d):
    """Smallest and largest influence coefficient of cell ``(i, j, k)`` (the convex hull)."""
    vmin = np.inf
    vmax = -np.inf
    for a in range(d + 1):
        for b in range(d + 1):
            for c in range(d + 1):
                v = float(coeffs[np.uint64(i + a), np.uint64(j + b), np.uint64(k + c)])
                vmin = min(vmin, v)
                vmax = max(vmax, v)
    return vmin, vmax


@jit()
def _cell_load(grid, scratch, i, j, k):
    return _ic_range(grid.coeffs, i, j, k, grid.degree)


@jit()
def _fill_cell(coeffs, d, power, i, j, k, tensor, tmp, bounds):
    """The cell's transformed coefficients into ``tensor`` and its value range into ``bounds``
    (a cache miss: kept out of line, with only the arrays it needs)."""
    if power:
        lo, hi = cell_transform(coeffs, i, j, k, d, POWER_MATRIX[d], tensor, tmp)
    else:
        ic_lo, ic_hi = cell_transform(coeffs, i, j, k, d, SB_MATRIX[d], tensor, tmp)
        # The cell's Bernstein control points (the scaled Bernstein coefficients divided by
        # their binomial weights and SCALE^3) bound its polynomial more tightly than the
        # influence coefficients, which bound them in turn.
        w = _CONTROL_WEIGHTS[d]
        lo = math.inf
        hi = -math.inf
        for p in range(d + 1):
            for q in range(d + 1):
                wpq = w[p] * w[q]
                for r in range(d + 1):
                    v = tensor[p, q, r] * (wpq * w[r])
                    lo = min(lo, v)
                    hi = max(hi, v)
        slack = _RANGE_SLACK * max(abs(lo), abs(hi))
        lo = max(lo - slack, ic_lo)
        hi = min(hi + slack, ic_hi)
    bounds[0] = lo
    bounds[1] = hi


@jit(inline="always")
def _cached_cell(grid, scratch, i, j, k):
    """Entry of cell ``(i, j, k)`` in the thread's cell cache, filled on a miss.

    Neighbouring rays (the driver traces tiles of 8 x 8 pixels) test the same cells, and the
    transform of a cell's 64 influence coefficients cost about as much as the segment's
    composition; the cache keeps it, and the cell's Bernstein range, per cell."""
    keys, tensors, bounds = scratch[13], scratch[14], scratch[15]
    entry = ((i & 3) << 5) | ((j & 3) << 3) | (k & 7)
    nx, ny, nz = _cell_count(grid)
    lin = (np.int64(i) * ny + j) * nz + k
    if keys[entry] != lin:
        _fill_cell(grid.coeffs, grid.degree, grid.power, i, j, k, tensors[entry], scratch[1],
                   bounds[entry])
        keys[entry] = lin
    return entry


@jit(inline="always")
def _cell_pieces(grid, scratch, ctx, cell, a, e, cuts, tags):
    """The whole cell is one piece; its tag is the cell's entry in the cell cache, which holds
    its range (``piece_range``) and transform (``piece_poly`` builds the polynomial from it only
    for a piece a mode asks for)."""
    cuts[0] = 0.0
    cuts[1] = 1.0
    i, j, k = cell
    tags[0] = _cached_cell(grid, scratch, i, j, k)
    return 1


@jit()
def _piece_range(grid, scratch, ctx, i, j, k, tag):
    """The cell's Bernstein range (power form: its influence coefficients' range)."""
    return scratch[15][tag, 0], scratch[15][tag, 1]


@jit()
def _piece_poly(grid, scratch, ctx, cell, tag, a, b):
    """The segment's polynomial from the cell's cached transform (``tag``), into ``scratch[6]``."""
    ax, ay, az = a
    bx, by, bz = b
    d = grid.degree
    basis, inner, middle, inv = scratch[2], scratch[3], scratch[4], scratch[5]
    poly = scratch[6]
    if grid.power:
        axis_basis_power(ax, bx, d, basis[0])
        axis_basis_power(ay, by, d, basis[1])
        axis_basis_power(az, bz, d, basis[2])
    else:
        axis_basis_sb(ax, bx, d, basis[0])
        axis_basis_sb(ay, by, d, basis[1])
        axis_basis_sb(az, bz, d, basis[2])
    compose(scratch[14][tag], basis[0], basis[1], basis[2], d, inner, middle, poly)
    for m in range(3 * d + 1):
        poly[m] *= inv[m]
    return PolyN(poly, 3 * d, grid.power, grid.finder, grid.iterations,
                 grid.tol, scratch[7], scratch[8], scratch[9], scratch[10], scratch[11],
                 scratch[12])


@jit()
def _gradient(grid, scratch, ctx, i, j, k, tag, x, y, z):
    _, gx, gy, gz = local_value_gradient(grid.coeffs, grid.degree, i, j, k, x, y, z)
    return gx, gy, gz


@jit(inline="always")
def _locate(s, n_cells):
    c = int(math.floor(s))
    c = min(max(c, 0), n_cells - 1)
    return c, s - c


@jit()
def _value_gradient_at(grid, scratch, x, y, z):
    nx, ny, nz = _cell_count(grid)
    i, u = _locate(min(max(x, 0.0), float(nx)), nx)
    j, v = _locate(min(max(y, 0.0), float(ny)), ny)
    k, w = _locate(min(max(z, 0.0), float(nz)), nz)
    return local_value_gradient(grid.coeffs, grid.degree, i, j, k, u, v, w)


@jit()
def _separate_shading(grid):
    """The linear B-spline (degree 1, the trilinear function) shades with the smooth field;
    the quadratic and cubic ones are C1 and C2 and shade with their own gradient."""
    return grid.degree == 1


@jit()
def _shading_gradient_at(grid, scratch, x, y, z):
    """Degree 1: the cubic B-spline of the coefficients (:mod:`.shading_field`; odd degree:
    no knot shift, the traversal space is the coefficients' index space). Others: their own
    gradient."""
    if grid.degree == 1:
        return halo_gradient(grid.halo, grid.halo_box, x, y, z)
    _, gx, gy, gz = _value_gradient_at(grid, scratch, x, y, z)
    return gx, gy, gz


# Every hook is inlined into the per-pair loop; the cell's transform (on a cache miss) and the
# segment's composition stay calls (``_fill_cell``, ``compose``), taking only the arrays they need.
register(BSplineGrid, cell_count=_cell_count, new_scratch=_new_scratch,
         cell_load=_cell_load,
         cell_pieces=_cell_pieces, piece_range=_piece_range, piece_poly=_piece_poly,
         gradient=_gradient, value_gradient_at=_value_gradient_at,
         separate_shading=_separate_shading, shading_gradient_at=_shading_gradient_at)
