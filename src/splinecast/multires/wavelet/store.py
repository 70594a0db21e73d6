"""Spline-wavelet pyramids in a Zarr store: written streamed, read lazily (Steinberger 2010, §4).

``sc.build_pyramid(src, "x.zarr", kind="wavelet", degree=3)`` (``splinecast pyramid SRC -o
x.zarr --wavelet 3``) runs :func:`.wavelet.transform.decompose` block by block with a
:class:`ZarrSink`, so the coarse levels and detail subbands go straight to the store and peak
memory is a few blocks, whatever the volume's size. ``sc.read("x.zarr")`` then returns a
:class:`WaveletVolume`, whose details are read from the store only when the reconstructor needs
them (:meth:`WaveletVolume.load_details`).

Layout of the store (a Zarr v3 group)
    ``wavelet/coarse/<j>``, j = 1..J
        Level-``j`` B-spline coefficients over the level's whole window
        (:attr:`.WaveletLayout.length`), indexed ``[i, j, k]`` along x, y, z (splinecast's
        order; these are spline coefficients on a padded window, not image samples, so they
        are not declared as NGFF ``multiscales`` datasets and other viewers ignore them).
    ``wavelet/detail/<j>/<band>``
        The seven detail subbands (``LLH`` .. ``HHH``, letters per axis x, y, z) that with
        ``coarse/<j>`` reconstruct level ``j - 1``; shapes :meth:`.WaveletLayout.band_shape`.
    ``wavelet/hull/<j>``, j = 0..J
        Per chunk of level ``j`` (shape ``layout.chunks(j) + (2,)``, float64): ``[min, max]``
        of the level's coefficients acting on the chunk's region, a conservative bound of the
        pure level-``j`` spline there (:mod:`.wavelet.ranges`). The view-dependent selection's
        ranges are derived from them when the store is opened.

    All arrays are zstd-compressed with a checksum, in chunks of :data:`STORE_CHUNK` nodes per
    axis, every chunk written. The root attribute ``"splinecast"`` says ``kind: "wavelet"``,
    the degree, levels, chunk edge ``k``, the volume's shape, spacing and origin, the
    coefficient dtype, the value range of the voxels, the wavelet and the boundary rules
    (:mod:`.wavelet.layout`: the voxels mirrored about the first and last voxel as the
    ``bspline`` models do, then whole-sample symmetric coarse / half-sample symmetric detail
    sequences for odd degree, half-sample symmetric / antisymmetric for even degree).

Lazy details
    The reconstructor (:class:`.wavelet.reconstruct.ChunkReconstructor`) asks for the details one
    block of :data:`STORE_CHUNK` nodes per axis at a time (:meth:`WaveletVolume.read_detail_block`:
    one store chunk of each of the seven subbands), the first time a chunk whose details are active
    needs them, and keeps them within its byte budget (least recently used blocks go first). A frame
    therefore reads only the details of the chunks it refines; ``details_read`` counts the blocks
    read so far.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from ..._atomic import atomic_directory
from ...errors import ParameterError, ReadError, limits
from ...io._common import fmt_shape, one_line, require
from ...io.omezarr import ATTRIBUTE
from ...volume import GridGeometry
from ..store.build_source import open_pyramid_source
from .filters import spline_wavelet
from .layout import DETAIL_BANDS, WaveletLayout
from .reconstruct import DETAIL_BLOCK
from .transform import WaveletPyramid, decompose

__all__ = ["KIND", "STORE_CHUNK", "ZarrSink", "WaveletVolume", "build_wavelet_pyramid",
           "open_wavelet_store"]

#: The ``kind`` of a spline-wavelet store in the root attribute ``"splinecast"``.
KIND = "wavelet"
#: Group holding the coefficient arrays.
GROUP = "wavelet"
#: Nodes per axis of one store chunk (a multiple of the default decomposition block's half), the
#: reconstructor's detail block: one block, one chunk of each subband.
STORE_CHUNK = DETAIL_BLOCK
#: Most levels a store may declare (2^20 voxels per axis need at most 18 with k >= 4).
MAX_LEVELS = 24
#: Largest chunk edge a store may declare (a brick is (k + d)^3 coefficients).
MAX_CHUNK = 256
#: Coarse nodes per axis of one decomposition block (a multiple of STORE_CHUNK: aligned writes).
BLOCK = 64

_BOUNDARY = {
    "voxels": "mirrored about the first and last voxel (a[-m] = a[m]), as the bspline models",
    "odd degree": "coarse sequences whole-sample symmetric, details half-sample symmetric",
    "even degree": "coarse sequences half-sample symmetric, details half-sample antisymmetric",
}


class ZarrSink:
    """The :class:`~.wavelet.transform.Sink` of a Zarr group: one array per name under
    ``wavelet/`` (chunks of :data:`STORE_CHUNK` nodes, zstd with a checksum)."""

    def __init__(self, group: Any) -> None:
        self.group = group

    def create(self, name: str, shape: tuple[int, ...], dtype: np.dtype) -> Any:
        from zarr.codecs import ZstdCodec

        chunks = tuple(max(1, min(STORE_CHUNK, int(n))) for n in shape)
        return self.group.create_array(
            f"{GROUP}/{name}", shape=tuple(int(n) for n in shape), dtype=np.dtype(dtype),
            chunks=chunks, compressors=ZstdCodec(level=3, checksum=True), fill_value=0,
            config={"write_empty_chunks": True})


class _SourceArray:
    """A :mod:`.store.pyramid` source as a sliceable array (``array[a:b, c:d, e:f]``)."""

    def __init__(self, source: Any) -> None:
        self.source = source
        self.shape = tuple(int(n) for n in source.shape)
        self.dtype = source.dtype

    def __getitem__(self, box: tuple[slice, slice, slice]) -> np.ndarray:
        lo = np.array([s.start for s in box], dtype=np.int64)
        hi = np.array([s.stop for s in box], dtype=np.int64)
        return self.source.read(lo, hi)


def _coefficient_dtype(voxels: np.dtype, dtype: Any) -> np.dtype:
    if dtype is None:
        return np.dtype(np.float64 if voxels == np.float64 else np.float32)
    out = np.dtype(dtype)
    if out not in (np.dtype(np.float32), np.dtype(np.float64)):
        raise ParameterError(f"dtype must be float32 or float64, got {dtype!r}")
    return out


def build_wavelet_pyramid(
    source: Any,
    path: str | os.PathLike[str],
    degree: int = 3,
    levels: int | None = None,
    chunk: int = 8,
    dtype: Any = None,
    overwrite: bool = False,
    *,
    name: str | None = None,
    block: int = BLOCK,
    progress: bool = False,
    allow_external: bool | None = None,
) -> WaveletVolume:
    """Write the spline-wavelet decomposition of ``source`` to a Zarr store at ``path``.

    Parameters
    ----------
    source : path, Volume, MultiscaleVolume, zarr.Array or numpy array
        As for :func:`splinecast.build_pyramid`; its voxels are the level-0 B-spline
        coefficients (the ``bspline`` models' default, no prefilter).
    path : path
        The store to create (a folder, conventionally ``name.zarr``).
    degree : int
        B-spline degree 1, 2 or 3 (rendered with model ``bspline<degree>``).
    levels : int, optional
        Decomposition steps J (default: the fewest whose coarsest chunk spans the volume).
    chunk : int
        Chunk edge k in nodes (even, at least 4; the thesis' 8).
    dtype : float32 or float64, optional
        Coefficient storage type (default: float64 for float64 voxels, else float32).
    overwrite : bool
        Replace an existing store.
    name : str, optional
        The image's name in the metadata (default: the store's file name).
    block : int
        Coarse nodes per axis of one decomposition block: peak memory is about
        ``60 (2 block + 8)^3`` bytes.
    progress : bool
        Print one line per level on stderr.
    allow_external : bool, optional
        When ``source`` is a path: let its header name data files outside its folder (as in
        :func:`splinecast.build_pyramid`).

    Returns
    -------
    WaveletVolume
        The written store, opened lazily.

    Raises
    ------
    ParameterError
        Bad ``degree``, ``levels``, ``chunk``, ``dtype`` or source, or an existing store without
        ``overwrite``. Nothing is left at ``path`` on failure.
    """
    zarr = require("zarr", path, action="writing", error=ParameterError)
    path = Path(os.fspath(path))
    if isinstance(degree, bool) or degree not in (1, 2, 3):
        raise ParameterError(f"degree must be 1, 2 or 3, got {degree!r}")
    src = open_pyramid_source(source, path, levels, overwrite, allow_external)
    if min(src.shape) < 2:
        raise ParameterError(f"{src.label}: a wavelet pyramid needs at least 2 voxels per axis, "
                             f"got {fmt_shape(src.shape)}")
    if src.dask is not None:
        src.read = lambda lo, hi, d=src.dask: np.asarray(
            d[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]].compute())
    coeff_dtype = _coefficient_dtype(src.dtype, dtype)
    start = time.perf_counter()
    with atomic_directory(path, overwrite=overwrite) as temp:
        root = zarr.open_group(os.fspath(temp), mode="w")
        pyramid = decompose(_SourceArray(src), degree, levels, chunk, coeff_dtype,
                            ZarrSink(root), block=block)
        lay = pyramid.layout
        for j in range(lay.levels + 1):
            table = np.stack([pyramid.hull_lo[j], pyramid.hull_hi[j]], axis=-1)
            arr = root.create_array(f"{GROUP}/hull/{j}", shape=table.shape, dtype=np.float64,
                                    chunks=table.shape, fill_value=0)
            arr[...] = table
        value_range = [float(pyramid.hull_lo[0].min()), float(pyramid.hull_hi[0].max())]
        keep = {k: src.metadata[k] for k in ("inside", "default_iso", "modality", "units")
                if k in src.metadata and isinstance(src.metadata[k], (str, int, float))}
        wavelet = spline_wavelet(lay.degree)
        root.attrs[ATTRIBUTE] = {
            "version": 1, "kind": KIND, "name": name or path.name,
            "degree": lay.degree, "levels": lay.levels, "chunk": lay.chunk,
            "shape": list(lay.shape), "window": list(lay.window),
            "spacing": [float(s) for s in src.spacing], "origin": [float(o) for o in src.origin],
            "dtype": coeff_dtype.name, "value_range": value_range,
            "wavelet": getattr(wavelet, "name", f"CDF spline wavelet of degree {lay.degree}"),
            "boundary": _BOUNDARY, "model": f"bspline{lay.degree}",
            "source": str(src.metadata.get("source", src.label)), "source_metadata": keep,
            "decompose_seconds": time.perf_counter() - start,
        }
    if progress:
        import sys

        print(f"{path.name}: wavelet degree {degree}, {lay.levels} levels in "
              f"{time.perf_counter() - start:.1f} s", file=sys.stderr)
    return open_wavelet_store(path)


@dataclass(eq=False)
class WaveletVolume(GridGeometry):
    """A spline-wavelet pyramid in a Zarr store, opened lazily (see the module docstring).

    Geometry (``shape``, ``spacing``, ``origin``, ``bounds``) is the source volume's, so
    cameras frame it like a :class:`~splinecast.Volume`; ``Scene(wv, lod=ε)`` renders it with
    model ``bspline<degree>`` (:class:`.scenes.wavelet.WaveletScene`).

    Attributes
    ----------
    path : Path
    layout : WaveletLayout
    dtype : numpy dtype
        Of the stored coefficients.
    metadata : dict
        ``name``, ``source``, ``format`` and what the build kept of the source's metadata.
    attributes : dict
        The root attribute ``"splinecast"`` (kind, degree, boundary rules, ...).
    hull_lo, hull_hi : list of arrays
        Per level 0..J, per chunk: the stored conservative value bounds.
    details_read : int
        Store chunks of details read so far (all seven subbands of one chunk count once).
    """

    path: Path
    layout: WaveletLayout
    dtype: np.dtype
    spacing: tuple[float, float, float]
    origin: tuple[float, float, float]
    metadata: dict[str, Any]
    attributes: dict[str, Any]
    root: Any
    hull_lo: list[np.ndarray]
    hull_hi: list[np.ndarray]
    details_read: int = 0
    _levels: dict[str, Any] = field(default_factory=dict)

    @property
    def shape(self) -> tuple[int, int, int]:  # type: ignore[override]
        return self.layout.shape

    @property
    def degree(self) -> int:
        """B-spline degree (the matching model is ``bspline<degree>``)."""
        return self.layout.degree

    @property
    def name(self) -> str:
        return str(self.metadata.get("name", self.path.name))

    @property
    def value_range(self) -> tuple[float, float]:
        """``(min, max)`` of the source's voxels (stored by the build)."""
        lo, hi = self.attributes["value_range"]
        return float(lo), float(hi)

    @cached_property
    def ranges(self) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Selection ranges per chunk of levels 0..J-1 (:func:`.selection_ranges`)."""
        from .ranges import selection_ranges

        return selection_ranges(self.layout, self.hull_lo, self.hull_hi)

    def _array(self, name: str) -> Any:
        """The checked :class:`~splinecast.io.omezarr.Level` of array ``wavelet/<name>``."""
        level = self._levels.get(name)
        if level is None:
            level = _checked_array(self.root, self.path, name, self._expected_shape(name),
                                   self.dtype)
            self._levels[name] = level
        return level

    def _expected_shape(self, name: str) -> tuple[int, ...]:
        parts = name.split("/")
        if parts[0] == "coarse":
            return self.layout.length(int(parts[1]))
        return self.layout.band_shape(int(parts[1]), parts[2])

    def _read(self, name: str, box: tuple[slice, ...] | None = None) -> np.ndarray:
        """Coefficients ``box`` (whole array by default) of ``wavelet/<name>``: every chunk file
        checked before it is opened, the box's bytes checked against the memory guard."""
        level = self._array(name)
        if box is None:
            return level.read((0, 0, 0), level.shape)
        return level.read([s.start for s in box], [s.stop for s in box])

    def coarse(self, level: int) -> np.ndarray:
        """Level ``level``'s coefficients (1..J), read whole."""
        if not 1 <= level <= self.layout.levels:
            raise ParameterError(f"level must be in 1..{self.layout.levels}, got {level!r}")
        return self._read(f"coarse/{level}")

    # ---------------------------------------------------------------- lazy details
    def read_detail_block(self, level: int, block: tuple[int, int, int]) -> list[np.ndarray]:
        """The seven level-``level`` detail subbands (in ``DETAIL_BANDS`` order) over nodes
        ``STORE_CHUNK * block`` onwards, at most :data:`STORE_CHUNK` per axis (one store chunk
        of each subband): the reconstructor's loader. Counts in ``details_read``."""
        lo = [STORE_CHUNK * int(b) for b in block]
        out = []
        for band in DETAIL_BANDS:
            # A block past a shorter subband's end (detail sequences may be a node shorter than
            # the coarse ones) holds none of its nodes: nothing to read.
            shape = self.layout.band_shape(level, band)
            box = tuple(slice(a, min(a + STORE_CHUNK, n)) for a, n in zip(lo, shape, strict=True))
            if any(s.start >= s.stop for s in box):
                out.append(np.zeros((0, 0, 0), dtype=self.dtype))
            else:
                out.append(self._read(f"detail/{level}/{band}", box))
        self.details_read += 1
        return out

    @cached_property
    def pyramid(self) -> WaveletPyramid:
        """A :class:`~.wavelet.transform.WaveletPyramid` view for the reconstructor: the
        coarsest level read, no details (they come block by block through
        :meth:`read_detail_block`)."""
        lay = self.layout
        coarse = {lay.levels: self.coarse(lay.levels)}
        return WaveletPyramid(lay, coarse, {}, self.hull_lo, self.hull_hi, self.dtype)

    def load(self) -> WaveletPyramid:
        """Everything read into memory: an in-memory
        :class:`~.wavelet.transform.WaveletPyramid` (every coarse level and detail subband)."""
        lay = self.layout
        coarse = {j: self.coarse(j) for j in range(1, lay.levels + 1)}
        details = {j: {b: self._read(f"detail/{j}/{b}") for b in DETAIL_BANDS}
                   for j in range(1, lay.levels + 1)}
        return WaveletPyramid(lay, coarse, details, list(self.hull_lo), list(self.hull_hi),
                              self.dtype)

    def __repr__(self) -> str:
        lay = self.layout
        return (f"WaveletVolume(name={self.name!r}, shape={fmt_shape(lay.shape)}, "
                f"degree={lay.degree}, levels={lay.levels}, chunk={lay.chunk}, "
                f"dtype={self.dtype})")


def _checked_array(root: Any, path: Path, name: str, shape: tuple[int, ...],
                   dtype: np.dtype) -> Any:
    """Array ``wavelet/<name>`` through the guarded store's checks, with the shape and data
    type the layout and the metadata promise."""
    from ...io.omezarr import guarded_array

    level = guarded_array(root, f"{GROUP}/{name}", str(path), path)
    if level.shape != tuple(shape):
        raise ReadError(f"{path}: {GROUP}/{name} has shape {fmt_shape(level.shape)}, the "
                        f"metadata imply {fmt_shape(shape)}")
    if level.dtype != dtype:
        raise ReadError(f"{path}: {GROUP}/{name} holds {level.dtype}, the metadata say {dtype}")
    return level


def _layout(attributes: dict[str, Any], path: Path) -> tuple[WaveletLayout, np.dtype,
                                                            tuple[float, ...], tuple[float, ...]]:
    """The layout, coefficient type, spacing and origin the root attribute describes, every
    field checked against :mod:`splinecast.errors.limits` before anything is sized by it."""
    where = f"{path}: attribute {ATTRIBUTE!r}"
    missing = [k for k in ("shape", "degree", "levels", "chunk", "dtype", "spacing", "origin",
                           "value_range") if k not in attributes]
    if missing:
        raise ReadError(f"{where} lacks {', '.join(missing)}")
    shape = limits.check_shape(attributes["shape"], f"{where}: shape", error=ReadError)
    if min(shape) < 2:
        raise ReadError(f"{where}: shape must have at least 2 voxels per axis, got "
                        f"{fmt_shape(shape)}")
    degree = limits.check_count(attributes["degree"], f"{where}: degree", lo=1, hi=3,
                                error=ReadError)
    levels = limits.check_count(attributes["levels"], f"{where}: levels", lo=1, hi=MAX_LEVELS,
                                error=ReadError)
    chunk = limits.check_count(attributes["chunk"], f"{where}: chunk", lo=4, hi=MAX_CHUNK,
                               error=ReadError)
    if chunk % 2:
        raise ReadError(f"{where}: chunk must be even, got {chunk}")
    model = attributes.get("model", f"bspline{degree}")
    if model != f"bspline{degree}":
        raise ReadError(f"{where}: model {limits.shorten(model)} does not match degree {degree}")
    name = attributes["dtype"]
    if name not in ("float32", "float64"):
        raise ReadError(f"{where}: dtype must be float32 or float64, got {limits.shorten(name)}")
    spacing = limits.check_spacing(attributes["spacing"], f"{where}: spacing", ReadError)
    origin = limits.check_origin(attributes["origin"], spacing, f"{where}: origin", ReadError)
    layout = WaveletLayout(shape, degree, levels, chunk)  # type: ignore[arg-type]
    limits.check_shape(layout.window, f"{where}: the padded window of {levels} levels",
                       error=ReadError)
    return layout, np.dtype(name), spacing, origin


def _hull(root: Any, path: Path, layout: WaveletLayout, level: int) -> np.ndarray:
    """The stored ``[min, max]`` table of ``level``: float64 of shape ``chunks + (2,)``, every
    chunk file present, finite with ``min <= max``."""
    from ...io.omezarr import _refused, read_array

    zarr = require("zarr", path, action="reading")
    key = f"{GROUP}/hull/{level}"
    expected = layout.chunks(level) + (2,)
    where = f"{path}/{key}"
    try:
        array = root[key]
        if not isinstance(array, zarr.Array):
            raise ReadError(f"{where}: is not a Zarr array")
        if tuple(array.shape) != expected or np.dtype(array.dtype) != np.float64:
            raise ReadError(f"{where}: holds {fmt_shape(array.shape)} {array.dtype}, expected "
                            f"{fmt_shape(expected)} float64")
        grid = limits.check_shape(array.chunks, f"{where}: chunk shape", ndim=4,
                                  error=ReadError)
        limits.check_memory(limits.nbytes(expected, 8), "the table", where, ReadError)
        counts = [-(-n // c) for n, c in zip(expected, grid, strict=True)]
        if int(np.prod(counts)) > limits.MAX_CHUNKS_PER_READ:
            raise ReadError(f"{where}: chunks of {fmt_shape(grid)} are too small")
        for unit in np.ndindex(*counts):
            file = path / key / array.metadata.encode_chunk_key(unit)
            if not file.is_file():
                raise ReadError(f"{where}: chunk file {file} is missing")
        table = np.asarray(read_array(array, where), dtype=np.float64)
    except KeyError:
        raise ReadError(f"{path}: array {key} is missing") from None
    except ReadError:
        raise
    except Exception as exc:  # zarr and the codecs raise many kinds for damaged data
        refused = _refused(exc)
        raise (refused or ReadError(f"{where}: cannot be read ({one_line(exc)})")) from None
    if not np.all(np.isfinite(table)) or np.any(table[..., 0] > table[..., 1]):
        raise ReadError(f"{where}: value bounds must be finite with min <= max")
    return table


def open_wavelet_store(path: str | os.PathLike[str], root: Any = None,
                       attributes: dict[str, Any] | None = None) -> WaveletVolume:
    """Open a store written by :func:`build_wavelet_pyramid` (metadata and hull tables only).

    The store is read through the guarded store of :mod:`splinecast.io.omezarr` (metadata small
    valid JSON, only regular files inside the store, chunks bounded before decompression); every
    field of the root attribute is checked against :mod:`splinecast.errors.limits`, and every
    array's shape and type against the layout it implies, before anything is allocated.

    Raises
    ------
    ReadError
        One line naming the store: not such a store, or its metadata, tables or arrays are
        damaged or inconsistent.
    """
    path = Path(os.fspath(path))
    if root is None:
        from ...io.omezarr import open_store

        root = open_store(path)
    if attributes is None:
        from ...io.omezarr import _our_attributes

        try:
            attributes = _our_attributes(dict(root.attrs).get(ATTRIBUTE),
                                         f"{path}: attribute {ATTRIBUTE!r}")
        except AttributeError:
            attributes = {}
    if not isinstance(attributes, dict) or attributes.get("kind") != KIND:
        raise ReadError(f"{path}: not a splinecast wavelet store")
    try:
        layout, dtype, spacing, origin = _layout(attributes, path)
    except ParameterError as exc:  # the layout's own consistency checks
        raise ReadError(f"{path}: damaged wavelet store metadata ({one_line(exc)})") from None
    hulls = [_hull(root, path, layout, j) for j in range(layout.levels + 1)]
    metadata: dict[str, Any] = {"name": attributes.get("name", path.name),
                                "source": str(path.absolute()), "format": "splinecast wavelet"}
    source_metadata = attributes.get("source_metadata", {})
    if isinstance(source_metadata, dict):
        metadata.update(source_metadata)
    wv = WaveletVolume(path, layout, dtype, spacing, origin, metadata,  # type: ignore[arg-type]
                       attributes, root, [t[..., 0] for t in hulls], [t[..., 1] for t in hulls])
    # Every array's metadata now, so a store whose arrays contradict the layout (or miss) is
    # refused on opening rather than in the middle of a frame.
    for j in range(1, layout.levels + 1):
        wv._array(f"coarse/{j}")
        for band in DETAIL_BANDS:
            wv._array(f"detail/{j}/{band}")
    return wv
