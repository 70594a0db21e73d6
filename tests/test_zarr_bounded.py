"""Every chunk decode of a Zarr store is bounded by the chunk's own size, for every codec the
reader accepts; a failure never poisons later reads; the command line prints one line.

References, all independent of the reader under test:

- zarr-python itself, reading the intact arrays it wrote with each accepted codec (the reader
  must give the same voxels, missing chunks as the fill value);
- hostile chunks built by hand from the formats' specifications (:mod:`fuzz.codecs`): zstd
  frames of RLE blocks that inflate to a gibibyte from 32 KiB, with or without a declared
  content size, blosc headers that lie, deflate/bz2/lzma bombs, shard indexes pointing
  anywhere;
- the peak resident memory of a child process (``ru_maxrss``) reading such a store, against
  the same child reading the intact store;
- the real command line in a subprocess: exit status, stderr line count, no output file.
"""

from __future__ import annotations

import bz2
import json
import lzma
import struct
import subprocess
import sys
import textwrap
import threading
from pathlib import Path

import numpy as np
import pytest

import splinecast as sc
from splinecast.errors import ReadError

zarr = pytest.importorskip("zarr")

from fuzz.codecs import (  # noqa: E402
    blosc_set,
    deflate_bomb,
    join_shard,
    shard_layout,
    split_shard,
    zstd_rle,
)
from zarr.codecs import (  # noqa: E402
    BloscCodec,
    BytesCodec,
    Crc32cCodec,
    GzipCodec,
    ShardingCodec,
    TransposeCodec,
    ZstdCodec,
)

GIB = 1 << 30
SHAPE = (10, 9, 8)  # z, y, x as stored; chunks of 4 leave partial edge chunks


def values(dtype="uint16") -> np.ndarray:
    return (np.arange(np.prod(SHAPE)).reshape(SHAPE) % 251).astype(dtype)


def _image(root, path: Path) -> Path:
    root.attrs.update({"multiscales": [{
        "version": "0.4", "axes": [{"name": a, "type": "space"} for a in "zyx"],
        "datasets": [{"path": "0", "coordinateTransformations": [
            {"type": "scale", "scale": [1.0, 1.0, 1.0]}]}]}]})
    return path


def v2_image(path: Path, compressor, dtype="uint16", order="C", fill=0,
             skip_first=False) -> Path:
    """An OME-Zarr 0.4 image (Zarr v2) with one level, as ome-zarr-py writes it."""
    root = zarr.open_group(str(path), mode="w", zarr_format=2)
    arr = root.create_array("0", shape=SHAPE, dtype=dtype, chunks=(4, 4, 4),
                            compressors=compressor, order=order, fill_value=fill,
                            chunk_key_encoding={"name": "v2", "separator": "/"})
    data = values(dtype)
    arr[...] = data
    if skip_first:
        (path / "0" / "0" / "0" / "0").unlink()
    return _image(root, path)


def v3_image(path: Path, **codecs) -> Path:
    """An OME-Zarr-like image (Zarr v3) with one level and the given codecs."""
    root = zarr.open_group(str(path), mode="w", zarr_format=3)
    dtype = codecs.pop("dtype", "uint16")
    arr = root.create_array("0", shape=SHAPE, dtype=dtype, chunks=codecs.pop("chunks", (4, 4, 4)),
                            **codecs)
    arr[...] = values(dtype)
    return _image(root, path)


def level_voxels(path: Path, **kw) -> np.ndarray:
    level = sc.read(path, **kw).levels[0]
    return level.read((0, 0, 0), level.shape)


def chunk_files(array: Path) -> list[Path]:
    return sorted(p for p in array.rglob("*") if p.is_file()
                  and p.name not in ("zarr.json", ".zarray", ".zattrs", ".zgroup"))


# --------------------------------------------------------------------------- round trips
import numcodecs  # noqa: E402

