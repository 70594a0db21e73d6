"""Readers and writers of splinecast.io: round trips, geometry, memory maps and user errors."""

from __future__ import annotations

import json
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from splinecast.errors import ParameterError, ReadError
from splinecast.io import OrientationWarning, SeveralVolumesWarning, read, write
from splinecast.volume import SUPPORTED_DTYPES, Volume

SPACING = (0.5, 0.75, 2.0)
ORIGIN = (-1.0, 2.0, 3.5)
SHAPE = (5, 6, 7)
MNI = Path(__file__).resolve().parents[2] / "shared" / "data" / "mni152_t1_1mm.nii.gz"


def ramp(dtype: np.dtype | type = np.uint16, shape: tuple[int, int, int] = SHAPE) -> np.ndarray:
    """Values that differ along every axis, so any transpose or flip shows up."""
    i, j, k = np.indices(shape)
    return ((i + 10 * j + 100 * k) % 120).astype(dtype)


def make_volume(dtype: np.dtype | type = np.uint16, **kw: object) -> Volume:
    return Volume(ramp(dtype), spacing=SPACING, origin=ORIGIN, **kw)


def is_memmap(a: np.ndarray) -> bool:
    while a is not None:
        if isinstance(a, np.memmap):
            return True
        a = a.base  # type: ignore[assignment]
    return False


def assert_same(vol: Volume, data: np.ndarray, spacing=SPACING, origin=ORIGIN) -> None:
    assert vol.shape == data.shape
    assert vol.dtype == data.dtype
    np.testing.assert_array_equal(vol.data, data)
    np.testing.assert_allclose(vol.spacing, spacing, rtol=1e-6)
    np.testing.assert_allclose(vol.origin, origin, rtol=1e-6, atol=1e-6)


