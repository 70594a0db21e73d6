"""A 2x2x2 mean pyramid in numpy, slab by slab: the stand-in store of tests and benchmarks.

Level ``l`` has ``ceil(n / 2)`` voxels per axis of level ``l - 1``; each voxel is the mean of the
(up to) 2x2x2 voxels below it (at an odd border the mean of those that exist), rounded to the
nearest integer for integer dtypes so every level keeps the source dtype, as a brick store does.
The continuous index map of a level is :func:`~.cut.histograms.mean_pyramid_map` (regular
spacing; the last voxel of an odd border averages fewer voxels and sits half a voxel off it, as
NGFF's one scale and translation per level cannot say otherwise).

The pyramid store of the multiresolution renderer writes its own levels; this module only lets the
cut metric be built and tested without it.
"""

from __future__ import annotations

import numpy as np

__all__ = ["mean_downsample", "mean_pyramid"]

#: Source voxels per slab (bounds the temporary float arrays to ~128 MiB).
_SLAB_VOXELS = 1 << 24


def mean_downsample(data: np.ndarray) -> np.ndarray:
    """One level down: the 2x2x2 mean, same dtype (integers rounded half up)."""
    data = np.asarray(data)
    shape = tuple(-(-n // 2) for n in data.shape)
    out = np.empty(shape, data.dtype)
    plane = int(np.prod(data.shape[1:]))
    slab = max(2, (_SLAB_VOXELS // max(plane, 1)) // 2 * 2)
    for x0 in range(0, data.shape[0], slab):
        block = np.asarray(data[x0:x0 + slab], np.float64)
        for axis in range(3):
            if block.shape[axis] % 2:  # replicate the last layer: the mean of what exists
                last = np.take(block, [-1], axis=axis)
                block = np.concatenate([block, last], axis=axis)
        nx, ny, nz = (s // 2 for s in block.shape)
        mean = block.reshape(nx, 2, ny, 2, nz, 2).mean(axis=(1, 3, 5))
        if np.issubdtype(data.dtype, np.integer):
            mean = np.floor(mean + 0.5)
        out[x0 // 2:x0 // 2 + nx] = mean.astype(data.dtype)
    return out


def mean_pyramid(source: np.ndarray, levels: int) -> list[np.ndarray]:
    """``[source, level 1, ..., level levels-1]``; ``source`` may be a ``numpy.memmap``."""
    out = [source]
    for _ in range(1, int(levels)):
        out.append(mean_downsample(out[-1]))
    return out
