"""Defaults that work: automatic isovalue, MIP window, DVR transfer function, content framing.

References: Otsu's threshold by brute force over every split of the raw values; percentiles by
numpy on the non-background voxels; the content box by hand from the object's voxel indices;
framing by projecting through the camera's own rays and by rendering.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import splinecast as sc
from splinecast.cli import main
from splinecast.render.defaults import (
    DVR_MAX_OPACITY,
    WINDOW_PERCENTILES,
    content_box,
    otsu_threshold,
    sample_values,
)

MNI = Path(__file__).resolve().parents[2] / "shared" / "data" / "mni152_t1_1mm.nii.gz"


def brute_force_otsu(values: np.ndarray) -> tuple[float, float]:
    """The split with the largest between-class variance, computed from the values themselves
    (no histogram): the two consecutive distinct values ``(a, b)`` it falls between."""
    values = np.sort(values.astype(np.float64))
    distinct = np.unique(values)
    best, best_t = -1.0, None
    for a, b in zip(distinct[:-1], distinct[1:], strict=True):
        low, high = values[values <= a], values[values >= b]
        w0, w1 = low.size / values.size, high.size / values.size
        between = w0 * w1 * (low.mean() - high.mean()) ** 2
        if between > best * (1 + 1e-12):
            best, best_t = between, (a, b)
    return best_t


def splits(t: float, between: tuple[float, float]) -> bool:
    return between[0] < t < between[1]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_otsu_matches_brute_force_on_integers(seed):
    rng = np.random.default_rng(seed)
    values = np.concatenate([rng.normal(40, 8, 3000), rng.normal(130, 20, 2000)])
    values = np.clip(np.rint(values), 0, 255)
    t = otsu_threshold(values, integer=True)
    assert splits(t, brute_force_otsu(values)) and t % 1 == 0.5


def test_otsu_on_floats_splits_two_clusters():
    rng = np.random.default_rng(5)
    values = np.concatenate([rng.uniform(-3.0, -2.0, 500), rng.uniform(4.0, 5.0, 700)])
    t = otsu_threshold(values)
    # Any split in the gap has the same, largest, variance.
    assert values[:500].max() < t < values[500:].min()


def test_auto_iso_on_a_volume_is_otsu_without_the_background():
    rng = np.random.default_rng(3)
    data = np.zeros((30, 30, 30), np.uint8)  # a large empty background...
    inner = np.clip(np.rint(rng.normal(60, 10, (12, 12, 12))), 1, 255)
    inner[3:9, 3:9, 3:9] = np.clip(np.rint(rng.normal(180, 15, (6, 6, 6))), 1, 255)
    data[9:21, 9:21, 9:21] = inner
    vol = sc.Volume(data)
    iso = sc.auto_iso(vol)
    assert splits(iso, brute_force_otsu(data[data > 0]))
    lo, hi = vol.value_range
    assert lo < iso < hi and iso % 1 == 0.5  # halfway between integers: no voxel on the surface
    # ... that would have pulled a threshold over all voxels down towards itself.
    assert brute_force_otsu(data.ravel())[1] < iso


def test_auto_iso_special_cases():
    mask = np.zeros((8, 8, 8), np.uint16)
    mask[2:5, 2:5, 2:5] = 10
    assert sc.auto_iso(sc.Volume(mask)) == 5.0
    assert sc.auto_iso(sc.Volume(np.full((4, 4, 4), 7.0))) == 7.0  # nothing to show
    demo = sc.demo("torus", size=16)
    assert sc.auto_iso(demo) == demo.metadata["default_iso"]
    # A NaN is neither background nor a value.
    data = np.zeros((6, 6, 6), np.float32)
    data[1:4, 1:4, 1:4] = 2.0
    data[0, 0, 0] = np.nan
    assert sc.auto_iso(sc.Volume(data)) == 1.0
    # A scene with no iso given renders at the automatic one.
    frame = sc.Scene(sc.Volume(mask)).render(sc.Camera.orbit(sc.Volume(mask), size=(8, 8)))
    assert frame.stats["iso"] == 5.0


def test_sampling_strides_big_volumes_evenly():
    data = np.arange(1, 41 * 30 * 20 + 1, dtype=np.float32).reshape(41, 30, 20)
    vol = sc.Volume(data)
    values = sample_values(vol, max_voxels=1000)
    assert values.size <= 1000
    stride = next(s for s in range(1, 41)  # the smallest stride leaving at most 1000 voxels
                  if np.prod([-(-n // s) for n in data.shape]) <= 1000)
    assert stride == 3
    np.testing.assert_array_equal(values, data[::stride, ::stride, ::stride].ravel()[1:])
    assert np.array_equal(sample_values(vol), data.ravel()[1:])  # small: every voxel


def projections(data: np.ndarray, kind: str, background: float) -> np.ndarray:
    """The pixels of the maximum (minimum) projections along the three axes that are not the
    background value, by numpy."""
    reduce = np.max if kind == "mip" else np.min
    pixels = np.concatenate([reduce(data.astype(np.float64), axis=a).ravel() for a in range(3)])
    return pixels[pixels != background]


def test_auto_window_is_percentiles_of_the_projections():
    rng = np.random.default_rng(7)
    data = np.zeros((20, 20, 20), np.float32)
    data[5:15, 5:15, 5:15] = rng.gamma(2.0, 10.0, (10, 10, 10)) + 1
    vol = sc.Volume(data)
    expected = np.percentile(projections(data, "mip", 0.0), WINDOW_PERCENTILES)
    np.testing.assert_allclose(sc.auto_window(vol), expected, rtol=1e-12)
    np.testing.assert_allclose(sc.auto_window(vol, "mip"), expected, rtol=1e-12)
    # minIP: the mirrored percentiles of the minimum projections (background left out).
    data = rng.gamma(2.0, 10.0, (20, 20, 20)).astype(np.float32)  # no background region
    vol = sc.Volume(data)
    assert sc.background_value(vol) == data.min()
    lo, hi = WINDOW_PERCENTILES
    expected = np.percentile(projections(data, "minip", float(data.min())),
                             (100 - hi, 100 - lo))
    np.testing.assert_allclose(sc.auto_window(vol, "minip"), expected, rtol=1e-12)
    assert sc.auto_window(sc.Volume(np.full((3, 3, 3), 2, np.uint8))) == (2.0, 3.0)
    with pytest.raises(sc.ParameterError, match="mode"):
        sc.auto_window(vol, "dvr")


def test_a_one_valued_projection_windows_from_the_background():
    """A probability map's MIP is 1 almost everywhere: the window runs from the background."""
    data = np.zeros((16, 16, 16), np.float32)
    data[3:13, 3:13, 3:13] = 1.0
    data[3, 3, 3:13] = 0.5  # a few dimmer voxels on an edge
    projected = projections(data, "mip", 0.0)
    assert np.percentile(projected, WINDOW_PERCENTILES[0]) == 1.0  # the percentiles coincide
    assert sc.auto_window(sc.Volume(data)) == (0.0, 1.0)