def files_in(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


# --------------------------------------------------------------------------- numpy
def test_npy_round_trip_is_memory_mapped(tmp_path: Path) -> None:
    vol = Volume(ramp(np.int16))
    path = tmp_path / "v.npy"
    write(vol, path)
    back = read(path)
    assert_same(back, vol.data, spacing=(1, 1, 1), origin=(0, 0, 0))
    assert isinstance(back.data, np.memmap)
    assert back.metadata["name"] == "v.npy"
    assert back.metadata["source"] == str(path.absolute())


def test_npy_warns_that_geometry_is_lost(tmp_path: Path) -> None:
    with pytest.warns(UserWarning, match="spacing"):
        write(make_volume(), tmp_path / "v.npy")


@pytest.mark.parametrize("key", ["data", "volume", "anything"])
def test_npz_keys_and_geometry(tmp_path: Path, key: str) -> None:
    path = tmp_path / "v.npz"
    np.savez(path, **{key: ramp(np.float32)}, spacing=np.array(SPACING), origin=np.array(ORIGIN))
    assert_same(read(path), ramp(np.float32))


def test_npz_written_by_write(tmp_path: Path) -> None:
    vol = make_volume(np.float64)
    write(vol, tmp_path / "v.npz")
    assert_same(read(tmp_path / "v.npz"), vol.data)


def test_npz_without_a_clear_array_is_refused(tmp_path: Path) -> None:
    np.savez(tmp_path / "two.npz", a=ramp(), b=ramp())
    with pytest.raises(ReadError, match="two.npz"):
        read(tmp_path / "two.npz")


# --------------------------------------------------------------------------- MetaImage
@pytest.mark.parametrize("dtype", SUPPORTED_DTYPES, ids=str)
def test_mhd_round_trip_every_dtype(tmp_path: Path, dtype: np.dtype) -> None:
    vol = make_volume(dtype)
    write(vol, tmp_path / "v.mhd")
    assert files_in(tmp_path) == ["v.mhd", "v.raw"]
    back = read(tmp_path / "v.mhd")
    assert_same(back, vol.data)
    assert is_memmap(back.data)
    # x varies fastest in the raw file, as MetaImage requires.
    raw = np.fromfile(tmp_path / "v.raw", dtype=dtype.newbyteorder("<"))
    np.testing.assert_array_equal(raw[:5], vol.data[:, 0, 0])


def write_mha_local(path: Path, data: np.ndarray, extra: str = "", prefix: bytes = b"") -> None:
    """A single-file MetaImage with big-endian voxels after the header."""
    header = (
        "ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = True\n"
        f"CompressedData = False\nDimSize = {' '.join(map(str, data.shape))}\n"
        f"ElementSpacing = {' '.join(map(str, SPACING))}\nOrigin = {' '.join(map(str, ORIGIN))}\n"
        f"{extra}ElementType = MET_SHORT\nElementDataFile = LOCAL\n"
    )
    path.write_bytes(header.encode() + prefix + data.astype(">i2").tobytes(order="F"))


def test_mha_local_big_endian(tmp_path: Path) -> None:
    write_mha_local(tmp_path / "v.mha", ramp(np.int16))
    back = read(tmp_path / "v.mha")
    assert back.dtype == np.dtype(np.int16) and back.dtype.isnative
    assert_same(back, ramp(np.int16))


def test_mhd_header_size_minus_one_reads_the_end(tmp_path: Path) -> None:
    write_mha_local(tmp_path / "v.mha", ramp(np.int16), extra="HeaderSize = -1\n", prefix=b"junk")
    assert_same(read(tmp_path / "v.mha"), ramp(np.int16))


def test_mhd_transform_matrix_warns(tmp_path: Path) -> None:
    rotation = "TransformMatrix = 0 1 0 1 0 0 0 0 1\n"
    write_mha_local(tmp_path / "v.mha", ramp(np.int16), extra=rotation)
    with pytest.warns(UserWarning, match="rotation is ignored"):
        read(tmp_path / "v.mha")


def test_mhd_rejects_what_it_cannot_read(tmp_path: Path) -> None:
    write(make_volume(), tmp_path / "v.mhd")
    text = (tmp_path / "v.mhd").read_text()
    for old, new, message in [
        ("NDims = 3", "NDims = 2", "NDims"),
        ("MET_USHORT", "MET_LONG_LONG", "ElementType"),
        ("CompressedData = False", "CompressedData = True", "CompressedData"),
    ]:
        (tmp_path / "bad.mhd").write_text(text.replace(old, new))
        with pytest.raises(ReadError, match=rf"bad\.mhd.*{message}"):
            read(tmp_path / "bad.mhd")


# --------------------------------------------------------------------------- raw + errors
def test_truncated_raw_file(tmp_path: Path) -> None:
    write(make_volume(), tmp_path / "v.mhd")
    raw = tmp_path / "v.raw"
    raw.write_bytes(raw.read_bytes()[:-10])
    with pytest.raises(ReadError, match=r"v\.raw: expected 420 bytes for 5x6x7 uint16.*truncated"):
        read(tmp_path / "v.mhd")


def test_header_size_disagrees_with_data(tmp_path: Path) -> None:
    write(make_volume(), tmp_path / "v.mhd")
    header = tmp_path / "v.mhd"
    header.write_text(header.read_text().replace("DimSize = 5 6 7", "DimSize = 5 6 6"))
    with pytest.raises(ReadError, match=r"v\.raw: expected 360 bytes.*file has 420.*v\.mhd"):
        read(header)


def test_missing_data_file(tmp_path: Path) -> None:
    write(make_volume(), tmp_path / "v.mhd")
    (tmp_path / "v.raw").unlink()
    with pytest.raises(ReadError, match=r"v\.raw: data file not found"):
        read(tmp_path / "v.mhd")


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ReadError, match=r"nothing\.nii\.gz: no such file"):
        read(tmp_path / "nothing.nii.gz")


def test_unknown_extension(tmp_path: Path) -> None:
    (tmp_path / "notes.xyz").write_text("hello")
    with pytest.raises(ReadError, match=r"notes\.xyz: unknown file format"):
        read(tmp_path / "notes.xyz")


def test_known_extension_with_wrong_content(tmp_path: Path) -> None:
    (tmp_path / "fake.nrrd").write_text("hello")
    with pytest.raises(ReadError, match=r"fake\.nrrd: not a valid nrrd file"):
        read(tmp_path / "fake.nrrd")


