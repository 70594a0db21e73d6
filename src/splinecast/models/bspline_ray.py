"""A B-spline cell's polynomial restricted to a ray segment: one univariate polynomial of degree 3d.

On the segment from local point ``a`` (entry) to ``b`` (exit) of a cell, ``u(s) = a + s (b - a)``
with ``s in [0, 1]``. The cell polynomial ``F(u) = sum_{pqr} T_pqr X_p(u_x) Y_q(u_y) Z_r(u_z)``
(tensor coefficients ``T`` from :func:`splinecast.models.bspline.cell_transform`) becomes

    ``g(s) = sum_p X_p(s) * ( sum_q Y_q(s) * ( sum_r T_pqr Z_r(s) ) )``

where ``*`` is polynomial multiplication, evaluated inside out so only one inner sum of degree
``d`` and one middle sum of degree ``2d`` are live (reference 000, section 3.3.2):

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
from .pieces import cell_range, register

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
    separately (the reference 000 "naive" baseline; ``tensor`` in power form)."""
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
    coeffs: np.ndarray, d: int, i: int, j: int, k: int, ax: float, ay: float, az: float,
    bx: float, by: float, bz: float, form: int, out: np.ndarray,
) -> None:
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
    _segment(coeffs, int(degree), i, j, k, a[0], a[1], a[2], b[0], b[1], b[2], FORMS[form], out)
    return out


# ----------------------------------------------------------------------------- ray pieces
@jit()
def _cell_count(grid):
    c, d = grid.coeffs, grid.degree
    return c.shape[0] - d, c.shape[1] - d, c.shape[2] - d


@jit()
def _new_scratch(grid):
    n = 3 * grid.degree
    inv = np.empty(n + 1)
    scale = SCALE[grid.degree] ** 3
    for m in range(n + 1):
        # True-scale coefficients: the matrices carry SCALE^3, the Bernstein form C(n, m).
        inv[m] = 1.0 / scale if grid.power else 1.0 / (scale * binomial(n, m))
    coeffs, tmp, work, degrees, stack, spans, cand = polyn_workspace()
    return (np.empty((4, 4, 4)), np.empty((4, 4, 4)), np.empty((3, 4, 4)), np.empty(4),
            np.empty(7), inv, coeffs, tmp, work, degrees, stack, spans, cand)


@jit(inline="always")
def _ic_range(coeffs, i, j, k, d):
    """Smallest and largest influence coefficient of cell ``(i, j, k)`` (the convex hull)."""
    vmin = np.inf
    vmax = -np.inf
    for a in range(d + 1):
        for b in range(d + 1):
            for c in range(d + 1):
                v = float(coeffs[i + a, j + b, k + c])
                vmin = min(vmin, v)
                vmax = max(vmax, v)
    return vmin, vmax


@jit()
def _cell_load(grid, scratch, i, j, k):
    return _ic_range(grid.coeffs, i, j, k, grid.degree)


@jit(inline="always")
def _cell_pieces(grid, scratch, ctx, i, j, k, ax, ay, az, ex, ey, ez, cuts, tags):
    """The whole cell is one piece; its polynomial is built here, into ``scratch[6]``."""
    cuts[0] = 0.0
    cuts[1] = 1.0
    tags[0] = 0
    _build_poly(grid, scratch, i, j, k, ax, ay, az, ax + ex, ay + ey, az + ez)
    return 1


@jit(inline="always")
def _build_poly(grid, scratch, i, j, k, ax, ay, az, bx, by, bz):
    d = grid.degree
    tensor, tmp, basis, inner, middle, inv = (scratch[0], scratch[1], scratch[2], scratch[3],
                                              scratch[4], scratch[5])
    poly = scratch[6]
    n = 3 * d
    if grid.power:
        cell_transform(grid.coeffs, i, j, k, d, POWER_MATRIX[d], tensor, tmp)
        axis_basis_power(ax, bx, d, basis[0])
        axis_basis_power(ay, by, d, basis[1])
        axis_basis_power(az, bz, d, basis[2])
    else:
        cell_transform(grid.coeffs, i, j, k, d, SB_MATRIX[d], tensor, tmp)
        axis_basis_sb(ax, bx, d, basis[0])
        axis_basis_sb(ay, by, d, basis[1])
        axis_basis_sb(az, bz, d, basis[2])
    compose(tensor, basis[0], basis[1], basis[2], d, inner, middle, poly)
    for m in range(n + 1):
        poly[m] *= inv[m]


@jit()
def _piece_poly(grid, scratch, ctx, i, j, k, tag, ax, ay, az, bx, by, bz):
    """The polynomial :func:`_cell_pieces` built for the cell."""
    return PolyN(scratch[6], 3 * grid.degree, grid.power, grid.finder, grid.iterations,
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


# Every hook is inlined into the per-pair loop; the cell's transform and composition stay calls
# inside ``cell_pieces`` (``cell_transform``, ``compose``), taking only the arrays they need.
register(BSplineGrid, cell_count=_cell_count, new_scratch=_new_scratch,
         cell_load=_cell_load,
         cell_pieces=_cell_pieces, piece_range=cell_range, piece_poly=_piece_poly,
         gradient=_gradient, value_gradient_at=_value_gradient_at)
