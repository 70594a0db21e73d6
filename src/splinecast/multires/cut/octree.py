"""The brick octree of a multiscale volume: which voxels each brick covers and reads.

Bricks and keys
    A brick is identified by its key ``(level, i, j, k)``: pyramid level (0 finest) and brick index
    along x, y, z. On level ``L`` with per-axis factor ``f_L`` (the power of two by which that axis
    was halved, see :mod:`~splinecast.multires.store.pyramid`), brick ``b`` covers the level-0
    index box
    ``[b B f_L, (b + 1) B f_L]`` per axis, clipped to the volume ``[0, n - 1]``: ``B`` cells of its
    own level. Every level has the same ``B`` cells per brick, so a brick's children on the next
    finer level are the 2 (or 1, along an axis that was not halved) bricks per axis inside it: up to
    eight. Trees are incomplete at the far borders (sizes that are not powers of two) and may have
    several roots (the coarsest level's bricks).

Ghosts (one rule for every model)
    A brick's array holds its level's voxels ``[b B - G, (b + 1) B + G]`` per axis: the ``B + 1``
    voxels of its cells and :data:`GHOST` ``= 2`` more on each side, so ``B + 1 + 2 G`` (37 for
    ``B = 32``). That is the widest support of the models: trilinear cell ``c`` reads voxels
    ``c .. c + 1``; cubic B-spline cell ``c`` reads ``c - 1 .. c + 2``; quadratic B-spline and
    type-6 (qss, s31) cube ``c`` read ``c - 1 .. c + 1``; the type-6 Laplacian prefilter widens that
    by one, to ``c - 2 .. c + 2``. Beyond the level's ends the ghosts are filled by the model's own
    border rule (``"edge"`` or ``"reflect"``, see :class:`.store.cache.BrickCache`). A brick
    therefore
    renders without reading its neighbours.

Stores written by other tools
    Levels of other pyramids need not be aligned like ours (ome-zarr-py and ngff-zarr put coarse
    voxel centres half a fine voxel off, and may not halve z). The octree uses every level whose
    per-axis factor to the previous one is 1 or 2 (others are skipped, listed in ``notes``) and
    maps a node's box into the level through the level's own scale and translation; its window is
    then ``floor(lo) - G .. ceil(hi) + G``, one voxel longer where the box is not aligned.

Value ranges
    ``ranges[p]`` holds each brick's own ``[min, max]`` (the ``minmax`` table, NaN where unknown
    until the brick is read), ``subtree[p]`` the union over the brick and all its descendants:
    a subtree whose range cannot contribute is never visited, its bricks never read.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ...errors import ParameterError
from ...io.omezarr import MultiscaleVolume
from ..store.tables import MINMAX

__all__ = ["GHOST", "DEFAULT_BRICK", "brick_counts", "BrickOctree"]

#: Ghost voxels on each side of a brick (enough for every model, see the module docstring).
GHOST = 2
#: Brick size used for stores that do not say (written by other tools).
DEFAULT_BRICK = 32


def brick_counts(shape: Any, brick: int) -> np.ndarray:
    """Bricks per axis for a grid of ``shape`` voxels: ``ceil((n - 1) / brick)``, at least 1."""
    cells = np.asarray(shape, dtype=np.int64) - 1
    return np.maximum(1, -(-cells // brick))


class BrickOctree:
    """Bricks of every usable level of a :class:`~splinecast.io.omezarr.MultiscaleVolume`.

    Parameters
    ----------
    volume : MultiscaleVolume
    brick : int, optional
        Cells per brick (default: the size the pyramid was built with, else 32).
    ghost : int
        Ghost voxels per side (default :data:`GHOST`).

    Attributes
    ----------
    levels : list of int
        Store levels the octree uses, finest first (position ``p`` in the arrays below).
    factors : ndarray (n_levels, 3)
        Power-of-two factor of each used level per axis, relative to level 0.
    counts : ndarray (n_levels, 3)
        Bricks per axis.
    ranges, subtree : list of ndarray (counts..., 2)
        Own and subtree value ranges (float64, NaN = unknown).
    notes : list of str
        Levels left out and why.
    """

    def __init__(self, volume: MultiscaleVolume, brick: int | None = None,
                 ghost: int = GHOST) -> None:
        self.volume = volume
        self.brick = int(brick or volume.brick or DEFAULT_BRICK)
        if self.brick < 2:
            raise ParameterError(f"brick must be at least 2, got {brick}")
        self.ghost = int(ghost)
        self.notes: list[str] = []
        base = volume.levels[0]
        self.n0 = np.asarray(base.shape, dtype=np.int64)
        spacing0 = np.asarray(base.spacing)
        origin0 = np.asarray(base.origin)
        levels, factors, scales, offsets = [0], [np.ones(3, np.int64)], [np.ones(3)], [np.zeros(3)]
        for level in volume.levels[1:]:
            ratio = np.asarray(level.spacing) / spacing0
            # The power of two nearest the ratio, kept within 1 .. 2^62 so that a level finer
            # than level 0 or absurdly coarse (a damaged store) fails the test below instead of
            # the integer power.
            if not np.all(np.isfinite(ratio) & (ratio > 0)):
                self.notes.append(f"level {level.index} skipped: scale {ratio.tolist()} x level 0 "
                                  "is not a positive number per axis")
                continue
            exponent = np.clip(np.round(np.log2(np.maximum(ratio, 1e-9))), 0, 62)
            factor = 2 ** exponent.astype(np.int64)
            step = factor // factors[-1]
            if (np.any(np.abs(ratio / factor - 1) > 0.25) or np.any(factor < factors[-1])
                    or np.any((step != 1) & (step != 2)) or np.all(step == 1)):
                self.notes.append(f"level {level.index} skipped: scale {ratio.tolist()} x level 0 "
                                  "is not 1 or 2 times the previous level's per axis")
                continue
            # level-L index = level-0 index * scale + offset
            scale = spacing0 / np.asarray(level.spacing)
            offset = (origin0 - np.asarray(level.origin)) / np.asarray(level.spacing)
            last = (self.n0 - 1) * scale + offset
            if np.any(offset < -1) or np.any(last > np.asarray(level.shape)):
                # Bricks of this level would read windows outside its voxels.
                self.notes.append(f"level {level.index} skipped: its voxels do not cover level 0 "
                                  f"(translation {np.asarray(level.origin).tolist()}, shape "
                                  f"{list(level.shape)})")
                continue
            levels.append(level.index)
            factors.append(factor)
            scales.append(scale)
            offsets.append(offset)
        self.levels = levels
        self.factors = np.array(factors)
        self._scale = np.array(scales)
        self._offset = np.array(offsets)
        cells0 = np.maximum(self.n0 - 1, 0)
        self.counts = np.maximum(1, -(-cells0 // (self.brick * self.factors)))
        self.ranges = [self._stored_ranges(p) for p in range(len(levels))]
        self.subtree = [r.copy() for r in self.ranges]
        for p in range(1, len(levels)):
            self._fold_children(p)

    # ------------------------------------------------------------------ levels
    @property
    def n_levels(self) -> int:
        return len(self.levels)

    @property
    def coarsest(self) -> int:
        """Store level of the coarsest used level (the roots)."""
        return self.levels[-1]

    def position(self, level: int) -> int:
        """Array position ``p`` of a store level."""
        try:
            return self.levels.index(level)
        except ValueError:
            raise ParameterError(f"level {level} is not part of the octree {self.levels}") from None

    def _stored_ranges(self, p: int) -> np.ndarray:
        shape = (*self.counts[p], 2)
        table = self.volume.table(MINMAX, self.levels[p])
        if table is not None and table.shape == shape:
            return table.astype(np.float64)
        return np.full(shape, np.nan)

    def _fold_children(self, p: int) -> None:
        """subtree[p] = own range of p united with the subtree ranges of its children."""
        ratio = self.factors[p] // self.factors[p - 1]
        child = self.subtree[p - 1]
        idx = np.indices(child.shape[:3]).reshape(3, -1).T // ratio
        valid = np.all(idx < self.counts[p], axis=1)
        idx, flat = idx[valid], child.reshape(-1, 2)[valid]
        own = self.ranges[p]
        sub = own.copy()
        target = (idx[:, 0], idx[:, 1], idx[:, 2])
        np.minimum.at(sub[..., 0], target, flat[:, 0])
        np.maximum.at(sub[..., 1], target, flat[:, 1])
        self.subtree[p] = sub

    def set_range(self, key: tuple[int, int, int, int], lo: float, hi: float) -> None:
        """Record a brick's value range once its voxels are known; refresh its ancestors'."""
        p = self.position(key[0])
        index = np.array(key[1:], dtype=np.int64)
        self.ranges[p][tuple(index)] = (lo, hi)
        while True:
            self._refresh(p, index)
            if p + 1 >= self.n_levels:
                return
            index = index // (self.factors[p + 1] // self.factors[p])
            p += 1

    def _refresh(self, p: int, index: np.ndarray) -> None:
        own = self.ranges[p][tuple(index)]
        if p == 0:
            self.subtree[0][tuple(index)] = own
            return
        kids = self.children(self.levels[p], index[None])
        parts = self.subtree[p - 1][kids[:, 0], kids[:, 1], kids[:, 2]]
        # np.min/np.max propagate NaN: one unknown child makes the subtree unknown (conservative).
        self.subtree[p][tuple(index)] = (np.min(np.append(parts[:, 0], own[0])),
                                         np.max(np.append(parts[:, 1], own[1])))

    # ------------------------------------------------------------------ geometry
    def roots(self) -> np.ndarray:
        """Indices (n, 3) of the coarsest level's bricks."""
        return np.indices(self.counts[-1]).reshape(3, -1).T.astype(np.int64)

    def box(self, level: int, index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Level-0 index boxes ``(lo, hi)`` (n, 3) of bricks ``index`` (n, 3) of ``level``."""
        p = self.position(level)
        size = self.brick * self.factors[p]
        index = np.asarray(index, dtype=np.int64).reshape(-1, 3)
        lo = np.minimum(index * size, np.maximum(self.n0 - 1, 0))
        hi = np.minimum((index + 1) * size, np.maximum(self.n0 - 1, 0))
        return lo.astype(np.float64), hi.astype(np.float64)

    def world_box(self, level: int, index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World boxes ``(lo, hi)`` (n, 3) of bricks ``index`` of ``level``."""
        lo, hi = self.box(level, index)
        return self.volume.index_to_world(lo), self.volume.index_to_world(hi)

    def level_map(self, level: int) -> tuple[np.ndarray, np.ndarray]:
        """``(scale, offset)``: level index = level-0 index * scale + offset (per axis)."""
        p = self.position(level)
        return self._scale[p], self._offset[p]

    def window(self, level: int, index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Voxel ranges ``[first, stop)`` (n, 3) of the level that bricks ``index`` read."""
        lo, hi = self.box(level, index)
        scale, offset = self.level_map(level)
        lo_l, hi_l = lo * scale + offset, hi * scale + offset
        first = np.floor(lo_l + 1e-9).astype(np.int64) - self.ghost
        stop = np.ceil(hi_l - 1e-9).astype(np.int64) + self.ghost + 1
        return first, stop

    def brick_bytes(self, level: int, index: np.ndarray) -> np.ndarray:
        """Bytes of each brick's array (window voxels times the voxel size)."""
        first, stop = self.window(level, index)
        return np.prod(stop - first, axis=1) * self.volume.dtype.itemsize

    def voxel_size(self, level: int) -> float:
        """Largest world voxel size of a level (what the level of detail compares)."""
        p = self.position(level)
        return float(np.max(np.asarray(self.volume.spacing) * self.factors[p]))

    # ------------------------------------------------------------------ tree
    def children(self, level: int, index: np.ndarray) -> np.ndarray:
        """Child indices (m, 3) on the next finer level of bricks ``index`` (n, 3); the children
        of brick ``n`` are contiguous, in the order of ``index``."""
        p = self.position(level)
        if p == 0:
            return np.empty((0, 3), dtype=np.int64)
        ratio = self.factors[p] // self.factors[p - 1]
        offsets = np.indices(ratio).reshape(3, -1).T
        index = np.asarray(index, dtype=np.int64).reshape(-1, 3)
        kids = (index[:, None, :] * ratio + offsets[None, :, :]).reshape(-1, 3)
        return kids[np.all(kids < self.counts[p - 1], axis=1)]

    def child_counts(self, level: int, index: np.ndarray) -> np.ndarray:
        """Number of children of each brick (what :meth:`children` returns per brick)."""
        p = self.position(level)
        index = np.asarray(index, dtype=np.int64).reshape(-1, 3)
        if p == 0:
            return np.zeros(len(index), dtype=np.int64)
        ratio = self.factors[p] // self.factors[p - 1]
        first = index * ratio
        last = np.minimum(first + ratio, self.counts[p - 1])
        return np.prod(np.maximum(last - first, 0), axis=1)

    def parent(self, key: tuple[int, int, int, int]) -> tuple[int, int, int, int] | None:
        """The key of a brick's parent (``None`` for a root)."""
        p = self.position(key[0])
        if p + 1 >= self.n_levels:
            return None
        ratio = self.factors[p + 1] // self.factors[p]
        i, j, k = (int(v) // int(r) for v, r in zip(key[1:], ratio, strict=True))
        return (self.levels[p + 1], i, j, k)

    def ancestors(self, key: tuple[int, int, int, int]) -> list[tuple[int, int, int, int]]:
        """Parent, grandparent, ... up to the root."""
        out = []
        parent = self.parent(key)
        while parent is not None:
            out.append(parent)
            parent = self.parent(parent)
        return out

    def __repr__(self) -> str:
        counts = ", ".join("x".join(str(int(c)) for c in row) for row in self.counts)
        return (f"BrickOctree(brick={self.brick}, ghost={self.ghost}, levels={self.levels}, "
                f"bricks=[{counts}])")


def total_bricks(octree: BrickOctree) -> int:
    """Number of bricks on all levels (for reports)."""
    return int(sum(math.prod(int(c) for c in row) for row in octree.counts))
