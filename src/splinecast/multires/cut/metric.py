"""The error of a brick and the priority of splitting it (Carmona & Froehlich 2011, eqs. 1-9).

* **Distortion** ``D(b)`` (eqs. 1-2): the CIELUV distance between the transfer-function-classified
  colours of the source voxels and of the brick's approximation, summed over the voxels, read from
  the brick's sparse 2D histogram (:mod:`.cut.histograms`) and the transfer function's pair table
  (:func:`.cut.colour.distortion_table`): ``D(b) = sum H_b(u, v) D(u, v)``. A transfer-function edit
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
* **Error** ``E(b) = D*(b) I(b)`` (eq. 7) and ``E(cut)``, the summed error per source voxel
  (eq. 8; :func:`cut_error` says which voxels).
* **Error reduction per child** ``ER(b) = (E(b) - sum_c E(c)) / |c|`` (eq. 9), over the visible
  children.

Priorities. ``P = E`` ("naive") or ``P = ER`` ("improved") for nodes that can be split; a node
without visible children cannot, its priority is ``-inf``. Split-and-collapse converges to the
greedy cut only for a *monotonic* priority (Carmona & Froehlich 2011, after the ROAM terrain
algorithm of Duchaineau et al. 1997): a child never ranks above its parent. ``E`` is monotonic,
``ER`` is not always (on the MNI152 tree about 1% of the nodes out-rank their parent), so a node's
priority is capped at its parent's:
``P(b) = min(P_raw(b), P(parent))``. The greedy selection from the root pops the same nodes in
the same order except within a group capped to one value (a node enters the queue only after its
parent was popped, when the parent held the highest priority), and the update's fixed point becomes
the greedy cut. Ties are broken by a strict order in which a parent precedes its children: first
by depth, then by id (:func:`rank`).

Two classes share one small protocol (``tree``, ``visible``, ``rank``, ``epoch``, ``tf_epoch``,
``priority(nodes)``, ``error(nodes)``) that the selection and update algorithms use:
:class:`CutMetric` (histograms, transfer function, interest point or region, eye) and
:class:`ArrayMetric` (given per-node errors, for abstract trees and tests). Both compute per node,
in compiled code, only what is asked for and cache it until an input changes (the epochs): a frame
touches the hull (the cut, its ancestors, its children, and the grandchildren the fix-up reads) and
the children of the nodes it splits, never the whole tree.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numba import prange

from ..._jit import jit, read_only
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
)
from ...errors import ParameterError
from ...transfer import TransferFunction
from .colour import distortion_table
from .histograms import BrickHistograms
from .tree import BrickTree

__all__ = [
    "TRANSPARENCY_BINS",
    "visible_nodes",
    "histogram_distortion",
    "importance",
    "frustum_planes",
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
@jit(nogil=True, inline="always")
def _node_distortion(offsets, keys, counts, table, b):
    acc = 0.0
    for e in range(offsets[b], offsets[b + 1]):
        acc += counts[e] * table[keys[e]]
    return acc


@jit(parallel=True, nogil=True)
def _sum_distortion_parallel(offsets, keys, counts, table, nodes, out):
    for t in prange(nodes.shape[0]):
        out[t] = _node_distortion(offsets, keys, counts, table, nodes[t])


def histogram_distortion(hist: BrickHistograms, table: np.ndarray,
                         nodes: np.ndarray | None = None) -> np.ndarray:
    """Raw ``D(b) = sum H_b(u, v) D(u, v)`` (eq. 1) for ``nodes`` (default: all), in parallel.

    ``table`` is :func:`.cut.colour.distortion_table` for the histograms' bin values.
    """
    if nodes is None:
        nodes = np.arange(hist.offsets.shape[0] - 1)
    nodes = np.ascontiguousarray(nodes, np.int64)
    out = np.empty(nodes.shape[0], np.float64)
    _sum_distortion_parallel(hist.offsets, hist.keys, hist.counts,
                             np.ascontiguousarray(table, np.float64).ravel(), nodes, out)
    return out


# ------------------------------------------------------------------------------ importance
# A view is a float64 vector: [has_interest, is_region, px, py, pz, lo xyz, hi xyz, has_eye,
# ex, ey, ez, t, frustum planes, margin, 6 x (nx, ny, nz, d)]; built by _view_vector.
_VIEW_SIZE = 42
_PLANES = 18  # index of the first frustum plane


def frustum_planes(camera: Any) -> np.ndarray:
    """The half-spaces ``n . x + d >= 0`` (``(5, 4)``, unit ``n``) holding every ray of ``camera``.

    Four side planes through the edges of the camera's image window (of its tile, for a tile
    camera) and the plane through the eye facing forward (no far plane: rays are unbounded).
    """
    basis = camera.pixel_basis()
    eye, forward = basis[BASIS_EYE:BASIS_EYE + 3], basis[BASIS_FORWARD:BASIS_FORWARD + 3]
    right, up = basis[BASIS_RIGHT:BASIS_RIGHT + 3], basis[BASIS_UP:BASIS_UP + 3]
    half_w, half_h = basis[BASIS_HALF_WIDTH], basis[BASIS_HALF_HEIGHT]
    ortho = basis[BASIS_ORTHO] != 0.0
    col0, row0 = basis[BASIS_COL0], basis[BASIS_ROW0]
    full_w, full_h = basis[BASIS_FULL_WIDTH], basis[BASIS_FULL_HEIGHT]
    x_lo = (col0 / full_w * 2.0 - 1.0) * half_w
    x_hi = ((col0 + camera.width) / full_w * 2.0 - 1.0) * half_w
    y_hi = (1.0 - row0 / full_h * 2.0) * half_h
    y_lo = (1.0 - (row0 + camera.height) / full_h * 2.0) * half_h
    planes = []
    if ortho:  # x_lo <= (p - eye) . right <= x_hi, the same for up
        sides = [(right, -x_lo), (-right, x_hi), (up, -y_lo), (-up, y_hi)]
        for n, off in sides:
            planes.append((*n, off - float(n @ eye)))
    else:  # x_lo (q . forward) <= q . right <= x_hi (q . forward), q = p - eye
        for n in (right - x_lo * forward, x_hi * forward - right, up - y_lo * forward,
                  y_hi * forward - up):
            n = n / np.linalg.norm(n)
            planes.append((*n, -float(n @ eye)))
    planes.append((*forward, -float(forward @ eye)))
    return np.asarray(planes, np.float64)


def _view_vector(interest: Any, region: Any, eye: Any, t: float, frustum: Any = None,
                 margin: float = 0.0) -> np.ndarray:
    v = np.zeros(_VIEW_SIZE)
    if frustum is not None:
        planes = np.asarray(frustum, np.float64).reshape(-1, 4)
        v[16] = planes.shape[0]
        v[17] = margin
        v[_PLANES:_PLANES + planes.size] = planes.ravel()
    if region is not None:
        lo, hi = (np.asarray(x, np.float64).reshape(3) for x in region)
        v[0:2] = 1.0
        v[2:5] = 0.5 * (lo + hi)
        v[5:8], v[8:11] = lo, hi
    elif interest is not None:
        v[0] = 1.0
        v[2:5] = np.asarray(interest, np.float64).reshape(3)
    if eye is not None:
        v[11] = 1.0
        v[12:15] = np.asarray(eye, np.float64).reshape(3)
    v[15] = t
    return v


@jit(nogil=True, inline="always")
def _gap(a0, a1, b0, b1):
    """Distance between the intervals [a0, a1] and [b0, b1] (0 when they overlap)."""
    return max(b0 - a1, a0 - b1, 0.0)


@jit(nogil=True, inline="always")
def _importance_one(box_min, box_max, b, view):
    """Eqs. (5)-(6) for box ``b`` (scalar reads: a row slice would cost an array object)."""
    x0, y0, z0 = box_min[b, 0], box_min[b, 1], box_min[b, 2]
    x1, y1, z1 = box_max[b, 0], box_max[b, 1], box_max[b, 2]
    diag = np.sqrt((x1 - x0) ** 2 + (y1 - y0) ** 2 + (z1 - z0) ** 2)
    r_x = -1.0
    if view[0] != 0.0:
        g0 = _gap(x0, x1, view[2], view[2])
        g1 = _gap(y0, y1, view[3], view[3])
        g2 = _gap(z0, z1, view[4], view[4])
        d = np.sqrt(g0 * g0 + g1 * g1 + g2 * g2)  # to the point, or to the region's centre
        if view[1] != 0.0:
            g0 = _gap(x0, x1, view[5], view[8])
            g1 = _gap(y0, y1, view[6], view[9])
            g2 = _gap(z0, z1, view[7], view[10])
            d = 0.5 * (d + np.sqrt(g0 * g0 + g1 * g1 + g2 * g2))
        r_x = diag / (diag + d) if diag + d > 0.0 else 1.0
    r_eye = -1.0
    if view[11] != 0.0:
        g0 = _gap(x0, x1, view[12], view[12])
        g1 = _gap(y0, y1, view[13], view[13])
        g2 = _gap(z0, z1, view[14], view[14])
        d = np.sqrt(g0 * g0 + g1 * g1 + g2 * g2)
        r_eye = diag / (diag + d) if diag + d > 0.0 else 1.0
    # Frustum culling: a box entirely behind one plane (by more than the margin) is out of view.
    for p in range(int(view[16])):
        q = _PLANES + 4 * p
        nx, ny, nz = view[q], view[q + 1], view[q + 2]
        reach = (nx * 0.5 * (x0 + x1) + ny * 0.5 * (y0 + y1) + nz * 0.5 * (z0 + z1) + view[q + 3]
                 + 0.5 * (abs(nx) * (x1 - x0) + abs(ny) * (y1 - y0) + abs(nz) * (z1 - z0)))
        if reach < -view[17]:
            return 0.0
    if r_x >= 0.0 and r_eye >= 0.0:
        return (1.0 - view[15]) * r_x + view[15] * r_eye
    if r_x >= 0.0:
        return r_x
    if r_eye >= 0.0:
        return r_eye
    return 1.0


@jit(nogil=True)
def _importance_boxes(box_min, box_max, view, out):
    for i in range(box_min.shape[0]):
        out[i] = _importance_one(box_min, box_max, i, view)


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
    box_min = np.ascontiguousarray(box_min, np.float64).reshape(-1, 3)
    box_max = np.ascontiguousarray(box_max, np.float64).reshape(-1, 3)
    out = np.empty(box_min.shape[0])
    # Read-only views: a tree's boxes are read-only, a caller's may not be (one compile for both).
    _importance_boxes(read_only(box_min), read_only(box_max),
                      _view_vector(interest, region, eye, t), out)
    return out


# ---------------------------------------------------------------- per-node lazy computation
class _State(NamedTuple):
    """Everything the compiled per-node functions read and cache (one metric's state).

    ``epochs`` holds [transfer-function epoch, view epoch, priority epoch, improved (0/1)]; a
    cached value is valid when its ``*_at`` entry equals the matching epoch.
    """

    parent: np.ndarray
    child_start: np.ndarray
    children: np.ndarray
    visible: np.ndarray
    box_min: np.ndarray
    box_max: np.ndarray
    h_offsets: np.ndarray
    h_keys: np.ndarray
    h_counts: np.ndarray
    table: np.ndarray
    viewing: np.ndarray
    epochs: np.ndarray
    raw: np.ndarray
    raw_at: np.ndarray
    fixed: np.ndarray
    fixed_at: np.ndarray
    imp: np.ndarray
    imp_at: np.ndarray
    prio: np.ndarray
    prio_at: np.ndarray
    stack: np.ndarray


class _Distortion(NamedTuple):
    """The arrays D and D* are made from: the tree's children and visibility, the histograms
    and the transparency table, and the two caches with their epochs."""

    child_start: np.ndarray
    children: np.ndarray
    visible: np.ndarray
    offsets: np.ndarray
    keys: np.ndarray
    counts: np.ndarray
    table: np.ndarray
    raw: np.ndarray
    raw_at: np.ndarray
    fixed: np.ndarray
    fixed_at: np.ndarray


class _Importance(NamedTuple):
    """The arrays I is made from: the boxes, the view vector, and the cache with its epochs."""

    box_min: np.ndarray
    box_max: np.ndarray
    viewing: np.ndarray
    imp: np.ndarray
    imp_at: np.ndarray


# The per-node functions test the caches in line; only a cache miss calls a (non-inlined) fill
# function. They take the state's arrays in the two groups above, made once per kernel call.
# Reading an array out of a tuple costs reference-count updates in compiled code that counts
# them (~100 ns per node for these groups), so the per-node fill function is compiled without
# counting (it allocates nothing), and the inlined helpers below are only reached through it
# or on a cache miss.
@jit(nogil=True, inline="always")
def _raw_fill(d, tf, b):
    """D(b) from the histogram (eq. 1), stored in the cache ``d.raw``."""
    d.raw[b] = _node_distortion(d.offsets, d.keys, d.counts, d.table, b)
    d.raw_at[b] = tf
    return d.raw[b]


@jit(nogil=True, inline="always")
def _fixed_fill(d, tf, b):
    """D*(b) = max(D(b), sum of the visible children's D): the fix-up of section 3.2.1."""
    child_start, children, visible, raw, raw_at = (d.child_start, d.children, d.visible, d.raw,
                                                    d.raw_at)
    below = 0.0
    for t in range(child_start[b], child_start[b + 1]):
        k = children[t]
        if visible[k]:
            below += raw[k] if raw_at[k] == tf else _raw_fill(d, tf, k)
    own = raw[b] if raw_at[b] == tf else _raw_fill(d, tf, b)
    d.fixed[b] = max(own, below)
    d.fixed_at[b] = tf
    return d.fixed[b]


@jit(nogil=True, _nrt=False)
def _fill_family(d, i, tf, view, b):
    """Make D* and I of ``b`` and of its visible children valid (E = D* I, eq. 7); ``d`` and
    ``i`` are the :class:`_Distortion` and :class:`_Importance` arrays."""
    child_start, children, visible, fixed_at = d.child_start, d.children, d.visible, d.fixed_at
    imp, imp_at = i.imp, i.imp_at
    for t in range(child_start[b], child_start[b + 1] + 1):
        k = children[t] if t < child_start[b + 1] else b   # the children, then b itself
        if k != b and not visible[k]:
            continue
        if fixed_at[k] != tf:
            _fixed_fill(d, tf, k)
        if imp_at[k] != view:  # in line: a call per node would cost more than the formula
            imp[k] = _importance_one(i.box_min, i.box_max, k, i.viewing)
            imp_at[k] = view


@jit(nogil=True, inline="always")
def _er_cached(child_start, children, visible, fixed, imp, b):
    """ER(b) (eq. 9) from valid D* and I; -inf without visible children."""
    total = 0.0
    count = 0
    for t in range(child_start[b], child_start[b + 1]):
        k = children[t]
        if visible[k]:
            total += fixed[k] * imp[k]
            count += 1
    if count == 0:
        return -np.inf
    return (fixed[b] * imp[b] - total) / count


@jit(nogil=True)
def _priorities(s, tf, view, epoch, improved, nodes, out):
    """Monotone priorities ``min(P_raw(b), P(parent))`` of ``nodes`` (P_raw = ER, or E for the
    naive priority), stale ancestors first, in three passes: list the stale nodes parents first,
    fill the E of each and of its visible children, then ER and P. ``s`` is the metric's
    :class:`_State`, unpacked once here (see above); ``tf``, ``view``, ``epoch``: the current
    epochs, ``improved``: the improved priority (ER) rather than the naive one (E)."""
    (parent, child_start, children, visible, box_min, box_max, offsets, keys, counts, table,
     viewing, _, raw, raw_at, fixed, fixed_at, imp, imp_at, prio, prio_at, stack) = s
    d = _Distortion(child_start, children, visible, offsets, keys, counts, table, raw, raw_at,
                    fixed, fixed_at)
    i_groups = _Importance(box_min, box_max, viewing, imp, imp_at)
    todo = np.empty(nodes.shape[0] * (stack.shape[0] + 1), np.int64)
    n = 0
    for i in range(nodes.shape[0]):
        top = 0
        a = nodes[i]
        while a >= 0 and prio_at[a] != epoch and prio_at[a] != -2:
            stack[top] = a
            top += 1
            a = parent[a]
        while top > 0:  # root side first, so a parent precedes its children in todo
            top -= 1
            todo[n] = stack[top]
            prio_at[stack[top]] = -2  # queued
            n += 1
    for j in range(n):
        _fill_family(d, i_groups, tf, view, todo[j])
    for j in range(n):
        b = todo[j]
        p = _er_cached(child_start, children, visible, fixed, imp, b)
        if not improved and p != -np.inf:
            p = fixed[b] * imp[b]  # naive: P = E for splittable nodes
        a = parent[b]
        prio[b] = min(p, prio[a]) if a >= 0 else p
        prio_at[b] = epoch
    for i in range(nodes.shape[0]):
        out[i] = prio[nodes[i]]


@jit(nogil=True)
def _map_nodes(s, nodes, what, out):
    """One of the per-node quantities (``what``: see _PRIORITY...) for every node of ``nodes``.

    Priorities are ``min(P_raw(b), P(parent))`` (P_raw = ER, or E for the naive priority), the
    stale ancestors of a node computed first, root down.
    """
    (parent, child_start, children, visible, box_min, box_max, offsets, keys, counts, table,
     viewing, epochs, raw, raw_at, fixed, fixed_at, imp, imp_at, prio, prio_at, stack) = s
    tf, view, epoch, improved = epochs[0], epochs[1], epochs[2], epochs[3]
    d = _Distortion(child_start, children, visible, offsets, keys, counts, table, raw, raw_at,
                    fixed, fixed_at)
    i_groups = _Importance(box_min, box_max, viewing, imp, imp_at)
    if what == 0:
        _priorities(s, tf, view, epoch, improved, nodes, out)
        return
    for i in range(nodes.shape[0]):
        b = nodes[i]
        if what == 3:
            out[i] = raw[b] if raw_at[b] == tf else _raw_fill(d, tf, b)
        elif what == 2 or what == 1:
            fixed_b = fixed[b] if fixed_at[b] == tf else _fixed_fill(d, tf, b)
            if what == 2:
                out[i] = fixed_b
            else:
                if imp_at[b] != view:
                    imp[b] = _importance_one(box_min, box_max, b, viewing)
                    imp_at[b] = view
                out[i] = fixed_b * imp[b]
        elif what == 4:
            if imp_at[b] != view:
                imp[b] = _importance_one(box_min, box_max, b, viewing)
                imp_at[b] = view
            out[i] = imp[b]
        else:
            _fill_family(d, i_groups, tf, view, b)
            out[i] = _er_cached(child_start, children, visible, fixed, imp, b)


_PRIORITY, _ERROR, _FIXED, _RAW, _IMPORTANCE, _REDUCTION = range(6)


def rank(tree: BrickTree) -> np.ndarray:
    """Tie-break order (int64, smaller first): by depth, then id; a parent precedes its children."""
    return tree.depth.astype(np.int64) * tree.size + np.arange(tree.size)


def cut_error(tree: BrickTree, error: np.ndarray, cut: np.ndarray, visible: np.ndarray) -> float:
    """``E(cut)`` of eq. (8): the cut's summed error per source voxel of the visible region.

    Eq. (8) divides by ``sum n(b)`` over the cut, "the number of source voxels approximated by
    the cut", a constant the paper then drops. With transparent bricks left out it is not quite
    constant (a coarse brick also covers its transparent children's voxels), so we divide by the
    voxels of the visible finest bricks, the same for every cut: comparing cuts by E(cut) is then
    comparing their error sums, which is what the optimum minimizes.
    """
    cut = np.asarray(cut, np.int64)
    visible = np.asarray(visible, bool)
    kids_visible = np.zeros(tree.size, bool)
    child = np.flatnonzero((tree.parent >= 0) & visible)
    kids_visible[tree.parent[child]] = True
    region = int(tree.voxels[visible & ~kids_visible].sum())
    return float(error[cut].sum() / max(region, 1))


class _LazyMetric:
    """Caches, epochs and the per-node queries shared by :class:`CutMetric` and
    :class:`ArrayMetric`."""

    def __init__(self, tree: BrickTree, histograms: BrickHistograms | None, improved: bool,
                 t: float):
        k = tree.size
        self.tree = tree
        self.improved = improved
        self.t = t
        self.rank = rank(tree)
        self.epoch = 0
        self.tf_epoch = 0
        self._view_epoch = 0
        self.visible = np.ones(k, bool)
        if histograms is None:
            offsets, keys, counts, table = (np.zeros(k + 1, np.int64), np.zeros(0, np.uint16),
                                            np.zeros(0, np.uint32), np.zeros(1))
        else:
            offsets, keys, counts = histograms.offsets, histograms.keys, histograms.counts
            table = np.zeros(histograms.quantizer.bins ** 2)
        self._state = _State(
            parent=tree.parent, child_start=tree.child_start, children=tree.children,
            visible=self.visible, box_min=tree.box_min, box_max=tree.box_max,
            h_offsets=offsets, h_keys=keys, h_counts=counts, table=table,
            viewing=np.zeros(_VIEW_SIZE), epochs=np.array([0, 0, 0, int(improved)], np.int64),
            raw=np.zeros(k), raw_at=np.full(k, -1, np.int64),
            fixed=np.zeros(k), fixed_at=np.full(k, -1, np.int64),
            imp=np.zeros(k), imp_at=np.full(k, -1, np.int64),
            prio=np.zeros(k), prio_at=np.full(k, -1, np.int64),
            stack=np.zeros(int(tree.depth.max()) + 2, np.int64))

    def _bump(self, transfer: bool, view: bool) -> None:
        if transfer:
            self.tf_epoch += 1
        if view:
            self._view_epoch += 1
        self.epoch += 1
        self._state.epochs[:3] = (self.tf_epoch, self._view_epoch, self.epoch)

    def _query(self, nodes: Any, what: int) -> np.ndarray:
        nodes = np.ascontiguousarray(nodes, np.int64).reshape(-1)
        out = np.empty(nodes.shape[0])
        _map_nodes(self._state, nodes, what, out)
        return out

    def priority(self, nodes: Any) -> np.ndarray:
        """Monotone split priority of ``nodes``."""
        return self._query(nodes, _PRIORITY)

    def error(self, nodes: Any) -> np.ndarray:
        """``E(b) = D*(b) I(b)`` (eq. 7)."""
        return self._query(nodes, _ERROR)

    def error_reduction(self, nodes: Any) -> np.ndarray:
        """``ER(b)`` (eq. 9); ``-inf`` for nodes without visible children."""
        return self._query(nodes, _REDUCTION)

    def all_errors(self) -> np.ndarray:
        """``E`` of every node (whole tree; for references and benchmarks)."""
        return self.error(np.arange(self.tree.size))


class ArrayMetric(_LazyMetric):
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
        super().__init__(tree, None, improved, 0.25)
        s = self._state
        s.imp[:] = 1.0
        self.set(error, visible)

    def set(self, error: np.ndarray, visible: np.ndarray | None = None) -> None:
        """New errors (and visibility): a new epoch; a new ``tf_epoch`` when visibility changed."""
        new_visible = (np.ones(self.tree.size, bool) if visible is None
                       else np.asarray(visible, bool))
        changed = not np.array_equal(new_visible, self.visible)
        self.visible[:] = new_visible
        self._bump(transfer=changed, view=False)
        s = self._state
        s.fixed[:] = np.asarray(error, np.float64)   # E given directly: D* = E and I = 1
        s.fixed_at[:] = self.tf_epoch
        s.imp_at[:] = self._view_epoch


class CutMetric(_LazyMetric):
    """``E``, ``ER`` and priorities of a brick pyramid under a transfer function and a view.

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
        super().__init__(tree, histograms, improved, t)
        self.histograms = histograms
        self.set_transfer_function(tf)
        self.set_view(interest=interest, region=region, eye=eye)

    def set_transfer_function(self, tf: TransferFunction) -> None:
        """New transfer function: new pair table and visibility; every D becomes stale."""
        self.tf = tf
        self.table = distortion_table(tf, self.histograms.quantizer.values).ravel()
        self._state.table[:] = self.table
        self.visible[:] = visible_nodes(self.tree, tf)
        self._bump(transfer=True, view=False)

    def set_view(self, interest: Any = None, region: Any = None, eye: Any = None,
                 frustum: Any = None, margin: float = 0.0) -> None:
        """New interest point or region, eye and view frustum: every importance becomes stale.

        ``frustum`` (``(n, 4)`` half-spaces ``n . x + d >= 0``, :func:`frustum_planes`) makes the
        importance of a box that lies more than ``margin`` outside one of them 0: its error is
        0, so it is never split (it stays as coarse as the cut allows, still covered once).
        """
        self.interest, self.region, self.eye = interest, region, eye
        self.frustum = frustum
        self._state.viewing[:] = _view_vector(interest, region, eye, self.t, frustum, margin)
        self._bump(transfer=False, view=True)

    def raw_distortion(self, nodes: Any) -> np.ndarray:
        """``D(b)`` from the histograms (eq. 1)."""
        return self._query(nodes, _RAW)

    def distortion(self, nodes: Any) -> np.ndarray:
        """``D*(b) = max(D(b), sum of the visible children's D)``: the fixed-up distortion."""
        return self._query(nodes, _FIXED)

    def importance(self, nodes: Any) -> np.ndarray:
        """``I(b)`` (eq. 6) under the current view."""
        return self._query(nodes, _IMPORTANCE)

    def update_all_distortions(self) -> np.ndarray:
        """Recompute ``D*`` for every node (the "full octree" update, raw D in parallel)."""
        s = self._state
        s.raw[:] = histogram_distortion(self.histograms, self.table)
        s.raw_at[:] = self.tf_epoch
        s.fixed_at[:] = -1
        return self.distortion(np.arange(self.tree.size))
