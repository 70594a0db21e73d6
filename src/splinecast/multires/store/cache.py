"""The RAM brick cache and its loader thread.

:class:`BrickCache` holds bricks (arrays with ghost layers, see :mod:`.cut.octree`) within a hard
byte budget. A background thread reads the bricks it is asked for, in the order given, from the
store; the bricks of the coarsest level are read when the cache opens and never leave, so every
frame can show the whole volume at some resolution. A frame asks for its cut
(:meth:`BrickCache.request`), waits for at most its load budget (:meth:`BrickCache.wait`), and
draws every brick that is not resident yet from its finest resident ancestor
(:meth:`BrickCache.resolve`). Rendering the same view again converges to the complete cut.

Budget accounting: the bytes of the resident brick arrays never exceed ``budget`` less what
:meth:`BrickCache.reserve` holds back for the renderer (the seam copies), checked before each
insertion (``peak_bytes`` records the maximum). A brick that does not fit without evicting
what the current view needs is not loaded (``dropped``). Transient buffers of one read (the union
window of up to 8 sibling bricks and its padded copies) and the decoded chunks kept for the
neighbours' ghost layers (:class:`~.store.chunk_cache.ChunkCache`: an eighth of the budget, at most
:data:`CHUNK_CACHE_MAX`) are the fixed overhead on top of the budget;
``benchmarks/bench_multires.py`` measures it.

Faults: a read that fails (missing or corrupt chunk, store deleted, I/O error) marks the brick
unavailable; the next call from the rendering thread issues a :class:`BrickUnavailableWarning`
naming the chunk, and the brick keeps being drawn from its ancestor. The store is opened read-only:
nothing is ever written into it.

A frame drawn at once (:meth:`BrickCache.drawing`) starts no read while it is drawn: a read
decompresses chunks, and on a machine with few cores that took the trace's cores (measured
when zarr's threads decoded them; the loader thread does now). Measured at 2048^3 on 2 cores,
the first DVR image drawn at once from the coarsest level took 1.5 s with the loader reading
beside it and 0.8-1.2 s without. Frames that wait for their load budget let the read-ahead run
beside their trace, which makes a cut complete in fewer frames.

Reads in flight: from a store on disk one loader thread reads one batch at a time (the read is
decompression, bound by the cores). From a store over a network a read mostly waits for its
round trips, so several loader threads read batches at once (``reads``, by default the
store's ``SPLINECAST_REMOTE_READS``), each taking the next batch in the request's order (the
view's bricks, centre first and coarse to fine, then the read-ahead); they start new reads only
while the transient buffers of those in flight stay within :data:`READS_SHARE` of the budget.
A camera move cancels each read whose bricks the new view does not need (see
:meth:`BrickCache._cancel_unneeded`).
"""

from __future__ import annotations

import threading
import warnings
from collections import OrderedDict
from collections.abc import Container, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...errors import ParameterError, ReadError
from ...io.cancel import CancelToken, ReadCancelled, cancellable
from ...io.omezarr import MultiscaleVolume
from ..cut.lod import Cut
from ..cut.octree import BrickOctree
from .budget import format_bytes, parse_bytes
from .chunk_cache import ChunkCache

__all__ = ["Brick", "BrickCache", "BrickUnavailableWarning", "DrawItem", "BORDERS", "read_bricks",
           "CHUNK_CACHE_MAX", "READS_SHARE"]

#: Steps of :meth:`BrickCache.reserve`, as a share of the budget.
RESERVE_STEP = 1 / 32

#: Most of the budget :meth:`BrickCache.reserve` holds back. The reservation shrinks the next
#: cut, whose seams it was measured on; held without limit, small budgets with small bricks
#: (whole copies at 8 bytes per voxel) gave so little to the cut that it fell to the coarsest
#: level.
RESERVE_MAX = 1 / 2

#: Most bytes of decoded store chunks a brick cache keeps besides its budget.
CHUNK_CACHE_MAX = 64 * 2**20

#: Share of the budget the transient buffers of the reads in flight beyond the first may take
#: (each: the union window of its bricks and their padded copies, estimated as twice the
#: bricks' bytes).
READS_SHARE = 1 / 8

