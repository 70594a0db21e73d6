"""Crack-free level boundaries: bricks of different levels made to agree where they meet.

Two bricks of one level reconstruct the same function (they read the same level), so they meet
without a seam. A brick next to a *coarser* one reconstructs a finer function, and on their
common face the two differ: an isosurface crossing the face has a crack, DVR shows a seam line.
The finer side is therefore changed, never the coarser one:

Restriction (all models)
    Every element ``p`` of a brick's array (level ``b``) that lies within the model's influence
    radius ``r = (support + 1) / 2`` voxels of a coarser drawable of the cut (max-norm distance to
    its box, in level-``b`` voxels) is replaced by the coarser drawable's function expressed at
    level ``b``. Within that radius lie all the elements the finer brick's reconstruction reads
    on the common face (faces, edges and corners alike: trilinear reads the face's own voxels,
    ``r = 1``; cubic B-spline and type-6 one layer more, ``r = 2`` and ``3/2``). When several
    coarser drawables are that close, the finest of them supplies the values; arrays are processed
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
    by the coarse-to-fine order (the finer coarse drawable was itself restricted to the coarsest).

Approximate for ``bspline2``, ``qss`` and ``s31``, and for pyramids offset by half a voxel
    Their coarse function is not in the finer level's space (even-degree knots and type-6 cubes
    lie between voxel centres, so the levels' drawables do not nest). The elements near the face get
    the coarse function's *values* there; the two sides then differ on the face by the fine
    level's approximation error of the smooth coarse function (measured in
    ``tests/test_multires_render.py``), not by the difference between the levels. For the
    isosurface the remaining crack is closed exactly by :class:`IsoClosure`: a ray that leaves
    one level with the field on one side of the isovalue and enters the next level on the other
    side hits the surface on the face between them (a sub-voxel wall instead of a hole). DVR may
    keep a faint seam of that size; several translucent isosurfaces (``iso=[...]``) are not
    closed.

Cost while a cut refines
    Every frame that brings bricks changes the cut, so the plan is redone per frame. It is
    incremental: an array's change is a function of its own contents (its key) and of the coarser
    drawables within its reach, their boxes and their own changes, so it is kept while those are the
    same, and a recomputed change that comes out equal keeps its identity (the finer arrays next
    to it, and the grid the renderer built from it, stay valid). The drawables within reach come
    from a k-d tree per class of box sizes, and nested models subdivide once per source array
    with per-axis matrices. The plan's work is then proportional to the bricks that arrived,
    not to the cut (``benchmarks/tools/bench_stream_frames.py`` times it frame by frame).
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from ...render.rays import GEOM_OFFSET
from .probe import grid_values_at, sample_grid

__all__ = ["Seams", "Change", "IsoClosure", "refine"]


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
        self.degree = model.nested_degree
        #: Elements closer than this (level voxels, max norm) to a coarser drawable are replaced.
        self.radius = (int(model.support) + 1) / 2.0
        self._last: tuple[Any, dict] | None = None
        # Per array key: what its change was computed from (the coarser drawables within reach,
        # with their boxes and the versions of their own changes), the change, and its version.
        # A cut that changes by a few bricks recomputes only the arrays near them.
        self._memo: dict[Hashable, tuple[tuple, Change | None, int]] = {}
        self._version = 0
        #: Arrays whose change was computed (not reused) by the last plan.
        self.recomputed = 0

    def closure(self, setup: Any, camera: Any) -> IsoClosure | None:
        """The closure of the first-hit isosurface (other modes: none)."""
        iso = setup.first_hit_iso()
        return None if iso is None else IsoClosure(iso, camera)

    def plan(self, drawables: Sequence[Any], renderer: Any) -> dict[Hashable, Change]:
        """The changes of every array of the cut whose bricks meet coarser ones."""
        signature = tuple((p.key, tuple(p.box_lo), tuple(p.box_hi)) for p in drawables)
        if self._last is not None and self._last[0] == signature:
            self.recomputed = 0
            return self._last[1]
        changes = self._plan(drawables, renderer)
        self._last = (signature, changes)
        return changes

    def _plan(self, drawables: Sequence[Any], renderer: Any) -> dict[Hashable, Change]:
        self.recomputed = 0
        if len({p.level for p in drawables}) < 2:
            self._memo = {}
            return {}
        by_key: dict[Hashable, Any] = {}
        for p in drawables:
            by_key.setdefault(p.key, p)
        levels = np.array([p.level for p in drawables])
        boxes = [renderer.box(p)[:2] for p in drawables]
        box_lo = np.array([b[0] for b in boxes]).reshape(-1, 3)
        box_hi = np.array([b[1] for b in boxes]).reshape(-1, 3)
        # Every drawable's box in the index space of each level that has arrays (once per level,
        # not once per array: the boxes are compared with every array of that level).
        in_level = {level: (renderer.levels[level].from_level0(box_lo),
                            renderer.levels[level].from_level0(box_hi))
                    for level in {p.level for p in by_key.values()}}
        reach = self._reach(by_key, levels, in_level, renderer)
        aligned = self.degree is not None and _aligned(renderer.tree)
        changes: dict[Hashable, Change] = {}
        versions: dict[Hashable, int] = {}
        memo: dict[Hashable, tuple[tuple, Change | None, int]] = {}
        grids: dict[Hashable, Any] = {}
        arrays: dict[Hashable, tuple[np.ndarray, np.ndarray]] = {}
        for key in sorted(reach, key=lambda k: -by_key[k].level):
            drawable = by_key[key]
            array, first = renderer.prepared(drawable)
            candidates = reach[key]
            lo = in_level[drawable.level][0][candidates]
            hi = in_level[drawable.level][1][candidates]
            depends = (tuple(drawables[int(n)].key for n in candidates), lo.tobytes(),
                       hi.tobytes(), tuple(versions.get(drawables[int(n)].key, 0)
                                           for n in candidates))
            kept = self._memo.get(key)
            if kept is not None and kept[0] == depends:
                memo[key] = kept
                if kept[1] is not None:
                    changes[key], versions[key] = kept[1], kept[2]
                continue
            self.recomputed += 1
            change = self._change(drawables, candidates, lo, hi, array, first, drawable.level,
                                  renderer, changes, arrays, grids, aligned)
            if kept is not None and _same(kept[1], change):
                # The same values again (what changed was too far away to matter): keep the
                # version, so the finer arrays next to this one are not recomputed in turn,
                # and the object, so the renderer keeps the grid it built from it.
                change, version = kept[1], kept[2]
            else:
                self._version += 1
                version = self._version
            memo[key] = (depends, change, version)
            if change is not None:
                changes[key], versions[key] = change, version
        self._memo = memo
        return changes

    def _reach(self, by_key: dict[Hashable, Any], levels: np.ndarray, in_level: dict,
               renderer: Any) -> dict[Hashable, np.ndarray]:
        """For every array that has coarser drawables within the radius of its elements: those
        drawables (indices into the cut), finest level first, then in the cut's order."""
        reach: dict[Hashable, np.ndarray] = {}
        for level in sorted(in_level):
            coarser = np.flatnonzero(levels > level)
            keys = [k for k, p in by_key.items() if p.level == level]
            if len(coarser) == 0 or not keys:
                continue
            firsts, extents = [], []
            for k in keys:
                array, first = renderer.prepared(by_key[k])
                firsts.append(first)
                extents.append(array.shape)
            w_lo = np.array(firsts, dtype=np.float64).reshape(-1, 3)
            w_hi = w_lo + np.array(extents, dtype=np.float64).reshape(-1, 3) - 1
            lo, hi = in_level[level][0][coarser], in_level[level][1][coarser]
            which, near = _within_reach(w_lo, w_hi, lo, hi, self.radius)
            # Finest coarser drawable first, then the cut's order (the order the values are taken
            # in where several coarser drawables are within reach of one element).
            order = np.lexsort((near, levels[coarser[near]], which))
            which, near = which[order], coarser[near[order]]
            bounds = np.flatnonzero(np.diff(which)) + 1
            for group in np.split(np.arange(len(which)), bounds):
                if len(group):
                    reach[keys[int(which[group[0]])]] = near[group]
        return reach

    def _change(self, drawables: Sequence[Any], candidates: np.ndarray, lo: np.ndarray,
                hi: np.ndarray, array: np.ndarray, first: np.ndarray, level: int,
                renderer: Any, changes: dict, arrays: dict, grids: dict,
                aligned: bool) -> Change | None:
        """The change of one array (level ``level``, first index ``first``) from the coarser
        drawables ``candidates`` (finest first) whose boxes in this level's index space are
        ``lo``, ``hi``."""
        shape = np.asarray(array.shape)
        taken = np.zeros(array.shape, dtype=bool)
        regions = []  # (candidate, start, stop, new elements of the region, flat indices)
        for m, n in enumerate(candidates):
            # The elements closer than the radius (max norm) to the box form a box themselves:
            # index i with lo - r < first + i < hi + r on every axis.
            start = np.clip(np.floor(lo[m] - self.radius - first).astype(np.int64) + 1, 0, shape)
            stop = np.clip(np.ceil(hi[m] + self.radius - first).astype(np.int64), 0, shape)
            if np.any(stop <= start):
                continue
            region = tuple(slice(a, b) for a, b in zip(start, stop, strict=True))
            new = ~taken[region]
            if not new.any():
                continue
            taken[region] = True
            local = np.nonzero(new)
            flat = np.ravel_multi_index(tuple(i + a for i, a in zip(local, start, strict=True)),
                                        array.shape)
            regions.append((int(n), start, stop, new, local, flat))
        if not regions:
            return None
        # One subdivision per source array over the box around all its regions (a cut's
        # substituted bricks share their ancestor's array: many regions, one source).
        boxes: dict[Hashable, tuple[np.ndarray, np.ndarray, np.ndarray | None]] = {}
        if aligned:
            for n, start, stop, _, _, _ in regions:
                key = drawables[n].key
                lo_, hi_ = boxes.get(key, (start, stop, None))[:2]
                boxes[key] = (np.minimum(lo_, start), np.maximum(hi_, stop), None)
            for key, (lo_, hi_, _) in boxes.items():
                source = next(drawables[n] for n, *_ in regions if drawables[n].key == key)
                src, src_first = self._source(source, renderer, changes, arrays)
                boxes[key] = (lo_, hi_, _subdivided(src, src_first, first + lo_, first + hi_ - 1,
                                                    source.level, level, renderer.tree,
                                                    self.degree))
        value_parts = []
        for n, start, stop, new, local, _ in regions:
            source = drawables[n]
            values = None
            if aligned:
                lo_, _, box = boxes[source.key]
                if box is None:  # the union does not fit: this region alone may
                    src, src_first = self._source(source, renderer, changes, arrays)
                    box, lo_ = _subdivided(src, src_first, first + start, first + stop - 1,
                                           source.level, level, renderer.tree,
                                           self.degree), start
                if box is not None:
                    at = start - lo_
                    values = box[tuple(slice(a, a + b - c) for a, b, c in
                                       zip(at, stop, start, strict=True))][new]
            if values is None:
                where = np.column_stack(local) + start + first
                values = self._values(source, where, level, renderer, changes, arrays, grids,
                                      aligned)
            value_parts.append(values)
        return Change(np.concatenate([r[5] for r in regions]), np.concatenate(value_parts))

    @staticmethod
    def _source(source: Any, renderer: Any, changes: dict,
                arrays: dict) -> tuple[np.ndarray, np.ndarray]:
        """A coarser drawable's array with its own change applied (once per plan), and its first
        index."""
        kept = arrays.get(source.key)
        if kept is None:
            array, first = renderer.prepared(source)
            change = changes.get(source.key)
            if change is not None:
                array = change.apply(array)
            kept = arrays[source.key] = (array, first)
        return kept

    def _values(self, source: Any, where: np.ndarray, level: int, renderer: Any,
                changes: dict, arrays: dict, grids: dict, aligned: bool) -> np.ndarray:
        """The (changed) function of the coarser drawable ``source`` at the level-``level``
        indices ``where`` (n, 3), as level-``level`` coefficients."""
        array, first = self._source(source, renderer, changes, arrays)
        if aligned:
            lo, hi = where.min(axis=0), where.max(axis=0)
            box = _subdivided(array, first, lo, hi, source.level, level, renderer.tree,
                              self.degree)
            if box is not None:
                local = where - lo
                return box[local[:, 0], local[:, 1], local[:, 2]]
        grid = grids.get(source.key)
        if grid is None:
            grid = grids[source.key] = renderer.grid(source.level, array, first)
        fine, coarse = renderer.levels[level], renderer.levels[source.level]
        points = coarse.from_level0((where - fine.offset) / fine.scale) + self.model.shift
        out = np.empty(len(points))
        offset = grid.geom[GEOM_OFFSET:GEOM_OFFSET + 3]
        sample_grid(grid.kernel, np.ascontiguousarray(points - offset), out)
        return out


