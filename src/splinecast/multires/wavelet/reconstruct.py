"""Gather-based reconstruction of selected chunks into B-spline coefficient bricks (Steinberger
2010, §4.4).

For a chunk ``(j, idx)`` the brick is the ``(k + d)^3`` level-``j`` nodes
``k idx - pad .. k idx - pad + k + d - 1`` per axis (:mod:`.wavelet.layout`). Each node is
gathered — never scattered — from the level-``j + 1`` coarse nodes and details under the synthesis
filters, separably along z, then y, then x, as the thesis' three kernels do:

    c_j[x] = Σ_m p[x - 2m] c_(j+1)[m] + Σ_m g[x - 2m] w_(j+1)[m]      (per axis)

Parent brick suffices
    The coarse nodes a brick needs are ``k/2 idx - pad .. k/2 idx + k/2 + (d + 1) // 2 - 1``,
    which lie inside the parent's own brick ``k idx' - pad .. k idx' + k + d - pad - 1``
    (``idx' = idx // 2``, either half) including its ghost nodes. So a chunk depends on its
    parent's brick and on the details in its footprint, owned by itself and its (clamped) neighbours
    ``idx - 1 .. idx + 1`` — never on a neighbouring brick of its own level.

Reuse across frames
    A brick's content is a function of its parent's content and of the active flags of those 27
    owners. Its *signature* hashes exactly that (the parent's signature and 27 bits), so a brick
    whose signature is unchanged is reused as is: lowering the detail leaves the coarser bricks
    valid (nothing is computed), and refining starts from the finest brick already present. The
    roots come from the stored coarsest level once.

Memory
    Bricks and the detail blocks they were made from are cached within a byte budget
    (:mod:`.wavelet.memory`): what the current selection uses stays, the least recently used
    rest makes room (the roots and coarse bricks every frame uses therefore stay resident).
"""

from __future__ import annotations

import time
from collections import namedtuple
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numba
import numpy as np

from ..._jit import jit
from ..._jit.work_queue import run_items, take
from ...errors import ParameterError
from .filters import spline_wavelet
from .layout import DETAIL_BANDS, WaveletLayout, reflect_index, reflect_indices
from .lod import Selection, _dilate
from .memory import Budget, SlotPool
from .transform import WaveletPyramid

__all__ = ["Brick", "ChunkReconstructor", "ReconstructionStats", "DETAIL_BLOCK"]

#: Detail nodes per axis of one resident block (the store's chunk edge: one block, one read).
DETAIL_BLOCK = 32

_MIX = np.uint64(0x9E3779B97F4A7C15)
#: Batches smaller than this run on one thread: waking the pool costs more than it saves.
PARALLEL_MIN_CHUNKS = 32


def _splitmix(x: np.ndarray) -> np.ndarray:
    """64-bit finaliser of SplitMix64 (wrap-around arithmetic on uint64 arrays)."""
    with np.errstate(over="ignore"):
        x = x + _MIX
        x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        return x ^ (x >> np.uint64(31))


def _owner_bits(active: np.ndarray) -> np.ndarray:
    """27-bit pattern of the active flags of each chunk's clamped 3x3x3 neighbourhood."""
    grown = np.pad(active, 1, mode="edge").astype(np.uint64)  # edge = clamped neighbours
    nx, ny, nz = active.shape
    bits = np.zeros(active.shape, dtype=np.uint64)
    bit = 0
    for dx in range(3):
        for dy in range(3):
            for dz in range(3):
                bits |= grown[dx:dx + nx, dy:dy + ny, dz:dz + nz] << np.uint64(bit)
                bit += 1
    return bits


#: The resident details of one level, as :func:`_reconstruct_one` reads them: the block table,
#: the blocks, the per-axis lengths of the coarse and detail bands, and the active chunks.
_Details = namedtuple("_Details", ("table", "blocks", "coarse_len", "detail_len", "active"))

#: How a level is synthesized: chunk edge ``k``, the bricks' ``pad``, the low- and high-pass
#: synthesis filters (taps and first index) and the boundary rules of the coarse and detail bands.
_Synthesis = namedtuple("_Synthesis", ("k", "pad", "p_taps", "p_start", "g_taps", "g_start",
                                       "coarse_rule", "detail_rule"))


