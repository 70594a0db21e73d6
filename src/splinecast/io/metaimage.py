"""MetaImage (ITK) ``.mhd``/``.mha``: a text header of ``Key = Value`` lines and raw voxels.

``foo.mhd`` usually names a separate data file (``ElementDataFile = foo.raw``); ``LOCAL`` (the
``.mha`` convention) means the voxels follow the header in the same file. Voxels are stored x
fastest and are memory-mapped. Only what splinecast can use is accepted: 3 dimensions, one channel,
uncompressed binary data.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from .._atomic import atomic_outputs
from ..errors import ParameterError, ReadError, limits
from ..volume import Volume
from ._common import finish_volume
from .rawfile import map_raw, write_raw

__all__ = ["read_metaimage", "write_metaimage", "MET_TYPES"]

#: MetaImage element types splinecast reads and writes (MET_LONG is 4 or 8 bytes depending on the
#: writer's platform, so it is deliberately absent).
MET_TYPES = {
    "MET_UCHAR": np.dtype(np.uint8),
    "MET_CHAR": np.dtype(np.int8),
    "MET_USHORT": np.dtype(np.uint16),
    "MET_SHORT": np.dtype(np.int16),
    "MET_UINT": np.dtype(np.uint32),
    "MET_INT": np.dtype(np.int32),
    "MET_FLOAT": np.dtype(np.float32),
    "MET_DOUBLE": np.dtype(np.float64),
}
_MET_NAMES = {dtype: name for name, dtype in MET_TYPES.items()}

#: A header longer than this is not a header (protects against reading a huge binary file).
_MAX_HEADER_LINES = 200
_MAX_LINE_BYTES = 1 << 16


def _parse_header(path: Path) -> tuple[dict[str, str], int]:
    """Return the header fields (keys lower-cased) and the byte offset just after the header."""
    fields: dict[str, str] = {}
    try:
        with open(path, "rb") as fh:
            for number in range(1, _MAX_HEADER_LINES + 1):
                raw = fh.readline(_MAX_LINE_BYTES + 1)
                if not raw:
                    break
                if len(raw) > _MAX_LINE_BYTES:
                    raise ReadError(f"{path}: not a MetaImage header (line {number} is too long)")
                try:
                    line = raw.decode("utf-8").strip()
                except UnicodeDecodeError:
                    line = raw.decode("latin-1").strip()
                if not line:
                    continue
                key, sep, value = line.partition("=")
                if not sep or not key.strip().replace("_", "").isalnum():
                    raise ReadError(
                        f"{path}: not a MetaImage header (line {number} is not 'Key = Value')"
                    )
                fields[key.strip().lower()] = value.strip()
                # ElementDataFile is always the last field; anything after it is voxel data.
                if key.strip().lower() == "elementdatafile":
                    return fields, fh.tell()
    except OSError as exc:
        raise ReadError(f"{path}: cannot read: {exc.strerror}") from None
    raise ReadError(f"{path}: MetaImage header has no ElementDataFile field")


def _numbers(fields: dict[str, str], key: str, path: Path, count: int = 3) -> list[float] | None:
    if key not in fields:
        return None
    try:
        values = [float(v) for v in fields[key].split()]
    except ValueError:
        values = []
    if len(values) != count:
        raise ReadError(f"{path}: {key} must be {count} numbers, got {limits.shorten(fields[key])}")
    return values


def _flag(fields: dict[str, str], key: str, default: bool, path: Path) -> bool:
    if key not in fields:
        return default
    value = fields[key].lower()
    if value in ("true", "1", "yes"):
        return True
    if value in ("false", "0", "no"):
        return False
    raise ReadError(f"{path}: {key} must be True or False, got {limits.shorten(fields[key])}")


def read_metaimage(path: Path, *, allow_external: bool | None = None) -> Volume:
    """Read a MetaImage ``.mhd``/``.mha`` file; the voxels are memory-mapped.

    ``TransformMatrix`` is not applied: a non-identity matrix only triggers a warning. The data
    file must lie in the header's folder or below unless ``allow_external`` (see
    :func:`splinecast.errors.limits.check_data_file`).
    """
    fields, header_end = _parse_header(path)
    if fields.get("objecttype", "Image").lower() != "image":
        shown = limits.shorten(fields["objecttype"])
        raise ReadError(f"{path}: ObjectType is {shown}, expected Image")
    ndims = fields.get("ndims")
    if ndims != "3":
        raise ReadError(f"{path}: NDims must be 3, got {limits.shorten(ndims)}")
    dims = _numbers(fields, "dimsize", path)
    if dims is None:
        raise ReadError(f"{path}: DimSize is missing")
    shape = limits.check_shape(dims, f"{path}: DimSize", error=ReadError)
    element = fields.get("elementtype", "").upper()
    if element not in MET_TYPES:
        valid = ", ".join(MET_TYPES)
        shown = limits.shorten(element) if element else "(missing)"
        raise ReadError(f"{path}: ElementType {shown} not supported ({valid})")
    channels = fields.get("elementnumberofchannels", "1")
    if channels != "1":
        raise ReadError(
            f"{path}: ElementNumberOfChannels is {limits.shorten(channels)}; only 1 is supported"
        )
    if _flag(fields, "compresseddata", False, path):
        raise ReadError(f"{path}: CompressedData = True is not supported; save uncompressed")
    if not _flag(fields, "binarydata", True, path):
        raise ReadError(f"{path}: BinaryData = False (text voxels) is not supported")
    msb_key = "binarydatabyteordermsb"
    if msb_key not in fields:
        msb_key = "elementbyteordermsb"
    big = _flag(fields, msb_key, False, path)
    dtype = MET_TYPES[element].newbyteorder(">" if big else "<")

    spacing = _numbers(fields, "elementspacing", path) or _numbers(fields, "elementsize", path)
    key = next((k for k in ("offset", "origin", "position") if k in fields), "offset")
    origin = _numbers(fields, key, path)
    for key in ("transformmatrix", "rotation", "orientation"):
        matrix = _numbers(fields, key, path, count=9)
        if matrix is not None and not np.allclose(matrix, np.eye(3).ravel(), atol=1e-6):
            warnings.warn(
                f"{path}: {key} is not the identity; the rotation is ignored",
                UserWarning,
                stacklevel=3,
            )
            break

    try:
        header_size = int(fields.get("headersize", "0"))
    except ValueError:
        header_size = None
    if header_size is None or header_size < -1:
        shown = limits.shorten(fields["headersize"])
        raise ReadError(f"{path}: HeaderSize must be an integer >= -1, got {shown}")
    datafile = fields["elementdatafile"]
    if datafile.upper() == "LOCAL":
        data_path = path
        offset = -1 if header_size == -1 else header_end + header_size
    elif datafile.upper().startswith("LIST") or "%" in datafile:
        raise ReadError(
            f"{path}: ElementDataFile {limits.shorten(datafile)} (file per slice) is not supported"
        )
    else:
        data_path = limits.check_data_file(
            path, datafile, "ElementDataFile", allow_external=allow_external
        )
        offset = header_size
    data = map_raw(data_path, shape, dtype, offset=offset, order="F", header=path.name)
    return finish_volume(
        data,
        spacing if spacing is not None else 1.0,
        origin if origin is not None else 0.0,
        path,
        metadata={"format": "metaimage", "data_file": str(data_path)},
    )


def write_metaimage(volume: Volume, path: Path) -> None:
    """Write ``name.mhd`` and ``name.raw`` (little-endian, x fastest) beside each other."""
    data = volume.data
    element = _MET_NAMES.get(data.dtype.newbyteorder("="))
    if element is None:
        raise ParameterError(f"{path}: MetaImage cannot hold {data.dtype} voxels")
    raw_path = path.with_suffix(".raw")
    header = "\n".join(
        [
            "ObjectType = Image",
            "NDims = 3",
            "BinaryData = True",
            "BinaryDataByteOrderMSB = False",
            "CompressedData = False",
            "TransformMatrix = 1 0 0 0 1 0 0 0 1",
            "Offset = " + " ".join(repr(float(v)) for v in volume.origin),
            "ElementSpacing = " + " ".join(repr(float(v)) for v in volume.spacing),
            "DimSize = " + " ".join(str(n) for n in volume.shape),
            f"ElementType = {element}",
            f"ElementDataFile = {raw_path.name}",
            "",
        ]
    )
    # Header last: it is the file people open, so it only appears once its data is complete.
    with atomic_outputs(raw_path, path) as (raw_temp, header_temp):
        with open(raw_temp, "wb") as fh:
            write_raw(fh, data)
        _write_header(header_temp, header)


def _write_header(path: Path, text: str) -> None:
    with open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(text)
