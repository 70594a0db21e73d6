"""Isovalue change for the type-6 splines: classify and compact active cubes and tetrahedra.

Kalbe et al. 2009 and Koch 2009 (section 4.1) prepare every frame's work list once per isovalue:
cubes whose patches may contain the isovalue, then, inside them, the tetrahedra whose patch may.
Here:

1. **Cube classification** (compiled scan and two-pass compaction, on threads): a cube is active
   when the isovalue lies in the exact range of its coefficients (the model's ``cube_lo`` /
   ``cube_hi``, computed once per volume, float32 rounded outward). No coefficient is computed
   here.
2. **Tetrahedron classification** (the model's ``tet_masks``, compiled and on threads over the
   candidate cubes): each tetrahedron is active when the isovalue lies in the range of its own
   Bernstein–Bézier coefficients (convex hull property: the patch lies in that range, so this is
   conservative).
3. **Compaction**: active cubes (with a 24-bit tetrahedron mask each), the list of active
   tetrahedra (``slot * 24 + tet``), the cube -> slot lookup grid the kernels use and the block
   flags for empty-space leaps (blocks of 64, 16, 4 and 2 cubes).
4. Optionally (``precompute=True``), the coefficients of every active cube are stored (the
   thesis' "high frame rate" variant, the model's ``coefficient_rows``) so the kernels read
   instead of recomputing them.

The classification of a model's own pieces comes from the model: a model that classifies its
cells hands a *classifier* from its ``active_cell_classifier()``, an object offering ``cube_lo``,
``cube_hi``, ``n_cells``, ``n_points``, ``precompute``, ``static_nbytes``,
``tet_masks(cubes, iso)`` and ``coefficient_rows(cubes)`` (the protocol
``splinecast.models.base.ActiveCellClassifier`` documents them); this layer never imports a
model and never asks which model it serves.

The scans run on threads that take slabs or chunks from a shared counter
(:func:`~splinecast._jit.work_queue.run_items`), not in Numba's parallel loops, which compile
about twice as long: these kernels are part of every type-6 model's first render.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from .._jit import jit
from .._jit.work_queue import run_items, take
from .minmax import BLOCK_SHIFTS, PAIR_SHIFT, MinMaxHierarchy

__all__ = ["ActiveCells", "CubeBoundHierarchy", "block_ranges", "candidate_cubes", "tet_list"]

def block_ranges(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Range of the cube bounds over aligned blocks of 4^3 cubes (iso-independent)."""
    shape = tuple((n + 3) >> 2 for n in lo.shape)
    blo = np.empty(shape, lo.dtype)
    bhi = np.empty(shape, hi.dtype)
    run_items(_block_range_slabs, shape[0], lo, hi, blo, bhi)
    return blo, bhi


@jit
def _block_range_slabs(lo, hi, blo, bhi, counter):
    """One thread's share of :func:`block_ranges`: the slabs of blocks it takes."""
    nx, ny, nz = lo.shape
    bx, by, bz = blo.shape
    while True:
        a = take(counter)
        if a >= bx:
            break
        for b in range(by):
            for c in range(bz):
                vmin = lo[4 * a, 4 * b, 4 * c]
                vmax = hi[4 * a, 4 * b, 4 * c]
                for i in range(4 * a, min(nx, 4 * a + 4)):
                    for j in range(4 * b, min(ny, 4 * b + 4)):
                        for k in range(4 * c, min(nz, 4 * c + 4)):
                            vmin = min(vmin, lo[i, j, k])
                            vmax = max(vmax, hi[i, j, k])
                blo[a, b, c] = vmin
                bhi[a, b, c] = vmax


@jit(inline="always")
def _scan_block(lo, hi, iso, a, b, c, out, n, write):
    nx, ny, nz = lo.shape
    for i in range(4 * a, min(nx, 4 * a + 4)):
        for j in range(4 * b, min(ny, 4 * b + 4)):
            for k in range(4 * c, min(nz, 4 * c + 4)):
                if lo[i, j, k] <= iso and hi[i, j, k] >= iso:
                    if write:
                        out[n] = (i * ny + j) * nz + k
                    n += 1
    return n


