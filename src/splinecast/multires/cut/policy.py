"""The error-metric cut of Carmona & Froehlich 2011 as the cut policy of a multiscale scene.

``Scene(pyramid, cut="error")`` draws, in DVR and MIP/minIP, the cut that
:class:`~.cut.update.CutUpdater` keeps up to date frame after frame (transfer-function distortion
times importance, greedy split-and-collapse under a brick budget N and a load budget M) instead of
the screen-space level-of-detail cut of :mod:`.cut.lod`. This module only connects the parts:

1. :func:`octree_tree`: the :class:`~.cut.tree.BrickTree` of a store's
   :class:`~.cut.octree.BrickOctree` (node ids level by level, finest first, C order of the brick
   grid
   within a level; a store whose coarsest level has several bricks gets a *virtual root* above
   them, never part of a cut) and the key ``(level, i, j, k)`` of every node;
2. :func:`octree_histograms`: the sparse (source value, approximation) histograms of every brick
   (:mod:`.cut.histograms`). A brick of ``B`` cells on a level with factor ``f`` owns the source
   voxels ``[b B f, (b + 1) B f)`` per axis (the last brick of an axis up to the volume's end), so
   the children of a brick own exactly its voxels; its approximation is the edge-clamped trilinear
   reconstruction of its level at the source voxel centres, through the level's own index map
   (:meth:`~.cut.octree.BrickOctree.level_map`: the vertex-centred binomial pyramid of
   :mod:`~splinecast.multires.store.pyramid` or another store's translation);
3. :class:`ErrorCut`: per frame, the metric's view (eye = the camera position, the optional point of
   interest) and transfer function are set (a new transfer function recomputes the hull's D from the
   histograms and repairs the cut), the updater makes one step, and the new cut becomes a
   :class:`~.cut.lod.Cut` for the :class:`~.cut.stream.BrickStream` -- whose cache, loader thread
   and
   substitution of missing bricks by resident ancestors are the same for both policies.

Choices
-------
* **Which bricks can be seen** comes from the renderer's :class:`~.cut.relevance.ValueFilter` (the
  transfer function's visible ranges, widened for the type-6 models) applied to the tree's
  hierarchical value ranges, so both policies leave out exactly the same transparent bricks; the
  transfer function itself gives the colours of eq. (2). MIP and minIP classify with their
  window and colormap at full opacity (every brick is visible).
* **N** is the cut's share of the byte budget divided by the bytes of a full brick (border bricks
  are smaller, so the cut's bytes stay within the share); at least the coarsest level's bricks.
  **M** is the scene's ``load_budget``, the same number of bricks the cache waits for per frame,
  but at least 8 (a split of an octree node needs up to 8 bricks: with less, a cut could never
  refine). A brick counts against M only if the cache does not hold it: before each update the
  updater's residency is the cache's (prefetched bricks are free), not the previous cut.
* **Fill**: a split that does not fit N or M is set aside and the next one tried
  (``CutUpdater(fill=True)``), so a small budget is used up by smaller splits (borders,
  transparent children) instead of being left unused behind a full octree split; the cut settles
  close to the greedy cut with ``fill=True``, which ``benchmarks/bench_cut.py`` compares with
  the optimum.
* **Prefetch** (what the loader reads when idle): the visible children of the cut's bricks of
  highest split priority, i.e. the next splits of the split queue S in order (the head of the
  extended cut S+ of section 4).
* **Histograms** come from the pyramid's ``hist2d`` group when it has one
  (:mod:`.store.hist_store`, written by ``build_pyramid(..., histograms=True)``): opening reads no
  level and a transfer-function edit no voxel. A store without it (or whose group does not fit
  the octree or is damaged: one warning says which) gets them built here from every level read
  whole, which bounds ``cut="error"`` on such stores to volumes whose levels fit in memory once.
* **Frustum culling**: a brick more than one finest brick's diagonal outside the camera's view
  frustum has importance 0 (:func:`~.cut.metric.frustum_planes`), so it is never split; the cut
  still covers it once. The margin keeps the finest neighbours of a brick in view refined with
  it, so no seam between levels touches a visible brick: at full budget the image is the finest
  level's.
* The isosurface modes keep the level-of-detail cut: D(b) measures classified colour, which an
  isosurface does not show (its error is geometric: the screen-space voxel size bounds it).
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

from ...camera import Camera
from ...errors import ParameterError, ReadError
from ...transfer import TransferFunction
from ..store.hist_store import HIST2D, read_histograms
from .histograms import (
    DEFAULT_BINS,
    BrickHistograms,
    Quantizer,
    box_histograms,
    stack_histograms,
)
from .lod import Cut, Key, cut_of_keys
from .metric import CutMetric, cut_error, frustum_planes
from .octree import BrickOctree
from .relevance import ValueFilter
from .tree import BrickTree
from .update import CutUpdate, CutUpdater

__all__ = ["CUT_POLICIES", "CUT_PRIORITIES", "check_cut", "octree_tree", "octree_histograms",
           "ErrorCut"]

#: Cut policies of a multiscale scene: screen-space level of detail, or the 002 error metric.
CUT_POLICIES = ("lod", "error")
#: Split priorities of the error cut: ``P = ER`` (eq. 9) or ``P = E``.
CUT_PRIORITIES = ("improved", "naive")


def check_cut(cut: Any) -> str:
    """A validated cut policy name (one line naming ``cut`` otherwise)."""
    if not isinstance(cut, str) or cut not in CUT_POLICIES:
        raise ParameterError(f"cut must be one of {', '.join(map(repr, CUT_POLICIES))}, "
                             f"got {cut!r}")
    return cut


def _footprints(octree: BrickOctree, p: int, index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Source voxels ``[lo, hi)`` (n, 3) owned by bricks ``index`` of octree position ``p``."""
    size = octree.brick * octree.factors[p]
    lo = index * size
    hi = np.where(index == octree.counts[p] - 1, octree.n0, (index + 1) * size)
    return lo, np.maximum(hi, lo + 1)


