"""Issue 17 for OME-Zarr stores and VTK image data: corrupt metadata, absurd sizes, pipes and
devices in place of files, links out of the store, truncated or bombed chunks and lying size
headers each give one clean line naming the file and exit status 2; nothing hangs, nothing is
allocated before the memory guard agrees, and nothing is left behind.

The stores and files are written by zarr-python, VTK and splinecast's own writers, then damaged
by hand; each expectation (the file named, what is wrong) follows from the damage done, not from
running the reader first.
"""

from __future__ import annotations

import base64
import json
import os
import struct
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import splinecast as sc
from splinecast.cli import main
from splinecast.errors import ReadError, limits

pytest.importorskip("zarr")
pytest.importorskip("vtkmodules")

SHAPE = (6, 5, 4)
SPACING = (0.5, 0.75, 2.0)


def ramp() -> np.ndarray:
    i, j, k = np.indices(SHAPE)
    return ((i + 10 * j + 100 * k) % 120).astype(np.uint16)


def cli(args: list[str], capsys: pytest.CaptureFixture) -> tuple[int, str, str]:
    try:
        code = main(args)
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def listing(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


def refused(args: list[str], capsys: pytest.CaptureFixture, folder: Path, *needles: str) -> str:
    """Run the command line; assert status 2, one ``splinecast: error:`` line holding every
    needle, nothing on stdout, and no file added under ``folder``."""
    before = listing(folder)
    code, out, err = cli(args, capsys)
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2, (code, err)
    assert len(lines) == 1 and lines[0].startswith("splinecast: error: "), err
    assert "Traceback" not in err and not out
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    assert listing(folder) == before
    return lines[0]


# --------------------------------------------------------------------------- OME-Zarr stores
@pytest.fixture
def store(tmp_path: Path) -> Path:
    """splinecast's own pyramid (Zarr v3, sharded, zstd), two levels; its root attributes do not
    store the value range, so ``info`` reads the coarsest level's chunk."""
    from splinecast.multires.store.pyramid import build_pyramid

    path = tmp_path / "v.ome.zarr"
    build_pyramid(sc.Volume(ramp(), spacing=SPACING), path, brick=4, workers=1, progress=False)
    root = json.loads((path / "zarr.json").read_text())
    del root["attributes"]["splinecast"]["value_range"]
    (path / "zarr.json").write_text(json.dumps(root))
    return path


@pytest.fixture
def v2store(tmp_path: Path) -> Path:
    """An OME-Zarr 0.4 image in Zarr v2 written by zarr-python directly (blosc chunks)."""
    import zarr

    path = tmp_path / "v.zarr"
    root = zarr.open_group(str(path), mode="w", zarr_format=2)
    data = np.ascontiguousarray(ramp().transpose(2, 1, 0))
    arr = root.create_array("0", shape=data.shape, dtype=data.dtype, chunks=(4, 4, 4))
    arr[...] = data
    root.attrs["multiscales"] = [{
        "version": "0.4", "axes": [{"name": a, "type": "space"} for a in "zyx"],
        "datasets": [{"path": "0", "coordinateTransformations": [
            {"type": "scale", "scale": [2.0, 0.75, 0.5]}]}]}]
    return path


def edit_json(path: Path, change) -> None:
    doc = json.loads(path.read_text())
    change(doc)
    path.write_text(json.dumps(doc))


def test_the_intact_stores_are_read(store, v2store, capsys):
    for path in (store, v2store):
        vol = sc.read(path)
        assert vol.shape == SHAPE and vol.spacing == SPACING
        np.testing.assert_array_equal(vol.levels[0].read((0, 0, 0), SHAPE), ramp())
        code, out, _ = cli(["info", str(path)], capsys)
        assert code == 0 and "6 x 5 x 4" in out


@pytest.mark.parametrize("text, what", [
    ('{"zarr_format": 3, "node_type": "group", "attributes": ', "not valid JSON"),
    ('{"zarr_format": 3, "node_type": "group"} junk', "not valid JSON"),
    ('{"zarr_format": 3, "a": NaN}', "not valid JSON"),
    ('{"zarr_format": 3, "a": 1e999}', "not valid JSON"),
    ('{"zarr_format": 3, "a": ' + "9" * 5000 + "}", "not valid JSON"),
    ("[" * 5000 + "]" * 5000, "JSON nested"),
    ("\udcff", "not UTF-8"),
])
def test_corrupt_root_metadata(store, capsys, text, what):
    (store / "zarr.json").write_bytes(text.encode("utf-8", "surrogateescape"))
    refused(["info", str(store)], capsys, store.parent, f"{store / 'zarr.json'}: ", what)


def test_corrupt_level_metadata_names_the_level_file(store, v2store, capsys):
    (store / "0" / "zarr.json").write_text('{"shape": [6, 5')
    refused(["info", str(store)], capsys, store.parent, str(store / "0" / "zarr.json"),
            "not valid JSON")
    (v2store / "0" / ".zarray").write_text("{'zarr_format': 2}")
    refused(["info", str(v2store)], capsys, v2store.parent, str(v2store / "0" / ".zarray"),
            "not valid JSON")


@pytest.mark.parametrize("change, needles", [
    (lambda d: d["attributes"]["ome"].update(multiscales="abc"),
     ["'multiscales' must be a non-empty list"]),
    (lambda d: d["attributes"].pop("ome"), ["without OME-Zarr 'multiscales' metadata"]),
    (lambda d: d["attributes"]["ome"]["multiscales"][0].update(axes=[1, 2, 3]),
     ["axis 0 must have a text 'name'"]),
    (lambda d: d["attributes"]["ome"]["multiscales"][0]["axes"][0].update(unit=[1]),
     ["axis 0 must have a text 'name'"]),
    (lambda d: d["attributes"]["ome"]["multiscales"][0]["datasets"][0]
     ["coordinateTransformations"][0].update(scale=[{"a": 1}, 1, 1]),
     ["scale must be 3 finite numbers"]),
    (lambda d: d["attributes"]["ome"]["multiscales"][0]["datasets"][0]
     ["coordinateTransformations"][0].update(scale=[1e-320, 1, 1]),
     ["scale must be three numbers between"]),
    (lambda d: d["attributes"]["ome"]["multiscales"][0]["datasets"][0]
     ["coordinateTransformations"][1].update(translation=[2**70, 0, 0]),
     ["translation", "2^40 voxel spacings"]),
    (lambda d: d["attributes"]["splinecast"].update(brick=2**70), ["brick must be an integer"]),
    (lambda d: d["attributes"]["splinecast"].update(value_range=[5, "x"]), ["value_range"]),
    (lambda d: d["attributes"]["splinecast"].update(source_metadata=[1]),
     ["source_metadata must be an object"]),
])
def test_wrong_types_in_group_metadata(store, capsys, change, needles):
    edit_json(store / "zarr.json", change)
    refused(["info", str(store)], capsys, store.parent, str(store), *needles)


@pytest.mark.parametrize("field, value, needles", [
    ("shape", [2**70, 5, 6], ["level '0'"]),
    ("shape", [-4, 5, 6], ["level '0'"]),
    ("shape", [0, 5, 6], ["level '0'"]),
    ("shape", [1048577, 5, 6], ["level '0': shape must be 3 integers between 1 and 1048576"]),
    ("shape", "abc", ["level '0'"]),
    ("data_type", "bogus", ["level '0'"]),
    ("data_type", "complex64", ["level '0'"]),
    ("data_type", 17, ["level '0'"]),
    ("fill_value", [1, 2], ["level '0'"]),
    ("node_type", "group", ["level '0'"]),
    ("zarr_format", 99, ["level '0'"]),
    ("codecs", [{"name": "nosuchcodec"}], ["level '0'"]),
])
def test_absurd_level_metadata(store, capsys, field, value, needles):
    edit_json(store / "0" / "zarr.json", lambda d: d.update({field: value}))
    refused(["info", str(store)], capsys, store.parent, str(store), *needles)


@pytest.mark.parametrize("chunks, needle", [
    ([0, 4, 4], "chunk shape"),
    ([-1, 4, 4], "chunk shape"),
    ([2**70, 4, 4], "chunk shape"),
])
def test_absurd_v2_chunks(v2store, capsys, chunks, needle):
    edit_json(v2store / "0" / ".zarray", lambda d: d.update(chunks=chunks))
    refused(["info", str(v2store)], capsys, v2store.parent, str(v2store))


def test_a_huge_shard_is_refused_by_the_memory_guard(store, capsys, monkeypatch):
    monkeypatch.setenv(limits.ENV_MAX_BYTES, "64MiB")

    def change(doc):
        doc["chunk_grid"]["configuration"]["chunk_shape"] = [1024, 1024, 1024]
        doc["codecs"][0]["configuration"]["chunk_shape"] = [4, 4, 4]

    edit_json(store / "0" / "zarr.json", change)
    refused(["info", str(store)], capsys, store.parent, "level '0'",
            "one 1024x1024x1024 shard needs 2.0 GiB", limits.ENV_MAX_BYTES)


def test_reading_a_huge_level_is_refused_by_the_memory_guard(v2store, capsys, monkeypatch):
    monkeypatch.setenv(limits.ENV_MAX_BYTES, "64MiB")
    edit_json(v2store / "0" / ".zarray", lambda d: d.update(shape=[4000, 4000, 4000]))
    refused(["info", str(v2store)], capsys, v2store.parent, f"{v2store}/0",
            "needs 238.4 GiB", limits.ENV_MAX_BYTES)


def test_reading_a_level_of_tiny_chunks_is_bounded(v2store, capsys):
    edit_json(v2store / "0" / ".zarray", lambda d: d.update(shape=[100, 100, 100],
                                                             chunks=[1, 1, 1]))
    refused(["info", str(v2store)], capsys, v2store.parent,
            f"needs 1000000 chunk files of 1x1x1 voxels, more than "
            f"{limits.MAX_CHUNKS_PER_READ}")


def _no_hang(args: list[str], timeout: float = 120) -> subprocess.CompletedProcess:
    """Run the command line in a subprocess that a hang would push past ``timeout``."""
    return subprocess.run([sys.executable, "-m", "splinecast.cli", *args], capture_output=True,
                          text=True, timeout=timeout)


def _one_line(proc: subprocess.CompletedProcess, *needles: str) -> None:
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert proc.returncode == 2, proc.stderr
    assert len(lines) == 1 and lines[0].startswith("splinecast: error: "), proc.stderr
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])