V2_CODECS = {
    "blosc-lz4": numcodecs.Blosc(cname="lz4", shuffle=numcodecs.Blosc.SHUFFLE),
    "blosc-zstd-bit": numcodecs.Blosc(cname="zstd", shuffle=numcodecs.Blosc.BITSHUFFLE,
                                      blocksize=256),
    "zstd": numcodecs.Zstd(level=3), "zlib": numcodecs.Zlib(level=6),
    "gzip": numcodecs.GZip(level=6), "lz4": numcodecs.LZ4(), "bz2": numcodecs.BZ2(level=9),
    "lzma": numcodecs.LZMA(preset=9), "none": None,
}


@pytest.mark.parametrize("name", sorted(V2_CODECS))
@pytest.mark.parametrize("layout", [("uint16", "C"), (">i2", "F"), ("<f4", "C")])
def test_v2_codecs_read_as_zarr_reads_them(tmp_path, name, layout):
    dtype, order = layout
    path = v2_image(tmp_path / "v.zarr", V2_CODECS[name], dtype, order, skip_first=True)
    reference = np.asarray(zarr.open_array(str(path / "0"), mode="r")[...])
    assert reference[0, 0, 0] == 0  # the missing chunk reads as the fill value
    got = level_voxels(path)
    np.testing.assert_array_equal(got, reference.transpose(2, 1, 0))
    assert got.dtype == reference.dtype


V3_CODECS = {
    "default": {},
    "big-endian-transpose-gzip-crc": dict(
        serializer=BytesCodec(endian="big"), filters=[TransposeCodec(order=(2, 0, 1))],
        compressors=[GzipCodec(level=5), Crc32cCodec()]),
    "zstd-checksum": dict(compressors=ZstdCodec(level=5, checksum=True)),
    "blosc": dict(compressors=BloscCodec(cname="lz4", clevel=5, shuffle="bitshuffle")),
    "sharded": dict(shards=(8, 8, 8), compressors=BloscCodec(cname="zstd")),
    "sharded-index-start": dict(serializer=ShardingCodec(
        chunk_shape=(4, 4, 4), codecs=[BytesCodec(), ZstdCodec()], index_location="start"),
        chunks=(8, 8, 8), compressors=None),
    "float-fill": dict(dtype="float32", fill_value=float("nan"), compressors=ZstdCodec()),
}


@pytest.mark.parametrize("name", sorted(V3_CODECS))
def test_v3_codecs_read_as_zarr_reads_them(tmp_path, name):
    path = v3_image(tmp_path / "v.zarr", **dict(V3_CODECS[name]))
    reference = np.asarray(zarr.open_array(str(path / "0"), mode="r")[...])
    for box in [((0, 0, 0), (8, 9, 10)), ((3, 1, 2), (7, 9, 5)), ((7, 8, 9), (8, 9, 10))]:
        lo, hi = box
        level = sc.read(path).levels[0]
        np.testing.assert_array_equal(
            level.read(lo, hi), reference.transpose(2, 1, 0)[lo[0]:hi[0], lo[1]:hi[1],
                                                             lo[2]:hi[2]])


@pytest.mark.parametrize("compressors, expected", [
    ([numcodecs.Delta(dtype="u2")], r"v.zarr/0: filters \['delta'\] are not supported"),
])
def test_v2_filters_are_refused_on_opening(tmp_path, compressors, expected):
    root = zarr.open_group(str(tmp_path / "v.zarr"), mode="w", zarr_format=2)
    arr = root.create_array("0", shape=SHAPE, dtype="u2", chunks=(4, 4, 4),
                            filters=compressors)
    arr[...] = values()
    _image(root, tmp_path / "v.zarr")
    with pytest.raises(ReadError, match=expected):
        sc.read(tmp_path / "v.zarr")


def test_an_unbounded_v3_codec_is_refused_on_opening(tmp_path):
    import warnings

    from zarr.codecs.numcodecs import Shuffle

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        path = v3_image(tmp_path / "v.zarr", compressors=[Shuffle(elementsize=2), ZstdCodec()])
    with pytest.raises(ReadError, match=r"v.zarr/0: codec 'numcodecs.shuffle' is not supported"):
        sc.read(path)


# --------------------------------------------------------------------------- hostile chunks
CHUNK_BYTES = 4 * 4 * 4 * 2  # one uint16 chunk of the images above


