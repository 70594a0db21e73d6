"""``read`` and ``write``: pick the format from the path's extension and the file's first bytes."""

from __future__ import annotations

import gzip
import os
import zlib
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import ParameterError, ReadError, limits
from ..volume import SUPPORTED_DTYPES, Volume
from .multichannel import MultichannelVolume, channel_indices, is_all, read_channels
from .remote import is_url
from .selection import Selection
from .sidecar import find_sidecar

if TYPE_CHECKING:
    from .omezarr import MultiscaleVolume

__all__ = ["read", "write", "sniff"]

#: Extension -> format. Checked longest first so ".nii.gz" wins over ".gz".
_EXTENSIONS = {
    ".npy": "npy",
    ".npz": "npz",
    ".mhd": "metaimage",
    ".mha": "metaimage",
    ".nrrd": "nrrd",
    ".nhdr": "nrrd",
    ".nii": "nifti",
    ".nii.gz": "nifti",
    ".hdr": "nifti",
    ".tif": "tiff",
    ".tiff": "tiff",
    ".dcm": "dicom",
    ".json": "sidecar",
    ".vti": "vti",
    ".vtk": "vtk",
}
#: Formats whose files always start with a recognisable signature.
_SIGNED = {"npy", "npz", "nrrd", "tiff", "nifti", "vti", "vtk"}
_SUPPORTED_READ = (
    ".npy .npz .mhd .mha .nrrd .nhdr .nii .nii.gz .tif .tiff .dcm .vti .vtk, raw + .json, "
    "a DICOM folder, an OME-Zarr or Zarr folder"
)
_NIFTI1_MAGIC = (b"n+1\0", b"ni1\0")
_NIFTI2_MAGIC = (b"n+2\0", b"ni2\0")
#: Enough bytes for every signature below (the NIfTI-1 magic sits at 344..348).
_HEAD_BYTES = 352
#: Formats whose header may name other files: their readers take ``allow_external``.
_NAMES_FILES = {"metaimage", "nrrd", "sidecar", "dicom", "nifti", "tiff"}
#: Formats that may hold several time points or channels: their readers take ``selection``
#: (besides ``allow_external``; VTK readers take it with ``array``).
_SELECTS = {"nifti", "tiff", "nrrd", "dicom"}