def octree_tree(octree: BrickOctree, ranges: list[np.ndarray] | None = None
                ) -> tuple[BrickTree, np.ndarray, int]:
    """The brick tree of an octree, the key of every node, and the virtual root (or -1).

    Parameters
    ----------
    octree : BrickOctree
    ranges : list of ndarray, optional
        Own value range ``(counts..., 2)`` per octree position (default ``octree.ranges``; NaN
        entries make the node and its ancestors count as containing every value).

    Returns
    -------
    tree : BrickTree
        ``level`` is the octree position (0 finest); boxes in world coordinates; ``voxels`` the
        source voxels a brick owns (see the module docstring).
    keys : ndarray (K, 4) int64
        ``(store level, i, j, k)``; the virtual root's is ``(-1, 0, 0, 0)``.
    virtual : int
        Node id of the virtual root, -1 when the coarsest level is one brick.
    """
    ranges = octree.ranges if ranges is None else ranges
    n_pos = octree.n_levels
    counts = [int(np.prod(c)) for c in octree.counts]
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    virtual = int(offsets[-1]) if counts[-1] > 1 else -1
    k = int(offsets[-1]) + (virtual >= 0)
    parent = np.full(k, -1, np.int64)
    level = np.full(k, n_pos, np.int64)
    box_min = np.zeros((k, 3))
    box_max = np.zeros((k, 3))
    voxels = np.zeros(k, np.int64)
    vmin = np.full(k, np.nan)
    vmax = np.full(k, np.nan)
    keys = np.zeros((k, 4), np.int64)
    for p in range(n_pos):
        idx = np.indices(octree.counts[p]).reshape(3, -1).T.astype(np.int64)
        ids = slice(int(offsets[p]), int(offsets[p + 1]))
        store_level = octree.levels[p]
        keys[ids, 0] = store_level
        keys[ids, 1:] = idx
        level[ids] = p
        box_min[ids], box_max[ids] = octree.world_box(store_level, idx)
        lo, hi = _footprints(octree, p, idx)
        voxels[ids] = np.prod(hi - lo, axis=1)
        own = ranges[p].reshape(-1, 2)
        vmin[ids], vmax[ids] = own[:, 0], own[:, 1]
        if p + 1 < n_pos:
            up = idx // (octree.factors[p + 1] // octree.factors[p])
            parent[ids] = offsets[p + 1] + np.ravel_multi_index(tuple(up.T), octree.counts[p + 1])
        elif virtual >= 0:
            parent[ids] = virtual
    unknown = np.isnan(vmin) | np.isnan(vmax)
    vmin[unknown], vmax[unknown] = -np.inf, np.inf  # unknown: may hold any value
    if virtual >= 0:
        keys[virtual] = (-1, 0, 0, 0)
        box_min[virtual] = box_min[:virtual].min(axis=0)
        box_max[virtual] = box_max[:virtual].max(axis=0)
        voxels[virtual] = int(np.prod(octree.n0))
        vmin[virtual], vmax[virtual] = np.nan, np.nan  # the union of the roots' (hierarchical)
    tree = BrickTree(parent, level=level, box_min=box_min, box_max=box_max, voxels=voxels,
                     value_min=vmin, value_max=vmax)
    return tree, keys, virtual