def hostile_v2(tmp_path: Path, compressor, payload: bytes) -> tuple[Path, Path]:
    path = v2_image(tmp_path / "v.zarr", compressor)
    chunk = path / "0" / "0" / "0" / "0"
    chunk.write_bytes(payload)
    return path, chunk


def hostile_v3(tmp_path: Path, payload: bytes, **codecs) -> tuple[Path, Path]:
    path = v3_image(tmp_path / "v.zarr", **codecs)
    chunk = path / "0" / "c" / "0" / "0" / "0"
    chunk.write_bytes(payload)
    return path, chunk


def _lzma_alone(dictionary: int) -> bytes:
    """128 zero bytes in the legacy .lzma format, its header asking for a ``dictionary``-byte
    dictionary (the header has no checksum: the decoder allocates what it says)."""
    data = bytearray(lzma.compress(bytes(128), format=lzma.FORMAT_ALONE))
    data[1:5] = struct.pack("<I", dictionary)
    return bytes(data)


def _blosc_chunk(tmp_path: Path) -> bytes:
    path = v2_image(tmp_path / "ref.zarr", numcodecs.Blosc())
    return (path / "0" / "0" / "0" / "0").read_bytes()


HOSTILE = {
    # name: (how the store is made, what the one line says)
    "zstd-declared-bomb": (lambda t: hostile_v3(t, zstd_rle(GIB), compressors=ZstdCodec()),
                           f"the zstd data declares {GIB} bytes, the chunk holds 128"),
    "zstd-undeclared-bomb": (lambda t: hostile_v3(t, zstd_rle(GIB, declare=False),
                                                  compressors=ZstdCodec()),
                             "(no content size declared) inflates beyond the chunk's 128 bytes"),
    "zstd-lying-size": (lambda t: hostile_v3(t, zstd_rle(GIB, declare=128),
                                             compressors=ZstdCodec()), "corrupt zstd data"),
    "zstd-two-frames": (lambda t: hostile_v3(t, zstd_rle(64) + zstd_rle(GIB, declare=False),
                                             compressors=ZstdCodec()),
                        "inflates beyond the chunk's 128 bytes"),
    "v2-zstd-bomb": (lambda t: hostile_v2(t, numcodecs.Zstd(), zstd_rle(GIB, declare=False)),
                     "inflates beyond the chunk's 128 bytes"),
    "blosc-nbytes": (lambda t: hostile_v2(t, numcodecs.Blosc(),
                                          blosc_set(_blosc_chunk(t), nbytes=2**31 - 1)),
                     "the blosc header gives 2147483647 bytes, the chunk holds 128"),
    "blosc-blocksize": (lambda t: hostile_v2(t, numcodecs.Blosc(),
                                             blosc_set(_blosc_chunk(t), blocksize=2**31)),
                        "the blosc header gives a block of 2147483648 bytes for 128"),
    "blosc-cbytes": (lambda t: hostile_v2(t, numcodecs.Blosc(),
                                          blosc_set(_blosc_chunk(t), cbytes=2**20)),
                     "compressed bytes, the chunk has"),
    "gzip-bomb": (lambda t: hostile_v3(t, deflate_bomb(32 << 20, gzip=True),
                                       compressors=GzipCodec()),
                  "the deflate stream inflates beyond the chunk's 128 bytes"),
    "zlib-bomb": (lambda t: hostile_v2(t, numcodecs.Zlib(), deflate_bomb(32 << 20)),
                  "the deflate stream inflates beyond the chunk's 128 bytes"),
    "bz2-bomb": (lambda t: hostile_v2(t, numcodecs.BZ2(), bz2.compress(bytes(64 << 20))),
                 "the bz2 stream inflates beyond the chunk's 128 bytes"),
    "lzma-bomb": (lambda t: hostile_v2(t, numcodecs.LZMA(), lzma.compress(bytes(16 << 20))),
                  "the lzma stream inflates beyond the chunk's 128 bytes"),
    "lzma-dictionary": (lambda t: hostile_v2(t, numcodecs.LZMA(), _lzma_alone(1 << 30)),
                        "Memory usage limit"),
    "lz4-header": (lambda t: hostile_v2(t, numcodecs.LZ4(), struct.pack("<i", 2**31 - 1)
                                        + bytes(12)),
                   "the lz4 header gives 2147483647 bytes, the chunk holds 128"),
    "crc32c": (lambda t: hostile_v3(t, bytes(CHUNK_BYTES) + b"\1\2\3\4",
                                    compressors=Crc32cCodec()), "crc32c checksum mismatch"),
}


