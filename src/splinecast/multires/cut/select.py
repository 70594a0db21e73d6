"""Cut selection from scratch: greedy by priority, and the exact optimum (Carmona & Froehlich
2011, sections 3.3-3.5).

A **cut** is a set of nodes that covers every visible (non-transparent) region of the volume
exactly once: no node of the cut is an ancestor of another, every visible leaf has exactly one cut
node on its path to the root, and no transparent node is in it. Its error is ``sum E(b)`` (eq. 8
divides by the covered voxel count, the same for every cut, so sums compare cuts).

* :func:`greedy_cut`: start from the root, split the node of highest priority while the split
  fits the brick budget ``N`` (classic priority-queue refinement, O(N log N)); with ``P = E`` this
  is the paper's "naive" selection, with ``P = ER`` its "improved" one.
* :func:`optimal_cut`: Algorithm 1, depth-first dynamic programming. Every node returns the best
  cut of exactly ``m`` bricks of its subtree for every ``m``; children are folded in one at a time
  (binary combines, entries beyond ``N`` dropped at once) and the node itself competes for
  ``m = 1``. The paper bounds it by O(K N^2); capping each table at the number of bricks the
  subtree can hold makes the total O(K N), the bound of tree knapsack.
* :func:`optimal_update`: the download-aware optimum of section 3.5: tables indexed by bricks
  ``m <= N`` and downloads ``k <= M``, a node costing one download unless it is resident,
  O(K N^2 M^2) (for small trees and budgets: a benchmark reference, not a frame-time algorithm).

A note on Algorithm 1 as printed: it initialises ``Result[1] = {b}`` and then combines the
children into ``Result``, which would put ``b`` and its descendants in one cut; its Fig. 2 trace
shows what is meant (node G lists its child's cut (Q,1,0) beside (G,1,1)): the children are
combined among themselves and ``b`` itself competes for ``m = 1``. That is what is done here.
"""

from __future__ import annotations

import heapq
from typing import Any

import numpy as np

from ..._jit import jit
from ...errors import ParameterError
from .tree import BrickTree

__all__ = ["greedy_cut", "optimal_cut", "optimal_cut_errors", "optimal_update"]


def greedy_cut(metric: Any, budget: int, fill: bool = False) -> np.ndarray:
    """Greedy refinement from the root under the brick budget ``N``.

    Parameters
    ----------
    metric : CutMetric or ArrayMetric
        Gives ``tree``, ``visible``, ``rank`` and ``priority(nodes)``.
    budget : int
        ``N``, the most bricks the cut may hold.
    fill : bool
        False (the paper's rule, and the fixed point of :class:`~.cut.update.CutUpdater`): stop
        at the first node whose split does not fit. True: keep that node unsplit and go on with
        the next ones, filling the budget with the splits that still fit.

    Returns
    -------
    numpy.ndarray
        Sorted node ids of the cut (empty when the root is transparent).

    Notes
    -----
    Pops the node of highest priority (ties: :func:`.cut.metric.rank`) and replaces it by its
    visible children, until the popped node's priority is not positive (no split reduces the
    error), or its split would exceed ``N``. The same stop rules as the update's, so that the
    update converges to this cut. With small budgets the first rule leaves up to
    ``children - 1`` slots unused and skips every smaller split behind a large one: on the
    MNI152 tree (N = 250 bricks of 16^3) that costs about 1% of E(cut) against the optimum,
    ``fill=True`` about 0.1%.
    """
    tree = metric.tree
    visible = metric.visible
    root = tree.root
    if not visible[root]:
        return np.zeros(0, np.int64)
    heap = [(-float(metric.priority([root])[0]), int(metric.rank[root]), root)]
    kept: list[int] = []  # nodes set aside unsplit (fill=True)
    count = 1
    while heap:
        neg, _, node = heap[0]
        if not -neg > 0.0:
            break
        kids = tree.children_of(node)
        kids = kids[visible[kids]]
        if count - 1 + kids.size > budget:
            if not fill:
                break
            kept.append(heapq.heappop(heap)[2])
            continue
        heapq.heappop(heap)
        count += kids.size - 1
        for kid, p in zip(kids.tolist(), metric.priority(kids).tolist(), strict=True):
            heapq.heappush(heap, (-p, int(metric.rank[kid]), kid))
    return np.sort(np.array([item[2] for item in heap] + kept, np.int64))


