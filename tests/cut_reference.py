"""Independent references for the cut-selection tests (issue 11), written from the definitions.

Nothing here imports splinecast's cut code: trees are plain parent lists, cuts are enumerated by
brute force, validity is checked leaf by leaf, and the distortion of a brick is summed voxel by
voxel with scipy's interpolation.

* :func:`random_parents` -- random trees (complete or with 1..k children per node).
* :func:`block_monotone_errors`, :func:`hierarchical_visibility` -- per-node data.
* :func:`all_cuts` -- every cut of a tree (exponential; small trees only).
* :func:`cuts_within` -- every cut of at most ``budget`` bricks (enumeration pruned by size).
* :func:`reference_greedy` -- greedy refinement from the root, step by step from the definition.
* :func:`is_valid_cut` -- covers every visible leaf exactly once, holds no invisible node.
* :func:`voxel_distortion` -- eq. (1)-(2) summed over the voxels of a brick.
* :func:`srgb_luv` -- CIE L*u*v* of sRGB colours (D65), from the CIE and sRGB definitions.
* :func:`smooth_volume` -- a smooth random field with some noise (test data).
* :func:`reference_priorities` -- eq. (9) and the monotone clamp, node by node in Python.
"""

from __future__ import annotations

import itertools

import numpy as np
from scipy import ndimage

__all__ = [
    "random_parents",
    "children_lists",
    "block_monotone_errors",
    "hierarchical_visibility",
    "all_cuts",
    "cuts_within",
    "reference_greedy",
    "is_valid_cut",
    "voxel_distortion",
    "srgb_luv",
    "smooth_volume",
    "reference_priorities",
]


def random_parents(rng: np.random.Generator, max_nodes: int, max_children: int = 8,
                   depth: int = 4, complete: bool = False) -> list[int]:
    """Parent list of a random tree grown breadth first (root 0)."""
    parent, level, frontier = [-1], [0], [0]
    while frontier and len(parent) < max_nodes:
        node = frontier.pop(0)
        if level[node] >= depth:
            continue
        if complete:
            k = max_children
        else:
            k = 0 if (level[node] > 0 and rng.random() < 0.2) else int(
                rng.integers(1, max_children + 1))
        for _ in range(k):
            parent.append(node)
            level.append(level[node] + 1)
            frontier.append(len(parent) - 1)
    return parent


def children_lists(parent: list[int]) -> list[list[int]]:
    kids: list[list[int]] = [[] for _ in parent]
    for node, p in enumerate(parent):
        if p >= 0:
            kids[p].append(node)
    return kids


def _postorder(parent: list[int]) -> list[int]:
    kids = children_lists(parent)
    out, stack = [], [parent.index(-1)]
    while stack:
        node = stack.pop()
        out.append(node)
        stack.extend(kids[node])
    return out[::-1]


def block_monotone_errors(rng: np.random.Generator, parent: list[int]) -> np.ndarray:
    """Leaves 0; a parent's error exceeds its children's sum (the typical octree case)."""
    kids = children_lists(parent)
    error = np.zeros(len(parent))
    for node in _postorder(parent):
        if kids[node]:
            error[node] = error[kids[node]].sum() * rng.uniform(1.0, 1.5) + rng.exponential(1.0)
    return error


def hierarchical_visibility(rng: np.random.Generator, parent: list[int],
                            p: float = 0.7) -> np.ndarray:
    """Random visible leaves; an inner node is visible when a visible leaf lies below it."""
    kids = children_lists(parent)
    visible = np.zeros(len(parent), bool)
    for node in _postorder(parent):
        visible[node] = (rng.random() < p) if not kids[node] else visible[kids[node]].any()
    return visible