@pytest.mark.parametrize("name", sorted(HOSTILE))
def test_a_hostile_chunk_is_one_error_naming_it(tmp_path, name):
    make, needle = HOSTILE[name]
    path, chunk = make(tmp_path)
    with pytest.raises(ReadError) as info:
        level_voxels(path)
    message = str(info.value)
    assert "chunk (0, 0, 0) (x, y, z) cannot be read" in message, message
    assert str(chunk) in message and needle in message, message
    assert len(message.splitlines()) == 1


def _sharded(tmp_path: Path) -> tuple[Path, Path, dict, list]:
    path = v3_image(tmp_path / "v.zarr", shards=(8, 8, 8), compressors=ZstdCodec())
    shard = path / "0" / "c" / "0" / "0" / "0"
    layout = shard_layout(json.loads((path / "0" / "zarr.json").read_text()))
    chunks = split_shard(shard.read_bytes(), layout["count"], layout["at_end"],
                         layout["checksum"])
    return path, shard, layout, chunks


@pytest.mark.parametrize("damage, needle", [
    ("inner-bomb", "inflates beyond the chunk's 128 bytes"),
    ("offset-past-end", "the shard index points to bytes"),
    ("huge-length", "the shard index points to 18446744073709551614 bytes"),
    ("wrapping", "the shard index points to"),
    ("checksum", "the shard index fails its crc32c checksum"),
    ("short", "less than its index"),
])
def test_a_hostile_shard_is_refused_before_decoding(tmp_path, damage, needle):
    path, shard, layout, chunks = _sharded(tmp_path)
    size = len(shard.read_bytes())
    if damage == "inner-bomb":
        chunks[0] = zstd_rle(GIB, declare=False)
        data = join_shard(chunks)
    elif damage == "offset-past-end":
        data = join_shard(chunks, entries={0: (size * 4, 10)})
    elif damage == "huge-length":
        data = join_shard(chunks, entries={0: (0, 2**64 - 2)})
    elif damage == "wrapping":  # offset + length wraps around 2^64 to a small number
        data = join_shard(chunks, entries={0: (2**64 - 8, 16)})
    elif damage == "checksum":
        data = bytearray(shard.read_bytes())
        data[-8] ^= 1
        data = bytes(data)
    else:
        data = shard.read_bytes()[:100]
    shard.write_bytes(data)
    with pytest.raises(ReadError) as info:
        level_voxels(path)
    message = str(info.value)
    assert str(shard) in message and needle in message, message
    assert "(0, 0, 0) (x, y, z) cannot be read" in message, message


# --------------------------------------------------------------------------- peak memory
_CHILD = textwrap.dedent("""
    import resource, sys
    import splinecast as sc
    level = sc.read(sys.argv[1]).levels[0]
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    try:
        level.read((0, 0, 0), level.shape)
        print("read", before, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
    except sc.ReadError as exc:
        print("refused", before, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
""")


