"""Issue 17, class by class: hostile files and options give one clean error, never a crash, a hang,
an exhausted memory, a traceback, noise before the error, or a read outside the data's folder.

Each test builds the hostile input the issue describes and checks the exact outcome (the error
class, the file or option named, and what must not have happened).
"""

from __future__ import annotations

import bz2
import gzip
import json
import logging
import struct
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import splinecast as sc
from splinecast.cli import main
from splinecast.errors import DataError, ParameterError, ReadError, limits

SHAPE = (6, 5, 4)
RAW = (np.arange(np.prod(SHAPE)) % 97).astype("<u2").reshape(SHAPE, order="F")


def raw_bytes() -> bytes:
    return RAW.tobytes(order="F")


def mhd(folder: Path, **fields: str) -> Path:
    """A MetaImage header (with ``v.raw`` beside it) whose fields can be overridden."""
    base = {"ObjectType": "Image", "NDims": "3", "DimSize": "6 5 4",
            "ElementSpacing": "0.5 0.5 2", "ElementType": "MET_USHORT",
            "ElementDataFile": "v.raw"}
    base.update(fields)
    data_file = base.pop("ElementDataFile")
    text = "".join(f"{k} = {v}\n" for k, v in base.items()) + f"ElementDataFile = {data_file}\n"
    (folder / "v.raw").write_bytes(raw_bytes())
    path = folder / "v.mhd"
    path.write_text(text)
    return path


def sidecar(folder: Path, **fields: object) -> Path:
    spec = {"shape": list(SHAPE), "dtype": "uint16", "spacing": [0.5, 0.5, 2.0]}
    spec.update(fields)
    (folder / "v.raw").write_bytes(raw_bytes())
    path = folder / "v.json"
    path.write_text(json.dumps(spec))
    return path


def nrrd_text(fields: dict[str, str]) -> str:
    base = {"type": "unsigned short", "dimension": "3", "sizes": "6 5 4", "endian": "little",
            "encoding": "raw", "spacings": "0.5 0.5 2"}
    base.update(fields)
    return "NRRD0004\n" + "".join(f"{k}: {v}\n" for k, v in base.items() if v is not None)


def cli(args: list[str], capsys: pytest.CaptureFixture) -> tuple[int, str, str]:
    """Run the command line as ``splinecast`` would (argparse errors exit with status 2)."""
    try:
        code = main(args)
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def one_error_line(err: str, *needles: str) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("splinecast: error: "), err
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    return lines[0]


# --------------------------------------------------------------------------- process crash
def test_subnormal_spacing_in_metaimage_is_refused_before_rendering(tmp_path):
    with pytest.raises(ReadError, match=r"v\.mhd: voxel spacing must be three numbers between"):
        sc.read(mhd(tmp_path, ElementSpacing="1e-320 1 1"))


def test_subnormal_spacing_in_a_sidecar_is_refused(tmp_path):
    with pytest.raises(ReadError, match=r"v\.json: voxel spacing"):
        sc.read(sidecar(tmp_path, spacing=[1, 1e-320, 1]))


def test_volume_refuses_subnormal_and_absurd_spacing():
    for spacing in (1e-320, 5e-324, 1e-300, 1e300):
        with pytest.raises(ParameterError, match="spacing"):
            sc.Volume(RAW, spacing=spacing)


# --------------------------------------------------------------------------- unhandled exceptions
@pytest.mark.parametrize(("encoding", "body"), [
    ("gzip", gzip.compress(raw_bytes())[:-12]),              # truncated stream
    ("gzip", b"\x1f\x8b\x08\x00garbage-not-deflate"),        # corrupt stream
    ("bzip2", b"BZh9" + b"\x00" * 40),                        # corrupt bzip2
    ("gzip", bz2.compress(raw_bytes())),                      # the wrong compressor
])
def test_corrupt_compressed_nrrd_is_a_read_error(tmp_path, encoding, body):
    path = tmp_path / "v.nrrd"
    path.write_bytes(nrrd_text({"encoding": encoding}).encode() + b"\n" + body)
    with pytest.raises(ReadError, match=r"v\.nrrd: (corrupt|compressed data ends)"):
        sc.read(path)


@pytest.mark.parametrize("encoding", ["lzma", "zrl", "hex", "bogus"])
def test_unknown_nrrd_encoding_is_a_read_error(tmp_path, encoding):
    path = tmp_path / "v.nrrd"
    path.write_bytes(nrrd_text({"encoding": encoding}).encode() + b"\n" + raw_bytes())
    with pytest.raises(ReadError, match=r"v\.nrrd: (NRRD encoding .* is not supported|bad NRRD)"):
        sc.read(path)


def test_unknown_npz_compression_is_a_read_error(tmp_path):
    path = tmp_path / "v.npz"
    np.savez_compressed(path, data=RAW)
    data = bytearray(path.read_bytes())
    # Compression method 99 (AES) in the local and central headers: zipfile cannot decode it.
    for offset in (8, data.rfind(b"PK\x01\x02") + 10):
        data[offset:offset + 2] = struct.pack("<H", 99)
    path.write_bytes(bytes(data))
    with pytest.raises(ReadError, match=r"v\.npz"):
        sc.read(path)


