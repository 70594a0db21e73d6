"""Every model in every mode, against references that evaluate the model's 3D reconstruction
directly (``model_reference``), never the renderer's ray pieces.

* iso: dense sampling along each ray (every 0.01 voxel) plus bisection; a hit is a genuine root
  of the reconstruction, never later than the first sampled crossing, and every sampled crossing
  is hit; normals against finite differences of the reconstruction;
* several isosurfaces: all crossings of every isovalue per ray (the composited opacity counts
  them) and the first one's depth;
* MIP / minIP: never below a dense sample and within 1e-6 of the refined extremum;
* DVR: a dense emission-absorption integral whose transfer function comes from its control
  points (``np.interp``): the error shrinks with the step and is within 1/255 at the defaults.
"""

from __future__ import annotations

import numpy as np
import pytest
from model_reference import (
    crossings,
    domain_interval,
    dvr_reference,
    field,
    gradient_fd,
    ray_samples,
)
from reference import smooth_noise
from scipy.optimize import minimize_scalar

import splinecast as sc

MODELS = ["trilinear", "bspline1", "bspline2", "bspline3", "qss", "s31"]
ISO = 0.2
TRANSPARENT = sc.Shading(background=(0.0, 0.0, 0.0, 0.0))


@pytest.fixture(scope="module")
def volume():
    data = smooth_noise((11, 10, 12), seed=7, sigma=1.6)
    return sc.Volume(data, spacing=(1.0, 1.2, 0.9), origin=(-3.0, 1.0, 0.5))


@pytest.fixture(scope="module")
def camera(volume):
    return sc.Camera.orbit(volume, azimuth=37, elevation=23, size=(14, 11))


@pytest.fixture(scope="module", params=MODELS)
def scene(request, volume):
    return sc.Scene(volume, model=request.param)


def _rays(camera):
    origins, dirs = camera.rays()
    for row in range(camera.height):
        for col in range(camera.width):
            yield row, col, origins[row, col], dirs[row, col]


def test_iso_first_hits_against_dense_sampling(scene, camera):
    f = field(scene)
    frame = scene.render(camera, iso=ISO)
    spacing, origin = np.asarray(scene.volume.spacing), np.asarray(scene.volume.origin)
    hits = 0
    for row, col, o, u in _rays(camera):
        ref = crossings(scene, f, o, u, ISO, first_only=True)
        t = frame.depth[row, col]
        if ref:
            assert np.isfinite(t), (row, col)
        if not np.isfinite(t):
            continue
        hits += 1
        tol = 1e-6 / np.linalg.norm(u / spacing)  # a millionth of a voxel, in world units
        if ref:
            assert t <= ref[0] + tol, (row, col)  # never after the first sampled crossing
        p = (o + t * u - origin) / spacing
        assert abs(f(p[None, :])[0] - ISO) < 1e-7  # a genuine root of the reconstruction
        g = gradient_fd(scene, f, o + t * u)
        if np.linalg.norm(g) > 1e-3:  # outward normal: against the gradient (inside = high)
            n = frame.normal[row, col]
            assert np.dot(n, -g / np.linalg.norm(g)) > 1 - 1e-5, (row, col)
    assert hits > 20


def test_several_isosurfaces_every_crossing(scene, camera):
    f = field(scene)
    isos = [-0.5, ISO, 0.6]
    frame = scene.render(camera, iso=isos, opacity=[0.3, 0.3, 0.3], shading=TRANSPARENT)
    layered = 0
    for row, col, o, u in _rays(camera):
        found = sorted(t for v in isos for t in crossings(scene, f, o, u, v))
        alpha = 1.0 - 0.7 ** len(found)
        assert frame.rgba[row, col, 3] == pytest.approx(alpha, abs=1e-6), (row, col)
        if found:
            assert frame.depth[row, col] == pytest.approx(found[0], abs=1e-6)
            layered += len(found) > 1
        else:
            assert not np.isfinite(frame.depth[row, col])
    assert layered > 10


