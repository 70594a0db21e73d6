"""Tensor-product B-splines of degree 1, 2 and 3 (Steinberger 2010): the model, its cell functions.

The reconstruction is ``f(x) = sum_m a_m B_d(x - m)`` per axis (tensor product in 3D), with ``B_d``
the centred uniform B-spline of degree ``d`` and ``x`` the voxel index (voxel ``v`` at ``x = v``,
see :mod:`splinecast.volume`). This is exactly the convention of
``scipy.ndimage.map_coordinates(a, x, order=d, mode="mirror", prefilter=False)``.

Coefficients
    By default the voxel values *are* the coefficients ``a`` (smoothing reconstruction, the
    thesis' choice: the surface does not pass through the samples, it is a low-pass of them).
    With ``prefilter=True`` they are first converted to interpolating coefficients
    (``scipy.ndimage.spline_filter`` with ``mode="mirror"``), so ``f(v) = data[v]`` at every voxel
    (to the voxels' precision: the coefficients are computed in float64 and stored as float32
    for float32 and 8/16-bit voxels, as float64 otherwise).

Boundary
    Outside the volume the coefficients are mirrored about the first and last voxel without
    repeating it (``a[-m] = a[m]``, numpy's ``"reflect"`` padding, scipy's ``"mirror"`` mode).
    The reconstruction is only rendered inside the box spanned by the voxel centres (the same
    world box as trilinear), where this makes the normal derivative vanish on the box faces.

Knots and cells
    For odd ``d`` the knots are the voxel centres, so the polynomial pieces are the voxel
    intervals ``[v, v + 1]`` (``n - 1`` cells per axis), as for trilinear. For even ``d`` the
    centred B-spline has its knots *between* voxel centres, so the pieces are ``[v - 1/2,
    v + 1/2]``: ``n`` cells per axis whose first and last are cut in half by the box. Kernels
    work in *spline index space* ``s = x + h`` with ``h = 1/2`` for even and ``0`` for odd
    degree, where cell ``c`` is ``[c, c + 1]``.

Layout
    The padded coefficient array ``P`` (``d // 2`` mirrored layers on each side) is laid out so
    that cell ``c`` depends on exactly ``P[c .. c + d]`` per axis: ``support = d`` for the
    min/max block hierarchy, whose bound is then the convex hull of the (d+1)^3 influence
    coefficients. Without prefilter, ``P`` keeps the voxels' dtype.

Per-cell polynomials
    The (d+1)^3 influence coefficients of a cell are transformed on the fly, one axis at a time,
    with the integer matrices below to the scaled Bernstein or power form of the cell's
    polynomial in local coordinates ``u in [0, 1]^3``. The factors ``1/2`` (quadratic) and ``1/6``
    (cubic) are left out, so the transformed coefficients are ``E = SCALE[d]^3`` times the true
    ones and integer data is transformed exactly; the renderer compares against ``E * iso``.
"""

from __future__ import annotations

from collections import namedtuple
from typing import Any

import numpy as np

from .._jit import jit
from ..errors import ParameterError
from ..roots.first_root import DEFAULT_ITERATIONS, POWER_FORM_FINDERS, finder_id
from ..volume import Volume
from .base import BrickRefusal, ReconstructionModel
from .shading_field import whole_halo
from .storage import coefficient_dtype, kernel_array
from .validation import require_renderable

__all__ = [
    "BSplineModel",
    "BSpline1Model",
    "BSpline2Model",
    "BSpline3Model",
    "SB_MATRIX",
    "POWER_MATRIX",
    "SCALE",
    "knot_offset",
    "pad_width",
    "cell_transform",
    "basis_weights",
    "evaluate",
    "gradient",
    "BSplineGrid",
]

#: Kernel grid of the B-spline models (hooks in :mod:`.bspline_ray`): padded coefficients (cell
#: ``c`` needs ``coeffs[c .. c + degree]``), the degree, whether the ray composition is in power
#: form, the root finder (:mod:`splinecast.roots.first_root` id, iterations, tolerance), and
#: the shading field's halo and box (:mod:`.shading_field`; degree 1 only, the others shade
#: with their own gradient).
BSplineGrid = namedtuple("BSplineGrid", ["coeffs", "degree", "power", "finder", "iterations",
                                         "tol", "halo", "halo_box"])