@pytest.mark.parametrize("method", [zipfile.ZIP_DEFLATED, zipfile.ZIP_BZIP2, zipfile.ZIP_LZMA])
def test_corrupt_npz_streams_are_a_read_error(tmp_path, method):
    path = tmp_path / "v.npz"
    from io import BytesIO

    buf = BytesIO()
    np.save(buf, RAW.astype(np.float32) * 1.5)
    with zipfile.ZipFile(path, "w", compression=method) as zf:
        zf.writestr("data.npy", buf.getvalue())
    data = bytearray(path.read_bytes())
    start = data.find(b"data.npy") + len("data.npy") + 20  # inside the compressed bytes
    for i in range(start, start + 16):
        data[i] ^= 0x5A
    path.write_bytes(bytes(data))
    with pytest.raises(ReadError, match=r"v\.npz"):
        sc.read(path)


@pytest.mark.parametrize(("header", "what"), [
    ("{'descr': '<u2', 'fortran_order': False, 'shape': (6, 5, 4", "header"),
    ("{'descr': '<u2', 'fortran_order': False, 'shape': (-6, 5, 4), }", "shape"),
    ("{'descr': '<u2', 'fortran_order': False, 'shape': (1180591620717411303424, 1, 1), }",
     "1180591620717411303424"),
    ("{'descr': '|O', 'fortran_order': False, 'shape': (6, 5, 4), }", "object"),
    ("{'descr': '<u2', 'fortran_order': False, 'shape': (2000, 2000, 2000), }", "truncated"),
])
def test_malformed_npy_headers(tmp_path, header, what):
    body = header.encode()
    pad = (-(10 + len(body) + 1)) % 64
    path = tmp_path / "v.npy"
    path.write_bytes(b"\x93NUMPY\x01\x00" + struct.pack("<H", len(body) + pad + 1) + body
                     + b" " * pad + b"\n" + raw_bytes())
    with pytest.raises(ReadError, match=r"v\.npy") as info:
        sc.read(path)
    assert what in str(info.value)


@pytest.mark.parametrize("dims", ["1e30 5 4", "inf 5 4", "nan 5 4", "1180591620717411303424 5 4",
                                  "6 0 4", "6 -5 4", "6.5 5 4"])
def test_absurd_metaimage_sizes(tmp_path, dims):
    with pytest.raises(ReadError, match=r"v\.mhd: DimSize must be 3 integers between 1 and"):
        sc.read(mhd(tmp_path, DimSize=dims))


@pytest.mark.parametrize("shape", [[1e30, 5, 4], [2**70, 5, 4], [6, 0, 4], ["6", 5, 4],
                                   [6, 5], [True, 5, 4]])
def test_absurd_sidecar_sizes(tmp_path, shape):
    with pytest.raises(ReadError, match=r"v\.json: 'shape'"):
        sc.read(sidecar(tmp_path, shape=shape))


def test_sidecar_with_infinite_and_nan_numbers(tmp_path):
    path = sidecar(tmp_path)
    path.write_text(path.read_text().replace("0.5", "Infinity", 1))
    with pytest.raises(ReadError, match=r"v\.json: not valid JSON"):
        sc.read(path)


def test_nul_byte_in_a_data_file_name(tmp_path):
    with pytest.raises(ReadError, match=r"ElementDataFile: the path .* contains a NUL byte"):
        sc.read(mhd(tmp_path, ElementDataFile="v.raw\0.png"))
    with pytest.raises(ReadError, match="NUL"):
        sc.read(sidecar(tmp_path, data_file="v.raw\0x"))


@pytest.mark.parametrize("dtype", ["(2,)<u2", "f4,f4", "|O", "S1000000000000", "((((", "<c16",
                                   "M8[s]", "bogus", "V8"])
def test_absurd_sidecar_dtypes(tmp_path, dtype):
    with pytest.raises(ReadError, match=r"v\.json: 'dtype'"):
        sc.read(sidecar(tmp_path, dtype=dtype))


def test_deeply_nested_and_huge_number_sidecars(tmp_path):
    path = sidecar(tmp_path)
    path.write_text('{"shape": ' + "[" * 50000 + "]" * 50000 + ', "dtype": "uint16"}')
    with pytest.raises(ReadError, match="nested"):
        sc.read(path)
    path.write_text('{"shape": [6, 5, ' + "4" * 5000 + '], "dtype": "uint16"}')
    with pytest.raises(ReadError, match="not valid JSON"):
        sc.read(path)


def _nifti(tmp_path: Path, **header: object) -> Path:
    nib = pytest.importorskip("nibabel")
    img = nib.Nifti1Image(RAW.astype(np.int16), np.diag([0.5, 0.5, 2.0, 1.0]))
    path = tmp_path / "v.nii"
    nib.save(img, path)
    data = bytearray(path.read_bytes())
    offsets = {"xyzt_units": (123, "B"), "dim2": (44, "h"), "dim1": (42, "h")}
    for name, value in header.items():
        offset, fmt = offsets[name]
        data[offset:offset + struct.calcsize(fmt)] = struct.pack("<" + fmt, value)
    path.write_bytes(bytes(data))
    return path


