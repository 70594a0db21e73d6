"""Normals and faces of every model's isosurface hits against the reconstruction itself.

With ``normals="exact"``, at each hit the reported unit normal must equal the normalized gradient
of the reconstruction there (outward: ``-g/|g|`` when the object is where values are high,
``+g/|g|`` when low), to 1e-6 per component, and the face must say whether the ray enters the
object: the field is evaluated just before and just after the hit along the ray.

The gradient is taken by central differences of a value evaluation that shares nothing with the
kernels' ray code (``evaluators.py``: the lerp-form trilinear interpolant, scipy's B-splines, the
type-6 models' point evaluation).

Why 1e-6 holds: inside one polynomial piece (a cell; a half-integer cell for even-degree
B-splines; a tetrahedron for the type-6 splines) the field has degree <= 3 per axis, so a central
difference with step h = 1e-5 voxels has truncation error h^2 |f'''| / 6 < 1e-9 and rounding error
~ eps |f| / h ~ 1e-10 for |f| <= 5; divided by |g| >= 0.05 this moves the normal by < 1e-8. The
stored normal is float32 (6e-8 per component). Hits closer than 1e-4 voxels to a piece boundary
(where the gradient of a C0 piece is not defined and a difference would straddle two pieces) are
left out; at least half the hits remain. The volume is anisotropic so the index-to-world gradient
scaling is exercised, and a clip plane exposes back faces.

With the default ``normals="smooth"`` the hits are the same, and the normal of the models that
are only continuous (trilinear, the linear B-spline) is the gradient of the cubic B-spline of the
voxels, continued linearly beyond the volume: the reference is scipy's ``map_coordinates``
(``order=3``, no prefilter) on the voxels padded by their odd reflection, by central differences
(the field is a cubic per cell: the same 1e-6 bound, and no piece boundary to avoid, it is C2).
The other models shade with their own gradient.
"""

from __future__ import annotations

import numpy as np
import pytest
from evaluators import Evaluator, model_evaluator
from pairs import MODELS_FOR_MODE
from scenes import NOISE_ISO, noise_volume

import splinecast as sc

ISO = NOISE_ISO
H = 1e-5  # finite-difference step, voxels
MARGIN = 1e-4  # distance to piece boundaries and the domain border, voxels
NORMAL_TOL = 1e-6


@pytest.fixture(scope="module")
def volume():
    return noise_volume()


@pytest.fixture(scope="module")
def camera(volume):
    return sc.Camera.orbit(volume, azimuth=40, elevation=25, size=(28, 22), zoom=1.2)


@pytest.fixture(scope="module")
def clip(volume, camera):
    """A plane through the volume centre keeping the half away from the camera: rays start on
    the cut, inside the object where it is cut, and see back faces there."""
    n = camera.forward
    return [(*n, -float(n @ volume.center))]


def gradient_world(value, p, spacing):
    grads = [(value(p + H * e) - value(p - H * e)) / (2 * H) for e in np.eye(3)]
    return np.stack(grads, axis=-1) / np.asarray(spacing)


def check_normals_and_faces(frame, volume, camera, ev, inside, isos):
    """Assert normals to NORMAL_TOL and faces at the hits of ``frame``; returns counts."""
    origins, dirs = camera.rays()
    hit = frame.hit
    assert hit.sum() > 60
    p = volume.world_to_index(frame.position[hit])
    d = dirs[hit] / np.asarray(volume.spacing)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)  # unit index-space direction
    value, lo, hi = ev.value, ev.lo, ev.hi
    interior = np.all((p > lo + 2 * MARGIN) & (p < hi - 2 * MARGIN), axis=-1)
    # --- faces: which side of the crossed isovalue the ray comes from
    v = value(p)
    crossed = np.asarray(isos)[np.argmin(np.abs(v[:, None] - np.asarray(isos)[None, :]), axis=1)]
    before = value(p - 1e-6 * d) - crossed
    after = value(p + 1e-6 * d) - crossed
    crossing = interior & (np.sign(before) * np.sign(after) < 0)
    assert crossing.sum() >= 0.95 * interior.sum()  # only grazing hits fail to change sign
    enters = (before < 0) if inside == "high" else (before > 0)
    face = frame.face[hit]
    np.testing.assert_array_equal(face[crossing], np.where(enters[crossing], 1, -1))
    # --- normals: normalized world gradient, pointing away from the inside
    g = gradient_world(value, p, volume.spacing)
    gnorm = np.linalg.norm(g, axis=-1)
    ok = interior & (ev.boundary(p) > MARGIN) & (gnorm > 0.05)
    assert ok.sum() >= 0.5 * hit.sum()
    expected = (-1.0 if inside == "high" else 1.0) * g[ok] / gnorm[ok, None]
    got = frame.normal[hit][ok].astype(np.float64)
    err = np.abs(got - expected).max()
    assert err <= NORMAL_TOL, err
    return int((face == 1).sum()), int((face == -1).sum())


