"""Greedy split-and-collapse cut updates under a brick budget N and a load budget M (Carmona &
Froehlich 2011).

Each frame starts from the previous cut instead of the root (section 3.5):

* **S**, the splittable nodes of the cut, in descending priority; **C**, the collapsible parents
  (every visible child in the cut), in ascending priority; **DL**, the bricks to download for the
  next frame. Both queues are :class:`~.cut.partial_queue.PartialQueue` s: when the priorities
  change
  (view, interest point, transfer function) they are re-prioritised and partially sorted in
  O(N + M log M), then the frame's O(M) operations cost O(log M) each.
* Loop on ``S0 = head(S)``: if splitting it fits N and M, split it (its visible children enter the
  cut and DL); if only N would be exceeded, collapse the lowest-priority collapsible parent and try
  again. Stop, in the paper's order, when (1) the priority of ``S0`` is not positive (no split
  reduces the error), (2) splitting ``S0`` would exceed M, (3) splitting ``S0`` would exceed N and
  the next collapsible parent does not rank below ``S0``, or collapsing it would exceed M (we
  count the split it makes room for too, so a frame never pays a collapse for a split M forbids).
* **Fill** (``fill=True``, not in the paper): instead of ending the frame at the first split that
  does not fit N (no collapse ranks below it) or M, that node is set aside for the frame and the
  next one is tried, at most ``skip_limit`` (default M) set-asides per frame, so the frame stays
  O(M log M). The frame uses the budgets a large split leaves unused: splits of nodes with fewer
  visible children (borders, transparent children), which matter when N and M are small against
  the 7 bricks and 8 downloads of a full octree split (with M = 8 the paper's rule cannot even
  pair a collapse with a split). The fixed point is then close to the greedy cut with
  ``fill=True`` (:func:`~.cut.select.greedy_cut`), which ``benchmarks/bench_cut.py`` finds
  closer to the optimum than the paper's rule.
* Downloads count the bricks of the new cut that were not resident (not in the previous frame's
  cut): a split downloads its non-resident children, a collapse its parent if not resident, and a
  brick downloaded earlier this frame and removed again is not downloaded.
* Incomplete trees: a split adds ``|children| - 1`` bricks (zero for a single child), a collapse
  frees as many. One split may need several collapses, and a parent with a single visible child
  frees nothing; as in the paper, each collapse is done as soon as the parent ranks below ``S0``
  (if the next one does not, the split waits: the cut has still moved toward the greedy cut, the
  fixed point of the updates).
* **Transfer-function changes** (section 3.6): transparent nodes leave the cut; then (i) the
  remaining cut nodes and their ancestors are marked, (ii) a walk from the root over visible nodes
  stops at cut nodes and inserts every unmarked node it meets; while the cut exceeds N (or the
  insertions exceed M) the lowest-priority collapsible parents that help are collapsed; then the
  frame continues with split-and-collapse as far as M allows. Only the hull (the cut, its
  ancestors, its children; their D comes from the histograms) is re-prioritised.

The same engine, counting every brick of the cut *and its ancestors* against a RAM capacity and
never collapsing a parent of the rendering cut, maintains the extended cut of the paging loader
(:mod:`.cut.paging`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ...errors import ParameterError
from .partial_queue import PartialQueue

__all__ = ["CutUpdater", "CutUpdate", "SplitCollapse"]

#: Why a frame's refinement stopped.
STOP_REASONS = ("zero error", "load budget", "brick budget", "nothing to split")


@dataclass
class CutUpdate:
    """What one frame's update did.

    Attributes
    ----------
    cut : numpy.ndarray
        Sorted node ids of the new cut.
    downloads : numpy.ndarray
        Bricks of the new cut that were not resident (DL), in the order they were decided.
    evicted : numpy.ndarray
        Resident bricks that left the cut (their slots are free).
    splits, collapses : int
        Operations performed.
    stop : str
        The stop condition that ended the frame (one of ``STOP_REASONS``).
    repaired : bool
        Whether the transfer function changed and the cut was repaired first.
    over_budget : bool
        A transfer-function repair could not get under N and M by collapsing (the cut is valid
        but larger than asked; the next frames collapse further).
    timings : dict
        Milliseconds spent re-prioritising (and repairing), refining, and committing.
    """

    cut: np.ndarray
    downloads: np.ndarray
    evicted: np.ndarray
    splits: int = 0
    collapses: int = 0
    stop: str = ""
    repaired: bool = False
    over_budget: bool = False
    timings: dict[str, float] = field(default_factory=dict)


class SplitCollapse:
    """The split-and-collapse engine shared by the rendering cut and the paging extended cut.

    Parameters
    ----------
    metric : CutMetric or ArrayMetric
        Priorities, errors, visibility and their epochs.
    cut : array of node ids
        A valid starting cut (for example ``[tree.root]`` or a greedy cut).
    budget : int
        Units available: bricks of the cut (``count_ancestors=False``) or bricks of the cut and
        all its ancestors (``True``, a RAM cache that pins the path to the root).
    load_budget : int or None
        Bricks that may become resident per call (None: unlimited).
    count_ancestors : bool
        See ``budget``.
    fill : bool
        Set aside a split that does not fit instead of ending the frame (see the module
        docstring); False is the paper's rule.
    skip_limit : int, optional
        Most set-asides per frame with ``fill`` (default: M, or 64 without a load budget).
    """

    def __init__(self, metric: Any, cut: Any, budget: int, load_budget: int | None,
                 count_ancestors: bool = False, fill: bool = False,
                 skip_limit: int | None = None):
        if budget < 1:
            raise ParameterError(f"the budget must be at least 1 brick, got {budget}")
        if load_budget is not None and load_budget < 0:
            raise ParameterError(f"the load budget must be >= 0, got {load_budget}")
        self.metric = metric
        self.tree = metric.tree
        self.budget = int(budget)
        self.load_budget = load_budget
        self.count_ancestors = count_ancestors
        self.fill = bool(fill)
        self.skip_limit = skip_limit
        k = self.tree.size
        self.in_cut = np.zeros(k, bool)
        cut = np.unique(np.asarray(cut, np.int64))
        self.in_cut[cut] = True
        self.cut: set[int] = set(cut.tolist())
        self.resident = self.in_cut.copy()
        capacity = max(1, load_budget if load_budget is not None else 64)
        self.split_queue = PartialQueue(capacity, k)      # S, key (-P, rank)
        self.collapse_queue = PartialQueue(capacity, k)   # C, key (P, -rank)
        self._epoch = None
        self._tf_epoch = metric.tf_epoch
        self._visible_children: dict[int, np.ndarray] = {}
        self.count = self._recount()
        self._begin_frame()
        # A starting cut made under another transfer function is repaired like an edited one.
        self.over_budget = self.repair()

    # ------------------------------------------------------------------------- structure
    def visible_children(self, node: int) -> np.ndarray:
        """Visible children of ``node`` (cached per transfer function)."""
        kids = self._visible_children.get(node)
        if kids is None:
            kids = self.tree.children_of(node)
            kids = kids[self.metric.visible[kids]]
            self._visible_children[node] = kids
        return kids

    def _recount(self) -> int:
        n = len(self.cut)
        if self.count_ancestors and n:
            n += int(self.tree.ancestors_of(np.fromiter(self.cut, np.int64, n)).size)
        return n

    def _split_units(self, kids: np.ndarray) -> int:
        return int(kids.size) if self.count_ancestors else int(kids.size) - 1

    def _collapsible(self, parent: int) -> bool:
        kids = self.visible_children(parent)
        return bool(kids.size) and bool(self.in_cut[kids].all())

    def can_collapse(self, parent: int) -> bool:
        """Hook: may this collapsible parent be collapsed now? (paging pins the render cut)."""
        return True

    # -------------------------------------------------------------------------- frame state
    def _begin_frame(self) -> None:
        self.downloads: list[int] = []
        self._download_set: set[int] = set()
        self._left: dict[int, None] = {}
        self.loads = 0

    def _enter(self, node: int) -> None:
        self.in_cut[node] = True
        self.cut.add(node)
        if not self.resident[node]:
            self.downloads.append(node)
            self._download_set.add(node)
            self.loads += 1

    def _leave(self, node: int) -> None:
        """``node`` leaves the cut; a brick decided this frame and not yet loaded is not loaded."""
        self.in_cut[node] = False
        self.cut.discard(node)
        if node in self._download_set:
            self._download_set.discard(node)
            self.loads -= 1
        elif self.resident[node]:
            self._left[node] = None

    def _commit_frame(self) -> tuple[np.ndarray, np.ndarray]:
        downloads = np.array([b for b in self.downloads if b in self._download_set], np.int64)
        evicted = np.array([b for b in self._left if not self.in_cut[b]], np.int64)
        self.resident[downloads] = True
        self.resident[evicted] = False
        self._begin_frame()
        return downloads, evicted

    # ------------------------------------------------------------------------- priorities
    def _s_key(self, node: int, p: float) -> tuple[float, int]:
        return (-p, int(self.metric.rank[node]))

    def _c_key(self, node: int, p: float) -> tuple[float, int]:
        return (p, -int(self.metric.rank[node]))

    def _rebuild_sets(self) -> None:
        """Recompute S and C from the cut (start, transfer-function repair), then sort them."""
        tree = self.tree
        cut = np.fromiter(self.cut, np.int64, len(self.cut))
        splittable = cut[np.isfinite(self.metric.priority(cut))] if cut.size else cut
        parents = np.unique(tree.parent[cut]) if cut.size else cut
        parents = parents[parents >= 0]
        kids, owner = tree.children_with_owner(parents, self.metric.visible)
        n_visible = np.bincount(owner, minlength=parents.size)
        n_in_cut = np.bincount(owner, weights=self.in_cut[kids], minlength=parents.size)
        collapsible = parents[(n_visible > 0) & (n_in_cut == n_visible)]
        self._sort_queues(splittable, collapsible)

    def reprioritize(self) -> None:
        """New priorities for S and C (the hull), then a partial sort of each: O(N + M log M)."""
        splittable = self.split_queue.nodes()
        collapsible = self.collapse_queue.nodes()
        self._sort_queues(splittable, collapsible)

    def _sort_queues(self, splittable: np.ndarray, collapsible: np.ndarray) -> None:
        rank = self.metric.rank
        self.split_queue.rebuild(splittable, -self.metric.priority(splittable), rank[splittable])
        self.collapse_queue.rebuild(collapsible, self.metric.priority(collapsible),
                                    -rank[collapsible])
        self._epoch = self.metric.epoch

    def _priority(self, node: int) -> float:
        return float(self.metric.priority(np.array([node]))[0])

    # --------------------------------------------------------------------------- operations
    def split(self, node: int) -> None:
        """Replace ``node`` by its visible children in the cut."""
        kids = self.visible_children(node)
        p_node = (-self.split_queue.key(node)[0] if node in self.split_queue
                  else self._priority(node))
        self.split_queue.discard(node)
        self._leave(node)
        parent = int(self.tree.parent[node])
        if parent >= 0:
            self.collapse_queue.discard(parent)
        priorities = self.metric.priority(kids).tolist()
        for kid, p in zip(kids.tolist(), priorities, strict=True):
            self._enter(kid)
            if p != -np.inf:
                self.split_queue.push(kid, self._s_key(kid, p))
        self.collapse_queue.push(node, self._c_key(node, p_node))
        self.count += self._split_units(kids)

    def collapse(self, parent: int) -> None:
        """Replace the visible children of ``parent`` (all in the cut) by ``parent``."""
        kids = self.visible_children(parent)
        p_parent = (self.collapse_queue.key(parent)[0] if parent in self.collapse_queue
                    else self._priority(parent))
        self.collapse_queue.discard(parent)
        for kid in kids.tolist():
            self.split_queue.discard(kid)
            self._leave(kid)
        self._enter(parent)
        self.split_queue.push(parent, self._s_key(parent, p_parent))
        grand = int(self.tree.parent[parent])
        if grand >= 0 and self._collapsible(grand):
            self.collapse_queue.push(grand, self._c_key(grand, self._priority(grand)))
        self.count -= self._split_units(kids)

    def _split_loads(self, kids: np.ndarray) -> int:
        return int(np.count_nonzero(~self.resident[kids]))

    def _collapse_loads(self, parent: int) -> int:
        kids = self.visible_children(parent)
        refund = sum(1 for k in kids.tolist() if k in self._download_set)
        return (0 if self.resident[parent] else 1) - refund

    def _fits_loads(self, extra: int) -> bool:
        return self.load_budget is None or self.loads + extra <= self.load_budget

    # ------------------------------------------------------------------------------ the loop
    def refine(self, allow_split: Any = None) -> tuple[str, int, int]:
        """Split and collapse until a stop condition holds. Returns (stop, splits, collapses).

        ``allow_split(node) -> bool`` may exclude nodes from splitting this call (the paging
        restriction: the children must be in RAM); excluded nodes are skipped, not stopped at.
        """
        splits = collapses = 0
        skipped_s: list[tuple[tuple[float, int], int]] = []
        skipped_c: list[tuple[tuple[float, int], int]] = []
        stop = STOP_REASONS[3]
        limit = self.skip_limit if self.skip_limit is not None else (
            self.load_budget if self.load_budget is not None else 64)
        set_aside = 0
        collapsed_now: set[int] = set()  # fill: not split again in the frame that collapsed it

        load_limited = False  # a split set aside for M: the frame is not final

        def aside(reason: str) -> bool:
            """With ``fill``, set S0 aside and go on (True); else the frame stops."""
            nonlocal set_aside, stop, load_limited
            stop = reason
            load_limited = load_limited or reason == STOP_REASONS[1]
            if not self.fill or set_aside >= limit:
                return False
            skipped_s.append(self.split_queue.pop())
            set_aside += 1
            return True

        while True:
            head = self.split_queue.peek()
            if head is None:
                if not set_aside:  # with set-asides, the budget that set them aside stopped it
                    stop = STOP_REASONS[3]
                break
            s_key, s0 = head
            if not -s_key[0] > 0.0:
                if not set_aside:  # as for an empty queue: what set splits aside stopped it
                    stop = STOP_REASONS[0]
                break
            if (allow_split is not None and not allow_split(s0)) or s0 in collapsed_now:
                skipped_s.append(self.split_queue.pop())
                continue
            kids = self.visible_children(s0)
            if not self._fits_loads(self._split_loads(kids)):
                if aside(STOP_REASONS[1]):
                    continue
                break
            if self.count + self._split_units(kids) > self.budget and self.fill:
                plan = self._plan_collapses(s_key, s0, kids)
                if plan is None:
                    if aside(STOP_REASONS[2]):
                        continue
                    break
                for c0 in plan:
                    self.collapse(c0)
                    collapsed_now.add(c0)
                    collapses += 1
                continue  # S0 fits now
            if self.count + self._split_units(kids) > self.budget:
                c_head = self.collapse_queue.peek()
                if c_head is None:
                    if aside(STOP_REASONS[2]):
                        continue
                    break
                c_key, c0 = c_head
                if not self.can_collapse(c0):
                    skipped_c.append(self.collapse_queue.pop())  # pinned (paging)
                    continue
                # C0 must rank below S0 in split order (P(C0) < P(S0), ties by rank), and the
                # collapse plus the split it makes room for must fit M.
                loads = self._collapse_loads(c0) + self._split_loads(kids)
                if (c_key >= (-s_key[0], -s_key[1]) or c0 == int(self.tree.parent[s0])
                        or not self._fits_loads(loads)):
                    if aside(STOP_REASONS[2]):
                        continue
                    break
                self.collapse(c0)
                collapses += 1
                continue
            self.split(s0)
            splits += 1
        for key, node in skipped_s:
            if self.in_cut[node] and node not in self.split_queue:
                self.split_queue.push(node, key)
        for key, node in skipped_c:
            if not self.in_cut[node] and self._collapsible(node):
                self.collapse_queue.push(node, key)
        if load_limited:  # a later frame still has a split to make
            stop = STOP_REASONS[1]
        return stop, splits, collapses

    def _plan_collapses(self, s_key: tuple[float, int], s0: int,
                        kids: np.ndarray) -> list[int] | None:
        """With ``fill``: the collapsible parents, lowest first and ranking below S0, that make
        room for splitting S0 within N and M together, or None (then none is collapsed: a
        collapse that enables no split would only raise the error)."""
        need = self.count + self._split_units(kids) - self.budget
        loads = self._split_loads(kids)
        parent = int(self.tree.parent[s0])
        popped: list[tuple[tuple[float, int], int]] = []
        plan: list[int] = []
        freed = 0
        while freed < need:
            head = self.collapse_queue.pop()
            if head is None:
                break
            popped.append(head)
            key, c0 = head
            if key >= (-s_key[0], -s_key[1]):
                break
            units = self._split_units(self.visible_children(c0))
            if c0 == parent or units <= 0 or not self.can_collapse(c0):
                continue
            plan.append(c0)
            freed += units
            loads += self._collapse_loads(c0)
        for key, c0 in popped:
            self.collapse_queue.push(c0, key)
        if freed < need or not self._fits_loads(loads):
            return None
        return plan

    # ------------------------------------------------------------------- transfer functions
    def repair(self) -> bool:
        """Make the cut valid for the metric's current visibility; True if over budget after.

        Removes transparent nodes, marks the rest and their ancestors, inserts the unmarked
        visible nodes met top-down, then collapses (lowest priority first, only collapses that
        help) until the budgets hold or no collapse helps.
        """
        tree = self.tree
        visible = self.metric.visible
        self._visible_children.clear()
        cut = np.fromiter(self.cut, np.int64, len(self.cut))
        for node in cut[~visible[cut]].tolist():
            self._leave(node)
        cut = cut[visible[cut]]
        # (i) mark the cut and its ancestors; (ii) the walk from the root over visible nodes
        # visits exactly the marked nodes above the cut (all ancestors of a cut node are marked
        # and visible) and inserts their unmarked visible children: one vectorized step.
        marked = np.zeros(tree.size, bool)
        marked[cut] = True
        above = tree.ancestors_of(cut)
        marked[above] = True
        kids, _ = tree.children_with_owner(above, visible)
        inserts = kids[~marked[kids]].tolist()
        if not cut.size and visible[tree.root]:
            inserts = [tree.root]
        for node in inserts:
            self._enter(node)
        self.count = self._recount()
        self._rebuild_sets()
        skipped: list[tuple[tuple[float, int], int]] = []
        while self.count > self.budget or not self._fits_loads(0):
            head = self.collapse_queue.pop()
            if head is None:
                break
            key, c0 = head
            over_n = self.count > self.budget
            helps = ((over_n and self._split_units(self.visible_children(c0)) > 0)
                     or (not over_n and self._collapse_loads(c0) < 0))
            if helps and self.can_collapse(c0):
                self.collapse_queue.push(c0, key)
                self.collapse(c0)
            else:
                skipped.append(head)
        for key, node in skipped:
            if not self.in_cut[node] and self._collapsible(node):
                self.collapse_queue.push(node, key)
        return self.count > self.budget or not self._fits_loads(0)

    def step(self, allow_split: Any = None) -> CutUpdate:
        """One frame: repair if the transfer function changed, re-prioritise if anything
        changed, refine, and report what to download and evict (with phase timings in ms)."""
        repaired = False
        over = self.over_budget
        t0 = time.perf_counter()
        if self.metric.tf_epoch != self._tf_epoch:
            over = self.repair()
            self._tf_epoch = self.metric.tf_epoch
            repaired = True
        elif self.metric.epoch != self._epoch:
            self.reprioritize()
        t1 = time.perf_counter()
        stop, splits, collapses = self.refine(allow_split)
        t2 = time.perf_counter()
        downloads, evicted = self._commit_frame()
        self.over_budget = False
        cut = np.sort(np.fromiter(self.cut, np.int64, len(self.cut)))
        t3 = time.perf_counter()
        timings = {"prioritize_ms": (t1 - t0) * 1e3, "refine_ms": (t2 - t1) * 1e3,
                   "commit_ms": (t3 - t2) * 1e3}
        return CutUpdate(cut, downloads, evicted, splits, collapses, stop, repaired, over,
                         timings)


class CutUpdater(SplitCollapse):
    """The rendering cut, updated frame to frame under N bricks and M downloads per frame.

    Parameters
    ----------
    metric : CutMetric or ArrayMetric
        Set its view or transfer function between frames; the updater notices (epochs).
    budget : int
        ``N``: brick slots of the renderer.
    load_budget : int or None
        ``M``: bricks downloaded per frame (None: unlimited).
    cut : array of node ids, optional
        Starting cut (default: the root, which is also what a first frame shows).
    fill : bool
        Set aside splits that do not fit and go on (see the module docstring; default: the
        paper's rule, stop there).

    Examples
    --------
    >>> updater = CutUpdater(metric, budget=2560, load_budget=164)   # doctest: +SKIP
    >>> metric.set_view(interest=(x, y, z), eye=camera_position)      # doctest: +SKIP
    >>> frame = updater.update()                                       # doctest: +SKIP
    >>> frame.downloads, frame.evicted, frame.cut                      # doctest: +SKIP
    """

    def __init__(self, metric: Any, budget: int, load_budget: int | None = None,
                 cut: Any = None, fill: bool = False):
        tree = metric.tree
        if cut is None:
            cut = [tree.root] if metric.visible[tree.root] else []
        super().__init__(metric, cut, budget, load_budget, count_ancestors=False, fill=fill)

    def update(self, in_ram: np.ndarray | None = None) -> CutUpdate:
        """Update the cut for the next frame.

        Parameters
        ----------
        in_ram : numpy.ndarray, optional
            Bool (K,): bricks the RAM cache holds. When given, only nodes whose visible children
            are all in RAM are split (section 4: a split never page-faults).
        """
        allow = None
        if in_ram is not None:
            in_ram = np.asarray(in_ram, bool)

            def allow(node: int) -> bool:
                return bool(in_ram[self.visible_children(node)].all())

        return self.step(allow)
