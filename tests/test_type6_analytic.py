"""Type-6 spline hits against an analytic surface, with no use of the models' prepared arrays.

For quadratic data ``q(x) = (x - c)^T M (x - c)`` (index units) both type-6 schemes give
``q + tr(M) / 4`` inside the volume, i.e. ``q + Delta q / 8`` (the S31 note and the s31 docstring;
QSS-A and QSS-B give the same), and S31 with ``prefilter=True`` gives ``q`` itself, where the
stencils see only real voxels (the prefilter's 7-point Laplacian and the 27 values around a cube:
cubes 2 .. n-3, i.e. index box [1.5, n - 2.5]). The isosurface is then the ellipsoid
``q = iso - shift``, and the first hit of a ray ``o + t d`` is the first root, after the clipped
start, of the scalar quadratic ``q(o + t d) = iso - shift``, solved here in closed form. The
normal is ``M (x - c)`` scaled to world units, pointing out of the ellipsoid (inside "low").

Tolerance on depths: the patch coefficients are averages of voxel values of size ``V <= 40``
(and the ray restriction is a few more operations), so each carries an absolute rounding error
below ``E = 64 eps V ~ 6e-13``; a root of a polynomial whose slope along the ray is at least
``S`` per voxel moves by at most ``E / S``. Rays whose slope at the root is below ``S = 0.05`` per
voxel are grazing and left out of the depth comparison (not of the hit/miss comparison); the
tolerance is ``E / 0.05 ~ 1.2e-11`` voxels, rounded up to 1e-10. Normals are compared to 1e-6
per component (they are stored as float32).
"""

from __future__ import annotations

import numpy as np
import pytest
from reference import planes_interval

import splinecast as sc

SHAPE = (16, 15, 17)
SPACING = np.array([1.0, 1.25, 0.8])
ORIGIN = np.array([-2.0, 1.0, 0.5])
CENTRE = np.array([7.4, 6.9, 8.2])  # index units
SEMI_AXES = np.array([4.0, 3.2, 3.6])  # index units, before rotation
LEVEL = 1.0  # the ellipsoid q = 1
DEPTH_TOL = 1e-10  # voxels (module docstring)
SLOPE_MIN = 0.05  # per voxel
NORMAL_TOL = 1e-6


def _rotation():
    a, b = 0.4, -0.7
    rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    rx = np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])
    return rz @ rx


M = _rotation() @ np.diag(1.0 / SEMI_AXES**2) @ _rotation().T
SHIFT = np.trace(M) / 4.0  # Delta q / 8 with Delta q = 2 tr(M)

# (model, options, what the reconstruction adds to q)
CASES = [
    ("s31", {"prefilter": True}, 0.0),
    ("s31", {"prefilter": True, "root_finder": "newton"}, 0.0),
    ("s31", {"prefilter": True, "precompute": True}, 0.0),
    ("s31", {}, SHIFT),
    ("qss", {}, SHIFT),
    ("qss", {"variant": "qss-a"}, SHIFT),
]


@pytest.fixture(scope="module")
def volume():
    idx = np.indices(SHAPE, dtype=np.float64)
    rel = np.moveaxis(idx, 0, -1) - CENTRE
    q = np.einsum("...i,ij,...j->...", rel, M, rel)
    return sc.Volume(q, spacing=SPACING, origin=ORIGIN, metadata={"inside": "low"})


def test_the_ellipsoid_lies_where_the_reconstruction_is_exact():
    # Its bounding box (centre +- the square roots of diag(M^-1)) is inside [1.5, n - 2.5].
    half = np.sqrt(np.diag(np.linalg.inv(M)) * (LEVEL + SHIFT))
    assert np.all(CENTRE - half > 1.5 + 0.5) and np.all(CENTRE + half < np.array(SHAPE) - 3.0)


