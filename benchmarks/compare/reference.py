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


@numba.njit(parallel=True, cache=True)
def _dvr_kernel(data, origin, spacing, origins, directions, step, values, alphas, lo, hi_v,
                out):  # pragma: no cover
    n0, n1, n2 = data.shape
    hi = np.array([n0 - 1.0, n1 - 1.0, n2 - 1.0])
    npts = values.shape[0]
    for p in numba.prange(origins.shape[0]):
        # Ray in index space, parametrized by index-space length s: x = o + s * d.
        o = (origins[p] - origin) / spacing
        d = directions[p] / spacing
        d = d / np.sqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2)
        s0, s1 = 0.0, np.inf
        for a in range(3):
            if d[a] != 0.0:
                ta = (0.0 - o[a]) / d[a]
                tb = (hi[a] - o[a]) / d[a]
                s0 = max(s0, min(ta, tb))
                s1 = min(s1, max(ta, tb))
            elif o[a] < 0.0 or o[a] > hi[a]:
                s1 = -1.0
        c = 0.0
        trans = 1.0
        if s1 > s0:
            n = max(1, int(np.ceil((s1 - s0) / step)))
            h = (s1 - s0) / n  # at most `step`: n equal segments, one sample at each midpoint
            for m in range(n):
                s = s0 + (m + 0.5) * h
                x = min(max(o[0] + s * d[0], 0.0), hi[0])
                y = min(max(o[1] + s * d[1], 0.0), hi[1])
                z = min(max(o[2] + s * d[2], 0.0), hi[2])
                i, j, k = min(int(x), n0 - 2), min(int(y), n1 - 2), min(int(z), n2 - 2)
                fx, fy, fz = x - i, y - j, z - k
                c00 = data[i, j, k] * (1 - fx) + data[i + 1, j, k] * fx
                c10 = data[i, j + 1, k] * (1 - fx) + data[i + 1, j + 1, k] * fx
                c01 = data[i, j, k + 1] * (1 - fx) + data[i + 1, j, k + 1] * fx
                c11 = data[i, j + 1, k + 1] * (1 - fx) + data[i + 1, j + 1, k + 1] * fx
                v = (c00 * (1 - fy) + c10 * fy) * (1 - fz) + (c01 * (1 - fy) + c11 * fy) * fz
                # Opacity of a one-voxel slab: piecewise linear, constant beyond the end points.
                if v <= values[0]:
                    a1 = alphas[0]
                elif v >= values[npts - 1]:
                    a1 = alphas[npts - 1]
                else:
                    q = 0
                    while values[q + 1] < v:
                        q += 1
                    w = (v - values[q]) / (values[q + 1] - values[q])
                    a1 = alphas[q] * (1 - w) + alphas[q + 1] * w
                if a1 <= 0.0:
                    continue
                alpha = 1.0 - (1.0 - min(a1, 1.0 - 1e-6)) ** h  # opacity of a slab h voxels thick
                grey = min(max((v - lo) / (hi_v - lo), 0.0), 1.0)
                c += trans * alpha * grey
                trans *= 1.0 - alpha
                if trans < 1e-7:
                    break
        out[p] = c


def reference_dvr(volume: sc.Volume, camera: sc.Camera, transfer: list[tuple[float, float]],
                  step: float = 0.0625) -> np.ndarray:
    """Emission-absorption compositing of the grey transfer function, every ``step`` voxels.

    ``transfer`` is the opacity as control points ``(value, alpha)`` with ``alpha`` the opacity of
    a slab one voxel (index unit) thick, linear between points and constant beyond them (the
    convention of ``splinecast.TransferFunction``); a sample over a segment ``h`` voxels long has
    opacity ``1 - (1 - alpha)^h``. The colour is a grey ramp over the data range. The field is the
    trilinear interpolant, sampled at the midpoints of equal segments no longer than ``step``
    (index-space length) between the ray's entry into and exit from the grid. Returns premultiplied
    RGB over black, shaped ``(height, width, 3)``.
    """
    origins, directions = camera.rays()
    h, w = camera.height, camera.width
    pts = np.asarray(transfer, np.float64)
    out = np.empty(h * w)
    lo, hi = volume.value_range
    _dvr_kernel(np.asarray(volume.data, np.float64), np.asarray(volume.origin, np.float64),
                np.asarray(volume.spacing, np.float64), origins.reshape(-1, 3),
                directions.reshape(-1, 3), float(step), pts[:, 0].copy(), pts[:, 1].copy(),
                float(lo), float(hi), out)
    grey = out.reshape(h, w)
    return np.repeat(grey[..., None], 3, axis=2)


def image_error(image: np.ndarray, reference: np.ndarray) -> float:
    """Mean absolute difference over pixels (and RGB channels) between an image and a reference.

    Both are premultiplied over the same (black) background, values in [0, 1]; images of another
    size are not accepted (render the method with the reference's camera).
    """
    image, reference = np.asarray(image, np.float64), np.asarray(reference, np.float64)
    if image.shape != reference.shape:
        raise ValueError(f"image shape {image.shape} != reference shape {reference.shape}")
    return float(np.mean(np.abs(image - reference)))
