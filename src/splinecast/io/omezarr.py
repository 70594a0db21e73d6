"""Reading OME-Zarr images (NGFF 0.4 and 0.5) and plain Zarr arrays as lazy multiscale volumes.

``open_zarr(path)`` reads metadata only: the group's and each level's ``zarr.json`` (or
``.zattrs``/``.zarray`` for Zarr v2) and, for pyramids written by splinecast, the small per-brick
tables under ``splinecast/``. Voxels are read when asked for, a box at a time, through
:meth:`Level.read`.

Accepted:

- OME-Zarr images written by splinecast, ome-zarr-py, ngff-zarr or any other writer: Zarr v3 with
  metadata under ``attributes["ome"]`` (0.5) or Zarr v2 with ``multiscales`` at the top of
  ``.zattrs`` (0.4 and older). Exactly three spatial axes; time or channel axes of length 1 are
  dropped, longer ones need ``timepoint=`` / ``channel=``.
- A ``bioformats2raw`` collection: its first image (``0/``), with a warning if it holds more.
- A plain Zarr array (v2 or v3): one level. Its ``dimension_names`` say which axis is x, y and z
  when they are named so; otherwise the order is NGFF's ``z, y, x`` (last index along x), the
  convention of napari, scikit-image and every Zarr writer in the field.

splinecast's own per-brick tables live in the same group (see :mod:`splinecast.multires.tables`):
``splinecast/<table>/<level>`` arrays, described by the root attribute ``"splinecast"``. Other
readers ignore them, as NGFF allows.
"""

from __future__ import annotations

import math
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ParameterError, ReadError
from ..volume import GridGeometry, Volume
from ._common import check_dtype, fmt_shape, one_line, require
from .ngff import parse_image, spatial_order
from .store_kinds import store_opener

__all__ = [
    "ATTRIBUTE",
    "TABLES_GROUP",
    "Level",
    "MultiscaleVolume",
    "is_zarr",
    "open_zarr",
    "open_store",
]

#: Root attribute holding splinecast's description of a pyramid it built (brick size, tables, ...).
ATTRIBUTE = "splinecast"
#: Subgroup holding splinecast's per-brick tables: ``splinecast/<table>/<level>``.
TABLES_GROUP = "splinecast"
_MARKERS = ("zarr.json", ".zgroup", ".zarray", ".zattrs")

def is_zarr(path: Path) -> bool:
    """``True`` for a folder that holds a Zarr group or array (v2 or v3)."""
    return path.is_dir() and any((path / m).is_file() for m in _MARKERS)


def _zarr(path: Path) -> Any:
    return require("zarr", path, action="reading")