def sniff(path: Path) -> str | None:
    """Recognise a file format from its first bytes; ``None`` if there is no known signature."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(_HEAD_BYTES)
    except OSError:
        return None
    if head.startswith(b"\x93NUMPY"):
        return "npy"
    if head.startswith((b"PK\x03\x04", b"PK\x05\x06")):
        return "npz"
    if head.startswith(b"NRRD"):
        return "nrrd"
    if head[:4] in (b"II*\0", b"MM\0*", b"II+\0", b"MM\0+"):
        return "tiff"
    if head[128:132] == b"DICM":
        return "dicom"
    if _is_nifti(head):
        return "nifti"
    if head.startswith(b"\x1f\x8b"):
        try:
            with gzip.open(path, "rb") as fh:
                inner = fh.read(_HEAD_BYTES)
        except (OSError, EOFError, zlib.error):
            return None
        return "nifti" if _is_nifti(inner) else None
    if head.lstrip().startswith((b"ObjectType", b"NDims")):
        return "metaimage"
    if head.startswith(b"# vtk DataFile"):
        return "vtk"
    if head.lstrip().startswith((b"<?xml", b"<VTKFile")) and b"<VTKFile" in head:
        return "vti"
    return None


def _is_nifti(head: bytes) -> bool:
    return head[344:348] in _NIFTI1_MAGIC or head[4:8] in _NIFTI2_MAGIC


def _extension_format(path: Path) -> str | None:
    name = path.name.lower()
    for ext in sorted(_EXTENSIONS, key=len, reverse=True):
        if name.endswith(ext):
            return _EXTENSIONS[ext]
    return None


def _reader(kind: str) -> Callable[[Path], Volume]:
    # Imported on use: each module is cheap, but this keeps `import splinecast.io` minimal.
    if kind == "npy":
        from .npyfile import read_npy

        return read_npy
    if kind == "npz":
        from .npyfile import read_npz

        return read_npz
    if kind == "metaimage":
        from .metaimage import read_metaimage

        return read_metaimage
    if kind == "nrrd":
        from .nrrdfile import read_nrrd

        return read_nrrd
    if kind == "nifti":
        from .nifti import read_nifti

        return read_nifti
    if kind == "tiff":
        from .tiff import read_tiff

        return read_tiff
    if kind == "dicom":
        from .dicom import read_dicom_file

        return read_dicom_file
    if kind in ("vti", "vtk"):
        from .vtkimage import read_legacy_vtk, read_vti

        return read_vti if kind == "vti" else read_legacy_vtk
    from .sidecar import read_sidecar

    return read_sidecar


def read(
    path: str | os.PathLike[str],
    *,
    array: str | None = None,
    allow_external: bool | None = None,
    storage_options: dict[str, Any] | None = None,
    timepoint: int | None = None,
    volume: int | None = None,
    channel: int | Sequence[int] | str | None = None,
) -> Volume | MultiscaleVolume | MultichannelVolume:
    """Read a volume from a file, a DICOM folder, a Zarr folder, a URL or a ``demo:`` name.

    Parameters
    ----------
    path : str or path-like
        A file (``.npy``, ``.npz``, ``.mhd``/``.mha``, ``.nrrd``/``.nhdr``, ``.nii``/``.nii.gz``,
        ``.tif``/``.tiff``, raw data with a ``.json`` sidecar, a ``.dcm`` slice), a folder holding
        a DICOM series, an OME-Zarr image or Zarr array folder (``x.zarr``), or
        ``"demo:<name>?size=N&..."`` for a synthetic volume (see :func:`splinecast.io.demo`). The
        format is recognised by the file's signature when it has one, by its extension otherwise.
        VTK image data: ``.vti`` (XML, any encoding) and legacy ``.vtk`` structured points (needs
        ``pip install 'splinecast[vtk]'``).

        Or an ``http://``, ``https://``, ``s3://`` or ``gs://`` URL (needs
        ``pip install 'splinecast[remote]'``) of an OME-Zarr image or Zarr array, read lazily
        chunk by chunk, or of a single file of the formats above, downloaded into a private
        temporary folder and read there (a header naming other files is refused). Access is
        anonymous unless credentials are configured in the environment or the usual
        configuration files (``~/.aws``, Google application default credentials).
    array : str, optional
        The point-data array to read from a VTK file that holds several (the error message of a
        read without it lists their names). Other formats hold one array and refuse it.
    allow_external : bool, optional
        Let a header (MetaImage ``ElementDataFile``, NRRD ``data file``, a sidecar's
        ``data_file``, a NIfTI ``.img``, an OME-TIFF's other files, a DICOM folder's symbolic
        links) name files outside its own folder. Default: no, unless
        ``SPLINECAST_ALLOW_EXTERNAL_DATA=1``. Never for a URL.
    storage_options : dict, optional
        For a URL: options of its fsspec filesystem, e.g. ``{"anon": True}``,
        ``{"key": ..., "secret": ..., "endpoint_url": ...}`` (S3), ``{"token": ...}`` (GCS),
        ``{"headers": {...}}`` (HTTP).
    timepoint : int, optional
        Which time point of a time series to read: the 4th dimension of a NIfTI image, the
        ``t`` axis of an OME-Zarr image, the ``T`` axis of a TIFF hyperstack. Default: the
        first, with a :class:`~splinecast.io.selection.SeveralVolumesWarning` when there are
        several. Only that time point is read (a compressed TIFF excepted).
    volume : int, optional
        Another name for ``timepoint`` (neuroimaging speaks of the volumes of a 4D NIfTI).
    channel : int, optional
        Which channel to read: the ``c`` axis of an OME-Zarr image, the ``C`` (or ``S``,
        colour samples) axis of a TIFF, the component of a multi-component VTK array, the 5th
        dimension of a NIfTI image. Default: the first, with a warning as for ``timepoint``.
        A list of indices (``[0, 2]``, or ``"0,2"``) or ``"all"`` reads several channels as
        one :class:`~splinecast.io.multichannel.MultichannelVolume`, which
        :class:`~splinecast.Scene` renders together (see :class:`splinecast.ChannelScene`).

    Returns
    -------
    Volume or MultiscaleVolume
        A Zarr folder gives a lazy :class:`~splinecast.io.omezarr.MultiscaleVolume` (metadata
        read, voxels not); several channels a
        :class:`~splinecast.io.multichannel.MultichannelVolume` of those; everything else a
        :class:`Volume`. Both have ``metadata["name"]`` (the
        file name or the ``demo:`` string), ``metadata["source"]`` (the full path) and
        ``metadata["format"]``; a file that can hold several time points or channels also
        ``metadata["timepoints"]``, ``["timepoint"]``, ``["channels"]`` and ``["channel"]``
        (the counts and the ones read). Uncompressed npy, raw, MetaImage, NRRD, NIfTI and TIFF
        data stay memory-mapped; big-endian data is copied once into native order.

    Raises
    ------
    ReadError
        Missing file, unknown format, bad header, truncated data, unsupported content, a size
        beyond the limits or the memory available (see :mod:`splinecast.errors.limits`), a data file
        outside the header's folder, or a missing optional library (with the command that
        installs it).
    ParameterError
        A bad ``demo:`` name or parameter; a ``timepoint``, ``volume`` or ``channel`` outside
        the file's range (the message gives the range), or other than 0 for a file that holds
        one volume.

    Warns
    -----
    OrientationWarning
        When axes were flipped, permuted or an oblique rotation was dropped to fit x, y, z.
    SeveralVolumesWarning
        When the file holds several time points or channels and none was chosen.
    """
    if is_all(channel) or channel_indices(channel) is not None:
        def read_one(index: int) -> Any:
            return read(path, array=array, allow_external=allow_external,
                        storage_options=storage_options, timepoint=timepoint, volume=volume,
                        channel=index)

        return read_channels(read_one, channel, str(path))
    selection = _selection(timepoint, volume, channel)
    if array is not None and not isinstance(array, str):
        raise ParameterError(f"array must be the name of a data array, got {array!r}")
    if isinstance(path, str) and path.startswith("demo:"):
        if array is not None:
            raise ParameterError(f"array={array!r} applies to VTK files, not to {path}")
        from .synthetic import demo_from_uri

        selection.single(path)
        return demo_from_uri(path)
    if is_url(path):  # kept as text: a Path would collapse the URL's "//"
        return _read_url(path, array, storage_options, selection)  # type: ignore[arg-type]
    if storage_options is not None:
        raise ParameterError(f"storage_options applies to URLs, not to the path {path}")
    path = limits.check_path_text(path, "file", ReadError)
    try:
        is_dir = path.is_dir()
        exists = is_dir or path.exists()
    except OSError as exc:
        raise ReadError(f"{path}: cannot read: {exc.strerror or exc}") from None
    if not exists:
        raise ReadError(f"{path}: no such file or folder")
    if is_dir:
        if array is not None:
            raise ParameterError(f"array={array!r} applies to VTK files, not to the folder {path}")
        from .omezarr import is_zarr, open_zarr

        if is_zarr(path) or path.suffix.lower() == ".zarr":
            return open_zarr(path, allow_external=allow_external, selection=selection)
        from .dicom import read_dicom_series

        return read_dicom_series(path, allow_external=allow_external, selection=selection)
    limits.check_regular_file(path, str(path))  # a device or pipe would block or never end
    by_content = sniff(path)
    by_extension = _extension_format(path)
    if by_content is not None:
        kind = by_content
    elif by_extension is None and find_sidecar(path) is not None:
        kind = "sidecar"  # headerless data (foo.raw) described by foo.json or foo.raw.json
    elif path.suffix.lower() == ".img" and path.with_suffix(".hdr").is_file():
        kind = "nifti"  # the data half of a NIfTI/Analyze .hdr/.img pair
    elif by_extension in _SIGNED and path.suffix.lower() != ".hdr":
        # (.hdr may be an Analyze 7.5 header, which has no signature: nibabel decides.)
        raise ReadError(
            f"{path}: not a valid {by_extension} file "
            f"(its first bytes lack the {by_extension} signature)"
        )
    elif by_extension is not None:
        kind = by_extension
    else:
        raise ReadError(_unknown_message(path))
    if kind in ("vti", "vtk"):
        return _reader(kind)(path, array, selection=selection)  # type: ignore[call-arg]
    if array is not None:
        raise ParameterError(f"array={array!r} applies to VTK files (.vti, .vtk), not to {path}")
    if kind in _SELECTS:
        return _reader(kind)(path, allow_external=allow_external,  # type: ignore[call-arg]
                             selection=selection)
    selection.single(str(path))
    if kind in _NAMES_FILES:
        return _reader(kind)(path, allow_external=allow_external)  # type: ignore[call-arg]
    return _reader(kind)(path)


def _read_url(url: str, array: str | None, storage_options: dict[str, Any] | None,
              selection: Selection) -> Volume | MultiscaleVolume:
    """An OME-Zarr image (or Zarr array) at ``url``, opened lazily; else a single file,
    downloaded into a private temporary folder and read there with external files refused
    (a header naming another file would lead outside the URL)."""
    from .remote import Remote, basename, download, has_zarr_metadata, redact

    remote = Remote(url, storage_options)
    name = basename(remote.url)
    kind = _extension_format(Path(name)) if name else None  # (a bare name, not the URL)
    if kind is None and (name.lower().endswith(".zarr") or has_zarr_metadata(remote)):
        if array is not None:
            raise ParameterError(f"array={array!r} applies to VTK files, not to the Zarr store "
                                 f"{redact(remote.url)}")
        from .omezarr import open_zarr

        return open_zarr(remote.url, storage_options=storage_options, selection=selection)
    if kind is None:
        raise ReadError(f"{redact(remote.url)}: neither a Zarr store (no zarr.json, .zgroup or "
                        ".zarray) nor a file of a known format by its name")
    with download(remote, name) as local:
        volume = read(local, array=array, allow_external=False, timepoint=selection.timepoint,
                      channel=selection.channel)
    volume.metadata["name"] = name
    volume.metadata["source"] = redact(remote.url)
    return volume


def _selection(timepoint: object, volume: object, channel: object) -> Selection:
    """The time point and channel asked for; ``volume`` is another name for ``timepoint``."""
    if timepoint is not None and volume is not None:
        raise ParameterError("give timepoint or volume (another name for it), not both")
    if volume is not None:
        return Selection(timepoint=volume, channel=channel, time_option="volume")  # type: ignore[arg-type]
    return Selection(timepoint=timepoint, channel=channel)  # type: ignore[arg-type]


def _unknown_message(path: Path) -> str:
    headers = [p.name for p in (path.with_suffix(".mhd"), path.with_suffix(".nhdr")) if p.is_file()]
    if headers:
        return f"{path}: raw voxels without a sidecar; read its header {headers[0]} instead"
    if path.suffix.lower() in (".raw", ".bin", ".dat", ".img"):
        return (
            f"{path}: raw voxels need a description: add {path.name}.json with shape and dtype "
            "(or write a .mhd header)"
        )
    return f"{path}: unknown file format (supported: {_SUPPORTED_READ})"


# --------------------------------------------------------------------------- writing
_WRITERS = (".npy", ".npz", ".mhd", ".raw", ".nrrd", ".vti")


def write(volume: Volume, path: str | os.PathLike[str]) -> None:
    """Write a volume; the format follows the extension.

    Parameters
    ----------
    volume : Volume
        The volume to save.
    path : str or path-like
        ``.npy`` (voxels only), ``.npz`` (voxels, spacing, origin), ``.mhd`` (writes ``name.mhd``
        and ``name.raw``), ``.raw`` (writes ``name.raw`` and the JSON sidecar ``name.json``) or
        ``.nrrd`` (needs pynrrd) or ``.vti`` (VTK XML image data, appended zlib-compressed binary;
        needs vtk). Raw data is little-endian with x varying fastest.

    Raises
    ------
    ParameterError
        Unknown extension, a folder that does not exist, voxels the format cannot hold, or any
        failure while writing. Nothing is left behind on failure: every file is written to a
        temporary beside its target and renamed into place only when complete.
    """
    path = limits.check_path_text(path, "output")
    suffix = path.suffix.lower()
    if suffix not in _WRITERS:
        raise ParameterError(
            f"{path}: cannot write '{suffix or path.name}' files (use {', '.join(_WRITERS)})"
        )
    data = volume.data
    if data.ndim != 3 or data.dtype.newbyteorder("=") not in SUPPORTED_DTYPES:
        raise ParameterError(f"{path}: cannot write {data.dtype} voxels of shape {data.shape}")
    if suffix == ".npy":
        from .npyfile import write_npy as writer
    elif suffix == ".npz":
        from .npyfile import write_npz as writer
    elif suffix == ".mhd":
        from .metaimage import write_metaimage as writer
    elif suffix == ".raw":
        from .sidecar import write_sidecar as writer
    elif suffix == ".vti":
        from .vtkimage import write_vti as writer
    else:
        from .nrrdfile import write_nrrd as writer
    writer(volume, path)
