"""VTK image data: XML ``.vti`` and legacy ``.vtk`` structured points, through the vtk package.

VTK decodes every encoding of its formats (ASCII, inline base64 binary, appended raw or base64,
zlib/LZ4/LZMA compression, either byte order); :meth:`splinecast.Volume.from_vtk` turns the
decoded ``vtkImageData`` into a volume (axis order, origin and array choice are explained there).
The vtk package is imported only here, when such a file is read or written
(``pip install 'splinecast[vtk]'``).

VTK reports most damage (bad XML, a wrong header) through its error events, which are turned into
one :class:`ReadError`; a file truncated inside its appended raw data is read without complaint,
so this module checks that every appended array lies within the file before VTK reads it.
"""

from __future__ import annotations

import contextlib
import importlib
import re
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from .._atomic import atomic_outputs
from ..errors import ParameterError, ReadError, SplinecastError
from ..volume import Volume

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


def _attributes(tag: bytes) -> dict[str, str]:
    return {k.decode(): v.decode() for k, v in re.findall(rb'(\w+)="([^"]*)"', tag)}


def _check_vti_header(path: Path, label: str) -> None:
    """Refuse what VTK would read silently wrong: a file that is not ImageData, and appended raw
    arrays that run past the end of the file."""
    raw = path.read_bytes()
    start = raw.find(b"<VTKFile")
    if start < 0:
        raise ReadError(f"{label}: not a VTK XML file (no <VTKFile> element)")
    end = raw.find(b">", start)
    head = _attributes(raw[start:end])
    if head.get("type") != "ImageData":
        raise ReadError(f"{label}: VTK {head.get('type', 'unknown')} data, not ImageData "
                        "(splinecast reads regular grids: .vti image data)")
    appended = raw.find(b"<AppendedData")
    if appended < 0:
        return
    tag_end = raw.find(b">", appended)
    if _attributes(raw[appended:tag_end]).get("encoding") != "raw":
        return  # base64: VTK's decoder reports damage
    data_start = raw.find(b"_", tag_end) + 1
    size_bytes = _HEADER_TYPES.get(head.get("header_type", "UInt32"))
    if size_bytes is None:
        raise ReadError(f"{label}: unknown header_type {head.get('header_type')!r}")
    order = "<" if head.get("byte_order", "LittleEndian") == "LittleEndian" else ">"
    header = np.dtype(f"{order}u{size_bytes}")
    compressed = "compressor" in head
    for tag in re.findall(rb"<DataArray[^>]*>", raw[:appended]):
        attrs = _attributes(tag)
        if attrs.get("format") != "appended":
            continue
        at = data_start + int(attrs.get("offset", "0"))
        if compressed:  # [blocks, block size, last block size, compressed sizes...]
            blocks = _read_header(raw, at, header, 1, label)[0]
            sizes = _read_header(raw, at + 3 * size_bytes, header, int(blocks), label)
            end_at = at + (3 + int(blocks)) * size_bytes + int(sizes.sum())
        else:
            end_at = at + size_bytes + int(_read_header(raw, at, header, 1, label)[0])
        if end_at > len(raw):
            raise ReadError(f"{label}: truncated: array {attrs.get('Name', '?')!r} needs "
                            f"{end_at} bytes, the file has {len(raw)}")


def _read_header(raw: bytes, at: int, header: np.dtype, count: int, label: str) -> np.ndarray:
    if at + count * header.itemsize > len(raw):
        raise ReadError(f"{label}: truncated inside the appended data")
    return np.frombuffer(raw, dtype=header, count=count, offset=at).astype(np.int64)


def _volume(image: Any, path: Path, array: str | None, fmt: str) -> Volume:
    meta = {"name": path.name, "source": str(path.absolute()), "format": fmt}
    try:
        return Volume.from_vtk(image, array=array, metadata=meta)
    except SplinecastError as exc:
        raise ReadError(str(exc)) from None


def read_vti(path: Path, array: str | None = None) -> Volume:
    """Read a VTK XML image data file (``.vti``) in any of VTK's encodings."""
    path = Path(path)
    xml = _vtk_module("vtkIOXML", path, "reading", ReadError)
    _check_vti_header(path, str(path))
    reader = xml.vtkXMLImageDataReader()
    reader.SetFileName(str(path))
    with _vtk_errors(reader, str(path), ReadError):
        reader.Update()
    return _volume(reader.GetOutput(), path, array, "vti")


def read_legacy_vtk(path: Path, array: str | None = None) -> Volume:
    """Read a legacy VTK file (``.vtk``) holding ``DATASET STRUCTURED_POINTS``."""
    path = Path(path)
    legacy = _vtk_module("vtkIOLegacy", path, "reading", ReadError)
    with open(path, "rb") as fh:
        head = fh.read(4096)
    if not head.startswith(b"# vtk DataFile"):
        raise ReadError(f"{path}: not a legacy VTK file (no '# vtk DataFile' line)")
    kind = _DATASET.search(head)
    if kind is None or kind.group(1).upper() != b"STRUCTURED_POINTS":
        found = kind.group(1).decode(errors="replace") if kind else "no DATASET"
        raise ReadError(f"{path}: legacy VTK {found}, not STRUCTURED_POINTS (image data)")
    reader = legacy.vtkStructuredPointsReader()
    reader.SetFileName(str(path))
    reader.ReadAllScalarsOn()
    reader.ReadAllFieldsOn()
    with _vtk_errors(reader, str(path), ReadError):
        reader.Update()
    return _volume(reader.GetOutput(), path, array, "vtk")


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