# ------------------------------------------------------------------------- dynamic programming
def _plan(tree: BrickTree, visible: np.ndarray, budget: int, root: int):
    """Post-order of the visible subtree of ``root``, its visible children and table caps."""
    if not visible[root]:
        raise ParameterError("the root of the selection is transparent: there is no cut")
    order = []
    stack = [root]
    while stack:  # pre-order, reversed below into a post-order (children before parents)
        node = stack.pop()
        order.append(node)
        kids = tree.children_of(node)
        stack.extend(kids[visible[kids]].tolist())
    post = np.array(order[::-1], np.int64)
    kid_start = np.zeros(tree.size + 1, np.int64)
    kids_all = tree.children_of_many(post)
    owner = np.repeat(post, tree.n_children[post])
    keep = visible[kids_all]
    kids_all, owner = kids_all[keep], owner[keep]
    counts = np.bincount(owner, minlength=tree.size)
    np.cumsum(counts, out=kid_start[1:])
    order_kids = np.argsort(owner, kind="stable")
    vis_kids = kids_all[order_kids]
    cap = np.minimum(tree.leaf_count(visible), budget).astype(np.int64)
    return post, kid_start, vis_kids, cap


@jit(nogil=True)
def _dp(post, kid_start, kids, cap, error, budget):
    """Algorithm 1 with capped tables. Returns per-node tables and the choices to backtrack."""
    k = error.shape[0]
    tab_at = np.zeros(k + 1, np.int64)
    # Table of node b: tab[tab_at[b] : tab_at[b] + cap[b] + 1], entry m = best error of m bricks.
    total = 0
    for b in post:
        tab_at[b] = total
        total += cap[b] + 1
    tab = np.full(total, np.inf)
    # Choice arrays: one per (node, child index >= 1), entry m = bricks taken by that child.
    choice_at = np.full(kids.shape[0] + 1, -1, np.int64)
    ctotal = 0
    for b in post:
        acc = 0
        for t in range(kid_start[b], kid_start[b + 1]):
            acc = min(acc + cap[kids[t]], budget) if t > kid_start[b] else cap[kids[t]]
            if t > kid_start[b]:
                choice_at[t] = ctotal
                ctotal += acc + 1
    choice = np.zeros(ctotal, np.int32)
    own = np.zeros(k, np.bool_)
    acc_tab = np.full(budget + 1, np.inf)
    new_tab = np.full(budget + 1, np.inf)
    for b in post:
        base = tab_at[b]
        first = kid_start[b]
        last = kid_start[b + 1]
        if first == last:
            tab[base + 1] = error[b]
            own[b] = True
            continue
        c0 = kids[first]
        acc_cap = cap[c0]
        for m in range(acc_cap + 1):
            acc_tab[m] = tab[tab_at[c0] + m]
        for t in range(first + 1, last):
            c = kids[t]
            cb = tab_at[c]
            new_cap = min(acc_cap + cap[c], budget)
            for m in range(new_cap + 1):
                new_tab[m] = np.inf
            at = choice_at[t]
            for i in range(1, acc_cap + 1):
                a = acc_tab[i]
                if a == np.inf:
                    continue
                for j in range(1, min(cap[c], new_cap - i) + 1):
                    v = a + tab[cb + j]
                    if v < new_tab[i + j]:
                        new_tab[i + j] = v
                        choice[at + i + j] = j
            for m in range(new_cap + 1):
                acc_tab[m] = new_tab[m]
            acc_cap = new_cap
        for m in range(acc_cap + 1):
            tab[base + m] = acc_tab[m]
        if error[b] <= tab[base + 1]:  # the node itself: one brick (ties: the coarser brick)
            tab[base + 1] = error[b]
            own[b] = True
    return tab, tab_at, choice, choice_at, own


