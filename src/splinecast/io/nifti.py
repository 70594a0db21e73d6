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

from ..errors import ReadError
from ..volume import Volume
from ._common import finish_volume, fmt_shape, one_line, require
from .orientation import align_to_world

__all__ = ["read_nifti"]


def read_nifti(path: Path) -> Volume:
    """Read a NIfTI image holding one 3D volume (a 4D image with a single volume is accepted)."""
    nib = require("nibabel", path)
    label = str(path)
    try:
        img = nib.load(str(path))
    except FileNotFoundError:
        raise ReadError(f"{label}: no such file") from None
    except Exception as exc:  # nibabel raises many types (ImageFileError, HeaderDataError, ...)
        raise ReadError(f"{label}: not a readable NIfTI image ({one_line(exc)})") from None
    shape = tuple(int(n) for n in img.shape)
    if len(shape) < 3:
        raise ReadError(f"{label}: a {len(shape)}D image ({fmt_shape(shape)}), expected 3D")
    if any(n != 1 for n in shape[3:]):
        raise ReadError(
            f"{label}: a 4D image with {int(np.prod(shape[3:]))} volumes ({fmt_shape(shape)}); "
            "only a single 3D volume can be read"
        )
    proxy = img.dataobj
    slope = float(getattr(proxy, "slope", 1.0))
    inter = float(getattr(proxy, "inter", 0.0))
    try:
        if hasattr(proxy, "get_unscaled"):
            raw = proxy.get_unscaled()  # a memmap for an uncompressed .nii
        else:
            raw = np.asanyarray(proxy)
    except Exception as exc:  # truncated gzip, short file, ...
        raise ReadError(f"{label}: cannot read the voxel data ({one_line(exc)})") from None
    # Drop trailing singleton dimensions by indexing, which keeps a memory map a view.
    raw = raw[(slice(None),) * 3 + (0,) * (raw.ndim - 3)]
    scaled = (np.isfinite(slope) and slope not in (0.0, 1.0)) or (np.isfinite(inter) and inter != 0)
    if scaled:
        out_dtype = np.float64 if raw.dtype == np.float64 else np.float32
        s = slope if np.isfinite(slope) and slope != 0 else 1.0
        data = np.asarray(raw, dtype=out_dtype) * out_dtype(s) + out_dtype(inter)
    else:
        data = raw
    affine = np.asarray(img.affine, dtype=np.float64)
    data, spacing, origin = align_to_world(data, affine[:3, :3], affine[:3, 3], label)
    metadata = {"format": "nifti", "scl_slope": slope, "scl_inter": inter}
    units = img.header.get_xyzt_units()[0] if hasattr(img.header, "get_xyzt_units") else None
    if units and units != "unknown":
        metadata["units"] = units
    return finish_volume(data, spacing, origin, path, metadata=metadata)