def _peak_kib(path: Path) -> tuple[str, int, int]:
    proc = subprocess.run([sys.executable, "-c", _CHILD, str(path)], capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    what, before, after = proc.stdout.split()
    return what, int(before), int(after)


def _every_chunk(path: Path, payload: bytes) -> None:
    for chunk in chunk_files(path / "0"):
        chunk.write_bytes(payload)


@pytest.mark.parametrize("bomb", ["zstd-undeclared", "zstd-declared", "shard"])
def test_peak_memory_of_a_bomb_store_stays_near_the_intact_one(tmp_path, bomb):
    """Every chunk of the store a gibibyte once inflated: the read's peak resident memory
    grows by less than 64 MiB over the same read of the intact store (whose chunks hold
    128 bytes each), where zarr's own decoders took gigabytes."""
    if bomb == "shard":
        good = v3_image(tmp_path / "good.zarr", shards=(8, 8, 8), compressors=ZstdCodec())
        bad = v3_image(tmp_path / "bad.zarr", shards=(8, 8, 8), compressors=ZstdCodec())
        layout = shard_layout(json.loads((bad / "0" / "zarr.json").read_text()))
        for shard in chunk_files(bad / "0"):
            inner = split_shard(shard.read_bytes(), layout["count"])
            shard.write_bytes(join_shard([None if c is None else zstd_rle(GIB, declare=False)
                                          for c in inner]))
    else:
        good = v3_image(tmp_path / "good.zarr", compressors=ZstdCodec())
        bad = v3_image(tmp_path / "bad.zarr", compressors=ZstdCodec())
        _every_chunk(bad, zstd_rle(GIB, declare=bomb == "zstd-declared"))
    what_good, _, peak_good = _peak_kib(good)
    what_bad, before, peak_bad = _peak_kib(bad)
    assert (what_good, what_bad) == ("read", "refused")
    assert peak_bad - max(peak_good, before) < 64 * 1024, (peak_good, before, peak_bad)


# --------------------------------------------------------------------------- no poisoning
def test_a_failure_never_poisons_later_reads(tmp_path):
    """A blosc chunk with a huge block size fails; every other chunk still reads, again and
    again, from the same level and from threads reading at once."""
    path = v2_image(tmp_path / "v.zarr", numcodecs.Blosc())
    chunk = path / "0" / "0" / "0" / "0"
    chunk.write_bytes(blosc_set(chunk.read_bytes(), blocksize=2**31))
    level = sc.read(path).levels[0]
    expected = values().transpose(2, 1, 0)
    errors: list[str] = []
    good: list[bool] = []

    def work() -> None:
        for _ in range(5):
            try:
                level.read((0, 0, 0), (4, 4, 4))
            except ReadError as exc:
                errors.append(str(exc))
            good.append(np.array_equal(level.read((4, 4, 4), (8, 9, 10)),
                                       expected[4:8, 4:9, 4:10]))

    threads = [threading.Thread(target=work) for _ in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(errors) == 15 and all("block of 2147483648 bytes" in e for e in errors)
    assert good == [True] * 15


# --------------------------------------------------------------------------- the command line
def _cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "splinecast.cli", *args], capture_output=True,
                          text=True, timeout=900, cwd=cwd)


def _lines(text: str) -> list[str]:
    return [line for line in text.splitlines() if line.strip()]


def test_the_cli_prints_one_line_for_members_refused_at_once(tmp_path):
    """A group whose six arrays' metadata all lead out of the store: zarr reads them at once
    and only the first refusal is reported; the others are no noise, before or after (shown
    with --verbose)."""
    store = tmp_path / "v.zarr"
    root = zarr.open_group(str(store), mode="w", zarr_format=2)
    outside = tmp_path / "outside"
    outside.mkdir()
    for k in range(6):
        root.create_array(str(k), shape=(4, 4, 4), dtype="u2", chunks=(4, 4, 4))[...] = 1
        meta = store / str(k) / ".zarray"
        (outside / str(k)).write_bytes(meta.read_bytes())
        meta.unlink()
        meta.symlink_to(outside / str(k))
    proc = _cli("info", str(store), cwd=tmp_path)
    lines = _lines(proc.stderr)
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert "lies outside the store's folder" in lines[0] and not proc.stdout
    # --verbose adds what was captured (the other refusals, when zarr's tasks had ended with
    # them before the first was reported), indented after the one line.
    verbose = _cli("info", str(store), "--verbose", cwd=tmp_path)
    more = _lines(verbose.stderr)
    # (which member's refusal comes first depends on which of zarr's reads ends first)
    assert verbose.returncode == 2 and "lies outside the store's folder" in more[0], \
        verbose.stderr
    assert not more[0].startswith(" "), verbose.stderr
    assert all(line.startswith("  ") for line in more[1:]), verbose.stderr