@jit(nogil=True)
def _backtrack(root, m_root, kid_start, kids, cap, tab_at, choice, choice_at, own, budget):
    out = np.empty(m_root, np.int64)
    n = 0
    stack_node = np.empty(m_root * 64 + 64, np.int64)
    stack_m = np.empty(m_root * 64 + 64, np.int64)
    stack_node[0] = root
    stack_m[0] = m_root
    top = 1
    while top > 0:
        top -= 1
        b = stack_node[top]
        m = stack_m[top]
        if m == 1 and own[b]:
            out[n] = b
            n += 1
            continue
        first = kid_start[b]
        for t in range(kid_start[b + 1] - 1, first, -1):
            j = choice[choice_at[t] + m]
            stack_node[top] = kids[t]
            stack_m[top] = j
            top += 1
            m -= j
        stack_node[top] = kids[first]
        stack_m[top] = m
        top += 1
    return out[:n]


def _tables(tree: BrickTree, error: np.ndarray, visible: np.ndarray | None, budget: int,
            root: int | None):
    if budget < 1:
        raise ParameterError(f"the brick budget must be at least 1, got {budget}")
    visible = np.ones(tree.size, bool) if visible is None else np.asarray(visible, bool)
    root = tree.root if root is None else int(root)
    post, kid_start, kids, cap = _plan(tree, visible, int(budget), root)
    tab, tab_at, choice, choice_at, own = _dp(post, kid_start, kids, cap,
                                              np.asarray(error, np.float64), int(budget))
    return root, kid_start, kids, cap, tab, tab_at, choice, choice_at, own


def optimal_cut_errors(tree: BrickTree, error: np.ndarray, visible: np.ndarray | None,
                       budget: int, root: int | None = None) -> np.ndarray:
    """Best ``sum E`` of a cut of exactly ``m`` bricks of ``root``'s subtree, ``m = 0..N``.

    ``inf`` where no cut of that size exists (entry 0 always). The rows of Fig. 2's trace.
    """
    root, _, _, cap, tab, tab_at, *_ = _tables(tree, error, visible, budget, root)
    out = np.full(int(budget) + 1, np.inf)
    out[:cap[root] + 1] = tab[tab_at[root]:tab_at[root] + cap[root] + 1]
    out[0] = np.inf
    return out


def optimal_cut(tree: BrickTree, error: np.ndarray, visible: np.ndarray | None,
                budget: int) -> tuple[np.ndarray, float]:
    """The cut of at most ``N`` bricks with the smallest ``sum E`` (Algorithm 1).

    Returns
    -------
    cut : numpy.ndarray
        Sorted node ids.
    total : float
        Its ``sum E``. Among equally good cuts the one with the fewest bricks is returned.
    """
    root, kid_start, kids, cap, tab, tab_at, choice, choice_at, own = _tables(
        tree, error, visible, budget, None)
    row = tab[tab_at[root]:tab_at[root] + cap[root] + 1]
    m = int(np.argmin(row[1:])) + 1
    cut = _backtrack(root, m, kid_start, kids, cap, tab_at, choice, choice_at, own, int(budget))
    return np.sort(cut), float(row[m])


# ------------------------------------------------------------------- download-aware optimum
@jit(nogil=True)
def _dp_downloads(post, kid_start, kids, cap, error, cost, budget, load):
    """Tables over (bricks m, downloads d); entry = best error. Same plan as :func:`_dp`."""
    k = error.shape[0]
    width = load + 1
    tab_at = np.zeros(k + 1, np.int64)
    total = 0
    for b in post:
        tab_at[b] = total
        total += (cap[b] + 1) * width
    tab = np.full(total, np.inf)
    choice_at = np.full(kids.shape[0] + 1, -1, np.int64)
    ctotal = 0
    for b in post:
        acc = 0
        for t in range(kid_start[b], kid_start[b + 1]):
            acc = min(acc + cap[kids[t]], budget) if t > kid_start[b] else cap[kids[t]]
            if t > kid_start[b]:
                choice_at[t] = ctotal
                ctotal += (acc + 1) * width
    choice = np.zeros(ctotal, np.int64)  # j * width + dj taken by the child
    own = np.zeros(k * width, np.bool_)  # node b itself is the cut for (m = 1, d)
    acc_tab = np.full((budget + 1) * width, np.inf)
    new_tab = np.full((budget + 1) * width, np.inf)
    for b in post:
        base = tab_at[b]
        first = kid_start[b]
        last = kid_start[b + 1]
        if first < last:
            c0 = kids[first]
            acc_cap = cap[c0]
            for e in range((acc_cap + 1) * width):
                acc_tab[e] = tab[tab_at[c0] + e]
            for t in range(first + 1, last):
                c = kids[t]
                cb = tab_at[c]
                new_cap = min(acc_cap + cap[c], budget)
                for e in range((new_cap + 1) * width):
                    new_tab[e] = np.inf
                at = choice_at[t]
                for i in range(1, acc_cap + 1):
                    for di in range(width):
                        a = acc_tab[i * width + di]
                        if a == np.inf:
                            continue
                        for j in range(1, min(cap[c], new_cap - i) + 1):
                            for dj in range(width - di):
                                v = a + tab[cb + j * width + dj]
                                slot = (i + j) * width + di + dj
                                if v < new_tab[slot]:
                                    new_tab[slot] = v
                                    choice[at + slot] = j * width + dj
                for e in range((new_cap + 1) * width):
                    acc_tab[e] = new_tab[e]
                acc_cap = new_cap
            for e in range((acc_cap + 1) * width):
                tab[base + e] = acc_tab[e]
        d = cost[b]
        if d <= load and error[b] <= tab[base + width + d]:
            tab[base + width + d] = error[b]
            own[b * width + d] = True
    return tab, tab_at, choice, choice_at, own


