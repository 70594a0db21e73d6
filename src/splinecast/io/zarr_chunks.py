"""Reading Zarr chunks with every decode bounded by the chunk's own size.

zarr-python decodes a chunk with each codec's own allocation and checks the result afterwards: a
zstd frame without a declared content size grows its buffer until the data ends, a blosc header's
``nbytes`` is allocated as given, a shard index may point anywhere. A chunk of a few kilobytes
can so claim gigabytes before any check runs. Here the bytes of a chunk are read from the store
and decoded by splinecast itself: every codec decompresses into a buffer of exactly the size the
array's metadata gives the chunk (or, between two compressors, at most the largest size an
encoded chunk may have), and anything that would inflate beyond it is refused with a
:class:`ChunkError` naming the chunk and its file. No decoder is called before its output size is
known and checked, so a read's peak memory is its output plus one chunk, whatever the files
say. The reads run in the calling thread: no event loop, no thread pool.

Accepted codecs (anything else is refused when the array is opened, naming the codec):

- Zarr v3: ``bytes`` (either byte order), ``transpose``, ``sharding_indexed`` (its index encoded
  with ``bytes`` and optionally ``crc32c``, at the start or the end of the shard; inner codecs as
  listed here, not sharded again), ``zstd``, ``blosc``, ``gzip``, ``crc32c``, and zarr-python's
  ``numcodecs.zstd``, ``numcodecs.blosc``, ``numcodecs.zlib``, ``numcodecs.gzip``,
  ``numcodecs.lz4``, ``numcodecs.bz2``, ``numcodecs.lzma``;
- Zarr v2: no filters; the compressor ``zstd``, ``blosc``, ``zlib``, ``gzip``, ``lz4``, ``bz2``,
  ``lzma`` or none; C or Fortran order.

How each one is bounded: zstd frames are walked first (:func:`zstd_content_size`), a declared
size must equal the chunk's and a frame without one decodes into the chunk's buffer, which it
may not overflow; a blosc header (:func:`blosc_sizes`) must give the chunk's size, a block no
larger and the chunk's exact compressed length before blosc reads it; lz4 (numcodecs' framing)
must give the chunk's size in its header; zlib, gzip, bz2 and lzma streams are inflated with an
output cap of one byte more than the chunk (lzma also under :data:`LZMA_MEMLIMIT`); a shard
index must be intact (checksum), and each entry must lie inside the shard's data and be no
larger than an encoded inner chunk can be.
"""

from __future__ import annotations

import math
import os
import stat
import struct
import threading
from collections import OrderedDict
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ReadError, limits

__all__ = [
    "ChunkError",
    "ChunkReader",
    "CODECS_V2",
    "CODECS_V3",
    "FileSource",
    "LZMA_MEMLIMIT",
    "blosc_sizes",
    "max_encoded_bytes",
    "zstd_content_size",
]

#: Compressors of Zarr v2 metadata (``compressor.id``) this reader decodes.
CODECS_V2 = ("zstd", "blosc", "zlib", "gzip", "lz4", "bz2", "lzma")
#: Codecs of Zarr v3 metadata this reader decodes.
CODECS_V3 = ("bytes", "transpose", "sharding_indexed", "zstd", "blosc", "gzip", "crc32c",
             *(f"numcodecs.{name}" for name in CODECS_V2))
#: Most memory an lzma stream's decoder may take (its dictionary): enough for every preset of
#: the xz format (``9e`` takes 65 MiB); a header asking for more is refused.
LZMA_MEMLIMIT = 80 << 20
#: An empty entry of a shard index (offset and length both 2^64 - 1).
_EMPTY = (1 << 64) - 1
#: Parsed shard indexes kept per reader (a brick read touches one shard many times): at most
#: this many, and this many bytes. A view's bricks are read centre first, in rings that cross
#: every shard of the view again and again: the cache holds a whole level's worth (a 1024^3
#: level in 128^3 shards has 512), or over a network each ring fetched the indexes again.
_INDEX_CACHE = 4096
_INDEX_CACHE_BYTES = 16 << 20

_ZSTD_MAGIC = 0xFD2FB528
_ZSTD_SKIPPABLE = 0x184D2A50  # .. 0x184D2A5F


class ChunkError(ReadError):
    """A chunk cannot be read; ``coords`` are its grid indices in the array's axis order
    (of the inner chunk, in a sharded array), ``file`` the file holding it."""

    def __init__(self, label: str, coords: tuple[int, ...], file: Any, reason: str,
                 kind: str = "chunk") -> None:
        self.label = label
        self.coords = tuple(int(c) for c in coords)
        self.file = file
        self.reason = reason
        self.kind = kind
        where = f" (file {file})" if file is not None else ""
        super().__init__(f"{label}: {kind} {self.coords} cannot be read{where}: {reason}")


class _Bad(Exception):
    """A decoder's refusal, before the chunk it belongs to is known (becomes a ChunkError)."""


def max_encoded_bytes(nbytes: int) -> int:
    """The largest size a chunk of ``nbytes`` decoded bytes may have once encoded: twice its
    bytes (incompressible data grows a little in every codec) plus headers."""
    return 2 * int(nbytes) + (1 << 16)


