"""Clip planes and the crop box, applied analytically to the ray interval.

A plane through the sphere ``|p| = 0.6``: rays that pass through the cut disk enter the kept half
space inside the sphere, so their first hit is the sphere's far side (a back face), exactly on the
analytic sphere and on the kept side of the plane; no hit lies on the clipped side.

Then, per ray and two-sided, for every model in iso and every mode that exists today (the lists
of ``pairs.py``): the kept interval ``[t_min, t_max]`` of each ray is computed here from the plane
equations (``reference.planes_interval``; a crop box is its six planes written out here), and

* iso: a ray whose unclipped first hit lies in its kept interval hits at the same depth (nothing
  was clipped that should not be); every other ray's hit is the first crossing inside the kept
  interval from dense sampling + bisection of the reconstruction, or a miss when there is none
  (nothing was kept that should not be); all hits lie in the kept region;
* multi-iso: the composite of the crossings inside the kept interval (dense reference);
* mip/minip: the extremum over the kept interval (dense samples + bounded refinement), at a
  depth inside it, NaN for a ray whose kept interval misses the volume;
* dvr: the dense emission-absorption integral over the kept interval (``test_dvr.py`` states
  the tolerance), far from the unclipped one.
"""

from __future__ import annotations

import numpy as np
import pytest
from evaluators import model_evaluator
from pairs import MODELS_FOR_MODE, pairs
from reference import all_crossings, box_interval, planes_interval
from scenes import NOISE_ISO, noise_volume
from scipy.optimize import minimize_scalar

import splinecast as sc
from splinecast.render.clipping import make_planes

CUT = 0.1  # keep x <= 0.1: the plane (-1, 0, 0, 0.1)


@pytest.fixture(scope="module")
def sphere_scene():
    vol = sc.demo("sphere", size=41)
    cam = sc.Camera((3.0, 0.0, 0.0), (0.0, 0.0, 0.0), size=(24, 24), ortho=True,
                    ortho_height=1.5)
    return vol, sc.Scene(vol), cam


def test_plane_through_sphere_shows_the_far_side(sphere_scene):
    vol, scene, cam = sphere_scene
    frame = scene.render(cam, iso=0.0, clip=[(-1.0, 0.0, 0.0, CUT)])
    origins, _ = cam.rays()
    y, z = origins[..., 1], origins[..., 2]
    r2 = y * y + z * z
    through_disk = r2 < 0.6**2 - CUT**2 - 0.02   # well inside the cut disk
    assert through_disk.sum() > 50
    pos = frame.position[through_disk]
    # The far side of the sphere: x = -sqrt(0.36 - y^2 - z^2).
    np.testing.assert_allclose(pos[:, 0], -np.sqrt(0.36 - r2[through_disk]), atol=5e-3)
    assert np.all(frame.face[through_disk] == -1)
    hits = frame.hit
    assert np.all(frame.position[hits][:, 0] <= CUT + 1e-9)
    # Rays beside the disk still see the unclipped front of the sphere.
    outside = (r2 > 0.6**2 - CUT**2 + 0.02) & (r2 < 0.6**2 - 0.02)
    assert np.all(frame.face[outside] == 1)
    np.testing.assert_allclose(frame.position[outside][:, 0],
                               np.sqrt(0.36 - r2[outside]), atol=5e-3)


def test_without_clip_the_near_side_is_hit(sphere_scene):
    vol, scene, cam = sphere_scene
    frame = scene.render(cam, iso=0.0)
    assert np.any(frame.position[frame.hit][:, 0] > CUT + 0.1)


def test_make_planes_validation():
    planes = make_planes([(0, 0, 1, 0.5)], crop=(0, 1, 0, 2, 0, 3))
    assert planes.shape == (7, 4)
    pts = np.array([[0.5, 1.0, 1.5], [1.5, 1.0, 1.5], [0.5, 1.0, -0.6]])
    keep = (pts @ planes[:, :3].T + planes[:, 3] >= 0).all(axis=1)
    assert keep.tolist() == [True, False, False]
    with pytest.raises(sc.ParameterError, match="non-zero normal"):
        make_planes([(0, 0, 0, 1)])
    with pytest.raises(sc.ParameterError, match="crop"):
        make_planes(crop=(1, 0, 0, 1, 0, 1))


