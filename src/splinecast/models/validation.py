"""Checks every model makes before reconstructing a volume."""

from __future__ import annotations

from ..errors import DataError
from ..volume import Volume

__all__ = ["require_renderable"]


def require_renderable(volume: Volume, min_voxels: int = 2) -> None:
    """Raise :class:`DataError` unless ``volume`` can be reconstructed.

    Non-finite policy: splinecast never guesses a value for a missing voxel, so NaN and infinite
    values are rejected (:meth:`Volume.require_finite`) with a message that names the volume and
    says how to fix it.

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
    volume.require_finite()  # the non-finite policy of splinecast.volume: NaN, +inf, -inf