def _same(a: Change | None, b: Change | None) -> bool:
    """Two plans' changes of one array replace the same elements by the same values."""
    if a is None or b is None:
        return a is b
    return np.array_equal(a.index, b.index) and np.array_equal(a.values, b.values)


def _within_reach(q_lo: np.ndarray, q_hi: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                  radius: float) -> tuple[np.ndarray, np.ndarray]:
    """The pairs ``(query, box)`` of query boxes ``q_lo .. q_hi`` (m, 3) and boxes ``lo .. hi``
    (n, 3) closer than ``radius`` in the max norm (the gap between the boxes).

    A k-d tree of the box centres (scipy) finds the candidates, per class of box sizes so that
    the search radius stays tight (a cut's boxes span many sizes); the exact gap then decides.
    A loop over the queries comparing each with every box cost a quadratic time in a cut of
    20 000 bricks."""
    from scipy.spatial import cKDTree

    centre, half = (lo + hi) / 2.0, (hi - lo) / 2.0
    q_centre, q_half = (q_lo + q_hi) / 2.0, (q_hi - q_lo) / 2.0
    size_class = np.floor(np.log2(np.maximum(half.max(axis=1), 0.5))).astype(np.int64)
    which_parts, box_parts = [], []
    for cls in np.unique(size_class):
        members = np.flatnonzero(size_class == cls)
        tree = cKDTree(centre[members])
        search = half[members].max() + q_half.max(axis=1) + radius + 1e-9
        found = tree.query_ball_point(q_centre, search, p=np.inf)
        counts = np.fromiter((len(f) for f in found), dtype=np.int64, count=len(found))
        if counts.sum() == 0:
            continue
        which_parts.append(np.repeat(np.arange(len(found)), counts))
        box_parts.append(members[np.concatenate([np.asarray(f, dtype=np.int64)
                                                 for f in found])])
    if not which_parts:
        return np.empty(0, dtype=np.int64), np.empty(0, dtype=np.int64)
    which, box = np.concatenate(which_parts), np.concatenate(box_parts)
    gap = np.maximum(np.maximum(lo[box] - q_hi[which], q_lo[which] - hi[box]), 0.0).max(axis=1)
    keep = gap < radius
    return which[keep], box[keep]