def test_nifti_unknown_unit_code_is_read_without_units(tmp_path):
    vol = sc.read(_nifti(tmp_path, xyzt_units=0x3F))
    assert "units" not in vol.metadata
    np.testing.assert_array_equal(vol.data, RAW.astype(np.int16))


def test_nifti_zero_dimension(tmp_path):
    with pytest.raises(ReadError, match=r"v\.nii: (dim must be|not a readable)"):
        sc.read(_nifti(tmp_path, dim2=0))


def _dicom_series(folder: Path, change=None, index: int = 1) -> Path:
    """Four slices from the fuzzing seeds' writer; ``change(ds)`` edits slice ``index``."""
    pytest.importorskip("pydicom")
    from fuzz.seeds import dicom_slice

    folder.mkdir(exist_ok=True)
    for k in range(4):
        ds = dicom_slice(RAW[:, :, k], (0.0, 0.0, 2.0 * k), "1.2.3.4", k)
        if change is not None and k == index:
            change(ds)
        ds.save_as(folder / f"IM{k}", enforce_file_format=True)
    return folder


def _raw_tag(keyword: str, vr: str, value: bytes):
    def change(ds):
        import pydicom

        tag = pydicom.tag.Tag(pydicom.datadict.tag_for_keyword(keyword))
        value_even = value + (b" " if len(value) % 2 else b"")
        ds._dict[tag] = pydicom.dataelem.RawDataElement(tag, vr, len(value_even), value_even, 0,
                                                        False, True)
    return change


