"""Decoded store chunks kept between brick reads, so that each chunk is decompressed about once.

A brick's window reaches ``GHOST`` voxels into its neighbours, so a batch of sibling bricks
(a 64^3 block of a 32^3-brick pyramid plus ghosts) overlaps four chunks per axis where it owns
two: read on their own, the batches of a cut decompress every chunk about eight times, and
zarr's per-chunk cost (most of a millisecond of Python and event-loop work besides the
decompression) made loading a 2048^3 pyramid's cut take minutes. Here a read takes the chunks
it finds decoded from a small LRU cache and reads only the chunk-aligned box of those missing,
in one store read.

The cache holds the level's voxels in (x, y, z) order exactly as :meth:`Level.read
<splinecast.io.omezarr.Level.read>` returns them; a failed read caches nothing, so damage is
reported as before (the read raises, naming the chunk).
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from typing import Any

import numpy as np

__all__ = ["ChunkCache"]

ChunkKey = tuple[int, int, int, int]


class ChunkCache:
    """An LRU cache of decoded chunks of a multiscale volume's levels, bounded in bytes.

    Parameters
    ----------
    max_bytes : int
        Most bytes of chunk data held (0: nothing is kept, every read goes to the store).
    """

    def __init__(self, max_bytes: int) -> None:
        self.max_bytes = int(max_bytes)
        self._chunks: OrderedDict[ChunkKey, np.ndarray] = OrderedDict()
        self._bytes = 0
        self._lock = threading.Lock()
        #: Chunks served from the cache and chunks read from the store.
        self.hits = 0
        self.misses = 0

    @property
    def nbytes(self) -> int:
        """Bytes of chunk data held."""
        return self._bytes

    def read(self, level_index: int, level: Any, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """Voxels ``[lo, hi)`` (x, y, z, inside the level) of ``level`` as a C-contiguous array,
        as ``level.read(lo, hi)`` returns them."""
        lo = np.asarray(lo, dtype=np.int64)
        hi = np.asarray(hi, dtype=np.int64)
        size = np.asarray(level.chunks, dtype=np.int64)
        shape = np.asarray(level.shape, dtype=np.int64)
        first = lo // size
        last = (hi - 1) // size
        keys = [(level_index, int(i), int(j), int(k))
                for i in range(first[0], last[0] + 1)
                for j in range(first[1], last[1] + 1)
                for k in range(first[2], last[2] + 1)]
        if self.max_bytes <= 0:
            return level.read(lo, hi)
        with self._lock:
            found = {key: self._chunks[key] for key in keys if key in self._chunks}
            for key in found:
                self._chunks.move_to_end(key)
        missing = [key for key in keys if key not in found]
        if missing:
            # One store read: the chunk-aligned box around the missing chunks.
            index = np.array([key[1:] for key in missing], dtype=np.int64)
            box_lo = index.min(axis=0) * size
            box_hi = np.minimum((index.max(axis=0) + 1) * size, shape)
            block = level.read(box_lo, box_hi)
            for key in missing:
                c_lo = np.asarray(key[1:], dtype=np.int64) * size - box_lo
                c_hi = np.minimum(c_lo + size, box_hi - box_lo)
                found[key] = np.ascontiguousarray(
                    block[c_lo[0]:c_hi[0], c_lo[1]:c_hi[1], c_lo[2]:c_hi[2]])
            self._keep({key: found[key] for key in missing})
        self.hits += len(keys) - len(missing)
        self.misses += len(missing)
        out = np.empty(tuple(int(v) for v in hi - lo), dtype=level.dtype)
        for key in keys:
            c_lo = np.asarray(key[1:], dtype=np.int64) * size
            chunk = found[key]
            a = np.maximum(lo, c_lo)
            b = np.minimum(hi, c_lo + np.asarray(chunk.shape))
            out[a[0] - lo[0]:b[0] - lo[0], a[1] - lo[1]:b[1] - lo[1], a[2] - lo[2]:b[2] - lo[2]] = (
                chunk[a[0] - c_lo[0]:b[0] - c_lo[0], a[1] - c_lo[1]:b[1] - c_lo[1],
                      a[2] - c_lo[2]:b[2] - c_lo[2]])
        return out

    def _keep(self, chunks: dict[ChunkKey, np.ndarray]) -> None:
        with self._lock:
            for key, chunk in chunks.items():
                if chunk.nbytes > self.max_bytes or key in self._chunks:
                    continue
                self._chunks[key] = chunk
                self._bytes += chunk.nbytes
            while self._bytes > self.max_bytes and self._chunks:
                _, old = self._chunks.popitem(last=False)
                self._bytes -= old.nbytes

    def clear(self) -> None:
        """Drop every chunk (a store that changed or disappeared)."""
        with self._lock:
            self._chunks.clear()
            self._bytes = 0
