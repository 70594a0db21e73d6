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
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from .errors import DataError, ParameterError

__all__ = ["Volume", "GridGeometry", "SUPPORTED_DTYPES"]

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


def _as_triple(value: Any, name: str) -> tuple[float, float, float]:
    arr = np.broadcast_to(np.asarray(value, dtype=np.float64), (3,))
    if not np.all(np.isfinite(arr)):
        raise ParameterError(f"{name} must be three finite numbers, got {value!r}")
    return (float(arr[0]), float(arr[1]), float(arr[2]))


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
        self.spacing: tuple[float, float, float] = _as_triple(spacing, "spacing")
        if min(self.spacing) <= 0:
            raise ParameterError(f"spacing must be positive, got {self.spacing}")
        self.origin: tuple[float, float, float] = _as_triple(origin, "origin")
        self.metadata: dict[str, Any] = dict(metadata or {})
        self._value_range: tuple[float, float] | None = None

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
        """``(min, max)`` of the finite voxel values (computed once, on first use)."""
        if self._value_range is None:
            data = self.data
            if data.dtype.kind == "f":
                finite = np.isfinite(data)
                if not finite.any():
                    raise DataError(f"{self.name}: the data contains no finite value")
                lo = float(np.min(data, where=finite, initial=np.inf))
                hi = float(np.max(data, where=finite, initial=-np.inf))
            else:
                lo, hi = float(data.min()), float(data.max())
            self._value_range = (lo, hi)
        return self._value_range

    def count_nan(self) -> int:
        """Number of NaN voxels (always 0 for integer data)."""
        if self.data.dtype.kind != "f":
            return 0
        return int(np.count_nonzero(np.isnan(self.data)))

    def __repr__(self) -> str:
        return (
            f"Volume(name={self.name!r}, shape={self.shape}, dtype={self.dtype}, "
            f"spacing={self.spacing}, origin={self.origin})"
        )
