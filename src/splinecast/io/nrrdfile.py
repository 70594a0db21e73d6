"""NRRD: ``.nrrd`` (header and data in one file) and ``.nhdr`` (detached header), via pynrrd.

Raw-encoded data, attached or detached, is memory-mapped after a size check; compressed or text
encodings are decoded by pynrrd into memory. The geometry comes from ``space directions`` (the
length of each axis vector is the spacing) or ``spacings``, and ``space origin``. The coordinates
are kept in the file's own space (e.g. LPS); its name is stored in ``metadata["space"]``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from .._atomic import atomic_outputs
from ..errors import ParameterError, ReadError
from ..volume import Volume
from ._common import finish_volume, fmt_shape, native, one_line, require
from .orientation import align_to_world
from .rawfile import map_raw

__all__ = ["read_nrrd", "write_nrrd"]

#: NRRD type names (all spellings of the format) -> numpy, for the types splinecast supports.
_NRRD_TYPES = {
    **dict.fromkeys(("signed char", "int8", "int8_t"), "i1"),
    **dict.fromkeys(("uchar", "unsigned char", "uint8", "uint8_t"), "u1"),
    **dict.fromkeys(
        ("short", "short int", "signed short", "signed short int", "int16", "int16_t"), "i2"
    ),
    **dict.fromkeys(
        ("ushort", "unsigned short", "unsigned short int", "uint16", "uint16_t"), "u2"
    ),
    **dict.fromkeys(("int", "signed int", "int32", "int32_t"), "i4"),
    **dict.fromkeys(("uint", "unsigned int", "uint32", "uint32_t"), "u4"),
    "float": "f4",
    "double": "f8",
}


def read_nrrd(path: Path) -> Volume:
    """Read a ``.nrrd`` or ``.nhdr`` file (3 dimensions, one value per voxel).

    Oblique ``space directions`` are snapped to the axes with a warning (the rotation is ignored);
    axes that run backwards are flipped as array views and the origin moved to match.
    """
    nrrd = require("nrrd", path)
    label = str(path)
    try:
        with open(path, "rb") as fh:
            header = nrrd.read_header(fh)
            header_end = fh.tell()
    except FileNotFoundError:
        raise ReadError(f"{label}: no such file") from None
    except OSError as exc:
        raise ReadError(f"{label}: cannot read: {exc.strerror}") from None
    except (nrrd.NRRDError, ValueError, StopIteration, UnicodeDecodeError) as exc:
        raise ReadError(f"{label}: bad NRRD header ({one_line(exc)})") from None

    sizes = [int(n) for n in np.atleast_1d(header.get("sizes", []))]
    if header.get("dimension") != 3 or len(sizes) != 3:
        raise ReadError(
            f"{label}: only 3D NRRD volumes are supported, this one has sizes {sizes or '(none)'}"
        )
    type_name = str(header.get("type", "")).lower()
    if type_name not in _NRRD_TYPES:
        raise ReadError(f"{label}: NRRD type {type_name or '(missing)'!r} is not supported")
    dtype = np.dtype(_NRRD_TYPES[type_name])
    if dtype.itemsize > 1:
        endian = header.get("endian", "little")
        if endian not in ("little", "big"):
            raise ReadError(f"{label}: endian must be little or big, got {endian!r}")
        dtype = dtype.newbyteorder("<" if endian == "little" else ">")
    encoding = str(header.get("encoding", "")).lower()

    if encoding == "raw":
        data = _map_raw_nrrd(path, header, header_end, tuple(sizes), dtype)
    else:
        try:
            data, _ = nrrd.read(str(path), index_order="F")
        except (nrrd.NRRDError, OSError, ValueError, EOFError) as exc:
            raise ReadError(f"{label}: cannot read the NRRD data ({one_line(exc)})") from None
        data = native(data)

    matrix, origin = _geometry(header, label)
    data, spacing, origin = align_to_world(data, matrix, origin, label)
    metadata: dict[str, Any] = {"format": "nrrd", "encoding": encoding}
    if "space" in header:
        metadata["space"] = header["space"]
    return finish_volume(data, spacing, origin, path, metadata=metadata)


def _map_raw_nrrd(
    path: Path, header: dict[str, Any], header_end: int, shape: tuple[int, ...], dtype: np.dtype
) -> np.ndarray:
    data_file = header.get("data file", header.get("datafile"))
    if data_file is None:
        data_path, offset = path, header_end
    else:
        data_file = str(data_file)
        if data_file.upper().startswith("LIST") or " " in data_file.strip():
            raise ReadError(f"{path}: multi-file NRRD data ({data_file!r}) is not supported")
        data_path, offset = path.parent / data_file, 0
    line_skip = int(header.get("line skip", header.get("lineskip", 0)))
    byte_skip = int(header.get("byte skip", header.get("byteskip", 0)))
    if line_skip < 0 or byte_skip < -1:
        raise ReadError(f"{path}: line skip must be >= 0 and byte skip >= -1")
    if line_skip:
        try:
            with open(data_path, "rb") as fh:
                fh.seek(offset)
                for _ in range(line_skip):
                    fh.readline()
                offset = fh.tell()
        except OSError as exc:
            raise ReadError(f"{data_path}: cannot read: {exc.strerror}") from None
    offset = -1 if byte_skip == -1 else offset + byte_skip
    return map_raw(data_path, shape, dtype, offset=offset, order="F", header=path.name)


def _geometry(header: dict[str, Any], label: str) -> tuple[np.ndarray, np.ndarray]:
    """Axis matrix (columns = world step per index axis) and origin from a NRRD header."""
    matrix = np.eye(3)
    spacings = np.asarray(header.get("spacings", [np.nan] * 3), dtype=np.float64).reshape(-1)
    for axis in range(3):
        if axis < spacings.size and np.isfinite(spacings[axis]) and spacings[axis] != 0:
            matrix[axis, axis] = spacings[axis]
    directions = header.get("space directions")
    if directions is not None:
        rows = np.asarray(directions, dtype=np.float64)
        if rows.shape != (3, 3):
            raise ReadError(
                f"{label}: space directions must be 3 vectors of 3 numbers, got shape {rows.shape}"
            )
        for axis in range(3):
            # pynrrd gives a row of NaN for an axis declared 'none'; keep its 'spacings' value.
            if np.all(np.isfinite(rows[axis])):
                matrix[:, axis] = rows[axis]
    origin = np.zeros(3)
    if header.get("space origin") is not None:
        origin = np.asarray(header["space origin"], dtype=np.float64).reshape(-1)
        if origin.size != 3 or not np.all(np.isfinite(origin)):
            raise ReadError(f"{label}: space origin must be 3 numbers, got {origin.tolist()}")
    return matrix, origin


def write_nrrd(volume: Volume, path: Path) -> None:
    """Write a ``.nrrd`` (attached header, raw little-endian encoding, x fastest) with pynrrd."""
    nrrd = require("nrrd", path, action="writing", error=ParameterError)
    data = volume.data
    if data.dtype.newbyteorder("=").str[1:] not in set(_NRRD_TYPES.values()):
        raise ParameterError(
            f"{path}: NRRD cannot hold {data.dtype} voxels ({fmt_shape(data.shape)})"
        )
    header = {
        "encoding": "raw",
        "endian": "little",
        "space dimension": 3,
        "space directions": np.diag(np.asarray(volume.spacing, dtype=np.float64)),
        "space origin": np.asarray(volume.origin, dtype=np.float64),
        "kinds": ["domain", "domain", "domain"],
    }
    little = np.asarray(data, dtype=data.dtype.newbyteorder("<"))
    with atomic_outputs(path) as (temp,), open(temp, "wb") as fh:
        nrrd.write(fh, little, header, index_order="F")
