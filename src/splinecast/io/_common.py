"""Helpers shared by the readers: optional imports, third-party failures, label formatting, memory
checks and the final Volume checks (the limits themselves live in
:mod:`splinecast.errors.limits`)."""

from __future__ import annotations

import importlib
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from ..errors import DataError, ReadError, SplinecastError, limits
from ..volume import CONVERTED_DTYPES, SUPPORTED_DTYPES, Volume, exact_supported

__all__ = [
    "require",
    "finish_volume",
    "fmt_shape",
    "native",
    "check_dtype",
    "check_in_memory",
    "one_line",
    "third_party",
]

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
    """First line of an exception's message (third-party messages can span several lines),
    cut to a readable length."""
    try:
        lines = str(exc).strip().splitlines()
    except Exception:  # a message whose __str__ fails still has a type
        lines = []
    text = lines[0] if lines else type(exc).__name__
    return text if len(text) <= 200 else text[:197] + "..."


@contextmanager
def third_party(label: str, what: str) -> Iterator[None]:
    """Turn any failure of a third-party reader inside the block into one :class:`ReadError`.

    ``what`` says what was being done (``"not a readable NIfTI image"``); the library's own first
    line follows in parentheses. Our own errors pass through unchanged. Only library calls belong
    inside the block, so that a bug of ours is not disguised as a bad file. ``MemoryError`` also
    becomes a ReadError: the reader's memory checks came first, so running out here means the
    file is lying about its content. (Warnings and log lines of the libraries are the command
    line's business: it captures them, see :mod:`splinecast.cli`.)
    """
    try:
        yield
    except SplinecastError:
        raise
    except FileNotFoundError:
        raise ReadError(f"{label}: no such file") from None
    except MemoryError:
        raise ReadError(f"{label}: {what} (out of memory while decoding)") from None
    except RecursionError:
        raise ReadError(f"{label}: {what} (nested too deeply)") from None
    except Exception as exc:  # libraries raise anything: ValueError, struct.error, KeyError, ...
        raise ReadError(f"{label}: {what} ({one_line(exc)})") from None


def fmt_shape(shape: Any) -> str:
    """``(64, 64, 32)`` -> ``"64x64x32"``, the way sizes are spoken about."""
    return "x".join(str(int(n)) for n in shape)


def check_in_memory(shape: Any, dtype: Any, label: str, copies: int = 1) -> None:
    """Refuse to load a ``shape`` array of ``dtype`` (``copies`` times) that would not fit the
    memory limit of :func:`splinecast.errors.limits.check_memory`; ``shape`` must be validated
    first."""
    dtype = np.dtype(dtype)
    size = limits.nbytes(shape, dtype.itemsize) * copies
    limits.check_memory(size, f"a {fmt_shape(shape)} {dtype.name} array", label, ReadError)


def check_dtype(dtype: Any, label: str) -> np.dtype:
    """Reject voxel types that :class:`Volume` can neither hold nor convert, naming the file.

    ``dtype`` may be a type name from a header: anything numpy cannot parse, or parses into a
    structured, sub-array or object type, is refused as well.
    """
    try:
        dtype = np.dtype(dtype)
    except Exception:  # numpy raises TypeError, ValueError, SyntaxError for absurd strings
        raise ReadError(f"{label}: {limits.shorten(dtype)} is not a voxel type") from None
    if dtype.fields is not None or dtype.subdtype is not None:
        raise ReadError(f"{label}: voxel type {limits.shorten(str(dtype))} is not supported")
    if dtype.newbyteorder("=") not in SUPPORTED_DTYPES + CONVERTED_DTYPES:
        names = ", ".join(str(d) for d in SUPPORTED_DTYPES + CONVERTED_DTYPES)
        raise ReadError(f"{label}: voxel type {dtype} is not supported (use one of {names})")
    return dtype


def native(data: np.ndarray, label: str = "data") -> np.ndarray:
    """Return ``data`` in native byte order.

    Big-endian files cannot be used in place by the numba kernels, so they are copied once into
    native order here (the only case in which a reader does not keep a memory map), after a
    memory check.
    """
    if not data.dtype.isnative:
        check_in_memory(data.shape, data.dtype, label)
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
    limits.check_shape(data.shape, f"{label}: the volume size", error=ReadError)
    check_dtype(data.dtype, label)
    data = native(data, label)
    if data.dtype not in SUPPORTED_DTYPES and data.dtype != np.bool_:
        # int64, uint64 -> at most as many bytes again; float16 -> float32, twice as many.
        check_in_memory(data.shape, np.float64 if data.dtype.itemsize == 8 else np.float32, label)
    try:  # int64, uint64, bool, float16 -> the smallest supported dtype holding them exactly
        data = exact_supported(data, label)
    except DataError as exc:
        raise ReadError(str(exc)) from None
    sp = limits.check_spacing(spacing, f"{label}: voxel spacing", ReadError)
    org = limits.check_origin(origin, sp, f"{label}: origin", ReadError)
    meta: dict[str, Any] = {"name": path.name or str(path), "source": str(path.absolute())}
    meta.update(metadata or {})
    return Volume(data, spacing=sp, origin=org, metadata=meta)
