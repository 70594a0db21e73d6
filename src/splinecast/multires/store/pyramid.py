"""Building an OME-Zarr 0.5 brick pyramid from any volume, chunk by chunk, in bounded memory.

Downsampling (the choice decides the NGFF translation; see also :mod:`.cut.octree`)
-----------------------------------------------------------------------------------
Vertex-centred (:mod:`.store.downsample`): coarse voxel ``c`` sits exactly on fine voxel ``2 c`` and
holds the binomial average ``(f[2c-1] + 2 f[2c] + f[2c+1]) / 4`` along every halved axis (the
separable 3x3x3 ``[1, 2, 1] / 4`` filter, exact for linear data, zero response at the fine Nyquist
frequency), with the fine grid mirrored about its first and last voxel outside. A halved axis of
``n`` voxels gives ``n // 2 + 1`` coarse ones, so every level spans at least the whole box of
level 0. Consequences:

- Level ``L`` has ``scale = spacing * f_L`` and the *same* ``translation`` as level 0 (``f_L`` the
  power of two by which the axis was halved); the coarse voxel centres are a subset of the fine
  ones. (A 2x2x2 mean would put them half a fine voxel further along, ``translation +=
  (f_L - 1) / 2 * spacing``, and brick boundaries of adjacent levels would not line up.)
- Brick ``b`` of ``B`` cells on level ``L`` covers level-0 voxels ``[b B f_L, (b + 1) B f_L]``
  exactly: the octree's bricks nest, and fine and coarse grids share the points of a coarse
  brick's faces, which is what crack-free level boundaries need.

Which axes are halved: at each level, every axis longer than one brick whose current voxel size is
within 1.5x of the finest such axis (anisotropic stacks, e.g. spacing (0.2, 0.2, 1) um, first get
halved in x and y only, as ome-zarr-py and ngff-zarr do). Levels are added until the coarsest fits
in one brick (or ``levels`` are made).

Storage: one Zarr v3 array per level (``0``, ``1``, ...; dimension names ``z, y, x``), chunks of one
brick (``B^3``) in shards of about ``128^3`` voxels, zstd with a checksum (so a damaged chunk is
detected instead of decoded into garbage), every chunk written (a missing file is then damage, not
"fill value"). Per-brick value ranges go to the ``minmax`` table (:mod:`.store.tables`).

Memory: the work is split into one task per output shard (dask, a few threads). A task holds one
shard of its level and at most a slab of the finer level around it, so peak memory depends on the
shard size and the number of threads, never on the volume's size.
"""

from __future__ import annotations

import math
import os
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from ..._atomic import atomic_directory
from ...errors import ParameterError
from ...io._common import fmt_shape, require
from ...io.ngff import multiscales_attributes, ngff_unit, to_ngff
from ...io.omezarr import ATTRIBUTE, Level
from ..cut.octree import GHOST, brick_counts
from ..wavelet.store import build_wavelet_pyramid
from .build_source import PyramidSource, level_source, open_pyramid_source
from .downsample import binomial_halve, fine_range
from .label_downsample import DESCRIPTION as LABEL_DOWNSAMPLING_TEXT
from .label_downsample import mode_halve
from .tables import MINMAX, window_minmax, write_table

__all__ = ["build_pyramid", "plan_levels", "DOWNSAMPLING"]

#: NGFF ``multiscales[0]["type"]`` of pyramids built here.
DOWNSAMPLING = "binomial-vertex-centred"
#: NGFF ``multiscales[0]["type"]`` of label pyramids built here (:mod:`.store.label_downsample`).
LABEL_DOWNSAMPLING = "mode-vertex-centred"
_SHARD_VOXELS = 128  # target shard side: 2 MiB of uint8 per shard file
_SLAB = 32  # output planes per downsampling step inside a task (bounds the temporaries)
_WRITE_BATCH = 64  # chunks zarr encodes per batch while the build writes
_READ_BYTES = 64 << 20  # fine voxels one downsampling read may hold (fewer reads: fewer decodes)


