"""NRRD: ``.nrrd`` (header and data in one file) and ``.nhdr`` (detached header).

pynrrd parses the header (read here up to :data:`_MAX_HEADER_BYTES`); the data is read here so that
every size is checked first: raw-encoded data, attached or detached, is memory-mapped after a size
check; gzip and bzip2 data is decompressed exactly as far as the header's byte count (never
further) after a memory check; text data is read with a bounded size. A detached data file must
lie in the header's folder or below (see :func:`splinecast.errors.limits.check_data_file`).
The geometry
comes from ``space directions`` (the length of each axis vector is the spacing) or ``spacings``,
and ``space origin``. The coordinates are kept in the file's own space (e.g. LPS); its name is
stored in ``metadata["space"]``.
"""

from __future__ import annotations

import bz2
import gzip
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any

import numpy as np

from .._atomic import atomic_outputs
from ..errors import ParameterError, ReadError, limits
from ..volume import Volume
from ._common import check_in_memory, finish_volume, fmt_shape, native, require, third_party
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
#: Encodings read here, by every name the format allows.
_COMPRESSED: dict[str, Callable[[IO[bytes]], IO[bytes]]] = {
    "gzip": lambda raw: gzip.GzipFile(fileobj=raw, mode="rb"),
    "gz": lambda raw: gzip.GzipFile(fileobj=raw, mode="rb"),
    "bzip2": lambda raw: bz2.BZ2File(raw, mode="rb"),
    "bz2": lambda raw: bz2.BZ2File(raw, mode="rb"),
}
_TEXT = ("text", "txt", "ascii")
#: A header longer than this is not a NRRD header.
_MAX_HEADER_BYTES = 1 << 20
#: Most characters a text-encoded value may take, with its separator (bounds a text read).
_MAX_TEXT_CHARS = 64
#: Largest "line skip" (lines) and decompressed "byte skip" (bytes) accepted.
_MAX_LINE_SKIP = 1 << 16
_MAX_BYTE_SKIP = 1 << 30


def read_nrrd(path: Path, *, allow_external: bool | None = None) -> Volume:
    """Read a ``.nrrd`` or ``.nhdr`` file (3 dimensions, one value per voxel).

    Oblique ``space directions`` are snapped to the axes with a warning (the rotation is ignored);
    axes that run backwards are flipped as array views and the origin moved to match.
    """
    nrrd = require("nrrd", path)
    label = str(path)
    lines, header_end = _header_lines(path)
    with third_party(label, "bad NRRD header"):
        header = nrrd.read_header(lines)

    with third_party(label, "bad NRRD sizes"):
        sizes = list(np.atleast_1d(header.get("sizes", [])).tolist())
    if header.get("dimension") != 3 or len(sizes) != 3:
        shown = limits.shorten(sizes) if sizes else "(none)"
        raise ReadError(f"{label}: only 3D NRRD volumes are supported, this one has sizes {shown}")
    shape = limits.check_shape(sizes, f"{label}: sizes", error=ReadError)
    type_name = str(header.get("type", "")).lower()
    if type_name not in _NRRD_TYPES:
        shown = limits.shorten(type_name) if type_name else "(missing)"
        raise ReadError(f"{label}: NRRD type {shown} is not supported")
    dtype = np.dtype(_NRRD_TYPES[type_name])
    if dtype.itemsize > 1:
        endian = header.get("endian", "little")
        if endian not in ("little", "big"):
            raise ReadError(f"{label}: endian must be little or big, got {limits.shorten(endian)}")
        dtype = dtype.newbyteorder("<" if endian == "little" else ">")
    encoding = str(header.get("encoding", "")).lower()

    data_path, offset = _data_location(path, header, header_end, allow_external)
    line_skip = limits.check_count(header.get("line skip", header.get("lineskip", 0)),
                                   f"{label}: line skip", lo=0, hi=_MAX_LINE_SKIP, error=ReadError)
    byte_skip = limits.check_count(header.get("byte skip", header.get("byteskip", 0)),
                                   f"{label}: byte skip", lo=-1, hi=_MAX_BYTE_SKIP,
                                   error=ReadError)
    if line_skip:
        offset = _skip_lines(data_path, offset, line_skip)
    if encoding == "raw":
        offset = -1 if byte_skip == -1 else offset + byte_skip
        data = map_raw(data_path, shape, dtype, offset=offset, order="F", header=path.name)
    elif encoding in _COMPRESSED:
        if byte_skip == -1:
            raise ReadError(f"{label}: byte skip -1 is not allowed with {encoding} data")
        data = _read_compressed(data_path, offset, byte_skip, _COMPRESSED[encoding], shape,
                                dtype, label)
    elif encoding in _TEXT:
        data = _read_text(data_path, offset, shape, dtype, label)
    else:
        shown = limits.shorten(encoding) if encoding else "(missing)"
        raise ReadError(f"{label}: NRRD encoding {shown} is not supported "
                        "(use raw, gzip, bzip2 or text)")

    with third_party(label, "bad NRRD geometry"):
        matrix, origin = _geometry(header, label)
    data, spacing, origin = align_to_world(data, matrix, origin, label)
    metadata: dict[str, Any] = {"format": "nrrd", "encoding": encoding}
    if "space" in header:
        metadata["space"] = str(header["space"])[:200]
    return finish_volume(data, spacing, origin, path, metadata=metadata)