# Rows: scaled Bernstein basis u^r (1-u)^(d-r); columns: the d+1 B-spline pieces on the cell
# (times SCALE[d]). Derived from the uniform B-spline segment polynomials; Steinberger 2010
# prints the quadratic one with an error, this is the corrected one (tests/test_bspline.py).
_SB = {
    1: [[1, 0], [0, 1]],
    2: [[1, 1, 0], [0, 4, 0], [0, 1, 1]],
    3: [[1, 4, 1, 0], [0, 12, 6, 0], [0, 6, 12, 0], [0, 1, 4, 1]],
}
# Rows: powers u^r; columns as above (times SCALE[d]).
_POWER = {
    1: [[1, 0], [-1, 1]],
    2: [[1, 1, 0], [-2, 2, 0], [1, -2, 1]],
    3: [[1, 4, 1, 0], [-3, 0, 3, 0], [3, -6, 3, 0], [-1, 3, -3, 1]],
}


def _stack(mats: dict[int, list[list[int]]]) -> np.ndarray:
    out = np.zeros((4, 4, 4))
    for d, m in mats.items():
        out[d, : d + 1, : d + 1] = m
    return out


#: ``SB_MATRIX[d]`` (zero-padded to 4x4): B-spline coefficients -> scaled Bernstein, times SCALE[d].
SB_MATRIX = _stack(_SB)
#: ``POWER_MATRIX[d]`` (zero-padded to 4x4): B-spline coefficients -> power form, times SCALE[d].
POWER_MATRIX = _stack(_POWER)
#: Per-axis factor left out of the matrices: 1, 1, 2, 6 for degree 0..3.
SCALE = np.array([1.0, 1.0, 2.0, 6.0])


def knot_offset(degree: int) -> float:
    """``h`` with spline index ``s = x + h``: 1/2 for even degree, 0 for odd."""
    return 0.5 if degree % 2 == 0 else 0.0


def pad_width(degree: int) -> int:
    """Mirrored coefficient layers added on each side of the volume."""
    return degree // 2


@jit()
def cell_transform(
    coeffs: np.ndarray, i: int, j: int, k: int, d: int, matrix: np.ndarray, out: np.ndarray,
    tmp: np.ndarray,
) -> tuple[float, float]:
    """Transform the influence coefficients of cell ``(i, j, k)`` with ``matrix`` (4x4).

    ``out[a, b, c]`` (shape at least (4, 4, 4)) receives the cell's polynomial coefficients,
    scaled by ``SCALE[d]^3``; ``tmp`` is scratch of the same shape. Returns the smallest and
    largest influence coefficient (the convex-hull bound of the cell's values).
    """
    n = d + 1
    vmin = np.inf
    vmax = -np.inf
    # Along z: tmp[a, b, r] = sum_c M[r, c] P[i+a, j+b, k+c]
    for a in range(n):
        for b in range(n):
            for r in range(n):
                tmp[a, b, r] = 0.0
            for c in range(n):
                v = float(coeffs[np.uint64(i + a), np.uint64(j + b), np.uint64(k + c)])
                vmin = min(vmin, v)
                vmax = max(vmax, v)
                for r in range(n):
                    tmp[a, b, r] += matrix[r, c] * v
    # Along y: out[a, q, r] = sum_b M[q, b] tmp[a, b, r]
    for a in range(n):
        for q in range(n):
            for r in range(n):
                acc = 0.0
                for b in range(n):
                    acc += matrix[q, b] * tmp[a, b, r]
                out[a, q, r] = acc
    # Along x: tmp[p, q, r] = sum_a M[p, a] out[a, q, r]; copied back into out.
    for p in range(n):
        for q in range(n):
            for r in range(n):
                acc = 0.0
                for a in range(n):
                    acc += matrix[p, a] * out[a, q, r]
                tmp[p, q, r] = acc
    for p in range(n):
        for q in range(n):
            for r in range(n):
                out[p, q, r] = tmp[p, q, r]
    return vmin, vmax


