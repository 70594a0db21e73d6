"""Gaussian pre-smoothing of a volume before reconstruction (Koch 2009, section 4).

A separable, truncated Gaussian of ``size`` 3 or 5 voxels per axis: the kernel has radius
``r = (size - 1) / 2`` voxels and standard deviation ``sigma = r / 2`` voxels (0.5 for 3^3, 1.0 for
5^3), so it is cut at two standard deviations, and its weights are normalized to sum to 1 (a
constant volume stays constant). Voxels beyond the border repeat the border voxel. Spacing is not
taken into account: the kernel is defined in voxels, as an interactive filter on the grid.
"""

from __future__ import annotations

import numpy as np

from ..errors import ParameterError
from ..volume import Volume

__all__ = ["gaussian_kernel", "smooth"]

#: Supported kernel sizes (voxels per axis).
SIZES = (3, 5)


def gaussian_kernel(size: int) -> np.ndarray:
    """The normalized 1D weights of the ``size``-tap kernel (sigma = (size - 1) / 4 voxels)."""
    if size not in SIZES:
        raise ParameterError(f"smoothing size must be 3 or 5, got {size!r}")
    radius = (size - 1) // 2
    sigma = radius / 2.0
    x = np.arange(-radius, radius + 1, dtype=np.float64)
    w = np.exp(-0.5 * (x / sigma) ** 2)
    return w / w.sum()


def smooth(volume: Volume, size: int = 3) -> Volume:
    """A new float32 volume: ``volume`` filtered with the ``size^3`` Gaussian.

    Parameters
    ----------
    volume : Volume
        The data (any dtype; the result is float32).
    size : {3, 5}
        Kernel edge in voxels.

    Examples
    --------
    >>> import splinecast as sc
    >>> vol = sc.smooth(sc.demo("noise", size=16), 3)
    >>> vol.dtype
    dtype('float32')
    """
    weights = gaussian_kernel(size)
    radius = (size - 1) // 2
    data = np.asarray(volume.data, dtype=np.float32)
    for axis in range(3):
        # One axis at a time over shifted views of an edge-padded copy: numpy does the loops.
        pad = [(0, 0)] * 3
        pad[axis] = (radius, radius)
        padded = np.pad(data, pad, mode="edge")
        out = np.zeros_like(data)
        n = data.shape[axis]
        for tap, w in enumerate(weights):
            index = [slice(None)] * 3
            index[axis] = slice(tap, tap + n)
            out += np.float32(w) * padded[tuple(index)]
        data = out
    metadata = dict(volume.metadata)
    metadata["smoothed"] = size
    return Volume(data, spacing=volume.spacing, origin=volume.origin, metadata=metadata)