def signed_map(shape=(24, 24, 24)) -> np.ndarray:
    """A statistical map: 0 outside a box, a negative and a positive blob inside."""
    idx = np.indices(shape).transpose(1, 2, 3, 0).astype(np.float64)
    neg = -6.0 * np.exp(-np.sum((idx - (8, 12, 12)) ** 2, axis=-1) / 30.0)
    pos = 4.0 * np.exp(-np.sum((idx - (16, 12, 12)) ** 2, axis=-1) / 30.0)
    data = np.zeros(shape, np.float32)
    data[3:-3, 3:-3, 3:-3] = (neg + pos)[3:-3, 3:-3, 3:-3]
    return data


def test_background_is_the_minimum_or_zero_whichever_more_voxels_hold():
    data = signed_map()
    assert sc.background_value(sc.Volume(data)) == 0.0  # 0 inside the range [-6, 4]
    ct = np.full((20, 20, 20), -1024, np.int16)  # air outside the field of view ...
    ct[4:16, 4:16, 4:16] = np.random.default_rng(1).integers(-1000, 1500, (12, 12, 12))
    ct[8, 8, 8] = 0
    assert sc.background_value(sc.Volume(ct)) == -1024.0
    # No value held by 1% of the voxels: the minimum (its few voxels are left out).
    smooth = np.random.default_rng(2).normal(0, 1, (20, 20, 20)).astype(np.float32)
    assert sc.background_value(sc.Volume(smooth)) == smooth.min()
    # The statistics leave the background out: the signed map's zeros here.
    np.testing.assert_array_equal(sample_values(sc.Volume(data)),
                                  data[data != 0].astype(np.float64))