def test_raw_without_description(tmp_path: Path) -> None:
    (tmp_path / "lonely.raw").write_bytes(b"\0" * 8)
    with pytest.raises(ReadError, match=r"lonely\.raw: raw voxels need a description"):
        read(tmp_path / "lonely.raw")


def test_format_found_from_content(tmp_path: Path) -> None:
    np.save(tmp_path / "v.npy", ramp())
    (tmp_path / "v.npy").rename(tmp_path / "v.dat")
    assert_same(read(tmp_path / "v.dat"), ramp(), spacing=(1, 1, 1), origin=(0, 0, 0))


# --------------------------------------------------------------------------- JSON sidecar
def test_raw_writer_and_sidecar_round_trip(tmp_path: Path) -> None:
    vol = make_volume(np.float32)
    write(vol, tmp_path / "v.raw")
    assert files_in(tmp_path) == ["v.json", "v.raw"]
    for path in (tmp_path / "v.raw", tmp_path / "v.json"):
        back = read(path)
        assert_same(back, vol.data)
        assert is_memmap(back.data)
        assert back.metadata["name"] == path.name


def test_sidecar_c_order_big_endian_header_bytes(tmp_path: Path) -> None:
    data = ramp(np.uint16)
    (tmp_path / "scan.raw").write_bytes(b"HEAD" + data.astype(">u2").tobytes(order="C"))
    sidecar = {
        "shape": list(data.shape), "dtype": "uint16", "spacing": list(SPACING),
        "origin": list(ORIGIN), "byte_order": "big", "order": "C", "header_bytes": 4,
    }
    (tmp_path / "scan.raw.json").write_text(json.dumps(sidecar))
    back = read(tmp_path / "scan.raw")
    assert back.dtype.isnative
    assert_same(back, data)


def test_sidecar_missing_required_key(tmp_path: Path) -> None:
    (tmp_path / "a.raw").write_bytes(b"\0" * 8)
    (tmp_path / "a.json").write_text(json.dumps({"shape": [2, 2, 2]}))
    with pytest.raises(ReadError, match=r"a\.json: required key 'dtype'"):
        read(tmp_path / "a.raw")


def test_sidecar_truncated(tmp_path: Path) -> None:
    (tmp_path / "a.raw").write_bytes(b"\0" * 7)
    (tmp_path / "a.json").write_text(json.dumps({"shape": [2, 2, 2], "dtype": "uint8"}))
    with pytest.raises(ReadError, match=r"a\.raw: expected 8 bytes for 2x2x2 uint8 after a 0-byte"):
        read(tmp_path / "a.raw")


# --------------------------------------------------------------------------- NRRD
def test_nrrd_round_trip_is_memory_mapped(tmp_path: Path) -> None:
    pytest.importorskip("nrrd")
    vol = make_volume(np.int32)
    write(vol, tmp_path / "v.nrrd")
    assert files_in(tmp_path) == ["v.nrrd"]
    back = read(tmp_path / "v.nrrd")
    assert_same(back, vol.data)
    assert is_memmap(back.data)


def test_nhdr_detached_raw(tmp_path: Path) -> None:
    nrrd = pytest.importorskip("nrrd")
    data = ramp(np.uint16)
    header = {
        "encoding": "raw", "space dimension": 3,
        "space directions": np.diag(SPACING), "space origin": np.array(ORIGIN),
    }
    nrrd.write(str(tmp_path / "v.nhdr"), data, header, index_order="F")
    assert files_in(tmp_path) == ["v.nhdr", "v.raw"]
    back = read(tmp_path / "v.nhdr")
    assert_same(back, data)
    assert is_memmap(back.data)


def test_nrrd_gzip_flipped_axis(tmp_path: Path) -> None:
    nrrd = pytest.importorskip("nrrd")
    data = ramp(np.float32)
    directions = np.diag([SPACING[0], -SPACING[1], SPACING[2]])
    header = {"space": "left-posterior-superior", "space directions": directions,
              "space origin": np.array(ORIGIN)}
    nrrd.write(str(tmp_path / "v.nrrd"), data, header, index_order="F")  # gzip by default
    with pytest.warns(OrientationWarning, match=r"v\.nrrd: axis y"):
        back = read(tmp_path / "v.nrrd")
    # The last y slice of the file is now first, and sits at the lowest y.
    expected_origin = (ORIGIN[0], ORIGIN[1] - (SHAPE[1] - 1) * SPACING[1], ORIGIN[2])
    assert_same(back, data[:, ::-1, :], origin=expected_origin)
    assert back.metadata["space"] == "left-posterior-superior"