@pytest.mark.parametrize(("keyword", "vr", "value"), [
    ("PixelSpacing", "DS", b"abc\\1"), ("PixelSpacing", "DS", b"0.5"),
    ("ImagePositionPatient", "DS", b"abc\\0\\2"), ("ImagePositionPatient", "DS", b"0\\0"),
    ("RescaleSlope", "DS", b"abc"), ("RescaleSlope", "DS", b"inf"),
    ("RescaleIntercept", "DS", b"nan"), ("RescaleIntercept", "DS", b"1\\2"),
    ("ImageOrientationPatient", "DS", b"1\\0\\0\\1\\0\\0"),
    ("NumberOfFrames", "IS", b"2"), ("SliceThickness", "DS", b"x"),
])
def test_dicom_hostile_tags(tmp_path, keyword, vr, value):
    folder = _dicom_series(tmp_path / "s", _raw_tag(keyword, vr, value))
    if keyword == "SliceThickness":  # used only for a single slice
        for extra in sorted(folder.iterdir())[:1] + sorted(folder.iterdir())[2:]:
            extra.unlink()
    with pytest.raises(ReadError, match=r"folder .*s"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # pydicom's own complaints about the values
            sc.read(folder)


def test_dicom_slice_without_rows(tmp_path):
    folder = _dicom_series(tmp_path / "s", lambda ds: delattr(ds, "Rows"))
    with pytest.raises(ReadError, match="IM1 has no Rows or Columns"):
        sc.read(folder)


def test_dicom_rgb_slice_among_greyscale(tmp_path):
    def rgb(ds):
        ds.SamplesPerPixel = 3
        ds.PhotometricInterpretation = "RGB"
        ds.PlanarConfiguration = 0

    folder = _dicom_series(tmp_path / "s", rgb, index=2)
    with pytest.raises(ReadError, match="IM2 is a colour image"):
        sc.read(folder)


def test_dicom_unknown_vr(tmp_path):
    folder = _dicom_series(tmp_path / "s")
    target = folder / "IM1"
    data = bytearray(target.read_bytes())
    where = data.find(b"\x28\x00\x30\x00DS")  # (0028,0030) PixelSpacing, explicit VR
    data[where + 4:where + 6] = b"ZZ"
    target.write_bytes(bytes(data))
    with pytest.raises(ReadError, match=r"slice IM1: cannot read PixelSpacing \(Unknown Value "
                                        r"Representation 'ZZ'"):
        sc.read(folder)


def test_tiff_imagej_spacing_that_is_not_a_number(tmp_path):
    tifffile = pytest.importorskip("tifffile")
    path = tmp_path / "v.tif"
    tifffile.imwrite(path, np.ascontiguousarray(RAW.transpose(2, 1, 0)), metadata=None,
                     photometric="minisblack",
                     description="ImageJ=1.11a\nimages=4\nslices=4\nspacing=abc\n")
    with pytest.raises(ReadError, match=r"v\.tif: ImageJ spacing must be a number"):
        sc.read(path)


def test_npz_without_an_array(tmp_path):
    path = tmp_path / "v.npz"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("notes.txt", "hello")
    with pytest.raises(ReadError, match=r"v\.npz: cannot tell which array .* no \.npy array"):
        sc.read(path)
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("data.npy", b"not an npy file")
    with pytest.raises(ReadError, match=r"v\.npz \[data\.npy\]: not a readable \.npy header"):
        sc.read(path)


@pytest.mark.parametrize(("args", "needle"), [
    (["--fov", "0"], "--fov"), (["--fov", "inf"], "--fov"), (["--fov", "nan"], "--fov"),
    (["--fov", "180"], "--fov"), (["--zoom", "inf"], "--zoom"), (["--zoom", "0"], "--zoom"),
    (["--distance", "-1"], "--distance"), (["--azimuth", "nan"], "--azimuth"),
    (["--iterations", "1000000000", "--model", "bspline1"], "--iterations"),
    (["--texture", "noise", "--texture-scale", "0"], "--texture-scale"),
    (["--termination", "2", "--mode", "dvr"], "--termination"),
    (["--clip", "nan,0,0,0"], "--clip"), (["--window", "nan,1", "--mode", "mip"], "--window"),
    (["--size", "9" * 5000 + "x1"], "--size"),
])
def test_cli_options_at_their_edges(tmp_path, capsys, args, needle):
    iso = [] if "--mode" in args else ["--iso", "0"]  # other modes refuse --iso
    code, out, err = cli(["render", "demo:sphere?size=10", *iso, "-o",
                          str(tmp_path / "o.png"), *args], capsys)
    assert code == 2 and out == ""
    one_error_line(err, needle)
    assert list(tmp_path.iterdir()) == []


def test_cli_over_long_paths(tmp_path, capsys):
    long_name = "x" * 5000
    code, _, err = cli(["render", long_name, "--iso", "0", "-o", str(tmp_path / "o.png")], capsys)
    assert code == 2
    one_error_line(err, "too long")
    code, _, err = cli(["render", "demo:sphere?size=10", "--iso", "0", "-o",
                        str(tmp_path / (long_name + ".png"))], capsys)
    assert code == 2
    one_error_line(err, "-o", "too long")
    code, _, err = cli(["info", str(tmp_path / ("a/" * 3000))], capsys)
    assert code == 2
    one_error_line(err, "too long")


def test_cli_nested_and_endless_transfer_functions(tmp_path, capsys):
    tf = tmp_path / "tf.json"
    tf.write_text("[" * 100000 + "]" * 100000)
    for source in (str(tf), "/dev/zero"):
        code, _, err = cli(["render", "demo:sphere?size=10", "--mode", "dvr", "--tf", source,
                            "-o", str(tmp_path / "o.png")], capsys)
        assert code == 2
        one_error_line(err, source)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tf.json"]


@pytest.mark.parametrize(("uri", "needle"), [
    ("demo:noise?seed=-1", "seed"), ("demo:noise?seed=1e30", "seed"),
    ("demo:sphere?size=1e400", "size"), ("demo:sphere?size=" + "9" * 5000, "size"),
])
def test_cli_bad_demo_parameters(tmp_path, capsys, uri, needle):
    code, _, err = cli(["info", uri], capsys)
    assert code == 2
    one_error_line(err, needle)


# --------------------------------------------------------------------------- memory
def test_npz_member_claiming_2000_cubed_is_refused_before_allocation(tmp_path, monkeypatch):
    header = b"{'descr': '<f4', 'fortran_order': False, 'shape': (2000, 2000, 2000), }"
    pad = (-(10 + len(header) + 1)) % 64
    npy = b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header) + pad + 1) + header \
        + b" " * pad + b"\n" + bytes(1000)
    path = tmp_path / "v.npz"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("data.npy", npy)
    with pytest.raises(ReadError, match=r"expected 32000000000 bytes .* holds 1128"):
        sc.read(path)
    monkeypatch.setenv(limits.ENV_MAX_BYTES, "1MiB")  # a member that is as long as it claims
    big = np.zeros((100, 100, 100), np.float32)
    np.savez_compressed(path, data=big)
    with pytest.raises(ReadError, match=r"needs 3.8 MiB, more than the cap"):
        sc.read(path)


def test_detached_nrrd_naming_dev_zero_is_refused(tmp_path):
    path = tmp_path / "v.nhdr"
    path.write_text(nrrd_text({"encoding": "gzip", "data file": "/dev/zero"}))
    with pytest.raises(ReadError, match="outside the header's folder"):
        sc.read(path)
    with pytest.raises(ReadError, match="/dev/zero: not a regular file"):
        sc.read(path, allow_external=True)


def test_gzip_bomb_in_the_folder_is_stopped_at_the_expected_size(tmp_path):
    (tmp_path / "v.raw.gz").write_bytes(gzip.compress(bytes(200_000_000)))  # 200 MB of zeros
    path = tmp_path / "v.nhdr"
    path.write_text(nrrd_text({"encoding": "gzip", "data file": "v.raw.gz"}))
    with pytest.raises(ReadError, match="holds more than the 240 bytes"):
        sc.read(path)


