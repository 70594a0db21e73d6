"""NumPy's own files: ``.npy`` (memory-mapped) and ``.npz`` (array plus optional spacing/origin).

The array axes are taken as (x, y, z), i.e. ``np.save("v.npy", vol.data)`` round-trips. The
``.npy`` header is parsed and validated (shape, type, byte count against the file or zip member
size) before anything is mapped or decompressed; pickled (object) arrays are never loaded.
"""

from __future__ import annotations

import warnings
import zipfile
from pathlib import Path
from typing import IO

import numpy as np

from .._atomic import atomic_outputs
from ..errors import ReadError, limits
from ..volume import Volume
from ._common import check_dtype, check_in_memory, finish_volume, fmt_shape, third_party

__all__ = ["read_npy", "read_npz", "write_npy", "write_npz"]

#: Keys tried, in order, for the voxel array of an ``.npz`` archive.
_DATA_KEYS = ("data", "volume")
_GEOMETRY_KEYS = ("spacing", "origin")
#: numpy's own bound on the header's text (a bigger one is refused, as np.load does).
_MAX_HEADER = 10_000
#: Largest zip member holding ``spacing`` or ``origin`` (three float64 and a header).
_MAX_GEOMETRY_BYTES = 4096


def _read_header(fh: IO[bytes], label: str) -> tuple[tuple[int, ...], bool, np.dtype]:
    """Shape, Fortran flag and dtype of the ``.npy`` stream ``fh``, positioned at the data."""
    fmt = np.lib.format
    with third_party(label, "not a readable .npy header"):
        version = fmt.read_magic(fh)
        if version == (1, 0):
            shape, fortran, dtype = fmt.read_array_header_1_0(fh, max_header_size=_MAX_HEADER)
        elif version == (2, 0):
            shape, fortran, dtype = fmt.read_array_header_2_0(fh, max_header_size=_MAX_HEADER)
        else:
            raise ReadError(f"{label}: .npy format version {version} is not supported")
    if not isinstance(shape, tuple) or len(shape) != 3:
        raise ReadError(f"{label}: expected a 3D volume, got an array of shape {shape!r}")
    shape = limits.check_shape(shape, f"{label}: the array shape", error=ReadError)
    dtype = check_dtype(dtype, label)
    return shape, bool(fortran), dtype


def read_npy(path: Path) -> Volume:
    """Read a ``.npy`` file as a read-only memory map (C or Fortran order, no copy)."""
    label = str(path)
    try:
        with open(path, "rb") as fh:
            shape, fortran, dtype = _read_header(fh, label)
            offset = fh.tell()
    except OSError as exc:
        raise ReadError(f"{label}: cannot read: {exc.strerror or exc}") from None
    expected = limits.nbytes(shape, dtype.itemsize)
    size = limits.check_regular_file(path, label).st_size
    wanted = f"expected {expected} bytes for {fmt_shape(shape)} {dtype.name}"
    if size != offset + expected:
        state = "truncated" if size < offset + expected else "longer than its header says"
        raise ReadError(f"{label}: {wanted} after a {offset}-byte header, file has {size} "
                        f"({state})")
    order = "F" if fortran else "C"
    with third_party(label, "cannot memory-map the data"):
        data = np.memmap(path, dtype=dtype, mode="r", offset=offset, shape=shape, order=order)
    return finish_volume(data, 1.0, 0.0, path, metadata={"format": "npy"})