@jit(inline="always")
def basis_weights(d: int, u: float) -> tuple:
    """Values and derivatives at local ``u`` of the ``d + 1`` B-spline pieces acting on a cell.

    Returns two 4-tuples ``(w, dw)`` (entries past ``d`` are 0), exact values with the SCALE
    factor divided out. Tuples, not arrays, so the hot path allocates nothing.
    """
    inv = 1.0 / SCALE[d]
    w0 = w1 = w2 = w3 = 0.0
    g0 = g1 = g2 = g3 = 0.0
    for a in range(d + 1):
        value = 0.0
        deriv = 0.0
        for r in range(d, -1, -1):  # Horner with derivative
            deriv = deriv * u + value
            value = value * u + POWER_MATRIX[d, r, a]
        if a == 0:
            w0, g0 = value * inv, deriv * inv
        elif a == 1:
            w1, g1 = value * inv, deriv * inv
        elif a == 2:
            w2, g2 = value * inv, deriv * inv
        else:
            w3, g3 = value * inv, deriv * inv
    return (w0, w1, w2, w3), (g0, g1, g2, g3)


@jit(inline="always")
def _cell_and_local(s: float, n_cells: int) -> tuple[int, float]:
    c = int(np.floor(s))
    if c < 0:
        c = 0
    elif c > n_cells - 1:
        c = n_cells - 1
    return c, s - c


@jit()
def local_value_gradient(
    coeffs: np.ndarray, d: int, i: int, j: int, k: int, ux: float, uy: float, uz: float,
) -> tuple[float, float, float, float]:
    """Value and index-space gradient ``(f, fx, fy, fz)`` of the spline in cell ``(i, j, k)`` at
    local coordinates ``u``, straight from the B-spline basis (no per-cell transform)."""
    wx, gx = basis_weights(d, ux)
    wy, gy = basis_weights(d, uy)
    wz, gz = basis_weights(d, uz)
    f = 0.0
    fx = 0.0
    fy = 0.0
    fz = 0.0
    for a in range(d + 1):
        for b in range(d + 1):
            for c in range(d + 1):
                v = float(coeffs[np.uint64(i + a), np.uint64(j + b), np.uint64(k + c)])
                f += wx[a] * wy[b] * wz[c] * v
                fx += gx[a] * wy[b] * wz[c] * v
                fy += wx[a] * gy[b] * wz[c] * v
                fz += wx[a] * wy[b] * gz[c] * v
    return f, fx, fy, fz


@jit()
def _evaluate(coeffs: np.ndarray, d: int, h: float, points: np.ndarray, out: np.ndarray) -> None:
    ncx = coeffs.shape[0] - d
    ncy = coeffs.shape[1] - d
    ncz = coeffs.shape[2] - d
    nvx = ncx - (1 if h > 0.0 else 0)  # last voxel index: n - 1
    nvy = ncy - (1 if h > 0.0 else 0)
    nvz = ncz - (1 if h > 0.0 else 0)
    for m in range(points.shape[0]):
        # Clamp to the voxel box, then move to spline index space.
        x = min(max(points[m, 0], 0.0), float(nvx)) + h
        y = min(max(points[m, 1], 0.0), float(nvy)) + h
        z = min(max(points[m, 2], 0.0), float(nvz)) + h
        i, ux = _cell_and_local(x, ncx)
        j, uy = _cell_and_local(y, ncy)
        k, uz = _cell_and_local(z, ncz)
        f, fx, fy, fz = local_value_gradient(coeffs, d, i, j, k, ux, uy, uz)
        out[m, 0] = f
        out[m, 1] = fx
        out[m, 2] = fy
        out[m, 3] = fz