#: The models whose shading field is the cubic B-spline of the voxels (the others: their own).
SMOOTHED = ("trilinear", "bspline1")


def smooth_evaluator(volume, ev: Evaluator) -> Evaluator:
    """The shading field of the C0 models: the cubic B-spline whose coefficients are the voxels,
    continued linearly beyond the volume (``v[-1] = 2 v[0] - v[1]``); the value and box of the
    model's own evaluator ``ev`` are kept for the faces, only its gradient is this field's."""
    from scipy import ndimage

    padded = np.pad(np.asarray(volume.data, np.float64), 1, mode="reflect", reflect_type="odd")

    def field(p):
        q = np.moveaxis(np.asarray(p, np.float64) + 1.0, -1, 0)
        return ndimage.map_coordinates(padded, q.reshape(3, -1), order=3, prefilter=False,
                                       mode="nearest").reshape(q.shape[1:])

    return Evaluator(field, lambda p: np.full(np.shape(p)[:-1], np.inf), ev.lo, ev.hi)


def check_smooth_normals(frame, volume, camera, field):
    """The hits' normals are the normalized gradient of ``field`` (outward, inside high)."""
    hit = frame.hit
    p = volume.world_to_index(frame.position[hit])
    interior = np.all((p > field.lo + 2 * MARGIN) & (p < field.hi - 2 * MARGIN), axis=-1)
    g = gradient_world(field.value, p, volume.spacing)
    gnorm = np.linalg.norm(g, axis=-1)
    ok = interior & (gnorm > 0.05)
    assert ok.sum() >= 0.9 * hit.sum()
    err = np.abs(frame.normal[hit][ok].astype(np.float64) + g[ok] / gnorm[ok, None]).max()
    assert err <= NORMAL_TOL, err


@pytest.mark.parametrize("inside", ["high", "low"])
@pytest.mark.parametrize("model_name", MODELS_FOR_MODE["iso"])
def test_iso_normals_and_faces(volume, camera, clip, model_name, inside):
    scene = sc.Scene(volume, model=model_name)
    ev = model_evaluator(model_name, volume, scene)
    fronts = backs = 0
    for planes in (None, clip):
        frame = scene.render(camera, iso=ISO, inside=inside, clip=planes, normals="exact")
        f, b = check_normals_and_faces(frame, volume, camera, ev, inside, [ISO])
        fronts, backs = fronts + f, backs + b
    assert fronts > 20 and backs > 20  # both faces were checked


@pytest.mark.parametrize("model_name", MODELS_FOR_MODE["iso"])
def test_smooth_normals_keep_the_hits_and_faces(volume, camera, clip, model_name):
    """The default: the same hits and faces as ``normals="exact"``; the C0 models' normals are
    the smooth field's (the sampled method's too), the others' their own gradient."""
    scene = sc.Scene(volume, model=model_name)
    ev = model_evaluator(model_name, volume, scene)
    for planes in (None, clip):
        exact = scene.render(camera, iso=ISO, clip=planes, normals="exact")
        frame = scene.render(camera, iso=ISO, clip=planes)
        np.testing.assert_array_equal(frame.depth, exact.depth)
        np.testing.assert_array_equal(frame.face, exact.face)
        if model_name in SMOOTHED:
            check_smooth_normals(frame, volume, camera, smooth_evaluator(volume, ev))
            assert not np.allclose(frame.normal[frame.hit], exact.normal[exact.hit], atol=1e-3)
        else:
            np.testing.assert_array_equal(frame.normal, exact.normal)
    if model_name == "trilinear":
        sampled = scene.render(camera, iso=ISO, method="sampled", step=0.1)
        check_smooth_normals(sampled, volume, camera, smooth_evaluator(volume, ev))


@pytest.mark.parametrize("model_name", MODELS_FOR_MODE["multi-iso"])
def test_multi_iso_first_crossing_normals_and_faces(volume, camera, clip, model_name):
    """``Frame.normal``/``face`` of several isosurfaces describe the first crossing."""
    scene = sc.Scene(volume, model=model_name)
    ev = model_evaluator(model_name, volume, scene)
    isos = [-0.4, ISO, 0.9]
    for planes in (None, clip):
        frame = scene.render(camera, iso=isos, clip=planes, normals="exact")
        check_normals_and_faces(frame, volume, camera, ev, "high", isos)
        smooth = scene.render(camera, iso=isos, clip=planes)
        np.testing.assert_array_equal(smooth.face, frame.face)
        if model_name in SMOOTHED:
            check_smooth_normals(smooth, volume, camera, smooth_evaluator(volume, ev))