# --------------------------------------------------------------------------- planning
def plan_levels(
    shape: Any, spacing: Any, brick: int, levels: int | None = None
) -> list[tuple[tuple[int, int, int], tuple[int, int, int]]]:
    """Shapes and per-axis factors of the pyramid's levels, finest first.

    Returns a list of ``(shape, factor)`` (x, y, z each), ``factor`` the power of two by which
    each axis was halved relative to level 0.

    >>> plan_levels((100, 100, 20), (1, 1, 1), 32)
    [((100, 100, 20), (1, 1, 1)), ((51, 51, 20), (2, 2, 1)), ((26, 26, 20), (4, 4, 1))]
    """
    shape = [int(n) for n in shape]
    factor = [1, 1, 1]
    plan = [(tuple(shape), tuple(factor))]
    while levels is None or len(plan) < levels:
        long = [a for a in range(3) if shape[a] > brick + 1]  # more than one brick of cells
        if not long:
            break
        size = [spacing[a] * factor[a] for a in range(3)]
        finest = min(size[a] for a in long)
        for a in long:
            if size[a] <= 1.5 * finest:
                shape[a] = shape[a] // 2 + 1
                factor[a] *= 2
        plan.append((tuple(shape), tuple(factor)))
    return plan  # type: ignore[return-value]


# --------------------------------------------------------------------------- tasks
def _shard_regions(shape: tuple[int, ...], shard: int) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    counts = [max(1, math.ceil(n / shard)) for n in shape]
    for i in range(counts[0]):
        for j in range(counts[1]):
            for k in range(counts[2]):
                lo = np.array([i, j, k]) * shard
                yield lo, np.minimum(lo + shard, shape)


def _write(array: Any, lo: np.ndarray, hi: np.ndarray, block: np.ndarray) -> None:
    """Write an (x, y, z) block into a level array stored in NGFF order (z, y, x)."""
    region = tuple(slice(int(a), int(b)) for a, b in zip(to_ngff(lo), to_ngff(hi), strict=True))
    array[region] = np.ascontiguousarray(block.transpose(2, 1, 0))