def test_signed_data_gets_a_diverging_map_and_a_symmetric_window():
    data = signed_map()
    vol = sc.Volume(data)
    assert sc.is_signed(vol) and sc.auto_colormap(vol) == sc.transfer.DIVERGING
    both = np.concatenate([projections(data, "mip", 0.0), projections(data, "minip", 0.0)])
    m = np.percentile(np.abs(both), WINDOW_PERCENTILES[1])
    for mode in ("mip", "minip"):
        np.testing.assert_allclose(sc.auto_window(vol, mode), (-m, m), rtol=1e-12)
    # Not signed: a CT (background -1024), an MRI with a few negative voxels of ringing.
    mri = np.zeros((20, 20, 20), np.float32)
    mri[4:16, 4:16, 4:16] = 100.0
    mri[4, 4:8, 4:8] = -3.0
    for data in (mri, np.where(signed_map() == 0, -1024, signed_map()).astype(np.float32)):
        assert not sc.is_signed(sc.Volume(data)) and sc.auto_colormap(sc.Volume(data)) == "gray"
    # Otsu's threshold of the absolute values: a positive isovalue between the strong values.
    data = signed_map()
    assert 0 < sc.auto_iso(sc.Volume(data)) == otsu_threshold(np.abs(data[data != 0]))


def test_projection_pixels_of_background_only_rays_show_the_background():
    """No box: a MIP pixel whose ray meets only background has the background colour, every
    other pixel the colormap's colour of its value."""
    vol = small_object(shape=(40, 40, 40), center=(20, 20, 20), radius=10.0)
    cam = sc.Camera.orbit(vol, size=(40, 32), fit="box")
    shading = sc.Shading(background=(0.2, 0.4, 0.6, 1.0))
    frame = sc.Scene(vol).render(cam, mode="mip", shading=shading, window=(10, 90))
    value = frame.value
    empty = value == 0  # the background value; NaN: rays that miss the volume
    assert empty.sum() > 100 and (value > 0).sum() > 20
    reference = sc.transfer.apply_colormap(value, (10, 90), "gray", shading.background)
    reference[empty] = shading.background
    np.testing.assert_array_equal(frame.rgba, reference)
    assert np.all(frame.rgba[np.isnan(value) | empty] == np.float32((0.2, 0.4, 0.6, 1.0)))


def test_a_negative_isovalue_of_a_signed_map_shows_front_faces():
    """The object of an isovalue below the background is the values below it: rays come from
    the background and meet front faces (inside "high" showed only back faces)."""
    vol = sc.Volume(signed_map())
    assert sc.auto_inside(vol, -3.0) == "low" and sc.auto_inside(vol, 2.0) == "high"
    assert sc.auto_inside(vol, [-3.0, 2.0]) == "high"
    cam = sc.Camera.orbit(vol, size=(32, 32), fit="box")
    scene = sc.Scene(vol)
    auto = scene.render(cam, iso=-3.0)
    assert auto.hit.sum() > 20 and np.all(auto.face[auto.hit] == 1)
    np.testing.assert_array_equal(auto.rgba, scene.render(cam, iso=-3.0, inside="low").rgba)
    assert np.all(scene.render(cam, iso=-3.0, inside="high").face[auto.hit] == -1)


def test_auto_transfer_function_ramps_from_the_iso():
    rng = np.random.default_rng(8)
    data = np.zeros((20, 20, 20), np.float32)
    data[4:16, 4:16, 4:16] = rng.uniform(10, 20, (12, 12, 12))
    data[8:12, 8:12, 8:12] = rng.uniform(50, 60, (4, 4, 4))
    vol = sc.Volume(data)
    tf = sc.auto_transfer_function(vol)
    iso = sc.auto_iso(vol)
    assert 20 <= iso <= 50
    top = np.percentile(data[data > iso].astype(np.float64), 99.5)
    assert tf.opacity(iso) == 0.0 and tf.opacity(top) == pytest.approx(DVR_MAX_OPACITY)
    assert tf.opacity(1e9) == pytest.approx(DVR_MAX_OPACITY)
    assert tf.visible_ranges()[0][0] == iso
    assert tf.domain == pytest.approx((iso, top)) and tf.colormap == "viridis"
    # The default is used by mode="dvr" when no tf is given: the same image.
    scene, cam = sc.Scene(vol), sc.Camera.orbit(vol, size=(16, 16))
    np.testing.assert_array_equal(scene.render(cam, mode="dvr").rgba,
                                  scene.render(cam, mode="dvr", tf=tf).rgba)


