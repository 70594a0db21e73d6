"""Independent reference images for MIP: dense trilinear sampling along every pixel ray."""

from __future__ import annotations

import numba
import numpy as np

import splinecast as sc


@numba.njit(parallel=True, cache=True)
def _mip_kernel(data, origin, spacing, origins, directions, step, out):  # pragma: no cover
    n0, n1, n2 = data.shape
    hi = np.array([n0 - 1.0, n1 - 1.0, n2 - 1.0])
    for p in numba.prange(origins.shape[0]):
        # Ray in index space: x = (o + t d - origin) / spacing.
        o = (origins[p] - origin) / spacing
        d = directions[p] / spacing
        t0, t1 = 0.0, np.inf
        for a in range(3):
            if d[a] != 0.0:
                ta = (0.0 - o[a]) / d[a]
                tb = (hi[a] - o[a]) / d[a]
                t0 = max(t0, min(ta, tb))
                t1 = min(t1, max(ta, tb))
            elif o[a] < 0.0 or o[a] > hi[a]:
                t1 = -1.0
        best = -np.inf
        if t1 >= t0:
            dt = step / np.sqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2)  # world step of `step` voxels
            t = t0
            while t <= t1:
                x = min(max(o[0] + t * d[0], 0.0), hi[0])
                y = min(max(o[1] + t * d[1], 0.0), hi[1])
                z = min(max(o[2] + t * d[2], 0.0), hi[2])
                i, j, k = min(int(x), n0 - 2), min(int(y), n1 - 2), min(int(z), n2 - 2)
                fx, fy, fz = x - i, y - j, z - k
                c00 = data[i, j, k] * (1 - fx) + data[i + 1, j, k] * fx
                c10 = data[i, j + 1, k] * (1 - fx) + data[i + 1, j + 1, k] * fx
                c01 = data[i, j, k + 1] * (1 - fx) + data[i + 1, j, k + 1] * fx
                c11 = data[i, j + 1, k + 1] * (1 - fx) + data[i + 1, j + 1, k + 1] * fx
                v = (c00 * (1 - fy) + c10 * fy) * (1 - fz) + (c01 * (1 - fy) + c11 * fy) * fz
                best = max(best, v)
                t += dt
        out[p] = best


def reference_mip(volume: sc.Volume, camera: sc.Camera, step: float = 0.0625) -> np.ndarray:
    """Maximum of the trilinear interpolant along each ray, sampled every ``step`` voxels.

    Returns the maximum normalized to [0, 1] over the data range, 0 where the ray misses the
    volume (the black background of the renderers), shaped ``(height, width)``.
    """
    origins, directions = camera.rays()
    h, w = camera.height, camera.width
    out = np.empty(h * w)
    _mip_kernel(np.asarray(volume.data, np.float64), np.asarray(volume.origin),
                np.asarray(volume.spacing), origins.reshape(-1, 3), directions.reshape(-1, 3),
                float(step), out)
    lo, hi = volume.value_range
    img = (out.reshape(h, w) - lo) / (hi - lo)
    return np.where(np.isfinite(img), img, 0.0)