def _aligned(tree: Any) -> bool:
    """Every level's voxels sit on level-0 voxels (``level index = level-0 index / factor``)."""
    for p, level in enumerate(tree.levels):
        scale, offset = tree.level_map(level)
        if np.any(offset != 0) or np.any(scale * tree.factors[p] != 1):
            return False
    return True


def _subdivided(array: np.ndarray, first: np.ndarray, box_lo: np.ndarray, box_hi: np.ndarray,
                coarse: int, fine: int, tree: Any, degree: int) -> np.ndarray | None:
    """Coefficients of the spline ``array`` (level ``coarse``) on level ``fine``'s index box
    ``box_lo .. box_hi`` (inclusive) by repeated subdivision, or ``None`` if ``array`` does not
    reach far enough.

    Subdivision is separable and linear, so the levels' steps along one axis compose into one
    matrix (:func:`_subdivision_matrix`, cached: it depends only on the block's length and the
    ratios); the block of coarse coefficients the box needs is then mapped by three matrix
    products instead of a chain of 3D refinements (a refinement per level and axis cost more in
    Python than in arithmetic)."""
    p_fine, p_coarse = tree.position(fine), tree.position(coarse)
    factor = np.asarray(tree.factors[p_coarse]) // np.asarray(tree.factors[p_fine])
    # Only the part of the array the box needs (the masks reach two coarse elements out).
    need_lo = np.floor(np.asarray(box_lo) / factor).astype(np.int64) - 2 - first
    need_hi = np.ceil(np.asarray(box_hi) / factor).astype(np.int64) + 3 - first
    need_lo = np.maximum(need_lo, 0)
    need_hi = np.minimum(need_hi, array.shape)
    block = array[tuple(slice(a, b) for a, b in zip(need_lo, need_hi, strict=True))]
    fine_start = first + need_lo
    ratios = [np.asarray(tree.factors[p]) // np.asarray(tree.factors[p - 1])
              for p in range(p_coarse, p_fine, -1)]
    # Each step needs at least three elements on every axis (as a 3D refinement would).
    length = np.asarray(block.shape)
    for ratio in ratios:
        if length.min() < 3:
            return None
        length = np.where(ratio == 2, 2 * length - (1 if degree == 1 else 3), length)
    rows = []
    for axis in range(3):
        chain = tuple(int(r[axis]) for r in ratios)
        for r in chain:
            if r == 2:
                fine_start[axis] = 2 * fine_start[axis] + (0 if degree == 1 else 1)
        lo = int(box_lo[axis] - fine_start[axis])
        hi = int(box_hi[axis] - fine_start[axis]) + 1
        if lo < 0 or hi > length[axis]:
            return None
        rows.append(_subdivision_matrix(block.shape[axis], chain, degree)[lo:hi])
    out = np.tensordot(rows[0], np.asarray(block, dtype=np.float64), axes=(1, 0))
    out = np.tensordot(out, rows[1], axes=(1, 1))  # (fx, nz, fy)
    return np.tensordot(out, rows[2], axes=(1, 1))  # (fx, fy, fz)