def candidate_cubes(
    lo: np.ndarray, hi: np.ndarray, blo: np.ndarray, bhi: np.ndarray, iso: float,
) -> np.ndarray:
    """Linear indices of the cubes with ``lo <= iso <= hi``, compacted in two passes on threads
    (count per slab, then write at the slab's offset).

    Only the 4^3 blocks whose range (``blo``, ``bhi``) holds ``iso`` are scanned; cubes come
    block by block (slabs of blocks in ``x`` order), which keeps later gathers local.
    """
    bx = blo.shape[0]
    counts = np.zeros(bx + 1, np.int64)
    iso = float(iso)
    run_items(_candidate_slabs, bx, lo, hi, blo, bhi, iso, counts, np.empty(0, np.int64), False)
    np.cumsum(counts, out=counts)
    out = np.empty(int(counts[bx]), np.int64)
    run_items(_candidate_slabs, bx, lo, hi, blo, bhi, iso, counts, out, True)
    return out


@jit
def _candidate_slabs(lo, hi, blo, bhi, iso, counts, out, write, counter):
    """One thread's share of :func:`candidate_cubes`: for the slabs it takes, the count of
    candidates into ``counts[a + 1]``, or (``write``) the candidates from offset ``counts[a]``."""
    bx, by, bz = blo.shape
    while True:
        a = take(counter)
        if a >= bx:
            break
        n = counts[a] if write else 0
        for b in range(by):
            for c in range(bz):
                if blo[a, b, c] <= iso and bhi[a, b, c] >= iso:
                    n = _scan_block(lo, hi, iso, a, b, c, out, n, write)
        if not write:
            counts[a + 1] = n


class CubeBoundHierarchy(MinMaxHierarchy):
    """The scene's block hierarchy built from a type-6 model's exact per-cube bounds.

    Same interface as :class:`~.minmax.MinMaxHierarchy` (levels of 4, 16, 64 cubes), but the
    finest ranges are the blocks' ranges of the cubes' coefficient ranges, which is valid for
    every scheme (also with negative weights) and costs no pass over the data.
    """

    def __init__(self, blo: np.ndarray, bhi: np.ndarray, n_cells: tuple[int, int, int]) -> None:
        self.n_cells = tuple(int(n) for n in n_cells)
        self._levels_from(blo, bhi)
        self.iso = None
        self.active = ()


#: Cubes per item of :func:`tet_list`'s passes.
_TET_CHUNK = 4096


def tet_list(masks: np.ndarray) -> np.ndarray:
    """Compact list ``slot * 24 + tet`` of the active tetrahedra (two-pass prefix on threads:
    count per chunk of cubes, then write at the chunk's offset)."""
    n_chunks = (masks.shape[0] + _TET_CHUNK - 1) // _TET_CHUNK
    counts = np.zeros(n_chunks + 1, np.int64)
    run_items(_count_tets, n_chunks, masks, counts)
    np.cumsum(counts, out=counts)
    out = np.empty(int(counts[n_chunks]), np.int32)
    run_items(_write_tets, n_chunks, masks, counts, out)
    return out


@jit
def _count_tets(masks, counts, counter):
    """One thread's share of :func:`tet_list`'s first pass: active tetrahedra per chunk."""
    n = masks.shape[0]
    while True:
        ch = take(counter)
        if ch >= counts.shape[0] - 1:
            break
        c = 0
        for m in range(ch * _TET_CHUNK, min(n, (ch + 1) * _TET_CHUNK)):
            x = masks[m]
            while x:
                x &= x - np.uint32(1)
                c += 1
        counts[ch + 1] = c


@jit
def _write_tets(masks, counts, out, counter):
    """One thread's share of :func:`tet_list`'s second pass: each chunk's entries."""
    n = masks.shape[0]
    while True:
        ch = take(counter)
        if ch >= counts.shape[0] - 1:
            break
        o = counts[ch]
        for m in range(ch * _TET_CHUNK, min(n, (ch + 1) * _TET_CHUNK)):
            x = masks[m]
            for t in range(24):
                if (x >> t) & 1:
                    out[o] = m * 24 + t
                    o += 1


#: Cubes per item of :func:`_update_lookup`'s passes.
_CUBE_CHUNK = 16384