def analytic_first_hits(camera, clip, level):
    """First root after the clipped start of q(o + t d) = level for every pixel ray.

    Returns ``(depth, slope)``: world depth (inf on a miss) and |dq/ds| per voxel at the root.
    """
    W, U = camera.rays()
    W, U = W.reshape(-1, 3), U.reshape(-1, 3)
    t_min, t_max = planes_interval(W, U, clip or [])
    o = (W - ORIGIN) / SPACING - CENTRE
    d = U / SPACING
    A = np.einsum("ri,ij,rj->r", d, M, d)
    B = 2 * np.einsum("ri,ij,rj->r", d, M, o)
    C = np.einsum("ri,ij,rj->r", o, M, o) - level
    disc = B * B - 4 * A * C
    sq = np.sqrt(np.maximum(disc, 0.0))
    # cancellation-free roots
    qq = -0.5 * (B + np.copysign(sq, B))
    r1, r2 = np.sort(np.stack([qq / A, np.where(qq != 0, C / np.where(qq != 0, qq, 1), 0)]),
                     axis=0)
    with np.errstate(invalid="ignore"):
        start_inside = np.isfinite(t_min) & (A * t_min**2 + B * t_min + C < 0)
    depth = np.where(start_inside, r2, np.where(r1 >= t_min, r1, np.inf))
    depth = np.where((disc >= 0) & (depth <= t_max), depth, np.inf)
    speed = np.linalg.norm(d, axis=1)  # voxels per world unit
    slope = np.abs(2 * A * depth + B) / speed
    shape = (camera.height, camera.width)
    return depth.reshape(shape), slope.reshape(shape), disc.reshape(shape)


@pytest.fixture(scope="module")
def cameras(volume):
    centre_world = ORIGIN + CENTRE * SPACING
    az, el = np.radians(35.0), np.radians(25.0)
    eye = centre_world + 16.0 * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az),
                                          np.sin(el)])
    cam = sc.Camera(eye, centre_world, fov=36.0, size=(26, 22))  # the ellipsoid fills the view
    n = cam.forward + np.array([0.1, -0.2, 0.05])
    cut = [(*n, -float(n @ centre_world))]  # keeps the far half: rays start inside the object
    return cam, cut


@pytest.mark.parametrize("model, options, shift", CASES,
                         ids=[f"{m}-{'-'.join(f'{k}={v}' for k, v in o.items())}"
                              for m, o, _ in CASES])
def test_hits_normals_and_faces_on_the_ellipsoid(volume, cameras, model, options, shift):
    cam, cut = cameras
    scene = sc.Scene(volume, model=model, **options)
    _, dirs = cam.rays()
    speed = np.linalg.norm(dirs / SPACING, axis=-1)
    checked_faces = set()
    for clip in (None, cut):
        frame = scene.render(cam, iso=LEVEL + shift, clip=clip)
        depth, slope, disc = analytic_first_hits(cam, clip, LEVEL)
        # hit or miss as the analytic ellipsoid says (tangent rays, disc ~ 0, are undecidable)
        decided = np.abs(disc) > 1e-9
        np.testing.assert_array_equal(frame.hit[decided], np.isfinite(depth)[decided])
        both = frame.hit & np.isfinite(depth)
        steep = both & (slope >= SLOPE_MIN)
        assert steep.sum() > 100
        err = np.abs(frame.depth[steep] - depth[steep]) * speed[steep]
        assert err.max() <= DEPTH_TOL, err.max()
        # normals: M (x - c) in index units, to world by 1/spacing, outward (q grows outwards)
        p = volume.world_to_index(frame.position[both]) - CENTRE
        g = (p @ M) / SPACING
        expected = g / np.linalg.norm(g, axis=-1, keepdims=True)
        assert np.abs(frame.normal[both] - expected).max() <= NORMAL_TOL
        # faces: the ray enters the ellipsoid (front) unless it started inside it (back)
        inside_before = np.einsum("ri,ij,rj->r", p - 1e-6 * (dirs[both] / SPACING), M,
                                  p - 1e-6 * (dirs[both] / SPACING)) < LEVEL
        np.testing.assert_array_equal(frame.face[both], np.where(inside_before, -1, 1))
        checked_faces |= set(np.unique(frame.face[both]).tolist())
    assert checked_faces == {-1, 1}