@lru_cache(maxsize=4096)
def _subdivision_matrix(length: int, chain: tuple[int, ...], degree: int) -> np.ndarray:
    """The matrix taking ``length`` coefficients along one axis through the subdivision steps
    ``chain`` (ratio 2: one :func:`refine` step; 1: unchanged) to the finest level's."""
    matrix = np.eye(length)
    for ratio in chain:
        if ratio == 2:
            matrix, _ = refine(matrix[:, :, None], np.zeros(3, dtype=np.int64),
                               np.array([2, 1, 1]), degree)
            matrix = matrix[:, :, 0]
    matrix.setflags(write=False)
    return matrix


class IsoClosure:
    """Closes the remaining cracks of a first-hit isosurface at level boundaries.

    Kept per frame: for every ray, where it left the last drawable it crossed without a hit, the
    field there minus the isovalue, and that drawable's level. When the ray enters a drawable of
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

    def enter(self, drawable: Any, grid: Any, tile: Any, t_range: np.ndarray, state: tuple,
              rect: tuple[int, int, int, int]) -> None:
        """Before tracing ``drawable``: a hit on the face where the field jumps across the iso."""
        depth, gradient = state[0], state[1]
        t_in = t_range[..., 0]
        exit_t = self._window(self.exit_t, rect)
        want = ((t_in <= t_range[..., 1]) & np.isinf(depth) & (exit_t == t_in)
                & (self._window(self.exit_level, rect) != drawable.level))
        if not want.any():
            return
        value, grad = self._values(grid, tile, t_in, want)
        g = value - self.iso
        before = self._window(self.exit_g, rect)
        jump = want & ((g == 0.0) | ((g < 0.0) != (before < 0.0)))
        depth[jump] = t_in[jump]
        gradient[jump] = grad[jump]
        self.hits += int(jump.sum())

    def leave(self, drawable: Any, grid: Any, tile: Any, t_range: np.ndarray, state: tuple,
              rect: tuple[int, int, int, int]) -> None:
        """After tracing ``drawable``: where the rays without a hit leave it, and the field
        there."""
        t_out = t_range[..., 1]
        want = (t_range[..., 0] <= t_out) & np.isinf(state[0])
        if not want.any():
            return
        value, _ = self._values(grid, tile, t_out, want)
        self._window(self.exit_t, rect)[want] = t_out[want]
        self._window(self.exit_g, rect)[want] = value[want] - self.iso
        self._window(self.exit_level, rect)[want] = drawable.level
