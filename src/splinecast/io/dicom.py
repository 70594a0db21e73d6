"""DICOM series: a folder of single-frame slices, read with pydicom.

Slices are ordered by their position along the slice normal (the cross product of the two
``ImageOrientationPatient`` vectors), not by file name or ``InstanceNumber``, which are often
wrong. ``pixel_array`` is ``(rows, columns)`` = ``(y, x)``; each slice is transposed so that the
volume is ``(x, y, z)``. The patient coordinate system (LPS) is kept as world space.

Value type: without rescaling the stored type is kept; with ``RescaleSlope == 1`` and an integral
``RescaleIntercept`` (the usual CT case) the result is int16 when the values fit; any other
rescaling gives float32.

Hostile input: every tag is read through :func:`_numbers` (numeric, finite, the expected count),
every slice must be one greyscale frame of the first slice's size, the stack's memory is checked
before any pixel is decoded (pixel data is read lazily, one slice at a time), and a slice that is
a symbolic link out of the folder is refused unless external files are allowed.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ReadError, limits
from ..volume import Volume
from ._common import check_dtype, check_in_memory, finish_volume, require, third_party
from .orientation import align_to_world
from .selection import Selection

__all__ = ["read_dicom_series", "read_dicom_file"]

#: Tolerance for "same orientation / same pixel spacing" across slices.
_SAME_TOL = 1e-4
#: Relative deviation of a slice gap from the median above which the series is called uneven.
_UNEVEN = 0.01
#: Values longer than this stay on disk until used (the pixel data), so a scan holds no pixels.
_DEFER_BYTES = 4096


def read_dicom_file(path: Path, *, allow_external: bool | None = None,
                    selection: Selection | None = None) -> Volume:
    """Read the series that a single DICOM file belongs to (from the file's folder)."""
    pydicom = require("pydicom", path)
    with third_party(str(path), "not a readable DICOM file"):
        ds = pydicom.dcmread(path, stop_before_pixels=True)
        uid = ds.get("SeriesInstanceUID", None)
    return read_dicom_series(path.parent, series_uid=str(uid) if uid else None, name=path.name,
                             allow_external=allow_external, selection=selection)


def read_dicom_series(
    folder: Path,
    series_uid: str | None = None,
    name: str | None = None,
    *,
    allow_external: bool | None = None,
    selection: Selection | None = None,
) -> Volume:
    """Read every DICOM slice of ``folder`` into one volume, or one time point of a series that
    repeats its slice positions over time (see :func:`_time_points`).

    Parameters
    ----------
    folder : Path
        Folder holding the slices; files that are not DICOM images (DICOMDIR, notes) are skipped.
    series_uid : str, optional
        Keep only this series (used when the user pointed at one file of a mixed folder).
    name : str, optional
        Name given in messages and ``metadata["name"]`` (default: the folder name).
    allow_external : bool, optional
        Follow slices that are symbolic links to files outside the folder (default: refuse,
        unless ``SPLINECAST_ALLOW_EXTERNAL_DATA=1``).
    selection : Selection, optional
        The time point to read of a time series (default: the first, with a
        :class:`~splinecast.io.selection.SeveralVolumesWarning`).

    Raises
    ------
    ReadError
        No readable slice, slices from different series or with different geometry, duplicate
        slice positions, tags that are missing or not numbers, multi-frame or colour slices, a
        stack too big for the memory limit, or pixel data pydicom cannot decode.
    """
    pydicom = require("pydicom", folder)
    if folder.name in ("", ".", ".."):
        folder = folder.resolve()  # "." has no name to show in messages and metadata
    label = f"folder {folder}"
    slices = _scan(pydicom, folder, label, series_uid, allow_external)

    _check_consistent(slices, label)
    first_file, first = slices[0]
    for file, ds in slices:
        if _int(ds, "SamplesPerPixel", file, label, 1) != 1:
            raise ReadError(f"{label}: slice {file.name} is a colour image (SamplesPerPixel > 1); "
                            "only greyscale is supported")
        if _int(ds, "NumberOfFrames", file, label, 1) != 1:
            raise ReadError(f"{label}: slice {file.name} holds several frames; multi-frame DICOM "
                            "is not supported, only one slice per file")

    row_dir, col_dir = _orientation(first, first_file, label)
    normal = np.cross(row_dir, col_dir)
    positions = []
    for file, ds in slices:
        ipp = _numbers(ds, "ImagePositionPatient", file, label, count=3)
        if ipp is None:
            raise ReadError(f"{label}: slice {file.name} has no ImagePositionPatient")
        positions.append(np.array(ipp))
    depth = np.array([p @ normal for p in positions])
    groups = _time_points(slices, depth, label)
    selection = selection or Selection()
    channel = selection.chan(label, 1)
    timepoint = selection.time(label, len(groups))
    chosen = groups[timepoint]
    slices = [slices[i] for i in chosen]
    positions = [positions[i] for i in chosen]
    depth = depth[chosen]
    order = np.argsort(depth, kind="stable")
    slices = [slices[i] for i in order]
    positions = [positions[i] for i in order]
    depth = depth[order]
    dz = _slice_distance(depth, slices, label)

    pixel_spacing = _numbers(first, "PixelSpacing", first_file, label, count=2, positive=True)
    if pixel_spacing is None:
        warnings.warn(f"{label}: no PixelSpacing; assuming 1 mm", UserWarning, stacklevel=3)
        pixel_spacing = [1.0, 1.0]
    # PixelSpacing is (distance between rows, distance between columns) = (dy, dx).
    dy, dx = pixel_spacing

    data = _stack(slices, label)
    matrix = np.column_stack([row_dir * dx, col_dir * dy, normal * dz])
    data, spacing, origin = align_to_world(data, matrix, positions[0], label)
    metadata = {
        "format": "dicom",
        "modality": _text(first, "Modality"),
        "series_description": _text(first, "SeriesDescription"),
        "series_uid": _text(first, "SeriesInstanceUID"),
        "slices": len(slices),
        **selection.metadata(len(groups), timepoint, 1, channel),
    }
    if name is not None:
        metadata["name"] = name
    return finish_volume(data, spacing, origin, folder, label=label, metadata=metadata)


def _scan(pydicom: Any, folder: Path, label: str, series_uid: str | None,
          allow_external: bool | None) -> list[tuple[Path, Any]]:
    """The image slices of ``folder`` (pixel data left on disk), skipping non-DICOM files."""
    slices: list[tuple[Path, Any]] = []
    try:
        files = sorted(p for p in folder.iterdir() if p.is_file())
    except OSError as exc:
        raise ReadError(f"{label}: cannot list: {exc.strerror}") from None
    for file in files:
        limits.check_data_file(file, file.name, "slice", allow_external=allow_external,
                               root_name="the series folder")
        try:
            ds = pydicom.dcmread(file, defer_size=_DEFER_BYTES)
        except (pydicom.errors.InvalidDicomError, OSError, EOFError):
            continue  # not DICOM: skipped silently, like any other stray file
        except Exception as exc:
            raise ReadError(f"{label}: slice {file.name} is damaged "
                            f"({limits.shorten(str(exc), 120)})") from None
        with third_party(f"{label}: slice {file.name}", "damaged tags"):
            if "PixelData" not in ds:
                continue  # DICOMDIR, structured reports, presentation states: no image
            uid = str(ds.get("SeriesInstanceUID", ""))
        if series_uid is not None and uid != series_uid:
            continue
        slices.append((file, ds))
    if not slices:
        raise ReadError(f"{label} contains no readable DICOM slices")
    return slices


def _get(ds: Any, keyword: str, file: Path, label: str) -> Any:
    """A tag's value, or None when absent or empty; a tag pydicom cannot parse is a ReadError."""
    with third_party(f"{label}: slice {file.name}", f"cannot read {keyword}"):
        value = ds.get(keyword, None)
    if value is None or (isinstance(value, str | bytes) and not value.strip()):
        return None
    return value


def _numbers(ds: Any, keyword: str, file: Path, label: str, count: int,
             positive: bool = False) -> list[float] | None:
    """``count`` finite numbers from a tag (None when absent), else a ReadError naming it."""
    value = _get(ds, keyword, file, label)
    if value is None:
        return None
    where = f"{label}: slice {file.name}: {keyword}"
    items = list(value) if isinstance(value, list | tuple) or hasattr(value, "__iter__") and \
        not isinstance(value, str | bytes) else [value]
    if len(items) != count:
        raise ReadError(f"{where} must be {count} numbers, got {limits.shorten(value)}")
    return [limits.check_finite_number(v, where, lo=0 if positive else -np.inf,
                                       lo_open=positive, error=ReadError) for v in items]


def _number(ds: Any, keyword: str, file: Path, label: str, default: float) -> float:
    values = _numbers(ds, keyword, file, label, count=1)
    return default if values is None else values[0]


def _int(ds: Any, keyword: str, file: Path, label: str, default: int) -> int:
    value = _number(ds, keyword, file, label, float(default))
    return limits.check_count(value, f"{label}: slice {file.name}: {keyword}", lo=0,
                              error=ReadError)


def _text(ds: Any, keyword: str) -> str:
    try:
        return str(ds.get(keyword, ""))[:200]
    except Exception:  # informational only: an unreadable description is left empty
        return ""


def _size(ds: Any, file: Path, label: str) -> tuple[int, int]:
    rows = _get(ds, "Rows", file, label)
    cols = _get(ds, "Columns", file, label)
    if rows is None or cols is None:
        raise ReadError(f"{label}: slice {file.name} has no Rows or Columns")
    rows = limits.check_count(rows, f"{label}: slice {file.name}: Rows", hi=limits.MAX_AXIS,
                              error=ReadError)
    cols = limits.check_count(cols, f"{label}: slice {file.name}: Columns", hi=limits.MAX_AXIS,
                              error=ReadError)
    return rows, cols


def _check_consistent(slices: list[tuple[Path, Any]], label: str) -> None:
    uids = {_text(ds, "SeriesInstanceUID") for _, ds in slices}
    if len(uids) > 1:
        raise ReadError(
            f"{label} mixes {len(uids)} DICOM series (SeriesInstanceUID); "
            "put each series in its own folder"
        )
    ref_file, ref = slices[0]
    ref_size = _size(ref, ref_file, label)
    ref_iop = _numbers(ref, "ImageOrientationPatient", ref_file, label, count=6)
    ref_ps = _numbers(ref, "PixelSpacing", ref_file, label, count=2, positive=True)
    for file, ds in slices[1:]:
        size = _size(ds, file, label)
        if size != ref_size:
            raise ReadError(
                f"{label}: slices differ in Rows/Columns "
                f"({ref_file.name}: {ref_size[0]}x{ref_size[1]}, {file.name}: {size[0]}x{size[1]})"
            )
        if not _same(_numbers(ds, "ImageOrientationPatient", file, label, count=6), ref_iop):
            raise ReadError(
                f"{label}: slices differ in ImageOrientationPatient ({ref_file.name}, {file.name})"
            )
        if not _same(_numbers(ds, "PixelSpacing", file, label, count=2, positive=True), ref_ps):
            raise ReadError(
                f"{label}: slices differ in PixelSpacing ({ref_file.name}, {file.name})"
            )


def _same(a: list[float] | None, b: list[float] | None) -> bool:
    if a is None or b is None:
        return a is None and b is None
    return bool(np.allclose(a, b, rtol=_SAME_TOL, atol=_SAME_TOL))


def _orientation(ds: Any, file: Path, label: str) -> tuple[np.ndarray, np.ndarray]:
    iop = _numbers(ds, "ImageOrientationPatient", file, label, count=6)
    if iop is None:
        raise ReadError(f"{label}: slice {file.name} has no ImageOrientationPatient")
    row_dir, col_dir = np.array(iop[:3]), np.array(iop[3:])
    n_row, n_col = np.linalg.norm(row_dir), np.linalg.norm(col_dir)
    if not (n_row > 1e-6 and n_col > 1e-6):
        raise ReadError(f"{label}: ImageOrientationPatient has a zero vector")
    row_dir, col_dir = row_dir / n_row, col_dir / n_col
    if np.linalg.norm(np.cross(row_dir, col_dir)) < 1e-3:
        raise ReadError(f"{label}: ImageOrientationPatient has parallel row and column vectors")
    return row_dir, col_dir


#: Tags that tell the time points of a series apart, most specific first.
_TIME_TAGS = ("TemporalPositionIdentifier", "TriggerTime", "AcquisitionNumber")


def _time_points(slices: list[tuple[Path, Any]], depth: np.ndarray,
                 label: str) -> list[np.ndarray]:
    """The slices of each time point (indices into ``slices``), in time order.

    A series whose slice positions all differ is one time point. One that repeats positions
    (a dynamic, cardiac or perfusion acquisition) is split by the first of :data:`_TIME_TAGS`
    that every slice has and that gives groups of equal size, each with every position once;
    without one, the repeated position is reported as a duplicate slice
    (:func:`_slice_distance`).
    """
    every = [np.arange(len(slices))]
    if len(slices) < 2:
        return every
    span = float(np.ptp(depth)) or 1.0
    positions = np.round(depth / (1e-4 * span)).astype(np.int64)
    if len(np.unique(positions)) == len(positions):
        return every
    for keyword in _TIME_TAGS:
        values = []
        for _, ds in slices:
            value = ds.get(keyword, None)
            try:
                values.append(float(value))
            except (TypeError, ValueError):
                break
        if len(values) != len(slices) or not np.all(np.isfinite(values)):
            continue
        keys = np.asarray(values)
        groups = [np.flatnonzero(keys == key) for key in np.unique(keys)]
        sizes = {len(g) for g in groups}
        if len(groups) > 1 and len(sizes) == 1 and all(
                len(np.unique(positions[g])) == len(g) for g in groups):
            return groups
    return every


def _slice_distance(depth: np.ndarray, slices: list[tuple[Path, Any]], label: str) -> float:
    if len(depth) == 1:
        file, first = slices[0]
        for key in ("SpacingBetweenSlices", "SliceThickness"):
            value = _number(first, key, file, label, 0.0)
            if value > 0:
                return value
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
    """Decode, rescale and stack the slices into an (x, y, z) array, one slice at a time."""
    first_file, first = slices[0]
    rows, cols = _size(first, first_file, label)
    rescale = []
    for file, ds in slices:
        slope = _number(ds, "RescaleSlope", file, label, 1.0) or 1.0
        inter = _number(ds, "RescaleIntercept", file, label, 0.0)
        rescale.append((slope, inter))
    # Budget the result at 4 bytes per voxel (the widest type chosen below) plus one decoded slice.
    check_in_memory((cols, rows, len(slices)), np.float32, label)

    def decode(file: Path, ds: Any) -> np.ndarray:
        with third_party(f"{label}: slice {file.name}", "cannot decode the pixel data"):
            frame = np.asarray(ds.pixel_array)
        if frame.shape != (rows, cols):
            raise ReadError(f"{label}: slice {file.name} decodes to shape {frame.shape}, "
                            f"expected {rows}x{cols}")
        return frame

    kind = decode(first_file, first).dtype
    check_dtype(kind, f"{label}: slice {first_file.name}")
    if all(sl == 1.0 and i == 0.0 for sl, i in rescale):
        dtype = kind  # stored values as they are
    elif kind.kind in "iub" and all(sl == 1.0 and i == int(i) and abs(i) < 2**31
                                    for sl, i in rescale):
        dtype = np.dtype(np.int32)  # integral shift: narrowed to int16 below when it fits
    else:
        dtype = np.dtype(np.float32)
    out = np.empty((cols, rows, len(slices)), dtype=dtype, order="F")
    for k, ((file, ds), (slope, inter)) in enumerate(zip(slices, rescale, strict=True)):
        frame = decode(file, ds)
        if not np.can_cast(frame.dtype, kind, "safe"):
            raise ReadError(f"{label}: slices differ in pixel type ({first_file.name}: {kind}, "
                            f"{file.name}: {frame.dtype})")
        if dtype.kind == "f":
            with np.errstate(over="ignore", invalid="ignore"):  # huge slopes: inf, the policy's
                out[:, :, k] = (frame.astype(np.float32) * np.float32(slope)
                                + np.float32(inter)).T
        elif dtype == np.int32:
            shifted = frame.astype(np.int64) + int(inter)
            if shifted.min() < np.iinfo(np.int32).min or shifted.max() > np.iinfo(np.int32).max:
                raise ReadError(f"{label}: slice {file.name}: RescaleIntercept {inter:g} puts "
                                "values outside the 32-bit range")
            out[:, :, k] = shifted.T
        else:
            out[:, :, k] = frame.T
    if dtype == np.int32:
        info = np.iinfo(np.int16)
        if info.min <= out.min() and out.max() <= info.max:
            check_in_memory(out.shape, np.int16, label)
            out = np.asfortranarray(out.astype(np.int16))
        else:
            check_in_memory(out.shape, np.float32, label)
            out = np.asfortranarray(out.astype(np.float32))
    return out
