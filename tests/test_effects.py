"""Surface effects (solid textures, cel shading) and Gaussian pre-smoothing.

Texture and cel expectations are computed here from the Frame's hit positions and normals and the
documented formulas; smoothing is compared with ``scipy.ndimage.gaussian_filter``.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

import splinecast as sc
from splinecast.render.effects import noise3

FLAT = dict(ambient=1.0, diffuse=0.0, specular=0.0)


@pytest.fixture(scope="module")
def sphere():
    vol = sc.demo("sphere", size=33)
    cam = sc.Camera.orbit(vol, azimuth=20, elevation=15, size=(32, 24))
    return vol, sc.Scene(vol), cam


def test_checker_texture_follows_the_hit_position(sphere):
    vol, scene, cam = sphere
    shading = sc.Shading(front_color=(0.8, 0.6, 0.4), **FLAT)
    fx = sc.SurfaceEffects(texture="checker", scale=0.15, dark=0.25)
    frame = scene.render(cam, iso=0.0, shading=shading, effects=fx, samples=1)
    hit = frame.hit & (frame.face == 1)
    cells = np.floor(frame.position[hit] / 0.15)
    frac = frame.position[hit] / 0.15 - cells
    safe = np.all((frac > 1e-6) & (frac < 1 - 1e-6), axis=1)
    dark = (cells.sum(axis=1).astype(np.int64) & 1) == 1
    expected = np.where(dark[:, None], 0.25 * np.array([0.8, 0.6, 0.4]), [0.8, 0.6, 0.4])
    np.testing.assert_allclose(frame.rgba[hit][safe, :3], expected[safe], atol=1e-6)
    assert dark[safe].any() and (~dark[safe]).any()


def test_cel_shading_has_the_requested_bands(sphere):
    vol, scene, cam = sphere
    shading = sc.Shading(front_color=(1.0, 1.0, 1.0), ambient=0.0, diffuse=1.0, specular=0.0)
    frame = scene.render(cam, iso=0.0, shading=shading, effects=sc.SurfaceEffects(cel_bands=4),
                         samples=1)
    hit = frame.hit
    _, dirs = cam.rays()
    cos = np.abs(np.sum(frame.normal[hit].astype(np.float64) * dirs[hit], axis=1))
    level = np.minimum(np.floor(cos * 4), 3) / 3
    np.testing.assert_allclose(frame.rgba[hit][:, 0], level, atol=1e-5)
    assert len(np.unique(np.round(frame.rgba[hit][:, 0], 5))) <= 4


def test_noise_is_seeded_smooth_and_zero_on_the_lattice():
    rng = np.random.default_rng(3)
    pts = rng.uniform(-5, 5, (200, 3))
    a = np.array([noise3(*p, 7) for p in pts])
    b = np.array([noise3(*p, 7) for p in pts])
    c = np.array([noise3(*p, 8) for p in pts])
    np.testing.assert_array_equal(a, b)
    assert np.abs(a - c).max() > 0.1
    assert np.abs(a).max() <= 1.0 and a.std() > 0.05
    lattice = rng.integers(-5, 5, (20, 3)).astype(float)
    assert all(noise3(*p, 7) == 0.0 for p in lattice)
    # Finite differences: a small move changes the noise proportionally (no jumps).
    h = 1e-5
    for p in pts[:50]:
        d = abs(noise3(p[0] + h, p[1], p[2], 7) - noise3(*p, 7))
        assert d < 10 * h


def test_noise_texture_renders_deterministically(sphere):
    vol, scene, cam = sphere
    fx = sc.SurfaceEffects(texture="noise", scale=0.2, seed=4)
    f1 = scene.render(cam, iso=0.0, effects=fx)
    f2 = scene.render(cam, iso=0.0, effects=fx)
    plain = scene.render(cam, iso=0.0)
    np.testing.assert_array_equal(f1.rgba, f2.rgba)
    assert np.abs(f1.rgba - plain.rgba).max() > 0.05


@pytest.mark.parametrize("size", [3, 5])
def test_smoothing_matches_a_truncated_gaussian(size):
    vol = sc.demo("noise", size=12)
    out = sc.smooth(vol, size)
    radius = (size - 1) // 2
    sigma = radius / 2
    ref = gaussian_filter(vol.data.astype(np.float64), sigma, mode="nearest",
                          truncate=radius / sigma)
    np.testing.assert_allclose(out.data, ref, atol=1e-6)
    assert out.spacing == vol.spacing and out.origin == vol.origin
    const = sc.Volume(np.full((5, 6, 7), 3.0, np.float32))
    np.testing.assert_allclose(sc.smooth(const, 5).data, 3.0, rtol=1e-6)
    with pytest.raises(sc.ParameterError, match="3 or 5"):
        sc.smooth(vol, 4)