# --------------------------------------------------------------------------- headers
def zstd_content_size(data: bytes | memoryview) -> int | None:
    """The bytes a zstd stream declares it decompresses to: the sum over its frames (skippable
    frames count 0), ``None`` when a frame does not declare its size.

    The frames and their blocks are walked as RFC 8878 lays them out, so a stream whose
    structure is broken (truncated, reserved bits or block types, trailing bytes) is refused
    before any decoder sees it.

    Raises
    ------
    ValueError
        Not a well-formed zstd stream.
    """
    view = memoryview(data).cast("B")
    at, total, known = 0, 0, True
    if len(view) < 4:
        raise ValueError("too short for a zstd frame")
    while at < len(view):
        if len(view) - at < 8 and at:
            raise ValueError(f"{len(view) - at} bytes after the last zstd frame")
        magic = int.from_bytes(view[at:at + 4], "little")
        if magic & 0xFFFFFFF0 == _ZSTD_SKIPPABLE:
            if len(view) - at < 8:
                raise ValueError("truncated skippable frame")
            size = int.from_bytes(view[at + 4:at + 8], "little")
            at += 8 + size
            if at > len(view):
                raise ValueError("truncated skippable frame")
            continue
        if magic != _ZSTD_MAGIC:
            raise ValueError("not a zstd frame" if at == 0 else "junk after a zstd frame")
        if len(view) - at < 6:
            raise ValueError("truncated zstd frame header")
        descriptor = view[at + 4]
        if descriptor & 0x08:
            raise ValueError("reserved bit set in a zstd frame header")
        fcs_flag, single = descriptor >> 6, (descriptor >> 5) & 1
        checksum = (descriptor >> 2) & 1
        did = (0, 1, 2, 4)[descriptor & 3]
        fcs = (1 if single else 0, 2, 4, 8)[fcs_flag]
        at += 5 + (0 if single else 1) + did
        if at + fcs > len(view):
            raise ValueError("truncated zstd frame header")
        if fcs:
            size = int.from_bytes(view[at:at + fcs], "little")
            total += size + 256 if fcs == 2 else size
        else:
            known = False
        at += fcs
        while True:
            if at + 3 > len(view):
                raise ValueError("truncated zstd block")
            header = int.from_bytes(view[at:at + 3], "little")
            last, kind, size = header & 1, (header >> 1) & 3, header >> 3
            if kind == 3:
                raise ValueError("reserved zstd block type")
            at += 3 + (1 if kind == 1 else size)
            if at > len(view):
                raise ValueError("truncated zstd block")
            if last:
                break
        at += 4 * checksum
        if at > len(view):
            raise ValueError("truncated zstd checksum")
    return total if known else None


def blosc_sizes(data: bytes | memoryview) -> tuple[int, int, int, int]:
    """``(typesize, nbytes, blocksize, cbytes)`` of a blosc (version 1 format) header.

    Raises
    ------
    ValueError
        Shorter than a header, or an unknown format version.
    """
    view = memoryview(data).cast("B")
    if len(view) < 16:
        raise ValueError("shorter than a blosc header")
    if view[0] not in (1, 2):
        raise ValueError(f"unknown blosc format version {view[0]}")
    nbytes, blocksize, cbytes = struct.unpack("<III", view[4:16])
    return int(view[3]), nbytes, blocksize, cbytes


# --------------------------------------------------------------------------- decoders
def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    line = text[0] if text else type(exc).__name__
    return limits.shorten(line, 160) if len(line) > 160 else line


def _target(size: int | None, cap: int) -> int:
    return cap if size is None else size


def _checked_length(n: int, size: int | None, cap: int, what: str) -> None:
    """``what`` (``"the blosc header gives"``) ``n`` bytes: exactly ``size``, or at most
    ``cap`` when the size is not known."""
    if size is not None and n != size:
        raise _Bad(f"{what} {n} bytes, the chunk holds {size}")
    if size is None and n > cap:
        raise _Bad(f"{what} {n} bytes, more than an encoded chunk can hold ({cap})")


def _zstd(data: bytes, size: int | None, cap: int) -> bytes | np.ndarray:
    import numcodecs.zstd

    try:
        declared = zstd_content_size(data)
    except ValueError as exc:
        raise _Bad(f"corrupt zstd data ({exc})") from None
    if declared is None and size is None:
        raise _Bad("a zstd frame without its content size inside another codec")
    want = _target(size, cap) if declared is None else declared
    if declared is not None:
        _checked_length(declared, size, cap, "the zstd data declares")
    out = np.empty(want, dtype=np.uint8)
    try:
        numcodecs.zstd.decompress(data, out)
    except (RuntimeError, ValueError) as exc:  # numcodecs' own messages
        if declared is None and "too small" in str(exc):
            raise _Bad(f"the zstd data (no content size declared) inflates beyond the "
                       f"chunk's {want} bytes") from None
        raise _Bad(f"corrupt zstd data ({_first_line(exc)})") from None
    return out


