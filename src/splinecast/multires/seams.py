"""Crack-free level boundaries: bricks of different levels made to agree where they meet.

Two bricks of one level reconstruct the same function (they read the same level), so they meet
without a seam. A brick next to a *coarser* one reconstructs a finer function, and on their
common face the two differ: an isosurface crossing the face has a crack, DVR shows a seam line.
The finer side is therefore changed, never the coarser one:

Restriction (all models)
    Every element ``p`` of a brick's array (level ``b``) that lies within the model's influence
    radius ``r = (support + 1) / 2`` voxels of a coarser piece of the cut (max-norm distance to
    its box, in level-``b`` voxels) is replaced by the coarser piece's function expressed at
    level ``b``. Within that radius lie all the elements the finer brick's reconstruction reads
    on the common face (faces, edges and corners alike: trilinear reads the face's own voxels,
    ``r = 1``; cubic B-spline and type-6 one layer more, ``r = 2`` and ``3/2``). When several
    coarser pieces are that close, the finest of them supplies the values; arrays are processed
    from the coarsest level to the finest, each using the already changed arrays of the coarser
    ones. The rule depends only on an element's position, so two bricks of one level that share
    an element change it alike and still agree with each other.

Exact where the finer level can represent the coarser function (*nested* models)
    Trilinear and the B-splines of odd degree (``bspline1``, ``bspline3``) have their knots on
    voxel centres, and the vertex-centred pyramid puts coarse voxel ``c`` on fine voxel ``2 c``:
    the coarse spline *is* a fine spline, whose coefficients follow by subdivision (degree 1:
    ``[1, 2, 1] / 2``, the coarse trilinear function sampled at the fine voxels; degree 3:
    ``[1, 4, 6, 4, 1] / 8``). Replacing the elements near the face by these coefficients makes
    the fine reconstruction equal the coarse one on the whole common boundary (C0, up to
    rounding): no crack in any mode. Several levels meeting at an edge or a corner are handled
    by the coarse-to-fine order (the finer coarse piece was itself restricted to the coarsest).

Approximate for the others (``bspline2``, ``qss``, ``s31``) and for pyramids not built by
splinecast (levels offset by half a voxel)
    Their coarse function is not in the finer level's space (even-degree knots and type-6 cubes
    lie between voxel centres, so the levels' pieces do not nest). The elements near the face get
    the coarse function's *values* there; the two sides then differ on the face by the fine
    level's approximation error of the smooth coarse function (measured in
    ``tests/test_multires_render.py``), not by the difference between the levels. For the
    isosurface the remaining crack is closed exactly by :class:`IsoClosure`: a ray that leaves
    one level with the field on one side of the isovalue and enters the next level on the other
    side hits the surface on the face between them (a sub-voxel wall instead of a hole). DVR may
    keep a faint seam of that size; several translucent isosurfaces (``iso=[...]``) are not
    closed.
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..render.iso import Iso
from .probe import grid_values_at, sample_grid

__all__ = ["Seams", "Change", "IsoClosure", "NESTED_DEGREE", "refine"]

#: Models whose coarse reconstruction is exactly a fine one, by their spline degree.
NESTED_DEGREE = {"trilinear": 1, "bspline1": 1, "bspline3": 3}


@dataclass(frozen=True)
class Change:
    """Values replacing elements of a brick's array (flat indices) at a seam."""

    index: np.ndarray
    values: np.ndarray

    def apply(self, array: np.ndarray) -> np.ndarray:
        """A float64 copy of ``array`` with the changed elements."""
        out = np.array(array, dtype=np.float64, order="C")
        out.reshape(-1)[self.index] = self.values
        return out


def refine(array: np.ndarray, first: np.ndarray, ratio: np.ndarray,
           degree: int) -> tuple[np.ndarray, np.ndarray]:
    """One level of B-spline subdivision: the same spline's coefficients on the grid halved along
    the axes where ``ratio`` is 2, and the index of the result's first element.

    Degree 1 (trilinear): ``f[2m] = a[m]``, ``f[2m + 1] = (a[m] + a[m + 1]) / 2``; degree 3:
    ``f[2m] = (a[m - 1] + 6 a[m] + a[m + 1]) / 8``, ``f[2m + 1] = (a[m] + a[m + 1]) / 2``. Only
    elements whose whole mask lies in ``array`` are returned.
    """
    out = np.asarray(array, dtype=np.float64)
    first = np.asarray(first, dtype=np.int64).copy()
    for axis in range(3):
        if ratio[axis] == 1:
            continue
        a = np.moveaxis(out, axis, 0)
        n = a.shape[0]
        if degree == 1:
            fine = np.empty((2 * n - 1, *a.shape[1:]))
            fine[0::2] = a
            fine[1::2] = 0.5 * (a[:-1] + a[1:])
            first[axis] = 2 * first[axis]
        else:
            fine = np.empty((2 * n - 3, *a.shape[1:]))
            fine[0::2] = 0.5 * (a[:-1] + a[1:])
            fine[1::2] = (a[:-2] + 6.0 * a[1:-1] + a[2:]) / 8.0
            first[axis] = 2 * first[axis] + 1
        out = np.moveaxis(fine, 0, axis)
    return np.ascontiguousarray(out), first


