"""The brick histograms of Carmona & Froehlich 2011 stored with a pyramid (the ``hist2d`` group).

:mod:`.cut.histograms` defines the sparse (source value, approximating value) histogram of a
brick; :mod:`.cut.policy` turns them into the distortion D(b) of every brick for any transfer
function. This module computes them for a pyramid store in bounded memory and stores them next to
the bricks, so that opening ``Scene(pyramid, cut="error")`` reads them instead of every level,
and a transfer-function edit never reads a voxel.

Layout (format version :data:`FORMAT_VERSION`)
----------------------------------------------
Group ``splinecast/hist2d`` in the pyramid's root; for every level ``L >= 1`` three 1-D arrays
``L/offsets`` (int64, one more than the level's bricks, C order of the brick grid ``(bi, bj,
bk)``), ``L/keys`` (uint16 for up to 256 bins: ``source_bin * bins + approx_bin``, ascending
within a brick) and ``L/counts`` (uint32, or uint64 beyond 2^32 voxels), zstd-compressed. Level 0
has no histograms (its bricks are the source). The root attribute ``splinecast["hist2d"]`` holds
``version``, ``bins``, ``value_range`` (the quantizer's ``[lo, hi]``), ``brick``, ``levels``,
``maps`` (per level ``[a, c]``: level index = ``a`` x level-0 index + ``c`` per axis), ``nbytes``
(raw bytes of the arrays) and ``source_nbytes``.

Which voxels a brick covers: brick ``b`` of ``B`` cells on a level with per-axis factor ``f`` owns
level-0 voxels ``[b B f, (b + 1) B f)`` per axis, the last brick of an axis up to the volume's
end, exactly as :func:`.cut.policy.octree_tree` counts them.

Memory
------
The source is read in cubic tiles of level 0 (``tile`` voxels a side, the pyramid's shard). Per
tile and level the bricks' histograms restricted to the tile are computed from the tile and the
few level voxels its trilinear reconstruction reads; histograms are additive over voxels, so a
brick larger than a tile is the sum of its parts. Peak memory is one tile and the level voxels
it needs, plus the histograms themselves (a few percent of the source, what the error cut holds
in memory anyway; about 2x that while a level's parts are merged), never a whole level.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ...errors import ParameterError, ReadError
from ...io.omezarr import ATTRIBUTE, TABLES_GROUP, read_array
from ..cut.histograms import BrickHistograms, Quantizer, box_histograms

__all__ = ["HIST2D", "FORMAT_VERSION", "level_footprints", "stream_level_histograms",
           "write_histograms", "read_histograms", "histogram_info"]

#: Name of the group (under ``splinecast/``) and of the root attribute entry.
HIST2D = "hist2d"
#: Version of the layout described above; a reader refuses other versions.
FORMAT_VERSION = 1

Reader = Callable[[np.ndarray, np.ndarray], np.ndarray]


def level_footprints(n0: Any, brick: int, factor: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Brick counts and level-0 voxel ranges ``[lo, hi)`` of every brick of one level.

    Returns ``counts`` (3,), ``lo`` and ``hi`` (n, 3) in C order of the brick grid.
    """
    n0 = np.asarray(n0, np.int64)
    size = int(brick) * np.asarray(factor, np.int64)
    counts = np.maximum(1, -(-np.maximum(n0 - 1, 0) // size))
    idx = np.indices(counts).reshape(3, -1).T.astype(np.int64)
    lo = idx * size
    hi = np.where(idx == counts - 1, n0, (idx + 1) * size)
    return counts, lo, np.maximum(hi, lo + 1)


def _merge(parts: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]], nbricks: int,
           quantizer: Quantizer, count_dtype: type) -> BrickHistograms:
    """Sum partial histograms ``(brick ids, rows, keys, counts)`` per brick into CSR form."""
    nkeys = quantizer.bins ** 2
    ids = np.concatenate([np.repeat(p[0], p[1]) for p in parts]) if parts else np.zeros(0, int)
    keys = np.concatenate([p[2] for p in parts]).astype(np.int64) if parts else ids
    counts = np.concatenate([p[3] for p in parts]).astype(np.int64) if parts else ids
    combined = ids.astype(np.int64) * nkeys + keys
    del ids, keys
    order = np.argsort(combined, kind="stable")
    combined = combined[order]
    counts = counts[order]
    del order
    if combined.size:
        first = np.flatnonzero(np.concatenate([[True], combined[1:] != combined[:-1]]))
        summed = np.add.reduceat(counts, first)
        combined = combined[first]
    else:
        summed = counts
    brick_of = combined // nkeys
    rows = np.bincount(brick_of, minlength=nbricks)
    offsets = np.concatenate([[0], np.cumsum(rows)]).astype(np.int64)
    key_dtype = np.uint16 if quantizer.bins <= 256 else np.uint32
    return BrickHistograms(offsets, (combined % nkeys).astype(key_dtype),
                           summed.astype(count_dtype), quantizer)


