"""Min/max block hierarchy for empty-space skipping.

Cells are grouped into aligned blocks of ``4``, ``16`` and ``64`` cells per axis. For every block
the hierarchy stores the smallest and largest value any reconstruction inside it can take; a model
supplies these as "the coefficients that influence a cell" (for trilinear interpolation: the eight
corner voxels, whose range bounds the interpolant by convexity). The ranges depend on the volume
only and are built once; an isovalue change only recomputes one boolean per block, "can this block
contain the isovalue?", which takes a few milliseconds even for 512^3 volumes.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .._jit import jit, read_only
from .._jit.work_queue import run_items, take

__all__ = ["BLOCK_SHIFTS", "PAIR_SHIFT", "MinMaxHierarchy", "inactive_block_size",
           "packed_pair_flags", "inactive_pair_size", "neighbourhood"]

#: log2 of the block edge (in cells) of each level, finest first.
BLOCK_SHIFTS = (2, 4, 6)

#: log2 of the edge of the "pairs", the blocks of 2x2x2 cells below the finest level. Their
#: ranges are stored in 8 bits within their 4-cell block's (in float64 they would take 2 bytes
#: a cell, more than a float32 volume), and an isovalue's flags of them are computed inside the
#: active finest blocks only (:meth:`MinMaxHierarchy.classify`). Isosurfaces use them.
PAIR_SHIFT = 1
# The pair kernels below split each finest block into 2 x 2 x 2 pairs.
assert BLOCK_SHIFTS[0] == PAIR_SHIFT + 1


#: Levels of the pairs' quantized ranges: 0 .. PAIR_LEVELS within their 4-cell block's range.
PAIR_LEVELS = 255.0


@jit(inline="always")
def _level_scale(vmin: float, vmax: float) -> float:
    """Levels per unit value of a 4-cell block's pairs; 0 when its range is one value or not
    finite (every pair is then flagged with the block)."""
    width = vmax - vmin
    if not (width > 0.0 and width < np.inf):
        return 0.0
    scale = PAIR_LEVELS / width
    return scale if scale < np.inf else 0.0


def _finest_ranges(
    coeffs: np.ndarray, support: int, n_cells: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ranges of the 4-cell blocks, and their 2-cell blocks' ranges quantized within them.

    ``pairs[bi, bj, bk, 2 * p]`` and ``[..., 2 * p + 1]`` are pair ``p = a * 4 + b * 2 + c``'s
    lowest and highest level: its values lie in ``lo + [low, high] * (hi - lo) / PAIR_LEVELS``
    (rounded outwards, so the levels bound the values; :func:`_pair_flags` explains why the
    test of an isovalue against them never misses one inside). A block's range is the union
    of its pairs' (their value windows cover its own). Slabs of blocks along the first axis
    are spread over threads (:func:`~splinecast._jit.work_queue.run_items`)."""
    block = 1 << BLOCK_SHIFTS[0]
    shape = tuple((int(n) + block - 1) // block for n in n_cells)
    lo = np.empty(shape, dtype=np.float64)
    hi = np.empty(shape, dtype=np.float64)
    pairs = np.zeros(shape + (16,), dtype=np.uint8)
    run_items(_finest_range_slabs, shape[0], coeffs, int(support), n_cells, lo, hi, pairs)
    return lo, hi, pairs


@jit
def _finest_range_slabs(coeffs, support, n_cells, lo, hi, pairs, counter):
    """One thread's share of :func:`_finest_ranges`: the slabs of blocks it takes."""
    block = 1 << BLOCK_SHIFTS[0]
    nbx, nby, nbz = lo.shape
    npx, npy, npz = (n_cells[0] + 1) // 2, (n_cells[1] + 1) // 2, (n_cells[2] + 1) // 2
    sx, sy, sz = coeffs.shape
    edge = block + support  # values per axis a block reads
    while True:
        bi = take(counter)
        if bi >= nbx:
            break
        plo = np.empty(8)
        phi = np.empty(8)
        # The range of each of the block's value columns along k over each half of the block
        # (cells 2 pk, 2 pk + 1): every value is read once per half instead of once per pair.
        col_lo = np.empty((edge, edge, 2))
        col_hi = np.empty((edge, edge, 2))
        i0 = block * bi
        ni = min(edge, sx - i0)
        for bj in range(nby):
            j0 = block * bj
            nj = min(edge, sy - j0)
            for bk in range(nbz):
                k0 = block * bk
                for c in range(2):
                    if 2 * bk + c >= npz:
                        continue
                    ka, kb = k0 + 2 * c, min(k0 + 2 * c + 2 + support, sz)
                    for a in range(ni):
                        for b in range(nj):
                            cmin = np.inf
                            cmax = -np.inf
                            for k in range(ka, kb):
                                v = float(coeffs[i0 + a, j0 + b, k])
                                cmin = min(cmin, v)
                                cmax = max(cmax, v)
                            col_lo[a, b, c] = cmin
                            col_hi[a, b, c] = cmax
                vmin = np.inf
                vmax = -np.inf
                for p in range(8):
                    pa, pb, pc = p >> 2, (p >> 1) & 1, p & 1
                    if 2 * bi + pa >= npx or 2 * bj + pb >= npy or 2 * bk + pc >= npz:
                        plo[p], phi[p] = np.inf, -np.inf
                        continue
                    a_lo = np.inf
                    b_hi = -np.inf
                    for a in range(2 * pa, min(2 * pa + 2 + support, ni)):
                        for b in range(2 * pb, min(2 * pb + 2 + support, nj)):
                            a_lo = min(a_lo, col_lo[a, b, pc])
                            b_hi = max(b_hi, col_hi[a, b, pc])
                    plo[p], phi[p] = a_lo, b_hi
                    vmin = min(vmin, a_lo)
                    vmax = max(vmax, b_hi)
                lo[bi, bj, bk] = vmin
                hi[bi, bj, bk] = vmax
                scale = _level_scale(vmin, vmax)
                for p in range(8):
                    if not plo[p] <= phi[p] or scale == 0.0:
                        continue  # no cells, or _pair_flags flags every pair
                    # The same monotone expression as the isovalue's level in _pair_flags.
                    q_lo = math.floor((plo[p] - vmin) * scale)
                    q_hi = math.ceil((phi[p] - vmin) * scale)
                    pairs[bi, bj, bk, 2 * p] = int(min(max(q_lo, 0.0), PAIR_LEVELS))
                    pairs[bi, bj, bk, 2 * p + 1] = int(min(max(q_hi, 0.0), PAIR_LEVELS))


def _pair_flags(lo: np.ndarray, hi: np.ndarray, pairs: np.ndarray, act0: np.ndarray,
                iso: float, n_cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Flags of the 2-cell blocks inside the active 4-cell blocks that can hold ``iso``.

    A pair's value ``v`` and the isovalue go to levels by the same expression,
    ``(x - lo) * scale``; subtraction and multiplication by a positive number are monotone in
    floating point, so ``v <= iso`` gives ``level(v) <= level(iso)`` exactly, and the stored
    levels, rounded outwards, bound ``level(v)``: a pair holding the isovalue is never missed.
    The top level also stands for anything above it (rounding can lift ``level(hi)`` above
    ``PAIR_LEVELS``). Blocks whose range is one value or not finite flag every pair.

    Returns the flags, one byte per 2-cell block, and the same packed into one byte per 4-cell
    block (:func:`packed_pair_flags`). Slabs of blocks along the first axis are spread over
    threads; a slab writes only its own pairs and bytes."""
    out = np.zeros(tuple((int(n) + 1) // 2 for n in n_cells), dtype=np.uint8)
    packed = np.zeros(act0.shape, dtype=np.uint8)
    run_items(_pair_flag_slabs, act0.shape[0], lo, hi, pairs, act0, float(iso), out, packed)
    return out, packed


@jit
def _pair_flag_slabs(lo, hi, pairs, act0, iso, out, packed, counter):
    """One thread's share of :func:`_pair_flags`: the slabs of blocks it takes."""
    npx, npy, npz = out.shape
    while True:
        bi = take(counter)
        if bi >= act0.shape[0]:
            break
        for bj in range(act0.shape[1]):
            for bk in range(act0.shape[2]):
                if act0[bi, bj, bk] == 0:
                    continue
                vmin, vmax = lo[bi, bj, bk], hi[bi, bj, bk]
                scale = _level_scale(vmin, vmax)
                level = (iso - vmin) * scale
                every = scale == 0.0
                for p in range(8):
                    pi, pj, pk = 2 * bi + (p >> 2), 2 * bj + ((p >> 1) & 1), 2 * bk + (p & 1)
                    if pi >= npx or pj >= npy or pk >= npz:
                        continue
                    q_lo = float(pairs[bi, bj, bk, 2 * p])
                    q_hi = float(pairs[bi, bj, bk, 2 * p + 1])
                    if every or (q_lo <= level and (q_hi >= level or q_hi == PAIR_LEVELS)):
                        out[pi, pj, pk] = 1
                        packed[bi, bj, bk] |= np.uint8(1 << p)


@jit
def packed_pair_flags(pairs: np.ndarray, shape: np.ndarray) -> np.ndarray:
    """The 2-cell blocks' flags packed into their 4-cell block's byte (bit
    ``((i >> 1) & 1) << 2 | ((j >> 1) & 1) << 1 | ((k >> 1) & 1)`` of block ``(i, j, k) >> 2``
    for cell ``(i, j, k)``), ``shape`` being the 4-cell blocks' counts: what
    :func:`inactive_pair_size` reads. One byte per 4-cell block stays in the L1 cache where one
    per pair does not, and the 4-cell flags need no read of their own."""
    out = np.zeros((shape[0], shape[1], shape[2]), np.uint8)
    npx, npy, npz = pairs.shape
    for pi in range(npx):
        for pj in range(npy):
            for pk in range(npz):
                if pairs[pi, pj, pk] != 0:
                    bit = ((pi & 1) << 2) | ((pj & 1) << 1) | (pk & 1)
                    out[pi >> 1, pj >> 1, pk >> 1] |= np.uint8(1 << bit)
    return out


@jit(inline="always")
def inactive_block_size(
    act0: np.ndarray, act1: np.ndarray, act2: np.ndarray, i: int, j: int, k: int
) -> int:
    """Edge in cells of the largest inactive block holding cell ``(i, j, k)``; 0 if it is active.

    The flags are :attr:`MinMaxHierarchy.active`, finest level first; the shifts are
    :data:`BLOCK_SHIFTS` (checked coarse to fine so the biggest leap is taken).
    """
    # Unsigned indices: cells are never negative, and numba then leaves out the negative-index
    # wrap-around it adds to every read with a signed index (this runs for every cell visited).
    ui, uj, uk = np.uint64(i), np.uint64(j), np.uint64(k)
    if act2[ui >> np.uint64(6), uj >> np.uint64(6), uk >> np.uint64(6)] == 0:
        return 64
    if act1[ui >> np.uint64(4), uj >> np.uint64(4), uk >> np.uint64(4)] == 0:
        return 16
    if act0[ui >> np.uint64(2), uj >> np.uint64(2), uk >> np.uint64(2)] == 0:
        return 4
    return 0


@jit(inline="always")
def inactive_pair_size(
    act0: np.ndarray, act1: np.ndarray, act2: np.ndarray, pairs: np.ndarray, i: int, j: int,
    k: int
) -> int:
    """:func:`inactive_block_size`, then 2 if the cell's 2-cell block is flagged inactive in
    ``pairs``, the 2-cell flags packed per 4-cell block (:func:`packed_pair_flags`; an empty
    array has no such level, and the 4-cell flags ``act0`` are read instead). A 4-cell block
    with no flagged pair is leapt whole."""
    # Coarse to fine, the 2-cell blocks last: reading the pair first (one read for an active
    # pair instead of four) was measured slower on every scene: the coarse levels are small
    # and stay in the L1 cache, and most questions end at one of them.
    if pairs.shape[0] == 0:
        return inactive_block_size(act0, act1, act2, i, j, k)
    ui, uj, uk = np.uint64(i), np.uint64(j), np.uint64(k)
    if act2[ui >> np.uint64(6), uj >> np.uint64(6), uk >> np.uint64(6)] == 0:
        return 64
    if act1[ui >> np.uint64(4), uj >> np.uint64(4), uk >> np.uint64(4)] == 0:
        return 16
    bits = pairs[ui >> np.uint64(2), uj >> np.uint64(2), uk >> np.uint64(2)]
    if bits == 0:
        return 4
    one = np.uint64(1)
    bit = (((ui >> one) & one) << np.uint64(2)) | (((uj >> one) & one) << one) | (
        (uk >> one) & one)
    return 0 if (np.uint64(bits) >> bit) & one else 2


@jit
def _coarsened(lo: np.ndarray, hi: np.ndarray, factor: int) -> tuple[np.ndarray, np.ndarray]:
    """Ranges of blocks ``factor`` times larger per axis (partial blocks at the upper ends).

    Compiled: the numpy version (pad, reshape, three reductions for each of min and max) cost
    about as much as the finest ranges for the small arrays of a brick cut, which builds
    hundreds of hierarchies per frame while it refines."""
    nx, ny, nz = lo.shape
    cx, cy = (nx + factor - 1) // factor, (ny + factor - 1) // factor
    cz = (nz + factor - 1) // factor
    out_lo = np.full((cx, cy, cz), np.inf)
    out_hi = np.full((cx, cy, cz), -np.inf)
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                a, b, c = i // factor, j // factor, k // factor
                out_lo[a, b, c] = min(out_lo[a, b, c], lo[i, j, k])
                out_hi[a, b, c] = max(out_hi[a, b, c], hi[i, j, k])
    return out_lo, out_hi


class MinMaxHierarchy:
    """Per-block value ranges at three levels, and the active flags for one isovalue.

    Below the finest level, the ranges of the 2-cell blocks are kept quantized within their
    4-cell block's range, and an isovalue's flags of them are computed in its active blocks
    (:meth:`classify`'s last array).

    Parameters
    ----------
    coeffs : ndarray, shape (sx, sy, sz)
        The values (voxels or spline coefficients) that bound the reconstruction.
    n_cells : tuple of 3 int
        Number of cells per axis.
    support : int
        Cell ``c`` depends on coefficients ``c .. c + support`` along each axis (1 for trilinear).
    """

    def __init__(self, coeffs: np.ndarray, n_cells: tuple[int, int, int], support: int) -> None:
        self.n_cells = tuple(int(n) for n in n_cells)
        # Read-only views: one compiled function for the arrays of files and of memory.
        lo, hi, self._pair_levels = _finest_ranges(read_only(coeffs), support,
                                                    np.asarray(self.n_cells, np.int64))
        self._levels_from(lo, hi)
        self.iso: float | None = None
        self.active: tuple[np.ndarray, ...] = ()

    def _levels_from(self, lo: np.ndarray, hi: np.ndarray) -> None:
        """The levels' ranges from the finest blocks' ``lo``, ``hi``."""
        self.lows = [lo]
        self.highs = [hi]
        for finer, coarser in zip(BLOCK_SHIFTS[:-1], BLOCK_SHIFTS[1:], strict=True):
            lo, hi = _coarsened(lo, hi, 1 << (coarser - finer))
            self.lows.append(lo)
            self.highs.append(hi)

    def classify(self, iso: float) -> tuple[np.ndarray, ...]:
        """Active flags (uint8, one array per level, finest first) for ``iso``, then the
        2-cell blocks' flags (empty without a pair level; see :func:`inactive_pair_size`)."""
        self.iso = float(iso)
        levels = tuple(
            ((lo <= iso) & (hi >= iso)).view(np.uint8)
            for lo, hi in zip(self.lows, self.highs, strict=True)
        )
        self.active = (*levels, self._pair_flags_for(self.iso, levels[0]))
        return self.active

    def active_cell_bounds(self) -> tuple[np.ndarray, np.ndarray] | None:
        """Smallest index-space box, in cells ``[lo, hi)``, holding every active finest block.

        ``None`` when no block is active. Rays that miss this box cannot meet the isovalue, so
        the renderer clips them to it before walking (cheap for objects that fill a small part
        of the volume).
        """
        act = self.active[0].view(bool)
        if not act.any():
            return None
        block = 1 << BLOCK_SHIFTS[0]
        lo, hi = np.empty(3, np.int64), np.empty(3, np.int64)
        for axis in range(3):
            others = tuple(a for a in range(3) if a != axis)
            used = np.flatnonzero(act.any(axis=others))
            lo[axis] = used[0] * block
            hi[axis] = min((used[-1] + 1) * block, self.n_cells[axis])
        return lo, hi

    def flags_for(self, ranges: list[tuple[float, float]]) -> tuple[np.ndarray, ...]:
        """Flags (uint8 per level, finest first) of the blocks meeting any of several closed
        value intervals; the hierarchy's own isovalue flags are left as they are."""
        flags = []
        for lo, hi in zip(self.lows, self.highs, strict=True):
            act = np.zeros(lo.shape, dtype=bool)
            for a, b in ranges:
                act |= (lo <= b) & (hi >= a)
            flags.append(act.view(np.uint8))
        return tuple(flags)

    def classify_any(self, ranges: list[tuple[float, float]]) -> tuple[np.ndarray, ...]:
        """Active flags for blocks meeting any of several closed value intervals."""
        self.iso = None
        self.active = self.flags_for(ranges)
        return self.active

    #: The 2-cell blocks' quantized ranges (:func:`_finest_ranges`; None: no pair level).
    _pair_levels: np.ndarray | None = None
    #: (isovalue, its pair flags, packed) of the last :meth:`_pair_flags_for` call.
    _pairs: tuple[float, np.ndarray, np.ndarray] | None = None

    def _pair_flags_for(self, iso: float, act0: np.ndarray) -> np.ndarray:
        """Flags (uint8) of the 2-cell blocks that can hold ``iso`` inside the active 4-cell
        blocks ``act0`` (this hierarchy's, for ``iso``; 0 elsewhere), for
        :func:`inactive_pair_size`.

        Computed from the pairs' ranges, stored quantized to 8 bits within their 4-cell
        block's (a quarter of a byte per cell, as much as the finest blocks' ranges), in the
        active finest blocks only: about a millisecond for a 256^3 volume, kept for the next
        call with the same isovalue (a brick's hierarchy is classified every frame). A
        hierarchy built from other ranges than the values' (:mod:`.active_cells`) has no pair
        level: the result is then empty.
        """
        if self._pair_levels is None:
            return np.zeros((0, 0, 0), np.uint8)
        if self._pairs is not None and self._pairs[0] == iso:
            return self._pairs[1]
        pairs, packed = _pair_flags(self.lows[0], self.highs[0], self._pair_levels, act0,
                                    float(iso), np.asarray(self.n_cells, np.int64))
        self._pairs = (float(iso), pairs, packed)
        return pairs

    def packed_pairs(self, pairs: np.ndarray, act0: np.ndarray) -> np.ndarray:
        """``pairs`` (2-cell flags) packed per 4-cell block for :func:`inactive_pair_size`:
        made with the flags by :meth:`classify`, packed here for other flags (``act0``: the
        4-cell flags, for their shape)."""
        if self._pairs is not None and self._pairs[1] is pairs:
            return self._pairs[2]
        return packed_pair_flags(pairs, np.asarray(act0.shape, np.int64))

    @property
    def nbytes(self) -> int:
        """Memory held by the ranges and flags."""
        levels = () if self._pair_levels is None else (self._pair_levels,)
        return sum(a.nbytes for a in (*self.lows, *self.highs, *self.active, *levels))


def neighbourhood(values: np.ndarray, reduce: Any) -> np.ndarray:
    """``reduce`` (``np.minimum``, ``np.maximum``, ``np.logical_or``) of every entry of a 3D
    array and its 26 neighbours (those inside the array), one axis at a time: a block's range
    joined with its neighbours', or flags grown by one block."""
    for axis in range(values.ndim):
        pad = [(1, 1) if d == axis else (0, 0) for d in range(values.ndim)]
        edged = np.pad(values, pad, mode="edge")  # the edge repeats itself: no new values
        n = values.shape[axis]
        part = [[slice(None)] * values.ndim for _ in range(3)]
        for shift in range(3):
            part[shift][axis] = slice(shift, shift + n)
        values = reduce(reduce(edged[tuple(part[0])], edged[tuple(part[1])]),
                        edged[tuple(part[2])])
    return values