Key = tuple[int, int, int, int]
#: Ghost filling beyond a level's ends, as the models pad a whole volume: ``"edge"`` repeats the
#: last voxel (trilinear, qss, s31), ``"reflect"`` mirrors about it (the B-spline models).
BORDERS = ("edge", "reflect")


class BrickUnavailableWarning(UserWarning):
    """A brick could not be read; a coarser level is drawn in its place."""


@dataclass(frozen=True, eq=False)
class Brick:
    """A brick's voxels with ghost layers, and where they sit.

    Attributes
    ----------
    key : (level, i, j, k)
    data : ndarray (nx, ny, nz)
        C-contiguous, the store's dtype, ``data[u, v, w]`` along x, y, z. Voxels outside the
        level are filled by the cache's border rule.
    first : (3,) int
        Level index of ``data[0, 0, 0]`` (negative at the low border: ghosts).
    origin, spacing : (3,) float
        World position of ``data[0, 0, 0]`` and world distance between its voxels: voxel ``u``
        is at ``origin + u * spacing``.
    offset, scale : (3,) float
        The same in level-0 (volume) index units: ``x0 = offset + u * scale``, so the brick is
        the grid ``data`` with index offset ``offset`` and scale ``scale`` in the volume.
    """

    key: Key
    data: np.ndarray
    first: tuple[int, int, int]
    origin: tuple[float, float, float]
    spacing: tuple[float, float, float]
    offset: tuple[float, float, float]
    scale: tuple[float, float, float]

    @property
    def nbytes(self) -> int:
        return int(self.data.nbytes)


@dataclass(frozen=True)
class DrawItem:
    """What to draw for brick ``n`` of a cut: its own brick, or an ancestor substituted for it."""

    n: int
    brick: Brick
    substituted: bool


def read_bricks(volume: MultiscaleVolume, octree: BrickOctree, keys: list[Key],
                border: str = "edge", chunks: ChunkCache | None = None) -> list[Brick]:
    """Read bricks ``keys`` of one level with one store read (the union of their windows).

    Each brick's array holds its window of the level (:meth:`BrickOctree.window`: its voxels
    and the ghost layers), the voxels beyond the level's ends filled by the ``border`` rule
    (``"edge"`` or ``"reflect"``). The store chunks read are those the union window overlaps
    (only those not in ``chunks``, a cache of decoded chunks, when given).

    Raises
    ------
    ReadError
        A chunk cannot be read (:meth:`splinecast.io.omezarr.Level.read`).
    """
    level_index = keys[0][0]
    level = volume.level(level_index)
    index = np.array([k[1:] for k in keys], dtype=np.int64)
    first, stop = octree.window(level_index, index)
    shape = np.array(level.shape)
    have_lo = np.clip(first.min(axis=0), 0, shape - 1)
    have_hi = np.clip(stop.max(axis=0), have_lo + 1, shape)
    if chunks is None:
        block = level.read(have_lo, have_hi)
    else:
        block = chunks.read(level_index, level, have_lo, have_hi)
    scale, offset = octree.level_map(level_index)
    out = []
    for n, key in enumerate(keys):
        lo = np.clip(first[n], 0, shape - 1)
        hi = np.clip(stop[n], lo + 1, shape)
        part = block[tuple(slice(a, b) for a, b in zip(lo - have_lo, hi - have_lo, strict=True))]
        pads = [(int(a), int(b)) for a, b in zip(lo - first[n], stop[n] - hi, strict=True)]
        data = np.pad(part, pads, mode=border) if any(a or b for a, b in pads) else (
            np.ascontiguousarray(part))
        origin = np.asarray(level.origin) + first[n] * np.asarray(level.spacing)
        out.append(Brick(
            key=key, data=np.ascontiguousarray(data),
            first=tuple(int(v) for v in first[n]),  # type: ignore[arg-type]
            origin=tuple(float(v) for v in origin),  # type: ignore[arg-type]
            spacing=tuple(float(v) for v in level.spacing),  # type: ignore[arg-type]
            offset=tuple(float(v) for v in (first[n] - offset) / scale),  # type: ignore
            scale=tuple(float(v) for v in 1.0 / scale),  # type: ignore[arg-type]
        ))
    return out