def _update_lookup(
    slot: np.ndarray, old: np.ndarray, new: np.ndarray, act0: np.ndarray, act1: np.ndarray,
    act2: np.ndarray, pairs: np.ndarray,
) -> None:
    """Reset the old active cubes' slots to -1, then enter the new ones and their block flags
    (the 2-cell blocks' too).

    On threads: the cubes of a list are distinct, and concurrent writes of a block flag all
    store the same value 1.
    """
    run_items(_reset_slots, -(-old.shape[0] // _CUBE_CHUNK), slot, old)
    act0[:] = 0
    act1[:] = 0
    act2[:] = 0
    pairs[:] = 0
    run_items(_enter_cubes, -(-new.shape[0] // _CUBE_CHUNK), slot, new, act0, act1, act2, pairs)


@jit
def _reset_slots(slot, old, counter):
    """One thread's share of :func:`_update_lookup`'s reset: chunks of the old cubes."""
    flat = slot.reshape(-1)  # a view (Numba refuses to reshape a non-contiguous array)
    while True:
        start = take(counter) * _CUBE_CHUNK
        if start >= old.shape[0]:
            break
        for m in range(start, min(start + _CUBE_CHUNK, old.shape[0])):
            flat[old[m]] = -1


@jit
def _enter_cubes(slot, new, act0, act1, act2, pairs, counter):
    """One thread's share of :func:`_update_lookup`'s entries: chunks of the new cubes."""
    ny, nz = slot.shape[1], slot.shape[2]
    flat = slot.reshape(-1)
    while True:
        start = take(counter) * _CUBE_CHUNK
        if start >= new.shape[0]:
            break
        for m in range(start, min(start + _CUBE_CHUNK, new.shape[0])):
            lin = new[m]
            flat[lin] = m
            k = lin % nz
            j = (lin // nz) % ny
            i = lin // (ny * nz)
            pairs[i >> 1, j >> 1, k >> 1] = 1
            act0[i >> 2, j >> 2, k >> 2] = 1
            act1[i >> 4, j >> 4, k >> 4] = 1
            act2[i >> 6, j >> 6, k >> 6] = 1


def _pack_pairs(pairs: np.ndarray, packed: np.ndarray) -> None:
    """The 2-cell flags packed per 4-cell block as :func:`~.minmax.packed_pair_flags` packs
    them (each block's byte written by one thread: concurrent ``|=`` could lose a bit)."""
    run_items(_pack_pair_slabs, packed.shape[0], pairs, packed)


@jit
def _pack_pair_slabs(pairs, packed, counter):
    """One thread's share of :func:`_pack_pairs`: the slabs of blocks it takes."""
    npx, npy, npz = pairs.shape
    bx, by, bz = packed.shape
    while True:
        a = take(counter)
        if a >= bx:
            break
        for b in range(by):
            for c in range(bz):
                bits = 0
                for p in range(8):
                    pi, pj, pk = 2 * a + (p >> 2), 2 * b + ((p >> 1) & 1), 2 * c + (p & 1)
                    if pi < npx and pj < npy and pk < npz and pairs[pi, pj, pk] != 0:
                        bits |= 1 << p
                packed[a, b, c] = bits


def _block_shape(shape: tuple[int, int, int], shift: int) -> tuple[int, int, int]:
    return tuple(-(-n // (1 << shift)) for n in shape)  # type: ignore[return-value]


class ActiveCells:
    """Per-isovalue work lists of a type-6 model (see the module docstring).

    Attributes
    ----------
    iso : float or None
        Isovalue of the current lists.
    cubes : ndarray of int64
        Linear (C-order) indices of the active cubes, listed block (4^3) by block; a cube's
        position here is its *slot*.
    tet_mask : ndarray of uint32
        Per active cube, bit ``t`` set when tetrahedron ``t`` is active.
    tets : ndarray of int32
        Compact list of active tetrahedra, ``slot * 24 + tet``.
    slot : ndarray of int32, shape = volume shape
        Slot of each cube, -1 for inactive cubes (the kernels' lookup).
    coeffs : ndarray of float64, shape (n_active, n_points) or (0, n_points)
        Stored coefficients of the active cubes when the model precomputes them.
    act0, act1, act2 : ndarray of uint8
        Block flags (blocks of 4, 16, 64 cubes) for :func:`~.minmax.inactive_block_size`.
    pairs, packed : ndarray of uint8
        Flags of the blocks of 2 cubes (one byte each) and the same packed per block of 4
        (:func:`~.minmax.packed_pair_flags`) for :func:`~.minmax.inactive_pair_size`: rays
        then leap the inactive pairs of an active block of 4 instead of visiting their cubes.
    """

    def __init__(self, model: Any) -> None:
        # ``model`` is the model's classifier (see the module docstring), usually the model.
        self.model = model
        self.iso: float | None = None
        shape = model.n_cells
        self.slot = np.full(shape, -1, dtype=np.int32)
        self.cubes = np.zeros(0, np.int64)
        self.tet_mask = np.zeros(0, np.uint32)
        self.tets = np.zeros(0, np.int32)
        self.coeffs = np.zeros((0, model.n_points))
        self.act0, self.act1, self.act2 = (
            np.zeros(_block_shape(shape, s), np.uint8) for s in BLOCK_SHIFTS
        )
        self.pairs = np.zeros(_block_shape(shape, PAIR_SHIFT), np.uint8)
        self.packed = np.zeros_like(self.act0)
        self.stats: dict[str, Any] = {}
        #: Range of the cube bounds per block of 4^3 cubes (iso-independent; skips the scan).
        self.block_lo, self.block_hi = block_ranges(model.cube_lo, model.cube_hi)

    def update(self, iso: float) -> dict[str, Any]:
        """Classify and compact for ``iso``; returns counts, timings (ms) and memory (bytes)."""
        m = self.model
        t0 = time.perf_counter()
        candidates = candidate_cubes(m.cube_lo, m.cube_hi, self.block_lo, self.block_hi, iso)
        t1 = time.perf_counter()
        masks = m.tet_masks(candidates, iso)
        t2 = time.perf_counter()
        keep = masks != 0
        if keep.all():
            new, self.tet_mask = candidates, masks
        else:
            new, self.tet_mask = candidates[keep], masks[keep]
        self.tets = tet_list(self.tet_mask)
        _update_lookup(self.slot, self.cubes, new, self.act0, self.act1, self.act2, self.pairs)
        _pack_pairs(self.pairs, self.packed)
        self.cubes = new
        t3 = time.perf_counter()
        if m.precompute:
            self.coeffs = m.coefficient_rows(new)
        else:
            self.coeffs = np.zeros((0, m.n_points))
        t4 = time.perf_counter()
        self.iso = iso
        n_cubes = int(new.shape[0])
        n_tets = int(self.tets.shape[0])
        lookup_bytes = int(self.slot.nbytes + self.block_lo.nbytes + self.block_hi.nbytes
                           + self.act0.nbytes + self.act1.nbytes
                           + self.act2.nbytes + self.pairs.nbytes + self.packed.nbytes)
        lists_bytes = int(self.cubes.nbytes + self.tet_mask.nbytes + self.tets.nbytes)
        coeff_bytes_precomputed = n_cubes * m.n_points * 8
        self.stats = {
            "cube_classify_ms": (t1 - t0) * 1e3,
            "tet_classify_ms": (t2 - t1) * 1e3,
            "compact_ms": (t3 - t2) * 1e3,
            "precompute_ms": (t4 - t3) * 1e3,
            "iso_change_ms": (t4 - t0) * 1e3,
            "cubes_candidate": int(candidates.shape[0]),
            "cubes_active": n_cubes,
            "tets_active": n_tets,
            "tets_per_active_cube": n_tets / n_cubes if n_cubes else 0.0,
            "precompute": bool(m.precompute),
            # Memory per variant: on the fly needs the padded data, the cube bounds, the lookup
            # and the lists; precomputed adds n_active x n_points float64 coefficients.
            "memory_on_the_fly_bytes": int(m.static_nbytes + lookup_bytes + lists_bytes),
            "memory_precomputed_bytes": int(m.static_nbytes + lookup_bytes + lists_bytes
                                            + coeff_bytes_precomputed),
        }
        return dict(self.stats)

    @property
    def nbytes(self) -> int:
        """Memory held by the per-isovalue arrays and the block ranges."""
        return int(sum(a.nbytes for a in (self.slot, self.cubes, self.tet_mask, self.tets,
                                           self.coeffs, self.act0, self.act1, self.act2,
                                           self.pairs, self.packed, self.block_lo,
                                           self.block_hi)))
