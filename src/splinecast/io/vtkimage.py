"""VTK image data: XML ``.vti`` and legacy ``.vtk`` structured points, through the vtk package.

VTK decodes every encoding of its formats (ASCII, inline base64 binary, appended raw or base64,
zlib/LZ4/LZMA compression, either byte order); :meth:`splinecast.Volume.from_vtk` turns the
decoded ``vtkImageData`` into a volume (axis order, origin and array choice are explained there).
The vtk package is imported only here, when such a file is read or written
(``pip install 'splinecast[vtk]'``).

VTK reports most damage (bad XML, a wrong header) through its error events, which are turned into
one :class:`ReadError`. What it trusts without checking (extents and component counts it
allocates from, size headers of binary data, compression block sizes, a legacy file's counts) is
checked here first, through :mod:`splinecast.errors.limits`: sizes, spacing, origin, memory, and
every binary array's size header against its extent and type and against the file's length, so
decompression is bounded by the size the extent gives.
"""

from __future__ import annotations

import binascii
import contextlib
import importlib
import math
import os
import re
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from .._atomic import atomic_outputs
from ..errors import ParameterError, ReadError, SplinecastError, limits
from ..volume import Volume, find_vtk_array
from .selection import Selection

__all__ = ["read_vti", "read_legacy_vtk", "write_vti"]

_HINT = "pip install 'splinecast[vtk]'"
_HEADER_TYPES = {"UInt32": 4, "UInt64": 8}
_DATASET = re.compile(rb"^DATASET\s+(\S+)", re.MULTILINE | re.IGNORECASE)


def _vtk_module(name: str, path: Path, action: str, error: type[SplinecastError]) -> ModuleType:
    try:
        return importlib.import_module(f"vtkmodules.{name}")
    except ImportError:
        raise error(f"{action} {path.name} needs vtk: {_HINT}") from None


@contextlib.contextmanager
def _vtk_errors(algorithm: Any, label: str, error: type[SplinecastError]) -> Iterator[None]:
    """Collect the errors VTK reports for ``algorithm`` (instead of printing them) and raise the
    first as one line."""
    core = importlib.import_module("vtkmodules.vtkCommonCore")
    messages: list[str] = []

    def on_error(_obj: Any, _event: str, message: Any = None) -> None:
        messages.append(str(message or "unknown VTK error"))

    on_error.CallDataType = "string0"  # VTK passes the message text to the observer
    tag = algorithm.AddObserver("ErrorEvent", on_error)
    logger = core.vtkLogger
    previous = logger.GetCurrentVerbosityCutoff()
    logger.SetStderrVerbosity(logger.VERBOSITY_OFF)
    display = core.vtkObject.GetGlobalWarningDisplay()
    core.vtkObject.GlobalWarningDisplayOff()
    try:
        yield
    finally:
        algorithm.RemoveObserver(tag)
        logger.SetStderrVerbosity(previous)
        core.vtkObject.SetGlobalWarningDisplay(display)
    if messages:
        first = " ".join(messages[0].split())
        first = re.sub(r"^.*?\(0x[0-9a-f]+\):\s*", "", first)  # drop "vtkClass (0x...): "
        raise error(f"{label}: VTK cannot read it: {first}")


_ATTRIBUTE = re.compile(rb"""(\w+)\s*=\s*(?:"([^"]*)"|'([^']*)')""")
_TAG = re.compile(rb"<(/?)(\w+)([^>]*)>")
#: VTK XML data types and their sizes in bytes (String: a bound per tuple for the memory check).
_XML_TYPES = {"Int8": 1, "UInt8": 1, "Int16": 2, "UInt16": 2, "Int32": 4, "UInt32": 4,
              "Int64": 8, "UInt64": 8, "Float32": 4, "Float64": 8, "String": 32}
_COMPRESSORS = ("vtkZLibDataCompressor", "vtkLZ4DataCompressor", "vtkLZMADataCompressor")
#: Largest block size a compressed array may declare beyond its own size (VTK writes 32 KiB).
_MAX_BLOCK = 1 << 24
#: Most components per tuple of any array (VTK writes at most 9 for tensors).
MAX_COMPONENTS = 1024


