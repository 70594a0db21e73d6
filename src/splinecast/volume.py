"""The :class:`Volume`: a 3D scalar grid with its place in the world.

Coordinate convention (the one used everywhere in splinecast)
--------------------------------------------------------------
``Volume.data`` is indexed ``data[i, j, k]`` where ``i`` runs along world x, ``j`` along world y and
``k`` along world z. The centre of voxel ``(i, j, k)`` is at world position::

    origin + (i, j, k) * spacing

so index space and world space differ by a per-axis scale and an offset only (no rotation; readers
of formats that store a rotation resample nothing and warn instead). The continuous reconstruction
covers the box spanned by the voxel centres, from ``origin`` to ``origin + (shape - 1) * spacing``.
Readers convert their format to this convention; nothing else in the package transposes axes.

Non-finite values (the policy)
------------------------------
A volume may hold NaN, +inf and -inf voxels: it can be read, described (``splinecast info``
counts them) and written. Nothing renders them: every model and every mode (iso, multi-iso, mip,
minip, dvr) refuses such a volume with a :class:`~splinecast.errors.DataError` that gives the
counts, before any compiled code runs, because no reconstruction can interpolate them. Replace
them first (for example ``numpy.nan_to_num``). :attr:`Volume.value_range` is the range of the
finite values.

Spacing and origin are validated by :mod:`splinecast.errors.limits` (finite, normal, within a
sane range).
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from typing import Any

import numpy as np

from .errors import DataError, ParameterError
from .errors.limits import check_origin, check_spacing

__all__ = ["Volume", "GridGeometry", "SUPPORTED_DTYPES", "CONVERTED_DTYPES", "exact_supported",
           "OrientationWarning", "find_vtk_array"]

#: dtypes the renderers use as they are (no copy).
SUPPORTED_DTYPES = (
    np.dtype(np.uint8),
    np.dtype(np.int8),
    np.dtype(np.uint16),
    np.dtype(np.int16),
    np.dtype(np.uint32),
    np.dtype(np.int32),
    np.dtype(np.float32),
    np.dtype(np.float64),
)

#: dtypes accepted and converted by :func:`exact_supported` to the smallest supported dtype that
#: holds every value exactly (bool becomes a uint8 view without a copy).
CONVERTED_DTYPES = (
    np.dtype(np.bool_),
    np.dtype(np.int64),
    np.dtype(np.uint64),
    np.dtype(np.float16),
)

# Candidates for integer data, smallest first; at equal size unsigned before signed, so 0..255
# labels become uint8. float64 comes last: it holds integers exactly up to 2**53 in magnitude.
_INTEGER_TARGETS = tuple(np.dtype(t) for t in (np.uint8, np.int8, np.uint16, np.int16,
                                                np.uint32, np.int32))


def exact_supported(data: np.ndarray, label: str = "data") -> np.ndarray:
    """Return ``data`` with a dtype of :data:`SUPPORTED_DTYPES`, holding exactly the same values.

    Supported dtypes pass through unchanged (a memory map stays one). ``bool`` becomes a uint8
    view (no copy); ``float16`` becomes float32; ``int64`` and ``uint64`` (NumPy's and PyVista's
    default integer types, typical for label volumes) become the smallest of uint8, int8,
    uint16, int16, uint32, int32 whose range holds the data's minimum and maximum, else float64
    if every value is exactly representable there (always for magnitudes up to 2**53). The
    conversion copies the array.

    Parameters
    ----------
    data : ndarray
        The voxels, in native byte order.
    label : str
        Name of the array or file for the error message.

    Raises
    ------
    DataError
        If no supported dtype holds every value exactly (large 64-bit integers), or the dtype is
        neither supported nor convertible (complex, object, strings, ...).
    """
    dtype = data.dtype
    if dtype in SUPPORTED_DTYPES:
        return data
    if dtype == np.bool_:
        return data.view(np.uint8)
    if dtype == np.float16:
        return data.astype(np.float32)
    if dtype not in CONVERTED_DTYPES:
        names = ", ".join(str(d) for d in SUPPORTED_DTYPES + CONVERTED_DTYPES)
        raise DataError(f"{label}: voxel type {dtype} is not supported (use one of {names})")
    if data.size == 0:
        return data.astype(np.uint8)
    lo, hi = int(data.min()), int(data.max())  # Python ints: exact for every int64/uint64
    for target in _INTEGER_TARGETS:
        info = np.iinfo(target)
        if info.min <= lo and hi <= info.max:
            return data.astype(target)
    as_float = data.astype(np.float64)
    # Exact when the round trip through float64 gives the same integers back. Casting a float
    # at or above 2**63 to int64 (2**64 to uint64) is undefined, so such maxima (which rounding
    # may produce from the largest integers) are ruled out before the round trip.
    limit = 2.0**63 if dtype == np.int64 else 2.0**64
    if float(as_float.max()) < limit and np.array_equal(as_float.astype(dtype), data):
        return as_float
    raise DataError(
        f"{label}: {dtype} values {lo}..{hi} cannot be held exactly by any supported voxel "
        "type (float64 is exact only up to 2**53); rescale or relabel the data"
    )


class OrientationWarning(UserWarning):
    """The file's voxel axes were flipped, permuted or (for oblique data) rotated to fit x, y, z,
    or a VTK image's direction matrix was not applied."""