def all_cuts(parent: list[int], visible: np.ndarray, node: int | None = None) -> list[tuple]:
    """Every cut of the visible subtree of ``node`` (default: the root), by enumeration."""
    kids = children_lists(parent)
    node = parent.index(-1) if node is None else node

    def cuts(b: int) -> list[tuple]:
        vis = [k for k in kids[b] if visible[k]]
        out = [(b,)]
        if vis:
            for combo in itertools.product(*[cuts(k) for k in vis]):
                out.append(tuple(x for part in combo for x in part))
        return out

    return cuts(node)


def cuts_within(parent: list[int], visible: np.ndarray, budget: int) -> list[tuple]:
    """Every cut of at most ``budget`` bricks of the visible tree, by enumeration.

    A node either is in the cut or is replaced by a cut of each of its visible children; a
    partial product is dropped as soon as it cannot leave one brick for each child still to come,
    so only cuts within the budget are ever built (still exponential in the tree: small trees).
    """
    kids = children_lists(parent)

    def cuts(b: int, cap: int) -> list[tuple]:
        out = [(b,)]
        vis = [k for k in kids[b] if visible[k]]
        if vis and len(vis) <= cap:
            partial: list[tuple] = [()]
            for i, k in enumerate(vis):
                later = len(vis) - i - 1  # children still to come, one brick each at least
                partial = [p + c for p in partial for c in cuts(k, cap - len(p) - later)]
            out.extend(partial)
        return out

    return cuts(parent.index(-1), budget)


def reference_greedy(parent: list[int], error: np.ndarray, visible: np.ndarray, budget: int,
                     improved: bool = True, fill: bool = False) -> list[int]:
    """Greedy refinement from the root under ``budget`` bricks, step by step (section 3.3).

    The front starts as the root. Each step takes the front node of highest priority
    (:func:`reference_priorities`; ties: the shallower node, then the smaller id) and stops when
    that priority is not positive. The node is replaced by its visible children when the front
    stays within ``budget``; otherwise the refinement stops (the paper's rule), or with ``fill``
    the node is set aside unsplit and the next one is tried. Returns the sorted cut.
    """
    _, prio = reference_priorities(parent, error, visible, improved)
    kids = children_lists(parent)
    depth = [0] * len(parent)
    for b in _postorder(parent)[::-1]:
        depth[b] = depth[parent[b]] + 1 if parent[b] >= 0 else 0
    root = parent.index(-1)
    if not visible[root]:
        return []
    front, aside = [root], []
    while front:
        node = min(front, key=lambda b: (-prio[b], depth[b], b))
        if not prio[node] > 0:
            break
        vis = [k for k in kids[node] if visible[k]]
        front.remove(node)
        if len(front) + len(aside) + len(vis) > budget:
            if not fill:
                front.append(node)
                break
            aside.append(node)
            continue
        front.extend(vis)
    return sorted(front + aside)


def is_valid_cut(parent: list[int], visible: np.ndarray, cut) -> bool:
    """True when every visible leaf has exactly one cut node on its path to the root and the
    cut holds no invisible node (so no cut node is an ancestor of another, nothing is missed)."""
    kids = children_lists(parent)
    chosen = set(int(b) for b in cut)
    if any(not visible[b] for b in chosen):
        return False
    for leaf in range(len(parent)):
        if kids[leaf] and any(visible[k] for k in kids[leaf]):
            continue  # not an effective leaf
        if not visible[leaf]:
            continue
        hits, b = 0, leaf
        while b >= 0:
            hits += b in chosen
            b = parent[b]
        if hits != 1:
            return False
    # Cut nodes strictly inside the tree must lie above some visible effective leaf: implied by
    # visibility being hierarchical; every cut node was checked visible above.
    return True


