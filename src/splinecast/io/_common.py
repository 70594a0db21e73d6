"""Helpers shared by the readers: optional imports, label formatting and the final Volume checks."""

from __future__ import annotations

import importlib
import os
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from ..errors import DataError, ReadError, SplinecastError
from ..volume import CONVERTED_DTYPES, SUPPORTED_DTYPES, Volume, exact_supported

__all__ = ["require", "finish_volume", "fmt_shape", "native", "check_dtype", "one_line"]

#: pip name of each optional import, for the install hint.
_PACKAGES = {"nrrd": "pynrrd", "nibabel": "nibabel", "pydicom": "pydicom", "tifffile": "tifffile",
             "zarr": "zarr", "dask.array": "dask"}
#: The extra of splinecast that installs a package (default: io).
_EXTRAS = {"zarr": "multires", "dask.array": "multires"}


def require(
    module: str,
    path: str | os.PathLike[str],
    *,
    action: str = "reading",
    error: type[SplinecastError] = ReadError,
) -> ModuleType:
    """Import an optional third-party module, or raise a one-line install hint.

    Imported here, inside the readers, so that ``import splinecast`` never pays for them.
    """
    try:
        return importlib.import_module(module)
    except ImportError:
        package = _PACKAGES.get(module, module)
        name = Path(path).name or str(path)
        extra = _EXTRAS.get(module, "io")
        raise error(f"{action} {name} needs {package}: pip install 'splinecast[{extra}]'") from None


def one_line(exc: BaseException) -> str:
    """First line of an exception's message (third-party messages can span several lines)."""
    lines = str(exc).strip().splitlines()
    return lines[0] if lines else type(exc).__name__


def fmt_shape(shape: Any) -> str:
    """``(64, 64, 32)`` -> ``"64x64x32"``, the way sizes are spoken about."""
    return "x".join(str(int(n)) for n in shape)


def check_dtype(dtype: np.dtype, label: str) -> np.dtype:
    """Reject voxel types that :class:`Volume` can neither hold nor convert, naming the file."""
    dtype = np.dtype(dtype)
    if dtype.newbyteorder("=") not in SUPPORTED_DTYPES + CONVERTED_DTYPES:
        names = ", ".join(str(d) for d in SUPPORTED_DTYPES + CONVERTED_DTYPES)
        raise ReadError(f"{label}: voxel type {dtype} is not supported (use one of {names})")
    return dtype


def native(data: np.ndarray) -> np.ndarray:
    """Return ``data`` in native byte order.

    Big-endian files cannot be used in place by the numba kernels, so they are copied once into
    native order here (the only case in which a reader does not keep a memory map).
    """
    if not data.dtype.isnative:
        # np.array (not astype) so the copy is a plain ndarray, not a memmap without a file.
        return np.array(data, dtype=data.dtype.newbyteorder("="))
    return data


def finish_volume(
    data: np.ndarray,
    spacing: Any,
    origin: Any,
    path: str | os.PathLike[str],
    label: str | None = None,
    metadata: dict[str, Any] | None = None,
) -> Volume:
    """Validate what a reader produced and wrap it in a :class:`Volume`.

    Every reader ends here so that shape, dtype and spacing problems are reported as a
    :class:`ReadError` naming the file, instead of a :class:`ParameterError` about ``data``.
    """
    path = Path(path)
    label = label or str(path)
    if data.ndim != 3:
        raise ReadError(f"{label}: expected a 3D volume, got an array of shape {data.shape}")
    if min(data.shape) < 1:
        raise ReadError(f"{label}: the volume is empty (shape {fmt_shape(data.shape)})")
    check_dtype(data.dtype, label)
    try:  # int64, uint64, bool, float16 -> the smallest supported dtype holding them exactly
        data = exact_supported(native(data), label)
    except DataError as exc:
        raise ReadError(str(exc)) from None
    sp = np.broadcast_to(np.asarray(spacing, dtype=np.float64), (3,))
    if not np.all(np.isfinite(sp)) or np.any(sp <= 0):
        raise ReadError(f"{label}: voxel spacing must be three positive numbers, got {tuple(sp)}")
    org = np.broadcast_to(np.asarray(origin, dtype=np.float64), (3,))
    if not np.all(np.isfinite(org)):
        raise ReadError(f"{label}: origin must be three finite numbers, got {tuple(org)}")
    meta: dict[str, Any] = {"name": path.name or str(path), "source": str(path.absolute())}
    meta.update(metadata or {})
    return Volume(data, spacing=tuple(sp), origin=tuple(org), metadata=meta)