# ----------------------------------------------------------------------- two-sided, per ray
ISO = NOISE_ISO
DEPTH_TOL = 1e-9  # voxels: both sides solve the same root to ~1e-12


@pytest.fixture(scope="module", name="noise_volume")
def noise_volume_fixture():
    return noise_volume()


@pytest.fixture(scope="module")
def noise_camera(noise_volume):
    return sc.Camera.orbit(noise_volume, azimuth=40, elevation=25, size=(16, 12), zoom=2.0)


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def clip_settings(volume):
    """``name -> (render keyword arguments, the same region as world planes)``."""
    c = volume.center
    ext = np.asarray(volume.extent)
    n1, n2 = _unit((-0.7, -0.4, -0.3)), _unit((-0.3, 0.8, 0.1))
    p1 = (*n1, -float(n1 @ c) + 3.5)  # keeps n1 . x + d >= 0, the side away from the camera
    p2 = (*n2, -float(n2 @ c) + 1.5)
    lo, hi = c - 0.4 * ext, c + 0.36 * ext
    crop = (lo[0], hi[0], lo[1], hi[1], lo[2], hi[2])
    crop_planes = []
    for a in range(3):
        e = np.eye(3)[a]
        crop_planes += [(*e, -lo[a]), (*(-e), hi[a])]  # lo <= x_a <= hi
    return {
        "plane": ({"clip": [p1]}, [p1]),
        "crop+2planes": ({"clip": [p1, p2], "crop": crop}, [p1, p2, *crop_planes]),
    }


def kept_intervals(volume, camera, planes, lo, hi):
    """Per-ray index rays and kept parameter intervals (box of the model and clip planes)."""
    W, U = (a.reshape(-1, 3) for a in camera.rays())
    o, d = volume.world_to_index(W), U / np.asarray(volume.spacing)
    b0, b1 = box_interval(o, d, lo, hi)
    p0, p1 = planes_interval(W, U, planes)
    return W, U, o, d, np.maximum(b0, p0), np.minimum(b1, p1)


def inside_planes(points, planes, slack=1e-9):
    p = np.asarray(planes, float)
    return np.all(points @ p[:, :3].T + p[:, 3] >= -slack, axis=-1)


@pytest.mark.parametrize("setting", ["plane", "crop+2planes"])
@pytest.mark.parametrize("model_name", MODELS_FOR_MODE["iso"])
def test_iso_clipping_per_ray(noise_volume, noise_camera, model_name, setting):
    vol, cam = noise_volume, noise_camera
    kwargs, planes = clip_settings(vol)[setting]
    scene = sc.Scene(vol, model=model_name)
    ev = model_evaluator(model_name, vol, scene)
    full = scene.render(cam, iso=ISO).depth.reshape(-1)
    clipped = scene.render(cam, iso=ISO, **kwargs)
    depth = clipped.depth.reshape(-1)
    W, U, o, d, t0, t1 = kept_intervals(vol, cam, planes, ev.lo, ev.hi)
    speed = np.linalg.norm(d, axis=1)
    # All hits lie in the kept region.
    hit = np.isfinite(depth)
    assert inside_planes(clipped.position.reshape(-1, 3)[hit], planes).all()
    # Unclipped hit inside the kept interval: the same hit.
    same = np.isfinite(full) & (full >= t0) & (full <= t1)
    assert same.sum() > 10
    np.testing.assert_array_less(np.abs(depth[same] - full[same]) * speed[same], DEPTH_TOL)
    # Every other ray: the first crossing inside the kept interval, or a miss.
    rest = np.flatnonzero(~same)
    crossings, ambiguous = all_crossings(ev.value, o[rest], d[rest], t0[rest], t1[rest], [ISO],
                                         step=5e-3, tangent=1e-2)
    assert ambiguous.mean() < 0.05
    changed = 0
    for r, rows, amb in zip(rest, crossings, ambiguous, strict=True):
        if amb:
            continue
        if len(rows) == 0:
            assert np.isinf(depth[r]), f"ray {r} hits at {depth[r]} where nothing is kept"
        else:
            assert abs(depth[r] - rows[0, 0]) * speed[r] < DEPTH_TOL, (r, depth[r], rows[0, 0])
        changed += bool(np.isfinite(full[r]))
    assert changed > 10  # rays whose visible surface the clipping changed were checked