def _bricks_of(lo: np.ndarray, hi: np.ndarray, counts: np.ndarray, brick: int):
    """Bricks whose first cell lies in the shard ``[lo, hi)``."""
    b_lo = lo // brick
    b_hi = np.minimum(-(-hi // brick), counts)
    return b_lo, np.maximum(b_hi, b_lo)


def _copy_task(source: PyramidSource, array: Any, lo: np.ndarray, hi: np.ndarray, brick: int,
               write: bool) -> tuple[np.ndarray, np.ndarray]:
    """Level 0: copy one shard from the source, and measure its bricks' value ranges."""
    shape = np.array(source.shape)
    ext_lo = np.maximum(lo - GHOST, 0)
    ext_hi = np.minimum(hi + GHOST + 1, shape)
    block = source.read(ext_lo, ext_hi)
    if write:
        core = tuple(slice(int(a), int(b)) for a, b in zip(lo - ext_lo, hi - ext_lo, strict=True))
        _write(array, lo, hi, block[core])
    counts = brick_counts(source.shape, brick)
    b_lo, b_hi = _bricks_of(lo, hi, counts, brick)
    return b_lo, window_minmax(block, ext_lo, b_lo, b_hi, brick, GHOST, shape)


def _downsample_task(fine: Any, halve: tuple[bool, bool, bool], shape: tuple[int, int, int],
                     array: Any, lo: np.ndarray, hi: np.ndarray,
                     brick: int, labels: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Level L+1: compute one shard (plus the ghost ring its bricks' ranges need) from level L.

    ``fine`` is anything with ``shape`` and ``read(lo, hi)``: the level just written, or for
    level 1 the source itself (level 0 equals it, and a memory-mapped source reads far faster
    than decoding the Zarr chunks again). The fine voxels are read in as few slabs as
    :data:`_READ_BYTES` allows (every read decodes whole chunks, so many thin reads decode the
    chunks on their boundaries over and over); the filter then runs a slab of output planes at a
    time over the slab in memory, which bounds its float64 temporaries. ``labels``: the
    weighted mode of :mod:`.store.label_downsample` instead of the binomial average.
    """
    halve_block = mode_halve if labels else binomial_halve
    out_shape = np.array(shape)
    ext_lo = np.maximum(lo - GHOST, 0)
    ext_hi = np.minimum(hi + GHOST + 1, out_shape)
    fine_shape = np.array(fine.shape)
    whole_lo, whole_hi = fine_range(ext_lo, ext_hi, halve, fine_shape)
    plane_bytes = int(np.prod(whole_hi[1:] - whole_lo[1:])) * np.dtype(fine.dtype).itemsize
    step = 2 if halve[0] else 1  # fine planes per output plane
    per_read = max(_SLAB, _READ_BYTES // max(1, plane_bytes * step) // _SLAB * _SLAB)
    slabs = []
    for r0 in range(int(ext_lo[0]), int(ext_hi[0]), per_read):
        r1 = min(r0 + per_read, int(ext_hi[0]))
        read_lo, read_hi = fine_range(np.array([r0, ext_lo[1], ext_lo[2]]),
                                      np.array([r1, ext_hi[1], ext_hi[2]]), halve, fine_shape)
        # C order and native bytes: the filter's loops run along the last axis (a raw source
        # memory-mapped x fastest reads as a Fortran-ordered block, several times slower to filter).
        block = fine.read(read_lo, read_hi)
        block = np.ascontiguousarray(block, dtype=block.dtype.newbyteorder("="))
        for s0 in range(r0, r1, _SLAB):
            out_lo = np.array([s0, ext_lo[1], ext_lo[2]])
            out_hi = np.array([min(s0 + _SLAB, r1), ext_hi[1], ext_hi[2]])
            slabs.append(halve_block(block, read_lo, fine_shape, halve, out_lo,
                                     out_hi - out_lo))
        del block
    out = np.concatenate(slabs, axis=0)
    core = tuple(slice(int(a), int(b)) for a, b in zip(lo - ext_lo, hi - ext_lo, strict=True))
    _write(array, lo, hi, out[core])
    counts = brick_counts(shape, brick)
    b_lo, b_hi = _bricks_of(lo, hi, counts, brick)
    return b_lo, window_minmax(out, ext_lo, b_lo, b_hi, brick, GHOST, out_shape)


# --------------------------------------------------------------------------- progress
class _Progress:
    """Task counts of one level on stderr, at most twice a second (dask callback)."""

    def __init__(self, label: str, total: int, enabled: bool) -> None:
        self.label, self.total, self.enabled = label, total, enabled
        self.done = 0
        self.last = 0.0
        self.start = time.perf_counter()

    def callback(self) -> Any:
        from dask.callbacks import Callback

        return Callback(posttask=self._posttask)

    def _posttask(self, *args: Any) -> None:
        self.done += 1
        now = time.perf_counter()
        if self.enabled and now - self.last > 0.5 and self.done < self.total:
            self.last = now
            print(f"\r{self.label}: {min(self.done, self.total)}/{self.total} shards "
                  f"({now - self.start:.1f} s)", end="", file=sys.stderr, flush=True)

    def finish(self) -> None:
        if self.enabled:
            print(f"\r{self.label}: {self.total}/{self.total} shards "
                  f"({time.perf_counter() - self.start:.1f} s)", file=sys.stderr, flush=True)


# --------------------------------------------------------------------------- build
def build_pyramid(
    source: Any,
    path: str | os.PathLike[str],
    brick: int = 32,
    levels: int | None = None,
    overwrite: bool = False,
    *,
    unit: str | None = None,
    name: str | None = None,
    shard: int | None = None,
    workers: int | None = None,
    progress: bool = True,
    allow_external: bool | None = None,
    kind: str = "plain",
    degree: int = 3,
    chunk: int = 8,
    dtype: Any = None,
    histograms: bool = False,
    bins: int | None = None,
    labels: bool | None = None,
) -> Any:
    """Write ``source`` as an OME-Zarr 0.5 brick pyramid at ``path``.

    ``kind="wavelet"`` writes a spline-wavelet pyramid instead
    (:func:`.wavelet.store.build_wavelet_pyramid`, with ``degree``, ``levels``, ``chunk``,
    ``dtype``, ``overwrite``, ``name`` and ``progress``) and returns its
    :class:`~.wavelet.store.WaveletVolume`.

    Parameters
    ----------
    source : path, Volume, MultiscaleVolume, zarr.Array, dask or numpy array
        Anything :func:`splinecast.read` reads (raw data stays memory-mapped), or an array: numpy
        and dask arrays are indexed ``[i, j, k]`` with ``i`` along x like ``Volume.data``; a bare
        ``zarr.Array`` follows its dimension names, else NGFF's ``z, y, x``.
    path : path
        The store to create (a folder, conventionally ``name.zarr``).
    brick : int
        Cells per brick along each axis (the same on every level); also the chunk size.
    levels : int, optional
        At most this many levels (default: until the coarsest fits in one brick).
    overwrite : bool
        Replace an existing store at ``path``.
    unit : str, optional
        Length unit of the spacing (``"millimeter"``, ``"mm"``, ``"micrometer"``, ...); by default
        the source's, when its header says.
    name : str, optional
        The image's name in the metadata (default: the store's file name).
    shard : int, optional
        Voxels per shard (file) side, a multiple of ``brick`` (default: about 128). One task
        writes one shard: peak memory grows with its cube.
    workers : int, optional
        Threads (default: up to 4, at most the cores). Peak memory grows with it.
    progress : bool
        Print per-level progress on stderr.
    allow_external : bool, optional
        When ``source`` is a path: let its header name data files outside its folder (see
        :func:`splinecast.read`; default: refused unless ``SPLINECAST_ALLOW_EXTERNAL_DATA=1``).
    kind : str
        ``"plain"`` (the binomial brick pyramid above) or ``"wavelet"``.
    degree, chunk, dtype
        Spline-wavelet pyramids only: B-spline degree 1..3, chunk edge in nodes, coefficient
        type (float32 or float64).
    histograms : bool
        Also store the sparse brick histograms of the ``cut="error"`` policy (group
        ``splinecast/hist2d``, :mod:`.store.hist_store`; one more pass over the source, tile by
        tile).
        Without them a ``Scene(..., cut="error")`` builds them when it opens, reading every level.
    bins : int, optional
        Histogram bins per value axis (default :data:`~.cut.histograms.DEFAULT_BINS`).
    labels : bool, optional
        A label volume (segmentation): the coarser levels take the most frequent label
        (:mod:`.store.label_downsample`), never an average, and the store says it is an NGFF label
        image (``image-label`` metadata, the source's colours kept), so readers render it as
        labels. Default: when the source is such a label image itself. Integer voxels only.

    Returns
    -------
    MultiscaleVolume or WaveletVolume
        The written store, opened lazily.

    Raises
    ------
    ParameterError
        Bad ``brick``/``levels``/``unit``, an existing store without ``overwrite``, a missing
        folder, or an unsupported source. Nothing is left at ``path`` on any failure: the store is
        written under a temporary name beside it and renamed when complete.
    """
    if kind == "wavelet":
        return build_wavelet_pyramid(source, path, degree, levels, chunk, dtype, overwrite,
                                     name=name, progress=progress,
                                     allow_external=allow_external)
    if kind != "plain":
        raise ParameterError(f"kind must be 'plain' or 'wavelet', got {kind!r}")
    if bins is not None and (isinstance(bins, bool) or int(bins) != bins
                             or not 2 <= bins <= 65536):
        raise ParameterError(f"bins must be an integer from 2 to 65536, got {bins!r}")
    zarr = require("zarr", path, action="writing", error=ParameterError)
    from zarr.codecs import ZstdCodec

    path = Path(os.fspath(path))
    integer = isinstance(brick, (int, np.integer)) and not isinstance(brick, bool)
    if not integer or not 4 <= brick <= 1024:
        raise ParameterError(f"brick must be an integer from 4 to 1024, got {brick!r}")
    brick = int(brick)
    src = open_pyramid_source(source, path, levels, overwrite, allow_external)
    if min(src.shape) < 1:
        raise ParameterError(f"{src.label}: the volume is empty ({fmt_shape(src.shape)})")
    image_label = src.metadata.get("image_label")
    if labels is None:
        labels = isinstance(image_label, dict)
    if labels and np.dtype(src.dtype).kind not in "iub":
        raise ParameterError(f"{src.label}: labels must be integers, the voxels are "
                             f"{np.dtype(src.dtype)} (convert the segmentation to an integer "
                             "type)")
    unit_name = ngff_unit(unit if unit is not None else src.metadata.get("units"))
    if unit is not None and unit_name is None:
        raise ParameterError(f"unit {unit!r} is not a length unit (try millimeter, micrometer)")
    plan = plan_levels(src.shape, src.spacing, brick, levels)
    if shard is None:
        shard = brick * max(1, _SHARD_VOXELS // brick)
    elif int(shard) != shard or shard < brick or shard % brick:
        raise ParameterError(f"shard must be a multiple of brick={brick}, got {shard!r}")
    shard = int(shard)
    workers = workers or max(1, min(4, os.cpu_count() or 1))
    import dask

    with atomic_directory(path, overwrite=overwrite) as temp:
        root = zarr.open_group(os.fspath(temp), mode="w")
        arrays, ranges = [], []
        for index, (shape, _factor) in enumerate(plan):
            arrays.append(root.create_array(
                str(index), shape=tuple(to_ngff(shape)), dtype=src.dtype.newbyteorder("="),
                chunks=(brick,) * 3, shards=(shard,) * 3,
                compressors=ZstdCodec(level=3, checksum=True), fill_value=0,
                dimension_names=("z", "y", "x"), config={"write_empty_chunks": True},
            ))
        for index, (shape, factor) in enumerate(plan):
            regions = list(_shard_regions(shape, shard))
            label = f"{path.name} level {index} ({fmt_shape(shape)})"
            bar = _Progress(label, len(regions), progress)
            if index == 0:
                write = src.dask is None
                if not write:  # dask writes a dask source itself, then tasks read it back
                    data = src.dask.transpose(2, 1, 0).rechunk((shard,) * 3)
                    with dask.config.set(scheduler="threads", num_workers=workers):
                        data.store(arrays[0], lock=False)
                    reader = level_source(_level_view(arrays[0], shape, index), src.label)
                else:
                    reader = src
                tasks = [dask.delayed(_copy_task)(reader, arrays[0], lo, hi, brick, write)
                         for lo, hi in regions]
            else:
                fine = _level_view(arrays[index - 1], plan[index - 1][0], index - 1)
                if index == 1 and src.dask is None:
                    fine = src  # equal to level 0 and cheaper to read than its chunks
                halve = tuple(factor[a] != plan[index - 1][1][a] for a in range(3))
                tasks = [dask.delayed(_downsample_task)(fine, halve, shape, arrays[index], lo,
                                                       hi, brick, bool(labels))
                         for lo, hi in regions]
            # zarr encodes a shard's chunks in batches instead of one at a time: a third
            # less CPU per shard written (reads do not gain), the bytes are the same.
            with bar.callback(), zarr.config.set({"codec_pipeline.batch_size": _WRITE_BATCH}):
                results = dask.compute(*tasks, scheduler="threads", num_workers=workers)
            bar.finish()
            counts = brick_counts(shape, brick)
            table = np.empty((*counts, 2), dtype=np.float64)
            for b_lo, block in results:
                b_hi = b_lo + np.array(block.shape[:3])
                table[b_lo[0]:b_hi[0], b_lo[1]:b_hi[1], b_lo[2]:b_hi[2]] = block
            ranges.append(table)
        for index, table in enumerate(ranges):
            write_table(root, MINMAX, index, table,
                        "value range [min, max] of each brick's voxels with ghosts "
                        f"({GHOST} per side); (+inf, -inf) when none is finite")
        lows = ranges[0][..., 0]
        highs = ranges[0][..., 1]
        value_range = [float(lows.min()), float(highs.max())]
        origin = src.origin
        datasets = [
            (str(i), tuple(s * f for s, f in zip(src.spacing, factor, strict=True)), origin)
            for i, (_shape, factor) in enumerate(plan)
        ]
        if labels:
            downsampling, described = LABEL_DOWNSAMPLING, {
                "description": LABEL_DOWNSAMPLING_TEXT,
                "method": "splinecast.multires.store.label_downsample.mode_halve",
            }
        else:
            downsampling, described = DOWNSAMPLING, {
                "description": "coarse voxel c = (f[2c-1] + 2 f[2c] + f[2c+1]) / 4 along every "
                               "halved axis, mirrored at the ends; voxel centres shared with "
                               "level 0 (translation unchanged)",
                "method": "splinecast.multires.store.downsample.binomial_halve",
            }
        attrs = multiscales_attributes(
            name or path.name, datasets, unit=unit_name, downsampling=downsampling,
            downsampling_metadata=described,
        )
        if labels:
            # NGFF's mark of a label image: readers (napari, splinecast) show it as labels.
            # The source's colours and names are kept; without any, the default palette applies.
            label_meta: dict[str, Any] = {"version": attrs["ome"]["version"]}
            if isinstance(image_label, dict):
                for key in ("colors", "properties"):
                    if isinstance(image_label.get(key), list):
                        label_meta[key] = image_label[key]
            attrs["ome"]["image-label"] = label_meta
        ours = dict(root.attrs.get(ATTRIBUTE, {}))
        keep = {k: src.metadata[k] for k in ("inside", "default_iso", "modality")
                if k in src.metadata and isinstance(src.metadata[k], (str, int, float))}
        ours.update({
            "version": 1, "brick": brick, "ghost": GHOST, "complete_chunks": True,
            "value_range": value_range, "source": str(src.metadata.get("source", src.label)),
            "source_metadata": keep, "labels": bool(labels),
        })
        root.attrs.update({**attrs, ATTRIBUTE: ours})
        if histograms:
            _store_histograms(root, arrays, plan, brick, shard, src.dtype, value_range,
                              bins, progress, path.name)
    from ...io.omezarr import open_zarr

    return open_zarr(path)


def _store_histograms(root: Any, arrays: list[Any], plan: list[Any], brick: int, shard: int,
                      dtype: np.dtype, value_range: list[float], bins: int | None,
                      progress: bool, name: str) -> None:
    """The ``hist2d`` group (:mod:`.store.hist_store`) from the levels just written, tile by
    tile."""
    from ..cut.histograms import DEFAULT_BINS, Quantizer
    from .hist_store import stream_level_histograms, write_histograms

    quantizer = Quantizer.for_data(dtype, value_range, int(bins or DEFAULT_BINS))
    views = [_level_view(arrays[i], plan[i][0], i) for i in range(len(plan))]
    factors = [np.asarray(f, np.int64) for _shape, f in plan]
    maps = [(1.0 / f, np.zeros(3)) for f in factors]  # vertex-centred: same translation
    bar = _Progress(f"{name} histograms", 1, progress)

    def tick(done: int, total: int) -> None:
        bar.total = total
        bar._posttask()

    hists = stream_level_histograms(views[0].read, [v.read for v in views[1:]],
                                    [shape for shape, _f in plan], factors, maps, brick,
                                    quantizer, tile=shard, progress=tick)
    bar.finish()
    source_nbytes = int(np.prod(plan[0][0])) * np.dtype(dtype).itemsize
    write_histograms(root, hists, list(range(1, len(plan))), brick, maps[1:], source_nbytes)


def _level_view(array: Any, shape: tuple[int, int, int], index: int) -> Level:
    """A just-written level array as a :class:`Level` (reads go through the reader's code)."""
    return Level(index=index, path=str(index), array=array, shape=shape,
                 spacing=(1.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0), label=f"level {index}")
