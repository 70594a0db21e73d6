"""The downsampling filter of splinecast's pyramids: vertex-centred binomial halving.

Coarse voxel ``c`` sits on fine voxel ``2 c`` and holds ``(f[2c-1] + 2 f[2c] + f[2c+1]) / 4`` along
every halved axis (separable, so 27 taps with weights ``w_a w_b w_c`` when all three axes are
halved). Outside the fine level the grid is mirrored about its first and last voxel (``f[-1] =
f[1]``, ``f[n] = f[n-2]``), which keeps the average of constant data constant and matches the
B-spline models' boundary rule. Sums are exact in float64; integer results are rounded half to
even (``numpy.rint``) and clipped to the type's range.

A compiled separable pass per axis (it releases the GIL, so the build's threads run in parallel)
works on a slab of the output at a time, which bounds its float64 temporaries.
"""

from __future__ import annotations

import numpy as np

from ..._jit import jit

__all__ = ["mirror", "binomial_halve"]


def mirror(index: np.ndarray, n: int) -> np.ndarray:
    """Indices reflected about the first and last voxel of an axis of ``n`` voxels."""
    if n == 1:
        return np.zeros_like(index)
    period = 2 * (n - 1)
    index = np.abs(index) % period
    return np.where(index > n - 1, period - index, index)


@jit(nogil=True)
def _filter_axis(src, index, weights, dst, axis):  # pragma: no cover - compiled
    """``dst[.., o, ..] = sum_t weights[t] * src[.., index[o, t], ..]`` along ``axis``.

    The loops keep the last (contiguous) axis innermost wherever they can, so they vectorise.
    """
    n0, n1, n2 = dst.shape
    dst[...] = 0.0
    if axis == 0:
        for i in range(n0):
            for t in range(weights.shape[0]):
                w, r = weights[t], index[i, t]
                for j in range(n1):
                    for k in range(n2):
                        dst[i, j, k] += w * src[r, j, k]
    elif axis == 1:
        for i in range(n0):
            for j in range(n1):
                for t in range(weights.shape[0]):
                    w, r = weights[t], index[j, t]
                    for k in range(n2):
                        dst[i, j, k] += w * src[i, r, k]
    else:
        for i in range(n0):
            for j in range(n1):
                for k in range(n2):
                    total = 0.0
                    for t in range(weights.shape[0]):
                        total += weights[t] * src[i, j, index[k, t]]
                    dst[i, j, k] = total


_WEIGHTS = np.array([0.25, 0.5, 0.25])


def binomial_halve(fine: np.ndarray, fine_lo: np.ndarray, fine_shape: np.ndarray,
                   halve: tuple[bool, bool, bool], out_lo: np.ndarray,
                   out_shape: np.ndarray) -> np.ndarray:
    """Coarse voxels ``out_lo .. out_lo + out_shape`` (x, y, z) from a fine block.

    ``fine`` holds the fine level's voxels from index ``fine_lo`` on and must contain every
    (mirrored) voxel the output needs: see :func:`fine_range`. ``fine_shape`` is the whole fine
    level's shape; ``halve`` says which axes are halved (the others are copied). One separable
    pass per halved axis, in float64 (exact for integer data).
    """
    values = fine
    offset = np.asarray(fine_lo, np.int64)
    for axis in range(3):
        o = np.arange(out_lo[axis], out_lo[axis] + out_shape[axis])
        if halve[axis]:
            taps = np.stack([2 * o - 1, 2 * o, 2 * o + 1], axis=1)
            index = mirror(taps, int(fine_shape[axis])) - offset[axis]
            weights = _WEIGHTS
        else:
            index = (o - offset[axis])[:, None]
            weights = np.ones(1)
        shape = list(values.shape)
        shape[axis] = len(o)
        out = np.empty(shape, dtype=np.float64)
        _filter_axis(values, np.ascontiguousarray(index, dtype=np.int64), weights, out, axis)
        values = out
    if fine.dtype.kind in "iu":
        info = np.iinfo(fine.dtype)
        return np.clip(np.rint(values), info.min, info.max).astype(fine.dtype)
    return values.astype(fine.dtype)


def fine_range(out_lo: np.ndarray, out_hi: np.ndarray, halve: tuple[bool, bool, bool],
               fine_shape: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fine voxels ``[lo, hi)`` that coarse voxels ``[out_lo, out_hi)`` read (after mirroring)."""
    lo, hi = np.zeros(3, np.int64), np.zeros(3, np.int64)
    for a in range(3):
        if halve[a]:
            idx = mirror(np.arange(2 * out_lo[a] - 1, 2 * out_hi[a]), int(fine_shape[a]))
        else:
            idx = np.arange(out_lo[a], out_hi[a])
        lo[a], hi[a] = idx.min(), idx.max() + 1
    return lo, hi