def find_vtk_array(image: Any, array: str | None, label: str) -> tuple[str, Any, bool]:
    """The data array of a ``vtkImageData`` that :meth:`Volume.from_vtk` reads.

    Parameters
    ----------
    image : vtkImageData or pyvista.ImageData
        The image.
    array : str or None
        The array's name; ``None``: the only numeric point (else cell) data array.
    label : str
        Names the image in messages.

    Returns
    -------
    name : str
        The array's name.
    vtk_array : vtkDataArray
        The array.
    on_points : bool
        Point data (else cell data).

    Raises
    ------
    ParameterError
        No such array, no numeric array, or several and no ``array``.
    """
    points, cells = _vtk_arrays(image.GetPointData()), _vtk_arrays(image.GetCellData())
    if array is not None:
        pool = points if array in points else cells
        if array not in pool:
            names = ", ".join(repr(n) for n in [*points, *cells]) or "none"
            raise ParameterError(f"{label}: no data array {array!r} (arrays: {names})")
    else:
        pool = points or cells
        if not pool:
            raise ParameterError(f"{label}: the image has no numeric point or cell data")
        if len(pool) > 1:
            names = ", ".join(repr(n) for n in pool)
            raise ParameterError(f"{label}: several data arrays ({names}); choose one with "
                                 "array=NAME")
        array = next(iter(pool))
    return array, pool[array], pool is points


def _vtk_arrays(attributes: Any) -> dict[str, Any]:
    """Name -> numeric data array of a vtkPointData / vtkCellData (string arrays left out)."""
    arrays = {}
    for index in range(attributes.GetNumberOfArrays()):
        arr = attributes.GetArray(index)  # None for non-numeric arrays
        if arr is not None:
            arrays[arr.GetName() or f"array {index}"] = arr
    return arrays


#: Voxels scanned per step of the value-range scan (bounds its temporary memory).
_SCAN_VOXELS = 1 << 24


