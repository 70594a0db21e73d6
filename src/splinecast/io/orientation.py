"""Bring a file's voxel axes onto splinecast's world axes (transpose and flip, never resample).

NRRD, NIfTI and DICOM describe where voxel ``(i, j, k)`` sits with a 3x3 matrix ``M`` (column ``c``
is the world step of one voxel along index axis ``c``) and the position of voxel 0. splinecast's
convention has no rotation: index axis 0 runs along +x, 1 along +y, 2 along +z. When ``M`` is a
scaled signed permutation this is reached exactly with array views (``transpose`` and reversed
slices), so a memory map stays a memory map. When ``M`` is oblique, each index axis is snapped to
the world axis it is closest to and the remaining rotation is dropped, with a warning.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

from ..errors import ReadError
from ..volume import OrientationWarning  # defined with the convention it protects

__all__ = ["OrientationWarning", "align_to_world"]

_AXES = "xyz"

#: Relative tolerance under which a direction counts as parallel to a world axis. Headers store
#: directions in float32 (NIfTI) or decimal text, so exact zeros cannot be expected.
_TOL = 1e-4




def align_to_world(
    data: np.ndarray, matrix: Any, origin: Any, label: str
) -> tuple[np.ndarray, tuple[float, float, float], tuple[float, float, float]]:
    """Return ``(data, spacing, origin)`` following splinecast's axis convention.

    Parameters
    ----------
    data : ndarray, shape (n0, n1, n2)
        Voxels in the file's index order.
    matrix : array_like, shape (3, 3)
        Column ``c`` is the world displacement of one step along index axis ``c``.
    origin : array_like, shape (3,)
        World position of voxel ``(0, 0, 0)`` as stored in the file.
    label : str
        File or folder name used in warnings and errors.

    Returns
    -------
    data : ndarray
        A view of ``data`` with axes transposed/reversed so that index axes run along +x, +y, +z.
    spacing : tuple of float
        Length of each (reordered) column of ``matrix``.
    origin : tuple of float
        World position of the new voxel ``(0, 0, 0)``.

    Warns
    -----
    OrientationWarning
        When axes are flipped or permuted (lossless) or the matrix is oblique (rotation dropped).
    """
    m = np.asarray(matrix, dtype=np.float64).reshape(3, 3)
    org = np.asarray(origin, dtype=np.float64).reshape(3)
    norms = np.linalg.norm(m, axis=0)
    if not np.all(np.isfinite(norms)) or np.any(norms <= 0):
        raise ReadError(f"{label}: voxel axis directions of zero or undefined length: {m.tolist()}")
    unit = m / norms
    # World axis each index axis is closest to; fall back to the identity for a 45-degree tie.
    world_of = np.argmax(np.abs(unit), axis=0)
    if sorted(world_of.tolist()) != [0, 1, 2]:
        world_of = np.arange(3)
    signs = np.sign(unit[world_of, np.arange(3)])
    signs[signs == 0] = 1.0
    snapped = np.zeros((3, 3))
    snapped[world_of, np.arange(3)] = signs
    if np.max(np.abs(unit - snapped)) > _TOL:
        warnings.warn(
            f"{label}: oblique voxel axes; the rotation is ignored (axes snapped to x, y, z)",
            OrientationWarning,
            stacklevel=3,
        )

    # Flipping index axis c moves voxel 0 to the far end of that axis.
    new_origin = org.copy()
    for c in range(3):
        if signs[c] < 0:
            new_origin += (data.shape[c] - 1) * m[:, c]
    index_of = np.argsort(world_of)  # index axis that becomes world axis a
    if not np.array_equal(index_of, np.arange(3)):
        order = ", ".join(_AXES[world_of[c]] for c in range(3))
        warnings.warn(
            f"{label}: voxel axes are stored in world order ({order}); "
            "the array is transposed (a view) to x, y, z",
            OrientationWarning,
            stacklevel=3,
        )
        data = data.transpose(tuple(index_of))
    flipped = [a for a in range(3) if signs[index_of[a]] < 0]
    if flipped:
        names = ", ".join(_AXES[a] for a in flipped)
        warnings.warn(
            f"{label}: axis {names} decreases with the voxel index in the file; "
            "the array is flipped (a view) so that it increases",
            OrientationWarning,
            stacklevel=3,
        )
        index = tuple(slice(None, None, -1) if a in flipped else slice(None) for a in range(3))
        data = data[index]
    spacing = norms[index_of]
    return (
        data,
        (float(spacing[0]), float(spacing[1]), float(spacing[2])),
        (float(new_origin[0]), float(new_origin[1]), float(new_origin[2])),
    )