def _blosc(data: bytes, size: int | None, cap: int) -> np.ndarray:
    import numcodecs.blosc

    try:
        typesize, nbytes, blocksize, cbytes = blosc_sizes(data)
    except ValueError as exc:
        raise _Bad(f"corrupt blosc data ({exc})") from None
    if cbytes != len(data):
        raise _Bad(f"the blosc header gives {cbytes} compressed bytes, the chunk has {len(data)}")
    _checked_length(nbytes, size, cap, "the blosc header gives")
    if not 0 < blocksize <= max(nbytes, 1) or typesize < 1:
        raise _Bad(f"the blosc header gives a block of {blocksize} bytes for {nbytes} "
                   f"(type size {typesize})")
    out = np.empty(nbytes, dtype=np.uint8)
    try:
        numcodecs.blosc.decompress(data, out)
    except (RuntimeError, ValueError) as exc:
        raise _Bad(f"corrupt blosc data ({_first_line(exc)})") from None
    return out


def _lz4(data: bytes, size: int | None, cap: int) -> np.ndarray:
    import numcodecs.lz4

    if len(data) < 4:
        raise _Bad("shorter than an lz4 header")
    declared = int.from_bytes(data[:4], "little", signed=True)
    if declared <= 0:
        raise _Bad(f"the lz4 header gives {declared} bytes")
    _checked_length(declared, size, cap, "the lz4 header gives")
    out = np.empty(declared, dtype=np.uint8)
    try:
        numcodecs.lz4.decompress(data, out)
    except (RuntimeError, ValueError) as exc:
        raise _Bad(f"corrupt lz4 data ({_first_line(exc)})") from None
    return out


def _inflate(data: bytes, size: int | None, cap: int) -> bytes:
    """zlib or gzip (one or more members), at most one byte more than the chunk inflated."""
    import zlib

    limit = _target(size, cap)
    decoded: list[bytes] = []
    got = 0
    stream = zlib.decompressobj(15 + 32)  # either header
    todo = data
    try:
        while True:
            more = stream.decompress(todo, limit + 1 - got)
            decoded.append(more)
            got += len(more)
            if got > limit:
                raise _Bad(f"the deflate stream inflates beyond the chunk's {limit} bytes")
            todo = stream.unconsumed_tail
            if stream.eof:
                rest = stream.unused_data
                if not rest:
                    break
                if rest[:2] != b"\x1f\x8b":
                    raise _Bad(f"{len(rest)} bytes after the deflate stream")
                stream, todo = zlib.decompressobj(15 + 32), rest
            elif not todo and not more:
                raise _Bad("the deflate stream is truncated")
    except zlib.error as exc:
        raise _Bad(f"corrupt deflate data ({_first_line(exc)})") from None
    out = b"".join(decoded)
    _checked_length(len(out), size, cap, "the deflate stream inflates to")
    return out


def _unpack_stream(make: Any, errors: tuple[type[BaseException], ...], name: str,
                   data: bytes, size: int | None, cap: int) -> bytes:
    """bz2 or lzma (concatenated streams too), at most one byte more than the chunk."""
    limit = _target(size, cap)
    decoded: list[bytes] = []
    got = 0
    stream = make()
    todo = data
    try:
        for _ in range(limit + len(data) + 2):  # each round makes progress or ends
            more = stream.decompress(todo, max_length=limit + 1 - got)
            todo = b""
            decoded.append(more)
            got += len(more)
            if got > limit:
                raise _Bad(f"the {name} stream inflates beyond the chunk's {limit} bytes")
            if stream.eof:
                rest = stream.unused_data
                if not rest:
                    break
                stream, todo = make(), rest
            elif stream.needs_input and not more:
                raise _Bad(f"the {name} stream is truncated")
    except errors as exc:
        raise _Bad(f"corrupt {name} data ({_first_line(exc)})") from None
    out = b"".join(decoded)
    _checked_length(len(out), size, cap, f"the {name} stream inflates to")
    return out


def _bz2(data: bytes, size: int | None, cap: int) -> bytes:
    import bz2

    return _unpack_stream(bz2.BZ2Decompressor, (OSError, ValueError, EOFError), "bz2", data,
                          size, cap)


def _lzma(data: bytes, size: int | None, cap: int) -> bytes:
    import lzma

    def make() -> Any:
        return lzma.LZMADecompressor(lzma.FORMAT_AUTO, memlimit=LZMA_MEMLIMIT)

    return _unpack_stream(make, (lzma.LZMAError, EOFError, ValueError), "lzma", data, size, cap)


def _crc32c(data: bytes, size: int | None, cap: int) -> bytes | memoryview:
    import google_crc32c

    if len(data) < 4:
        raise _Bad("shorter than its crc32c checksum")
    body = memoryview(data)[:-4]
    if int.from_bytes(data[-4:], "little") != google_crc32c.value(bytes(body)):
        raise _Bad("crc32c checksum mismatch")
    _checked_length(len(body), size, cap, "the data before its checksum has")
    return body


#: Decoders of bytes-to-bytes codecs by name: ``decode(data, size, cap)`` returns exactly
#: ``size`` bytes (``None``: at most ``cap``).
_DECODERS = {"zstd": _zstd, "blosc": _blosc, "zlib": _inflate, "gzip": _inflate, "lz4": _lz4,
             "bz2": _bz2, "lzma": _lzma, "crc32c": _crc32c}


# --------------------------------------------------------------------------- plans
@dataclass(frozen=True)
class _Shard:
    """The layout of one shard: inner chunks, their codecs, where and how the index is kept."""

    grid: tuple[int, ...]  # inner chunks per shard along each axis
    inner: _Plan
    at_end: bool
    checksum: bool

    @property
    def count(self) -> int:
        return math.prod(self.grid)

    @property
    def index_bytes(self) -> int:
        return 16 * self.count + (4 if self.checksum else 0)