def test_cli_image_size_is_checked_against_memory(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv(limits.ENV_MAX_BYTES, "256MiB")
    code, _, err = cli(["render", "demo:sphere?size=10", "--iso", "0", "--size", "8000x8000",
                        "-o", str(tmp_path / "o.png")], capsys)
    assert code == 2
    one_error_line(err, "--size", "8000x8000 image needs 5.7 GiB", "SPLINECAST_MAX_BYTES")
    code, _, err = cli(["render", "demo:sphere?size=10", "--iso", "0", "--size", "1x64000000",
                        "-o", str(tmp_path / "o.png")], capsys)
    assert code == 2
    one_error_line(err, "--size", "image height must be an integer >= 1 and at most 32768")


def test_scene_render_checks_the_image_memory(monkeypatch):
    vol = sc.demo("sphere", size=10)
    scene = sc.Scene(vol)
    monkeypatch.setenv(limits.ENV_MAX_BYTES, "1MiB")
    cam = sc.Camera.orbit(vol, size=(200, 200))  # 200*200*96 bytes = 3.7 MiB
    with pytest.raises(ParameterError, match="camera size: a 200x200 image needs 3.7 MiB"):
        scene.render(cam, iso=0.0)


def test_demo_size_is_checked_against_memory(monkeypatch):
    monkeypatch.setenv(limits.ENV_MAX_BYTES, "1GiB")
    with pytest.raises(ParameterError, match=r"demo 'sphere': size: a 2000x2000x2000 float32 "
                                             r"volume needs 29.8 GiB"):
        sc.read("demo:sphere?size=2000")


def test_transfer_function_from_dev_zero():
    with pytest.raises(ReadError, match="/dev/zero: longer than 1.0 MiB"):
        sc.TransferFunction.load("/dev/zero")


def test_huge_nifti_dimensions_are_refused_before_decoding(tmp_path, monkeypatch):
    nib = pytest.importorskip("nibabel")
    path = tmp_path / "v.nii.gz"
    nib.save(nib.Nifti1Image(np.zeros((40, 40, 40), np.float32), np.eye(4)), path)
    monkeypatch.setenv(limits.ENV_MAX_BYTES, "100KiB")

    def no_decoding(*args, **kwargs):
        raise AssertionError("the voxels were decoded before the memory check")

    monkeypatch.setattr(nib.arrayproxy.ArrayProxy, "get_unscaled", no_decoding)
    with pytest.raises(ReadError, match=r"v\.nii\.gz: a 40x40x40 float32 array needs 250.0 KiB"):
        sc.read(path)


def test_huge_tiff_is_refused_before_decoding(tmp_path, monkeypatch):
    tifffile = pytest.importorskip("tifffile")
    path = tmp_path / "v.tif"
    tifffile.imwrite(path, np.zeros((40, 40, 40), np.uint16), compression="zlib")
    monkeypatch.setenv(limits.ENV_MAX_BYTES, "100KiB")

    def no_decoding(*args, **kwargs):
        raise AssertionError("the pixels were decoded before the memory check")

    monkeypatch.setattr(tifffile.TiffPageSeries, "asarray", no_decoding)
    with pytest.raises(ReadError, match=r"v\.tif: a 40x40x40 uint16 array needs 125.0 KiB"):
        sc.read(path)


# --------------------------------------------------------------------------- hangs
def test_sampled_step_has_a_lower_bound(tmp_path, capsys):
    code, _, err = cli(["render", "demo:sphere?size=10", "--iso", "0", "--method", "sampled",
                        "--step", "1e-300", "-o", str(tmp_path / "o.png")], capsys)
    assert code == 2
    one_error_line(err, "--step", ">= 0.001")
    vol = sc.demo("sphere", size=10)
    cam = sc.Camera.orbit(vol, size=(8, 8))
    with pytest.raises(ParameterError, match="step must be a finite number >= 0.001"):
        sc.Scene(vol).render(cam, iso=0.0, method="sampled", step=1e-300)


def test_dvr_step_has_a_lower_bound(tmp_path, capsys):
    tf = tmp_path / "tf.json"
    sc.TransferFunction([[0, 0], [1, 0.5]], (0, 1)).save(tf)
    code, _, err = cli(["render", "demo:sphere?size=10", "--mode", "dvr", "--tf", str(tf),
                        "--step", "1e-6", "-o", str(tmp_path / "o.png")], capsys)
    assert code == 2
    one_error_line(err, "--step")
    with pytest.raises(ParameterError, match="step"):
        sc.DVRSettings(step=1e-6)


def test_samples_per_ray_are_capped_for_the_volume(monkeypatch):
    vol = sc.Volume(np.zeros((2, 2, 2), np.float32))
    cam = sc.Camera.orbit(vol, size=(4, 4))
    monkeypatch.setattr(limits, "MAX_SAMPLES_PER_RAY", 100)  # diagonal 1.7 voxels / 0.01 = 173
    with pytest.raises(ParameterError, match="more than 100 samples per ray"):
        sc.Scene(vol).render(cam, mode="mip", method="sampled", step=0.01)


# --------------------------------------------------------------------------- outside the folder
def _sentinel(tmp_path: Path) -> Path:
    """A file outside the data folder that would read as valid voxels."""
    secret = tmp_path / "secret.raw"
    secret.write_bytes(raw_bytes())
    (tmp_path / "data").mkdir()
    return secret


@pytest.mark.parametrize("name", ["../secret.raw", "{abs}", "../../../../../../../etc/passwd",
                                  "/etc/passwd", "link.raw"])
def test_headers_cannot_name_files_outside_their_folder(tmp_path, name):
    secret = _sentinel(tmp_path)
    folder = tmp_path / "data"
    (folder / "link.raw").symlink_to(secret)
    name = name.replace("{abs}", str(secret))
    headers = [
        mhd(folder, ElementDataFile=name),
        sidecar(folder, data_file=name),
    ]
    nhdr = folder / "v.nhdr"
    nhdr.write_text(nrrd_text({"data file": name}))
    headers.append(nhdr)
    for header in headers:
        with pytest.raises(ReadError, match="lies outside the header's folder"):
            sc.read(header)


def test_outside_files_are_read_when_explicitly_allowed(tmp_path, monkeypatch, capsys):
    secret = _sentinel(tmp_path)
    header = mhd(tmp_path / "data", ElementDataFile="../secret.raw")
    vol = sc.read(header, allow_external=True)
    assert vol.metadata["data_file"] == str(tmp_path / "data" / "../secret.raw")
    np.testing.assert_array_equal(vol.data, RAW)
    code, out, _ = cli(["info", "--allow-external-data", str(header)], capsys)
    assert code == 0 and "6 x 5 x 4" in out
    monkeypatch.setenv(limits.ENV_ALLOW_EXTERNAL, "1")
    np.testing.assert_array_equal(sc.read(header).data, RAW)
    assert secret.exists()


def test_a_dicom_slice_linked_out_of_the_folder_is_refused(tmp_path):
    folder = _dicom_series(tmp_path / "s")
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    (folder / "IM3").rename(outside / "IM3")
    (folder / "IM3").symlink_to(outside / "IM3")
    with pytest.raises(ReadError, match="IM3: slice 'IM3' lies outside the series folder"):
        sc.read(folder)
    assert sc.read(folder, allow_external=True).shape == SHAPE


# --------------------------------------------------------------------------- non-finite data
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize("mode", ["iso", "multi-iso", "mip", "minip", "dvr"])
def test_non_finite_data_is_refused_in_every_mode(bad, mode):
    data = np.linspace(0, 1, 8 * 8 * 8, dtype=np.float32).reshape(8, 8, 8)
    data[3, 4, 5] = bad
    vol = sc.Volume(data)
    assert vol.value_range == (0.0, 1.0)  # the range of the finite values
    counts = {"nan": (1, 0, 0), "inf": (0, 1, 0), "-inf": (0, 0, 1)}[str(float(bad))]
    assert vol.nonfinite_counts() == counts
    kwargs = {"iso": {"mode": "iso", "iso": 0.5}, "multi-iso": {"mode": "iso", "iso": [0.3, 0.6]},
              "mip": {"mode": "mip"}, "minip": {"mode": "minip"},
              "dvr": {"mode": "dvr", "tf": sc.TransferFunction([[0, 0], [1, 1]], (0, 1))}}[mode]
    cam = sc.Camera.orbit(vol, size=(8, 8))
    wanted = "{} NaN, {} \\+inf and {} -inf values".format(*counts)
    with pytest.raises(DataError, match=wanted):
        sc.Scene(vol).render(cam, **kwargs)
    # Scene.render's own check, for a scene whose model was prepared from finite data.
    with pytest.raises(DataError, match=wanted):
        limits.check_render(vol, cam)


@pytest.mark.parametrize("model", list(sc.MODELS))
def test_every_model_refuses_infinite_data(model):
    data = np.zeros((6, 6, 6), np.float32)
    data[2, 2, 2] = np.inf
    with pytest.raises(DataError, match=r"1 \+inf"):
        sc.Scene(sc.Volume(data), model=model)


def test_info_reports_infinite_values(tmp_path, capsys):
    data = np.zeros((4, 4, 4), np.float32)
    data[0, 0, 0], data[1, 1, 1] = np.inf, -np.inf
    np.save(tmp_path / "v.npy", data)
    code, out, _ = cli(["info", str(tmp_path / "v.npy")], capsys)
    assert code == 0
    assert "infinite:  1 +inf, 1 -inf" in out and "range:     0 .. 0" in out


# --------------------------------------------------------------------------- noise
def _noisy_reader(monkeypatch):
    """A reader that warns and logs like nibabel/pydicom do, then fails."""
    from splinecast.io import dispatch

    def reader(path, **_):
        warnings.warn("pydicom-like warning from a library", UserWarning, stacklevel=1)
        logging.getLogger("nibabel.global").error("nibabel-like log line")
        print("a line printed by a library", file=__import__("sys").stderr)
        raise ReadError(f"{path}: not a readable volume (library failure)")

    monkeypatch.setattr(dispatch, "_reader", lambda kind: reader)


def test_library_noise_never_comes_before_the_error(tmp_path, capsys, monkeypatch):
    pytest.importorskip("nibabel")  # its logger has its own stderr handler
    path = tmp_path / "v.nii"
    path.write_bytes(b"\0" * 344 + b"n+1\0" + b"\0" * 8)
    _noisy_reader(monkeypatch)
    code, out, err = cli(["info", str(path)], capsys)
    assert code == 2 and out == ""
    one_error_line(err, "v.nii", "library failure")
    code, _, err = cli(["info", "--verbose", str(path)], capsys)
    lines = err.splitlines()
    assert code == 2 and lines[0].startswith("splinecast: error:")
    rest = "\n".join(lines[1:])
    assert "pydicom-like warning" in rest and "nibabel-like log line" in rest
    assert "a line printed by a library" in rest


def test_real_dicom_warnings_are_captured(tmp_path, capsys):
    folder = _dicom_series(tmp_path / "s", _raw_tag("PixelSpacing", "DS", b"abc\\1"))
    code, _, err = cli(["info", str(folder)], capsys)
    assert code == 2
    one_error_line(err, "PixelSpacing")


def _ome_tiff(folder: Path, other: str) -> Path:
    """An OME-TIFF whose OME-XML says half of its planes are in the file ``other``."""
    tifffile = pytest.importorskip("tifffile")
    xml = (
        '<?xml version="1.0" encoding="UTF-8"?>'
        '<OME xmlns="http://www.openmicroscopy.org/Schemas/OME/2016-06" UUID="urn:uuid:1">'
        '<Image ID="Image:0"><Pixels ID="Pixels:0" DimensionOrder="XYZCT" Type="uint16" '
        'SizeX="6" SizeY="5" SizeZ="8" SizeC="1" SizeT="1">'
        '<Channel ID="Channel:0:0" SamplesPerPixel="1"/>'
        '<TiffData FirstZ="0" IFD="0" PlaneCount="4"><UUID FileName="v.ome.tif">urn:uuid:1'
        '</UUID></TiffData>'
        f'<TiffData FirstZ="4" IFD="0" PlaneCount="4"><UUID FileName="{other}">urn:uuid:2'
        '</UUID></TiffData></Pixels></Image></OME>'
    )
    path = folder / "v.ome.tif"
    tifffile.imwrite(path, np.ascontiguousarray(RAW.transpose(2, 1, 0)), description=xml,
                     metadata=None, photometric="minisblack")
    return path


def test_ome_tiff_cannot_name_files_outside_its_folder(tmp_path):
    tifffile = pytest.importorskip("tifffile")
    (tmp_path / "data").mkdir()
    secret = tmp_path / "secret.ome.tif"
    tifffile.imwrite(secret, np.ascontiguousarray(RAW.transpose(2, 1, 0)) + 1000,
                     photometric="minisblack")
    path = _ome_tiff(tmp_path / "data", "../secret.ome.tif")
    with pytest.raises(ReadError, match="OME-XML FileName '../secret.ome.tif' lies outside"):
        sc.read(path)
    vol = sc.read(path, allow_external=True)  # allowed: the other file's planes are read
    assert vol.shape == (6, 5, 8)
    np.testing.assert_array_equal(vol.data[:, :, 4:], RAW + 1000)


def test_ome_tiff_with_its_other_file_beside_it(tmp_path):
    tifffile = pytest.importorskip("tifffile")
    tifffile.imwrite(tmp_path / "w.ome.tif", np.ascontiguousarray(RAW.transpose(2, 1, 0)) + 7,
                     photometric="minisblack")
    vol = sc.read(_ome_tiff(tmp_path, "w.ome.tif"))
    np.testing.assert_array_equal(vol.data[:, :, :4], RAW)
    np.testing.assert_array_equal(vol.data[:, :, 4:], RAW + 7)


@pytest.mark.parametrize("layout", ["C", "F", "view"])
def test_value_range_and_counts_scan_in_slabs(monkeypatch, layout):
    import splinecast.volume as volume_module

    monkeypatch.setattr(volume_module, "_SCAN_VOXELS", 7)  # many slabs, ragged last one
    rng = np.random.default_rng(3)
    data = rng.normal(size=(9, 7, 5)).astype(np.float64)
    data[rng.random(data.shape) < 0.05] = np.nan
    data[0, 0, 0], data[8, 6, 4], data[4, 3, 2] = np.inf, -np.inf, np.inf
    data = {"C": data, "F": np.asfortranarray(data), "view": data[::-1, ::2, :]}[layout]
    vol = sc.Volume(data)
    finite = data[np.isfinite(data)]
    assert vol.value_range == (float(finite.min()), float(finite.max()))
    assert vol.nonfinite_counts() == (int(np.isnan(data).sum()), int((data == np.inf).sum()),
                                      int((data == -np.inf).sum()))


def test_names_from_a_header_cannot_break_the_error_line(tmp_path, capsys):
    header = mhd(tmp_path, ElementDataFile="\x1b[31mred\x1esplit\u2028.raw")
    code, _, err = cli(["info", str(header)], capsys)
    assert code == 2
    line = one_error_line(err, "data file not found")
    assert "\x1b" not in line and "\\x1b[31mred\\x1esplit\\u2028.raw" in line


def test_dicom_huge_integral_intercept_gives_float_data(tmp_path):
    folder = _dicom_series(tmp_path / "s", _raw_tag("RescaleIntercept", "DS", b"1e300"))
    vol = sc.read(folder)  # float32: 1e300 overflows to +inf, which only rendering refuses
    assert vol.dtype == np.float32
    assert vol.nonfinite_counts() == (0, SHAPE[0] * SHAPE[1], 0)
    with pytest.raises(DataError, match=r"30 \+inf"):
        sc.Scene(vol)


def test_output_path_with_a_trailing_slash_is_refused(tmp_path, capsys):
    code, _, err = cli(["render", "demo:sphere?size=10", "--iso", "0", "-o",
                        str(tmp_path / "o.png"), "--depth", str(tmp_path / "d.npy") + "/"], capsys)
    assert code == 2
    one_error_line(err, "--depth", "names a folder")
    assert list(tmp_path.iterdir()) == []


# ------------------------------------------------------------------- the limits at their edge
def test_a_volume_axis_of_exactly_the_limit_is_read_and_one_more_is_refused(tmp_path):
    """MAX_AXIS = 2^20 voxels along an axis: a 2^20 x 1 x 1 uint8 volume (1 MiB) is read; the
    same header with one voxel more is refused before anything is read."""
    n = limits.MAX_AXIS
    assert n == 1 << 20
    values = (np.arange(n) % 251).astype(np.uint8)
    (tmp_path / "long.raw").write_bytes(values.tobytes())
    header = tmp_path / "long.mhd"
    header.write_text(f"ObjectType = Image\nNDims = 3\nDimSize = {n} 1 1\n"
                      "ElementType = MET_UCHAR\nElementDataFile = long.raw\n")
    vol = sc.read(header)
    assert vol.shape == (n, 1, 1)
    np.testing.assert_array_equal(vol.data[:, 0, 0], values)
    header.write_text(f"ObjectType = Image\nNDims = 3\nDimSize = {n + 1} 1 1\n"
                      "ElementType = MET_UCHAR\nElementDataFile = long.raw\n")
    with pytest.raises(ReadError, match=rf"long\.mhd: DimSize must be 3 integers between 1 and "
                                        rf"{n}, got {n + 1}"):
        sc.read(header)


def test_an_image_side_of_exactly_the_limit_renders_and_one_more_is_refused(tmp_path, capsys):
    """MAX_IMAGE_SIDE = 32768 pixels: a 32768 x 1 image renders (command line and API, the same
    pixels); 32769 is refused with one line naming the option."""
    side = limits.MAX_IMAGE_SIDE
    assert side == 1 << 15
    out = tmp_path / "wide.png"
    # A vertical field of view of 0.01 degrees spans +-70 degrees across 32768 pixels.
    view = ["--azimuth", "30", "--elevation", "20", "--distance", "30", "--fov", "0.01",
            "--fit", "box"]
    code, _, err = cli(["render", "demo:sphere?size=10", "--iso", "0", "--size", f"{side}x1",
                        *view, "--quiet", "-o", str(out)], capsys)
    assert code == 0, err
    with Image.open(out) as image:
        assert image.size == (side, 1)
        pixels = np.asarray(image.convert("RGBA"))
    vol = sc.demo("sphere", size=10)
    cam = sc.Camera.orbit(vol, azimuth=30, elevation=20, distance=30, size=(side, 1), fov=0.01,
                          fit="box")
    frame = sc.Scene(vol).render(cam, iso=0.0)
    np.testing.assert_array_equal(pixels, frame.to_uint8())
    assert np.isfinite(frame.depth).sum() > 100  # the sphere is in the row
    code, _, err = cli(["render", "demo:sphere?size=10", "--iso", "0", "--size",
                        f"{side + 1}x1", "-o", str(out)], capsys)
    assert code == 2
    one_error_line(err, "--size", f"image width must be an integer >= 1 and at most {side}, "
                               f"got {side + 1}")
    with pytest.raises(sc.ParameterError, match=f"camera size: image height must be an integer "
                                                f">= 1 and at most {side}, got {side + 1}"):
        sc.Scene(vol).render(sc.Camera.orbit(vol, size=(1, side + 1)), iso=0.0)


def test_an_iteration_budget_of_exactly_the_limit_is_accepted_and_one_more_is_refused(
        tmp_path, capsys):
    """MAX_ROOT_ITERATIONS = 1000 for ``--iterations``."""
    most = limits.MAX_ROOT_ITERATIONS
    assert most == 1000
    base = ["render", "demo:sphere?size=10", "--iso", "0", "--model", "bspline3",
            "--root-finder", "newton", "--size", "8x6", "--quiet", "-o", str(tmp_path / "i.png")]
    code, _, err = cli([*base, "--iterations", str(most)], capsys)
    assert code == 0, err
    code, _, err = cli([*base, "--iterations", str(most + 1)], capsys)
    assert code == 2
    one_error_line(err, "--iterations", f"must be an integer >= 1 and at most {most}, "
                                        f"got {most + 1}")
