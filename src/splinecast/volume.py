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

Spacing and origin are validated by :mod:`splinecast.limits` (finite, normal, within a sane range).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from .errors import DataError, ParameterError
from .limits import check_origin, check_spacing

__all__ = ["Volume", "SUPPORTED_DTYPES"]

#: dtypes kept as they are; anything else is rejected rather than silently converted.
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


#: Voxels scanned per step of the value-range scan (bounds its temporary memory).
_SCAN_VOXELS = 1 << 24


class Volume:
    """A scalar field sampled on a regular 3D grid.

    Parameters
    ----------
    data : array_like, shape (nx, ny, nz)
        Voxel values, indexed ``data[i, j, k]`` with ``i`` along x. The dtype is kept (uint8,
        int8, uint16, int16, uint32, int32, float32, float64); a ``numpy.memmap`` stays
        memory-mapped.
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
        if data.dtype == np.bool_:
            data = data.view(np.uint8)
        if data.dtype not in SUPPORTED_DTYPES:
            raise ParameterError(
                f"data dtype {data.dtype} is not supported "
                f"(use one of {', '.join(str(d) for d in SUPPORTED_DTYPES)})"
            )
        self.data: np.ndarray = data
        self.spacing: tuple[float, float, float] = check_spacing(spacing, "spacing")
        self.origin: tuple[float, float, float] = check_origin(origin, self.spacing, "origin")
        self.metadata: dict[str, Any] = dict(metadata or {})
        self._value_range: tuple[float, float] | None = None
        self._nonfinite: tuple[int, int, int] | None = None

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
        for the finite value range and the non-finite counts."""
        data = self.data
        if data.dtype.kind != "f":
            if data.size:
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
        self._value_range = (lo, hi)

    def __repr__(self) -> str:
        return (
            f"Volume(name={self.name!r}, shape={self.shape}, dtype={self.dtype}, "
            f"spacing={self.spacing}, origin={self.origin})"
        )