class GridGeometry:
    """World placement of a regular grid: what :class:`Volume` and a lazy multiscale volume share.

    Subclasses set ``shape`` (voxels along x, y, z), ``spacing`` and ``origin`` (x, y, z, world
    units); everything here follows from those three by the convention of this module.
    """

    shape: tuple[int, int, int]
    spacing: tuple[float, float, float]
    origin: tuple[float, float, float]

    @property
    def extent(self) -> tuple[float, float, float]:
        """World size of the box spanned by the voxel centres, ``(shape - 1) * spacing``."""
        return tuple(  # type: ignore[return-value]
            (n - 1) * s for n, s in zip(self.shape, self.spacing, strict=True)
        )

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """World-space corners ``(lo, hi)`` of the reconstruction box."""
        lo = np.array(self.origin)
        return lo, lo + np.array(self.extent)

    @property
    def center(self) -> np.ndarray:
        """World position of the centre of the reconstruction box."""
        lo, hi = self.bounds
        return 0.5 * (lo + hi)

    def index_to_world(self, ijk: Any) -> np.ndarray:
        """Map (fractional) voxel indices, shape (..., 3), to world positions."""
        return np.asarray(self.origin) + np.asarray(ijk, dtype=np.float64) * np.asarray(
            self.spacing
        )

    def world_to_index(self, xyz: Any) -> np.ndarray:
        """Map world positions, shape (..., 3), to fractional voxel indices."""
        return (np.asarray(xyz, dtype=np.float64) - np.asarray(self.origin)) / np.asarray(
            self.spacing
        )