def _read_level(octree: BrickOctree, p: int) -> np.ndarray:
    level = octree.volume.level(octree.levels[p])
    return level.read((0, 0, 0), level.shape)


def octree_histograms(octree: BrickOctree, quantizer: Quantizer,
                      levels: list[np.ndarray] | None = None) -> BrickHistograms:
    """Histograms of every node of :func:`octree_tree` (leaves and the virtual root empty).

    Parameters
    ----------
    octree : BrickOctree
    quantizer : Quantizer
    levels : list of ndarray, optional
        The octree's levels, finest first (default: read whole from the store, one at a time
        beside the source).
    """
    source = levels[0] if levels is not None else _read_level(octree, 0)
    q = quantizer
    empty = BrickHistograms(np.zeros(2, np.int64), np.zeros(0, np.uint16), np.zeros(0, np.uint32),
                            q)  # one node without entries (the virtual root)
    leaves = int(np.prod(octree.counts[0]))
    parts = [BrickHistograms(np.zeros(leaves + 1, np.int64), empty.keys, empty.counts, q)]
    for p in range(1, octree.n_levels):
        coarse = levels[p] if levels is not None else _read_level(octree, p)
        idx = np.indices(octree.counts[p]).reshape(3, -1).T.astype(np.int64)
        lo, hi = _footprints(octree, p, idx)
        a, c = octree.level_map(octree.levels[p])
        parts.append(box_histograms(source, coarse, lo, hi, a, c, q))
    if int(np.prod(octree.counts[-1])) > 1:
        parts.append(empty)
    hist = stack_histograms(parts)
    return hist


def _signature(tf: TransferFunction, value_filter: ValueFilter | None) -> tuple:
    intervals = None if value_filter is None else (tuple(value_filter.intervals or ()),
                                                    value_filter.widen)
    return (tf.opacity_points.tobytes(), tf.domain, repr(tf.colormap), intervals)


class _RenderUpdater(CutUpdater):
    """The rendering cut's updater; the virtual root above several coarsest bricks stays split."""

    def __init__(self, metric: CutMetric, budget: int, load_budget: int | None, cut: Any,
                 virtual: int, fill: bool):
        self.virtual = virtual
        super().__init__(metric, budget, load_budget, cut=cut, fill=fill)

    def can_collapse(self, parent: int) -> bool:
        return parent != self.virtual