def test_nrrd_oblique_warns(tmp_path: Path) -> None:
    nrrd = pytest.importorskip("nrrd")
    c, s = np.cos(0.2), np.sin(0.2)
    directions = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]]) * np.array(SPACING)[:, None]
    header = {"encoding": "raw", "space dimension": 3, "space directions": directions}
    nrrd.write(str(tmp_path / "o.nrrd"), ramp(), header, index_order="F")
    with pytest.warns(OrientationWarning, match=r"o\.nrrd: oblique.*rotation is ignored"):
        back = read(tmp_path / "o.nrrd")
    np.testing.assert_allclose(back.spacing, SPACING)


# --------------------------------------------------------------------------- NIfTI
def nifti(tmp_path: Path, name: str, data: np.ndarray, affine: np.ndarray, **header) -> Path:
    nib = pytest.importorskip("nibabel")
    img = nib.Nifti1Image(data, affine)
    for key, value in header.items():
        img.header[key] = value
    path = tmp_path / name
    nib.save(img, path)
    return path


def affine_of(spacing=SPACING, origin=ORIGIN) -> np.ndarray:
    aff = np.diag([*spacing, 1.0])
    aff[:3, 3] = origin
    return aff


@pytest.mark.parametrize("name", ["v.nii", "v.nii.gz"])
def test_nifti_round_trip(tmp_path: Path, name: str) -> None:
    data = ramp(np.int16)
    path = nifti(tmp_path, name, data, affine_of())
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # an axis-aligned affine warns about nothing
        back = read(path)
    assert_same(back, data)
    if name == "v.nii":
        assert is_memmap(back.data)


def test_nifti_flipped_axis(tmp_path: Path) -> None:
    data = ramp(np.uint8)
    aff = affine_of()
    aff[0, 0] = -SPACING[0]  # x decreases with i, as in radiological (LAS) storage
    path = nifti(tmp_path, "flip.nii", data, aff)
    with pytest.warns(OrientationWarning, match=r"flip\.nii: axis x.*flipped"):
        back = read(path)
    expected_origin = (ORIGIN[0] - (SHAPE[0] - 1) * SPACING[0], ORIGIN[1], ORIGIN[2])
    assert_same(back, data[::-1], origin=expected_origin)
    # Every voxel keeps its world position: file voxel (i, j, k) is at aff @ (i, j, k, 1).
    i, j, k = 1, 2, 3
    world = (aff @ [i, j, k, 1])[:3]
    idx = np.rint(back.world_to_index(world)).astype(int)
    assert back.data[tuple(idx)] == data[i, j, k]
    assert is_memmap(back.data)


def test_nifti_oblique(tmp_path: Path) -> None:
    c, s = np.cos(0.3), np.sin(0.3)
    aff = affine_of()
    aff[:3, :3] = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ np.diag(SPACING)
    path = nifti(tmp_path, "tilt.nii.gz", ramp(np.float32), aff)
    with pytest.warns(OrientationWarning, match=r"tilt\.nii\.gz: oblique.*rotation is ignored"):
        back = read(path)
    assert_same(back, ramp(np.float32))


def test_nifti_scaling_is_applied(tmp_path: Path) -> None:
    data = ramp(np.int16)
    path = nifti(tmp_path, "s.nii", data, affine_of(), scl_slope=0.5, scl_inter=-10.0)
    back = read(path)
    assert back.dtype == np.float32
    np.testing.assert_allclose(back.data, data * 0.5 - 10.0)


def test_nifti_4d(tmp_path: Path) -> None:
    single = nifti(tmp_path, "one.nii", ramp(np.uint8)[..., None], affine_of())
    assert_same(read(single), ramp(np.uint8))
    many = nifti(tmp_path, "many.nii", np.stack([ramp(np.uint8)] * 3, axis=-1), affine_of())
    with pytest.warns(SeveralVolumesWarning, match=r"many\.nii: holds 3 time points"):
        assert_same(read(many), ramp(np.uint8))
    six = nifti(tmp_path, "six.nii", np.zeros((2, 2, 2, 1, 1, 2), np.uint8), affine_of())
    with pytest.raises(ReadError, match=r"six\.nii: a 6D image .*beyond the 5th"):
        read(six)