def _header_lines(path: Path) -> tuple[list[bytes], int]:
    """The header's lines (up to the blank line that ends it) and the offset just after it."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(_MAX_HEADER_BYTES + 1)
    except OSError as exc:
        raise ReadError(f"{path}: cannot read: {exc.strerror or exc}") from None
    lines = head.splitlines(keepends=True)
    end = 0
    for number, line in enumerate(lines):
        if number and not line.rstrip():
            return lines[:number], end + len(line)
        end += len(line)
    if len(head) > _MAX_HEADER_BYTES:
        raise ReadError(f"{path}: NRRD header longer than {_MAX_HEADER_BYTES} bytes")
    return lines, len(head)  # a detached header: it ends with the file


def _data_location(path: Path, header: dict[str, Any], header_end: int,
                   allow_external: bool | None) -> tuple[Path, int]:
    """The file holding the voxels and where they start (before line and byte skips)."""
    data_file = header.get("data file", header.get("datafile"))
    if data_file is None:
        return path, header_end
    data_file = str(data_file)
    if data_file.upper().startswith("LIST") or " " in data_file.strip():
        raise ReadError(
            f"{path}: multi-file NRRD data ({limits.shorten(data_file)}) is not supported"
        )
    return limits.check_data_file(path, data_file, "data file",
                                  allow_external=allow_external), 0


def _skip_lines(data_path: Path, offset: int, count: int) -> int:
    """Offset after ``count`` lines from ``offset`` (each at most one header's length)."""
    with third_party(str(data_path), "cannot skip lines"):
        limits.check_regular_file(data_path, str(data_path))
        with open(data_path, "rb") as fh:
            fh.seek(offset)
            for _ in range(count):
                if len(fh.readline(_MAX_HEADER_BYTES + 1)) > _MAX_HEADER_BYTES:
                    raise ReadError(f"{data_path}: a skipped line is longer than "
                                    f"{_MAX_HEADER_BYTES} bytes")
            return fh.tell()


def _read_compressed(data_path: Path, offset: int, byte_skip: int, opener: Any,
                     shape: tuple[int, ...], dtype: np.dtype, label: str) -> np.ndarray:
    """Decompress exactly the header's byte count (after ``byte_skip`` bytes), no further."""
    expected = limits.nbytes(shape, dtype.itemsize)
    check_in_memory(shape, dtype, label, copies=2 if not dtype.isnative else 1)
    limits.check_regular_file(data_path, str(data_path))
    with third_party(str(data_path), "cannot open the compressed data"):
        raw = open(data_path, "rb")
    with raw:
        with third_party(str(data_path), "corrupt compressed data"):
            raw.seek(offset)
            stream = opener(raw)
            _discard(stream, byte_skip, str(data_path))
        buffer = limits.read_exact(stream, expected, str(data_path), "compressed data")
    data = buffer.view(dtype).reshape(shape, order="F")
    return native(data, label)


def _discard(stream: IO[bytes], count: int, name: str) -> None:
    while count > 0:
        chunk = stream.read(min(count, 1 << 20))
        if not chunk:
            raise ReadError(f"{name}: the compressed data ends within its byte skip")
        count -= len(chunk)


def _read_text(data_path: Path, offset: int, shape: tuple[int, ...], dtype: np.dtype,
               label: str) -> np.ndarray:
    """Whitespace-separated numbers, bounded by :data:`_MAX_TEXT_CHARS` per value."""
    count = limits.nbytes(shape, 1)
    # The tokens briefly live as Python strings and as float64: budget that, not just the result.
    check_in_memory(shape, np.float64, label, copies=8)
    size = limits.check_regular_file(data_path, str(data_path)).st_size
    budget = count * _MAX_TEXT_CHARS + 4096
    if size - offset > budget:
        raise ReadError(f"{data_path}: {size - offset} bytes of text for {count} values; "
                        "longer than the header allows")
    with third_party(str(data_path), "cannot read the text data"):
        with open(data_path, "rb") as fh:
            fh.seek(offset)
            tokens = fh.read(budget).split()
    if len(tokens) != count:
        raise ReadError(f"{data_path}: expected {count} values for {fmt_shape(shape)}, "
                        f"found {len(tokens)}")
    with third_party(str(data_path), "text data holds a value that is not a number"):
        values = np.array(tokens, dtype=np.float64)
    del tokens
    if dtype.kind in "iu":
        info = np.iinfo(dtype)
        if not (np.all(values == np.round(values)) and values.min() >= info.min
                and values.max() <= info.max):
            raise ReadError(f"{data_path}: text values do not fit the {dtype.name} type")
    return values.astype(dtype.newbyteorder("=")).reshape(shape, order="F")


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