class ErrorCut:
    """The error-metric cut of a :class:`~.cut.octree.BrickOctree`, one update per frame.

    Parameters
    ----------
    octree : BrickOctree
        The stream's octree (its value ranges are those of the store's ``minmax`` table).
    bins : int, optional
        Histogram bins per value axis (default: the stored histograms', else
        :data:`~.cut.histograms.DEFAULT_BINS`).
    improved : bool
        ``P = ER`` (the paper's "improved" priority, default) or ``P = E`` ("naive").
    interest : 3 floats, optional
        Default point of interest (world coordinates) of eqs. (5)-(6); without one the importance
        is the eye term alone.
    fill : bool
        Set aside a split that does not fit N or M and go on (default; see
        :mod:`.cut.update`), or end the frame there (the paper's rule).
    levels : list of ndarray, optional
        The levels in memory (default: read from the store once, here, unless the store holds
        its histograms).
    stored : bool
        Use the histograms stored with the pyramid (:mod:`.store.hist_store`) when it has them
        (default); otherwise, or when they do not fit this octree or are damaged (one warning
        says so), build them from the levels.
    frustum : bool
        Frustum culling (default): a brick more than :attr:`frustum_margin` outside the camera's
        view frustum has importance 0, so it is never split (the cut still covers it once, as
        coarse as it is).

    Attributes
    ----------
    tree, keys, virtual
        See :func:`octree_tree`.
    histograms : BrickHistograms
    metric : CutMetric or None
        Made at the first frame (it needs a transfer function).
    updater : CutUpdater or None
    last : CutUpdate or None
        The last frame's update.
    build_ms : float
        Time spent reading the levels and building the histograms.
    """

    def __init__(self, octree: BrickOctree, *, bins: int | None = None, improved: bool = True,
                 interest: Any = None, fill: bool = True,
                 levels: list[np.ndarray] | None = None, stored: bool = True,
                 frustum: bool = True) -> None:
        start = time.perf_counter()
        self.octree = octree
        self.improved = bool(improved)
        self.fill = bool(fill)
        self.frustum = bool(frustum)
        self.interest = _check_interest(interest)
        volume = octree.volume
        self._levels: dict[int, np.ndarray] = dict(enumerate(levels)) if levels else {}
        #: Where the histograms came from: ``"store"`` (the pyramid's ``hist2d`` group) or
        #: ``"built"`` (from the levels, at opening).
        self.histogram_source = "built"
        self.histogram_note = ""
        hist = self._stored_histograms(bins) if stored and levels is None else None
        if hist is None:
            self.quantizer = Quantizer.for_data(volume.dtype, volume.value_range,
                                                DEFAULT_BINS if bins is None else bins)
        else:
            self.quantizer = hist.quantizer
            self.histogram_source = "store"
        ranges = [self._fill_ranges(p) for p in range(octree.n_levels)]
        self.tree, self.keys, self.virtual = octree_tree(octree, ranges)
        if hist is None:
            hist = octree_histograms(octree, self.quantizer,
                                     [self._level(p) for p in range(octree.n_levels)])
        self.histograms = hist
        self._levels = {}  # the levels were only needed for the histograms
        finest = self.tree.level == 0
        #: How far outside the view frustum a brick still counts as in view (world units): the
        #: diagonal of a finest brick, so the finest neighbours of a brick in view are refined
        #: with it and no seam between levels touches what the camera sees.
        self.frustum_margin = float(np.linalg.norm(
            self.tree.box_max[finest] - self.tree.box_min[finest], axis=1).max())
        self.brick_bytes = int(max(octree.brick_bytes(octree.levels[p],
                                                      np.zeros((1, 3), np.int64)).max()
                                   for p in range(octree.n_levels)))
        roots = np.flatnonzero(self.tree.parent == (self.virtual if self.virtual >= 0 else -2))
        self.roots = roots if self.virtual >= 0 else np.array([self.tree.root], np.int64)
        self._node_of = {tuple(int(v) for v in key): n for n, key in enumerate(self.keys)}
        self.metric: CutMetric | None = None
        self.updater: _RenderUpdater | None = None
        self.last: CutUpdate | None = None
        self._signature: tuple | None = None
        self.build_ms = (time.perf_counter() - start) * 1e3

    def _level(self, p: int) -> np.ndarray:
        if p not in self._levels:
            self._levels[p] = _read_level(self.octree, p)
        return self._levels[p]

    def _stored_histograms(self, bins: int | None) -> BrickHistograms | None:
        """The store's ``hist2d`` group in node order, or None (with one warning saying why,
        unless the store simply predates stored histograms and says nothing)."""
        octree = self.octree
        volume = octree.volume
        attributes = getattr(volume, "attributes", {})
        if octree.n_levels == 1:  # only leaves: nothing to store or build
            return BrickHistograms(np.zeros(int(np.prod(octree.counts[0])) + 1, np.int64),
                                   np.zeros(0, np.uint16), np.zeros(0, np.uint32),
                                   Quantizer.for_data(volume.dtype, volume.value_range,
                                                      DEFAULT_BINS if bins is None else bins))
        if HIST2D not in attributes:
            self.histogram_note = ("no stored brick histograms: building them from every level "
                                   "(rebuild the pyramid with --histograms to skip this)")
            warnings.warn(f"{getattr(volume, 'path', 'pyramid')}: {self.histogram_note}",
                          UserWarning, stacklevel=4)
            return None
        try:
            stored = read_histograms(volume, octree.brick, octree.levels[1:],
                                     [octree.level_map(lv) for lv in octree.levels[1:]], bins)
        except (ParameterError, ReadError) as exc:
            self.histogram_note = f"{exc}; building them from every level instead"
            warnings.warn(self.histogram_note, UserWarning, stacklevel=4)
            return None
        q = stored[0].quantizer if stored else Quantizer.for_data(
            volume.dtype, volume.value_range, DEFAULT_BINS if bins is None else bins)
        leaves = int(np.prod(octree.counts[0]))
        empty = np.zeros(0, np.uint16)
        parts = [BrickHistograms(np.zeros(leaves + 1, np.int64), empty,
                                 np.zeros(0, np.uint32), q), *stored]
        if int(np.prod(octree.counts[-1])) > 1:
            parts.append(BrickHistograms(np.zeros(2, np.int64), empty, np.zeros(0, np.uint32),
                                         q))
        return stack_histograms(parts)

    def _fill_ranges(self, p: int) -> np.ndarray:
        """The octree's own ranges of position ``p``, NaN entries computed from the level over
        each brick's window (as the ``minmax`` table is; the level is read only then)."""
        ranges = np.array(self.octree.ranges[p], dtype=np.float64, copy=True)
        missing = np.argwhere(np.isnan(ranges).any(axis=-1))
        if missing.size:
            data = self._level(p)
            first, stop = self.octree.window(self.octree.levels[p], missing)
            for n, idx in enumerate(missing):
                lo = np.clip(first[n], 0, data.shape)
                hi = np.clip(stop[n], lo, data.shape)
                block = data[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]]
                ranges[tuple(idx)] = (block.min(), block.max()) if block.size else (np.nan,) * 2
        return ranges

    # ------------------------------------------------------------------------------ a frame
    def budget_bricks(self, budget_bytes: int) -> int:
        """N for a byte budget: full bricks that fit, at least the coarsest level's."""
        return max(int(budget_bytes) // self.brick_bytes, len(self.roots), 1)

    def _prepare(self, camera: Camera, tf: TransferFunction, value_filter: ValueFilter | None,
                 interest: Any, budget: int, load_budget: int | None,
                 resident: Iterable[Key] | None) -> None:
        interest = self.interest if interest is None else _check_interest(interest)
        signature = _signature(tf, value_filter)
        if self.metric is None:
            self.metric = CutMetric(self.tree, self.histograms, tf, interest=interest,
                                    eye=camera.position, improved=self.improved)
            self._set_visible(value_filter)
            self._signature = signature
        elif signature != self._signature:
            self.metric.set_transfer_function(tf)
            self._set_visible(value_filter)
            self._signature = signature
        frustum = frustum_planes(camera) if self.frustum else None
        self.metric.set_view(interest=interest, eye=camera.position, frustum=frustum,
                             margin=self.frustum_margin)
        if self.updater is None:
            start = self.roots[self.metric.visible[self.roots]]
            self.updater = _RenderUpdater(self.metric, budget, load_budget, start, self.virtual,
                                          self.fill)
        self.updater.budget = int(budget)
        self.updater.load_budget = None if load_budget is None else max(int(load_budget), 8)
        if resident is not None:
            held = [self._node_of.get(key, -1) for key in resident]
            self.updater.resident[:] = False
            self.updater.resident[[n for n in held if n >= 0]] = True

    def _set_visible(self, value_filter: ValueFilter | None) -> None:
        """Visibility from the renderer's value filter (hierarchical: ranges are)."""
        assert self.metric is not None
        tree = self.tree
        if value_filter is None:
            self.metric.visible[:] = True
        else:
            self.metric.visible[:] = value_filter.contributes(tree.value_min, tree.value_max)

    def update(self, camera: Camera, tf: TransferFunction, value_filter: ValueFilter | None,
               budget: int, load_budget: int | None = None, interest: Any = None,
               resident: Iterable[Key] | None = None) -> CutUpdate:
        """One frame of the updater: the node ids of the new cut in ``CutUpdate.cut``.

        Parameters
        ----------
        camera : Camera
            Its position is the eye of eq. (6).
        tf : TransferFunction
            Classification of eq. (2).
        value_filter : ValueFilter or None
            Visible value ranges (None: everything is visible).
        budget : int
            N, bricks.
        load_budget : int, optional
            M, bricks entering the cut this frame.
        interest : 3 floats, optional
            Point of interest of this frame (default: the one given at construction).
        resident : iterable of keys, optional
            The bricks the cache holds (they cost no load); default: the previous cut.
        """
        self._prepare(camera, tf, value_filter, interest, budget, load_budget, resident)
        assert self.updater is not None
        update = self.updater.update()
        if self.virtual >= 0 and self.updater.in_cut[self.virtual]:
            self.updater.split(self.virtual)  # only after a repair emptied the cut
            update.cut = np.sort(np.fromiter(self.updater.cut, np.int64, len(self.updater.cut)))
        self.last = update
        return update

    def error(self, cut: np.ndarray) -> float:
        """``E(cut)`` (eq. 8) under the current metric."""
        assert self.metric is not None
        cut = np.asarray(cut, np.int64)
        errors = np.zeros(self.tree.size)
        errors[cut] = self.metric.error(cut)
        return cut_error(self.tree, errors, cut, self.metric.visible)

    def selector(self, camera: Camera, tf: TransferFunction, value_filter: ValueFilter | None,
                 load_budget: int | None, interest: Any = None,
                 resident_keys: Callable[[], Iterable[Key]] | None = None
                 ) -> Callable[[int, Callable[[Key], bool], int], Cut]:
        """A :data:`~.cut.stream.Selector` for one frame (what :meth:`BrickStream.frame
        <.stream.BrickStream.frame>` calls with its byte budget); ``resident_keys()`` lists the
        cache's bricks (:meth:`.store.cache.BrickCache.resident_keys`)."""

        def select(budget_bytes: int, resident: Callable[[Key], bool], prefetch: int) -> Cut:
            held = None if resident_keys is None else resident_keys()
            update = self.update(camera, tf, value_filter, self.budget_bricks(budget_bytes),
                                 load_budget, interest, held)
            return self.to_cut(update.cut, value_filter, resident, prefetch,
                               limited=update.stop == "brick budget")

        return select

    def to_cut(self, nodes: np.ndarray, value_filter: ValueFilter | None,
               resident: Callable[[Key], bool], prefetch: int, limited: bool = False) -> Cut:
        """The :class:`~.cut.lod.Cut` of tree nodes, with the next splits as prefetch."""
        assert self.metric is not None
        nodes = np.asarray(nodes, np.int64)
        cut = cut_of_keys(self.octree, self.keys[nodes], self.metric.error(nodes), value_filter,
                          resident, limited)
        if prefetch > 0 and nodes.size:
            priority = self.metric.priority(nodes)
            order = np.argsort(-priority, kind="stable")
            extra: list[Key] = []
            want = set(cut.requests)
            for n in order.tolist():
                if len(extra) >= prefetch or not priority[n] > 0:
                    break
                kids = self.tree.children_of(int(nodes[n]))
                for kid in kids[self.metric.visible[kids]].tolist():
                    key: Key = tuple(int(v) for v in self.keys[kid])  # type: ignore[assignment]
                    if key not in want:  # resident ones too: see lod._assemble
                        extra.append(key)
            cut.prefetch = extra[:prefetch]
        return cut

    def stats(self) -> dict[str, Any]:
        """What the last frame's update did, for ``frame.stats``."""
        if self.last is None or self.updater is None:
            return {"cut_policy": "error"}
        last = self.last
        return {"cut_policy": "error", "cut_error": self.error(last.cut),
                "cut_stop": last.stop, "cut_final": last.stop != "load budget",
                "cut_splits": last.splits, "cut_collapses": last.collapses,
                "cut_budget_bricks": self.updater.budget, "cut_repaired": last.repaired,
                "cut_update_ms": sum(last.timings.values())}


def _check_interest(interest: Any) -> np.ndarray | None:
    if interest is None:
        return None
    try:
        point = np.asarray(interest, dtype=np.float64).reshape(3)
    except (TypeError, ValueError):
        raise ParameterError(f"interest must be a point (x, y, z), got {interest!r}") from None
    if not np.all(np.isfinite(point)):
        raise ParameterError(f"interest must be a finite point (x, y, z), got {interest!r}")
    return point