def small_object(shape=(90, 80, 70), center=(60, 25, 40), radius=5.0) -> sc.Volume:
    """A ball of value 100 in a large empty uint8 volume, far from the volume's centre."""
    idx = np.indices(shape).transpose(1, 2, 3, 0)
    inside = np.linalg.norm(idx - np.asarray(center), axis=-1) <= radius
    return sc.Volume((inside * 100).astype(np.uint8), spacing=(0.5, 1.0, 2.0),
                     origin=(-3.0, 4.0, 1.0))


def test_content_box_is_the_object_grown_by_one_voxel():
    vol = small_object()
    ijk = np.argwhere(vol.data >= 50)
    lo, hi = content_box(vol, iso=50)
    np.testing.assert_allclose(lo, vol.index_to_world(ijk.min(axis=0) - 1))
    np.testing.assert_allclose(hi, vol.index_to_world(ijk.max(axis=0) + 1))
    # Inside "low": the complement, which reaches the grid's corners.
    np.testing.assert_allclose(content_box(vol, iso=50, inside="low"), vol.bounds)
    # Nothing visible: the whole grid.
    np.testing.assert_allclose(content_box(vol, iso=200), vol.bounds)
    # A transfer function: the voxels it makes visible.
    tf = sc.TransferFunction([(90, 0.0), (95, 0.5)], domain=(0, 100))
    np.testing.assert_allclose(content_box(vol, tf=tf), (lo, hi))
    # Strided: still holds the exact box, and is at most a stride (+1 voxel) larger.
    slo, shi = content_box(vol, iso=50, max_voxels=5000)
    spacing = np.asarray(vol.spacing)
    assert np.all(slo <= lo) and np.all(shi >= hi)
    assert np.all(lo - slo <= 6 * spacing) and np.all(shi - hi <= 6 * spacing)


