"""Quality metrics: where each method put the surface and which way its normal points.

Every method yields, per pixel, a depth (world distance along the unit ray of
:meth:`splinecast.Camera.rays`, ``inf`` on a miss) and a unit normal. Against the analytic function
``f`` the volume samples:

* **position error** of a hit point ``p``: ``|f(p) - iso| / |grad f(p)|``, the distance from
  ``p`` to the exact isosurface to first order (exact for the sphere and torus signed distance
  fields, where ``|grad f| = 1``), reported in voxels;
* **normal error**: the angle between the rendered normal and ``grad f(p)``, both turned to face
  the camera, so a method's inward/outward convention does not count as an error.

The errors measure each method against the *function*, so they include the reconstruction error
of the trilinear interpolant that all methods share, plus what each adds (flat triangles, mesh
normals from finite differences, z-buffer quantization).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import splinecast as sc

from .scenes import Truth


def zbuffer_to_depth(zbuffer: np.ndarray, camera: sc.Camera, near: float, far: float) -> np.ndarray:
    """Convert an OpenGL z-buffer (row 0 on top, values in [0, 1]) to depth along each ray.

    Perspective: the window depth ``zb`` maps to normalized device depth ``zn = 2 zb - 1`` and to
    the eye-space distance along the view axis ``ze = 2 n f / (f + n - zn (f - n))``; the distance
    along the unit ray of a pixel is ``ze / (d . forward)``. Orthographic: depth is linear,
    ``ze = n + zb (f - n)``, and rays are parallel to the view axis. ``zb == 1`` (the cleared
    background) is a miss (``inf``).
    """
    zb = np.asarray(zbuffer, np.float64)
    _, directions = camera.rays()
    if camera.ortho:
        eye_z = near + zb * (far - near)
        depth = eye_z / (directions @ camera.forward)
    else:
        zn = 2.0 * zb - 1.0
        eye_z = 2.0 * near * far / (far + near - zn * (far - near))
        depth = eye_z / (directions @ camera.forward)
    depth[zb >= 1.0] = np.inf
    return depth


@dataclass
class SurfaceQuality:
    """Per-pixel errors of one rendered surface (NaN where the method missed)."""

    position_voxels: np.ndarray
    normal_degrees: np.ndarray
    hits: int

    def summary(self) -> dict[str, float]:
        """Mean, 95th percentile and maximum of both errors over the hit pixels."""
        out: dict[str, float] = {"hits": self.hits}
        for name, err in (("position_voxels", self.position_voxels),
                          ("normal_degrees", self.normal_degrees)):
            values = err[np.isfinite(err)]
            if values.size == 0:
                out.update({f"{name}_mean": np.nan, f"{name}_p95": np.nan, f"{name}_max": np.nan})
                continue
            out[f"{name}_mean"] = float(values.mean())
            out[f"{name}_p95"] = float(np.percentile(values, 95))
            out[f"{name}_max"] = float(values.max())
        return out


def surface_quality(depth: np.ndarray, normals: np.ndarray, camera: sc.Camera, truth: Truth,
                    iso: float, voxel: float) -> SurfaceQuality:
    """Position and normal errors of a rendered surface against the analytic function.

    Parameters
    ----------
    depth : ndarray (h, w)
        World distance along the unit rays of ``camera``; ``inf`` on a miss.
    normals : ndarray (h, w, 3)
        The rendered normals (any length and orientation; normalized here).
    camera : Camera
        The camera the image was rendered with.
    truth : Truth
        The analytic function and its gradient.
    iso : float
        Isovalue.
    voxel : float
        Voxel size in world units (errors are reported in voxels).
    """
    origins, directions = camera.rays()
    hit = np.isfinite(depth)
    pos_err = np.full(depth.shape, np.nan)
    ang_err = np.full(depth.shape, np.nan)
    if hit.any():
        d = directions[hit]
        p = origins[hit] + depth[hit][:, None] * d
        grad = truth.gradient(p)
        gnorm = np.linalg.norm(grad, axis=-1)
        pos_err[hit] = np.abs(truth.value(p) - iso) / np.maximum(gnorm, 1e-300) / voxel
        n = np.asarray(normals, np.float64)[hit]
        n = n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-300)
        g = grad / np.maximum(gnorm, 1e-300)[:, None]
        # Face both towards the camera: the visible side is what the image shows.
        n *= np.where(np.sum(n * d, axis=-1) > 0, -1.0, 1.0)[:, None]
        g *= np.where(np.sum(g * d, axis=-1) > 0, -1.0, 1.0)[:, None]
        cos = np.clip(np.sum(n * g, axis=-1), -1.0, 1.0)
        ang_err[hit] = np.degrees(np.arccos(cos))
    return SurfaceQuality(pos_err, ang_err, int(hit.sum()))


def mesh_normals_at(points: np.ndarray, vertices: np.ndarray, triangles: np.ndarray,
                    vertex_normals: np.ndarray, candidates: int = 8,
                    chunk: int = 65536) -> np.ndarray:
    """The interpolated vertex normal of a triangle mesh at points lying on it.

    This is the normal the rasterizer shades a fragment with (per-vertex normals interpolated
    with the fragment's barycentric coordinates, perspective-correct, i.e. barycentric in 3D).
    Each point (a pixel's hit from the z-buffer) is assigned to the closest of the ``candidates``
    triangles whose centroids are nearest; triangles are about a voxel wide and the z-buffer puts
    points within ~1e-6 voxel of the surface, so the closest triangle is the one drawn.

    Returns
    -------
    ndarray (n, 3)
        Unnormalized interpolated normals.
    """
    from scipy.spatial import cKDTree

    tri = vertices[triangles]                                   # (m, 3, 3)
    tree = cKDTree(tri.mean(axis=1))
    k = min(candidates, len(triangles))
    # Chunks keep the (n, k, 3) temporaries small at 1024x768.
    return np.concatenate([
        _interpolate(points[s:s + chunk], tree, k, tri, triangles, vertex_normals)
        for s in range(0, len(points), chunk)
    ]) if len(points) else np.zeros((0, 3))


def _interpolate(points, tree, k, tri, triangles, vertex_normals) -> np.ndarray:
    _, idx = tree.query(points, k=k)
    idx = idx.reshape(len(points), k)
    a, b, c = (tri[idx, i] for i in range(3))                   # (n, k, 3) each
    # Barycentric coordinates of the projection onto each candidate's plane, clamped to the
    # triangle, and the distance from the point to that clamped point.
    p = points[:, None, :]
    v0, v1, v2 = b - a, c - a, p - a
    d00 = np.sum(v0 * v0, -1)
    d01 = np.sum(v0 * v1, -1)
    d11 = np.sum(v1 * v1, -1)
    d20 = np.sum(v2 * v0, -1)
    d21 = np.sum(v2 * v1, -1)
    den = np.where(np.abs(d00 * d11 - d01 * d01) > 0, d00 * d11 - d01 * d01, 1.0)
    v = (d11 * d20 - d01 * d21) / den
    w = (d00 * d21 - d01 * d20) / den
    v, w = np.clip(v, 0, 1), np.clip(w, 0, 1)
    over = v + w > 1
    total = np.where(over, v + w, 1.0)
    v, w = np.where(over, v / total, v), np.where(over, w / total, w)
    u = 1 - v - w
    closest = u[..., None] * a + v[..., None] * b + w[..., None] * c
    dist = np.linalg.norm(closest - p, axis=-1)
    best = np.argmin(dist, axis=1)
    rows = np.arange(len(points))
    t = idx[rows, best]
    bu, bv, bw = u[rows, best], v[rows, best], w[rows, best]
    vn = vertex_normals[triangles[t]]                           # (n, 3, 3)
    return bu[:, None] * vn[:, 0] + bv[:, None] * vn[:, 1] + bw[:, None] * vn[:, 2]
