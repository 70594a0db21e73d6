"""The brick tree a cut is chosen from: flat arrays a pyramid store can fill.

A multiresolution volume is a tree of bricks (Carmona & Froehlich 2011, section 3.1): the leaves are
bricks of the finest level (level 0, the source data), every inner node is a brick of a coarser
level that approximates the source region of its children. Every brick has the same voxel count, so
any GPU or RAM slot holds any brick; the tree is an octree, incomplete at borders (a node has 1 to 8
children).

:class:`BrickTree` describes such a tree with flat numpy arrays and nothing else (no voxels, no
file handles), so the cut algorithms run on it without a store, a renderer or a transfer function:

=============================  ===========  =====================================================
array                          dtype        meaning
=============================  ===========  =====================================================
``parent``                     int32 (K,)   parent node id, -1 for the root (exactly one root)
``child_start``, ``children``  int64/int32  children of node ``b`` are ``children[child_start[b]:
                                            child_start[b + 1]]`` (CSR, ascending ids)
``level``                      int16 (K,)   pyramid level, 0 = finest (the NGFF dataset index)
``box_min``, ``box_max``       float64      world-space box of the source region the brick
                               (K, 3)       covers (importance, eq. 5)
``voxels``                     int64 (K,)   n(b): source voxels the brick approximates (eq. 1, 8)
``value_min``, ``value_max``   float64      range of the source values below the brick, made
                               (K,)         hierarchical (a parent's range holds its children's):
                                            what the transparency test of section 3.6 reads
=============================  ===========  =====================================================

:func:`regular_brick_tree` builds the tree of a 2x2x2 pyramid over a grid: level ``l`` has
``ceil(n_{l-1} / 2)`` voxels per axis, bricks of ``brick`` voxels per axis, node ids level by level
from the finest to the root, C order of the brick grid within a level (:class:`BrickGrid`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...errors import ParameterError

__all__ = ["BrickTree", "BrickGrid", "regular_brick_tree", "segment_indices"]


class BrickTree:
    """A tree of bricks described by flat arrays (see the module docstring for the fields).

    Build one with :meth:`from_parents` (any tree, for tests and stores with their own numbering)
    or :func:`regular_brick_tree` (the octree of a 2x2x2 pyramid). Trees are immutable; the
    derived arrays ``depth`` (0 at the root), ``topdown`` (node ids, parents before children) and
    ``n_children`` are computed once.
    """

    parent: np.ndarray
    child_start: np.ndarray
    children: np.ndarray
    level: np.ndarray
    box_min: np.ndarray
    box_max: np.ndarray
    voxels: np.ndarray
    value_min: np.ndarray
    value_max: np.ndarray
    grid: BrickGrid | None
    root: int
    depth: np.ndarray
    topdown: np.ndarray
    n_children: np.ndarray

    def __init__(self, parent: np.ndarray, *, level: np.ndarray, box_min: np.ndarray,
                 box_max: np.ndarray, voxels: np.ndarray, value_min: np.ndarray,
                 value_max: np.ndarray, grid: BrickGrid | None = None):
        parent = np.ascontiguousarray(parent, dtype=np.int32)
        k = parent.shape[0]
        if parent.ndim != 1 or k == 0:
            raise ParameterError("parent must be a non-empty 1D array of node ids")
        roots = np.flatnonzero(parent < 0)
        if roots.size != 1:
            raise ParameterError(
                f"a brick tree needs exactly one root (parent -1), got {roots.size}")
        if np.any(parent >= k):
            raise ParameterError("parent holds ids outside the tree")
        self.parent = parent
        self.root = int(roots[0])
        # Children in CSR form, ascending ids within a node (a stable sort by parent).
        others = np.flatnonzero(parent >= 0)
        order = others[np.argsort(parent[others], kind="stable")]
        self.children = order.astype(np.int32)
        counts = np.bincount(parent[others], minlength=k)
        self.child_start = np.zeros(k + 1, np.int64)
        np.cumsum(counts, out=self.child_start[1:])
        self.n_children = counts.astype(np.int32)
        # Breadth-first order from the root; a node never reached means a cycle.
        depth = np.full(k, -1, np.int32)
        depth[self.root] = 0
        frontier = np.array([self.root], np.int64)
        layers = [frontier]
        while frontier.size:
            nxt = self.children_of_many(frontier)
            depth[nxt] = depth[frontier].max() + 1 if frontier.size else 0
            frontier = nxt
            if nxt.size:
                layers.append(nxt)
        if np.any(depth < 0):
            raise ParameterError("parent describes a graph with a cycle, not a tree")
        self.depth = depth.astype(np.int16)
        self._layers: list[np.ndarray] | None = None
        self.topdown = np.concatenate(layers).astype(np.int32)
        self.level = _node_array(level, k, np.int16, "level")
        self.box_min = _node_array(box_min, k, np.float64, "box_min", (3,))
        self.box_max = _node_array(box_max, k, np.float64, "box_max", (3,))
        self.voxels = _node_array(voxels, k, np.int64, "voxels")
        vmin = _node_array(value_min, k, np.float64, "value_min")
        vmax = _node_array(value_max, k, np.float64, "value_max")
        self.value_min, self.value_max = _hierarchical_ranges(self, vmin, vmax)
        self.grid = grid
        for name in ("parent", "children", "child_start", "n_children", "depth", "topdown",
                     "level", "box_min", "box_max", "voxels", "value_min", "value_max"):
            getattr(self, name).flags.writeable = False

    # ------------------------------------------------------------------------------ building
    @classmethod
    def from_parents(cls, parent: Sequence[int] | np.ndarray, *, level: Any = None,
                     box_min: Any = None, box_max: Any = None, voxels: Any = None,
                     value_min: Any = None, value_max: Any = None) -> BrickTree:
        """A tree from its parent array; every other field is optional.

        Defaults, for abstract trees in tests: ``level`` = height above the deepest leaf,
        unit boxes at the origin, ``voxels`` = number of leaves below the node (1 per leaf), and
        the value range ``[0, 1]`` everywhere. Ranges given for leaves only (NaN elsewhere) are
        propagated to the ancestors.
        """
        parent = np.asarray(parent, dtype=np.int32)
        k = parent.shape[0]
        probe = cls(parent, level=np.zeros(k), box_min=np.zeros((k, 3)),
                    box_max=np.ones((k, 3)), voxels=np.ones(k), value_min=np.zeros(k),
                    value_max=np.ones(k))
        if level is None:
            level = probe.depth.max() - probe.depth
        if voxels is None:
            voxels = probe.leaf_count(np.ones(k, bool))
        return cls(parent, level=level,
                   box_min=np.zeros((k, 3)) if box_min is None else box_min,
                   box_max=np.ones((k, 3)) if box_max is None else box_max,
                   voxels=voxels,
                   value_min=np.zeros(k) if value_min is None else value_min,
                   value_max=np.ones(k) if value_max is None else value_max)

    # ---------------------------------------------------------------------------- navigation
    @property
    def size(self) -> int:
        """K, the number of nodes."""
        return int(self.parent.shape[0])

    @property
    def is_leaf(self) -> np.ndarray:
        """Nodes without children (finest-level bricks in a pyramid)."""
        return self.n_children == 0

    def children_of(self, node: int) -> np.ndarray:
        """Child ids of one node (a read-only view)."""
        return self.children[self.child_start[node]:self.child_start[node + 1]]

    def children_of_many(self, nodes: np.ndarray) -> np.ndarray:
        """Child ids of several nodes, concatenated in the order of ``nodes``."""
        nodes = np.asarray(nodes, np.int64)
        if nodes.size == 0:
            return np.zeros(0, np.int64)
        start = self.child_start[nodes]
        count = self.child_start[nodes + 1] - start
        return self.children[segment_indices(start, count)].astype(np.int64)

    def children_with_owner(self, nodes: np.ndarray, mask: np.ndarray | None = None
                            ) -> tuple[np.ndarray, np.ndarray]:
        """Children of ``nodes`` (those in ``mask`` if given) and the position of their parent
        in ``nodes``: the vectorized form of a loop over the nodes' children."""
        nodes = np.asarray(nodes, np.int64)
        kids = self.children_of_many(nodes)
        owner = np.repeat(np.arange(nodes.shape[0]), self.n_children[nodes])
        if mask is not None:
            keep = mask[kids]
            kids, owner = kids[keep], owner[keep]
        return kids, owner

    def ancestors_of(self, nodes: np.ndarray) -> np.ndarray:
        """Sorted ids of every proper ancestor of ``nodes`` (the root included)."""
        seen = np.zeros(self.size, bool)
        current = np.unique(self.parent[np.asarray(nodes, np.int64)])
        current = current[current >= 0]
        while current.size:
            current = current[~seen[current]]
            seen[current] = True
            current = self.parent[current]
            current = np.unique(current[current >= 0])
        return np.flatnonzero(seen)

    def leaf_count(self, visible: np.ndarray) -> np.ndarray:
        """Per node, the number of visible "effective leaves" below it (itself included).

        An effective leaf is a visible node without visible children: the finest brick a cut can
        hold there. The count is the largest possible cut of the node's subtree.
        """
        visible = np.asarray(visible, bool)
        vis_children = np.zeros(self.size, np.int64)
        np.add.at(vis_children, self.parent[visible & (self.parent >= 0)], 1)
        count = np.where(visible & (vis_children == 0), 1, 0).astype(np.int64)
        for nodes in self.depth_layers()[:0:-1]:
            nodes = nodes[visible[nodes]]
            np.add.at(count, self.parent[nodes], count[nodes])
        return count

    def depth_layers(self) -> list[np.ndarray]:
        """Node ids grouped by depth, the root's layer first (for level-by-level passes)."""
        if self._layers is None:
            order = self.topdown
            bounds = np.searchsorted(self.depth[order], np.arange(int(self.depth.max()) + 2))
            self._layers = [order[bounds[d]:bounds[d + 1]] for d in range(len(bounds) - 1)]
        return self._layers


