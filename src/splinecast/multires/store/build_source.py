"""What a pyramid builder reads: any accepted source opened lazily, in splinecast axis order.

Both builders, the binomial brick pyramid (:mod:`splinecast.multires.store.pyramid`) and the
spline-wavelet pyramid (:mod:`splinecast.multires.wavelet.store`), accept the same sources (a
path, a :class:`~splinecast.Volume`, a :class:`~splinecast.io.omezarr.MultiscaleVolume`, a zarr,
dask or numpy array) and make the same
checks before reading anything; they share this module so that neither imports the other's
internals.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import ParameterError, ReadError
from ...io.omezarr import Level, MultiscaleVolume
from ...volume import SUPPORTED_DTYPES, Volume

__all__ = ["PyramidSource", "level_source", "open_pyramid_source"]


class PyramidSource:
    """Random access to the source volume in splinecast order: ``read(lo, hi)`` -> (x, y, z)."""

    def __init__(self, shape: tuple[int, int, int], dtype: np.dtype,
                 read: Callable[[np.ndarray, np.ndarray], np.ndarray], label: str,
                 spacing: Any = (1.0, 1.0, 1.0), origin: Any = (0.0, 0.0, 0.0),
                 metadata: dict[str, Any] | None = None, dask: Any = None) -> None:
        self.shape, self.dtype, self.read, self.label = shape, np.dtype(dtype), read, label
        self.spacing, self.origin = tuple(spacing), tuple(origin)
        self.metadata = metadata or {}
        self.dask = dask  # a dask array source is written to level 0 by dask itself


def _from_array(data: Any, label: str, **kw: Any) -> PyramidSource:
    def read(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        try:
            return np.array(data[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]])
        except OSError as exc:  # a memory-mapped file that shrank, a disk error
            raise ReadError(f"{label}: cannot read voxels {lo.tolist()}..{hi.tolist()}: "
                            f"{exc}") from None

    return PyramidSource(tuple(int(n) for n in data.shape), data.dtype, read, label, **kw)


def level_source(level: Level, label: str, **kw: Any) -> PyramidSource:
    """A stored pyramid level as a source (the reader's checks apply to its reads)."""
    return PyramidSource(level.shape, level.dtype, level.read, label, **kw)


def _open_source(source: Any, allow_external: bool | None = None) -> PyramidSource:
    """Wrap any accepted source; nothing is read here."""
    if isinstance(source, (str, os.PathLike)):
        from ...io import read

        source = read(source, allow_external=allow_external)
    if isinstance(source, MultiscaleVolume):
        level = source.levels[0]
        return level_source(level, str(source.path), spacing=source.spacing,
                           origin=source.origin, metadata=dict(source.metadata))
    if isinstance(source, Volume):
        return _from_array(source.data, source.name, spacing=source.spacing,
                           origin=source.origin, metadata=dict(source.metadata))
    module = type(source).__module__
    if module.startswith("dask"):
        src = PyramidSource(tuple(int(n) for n in source.shape), source.dtype, lambda lo, hi: None,
                      "dask array", dask=source)
        return src
    if module.startswith("zarr"):
        from ...io.omezarr import _plain_array  # the reader's axis rules for bare arrays
        from ...io.selection import Selection

        level = _plain_array(Path("zarr array"), source, "zarr array", Selection()).levels[0]
        level.folder = None  # not a local folder of ours: no file checks
        return level_source(level, "zarr array")
    if hasattr(source, "shape") and hasattr(source, "dtype") and len(source.shape) == 3:
        return _from_array(source, "array")
    raise ParameterError(
        f"source must be a path, a Volume, a MultiscaleVolume or a 3D array, got {type(source)}"
    )


def open_pyramid_source(source: Any, path: Path, levels: int | None, overwrite: bool,
                        allow_external: bool | None) -> PyramidSource:
    """The checks every pyramid builder makes before reading anything (``levels``, an existing
    ``path``), then ``source`` opened lazily and its voxel type and rank checked."""
    if levels is not None and (isinstance(levels, bool) or int(levels) != levels or levels < 1):
        raise ParameterError(f"levels must be a positive integer, got {levels!r}")
    if path.exists() and not overwrite:
        raise ParameterError(f"{path}: already exists (pass overwrite=True or --overwrite)")
    src = _open_source(source, allow_external)
    if src.dtype.newbyteorder("=") not in SUPPORTED_DTYPES or len(src.shape) != 3:
        raise ParameterError(f"{src.label}: cannot build a pyramid of {src.dtype} voxels of "
                             f"shape {src.shape}")
    return src
