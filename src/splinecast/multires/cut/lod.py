"""Level of detail by projected voxel size: the cut for a camera, and the bricks to load for it.

A brick is refined (replaced by its children) while one of its voxels covers more than ``lod``
pixels on screen, as seen from the camera:

    pixels = voxel size / (distance * pixel angle)        (perspective)
    pixels = voxel size / (window height / image height)  (orthographic)

with the voxel size the largest world size of the level's voxels and the distance the Euclidean
distance from the eye to the brick's box (0 inside: always refined), as in Steinberger 2010's
"collapse when diameter / distance < epsilon". Bricks outside the camera's view (a tile's view
for :meth:`Camera.tile <splinecast.camera.Camera.tile>` cameras) and bricks whose value range
cannot contribute (:class:`.cut.relevance.ValueFilter`) are left out and never refined.

Budget: a child is never coarser on screen than its parent, so refining every brick above a
threshold gives the same cut as refining greedily in order of projected size. When the ideal cut
does not fit ``budget`` bytes, refinements are taken in that order (largest voxels on screen
first) while they fit: the cut is then the best the memory allows at a coarser effective ``lod``.

Load order (``Cut.requests``): the cut's bricks that are not resident, and their ancestors that
are not resident either, coarse levels first: the first frames then sharpen everywhere at once
instead of finishing one region at a time. Within a level, the policy's priority (largest on
screen first) orders them; a frame then puts the bricks nearest the centre of the screen first
(:func:`centre_first`), where the eye looks, as Neuroglancer does: over a slow connection the
middle of the picture sharpens first.
``Cut.prefetch`` lists the children of the bricks closest to being refined, for the loader to read
when it is idle.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ...camera import (
    BASIS_COL0,
    BASIS_EYE,
    BASIS_FORWARD,
    BASIS_FULL_HEIGHT,
    BASIS_FULL_WIDTH,
    BASIS_HALF_HEIGHT,
    BASIS_HALF_WIDTH,
    BASIS_ORTHO,
    BASIS_RIGHT,
    BASIS_ROW0,
    BASIS_UP,
    Camera,
)
from ...errors import ParameterError
from .octree import BrickOctree
from .relevance import ValueFilter

__all__ = ["Cut", "select_cut", "cut_of_keys", "centre_first", "projected_voxels",
           "view_planes"]

Key = tuple[int, int, int, int]


@dataclass
class Cut:
    """The bricks to render for one view, with what to load for them.

    Attributes
    ----------
    keys : ndarray (n, 4) int64
        ``(level, i, j, k)`` of each brick of the cut.
    priority : ndarray (n,)
        Pixels covered by one of the brick's voxels.
    box_lo, box_hi : ndarray (n, 3)
        Level-0 index boxes (what to render of each brick; they tile the visible, contributing
        part of the volume without overlap).
    world_lo, world_hi : ndarray (n, 3)
        The same boxes in world coordinates.
    level_lo, level_hi : ndarray (n, 3)
        The same boxes in the index space of each brick's own level.
    nbytes : int
        Bytes of the cut's bricks.
    requests : list of key
        Bricks to read, in order (see the module docstring).
    prefetch : list of key
        Bricks to read when idle, in order.
    keep : set of key
        The cut and its ancestors: what the cache must not evict for this view.
    limited : bool
        The budget stopped refinement before ``lod`` was reached.
    """

    keys: np.ndarray
    priority: np.ndarray
    box_lo: np.ndarray
    box_hi: np.ndarray
    world_lo: np.ndarray
    world_hi: np.ndarray
    level_lo: np.ndarray
    level_hi: np.ndarray
    nbytes: int
    requests: list[Key] = field(default_factory=list)
    prefetch: list[Key] = field(default_factory=list)
    keep: set[Key] = field(default_factory=set)
    limited: bool = False

    def __len__(self) -> int:
        return len(self.keys)

    def key(self, n: int) -> Key:
        """Key of the ``n``-th brick as a tuple of ints."""
        return tuple(int(v) for v in self.keys[n])  # type: ignore[return-value]

    def levels(self) -> dict[int, int]:
        """Number of bricks per level."""
        levels, counts = np.unique(self.keys[:, 0], return_counts=True)
        return {int(a): int(b) for a, b in zip(levels, counts, strict=True)}


def _window(camera: Camera) -> tuple[np.ndarray, float, float, float, float, bool]:
    basis = camera.pixel_basis()
    half_w, half_h = basis[BASIS_HALF_WIDTH], basis[BASIS_HALF_HEIGHT]
    ortho = basis[BASIS_ORTHO] > 0.5
    col0, row0 = basis[BASIS_COL0], basis[BASIS_ROW0]
    full_w, full_h = basis[BASIS_FULL_WIDTH], basis[BASIS_FULL_HEIGHT]
    sx0 = (col0 / full_w * 2 - 1) * half_w
    sx1 = ((col0 + camera.width) / full_w * 2 - 1) * half_w
    sy1 = (1 - row0 / full_h * 2) * half_h
    sy0 = (1 - (row0 + camera.height) / full_h * 2) * half_h
    return basis, sx0, sx1, sy0, sy1, bool(ortho)


def view_planes(camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """Half-spaces ``n . p + d >= 0`` (normals (5, 3), offsets (5,)) bounding what the camera
    (or tile) sees: four sides and the eye plane."""
    basis, sx0, sx1, sy0, sy1, ortho = _window(camera)
    eye, f = basis[BASIS_EYE:BASIS_EYE + 3], basis[BASIS_FORWARD:BASIS_FORWARD + 3]
    r, u = basis[BASIS_RIGHT:BASIS_RIGHT + 3], basis[BASIS_UP:BASIS_UP + 3]
    if ortho:
        normals = np.array([r, -r, u, -u, f])
        offsets = np.array([-sx0, sx1, -sy0, sy1, 0.0]) + np.array(
            [-(r @ eye), r @ eye, -(u @ eye), u @ eye, -(f @ eye)])
    else:
        normals = np.array([r - sx0 * f, sx1 * f - r, u - sy0 * f, sy1 * f - u, f])
        offsets = -(normals @ eye)
    return normals, offsets


def _visible(lo: np.ndarray, hi: np.ndarray, planes: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """Boxes (n, 3) not entirely outside one of the planes (conservative)."""
    normals, offsets = planes
    # The corner farthest along each plane's normal decides.
    corner = np.where(normals[None, :, :] > 0, hi[:, None, :], lo[:, None, :])
    return np.all(np.einsum("npk,pk->np", corner, normals) + offsets >= -1e-9, axis=1)


def projected_voxels(octree: BrickOctree, level: int, world_lo: np.ndarray, world_hi: np.ndarray,
                     camera: Camera) -> np.ndarray:
    """Pixels covered by one voxel of ``level`` in each box (n, 3), seen from ``camera``."""
    basis, _, _, _, _, ortho = _window(camera)
    half_h, full_h = basis[BASIS_HALF_HEIGHT], basis[BASIS_FULL_HEIGHT]
    pixel = 2.0 * half_h / full_h  # world size of a pixel at unit distance (or anywhere, ortho)
    voxel = octree.voxel_size(level)
    if ortho:
        return np.full(len(world_lo), voxel / pixel)
    eye = basis[BASIS_EYE:BASIS_EYE + 3]
    nearest = np.clip(eye, world_lo, world_hi)
    distance = np.linalg.norm(nearest - eye, axis=1)
    with np.errstate(divide="ignore"):
        return np.where(distance > 0, voxel / (np.maximum(distance, 1e-300) * pixel), np.inf)


@dataclass
class _Level:
    level: int
    index: np.ndarray  # (n, 3)
    parent: np.ndarray  # (n,) position in the previous (coarser) _Level, -1 for roots
    priority: np.ndarray
    nbytes: np.ndarray
    own: np.ndarray  # own range contributes
    split: np.ndarray | None = None


def select_cut(
    octree: BrickOctree,
    camera: Camera,
    lod: float = 1.0,
    budget: int | None = None,
    value_filter: ValueFilter | None = None,
    resident: Callable[[Key], bool] | None = None,
    prefetch: int = 64,
) -> Cut:
    """Choose the bricks to render for ``camera``.

    Parameters
    ----------
    octree : BrickOctree
    camera : Camera
    lod : float
        Refine while a voxel covers more than this many pixels (1: about one voxel per pixel;
        2: half the resolution, a quarter of the bricks).
    budget : int, optional
        Bytes the cut's bricks may take (see the module docstring).
    value_filter : ValueFilter, optional
        Which value ranges can contribute (default: all).
    resident : callable, optional
        ``resident(key)`` tells which bricks the cache holds (for ``requests``).
    prefetch : int
        At most this many bricks in ``Cut.prefetch``.
    """
    if not (isinstance(lod, (int, float)) and math.isfinite(lod) and lod > 0):
        raise ParameterError(f"lod must be a positive number of pixels, got {lod!r}")
    value_filter = value_filter or ValueFilter()
    resident = resident or (lambda key: False)
    planes = view_planes(camera)

    def make(level: int, index: np.ndarray, parent: np.ndarray) -> _Level:
        p = octree.position(level)
        sub = octree.subtree[p][index[:, 0], index[:, 1], index[:, 2]]
        lo, hi = octree.world_box(level, index)
        keep = value_filter.contributes(sub[:, 0], sub[:, 1]) & _visible(lo, hi, planes)
        index, parent, lo, hi = index[keep], parent[keep], lo[keep], hi[keep]
        own = octree.ranges[p][index[:, 0], index[:, 1], index[:, 2]]
        shows = value_filter.contributes(own[:, 0], own[:, 1])
        # A brick whose own voxels cannot contribute is not read: it costs nothing in the cut.
        return _Level(level, index, parent, projected_voxels(octree, level, lo, hi, camera),
                      octree.brick_bytes(level, index) * shows, shows)

    # Walk down from the roots, refining everything above the threshold (the ideal cut).
    levels = [make(octree.coarsest, octree.roots(), np.full(len(octree.roots()), -1))]
    for p in range(octree.n_levels - 1, 0, -1):
        cur = levels[-1]
        cur.split = cur.priority > lod
        parents = np.flatnonzero(cur.split)
        counts = octree.child_counts(cur.level, cur.index[parents])
        kids = octree.children(cur.level, cur.index[parents])
        levels.append(make(octree.levels[p - 1], kids, np.repeat(parents, counts)))
    levels[-1].split = np.zeros(len(levels[-1].index), dtype=bool)

    limited = False
    if budget is not None:
        limited = _fit_budget(levels, int(budget))
    return _assemble(octree, levels, value_filter, resident, prefetch, lod, limited)


def _fit_budget(levels: list[_Level], budget: int) -> bool:
    """Undo the refinements that do not fit, largest projected size first kept; True if any."""
    def cut_bytes() -> int:
        total = 0
        for n, lv in enumerate(levels):
            alive = _alive(levels, n)
            total += int(lv.nbytes[alive & ~lv.split].sum())
        return total

    if cut_bytes() <= budget:
        return False
    # Each split's cost: its children's bytes minus its own (children filtered as in the walk).
    events = []
    for n, lv in enumerate(levels[:-1]):
        child = levels[n + 1]
        extra = np.bincount(child.parent, weights=child.nbytes, minlength=len(lv.index))
        for pos in np.flatnonzero(lv.split):
            events.append((-lv.priority[pos], -lv.level, n, pos, extra[pos] - lv.nbytes[pos]))
    events.sort()
    for lv in levels:
        lv.split = np.zeros(len(lv.index), dtype=bool)
    total = int(levels[0].nbytes.sum())
    for _, _, n, pos, cost in events:
        parent = levels[n].parent[pos]
        if n > 0 and not levels[n - 1].split[parent]:
            continue  # its parent stayed whole
        if total + cost <= budget:
            levels[n].split[pos] = True
            total += int(cost)
    return True


def _alive(levels: list[_Level], n: int) -> np.ndarray:
    """Which entries of level ``n`` are reached (every ancestor split)."""
    if n == 0:
        return np.ones(len(levels[0].index), dtype=bool)
    above = _alive(levels, n - 1) & levels[n - 1].split
    return above[levels[n].parent] if len(levels[n].parent) else np.zeros(0, dtype=bool)


def cut_of_keys(octree: BrickOctree, key_arr: np.ndarray, priority: np.ndarray,
                value_filter: ValueFilter | None = None,
                resident: Callable[[Key], bool] | None = None, limited: bool = False) -> Cut:
    """The :class:`Cut` of given bricks: boxes, bytes, what to keep and what to read.

    Shared by every cut policy (the level of detail here, the error metric of
    :mod:`.cut.policy`). ``Cut.requests`` lists the bricks and their non-resident contributing
    ancestors, coarse levels first and, within a level, highest ``priority`` first;
    ``Cut.prefetch`` is left empty for the policy to fill.

    Parameters
    ----------
    octree : BrickOctree
    key_arr : ndarray (n, 4) int64
        ``(level, i, j, k)`` of each brick; their boxes must not overlap.
    priority : ndarray (n,)
        The policy's priority of each brick (request order within a level).
    value_filter : ValueFilter, optional
        Which ancestors are worth reading for a substitution (default: all).
    resident : callable, optional
        ``resident(key)``: what the cache holds.
    limited : bool
        The budget stopped refinement (reported as ``Cut.limited``).
    """
    value_filter = value_filter or ValueFilter()
    resident = resident or (lambda key: False)
    key_arr = np.asarray(key_arr, np.int64).reshape(-1, 4)
    priority = np.asarray(priority, np.float64).reshape(-1)
    box_lo, box_hi = np.zeros((len(key_arr), 3)), np.zeros((len(key_arr), 3))
    level_lo, level_hi = np.zeros((len(key_arr), 3)), np.zeros((len(key_arr), 3))
    nbytes = 0
    for level in np.unique(key_arr[:, 0]):
        rows = key_arr[:, 0] == level
        box_lo[rows], box_hi[rows] = octree.box(int(level), key_arr[rows, 1:])
        scale, offset = octree.level_map(int(level))
        level_lo[rows] = box_lo[rows] * scale + offset
        level_hi[rows] = box_hi[rows] * scale + offset
        nbytes += int(octree.brick_bytes(int(level), key_arr[rows, 1:]).sum())
    volume = octree.volume
    cut = Cut(key_arr, priority, box_lo, box_hi, volume.index_to_world(box_lo),
              volume.index_to_world(box_hi), level_lo, level_hi, nbytes, limited=limited)

    cut.keep, want = _chains(octree, key_arr, priority, value_filter, resident)
    cut.requests = sorted(want, key=lambda k: (-k[0], -want[k]))
    return cut


def _chains(octree: BrickOctree, key_arr: np.ndarray, priority: np.ndarray,
            value_filter: ValueFilter, resident: Callable[[Key], bool]
            ) -> tuple[set[Key], dict[Key, float]]:
    """What the cache must keep and what to read with its priority: along each brick's chain
    of ancestors up to the first resident one (or the coarsest level), the brick itself and the
    ancestors (kept all, read those that can contribute, at the highest priority of the bricks
    below them).

    Level by level, finest first, with the chains that meet at a brick merged (from there up
    they are the same chain; it goes on reading if any of them does): a cut of a 2048^3 pyramid
    under a 1 GiB budget holds 20 000 bricks, and one loop over them in Python took most of two
    seconds per frame.
    """
    keep: set[Key] = set()
    want: dict[Key, float] = {}
    up_index = np.zeros((0, 3), np.int64)  # ancestors carried up from the level below
    up_priority = np.zeros(0)
    up_active = np.zeros(0, bool)
    for p, level in enumerate(octree.levels):
        rows = key_arr[:, 0] == level
        index = np.concatenate([key_arr[rows, 1:], up_index])
        if not len(index):
            continue
        prio = np.concatenate([priority[rows], up_priority])
        active = np.concatenate([np.ones(int(rows.sum()), bool), up_active])
        own = np.concatenate([np.ones(int(rows.sum()), bool), np.zeros(len(up_index), bool)])
        unique, inverse = np.unique(index, axis=0, return_inverse=True)
        inverse = inverse.reshape(-1)
        m = len(unique)
        is_active = np.zeros(m, bool)
        np.logical_or.at(is_active, inverse, active)
        is_own = np.zeros(m, bool)
        np.logical_or.at(is_own, inverse, own)
        best = np.full(m, -np.inf)
        np.maximum.at(best, inverse[active], prio[active])
        keys = [(int(level), i, j, k) for i, j, k in unique.tolist()]
        # Kept: the cut's bricks and the chains above the missing ones up to their first
        # resident ancestor (what a frame may draw). Keeping every ancestor of the cut made the
        # kept set outgrow the budget under small budgets, and the cut's last brick never fit.
        keep.update(keys[u] for u in np.flatnonzero(is_active))
        if level == octree.coarsest:
            break  # always resident: nothing above is read
        ranges = octree.ranges[p][unique[:, 0], unique[:, 1], unique[:, 2]]
        shows = is_own | value_filter.contributes(ranges[:, 0], ranges[:, 1])
        goes_on = is_active.copy()
        for u in np.flatnonzero(is_active):
            if resident(keys[u]):
                goes_on[u] = False  # what lies above a resident brick is not needed
            elif shows[u]:
                want[keys[u]] = float(best[u])
        ratio = octree.factors[p + 1] // octree.factors[p]
        up_index = unique // ratio
        up_priority = best
        up_active = goes_on
    return keep, want


def _assemble(octree: BrickOctree, levels: list[_Level], value_filter: ValueFilter,
              resident: Callable[[Key], bool], prefetch: int, lod: float,
              limited: bool) -> Cut:
    keys, prio = [], []
    alive = [_alive(levels, n) for n in range(len(levels))]
    for n, lv in enumerate(levels):
        take = alive[n] & ~lv.split & lv.own
        idx = lv.index[take]
        keys.append(np.column_stack([np.full(len(idx), lv.level), idx]))
        prio.append(lv.priority[take])
    key_arr = np.concatenate(keys).astype(np.int64) if keys else np.zeros((0, 4), np.int64)
    priority = np.concatenate(prio) if prio else np.zeros(0)
    cut = cut_of_keys(octree, key_arr, priority, value_filter, resident, limited)
    want = set(cut.requests)

    # Prefetch: the contributing children of the cut's bricks nearest to being refined.
    # Resident ones stay in the list, so that it stays the same while the view does (the
    # cache reads what is missing of it; a list of only missing bricks moved on to the next
    # ones as soon as the first were read, and evicted them for those).
    order = np.argsort(-cut.priority, kind="stable")
    extra: list[Key] = []
    for n in order:
        if len(extra) >= prefetch or cut.priority[n] <= lod / 2:
            break
        level = int(cut.keys[n, 0])
        if level == octree.levels[0]:
            continue
        p = octree.position(level) - 1
        finer = octree.levels[p]
        kids = octree.children(level, cut.keys[n, 1:][None])
        ranges = octree.ranges[p][tuple(kids.T)]
        for idx in kids[value_filter.contributes(ranges[:, 0], ranges[:, 1])]:
            key = (finer, int(idx[0]), int(idx[1]), int(idx[2]))
            if key not in want:
                extra.append(key)
    cut.prefetch = extra[:prefetch]
    return cut


def centre_first(requests: list[Key], octree: BrickOctree, camera: Camera) -> list[Key]:
    """``requests`` with coarse levels first and, within a level, the bricks whose centre lies
    nearest the middle of ``camera``'s image first.

    Nearness is the angle between the view direction and the direction from the eye to the
    brick's centre (perspective), or the distance of the centre from the view axis
    (orthographic); bricks equally near keep their order in ``requests``.
    """
    if not requests:
        return []
    keys = np.asarray(requests, np.int64).reshape(-1, 4)
    away = np.zeros(len(keys))
    for level in np.unique(keys[:, 0]):
        rows = keys[:, 0] == level
        lo, hi = octree.world_box(int(level), keys[rows, 1:])
        v = 0.5 * (lo + hi) - camera.position
        along = v @ camera.forward
        aside = np.linalg.norm(v - along[:, None] * camera.forward, axis=1)
        away[rows] = aside if camera.ortho else np.arctan2(aside, along)
    order = np.lexsort((np.arange(len(keys)), away, -keys[:, 0]))
    return [requests[i] for i in order]