def voxel_distortion(source: np.ndarray, coarse: np.ndarray, level: int, lo, hi,
                     bin_of, luv_of_bins, index_map=None) -> float:
    """Eq. (1)-(2) for one brick: per source voxel, the distance between the classified colours
    of its (quantized) value and of the (quantized) trilinear value of ``coarse`` at its centre.

    The coarse position of source index ``i`` is ``(i + 1/2) / 2^level - 1/2`` (the centroid
    convention of a mean pyramid), or ``a i + c`` when ``index_map = (a, c)`` is given (per
    axis), clamped to the grid (``mode="nearest"``).
    """
    axes = [np.arange(lo[a], hi[a], dtype=np.float64) for a in range(3)]
    grids = np.meshgrid(*axes, indexing="ij")
    f = 2.0 ** level
    if index_map is None:
        a_map, c_map = np.full(3, 1.0 / f), np.full(3, 0.5 / f - 0.5)
    else:
        a_map, c_map = (np.broadcast_to(np.asarray(x, np.float64), (3,)) for x in index_map)
    coords = [np.clip(g * a_map[ax] + c_map[ax], 0, n - 1)
              for ax, (g, n) in enumerate(zip(grids, coarse.shape, strict=True))]
    approx = ndimage.map_coordinates(coarse.astype(np.float64), coords, order=1, mode="nearest")
    src = source[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]]
    a = luv_of_bins[bin_of(src)]
    b = luv_of_bins[bin_of(approx)]
    return float(np.sqrt(((a - b) ** 2).sum(axis=-1)).sum())


def srgb_luv(rgb: np.ndarray) -> np.ndarray:
    """CIE 1976 L*u*v* of sRGB colours in [0, 1] (..., 3): the sRGB decoding curve and matrix of
    IEC 61966-2-1, white D65 (Xn, Yn, Zn = 0.95047, 1, 1.08883), black at (0, 0, 0)."""
    c = np.clip(np.asarray(rgb, np.float64), 0.0, 1.0)
    linear = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    to_xyz = np.array([[0.4124564, 0.3575761, 0.1804375],
                       [0.2126729, 0.7151522, 0.0721750],
                       [0.0193339, 0.1191920, 0.9503041]])
    x, y, z = np.moveaxis(linear @ to_xyz.T, -1, 0)
    xn, yn, zn = 0.95047, 1.0, 1.08883
    lightness = np.where(y / yn > (6 / 29) ** 3, 116 * np.cbrt(y / yn) - 16, (29 / 3) ** 3 * y / yn)
    den = x + 15 * y + 3 * z
    safe = np.where(den > 0, den, 1.0)
    u = np.where(den > 0, 4 * x / safe, 0.0)
    v = np.where(den > 0, 9 * y / safe, 0.0)
    den_n = xn + 15 * yn + 3 * zn
    return np.stack([lightness, 13 * lightness * (u - 4 * xn / den_n),
                     13 * lightness * (v - 9 * yn / den_n)], axis=-1)


def smooth_volume(shape, seed: int, dtype=np.uint8) -> np.ndarray:
    """Smooth random field plus 5% noise, scaled to 0..255."""
    rng = np.random.default_rng(seed)
    field = ndimage.gaussian_filter(rng.random(shape), 2.0) + 0.05 * rng.random(shape)
    field = (field - field.min()) / np.ptp(field) * 255
    return field.astype(dtype)


def reference_priorities(parent: list[int], error: np.ndarray, visible: np.ndarray,
                         improved: bool) -> tuple[np.ndarray, np.ndarray]:
    """``(ER, P)`` per node: ER over visible children (-inf without any), P = ER or E for
    splittable nodes, clamped by the parent's P, root first."""
    kids = children_lists(parent)
    n = len(parent)
    er = np.full(n, -np.inf)
    for b in range(n):
        vis = [k for k in kids[b] if visible[k]]
        if vis:
            er[b] = (error[b] - sum(error[k] for k in vis)) / len(vis)
    raw = er.copy() if improved else np.where(np.isfinite(er), error, -np.inf)
    prio = np.empty(n)
    for b in _postorder(parent)[::-1]:  # parents before children
        prio[b] = raw[b] if parent[b] < 0 else min(raw[b], prio[parent[b]])
    return er, prio