@jit()
def _reconstruct_one(
    child: np.ndarray, parent: np.ndarray, out: np.ndarray, details: tuple, synthesis: tuple,
    owners_used: np.ndarray,
) -> int:
    """One brick ``out`` of chunk ``child`` from its ``parent`` brick and masked details
    (``details``: a :class:`_Details`; ``synthesis``: the level's :class:`_Synthesis`).

    The details are resident blocks of :data:`DETAIL_BLOCK` nodes per axis: ``table[bx, by, bz]``
    is the slot of ``blocks`` holding block ``(bx, by, bz)`` of the level's seven subbands (in
    :data:`DETAIL_BANDS` order), -1 when not resident. ``owners_used[a, b, c]`` is set when
    details of the owner at offset ``(a - 1, b - 1, c - 1)`` entered the brick. Returns the
    number of details gathered from an owner outside that 3x3x3 neighbourhood or from a block
    that is not resident (0 by design).
    """
    table, blocks, coarse_len, detail_len, active = details
    k, pad, p_taps, p_start, g_taps, g_start, coarse_rule, detail_rule = synthesis
    size = out.shape[0]
    p_stop = p_start + p_taps.shape[0] - 1
    g_stop = g_start + g_taps.shape[0] - 1
    half = k // 2
    n_chunks_x, n_chunks_y, n_chunks_z = active.shape
    stray = 0
    first = np.empty(3, np.int64)
    lo = np.empty((2, 3), np.int64)  # [letter L/H, axis]: first input node
    span = np.empty((2, 3), np.int64)
    fmax = 0
    for a in range(3):
        first[a] = k * child[a] - pad
        lo[0, a] = -((-(first[a] - p_stop)) // 2)
        lo[1, a] = -((-(first[a] - g_stop)) // 2)
        span[0, a] = (first[a] + size - 1 - p_start) // 2 - lo[0, a] + 1
        span[1, a] = (first[a] + size - 1 - g_start) // 2 - lo[1, a] + 1
        fmax = max(fmax, span[0, a], span[1, a])
    src = np.zeros((8, fmax, fmax, fmax))
    # Gather: band 0 (LLL) from the parent brick, bands 1..7 from the detail subbands.
    px = lo[0, 0] - (k * (child[0] // 2) - pad)
    py = lo[0, 1] - (k * (child[1] // 2) - pad)
    pz = lo[0, 2] - (k * (child[2] // 2) - pad)
    for mx in range(span[0, 0]):
        for my in range(span[0, 1]):
            for mz in range(span[0, 2]):
                src[0, mx, my, mz] = parent[px + mx, py + my, pz + mz]
    width = blocks.shape[2]
    for b in range(1, 8):
        lx, ly, lz = (b >> 2) & 1, (b >> 1) & 1, b & 1
        rx = coarse_rule if lx == 0 else detail_rule
        ry = coarse_rule if ly == 0 else detail_rule
        rz = coarse_rule if lz == 0 else detail_rule
        nx = coarse_len[0] if lx == 0 else detail_len[0]
        ny = coarse_len[1] if ly == 0 else detail_len[1]
        nz = coarse_len[2] if lz == 0 else detail_len[2]
        for mx in range(span[lx, 0]):
            ix, sx = reflect_index(lo[lx, 0] + mx, nx, rx)
            ox = min(ix // half, n_chunks_x - 1)
            for my in range(span[ly, 1]):
                iy, sy = reflect_index(lo[ly, 1] + my, ny, ry)
                oy = min(iy // half, n_chunks_y - 1)
                for mz in range(span[lz, 2]):
                    iz, sz = reflect_index(lo[lz, 2] + mz, nz, rz)
                    oz = min(iz // half, n_chunks_z - 1)
                    if not active[ox, oy, oz]:
                        continue
                    ax = ox - child[0] + 1
                    ay = oy - child[1] + 1
                    az = oz - child[2] + 1
                    if 0 <= ax <= 2 and 0 <= ay <= 2 and 0 <= az <= 2:
                        owners_used[ax, ay, az] = True
                    else:
                        stray += 1
                    slot = table[ix // width, iy // width, iz // width]
                    if slot < 0:
                        stray += 1
                        continue
                    src[b, mx, my, mz] = sx * sy * sz * blocks[
                        slot, b - 1, ix % width, iy % width, iz % width]
    # Along z: tz[pair (bx by), mx, my, z] from the (bx by L, bx by H) bands.
    tz = np.zeros((4, fmax, fmax, size))
    for b in range(8):
        pair, letter = b >> 1, b & 1
        lx, ly = (pair >> 1) & 1, pair & 1
        taps = p_taps if letter == 0 else g_taps
        start = p_start if letter == 0 else g_start
        for z in range(size):
            zg = first[2] + z
            for t in range(taps.shape[0]):
                if (zg - start - t) % 2 != 0:
                    continue
                mz = (zg - start - t) // 2 - lo[letter, 2]
                w = taps[t]
                for mx in range(span[lx, 0]):
                    for my in range(span[ly, 1]):
                        tz[pair, mx, my, z] += w * src[b, mx, my, mz]
    # Along y: uy[bx, mx, y, z] from the (bx L, bx H) pairs.
    uy = np.zeros((2, fmax, size, size))
    for pair in range(4):
        lx, letter = pair >> 1, pair & 1
        taps = p_taps if letter == 0 else g_taps
        start = p_start if letter == 0 else g_start
        for y in range(size):
            yg = first[1] + y
            for t in range(taps.shape[0]):
                if (yg - start - t) % 2 != 0:
                    continue
                my = (yg - start - t) // 2 - lo[letter, 1]
                w = taps[t]
                for mx in range(span[lx, 0]):
                    for z in range(size):
                        uy[lx, mx, y, z] += w * tz[pair, mx, my, z]
    # Along x: the brick.
    for x in range(size):
        xg = first[0] + x
        for y in range(size):
            for z in range(size):
                out[x, y, z] = 0.0
        for letter in range(2):
            taps = p_taps if letter == 0 else g_taps
            start = p_start if letter == 0 else g_start
            for t in range(taps.shape[0]):
                if (xg - start - t) % 2 != 0:
                    continue
                mx = (xg - start - t) // 2 - lo[letter, 0]
                w = taps[t]
                for y in range(size):
                    for z in range(size):
                        out[x, y, z] += w * uy[letter, mx, y, z]
    return stray


def _reconstruct_chunks(
    children: np.ndarray, parent_slot: np.ndarray, parents: np.ndarray, out_slot: np.ndarray,
    out: np.ndarray, details: tuple, synthesis: tuple, owners_used: np.ndarray,
) -> int:
    """:func:`_reconstruct_one` for every child, on threads; returns the summed stray count."""
    stray = np.zeros(children.shape[0], np.int64)
    run_items(_reconstruct_items, children.shape[0], children, parent_slot, parents, out_slot,
              out, details, synthesis, owners_used, stray)
    return int(stray.sum())


@jit
def _reconstruct_items(children, parent_slot, parents, out_slot, out, details, synthesis,
                       owners_used, stray, counter):
    """One thread's share of :func:`_reconstruct_chunks`: the children it takes."""
    while True:
        q = take(counter)
        if q >= children.shape[0]:
            break
        stray[q] = _reconstruct_one(
            children[q], parents[parent_slot[q]], out[out_slot[q]], details, synthesis,
            owners_used[q])


@dataclass
class Brick:
    """A reconstructed coefficient brick, ready for the ``bspline<d>`` model's kernels.

    Attributes
    ----------
    level : int
    index : tuple of 3 ints
        Chunk index on ``level``.
    coeffs : ndarray, shape (k + d, k + d, k + d)
        A ``BSplineModel``-style padded coefficient array: local cell ``c`` depends on
        ``coeffs[c .. c + d]``; local voxel ``v`` is ``coeffs[v + pad]``. A view into the
        reconstructor's cache, valid until its next :meth:`ChunkReconstructor.update`.
    origin : ndarray, shape (3,)
        World-voxel position of local voxel 0 (multiply by spacing, add the volume origin).
    scale : float
        Voxels per local voxel, ``2^level``.
    octants : int
        Which octants of the chunk's region to draw (:data:`.wavelet.lod.WHOLE_CHUNK` = all).
    """

    level: int
    index: tuple[int, int, int]
    coeffs: np.ndarray
    origin: np.ndarray
    scale: float
    octants: int


@dataclass
class ReconstructionStats:
    """What one :meth:`ChunkReconstructor.update` did."""

    computed: list[int] = field(default_factory=list)
    reused: list[int] = field(default_factory=list)
    milliseconds: float = 0.0
    #: Per level 0..J-1: chunks whose details entered a computed brick this update.
    detail_owners: list[np.ndarray] = field(default_factory=list)
    #: Detail blocks the ``loader`` read this update.
    details_read: int = 0
    #: Bytes the cached bricks and detail blocks hold after the update.
    resident_bytes: int = 0


class ChunkReconstructor:
    """Reconstructs and caches the bricks of successive selections of one pyramid.

    Parameters
    ----------
    pyramid : WaveletPyramid
        Its layout, coefficient type and coarsest level (read once for the root bricks).
    loader : callable, optional
        ``loader(level, block) -> sequence of 7 arrays``: the level-``level`` details of block
        ``block`` (3 ints; nodes ``DETAIL_BLOCK * block`` onwards, at most :data:`DETAIL_BLOCK`
        per axis, clipped to each subband's shape), in :data:`DETAIL_BANDS` order
        (:meth:`.wavelet.store.WaveletVolume.read_detail_block`). Default: slices of
        ``pyramid.details``.
    budget : int, optional
        Bytes the cached bricks and detail blocks may hold together (``None``: unbounded).
        What the current selection needs is never evicted, so a selection larger than the budget
        still renders, above it; otherwise the least recently used bricks and blocks make room.
    label : str
        Names the pyramid in the memory guard's message (the store's path).

    Notes
    -----
    Memory is two :class:`.wavelet.memory.SlotPool`: bricks of every level in one array (the
    kernel reads a parent slot and writes a child slot of the same array), detail blocks in
    another with one slot table per level. ``resident_bytes`` is their size.
    """

    def __init__(self, pyramid: WaveletPyramid,
                 loader: Callable[[int, tuple[int, int, int]], Sequence[np.ndarray]] | None = None,
                 budget: int | None = None, label: str = "wavelet pyramid") -> None:
        self.pyramid = pyramid
        self.loader = loader if loader is not None else self._from_pyramid
        self.layout: WaveletLayout = pyramid.layout
        lay = self.layout
        w = spline_wavelet(lay.degree)
        self._p = (np.ascontiguousarray(w.synthesis_low.taps), w.synthesis_low.start)
        self._g = (np.ascontiguousarray(w.synthesis_high.taps), w.synthesis_high.start)
        size = lay.brick_size
        dtype = np.dtype(pyramid.dtype)
        self._frame = 0
        #: Counts the updates (and clears) that wrote or dropped a brick: while it stays, every
        #: brick array handed out earlier still holds its chunk's current coefficients.
        self.version = 0
        self._budget = Budget(budget, self._remapped)
        self._bricks = SlotPool((size, size, size), dtype, self._release_bricks,
                                "coefficient bricks", label)
        self._blocks = SlotPool((7,) + (DETAIL_BLOCK,) * 3, dtype, self._release_blocks,
                                "detail blocks", label)
        self._budget.pools = [self._bricks, self._blocks]
        self._slot = [np.full(lay.chunks(j), -1, dtype=np.int64) for j in range(lay.levels + 1)]
        self._sig = [np.zeros(lay.chunks(j), dtype=np.uint64) for j in range(lay.levels + 1)]
        self._table: dict[int, np.ndarray] = {
            j: np.full(tuple(-(-n // DETAIL_BLOCK) for n in lay.length(j)), -1, dtype=np.int64)
            for j in range(1, lay.levels + 1)}
        self._owner_maps = {j: [self._owner_blocks(j, a) for a in range(3)]
                            for j in range(1, lay.levels + 1)}
        self._roots()

    @property
    def budget(self) -> int | None:
        """The byte budget of the cached bricks and detail blocks (``None``: unbounded)."""
        return self._budget.limit

    @property
    def resident_bytes(self) -> int:
        """Bytes the cached bricks and detail blocks hold now."""
        return self._budget.nbytes

    # ---------------------------------------------------------------- memory bookkeeping
    def _release_bricks(self, levels: np.ndarray, flats: np.ndarray) -> None:
        for j in np.unique(levels):
            self._slot[int(j)].reshape(-1)[flats[levels == j]] = -1

    def _release_blocks(self, levels: np.ndarray, flats: np.ndarray) -> None:
        for j in np.unique(levels):
            self._table[int(j)].reshape(-1)[flats[levels == j]] = -1

    def _remapped(self, pool: SlotPool, remap: np.ndarray) -> None:
        tables = self._slot if pool is self._bricks else list(self._table.values())
        for table in tables:
            live = table >= 0
            table[live] = remap[table[live]]

    def _from_pyramid(self, level: int, block: tuple[int, int, int]) -> list[np.ndarray]:
        lo = [DETAIL_BLOCK * int(b) for b in block]
        box = tuple(slice(a, a + DETAIL_BLOCK) for a in lo)
        return [np.asarray(self.pyramid.details[level][band][box]) for band in DETAIL_BANDS]

    def _owner_blocks(self, level: int, axis: int) -> np.ndarray:
        """``M[o, b]``: owner ``o`` (a chunk of level ``level - 1``) has level-``level`` details
        in block ``b`` along ``axis``."""
        lay = self.layout
        n_nodes = lay.length(level)[axis]
        owners = lay.owner(level - 1, axis, np.arange(n_nodes))
        m = np.zeros((lay.chunks(level - 1)[axis], -(-n_nodes // DETAIL_BLOCK)), dtype=np.int64)
        m[owners, np.arange(n_nodes) // DETAIL_BLOCK] = 1
        return m

    def _ensure_blocks(self, level: int, owners: np.ndarray) -> int:
        """Make resident the detail blocks of ``level`` that chunks ``owners`` own; returns how
        many were loaded."""
        need = owners.astype(np.int64)
        for axis, m in enumerate(self._owner_maps[level]):
            need = np.moveaxis(np.tensordot(np.moveaxis(need, axis, -1), m, axes=1), -1, axis)
        need = need > 0
        table = self._table[level]
        present = table[need]
        self._blocks.touch(present[present >= 0], self._frame)
        missing = need & (table < 0)
        flats = np.flatnonzero(missing)
        if flats.size == 0:
            return 0
        self._budget.make_room(self._blocks, int(flats.size), self._frame)
        slots = self._blocks.take(level, flats, self._frame)
        table.reshape(-1)[flats] = slots
        shape = table.shape
        for slot, flat in zip(slots, flats, strict=True):
            block = np.unravel_index(int(flat), shape)
            target = self._blocks.array[slot]
            target[...] = 0
            for b, part in enumerate(self.loader(level, tuple(int(i) for i in block))):
                target[b, :part.shape[0], :part.shape[1], :part.shape[2]] = part
        return int(flats.size)

    def _roots(self) -> None:
        lay = self.layout
        top = lay.levels
        shape = lay.chunks(top)
        size = lay.brick_size
        count = int(np.prod(shape))
        self._budget.make_room(self._bricks, count, self._frame)
        slots = self._bricks.take(top, np.arange(count), self._frame)
        coarse = self.pyramid.coarse[top]
        for n, idx in enumerate(np.ndindex(*shape)):
            rows = [reflect_indices(np.arange(size) + lay.brick_first_node(idx[a]),
                                    lay.length(top)[a], lay.coarse_rule)[0] for a in range(3)]
            box = np.asarray(coarse[min(rows[0]):max(rows[0]) + 1, min(rows[1]):max(rows[1]) + 1,
                                    min(rows[2]):max(rows[2]) + 1])
            self._bricks.array[slots[n]] = box[np.ix_(rows[0] - min(rows[0]),
                                                       rows[1] - min(rows[1]),
                                                       rows[2] - min(rows[2]))]
        self._slot[top].reshape(-1)[:] = slots
        flat = np.arange(count, dtype=np.uint64).reshape(shape)
        self._sig[top] = _splitmix(flat + np.uint64(1))

    def clear(self) -> None:
        """Forget every brick but the roots (detail blocks stay resident)."""
        top = self.layout.levels
        self.version += 1
        live = (self._bricks.level >= 0) & (self._bricks.level < top)
        self._bricks.level[live] = -1
        for j in range(top):
            self._slot[j][:] = -1

    def _slots_for(self, level: int, need: np.ndarray) -> np.ndarray:
        """Slots for chunks ``need`` (free slots of the pool for new ones)."""
        slots = self._slot[level][need]
        fresh = slots < 0
        count = int(fresh.sum())
        if count:
            self._budget.make_room(self._bricks, count, self._frame)
            slots = self._slot[level][need]  # making room may not move these (touched)
            fresh = slots < 0
            flats = np.flatnonzero(need)[fresh]  # both in C order
            slots[fresh] = self._bricks.take(level, flats, self._frame)
            self._slot[level][need] = slots
        self._bricks.touch(slots, self._frame)
        return slots

    def update(self, selection: Selection) -> ReconstructionStats:
        """Make every brick of ``selection`` current; returns what was computed and reused."""
        lay = self.layout
        if selection.layout != lay:
            raise ParameterError("selection was made for another layout")
        stats = ReconstructionStats()
        start = time.perf_counter()
        self._frame += 1
        # Everything the selection needs that is cached now stays for this frame.
        for j in range(lay.levels + 1):
            present = self._slot[j][selection.reconstructed[j]]
            self._bricks.touch(present[present >= 0], self._frame)
        k, pad = lay.chunk, lay.pad
        for j in range(lay.levels - 1, -1, -1):
            active = np.ascontiguousarray(selection.active[j])
            parent_sig = self._sig[j + 1][np.ix_(*[np.arange(n) // 2 for n in lay.chunks(j)])]
            sig = _splitmix(parent_sig ^ _splitmix(_owner_bits(active)))
            need = selection.reconstructed[j]
            current = need & (self._slot[j] >= 0) & (self._sig[j] == sig)
            todo = need & ~current
            used = np.zeros(lay.chunks(j), dtype=bool)
            if todo.any():
                self.version += 1
                stats.details_read += self._ensure_blocks(j + 1, active & _dilate(todo))
                children = np.argwhere(todo).astype(np.int64)
                out_slot = self._slots_for(j, todo)
                # argwhere and boolean indexing both run in C order, so they line up.
                parent_slot = self._slot[j + 1][children[:, 0] // 2, children[:, 1] // 2,
                                                children[:, 2] // 2]
                if np.any(parent_slot < 0):
                    raise RuntimeError("a reconstructed chunk's parent is missing")
                owners = np.zeros((children.shape[0], 3, 3, 3), dtype=np.bool_)
                threads = numba.get_num_threads()
                if children.shape[0] < PARALLEL_MIN_CHUNKS:
                    numba.set_num_threads(1)
                pool = self._bricks.array
                try:
                    details = _Details(self._table[j + 1], self._blocks.array,
                                       np.asarray(lay.length(j + 1), np.int64),
                                       np.asarray(lay.detail_length(j + 1), np.int64), active)
                    synthesis = _Synthesis(k, pad, self._p[0], self._p[1], self._g[0],
                                           self._g[1], lay.coarse_rule, lay.detail_rule)
                    stray = _reconstruct_chunks(children, parent_slot, pool, out_slot, pool,
                                                details, synthesis, owners)
                finally:
                    numba.set_num_threads(threads)
                if stray:
                    raise RuntimeError("details from outside a chunk's neighbourhood or from a "
                                       "block that is not resident")
                for off in np.argwhere(owners.any(axis=0)):
                    hit = owners[:, off[0], off[1], off[2]]
                    pos = [np.clip(children[hit, a] + off[a] - 1, 0, lay.chunks(j)[a] - 1)
                           for a in range(3)]
                    used[pos[0], pos[1], pos[2]] = True
                self._sig[j][todo] = sig[todo]
            stats.computed.insert(0, int(todo.sum()))
            stats.reused.insert(0, int(current.sum()))
            stats.detail_owners.insert(0, used)
        stats.milliseconds = (time.perf_counter() - start) * 1e3
        stats.resident_bytes = self.resident_bytes
        return stats

    def signature(self, level: int, index: tuple[int, int, int]) -> int:
        """Hash of the current content of a chunk's brick (equal signatures, equal bricks)."""
        return int(self._sig[level][tuple(index)])

    def coefficients(self, level: int, index: tuple[int, int, int]) -> np.ndarray:
        """The current brick array of chunk ``index`` on ``level`` (:attr:`Brick.coeffs`)."""
        slot = self._slot[level][index]
        if slot < 0:
            raise KeyError(f"chunk {index} of level {level} is not reconstructed")
        return self._bricks.array[slot]

    def brick(self, level: int, index: tuple[int, int, int], octants: int = 0xFF) -> Brick:
        """The current brick of chunk ``index`` on ``level`` (after :meth:`update`)."""
        slot = self._slot[level][index]
        if slot < 0:
            raise KeyError(f"chunk {index} of level {level} is not reconstructed")
        lay = self.layout
        return Brick(level, tuple(int(i) for i in index), self._bricks.array[slot],
                     lay.brick_origin(level, index), float(2**level), octants)

    def bricks(self, selection: Selection) -> list[Brick]:
        """Every brick that draws part of ``selection`` (call :meth:`update` first)."""
        return [self.brick(j, idx, mask) for j, idx, mask in selection.drawn()]
