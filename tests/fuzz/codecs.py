"""Chunk bytes built and taken apart by hand: zstd frames (with or without a declared content
size, compression bombs of any size in a few kilobytes), blosc headers, Zarr v3 shard indexes.

Written from the formats' specifications (RFC 8878 for zstd, the blosc 1 header, the Zarr v3
``sharding_indexed`` codec), independently of the reader under test: the tests and the fuzzing
mutations build hostile chunks with them, and the reader must refuse them by itself.
"""

from __future__ import annotations

import json
import math
import struct
import zlib
from pathlib import Path

ZSTD_MAGIC = b"\x28\xb5\x2f\xfd"
#: The largest block a zstd frame may hold (and an RLE block regenerate): 128 KiB.
ZSTD_BLOCK = 1 << 17
EMPTY = (1 << 64) - 1


def crc32c(data: bytes) -> int:
    import google_crc32c

    return google_crc32c.value(bytes(data))


def zstd_rle(total: int, declare: bool | int = True, value: int = 7,
             checksum: bool = False) -> bytes:
    """A zstd frame that inflates to ``total`` bytes of ``value`` from RLE blocks (4 bytes per
    128 KiB: a gibibyte in 32 KiB). ``declare``: write the content size (``True``), leave it out
    (``False``), or declare this other number (a lie)."""
    if declare is False:
        header = ZSTD_MAGIC + bytes([0x04 if checksum else 0x00, 0x38])  # window 128 KiB
    else:
        size = total if declare is True else int(declare)
        header = ZSTD_MAGIC + bytes([0xC4 if checksum else 0xC0, 0x38]) + struct.pack("<Q", size)
    blocks = bytearray(header)
    count = max(1, -(-total // ZSTD_BLOCK))
    for n in range(count):
        size = min(ZSTD_BLOCK, total - n * ZSTD_BLOCK)
        word = (1 if n == count - 1 else 0) | (1 << 1) | (size << 3)
        blocks += word.to_bytes(3, "little") + bytes([value])
    if checksum:
        blocks += b"\0\0\0\0"  # wrong on purpose for anything but the empty frame
    return bytes(blocks)


def zstd_frame_info(data: bytes) -> dict | None:
    """Where the header fields of the first zstd frame in ``data`` are: ``descriptor`` offset,
    ``fcs`` (offset, width) of the content size, or None if ``data`` is not a zstd frame."""
    if not data.startswith(ZSTD_MAGIC) or len(data) < 6:
        return None
    descriptor = data[4]
    single = (descriptor >> 5) & 1
    did = (0, 1, 2, 4)[descriptor & 3]
    width = (1 if single else 0, 2, 4, 8)[descriptor >> 6]
    at = 5 + (0 if single else 1) + did
    return {"descriptor": 4, "fcs": (at, width), "single": bool(single)}


def zstd_without_size(data: bytes) -> bytes | None:
    """The same frame with its content-size field removed (the flag cleared): a frame a
    streaming encoder writes. None if the frame is single-segment (it then needs the size)."""
    info = zstd_frame_info(data)
    if info is None or info["single"] or info["fcs"][1] == 0:
        return None
    at, width = info["fcs"]
    descriptor = data[4] & 0x3F
    return data[:4] + bytes([descriptor]) + data[5:at] + data[at + width:]


def zstd_with_size(data: bytes, size: int) -> bytes | None:
    """The same frame declaring ``size`` bytes of content (8-byte field)."""
    info = zstd_frame_info(data)
    if info is None:
        return None
    at, width = info["fcs"]
    descriptor = (data[4] & 0x3F) | 0xC0
    return data[:4] + bytes([descriptor]) + data[5:at] + struct.pack("<Q", size % 2**64) + \
        data[at + width:]


def deflate_bomb(total: int, gzip: bool = False) -> bytes:
    """A zlib (or gzip) stream of ``total`` zero bytes, compressed piece by piece (about a
    thousandth of ``total``), without ever holding ``total`` bytes."""
    encoder = zlib.compressobj(9, zlib.DEFLATED, 31 if gzip else 15)
    piece = bytes(1 << 20)
    out = []
    left = total
    while left > 0:
        out.append(encoder.compress(piece[:min(left, len(piece))]))
        left -= len(piece)
    out.append(encoder.flush())
    return b"".join(out)


# --------------------------------------------------------------------------- blosc
BLOSC_FIELDS = {"version": (0, "B"), "versionlz": (1, "B"), "flags": (2, "B"),
                "typesize": (3, "B"), "nbytes": (4, "<I"), "blocksize": (8, "<I"),
                "cbytes": (12, "<I")}


def is_blosc(data: bytes) -> bool:
    return len(data) >= 16 and data[0] in (1, 2) and \
        struct.unpack("<I", data[12:16])[0] == len(data)


def blosc_set(data: bytes, **fields: int) -> bytes:
    """``data`` with blosc header fields (``nbytes=...``, ``blocksize=...``) replaced."""
    out = bytearray(data)
    for name, value in fields.items():
        at, fmt = BLOSC_FIELDS[name]
        width = struct.calcsize(fmt)
        out[at:at + width] = struct.pack(fmt, value % 2 ** (8 * width))
    return bytes(out)


def blosc_memcpy(payload: bytes, nbytes: int | None = None, typesize: int = 2) -> bytes:
    """A blosc chunk storing ``payload`` uncompressed (the memcpyed flag), its header claiming
    ``nbytes`` (default: the truth)."""
    n = len(payload) if nbytes is None else nbytes
    header = struct.pack("<BBBBIII", 2, 1, 0x02 | 0x01, typesize, n, n, len(payload) + 16)
    return header + payload


# --------------------------------------------------------------------------- shards
def shard_layout(meta: dict) -> dict | None:
    """What a Zarr v3 array's ``zarr.json`` says about its shards: inner chunks per shard,
    inner codecs, index location and checksum; None if not sharded."""
    codecs = meta.get("codecs") or []
    for codec in codecs:
        if isinstance(codec, dict) and codec.get("name") == "sharding_indexed":
            config = codec.get("configuration", {})
            outer = meta["chunk_grid"]["configuration"]["chunk_shape"]
            inner = config["chunk_shape"]
            index = [c.get("name") if isinstance(c, dict) else c
                     for c in config.get("index_codecs", [])]
            return {"count": math.prod(o // i for o, i in zip(outer, inner, strict=True)),
                    "inner": inner, "codecs": config.get("codecs", []),
                    "at_end": config.get("index_location", "end") == "end",
                    "checksum": "crc32c" in index}
    return None


def split_shard(data: bytes, count: int, at_end: bool = True,
                checksum: bool = True) -> list[bytes | None]:
    """The inner chunks of a shard (None for empty entries), in the index's order."""
    size = 16 * count + (4 if checksum else 0)
    index = data[-size:] if at_end else data[:size]
    chunks: list[bytes | None] = []
    for n in range(count):
        offset, length = struct.unpack("<QQ", index[16 * n:16 * n + 16])
        chunks.append(None if offset == EMPTY else data[offset:offset + length])
    return chunks


def join_shard(chunks: list[bytes | None], at_end: bool = True, checksum: bool = True,
               entries: dict[int, tuple[int, int]] | None = None) -> bytes:
    """A shard holding ``chunks`` (None: empty), its index valid (crc32c recomputed) unless
    ``entries`` overrides some of its (offset, length) pairs afterwards."""
    size = 16 * len(chunks) + (4 if checksum else 0)
    body = bytearray()
    start = 0 if at_end else size
    pairs = []
    for chunk in chunks:
        if chunk is None:
            pairs.append((EMPTY, EMPTY))
        else:
            pairs.append((start + len(body), len(chunk)))
            body += chunk
    for n, pair in (entries or {}).items():
        pairs[n] = pair
    index = b"".join(struct.pack("<QQ", o % 2**64, n % 2**64) for o, n in pairs)
    if checksum:
        index += struct.pack("<I", crc32c(index))
    return bytes(body) + index if at_end else index + bytes(body)


def array_meta(chunk: Path) -> dict | None:
    """The ``zarr.json`` or ``.zarray`` of the array a chunk file belongs to (nearest above)."""
    for parent in chunk.parents:
        for name in ("zarr.json", ".zarray"):
            meta = parent / name
            if meta.is_file():
                try:
                    doc = json.loads(meta.read_text())
                except ValueError:
                    return None
                if isinstance(doc, dict) and (doc.get("node_type") == "array" or name == ".zarray"):
                    return doc
                return None
    return None
