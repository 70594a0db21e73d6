"""Min/max block hierarchy for empty-space skipping.

Cells are grouped into aligned blocks of ``4``, ``16`` and ``64`` cells per axis. For every block
the hierarchy stores the smallest and largest value any reconstruction inside it can take; a model
supplies these as "the coefficients that influence a cell" (for trilinear interpolation: the eight
corner voxels, whose range bounds the interpolant by convexity). The ranges depend on the volume
only and are built once; an isovalue change only recomputes one boolean per block, "can this block
contain the isovalue?", which takes a few milliseconds even for 512^3 volumes.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import prange

from .._jit import jit

__all__ = ["BLOCK_SHIFTS", "MinMaxHierarchy", "inactive_block_size", "neighbourhood"]

#: log2 of the block edge (in cells) of each level, finest first.
BLOCK_SHIFTS = (2, 4, 6)


@jit(parallel=True)
def _finest_ranges(
    coeffs: np.ndarray, block: int, support: int, n_cells: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    nbx = (n_cells[0] + block - 1) // block
    nby = (n_cells[1] + block - 1) // block
    nbz = (n_cells[2] + block - 1) // block
    lo = np.empty((nbx, nby, nbz), dtype=np.float64)
    hi = np.empty((nbx, nby, nbz), dtype=np.float64)
    sx, sy, sz = coeffs.shape
    for bi in prange(nbx):
        i0 = bi * block
        i1 = min(i0 + block + support, sx)
        for bj in range(nby):
            j0 = bj * block
            j1 = min(j0 + block + support, sy)
            for bk in range(nbz):
                k0 = bk * block
                k1 = min(k0 + block + support, sz)
                vmin = np.inf
                vmax = -np.inf
                for i in range(i0, i1):
                    for j in range(j0, j1):
                        for k in range(k0, k1):
                            v = float(coeffs[i, j, k])
                            vmin = min(vmin, v)
                            vmax = max(vmax, v)
                lo[bi, bj, bk] = vmin
                hi[bi, bj, bk] = vmax
    return lo, hi


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
        block0 = 1 << BLOCK_SHIFTS[0]
        lo, hi = _finest_ranges(coeffs, block0, support, np.asarray(self.n_cells, np.int64))
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
        """Active flags (uint8, one array per level, finest first) for ``iso``."""
        self.iso = float(iso)
        self.active = tuple(
            ((lo <= iso) & (hi >= iso)).view(np.uint8)
            for lo, hi in zip(self.lows, self.highs, strict=True)
        )
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

    @property
    def nbytes(self) -> int:
        """Memory held by the ranges and flags."""
        return sum(a.nbytes for a in (*self.lows, *self.highs, *self.active))


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