def _attributes(tag: bytes) -> dict[str, str]:
    return {m.group(1).decode(): (m.group(2) if m.group(2) is not None else m.group(3))
            .decode("utf-8", "replace") for m in _ATTRIBUTE.finditer(tag)}


def _numbers(text: str | None, count: int, field: str, label: str) -> list[str]:
    values = (text or "").split()
    if len(values) != count:
        raise ReadError(f"{label}: {field} must be {count} numbers, got "
                        f"{limits.shorten(text)}")
    return values


def _extent(text: str | None, field: str, label: str) -> tuple[int, ...]:
    """Six integers ``x0 x1 y0 y1 z0 z1`` with ``x0 <= x1`` (etc.), each within 32 bits."""
    values = [limits.check_count(_integer(v), f"{label}: {field}", lo=-(2**31), hi=2**31 - 1,
                                 error=ReadError)
              for v in _numbers(text, 6, field, label)]
    sizes = [values[2 * a + 1] - values[2 * a] + 1 for a in range(3)]
    limits.check_shape(sizes, f"{label}: {field} {text!r} gives sizes", error=ReadError)
    return tuple(values)


def _integer(text: str) -> int | str:
    try:
        return int(text)
    except ValueError:
        return text


class _Sizes:
    """The binary size header of one array: reads words from raw bytes or base64 text."""

    def __init__(self, label: str, width: int, order: str) -> None:
        self.label, self.width = label, width
        self.dtype = np.dtype(f"{order}u{width}")

    def raw(self, data: bytes, at: int, count: int) -> np.ndarray:
        if at < 0 or at + count * self.width > len(data):
            raise ReadError(f"{self.label}: truncated inside the appended data (a size header "
                            f"at byte {at} runs past the end of the file)")
        return np.frombuffer(data, dtype=self.dtype, count=count, offset=at).astype(object)

    def base64(self, text: bytes, count: int) -> np.ndarray:
        need = -(-count * self.width // 3) * 4
        chunk = text[:need]
        if len(chunk) < need:
            raise ReadError(f"{self.label}: truncated base64 data (a size header is cut)")
        try:
            decoded = binascii.a2b_base64(chunk)
        except binascii.Error as exc:
            raise ReadError(f"{self.label}: corrupt base64 data ({exc})") from None
        if len(decoded) < count * self.width:
            raise ReadError(f"{self.label}: truncated base64 data (a size header is cut)")
        return np.frombuffer(decoded, dtype=self.dtype, count=count).astype(object)


def _check_array_sizes(words: Any, expected: int, compressed: bool, available: int,
                       name: str, label: str) -> None:
    """The size header of one binary array against what its extent and type give.

    ``words(offset, count)`` reads ``count`` header words starting at word ``offset``;
    ``available`` is how many data bytes follow the header at most (the rest of the file).
    """
    where = f"{label}: array {name!r}"
    if not compressed:
        size = int(words(0, 1)[0])
        if size != expected:
            raise ReadError(f"{where}: the header gives {size} bytes, its extent and type "
                            f"give {expected}")
        if size > available:
            raise ReadError(f"{label}: truncated: array {name!r} needs {size} bytes, "
                            f"{available} are left in the file")
        return
    blocks, block, last = (int(v) for v in words(0, 3))
    if block < 1 or last > block or (block > expected and block > _MAX_BLOCK):
        raise ReadError(f"{where}: impossible compression blocks (block size {block}, last "
                        f"block {last})")
    total = (blocks - 1) * block + (last or block) if blocks else 0
    if total != expected:
        raise ReadError(f"{where}: the compression header gives {total} bytes once "
                        f"decompressed, its extent and type give {expected}")
    if blocks * 3 > available:  # a compressed block takes a few bytes at least
        raise ReadError(f"{where}: truncated: {blocks} compressed blocks announced")
    sizes = words(3, blocks)
    worst = block + block // 8 + 1024  # no compressor expands a block more than this
    if any(int(c) > worst for c in sizes) or sum(int(c) for c in sizes) > available:
        raise ReadError(f"{where}: compressed block sizes run past the end of the file or "
                        f"exceed the block size")


def _check_vti_header(path: Path, label: str) -> bytes:
    """Everything VTK would trust in a ``.vti`` before it reads it, checked against
    :mod:`splinecast.errors.limits`: the file is regular and fits in memory, it holds
    ImageData, the extents give valid sizes, spacing and origin are sane, every data array has
    a known type, a bounded component count and (binary) a size header that agrees with its
    extent and type and lies within the file, and all arrays together fit in memory (VTK
    allocates them from the extents before decoding). Returns the file's bytes."""
    info = limits.check_regular_file(path, label)
    limits.check_memory(2 * info.st_size, "the file (read twice)", label, ReadError)
    fd = limits.open_regular(path, label)
    with os.fdopen(fd, "rb") as fh:
        raw = fh.read(info.st_size + 1)
    start = raw.find(b"<VTKFile")
    if start < 0:
        raise ReadError(f"{label}: not a VTK XML file (no <VTKFile> element)")
    head = _attributes(raw[start:raw.find(b">", start)])
    if head.get("type") != "ImageData":
        kind = limits.printable(str(head.get("type", "unknown"))[:40])
        raise ReadError(f"{label}: VTK {kind} data, not "
                        "ImageData (splinecast reads regular grids: .vti image data)")
    width = _HEADER_TYPES.get(head.get("header_type", "UInt32"))
    if width is None:
        raise ReadError(f"{label}: unknown header_type {limits.shorten(head.get('header_type'))}")
    order = head.get("byte_order", "LittleEndian")
    if order not in ("LittleEndian", "BigEndian"):
        raise ReadError(f"{label}: unknown byte_order {limits.shorten(order)}")
    compressor = head.get("compressor")
    if compressor is not None and compressor not in _COMPRESSORS:
        raise ReadError(f"{label}: unknown compressor {limits.shorten(compressor)}")
    sizes = _Sizes(label, width, "<" if order == "LittleEndian" else ">")
    appended_at = raw.find(b"<AppendedData")
    body = raw[:appended_at] if appended_at >= 0 else raw

    whole: tuple[int, ...] | None = None
    whole_counts = {"PointData": 0, "CellData": 0}
    counts = {"PointData": 0, "CellData": 0}
    section = None
    total = 0
    appended: list[tuple[int, int, str]] = []  # (offset, expected bytes, name)
    for tag in _TAG.finditer(body):
        closing, element, attrs = tag.group(1), tag.group(2).decode(), _attributes(tag.group(3))
        if element == "ImageData" and not closing:
            whole = _extent(attrs.get("WholeExtent"), "WholeExtent", label)
            whole_dims = [whole[2 * a + 1] - whole[2 * a] + 1 for a in range(3)]
            whole_counts = {"PointData": math.prod(whole_dims),
                            "CellData": math.prod(max(d - 1, 1) for d in whole_dims)}
            spacing = limits.check_spacing(
                [_float(v) for v in _numbers(attrs.get("Spacing", "1 1 1"), 3, "Spacing", label)],
                f"{label}: Spacing", ReadError)
            limits.check_origin(
                [_float(v) for v in _numbers(attrs.get("Origin", "0 0 0"), 3, "Origin", label)],
                spacing, f"{label}: Origin", ReadError)
        elif element == "Piece" and not closing:
            if whole is None:
                raise ReadError(f"{label}: <Piece> outside <ImageData>")
            ext = _extent(attrs.get("Extent"), "Piece Extent", label)
            if any(ext[2 * a] < whole[2 * a] or ext[2 * a + 1] > whole[2 * a + 1]
                   for a in range(3)):
                raise ReadError(f"{label}: Piece Extent {ext} lies outside WholeExtent {whole}")
            dims = [ext[2 * a + 1] - ext[2 * a] + 1 for a in range(3)]
            counts = {"PointData": math.prod(dims),
                      "CellData": math.prod(max(d - 1, 1) for d in dims)}
        elif element in ("PointData", "CellData", "FieldData"):
            section = None if closing else element
        elif element == "DataArray" and not closing:
            name = attrs.get("Name", "?")
            kind = attrs.get("type")
            if kind not in _XML_TYPES:
                raise ReadError(f"{label}: array {limits.shorten(name)}: unknown data type "
                                f"{limits.shorten(kind)}")
            components = limits.check_count(
                _integer(attrs.get("NumberOfComponents", "1")),
                f"{label}: array {limits.shorten(name)}: NumberOfComponents",
                hi=MAX_COMPONENTS, error=ReadError)
            if section == "FieldData" or section is None:
                tuples = limits.check_count(
                    _integer(attrs.get("NumberOfTuples", "1")),
                    f"{label}: array {limits.shorten(name)}: NumberOfTuples", lo=0,
                    hi=2**48, error=ReadError)
                allocated = tuples
            else:
                tuples = counts[section]
                # VTK allocates the output's arrays for the whole extent, whatever the pieces.
                allocated = max(tuples, whole_counts[section])
            expected = tuples * components * _XML_TYPES[kind]
            total += allocated * components * _XML_TYPES[kind]
            limits.check_memory(total, "the data arrays", label, ReadError)
            fmt = attrs.get("format")
            if fmt not in ("ascii", "binary", "appended"):
                raise ReadError(f"{label}: array {limits.shorten(name)}: unknown format "
                                f"{limits.shorten(fmt)}")
            if kind == "String":
                # Image data is numeric; a string array is at most metadata. VTK's binary string
                # decoder trusts its input (a damaged one crashes the process), so only ASCII
                # string arrays of the field data are passed on.
                if section in ("PointData", "CellData") or fmt != "ascii":
                    raise ReadError(f"{label}: array {limits.shorten(name)}: String arrays are "
                                    "read only as ascii field data")
                continue  # sizes of strings are not known in advance; the memory bound holds
            if fmt == "appended":
                offset = limits.check_count(
                    _integer(attrs.get("offset", "")), f"{label}: array "
                    f"{limits.shorten(name)}: offset", lo=0, hi=len(raw), error=ReadError)
                appended.append((offset, expected, name))
            elif fmt == "binary":
                text = raw[tag.end():raw.find(b"<", tag.end())].strip()
                _check_array_sizes(lambda first, n, t=text: sizes.base64(t, first + n)[first:],
                                   expected, compressor is not None, len(text) * 3 // 4, name,
                                   label)
    if whole is None:
        raise ReadError(f"{label}: no <ImageData> element with a WholeExtent")
    if not appended:
        return raw
    if appended_at < 0:
        raise ReadError(f"{label}: arrays are appended, but there is no <AppendedData>")
    tag_end = raw.find(b">", appended_at)
    encoding = _attributes(raw[appended_at:tag_end]).get("encoding")
    if encoding not in ("raw", "base64"):
        raise ReadError(f"{label}: unknown AppendedData encoding {limits.shorten(encoding)}")
    # VTK takes the first character after the tag that is not white space as the start mark
    # and, if it is not '_', reads the arrays from the end of the file (garbage that can crash
    # its decoder): so must the check, instead of searching for the next '_'.
    mark = tag_end + 1
    while mark < len(raw) and raw[mark] in b" \t\r\n":
        mark += 1
    if tag_end < 0 or mark >= len(raw) or raw[mark] != ord("_"):
        raise ReadError(f"{label}: the appended data does not start with the '_' mark right "
                        "after <AppendedData>")
    data_start = mark + 1
    for offset, expected, name in appended:
        at = data_start + offset
        if encoding == "raw":
            hsize = width

            def words(first: int, n: int, at: int = at) -> np.ndarray:
                return sizes.raw(raw, at + first * width, n)
        else:
            text = raw[at:raw.find(b"<", at) if raw.find(b"<", at) >= 0 else len(raw)]
            hsize = 0

            def words(first: int, n: int, text: bytes = text) -> np.ndarray:
                return sizes.base64(text, first + n)[first:]
        _check_array_sizes(words, expected, compressor is not None,
                           len(raw) - at - hsize if encoding == "raw" else len(raw) - at,
                           name, label)
    return raw


def _float(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        return math.nan


#: Legacy data types and their sizes in bytes.
_LEGACY_TYPES = {"bit": 1, "unsigned_char": 1, "char": 1, "unsigned_short": 2, "short": 2,
                 "unsigned_int": 4, "int": 4, "unsigned_long": 8, "long": 8, "float": 4,
                 "double": 8, "vtkidtype": 8, "vtktypeint64": 8, "vtktypeuint64": 8}


def _skip_tokens(raw: bytes, pos: int, count: int, what: str) -> int:
    """Position after the next ``count`` whitespace-separated values of an ASCII file (scanned a
    megabyte at a time, so a large file costs no more than one pass)."""
    left = count
    while left > 0:
        if pos >= len(raw):
            raise ReadError(f"{what}: truncated: {count} values announced, "
                            f"{count - left} in the file")
        end = min(len(raw), pos + (1 << 20))
        while end < len(raw) and not raw[end:end + 1].isspace():
            end += 1
        found = len(raw[pos:end].split())
        if found < left:
            left -= found
            pos = end
            continue
        for n, match in enumerate(re.finditer(rb"\S+", raw[pos:end]), 1):
            if n == left:
                return pos + match.end()
    return pos


def _check_legacy_header(path: Path, label: str) -> None:
    """What VTK's legacy reader would allocate from a header, checked before it reads: sizes
    (DIMENSIONS, POINT_DATA, CELL_DATA), spacing and origin, the count, type and component
    number of every data section, that binary sections lie within the file, and that all of
    them together fit in memory."""
    info = limits.check_regular_file(path, label)
    limits.check_memory(info.st_size, "the file", label, ReadError)
    fd = limits.open_regular(path, label)
    with os.fdopen(fd, "rb") as fh:
        raw = fh.read(info.st_size + 1)
    lines = raw.split(b"\n", 4)
    if len(lines) < 4 or not lines[0].startswith(b"# vtk DataFile"):
        raise ReadError(f"{label}: not a legacy VTK file (no '# vtk DataFile' line)")
    binary = lines[2].strip().upper() == b"BINARY"
    pos = sum(len(line) + 1 for line in lines[:3])
    dims: list[int] | None = None
    spacing: tuple[float, float, float] = (1.0, 1.0, 1.0)
    current = 0
    total = 0

    def next_line() -> list[str]:
        nonlocal pos
        end = raw.find(b"\n", pos)
        end = len(raw) if end < 0 else end
        words = raw[pos:end].decode("latin-1").split()
        pos = end + 1
        return words

    def data(count: int, kind: str, what: str) -> None:
        """Account for ``count`` values of ``kind`` and skip them in a binary file."""
        nonlocal pos, total
        size = _LEGACY_TYPES.get(kind.lower())
        if size is None:
            raise ReadError(f"{label}: {what}: unknown data type {limits.shorten(kind)}")
        nbytes = count * size
        total += nbytes
        limits.check_memory(total, "the data arrays", label, ReadError)
        if binary:
            if kind.lower() == "bit":
                nbytes = -(-count // 8)
            if pos + nbytes > len(raw):
                raise ReadError(f"{label}: {what}: truncated: {nbytes} bytes announced, "
                                f"{max(0, len(raw) - pos)} left in the file")
            pos += nbytes
            if raw[pos:pos + 1] == b"\n":
                pos += 1
        else:
            pos = _skip_tokens(raw, pos, count, f"{label}: {what}")

    def number(text: str, what: str, hi: int = 2**48) -> int:
        return limits.check_count(_integer(text), f"{label}: {what}", lo=0, hi=hi,
                                  error=ReadError)

    while pos < len(raw):
        words = next_line()
        if not words:
            continue
        key = words[0].upper()
        if key == "DIMENSIONS":
            dims = list(limits.check_shape([_integer(w) for w in words[1:]],
                                           f"{label}: DIMENSIONS", error=ReadError))
        elif key in ("SPACING", "ASPECT_RATIO"):
            spacing = limits.check_spacing([_float(w) for w in words[1:]], f"{label}: {key}",
                                           ReadError)
        elif key == "ORIGIN":
            limits.check_origin([_float(w) for w in words[1:]], spacing, f"{label}: ORIGIN",
                                ReadError)
        elif key in ("POINT_DATA", "CELL_DATA"):
            if len(words) != 2:
                raise ReadError(f"{label}: {key} needs one count")
            current = number(words[1], key)
            if dims is not None:
                wanted = math.prod(dims) if key == "POINT_DATA" else \
                    math.prod(max(d - 1, 1) for d in dims)
                if current != wanted:
                    raise ReadError(f"{label}: {key} {current} does not match DIMENSIONS "
                                    f"{dims} ({wanted})")
        elif key == "SCALARS":
            if len(words) not in (3, 4):
                raise ReadError(f"{label}: SCALARS needs a name, a type and optionally 1 to 4 "
                                "components")
            components = number(words[3], "SCALARS components", 4) if len(words) == 4 else 1
            if components < 1:
                raise ReadError(f"{label}: SCALARS needs 1 to 4 components")
            save = pos
            following = next_line()
            if not (following and following[0].upper() == "LOOKUP_TABLE"):
                pos = save
            data(current * components, words[2], f"SCALARS {limits.shorten(words[1])}")
        elif key in ("VECTORS", "NORMALS", "TENSORS", "TENSORS6"):
            if len(words) != 3:
                raise ReadError(f"{label}: {key} needs a name and a type")
            per = {"TENSORS": 9, "TENSORS6": 6}.get(key, 3)
            data(current * per, words[2], f"{key} {limits.shorten(words[1])}")
        elif key == "TEXTURE_COORDINATES":
            if len(words) != 4:
                raise ReadError(f"{label}: TEXTURE_COORDINATES needs a name, 1 to 3 and a type")
            data(current * max(1, number(words[2], "TEXTURE_COORDINATES dimension", 3)),
                 words[3], "TEXTURE_COORDINATES")
        elif key == "COLOR_SCALARS":
            if len(words) != 3:
                raise ReadError(f"{label}: COLOR_SCALARS needs a name and a count")
            per = number(words[2], "COLOR_SCALARS values", MAX_COMPONENTS)
            data(current * per, "unsigned_char" if binary else "float", "COLOR_SCALARS")
        elif key == "LOOKUP_TABLE":
            if len(words) != 3:
                raise ReadError(f"{label}: LOOKUP_TABLE needs a name and a size")
            entries = number(words[2], "LOOKUP_TABLE size", 1 << 24)
            data(entries * 4, "unsigned_char" if binary else "float", "LOOKUP_TABLE")
        elif key == "FIELD":
            if len(words) != 3:
                raise ReadError(f"{label}: FIELD needs a name and an array count")
            for _ in range(number(words[2], "FIELD arrays", 1 << 16)):
                spec = next_line()
                while not spec and pos < len(raw):
                    spec = next_line()
                if len(spec) != 4:
                    raise ReadError(f"{label}: FIELD array needs a name, components, tuples "
                                    "and a type")
                comps = number(spec[1], "FIELD components", MAX_COMPONENTS)
                data(comps * number(spec[2], "FIELD tuples"), spec[3],
                     f"FIELD array {limits.shorten(spec[0])}")
        elif key == "METADATA":
            while pos < len(raw) and next_line():
                pass
        elif key != "DATASET":
            raise ReadError(f"{label}: unexpected {limits.shorten(words[0])!s} in the header")
    if dims is None:
        raise ReadError(f"{label}: no DIMENSIONS line")


def _volume(image: Any, path: Path, array: str | None, fmt: str,
            selection: Selection | None) -> Volume:
    """The volume of the chosen array and component; the components of a vector or colour
    array are its channels (time points belong to a series of files, which VTK lists in a
    ``.pvd``, not to one image)."""
    selection = selection or Selection()
    label = str(path)
    meta: dict[str, Any] = {"name": path.name, "source": str(path.absolute()), "format": fmt}
    try:
        name, vtk_array, _ = find_vtk_array(image, array, path.name)
    except SplinecastError as exc:
        raise ReadError(str(exc)) from None
    components = int(vtk_array.GetNumberOfComponents())
    timepoint = selection.time(label, 1)
    component = selection.chan(label, components, "component")
    meta.update(selection.metadata(1, timepoint, components, component))
    try:
        return Volume.from_vtk(image, array=name, metadata=meta, component=component)
    except SplinecastError as exc:
        raise ReadError(str(exc)) from None


def read_vti(path: Path, array: str | None = None, *,
             selection: Selection | None = None) -> Volume:
    """Read a VTK XML image data file (``.vti``) in any of VTK's encodings; ``selection``
    chooses the component of a multi-component array (default: the first, with a
    :class:`~splinecast.io.selection.SeveralVolumesWarning`)."""
    path = Path(path)
    xml = _vtk_module("vtkIOXML", path, "reading", ReadError)
    _check_vti_header(path, str(path))
    reader = xml.vtkXMLImageDataReader()
    reader.SetFileName(str(path))
    with _vtk_errors(reader, str(path), ReadError):
        reader.Update()
    return _volume(reader.GetOutput(), path, array, "vti", selection)


def read_legacy_vtk(path: Path, array: str | None = None, *,
                    selection: Selection | None = None) -> Volume:
    """Read a legacy VTK file (``.vtk``) holding ``DATASET STRUCTURED_POINTS`` (``selection``
    as for :func:`read_vti`)."""
    path = Path(path)
    legacy = _vtk_module("vtkIOLegacy", path, "reading", ReadError)
    limits.check_regular_file(path, str(path))
    fd = limits.open_regular(path, str(path))
    with os.fdopen(fd, "rb") as fh:
        head = fh.read(4096)
    if not head.startswith(b"# vtk DataFile"):
        raise ReadError(f"{path}: not a legacy VTK file (no '# vtk DataFile' line)")
    kind = _DATASET.search(head)
    if kind is None or kind.group(1).upper() != b"STRUCTURED_POINTS":
        found = kind.group(1).decode(errors="replace") if kind else "no DATASET"
        found = found if len(found) <= 40 else found[:37] + "..."
        raise ReadError(f"{path}: legacy VTK {limits.printable(found)}, "
                        "not STRUCTURED_POINTS (image data)")
    _check_legacy_header(path, str(path))
    reader = legacy.vtkStructuredPointsReader()
    reader.SetFileName(str(path))
    reader.ReadAllScalarsOn()
    reader.ReadAllFieldsOn()
    with _vtk_errors(reader, str(path), ReadError):
        reader.Update()
    return _volume(reader.GetOutput(), path, array, "vtk", selection)


def write_vti(volume: Volume, path: Path) -> None:
    """Write ``volume`` as a ``.vti`` file: appended raw binary, zlib-compressed, 64-bit headers.

    The array is named ``volume.metadata["array"]`` (the name it was read with) or ``"values"``
    (PyVista's default) and marked as the active scalars.
    """
    path = Path(path)
    xml = _vtk_module("vtkIOXML", path, "writing", ParameterError)
    model = _vtk_module("vtkCommonDataModel", path, "writing", ParameterError)
    support = importlib.import_module("vtkmodules.util.numpy_support")
    image = model.vtkImageData()
    image.SetDimensions(*volume.shape)
    image.SetSpacing(*volume.spacing)
    image.SetOrigin(*volume.origin)
    # VTK wants x fastest: the C-order ravel of the (z, y, x) transpose.
    flat = np.ascontiguousarray(volume.data.transpose(2, 1, 0)).ravel()
    values = support.numpy_to_vtk(flat, deep=True)
    values.SetName(str(volume.metadata.get("array", "values")))
    image.GetPointData().SetScalars(values)
    writer = xml.vtkXMLImageDataWriter()
    writer.SetInputData(image)
    writer.SetDataModeToAppended()
    writer.EncodeAppendedDataOff()
    writer.SetCompressorTypeToZLib()
    writer.SetHeaderTypeToUInt64()
    with atomic_outputs(path) as (temp,):
        writer.SetFileName(str(temp))
        with _vtk_errors(writer, str(path), ParameterError):
            ok = writer.Write()
        if not ok:
            raise ParameterError(f"{path}: VTK could not write the file")