def _remotes_of(volume: MultiscaleVolume) -> list[Any]:
    """The network locations (:class:`~splinecast.io.remote.Remote`) the volume's levels are
    read from, each once (the levels of a store share one); none for a store on disk."""
    found: dict[int, Any] = {}
    for level in getattr(volume, "levels", ()):
        source = getattr(getattr(level, "reader", None), "source", None)
        remote = getattr(source, "remote", None)
        if remote is not None:
            found[id(remote)] = remote
    return list(found.values())


@dataclass(eq=False)
class _Read:
    """One batch of bricks being read by a loader thread, and what stops it."""

    keys: list[Key]
    token: CancelToken
    nbytes: int  # estimated transient bytes


class BrickCache:
    """Resident bricks of a multiscale volume within a byte budget, filled by a loader thread.

    Parameters
    ----------
    volume : MultiscaleVolume
    budget : int or str
        Hard limit for the bytes of resident bricks (``"2GiB"``, ``"512MB"``, bytes).
    octree : BrickOctree, optional
        Default: ``BrickOctree(volume)``.
    border : {"edge", "reflect"}
        How ghosts beyond a level's ends are filled (the model's boundary rule).
    loads_per_frame : int
        Load budget M: :meth:`wait` returns after this many bricks were read in the frame.
    start : bool
        Start the loader threads now (else call :meth:`start`).
    reads : int, optional
        Most batches read at once, each by its own loader thread. Default: 1 for a store on
        disk (reading is decompressing, bound by the cores), the store's
        :attr:`~splinecast.io.remote.RemoteSettings.reads` over a network (a read mostly waits
        for its round trips).

    Raises
    ------
    ParameterError
        Bad budget or border, or a budget smaller than the coarsest level's bricks (checked
        before reading them).
    ReadError
        The coarsest level cannot be read.
    """

    def __init__(self, volume: MultiscaleVolume, budget: Any = "1GiB", *,
                 octree: BrickOctree | None = None, border: str = "edge",
                 loads_per_frame: int = 64, start: bool = True, reads: int | None = None
                 ) -> None:
        if border not in BORDERS:
            raise ParameterError(f"border must be one of {', '.join(BORDERS)}, got {border!r}")
        if not isinstance(loads_per_frame, int) or loads_per_frame < 1:
            raise ParameterError(f"loads_per_frame must be a positive integer, "
                                 f"got {loads_per_frame!r}")
        self.volume = volume
        self.octree = octree or BrickOctree(volume)
        self.budget = parse_bytes(budget, "budget")
        self.border = border
        self.loads_per_frame = loads_per_frame
        #: Decoded store chunks shared by neighbouring bricks' reads (their ghost layers): an
        #: eighth of the budget, at most :data:`CHUNK_CACHE_MAX` bytes, outside the budget
        #: (part of the fixed overhead).
        self.chunks = ChunkCache(min(CHUNK_CACHE_MAX, self.budget // 8))
        self._remotes = _remotes_of(volume)
        if reads is None:
            reads = max((int(getattr(r.settings, "reads", 1)) for r in self._remotes), default=1)
        if not isinstance(reads, int) or reads < 1:
            raise ParameterError(f"reads must be a positive integer, got {reads!r}")
        #: Most batches read at once (loader threads).
        self.reads = reads
        self._cond = threading.Condition()
        self._bricks: OrderedDict[Key, Brick] = OrderedDict()  # least recently used first
        self._bytes = 0
        self.peak_bytes = 0
        self._pinned: set[Key] = set()
        self._keep: set[Key] = set()
        self._queue: list[Key] = []
        self._needed: set[Key] = set()
        #: The bricks read ahead for the next frames (see :meth:`request`): they may not evict
        #: one another, which made a steady view read and evict the same bricks forever.
        self._prefetch: set[Key] = set()
        self._pinned_bytes = 0
        #: Bytes of the budget held back for what the renderer keeps beside the bricks (see
        #: :meth:`reserve`).
        self._reserved = 0
        self._inflight: set[Key] = set()
        #: The reads under way, in the order they started (the request's priority order); each
        #: token cancels its read's requests in flight, over a network, when a new request no
        #: longer needs its bricks (see :meth:`_cancel_unneeded`).
        self._reads: list[_Read] = []
        self._reading_bytes = 0
        #: Most reads seen under way at once.
        self.peak_reads = 0
        self._failed: dict[Key, str] = {}  # brick -> why it could not be read
        self._unreadable: list[Key] = []  # of the last resolved cut
        self._warnings: list[str] = []
        self._ranges: list[tuple[Key, float, float]] = []
        self._counts = dict(loaded=0, loaded_frame=0, evicted=0, dropped=0, substituted=0,
                            cancelled=0)
        self._stop = False
        self._threads: list[threading.Thread] = []
        #: Frames being drawn (:meth:`drawing`); the loader starts no read while it is > 0.
        self._drawing = 0
        #: Whether reads wait while a frame is drawn (``False``: they run beside the trace).
        self.pause_while_drawing = True
        #: Counts every change of what a cut can be drawn from (a brick read, evicted, found
        #: unavailable or dropped for want of room, a value range learnt): equal versions,
        #: equal cuts and draw items for an unchanged view (:class:`~.cut.stream.BrickStream`).
        self.version = 0
        self._pin_coarsest()
        self.update_ranges()
        if start:
            self.start()

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> None:
        """Start the loader threads (once)."""
        if not self._threads:
            self._threads = [threading.Thread(target=self._run, daemon=True,
                                              name=f"splinecast-brick-loader-{n}")
                             for n in range(self.reads)]
            for thread in self._threads:
                thread.start()

    def close(self, timeout: float = 10.0) -> None:
        """Stop the loader threads and wait for them (remote reads in progress are cancelled,
        a local one finishes first)."""
        with self._cond:
            self._stop = True
            for read in self._reads:
                read.token.cancel()
            self._cond.notify_all()
        for thread in self._threads:
            thread.join(timeout)

    @property
    def running(self) -> bool:
        return any(thread.is_alive() for thread in self._threads)

    def __enter__(self) -> BrickCache:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # ------------------------------------------------------------------ reading
    def _pin_coarsest(self) -> None:
        roots = self.octree.roots()
        need = int(self.octree.brick_bytes(self.octree.coarsest, roots).sum())
        if need > self.budget:
            raise ParameterError(
                f"budget {format_bytes(self.budget)} is smaller than the coarsest level of "
                f"{self.volume.path} ({format_bytes(need)}), which stays resident"
            )
        keys = [(self.octree.coarsest, *map(int, idx)) for idx in roots]
        for key, brick in zip(keys, self._read(keys), strict=True):
            self._insert(brick)
            self._pinned.add(key)
            self._pinned_bytes += brick.nbytes

    def _read(self, keys: list[Key]) -> list[Brick]:
        """Read bricks of one level with one store read (their union window); no lock held."""
        bricks = read_bricks(self.volume, self.octree, keys, self.border, self.chunks)
        for brick in bricks:
            self._note_range(brick.key, brick.data)
        return bricks

    def _note_range(self, key: Key, data: np.ndarray) -> None:
        """Queue the range of a brick read from a store without tables (applied by the caller's
        thread, which owns the octree)."""
        p = self.octree.position(key[0])
        if not np.isnan(self.octree.ranges[p][key[1:]][0]):
            return
        values = data[np.isfinite(data)] if data.dtype.kind == "f" else data
        lo, hi = (float(values.min()), float(values.max())) if values.size else (np.inf, -np.inf)
        with self._cond:
            self._ranges.append((key, lo, hi))

    def update_ranges(self) -> None:
        """Enter the value ranges learnt from bricks read since the last call into the octree
        (stores without tables); call it from the thread that selects cuts, before selecting."""
        with self._cond:
            updates, self._ranges = self._ranges, []
        for key, lo, hi in updates:
            self.octree.set_range(key, lo, hi)
        if updates:
            with self._cond:
                self.version += 1

    # ------------------------------------------------------------------ residency (locked)
    def _insert(self, brick: Brick) -> bool:
        if brick.key in self._bricks:
            return True
        ahead = brick.key in self._prefetch and brick.key not in self._needed
        if not self._make_room(brick.nbytes, self._prefetch if ahead else ()):
            self._counts["dropped"] += 1
            if not ahead:  # a brick of the cut that did not fit: its next cut may keep less
                self.version += 1
            return False
        self._bricks[brick.key] = brick
        self.version += 1
        self._bytes += brick.nbytes
        self.peak_bytes = max(self.peak_bytes, self._bytes)
        return True

    def _make_room(self, nbytes: int, protect: Container[Key] = ()) -> bool:
        """Evict least recently used bricks (never pinned or kept ones, nor ``protect``) until
        ``nbytes`` more fit in :attr:`brick_budget`; whether they do."""
        limit = self.brick_budget
        if self._bytes + nbytes <= limit:
            return True
        # The victims, least recently used first, are chosen before any is dropped: copying
        # every key for each insert made a full cache of tens of thousands of bricks quadratic.
        victims, freed = [], 0
        for key, brick in self._bricks.items():
            if key in self._pinned or key in self._keep or key in protect:
                continue
            victims.append(key)
            freed += brick.nbytes
            if self._bytes - freed + nbytes <= limit:
                break
        for key in victims:
            self._bytes -= self._bricks.pop(key).nbytes
            self._counts["evicted"] += 1
            self.version += 1
        return self._bytes + nbytes <= limit

    # ------------------------------------------------------------------ the loader thread
    def _next_batch(self) -> list[Key]:
        """The next wanted brick and its queued siblings (read together)."""
        while self._queue:
            key = self._queue.pop(0)
            if key in self._inflight:
                continue  # still needed: its read under way discards it when it lands
            if key in self._bricks or key in self._failed:
                self._needed.discard(key)
                continue
            parent = self.octree.parent(key)
            batch = [key]
            for other in list(self._queue):
                if len(batch) == 8:
                    break
                if (other[0] == key[0] and other not in self._bricks and other not in self._failed
                        and other not in self._inflight and self.octree.parent(other) == parent):
                    batch.append(other)
                    self._queue.remove(other)
            return batch
        return []

    def _may_start(self) -> bool:
        """Whether a loader thread may start a read now (lock held): something queued, no
        frame being drawn, fewer than :attr:`reads` reads under way, and room for one more
        batch's transient buffers (the first read always has it)."""
        if not self._queue or self._drawing or len(self._reads) >= self.reads:
            return False
        if not self._reads:
            return True
        room = int(self.budget * READS_SHARE) - self._reading_bytes
        return 16 * self._estimated_bytes(self._queue[:1])[0] <= room

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._stop and not self._may_start():
                    self._cond.wait()
                if self._stop:
                    return
                try:
                    batch = self._next_batch()
                except Exception as exc:  # a bug must not stop the loading for good
                    self._warnings.append(f"brick loader: {type(exc).__name__}: {exc}")
                    self._queue.clear()
                    self._needed.clear()
                    self._cond.notify_all()
                    continue
                if not batch:  # the queue held only bricks read meanwhile: tell settle()
                    self._cond.notify_all()
                    continue
                self._inflight.update(batch)
                read = _Read(batch, CancelToken(), 2 * sum(self._estimated_bytes(batch)))
                self._reads.append(read)
                self._reading_bytes += read.nbytes
                self.peak_reads = max(self.peak_reads, len(self._reads))
            with cancellable(read.token):
                bricks, failures, cancelled = self._read_safely(batch)
            with self._cond:
                self._reads.remove(read)
                self._reading_bytes -= read.nbytes
                if cancelled:
                    # No longer wanted when it was stopped; a later request may want it again
                    # (then it is queued, and stays needed).
                    self._counts["cancelled"] += 1
                    for key in batch:
                        self._inflight.discard(key)
                        if key not in self._queue:
                            self._needed.discard(key)
                    self._cond.notify_all()
                    continue
                for brick in bricks:
                    if self._insert(brick):
                        self._counts["loaded"] += 1
                        self._counts["loaded_frame"] += 1
                for key, reason in failures.items():
                    self._failed[key] = reason
                    self.version += 1
                    self._warnings.append(f"brick {key} unavailable ({reason}); drawing a "
                                          "coarser level")
                for key in batch:
                    self._inflight.discard(key)
                    self._needed.discard(key)
                self._cond.notify_all()

    def _read_safely(self, batch: list[Key]) -> tuple[list[Brick], dict[Key, str], bool]:
        """The bricks read, the failures, and whether the read was cancelled (then nothing)."""
        try:
            return self._read(batch), {}, False
        except ReadCancelled:
            return [], {}, True
        except Exception:  # isolate the culprit: read the bricks one by one
            bricks, failures = [], {}
            for key in batch:
                try:
                    bricks.extend(self._read([key]))
                except ReadCancelled:
                    return [], {}, True
                except ReadError as exc:
                    failures[key] = str(exc)
                except Exception as exc:  # never let the loader thread die
                    failures[key] = f"{type(exc).__name__}: {exc}"
            return bricks, failures, False

    # ------------------------------------------------------------------ the rendering thread
    @contextmanager
    def drawing(self) -> Iterator[None]:
        """A frame is being drawn: the loader starts no new read until it ends (a read in
        progress finishes). Nothing inside may wait for the loader (:meth:`wait`,
        :meth:`settle`)."""
        if not self.pause_while_drawing:
            yield
            return
        with self._cond:
            self._drawing += 1
        try:
            yield
        finally:
            with self._cond:
                self._drawing -= 1
                self._cond.notify_all()

    def request(self, keys: Iterable[Key], keep: Iterable[Key] = (),
                prefetch: Iterable[Key] = ()) -> None:
        """Replace what the loader reads: ``keys`` in this order, then ``prefetch``; ``keep``
        (plus ``keys``) must not be evicted for it. Bricks resident or unavailable are skipped.

        ``prefetch`` is the read-ahead set in priority order, resident bricks included: its
        longest head that fits in the budget beside ``keep``, the pinned bricks and ``keys``
        is read, and its bricks evict only bricks outside the set. A view that stays the same
        thus reads nothing once that head is resident."""
        self.update_ranges()
        keys = list(keys)
        prefetch = list(prefetch)
        sizes = self._estimated_bytes(prefetch)
        with self._cond:
            self._keep = set(keep) | set(keys)
            wanted = [k for k in keys if k not in self._bricks and k not in self._failed]
            self._needed = set(wanted)
            # Read ahead only what fits beside the bricks kept and those still to read: a
            # prefetch that evicted the bricks prefetched before it was read again every frame.
            room = (self.brick_budget - self._pinned_bytes - sum(self._estimated_bytes(wanted))
                    - sum(self._bricks[k].nbytes for k in self._keep
                          if k in self._bricks and k not in self._pinned))
            ahead = []
            for key, size in zip(prefetch, sizes, strict=True):
                if key in self._failed or key in self._needed or key in self._keep:
                    continue
                if size > room:
                    break
                room -= size
                ahead.append(key)
            self._prefetch = set(ahead)
            self._queue = wanted + [k for k in ahead if k not in self._bricks]
            self._cancel_unneeded()
            self._cond.notify_all()

    def _cancel_unneeded(self) -> None:
        """Stop the reads under way that the new request does not need (lock held).

        A read is kept while one of its bricks is still to be read for the view. A read of
        bricks the request neither needs nor reads ahead is stopped. A read ahead is kept
        unless the view's bricks that no read has started yet need its place: then the reads
        ahead started last are stopped until there are as many free places as such bricks (or
        every place is free); stopping more would only start them again. Only remote reads
        stop early (their requests in flight are cancelled); a local read finishes, and its
        bricks land within the budget."""
        live = [read for read in self._reads if not read.token.cancelled]
        waiting = len(self._needed - self._inflight)
        free = self.reads - len(live)
        ahead = []
        for read in live:
            if self._needed.intersection(read.keys):
                continue
            if self._prefetch.intersection(read.keys):
                ahead.append(read)
            else:
                read.token.cancel()
                free += 1
        for read in reversed(ahead):  # the last started, last in priority, first
            if free >= min(waiting, self.reads):
                break
            read.token.cancel()
            free += 1

    def _estimated_bytes(self, keys: list[Key]) -> list[int]:
        """Bytes each brick takes when resident (from the octree's windows)."""
        if not keys:
            return []
        arr = np.asarray(keys, dtype=np.int64).reshape(-1, 4)
        out = np.zeros(len(arr), dtype=np.int64)
        for level in np.unique(arr[:, 0]):
            rows = arr[:, 0] == level
            out[rows] = self.octree.brick_bytes(int(level), arr[rows, 1:])
        return out.tolist()

    def request_cut(self, cut: Cut) -> None:
        """:meth:`request` the bricks of a cut (its requests, keep set and prefetch list)."""
        self.request(cut.requests, keep=cut.keep, prefetch=cut.prefetch)

    def begin_frame(self) -> None:
        """Start counting this frame's loads and substitutions."""
        with self._cond:
            self._counts["loaded_frame"] = 0
            self._counts["substituted"] = 0

    def wait(self, max_loads: int | None = None, timeout: float | None = None) -> int:
        """Block until the requested bricks are resident (or unavailable), ``max_loads``
        (default: ``loads_per_frame``) bricks were read in this frame, or ``timeout`` seconds
        passed. Returns the number of bricks read in this frame."""
        limit = self.loads_per_frame if max_loads is None else int(max_loads)
        with self._cond:
            self._cond.wait_for(
                lambda: not self._needed or self._counts["loaded_frame"] >= limit
                or not self.running, timeout)
            loaded = self._counts["loaded_frame"]
        self._flush_warnings()
        return loaded

    def settle(self, timeout: float | None = None) -> bool:
        """Block until the loader has nothing left to read (requests and read-ahead) or
        ``timeout`` seconds passed; whether it is idle."""
        with self._cond:
            return self._cond.wait_for(
                lambda: (not self._queue and not self._inflight) or not self.running, timeout)

    def clear(self) -> None:
        """Stop reading and evict every brick but the pinned ones (the scene is about to hold
        the finest level whole, :mod:`.whole_level`, and gives it the budget). A remote
        read already under way is cancelled; a local one still lands, within the budget."""
        with self._cond:
            for read in self._reads:
                read.token.cancel()
            self._queue.clear()
            self._needed.clear()
            self._keep = set()
            self._prefetch = set()
            for key in [k for k in self._bricks if k not in self._pinned]:
                self._bytes -= self._bricks.pop(key).nbytes
                self._counts["evicted"] += 1
            self.version += 1
            self._cond.notify_all()
        self.chunks.clear()

    def get(self, key: Key) -> Brick | None:
        """The resident brick ``key`` (marked as recently used) or ``None``."""
        with self._cond:
            brick = self._bricks.get(tuple(key))
            if brick is not None:
                self._bricks.move_to_end(brick.key)
            return brick

    def is_resident(self, key: Key) -> bool:
        return tuple(key) in self._bricks

    def resident_keys(self) -> list[Key]:
        """Keys of the bricks resident now (a snapshot)."""
        with self._cond:
            return list(self._bricks)

    def is_unavailable(self, key: Key) -> bool:
        return tuple(key) in self._failed

    def ancestor(self, key: Key, found: dict[Key, Brick] | None = None) -> Brick:
        """The finest resident ancestor of ``key`` (the coarsest level is always resident).

        ``found`` remembers the brick found for each parent on the way, for later calls that
        pass the same dict (siblings share their ancestors)."""
        found = {} if found is None else found
        visited = []
        parent = self.octree.parent(tuple(key))
        while parent is not None:
            brick = found.get(parent)
            if brick is None:
                brick = self.get(parent)
            if brick is not None:
                for seen in visited:
                    found[seen] = brick
                found[parent] = brick
                return brick
            visited.append(parent)
            parent = self.octree.parent(parent)
        raise RuntimeError(f"no resident ancestor of {key}: the coarsest level must be pinned")

    def resolve(self, cut: Cut) -> list[DrawItem]:
        """What to draw for each brick of ``cut``: itself if resident, else its finest resident
        ancestor (counted in ``stats()["substituted"]``)."""
        self._flush_warnings()
        items = []
        substituted = 0
        unreadable: list[Key] = []
        # Siblings share their ancestors: each parent's finest resident ancestor is looked up
        # once (a first frame substitutes thousands of bricks from a few coarse ones).
        found: dict[Key, Brick] = {}
        for n in range(len(cut)):
            key = cut.key(n)
            brick = self.get(key)
            if brick is None:
                brick = self.ancestor(key, found)
                substituted += 1
                if key in self._failed:
                    unreadable.append(key)
            items.append(DrawItem(n, brick, brick.key != key))
        with self._cond:
            self._counts["substituted"] = substituted
            self._unreadable = unreadable
        return items

    def unreadable(self) -> list[tuple[Key, str]]:
        """The bricks of the last :meth:`resolve`'s cut that could not be read (drawn from an
        ancestor instead), with what was wrong (naming the chunk)."""
        with self._cond:
            return [(key, self._failed[key]) for key in self._unreadable]

    def note_substituted(self, count: int, unreadable: list[Key] | None = None) -> None:
        """Set the substitution count (and the unreadable bricks) of this frame (a caller
        drawing the items of an earlier :meth:`resolve` again, unchanged since)."""
        with self._cond:
            self._counts["substituted"] = int(count)
            if unreadable is not None:
                self._unreadable = list(unreadable)

    def _flush_warnings(self) -> None:
        with self._cond:
            pending, self._warnings = self._warnings, []
        for message in pending:
            warnings.warn(message, BrickUnavailableWarning, stacklevel=3)

    @property
    def nbytes(self) -> int:
        """Bytes of the resident bricks."""
        return self._bytes

    @property
    def pinned_bytes(self) -> int:
        return self._pinned_bytes

    @property
    def brick_budget(self) -> int:
        """The bytes resident bricks may take: the budget less what :meth:`reserve` holds."""
        return self.budget - self._reserved

    @property
    def reserved_bytes(self) -> int:
        return self._reserved

    def reserve(self, nbytes: int) -> bool:
        """Hold back ``nbytes`` of the budget for what the renderer keeps beside the bricks
        (the float64 copies of the bricks changed at level seams), so that the two together
        stay within the budget; bricks not needed by the view are evicted down to what is
        left. The reservation moves in steps of :data:`RESERVE_STEP` of the budget, up as soon
        as ``nbytes`` passes it and down only when it falls a whole step below: small changes
        from frame to frame would otherwise change the cut's share, hence the cut and its seams,
        every frame. It holds at most :data:`RESERVE_MAX` of the budget (what is more stays
        beside the budget) and never the pinned coarsest level.

        Returns
        -------
        bool
            Whether the reservation changed (then :attr:`version` does too: the next frame
            chooses its cut for the room left).
        """
        step = max(1, int(self.budget * RESERVE_STEP))
        wanted = -(-max(0, int(nbytes)) // step) * step
        with self._cond:
            wanted = min(wanted, int(self.budget * RESERVE_MAX),
                         self.budget - self._pinned_bytes)
            if wanted <= self._reserved and wanted >= self._reserved - step:
                return False
            self._reserved = wanted
            self.version += 1
            self._make_room(0)
            return True

    def stats(self) -> dict[str, Any]:
        """Counts for ``frame.stats``: resident bricks and bytes, budget, requested (still to
        read), loaded (this frame / in total), substituted (last :meth:`resolve`), unreadable
        (of those substituted, bricks that could not be read: see :meth:`unreadable`),
        unavailable (bricks that could not be read, of any cut), evicted, dropped (did not
        fit), reads_cancelled (reads stopped under way: a camera move no longer needed them),
        complete (nothing substituted), remote_requests (requests made to the store over a
        network since it was opened, retries included; 0 for a store on disk), reads_peak
        (most batches seen read at once, at most :attr:`reads`)."""
        with self._cond:
            return {
                "resident": len(self._bricks),
                "resident_bytes": self._bytes,
                "peak_bytes": self.peak_bytes,
                "budget": self.budget,
                "reserved_bytes": self._reserved,
                "requested": len(self._needed),
                "loaded_this_frame": self._counts["loaded_frame"],
                "loaded": self._counts["loaded"],
                "substituted": self._counts["substituted"],
                "complete": self._counts["substituted"] == 0,
                "unreadable": len(self._unreadable),
                "unavailable": len(self._failed),
                "evicted": self._counts["evicted"],
                "dropped": self._counts["dropped"],
                "reads_cancelled": self._counts["cancelled"],
                "chunks_decoded": self.chunks.misses,
                "chunks_reused": self.chunks.hits,
                "remote_requests": sum(remote.requests for remote in self._remotes),
                "reads_peak": self.peak_reads,
            }

    def __repr__(self) -> str:
        return (f"BrickCache({self.volume.name}, {len(self._bricks)} bricks, "
                f"{format_bytes(self._bytes)} of {format_bytes(self.budget)})")
