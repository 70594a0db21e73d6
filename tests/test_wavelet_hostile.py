"""Hostile spline-wavelet stores: every damage is one line naming the store, exit status 2, and
nothing written.

Each test builds a small valid store, damages one thing (metadata JSON, a shape that lies, a
truncated, missing or bomb chunk, levels or degree that contradict the arrays, a file outside
the store), and checks the command line (``render --lod 0``: every detail is read) and the API.
"""

from __future__ import annotations

import json
import os
import struct
from pathlib import Path

import numpy as np
import pytest
from fuzz.codecs import zstd_rle

import splinecast as sc
from splinecast.cli import main
from splinecast.multires.wavelet.store import build_wavelet_pyramid

pytest.importorskip("zarr")


@pytest.fixture
def store(tmp_path: Path) -> Path:
    data = np.random.default_rng(5).standard_normal((21, 18, 13)).astype(np.float32)
    build_wavelet_pyramid(data, tmp_path / "w.zarr", degree=3, chunk=4)
    return tmp_path / "w.zarr"


def _meta(store: Path, array: str = "") -> Path:
    return store / array / "zarr.json" if array else store / "zarr.json"


def _edit(path: Path, change) -> None:
    doc = json.loads(path.read_text())
    change(doc)
    path.write_text(json.dumps(doc))


def _attrs(doc: dict) -> dict:
    return doc["attributes"]["splinecast"]


def _chunk(store: Path, array: str) -> Path:
    files = sorted(p for p in (store / array).rglob("*") if p.is_file() and p.name != "zarr.json")
    assert files, array
    return files[0]


def _refused(store: Path, capsys, match: str | None = None) -> str:
    """Render with ``--lod 0`` (reads every array): status 2, one error line naming the store,
    no image, and nothing new anywhere under the store's folder."""
    out = store.parent / "out.png"
    before = sorted(p.relative_to(store.parent) for p in store.parent.rglob("*"))
    capsys.readouterr()
    status = main(["render", str(store), "-o", str(out), "--size", "12x12", "--lod", "0",
                   "--quiet"])
    err = capsys.readouterr().err.strip()
    assert status == 2, err
    assert len(err.splitlines()) == 1, err
    assert err.startswith("splinecast: error:") and str(store) in err, err
    if match is not None:
        assert match in err, err
    assert not out.exists()
    assert sorted(p.relative_to(store.parent) for p in store.parent.rglob("*")) == before
    return err


def test_the_undamaged_store_renders(store, capsys):
    out = store.parent / "ok.png"
    assert main(["render", str(store), "-o", str(out), "--size", "12x12", "--lod", "0",
                 "--quiet"]) == 0
    assert out.is_file()


@pytest.mark.parametrize("text", ["", "{", "null", "[]", '{"zarr_format": 3, "node_type": '
                                  '"group", "attributes": {"splinecast": ' + "[" * 3000 + "]"
                                  * 3000 + "}}"])
def test_broken_root_metadata(store, capsys, text):
    _meta(store).write_text(text)
    _refused(store, capsys)


@pytest.mark.parametrize("field, value, match", [
    ("shape", [2000, 2000, 2000], "hull/0"),
    ("shape", [21, 18], "shape"),
    ("shape", [2**70, 1, 1], "shape"),
    ("levels", 9, "is missing"),
    ("levels", 10**9, "levels"),
    ("levels", 0, "levels"),
    ("degree", 1, "model"),
    ("degree", 2, "model"),
    ("degree", "three", "degree"),
    ("chunk", 5, "chunk"),
    ("chunk", 8, "hull/0"),
    ("chunk", 2**40, "chunk"),
    ("dtype", "float64", "holds float32"),
    ("dtype", "|O", "dtype"),
    ("spacing", [1e-320, 1, 1], "spacing"),
    ("origin", [float("nan")] * 3, None),
    ("value_range", [3, 1], "value_range"),
    ("kind", "other", "kind"),
])
def test_root_attribute_that_lies(store, capsys, field, value, match):
    _edit(_meta(store), lambda d: _attrs(d).__setitem__(field, value))
    _refused(store, capsys, match)


@pytest.mark.parametrize("field", ["shape", "degree", "levels", "chunk", "dtype", "spacing"])
def test_root_attribute_missing(store, capsys, field):
    _edit(_meta(store), lambda d: _attrs(d).pop(field))
    _refused(store, capsys, field)