@jit(nogil=True)
def _backtrack_downloads(root, m_root, d_root, kid_start, kids, choice, choice_at, own, width):
    out = np.empty(m_root, np.int64)
    n = 0
    stack_node = np.empty(m_root * 64 + 64, np.int64)
    stack_m = np.empty(m_root * 64 + 64, np.int64)
    stack_d = np.empty(m_root * 64 + 64, np.int64)
    stack_node[0] = root
    stack_m[0] = m_root
    stack_d[0] = d_root
    top = 1
    while top > 0:
        top -= 1
        b = stack_node[top]
        m = stack_m[top]
        d = stack_d[top]
        if m == 1 and own[b * width + d]:
            out[n] = b
            n += 1
            continue
        first = kid_start[b]
        for t in range(kid_start[b + 1] - 1, first, -1):
            code = choice[choice_at[t] + m * width + d]
            j = code // width
            dj = code % width
            stack_node[top] = kids[t]
            stack_m[top] = j
            stack_d[top] = dj
            top += 1
            m -= j
            d -= dj
        stack_node[top] = kids[first]
        stack_m[top] = m
        stack_d[top] = d
        top += 1
    return out[:n]


def optimal_update(tree: BrickTree, error: np.ndarray, visible: np.ndarray | None, budget: int,
                   load_budget: int, resident: np.ndarray) -> tuple[np.ndarray, float] | None:
    """The best cut reachable in one frame: at most ``N`` bricks, at most ``M`` downloads.

    Parameters
    ----------
    tree, error, visible, budget
        As :func:`optimal_cut`.
    load_budget : int
        ``M``: bricks that may be downloaded this frame.
    resident : numpy.ndarray
        Bool (K,): bricks already in the slots (the previous cut); any other node of the new
        cut is one download.

    Returns
    -------
    (cut, total) or None
        None when no valid cut needs at most ``M`` downloads.
    """
    if budget < 1 or load_budget < 0:
        raise ParameterError("need budget >= 1 and load_budget >= 0")
    visible = np.ones(tree.size, bool) if visible is None else np.asarray(visible, bool)
    post, kid_start, kids, cap = _plan(tree, visible, int(budget), tree.root)
    cost = np.where(np.asarray(resident, bool), 0, 1).astype(np.int64)
    width = int(load_budget) + 1
    tab, tab_at, choice, choice_at, own = _dp_downloads(
        post, kid_start, kids, cap, np.asarray(error, np.float64), cost, int(budget),
        int(load_budget))
    root = tree.root
    row = tab[tab_at[root]:tab_at[root] + (cap[root] + 1) * width].reshape(-1, width)
    row = row.copy()
    row[0] = np.inf
    best = int(np.argmin(row))
    if not np.isfinite(row.flat[best]):
        return None
    m, d = divmod(best, width)
    cut = _backtrack_downloads(root, m, d, kid_start, kids, choice, choice_at, own, width)
    return np.sort(cut), float(row[m, d])
