"""NumPy's own files: ``.npy`` (memory-mapped) and ``.npz`` (array plus optional spacing/origin).

The array axes are taken as (x, y, z), i.e. ``np.save("v.npy", vol.data)`` round-trips.
"""

from __future__ import annotations

import warnings
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from .._atomic import atomic_outputs
from ..errors import ReadError
from ..volume import Volume
from ._common import finish_volume, one_line

__all__ = ["read_npy", "read_npz", "write_npy", "write_npz"]

#: Keys tried, in order, for the voxel array of an ``.npz`` archive.
_DATA_KEYS = ("data", "volume")
_GEOMETRY_KEYS = ("spacing", "origin")


def read_npy(path: Path) -> Volume:
    """Read a ``.npy`` file as a read-only memory map (C or Fortran order, no copy)."""
    try:
        data = np.load(path, mmap_mode="r", allow_pickle=False)
    except (OSError, ValueError, EOFError) as exc:
        raise ReadError(f"{path}: not a readable .npy file ({one_line(exc)})") from None
    return finish_volume(data, 1.0, 0.0, path, metadata={"format": "npy"})


def read_npz(path: Path) -> Volume:
    """Read an ``.npz`` archive: voxels under ``data``, ``volume`` or the only array.

    Optional ``spacing`` and ``origin`` arrays (a scalar or 3 numbers) give the geometry. The
    voxel array is loaded into memory (zip members cannot be memory-mapped).
    """
    try:
        archive = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise ReadError(f"{path}: not a readable .npz archive ({one_line(exc)})") from None
    if not isinstance(archive, np.lib.npyio.NpzFile):
        raise ReadError(f"{path}: expected an .npz archive, found a single array")
    with archive:
        keys = list(archive.files)
        key = next((k for k in _DATA_KEYS if k in keys), None)
        if key is None:
            candidates = [k for k in keys if k not in _GEOMETRY_KEYS]
            if len(candidates) != 1:
                raise ReadError(
                    f"{path}: cannot tell which array holds the voxels (found {keys}); "
                    "name it 'data' or 'volume'"
                )
            key = candidates[0]
        try:
            data = archive[key]
            spacing = _geometry(archive, "spacing", 1.0, path)
            origin = _geometry(archive, "origin", 0.0, path)
        except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
            raise ReadError(f"{path}: damaged .npz archive ({one_line(exc)})") from None
    return finish_volume(data, spacing, origin, path, metadata={"format": "npz", "key": key})


def _geometry(archive: Any, key: str, default: float, path: Path) -> np.ndarray:
    if key not in archive.files:
        return np.full(3, default)
    value = np.asarray(archive[key], dtype=np.float64).reshape(-1)
    if value.size == 1:
        return np.full(3, value[0])
    if value.size != 3:
        raise ReadError(f"{path}: '{key}' must hold 1 or 3 numbers, got {value.size}")
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

