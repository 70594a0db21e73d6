"""Antialiasing (``Scene.render(samples=...)``) against brute-force supersampling.

The references are built by the test from whole renders without antialiasing (``samples=1``):

* a box filter of a pixel, by rendering the same view at eight times the resolution (the 64
  rays through the centres of an 8 x 8 grid of sub-pixels) and averaging each 8 x 8 block: an
  antialiased frame must be much closer to it than the frame traced through the centres, on
  the pixels where the two differ;
* ``samples=n`` other than 5 is the mean of ``n`` renders whose rays pass at the documented
  places in the pixel (``sample_offsets``: for 4, the centres of the 2 x 2 sub-pixels; through
  ``Camera.shifted``), on the pixels it antialiases.

And what antialiasing must keep: depth, position, normal and face are the centre ray's; the
pixels off the edges keep their colour; windows of the image (``Camera.tile``) antialias to the
same colours as the whole image, bit for bit.
"""

from __future__ import annotations

import numpy as np
import pytest
from scenes import NOISE_ISO, noise_volume

import splinecast as sc
from splinecast.render.antialias import DEFAULT_SAMPLES, edge_mask, sample_offsets


@pytest.fixture(scope="module")
def volume():
    return noise_volume()


@pytest.fixture(scope="module")
def scene(volume):
    return sc.Scene(volume)


@pytest.fixture(scope="module")
def camera(volume):
    return sc.Camera.orbit(volume, azimuth=40, elevation=25, size=(40, 30), zoom=1.3)


def _box_reference(scene, camera, factor=8, **options):
    """Each pixel's colour averaged over ``factor^2`` rays on a regular grid inside it: the
    same view rendered ``factor`` times larger, without antialiasing, then block-averaged."""
    big = sc.Camera(camera.position, camera.look_at, up=camera.up, fov=camera.fov,
                    size=(camera.width * factor, camera.height * factor))
    rgba = scene.render(big, samples=1, **options).rgba.astype(np.float64)
    return rgba.reshape(camera.height, factor, camera.width, factor, 4).mean(axis=(1, 3))


def test_the_default_antialiases_isosurfaces_and_keeps_their_geometry(scene, camera):
    plain = scene.render(camera, iso=NOISE_ISO, samples=1)
    frame = scene.render(camera, iso=NOISE_ISO)
    assert frame.stats["samples"] == DEFAULT_SAMPLES
    for name in ("depth", "position", "normal", "face"):
        np.testing.assert_array_equal(getattr(frame, name), getattr(plain, name), err_msg=name)
    edges = edge_mask(plain.rgba, plain.depth, plain.normal, plain.face)
    assert frame.stats["antialiased"] == edges.sum() > 20
    np.testing.assert_array_equal(frame.rgba[~edges], plain.rgba[~edges])
    assert np.abs(frame.rgba[edges] - plain.rgba[edges]).max() > 0.1
    # Closer to the box filter of the pixels: on the pixels it changed, the error of the
    # centre rays shrinks by more than a third (measured: to 0.54 of it).
    truth = _box_reference(scene, camera, iso=NOISE_ISO)
    changed = np.any(frame.rgba != plain.rgba, axis=-1)
    before = np.abs(plain.rgba[changed] - truth[changed]).mean()
    after = np.abs(frame.rgba[changed] - truth[changed]).mean()
    assert after < 0.65 * before, (before, after)
    # Off the edges the centre ray is already close to the box filter.
    assert np.abs(frame.rgba[~edges] - truth[~edges]).mean() < before / 4