@pytest.mark.parametrize("kind", ["mip", "minip"])
def test_projection_against_refined_dense_extremum(scene, camera, kind):
    f = field(scene)
    frame = scene.render(camera, mode=kind)
    sign = 1.0 if kind == "mip" else -1.0
    spacing, origin = np.asarray(scene.volume.spacing), np.asarray(scene.volume.origin)
    checked = 0
    for row, col, o, u in list(_rays(camera))[::3]:
        t0, t1 = domain_interval(scene, o, u)
        if not t0 < t1:
            assert np.isnan(frame.value[row, col])
            continue
        ts, vs, _ = ray_samples(scene, f, o, u, t0, t1, 0.005)
        best = int(np.argmax(sign * vs))
        lo_t, hi_t = ts[max(best - 1, 0)], ts[min(best + 1, len(ts) - 1)]

        def neg(t, o=o, u=u):
            return -sign * f(((o + t * u - origin) / spacing)[None, :])[0]
        res = minimize_scalar(neg, bounds=(lo_t, hi_t), method="bounded",
                              options={"xatol": 1e-12})
        refined = max(sign * vs[best], -res.fun)
        got = sign * frame.value[row, col]
        assert got >= (sign * vs).max() - 1e-12
        assert abs(got - refined) < 1e-6
        checked += 1
    assert checked >= 15


TF_POINTS = [(-0.6, 0.0), (-0.1, 0.35), (0.4, 0.0), (0.8, 0.5)]
TF_DOMAIN = (-2.0, 2.0)


@pytest.fixture(scope="module")
def tf():
    return sc.TransferFunction(TF_POINTS, domain=TF_DOMAIN, colormap="viridis")


def _dvr_error(scene, camera, tf, settings, refs):
    frame = scene.render(camera, mode="dvr", tf=tf, dvr=settings, shading=TRANSPARENT)
    err = 0.0
    for (row, col), (rgb, alpha) in refs.items():
        err = max(err, float(np.abs(frame.rgba[row, col, :3] - rgb).max()),
                  abs(float(frame.rgba[row, col, 3]) - alpha))
    return err


def test_dvr_converges_to_the_emission_absorption_integral(scene, camera, tf):
    f = field(scene)
    refs = {(row, col): dvr_reference(scene, f, o, u, TF_POINTS, "viridis", TF_DOMAIN)
            for row, col, o, u in list(_rays(camera))[::2]}
    assert max(a for _, a in refs.values()) > 0.3  # something is visible
    errs = [_dvr_error(scene, camera, tf, sc.DVRSettings(step=s, table_size=1024), refs)
            for s in (1.0, 0.25, 0.0625)]
    assert errs[0] > errs[2] and errs[2] < 0.2 * errs[0] + 1e-4
    # The largest error over every checked pixel at the default settings.
    assert _dvr_error(scene, camera, tf, sc.DVRSettings(), refs) < 1.0 / 255.0


def test_three_nested_translucent_s31_surfaces_blend_in_depth_order():
    """Reference 004's "Blending kubischer C1-Splines": three nested translucent isosurfaces of
    the smooth C1 spline, each crossing shaded (headlight Blinn-Phong, written out here) and
    composited front to back in depth order, against the crossings of the directly evaluated
    spline and finite-difference normals."""
    vol = sc.demo("sphere", size=20)  # |p| - 0.6; the inside is where values are low
    scene = sc.Scene(vol, model="s31")
    cam = sc.Camera.orbit(vol, azimuth=20, elevation=15, size=(12, 10))
    isos = [-0.3, -0.1, 0.1]
    colors = np.array([(1.0, 0.2, 0.1), (0.1, 0.9, 0.2), (0.2, 0.3, 1.0)])
    opacity = [0.5, 0.4, 0.6]
    shading = sc.Shading(background=(0.0, 0.0, 0.0, 0.0))
    frame = scene.render(cam, iso=isos, colors=colors, opacity=opacity, shading=shading,
                         inside="low")
    f = field(scene)
    deep = 0
    for row, col, o, u in _rays(cam):
        hits = sorted((t, q) for q, v in enumerate(isos) for t in crossings(scene, f, o, u, v))
        deep += len(hits) >= 5
        acc = np.zeros(3)
        alpha = 0.0
        for t, q in hits:
            g = gradient_fd(scene, f, o + t * u)
            cos = abs(np.dot(g / np.linalg.norm(g), u))
            light = shading.ambient + shading.diffuse * cos
            rgb = np.minimum(colors[q] * light + shading.specular * cos**shading.shininess, 1.0)
            acc += (1.0 - alpha) * opacity[q] * rgb
            alpha += (1.0 - alpha) * opacity[q]
        np.testing.assert_allclose(frame.rgba[row, col, :3], acc, atol=1e-5,
                                   err_msg=f"pixel {row, col}")
        assert frame.rgba[row, col, 3] == pytest.approx(alpha, abs=1e-6)
        if hits:
            assert frame.depth[row, col] == pytest.approx(hits[0][0], abs=1e-6)
    assert deep > 10  # rays through all three shells (six crossings) are checked
