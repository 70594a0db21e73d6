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
from .selection import Selection

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


def read_nrrd(path: Path, *, allow_external: bool | None = None,
              selection: Selection | None = None) -> Volume:
    """Read a ``.nrrd`` or ``.nhdr`` file: a 3D volume, or one volume of a 4D file.

    A 4D file has three spatial axes and one more, told apart by ``kinds`` (``domain`` and
    ``space`` are spatial) or, without kinds, by the axis whose ``space directions`` entry is
    ``none``. An extra axis of kind ``time`` holds time points; any other (``list``, ``vector``,
    ``RGB-color``, ...) holds channels; without kinds it is taken for time. ``selection`` says
    which to read (default: the first, with a
    :class:`~splinecast.io.selection.SeveralVolumesWarning`).

    Oblique ``space directions`` are snapped to the axes with a warning (the rotation is ignored);
    axes that run backwards are flipped as array views and the origin moved to match.
    """
    nrrd = require("nrrd", path)
    label = str(path)
    selection = selection or Selection()
    lines, header_end = _header_lines(path)
    with third_party(label, "bad NRRD header"):
        header = nrrd.read_header(lines)

    with third_party(label, "bad NRRD sizes"):
        sizes = list(np.atleast_1d(header.get("sizes", [])).tolist())
    dimension = header.get("dimension")
    if dimension not in (3, 4) or len(sizes) != dimension:
        shown = limits.shorten(sizes) if sizes else "(none)"
        raise ReadError(f"{label}: only 3D and 4D NRRD volumes are supported, this one has "
                        f"sizes {shown}")
    shape = limits.check_shape(sizes, f"{label}: sizes", error=ReadError, ndim=dimension)
    extra = _extra_axis(header, len(shape), label)
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

    if extra is None:
        chosen = selection.single(label)
        index = 0
    else:
        # Without kinds the extra axis is taken for time, as a 4D NIfTI's fourth axis is.
        is_time = "kinds" not in header or str(header["kinds"][extra]).lower() == "time"
        count = shape[extra]
        # The axis the file lacks is checked first: a wrong option fails before any warning.
        if is_time:
            channel = selection.chan(label, 1)
            index = selection.time(label, count)
            chosen = selection.metadata(count, index, 1, channel)
        else:
            timepoint = selection.time(label, 1)
            index = selection.chan(label, count)
            chosen = selection.metadata(1, timepoint, count, index)

    spatial = _spatial_header(header, extra)
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
        after = 0
        if extra == len(shape) - 1:  # the slowest axis: decompress, not keep, the others
            one, count = tuple(shape[:3]), shape[3]
            size = limits.nbytes(one, dtype.itemsize)
            byte_skip, after = byte_skip + index * size, (count - index - 1) * size
            shape, extra, index = one, None, 0
        data = _read_compressed(data_path, offset, byte_skip, _COMPRESSED[encoding], shape,
                                dtype, label, after)
    elif encoding in _TEXT:
        data = _read_text(data_path, offset, shape, dtype, label)
    else:
        shown = limits.shorten(encoding) if encoding else "(missing)"
        raise ReadError(f"{label}: NRRD encoding {shown} is not supported "
                        "(use raw, gzip, bzip2 or text)")
    if extra is not None:
        data = np.take(data, index, axis=extra) if encoding == "raw" else np.ascontiguousarray(
            np.take(data, index, axis=extra))

    with third_party(label, "bad NRRD geometry"):
        matrix, origin = _geometry(spatial, label)
    data, spacing, origin = align_to_world(data, matrix, origin, label)
    metadata: dict[str, Any] = {"format": "nrrd", "encoding": encoding, **chosen}
    if "space" in header:
        metadata["space"] = str(header["space"])[:200]
    return finish_volume(data, spacing, origin, path, metadata=metadata)


#: NRRD axis kinds of spatial axes (every other kind is a time or channel axis).
_SPATIAL_KINDS = {"domain", "space"}


def _extra_axis(header: dict[str, Any], dimension: int, label: str) -> int | None:
    """The axis of a 4D file that is not spatial (``None`` for a 3D file)."""
    if dimension == 3:
        return None
    kinds = header.get("kinds")
    if kinds is not None and len(kinds) == dimension:
        others = [i for i, kind in enumerate(kinds) if str(kind).lower() not in _SPATIAL_KINDS]
    else:
        rows = header.get("space directions")
        others = [] if rows is None else [
            i for i, row in enumerate(np.asarray(rows, dtype=np.float64).reshape(dimension, -1))
            if not np.all(np.isfinite(row))]
    if len(others) != 1:
        raise ReadError(f"{label}: a 4D NRRD needs exactly one axis that is not spatial (by its "
                        "kinds, or a space direction of none); cannot tell which it is")
    return others[0]


def _spatial_header(header: dict[str, Any], extra: int | None) -> dict[str, Any]:
    """``header`` with the geometry entries of the three spatial axes only."""
    if extra is None:
        return header
    spatial = dict(header)
    for key in ("spacings", "space directions"):
        if header.get(key) is not None:
            values = np.asarray(header[key], dtype=np.float64)
            spatial[key] = np.delete(values, extra, axis=0)
    return spatial


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
                     shape: tuple[int, ...], dtype: np.dtype, label: str,
                     after: int = 0) -> np.ndarray:
    """Decompress exactly the header's byte count (after ``byte_skip`` bytes), no further.

    ``after``: bytes that follow the ones read (the later volumes of a 4D file, not kept), which
    are decompressed and dropped to check that the stream ends where the header says."""
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
        if not after:
            buffer = limits.read_exact(stream, expected, str(data_path), "compressed data")
        else:
            buffer = limits.read_exact(_Window(stream, expected), expected, str(data_path),
                                       "compressed data")
            with third_party(str(data_path), "corrupt compressed data"):
                _discard(stream, after, str(data_path))
                more = stream.read(1)
            if more:
                raise ReadError(f"{data_path}: compressed data holds more than the "
                                f"{byte_skip + expected + after} bytes the header gives")
    data = buffer.view(dtype).reshape(shape, order="F")
    return native(data, label)


class _Window:
    """The first ``size`` bytes of a stream, then its end (the stream stays open)."""

    def __init__(self, stream: IO[bytes], size: int) -> None:
        self.stream, self.left = stream, size

    def read(self, count: int = -1) -> bytes:
        count = self.left if count < 0 else min(count, self.left)
        chunk = self.stream.read(count) if count else b""
        self.left -= len(chunk)
        return chunk


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
