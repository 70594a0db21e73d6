"""Trilinear interpolation: the cell functions of the exact trilinear isosurface renderer.

Inside cell ``(i, j, k)`` with local coordinates ``x, y, z`` in ``[0, 1]`` the interpolant is
written in the monomial form::

    f = k0 + k1 x + k2 y + k3 z + k4 xy + k5 xz + k6 yz + k7 xyz

On a ray segment ``(x, y, z) = a + s e`` (``a`` the entry point, ``e`` the entry-to-exit vector,
``s`` in ``[0, 1]``) it is the exact cubic ``c3 s^3 + c2 s^2 + c1 s + c0`` with ``c0 = f(a)``,
``c1 = grad f(a) . e``, ``c2`` the mixed second derivatives contracted with ``e`` and
``c3 = k7 ex ey ez`` (Józsa et al. 2014, section 5; we expand the polynomial directly instead of
fitting it to four samples, which avoids the cancellation of that fit). All arithmetic is float64;
voxels are converted on load from the kernels' element type (:mod:`.storage`: float32 for 8- and
16-bit integers, else the stored type).
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np

from .._jit import jit
from .._jit.prefetch import prefetch
from ..roots.pieces import PowerCubic
from ..volume import Volume
from ._trilinear_vector import cell_value
from .base import ReconstructionModel
from .pieces import cell_range, register, whole_cell
from .shading_field import SHADING_HALO, halo_gradient, whole_halo
from .storage import kernel_array
from .validation import require_renderable

__all__ = [
    "TrilinearModel",
    "TrilinearGrid",
    "cell_corners",
    "corner_monomials",
    "cell_monomials",
    "ray_cubic",
    "local_value",
    "local_gradient",
    "evaluate",
    "gradient",
]


@jit(inline="always")
def cell_corners(data: np.ndarray, i: int, j: int, k: int) -> tuple:
    """Corner range and the eight corner values of cell ``(i, j, k)``, as float64.

    Returns ``(vmin, vmax, c000, c100, c010, c110, c001, c101, c011, c111)``.
    """
    # Unsigned indices (cells are never negative): with signed ones numba adds a negative-index
    # wrap-around to each of the eight reads, a measurable share of a trilinear frame.
    ui0, uj0, uk0 = np.uint64(i), np.uint64(j), np.uint64(k)
    ui1, uj1, uk1 = ui0 + np.uint64(1), uj0 + np.uint64(1), uk0 + np.uint64(1)
    c000 = np.float64(data[ui0, uj0, uk0])
    c100 = np.float64(data[ui1, uj0, uk0])
    c010 = np.float64(data[ui0, uj1, uk0])
    c110 = np.float64(data[ui1, uj1, uk0])
    c001 = np.float64(data[ui0, uj0, uk1])
    c101 = np.float64(data[ui1, uj0, uk1])
    c011 = np.float64(data[ui0, uj1, uk1])
    c111 = np.float64(data[ui1, uj1, uk1])
    vmin = min(min(min(c000, c100), min(c010, c110)), min(min(c001, c101), min(c011, c111)))
    vmax = max(max(max(c000, c100), max(c010, c110)), max(max(c001, c101), max(c011, c111)))
    return vmin, vmax, c000, c100, c010, c110, c001, c101, c011, c111


@jit(inline="always")
def corner_monomials(corners: tuple) -> tuple:
    """Monomial coefficients ``k0..k7`` from :func:`cell_corners`' tuple."""
    c000, c100, c010, c110 = corners[2], corners[3], corners[4], corners[5]
    c001, c101, c011, c111 = corners[6], corners[7], corners[8], corners[9]
    k1 = c100 - c000
    k2 = c010 - c000
    k3 = c001 - c000
    k4 = c110 - c100 - c010 + c000
    k5 = c101 - c100 - c001 + c000
    k6 = c011 - c010 - c001 + c000
    k7 = c111 - c110 - c101 - c011 + c100 + c010 + c001 - c000
    return c000, k1, k2, k3, k4, k5, k6, k7


@jit(inline="always")
def cell_monomials(data: np.ndarray, i: int, j: int, k: int) -> tuple:
    """Corner range and monomial coefficients ``k0..k7`` of cell ``(i, j, k)``.

    Returns ``(vmin, vmax, k0, k1, k2, k3, k4, k5, k6, k7)``.
    """
    corners = cell_corners(data, i, j, k)
    k0, k1, k2, k3, k4, k5, k6, k7 = corner_monomials(corners)
    return corners[0], corners[1], k0, k1, k2, k3, k4, k5, k6, k7


@jit(inline="always")
def local_value(k0, k1, k2, k3, k4, k5, k6, k7, x, y, z):
    """Interpolant at local coordinates ``(x, y, z)`` of a cell."""
    return k0 + k1 * x + k2 * y + k3 * z + k4 * x * y + k5 * x * z + k6 * y * z + k7 * x * y * z