def test_nifti_real_mri() -> None:
    pytest.importorskip("nibabel")
    if not MNI.is_file():
        pytest.skip(f"the MNI152 sample is not present at {MNI}")
    vol = read(MNI)
    assert vol.shape == (197, 233, 189)
    assert vol.dtype == np.uint8
    np.testing.assert_allclose(vol.spacing, (1.0, 1.0, 1.0))
    assert vol.metadata["name"] == "mni152_t1_1mm.nii.gz"
    assert vol.value_range[1] > 0


# --------------------------------------------------------------------------- DICOM
def write_dicom_series(
    folder: Path,
    data: np.ndarray,
    *,
    spacing=(0.7, 0.8, 2.5),
    origin=(-50.0, -60.0, 10.0),
    slope: float = 1.0,
    intercept: float = 0.0,
    series_uid: str | None = None,
    z_positions: list[float] | None = None,
    orientation: tuple[float, ...] = (1, 0, 0, 0, 1, 0),
    seed: int = 0,
    tags: dict | None = None,
    prefix: str = "IM",
) -> None:
    """One file per slice (data[:, :, k]), shuffled, under meaningless names.

    ``z_positions`` are the slice offsets from ``origin`` along the slice normal; ``tags`` are
    set on every slice; ``prefix`` starts the file names.
    """
    pydicom = pytest.importorskip("pydicom")
    from pydicom.dataset import Dataset, FileMetaDataset
    from pydicom.uid import CTImageStorage, ExplicitVRLittleEndian, generate_uid

    folder.mkdir(exist_ok=True)
    series_uid = series_uid or generate_uid()
    nx, ny, nz = data.shape
    offsets = z_positions or [k * spacing[2] for k in range(nz)]
    normal = np.cross(orientation[:3], orientation[3:])
    order = np.random.default_rng(seed).permutation(nz)
    for n, k in enumerate(order):
        meta = FileMetaDataset()
        meta.MediaStorageSOPClassUID = CTImageStorage
        meta.MediaStorageSOPInstanceUID = generate_uid()
        meta.TransferSyntaxUID = ExplicitVRLittleEndian
        ds = Dataset()
        ds.file_meta = meta
        ds.SOPClassUID = CTImageStorage
        ds.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
        ds.SeriesInstanceUID = series_uid
        ds.Modality = "CT"
        ds.Rows, ds.Columns = ny, nx
        ds.SamplesPerPixel = 1
        ds.PhotometricInterpretation = "MONOCHROME2"
        ds.BitsAllocated = ds.BitsStored = 16
        ds.HighBit = 15
        ds.PixelRepresentation = 1 if data.dtype.kind == "i" else 0
        ds.PixelSpacing = [spacing[1], spacing[0]]  # (between rows, between columns)
        ds.ImageOrientationPatient = list(orientation)
        ds.ImagePositionPatient = list(np.asarray(origin) + offsets[k] * normal)
        ds.RescaleSlope = slope
        ds.RescaleIntercept = intercept
        ds.InstanceNumber = int(n)
        for keyword, value in (tags or {}).items():
            setattr(ds, keyword, value)
        rows_cols = np.ascontiguousarray(data[:, :, k].T)  # DICOM pixels are (y, x)
        ds.PixelData = rows_cols.astype(data.dtype.newbyteorder("<")).tobytes()
        ds.save_as(folder / f"{prefix}{n:04d}", enforce_file_format=True)
    assert pydicom  # imported for the skip


def test_dicom_series_with_rescale(tmp_path: Path) -> None:
    raw = ramp(np.uint16, (6, 5, 4)) * 10
    write_dicom_series(tmp_path / "ct", raw, intercept=-1024.0)
    (tmp_path / "ct" / "README.txt").write_text("not a slice")
    vol = read(tmp_path / "ct")
    assert vol.dtype == np.int16
    assert_same(vol, raw.astype(np.int16) - 1024, spacing=(0.7, 0.8, 2.5), origin=(-50, -60, 10))
    assert vol.metadata["name"] == "ct"
    assert vol.metadata["slices"] == 4