def open_store(path: str | os.PathLike[str], mode: str = "r") -> Any:
    """Open a local Zarr hierarchy (group or array) with zarr-python; read-only by default."""
    zarr = _zarr(Path(path))
    from zarr.storage import LocalStore

    store = LocalStore(os.fspath(path), read_only=(mode == "r"))
    try:
        return zarr.open(store=store, mode=mode)
    except Exception as exc:  # zarr raises several kinds for unreadable metadata
        raise ReadError(f"{path}: not a readable Zarr group or array ({one_line(exc)})") from None


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

    def read(self, lo: Any, hi: Any) -> np.ndarray:
        """Voxels ``[lo, hi)`` (x, y, z; clipped to the level) as a C-contiguous (x, y, z) array.

        Raises
        ------
        ReadError
            Naming the chunk and its file when a chunk is missing (in a store whose chunks are
            all written) or cannot be decoded, or the store is gone.
        """
        lo = np.clip(np.asarray(lo, dtype=np.int64), 0, self.shape)
        hi = np.clip(np.asarray(hi, dtype=np.int64), lo, self.shape)
        self._check_files(lo, hi)
        try:
            block = np.asarray(self.array[self._selection(lo, hi)])
        except Exception as exc:  # decoding, I/O and metadata errors all mean "unavailable"
            raise self._diagnose(lo, hi, exc) from None
        # The array's spatial axes in x, y, z order, then one copy into C order for the kernels.
        return np.ascontiguousarray(np.transpose(block, self.order))

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
        """In a store whose every chunk was written, a missing file is damage, not fill value."""
        if self.folder is None:
            return
        if not self.folder.is_dir():
            raise ReadError(f"{self.label}: level folder {self.folder} is gone")
        if not self.complete:
            return
        grid = self._grid()
        for unit in self._units(lo, hi, grid):
            path = self._file_of(unit)
            if path is not None and not path.is_file():
                raise ReadError(f"{self.label}: chunk file {path} is missing")

    def _diagnose(self, lo: np.ndarray, hi: np.ndarray, exc: Exception) -> ReadError:
        """Find the first chunk of the box that cannot be read and name it."""
        chunks = self.chunks
        for unit in self._units(lo, hi, chunks):
            c_lo = np.maximum(np.array(unit) * chunks, lo)
            c_hi = np.minimum((np.array(unit) + 1) * chunks, hi)
            try:
                self.array[self._selection(c_lo, c_hi)]
            except Exception as inner:
                outer = np.array(unit) * chunks // self._grid()
                path = self._file_of(tuple(int(v) for v in outer))
                where = f" (file {path})" if path is not None else ""
                return ReadError(
                    f"{self.label}: chunk {unit} (x, y, z) cannot be read{where}: {one_line(inner)}"
                )
        return ReadError(f"{self.label}: voxels {lo.tolist()}..{hi.tolist()} cannot be read: "
                         f"{one_line(exc)}")

    # ------------------------------------------------------------------ whole-level access
    def to_dask(self) -> Any:
        """The level as a lazy dask array in splinecast order (x, y, z); nothing is read."""
        da = require("dask.array", self.label, action="reading")
        arr = da.from_zarr(self.array)
        arr = arr[tuple(self.select)] if self.select else arr
        return arr.transpose(self.order)

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
        return str(self.metadata.get("name", self.path.name))

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
        try:
            return np.asarray(self.root[f"{TABLES_GROUP}/{name}/{level}"][...])
        except KeyError:
            return None
        except Exception as exc:
            raise ReadError(f"{self.path}: table {name}/{level} cannot be read: "
                            f"{one_line(exc)}") from None

    def __repr__(self) -> str:
        shapes = ", ".join(fmt_shape(lv.shape) for lv in self.levels)
        return (f"MultiscaleVolume(name={self.name!r}, dtype={self.dtype}, levels=[{shapes}], "
                f"spacing={self.spacing}, origin={self.origin})")


# --------------------------------------------------------------------------- opening
def _attrs(node: Any) -> dict[str, Any]:
    return dict(node.attrs.asdict() if hasattr(node.attrs, "asdict") else node.attrs)


def _leading_selection(shape: tuple[int, ...], names: tuple[str, ...], n_lead: int,
                       channel: int | None, timepoint: int | None, label: str) -> tuple[int, ...]:
    select = []
    for axis in range(n_lead):
        size, name = shape[axis], names[axis]
        wanted = timepoint if name.lower() in ("t", "time") else channel
        if wanted is None:
            if size != 1:
                option = "timepoint" if name.lower() in ("t", "time") else "channel"
                raise ReadError(
                    f"{label}: axis {name!r} has {size} entries; splinecast renders one scalar "
                    f"field: open it with splinecast.io.omezarr.open_zarr(path, {option}=N)"
                )
            wanted = 0
        if not 0 <= wanted < size:
            raise ParameterError(f"{label}: axis {name!r} has {size} entries, asked for {wanted}")
        select.append(int(wanted))
    return tuple(select)


def _level(index: int, path: str, array: Any, scale: Any, translation: Any,
           select: tuple[int, ...], order: tuple[int, int, int], label: str,
           folder: Path | None, complete: bool) -> Level:
    ndim = len(array.shape)
    if ndim != len(select) + 3:
        raise ReadError(f"{label}: level {path!r} has {ndim} dimensions, the axes list "
                        f"{len(select) + 3}")
    check_dtype(np.dtype(array.dtype), f"{label}: level {path!r}")
    spatial_shape = array.shape[len(select):]
    spatial_scale = scale[len(select):]
    spatial_translation = translation[len(select):]
    level = Level(
        index=index,
        path=path,
        array=array,
        shape=tuple(int(spatial_shape[a]) for a in order),  # type: ignore[arg-type]
        spacing=tuple(float(spatial_scale[a]) for a in order),  # type: ignore[arg-type]
        origin=tuple(float(spatial_translation[a]) for a in order),  # type: ignore[arg-type]
        label=f"{label}/{path}",
        select=select,
        order=order,
        folder=folder,
        complete=complete,
    )
    if min(level.shape) < 1:
        raise ReadError(f"{level.label}: the level is empty (shape {fmt_shape(level.shape)})")
    return level