@pytest.mark.parametrize("which", ["zarr.json", "0/zarr.json", "1/c/0/0/0"])
def test_a_fifo_in_place_of_a_store_file_does_not_hang(store, which):
    target = store / which
    target.unlink()
    os.mkfifo(target)
    _one_line(_no_hang(["info", str(store)]), str(target), "not a regular file")


@pytest.mark.parametrize("which", ["zarr.json", "0/zarr.json", "1/c/0/0/0"])
def test_a_folder_or_device_in_place_of_a_store_file(store, capsys, which):
    target = store / which
    target.unlink()
    target.mkdir()
    refused(["info", str(store)], capsys, store.parent, str(target), "not a regular file")
    target.rmdir()
    target.symlink_to("/dev/zero")
    refused(["info", str(store)], capsys, store.parent, str(target), "not a regular file")


def test_a_chunk_linked_out_of_the_store(store, tmp_path, capsys, monkeypatch):
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    coarse = sc.read(store).levels[1]
    expected = coarse.read((0, 0, 0), coarse.shape)
    chunk = store / "1" / "c" / "0" / "0" / "0"
    (outside / "chunk").write_bytes(chunk.read_bytes())
    chunk.unlink()
    chunk.symlink_to(outside / "chunk")
    refused(["info", str(store)], capsys, tmp_path, str(chunk), "lies outside the store's folder",
            "--allow-external-data")
    with pytest.raises(ReadError, match="lies outside"):
        sc.read(store).levels[1].read((0, 0, 0), coarse.shape)
    # Allowed explicitly: the same bytes, so the same voxels.
    code, out, _ = cli(["info", "--allow-external-data", str(store)], capsys)
    assert code == 0 and "6 x 5 x 4" in out
    np.testing.assert_array_equal(
        sc.read(store, allow_external=True).levels[1].read((0, 0, 0), coarse.shape), expected)
    monkeypatch.setenv(limits.ENV_ALLOW_EXTERNAL, "1")
    np.testing.assert_array_equal(sc.read(store).levels[1].read((0, 0, 0), coarse.shape),
                                  expected)


