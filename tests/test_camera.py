"""The :class:`Camera`: ray generation, orbit placement, and the compiled per-pixel rays.

Expected values come from the pinhole / orthographic model written out here (screen coordinates of
pixel centres, look-at frame), not from the camera's own helpers.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit

import splinecast
from splinecast import Camera, ParameterError, Volume
from splinecast.render.rays import pixel_ray


def unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def angle(u, v):
    c = np.dot(unit(u), unit(v))
    return math.acos(min(1.0, max(-1.0, c)))


def box_volume(shape=(11, 21, 31), spacing=(1.0, 0.5, 2.0), origin=(-3.0, 4.0, 1.5)):
    return Volume(np.zeros(shape, np.float32), spacing=spacing, origin=origin)


@pytest.mark.parametrize("size", [(32, 24), (7, 9), (1, 1), (40, 1)])
@pytest.mark.parametrize("ortho", [False, True])
def test_rays_shapes_and_unit_directions(size, ortho):
    cam = Camera((5.0, -3.0, 2.0), (0.5, 1.0, -1.0), size=size, ortho=ortho)
    origins, directions = cam.rays()
    w, h = size
    assert origins.shape == directions.shape == (h, w, 3)
    assert origins.dtype == directions.dtype == np.float64
    np.testing.assert_allclose(np.linalg.norm(directions, axis=-1), 1.0, rtol=0, atol=1e-15)
    assert np.all(np.isfinite(origins))


def test_frame_is_orthonormal_and_looks_at_target():
    cam = Camera((5.0, -3.0, 2.0), (0.5, 1.0, -1.0), up=(0.2, 0.1, 3.0))
    f = unit(np.subtract((0.5, 1.0, -1.0), (5.0, -3.0, 2.0)))
    np.testing.assert_allclose(cam.forward, f, atol=1e-15)
    basis = np.stack([cam.right, cam.up, cam.forward])
    np.testing.assert_allclose(basis @ basis.T, np.eye(3), atol=1e-15)
    # right-handed: right x up = -forward (looking down -z in camera coordinates)
    np.testing.assert_allclose(np.cross(cam.right, cam.up), -cam.forward, atol=1e-15)
    # `up` is the given up direction made orthogonal to the view direction
    up_given = unit((0.2, 0.1, 3.0))
    expected_up = unit(up_given - np.dot(up_given, f) * f)
    np.testing.assert_allclose(cam.up, expected_up, atol=1e-15)


def test_row_zero_is_top_and_column_zero_is_left():
    cam = Camera((10.0, 0.0, 0.0), (0.0, 0.0, 0.0), up=(0.0, 0.0, 1.0), size=(16, 12), fov=40)
    _, d = cam.rays()
    up_dot = d @ cam.up
    assert np.all(up_dot[0] > up_dot[-1])
    assert np.all(np.diff(up_dot, axis=0) < 0)  # decreasing downwards, every column
    right_dot = d @ cam.right
    assert np.all(np.diff(right_dot, axis=1) > 0)  # increasing to the right, every row
    # looking along -x (west) with z up, the image's right is +y (north)
    assert d[6, 0, 1] < 0 < d[6, -1, 1]
    # orthographic: the same for origins
    cam = Camera((10.0, 0.0, 0.0), (0.0, 0.0, 0.0), size=(16, 12), ortho=True, ortho_height=3.0)
    o, _ = cam.rays()
    assert np.all(np.diff(o[..., 2], axis=0) < 0)
    assert np.all(np.diff(o[..., 1], axis=1) > 0)


@pytest.mark.parametrize("size", [(9, 7), (31, 31), (5, 41)])
def test_centre_pixel_looks_forward(size):
    cam = Camera((1.0, 2.0, 3.0), (-4.0, 0.5, 1.0), size=size, fov=50)
    _, d = cam.rays()
    w, h = size
    np.testing.assert_allclose(d[h // 2, w // 2], cam.forward, atol=1e-15)


@pytest.mark.parametrize("fov", [10.0, 30.0, 75.0, 120.0])
@pytest.mark.parametrize("size", [(9, 7), (21, 40)])
def test_perspective_field_of_view(fov, size):
    cam = Camera((0.0, 0.0, 0.0), (0.0, 5.0, 0.0), size=size, fov=fov)
    _, d = cam.rays()
    w, h = size
    # Pinhole at unit distance: the image window spans tan(fov/2) up and down; pixel centres
    # are at (1 - (row + 1/2) 2 / h) tan(fov/2), so the outermost rows are (1 - 1/h) of it.
    t = math.tan(math.radians(fov) / 2)
    half_angle = math.atan((1 - 1 / h) * t)
    col = w // 2  # pixel column closest to the centre
    sx = ((col + 0.5) / w * 2 - 1) * t * w / h
    top_expected = unit(cam.forward + sx * cam.right + (1 - 1 / h) * t * cam.up)
    np.testing.assert_allclose(d[0, col], top_expected, atol=1e-15)
    if w % 2:
        assert angle(d[0, col], d[-1, col]) == pytest.approx(2 * half_angle, abs=1e-13)
    # horizontally the window is wider by the aspect ratio (square pixels)
    row = h // 2
    sy = (1 - (row + 0.5) / h * 2) * t
    expected_left = unit(cam.forward - (1 - 1 / w) * t * w / h * cam.right + sy * cam.up)
    np.testing.assert_allclose(d[row, 0], expected_left, atol=1e-15)


def test_orthographic_rays_parallel_on_a_plane():
    cam = Camera((3.0, -2.0, 7.0), (0.0, 1.0, 0.0), up=(0, 0, 1), size=(13, 9), ortho=True,
                 ortho_height=4.5)
    o, d = cam.rays()
    np.testing.assert_array_equal(d, np.broadcast_to(cam.forward, d.shape))
    # origins on the plane through the eye perpendicular to the view direction
    np.testing.assert_allclose((o - cam.position) @ cam.forward, 0.0, atol=1e-14)
    # pixel pitch ortho_height / height in both directions, centred on the eye
    pitch = 4.5 / 9
    np.testing.assert_allclose(np.diff(o, axis=1), np.broadcast_to(pitch * cam.right, (9, 12, 3)),
                               atol=1e-14)
    np.testing.assert_allclose(np.diff(o, axis=0), np.broadcast_to(-pitch * cam.up, (8, 13, 3)),
                               atol=1e-14)
    np.testing.assert_allclose(o[4, 6], cam.position, atol=1e-14)
    # the window edges are at +-ortho_height/2
    np.testing.assert_allclose((o[0, 6] - cam.position) @ cam.up, 4.5 / 2 - pitch / 2, atol=1e-14)


@pytest.mark.parametrize(
    "azimuth, elevation",
    [(0, 0), (90, 0), (30, 20), (-135, -40), (45, 35.264389682754654), (200, 89.0)],
)
def test_orbit_places_the_eye_on_the_sphere(azimuth, elevation):
    vol = box_volume()
    lo = np.array(vol.origin)
    hi = lo + (np.array(vol.shape) - 1) * np.array(vol.spacing)
    centre = (lo + hi) / 2
    cam = Camera.orbit(vol, azimuth=azimuth, elevation=elevation, size=(40, 30), distance=50.0)
    az, el = math.radians(azimuth), math.radians(elevation)
    expected_dir = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az),
                             math.sin(el)])
    np.testing.assert_allclose(cam.position - centre, 50.0 * expected_dir, atol=1e-12)
    np.testing.assert_allclose(cam.look_at, centre, atol=1e-14)
    # the volume centre is on the optical axis, in the middle of the image
    np.testing.assert_allclose(cam.forward, -expected_dir, atol=1e-14)
    # z is up: the camera's up vector has a non-negative z component (and is level with z
    # when looking horizontally)
    assert cam.up[2] > 0
    # azimuth 0 looks from +x, 90 from +y (checked by the formula above for those angles)


@pytest.mark.parametrize("elevation", [90.0, -90.0])
@pytest.mark.parametrize("azimuth", [0.0, 60.0])
def test_orbit_straight_above_or_below(elevation, azimuth):
    vol = box_volume()
    cam = Camera.orbit(vol, azimuth=azimuth, elevation=elevation, size=(32, 32))
    o, d = cam.rays()
    assert np.all(np.isfinite(o)) and np.all(np.isfinite(d))
    s = math.copysign(1.0, elevation)
    np.testing.assert_allclose(cam.forward, (0.0, 0.0, -s), atol=1e-12)
    basis = np.stack([cam.right, cam.up, cam.forward])
    np.testing.assert_allclose(basis @ basis.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(cam.position[:2], vol.center[:2], atol=1e-12)
    # continuity with a slightly lower elevation: the image is not spun around
    near = Camera.orbit(vol, azimuth=azimuth, elevation=elevation - s * 1e-3, size=(32, 32))
    assert np.dot(near.up, cam.up) > 0.999
    assert np.dot(near.right, cam.right) > 0.999


def test_orbit_default_distance_frames_the_volume():
    vol = box_volume()
    lo, hi = vol.bounds
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (lo[2], hi[2])])
    for size in ((64, 48), (48, 64)):
        for ortho in (False, True):
            cam = Camera.orbit(vol, azimuth=20, elevation=30, size=size, ortho=ortho)
            w, h = size
            rel = corners - cam.position
            z = rel @ cam.forward
            x, y = rel @ cam.right, rel @ cam.up
            if ortho:
                half_h = cam.ortho_height / 2
                sx, sy = x, y
            else:
                half_h = math.tan(math.radians(cam.fov) / 2)
                assert np.all(z > 0)
                sx, sy = x / z, y / z
            assert np.all(np.abs(sy) <= half_h * (1 + 1e-12))
            assert np.all(np.abs(sx) <= half_h * w / h * (1 + 1e-12))


@njit
def _rays_via_kernel(basis, width, height):
    o = np.empty((height, width, 3))
    d = np.empty((height, width, 3))
    for r in range(height):
        for c in range(width):
            wx, wy, wz, ux, uy, uz = pixel_ray(basis, r, c, width, height)
            o[r, c, 0], o[r, c, 1], o[r, c, 2] = wx, wy, wz
            d[r, c, 0], d[r, c, 1], d[r, c, 2] = ux, uy, uz
    return o, d


@pytest.mark.parametrize("ortho", [False, True])
@pytest.mark.parametrize("size", [(17, 11), (64, 48)])
def test_pixel_basis_and_compiled_rays_match_rays(ortho, size):
    vol = box_volume()
    cam = Camera.orbit(vol, azimuth=-70, elevation=15, size=size, ortho=ortho, fov=35)
    basis = cam.pixel_basis()
    assert basis.shape == (22,) and basis.dtype == np.float64
    o_ref, d_ref = cam.rays()
    o, d = _rays_via_kernel(basis, cam.width, cam.height)
    np.testing.assert_allclose(o, o_ref, rtol=0, atol=1e-14 * max(1.0, np.abs(o_ref).max()))
    np.testing.assert_allclose(d, d_ref, rtol=0, atol=1e-14)
    # and called directly from Python for a couple of pixels
    for r, c in ((0, 0), (cam.height - 1, cam.width // 3)):
        got = pixel_ray(basis, r, c, cam.width, cam.height)
        np.testing.assert_allclose(got[:3], o_ref[r, c], rtol=0, atol=1e-13)
        np.testing.assert_allclose(got[3:], d_ref[r, c], rtol=0, atol=1e-14)


@pytest.mark.parametrize("ortho", [False, True])
def test_shifted_rays_pass_off_the_pixel_centres(ortho):
    """A shifted camera's ray through pixel (row, col) is the one through screen point
    (col + 1/2 + dx, row + 1/2 + dy) of the full image: for an orthographic camera the origin
    moves by dx pixel widths along ``right`` and dy down; for a perspective one the direction is
    the unit vector through that point of the image plane at unit distance. Its tiles keep the
    shift, and the compiled rays agree."""
    vol = box_volume()
    cam = Camera.orbit(vol, azimuth=40, elevation=-25, size=(19, 13), ortho=ortho, fov=40)
    dx, dy = 0.375, -0.5
    shifted = cam.shifted(dx, dy)
    o, d = shifted.rays()
    o0, d0 = cam.rays()
    half_h = cam.ortho_height / 2 if ortho else np.tan(np.radians(cam.fov) / 2)
    pixel = 2.0 * half_h / cam.height  # the same width and height (square pixels)
    if ortho:
        expected = o0 + dx * pixel * cam.right - dy * pixel * cam.up
        np.testing.assert_allclose(o, expected, rtol=0, atol=1e-12)
        np.testing.assert_allclose(d, d0, rtol=0, atol=0)
    else:
        ray = d0 / (d0 @ cam.forward)[..., None]  # through the image plane at unit distance
        ray = ray + dx * pixel * cam.right - dy * pixel * cam.up
        np.testing.assert_allclose(d, ray / np.linalg.norm(ray, axis=-1, keepdims=True),
                                   rtol=0, atol=1e-14)
        np.testing.assert_array_equal(o, o0)
    o_k, d_k = _rays_via_kernel(shifted.pixel_basis(), cam.width, cam.height)
    np.testing.assert_allclose(o_k, o, rtol=0, atol=1e-13)
    np.testing.assert_allclose(d_k, d, rtol=0, atol=1e-14)
    tile = shifted.tile(3, 4, 5, 6)
    np.testing.assert_array_equal(tile.rays()[1], d[4:10, 3:8])
    np.testing.assert_array_equal(cam.shifted(0.0, 0.0).rays()[1], d0)  # bit for bit
    for bad in ((0.6, 0.0), (0.0, -0.51), (np.nan, 0.0), ("a", 0.0)):
        with pytest.raises(ParameterError, match="sub-pixel shift"):
            cam.shifted(*bad)


@pytest.mark.parametrize(
    "size", [(0, 10), (10, 0), (-5, 10), (10, -1), "12", "axb", "0x10", "10x-3", "3x4x5", 12, None]
)
def test_bad_sizes_raise(size):
    with pytest.raises(ParameterError, match="size"):
        Camera((1.0, 0.0, 0.0), (0.0, 0.0, 0.0), size=size)
    vol = box_volume()
    with pytest.raises(ParameterError, match="size"):
        Camera.orbit(vol, size=size)


def test_size_as_string():
    cam = Camera((1.0, 0.0, 0.0), (0.0, 0.0, 0.0), size="40x30")
    assert cam.size == (40, 30)
    assert cam.rays()[0].shape == (30, 40, 3)


def test_other_bad_parameters():
    with pytest.raises(ParameterError):
        Camera((1.0, 0.0, 0.0), (1.0, 0.0, 0.0))  # looks at itself
    with pytest.raises(ParameterError, match="fov"):
        Camera((1.0, 0.0, 0.0), (0.0, 0.0, 0.0), fov=180)
    with pytest.raises(ParameterError):
        Camera.orbit(box_volume(), azimuth=float("nan"))
    assert issubclass(ParameterError, splinecast.SplinecastError)


@pytest.mark.parametrize("ortho", [False, True])
def test_tiles_render_the_full_image_bit_for_bit(ortho):
    """Tiles (and tiles of tiles) assemble into exactly the full image's rays and pixels."""
    import splinecast as sc

    vol = sc.demo("sphere", size=20)
    cam = Camera.orbit(vol, azimuth=25, elevation=35, size=(37, 23), ortho=ortho)
    o_full, d_full = cam.rays()
    scene = sc.Scene(vol)
    full = scene.render(cam, iso=0.0)
    for c0, r0, w, h in ((0, 0, 37, 23), (5, 3, 11, 7), (36, 22, 1, 1), (0, 10, 37, 13)):
        tile = cam.tile(c0, r0, w, h)
        o, d = tile.rays()
        np.testing.assert_array_equal(o, o_full[r0:r0 + h, c0:c0 + w])
        np.testing.assert_array_equal(d, d_full[r0:r0 + h, c0:c0 + w])
        part = scene.render(tile, iso=0.0)
        np.testing.assert_array_equal(part.depth, full.depth[r0:r0 + h, c0:c0 + w])
        np.testing.assert_array_equal(part.rgba, full.rgba[r0:r0 + h, c0:c0 + w])
    sub = cam.tile(4, 2, 20, 15).tile(3, 1, 5, 4)  # a tile of a tile refers to the full image
    np.testing.assert_array_equal(sub.rays()[1], d_full[3:7, 7:12])
    with pytest.raises(sc.ParameterError, match="inside"):
        cam.tile(30, 0, 8, 5)