def projected_extent(cam: sc.Camera, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Largest |screen coordinate| of the box's corners as a fraction of the half image
    (x, y), through the camera's own ray directions (the independent path)."""
    corners = np.array([[(lo, hi)[b >> a & 1][a] for a in range(3)] for b in range(8)])
    origins, directions = cam.rays()
    # Screen coordinates of a direction d: (d.right, d.up) / d.forward; the image spans the
    # coordinates of the outermost pixel centres plus half a pixel.
    d = directions
    sx = (d @ cam.right) / (d @ cam.forward)
    sy = (d @ cam.up) / (d @ cam.forward)
    half_w = sx[0, -1] * cam.width / (cam.width - 1)
    half_h = sy[0, 0] * cam.height / (cam.height - 1)
    v = corners - cam.position
    return np.array([np.max(np.abs(v @ cam.right / (v @ cam.forward))) / half_w,
                     np.max(np.abs(v @ cam.up / (v @ cam.forward))) / half_h])


@pytest.mark.parametrize("azimuth, elevation, size", [(30, 20, (64, 48)), (-100, 60, (40, 80)),
                                                      (0, 90, (50, 50))])
def test_fit_frames_the_box_tightly(azimuth, elevation, size):
    vol = small_object()
    lo, hi = content_box(vol, iso=50)
    cam = sc.Camera.orbit(vol, azimuth=azimuth, elevation=elevation, size=size, fit=(lo, hi))
    extent = projected_extent(cam, lo, hi)
    assert np.all(extent <= 1 / sc.camera.FIT_MARGIN + 1e-9)  # every corner in the image
    assert np.max(extent) == pytest.approx(1 / sc.camera.FIT_MARGIN, rel=1e-9)  # and tight
    np.testing.assert_allclose(cam.look_at, 0.5 * (lo + hi))


def test_fit_box_keeps_the_bounding_sphere():
    vol = small_object()
    a = sc.Camera.orbit(vol, azimuth=10, elevation=5, size=(30, 20))
    b = sc.Camera.orbit(vol, azimuth=10, elevation=5, size=(30, 20), fit="box")
    lo, hi = vol.bounds
    radius = 0.5 * np.linalg.norm(hi - lo)
    half_fov = np.radians(15)
    np.testing.assert_allclose(np.linalg.norm(a.position - vol.center), radius / np.sin(half_fov))
    np.testing.assert_array_equal(a.position, b.position)
    with pytest.raises(sc.ParameterError, match="fit='content' needs to know what is visible"):
        sc.Camera.orbit(vol, fit="content")  # a bare volume has no isovalue
    with pytest.raises(sc.ParameterError, match="fit must be 'box', 'content' or a world box"):
        sc.Camera.orbit(vol, fit="contents")
    with pytest.raises(sc.ParameterError, match="lo <= hi"):
        sc.Camera.orbit(vol, fit=((0, 0, 0), (1, -1, 1)))


def hit_extent(mask: np.ndarray) -> float:
    """Largest fraction of the image's height or width covered by the mask's bounding box."""
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if rows.size == 0:
        return 0.0
    return max((rows[-1] - rows[0] + 1) / mask.shape[0], (cols[-1] - cols[0] + 1) / mask.shape[1])


@pytest.mark.parametrize("ortho", [False, True])
def test_content_framing_fills_the_image_with_a_small_object(ortho):
    vol = small_object()
    scene = sc.Scene(vol)
    box = sc.Camera.orbit(vol, size=(48, 40), ortho=ortho)
    fit = sc.Camera.orbit(vol, size=(48, 40), ortho=ortho, fit=content_box(vol))
    assert hit_extent(scene.render(box).hit) < 0.25  # the problem of the issue
    assert hit_extent(scene.render(fit).hit) >= 0.5
    # fit="content" on the scene frames what its (automatic) isovalue shows: the same camera.
    by_scene = sc.Camera.orbit(scene, size=(48, 40), ortho=ortho, fit="content")
    np.testing.assert_array_equal(by_scene.position, fit.position)


def drawn_pixels(image: np.ndarray) -> np.ndarray:
    """Pixels brighter than the background colour (MIP's black voxels do not count)."""
    return image[..., :3].max(axis=-1) > 40


def cli(argv: list[str], capsys) -> tuple[int, str, str]:
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def test_cli_renders_without_iso_window_or_tf(tmp_path, capsys):
    vol = small_object()
    src = tmp_path / "ball.npz"
    sc.write(vol, src)
    for mode in ("iso", "mip", "dvr"):
        png = tmp_path / f"{mode}.png"
        code, _, err = cli(["render", str(src), "--mode", mode, "--size", "40x32",
                            "-o", str(png)], capsys)
        assert code == 0, err
        assert hit_extent(drawn_pixels(np.asarray(Image.open(png)))) >= 0.5, mode
    assert f"iso {sc.auto_iso(vol):g} (automatic: Otsu" in cli(
        ["render", str(src), "--size", "8x8", "-o", str(png)], capsys)[2]
    err = cli(["render", str(src), "--mode", "mip", "--size", "8x8", "-o", str(png)], capsys)[2]
    assert "window {:g}..{:g} (automatic".format(*sc.auto_window(vol)) in err
    err = cli(["render", str(src), "--mode", "dvr", "--size", "8x8", "-o", str(png)], capsys)[2]
    assert f"opacity 0 at {sc.auto_iso(vol):g} rising to {DVR_MAX_OPACITY:g}" in err


@pytest.fixture(scope="module")
def mri() -> Path:
    pytest.importorskip("nibabel")
    if not MNI.is_file():
        pytest.skip(f"the MNI152 sample is not present at {MNI}")
    return MNI


@pytest.mark.parametrize("mode", ["iso", "mip", "dvr"])
def test_newcomer_commands_on_the_mri(mri, tmp_path, capsys, mode):
    """`splinecast render head.nii.gz -o head.png` (and --mode mip / dvr) with nothing else."""
    png = tmp_path / f"{mode}.png"
    code, _, err = cli(["render", str(mri), "--mode", mode, "--size", "96x80", "-o", str(png)],
                       capsys)
    assert code == 0, err
    drawn = drawn_pixels(np.asarray(Image.open(png)))
    vol = sc.read(mri)
    lo, hi = vol.value_range
    if mode == "iso":
        iso = float(re.search(r"iso ([0-9.e+-]+) \(automatic", err).group(1))
        assert lo < iso < hi and iso == pytest.approx(sc.auto_iso(vol), abs=1e-4)
    assert hit_extent(drawn) >= 0.5  # the brain fills the frame
    assert drawn.mean() > 0.1, "the image is (nearly) empty"