def test_a_level_leading_out_of_the_store(store, tmp_path, capsys):
    import shutil

    shutil.copytree(store / "0", tmp_path / "outside0")
    edit_json(store / "zarr.json", lambda d: d["attributes"]["ome"]["multiscales"][0]
              ["datasets"][0].update(path="../outside0"))
    refused(["info", str(store)], capsys, tmp_path, "level '../outside0'",
            "is not a readable Zarr array")
    # The same through a symbolic link: the level's folder itself leads out.
    edit_json(store / "zarr.json", lambda d: d["attributes"]["ome"]["multiscales"][0]
              ["datasets"][0].update(path="0"))
    shutil.rmtree(store / "0")
    (store / "0").symlink_to(tmp_path / "outside0")
    refused(["info", str(store)], capsys, tmp_path, str(store / "0" / "zarr.json"),
            "lies outside the store's folder")


@pytest.mark.parametrize("damage, needles", [
    (lambda b: b[: len(b) // 2], ["cannot be read"]),
    (lambda b: b"", ["cannot be read"]),
    (lambda b: bytes(len(b)), ["cannot be read"]),
    (lambda b: b + bytes(10**6), ["holds", "more than a chunk of"]),
])
def test_damaged_chunks_name_the_chunk(store, v2store, capsys, damage, needles):
    chunks = [store / "1" / "c" / "0" / "0" / "0", v2store / "0" / "0.0.0"]
    if "holds" in needles:  # a 4x4x4 chunk of uint16 can never take a megabyte
        chunks = chunks[1:]
    for chunk in chunks:
        folder = chunk.parents[4] if chunk.is_relative_to(store) else chunk.parents[1]
        chunk.write_bytes(damage(chunk.read_bytes()))
        line = refused(["info", str(folder)], capsys, folder.parent, str(chunk), *needles)
        if "cannot be read" in needles:  # the chunk, or the shard whose index is damaged
            assert "chunk (0, 0, 0)" in line or "shard (0, 0, 0)" in line


@pytest.mark.parametrize("declared", [2**40, 2**62, 300 << 20])
def test_a_zstd_bomb_is_refused_from_its_header(store, capsys, monkeypatch, declared):
    """An inner chunk of a shard (its index kept valid) declaring far more than its 4x4x4
    uint16 voxels: refused from the header, naming the chunk, whatever the memory cap."""
    from fuzz.codecs import join_shard, shard_layout, split_shard

    monkeypatch.setenv(limits.ENV_MAX_BYTES, "256MiB")
    shard = store / "1" / "c" / "0" / "0" / "0"
    layout = shard_layout(json.loads((store / "1" / "zarr.json").read_text()))
    chunks = split_shard(shard.read_bytes(), layout["count"], layout["at_end"],
                         layout["checksum"])
    frame = b"\x28\xb5\x2f\xfd\xe0" + struct.pack("<Q", declared) + b"\x01\x00\x00"
    chunks[0] = frame
    shard.write_bytes(join_shard(chunks, layout["at_end"], layout["checksum"]))
    refused(["info", str(store)], capsys, store.parent, str(shard), "chunk (0, 0, 0)",
            f"the zstd data declares {declared} bytes, the chunk holds 128")


# --------------------------------------------------------------------------- VTK image data
def write_vti(path: Path, mode: str = "appended", compressed: bool = False,
              header: str = "UInt32", encode: bool = False) -> Path:
    from vtkmodules.util.numpy_support import numpy_to_vtk
    from vtkmodules.vtkCommonDataModel import vtkImageData
    from vtkmodules.vtkIOXML import vtkXMLImageDataWriter

    image = vtkImageData()
    image.SetDimensions(*SHAPE)
    image.SetSpacing(*SPACING)
    values = numpy_to_vtk(np.ascontiguousarray(ramp().transpose(2, 1, 0)).ravel(), deep=True)
    values.SetName("v")
    image.GetPointData().SetScalars(values)
    writer = vtkXMLImageDataWriter()
    writer.SetInputData(image)
    {"appended": writer.SetDataModeToAppended, "binary": writer.SetDataModeToBinary,
     "ascii": writer.SetDataModeToAscii}[mode]()
    writer.SetEncodeAppendedData(encode)
    (writer.SetCompressorTypeToZLib if compressed else writer.SetCompressorTypeToNone)()
    (writer.SetHeaderTypeToUInt64 if header == "UInt64" else writer.SetHeaderTypeToUInt32)()
    writer.SetFileName(str(path))
    assert writer.Write()
    return path


def patch(path: Path, old: bytes, new: bytes) -> None:
    data = path.read_bytes()
    assert old in data, old
    path.write_bytes(data.replace(old, new, 1))


@pytest.fixture
def vti(tmp_path: Path) -> Path:
    folder = tmp_path / "d"
    folder.mkdir()
    return write_vti(folder / "v.vti")


def test_vti_encodings_still_read(tmp_path):
    for n, (mode, compressed, header, encode) in enumerate([
            ("appended", False, "UInt32", False), ("appended", True, "UInt64", False),
            ("appended", True, "UInt32", True), ("binary", False, "UInt32", False),
            ("binary", True, "UInt64", False), ("ascii", False, "UInt32", False)]):
        path = write_vti(tmp_path / f"{n}.vti", mode, compressed, header, encode)
        np.testing.assert_array_equal(sc.read(path).data, ramp())


@pytest.mark.parametrize("old, new, needles", [
    (b'WholeExtent="0 5 0 4 0 3"', b'WholeExtent="0 -1 0 4 0 3"', ["WholeExtent"]),
    (b'WholeExtent="0 5 0 4 0 3"', b'WholeExtent="0 1e30 0 4 0 3"', ["WholeExtent"]),
    (b'WholeExtent="0 5 0 4 0 3"', b'WholeExtent="0 5 0 4"', ["WholeExtent must be 6 numbers"]),
    (b'WholeExtent="0 5 0 4 0 3"', b'WholeExtent="0 9223372036854775807 0 0 0 0"',
     ["WholeExtent"]),
    (b' Extent="0 5 0 4 0 3"', b' Extent="0 6 0 4 0 3"', ["outside WholeExtent"]),
    (b'Spacing="0.5 0.75 2"', b'Spacing="1e-320 0.75 2"', ["Spacing must be three numbers"]),
    (b'Spacing="0.5 0.75 2"', b'Spacing="nan 0.75 2"', ["Spacing must be three numbers"]),
    (b'Origin="0 0 0"', b'Origin="1e300 0 0"', ["Origin", "2^40 voxel spacings"]),
    (b'NumberOfComponents="1"', b'NumberOfComponents="2147483647"',
     ["NumberOfComponents must be an integer >= 1 and at most 1024"]),
    (b'type="UInt16"', b'type="Bogus"', ["unknown data type 'Bogus'"]),
    # VTK's binary string decoder crashed the process on such an array (fuzz case #3761).
    (b'type="UInt16"', b'type="String"', ["'v'", "String arrays are read only as ascii field"]),
    (b'format="appended"', b'format="hex"', ["unknown format 'hex'"]),
    (b'header_type="UInt32"', b'header_type="UInt8"', ["unknown header_type 'UInt8'"]),
    (b'byte_order="LittleEndian"', b'byte_order="Middle"', ["unknown byte_order"]),
    (b'offset="0"', b'offset="-1"', ["offset must be an integer >= 0"]),
    (b'encoding="raw"', b'encoding="zip"', ["unknown AppendedData encoding"]),
    (b'type="ImageData"', b'type="PolyData"', ["VTK PolyData data, not ImageData"]),
])
def test_hostile_vti_attributes(vti, capsys, old, new, needles):
    if b"NumberOfComponents" in old and old not in vti.read_bytes():
        patch(vti, b'type="UInt16"', b'type="UInt16" NumberOfComponents="1"')
    patch(vti, old, new)
    refused(["info", str(vti)], capsys, vti.parent, str(vti), *needles)


def test_huge_vti_extent_is_refused_before_vtk_allocates(vti, capsys, monkeypatch):
    monkeypatch.setenv(limits.ENV_MAX_BYTES, "64MiB")
    patch(vti, b'WholeExtent="0 5 0 4 0 3"', b'WholeExtent="0 1999 0 1999 0 1999"')
    patch(vti, b'Extent="0 5 0 4 0 3"', b'Extent="0 1999 0 1999 0 1999"')
    refused(["info", str(vti)], capsys, vti.parent, str(vti), "the data arrays needs 14.9 GiB",
            limits.ENV_MAX_BYTES)


def _appended_header_at(path: Path) -> int:
    data = path.read_bytes()
    return data.find(b"_", data.find(b"<AppendedData")) + 1


@pytest.mark.parametrize("size, needles", [
    (2**32 - 1, ["the header gives 4294967295 bytes, its extent and type give 240"]),
    (239, ["the header gives 239 bytes"]),
])
def test_appended_raw_size_header(vti, capsys, size, needles):
    at = _appended_header_at(vti)
    data = bytearray(vti.read_bytes())
    data[at:at + 4] = struct.pack("<I", size)
    vti.write_bytes(bytes(data))
    refused(["info", str(vti)], capsys, vti.parent, str(vti), "array 'v'", *needles)


def _appended_tag(data: bytes) -> bytes:
    start = data.find(b"<AppendedData")
    return data[start:data.find(b">", start) + 1]


@pytest.mark.parametrize("damage", ["duplicated element", "text before the mark", "no mark"])
def test_appended_data_must_start_with_its_mark(vti, capsys, damage):
    # VTK reads the arrays from the end of the file when the first character after the tag is
    # not '_' (a duplicated, self-closing <AppendedData/> before the real one aborted the
    # process in its decoder); a check that searched for the next '_' passed such files on.
    data = vti.read_bytes()
    tag = _appended_tag(data)
    if damage == "duplicated element":
        data = data.replace(tag, tag[:-1] + b" />\n  </PointData>\n  " + tag, 1)
    elif damage == "text before the mark":
        data = data.replace(tag, tag + b"x", 1)
    else:
        at = data.find(b"_", data.find(tag))
        data = data[:at] + b"=" + data[at + 1:]
    vti.write_bytes(data)
    refused(["info", str(vti)], capsys, vti.parent, str(vti),
            "the appended data does not start with the '_' mark")


def test_white_space_before_the_appended_mark_is_read(vti):
    data = vti.read_bytes()
    tag = _appended_tag(data)
    at = data.find(b"_", data.find(tag))
    vti.write_bytes(data[:data.find(tag) + len(tag)] + b"\r\n\t " + data[at:])
    np.testing.assert_array_equal(sc.read(vti).data, ramp())


def test_truncated_appended_data(vti, capsys):
    vti.write_bytes(vti.read_bytes()[:-40])
    refused(["info", str(vti)], capsys, vti.parent, str(vti), "truncated: array 'v' needs 240")


@pytest.mark.parametrize("word, value, needle", [
    (1, 2**63, "impossible compression blocks"),
    (0, 2**40, "the compression header gives"),
    (2, 10**9, "impossible compression blocks"),
    (3, 2**62, "compressed block sizes run past the end"),
])
def test_compressed_block_headers(tmp_path, capsys, word, value, needle):
    path = write_vti(tmp_path / "z.vti", compressed=True, header="UInt64")
    at = _appended_header_at(path) + 8 * word
    data = bytearray(path.read_bytes())
    data[at:at + 8] = struct.pack("<Q", value)
    path.write_bytes(bytes(data))
    refused(["info", str(path)], capsys, tmp_path, str(path), "array 'v'", needle)


def test_inline_base64_size_header(tmp_path, capsys):
    path = write_vti(tmp_path / "b.vti", mode="binary")
    data = path.read_bytes()
    start = data.find(b">", data.find(b'format="binary"')) + 1
    text = data[start:data.find(b"<", start)].strip()
    at = data.find(text)
    hostile = base64.b64encode(struct.pack("<I", 2**31))
    path.write_bytes(data[:at] + hostile + text[len(hostile):] + data[at + len(text):])
    refused(["info", str(path)], capsys, tmp_path, str(path),
            "the header gives 2147483648 bytes, its extent and type give 240")


def test_a_fifo_named_like_a_vti_does_not_hang(tmp_path):
    path = tmp_path / "v.vti"
    os.mkfifo(path)
    _one_line(_no_hang(["info", str(path)]), str(path), "not a regular file")


# --------------------------------------------------------------------------- legacy VTK
def legacy(folder: Path, header: dict[str, str] | None = None, body: bytes | None = None,
           binary: bool = True) -> Path:
    fields = {"DIMENSIONS": "6 5 4", "ORIGIN": "0 0 0", "SPACING": "0.5 0.75 2",
              "POINT_DATA": "120", "SCALARS": "v unsigned_short 1"}
    fields.update(header or {})
    lines = ["# vtk DataFile Version 3.0", "t", "BINARY" if binary else "ASCII",
             "DATASET STRUCTURED_POINTS"]
    lines += [f"{k} {v}" for k, v in fields.items() if v is not None]
    lines += ["LOOKUP_TABLE default", ""]
    if body is None:
        values = ramp().ravel(order="F")
        body = values.astype(">u2").tobytes() if binary else \
            " ".join(map(str, values)).encode() + b"\n"
    path = folder / "v.vtk"
    path.write_bytes("\n".join(lines).encode() + body)
    return path


def test_legacy_files_still_read(tmp_path):
    for binary in (True, False):
        np.testing.assert_array_equal(sc.read(legacy(tmp_path, binary=binary)).data, ramp())


@pytest.mark.parametrize("header, body, needles", [
    ({"DIMENSIONS": "6 5 -4"}, None, ["DIMENSIONS must be 3 integers"]),
    ({"DIMENSIONS": "6 5 1e30"}, None, ["DIMENSIONS must be 3 integers"]),
    ({"POINT_DATA": "121"}, None, ["POINT_DATA 121 does not match DIMENSIONS"]),
    ({"POINT_DATA": "abc"}, None, ["POINT_DATA must be an integer"]),
    ({"SCALARS": "v unsigned_short 5"}, None, ["SCALARS components must be an integer"]),
    ({"SCALARS": "v complex 1"}, None, ["unknown data type 'complex'"]),
    ({"SPACING": "0 1 1"}, None, ["SPACING must be three numbers"]),
    ({"ORIGIN": "nan 0 0"}, None, ["ORIGIN must be three finite numbers"]),
    ({}, b"\x00" * 100, ["truncated: 240 bytes announced, 100 left"]),
])
def test_hostile_legacy_headers(tmp_path, capsys, header, body, needles):
    path = legacy(tmp_path, header, body)
    refused(["info", str(path)], capsys, tmp_path, str(path), *needles)


def test_legacy_counts_are_checked_against_memory(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv(limits.ENV_MAX_BYTES, "64MiB")
    path = legacy(tmp_path, {"DIMENSIONS": "2000 2000 2000", "POINT_DATA": "8000000000"})
    refused(["info", str(path)], capsys, tmp_path, str(path), "the data arrays needs 14.9 GiB")
    # A FIELD array after the scalars, claiming 2^40 tuples.
    values = ramp().ravel(order="F").astype(">u2").tobytes()
    path = legacy(tmp_path, body=values + b"\nFIELD f 1\nbig 1 1099511627776 float\n")
    refused(["info", str(path)], capsys, tmp_path, str(path), "the data arrays needs 4.0 TiB")


# --------------------------------------------------------------------------- movie and pyramid
@pytest.fixture
def outside_header(tmp_path: Path) -> Path:
    """A MetaImage header whose data file lies one folder up."""
    folder = tmp_path / "data"
    folder.mkdir()
    (tmp_path / "v.raw").write_bytes(ramp().astype("<u2").tobytes(order="F"))
    header = folder / "v.mhd"
    header.write_text("ObjectType = Image\nNDims = 3\nDimSize = 6 5 4\n"
                      "ElementSpacing = 0.5 0.75 2\nElementType = MET_USHORT\n"
                      "ElementDataFile = ../v.raw\n")
    return header


def test_pyramid_allows_external_data_only_when_asked(outside_header, tmp_path, capsys):
    out = tmp_path / "p.zarr"
    refused(["pyramid", str(outside_header), "-o", str(out), "--brick", "4", "--quiet"], capsys,
            tmp_path, "ElementDataFile", "lies outside the header's folder",
            "--allow-external-data")
    assert not out.exists()
    code, stdout, err = cli(["pyramid", str(outside_header), "-o", str(out), "--brick", "4",
                             "--quiet", "--allow-external-data"], capsys)
    assert code == 0, err
    np.testing.assert_array_equal(sc.read(out).levels[0].read((0, 0, 0), SHAPE), ramp())


def test_movie_allows_external_data_only_when_asked(outside_header, tmp_path, capsys):
    frames = tmp_path / "frames"
    args = ["movie", str(outside_header), "-o", f"{frames}/", "--frames", "1", "--size", "8x8",
            "--iso", "50", "--quiet"]
    refused(args, capsys, tmp_path, "ElementDataFile", "lies outside the header's folder")
    assert not frames.exists()
    code, _, err = cli([*args, "--allow-external-data"], capsys)
    assert code == 0, err
    assert sorted(p.name for p in frames.iterdir()) == ["frame_0000.png"]


def test_scene_source_carries_the_permission_to_workers(outside_header):
    from splinecast.distributed import SceneSource

    with pytest.raises(ReadError, match="lies outside"):
        SceneSource(outside_header).read()
    source = SceneSource(outside_header, allow_external=True)
    np.testing.assert_array_equal(source.read().data, ramp())
    assert hash(source) != hash(SceneSource(outside_header))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        import pickle

        assert pickle.loads(pickle.dumps(source)).allow_external is True


def _two_level_store(path: Path, level_1: list[dict]) -> Path:
    """An OME-Zarr store of the ramp (level 0, scale 2 x 0.75 x 0.5 in z y x) and its 2x
    subsampling as level 1, placed by the coordinate transformations ``level_1``."""
    import zarr

    root = zarr.open_group(str(path), mode="w", zarr_format=2)
    data = np.ascontiguousarray(ramp().transpose(2, 1, 0))
    for level, block in enumerate((data, data[::2, ::2, ::2])):
        arr = root.create_array(str(level), shape=block.shape, dtype=block.dtype,
                                chunks=(4, 4, 4))
        arr[...] = block
    root.attrs["multiscales"] = [{
        "version": "0.4", "axes": [{"name": a, "type": "space"} for a in "zyx"],
        "datasets": [
            {"path": "0", "coordinateTransformations": [
                {"type": "scale", "scale": [2.0, 0.75, 0.5]}]},
            {"path": "1", "coordinateTransformations": level_1}]}]
    return path


def test_a_level_that_does_not_cover_level_0_is_left_out(tmp_path):
    """A coarse level translated 50 voxels away would make bricks read outside its voxels."""
    from splinecast.multires.cut.octree import BrickOctree

    path = _two_level_store(tmp_path / "v.zarr", [
        {"type": "scale", "scale": [4.0, 1.5, 1.0]},
        {"type": "translation", "translation": [0.0, 0.0, 50.0]}])
    tree = BrickOctree(sc.read(path), brick=4)
    assert tree.levels == [0]
    assert any("level 1 skipped: its voxels do not cover level 0" in n for n in tree.notes)


@pytest.mark.parametrize("scale", [[1.0, 0.375, 0.25], [0.5, 0.1875, 0.125], [2.0, 0.75, 0.25]])
def test_a_level_finer_than_level_0_is_left_out(tmp_path, scale):
    """Level 1's scale half or a quarter of level 0's on some axis (a store whose scale was lost
    or damaged): the level is left out with a note, and the store still renders from level 0,
    instead of failing in the power of two its factor was rounded to."""
    from splinecast.multires.cut.octree import BrickOctree

    path = _two_level_store(tmp_path / "v.zarr", [{"type": "scale", "scale": scale}])
    volume = sc.read(path)
    tree = BrickOctree(volume, brick=4)
    assert tree.levels == [0]
    assert any(n.startswith("level 1 skipped") for n in tree.notes), tree.notes
    camera = sc.Camera.orbit(volume, size=(16, 12))
    with sc.Scene(volume, budget="64MiB", lod=1.0) as scene:
        frame = scene.render(camera, iso=40.0, complete=True)
    # Level 0 alone, in memory: the same voxels, spacing and origin.
    expected = sc.Scene(volume.levels[0].to_volume()).render(camera, iso=40.0, samples=1)
    np.testing.assert_array_equal(np.isfinite(frame.depth), np.isfinite(expected.depth))


def test_whole_extent_counts_even_when_the_piece_is_small(vti, capsys, monkeypatch):
    """VTK allocates the output for the whole extent: a huge WholeExtent around the original
    small piece must be refused before VTK aborts on std::bad_alloc (fuzz #15210)."""
    monkeypatch.setenv(limits.ENV_MAX_BYTES, "64MiB")
    patch(vti, b'WholeExtent="0 5 0 4 0 3"', b'WholeExtent="0 65535 0 65535 0 65535"')
    refused(["info", str(vti)], capsys, vti.parent, str(vti), "the data arrays needs 512.0 TiB")