class Volume(GridGeometry):
    """A scalar field sampled on a regular 3D grid.

    Parameters
    ----------
    data : array_like, shape (nx, ny, nz)
        Voxel values, indexed ``data[i, j, k]`` with ``i`` along x. The dtype is kept (uint8,
        int8, uint16, int16, uint32, int32, float32, float64); a ``numpy.memmap`` stays
        memory-mapped. bool, float16, int64 and uint64 are converted to the smallest of those
        that holds every value exactly (see :func:`exact_supported`).
    spacing : float or sequence of 3 floats, optional
        Distance between voxel centres along x, y, z in world units (default 1).
    origin : sequence of 3 floats, optional
        World position of the centre of voxel ``(0, 0, 0)`` (default 0).
    metadata : mapping, optional
        Free-form information (source file, units, modality, ...). The key ``"name"`` is used in
        error messages; ``"inside"`` (``"high"`` or ``"low"``) says on which side of an isovalue
        the object lies, which decides front and back faces when rendering.

    Examples
    --------
    >>> import numpy as np
    >>> vol = Volume(np.zeros((4, 5, 6), np.uint8), spacing=(1.0, 1.0, 2.5))
    >>> vol.shape, vol.extent
    ((4, 5, 6), (3.0, 4.0, 12.5))
    """

    def __init__(
        self,
        data: Any,
        spacing: Any = 1.0,
        origin: Any = 0.0,
        metadata: Mapping[str, Any] | None = None,
    ) -> None:
        if not isinstance(data, np.ndarray):
            data = np.asarray(data)
        if data.ndim != 3:
            raise ParameterError(f"data must be a 3D array, got shape {data.shape}")
        if not data.dtype.isnative:
            data = data.astype(data.dtype.newbyteorder("="))
        data = exact_supported(data, metadata.get("name", "data") if metadata else "data")
        self.data: np.ndarray = data
        self.spacing: tuple[float, float, float] = check_spacing(spacing, "spacing")
        self.origin: tuple[float, float, float] = check_origin(origin, self.spacing, "origin")
        self.metadata: dict[str, Any] = dict(metadata or {})
        self._value_range: tuple[float, float] | None = None
        self._nonfinite: tuple[int, int, int] | None = None

    @classmethod
    def from_vtk(cls, image: Any, array: str | None = None,
                 metadata: Mapping[str, Any] | None = None,
                 component: int | None = None) -> Volume:
        """A volume from a ``vtkImageData`` or ``pyvista.ImageData`` (neither is imported here).

        Parameters
        ----------
        image : vtkImageData or pyvista.ImageData
            The image. Its point data are the voxels: VTK stores them x fastest, so the flat
            array becomes ``data[i, j, k]`` (a view, no copy) and voxel ``(i, j, k)`` of the
            image's extent is at ``origin + (i, j, k) * spacing``, splinecast's convention. An
            image with cell data only gives one voxel per cell, centred in it.
        array : str, optional
            Name of the point (or cell) data array; needed when there are several.
        metadata : mapping, optional
            Added to the volume's metadata (``"name"`` is used in messages).
        component : int, optional
            Which component of an array with several (a vector or colour array) to read; needed
            for such arrays.

        Returns
        -------
        Volume
            Sharing memory with the VTK array (modify a copy, not the VTK object, to keep the
            volume unchanged); ``metadata["array"]`` names the array. int64, uint64, bool and
            float16 arrays are converted (see :func:`exact_supported`).

        Raises
        ------
        ParameterError
            Not image data, no numeric array, an unknown or ambiguous ``array`` (the message
            lists the names), an array with several components and no ``component``, or a
            ``component`` out of range.

        Warns
        -----
        OrientationWarning
            When the image has a direction matrix other than the identity: it is not applied
            (the voxels are placed axis-aligned, as VTK filters that predate direction matrices
            do).

        Examples
        --------
        >>> import pyvista as pv  # doctest: +SKIP
        >>> grid = pv.ImageData(dimensions=(40, 30, 20), spacing=(1, 1, 2))  # doctest: +SKIP
        >>> grid["density"] = values.ravel(order="F")  # doctest: +SKIP
        >>> vol = sc.Volume.from_vtk(grid)  # doctest: +SKIP
        """
        meta = dict(metadata or {})
        label = str(meta.get("name", "the VTK image"))
        needed = ("GetDimensions", "GetExtent", "GetSpacing", "GetOrigin", "GetPointData",
                  "GetCellData")
        if not all(hasattr(image, name) for name in needed):
            raise ParameterError(
                f"{label}: expected a vtkImageData or pyvista.ImageData, got "
                f"{type(image).__name__}"
            )
        array, vtk_array, on_points = find_vtk_array(image, array, label)
        components = vtk_array.GetNumberOfComponents()
        if component is None and components != 1:
            raise ParameterError(
                f"{label}: array {array!r} has {components} components; splinecast renders "
                "scalar data (choose one with component=N)"
            )
        if component is not None:
            if isinstance(component, bool) or not isinstance(component, int | np.integer):
                raise ParameterError(f"{label}: component must be an integer, got "
                                     f"{component!r}")
            if not 0 <= component < components:
                raise ParameterError(f"{label}: component {component} is out of range (array "
                                     f"{array!r} has {components}: 0 to {components - 1})")
        from vtkmodules.util.numpy_support import vtk_to_numpy  # present with any VTK object

        flat = vtk_to_numpy(vtk_array)
        if flat.ndim == 2:
            # One component of interleaved tuples, copied so that x runs contiguously, as the
            # kernels walk it.
            flat = np.ascontiguousarray(flat[:, component or 0])
        dims = np.asarray(image.GetDimensions(), dtype=np.int64)
        spacing = np.asarray(image.GetSpacing(), dtype=np.float64)
        first = np.asarray(image.GetExtent()[::2], dtype=np.float64)
        if not on_points:  # one voxel per cell, at the cell's centre
            dims = np.maximum(dims - 1, 1)
            first = first + 0.5
        if flat.size != int(np.prod(dims)):
            raise ParameterError(f"{label}: array {array!r} has {flat.size} values for "
                                 f"{'x'.join(str(n) for n in dims)} voxels")
        if hasattr(image, "GetDirectionMatrix"):
            matrix = image.GetDirectionMatrix()
            direction = np.array([[matrix.GetElement(r, c) for c in range(3)] for r in range(3)])
            if not np.allclose(direction, np.eye(3), rtol=0.0, atol=1e-6):
                warnings.warn(
                    f"{label}: the direction matrix {direction.round(6).tolist()} is not applied;"
                    " the voxels are placed along x, y, z",
                    OrientationWarning,
                    stacklevel=2,
                )
        # x varies fastest: C order over (z, y, x), transposed (a view) to data[i, j, k].
        data = flat.reshape(dims[::-1]).transpose(2, 1, 0)
        origin = np.asarray(image.GetOrigin(), dtype=np.float64) + first * spacing
        meta.setdefault("name", label)
        meta["array"] = array
        return cls(data, spacing=spacing, origin=origin, metadata=meta)

    # ------------------------------------------------------------------ geometry
    @property
    def shape(self) -> tuple[int, int, int]:
        """Number of voxels along x, y, z."""
        return tuple(int(n) for n in self.data.shape)  # type: ignore[return-value]

    @property
    def dtype(self) -> np.dtype:
        """The stored dtype of the voxels."""
        return self.data.dtype

    @property
    def name(self) -> str:
        """A human-readable name for messages (the file name when read from disk)."""
        return str(self.metadata.get("name", "volume"))

    # ------------------------------------------------------------------ values
    @property
    def value_range(self) -> tuple[float, float]:
        """``(min, max)`` of the finite voxel values (computed once, on first use).

        Raises
        ------
        DataError
            If the data holds no finite value at all.
        """
        if self._value_range is None:
            self._scan()
        assert self._value_range is not None
        return self._value_range

    def nonfinite_counts(self) -> tuple[int, int, int]:
        """Numbers of NaN, +inf and -inf voxels (all 0 for integer data)."""
        if self._nonfinite is None:
            self._scan()
        assert self._nonfinite is not None
        return self._nonfinite

    def count_nan(self) -> int:
        """Number of NaN voxels (always 0 for integer data)."""
        return self.nonfinite_counts()[0]

    def require_finite(self) -> None:
        """Raise :class:`DataError` if any voxel is NaN or infinite (see the module's policy)."""
        nan, pos, neg = self.nonfinite_counts()
        if nan or pos or neg:
            raise DataError(
                f"{self.name}: the data contains {nan} NaN, {pos} +inf and {neg} -inf values; "
                "replace them (for example with numpy.nan_to_num) before rendering"
            )

    def _scan(self) -> None:
        """One pass over the data, in slabs along its slowest axis (bounded temporary memory),
        for the finite value range and the non-finite counts.

        A value range set before (a multiscale scene's preview carries the whole volume's range,
        not its own level's) is kept: only the counts are filled in then.
        """
        data = self.data
        if data.dtype.kind != "f":
            if data.size and self._value_range is None:
                self._value_range = (float(data.min()), float(data.max()))
            self._nonfinite = (0, 0, 0)
            if not data.size:
                raise DataError(f"{self.name}: the volume holds no voxel")
            return
        axis = int(np.argmax(np.abs(data.strides)))
        per_slab = max(1, data.size // max(1, data.shape[axis]))
        width = max(1, _SCAN_VOXELS // per_slab)
        lo, hi = np.inf, -np.inf
        nan = pos = neg = 0
        for start in range(0, data.shape[axis], width):
            index = [slice(None)] * data.ndim
            index[axis] = slice(start, start + width)
            slab = data[tuple(index)]  # a view: contiguous along the slowest axis
            finite = np.isfinite(slab)
            if not finite.all():
                nan += int(np.count_nonzero(np.isnan(slab)))
                pos += int(np.count_nonzero(slab == np.inf))
                neg += int(np.count_nonzero(slab == -np.inf))
            if finite.any():
                lo = min(lo, float(np.min(slab, where=finite, initial=np.inf)))
                hi = max(hi, float(np.max(slab, where=finite, initial=-np.inf)))
        self._nonfinite = (nan, pos, neg)
        if lo > hi:
            raise DataError(f"{self.name}: the data contains no finite value")
        if self._value_range is None:
            self._value_range = (lo, hi)

    def __repr__(self) -> str:
        return (
            f"Volume(name={self.name!r}, shape={self.shape}, dtype={self.dtype}, "
            f"spacing={self.spacing}, origin={self.origin})"
        )
