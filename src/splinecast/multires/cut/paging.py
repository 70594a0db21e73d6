"""The extended cut S+ that decides what the RAM brick cache loads next (Carmona & Froehlich 2011,
section 4).

RAM holds the rendering cut S and all its ancestors (about N/7 more bricks for a full octree), so a
collapse never page-faults. The rest of the cache holds finer bricks, chosen by the same
split-and-collapse logic and the same priority P(b) as the rendering cut, one level of paging
further: the **extended cut** S+ (finer than or equal to S everywhere) and its collapsible parents
C+. Every node of S+ and all its ancestors are in RAM; the cache's capacity counts them all.

* The loader splits ``head(S+)`` (it loads the split node's visible children) while the cache
  has room; when it is full it collapses the lowest-priority parent of C+ (evicting its children)
  if that ranks below ``head(S+)``, else it idles until the priorities change.
* Nodes of C+ whose children belong to the rendering cut (the nodes of C that are in C+) are never
  collapsed: S stays resident.
* The rendering update splits only nodes whose children are in RAM
  (:meth:`~.cut.update.CutUpdater.update` with ``in_ram``), so S never leaves the cached tree;
  :meth:`ExtendedCut.set_render_cut` still forces S+ below any rendering node it does not cover
  (after a transfer-function repair the two cuts are repaired independently).

Threading: the loader thread should own its :class:`ExtendedCut` and its own
:class:`~.cut.metric.CutMetric` (a second instance over the same tree and histograms, whose view
and transfer function the main thread updates by message, as the paper does); the metric's caches
are not shared between threads.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .update import CutUpdate, SplitCollapse

__all__ = ["ExtendedCut"]


class ExtendedCut(SplitCollapse):
    """S+ and C+ of the paging loader, maintained by split-and-collapse.

    Parameters
    ----------
    metric : CutMetric or ArrayMetric
        Priorities (the loader's own instance; see the module docstring).
    capacity : int
        Bricks the RAM cache holds: S+ plus all its ancestors.
    render_cut : array of node ids
        The current rendering cut S (pinned).
    loads_per_plan : int or None
        Most bricks one :meth:`plan` call may ask to load (None: until the cache is full).
    """

    def __init__(self, metric: Any, capacity: int, render_cut: Any,
                 loads_per_plan: int | None = None):
        self.in_render = np.zeros(metric.tree.size, bool)
        self.in_render[np.asarray(render_cut, np.int64)] = True
        super().__init__(metric, render_cut, capacity, loads_per_plan, count_ancestors=True)
        self.cached = self._cached_tree()
        self.resident = self.cached.copy()
        self.set_render_cut(render_cut)

    def _cached_tree(self) -> np.ndarray:
        """S+ and all its ancestors: what RAM holds once the plan is carried out."""
        mask = self.in_cut.copy()
        if self.cut:
            mask[self.tree.ancestors_of(np.fromiter(self.cut, np.int64, len(self.cut)))] = True
        return mask

    def set_render_cut(self, render_cut: Any) -> None:
        """Pin the rendering cut; split S+ down to any rendering node it does not cover yet."""
        render_cut = np.asarray(render_cut, np.int64)
        if self.metric.tf_epoch != self._tf_epoch:  # repair S+ for the new visibility first
            self.repair()
            self._tf_epoch = self.metric.tf_epoch
        self.in_render[:] = False
        self.in_render[render_cut] = True
        cached = self._cached_tree()
        for node in render_cut[~cached[render_cut]].tolist():
            path = []
            b = node
            while not self.in_cut[b]:
                path.append(b)
                b = int(self.tree.parent[b])
            for step in [b, *path[:0:-1]]:
                self.split(step)

    def can_collapse(self, parent: int) -> bool:
        """Never evict bricks of the rendering cut (the nodes of C that are in C+)."""
        return not bool(self.in_render[self.visible_children(parent)].any())

    def _leave(self, node: int) -> None:
        # A split node stays in RAM as an ancestor; loads and evictions are counted on the
        # cached tree when the plan is committed.
        self.in_cut[node] = False
        self.cut.discard(node)

    def _commit_frame(self) -> tuple[np.ndarray, np.ndarray]:
        cached = self._cached_tree()
        order = [b for b in dict.fromkeys(self.downloads) if cached[b] and not self.resident[b]]
        loads = np.array(order, np.int64)
        missing = np.flatnonzero(cached & ~self.resident)  # e.g. ancestors of repaired nodes
        loads = np.concatenate([loads, np.setdiff1d(missing, loads)])
        evicted = np.flatnonzero(self.resident & ~cached)
        self.resident = cached
        self.cached = cached
        self._begin_frame()
        return loads, evicted

    def plan(self) -> CutUpdate:
        """The loader's next moves: ``downloads`` are the bricks to read, in priority order;
        ``evicted`` the bricks to drop. ``stop`` says why it stopped (``"brick budget"``: the
        cache is full and no collapse ranks below the next split, so the loader may idle)."""
        return self.step()

    def prefetch_order(self, limit: int | None = None) -> np.ndarray:
        """The next bricks to load, in priority order (at most ``limit`` this call)."""
        saved = self.load_budget
        if limit is not None:
            self.load_budget = int(limit)
        try:
            return self.plan().downloads
        finally:
            self.load_budget = saved
