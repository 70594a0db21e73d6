"""Slot pools under one byte budget: the memory of a wavelet chunk reconstructor.

A :class:`SlotPool` keeps equally shaped items (coefficient bricks, or blocks of the seven detail
subbands) in one array that the compiled kernels index by slot. Each slot records its owner (a
level and a flat index, so the owner's table can be cleared when the slot is taken away) and the
frame that last used it. Slots are freed by :meth:`SlotPool.evict` in least-recently-used order,
never those used by the current frame, and :meth:`SlotPool.compact` shrinks the array to its live
slots, so the bytes held by the pools (``array.nbytes``, what is resident) can go down as well as
up. :class:`Budget` decides, before a pool grows, what must go first.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ...errors import ReadError, limits

__all__ = ["SlotPool", "Budget"]


class SlotPool:
    """Items of ``item_shape`` in one array of slots, with owners, use stamps and a free list.

    Parameters
    ----------
    item_shape : tuple of int
    dtype : numpy dtype
    release : callable
        ``release(levels, flats)``: the owners of evicted slots (clear their slot tables).
    what, label : str
        What the items are and whose they are, for the memory guard's message.
    """

    def __init__(self, item_shape: tuple[int, ...], dtype: np.dtype,
                 release: Callable[[np.ndarray, np.ndarray], None], what: str = "items",
                 label: str = "wavelet pyramid") -> None:
        self.what, self.label = what, label
        self.array = np.zeros((0, *item_shape), dtype=dtype)
        self.level = np.zeros(0, dtype=np.int64)  # owner's level, -1 when free
        self.flat = np.zeros(0, dtype=np.int64)  # owner's flat index on its level
        self.stamp = np.zeros(0, dtype=np.int64)  # frame of last use
        self.release = release
        self.item_bytes = int(np.prod(item_shape)) * np.dtype(dtype).itemsize

    @property
    def capacity(self) -> int:
        return self.array.shape[0]

    @property
    def nbytes(self) -> int:
        """Bytes resident in the pool's array."""
        return int(self.array.nbytes)

    @property
    def free(self) -> int:
        return int(np.count_nonzero(self.level < 0))

    def touch(self, slots: np.ndarray, frame: int) -> None:
        """Mark ``slots`` as used by ``frame`` (protected from eviction during it)."""
        self.stamp[np.asarray(slots, dtype=np.int64)] = frame

    def grow(self, count: int) -> None:
        """Add ``count`` free slots (the array is reallocated)."""
        if count <= 0:
            return
        # Sizes derive from the store's shapes: the memory guard sees every growth first.
        limits.check_memory((self.capacity + count) * self.item_bytes,
                            f"{self.capacity + count} cached {self.what}", self.label, ReadError)
        grown = np.zeros((self.capacity + count, *self.array.shape[1:]), self.array.dtype)
        grown[:self.capacity] = self.array
        self.array = grown
        self.level = np.concatenate([self.level, np.full(count, -1, np.int64)])
        self.flat = np.concatenate([self.flat, np.zeros(count, np.int64)])
        self.stamp = np.concatenate([self.stamp, np.full(count, -1, np.int64)])

    def take(self, level: int, flats: np.ndarray, frame: int) -> np.ndarray:
        """Free slots for owners ``flats`` of ``level`` (there must be enough)."""
        flats = np.asarray(flats, dtype=np.int64)
        slots = np.flatnonzero(self.level < 0)[:flats.size]
        if slots.size < flats.size:
            raise RuntimeError("slot pool: not enough free slots")
        self.level[slots] = level
        self.flat[slots] = flats
        self.stamp[slots] = frame
        return slots

    def evict(self, count: int, frame: int) -> int:
        """Free up to ``count`` live slots not used by ``frame``, least recently used first
        (finer levels first among equals); returns how many were freed."""
        candidates = np.flatnonzero((self.level >= 0) & (self.stamp != frame))
        if count <= 0 or candidates.size == 0:
            return 0
        order = np.lexsort((self.level[candidates], self.stamp[candidates]))
        gone = candidates[order[:count]]
        self.release(self.level[gone].copy(), self.flat[gone].copy())
        self.level[gone] = -1
        return int(gone.size)

    def compact(self) -> np.ndarray | None:
        """Shrink the array to its live slots; returns ``new slot`` per old slot (-1: freed),
        or ``None`` if nothing moved."""
        live = np.flatnonzero(self.level >= 0)
        if live.size == self.capacity:
            return None
        remap = np.full(self.capacity, -1, dtype=np.int64)
        remap[live] = np.arange(live.size)
        self.array = np.ascontiguousarray(self.array[live])
        self.level, self.flat, self.stamp = self.level[live], self.flat[live], self.stamp[live]
        return remap


class Budget:
    """Keeps the pools' resident bytes under ``limit`` (``None``: unbounded) where possible.

    Before a pool takes ``count`` slots, :meth:`make_room` frees what the current frame does not
    use — in that pool first (its slots are reused without reallocating), then in the others,
    which are then compacted — and grows the pool by what is still missing. A frame that needs
    more than the limit by itself still gets it: nothing it uses is ever evicted.
    """

    def __init__(self, limit: int | None,
                 remapped: Callable[[SlotPool, np.ndarray], None]) -> None:
        self.limit = limit
        self.pools: list[SlotPool] = []
        self.remapped = remapped  # tell the owner tables of a compacted pool

    @property
    def nbytes(self) -> int:
        return sum(p.nbytes for p in self.pools)

    def make_room(self, pool: SlotPool, count: int, frame: int) -> None:
        missing = count - pool.free
        if missing <= 0:
            return
        if self.limit is None:
            pool.grow(max(missing, pool.capacity))  # doubling: few reallocations
            return
        over = self.nbytes + missing * pool.item_bytes - self.limit
        if over > 0:
            missing -= pool.evict(missing, frame)
            over = self.nbytes + missing * pool.item_bytes - self.limit
        for other in self.pools:
            if over <= 0 or missing <= 0:
                break
            if other is pool:
                continue
            other.evict(-(-over // other.item_bytes), frame)
            remap = other.compact()
            if remap is not None:
                self.remapped(other, remap)
            over = self.nbytes + missing * pool.item_bytes - self.limit
        if missing > 0:
            room = (self.limit - self.nbytes) // pool.item_bytes
            pool.grow(max(missing, min(pool.capacity, room)))