def evaluate(coeffs: np.ndarray, degree: int, points: np.ndarray) -> np.ndarray:
    """Spline values at voxel-index points, shape (m, 3) -> (m,); points are clamped to the box.

    ``coeffs`` is a model's padded coefficient array (:attr:`BSplineModel.coefficients`).
    """
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    out = np.empty((pts.shape[0], 4))
    _evaluate(coeffs, int(degree), knot_offset(degree), pts, out)
    return out[:, 0]


def gradient(coeffs: np.ndarray, degree: int, points: np.ndarray) -> np.ndarray:
    """Voxel-index-space gradient at points, shape (m, 3) -> (m, 3) (clamped to the box)."""
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    out = np.empty((pts.shape[0], 4))
    _evaluate(coeffs, int(degree), knot_offset(degree), pts, out)
    return out[:, 1:]


class BSplineModel(ReconstructionModel):
    """Tensor-product B-spline reconstruction of one degree, prepared from a volume.

    Use the subclasses (``model="bspline1" | "bspline2" | "bspline3"``); see the module
    docstring for the conventions.

    Parameters
    ----------
    volume : Volume
        The data; at least 2 voxels per axis, no NaN or infinity.
    prefilter : bool
        Convert the voxels to interpolating coefficients first (needs scipy, the ``spline``
        extra). Default False: the voxels are the coefficients.
    root_finder : str
        ``"bernstein"`` (default), ``"rfbs"``, ``"sturm"`` or ``"newton"``; see
        :mod:`splinecast.roots.first_root`. The Bernstein-form finders compose the ray profile
        in scaled Bernstein form, the others in power form.
    iterations : int, optional
        Iteration budget of the root finder (default: its own, generous enough to converge).
    tolerance : float
        Convergence tolerance of the root finder in the per-cell ray parameter (0..1).

    Raises
    ------
    DataError
        If the volume is too small or holds non-finite values.
    ParameterError
        For an unknown root finder or an impossible iteration count or tolerance.
    """

    name = "bspline"
    degree = 0
    #: The coefficients are mirrored beyond the ends (:func:`pad_width`), as SciPy's
    #: ``mode="mirror"`` does.
    border_rule = "reflect"
    #: Render methods the kernel implements.
    methods = ("exact",)

    def __init__(
        self,
        volume: Volume,
        prefilter: bool = False,
        root_finder: str = "bernstein",
        iterations: int | None = None,
        tolerance: float = 1e-12,
    ) -> None:
        d = self.degree
        require_renderable(volume)
        self.root_finder_id = finder_id(root_finder)
        self.root_finder = root_finder
        if iterations is None:
            iterations = DEFAULT_ITERATIONS[root_finder]
        if isinstance(iterations, bool) or int(iterations) != iterations or iterations < 1:
            raise ParameterError(f"iterations must be a positive integer, got {iterations!r}")
        self.iterations = int(iterations)
        if not (np.isfinite(tolerance) and 0 < tolerance < 1):
            raise ParameterError(f"tolerance must be in (0, 1), got {tolerance!r}")
        self.tolerance = float(tolerance)
        self.prefilter = bool(prefilter)
        self.volume = volume
        data = volume.data
        if self.prefilter and d > 1:
            from scipy import ndimage  # lazy: scipy is an optional extra ("spline")

            # Computed in float64, stored at the voxels' precision (float32 for float32 and
            # 8/16-bit data): the float32 kernels serve it, at half the memory.
            data = ndimage.spline_filter(
                np.asarray(data, dtype=np.float64), order=d, output=np.float64, mode="mirror"
            ).astype(coefficient_dtype(data.dtype), copy=False)
        else:
            data = kernel_array(data)  # one kernel for 8/16-bit integers and float32 (exact)
        pad = pad_width(d)
        if pad:
            self.coeffs = np.pad(data, pad, mode="reflect")
        else:
            self.coeffs = np.ascontiguousarray(data)
        self.n_cells = tuple(int(s) - d for s in self.coeffs.shape)

    #: cell ``c`` depends on coefficients ``c .. c + support`` per axis (set per subclass).
    support = 0

    @classmethod
    def brick_refusal(cls, options: dict[str, Any]) -> BrickRefusal | None:
        """Interpolating coefficients (``prefilter=True``) cannot be made brick by brick."""
        if options.get("prefilter"):
            return BrickRefusal("prefilter=True", "the interpolating B-spline coefficients depend "
                                "on the whole volume, a brick cannot reproduce them (render the "
                                "voxels as coefficients, the default, or use s31)")
        return None

    @property
    def shift(self) -> float:
        """The traversal walks cells in ``voxel index + shift`` (the knot offset ``h``)."""
        return knot_offset(self.degree)

    @property
    def prepared(self) -> np.ndarray:
        """The padded coefficients: cell ``c`` depends on ``prepared[c .. c + degree]``."""
        return self.coeffs

    def domain(self) -> tuple[np.ndarray, np.ndarray]:
        """The box rendered, in voxel index space: the box spanned by the voxel centres."""
        return np.zeros(3), np.asarray(self.volume.shape, np.float64) - 1.0

    def kernel_grid(self, array: np.ndarray | None = None,
                    halo: tuple[np.ndarray, np.ndarray] | None = None) -> tuple:
        """The :class:`BSplineGrid` of ``array`` (a block of :attr:`prepared` with its ghost
        layers; default: the whole volume) and, for degree 1, the shading field's
        ``(halo, box)`` (:mod:`.shading_field`; default: ``array`` itself, all of it real)."""
        coeffs = self.coeffs if array is None else np.ascontiguousarray(array)
        halo_array, box = whole_halo(coeffs) if halo is None else halo
        # The halo is often the grid's own array (a whole volume, a pyramid brick): no copy.
        halo_array = coeffs if halo_array is array else np.ascontiguousarray(halo_array)
        return BSplineGrid(coeffs, self.degree, self.root_finder_id in POWER_FORM_FINDERS,
                           self.root_finder_id, self.iterations, self.tolerance, halo_array, box)

    @property
    def coefficients(self) -> np.ndarray:
        """The padded coefficients; cell ``c`` is bounded by ``coefficients[c .. c + d]``."""
        return self.coeffs

    @property
    def nbytes(self) -> int:
        """Memory held by the prepared arrays."""
        return int(self.coeffs.nbytes) if self.coeffs is not self.volume.data else 0

    def evaluate(self, points: np.ndarray) -> np.ndarray:
        """Reconstructed values at voxel-index points, shape (m, 3) (clamped to the box)."""
        return evaluate(self.coeffs, self.degree, points)

    def gradient(self, points: np.ndarray) -> np.ndarray:
        """Gradient per voxel-index unit at points, shape (m, 3) -> (m, 3)."""
        return gradient(self.coeffs, self.degree, points)


class BSpline1Model(BSplineModel):
    """Trilinear B-spline (degree 1): the same function as ``trilinear``, via the spline path."""

    name = "bspline1"
    degree = 1
    support = 1
    nested_degree = 1
    typical_compile_s = 45
    #: Voxels the shading field reads beyond a cell's support (:mod:`.shading_field`): the
    #: linear B-spline's gradient jumps between cells, as the trilinear one's.
    shading_halo = 1
    #: Rays are traced in tiles of 8 x 8 pixels, as the trilinear model's: neighbouring rays
    #: read the same coefficients while they are in the cache. Degree 3 keeps rows: its cells
    #: cost root finding rather than loads, and tiles measured slower there.
    band_rows = 8
    tile = 8


class BSpline2Model(BSplineModel):
    """Triquadratic B-spline (C1)."""

    name = "bspline2"
    degree = 2
    support = 2
    typical_compile_s = 60
    #: Tiles of 8 x 8 pixels, as :class:`BSpline1Model`.
    band_rows = 8
    tile = 8


class BSpline3Model(BSplineModel):
    """Tricubic B-spline (C2)."""

    name = "bspline3"
    degree = 3
    support = 3
    nested_degree = 3
    typical_compile_s = 70