def test_box_filter_samples_are_the_mean_of_shifted_rays(scene, camera):
    """``samples=4``: the mean of the renders through the centres of the pixel's 2 x 2
    sub-pixels, on the edge pixels, exactly (up to float32 colours)."""
    plain = scene.render(camera, iso=NOISE_ISO, samples=1)
    frame = scene.render(camera, iso=NOISE_ISO, samples=4)
    offsets = sample_offsets(4)
    np.testing.assert_array_equal(np.sort(offsets, axis=0),
                                  [[-0.25, -0.25], [-0.25, -0.25], [0.25, 0.25], [0.25, 0.25]])
    assert len({tuple(p) for p in offsets}) == 4
    shifted = [scene.render(camera.shifted(dx, dy), iso=NOISE_ISO, samples=1).rgba
               for dx, dy in offsets]
    mean = np.mean(shifted, axis=0)
    edges = edge_mask(plain.rgba, plain.depth, plain.normal, plain.face)
    np.testing.assert_allclose(frame.rgba[edges], mean[edges], rtol=0, atol=1e-6)
    np.testing.assert_array_equal(frame.rgba[~edges], plain.rgba[~edges])
    truth = _box_reference(scene, camera, iso=NOISE_ISO)
    before = np.abs(plain.rgba[edges] - truth[edges]).mean()
    assert np.abs(frame.rgba[edges] - truth[edges]).mean() < 0.6 * before


def test_windows_antialias_like_the_whole_image(scene, camera):
    """Stripes and tiles (the viewer's, Dask's) compare with, and share corners with, the
    pixels around them: assembled, they are the whole image's antialiased colours."""
    whole = scene.render(camera, iso=NOISE_ISO)
    for rows, cols in ((8, camera.width), (8, 16)):
        image = np.empty_like(whole.rgba)
        for r in range(0, camera.height, rows):
            for c in range(0, camera.width, cols):
                h, w = min(rows, camera.height - r), min(cols, camera.width - c)
                image[r:r + h, c:c + w] = scene.render(camera.tile(c, r, w, h),
                                                       iso=NOISE_ISO).rgba
        np.testing.assert_array_equal(image, whole.rgba)


def test_several_isosurfaces_and_effects_are_antialiased(scene, camera):
    """Translucent surfaces and surface effects: the edges change, the rest does not, and
    the image gets closer to its box filter."""
    for options in ({"iso": [-0.4, NOISE_ISO], "opacity": [0.4, 1.0]},
                    {"iso": NOISE_ISO, "effects": sc.SurfaceEffects(texture="checker",
                                                                   scale=0.3)}):
        plain = scene.render(camera, samples=1, **options)
        frame = scene.render(camera, **options)
        np.testing.assert_array_equal(frame.depth, plain.depth)
        edges = edge_mask(plain.rgba, plain.depth, plain.normal, plain.face)
        np.testing.assert_array_equal(frame.rgba[~edges], plain.rgba[~edges])
        truth = _box_reference(scene, camera, **options)
        before = np.abs(plain.rgba[edges] - truth[edges]).mean()
        assert np.abs(frame.rgba[edges] - truth[edges]).mean() < 0.7 * before


def test_what_antialiasing_leaves_alone(scene, camera):
    """Without colours there is nothing to antialias."""
    plain = scene.render(camera, iso=NOISE_ISO, samples=1, outputs=("depth", "normal"))
    frame = scene.render(camera, iso=NOISE_ISO, outputs=("depth", "normal"))
    assert "antialiased" not in frame.stats
    np.testing.assert_array_equal(frame.normal, plain.normal)


@pytest.mark.parametrize("samples", [0, -1, 65, 2.5, True, "4", [4]])
def test_bad_sample_counts_are_refused(scene, camera, samples):
    with pytest.raises(sc.ParameterError,
                       match=r"samples must be an integer from 1 \(no antialiasing\) to 64"):
        scene.render(camera, iso=NOISE_ISO, samples=samples)


def test_bad_normals_are_refused(scene, camera):
    with pytest.raises(sc.ParameterError, match="normals must be one of smooth, exact"):
        scene.render(camera, iso=NOISE_ISO, normals="flat")
    with pytest.raises(sc.ParameterError, match="normals must be one of smooth, exact"):
        scene.render(camera, mode="mip", normals=None)
