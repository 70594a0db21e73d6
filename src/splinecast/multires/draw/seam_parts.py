"""A brick changed at a seam, drawn as thin shells of changed values around its unchanged core.

:mod:`.draw.seams` makes neighbouring levels agree by replacing the elements of the finer brick that
lie within the model's radius ``r`` of a coarser drawable. Those elements all lie near the brick's
faces, yet a grid needs one dense array, so the changed brick used to be drawn from a float64
copy of its whole array: 8 bytes per voxel for every brick at a level boundary, 2 MiB per 64^3
brick, as much again as the budget itself when a large view refined.

The box of such a brick is split instead, like a k-d tree, into up to six *shells* (a slab
along each face near which elements changed: x first, over the whole box; then y over what is
left; then z) and the *core* that remains. The core is drawn from the brick's own grid (the
store's values, already built and shared with frames without the seam): no point of the core
is within ``r`` of a changed element, so it reads exactly the values the changed copy holds.
Each shell gets a float64 copy of only the elements its points read. A ray crosses the parts
of a box one after the other in the k-d order seen from the eye (:func:`part_order`), so the
drawables of a cut stay in a valid front-to-back order when a brick is replaced by its parts.

Shell thicknesses are whole level voxels counted from the box's faces, which lie on the
model's cell boundaries; the parts therefore cut rays where cells do, and a first hit and its
normal are those of the whole changed copy, bit for bit (translucent isosurfaces too; DVR's
segments restart at the parts' faces: the same integral to about 1e-5;
``tests/test_seam_parts.py``, whose views do not exercise MIP at a seam).
Where the shells would hold more than :data:`SHELL_SHARE_MAX` of the brick's elements (small
bricks, cubic models with coarser neighbours on many faces, changes reaching deep) the whole
copy is kept. With 64^3 bricks the shells held a third to a half of what the whole copies did
in the test's cuts (trilinear a third).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Parts", "split_box", "part_order", "crop_range", "SHELL_SHARE_MAX"]

#: A brick is split only when its shells' copies hold at most this share of its array's
#: elements: above it they would save little over one copy of the whole brick, and every part
#: costs the launch a drawable.
SHELL_SHARE_MAX = 0.75


@dataclass(frozen=True)
class Parts:
    """The parts of a box in the level's index space.

    Attributes
    ----------
    boxes : ndarray (n, 2, 3)
        ``boxes[p] = (lo, hi)`` of part ``p``; the last part is the core.
    axis : ndarray (n - 1,) of int
        The axis across which shell ``p`` is a slab.
    upper : ndarray (n - 1,) of bool
        Shell ``p`` lies at the upper end of that axis.
    """

    boxes: np.ndarray
    axis: np.ndarray
    upper: np.ndarray


def split_box(lo: np.ndarray, hi: np.ndarray, elements: np.ndarray,
              radius: float) -> Parts | None:
    """Shells and core of the box ``[lo, hi]`` so that no point of the core lies within
    ``radius`` (max norm) of any of ``elements``.

    Parameters
    ----------
    lo, hi : ndarray (3,)
        The box, in the level's index space (element ``q`` of the level sits at ``q``).
    elements : ndarray (m, 3)
        Positions of the changed elements, each within ``radius`` of the box's boundary.
    radius : float
        How far from a point the model's reconstruction reads elements.

    Returns
    -------
    Parts or None
        ``None`` when there is nothing to split off or no core would be left.
    """
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    elements = np.asarray(elements, dtype=np.float64).reshape(-1, 3)
    if not len(elements):
        return None
    # Each element goes with the face it is nearest to; that face's shell is thick enough that
    # the core's points are farther than ``radius`` from it along the face's axis (a whole
    # number of voxels, strictly more than the distance plus the radius).
    distance = np.concatenate([elements - lo, hi - elements], axis=1)  # (m, 6): lo faces, hi
    face = np.argmin(distance, axis=1)
    thickness = np.zeros(6)
    for f in np.unique(face):
        reach = float(distance[face == f, f].max()) + radius
        thickness[f] = max(1.0, math.floor(reach) + 1.0)
    t_lo, t_hi = thickness[:3], thickness[3:]
    core_lo, core_hi = lo + t_lo, hi - t_hi
    if np.any(core_hi <= core_lo):
        return None
    boxes, axes, uppers = [], [], []
    rest_lo, rest_hi = lo.copy(), hi.copy()
    for a in range(3):
        if t_lo[a] > 0:
            box_hi = rest_hi.copy()
            box_hi[a] = core_lo[a]
            boxes.append((rest_lo.copy(), box_hi))
            axes.append(a)
            uppers.append(False)
        if t_hi[a] > 0:
            box_lo = rest_lo.copy()
            box_lo[a] = core_hi[a]
            boxes.append((box_lo, rest_hi.copy()))
            axes.append(a)
            uppers.append(True)
        rest_lo[a], rest_hi[a] = core_lo[a], core_hi[a]
    boxes.append((rest_lo, rest_hi))
    return Parts(np.array(boxes, dtype=np.float64), np.array(axes, dtype=np.int64),
                 np.array(uppers, dtype=bool))


def part_order(parts: Parts, eye: np.ndarray, perspective: bool) -> list[int]:
    """The parts in the order every ray from the eye crosses them (indices into ``parts``).

    The split is a k-d tree: along x a lower shell, the rest and an upper shell, the rest split
    along y, then z. The side of a split plane holding the eye is crossed first; a ray from an
    eye between the two planes of one axis enters the rest first and then at most one of the
    two shells.

    Parameters
    ----------
    parts : Parts
    eye : ndarray (3,)
        The eye in the same index space (perspective), or the viewing direction there
        (orthographic).
    perspective : bool
    """
    core = len(parts.boxes) - 1
    order: list[int] = [core]
    for a in (2, 1, 0):  # build from the innermost split outwards
        lower = [p for p in range(core) if parts.axis[p] == a and not parts.upper[p]]
        upper = [p for p in range(core) if parts.axis[p] == a and parts.upper[p]]
        if not lower and not upper:
            continue
        rest_lo = parts.boxes[lower[0]][1][a] if lower else None
        rest_hi = parts.boxes[upper[0]][0][a] if upper else None
        if perspective:
            if rest_lo is not None and eye[a] < rest_lo:
                order = lower + order + upper
            elif rest_hi is not None and eye[a] > rest_hi:
                order = upper + order + lower
            else:
                order = order + lower + upper
        elif eye[a] >= 0:
            order = lower + order + upper
        else:
            order = upper + order + lower
    return order


def crop_range(lo: np.ndarray, hi: np.ndarray, first: np.ndarray, shape: np.ndarray,
               radius: float) -> tuple[np.ndarray, np.ndarray]:
    """The elements (array index ``start`` up to ``stop``, exclusive) that points of the box
    ``[lo, hi]`` can read: those within ``radius`` of it. (The radius is an upper bound: a
    point a rounding error outside the box, whose cell may be the one before, still reads
    only elements within it.)"""
    first = np.asarray(first, dtype=np.float64)
    start = np.floor(np.asarray(lo) - radius - first).astype(np.int64)
    stop = np.ceil(np.asarray(hi) + radius - first).astype(np.int64) + 1
    shape = np.asarray(shape, dtype=np.int64)
    return np.clip(start, 0, shape), np.clip(stop, 0, shape)