def _member(archive: zipfile.ZipFile, info: zipfile.ZipInfo, label: str,
            max_bytes: int | None = None) -> np.ndarray:
    """One array of an ``.npz``: header checked against the member's size, then decompressed
    exactly that far (never further) after a memory check."""
    where = f"{label} [{info.filename}]"
    if max_bytes is not None and info.file_size > max_bytes:
        raise ReadError(f"{where}: {info.file_size} bytes, expected a few numbers")
    with third_party(where, "damaged .npz member"):
        fh = archive.open(info)
    with fh:
        fmt = np.lib.format
        if max_bytes is not None:  # spacing/origin: any small shape, parsed the same way
            with third_party(where, "not a readable .npy header"):
                version = fmt.read_magic(fh)
                reader = {(1, 0): fmt.read_array_header_1_0, (2, 0): fmt.read_array_header_2_0}
                if version not in reader:
                    raise ReadError(f"{where}: .npy format version {version} is not supported")
                shape, fortran, dtype = reader[version](fh, max_header_size=_MAX_HEADER)
            dtype = check_dtype(dtype, where)
            if len(shape) > 1 or any(not 1 <= int(n) <= 3 for n in shape):
                raise ReadError(f"{where} must hold 1 or 3 numbers, got shape {shape}")
        else:
            shape, fortran, dtype = _read_header(fh, where)
        expected = limits.nbytes(shape, dtype.itemsize)
        header = info.file_size - expected
        if header < 0 or header > _MAX_HEADER + 16:
            raise ReadError(
                f"{where}: expected {expected} bytes for {fmt_shape(shape) or 'a scalar'} "
                f"{dtype.name}, the member holds {info.file_size}"
            )
        check_in_memory(shape, dtype, where)
        raw = limits.read_exact(fh, expected, where, "array data")
    return raw.view(dtype).reshape(shape, order="F" if fortran else "C")


def read_npz(path: Path) -> Volume:
    """Read an ``.npz`` archive: voxels under ``data``, ``volume`` or the only array.

    Optional ``spacing`` and ``origin`` arrays (a scalar or 3 numbers) give the geometry. The
    voxel array is loaded into memory (zip members cannot be memory-mapped).
    """
    label = str(path)
    with third_party(label, "not a readable .npz archive"):
        archive = zipfile.ZipFile(path)
    with archive:
        with third_party(label, "not a readable .npz archive"):
            members = {
                info.filename[: -len(".npy")]: info
                for info in archive.infolist()
                if info.filename.endswith(".npy")
            }
        keys = list(members)
        key = next((k for k in _DATA_KEYS if k in keys), None)
        if key is None:
            candidates = [k for k in keys if k not in _GEOMETRY_KEYS]
            if len(candidates) != 1:
                found = limits.shorten(keys, 80) if keys else "no .npy array"
                raise ReadError(
                    f"{path}: cannot tell which array holds the voxels (found {found}); "
                    "name it 'data' or 'volume'"
                )
            key = candidates[0]
        data = _member(archive, members[key], label)
        spacing = _geometry(archive, members, "spacing", 1.0, label)
        origin = _geometry(archive, members, "origin", 0.0, label)
    return finish_volume(data, spacing, origin, path, metadata={"format": "npz", "key": key})


def _geometry(archive: zipfile.ZipFile, members: dict[str, zipfile.ZipInfo], key: str,
              default: float, label: str) -> np.ndarray:
    if key not in members:
        return np.full(3, default)
    value = _member(archive, members[key], label, max_bytes=_MAX_GEOMETRY_BYTES)
    if value.dtype.kind not in "uif":
        raise ReadError(f"{label}: '{key}' must hold numbers, got {value.dtype}")
    value = np.asarray(value, dtype=np.float64).reshape(-1)
    if value.size == 1:
        return np.full(3, value[0])
    if value.size != 3:
        raise ReadError(f"{label}: '{key}' must hold 1 or 3 numbers, got {value.size}")
    return value


def write_npy(volume: Volume, path: Path) -> None:
    """Write the voxels to ``.npy``, which cannot hold spacing or origin (warns if they are set)."""
    if volume.spacing != (1.0, 1.0, 1.0) or volume.origin != (0.0, 0.0, 0.0):
        warnings.warn(
            f"{path}: .npy stores no spacing or origin; use .npz, .mhd or .nrrd to keep them",
            UserWarning,
            stacklevel=3,
        )
    with atomic_outputs(path) as (temp,), open(temp, "wb") as fh:
        np.save(fh, np.asanyarray(volume.data), allow_pickle=False)


def write_npz(volume: Volume, path: Path) -> None:
    """Write an uncompressed ``.npz`` with ``data``, ``spacing`` and ``origin``."""
    with atomic_outputs(path) as (temp,), open(temp, "wb") as fh:
        np.savez(
            fh,
            data=np.asarray(volume.data),
            spacing=np.array(volume.spacing),
            origin=np.array(volume.origin),
        )