@jit(inline="always")
def local_gradient(k1, k2, k3, k4, k5, k6, k7, x, y, z):
    """Gradient (per unit index length) at local coordinates ``(x, y, z)`` of a cell."""
    gx = k1 + k4 * y + k5 * z + k7 * y * z
    gy = k2 + k4 * x + k6 * z + k7 * x * z
    gz = k3 + k5 * x + k6 * y + k7 * x * y
    return gx, gy, gz


@jit(inline="always")
def ray_cubic(k, a, e):
    """Power-form coefficients ``(c3, c2, c1, c0)`` of the interpolant along ``a + s e``
    (``a``, ``e``: ``(x, y, z)`` tuples) from the cell's monomial coefficients ``k``, the
    tuple ``(k0, ..., k7)`` of :func:`corner_monomials`."""
    k0, k1, k2, k3, k4, k5, k6, k7 = k
    ax, ay, az = a
    ex, ey, ez = e
    c0 = local_value(k0, k1, k2, k3, k4, k5, k6, k7, ax, ay, az)
    gx, gy, gz = local_gradient(k1, k2, k3, k4, k5, k6, k7, ax, ay, az)
    c1 = gx * ex + gy * ey + gz * ez
    c2 = ex * ey * (k4 + k7 * az) + ex * ez * (k5 + k7 * ay) + ey * ez * (k6 + k7 * ax)
    c3 = k7 * ex * ey * ez
    return c3, c2, c1, c0


@jit(inline="always")
def _cell_and_local(p: float, n_cells: int) -> tuple[int, float]:
    c = int(np.floor(p))
    if c < 0:
        c = 0
    elif c > n_cells - 1:
        c = n_cells - 1
    return c, p - c