class Seams:
    """Restriction of the finer bricks at level boundaries, and the isosurface's closure.

    Parameters
    ----------
    model : a model of :data:`splinecast.models.MODELS`
    """

    def __init__(self, model: Any) -> None:
        self.model = model
        self.degree = NESTED_DEGREE.get(model.name)
        #: Elements closer than this (level voxels, max norm) to a coarser piece are replaced.
        self.radius = (int(model.support) + 1) / 2.0
        self._last: tuple[Any, dict] | None = None

    def closure(self, setup: Any, camera: Any) -> IsoClosure | None:
        """The closure of the first-hit isosurface (other modes: none)."""
        if isinstance(setup, Iso):
            return IsoClosure(setup.params.iso, camera)
        return None

    def plan(self, pieces: Sequence[Any], renderer: Any) -> dict[Hashable, Change]:
        """The changes of every array of the cut whose bricks meet coarser ones."""
        signature = tuple((p.key, tuple(p.box_lo), tuple(p.box_hi)) for p in pieces)
        if self._last is not None and self._last[0] == signature:
            return self._last[1]
        changes = self._plan(pieces, renderer)
        self._last = (signature, changes)
        return changes

    def _plan(self, pieces: Sequence[Any], renderer: Any) -> dict[Hashable, Change]:
        if len({p.level for p in pieces}) < 2:
            return {}
        by_key: dict[Hashable, Any] = {}
        for p in pieces:
            by_key.setdefault(p.key, p)
        levels = np.array([p.level for p in pieces])
        boxes = [renderer.box(p)[:2] for p in pieces]
        box_lo = np.array([b[0] for b in boxes]).reshape(-1, 3)
        box_hi = np.array([b[1] for b in boxes]).reshape(-1, 3)
        changes: dict[Hashable, Change] = {}
        grids: dict[Hashable, Any] = {}
        for key in sorted(by_key, key=lambda k: -by_key[k].level):
            piece = by_key[key]
            array, first = renderer.prepared(piece)
            geometry = renderer.levels[piece.level]
            coarser = np.flatnonzero(levels > piece.level)
            if len(coarser) == 0:
                continue
            # The coarser boxes in this level's index space, and those within reach.
            lo = geometry.from_level0(box_lo[coarser])
            hi = geometry.from_level0(box_hi[coarser])
            w_lo = first.astype(np.float64)
            w_hi = w_lo + np.asarray(array.shape) - 1
            gap = np.maximum(np.maximum(lo - w_hi, w_lo - hi), 0.0).max(axis=1)
            near = gap < self.radius
            if not near.any():
                continue
            order = np.argsort(levels[coarser[near]], kind="stable")  # finest coarser first
            candidates = coarser[near][order]
            lo, hi = lo[near][order], hi[near][order]
            axes = [first[a] + np.arange(array.shape[a], dtype=np.float64) for a in range(3)]
            taken = np.zeros(array.shape, dtype=bool)
            index_parts, value_parts = [], []
            for m, n in enumerate(candidates):
                d = [np.maximum(np.maximum(lo[m, a] - axes[a], axes[a] - hi[m, a]), 0.0)
                     for a in range(3)]
                dist = np.maximum(np.maximum(d[0][:, None, None], d[1][None, :, None]),
                                  d[2][None, None, :])
                new = (dist < self.radius) & ~taken
                if not new.any():
                    continue
                taken |= new
                flat = np.flatnonzero(new)
                where = np.column_stack(np.unravel_index(flat, array.shape)) + first
                source = pieces[int(n)]
                values = self._values(source, where, piece.level, renderer, changes, grids)
                index_parts.append(flat)
                value_parts.append(values)
            if index_parts:
                changes[key] = Change(np.concatenate(index_parts), np.concatenate(value_parts))
        return changes

    def _values(self, source: Any, where: np.ndarray, level: int, renderer: Any,
                changes: dict, grids: dict) -> np.ndarray:
        """The (changed) function of the coarser piece ``source`` at the level-``level``
        indices ``where`` (n, 3), as level-``level`` coefficients."""
        array, first = renderer.prepared(source)
        change = changes.get(source.key)
        if change is not None:
            array = change.apply(array)
        tree = renderer.tree
        if self.degree is not None and _aligned(tree):
            values = _subdivided(array, first, where, source.level, level, tree, self.degree)
            if values is not None:
                return values
        grid = grids.get(source.key)
        if grid is None:
            grid = grids[source.key] = renderer.grid(source.level, array, first)
        fine, coarse = renderer.levels[level], renderer.levels[source.level]
        points = coarse.from_level0((where - fine.offset) / fine.scale) + self.model.shift
        out = np.empty(len(points))
        sample_grid(grid.kernel, np.ascontiguousarray(points - grid.geom[7:10]), out)
        return out


