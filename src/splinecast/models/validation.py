"""Checks every model makes before reconstructing a volume."""

from __future__ import annotations

import numpy as np

from ..errors import DataError
from ..volume import Volume

__all__ = ["require_renderable"]


def require_renderable(volume: Volume, min_voxels: int = 2) -> None:
    """Raise :class:`DataError` unless ``volume`` can be reconstructed.

    NaN policy: splinecast never guesses a value for a missing voxel, so NaN (and infinite)
    values are rejected with a message that names the volume and says how to fix it.

    Parameters
    ----------
    volume : Volume
        The data.
    min_voxels : int
        Smallest number of voxels needed along every axis.
    """
    if min(volume.shape) < min_voxels:
        raise DataError(
            f"{volume.name}: needs at least {min_voxels} voxels along every axis, "
            f"shape is {volume.shape}"
        )
    nan_count = volume.count_nan()
    if nan_count:
        raise DataError(
            f"{volume.name}: the data contains {nan_count} NaN values; replace them "
            "(for example with numpy.nan_to_num) before rendering"
        )
    if np.isinf(volume.value_range).any():
        raise DataError(f"{volume.name}: the data contains infinite values")
