"""The error of a brick and the priority of splitting it (reference 002, eqs. 1-9).

* **Distortion** ``D(b)`` (eqs. 1-2): the CIELUV distance between the transfer-function-classified
  colours of the source voxels and of the brick's approximation, summed over the voxels, read from
  the brick's sparse 2D histogram (:mod:`.cut_histograms`) and the transfer function's pair table
  (:func:`.colour.distortion_table`): ``D(b) = sum H_b(u, v) D(u, v)``. A transfer-function edit
  recomputes it without reading a voxel.
* **Fix-up** (section 3.2.1, "block-based monotonicity"): where a parent's distortion is below the
  sum of its children's, it is replaced by that sum: ``D*(b) = max(D(b), sum_c D(c))`` over the
  visible children. It is applied one level deep, exactly as the paper words it, so ``D*(b)``
  needs only ``b``'s and its children's histograms, and a hull-only update gives the same numbers
  as a whole-tree one.
* **Importance** (eqs. 5-6): ``R(b, x) = diag(b) / (diag(b) + d(b, x))`` with ``d`` the distance
  from the brick's box to the interest point (0 inside); for a region of interest ``d`` is the mean
  of the box-to-region and box-to-region-centre distances; ``I(b) = (1 - t) R(b, x) + t R(b, eye)``
  with ``t = 1/4``. Without an eye ``I = R(b, x)``; without an interest point ``I = R(b, eye)``;
  with neither, ``I = 1``.
* **Error** ``E(b) = D*(b) I(b)`` (eq. 7) and ``E(cut) = sum E(b) / sum n(b)`` (eq. 8).
* **Error reduction per child** ``ER(b) = (E(b) - sum_c E(c)) / |c|`` (eq. 9), over the visible
  children.

Priorities. ``P = E`` ("naive") or ``P = ER`` ("improved") for nodes that can be split; a node
without visible children cannot, its priority is ``-inf``. Split-and-collapse converges to the
greedy cut only for a *monotonic* priority (reference 002 citing ROAM [19]): a child never ranks
above its parent. ``E`` is monotonic, ``ER`` is not always, so both are made monotonic the way
ROAM does: ``P(b) = min(P_raw(b), P(parent))``. For the greedy selection from the root this
changes nothing but the order of ties (a node enters the queue only after its parent was popped,
at which point the parent held the highest priority), and it makes the update's fixed point the
greedy cut. Ties are broken by a strict order in which a parent precedes its children: first by
depth, then by id (:func:`rank`).

Two implementations of one small protocol (``visible``, ``epoch``, ``tf_epoch``, ``priority``,
``error``) feed the selection and update algorithms: :class:`CutMetric` (histograms, transfer
function, interest point, eye; computed lazily per node and cached) and :class:`ArrayMetric`
(given per-node errors, for tests and abstract trees).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import prange

from .._jit import jit
from ..errors import ParameterError
from ..transfer import TransferFunction
from .colour import distortion_table
from .cut_histograms import BrickHistograms
from .cut_tree import BrickTree

__all__ = [
    "TRANSPARENCY_BINS",
    "visible_nodes",
    "histogram_distortion",
    "importance",
    "error_reduction",
    "monotone_priority",
    "rank",
    "cut_error",
    "ArrayMetric",
    "CutMetric",
]

#: Bins of the transparency prefix table T (section 3.6; the paper quantizes into 255 intervals).
TRANSPARENCY_BINS = 1024


# ----------------------------------------------------------------------------- transparency
def visible_nodes(tree: BrickTree, tf: TransferFunction, bins: int = TRANSPARENCY_BINS
                  ) -> np.ndarray:
    """Nodes that are not fully transparent under ``tf``: bool (K,).

    The prefix table ``T`` of section 3.6 (:meth:`TransferFunction.transparency_prefix`): a node
    whose values fall into bins ``a..b`` is transparent exactly when ``T[b + 1] == T[a]``, two
    reads per node. The ranges are hierarchical, so a transparent node has only transparent
    descendants.
    """
    table = tf.transparency_prefix(bins)
    lo, hi = tf.domain
    scale = bins / (hi - lo)
    a = np.clip(np.floor((tree.value_min - lo) * scale), 0, bins - 1).astype(np.int64)
    b = np.clip(np.floor((tree.value_max - lo) * scale), 0, bins - 1).astype(np.int64)
    return table[b + 1] != table[a]


# ------------------------------------------------------------------------------ distortion
@jit(parallel=True, nogil=True)
def _sum_distortion(offsets, keys, counts, table, nodes, out):
    for t in prange(nodes.shape[0]):
        b = nodes[t]
        acc = 0.0
        for e in range(offsets[b], offsets[b + 1]):
            acc += counts[e] * table[keys[e]]
        out[t] = acc


def histogram_distortion(hist: BrickHistograms, table: np.ndarray,
                         nodes: np.ndarray | None = None) -> np.ndarray:
    """Raw ``D(b) = sum H_b(u, v) D(u, v)`` (eq. 1) for ``nodes`` (default: all).

    ``table`` is :func:`.colour.distortion_table` for the histograms' bin values.
    """
    if nodes is None:
        nodes = np.arange(hist.offsets.shape[0] - 1)
    nodes = np.ascontiguousarray(nodes, np.int64)
    out = np.empty(nodes.shape[0], np.float64)
    _sum_distortion(hist.offsets, hist.keys, hist.counts, np.ascontiguousarray(table).ravel(),
                    nodes, out)
    return out


# ------------------------------------------------------------------------------ importance
def _box_point_distance(box_min: np.ndarray, box_max: np.ndarray, p: np.ndarray) -> np.ndarray:
    gap = np.maximum(np.maximum(box_min - p, p - box_max), 0.0)
    return np.sqrt(np.einsum("ij,ij->i", gap, gap))


def _box_box_distance(box_min: np.ndarray, box_max: np.ndarray, lo: np.ndarray,
                      hi: np.ndarray) -> np.ndarray:
    gap = np.maximum(np.maximum(box_min - hi, lo - box_max), 0.0)
    return np.sqrt(np.einsum("ij,ij->i", gap, gap))


def importance(box_min: np.ndarray, box_max: np.ndarray, interest: Any = None,
               region: Any = None, eye: Any = None, t: float = 0.25) -> np.ndarray:
    """``I(b)`` of eqs. (5)-(6) for boxes ``(n, 3)``.

    Parameters
    ----------
    box_min, box_max : numpy.ndarray
        World-space boxes of the bricks.
    interest : 3 floats, optional
        Point of interest (PI), world coordinates.
    region : ((x0, y0, z0), (x1, y1, z1)), optional
        Region of interest (ROI) as a world box; replaces ``interest``.
    eye : 3 floats, optional
        Viewpoint.
    t : float
        Weight of the eye term (the paper's choice, 1/4).
    """
    box_min = np.asarray(box_min, np.float64).reshape(-1, 3)
    box_max = np.asarray(box_max, np.float64).reshape(-1, 3)
    diag = np.linalg.norm(box_max - box_min, axis=1)

    def ratio(d: np.ndarray) -> np.ndarray:
        den = diag + d
        return np.where(den > 0, diag / np.where(den > 0, den, 1.0), 1.0)

    d_x = None
    if region is not None:
        lo, hi = (np.asarray(v, np.float64).reshape(3) for v in region)
        d_x = 0.5 * (_box_box_distance(box_min, box_max, lo, hi)
                     + _box_point_distance(box_min, box_max, 0.5 * (lo + hi)))
    elif interest is not None:
        d_x = _box_point_distance(box_min, box_max, np.asarray(interest, np.float64).reshape(3))
    d_eye = None if eye is None else _box_point_distance(
        box_min, box_max, np.asarray(eye, np.float64).reshape(3))
    if d_x is not None and d_eye is not None:
        return (1.0 - t) * ratio(d_x) + t * ratio(d_eye)
    if d_x is not None:
        return ratio(d_x)
    if d_eye is not None:
        return ratio(d_eye)
    return np.ones(diag.shape[0])


# ---------------------------------------------------------------------- reduction, priority
def error_reduction(tree: BrickTree, error: np.ndarray, visible: np.ndarray,
                    nodes: np.ndarray | None = None) -> np.ndarray:
    """``ER(b)`` of eq. (9) over visible children; ``-inf`` for nodes without any."""
    nodes = np.arange(tree.size) if nodes is None else np.asarray(nodes, np.int64)
    kids, owner = tree.children_with_owner(nodes, np.asarray(visible, bool))
    total = np.bincount(owner, weights=error[kids], minlength=nodes.shape[0])
    count = np.bincount(owner, minlength=nodes.shape[0])
    with np.errstate(invalid="ignore", divide="ignore"):
        er = (error[nodes] - total) / count
    return np.where(count > 0, er, -np.inf)


def monotone_priority(tree: BrickTree, raw: np.ndarray) -> np.ndarray:
    """``P(b) = min(raw(b), P(parent))`` for every node (root first)."""
    p = np.asarray(raw, np.float64).copy()
    for nodes in tree.depth_layers()[1:]:
        p[nodes] = np.minimum(p[nodes], p[tree.parent[nodes]])
    return p


def rank(tree: BrickTree) -> np.ndarray:
    """Tie-break order (int64, smaller first): by depth, then id; a parent precedes its children."""
    return tree.depth.astype(np.int64) * tree.size + np.arange(tree.size)


def cut_error(tree: BrickTree, error: np.ndarray, cut: np.ndarray) -> float:
    """``E(cut)`` of eq. (8): the cut's summed error per source voxel it covers."""
    cut = np.asarray(cut, np.int64)
    return float(error[cut].sum() / max(int(tree.voxels[cut].sum()), 1))


# ------------------------------------------------------------------------------- protocol
class ArrayMetric:
    """Priorities from given per-node errors ``E`` (abstract trees, tests, benchmarks).

    Parameters
    ----------
    tree : BrickTree
    error : numpy.ndarray
        ``E(b)`` for every node.
    visible : numpy.ndarray, optional
        Non-transparent nodes (default all). Must be hierarchical (a visible node's ancestors
        visible).
    improved : bool
        ``P = ER`` (True) or ``P = E`` (False), both made monotonic.
    """

    def __init__(self, tree: BrickTree, error: np.ndarray, visible: np.ndarray | None = None,
                 improved: bool = True):
        self.tree = tree
        self.improved = improved
        self.epoch = 0
        self.tf_epoch = 0
        self.rank = rank(tree)
        self.visible: np.ndarray | None = None
        self.set(error, visible)

    def set(self, error: np.ndarray, visible: np.ndarray | None = None) -> None:
        """New errors (and visibility): a new epoch; a new ``tf_epoch`` when visibility changed."""
        tree = self.tree
        new_visible = np.ones(tree.size, bool) if visible is None else np.array(visible, bool)
        if self.visible is not None and not np.array_equal(new_visible, self.visible):
            self.tf_epoch += 1
        self.visible = new_visible
        self._error = np.asarray(error, np.float64)
        reduction = error_reduction(tree, self._error, self.visible)
        raw = reduction if self.improved else np.where(np.isfinite(reduction), self._error,
                                                       -np.inf)
        self._priority = monotone_priority(tree, raw)
        self.epoch += 1

    def error(self, nodes: np.ndarray) -> np.ndarray:
        """``E`` of ``nodes``."""
        return self._error[np.asarray(nodes, np.int64)]

    def priority(self, nodes: np.ndarray) -> np.ndarray:
        """Monotone priority of ``nodes``."""
        return self._priority[np.asarray(nodes, np.int64)]

    def all_errors(self) -> np.ndarray:
        """``E`` of every node."""
        return self._error


class CutMetric:
    """``E``, ``ER`` and priorities of a brick pyramid under a transfer function and a view.

    Values are computed per node when first asked for and cached until the transfer function
    (distortion, visibility) or the view (importance) changes, so a frame touches only the nodes
    the cut algorithms look at: the hull (the cut, its ancestors, its children; reference 002
    section 3.6) and the children of nodes split this frame.

    Parameters
    ----------
    tree : BrickTree
        With value ranges (transparency).
    histograms : BrickHistograms
        One entry range per node of ``tree``.
    tf : TransferFunction
    interest, region, eye : optional
        See :func:`importance`.
    improved : bool
        ``P = ER`` (True, the paper's "improved") or ``P = E`` ("naive").
    t : float
        Eye weight of eq. (6).
    """

    def __init__(self, tree: BrickTree, histograms: BrickHistograms, tf: TransferFunction, *,
                 interest: Any = None, region: Any = None, eye: Any = None,
                 improved: bool = True, t: float = 0.25):
        if histograms.offsets.shape[0] != tree.size + 1:
            raise ParameterError(f"histograms describe {histograms.offsets.shape[0] - 1} nodes, "
                                 f"the tree has {tree.size}")
        self.tree = tree
        self.histograms = histograms
        self.improved = improved
        self.t = t
        self.rank = rank(tree)
        k = tree.size
        self.epoch = 0
        self.tf_epoch = 0
        self._view_epoch = 0
        self._raw = np.zeros(k)
        self._raw_at = np.full(k, -1, np.int64)      # tf_epoch the raw D was computed for
        self._fixed = np.zeros(k)
        self._fixed_at = np.full(k, -1, np.int64)
        self._imp = np.zeros(k)
        self._imp_at = np.full(k, -1, np.int64)      # view epoch
        self._prio = np.zeros(k)
        self._prio_at = np.full(k, -1, np.int64)     # epoch
        self._has_hist = histograms.offsets[1:] > histograms.offsets[:-1]
        self.set_transfer_function(tf)
        self.set_view(interest=interest, region=region, eye=eye)

    # ------------------------------------------------------------------------------ inputs
    def set_transfer_function(self, tf: TransferFunction) -> None:
        """New transfer function: new pair table and visibility; every D becomes stale."""
        self.tf = tf
        self.table = distortion_table(tf, self.histograms.quantizer.values).ravel()
        self.visible = visible_nodes(self.tree, tf)
        self.tf_epoch += 1
        self.epoch += 1

    def set_view(self, interest: Any = None, region: Any = None, eye: Any = None) -> None:
        """New interest point or region and eye: every importance becomes stale."""
        self.interest, self.region, self.eye = interest, region, eye
        self._view_epoch += 1
        self.epoch += 1

    # ---------------------------------------------------------------------------- per node
    def raw_distortion(self, nodes: np.ndarray) -> np.ndarray:
        """``D(b)`` from the histograms (eq. 1), computed for stale nodes only."""
        nodes = np.asarray(nodes, np.int64)
        stale = nodes[self._raw_at[nodes] != self.tf_epoch]
        if stale.size:
            stale = np.unique(stale)
            with_hist = stale[self._has_hist[stale]]
            self._raw[stale] = 0.0
            if with_hist.size:
                self._raw[with_hist] = histogram_distortion(self.histograms, self.table,
                                                            with_hist)
            self._raw_at[stale] = self.tf_epoch
        return self._raw[nodes]

    def distortion(self, nodes: np.ndarray) -> np.ndarray:
        """``D*(b) = max(D(b), sum of the visible children's D)``: the fixed-up distortion."""
        nodes = np.asarray(nodes, np.int64)
        stale = nodes[self._fixed_at[nodes] != self.tf_epoch]
        if stale.size:
            stale = np.unique(stale)
            kids, owner = self.tree.children_with_owner(stale, self.visible)
            below = np.bincount(owner, weights=self.raw_distortion(kids),
                                minlength=stale.shape[0])
            self._fixed[stale] = np.maximum(self.raw_distortion(stale), below)
            self._fixed_at[stale] = self.tf_epoch
        return self._fixed[nodes]

    def importance(self, nodes: np.ndarray) -> np.ndarray:
        """``I(b)`` (eq. 6) under the current view."""
        nodes = np.asarray(nodes, np.int64)
        stale = nodes[self._imp_at[nodes] != self._view_epoch]
        if stale.size:
            self._imp[stale] = importance(self.tree.box_min[stale], self.tree.box_max[stale],
                                          self.interest, self.region, self.eye, self.t)
            self._imp_at[stale] = self._view_epoch
        return self._imp[nodes]

    def error(self, nodes: np.ndarray) -> np.ndarray:
        """``E(b) = D*(b) I(b)`` (eq. 7)."""
        return self.distortion(nodes) * self.importance(nodes)

    def error_reduction(self, nodes: np.ndarray) -> np.ndarray:
        """``ER(b)`` (eq. 9); ``-inf`` for nodes without visible children."""
        nodes = np.asarray(nodes, np.int64)
        kids, owner = self.tree.children_with_owner(nodes, self.visible)
        total = np.bincount(owner, weights=self.error(kids), minlength=nodes.shape[0])
        count = np.bincount(owner, minlength=nodes.shape[0])
        with np.errstate(invalid="ignore", divide="ignore"):
            er = (self.error(nodes) - total) / count
        return np.where(count > 0, er, -np.inf)

    def priority(self, nodes: np.ndarray) -> np.ndarray:
        """Monotone split priority of ``nodes`` (computing the ancestors' first when stale)."""
        nodes = np.asarray(nodes, np.int64)
        stale = nodes[self._prio_at[nodes] != self.epoch]
        if stale.size:
            stale = np.unique(stale)
            parents = self.tree.parent[stale]
            parents = parents[parents >= 0]
            missing = np.unique(parents[self._prio_at[parents] != self.epoch])
            if missing.size:
                self.priority(missing)  # recursion depth is at most the tree's depth
            if self.improved:
                raw = self.error_reduction(stale)
            else:
                splittable = np.isfinite(self.error_reduction(stale))
                raw = np.where(splittable, self.error(stale), -np.inf)
            par = self.tree.parent[stale]
            cap = np.where(par >= 0, self._prio[np.maximum(par, 0)], np.inf)
            self._prio[stale] = np.minimum(raw, cap)
            self._prio_at[stale] = self.epoch
        return self._prio[nodes]

    # -------------------------------------------------------------------------- whole tree
    def update_all_distortions(self) -> np.ndarray:
        """Recompute ``D*`` for every node (the "full octree" update); returns it."""
        everything = np.arange(self.tree.size)
        self._raw_at[:] = -1
        self._fixed_at[:] = -1
        return self.distortion(everything)

    def all_errors(self) -> np.ndarray:
        """``E`` of every node (whole tree; for references and benchmarks)."""
        return self.error(np.arange(self.tree.size))