@dataclass(frozen=True)
class _Plan:
    """How the stored bytes of one chunk become its array."""

    shape: tuple[int, ...]  # the chunk's shape (as the array's axes)
    dtype: np.dtype  # with the stored byte order
    steps: tuple[str, ...]  # bytes-to-bytes decoders, in decoding order
    order: tuple[int, ...] | str = "C"  # "C", "F" or a transpose permutation
    shard: _Shard | None = None

    @property
    def nbytes(self) -> int:
        return math.prod(self.shape) * self.dtype.itemsize

    def decode(self, data: bytes) -> np.ndarray:
        """The chunk's array from its stored bytes (not for a shard); raises :class:`_Bad`."""
        if len(data) > max_encoded_bytes(self.nbytes):
            raise _Bad(f"{len(data)} bytes, more than a chunk of {self.nbytes} bytes can take "
                       f"encoded ({max_encoded_bytes(self.nbytes)})")
        sizes = self._sizes()
        buf: Any = data
        for step, size in zip(self.steps, sizes, strict=True):
            buf = _DECODERS[step](bytes(buf) if not isinstance(buf, bytes) else buf, size,
                                  max_encoded_bytes(self.nbytes))
        raw = np.frombuffer(buf, dtype=np.uint8)
        if raw.size != self.nbytes:
            raise _Bad(f"{raw.size} bytes, a chunk of {self.nbytes}")
        if self.order == "C":
            return raw.view(self.dtype).reshape(self.shape)
        if self.order == "F":
            return raw.view(self.dtype).reshape(self.shape[::-1]).T
        perm = self.order
        stored = raw.view(self.dtype).reshape([self.shape[p] for p in perm])
        return stored.transpose(np.argsort(perm))

    def _sizes(self) -> list[int | None]:
        """The exact output size of each step when it is known (``None``: capped)."""
        sizes: list[int | None] = []
        size: int | None = self.nbytes
        for step in reversed(self.steps):
            sizes.append(size)
            size = (size + 4 if step == "crc32c" and size is not None else None)
        return sizes[::-1]


def _name_config(codec: Any, where: str) -> tuple[str, dict]:
    if isinstance(codec, str):
        return codec, {}
    if not isinstance(codec, dict) or not isinstance(codec.get("name"), str):
        raise ReadError(f"{where}: a codec must be an object with a 'name', got "
                        f"{limits.shorten(codec)}")
    config = codec.get("configuration") or {}
    if not isinstance(config, dict):
        raise ReadError(f"{where}: codec {codec['name']!r} has a configuration that is not "
                        "an object")
    return codec["name"], config


def _unsupported(name: str, where: str, accepted: tuple[str, ...]) -> ReadError:
    return ReadError(f"{where}: codec {limits.shorten(name)} is not supported (splinecast reads "
                     f"{', '.join(accepted)})")


def _plan_v3(codecs: Any, shape: tuple[int, ...], dtype: np.dtype, where: str,
             nested: bool = False) -> _Plan:
    if not isinstance(codecs, list | tuple) or not codecs:
        raise ReadError(f"{where}: 'codecs' must be a non-empty list")
    order: tuple[int, ...] | str = "C"
    steps: list[str] = []
    shard = None
    stage = "array"
    stored = dtype
    for codec in codecs:
        name, config = _name_config(codec, where)
        if name == "transpose" and stage == "array":
            perm = config.get("order")
            if (not isinstance(perm, list | tuple)
                    or not all(isinstance(p, int) and not isinstance(p, bool) for p in perm)
                    or sorted(perm) != list(range(len(shape)))):
                raise ReadError(f"{where}: transpose order {limits.shorten(perm)} is not a "
                                f"permutation of {len(shape)} axes")
            if order != "C":
                raise ReadError(f"{where}: more than one transpose codec")
            order = tuple(int(p) for p in perm)
        elif name == "bytes" and stage == "array":
            endian = config.get("endian", "little")
            if endian not in ("little", "big"):
                raise ReadError(f"{where}: bytes codec endian {limits.shorten(endian)}")
            stored = dtype.newbyteorder("<" if endian == "little" else ">")
            stage = "bytes"
        elif name == "sharding_indexed" and stage == "array":
            if nested:
                raise ReadError(f"{where}: a shard inside a shard is not supported")
            if order != "C":
                raise ReadError(f"{where}: a transpose before sharding is not supported")
            shard = _plan_shard(config, shape, dtype, where)
            stage = "shard"
        elif stage == "bytes" and (name in ("zstd", "blosc", "gzip", "crc32c") or (
                name.startswith("numcodecs.") and name[10:] in CODECS_V2)):
            steps.append(name.removeprefix("numcodecs."))
        elif stage == "shard":
            raise ReadError(f"{where}: codec {limits.shorten(name)} after sharding is not "
                            "supported")
        else:
            raise _unsupported(name, where, CODECS_V3)
    if stage == "array":
        raise ReadError(f"{where}: the codecs lack an array-to-bytes codec (bytes or "
                        "sharding_indexed)")
    return _Plan(shape, stored, tuple(reversed(steps)), order, shard)