def test_dicom_series_fractional_slope(tmp_path: Path) -> None:
    raw = ramp(np.int16, (6, 5, 4))
    write_dicom_series(tmp_path / "pet", raw, slope=0.25, intercept=1.5)
    vol = read(tmp_path / "pet")
    assert vol.dtype == np.float32
    np.testing.assert_allclose(vol.data, raw * 0.25 + 1.5)


def test_dicom_single_file_reads_its_series(tmp_path: Path) -> None:
    raw = ramp(np.int16, (6, 5, 4))
    write_dicom_series(tmp_path / "s", raw)
    vol = read(tmp_path / "s" / "IM0002")
    np.testing.assert_array_equal(vol.data, raw)
    assert vol.metadata["name"] == "IM0002"


def test_dicom_coronal_series_is_put_in_world_order(tmp_path: Path) -> None:
    raw = ramp(np.int16, (6, 5, 4))
    spacing, origin = (0.7, 0.8, 2.5), np.array([-50.0, -60.0, 10.0])
    row, col = np.array([1.0, 0, 0]), np.array([0, 0, -1.0])
    write_dicom_series(tmp_path / "cor", raw, spacing=spacing, origin=tuple(origin),
                       orientation=(*row, *col))
    with pytest.warns(OrientationWarning, match="cor"):
        vol = read(tmp_path / "cor")
    assert vol.shape == (6, 4, 5)
    np.testing.assert_allclose(vol.spacing, (0.7, 2.5, 0.8))
    for ijk in [(0, 0, 0), (5, 4, 3), (2, 1, 3)]:
        i, j, k = ijk
        world = origin + i * spacing[0] * row + j * spacing[1] * col + k * spacing[2] * np.cross(
            row, col
        )
        idx = np.rint(vol.world_to_index(world)).astype(int)
        assert vol.data[tuple(idx)] == raw[ijk]


def test_dicom_uneven_slices_warn(tmp_path: Path) -> None:
    write_dicom_series(tmp_path / "u", ramp(np.int16, (4, 4, 4)), z_positions=[0, 2, 4, 7])
    with pytest.warns(UserWarning, match="uneven slice spacing"):
        vol = read(tmp_path / "u")
    assert vol.spacing[2] == pytest.approx(2.0)


def test_dicom_duplicate_positions(tmp_path: Path) -> None:
    write_dicom_series(tmp_path / "d", ramp(np.int16, (4, 4, 3)), z_positions=[0, 2, 2])
    with pytest.raises(ReadError, match=r"folder .*d: .*duplicate slice"):
        read(tmp_path / "d")


@pytest.mark.parametrize("tag", ["TemporalPositionIdentifier", "TriggerTime",
                                 "AcquisitionNumber"])
def test_dicom_time_series_reads_one_time_point(tmp_path: Path, tag: str) -> None:
    """Three time points of one series in one folder (the positions repeat), told apart by
    ``tag``: each reads as the volume written for it, in time order; out of range is one line."""
    from pydicom.uid import generate_uid

    series = generate_uid()
    frames = [ramp(np.int16, (6, 5, 4)) + 100 * t for t in range(3)]
    values = {"TemporalPositionIdentifier": [1, 2, 3], "TriggerTime": [0.0, 350.5, 701.0],
              "AcquisitionNumber": [7, 8, 9]}[tag]
    for t in (2, 0, 1):  # written out of time order
        write_dicom_series(tmp_path / "dyn", frames[t], series_uid=series, seed=t,
                           tags={tag: values[t]}, prefix=f"T{t}_")
    for t in range(3):
        vol = read(tmp_path / "dyn", timepoint=t)
        assert_same(vol, frames[t], spacing=(0.7, 0.8, 2.5), origin=(-50, -60, 10))
        assert vol.metadata["timepoints"] == 3 and vol.metadata["timepoint"] == t
        assert vol.metadata["slices"] == 4
    one = read(tmp_path / "dyn" / "T1_0002", timepoint=1)  # a file of the series
    np.testing.assert_array_equal(one.data, frames[1])
    with pytest.warns(SeveralVolumesWarning, match="3 time points"):
        np.testing.assert_array_equal(read(tmp_path / "dyn").data, frames[0])
    with pytest.raises(ParameterError, match=r"dyn.*timepoint 3 is out of range"):
        read(tmp_path / "dyn", timepoint=3)


