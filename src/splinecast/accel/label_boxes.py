"""The labels of a label volume and the voxel box each one occupies, in one pass.

A label volume (a segmentation) holds an integer per voxel: 0 is the background, every other
value names a region. Rendering draws each label's surface from a sub-volume around it, so the
renderer needs, per label, the smallest box of voxels that holds all of it.
"""

from __future__ import annotations

import numpy as np

from .._jit import jit
from ..errors import DataError

__all__ = ["label_boxes", "integer_labels"]

#: Label values spanning at most this many integers are indexed directly (a table of that many
#: boxes); wider ranges are first mapped to their rank among the values present.
_DIRECT_RANGE = 1 << 22
#: Voxels mapped to ranks at a time (bounds the int32 temporary).
_SLAB_VOXELS = 1 << 24


@jit(nogil=True)
def _grow_boxes(data, offset, lo, hi):  # pragma: no cover - compiled
    """``lo[v] = min``, ``hi[v] = max`` of the indices of the voxels holding ``v + offset``."""
    n0, n1, n2 = data.shape
    for i in range(n0):
        for j in range(n1):
            for k in range(n2):
                v = np.int64(data[i, j, k]) - offset
                if i < lo[v, 0]:
                    lo[v, 0] = i
                if i > hi[v, 0]:
                    hi[v, 0] = i
                if j < lo[v, 1]:
                    lo[v, 1] = j
                if j > hi[v, 1]:
                    hi[v, 1] = j
                if k < lo[v, 2]:
                    lo[v, 2] = k
                if k > hi[v, 2]:
                    hi[v, 2] = k


def integer_labels(data: np.ndarray, label: str) -> np.ndarray:
    """``data`` as integers: integer arrays as they are, floating-point ones (NIfTI and NRRD
    segmentations are often stored as float32) converted when every value is a whole number.

    Raises
    ------
    DataError
        If a floating-point voxel is not a whole number (not a label volume).
    """
    if data.dtype.kind in "iu":
        return data
    if data.dtype.kind == "b":
        return data.view(np.uint8)
    if data.dtype.kind != "f":
        raise DataError(f"{label}: voxel type {data.dtype} cannot hold labels")
    whole = np.isfinite(data) & (data == np.rint(data))
    if not whole.all():
        bad = data[~whole][0]
        raise DataError(f"{label}: not a label volume: voxel value {bad!r} is not a whole number "
                        "(labels are integers)")
    lo, hi = float(data.min()), float(data.max())
    target = next(t for t in (np.uint8, np.uint16, np.int32, np.int64)
                  if np.iinfo(t).min <= lo and hi <= np.iinfo(t).max)
    return data.astype(target)


def label_boxes(data: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The nonzero label values of an integer volume and the voxel box of each.

    Parameters
    ----------
    data : ndarray (nx, ny, nz), integer dtype

    Returns
    -------
    values : ndarray (n,), int64
        The label values present, 0 left out, increasing.
    lo, hi : ndarray (n, 3), int64
        First and last voxel index (inclusive) of each label along x, y, z.
    """
    if data.size == 0:
        empty = np.zeros((0, 3), np.int64)
        return np.zeros(0, np.int64), empty, empty
    vmin, vmax = int(data.min()), int(data.max())
    big = np.iinfo(np.int64).max
    if vmax - vmin < _DIRECT_RANGE:
        n = vmax - vmin + 1
        lo = np.full((n, 3), big, np.int64)
        hi = np.full((n, 3), -1, np.int64)
        _grow_boxes(data, np.int64(vmin), lo, hi)
        present = hi[:, 0] >= 0
        values = np.flatnonzero(present).astype(np.int64) + vmin
        lo, hi = lo[present], hi[present]
    else:
        values = np.unique(data).astype(np.int64)
        n = values.size
        lo = np.full((n, 3), big, np.int64)
        hi = np.full((n, 3), -1, np.int64)
        step = max(1, _SLAB_VOXELS // max(1, data.shape[1] * data.shape[2]))
        for x0 in range(0, data.shape[0], step):
            rank = np.searchsorted(values, data[x0:x0 + step]).astype(np.int32)
            part_lo = np.full((n, 3), big, np.int64)
            part_hi = np.full((n, 3), -1, np.int64)
            _grow_boxes(rank, np.int64(0), part_lo, part_hi)
            seen = part_hi[:, 0] >= 0
            part_lo[seen, 0] += x0
            part_hi[seen, 0] += x0
            lo, hi = np.minimum(lo, part_lo), np.maximum(hi, part_hi)
    keep = values != 0
    return values[keep], lo[keep], hi[keep]