def _plan_shard(config: dict, shape: tuple[int, ...], dtype: np.dtype, where: str) -> _Shard:
    inner_shape = config.get("chunk_shape")
    inner = limits.check_shape(inner_shape, f"{where}: inner chunk shape", ndim=len(shape),
                               error=ReadError)
    if any(s % c for s, c in zip(shape, inner, strict=True)):
        raise ReadError(f"{where}: inner chunks of {inner} do not tile shards of {shape}")
    grid = tuple(s // c for s, c in zip(shape, inner, strict=True))
    if math.prod(grid) > limits.MAX_CHUNKS_PER_READ:
        raise ReadError(f"{where}: {math.prod(grid)} inner chunks per shard, more than "
                        f"{limits.MAX_CHUNKS_PER_READ}")
    plan = _plan_v3(config.get("codecs", [{"name": "bytes"}]), inner, dtype, where, nested=True)
    index = config.get("index_codecs", [{"name": "bytes"}, {"name": "crc32c"}])
    names = [_name_config(c, where)[0] for c in index] if isinstance(index, list | tuple) else []
    configs = [_name_config(c, where)[1] for c in index] if names else []
    if names not in (["bytes"], ["bytes", "crc32c"]) or configs[0].get(
            "endian", "little") != "little":
        raise ReadError(f"{where}: shard index codecs {limits.shorten(index)} are not supported "
                        "(bytes, little-endian, and optionally crc32c)")
    location = config.get("index_location", "end")
    if location not in ("start", "end"):
        raise ReadError(f"{where}: index_location must be start or end, got "
                        f"{limits.shorten(location)}")
    return _Shard(grid, plan, location == "end", names[-1] == "crc32c")


def _plan_v2(meta: dict, shape: tuple[int, ...], where: str) -> _Plan:
    filters = meta.get("filters")
    if filters:
        ids = [f.get("id") if isinstance(f, dict) else f for f in filters] \
            if isinstance(filters, list) else [filters]
        raise ReadError(f"{where}: filters {limits.shorten(ids)} are not supported (splinecast "
                        "reads Zarr v2 arrays without filters)")
    order = meta.get("order", "C")
    if order not in ("C", "F"):
        raise ReadError(f"{where}: order must be C or F, got {limits.shorten(order)}")
    try:
        dtype = np.dtype(meta.get("dtype"))
    except (TypeError, ValueError):
        raise ReadError(f"{where}: unsupported data type {limits.shorten(meta.get('dtype'))}"
                        ) from None
    compressor = meta.get("compressor")
    steps: tuple[str, ...] = ()
    if compressor is not None:
        cid = compressor.get("id") if isinstance(compressor, dict) else compressor
        if cid not in CODECS_V2:
            raise _unsupported(str(cid), where, CODECS_V2)
        steps = (cid,)
    return _Plan(shape, dtype, steps, order)


# --------------------------------------------------------------------------- sources
class FileSource:
    """The files of a local store, each checked before it is opened: a regular file (never a
    folder, pipe or device), inside the store's folder unless ``allow_external`` (symbolic
    links resolved), and byte ranges within the file and the memory guard."""

    def __init__(self, root: Path, allow_external: bool | None = None) -> None:
        self.root = Path(root)
        self.allow_external = allow_external
        self._inside: set[str] = set()

    def path(self, key: str) -> Path:
        return self.root / key

    def size(self, key: str) -> int | None:
        """The file's size in bytes; ``None`` when it does not exist."""
        path = self.root / key
        label = str(path)
        try:
            info = os.stat(path)
        except (FileNotFoundError, NotADirectoryError):
            return None
        except OSError as exc:
            raise ReadError(f"{label}: cannot read: {exc.strerror or exc}") from None
        if not stat.S_ISREG(info.st_mode):
            kind = "a folder" if stat.S_ISDIR(info.st_mode) else "a pipe" \
                if stat.S_ISFIFO(info.st_mode) else "a device or socket"
            raise ReadError(f"{label}: is {kind}, not a regular file")
        if key not in self._inside:
            limits.check_inside(path, self.root, label, allow_external=self.allow_external)
            self._inside.add(key)
        return int(info.st_size)

    def stamp(self, key: str) -> tuple[int, int] | None:
        """What tells a changed file (size and modification time), ``None`` if missing."""
        try:
            info = os.stat(self.root / key)
        except OSError:
            return None
        return int(info.st_size), int(info.st_mtime_ns)

    def read(self, key: str, start: int, stop: int) -> bytes:
        """Bytes ``[start, stop)`` of a file :meth:`size` has checked."""
        path = self.root / key
        label = str(path)
        limits.check_memory(stop - start, "a chunk", label, ReadError)
        fd = limits.open_regular(path, label)
        try:
            with os.fdopen(fd, "rb") as fh:
                fh.seek(start)
                data = fh.read(stop - start)
        except OSError as exc:
            raise ReadError(f"{label}: cannot read: {exc.strerror or exc}") from None
        if len(data) != stop - start:
            raise ReadError(f"{label}: ended after {start + len(data)} of {stop} bytes (the file "
                            "changed while read)")
        return data


class _StoreSource:
    """Any other zarr store (in memory, remote), through its own synchronous interface."""

    def __init__(self, store: Any) -> None:
        self.store = store

    def path(self, key: str) -> str:
        return key

    def _get(self, key: str, byte_range: Any = None) -> bytes | None:
        from zarr.core.buffer.core import default_buffer_prototype
        from zarr.core.sync import sync

        buf = sync(self.store.get(key, default_buffer_prototype(), byte_range))
        return None if buf is None else buf.to_bytes()

    def size(self, key: str) -> int | None:
        data = self._get(key)
        return None if data is None else len(data)

    def stamp(self, key: str) -> None:
        return None

    def read(self, key: str, start: int, stop: int) -> bytes:
        from zarr.abc.store import RangeByteRequest

        data = self._get(key, RangeByteRequest(start, stop))
        if data is None or len(data) != stop - start:
            raise ReadError(f"{key}: cannot read bytes {start}..{stop}")
        return data


def source_of(store: Any) -> Any:
    """The byte source of a zarr store: its files for a local store (the guarded one's
    permission for files outside it carried over), else the store itself."""
    chunk_source = getattr(store, "chunk_source", None)
    if chunk_source is not None:  # a store that says where its chunks are (a remote one)
        return chunk_source()
    root = getattr(store, "root", None)
    if isinstance(root, Path) and root.is_dir():
        return FileSource(root, getattr(store, "allow_external", True))
    return _StoreSource(store)


# --------------------------------------------------------------------------- the reader
class ChunkReader:
    """Boxes of one Zarr array, read chunk by chunk with bounded decoding.

    Parameters
    ----------
    array : zarr.Array
        Opened (metadata only); its chunks are read here, never through zarr.
    label : str
        Names the array in messages (a file, ``store/level``).
    source : optional
        Where the chunk files are (default: :func:`source_of` the array's store).

    Raises
    ------
    ReadError
        A codec this module does not decode, or codec settings that contradict the array.
    """

    def __init__(self, array: Any, label: str, source: Any = None) -> None:
        self.label = label
        self.source = source if source is not None else source_of(array.store)
        meta = array.metadata.to_dict()
        self.shape = tuple(int(n) for n in array.shape)
        try:
            self.dtype = np.dtype(array.dtype)
        except TypeError:  # a zarr data type numpy has no name for
            raise ReadError(f"{label}: unsupported data type {limits.shorten(array.dtype)}"
                            ) from None
        if self.dtype.kind not in "biuf":
            raise ReadError(f"{label}: data type {self.dtype} does not hold numbers")
        self.prefix = f"{array.path}/" if array.path else ""
        self._encode = array.metadata.encode_chunk_key
        outer = tuple(int(n) for n in (array.shards or array.chunks))
        self.outer = outer
        if meta.get("zarr_format") == 2:
            self.plan = _plan_v2(meta, outer, label)
        else:
            self.plan = _plan_v3(meta.get("codecs"), outer, self.dtype, label)
        self.inner = self.plan.shard.inner.shape if self.plan.shard else outer
        fill = array.fill_value
        try:
            self.fill = np.array(0 if fill is None else fill, dtype=self.dtype)
        except (TypeError, ValueError, OverflowError):
            raise ReadError(f"{label}: fill value {limits.shorten(fill)} is not a "
                            f"{self.dtype}") from None
        self._indexes: OrderedDict[tuple, np.ndarray] = OrderedDict()
        self._index_bytes = 0
        self._lock = threading.Lock()

    # ------------------------------------------------------------------ files
    def key(self, coords: tuple[int, ...]) -> str:
        """Store key of the file of outer unit ``coords`` (a shard, or a chunk)."""
        return self.prefix + self._encode(tuple(int(c) for c in coords))

    def file(self, coords: tuple[int, ...]) -> Any:
        return self.source.path(self.key(coords))

    # ------------------------------------------------------------------ reading
    def read(self, lo: Any, hi: Any) -> np.ndarray:
        """The array's elements ``[lo, hi)`` (one bound per axis, inside the array) as a
        C-contiguous array; missing chunks hold the fill value.

        Raises
        ------
        ChunkError
            Naming the first chunk that cannot be decoded and its file.
        ReadError
            A file refused by the source's checks (outside the store, not a regular file).
        """
        lo = tuple(int(v) for v in lo)
        hi = tuple(int(v) for v in hi)
        out = np.empty(tuple(b - a for a, b in zip(lo, hi, strict=True)), dtype=self.dtype)
        if out.size == 0:
            return out
        count = math.prod((b - 1) // n - a // n + 1
                          for a, b, n in zip(lo, hi, self.inner, strict=True))
        if count > limits.MAX_CHUNKS_PER_READ:
            raise ReadError(f"{self.label}: reading {lo}..{hi} needs {count} chunks, more than "
                            f"{limits.MAX_CHUNKS_PER_READ}; the array's chunks are too small")
        units = _units(lo, hi, self.outer)
        if not hasattr(self.source, "prefetch"):
            for unit in units:
                self._read_unit(unit, lo, hi, out)
            return out
        # A remote source: the requests of a batch of chunks are made concurrently (latency is
        # paid once per batch, not per chunk), then decoded here one by one as for local files.
        batch: list[tuple[int, ...]] = []
        for unit in units:
            batch.append(unit)
            if len(batch) >= self.source.batch:
                self._read_batch(batch, lo, hi, out)
                batch = []
        if batch:
            self._read_batch(batch, lo, hi, out)
        return out

    def _read_unit(self, unit: tuple[int, ...], lo: tuple, hi: tuple, out: np.ndarray) -> None:
        if self.plan.shard is None:
            self._read_chunk(unit, lo, hi, out)
        else:
            self._read_shard(unit, lo, hi, out)

    def _read_batch(self, batch: list[tuple[int, ...]], lo: tuple, hi: tuple,
                    out: np.ndarray) -> None:
        """Fetch what ``batch`` needs from a remote source at once, then decode it."""
        source = self.source
        try:
            keys = [self.key(unit) for unit in batch]
            if self.plan.shard is None:
                bound = max_encoded_bytes(self.plan.nbytes)
                source.prefetch([(key, None, None, bound) for key in keys])
            else:
                self._prefetch_shards(batch, keys, lo, hi)
            for unit in batch:
                self._read_unit(unit, lo, hi, out)
        finally:
            source.forget()

    def _prefetch_shards(self, batch: list[tuple[int, ...]], keys: list[str], lo: tuple,
                         hi: tuple) -> None:
        """Sizes, then indexes, then the inner chunks the box needs: three rounds of concurrent
        requests for a batch of shards, two where the source fetches an index at a shard's end
        and its size with one request (a suffix range over HTTP). Whatever is wrong is left for
        :meth:`_read_shard` to report in its usual words."""
        shard = self.plan.shard
        assert shard is not None
        source = self.source
        n = shard.index_bytes
        tails = getattr(source, "prefetch_tails", None)
        if tails is not None and shard.at_end:
            with self._lock:
                unknown = [key for key in keys if (key, source.stamp(key)) not in self._indexes]
            tails(unknown, n)
        source.prefetch_sizes(keys)
        bound = shard.count * max_encoded_bytes(shard.inner.nbytes) + n
        indexes = []
        for key in keys:
            size = source.size(key)
            if size is None or not n <= size <= bound:
                continue
            if (key, source.stamp(key)) in self._indexes:
                continue  # parsed before
            start = size - n if shard.at_end else 0
            indexes.append((key, start, start + n, n))
        source.prefetch(indexes)
        ranges = []
        for unit, key in zip(batch, keys, strict=True):
            size = source.size(key)
            if size is None or not n <= size <= bound:
                continue
            index = self._index(unit, key, size)
            for offset, length, _, _ in self._inner_parts(unit, lo, hi, index):
                if offset != _EMPTY:
                    ranges.append((key, offset, offset + length, length))
        source.prefetch(ranges)

    def _inner_parts(self, unit: tuple[int, ...], lo: tuple, hi: tuple,
                     index: np.ndarray) -> Iterator[tuple[int, int, tuple, tuple]]:
        """``(offset, length, inner, origin)`` of each inner chunk of shard ``unit`` inside the
        box (``offset`` is ``_EMPTY`` for a chunk never written)."""
        shard = self.plan.shard
        assert shard is not None
        shard_origin = tuple(u * n for u, n in zip(unit, self.outer, strict=True))
        s_lo = tuple(max(a, o) for a, o in zip(lo, shard_origin, strict=True))
        s_hi = tuple(min(b, o + n) for b, o, n in zip(hi, shard_origin, self.outer, strict=True))
        first = tuple(u * g for u, g in zip(unit, shard.grid, strict=True))
        for inner in _units(s_lo, s_hi, self.inner):
            origin = tuple(i * n for i, n in zip(inner, self.inner, strict=True))
            local = tuple(i - f for i, f in zip(inner, first, strict=True))
            offset, length = (int(v) for v in index[np.ravel_multi_index(local, shard.grid)])
            yield offset, length, inner, origin

    def read_all(self) -> np.ndarray:
        """The whole array (check its bytes against the memory guard first)."""
        return self.read((0,) * len(self.shape), self.shape)

    def _place(self, out: np.ndarray, lo: tuple, hi: tuple, origin: tuple,
               chunk: np.ndarray | None) -> None:
        """Copy the part of ``chunk`` (at element ``origin``; None: the fill value) in the
        box into ``out``."""
        inner = tuple(slice(max(a, o) - o, min(b, o + n) - o)
                      for a, b, o, n in zip(lo, hi, origin, self.inner, strict=True))
        where = tuple(slice(s.start + o - a, s.stop + o - a)
                      for s, o, a in zip(inner, origin, lo, strict=True))
        out[where] = self.fill if chunk is None else chunk[inner]

    def _read_chunk(self, unit: tuple[int, ...], lo: tuple, hi: tuple, out: np.ndarray) -> None:
        key = self.key(unit)
        origin = tuple(u * n for u, n in zip(unit, self.outer, strict=True))
        bound = max_encoded_bytes(self.plan.nbytes)
        if hasattr(self.source, "whole"):
            # Remote: one request, capped at the bound (a larger file is refused unread).
            data = self.source.whole(key, bound)
            if data is None:
                self._place(out, lo, hi, origin, None)
                return
        else:
            size = self.source.size(key)
            if size is None:
                self._place(out, lo, hi, origin, None)
                return
            if size > bound:
                raise ChunkError(self.label, unit, self.source.path(key),
                                 f"{size} bytes, more than a chunk of {self.plan.nbytes} bytes "
                                 f"can take encoded ({bound})")
            data = self.source.read(key, 0, size)
        try:
            chunk = self.plan.decode(data)
        except _Bad as exc:
            raise ChunkError(self.label, unit, self.source.path(key), str(exc)) from None
        self._place(out, lo, hi, origin, chunk)

    def _index(self, unit: tuple[int, ...], key: str, size: int) -> np.ndarray:
        """The shard's index as ``(count, 2)`` uint64 (offset, length), checked: intact, and
        every entry empty or inside the shard's data and no larger than an encoded inner
        chunk."""
        shard = self.plan.shard
        assert shard is not None
        stamp = self.source.stamp(key)
        with self._lock:
            cached = self._indexes.get((key, stamp)) if stamp is not None else None
            if cached is not None:
                self._indexes.move_to_end((key, stamp))
                return cached
        n = shard.index_bytes
        path = self.source.path(key)
        first = tuple(u * g for u, g in zip(unit, shard.grid, strict=True))
        if size < n:
            raise ChunkError(self.label, unit, path,
                             f"the shard holds {size} bytes, less than its index ({n})", "shard")
        start = size - n if shard.at_end else 0
        raw = self.source.read(key, start, start + n)
        if shard.checksum:
            import google_crc32c

            if int.from_bytes(raw[-4:], "little") != google_crc32c.value(raw[:-4]):
                raise ChunkError(self.label, unit, path, "the shard index fails its crc32c "
                                 "checksum", "shard")
        index = np.frombuffer(raw, dtype="<u8", count=2 * shard.count).reshape(-1, 2)
        index = index.astype(np.uint64)
        offset, length = index[:, 0], index[:, 1]
        empty = (offset == _EMPTY) & (length == _EMPTY)
        lo_data = 0 if shard.at_end else n
        hi_data = size - n if shard.at_end else size
        bound = max_encoded_bytes(shard.inner.nbytes)
        # offset + length may wrap around in uint64: compare offset with hi_data - length.
        fits = (length <= min(bound, hi_data)) & (offset >= lo_data)
        fits &= offset <= np.uint64(hi_data) - np.minimum(length, np.uint64(hi_data))
        bad = np.flatnonzero(~(empty | fits))
        if bad.size:
            e = int(bad[0])
            start, count = int(offset[e]), int(length[e])
            inner = np.unravel_index(e, shard.grid)
            coords = tuple(f + int(i) for f, i in zip(first, inner, strict=True))
            what = (f"{count} bytes, more than an inner chunk can take encoded ({bound})"
                    if count > bound else f"bytes {start}..{start + count}, outside the "
                    f"shard's data ({lo_data}..{hi_data})")
            raise ChunkError(self.label, coords, path, f"the shard index points to {what}")
        index = index.copy()
        index[empty] = _EMPTY
        if stamp is not None:
            with self._lock:
                if (key, stamp) not in self._indexes:
                    self._indexes[(key, stamp)] = index
                    self._index_bytes += index.nbytes
                while (len(self._indexes) > _INDEX_CACHE
                       or self._index_bytes > _INDEX_CACHE_BYTES):
                    self._index_bytes -= self._indexes.popitem(last=False)[1].nbytes
        return index

    def _read_shard(self, unit: tuple[int, ...], lo: tuple, hi: tuple, out: np.ndarray) -> None:
        shard = self.plan.shard
        assert shard is not None
        key = self.key(unit)
        size = self.source.size(key)
        shard_origin = tuple(u * n for u, n in zip(unit, self.outer, strict=True))
        s_lo = tuple(max(a, o) for a, o in zip(lo, shard_origin, strict=True))
        s_hi = tuple(min(b, o + n) for b, o, n in zip(hi, shard_origin, self.outer, strict=True))
        if size is None:
            for inner in _units(s_lo, s_hi, self.inner):
                origin = tuple(i * n for i, n in zip(inner, self.inner, strict=True))
                self._place(out, lo, hi, origin, None)
            return
        bound = (shard.count * max_encoded_bytes(shard.inner.nbytes) + shard.index_bytes)
        if size > bound:
            raise ChunkError(self.label, unit, self.source.path(key),
                             f"the shard holds {size} bytes, more than it can take encoded "
                             f"({bound})", "shard")
        index = self._index(unit, key, size)
        for offset, length, inner, origin in self._inner_parts(unit, lo, hi, index):
            if offset == _EMPTY:
                self._place(out, lo, hi, origin, None)
                continue
            data = self.source.read(key, offset, offset + length)
            try:
                chunk = shard.inner.decode(data)
            except _Bad as exc:
                raise ChunkError(self.label, inner, self.source.path(key), str(exc)) from None
            self._place(out, lo, hi, origin, chunk)


def _units(lo: tuple, hi: tuple, grid: tuple) -> Iterator[tuple[int, ...]]:
    """Grid cells (of size ``grid``) that the box ``[lo, hi)`` overlaps, in C order."""
    ranges = [range(a // g, (b - 1) // g + 1) for a, b, g in zip(lo, hi, grid, strict=True)]
    if any(len(r) == 0 for r in ranges):
        return
    for flat in np.ndindex(*(len(r) for r in ranges)):
        yield tuple(r[i] for r, i in zip(ranges, flat, strict=True))