def stream_level_histograms(read_source: Reader, read_levels: Sequence[Reader],
                            level_shapes: Sequence[Any], factors: Sequence[Any],
                            maps: Sequence[tuple[Any, Any]], brick: int, quantizer: Quantizer,
                            tile: int = 128, progress: Callable[[int, int], None] | None = None
                            ) -> list[BrickHistograms]:
    """Histograms of every brick of levels 1.. of a pyramid, reading it tile by tile.

    Parameters
    ----------
    read_source : callable
        ``read(lo, hi)`` -> level-0 voxels ``[lo, hi)`` as an (x, y, z) array.
    read_levels : sequence of callable
        The same for levels 1, 2, ...
    level_shapes : sequence of 3 ints
        Shapes of levels 0, 1, ... (x, y, z).
    factors : sequence of 3 ints
        Per-axis factor of levels 0, 1, ... relative to level 0.
    maps : sequence of (a, c)
        Level index = ``a`` x level-0 index + ``c`` for levels 0, 1, ...
    brick : int
        Cells per brick.
    quantizer : Quantizer
    tile : int
        Level-0 voxels per tile side (bounds the memory).
    progress : callable, optional
        Called with (tiles done, tiles) after each tile.

    Returns
    -------
    list of BrickHistograms
        One per level 1, 2, ..., bricks in C order of the level's brick grid.
    """
    n0 = np.asarray(level_shapes[0], np.int64)
    tile = max(int(tile), 1)
    n_levels = len(level_shapes)
    count_dtype = np.uint32 if int(np.prod(n0)) < 2**32 else np.uint64
    geometry = [level_footprints(n0, brick, factors[lv]) for lv in range(n_levels)]
    parts: list[list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]] = [
        [] for _ in range(n_levels)]
    tiles = [int(math.ceil(n / tile)) for n in n0]
    total = int(np.prod(tiles))
    done = 0
    for t in np.ndindex(*tiles):
        t_lo = np.asarray(t, np.int64) * tile
        t_hi = np.minimum(t_lo + tile, n0)
        block = np.ascontiguousarray(read_source(t_lo, t_hi))
        for lv in range(1, n_levels):
            counts, lo, hi = geometry[lv]
            size = int(brick) * np.asarray(factors[lv], np.int64)
            b_lo = np.minimum(t_lo // size, counts - 1)
            b_hi = np.maximum(np.minimum(-(-t_hi // size), counts), b_lo + 1)
            idx = np.indices(b_hi - b_lo).reshape(3, -1).T + b_lo
            ids = np.ravel_multi_index(tuple(idx.T), tuple(counts))
            box_lo = np.maximum(lo[ids], t_lo) - t_lo
            box_hi = np.minimum(hi[ids], t_hi) - t_lo
            keep = np.all(box_hi > box_lo, axis=1)
            ids, box_lo, box_hi = ids[keep], box_lo[keep], box_hi[keep]
            if not ids.size:
                continue
            a = np.asarray(maps[lv][0], np.float64) * np.ones(3)
            c = np.asarray(maps[lv][1], np.float64) * np.ones(3)
            shape = np.asarray(level_shapes[lv], np.int64)
            # The level voxels the reconstruction at the tile's voxels reads (edge-clamped).
            u_lo = np.clip(np.floor(a * t_lo + c), 0, shape - 1).astype(np.int64)
            u_hi = np.clip(np.floor(a * (t_hi - 1) + c).astype(np.int64) + 2, u_lo + 1, shape)
            coarse = np.ascontiguousarray(read_levels[lv - 1](u_lo, u_hi))
            hist = box_histograms(block, coarse, box_lo, box_hi, a, a * t_lo + c - u_lo,
                                  quantizer)
            parts[lv].append((ids, np.diff(hist.offsets), hist.keys, hist.counts))
        done += 1
        if progress is not None:
            progress(done, total)
    out = []
    for lv in range(1, n_levels):
        nbricks = int(np.prod(geometry[lv][0]))
        out.append(_merge(parts[lv], nbricks, quantizer, count_dtype))
        parts[lv] = []
    return out


def write_histograms(root: Any, hists: Sequence[BrickHistograms], levels: Sequence[int],
                     brick: int, maps: Sequence[tuple[Any, Any]], source_nbytes: int) -> int:
    """Store ``hists`` (levels ``levels``) in ``root`` (an open zarr group); returns raw bytes."""
    from zarr.codecs import ZstdCodec

    if not hists:
        return 0
    q = hists[0].quantizer
    nbytes = 0
    for level, hist in zip(levels, hists, strict=True):
        for name in ("offsets", "keys", "counts"):
            values = np.asarray(getattr(hist, name))
            array = root.create_array(
                f"{TABLES_GROUP}/{HIST2D}/{int(level)}/{name}", shape=values.shape,
                dtype=values.dtype, chunks=(max(1, min(values.size, 1 << 20)),),
                compressors=ZstdCodec(level=3, checksum=True), overwrite=True)
            if values.size:
                array[...] = values
            nbytes += values.nbytes
    attrs = dict(root.attrs.get(ATTRIBUTE, {}))
    attrs[HIST2D] = {
        "version": FORMAT_VERSION, "bins": q.bins, "value_range": [q.lo, q.hi],
        "brick": int(brick), "levels": [int(v) for v in levels],
        "maps": [[np.asarray(a, float).tolist(), np.asarray(c, float).tolist()]
                 for a, c in maps],
        "nbytes": int(nbytes), "source_nbytes": int(source_nbytes),
        "description": "sparse 2D histograms (source value bin x approximating value bin) of "
                       "every brick of levels >= 1: CSR offsets/keys/counts per level",
    }
    root.attrs[ATTRIBUTE] = attrs
    return nbytes


def histogram_info(volume: Any) -> dict[str, Any] | None:
    """The ``hist2d`` metadata of a store (None if it has none), plus ``disk_bytes``."""
    meta = volume.attributes.get(HIST2D) if hasattr(volume, "attributes") else None
    if not isinstance(meta, dict):
        return None
    info = dict(meta)
    disk = 0
    path = getattr(volume, "path", None)
    if path is not None:
        from pathlib import Path

        folder = Path(path) / TABLES_GROUP / HIST2D
        if folder.is_dir():
            disk = sum(f.stat().st_size for f in folder.rglob("*") if f.is_file())
    info["disk_bytes"] = disk
    return info


def read_histograms(volume: Any, brick: int, levels: Sequence[int],
                    maps: Sequence[tuple[Any, Any]], bins: int | None = None
                    ) -> list[BrickHistograms]:
    """The stored histograms of store levels ``levels`` (none of them level 0).

    Parameters
    ----------
    volume : MultiscaleVolume
    brick : int
        The octree's cells per brick (must be the stored one).
    levels : sequence of int
        Store levels wanted.
    maps : sequence of (a, c)
        Their level maps (must match the stored ones).
    bins : int, optional
        Bins wanted (default: the stored ones).

    Raises
    ------
    ParameterError
        The store has no histograms, or none that fit (other brick, bins, levels or maps).
    ReadError
        The group is damaged (one line naming the store and the array).
    """
    where = f"{getattr(volume, 'path', 'store')}: {TABLES_GROUP}/{HIST2D}"
    meta = volume.attributes.get(HIST2D)
    if meta is None or getattr(volume, "root", None) is None:
        raise ParameterError(f"{where}: the store has no brick histograms")
    try:
        version = int(meta["version"])
        stored_bins = int(meta["bins"])
        lo, hi = (float(v) for v in meta["value_range"])
        stored_brick = int(meta["brick"])
        stored_levels = [int(v) for v in meta["levels"]]
        stored_maps = [(np.asarray(m[0], float), np.asarray(m[1], float)) for m in meta["maps"]]
        quantizer = Quantizer(lo, hi, stored_bins)
    except (KeyError, TypeError, ValueError, ParameterError) as exc:
        raise ReadError(f"{where}: damaged metadata ({exc})") from None
    if version != FORMAT_VERSION:
        raise ParameterError(f"{where}: format version {version}, this reader knows "
                             f"{FORMAT_VERSION}")
    if stored_brick != int(brick):
        raise ParameterError(f"{where}: stored for {stored_brick}^3 bricks, the octree uses "
                             f"{brick}^3")
    if bins is not None and int(bins) != stored_bins:
        raise ParameterError(f"{where}: stored with {stored_bins} bins, {bins} wanted")
    n0 = np.asarray(volume.levels[0].shape, np.int64)
    out = []
    for level, (a, c) in zip(levels, maps, strict=True):
        if level not in stored_levels or len(stored_maps) != len(stored_levels):
            raise ParameterError(f"{where}: no histograms of level {level}")
        sa, sc = stored_maps[stored_levels.index(level)]
        if not (np.allclose(sa, a) and np.allclose(sc, c)):
            raise ParameterError(f"{where}: level {level} was stored for another level map")
        factor = np.round(1.0 / np.asarray(a, float)).astype(np.int64)
        counts, _lo, _hi = level_footprints(n0, brick, factor)
        nbricks = int(np.prod(counts))
        try:
            group = volume.root[f"{TABLES_GROUP}/{HIST2D}/{level}"]
            offsets, keys, cnt = (read_array(group[name], f"{where}/{level}/{name}")
                                  for name in ("offsets", "keys", "counts"))
        except ReadError:
            raise
        except Exception as exc:  # noqa: BLE001 - any zarr/codec failure is damage
            raise ReadError(f"{where}/{level}: cannot read ({type(exc).__name__}: "
                            f"{str(exc).splitlines()[0] if str(exc) else 'damaged'})") from None
        ok = (offsets.ndim == keys.ndim == cnt.ndim == 1 and offsets.dtype.kind in "iu"
              and keys.dtype.kind == "u" and cnt.dtype.kind == "u"
              and offsets.shape == (nbricks + 1,) and keys.shape == cnt.shape
              and offsets.size and offsets[0] == 0 and offsets[-1] == keys.size
              and np.all(np.diff(offsets) >= 0)
              and (keys.size == 0 or int(keys.max()) < stored_bins ** 2))
        if not ok:
            raise ReadError(f"{where}/{level}: inconsistent arrays (expected {nbricks} bricks)")
        out.append(BrickHistograms(offsets.astype(np.int64), keys, cnt, quantizer))
    return out