def open_zarr(
    path: str | os.PathLike[str], *, channel: int | None = None, timepoint: int | None = None
) -> Any:
    """Open an OME-Zarr image or a plain Zarr array lazily (metadata only).

    Parameters
    ----------
    path : str or path-like
        The image's folder (``x.zarr``, ``x.ome.zarr``), a ``bioformats2raw`` collection, or a
        Zarr array's folder.
    channel, timepoint : int, optional
        Which entry of a channel or time axis longer than 1 to read.

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
    path = Path(os.fspath(path))
    if not path.exists():
        raise ReadError(f"{path}: no such file or folder")
    node = open_store(path)
    zarr = _zarr(path)
    label = str(path)
    attrs = _attrs(node)
    local = path.absolute()
    if isinstance(node, zarr.Array):
        return _plain_array(path, node, label)
    ome = attrs.get("ome") if isinstance(attrs.get("ome"), dict) else attrs
    if "bioformats2raw.layout" in ome and "multiscales" not in ome:
        series = sorted(k for k in node.group_keys() if k.isdigit())
        if not series:
            raise ReadError(f"{label}: bioformats2raw collection without images")
        if len(series) > 1:
            warnings.warn(f"{label}: holds {len(series)} images; reading the first (0/)",
                          stacklevel=2)
        return open_zarr(path / "0", channel=channel, timepoint=timepoint)
    ours = attrs.get(ATTRIBUTE, {}) if isinstance(attrs.get(ATTRIBUTE), dict) else {}
    kind = ours.get("kind")
    if kind is not None:
        opener = store_opener(kind)
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
        try:
            array = node[dataset.path]
        except KeyError:
            raise ReadError(
                f"{label}: level {dataset.path!r} listed in the metadata is missing"
            ) from None
        if not isinstance(array, zarr.Array):
            raise ReadError(f"{label}: level {dataset.path!r} is not an array")
        select = _leading_selection(tuple(array.shape), image.axis_names, n_lead, channel,
                                    timepoint, label)
        levels.append(_level(index, dataset.path, array, dataset.scale, dataset.translation,
                             select, order, label, local / dataset.path, complete))
    units = {u for u in image.units[n_lead:] if u}
    metadata: dict[str, Any] = {
        "name": path.name,
        "source": str(local),
        "format": f"ome-zarr {image.version}",
    }
    if len(units) == 1:
        metadata["units"] = units.pop()
    if image.downsampling:
        metadata["downsampling"] = image.downsampling
    metadata.update(ours.get("source_metadata", {}))
    return MultiscaleVolume(path=path, levels=levels, metadata=metadata, attributes=ours,
                            root=node)


def _plain_array(path: Path, array: Any, label: str) -> MultiscaleVolume:
    shape = tuple(array.shape)
    names = getattr(array.metadata, "dimension_names", None) or ()
    lead = len(shape) - 3
    if lead < 0 or any(n != 1 for n in shape[:lead]):
        raise ReadError(f"{label}: expected a 3D array, got shape {fmt_shape(shape)}")
    order = spatial_order(tuple(str(n) for n in names[lead:])) if names else (2, 1, 0)
    level = _level(0, "", array, (1.0,) * len(shape), (0.0,) * len(shape), (0,) * lead, order,
                   label, None, False)
    level.folder = path.absolute()
    level.label = label
    return MultiscaleVolume(
        path=path,
        levels=[level],
        metadata={"name": path.name, "source": str(path.absolute()),
                  "format": f"zarr v{array.metadata.zarr_format} array"},
    )