def _pyramid_with_bomb(tmp_path: Path) -> tuple[Path, list[Path]]:
    """splinecast's pyramid of a sphere whose every level-0 chunk is a gibibyte bomb (the
    shard indexes kept valid): no level-0 brick can be read."""
    from splinecast.multires.store.pyramid import build_pyramid

    i, j, k = np.indices((16, 16, 16))
    data = (np.sqrt((i - 7.5) ** 2 + (j - 7.5) ** 2 + (k - 7.5) ** 2) * 10).astype(np.uint16)
    path = tmp_path / "p.zarr"
    build_pyramid(sc.Volume(data), path, brick=4, workers=1, progress=False)
    layout = shard_layout(json.loads((path / "0" / "zarr.json").read_text()))
    shards = chunk_files(path / "0")
    for shard in shards:
        inner = split_shard(shard.read_bytes(), layout["count"], layout["at_end"],
                            layout["checksum"])
        shard.write_bytes(join_shard([None if c is None else zstd_rle(GIB, declare=False)
                                      for c in inner], layout["at_end"], layout["checksum"]))
    return path, shards


def test_a_still_image_with_an_unreadable_brick(tmp_path):
    from splinecast.multires.store.cache import BrickUnavailableWarning

    """render: exit 2 with one line naming the chunk and no image; with --allow-missing the
    image is written and the last line says it is incomplete; the API's frame says so too."""
    path, shards = _pyramid_with_bomb(tmp_path)
    shard = str(shards[0].parent.parent.parent.parent)  # the level's folder: 0/c/i/j/k
    args = ["render", str(path), "-o", "out.png", "--size", "16x16", "--iso", "40", "--quiet",
            "--lod", "0.01"]
    proc = _cli(*args, cwd=tmp_path)
    lines = _lines(proc.stderr)
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert lines[0].startswith("splinecast: error: ") and shard in lines[0]
    assert "inflates beyond" in lines[0] and not (tmp_path / "out.png").exists()
    proc = _cli(*args, "--allow-missing", cwd=tmp_path)
    lines = _lines(proc.stderr)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "out.png").is_file()
    assert lines[-1].startswith("splinecast: warning: out.png is incomplete: ")
    assert "drawn from a coarser level" in lines[-1] and shard in lines[-1]

    volume = sc.read(path)
    camera = sc.Camera.orbit(volume, size=(16, 16), zoom=1.0)
    with sc.Scene(volume, lod=0.01) as scene:
        with pytest.warns(BrickUnavailableWarning, match="inflates beyond"):
            frame = scene.render(camera, iso=40, complete=True)
        assert frame.stats["unreadable"] > 0 and not frame.stats["complete"]
        assert shard in frame.stats["unreadable_reason"]
        with pytest.raises(ReadError, match="inflates beyond"):
            scene.render(camera, iso=40, complete=True, missing="error")


def test_allow_missing_applies_to_pyramids_only(tmp_path):
    np.save(tmp_path / "v.npy", values().astype(np.float32))
    proc = _cli("render", "v.npy", "-o", "o.png", "--size", "8x8", "--allow-missing", "--quiet",
                cwd=tmp_path)
    assert proc.returncode == 2 and "--allow-missing applies to multiscale" in proc.stderr
    assert len(_lines(proc.stderr)) == 1 and not (tmp_path / "o.png").exists()



def test_the_zstd_walker_agrees_with_libzstd():
    """Declared sizes summed over frames (skippable frames count nothing) as libzstd decodes
    them; a frame without a size makes the sum unknown; broken structure is refused."""
    from numcodecs import zstd

    from splinecast.io.zarr_chunks import zstd_content_size

    a, b = bytes(range(256)) * 3, b"xyz" * 1000
    one, two = zstd.compress(a), zstd.compress(b)
    skippable = struct.pack("<II", 0x184D2A50, 5) + b"12345"
    assert zstd_content_size(one) == len(a) == len(zstd.decompress(one))
    both = skippable + one + two
    assert zstd_content_size(both) == len(a) + len(b) == len(zstd.decompress(both))
    assert zstd_content_size(one + zstd_rle(1000, declare=False)) is None
    assert zstd_content_size(zstd_rle(GIB)) == GIB
    for broken in (one[:-3], one + b"junk", b"\x28\xb5\x2f\xfd\x08", skippable[:6]):
        with pytest.raises(ValueError):
            zstd_content_size(broken)
