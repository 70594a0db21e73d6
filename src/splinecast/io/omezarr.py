"""Reading OME-Zarr images (NGFF 0.4 and 0.5) and plain Zarr arrays as lazy multiscale volumes.

``open_zarr(path)`` reads metadata only: the group's and each level's ``zarr.json`` (or
``.zattrs``/``.zarray`` for Zarr v2) and, for pyramids written by splinecast, the small per-brick
tables under ``splinecast/``. Voxels are read when asked for, a box at a time, through
:meth:`Level.read`.

Accepted:

- OME-Zarr images written by splinecast, ome-zarr-py, ngff-zarr or any other writer: Zarr v3 with
  metadata under ``attributes["ome"]`` (0.5) or Zarr v2 with ``multiscales`` at the top of
  ``.zattrs`` (0.4 and older). Exactly three spatial axes; one entry of a time and a channel axis
  is read (``timepoint=`` / ``channel=``, the first by default: see
  :mod:`splinecast.io.selection`).
- A ``bioformats2raw`` collection: its first image (``0/``), with a warning if it holds more.
- A plain Zarr array (v2 or v3): one level. Its ``dimension_names`` say which axis is x, y and z
  when they are named so; otherwise the order is NGFF's ``z, y, x`` (last index along x), the
  convention of napari, scikit-image and every Zarr writer in the field.

splinecast's own per-brick tables live in the same group (see
:mod:`splinecast.multires.store.tables`):
``splinecast/<table>/<level>`` arrays, described by the root attribute ``"splinecast"``. Other
readers ignore them, as NGFF allows.
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import stat
import struct
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ParameterError, ReadError, limits
from ..volume import GridGeometry, Volume
from ._common import check_dtype, fmt_shape, one_line, require
from .ngff import omero_channels, parse_image, spatial_order
from .remote import is_url
from .selection import Selection
from .store_kinds import store_opener
from .zarr_chunks import ChunkError, ChunkReader, FileSource

__all__ = [
    "ATTRIBUTE",
    "TABLES_GROUP",
    "Level",
    "MultiscaleVolume",
    "is_zarr",
    "open_zarr",
    "open_store",
    "guarded_array",
    "read_array",
]

#: Root attribute holding splinecast's description of a pyramid it built (brick size, tables, ...).
ATTRIBUTE = "splinecast"
#: Subgroup holding splinecast's per-brick tables: ``splinecast/<table>/<level>``.
TABLES_GROUP = "splinecast"
_MARKERS = ("zarr.json", ".zgroup", ".zarray", ".zattrs")
#: Metadata files of Zarr v2 and v3 (and consolidated metadata): small JSON, validated first.
_METADATA = frozenset((*_MARKERS, ".zmetadata"))
#: First bytes of a zstd frame and of a blosc chunk header (version 2).
_ZSTD_MAGIC = b"\x28\xb5\x2f\xfd"


def _zstd_content_size(data: bytes) -> int | None:
    """The decompressed size a zstd frame header declares, ``None`` if it declares none."""
    if len(data) < 5:
        return None
    descriptor = data[4]
    fcs_flag, single = descriptor >> 6, (descriptor >> 5) & 1
    window = 0 if single else 1
    did = (0, 1, 2, 4)[descriptor & 3]
    width = (1 if single else 0, 2, 4, 8)[fcs_flag]
    at = 5 + window + did
    if width == 0 or len(data) < at + width:
        return None
    size = int.from_bytes(data[at:at + width], "little")
    return size + 256 if width == 2 else size


def _declared_size(data: bytes) -> int | None:
    """Bytes a compressed chunk says it decompresses to (zstd frame, blosc header), if known."""
    if data.startswith(_ZSTD_MAGIC):
        return _zstd_content_size(data)
    if len(data) >= 16 and data[0] in (1, 2) and data[3] in (1, 2, 4, 8, 16):  # blosc
        nbytes, blocksize, cbytes = struct.unpack("<III", data[4:16])
        if cbytes == len(data):
            return max(nbytes, blocksize)
    return None

def is_zarr(path: Path) -> bool:
    """``True`` for a folder that holds a Zarr group or array (v2 or v3)."""
    return path.is_dir() and any((path / m).is_file() for m in _MARKERS)


def _zarr(path: Path | str) -> Any:
    # (the name only: a URL is not made a Path, which would collapse its "//")
    name = path.rstrip("/").rsplit("/", 1)[-1] if isinstance(path, str) else path
    return require("zarr", name, action="reading")


def _guarded_store_class() -> type:
    """``LocalStore`` whose every read goes through :mod:`splinecast.errors.limits` first."""
    from zarr.abc.store import OffsetByteRequest, RangeByteRequest, SuffixByteRequest
    from zarr.storage import LocalStore

    class GuardedStore(LocalStore):
        """A read-only local store that refuses, with one :class:`ReadError` naming the file:

        - a folder, pipe, device or socket in place of a metadata or chunk file (never opened,
          so a FIFO cannot block),
        - a file that leads (through symbolic links or ``..`` in a key) outside the store's
          folder, unless external data is allowed,
        - metadata that is not small, valid JSON with finite numbers and bounded nesting,
        - a chunk (or byte range) larger than the memory guard allows, and a compressed chunk
          whose header declares more bytes than the guard allows.
        """

        allow_external: bool | None = None

        def _files(self) -> FileSource:
            files = self.__dict__.get("_file_source")
            if files is None:
                files = self.__dict__["_file_source"] = FileSource(self.root,
                                                                   self.allow_external)
            return files

        def _read(self, key: str, prototype: Any, byte_range: Any) -> Any:
            files = self._files()
            path = files.path(key)
            label = str(path)
            size = files.size(key)  # a regular file inside the store, or None if missing
            if size is None:
                return None  # missing: zarr decides (fill value, or "no such array")
            name = key.rsplit("/", 1)[-1]
            if name in _METADATA:
                if byte_range is not None:
                    raise ReadError(f"{label}: partial read of a metadata file")
                raw = limits.read_limited(path, limits.MAX_JSON_BYTES, label)
                limits.parse_json(raw, label)
                return prototype.buffer.from_bytes(raw)
            if isinstance(byte_range, RangeByteRequest):
                start, stop = byte_range.start, byte_range.end
            elif isinstance(byte_range, OffsetByteRequest):
                start, stop = byte_range.offset, size
            elif isinstance(byte_range, SuffixByteRequest):
                start, stop = max(0, size - byte_range.suffix), size
            else:
                start, stop = 0, size
            if not 0 <= start <= stop <= size:
                raise ReadError(f"{label}: bytes {start}..{stop} requested, the file has {size} "
                                "(a corrupt shard index?)")
            data = files.read(key, start, stop)
            declared = _declared_size(data)
            if declared is not None:
                limits.check_memory(declared, f"a chunk declaring {declared} bytes once "
                                    "decompressed", label, ReadError)
            return prototype.buffer.from_bytes(data)

        def get_sync(self, key: str, *, prototype: Any = None, byte_range: Any = None) -> Any:
            from zarr.core.buffer.core import default_buffer_prototype

            self._ensure_open_sync()
            return self._read(key, prototype or default_buffer_prototype(), byte_range)

        async def get(self, key: str, prototype: Any = None, byte_range: Any = None) -> Any:
            import asyncio

            from zarr.core.buffer.core import default_buffer_prototype

            if not self._is_open:
                await self._open()
            return await asyncio.to_thread(self._read, key,
                                           prototype or default_buffer_prototype(), byte_range)

        async def get_partial_values(self, prototype: Any, key_ranges: Any) -> list[Any]:
            return [await self.get(key, prototype, byte_range) for key, byte_range in key_ranges]

    return GuardedStore


_GUARDED: list[type] = []


def _refused(exc: BaseException) -> ReadError | None:
    """The :class:`ReadError` of the guarded store inside an exception zarr may have wrapped."""
    seen = 0
    while exc is not None and seen < 8:
        if isinstance(exc, ReadError):
            return exc
        if isinstance(exc, BaseExceptionGroup):
            for inner in exc.exceptions:
                found = _refused(inner)
                if found is not None:
                    return found
        exc = exc.__cause__ or exc.__context__
        seen += 1
    return None


#: Where the failures zarr's event loop drops are logged (debug level; ``--verbose`` shows them).
_LOG = logging.getLogger("splinecast.io.zarr")
#: What zarr's event loop says about a failure that nobody awaited.
_UNRETRIEVED = ("Task exception was never retrieved", "Future exception was never retrieved",
                "Task was destroyed but it is pending")


def _quiet_unretrieved() -> None:
    """Let zarr's event loop log at debug level, not print, the failures nobody awaited.

    zarr-python reads a group's members and metadata files concurrently; when the guarded store
    refuses several files at once, the first refusal reaches the caller (and becomes its one
    line) while the others end in tasks no one awaits, which the loop would print as "Task
    exception was never retrieved" at any moment, even after the process reported its error.
    Installed on zarr's loop (again after a fork, which gives the child a new loop); other
    contexts go to the loop's default handler.
    """
    try:
        from zarr.core.sync import _get_loop

        loop = _get_loop()
    except (ImportError, AttributeError, RuntimeError):  # another zarr: nothing to quiet
        return
    if loop.get_exception_handler() is not _drop_unretrieved:
        loop.set_exception_handler(_drop_unretrieved)


def _drop_unretrieved(loop: Any, context: dict[str, Any]) -> None:
    message = str(context.get("message", ""))
    if message.startswith(_UNRETRIEVED):
        exc = context.get("exception")
        _LOG.debug("zarr: %s%s", message, f" ({type(exc).__name__}: {one_line(exc)})"
                   if exc is not None else "")
        return
    loop.default_exception_handler(context)


def open_store(path: str | os.PathLike[str], mode: str = "r",
               allow_external: bool | None = None,
               storage_options: dict[str, Any] | None = None) -> Any:
    """Open a Zarr hierarchy (group or array) with zarr-python; read-only by default.

    ``path`` is a local folder or an ``http(s)://``, ``s3://`` or ``gs://`` URL (read-only,
    through :mod:`.remote`; ``storage_options`` go to its fsspec filesystem). Read-only stores
    go through a guarded store: metadata files are validated as JSON (size, nesting, finite
    numbers), no file outside the store's folder is followed (unless ``allow_external``; never
    for a URL), and a pipe, device or folder in place of a file is refused.
    """
    if is_url(path):
        return _open_remote_store(str(path), mode, storage_options)
    zarr = _zarr(Path(path))
    if mode == "r":
        if not _GUARDED:
            _GUARDED.append(_guarded_store_class())
        store = _GUARDED[0](os.fspath(path), read_only=True)
        store.allow_external = allow_external
        _quiet_unretrieved()
    else:
        from zarr.storage import LocalStore

        store = LocalStore(os.fspath(path), read_only=False)
    try:
        return zarr.open(store=store, mode=mode)
    except Exception as exc:  # zarr raises several kinds for unreadable metadata
        refused = _refused(exc)
        if refused is not None:
            raise refused from None
        raise ReadError(f"{path}: not a readable Zarr group or array ({one_line(exc)})") from None


def _open_remote_store(url: str, mode: str, storage_options: dict[str, Any] | None) -> Any:
    from .remote import Remote, open_remote_group, redact

    if mode != "r":
        raise ParameterError(f"{redact(url)}: remote stores are read-only")
    _zarr(url)
    remote = Remote(url, storage_options)
    _quiet_unretrieved()
    try:
        return open_remote_group(remote)
    except Exception as exc:
        refused = _refused(exc)
        if refused is not None:
            raise refused from None
        if isinstance(exc, FileNotFoundError | KeyError) or "not found" in str(exc).lower():
            raise ReadError(f"{redact(remote.url)}: no Zarr group or array there (no zarr.json, "
                            ".zgroup or .zarray)") from None
        raise ReadError(f"{redact(remote.url)}: not a readable Zarr group or array "
                        f"({one_line(exc)})") from None


@dataclass
class Level:
    """One resolution level of a :class:`MultiscaleVolume`: a lazy Zarr array and its placement.

    ``shape``, ``spacing`` and ``origin`` are in splinecast order (x, y, z); voxel ``(i, j, k)`` of
    this level has its centre at ``origin + (i, j, k) * spacing`` in the same world as level 0.
    """

    index: int
    path: str
    array: Any
    shape: tuple[int, int, int]
    spacing: tuple[float, float, float]
    origin: tuple[float, float, float]
    label: str
    select: tuple[int, ...] = ()  # indices of the leading non-spatial axes
    order: tuple[int, int, int] = (2, 1, 0)  # array axis (after `select`) of x, y, z
    folder: Path | None = None  # the level's folder, for local stores
    complete: bool = False  # every chunk was written: a missing file is damage, not fill value
    reader: ChunkReader | None = field(default=None, repr=False)  # bounded chunk decoding

    @property
    def dtype(self) -> np.dtype:
        return np.dtype(self.array.dtype)

    @property
    def nbytes(self) -> int:
        return math.prod(self.shape) * self.dtype.itemsize

    @property
    def chunks(self) -> tuple[int, int, int]:
        """Shape of one stored chunk (the unit of decompression), x, y, z."""
        spatial = self.array.chunks[len(self.select):]
        return tuple(int(spatial[a]) for a in self.order)  # type: ignore[return-value]

    def _selection(self, lo: Any, hi: Any) -> tuple[Any, ...]:
        spatial: list[slice] = [slice(0, 0)] * 3
        for axis in range(3):
            spatial[self.order[axis]] = slice(int(lo[axis]), int(hi[axis]))
        return (*self.select, *spatial)

    def chunk_reader(self) -> ChunkReader:
        """The level's :class:`~.zarr_chunks.ChunkReader` (made on first use for a level built
        by hand; :func:`open_zarr` makes it on opening, refusing codecs it cannot bound)."""
        if self.reader is None:
            self.reader = ChunkReader(self.array, self.label)
        return self.reader

    def read(self, lo: Any, hi: Any) -> np.ndarray:
        """Voxels ``[lo, hi)`` (x, y, z; clipped to the level) as a C-contiguous (x, y, z) array.

        Every chunk is decoded into a buffer of exactly its own size (:mod:`.zarr_chunks`): a
        chunk whose data would inflate beyond it is refused, whatever its headers say.

        Raises
        ------
        ReadError
            Naming the chunk and its file when a chunk is missing (in a store whose chunks are
            all written) or cannot be decoded, or the store is gone.
        """
        lo = np.clip(np.asarray(lo, dtype=np.int64), 0, self.shape)
        hi = np.clip(np.asarray(hi, dtype=np.int64), lo, self.shape)
        box = tuple(int(v) for v in hi - lo)
        limits.check_memory(2 * limits.nbytes(box, self.dtype.itemsize),
                            f"reading {fmt_shape(box)} {self.dtype} voxels", self.label, ReadError)
        self._check_files(lo, hi)
        starts, stops = list(self.select), [i + 1 for i in self.select]
        for a in range(3):  # array axis order (after the leading ones)
            axis = self.order.index(a)
            starts.append(int(lo[axis]))
            stops.append(int(hi[axis]))
        try:
            block = self.chunk_reader().read(starts, stops)
        except ChunkError as exc:
            raise self._named(exc) from None
        except ReadError:
            raise
        except Exception as exc:  # a failure the decoders did not foresee still names the box
            raise ReadError(f"{self.label}: voxels {lo.tolist()}..{hi.tolist()} cannot be read "
                            f"({type(exc).__name__}: {one_line(exc)})") from None
        block = block[(0,) * len(self.select)] if self.select else block
        # The array's spatial axes in x, y, z order, then one copy into C order for the kernels.
        return np.ascontiguousarray(np.transpose(block, self.order))

    def _named(self, exc: ChunkError) -> ReadError:
        """A chunk's error with its grid position in x, y, z order."""
        spatial = exc.coords[len(self.select):]
        if len(spatial) != 3:
            return exc
        xyz = tuple(int(spatial[a]) for a in self.order)
        where = f" (file {exc.file})" if exc.file is not None else ""
        return ReadError(f"{self.label}: {exc.kind} {xyz} (x, y, z) cannot be read{where}: "
                         f"{exc.reason}")

    # ------------------------------------------------------------------ fault reporting
    def _grid(self) -> tuple[int, int, int]:
        """Shape of the unit stored in one file (a shard if sharded, else a chunk), x, y, z."""
        outer = self.array.shards or self.array.chunks
        spatial = outer[len(self.select):]
        return tuple(int(spatial[a]) for a in self.order)  # type: ignore[return-value]

    def _file_of(self, coords_xyz: tuple[int, int, int]) -> Path | None:
        if self.folder is None:
            return None
        outer = [0] * 3
        for axis in range(3):
            outer[self.order[axis]] = coords_xyz[axis]
        grid = self.array.shards or self.array.chunks
        lead = [i // c for i, c in zip(self.select, grid, strict=False)]
        key = self.array.metadata.encode_chunk_key((*lead, *outer))
        return self.folder / key

    def _units(self, lo: np.ndarray, hi: np.ndarray, grid: tuple[int, int, int]):
        first = lo // grid
        last = (np.maximum(hi, lo + 1) - 1) // grid
        for i in range(first[0], last[0] + 1):
            for j in range(first[1], last[1] + 1):
                for k in range(first[2], last[2] + 1):
                    yield (int(i), int(j), int(k))

    def _check_files(self, lo: np.ndarray, hi: np.ndarray) -> None:
        """Every file the box needs, before zarr opens any: a regular file (not a pipe, device
        or folder) no larger than its chunk can be once encoded; in a store whose every chunk
        was written, a missing file is damage, not fill value. A box needing more than
        :data:`~splinecast.errors.limits.MAX_CHUNKS_PER_READ` files is refused."""
        if self.folder is None:
            return
        if not self.folder.is_dir():
            raise ReadError(f"{self.label}: level folder {self.folder} is gone")
        grid = self._grid()
        first = lo // grid
        last = (np.maximum(hi, lo + 1) - 1) // grid
        count = math.prod(int(n) for n in last - first + 1)
        if count > limits.MAX_CHUNKS_PER_READ:
            raise ReadError(
                f"{self.label}: reading voxels {lo.tolist()}..{hi.tolist()} needs {count} chunk "
                f"files of {fmt_shape(grid)} voxels, more than {limits.MAX_CHUNKS_PER_READ}; "
                "the store's chunks are too small"
            )
        bound = self._max_file_bytes()
        for unit in self._units(lo, hi, grid):
            path = self._file_of(unit)
            if path is None:
                continue
            try:
                info = os.stat(path)
            except (FileNotFoundError, NotADirectoryError):
                if self.complete:
                    raise ReadError(f"{self.label}: chunk file {path} is missing") from None
                continue
            except OSError as exc:
                raise ReadError(f"{self.label}: chunk file {path} cannot be read: "
                                f"{exc.strerror or exc}") from None
            if not stat.S_ISREG(info.st_mode):
                raise ReadError(f"{self.label}: chunk file {path} is not a regular file")
            if info.st_size > bound:
                raise ReadError(
                    f"{self.label}: chunk file {path} holds {info.st_size} bytes, more than a "
                    f"chunk of {fmt_shape(grid)} {self.dtype} voxels can take encoded ({bound})"
                )

    def _max_file_bytes(self) -> int:
        """Largest size a file of this level can have: its voxels, twice (incompressible data
        grows a little in every codec), plus the shard index and headers."""
        outer = self.array.shards or self.array.chunks
        inner = self.array.chunks
        units = math.prod(-(-int(o) // int(i)) for o, i in zip(outer, inner, strict=False))
        return 2 * limits.nbytes(outer, self.dtype.itemsize) + 64 * units + (1 << 16)

    # ------------------------------------------------------------------ whole-level access
    def to_dask(self) -> Any:
        """The level as a lazy dask array in splinecast order (x, y, z), one block per stored
        chunk; nothing is read until computed, then through :meth:`read`."""
        da = require("dask.array", self.label, action="reading")
        return da.from_array(_LevelBlocks(self), chunks=self.chunks, asarray=False)

    def to_volume(self, max_bytes: int = 2**31) -> Volume:
        """Read the whole level into memory as a :class:`~splinecast.volume.Volume`.

        Raises
        ------
        ParameterError
            If the level is larger than ``max_bytes`` (checked before anything is read).
        """
        if self.nbytes > max_bytes:
            raise ParameterError(
                f"{self.label}: level {self.index} ({fmt_shape(self.shape)}, "
                f"{self.nbytes / 2**20:.0f} MiB) exceeds max_bytes={max_bytes / 2**20:.0f} MiB"
            )
        data = self.read((0, 0, 0), self.shape)
        return Volume(data, spacing=self.spacing, origin=self.origin,
                      metadata={"name": f"{self.label} level {self.index}"})


class _LevelBlocks:
    """A level as what ``dask.array.from_array`` slices (x, y, z order), read by
    :meth:`Level.read`."""

    def __init__(self, level: Level) -> None:
        self.level = level
        self.shape = level.shape
        self.dtype = level.dtype
        self.ndim = 3

    def __getitem__(self, box: tuple[slice, ...]) -> np.ndarray:
        lo = [s.start or 0 for s in box]
        hi = [n if s.stop is None else s.stop for s, n in zip(box, self.shape, strict=True)]
        return self.level.read(lo, hi)


def read_array(array: Any, label: str) -> np.ndarray:
    """A whole Zarr array of a store (a table, an index), its bytes checked against the memory
    guard first and every chunk decoded within its own size (:mod:`.zarr_chunks`).

    Raises
    ------
    ReadError
        Naming ``label`` (and the chunk): too large, an unsupported codec, a damaged chunk.
    """
    itemsize = np.dtype(array.dtype).itemsize
    limits.check_memory(limits.nbytes(array.shape, itemsize), "the array", label, ReadError)
    return ChunkReader(array, label).read_all()


@dataclass
class MultiscaleVolume(GridGeometry):
    """A lazy multiresolution volume: the levels of an OME-Zarr image, finest first.

    Geometry (``shape``, ``spacing``, ``origin``, ``bounds``, ``index_to_world``, ...) is that of
    level 0 and follows :mod:`splinecast.volume`, so cameras frame it like a :class:`Volume`
    (``Camera.orbit(mv)``). No voxel is read until a level's :meth:`Level.read` is called.

    Attributes
    ----------
    levels : list of Level
        Finest first, as the metadata lists them.
    metadata : dict
        ``name``, ``source``, ``format``, ``units`` when known, and what splinecast stored about
        the source (``inside``, ``default_iso``).
    attributes : dict
        splinecast's description of a pyramid it built (empty for other stores): ``brick``,
        ``ghost``, ``downsampling``, ``value_range``, ``tables``.
    """

    path: Path
    levels: list[Level]
    metadata: dict[str, Any] = field(default_factory=dict)
    attributes: dict[str, Any] = field(default_factory=dict)
    root: Any = None
    _value_range: tuple[float, float] | None = None

    @property
    def shape(self) -> tuple[int, int, int]:  # type: ignore[override]
        return self.levels[0].shape

    @property
    def spacing(self) -> tuple[float, float, float]:  # type: ignore[override]
        return self.levels[0].spacing

    @property
    def origin(self) -> tuple[float, float, float]:  # type: ignore[override]
        return self.levels[0].origin

    @property
    def dtype(self) -> np.dtype:
        return self.levels[0].dtype

    @property
    def name(self) -> str:
        name = self.metadata.get("name")
        return str(name) if name is not None else str(getattr(self.path, "name", self.path))

    @property
    def brick(self) -> int | None:
        """Brick size the pyramid was built for (``None`` for stores splinecast did not write)."""
        value = self.attributes.get("brick")
        return int(value) if value is not None else None

    @property
    def value_range(self) -> tuple[float, float]:
        """``(min, max)`` of the finest level: stored by splinecast's build, else estimated.

        For stores without splinecast's tables the range of the coarsest level is used (read on
        first use; ``metadata["value_range_exact"]`` is then ``False``): averaging narrows a
        range, so isovalues near the extremes may be refused.
        """
        if self._value_range is None:
            stored = self.attributes.get("value_range")
            if stored is not None:
                self._value_range = (float(stored[0]), float(stored[1]))
                self.metadata["value_range_exact"] = True
            else:
                coarse = self.levels[-1]
                data = coarse.read((0, 0, 0), coarse.shape)
                if data.dtype.kind == "f":
                    data = data[np.isfinite(data)]
                if data.size == 0:
                    raise ReadError(f"{self.path}: the coarsest level holds no finite value")
                self._value_range = (float(data.min()), float(data.max()))
                self.metadata["value_range_exact"] = False
        return self._value_range

    def level(self, index: int) -> Level:
        """Level ``index`` (0 is the finest; negative counts from the coarsest)."""
        try:
            return self.levels[index]
        except IndexError:
            raise ParameterError(
                f"level {index} does not exist in {self.path} ({len(self.levels)} levels)"
            ) from None

    def tables(self) -> list[str]:
        """Names of splinecast's per-brick tables stored with the pyramid."""
        return sorted(self.attributes.get("tables", {}))

    def table(self, name: str, level: int) -> np.ndarray | None:
        """Per-brick table ``name`` of ``level`` as an array indexed ``[bi, bj, bk, ...]`` (brick
        index along x, y, z first), or ``None`` if the store has none."""
        if name not in self.attributes.get("tables", {}) or self.root is None:
            return None
        where = f"{self.path}: table {name}/{level}"
        try:
            array = self.root[f"{TABLES_GROUP}/{name}/{level}"]
            if not hasattr(array, "dtype") or np.dtype(array.dtype).kind not in "fiub":
                raise ReadError(f"{where} does not hold numbers")
            return read_array(array, where)
        except KeyError:
            return None
        except ReadError:
            raise
        except Exception as exc:
            refused = _refused(exc)
            raise (refused or ReadError(f"{where} cannot be read: {one_line(exc)}")) from None

    def __repr__(self) -> str:
        shapes = ", ".join(fmt_shape(lv.shape) for lv in self.levels)
        return (f"MultiscaleVolume(name={self.name!r}, dtype={self.dtype}, levels=[{shapes}], "
                f"spacing={self.spacing}, origin={self.origin})")


# --------------------------------------------------------------------------- opening
def _attrs(node: Any) -> dict[str, Any]:
    return dict(node.attrs.asdict() if hasattr(node.attrs, "asdict") else node.attrs)


def _is_time(name: str) -> bool:
    return name.lower() in ("t", "time")


def _leading_selection(shape: tuple[int, ...], names: tuple[str, ...], n_lead: int,
                       selection: Selection, label: str) -> tuple[int, ...]:
    """The index read on each axis before the spatial ones: the chosen time point on a time
    axis, the chosen channel on any other (NGFF allows one of each)."""
    select = []
    for axis in range(n_lead):
        size, name = shape[axis], names[axis]
        if _is_time(name):
            select.append(selection.time(label, size))
        else:
            select.append(selection.chan(label, size))
    return tuple(select)


def _lead_counts(shape: tuple[int, ...], names: tuple[str, ...], n_lead: int,
                 select: tuple[int, ...], selection: Selection) -> dict[str, int]:
    """The metadata entries of the counts and the choice (1 and 0 for an axis the image lacks)."""
    timepoints, timepoint, channels, channel = 1, 0, 1, 0
    for axis in range(n_lead):
        if _is_time(names[axis]):
            timepoints, timepoint = shape[axis], select[axis]
        else:
            channels, channel = shape[axis], select[axis]
    return selection.metadata(timepoints, timepoint, channels, channel)


def _level(index: int, path: str, array: Any, scale: Any, translation: Any,
           select: tuple[int, ...], order: tuple[int, int, int], label: str,
           folder: Path | None, complete: bool) -> Level:
    ndim = len(array.shape)
    if ndim != len(select) + 3:
        raise ReadError(f"{label}: level {path!r} has {ndim} dimensions, the axes list "
                        f"{len(select) + 3}")
    where = f"{label}: level {path!r}"
    try:
        dtype = np.dtype(array.dtype)
    except Exception:  # a zarr data type numpy has no name for
        raise ReadError(f"{where}: unsupported data type {limits.shorten(array.dtype)}") from None
    check_dtype(dtype, where)
    spatial_shape = array.shape[len(select):]
    spatial_scale = scale[len(select):]
    spatial_translation = translation[len(select):]
    shape = limits.check_shape([spatial_shape[a] for a in order], f"{where}: shape",
                               error=ReadError)
    spacing = limits.check_spacing([spatial_scale[a] for a in order], f"{where}: scale",
                                   ReadError)
    origin = limits.check_origin([spatial_translation[a] for a in order], spacing,
                                 f"{where}: translation", ReadError)
    outer = tuple(array.shards or array.chunks)
    for what, grid in (("chunk", tuple(array.chunks)), ("shard", outer)):
        limits.check_shape(grid, f"{where}: {what} shape", ndim=len(array.shape),
                           error=ReadError)
    limits.check_memory(limits.nbytes(outer, dtype.itemsize),
                        f"one {fmt_shape(outer)} {'shard' if array.shards else 'chunk'}", where,
                        ReadError)
    level = Level(
        index=index,
        path=path,
        array=array,
        shape=shape,  # type: ignore[arg-type]
        spacing=spacing,
        origin=origin,
        label=f"{label}/{path}",
        select=select,
        order=order,
        folder=folder,
        complete=complete,
        reader=ChunkReader(array, f"{label}/{path}"),
    )
    if complete and hasattr(level.reader.source, "strict"):  # type: ignore[union-attr]
        level.reader.source.strict = True  # type: ignore[union-attr]  (remote: 404 is damage)
    if min(level.shape) < 1:
        raise ReadError(f"{level.label}: the level is empty (shape {fmt_shape(level.shape)})")
    return level


def guarded_array(node: Any, key: str, label: str, folder: Path) -> Level:
    """Array ``key`` of an opened splinecast store (not an image) as a checked :class:`Level`.

    For stores whose arrays are indexed ``[x, y, z]`` as stored and every chunk was written
    (splinecast's spline-wavelet pyramids): the array's metadata goes through the same checks
    as an image level (data type, shape and chunk shape within the limits, one chunk within the
    memory guard), and :meth:`Level.read` checks every chunk file before zarr opens it (a
    missing file is damage, not fill value).

    Raises
    ------
    ReadError
        Naming ``label/key``: missing, not an array, unreadable or out-of-limits metadata.
    """
    zarr = _zarr(folder)
    with _zarr_calls(f"{label}/{key}"):
        try:
            array = node[key]
        except KeyError:
            raise ReadError(f"{label}: array {key} is missing") from None
        if not isinstance(array, zarr.Array):
            raise ReadError(f"{label}/{key}: is not a Zarr array")
        if len(array.shape) != 3:
            raise ReadError(f"{label}/{key}: has {len(array.shape)} dimensions, expected 3")
        return _level(0, key, array, (1.0,) * 3, (0.0,) * 3, (), (0, 1, 2), label,
                      folder / key, True)


def open_zarr(
    path: str | os.PathLike[str], *, channel: int | None = None, timepoint: int | None = None,
    allow_external: bool | None = None, storage_options: dict[str, Any] | None = None,
    selection: Selection | None = None,
) -> Any:
    """Open an OME-Zarr image or a plain Zarr array lazily (metadata only).

    Parameters
    ----------
    path : str or path-like
        The image's folder (``x.zarr``, ``x.ome.zarr``), a ``bioformats2raw`` collection, or a
        Zarr array's folder.
    channel, timepoint : int, optional
        Which entry of the channel and time axes to read (default: the first, with a
        :class:`~splinecast.io.selection.SeveralVolumesWarning` when the axis is longer
        than 1).
    allow_external : bool, optional
        Follow symbolic links to files outside the store's folder (default: refused, unless
        ``SPLINECAST_ALLOW_EXTERNAL_DATA=1``). Never for a URL.
    storage_options : dict, optional
        For a URL: options of its fsspec filesystem (see :func:`splinecast.read`).
    selection : Selection, optional
        Instead of ``channel`` and ``timepoint`` (what :func:`splinecast.read` passes: it knows
        which keyword the time point was given with).

    Returns
    -------
    MultiscaleVolume
        Or, for a splinecast store of another kind (a spline-wavelet pyramid), the object its
        registered opener returns (:func:`.store_kinds.register_store_kind`).

    Raises
    ------
    ReadError
        Not a Zarr hierarchy, no image metadata in a group, not three spatial axes, a level that
        does not match the axes, unsupported voxel type, or zarr-python missing.
    """
    if is_url(path):
        from .remote import check_url, redact

        url = check_url(str(path))
        if selection is None:
            selection = Selection(timepoint=timepoint, channel=channel)
        with _zarr_calls(redact(url)):
            return _open_zarr(url, selection, False, storage_options)
    path = Path(os.fspath(path))
    if not path.exists():
        raise ReadError(f"{path}: no such file or folder")
    if selection is None:
        selection = Selection(timepoint=timepoint, channel=channel)
    with _zarr_calls(str(path)):
        return _open_zarr(path, selection, allow_external)


@contextlib.contextmanager
def _zarr_calls(label: str) -> Any:
    """zarr-python reads metadata lazily (listing members, opening arrays): whatever it raises
    on a damaged store becomes one ReadError; the guarded store's own refusal passes through."""
    try:
        yield
    except ReadError:
        raise
    except ParameterError:
        raise
    except Exception as exc:  # zarr and numcodecs raise ValueError, TypeError, KeyError, ...
        refused = _refused(exc)
        raise (refused or ReadError(f"{label}: not a readable Zarr store "
                                    f"({one_line(exc)})")) from None


def _open_zarr(path: Path | str, selection: Selection, allow_external: bool | None,
               storage_options: dict[str, Any] | None = None) -> MultiscaleVolume:
    """Open a local folder (``Path``) or a checked URL (``str``, kept as text)."""
    remote = isinstance(path, str)
    node = open_store(path, allow_external=allow_external, storage_options=storage_options)
    zarr = _zarr(path)
    label = str(path)
    attrs = _attrs(node)
    local = None if remote else path.absolute()  # type: ignore[union-attr]
    name = path.rsplit("/", 1)[-1] if remote else path.name  # type: ignore[union-attr]
    if isinstance(node, zarr.Array):
        return _plain_array(path, node, label, selection)
    ome = attrs.get("ome") if isinstance(attrs.get("ome"), dict) else attrs
    if "bioformats2raw.layout" in ome and "multiscales" not in ome and remote:
        # Object stores and web servers are not listed: the layout puts the first image at 0/.
        return open_zarr(f"{path}/0", storage_options=storage_options, selection=selection)
    if "bioformats2raw.layout" in ome and "multiscales" not in ome:
        series = sorted(k for k in node.group_keys() if k.isdigit())
        if not series:
            raise ReadError(f"{label}: bioformats2raw collection without images")
        if len(series) > 1:
            warnings.warn(f"{label}: holds {len(series)} images; reading the first (0/)",
                          stacklevel=2)
        return open_zarr(path / "0", selection=selection, allow_external=allow_external)
    ours = _our_attributes(attrs.get(ATTRIBUTE), f"{label}: attribute {ATTRIBUTE!r}")
    kind = ours.get("kind")
    if kind is not None:
        selection.single(label)  # a splinecast store holds one volume
        opener = store_opener(kind)
        if remote:
            raise ReadError(f"{label}: a splinecast store of kind {kind!r} is read from a local "
                            "folder only")
        if opener is None:
            raise ReadError(f"{label}: a splinecast store of kind {kind!r}, which this version "
                            "cannot read")
        return opener(path, node, ours)
    image = parse_image(attrs, label)
    if image is None:
        arrays = sorted(node.array_keys())
        hint = f" (it holds arrays {', '.join(arrays[:4])}: open one of them)" if arrays else ""
        raise ReadError(f"{label}: a Zarr group without OME-Zarr 'multiscales' metadata{hint}")
    n_lead = image.spatial[0]
    if image.spatial != (n_lead, n_lead + 1, n_lead + 2) or n_lead != len(image.axis_names) - 3:
        raise ReadError(f"{label}: the spatial axes must come last ({image.axis_names})")
    order = spatial_order(image.axis_names[n_lead:])
    complete = bool(ours.get("complete_chunks", False))
    levels = []
    for index, dataset in enumerate(image.datasets):
        array = _child(node, dataset.path, label)
        if not isinstance(array, zarr.Array):
            raise ReadError(f"{label}: level {dataset.path!r} is not an array")
        if index == 0:  # the full-resolution level: the counts, the choice, its messages
            select = _leading_selection(tuple(array.shape), image.axis_names, n_lead,
                                        selection, label)
            chosen = _lead_counts(tuple(array.shape), image.axis_names, n_lead, select,
                                  selection)
        elif tuple(array.shape[:n_lead]) != tuple(levels[0].array.shape[:n_lead]):
            raise ReadError(f"{label}: level {dataset.path!r} has {array.shape[:n_lead]} "
                            f"entries on the axes {image.axis_names[:n_lead]}, level "
                            f"{image.datasets[0].path!r} {levels[0].array.shape[:n_lead]}")
        levels.append(_level(index, dataset.path, array, dataset.scale, dataset.translation,
                             select, order, label,
                             None if local is None else local / dataset.path, complete))
    units = {u for u in image.units[n_lead:] if u}
    metadata: dict[str, Any] = {
        "name": name,
        "source": label if local is None else str(local),
        "format": f"ome-zarr {image.version}",
    }
    metadata.update(chosen)
    metadata.update(_display(attrs, chosen))
    if len(units) == 1:
        metadata["units"] = units.pop()
    if image.downsampling:
        metadata["downsampling"] = image.downsampling
    metadata.update(ours.get("source_metadata", {}))
    if isinstance(ome.get("image-label"), dict):
        # An NGFF label image (a segmentation): its colours and names, and the sign that it
        # renders as labels (Scene(vol, labels=True), the CLI's default for such stores).
        metadata["image_label"] = ome["image-label"]
    return MultiscaleVolume(path=path, levels=levels, metadata=metadata, attributes=ours,
                            root=node)


def _display(attrs: dict[str, Any], chosen: dict[str, int]) -> dict[str, Any]:
    """Metadata entries of the image's ``omero`` display settings (:func:`.ngff.omero_channels`):
    ``"omero"``, the list for every channel, and for the channel read its ``channel_label``,
    ``channel_color``, ``channel_window`` and ``channel_active`` (those it has)."""
    found = omero_channels(attrs, chosen["channels"])
    if found is None:
        return {}
    entries: dict[str, Any] = {"omero": found}
    for key, value in found[chosen["channel"]].items():
        if value is not None:
            entries[f"channel_{key}"] = value
    return entries


def _child(node: Any, key: str, label: str) -> Any:
    """``node[key]``: zarr's errors on unreadable metadata become one ReadError naming it."""
    try:
        return node[key]
    except KeyError:
        raise ReadError(f"{label}: level {key!r} listed in the metadata is missing") from None
    except Exception as exc:  # zarr raises ValueError, TypeError, ... for malformed metadata
        refused = _refused(exc)
        if refused is not None:
            raise refused from None
        if is_url(label):
            meta: Any = f"{label}/{key}"
        else:
            folder = Path(label) / key
            meta = next((folder / m for m in ("zarr.json", ".zarray")
                         if (folder / m).exists()), folder)
        raise ReadError(f"{label}: level {key!r} ({meta}) is not a readable Zarr array "
                        f"({one_line(exc)})") from None


def _our_attributes(value: Any, where: str) -> dict[str, Any]:
    """splinecast's own root attribute, checked field by field (it drives the renderer)."""
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise ReadError(f"{where} must be an object, got {limits.shorten(value)}")
    ours = dict(value)
    for key in ("brick", "ghost", "shard"):
        if ours.get(key) is not None:
            ours[key] = limits.check_count(ours[key], f"{where}: {key}", lo=0,
                                           hi=limits.MAX_AXIS, error=ReadError)
    if ours.get("value_range") is not None:
        pair = ours["value_range"]
        if not isinstance(pair, list | tuple) or len(pair) != 2:
            raise ReadError(f"{where}: value_range must be two numbers, got "
                            f"{limits.shorten(pair)}")
        lo, hi = (limits.check_finite_number(v, f"{where}: value_range", error=ReadError)
                  for v in pair)
        if lo > hi:
            raise ReadError(f"{where}: value_range must be (min, max), got {[lo, hi]}")
        ours["value_range"] = [lo, hi]
    for key in ("tables", "source_metadata"):
        if key in ours and not isinstance(ours[key], dict):
            raise ReadError(f"{where}: {key} must be an object, got {limits.shorten(ours[key])}")
    return ours


def _plain_array(path: Path | str, array: Any, label: str, selection: Selection
                 ) -> MultiscaleVolume:
    shape = tuple(array.shape)
    chosen = selection.single(label)
    names = getattr(array.metadata, "dimension_names", None) or ()
    lead = len(shape) - 3
    if lead < 0 or any(n != 1 for n in shape[:lead]):
        raise ReadError(f"{label}: expected a 3D array, got shape {fmt_shape(shape)}")
    order = spatial_order(tuple(str(n) for n in names[lead:])) if names else (2, 1, 0)
    level = _level(0, "", array, (1.0,) * len(shape), (0.0,) * len(shape), (0,) * lead, order,
                   label, None, False)
    remote = isinstance(path, str)
    level.folder = None if remote else path.absolute()  # type: ignore[union-attr]
    level.label = label
    level.chunk_reader().label = label
    return MultiscaleVolume(
        path=path,  # type: ignore[arg-type]
        levels=[level],
        metadata={"name": path.rsplit("/", 1)[-1] if remote else path.name,  # type: ignore
                  "source": label if remote else str(path.absolute()),  # type: ignore
                  "format": f"zarr v{array.metadata.zarr_format} array", **chosen},
    )