@jit()
def evaluate(data: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Trilinear interpolant at index-space points, shape (m, 3); points outside are clamped."""
    nx, ny, nz = data.shape[0] - 1, data.shape[1] - 1, data.shape[2] - 1
    out = np.empty(points.shape[0])
    for m in range(points.shape[0]):
        i, x = _cell_and_local(min(max(points[m, 0], 0.0), nx), nx)
        j, y = _cell_and_local(min(max(points[m, 1], 0.0), ny), ny)
        k, z = _cell_and_local(min(max(points[m, 2], 0.0), nz), nz)
        _, _, k0, k1, k2, k3, k4, k5, k6, k7 = cell_monomials(data, i, j, k)
        out[m] = local_value(k0, k1, k2, k3, k4, k5, k6, k7, x, y, z)
    return out


@jit()
def gradient(data: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Index-space gradient of the interpolant at points, shape (m, 3)."""
    nx, ny, nz = data.shape[0] - 1, data.shape[1] - 1, data.shape[2] - 1
    out = np.empty((points.shape[0], 3))
    for m in range(points.shape[0]):
        i, x = _cell_and_local(min(max(points[m, 0], 0.0), nx), nx)
        j, y = _cell_and_local(min(max(points[m, 1], 0.0), ny), ny)
        k, z = _cell_and_local(min(max(points[m, 2], 0.0), nz), nz)
        _, _, k0, k1, k2, k3, k4, k5, k6, k7 = cell_monomials(data, i, j, k)
        out[m, 0], out[m, 1], out[m, 2] = local_gradient(k1, k2, k3, k4, k5, k6, k7, x, y, z)
    return out


# ----------------------------------------------------------------------------- ray pieces
#: Kernel grid of the trilinear model: the voxels (cell ``c`` needs voxels ``c .. c + 1``), and
#: the halo of the shading field with its box (:mod:`.shading_field`).
TrilinearGrid = namedtuple("TrilinearGrid", ["data", "halo", "halo_box"])


@jit()
def _cell_count(grid):
    d = grid.data
    return d.shape[0] - 1, d.shape[1] - 1, d.shape[2] - 1


@jit()
def _new_scratch(grid):
    return np.empty(0)


@jit()
def _cell_load(grid, scratch, i, j, k):
    # The corners only: most cells a ray visits are not tested, and need no monomials.
    return cell_corners(grid.data, i, j, k)


@jit()
def _piece_poly(grid, scratch, ctx, cell, tag, a, b):
    ax, ay, az = a
    bx, by, bz = b
    c3, c2, c1, c0 = ray_cubic(corner_monomials(ctx), a, (bx - ax, by - ay, bz - az))
    return PowerCubic(c0, c1, c2, c3)


@jit()
def _gradient(grid, scratch, ctx, i, j, k, tag, x, y, z):
    _, k1, k2, k3, k4, k5, k6, k7 = corner_monomials(ctx)
    return local_gradient(k1, k2, k3, k4, k5, k6, k7, x, y, z)


@jit()
def _value_gradient_at(grid, scratch, x, y, z):
    data = grid.data
    nx, ny, nz = data.shape[0] - 1, data.shape[1] - 1, data.shape[2] - 1
    i, u = _cell_and_local(min(max(x, 0.0), float(nx)), nx)
    j, v = _cell_and_local(min(max(y, 0.0), float(ny)), ny)
    k, w = _cell_and_local(min(max(z, 0.0), float(nz)), nz)
    _, _, k0, k1, k2, k3, k4, k5, k6, k7 = cell_monomials(data, i, j, k)
    gx, gy, gz = local_gradient(k1, k2, k3, k4, k5, k6, k7, u, v, w)
    return local_value(k0, k1, k2, k3, k4, k5, k6, k7, u, v, w), gx, gy, gz


@jit()
def _value_at(grid, scratch, x, y, z):
    """The interpolant at a point, clamped into the grid, as three rounds of linear
    interpolation (a fixed-step ray caster takes one per sample)."""
    data = grid.data
    nx, ny, nz = data.shape[0] - 1, data.shape[1] - 1, data.shape[2] - 1
    x = min(max(x, 0.0), float(nx))
    y = min(max(y, 0.0), float(ny))
    z = min(max(z, 0.0), float(nz))
    # Unsigned indices: the coordinates are clamped to be non-negative, and numba then leaves
    # out the negative-index wrap-around it would otherwise add to each of the eight reads.
    ci, cj, ck = min(int(x), nx - 1), min(int(y), ny - 1), min(int(z), nz - 1)
    u, v, w = x - ci, y - cj, z - ck
    # Along the first axis, then the second, then the third, each voxel converted to float64
    # before any difference (the data may be unsigned integers); the rows' two voxels along
    # the third axis as the two lanes of a vector (the same operations per lane).
    return cell_value(data, np.uint64(ci), np.uint64(cj), np.uint64(ck), u, v, w)


@jit(inline="always")
def _lerp2(a00, a10, a01, a11, s, t):
    """Bilinear interpolation, along the first axis (``s``) before the second, in
    :func:`_value_at`'s order, so a value on a plane of voxels is the same to the last bit (on
    the last plane :func:`_value_at` interpolates toward it from the cell before, which
    rounds)."""
    c0 = a00 + s * (a10 - a00)
    c1 = a01 + s * (a11 - a01)
    return c0 + t * (c1 - c0)


@jit()
def _value_on_plane(grid, scratch, axis, p, a, b):
    """The bilinear of voxel plane ``p`` across ``axis`` at in-plane coordinates ``(a, b)``:
    4 reads instead of 8."""
    data = grid.data
    nx, ny, nz = data.shape[0] - 1, data.shape[1] - 1, data.shape[2] - 1
    if axis == 0:
        n, na, nb = nx, ny, nz
    elif axis == 1:
        n, na, nb = ny, nx, nz
    else:
        n, na, nb = nz, nx, ny
    # Clamped into the grid; unsigned indices, so numba leaves out the negative-index
    # wrap-around of each read.
    a = min(max(a, 0.0), float(na))
    b = min(max(b, 0.0), float(nb))
    ca, cb = min(int(a), na - 1), min(int(b), nb - 1)
    s, t = a - ca, b - cb
    q = np.uint64(min(max(p, 0.0), float(n)))
    i, j = np.uint64(ca), np.uint64(cb)
    i1, j1 = i + np.uint64(1), j + np.uint64(1)
    if axis == 0:
        return _lerp2(np.float64(data[q, i, j]), np.float64(data[q, i1, j]),
                      np.float64(data[q, i, j1]), np.float64(data[q, i1, j1]), s, t)
    if axis == 1:
        return _lerp2(np.float64(data[i, q, j]), np.float64(data[i1, q, j]),
                      np.float64(data[i, q, j1]), np.float64(data[i1, q, j1]), s, t)
    return _lerp2(np.float64(data[i, j, q]), np.float64(data[i1, j, q]),
                  np.float64(data[i, j1, q]), np.float64(data[i1, j1, q]), s, t)


@jit()
def _prefetch_at(grid, scratch, x, y, z):
    """Prefetch the four rows of voxels :func:`_value_at` reads at the point (each row's two
    voxels lie side by side along the last axis)."""
    data = grid.data
    nx, ny, nz = data.shape[0] - 1, data.shape[1] - 1, data.shape[2] - 1
    # Clamped as unsigned integers, without the float clamps of the read: a point below 0 (or
    # not a number) truncates to a negative integer, which as unsigned is above the top and is
    # clamped to it; a prefetch of the wrong voxels only costs its hint.
    i = min(np.uint64(int(x)), np.uint64(nx - 1))
    j = min(np.uint64(int(y)), np.uint64(ny - 1))
    k = min(np.uint64(int(z)), np.uint64(nz - 1))
    i1, j1 = i + np.uint64(1), j + np.uint64(1)
    prefetch(data, (i, j, k))
    prefetch(data, (i1, j, k))
    prefetch(data, (i, j1, k))
    prefetch(data, (i1, j1, k))


@jit()
def _look_ahead(grid):
    """Eight loads and seven blends a value: the fixed-step loop takes it one sample early."""
    return True


@jit()
def _separate_shading(grid):
    """The trilinear gradient jumps between cells: shading uses the smooth field."""
    return True


@jit()
def _shading_gradient_at(grid, scratch, x, y, z):
    """The cubic B-spline's gradient (:mod:`.shading_field`); the traversal space is the
    grid array's index space (no shift)."""
    return halo_gradient(grid.halo, grid.halo_box, x, y, z)


register(TrilinearGrid, cell_count=_cell_count, new_scratch=_new_scratch, cell_load=_cell_load,
         cell_pieces=whole_cell, piece_range=cell_range, piece_poly=_piece_poly,
         gradient=_gradient, value_gradient_at=_value_gradient_at, value_at=_value_at,
         value_on_plane=_value_on_plane, look_ahead=_look_ahead, prefetch_at=_prefetch_at,
         separate_shading=_separate_shading, shading_gradient_at=_shading_gradient_at)


class TrilinearModel(ReconstructionModel):
    """Trilinear reconstruction prepared from a volume.

    The voxels are used as they are stored (no conversion of the whole volume): the kernels read
    the eight corners of a cell and convert them to float64. A C-contiguous copy is made only when
    the array is not already C-contiguous (for example a Fortran-ordered memory map).

    Parameters
    ----------
    volume : Volume
        The data; it needs at least 2 voxels per axis and no NaN.

    Raises
    ------
    DataError
        If the volume is too small or holds NaN values.
    """

    name = "trilinear"
    #: cell ``c`` depends on voxels ``c .. c + support`` per axis.
    support = 1
    #: A coarse level's trilinear interpolant is a fine level's (the linear B-spline refined).
    nested_degree = 1
    typical_compile_s = 40
    #: index-space coordinate of the lower corner of cell 0 (cell ``c`` spans ``[c, c + 1]``).
    cell_offset = 0.0
    #: The traversal walks cells in ``voxel index + shift`` (cell ``c`` is ``[c, c + 1]`` there).
    shift = 0.0
    #: Rays are traced in tiles of 8 x 8 pixels: neighbouring rays read the same voxels while
    #: they are in the cache (whole rows let them fall out before the next row needs them).
    band_rows = 8
    tile = 8
    #: In the modes whose rays go through the volume (DVR, MIP) a thread traces 32 rows at a
    #: time, a column of four tiles after another: a tile's neighbours then find the voxels
    #: they share with it still in the cache (exact MIP 1.05-1.12x, DVR 1.01-1.14x faster
    #: than a band of 8 rows across the image).
    work_rows = 32
    #: The shading field reads this many voxels beyond a cell's support on each side
    #: (:mod:`.shading_field`): a brick's grid carries them as its halo.
    shading_halo = SHADING_HALO

    def __init__(self, volume: Volume) -> None:
        require_renderable(volume)
        self.volume = volume
        self.data = kernel_array(volume.data)  # one kernel for 8/16-bit integers and float32
        self.n_cells = tuple(n - 1 for n in volume.shape)

    @property
    def prepared(self) -> np.ndarray:
        """The array the kernels read: cell ``c`` depends on ``prepared[c .. c + support]``."""
        return self.data

    def domain(self) -> tuple[np.ndarray, np.ndarray]:
        """The box rendered, in voxel index space: the box spanned by the voxel centres."""
        return np.zeros(3), np.asarray(self.volume.shape, np.float64) - 1.0

    def kernel_grid(self, array: np.ndarray | None = None,
                    halo: tuple[np.ndarray, np.ndarray] | None = None) -> tuple:
        """The :class:`TrilinearGrid` of ``array`` (a block of :attr:`prepared` with its ghost
        layer; default: the whole volume) and the shading field's ``(halo, box)``
        (:mod:`.shading_field`; default: ``array`` itself, all of it real)."""
        data = self.data if array is None else np.ascontiguousarray(array)
        halo_array, box = whole_halo(data) if halo is None else halo
        # The halo is often the grid's own array (a whole volume, a pyramid brick): no copy.
        halo_array = data if halo_array is array else np.ascontiguousarray(halo_array)
        return TrilinearGrid(data, halo_array, box)

    @property
    def coefficients(self) -> np.ndarray:
        """The values that bound the reconstruction cell by cell (here: the voxels)."""
        return self.data

    @property
    def nbytes(self) -> int:
        """Memory held by the prepared arrays."""
        return int(self.data.nbytes) if self.data is not self.volume.data else 0
