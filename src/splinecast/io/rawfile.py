"""Headerless voxel data: memory-map it after checking its size, and write it x-fastest.

MetaImage, detached NRRD and the JSON sidecar all describe a raw block of voxels with x varying
fastest. Mapping that block with ``shape=(nx, ny, nz), order="F"`` gives ``data[i, j, k]`` with
``i`` along x directly, without copying a byte. Big-endian data is the exception: it is copied
once into native order (see :func:`splinecast.io._common.native`).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import BinaryIO

import numpy as np

from ..errors import ReadError, limits
from ._common import check_dtype, fmt_shape, native, third_party

__all__ = ["map_raw", "write_raw"]

#: Planes written per call: large enough to be fast, small enough not to copy a whole volume.
_PLANES_PER_WRITE = 8


def map_raw(
    path: str | os.PathLike[str],
    shape: tuple[int, int, int],
    dtype: np.dtype,
    *,
    offset: int = 0,
    order: str = "F",
    header: str | None = None,
) -> np.ndarray:
    """Memory-map raw voxels, checking the file size against the header first.

    Parameters
    ----------
    path : path-like
        The data file.
    shape : tuple of 3 int
        ``(nx, ny, nz)``; a fourth entry for a 4D file.
    dtype : numpy dtype
        Voxel type including byte order.
    offset : int, optional
        Bytes to skip before the voxels; ``-1`` means the voxels are the last bytes of the file.
    order : {"F", "C"}, optional
        ``"F"``: x varies fastest in the file (MetaImage, NRRD); ``"C"``: z varies fastest.
    header : str, optional
        Name of the header that described the data, quoted when the file is too long.

    Returns
    -------
    ndarray
        A read-only :class:`numpy.memmap` of shape ``(nx, ny, nz)``, or a native-order copy for
        big-endian data.
    """
    path = Path(path)
    dtype = check_dtype(dtype, str(path))
    # Four axes: a 4D file (time points or channels) mapped whole, a volume taken by the caller.
    shape = limits.check_shape(shape, f"{header or path}: the size", error=ReadError,
                               ndim=4 if len(shape) == 4 else 3)
    if order not in ("F", "C"):
        raise ReadError(f"{path}: voxel order must be 'F' (x fastest) or 'C', got {order!r}")
    offset = limits.check_count(offset, f"{header or path}: the header size", lo=-1,
                                error=ReadError)
    expected = limits.nbytes(shape, dtype.itemsize)
    if not path.exists():
        named = f" (named in {header})" if header else ""
        raise ReadError(f"{path}: data file not found{named}")
    size = limits.check_regular_file(path, str(path)).st_size
    if offset == -1:
        offset = size - expected
        if offset < 0:
            raise ReadError(
                f"{path}: expected {expected} bytes for {fmt_shape(shape)} {dtype.name}, "
                f"file has {size} (truncated)"
            )
    elif offset < 0:
        raise ReadError(f"{path}: header size must be >= 0 or -1, got {offset}")
    wanted = (
        f"expected {expected} bytes for {fmt_shape(shape)} {dtype.name} "
        f"after a {offset}-byte header"
    )
    if size < offset + expected:
        raise ReadError(f"{path}: {wanted}, file has {size} (truncated)")
    if size > offset + expected:
        where = f"{header} describes" if header else "the header describes"
        raise ReadError(
            f"{path}: {wanted}, file has {size} (longer than {where}; wrong size or type?)"
        )
    with third_party(str(path), "cannot memory-map the data"):
        data = np.memmap(path, dtype=dtype, mode="r", offset=offset, shape=shape, order=order)
    return native(data, str(path))


def write_raw(fh: BinaryIO, data: np.ndarray) -> None:
    """Write ``data`` (shape (nx, ny, nz)) little-endian with x varying fastest.

    Writes a few z-planes at a time so that a memory-mapped volume is never copied whole.
    """
    little = data.dtype.newbyteorder("<")
    for k0 in range(0, data.shape[2], _PLANES_PER_WRITE):
        block = np.asarray(data[:, :, k0 : k0 + _PLANES_PER_WRITE], dtype=little)
        fh.write(block.tobytes(order="F"))