@pytest.mark.parametrize("model_name", MODELS_FOR_MODE["multi-iso"])
def test_multi_iso_clipping_per_ray(noise_volume, noise_camera, model_name):
    vol, cam = noise_volume, noise_camera
    kwargs, planes = clip_settings(vol)["crop+2planes"]
    isos, colors, opacity = [-0.5, ISO, 0.8], np.eye(3), [0.3, 0.25, 0.35]
    flat = sc.Shading(ambient=1.0, diffuse=0.0, specular=0.0, background=(0, 0, 0, 1))
    scene = sc.Scene(vol, model=model_name)
    ev = model_evaluator(model_name, vol, scene)
    # One ray a pixel: each pixel's colour is its ray's, as the per-ray reference composites.
    full = scene.render(cam, iso=isos, colors=colors, opacity=opacity, shading=flat, samples=1)
    frame = scene.render(cam, iso=isos, colors=colors, opacity=opacity, shading=flat, samples=1,
                         **kwargs)
    W, U, o, d, t0, t1 = kept_intervals(vol, cam, planes, ev.lo, ev.hi)
    crossings, ambiguous = all_crossings(ev.value, o, d, t0, t1, isos, step=5e-3, tangent=1e-2)
    assert ambiguous.mean() < 0.05
    rgb = frame.rgba[..., :3].reshape(-1, 3)
    for r in np.flatnonzero(~ambiguous):
        expect, a = np.zeros(3), 0.0
        for _, k in crossings[r]:
            expect += (1 - a) * opacity[int(k)] * colors[int(k)]
            a += (1 - a) * opacity[int(k)]
        np.testing.assert_allclose(rgb[r], expect, atol=1e-5, err_msg=f"ray {r}")
    assert np.abs(full.rgba - frame.rgba).max() > 0.1  # the clipping mattered


def _extremum_over(f, sign, t0, t1, step):
    """Largest ``sign * f`` on ``[t0, t1]``: dense samples plus a bounded refinement."""
    ts = np.append(np.arange(t0, t1, step), t1)
    samples = sign * f(ts)
    best = int(np.argmax(samples))
    lo_t, hi_t = ts[max(best - 1, 0)], ts[min(best + 1, len(ts) - 1)]
    # Brent's tolerance has a part relative to the abscissa: search u = t - lo_t, not t (~40).
    res = minimize_scalar(lambda u: -sign * f(np.array([lo_t + u]))[0], bounds=(0, hi_t - lo_t),
                          method="bounded", options={"xatol": 1e-13})
    return samples.max(), max(samples[best], -res.fun)


@pytest.mark.parametrize("model_name, mode", pairs("mip", "minip"))
def test_mip_clipping_per_ray(noise_volume, noise_camera, model_name, mode):
    vol, cam = noise_volume, noise_camera
    kwargs, planes = clip_settings(vol)["crop+2planes"]
    sign = 1.0 if mode == "mip" else -1.0
    scene = sc.Scene(vol, model=model_name)
    ev = model_evaluator(model_name, vol, scene)
    full = scene.render(cam, mode=mode).value.reshape(-1)
    frame = scene.render(cam, mode=mode, **kwargs)
    value, depth = frame.value.reshape(-1), frame.depth.reshape(-1)
    W, U, o, d, t0, t1 = kept_intervals(vol, cam, planes, ev.lo, ev.hi)
    changed = 0
    for r in range(len(W)):
        if not t0[r] < t1[r]:
            assert np.isnan(value[r]) and np.isinf(depth[r])
            continue

        def f(t, r=r):
            return ev.value(o[r] + np.multiply.outer(t, d[r]))

        step = 2e-3 / np.linalg.norm(d[r])  # 0.002 voxels
        sampled, refined = _extremum_over(f, sign, t0[r], t1[r], step)
        got = sign * value[r]
        assert got >= sampled - 1e-12  # nothing kept was dropped
        assert abs(got - refined) < 1e-9  # nothing clipped was used (both in float64)
        assert t0[r] - 1e-9 <= depth[r] <= t1[r] + 1e-9
        changed += abs(value[r] - full[r]) > 1e-3
    assert changed > 10
