"""Public behaviour outside the kernels: ``Volume`` validation, the Blinn–Phong formula of
``Shading`` and its parameters, ``SurfaceEffects`` validation, ``Frame.save``/``save_depth``, and
``Camera.orbit(zoom=...)`` framing (projected box corners against the analytic projection).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from PIL import Image

import splinecast as sc

# =============================================================================== Volume

SUPPORTED = ["uint8", "int8", "uint16", "int16", "uint32", "int32", "float32", "float64"]


@pytest.mark.parametrize("dtype", SUPPORTED)
def test_volume_keeps_supported_dtypes_without_a_copy(dtype):
    data = np.arange(24).reshape(2, 3, 4).astype(dtype)
    vol = sc.Volume(data)
    assert vol.data is data and vol.dtype == np.dtype(dtype)
    assert vol.value_range == (0.0, 23.0)


def test_volume_views_bool_as_uint8_and_keeps_a_memmap(tmp_path):
    vol = sc.Volume(np.array([[[True, False]]]))
    assert vol.dtype == np.uint8 and vol.value_range == (0.0, 1.0)
    path = tmp_path / "m.npy"
    np.save(path, np.zeros((2, 2, 2), np.int16))
    mm = np.load(path, mmap_mode="r")
    assert isinstance(sc.Volume(mm).data, np.memmap)


@pytest.mark.parametrize(("dtype", "expected"), [
    ("int64", "uint8"), ("uint64", "uint8"), ("float16", "float32"), (">f4", "float32"),
])
def test_volume_converts_other_numeric_dtypes_exactly(dtype, expected):
    # The conversions themselves are tested in test_dtypes.py.
    data = np.arange(8).reshape(2, 2, 2).astype(dtype)
    vol = sc.Volume(data)
    assert vol.dtype == np.dtype(expected) and vol.dtype.isnative
    np.testing.assert_array_equal(vol.data, data)


@pytest.mark.parametrize("dtype", ["complex64", "object"])
def test_volume_refuses_other_dtypes_naming_them(dtype):
    data = np.zeros((2, 2, 2), dtype=np.dtype(dtype))
    with pytest.raises(sc.DataError, match=f"voxel type {np.dtype(dtype)} is not supported"):
        sc.Volume(data)


@pytest.mark.parametrize("shape", [(), (4,), (4, 4), (2, 2, 2, 2)])
def test_volume_needs_3d_data(shape):
    with pytest.raises(sc.ParameterError, match=r"3D array, got shape " + re_shape(shape)):
        sc.Volume(np.zeros(shape, np.float32))


def re_shape(shape):
    return str(tuple(shape)).replace("(", r"\(").replace(")", r"\)")


@pytest.mark.parametrize("spacing", [0.0, -1.0, (1.0, 0.0, 1.0), (1.0, 1.0, -0.5)])
def test_volume_refuses_spacing_that_is_not_positive(spacing):
    with pytest.raises(sc.ParameterError, match="spacing must be three numbers between 1e-12"):
        sc.Volume(np.zeros((2, 2, 2)), spacing=spacing)


@pytest.mark.parametrize("name", ["spacing", "origin"])
@pytest.mark.parametrize("value", [math.nan, math.inf, (1.0, -math.inf, 1.0), None])
def test_volume_refuses_non_finite_spacing_and_origin(name, value):
    # splinecast.errors.limits: a spacing must also lie in SPACING_RANGE, so its message gives
    # the range.
    wanted = "three numbers between" if name == "spacing" else "three finite numbers"
    with pytest.raises(sc.ParameterError, match=f"{name} must be {wanted}"):
        sc.Volume(np.zeros((2, 2, 2)), **{name: value})


@pytest.mark.parametrize("name", ["spacing", "origin"])
@pytest.mark.parametrize("value", [(1.0, 2.0), (1.0, 2.0, 3.0, 4.0), "abc"])
def test_volume_refuses_spacing_and_origin_of_the_wrong_length(name, value):
    with pytest.raises(sc.ParameterError, match=name):
        sc.Volume(np.zeros((2, 2, 2)), **{name: value})


def test_volume_geometry_follows_the_voxel_centre_convention():
    vol = sc.Volume(np.zeros((4, 5, 6)), spacing=(0.5, 2.0, 1.5), origin=(-1.0, 3.0, 0.25),
                    metadata={"name": "v"})
    assert vol.spacing == (0.5, 2.0, 1.5) and vol.origin == (-1.0, 3.0, 0.25)
    assert vol.extent == (1.5, 8.0, 7.5)  # (shape - 1) * spacing
    lo, hi = vol.bounds
    np.testing.assert_array_equal(lo, [-1.0, 3.0, 0.25])
    np.testing.assert_array_equal(hi, [0.5, 11.0, 7.75])
    ijk = np.array([[3.0, 4.0, 5.0], [0.5, 1.25, 2.0]])
    world = vol.index_to_world(ijk)
    np.testing.assert_array_equal(world, [[0.5, 11.0, 7.75], [-0.75, 5.5, 3.25]])
    np.testing.assert_array_equal(vol.world_to_index(world), ijk)
    assert sc.Volume(np.zeros((2, 2, 2)), spacing=2.0).spacing == (2.0, 2.0, 2.0)


def test_volume_value_range_ignores_nan_and_refuses_all_nan():
    data = np.full((2, 2, 2), np.nan, np.float32)
    data[0, 0, 0], data[1, 1, 1] = -2.0, 5.0
    vol = sc.Volume(data)
    assert vol.value_range == (-2.0, 5.0) and vol.count_nan() == 6
    with pytest.raises(sc.DataError, match="no finite value"):
        _ = sc.Volume(np.full((2, 2, 2), np.nan), metadata={"name": "allnan"}).value_range


# =============================================================================== Shading

# Rays pointing along -x at the sphere |p| = 0.6 of the demo (a distance field: inside "low").
# The clip plane keeps x <= -2y: on the image's y < 0 side nothing of the sphere is cut (front
# faces); on the y > 0 side the near cap is cut off and rays see the far side's back faces.
CLIP = [(-1.0, -2.0, 0.0, 0.0)]
SHADINGS = [
    sc.Shading(),
    sc.Shading(front_color=(1.0, 0.2, 0.0), back_color=(0.0, 0.3, 1.0), ambient=0.3,
               diffuse=0.5, specular=0.0, shininess=1.0, background=(0.1, 0.2, 0.3, 0.4)),
    sc.Shading(front_color=(0.5, 0.5, 0.5), ambient=0.0, diffuse=1.0, specular=0.6,
               shininess=3.0),
    sc.Shading(front_color=(0.9, 0.9, 0.9), ambient=0.5, diffuse=0.9, specular=0.5,
               shininess=60.0),  # saturates: the formula's min(., 1)
]


@pytest.fixture(scope="module")
def shading_scene():
    vol = sc.demo("sphere", size=24)
    cam = sc.Camera((3.0, 0.3, -0.2), (0.0, 0.0, 0.0), size=(24, 20), fov=28.0)
    return sc.Scene(vol), cam


def blinn_phong(shading: sc.Shading, face, normal, directions):
    """The headlight Blinn–Phong of the docs: ``base (ambient + diffuse c) + specular
    c^shininess`` per channel, capped at 1, with ``c = |n . u|`` and base the front or back
    colour."""
    c = np.abs(np.sum(normal * directions, axis=-1))[..., None]
    base = np.where((face > 0)[..., None], shading.front_color, shading.back_color)
    light = base * (shading.ambient + shading.diffuse * c) + shading.specular * c**shading.shininess
    return np.minimum(light, 1.0)


@pytest.mark.parametrize("index", range(len(SHADINGS)))
def test_blinn_phong_colours_follow_the_formula(shading_scene, index):
    scene, cam = shading_scene
    shading = SHADINGS[index]
    # One ray a pixel: an antialiased edge pixel's colour is a mean of several rays' colours.
    frame = scene.render(cam, iso=0.0, shading=shading, clip=CLIP, samples=1)
    _, dirs = cam.rays()
    hit = frame.hit
    assert (frame.face[hit] == 1).sum() > 20 and (frame.face[hit] == -1).sum() > 20
    assert (~hit).sum() > 20
    normal = frame.normal.astype(np.float64)
    expected = blinn_phong(shading, frame.face, normal, dirs)
    # The kernel shades with the float64 normal and stores it as float32: |dc| <= 3 * 2^-24,
    # and d(colour)/dc <= diffuse + specular * shininess; the colour itself is float32.
    tol = 3 * 2.0**-24 * (shading.diffuse + shading.specular * shading.shininess) + 2.0**-23
    np.testing.assert_allclose(frame.rgba[hit][:, :3], expected[hit], rtol=0, atol=tol)
    np.testing.assert_array_equal(frame.rgba[hit][:, 3], 1.0)
    np.testing.assert_array_equal(frame.rgba[~hit],
                                  np.broadcast_to(np.float32(shading.background), (
                                      int((~hit).sum()), 4)))
    if index == 3:
        assert np.any(frame.rgba[hit][:, :3] == 1.0)  # the cap was exercised


def test_each_shading_parameter_changes_the_image_as_the_formula_says(shading_scene):
    scene, cam = shading_scene
    base = sc.Shading(ambient=0.2, diffuse=0.6, specular=0.3, shininess=8.0)
    ref = scene.render(cam, iso=0.0, shading=base, clip=CLIP, samples=1)
    _, dirs = cam.rays()
    hit = ref.hit
    normal = ref.normal.astype(np.float64)
    for change in ({"ambient": 0.5}, {"diffuse": 0.1}, {"specular": 0.0}, {"shininess": 2.0},
                   {"front_color": (0.1, 0.9, 0.2)}, {"back_color": (0.9, 0.1, 0.1)}):
        shading = sc.Shading(**{**base.__dict__, **change})
        frame = scene.render(cam, iso=0.0, shading=shading, clip=CLIP, samples=1)
        expected = blinn_phong(shading, ref.face, normal, dirs)
        assert np.abs(frame.rgba[hit][:, :3] - ref.rgba[hit][:, :3]).max() > 0.01, change
        np.testing.assert_allclose(frame.rgba[hit][:, :3], expected[hit], atol=1e-5)


@pytest.mark.parametrize("kwargs, word", [
    ({"front_color": (1.0, 0.5)}, "front_color"),
    ({"back_color": (0.0, 1.5, 0.0)}, "back_color"),
    ({"background": (0.0, 0.0, 0.0)}, "background"),
    ({"ambient": -0.1}, "ambient"),
    ({"diffuse": math.nan}, "diffuse"),
    ({"specular": -1.0}, "specular"),
    ({"shininess": -2.0}, "shininess"),
])
def test_shading_validation(kwargs, word):
    with pytest.raises(sc.ParameterError, match=word):
        sc.Shading(**kwargs)


# =============================================================================== SurfaceEffects

@pytest.mark.parametrize("kwargs, word", [
    ({"texture": "marble"}, "texture must be one of"),
    ({"texture": "checker", "scale": 0.0}, "scale"),
    ({"texture": "checker", "scale": -1.0}, "scale"),
    ({"texture": "noise", "scale": math.inf}, "scale"),
    ({"texture": "noise", "scale": math.nan}, "scale"),
    ({"dark": 1.5}, "dark"),
    ({"dark": -0.1}, "dark"),
    ({"strength": 2.0}, "strength"),
    ({"strength": math.nan}, "strength"),
    ({"cel_bands": 1}, "cel_bands"),
    ({"cel_bands": -3}, "cel_bands"),
    ({"cel_bands": 2.5}, "cel_bands"),
])
def test_surface_effects_validation(kwargs, word):
    with pytest.raises(sc.ParameterError, match=word):
        sc.SurfaceEffects(**kwargs)


def test_surface_effects_active_and_packing():
    assert not sc.SurfaceEffects().active
    assert sc.SurfaceEffects(texture="noise").active and sc.SurfaceEffects(cel_bands=2).active
    packed = sc.SurfaceEffects(texture="noise", scale=0.25, seed=7, strength=0.3, dark=0.2,
                               cel_bands=5).as_array()
    np.testing.assert_array_equal(packed, [2, 0.25, 7, 0.3, 0.2, 5])
    with pytest.raises(sc.ParameterError, match="effects"):
        vol = sc.demo("sphere", size=8)
        sc.Scene(vol).render(sc.Camera.orbit(vol, size=(4, 4)), effects={"texture": "noise"})


# =============================================================================== Frame output

@pytest.fixture(scope="module")
def small_frame():
    vol = sc.demo("sphere", size=12)
    return sc.Scene(vol).render(sc.Camera.orbit(vol, size=(10, 8)), iso=0.0)


def test_to_uint8_rounds_to_nearest_and_clips():
    rgba = np.array([[[0.0, 1.0, 0.5, 1 / 255], [-0.5, 1.5, 0.499 / 255, 254.51 / 255]]],
                    np.float32)
    frame = sc.Frame(rgba, np.zeros((1, 2)), np.zeros((1, 2, 3)), np.zeros((1, 2, 3)),
                     np.zeros((1, 2), np.int8), *[np.zeros((1, 2), np.int32)] * 3)
    # 0.5 * 255 = 127.5 rounds up; values outside [0, 1] clip.
    assert frame.to_uint8().tolist() == [[[0, 255, 128, 1], [0, 255, 0, 255]]]


def test_save_and_save_depth_round_trip(small_frame, tmp_path):
    small_frame.save(tmp_path / "a.PNG")  # the suffix check ignores case
    image = np.asarray(Image.open(tmp_path / "a.PNG"))
    np.testing.assert_array_equal(image, small_frame.to_uint8())
    small_frame.save_depth(tmp_path / "d.npy")
    depth = np.load(tmp_path / "d.npy")
    assert depth.dtype == np.float64 and np.isinf(depth).any()
    np.testing.assert_array_equal(depth, small_frame.depth)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.PNG", "d.npy"]


@pytest.mark.parametrize("method, name, word", [
    ("save", "out.gif", "must be saved as .png"),
    ("save", "out", "must be saved as .png"),
    ("save_depth", "depth.txt", "must be saved as .npy"),
    ("save", "missing/out.png", "does not exist"),
    ("save_depth", "missing/d.npy", "does not exist"),
    ("save", "folder.png", "cannot write"),
    ("save_depth", "folder.npy", "cannot write"),
])
def test_save_errors_name_the_path_and_leave_nothing(small_frame, tmp_path, method, name, word):
    (tmp_path / "folder.png").mkdir()
    (tmp_path / "folder.npy").mkdir()
    before = sorted(tmp_path.rglob("*"))
    with pytest.raises(sc.ParameterError, match=word) as info:
        getattr(small_frame, method)(tmp_path / name)
    assert name.split("/")[-1] in str(info.value)
    assert sorted(tmp_path.rglob("*")) == before  # no partial file, no temporary left


# =============================================================================== Camera.orbit zoom

def _box(half=1.0):
    """A volume whose box of voxel centres is [-half, half]^3 (bounding sphere radius half*√3)."""
    return sc.Volume(np.zeros((3, 3, 3), np.float32), spacing=half, origin=-half)


def _corners(half=1.0):
    return np.array([[x, y, z] for x in (-half, half) for y in (-half, half)
                     for z in (-half, half)])


def _pixel_of(cam, points):
    """Fractional (col, row) where ``points`` appear, found from the camera's own rays.

    The camera looks from +x along -x (azimuth 0, elevation 0), so its image axes are world +y
    (right) and +z (up). The screen coordinate of a pixel's ray -- the ray's y, z per unit of
    travel along -x (perspective) or its origin's y, z (orthographic) -- is affine in the pixel
    indices; it is fitted from ``rays()`` and inverted for the points.
    """
    origins, dirs = cam.rays()
    if cam.ortho:
        sx, sy = origins[..., 1], origins[..., 2]
        px, py = points[:, 1], points[:, 2]
    else:
        sx, sy = dirs[..., 1] / -dirs[..., 0], dirs[..., 2] / -dirs[..., 0]
        depth = cam.position[0] - points[:, 0]
        px, py = points[:, 1] / depth, points[:, 2] / depth
    ax, bx = np.polyfit(np.arange(cam.width), sx[0, :], 1)
    ay, by = np.polyfit(np.arange(cam.height), sy[:, 0], 1)
    cols, rows = np.meshgrid(np.arange(cam.width), np.arange(cam.height))
    np.testing.assert_allclose(sx, ax * cols + bx, atol=1e-12)
    np.testing.assert_allclose(sy, ay * rows + by, atol=1e-12)
    return np.stack([(px - bx) / ax, (py - by) / ay], axis=-1)


@pytest.mark.parametrize("size", [(40, 30), (30, 40)])
@pytest.mark.parametrize("zoom", [0.5, 1.0, 1.6, 3.0])
def test_orbit_zoom_scales_the_framed_box(size, zoom):
    vol = _box()
    width, height = size
    radius = math.sqrt(3.0)
    centre = np.array([(width - 1) / 2, (height - 1) / 2])
    corners = _corners()
    # Perspective: the eye moves to 1/zoom of the distance at which the bounding sphere just
    # fits the narrower field of view; a corner (x, y, z) then appears at screen coordinates
    # (y, z) / (D - x), D = radius / sin(half_fov_min) / zoom.
    fov = 30.0
    half = math.radians(fov) / 2
    half_min = min(half, math.atan(math.tan(half) * width / height))
    distance = radius / math.sin(half_min) / zoom
    cam = sc.Camera.orbit(vol, azimuth=0.0, elevation=0.0, size=size, fov=fov, zoom=zoom)
    np.testing.assert_allclose(cam.position, [distance, 0.0, 0.0], atol=1e-12)
    pixel_per_unit = height / 2 / math.tan(half)  # at unit distance in front of the eye
    screen = corners[:, 1:] / (distance - corners[:, :1])
    expected = centre + pixel_per_unit * screen * [1.0, -1.0]  # row 0 is the top
    np.testing.assert_allclose(_pixel_of(cam, corners), expected, atol=1e-9)
    # Orthographic: the window just holds the bounding sphere on the narrower side at zoom 1
    # and shrinks by 1/zoom: a corner's offset from the image centre scales by zoom exactly.
    ortho = sc.Camera.orbit(vol, azimuth=0.0, elevation=0.0, size=size, ortho=True, zoom=zoom)
    pixel_per_unit = min(width, height) / (2 * radius) * zoom
    expected = centre + pixel_per_unit * corners[:, 1:] * [1.0, -1.0]
    np.testing.assert_allclose(_pixel_of(ortho, corners), expected, atol=1e-9)
    if zoom == 1.0:
        # The box fits: every corner projects inside the image.
        for c in (cam, ortho):
            p = _pixel_of(c, corners)
            assert np.all(p >= -0.5) and np.all(p <= np.array(size) - 0.5)


@pytest.mark.parametrize("zoom", [0.0, -1.0, math.nan])
def test_orbit_refuses_a_zoom_that_is_not_positive(zoom):
    with pytest.raises(sc.ParameterError, match="zoom"):
        sc.Camera.orbit(_box(), zoom=zoom)