def segment_indices(start: np.ndarray, count: np.ndarray) -> np.ndarray:
    """Concatenation of ``arange(s, s + c)`` for every pair ``(s, c)``, without a Python loop."""
    total = int(count.sum())
    if total == 0:
        return np.zeros(0, np.int64)
    start = np.asarray(start, np.int64)
    count = np.asarray(count, np.int64)
    offsets = np.repeat(start - np.concatenate([[0], np.cumsum(count)[:-1]]), count)
    return offsets + np.arange(total)


def _node_array(value: Any, k: int, dtype: Any, name: str, tail: tuple = ()) -> np.ndarray:
    arr = np.ascontiguousarray(np.broadcast_to(np.asarray(value, dtype=dtype), (k, *tail)),
                               dtype=dtype).copy()
    return arr


def _hierarchical_ranges(tree: BrickTree, vmin: np.ndarray,
                         vmax: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Grow every node's value range to hold its children's (bottom-up; NaN = unknown)."""
    lo = np.where(np.isnan(vmin), np.inf, vmin)
    hi = np.where(np.isnan(vmax), -np.inf, vmax)
    # One vectorized pass per depth, deepest first: children are final before their parent.
    for nodes in tree.depth_layers()[:0:-1]:
        np.minimum.at(lo, tree.parent[nodes], lo[nodes])
        np.maximum.at(hi, tree.parent[nodes], hi[nodes])
    return lo, hi


@dataclass(frozen=True)
class BrickGrid:
    """Geometry of a 2x2x2 brick pyramid over a grid (what :func:`regular_brick_tree` built).

    Attributes
    ----------
    shape : tuple of int
        Source grid shape (level 0).
    brick : int
        Voxels per brick edge, the same on every level.
    level_shapes : list of tuple
        Voxel grid shape of every level, ``ceil(previous / 2)`` per axis.
    level_bricks : list of tuple
        Brick grid shape of every level, ``ceil(level_shape / brick)`` per axis.
    level_offsets : numpy.ndarray
        Node id of the first brick of every level (plus the total count at the end).
    """

    shape: tuple[int, int, int]
    brick: int
    level_shapes: list[tuple[int, int, int]]
    level_bricks: list[tuple[int, int, int]]
    level_offsets: np.ndarray

    @property
    def levels(self) -> int:
        """Number of levels (the root's level + 1)."""
        return len(self.level_shapes)

    def node_id(self, level: int, index: Any) -> np.ndarray:
        """Node ids of bricks ``index`` (..., 3) on ``level``."""
        idx = np.asarray(index, np.int64)
        flat = np.ravel_multi_index(tuple(np.moveaxis(idx, -1, 0)), self.level_bricks[level])
        return self.level_offsets[level] + flat

    def footprint(self, level: int, index: Any) -> tuple[np.ndarray, np.ndarray]:
        """Source voxel ranges ``[lo, hi)`` (..., 3) covered by bricks ``index`` on ``level``."""
        idx = np.asarray(index, np.int64)
        edge = self.brick << level
        lo = idx * edge
        hi = np.minimum(lo + edge, np.asarray(self.shape))
        return lo, hi


def regular_brick_tree(shape: Sequence[int], brick: int, spacing: Any = 1.0, origin: Any = 0.0,
                       leaf_min: np.ndarray | None = None,
                       leaf_max: np.ndarray | None = None) -> BrickTree:
    """The brick octree of a 2x2x2 pyramid over a grid of ``shape`` voxels.

    Parameters
    ----------
    shape : (nx, ny, nz)
        Source grid shape, ``data[i, j, k]`` with ``i`` along x.
    brick : int
        Voxels per brick edge on every level.
    spacing, origin : float or 3 floats
        World placement of the source grid (voxel centres at ``origin + index * spacing``).
    leaf_min, leaf_max : arrays shaped like the level-0 brick grid, optional
        Value range of every finest brick (include the voxels the reconstruction reads across
        the brick's faces); propagated to the ancestors. Default ``[0, 1]``: all visible.

    Returns
    -------
    BrickTree
        With ``grid`` set. A brick's box is the region its source voxels own, from
        ``origin + (lo - 1/2) spacing`` to ``origin + (hi - 1/2) spacing``.
    """
    shape = tuple(int(n) for n in shape)
    if len(shape) != 3 or min(shape) < 1 or int(brick) < 1:
        raise ParameterError(f"need a 3D shape and a positive brick size, got {shape}, {brick}")
    brick = int(brick)
    spacing = np.broadcast_to(np.asarray(spacing, np.float64), (3,))
    origin = np.broadcast_to(np.asarray(origin, np.float64), (3,))
    level_shapes = [shape]
    level_bricks = [tuple(-(-n // brick) for n in shape)]
    while level_bricks[-1] != (1, 1, 1):
        level_shapes.append(tuple(-(-n // 2) for n in level_shapes[-1]))
        level_bricks.append(tuple(-(-n // brick) for n in level_shapes[-1]))
    counts = [int(np.prod(b)) for b in level_bricks]
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    grid = BrickGrid(shape, brick, level_shapes, level_bricks, offsets)
    k = int(offsets[-1])
    parent = np.full(k, -1, np.int32)
    level = np.zeros(k, np.int16)
    box_min = np.zeros((k, 3))
    box_max = np.zeros((k, 3))
    voxels = np.zeros(k, np.int64)
    for lv, nb in enumerate(level_bricks):
        idx = np.indices(nb).reshape(3, -1).T
        ids = slice(offsets[lv], offsets[lv + 1])
        lo, hi = grid.footprint(lv, idx)
        level[ids] = lv
        box_min[ids] = origin + (lo - 0.5) * spacing
        box_max[ids] = origin + (hi - 0.5) * spacing
        voxels[ids] = np.prod(hi - lo, axis=1)
        if lv + 1 < len(level_bricks):
            parent[ids] = grid.node_id(lv + 1, idx // 2)
    vmin = np.full(k, np.nan)
    vmax = np.full(k, np.nan)
    vmin[:counts[0]] = 0.0 if leaf_min is None else np.asarray(leaf_min, np.float64).ravel()
    vmax[:counts[0]] = 1.0 if leaf_max is None else np.asarray(leaf_max, np.float64).ravel()
    return BrickTree(parent, level=level, box_min=box_min, box_max=box_max, voxels=voxels,
                     value_min=vmin, value_max=vmax, grid=grid)
