"""DICOM series: a folder of single-frame slices, read with pydicom.

Slices are ordered by their position along the slice normal (the cross product of the two
``ImageOrientationPatient`` vectors), not by file name or ``InstanceNumber``, which are often
wrong. ``pixel_array`` is ``(rows, columns)`` = ``(y, x)``; each slice is transposed so that the
volume is ``(x, y, z)``. The patient coordinate system (LPS) is kept as world space.

Value type: without rescaling the stored type is kept; with ``RescaleSlope == 1`` and an integral
``RescaleIntercept`` (the usual CT case) the result is int16 when the values fit; any other
rescaling gives float32.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ReadError
from ..volume import Volume
from ._common import check_dtype, finish_volume, one_line, require
from .orientation import align_to_world

__all__ = ["read_dicom_series", "read_dicom_file"]

#: Tolerance for "same orientation / same pixel spacing" across slices.
_SAME_TOL = 1e-4
#: Relative deviation of a slice gap from the median above which the series is called uneven.
_UNEVEN = 0.01


def read_dicom_file(path: Path) -> Volume:
    """Read the series that a single DICOM file belongs to (from the file's folder)."""
    pydicom = require("pydicom", path)
    try:
        ds = pydicom.dcmread(path, stop_before_pixels=True)
    except Exception as exc:  # pydicom raises a wide variety of errors on bad files
        raise ReadError(f"{path}: not a readable DICOM file ({one_line(exc)})") from None
    uid = getattr(ds, "SeriesInstanceUID", None)
    return read_dicom_series(path.parent, series_uid=str(uid) if uid else None, name=path.name)


def read_dicom_series(
    folder: Path, series_uid: str | None = None, name: str | None = None
) -> Volume:
    """Read every DICOM slice of ``folder`` into one volume.

    Parameters
    ----------
    folder : Path
        Folder holding the slices; files that are not DICOM images (DICOMDIR, notes) are skipped.
    series_uid : str, optional
        Keep only this series (used when the user pointed at one file of a mixed folder).
    name : str, optional
        Name given in messages and ``metadata["name"]`` (default: the folder name).

    Raises
    ------
    ReadError
        No readable slice, slices from different series or with different geometry, duplicate
        slice positions, or pixel data pydicom cannot decode.
    """
    pydicom = require("pydicom", folder)
    if folder.name in ("", ".", ".."):
        folder = folder.resolve()  # "." has no name to show in messages and metadata
    label = f"folder {folder}"
    slices: list[tuple[Path, Any]] = []
    try:
        files = sorted(p for p in folder.iterdir() if p.is_file())
    except OSError as exc:
        raise ReadError(f"{label}: cannot list: {exc.strerror}") from None
    for file in files:
        try:
            ds = pydicom.dcmread(file)
        except (pydicom.errors.InvalidDicomError, OSError, EOFError):
            continue  # not DICOM: skipped silently, like any other stray file
        except Exception as exc:
            raise ReadError(f"{label}: slice {file.name} is damaged ({one_line(exc)})") from None
        if "PixelData" not in ds:
            continue  # DICOMDIR, structured reports, presentation states: no image
        if series_uid is not None and str(getattr(ds, "SeriesInstanceUID", "")) != series_uid:
            continue
        slices.append((file, ds))
    if not slices:
        raise ReadError(f"{label} contains no readable DICOM slices")

    _check_consistent(slices, label)
    first = slices[0][1]
    if int(getattr(first, "SamplesPerPixel", 1)) != 1:
        raise ReadError(f"{label}: colour images (SamplesPerPixel > 1) are not supported")
    if int(getattr(first, "NumberOfFrames", 1) or 1) != 1:
        raise ReadError(f"{label}: multi-frame DICOM is not supported, only one slice per file")

    row_dir, col_dir = _orientation(first, slices[0][0], label)
    normal = np.cross(row_dir, col_dir)
    positions = []
    for file, ds in slices:
        ipp = getattr(ds, "ImagePositionPatient", None)
        if ipp is None or len(ipp) != 3:
            raise ReadError(f"{label}: slice {file.name} has no ImagePositionPatient")
        positions.append(np.array([float(v) for v in ipp]))
    depth = np.array([p @ normal for p in positions])
    order = np.argsort(depth, kind="stable")
    slices = [slices[i] for i in order]
    positions = [positions[i] for i in order]
    depth = depth[order]
    dz = _slice_distance(depth, slices, first, label)

    pixel_spacing = getattr(first, "PixelSpacing", None)
    if pixel_spacing is None:
        warnings.warn(f"{label}: no PixelSpacing; assuming 1 mm", UserWarning, stacklevel=3)
        pixel_spacing = (1.0, 1.0)
    # PixelSpacing is (distance between rows, distance between columns) = (dy, dx).
    dy, dx = float(pixel_spacing[0]), float(pixel_spacing[1])

    data = _stack(slices, label)
    matrix = np.column_stack([row_dir * dx, col_dir * dy, normal * dz])
    data, spacing, origin = align_to_world(data, matrix, positions[0], label)
    metadata = {
        "format": "dicom",
        "modality": str(getattr(first, "Modality", "")),
        "series_description": str(getattr(first, "SeriesDescription", "")),
        "series_uid": str(getattr(first, "SeriesInstanceUID", "")),
        "slices": len(slices),
    }
    if name is not None:
        metadata["name"] = name
    return finish_volume(data, spacing, origin, folder, label=label, metadata=metadata)


def _check_consistent(slices: list[tuple[Path, Any]], label: str) -> None:
    uids = {str(getattr(ds, "SeriesInstanceUID", "")) for _, ds in slices}
    if len(uids) > 1:
        raise ReadError(
            f"{label} mixes {len(uids)} DICOM series (SeriesInstanceUID); "
            "put each series in its own folder"
        )
    ref_file, ref = slices[0]
    ref_iop = _floats(getattr(ref, "ImageOrientationPatient", None))
    ref_ps = _floats(getattr(ref, "PixelSpacing", None))
    for file, ds in slices[1:]:
        if (ds.Rows, ds.Columns) != (ref.Rows, ref.Columns):
            raise ReadError(
                f"{label}: slices differ in Rows/Columns "
                f"({ref_file.name}: {ref.Rows}x{ref.Columns}, {file.name}: {ds.Rows}x{ds.Columns})"
            )
        if not _same(_floats(getattr(ds, "ImageOrientationPatient", None)), ref_iop):
            raise ReadError(
                f"{label}: slices differ in ImageOrientationPatient ({ref_file.name}, {file.name})"
            )
        if not _same(_floats(getattr(ds, "PixelSpacing", None)), ref_ps):
            raise ReadError(
                f"{label}: slices differ in PixelSpacing ({ref_file.name}, {file.name})"
            )


def _floats(value: Any) -> np.ndarray | None:
    if value is None:
        return None
    return np.array([float(v) for v in value])


def _same(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    if a is None or b is None:
        return a is None and b is None
    return a.shape == b.shape and bool(np.allclose(a, b, rtol=_SAME_TOL, atol=_SAME_TOL))


def _orientation(ds: Any, file: Path, label: str) -> tuple[np.ndarray, np.ndarray]:
    iop = _floats(getattr(ds, "ImageOrientationPatient", None))
    if iop is None or iop.size != 6:
        raise ReadError(f"{label}: slice {file.name} has no ImageOrientationPatient")
    row_dir, col_dir = iop[:3], iop[3:]
    n_row, n_col = np.linalg.norm(row_dir), np.linalg.norm(col_dir)
    if n_row == 0 or n_col == 0:
        raise ReadError(f"{label}: ImageOrientationPatient has a zero vector")
    return row_dir / n_row, col_dir / n_col


def _slice_distance(
    depth: np.ndarray, slices: list[tuple[Path, Any]], first: Any, label: str
) -> float:
    if len(depth) == 1:
        for key in ("SpacingBetweenSlices", "SliceThickness"):
            value = getattr(first, key, None)
            if value is not None and float(value) > 0:
                return float(value)
        return 1.0
    gaps = np.diff(depth)
    median = float(np.median(gaps))
    tiny = max(1e-3 * abs(median), 1e-4)
    duplicates = np.flatnonzero(gaps < tiny)
    if duplicates.size:
        k = int(duplicates[0])
        raise ReadError(
            f"{label}: slices {slices[k][0].name} and {slices[k + 1][0].name} "
            f"are at the same position (duplicate slice)"
        )
    deviation = float(np.max(np.abs(gaps - median)))
    if deviation > _UNEVEN * median:
        warnings.warn(
            f"{label}: uneven slice spacing ({gaps.min():.4g} to {gaps.max():.4g} mm); "
            f"using the median {median:.4g} mm",
            UserWarning,
            stacklevel=4,
        )
    return median


def _stack(slices: list[tuple[Path, Any]], label: str) -> np.ndarray:
    """Decode, rescale and stack the slices into an (x, y, z) array."""
    frames = []
    rescale = []
    for file, ds in slices:
        try:
            frames.append(ds.pixel_array)
        except Exception as exc:  # missing decoder plugin, corrupt pixel data
            raise ReadError(f"{label}: cannot decode {file.name} ({one_line(exc)})") from None
        slope = float(getattr(ds, "RescaleSlope", 1.0) or 1.0)
        inter = float(getattr(ds, "RescaleIntercept", 0.0) or 0.0)
        rescale.append((slope, inter))
    raw_dtype = np.result_type(*[f.dtype for f in frames])
    rows, cols = frames[0].shape
    if all(s == 1.0 and i == 0.0 for s, i in rescale):
        dtype = check_dtype(raw_dtype, label)
    elif all(s == 1.0 and i == int(i) for s, i in rescale):
        lo = min(int(f.min()) + int(i) for f, (_, i) in zip(frames, rescale, strict=True))
        hi = max(int(f.max()) + int(i) for f, (_, i) in zip(frames, rescale, strict=True))
        info = np.iinfo(np.int16)
        dtype = np.dtype(np.int16) if info.min <= lo and hi <= info.max else np.dtype(np.float32)
    else:
        dtype = np.dtype(np.float32)
    out = np.empty((cols, rows, len(frames)), dtype=dtype, order="F")
    for k, (frame, (slope, inter)) in enumerate(zip(frames, rescale, strict=True)):
        if dtype.kind == "f":
            out[:, :, k] = (frame.astype(np.float32) * np.float32(slope) + np.float32(inter)).T
        elif slope == 1.0 and inter == 0.0:
            out[:, :, k] = frame.T
        else:
            out[:, :, k] = (frame.astype(np.int32) + int(inter)).T
    return out
