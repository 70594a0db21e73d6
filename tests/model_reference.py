"""Each model's reconstruction evaluated directly at points, for references along rays.

These evaluate the 3D reconstruction itself, never its restriction to a ray (the renderer's ray
pieces): trilinear interpolation in lerp form (:func:`reference.trilinear`), tensor B-splines by
``scipy.ndimage.map_coordinates`` (an implementation independent of splinecast), and the type-6
splines by the model's direct evaluation from its coefficient rules and de Casteljau's algorithm
(not the renderer's averaging chain, cube cache and blossoms). On top: dense sampling along a
ray with bisection (first crossings, all crossings), refined extrema, and an emission-absorption
integral whose transfer function is evaluated from its control points with ``np.interp``.
"""

from __future__ import annotations

import numpy as np
from reference import trilinear
from scipy.ndimage import map_coordinates

import splinecast as sc

__all__ = ["field", "domain_interval", "ray_samples", "crossings", "gradient_fd",
           "tf_opacity", "tf_color", "dvr_reference"]


def field(scene: sc.Scene):
    """``f(points)`` with points in voxel index space, shape (..., 3): the model's spline."""
    name = scene.model.name
    data = np.asarray(scene.volume.data, np.float64)
    if name == "trilinear":
        return lambda p: trilinear(data, p)
    if name.startswith("bspline"):
        d = int(name[-1])

        def spline(p):
            p = np.asarray(p, np.float64)
            flat = p.reshape(-1, 3).T
            return map_coordinates(data, flat, order=d, mode="mirror",
                                   prefilter=False).reshape(p.shape[:-1])
        return spline
    model = scene.model
    return lambda p: model.evaluate(np.asarray(p, np.float64).reshape(-1, 3)).reshape(
        np.shape(p)[:-1])


def domain_interval(scene: sc.Scene, o: np.ndarray, u: np.ndarray) -> tuple[float, float]:
    """Parameter interval of the world ray ``o + t u`` (t >= 0) inside the model's domain."""
    vol = scene.volume
    lo, hi = scene.model.domain()
    origin, spacing = np.asarray(vol.origin), np.asarray(vol.spacing)
    wlo, whi = origin + lo * spacing, origin + hi * spacing
    with np.errstate(divide="ignore", invalid="ignore"):
        ta, tb = (wlo - o) / u, (whi - o) / u
    t0 = max(0.0, float(np.nanmax(np.minimum(ta, tb))))
    t1 = float(np.nanmin(np.maximum(ta, tb)))
    return t0, t1


def ray_samples(scene, f, o, u, t0, t1, dvox):
    """Parameters and field values every ``dvox`` voxels from ``t0`` to ``t1`` (both ends)."""
    spacing, origin = np.asarray(scene.volume.spacing), np.asarray(scene.volume.origin)
    per_world = float(np.linalg.norm(u / spacing))  # voxels per world unit along the ray
    n = max(int((t1 - t0) * per_world / dvox) + 2, 2)
    ts = np.linspace(t0, t1, n)
    p = (o + np.multiply.outer(ts, u) - origin) / spacing
    return ts, f(p), per_world


def _at(scene, f, o, u, t):
    spacing, origin = np.asarray(scene.volume.spacing), np.asarray(scene.volume.origin)
    return float(f(((o + t * u - origin) / spacing)[None, :])[0])


def crossings(scene, f, o, u, iso, dvox=0.01, first_only=False):
    """Parameters where the field crosses ``iso`` along the ray: sign changes of samples every
    ``dvox`` voxels, refined by bisection to 1e-13 world units (increasing)."""
    t0, t1 = domain_interval(scene, o, u)
    if not t0 < t1:
        return []
    ts, vs, _ = ray_samples(scene, f, o, u, t0, t1, dvox)
    g = vs - iso
    out = []
    for m in np.flatnonzero((g[:-1] < 0) != (g[1:] < 0)):
        a, b, ga = ts[m], ts[m + 1], g[m]
        while b - a > 1e-13:
            mid = 0.5 * (a + b)
            gm = _at(scene, f, o, u, mid) - iso
            if (gm < 0) == (ga < 0):
                a, ga = mid, gm
            else:
                b = mid
        out.append(0.5 * (a + b))
        if first_only:
            break
    return out


def gradient_fd(scene, f, point_world, h=1e-5):
    """World-space gradient of the field by central differences (``h`` voxels)."""
    spacing, origin = np.asarray(scene.volume.spacing), np.asarray(scene.volume.origin)
    p = (np.asarray(point_world) - origin) / spacing
    g = np.empty(3)
    for a in range(3):
        e = np.zeros(3)
        e[a] = h
        g[a] = (f((p + e)[None, :])[0] - f((p - e)[None, :])[0]) / (2 * h * spacing[a])
    return g


def tf_opacity(points, values):
    """Opacity of a transfer function from its ``(value, alpha)`` control points."""
    pts = np.asarray(points, np.float64)
    return np.interp(values, pts[:, 0], pts[:, 1])


def tf_color(colormap, domain, values):
    """RGB of a named colormap stretched over ``domain``, from its control points."""
    cm = np.asarray(sc.transfer.COLORMAPS[colormap], np.float64)
    x = (np.asarray(values) - domain[0]) / (domain[1] - domain[0])
    return np.stack([np.interp(x, cm[:, 0], cm[:, c]) for c in (1, 2, 3)], axis=-1)


def dvr_reference(scene, f, o, u, points, colormap, domain, dvox=0.002):
    """Premultiplied RGB and opacity of the emission-absorption integral along one ray.

    ``alpha`` of the control points is the opacity of one voxel of material, so the extinction
    is ``tau = -ln(1 - alpha)`` per voxel length; the integral is evaluated with the midpoint
    rule on ``dvox``-voxel steps (transmittance exact per step).
    """
    t0, t1 = domain_interval(scene, o, u)
    if not t0 < t1:
        return np.zeros(3), 0.0
    ts, _, per_world = ray_samples(scene, f, o, u, t0, t1, dvox)
    mids = 0.5 * (ts[:-1] + ts[1:])
    spacing, origin = np.asarray(scene.volume.spacing), np.asarray(scene.volume.origin)
    v = f((o + np.multiply.outer(mids, u) - origin) / spacing)
    lengths = np.diff(ts) * per_world
    tau = -np.log1p(-np.minimum(tf_opacity(points, v), 1 - 1e-6))
    a = -np.expm1(-tau * lengths)
    trans = np.concatenate([[1.0], np.cumprod(1.0 - a)[:-1]])
    c = tf_color(colormap, domain, v)
    rgb = (c * (trans * a)[:, None]).sum(axis=0)
    return rgb, 1.0 - float(np.prod(1.0 - a))
