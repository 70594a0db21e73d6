"""NIfTI-1/2 (``.nii``, ``.nii.gz``, ``.hdr``/``.img`` pairs) via nibabel.

The voxels come from ``img.dataobj`` so their stored dtype is kept and an uncompressed ``.nii`` is
memory-mapped. A 4D (or 5D) image is a series of volumes, one of which is read (see
:mod:`splinecast.io.selection`). ``scl_slope``/``scl_inter``, when set to anything but 1 and 0, are
applied (float32 result, float64 for float64 data). The affine gives spacing (column lengths of its
3x3 part) and origin (its translation); axes that run backwards are flipped and an oblique rotation
is dropped, both with an :class:`~splinecast.io.orientation.OrientationWarning`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ReadError, limits
from ..volume import Volume
from ._common import check_dtype, check_in_memory, finish_volume, fmt_shape, require, third_party
from .orientation import align_to_world
from .selection import Selection

__all__ = ["read_nifti"]


def read_nifti(path: Path, *, allow_external: bool | None = None,
               selection: Selection | None = None) -> Volume:
    """Read one 3D volume of a NIfTI image.

    The 4th dimension is time, the 5th the components of a vector or tensor image (NIfTI's
    convention), read as channels: ``selection`` says which of each to read (default: the
    first, with a :class:`~splinecast.io.selection.SeveralVolumesWarning` when there are
    several). Only the chosen volume is read: sliced from the memory map of an uncompressed
    file, streamed out of a compressed one.

    The header's sizes, type and data offset are checked against the limits, the file size and
    the memory available before nibabel reads any voxel; for an ``.hdr``/``.img`` pair the
    ``.img`` must lie beside the header (symbolic links resolved) unless ``allow_external``.
    """
    nib = require("nibabel", path)
    selection = selection or Selection()
    label = str(path)
    with third_party(label, "not a readable NIfTI image"):
        img = nib.load(str(path))
        header_shape = tuple(img.shape)
        proxy = img.dataobj
        dtype = img.get_data_dtype()
        offset = int(getattr(proxy, "offset", 0))
        image_file = img.file_map["image"].filename
    if len(header_shape) < 3:
        raise ReadError(
            f"{label}: a {len(header_shape)}D image ({limits.shorten(header_shape)}), expected 3D"
        )
    extra = [_as_int(n) for n in header_shape[3:]]
    if len(header_shape) > 7 or any(n is None or n < 1 for n in extra):
        raise ReadError(f"{label}: impossible NIfTI dimensions {limits.shorten(header_shape)}")
    if any(n != 1 for n in extra[2:]):
        raise ReadError(
            f"{label}: a {len(header_shape)}D image ({fmt_shape(header_shape)}); dimensions "
            "beyond the 5th (time, then components) cannot be read"
        )
    counts = [*extra, 1, 1][:2]
    timepoint = selection.time(label, counts[0])
    channel = selection.chan(label, counts[1])
    shape = limits.check_shape(header_shape[:3], f"{label}: dim", error=ReadError)
    dtype = check_dtype(dtype, label)
    expected = limits.nbytes(header_shape, dtype.itemsize)
    if image_file is not None and Path(image_file).name != path.name:
        limits.check_data_file(path, Path(image_file).name, "image file",
                               allow_external=allow_external)
    compressed = image_file is None or str(image_file).lower().endswith(".gz")
    if not compressed:
        size = limits.check_regular_file(Path(image_file), str(image_file)).st_size
        if size < offset + expected:
            raise ReadError(
                f"{label}: expected {expected} bytes for {fmt_shape(header_shape)} {dtype.name} "
                f"after {offset} bytes, the file has {size} (truncated)"
            )
    else:
        check_in_memory(shape, dtype, label)  # one volume decompressed (bounded by the header)

    with third_party(label, "bad scaling (scl_slope/scl_inter)"):
        slope = float(getattr(proxy, "slope", 1.0))
        inter = float(getattr(proxy, "inter", 0.0))
    # The chosen volume, trailing singleton dimensions dropped by indexing.
    chosen = (slice(None),) * 3 + tuple([timepoint, channel, 0, 0][: len(header_shape) - 3])
    with third_party(label, "cannot read the voxel data"):
        if compressed and any(n != 1 for n in extra):
            raw = _stream_volume(img, chosen, header_shape, dtype, offset,
                                 getattr(proxy, "order", "F"))
        elif hasattr(proxy, "get_unscaled"):
            raw = proxy.get_unscaled()[chosen]  # a view of the memory map of a .nii
        else:
            raw = np.asanyarray(proxy)[chosen]
    scaled = (np.isfinite(slope) and slope not in (0.0, 1.0)) or (np.isfinite(inter) and inter != 0)
    if scaled:
        out_dtype = np.float64 if raw.dtype == np.float64 else np.float32
        check_in_memory(shape, out_dtype, label, copies=2)
        s = slope if np.isfinite(slope) and slope != 0 else 1.0
        with np.errstate(over="ignore", invalid="ignore"):  # huge slopes give inf: the policy's
            data = np.asarray(raw, dtype=out_dtype) * out_dtype(s) + out_dtype(inter)
    else:
        data = raw
    with third_party(label, "bad NIfTI geometry (qform/sform)"):
        affine = np.asarray(img.affine, dtype=np.float64)
    if affine.shape != (4, 4):
        raise ReadError(f"{label}: bad NIfTI geometry (affine of shape {affine.shape})")
    data, spacing, origin = align_to_world(data, affine[:3, :3], affine[:3, 3], label)
    metadata = {"format": "nifti", "scl_slope": slope, "scl_inter": inter,
                **selection.metadata(counts[0], timepoint, counts[1], channel)}
    units = _spatial_units(img.header)
    if units:
        metadata["units"] = units
    return finish_volume(data, spacing, origin, path, metadata=metadata)


def _stream_volume(img: Any, chosen: tuple[Any, ...], shape: tuple[int, ...], dtype: np.dtype,
                   offset: int, order: str) -> np.ndarray:
    """One volume of a compressed image, unscaled: nibabel's ``fileslice`` decompresses the
    stream up to it and keeps only its bytes (the scaling is applied by the caller, in float32
    as for a 3D file; nibabel's own slicing would scale in float64)."""
    from nibabel.fileslice import fileslice

    with img.file_map["image"].get_prepare_fileobj("rb") as fileobj:
        return fileslice(fileobj, chosen, shape, dtype, offset, order=order)


def _as_int(value: object) -> int | None:
    try:
        return int(value)  # type: ignore[call-overload]
    except (TypeError, ValueError, OverflowError):
        return None


def _spatial_units(header: object) -> str | None:
    """The spatial unit name, or None when it is absent, unknown or unreadable (an unknown code
    is not an error: the unit is informational)."""
    try:
        units = header.get_xyzt_units()[0]  # type: ignore[attr-defined]
    except Exception:  # nibabel raises KeyError for codes it does not know
        return None
    return str(units) if units and units != "unknown" else None
