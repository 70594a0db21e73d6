"""NIfTI-1/2 (``.nii``, ``.nii.gz``, ``.hdr``/``.img`` pairs) via nibabel.

The voxels come from ``img.dataobj`` so their stored dtype is kept and an uncompressed ``.nii`` is
memory-mapped. ``scl_slope``/``scl_inter``, when set to anything but 1 and 0, are applied (float32
result, float64 for float64 data). The affine gives spacing (column lengths of its 3x3 part) and
origin (its translation); axes that run backwards are flipped and an oblique rotation is dropped,
both with an :class:`~splinecast.io.orientation.OrientationWarning`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import ReadError, limits
from ..volume import Volume
from ._common import check_dtype, check_in_memory, finish_volume, fmt_shape, require, third_party
from .orientation import align_to_world

__all__ = ["read_nifti"]


def read_nifti(path: Path, *, allow_external: bool | None = None) -> Volume:
    """Read a NIfTI image holding one 3D volume (a 4D image with a single volume is accepted).

    The header's sizes, type and data offset are checked against the limits, the file size and
    the memory available before nibabel reads any voxel; for an ``.hdr``/``.img`` pair the
    ``.img`` must lie beside the header (symbolic links resolved) unless ``allow_external``.
    """
    nib = require("nibabel", path)
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
    if any(n != 1 for n in extra):
        volumes = int(np.prod(extra, dtype=object))
        raise ReadError(
            f"{label}: a {len(header_shape)}D image with {volumes} volumes "
            f"({fmt_shape(header_shape)}); only a single 3D volume can be read"
        )
    shape = limits.check_shape(header_shape[:3], f"{label}: dim", error=ReadError)
    dtype = check_dtype(dtype, label)
    expected = limits.nbytes(shape, dtype.itemsize)
    if image_file is not None and Path(image_file).name != path.name:
        limits.check_data_file(path, Path(image_file).name, "image file",
                               allow_external=allow_external)
    if image_file is not None and not str(image_file).lower().endswith(".gz"):
        size = limits.check_regular_file(Path(image_file), str(image_file)).st_size
        if size < offset + expected:
            raise ReadError(
                f"{label}: expected {expected} bytes for {fmt_shape(shape)} {dtype.name} after "
                f"{offset} bytes, the file has {size} (truncated)"
            )
    else:
        check_in_memory(shape, dtype, label)  # decompressed in full (bounded by the header)

    with third_party(label, "bad scaling (scl_slope/scl_inter)"):
        slope = float(getattr(proxy, "slope", 1.0))
        inter = float(getattr(proxy, "inter", 0.0))
    with third_party(label, "cannot read the voxel data"):
        if hasattr(proxy, "get_unscaled"):
            raw = proxy.get_unscaled()  # a memmap for an uncompressed .nii
        else:
            raw = np.asanyarray(proxy)
    # Drop trailing singleton dimensions by indexing, which keeps a memory map a view.
    raw = raw[(slice(None),) * 3 + (0,) * (raw.ndim - 3)]
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
    metadata = {"format": "nifti", "scl_slope": slope, "scl_inter": inter}
    units = _spatial_units(img.header)
    if units:
        metadata["units"] = units
    return finish_volume(data, spacing, origin, path, metadata=metadata)


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