def test_dicom_repeated_positions_without_a_time_tag_stay_duplicates(tmp_path: Path) -> None:
    from pydicom.uid import generate_uid

    series = generate_uid()
    for t in range(2):
        write_dicom_series(tmp_path / "rep", ramp(np.int16, (4, 4, 3)), series_uid=series,
                           prefix=f"R{t}_")
    with pytest.raises(ReadError, match="duplicate slice"):
        read(tmp_path / "rep")


def test_dicom_folder_without_slices(tmp_path: Path) -> None:
    pytest.importorskip("pydicom")
    folder = tmp_path / "empty_study"
    folder.mkdir()
    (folder / "notes.txt").write_text("nothing here")
    (folder / "image.dcm").write_bytes(b"\0" * 200)
    with pytest.raises(ReadError, match=r"folder .*empty_study contains no readable DICOM slices"):
        read(folder)


def test_dicom_mixed_series(tmp_path: Path) -> None:
    write_dicom_series(tmp_path / "mixed", ramp(np.int16, (4, 4, 3)), seed=1)
    write_dicom_series(tmp_path / "other", ramp(np.int16, (4, 4, 3)), seed=2)
    for n, f in enumerate(sorted((tmp_path / "other").iterdir())):
        f.rename(tmp_path / "mixed" / f"B{n}")
    with pytest.raises(ReadError, match=r"folder .*mixed mixes 2 DICOM series"):
        read(tmp_path / "mixed")


def test_dicom_mixed_sizes(tmp_path: Path) -> None:
    uid = "1.2.3.4.5"
    write_dicom_series(tmp_path / "sizes", ramp(np.int16, (4, 4, 2)), series_uid=uid)
    write_dicom_series(tmp_path / "b", ramp(np.int16, (5, 4, 1)), series_uid=uid,
                       z_positions=[30.0])
    (tmp_path / "b" / "IM0000").rename(tmp_path / "sizes" / "extra")
    with pytest.raises(ReadError, match=r"folder .*sizes: slices differ in Rows/Columns"):
        read(tmp_path / "sizes")


# --------------------------------------------------------------------------- TIFF
def test_tiff_stack_with_imagej_spacing(tmp_path: Path) -> None:
    tifffile = pytest.importorskip("tifffile")
    data = ramp(np.uint16)
    path = tmp_path / "stack.tif"
    tifffile.imwrite(
        path, np.ascontiguousarray(data.transpose(2, 1, 0)), imagej=True,
        resolution=(1 / SPACING[0], 1 / SPACING[1]),
        metadata={"axes": "ZYX", "spacing": SPACING[2], "unit": "um"},
    )
    vol = read(path)
    assert_same(vol, data, origin=(0, 0, 0))
    assert vol.metadata["units"] == "um"


def test_tiff_plain_multipage(tmp_path: Path) -> None:
    tifffile = pytest.importorskip("tifffile")
    data = ramp(np.float32)
    tifffile.imwrite(tmp_path / "plain.tiff", np.ascontiguousarray(data.transpose(2, 1, 0)))
    assert_same(read(tmp_path / "plain.tiff"), data, spacing=(1, 1, 1), origin=(0, 0, 0))


def test_tiff_2d_is_refused(tmp_path: Path) -> None:
    tifffile = pytest.importorskip("tifffile")
    tifffile.imwrite(tmp_path / "flat.tif", np.zeros((4, 5), np.uint8))
    with pytest.raises(ReadError, match=r"flat\.tif: a single 2D image"):
        read(tmp_path / "flat.tif")


# --------------------------------------------------------------------------- writers
def test_write_unknown_extension(tmp_path: Path) -> None:
    with pytest.raises(ParameterError, match=r"v\.png: cannot write"):
        write(make_volume(), tmp_path / "v.png")
    assert files_in(tmp_path) == []