def _aligned(tree: Any) -> bool:
    """Every level's voxels sit on level-0 voxels (``level index = level-0 index / factor``)."""
    for p, level in enumerate(tree.levels):
        scale, offset = tree.level_map(level)
        if np.any(offset != 0) or np.any(scale * tree.factors[p] != 1):
            return False
    return True


def _subdivided(array: np.ndarray, first: np.ndarray, where: np.ndarray, coarse: int, fine: int,
                tree: Any, degree: int) -> np.ndarray | None:
    """Coefficients of the spline ``array`` (level ``coarse``) at level ``fine``'s indices
    ``where`` by repeated subdivision, or ``None`` if ``array`` does not reach far enough."""
    p_fine, p_coarse = tree.position(fine), tree.position(coarse)
    factor = np.asarray(tree.factors[p_coarse]) // np.asarray(tree.factors[p_fine])
    # Only the part of the array the positions need (the masks reach two coarse elements out).
    need_lo = np.floor(where.min(axis=0) / factor).astype(np.int64) - 2 - first
    need_hi = np.ceil(where.max(axis=0) / factor).astype(np.int64) + 3 - first
    need_lo = np.maximum(need_lo, 0)
    need_hi = np.minimum(need_hi, array.shape)
    block = array[tuple(slice(a, b) for a, b in zip(need_lo, need_hi, strict=True))]
    start = first + need_lo
    for p in range(p_coarse, p_fine, -1):
        ratio = np.asarray(tree.factors[p]) // np.asarray(tree.factors[p - 1])
        if min(block.shape) < 3:
            return None
        block, start = refine(block, start, ratio, degree)
    local = where - start
    if np.any(local < 0) or np.any(local >= np.asarray(block.shape)):
        return None
    return block[local[:, 0], local[:, 1], local[:, 2]]


class IsoClosure:
    """Closes the remaining cracks of a first-hit isosurface at level boundaries.

    Kept per frame: for every ray, where it left the last piece it crossed without a hit, the
    field there minus the isovalue, and that piece's level. When the ray enters a piece of
    another level at the same parameter and the field there lies on the other side of the
    isovalue, the ray hits the surface at the face (depth and gradient written into the Iso
    mode's state: ``state[0]`` depth, ``state[1]`` world gradient).
    """

    def __init__(self, iso: float, camera: Any) -> None:
        self.iso = float(iso)
        shape = (camera.height, camera.width)
        self.exit_t = np.full(shape, np.nan)
        self.exit_g = np.full(shape, np.nan)
        self.exit_level = np.full(shape, -1, dtype=np.int64)
        self.hits = 0

    def _values(self, grid: Any, tile: Any, t: np.ndarray,
                want: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        value = np.zeros(t.shape)
        gradient = np.zeros((*t.shape, 3))
        grid_values_at(grid.kernel, grid.geom, tile.pixel_basis(), np.ascontiguousarray(t),
                       want, value, gradient)
        return value, gradient

    @staticmethod
    def _window(array: np.ndarray, rect: tuple[int, int, int, int]) -> np.ndarray:
        c0, r0, w, h = rect
        return array[r0:r0 + h, c0:c0 + w]

    def enter(self, piece: Any, grid: Any, tile: Any, t_range: np.ndarray, state: tuple,
              rect: tuple[int, int, int, int]) -> None:
        """Before tracing ``piece``: a hit on the face where the field jumps across the iso."""
        depth, gradient = state[0], state[1]
        t_in = t_range[..., 0]
        exit_t = self._window(self.exit_t, rect)
        want = ((t_in <= t_range[..., 1]) & np.isinf(depth) & (exit_t == t_in)
                & (self._window(self.exit_level, rect) != piece.level))
        if not want.any():
            return
        value, grad = self._values(grid, tile, t_in, want)
        g = value - self.iso
        before = self._window(self.exit_g, rect)
        jump = want & ((g == 0.0) | ((g < 0.0) != (before < 0.0)))
        depth[jump] = t_in[jump]
        gradient[jump] = grad[jump]
        self.hits += int(jump.sum())

    def leave(self, piece: Any, grid: Any, tile: Any, t_range: np.ndarray, state: tuple,
              rect: tuple[int, int, int, int]) -> None:
        """After tracing ``piece``: where the rays without a hit leave it, and the field there."""
        t_out = t_range[..., 1]
        want = (t_range[..., 0] <= t_out) & np.isinf(state[0])
        if not want.any():
            return
        value, _ = self._values(grid, tile, t_out, want)
        self._window(self.exit_t, rect)[want] = t_out[want]
        self._window(self.exit_g, rect)[want] = value[want] - self.iso
        self._window(self.exit_level, rect)[want] = piece.level