@pytest.mark.parametrize("array, change, match", [
    ("wavelet/detail/1/HHH", lambda d: d.__setitem__("shape", [2000, 2000, 2000]), "HHH"),
    ("wavelet/detail/2/LLH", lambda d: d.__setitem__("shape", [3, 3, 3]), "LLH"),
    ("wavelet/coarse/3", lambda d: d.__setitem__("data_type", "float64"), "coarse/3"),
    ("wavelet/coarse/1", lambda d: d.__setitem__("shape", [11, 10, 7, 1]), "coarse/1"),
    ("wavelet/detail/1/LHL", lambda d: d["chunk_grid"]["configuration"].__setitem__(
        "chunk_shape", [1, 1, 1]), "LHL"),
    ("wavelet/detail/1/LHL", lambda d: d["chunk_grid"]["configuration"].__setitem__(
        "chunk_shape", [2**20, 2**20, 2**20]), "LHL"),
    ("wavelet/hull/1", lambda d: d.__setitem__("shape", [1, 1, 1, 2]), "hull/1"),
    ("wavelet/hull/0", lambda d: d.__setitem__("data_type", "uint8"), "hull/0"),
])
def test_array_metadata_that_lies(store, capsys, array, change, match):
    _edit(_meta(store, array), change)
    _refused(store, capsys, match)


@pytest.mark.parametrize("array", ["wavelet/detail/1/HLL", "wavelet/detail/2/HHH",
                                   "wavelet/coarse/3", "wavelet/hull/1"])
def test_missing_array(store, capsys, array):
    _meta(store, array).unlink()
    _refused(store, capsys, array.rsplit("/", 1)[0])


# coarse/3 is the coarsest level (rendering reads it; the finer coarse levels are redundant).
@pytest.mark.parametrize("array", ["wavelet/detail/1/HLH", "wavelet/coarse/3", "wavelet/hull/0"])
@pytest.mark.parametrize("damage", ["truncate", "missing", "empty", "bomb", "bomb-undeclared",
                                    "bomb-lying", "junk", "folder", "outside"])
def test_damaged_chunk(store, capsys, array, damage):
    target = _chunk(store, array)
    data = target.read_bytes()
    if damage == "truncate":
        target.write_bytes(data[: len(data) // 2])
    elif damage == "missing":
        target.unlink()
    elif damage == "empty":
        target.write_bytes(b"")
    elif damage == "bomb":  # a zstd frame that declares 2^40 bytes of content
        target.write_bytes(b"\x28\xb5\x2f\xfd\xe0" + struct.pack("<Q", 2**40) + b"\x01\x00\x00")
    elif damage == "bomb-undeclared":  # a gibibyte of RLE blocks, no content size declared
        target.write_bytes(zstd_rle(1 << 30, declare=False))
    elif damage == "bomb-lying":  # declares the chunk's own size, holds a gibibyte
        doc = json.loads(_meta(store, array).read_text())
        size = int(np.prod(doc["chunk_grid"]["configuration"]["chunk_shape"]))
        size *= np.dtype(doc["data_type"]).itemsize
        target.write_bytes(zstd_rle(1 << 30, declare=size))
    elif damage == "junk":
        target.write_bytes(bytes(range(256)) * 4)
    elif damage == "folder":
        target.unlink()
        target.mkdir()
    else:
        outside = store.parent / "elsewhere.bin"
        outside.write_bytes(data)
        target.unlink()
        os.symlink(outside, target)
    _refused(store, capsys)


def test_the_api_raises_read_errors_naming_the_store(store):
    target = _chunk(store, "wavelet/detail/1/HHL")
    target.write_bytes(target.read_bytes()[:10])
    wv = sc.read(store)  # opening reads metadata and tables only
    with pytest.raises(sc.ReadError, match="w.zarr"):
        wv.load()
    scene = sc.Scene(wv, lod=0.0)
    camera = sc.Camera.orbit(wv, size=(12, 12))
    with pytest.raises(sc.ReadError, match="HHL"):
        scene.render(camera, iso=0.0)


def test_memory_guard_refuses_details_larger_than_the_cap(store, monkeypatch, capsys):
    # Enough for the 12x12 image (13.5 KiB), not for the level-1 details (37 KiB).
    monkeypatch.setenv("SPLINECAST_MAX_BYTES", "20KiB")
    _refused(store, capsys, "SPLINECAST_MAX_BYTES")