@pytest.mark.parametrize("ext", [".npy", ".npz", ".mhd", ".raw", ".nrrd"])
def test_writer_into_missing_folder(tmp_path: Path, ext: str) -> None:
    with pytest.raises(ParameterError, match="does not exist"):
        write(Volume(ramp()), tmp_path / "nowhere" / f"v{ext}")
    assert files_in(tmp_path) == []


@pytest.mark.parametrize("ext", [".npy", ".npz", ".mhd", ".raw", ".nrrd"])
def test_writer_refuses_unsupported_dtype(tmp_path: Path, ext: str) -> None:
    vol = Volume(ramp())
    vol.data = vol.data.astype(np.float16)  # slipped past the constructor's check
    with pytest.raises(ParameterError, match=rf"v\{ext}: cannot write float16"):
        write(vol, tmp_path / f"v{ext}")
    assert files_in(tmp_path) == []


def test_writer_failure_midway_leaves_nothing(tmp_path: Path, monkeypatch) -> None:
    from splinecast.io import metaimage

    def broken(path: Path, text: str) -> None:
        Path(path).write_text(text[:10])
        raise RuntimeError("disk on fire")

    monkeypatch.setattr(metaimage, "_write_header", broken)
    with pytest.raises(RuntimeError, match="disk on fire"):
        write(make_volume(), tmp_path / "v.mhd")
    assert files_in(tmp_path) == []


def test_writer_replaces_existing_file(tmp_path: Path) -> None:
    write(Volume(ramp()), tmp_path / "v.npz")
    write(Volume(ramp(np.float32)), tmp_path / "v.npz")
    assert read(tmp_path / "v.npz").dtype == np.float32
    assert files_in(tmp_path) == ["v.npz"]


def test_missing_optional_library(tmp_path: Path, monkeypatch) -> None:
    np.save(tmp_path / "x.npy", ramp())
    (tmp_path / "x.nrrd").write_bytes(b"NRRD0004\ntype: uchar\n\n")
    monkeypatch.setitem(sys.modules, "nrrd", None)  # makes `import nrrd` fail
    hint = r"reading x\.nrrd needs pynrrd: pip install 'splinecast\[io\]'"
    with pytest.raises(ReadError, match=hint):
        read(tmp_path / "x.nrrd")
    with pytest.raises(ParameterError, match=r"writing y\.nrrd needs pynrrd"):
        write(Volume(ramp()), tmp_path / "y.nrrd")


# --------------------------------------------------------------------------- orientation
@pytest.mark.parametrize(
    "matrix",
    [
        np.diag([0.5, -0.75, 2.0]),
        # index axis 0 -> world y, 1 -> world -z, 2 -> world x (a coronal-like layout)
        np.array([[0.0, 0.0, 2.0], [0.5, 0.0, 0.0], [0.0, -0.75, 0.0]]),
    ],
    ids=["flip", "permute"],
)
def test_align_to_world_keeps_every_voxel_in_place(matrix: np.ndarray) -> None:
    from splinecast.io.orientation import align_to_world

    data = ramp(np.int32)
    origin = np.array(ORIGIN)
    with pytest.warns(OrientationWarning, match="file.x"):
        out, spacing, new_origin = align_to_world(data, matrix, origin, "file.x")
    vol = Volume(out, spacing=spacing, origin=new_origin)
    assert np.shares_memory(out, data)  # views only
    for ijk in np.ndindex(*data.shape):
        world = origin + matrix @ np.array(ijk)
        idx = vol.world_to_index(world)
        np.testing.assert_allclose(idx, np.rint(idx), atol=1e-9)
        assert vol.data[tuple(np.rint(idx).astype(int))] == data[ijk]


def test_nifti_pair_img_file(tmp_path: Path) -> None:
    nib = pytest.importorskip("nibabel")
    img = nib.Nifti1Pair(ramp(np.int16), affine_of())
    nib.save(img, tmp_path / "pair.img")
    assert files_in(tmp_path) == ["pair.hdr", "pair.img"]
    for name in ("pair.hdr", "pair.img"):
        assert_same(read(tmp_path / name), ramp(np.int16))
