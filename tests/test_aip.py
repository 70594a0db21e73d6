"""The average intensity projection (``sc.Aip``, ``mode="aip"``) against independent references.

References, none of them the code under test:

- dense sampling: the mean of 20000 evenly spaced samples (midpoint rule) of the model's
  reconstruction along each pixel's ray inside the model's box, the ray clipped to the box by
  the slab test of ``tests/reference.py`` (the trilinear interpolant in lerp form; scipy's
  ``map_coordinates`` for the cubic B-spline, whose pieces are degree 9 along a ray, the
  highest the quadrature must integrate exactly);
- a linear ramp, whose mean along a segment is its value at the segment's midpoint (the
  trilinear interpolant reproduces it), with and without a crop box (the segment then clipped
  to the box here);
- a second code path: a pyramid's bricks (state carried brick to brick), level 0 held whole,
  and sort-last Dask (partial states of two workers combined) against the in-memory render;
- the command line against the API render with the window the mode chooses.
"""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image
from reference import box_interval, bspline, smooth_noise, trilinear

import splinecast as sc
from splinecast.cli import main

SAMPLES = 20000


def _index_rays(vol: sc.Volume, cam: sc.Camera) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel rays in voxel index space, parametrized by world distance."""
    W, U = cam.rays()
    W, U = W.reshape(-1, 3), U.reshape(-1, 3)
    spacing, origin = np.asarray(vol.spacing), np.asarray(vol.origin)
    return (W - origin) / spacing, U / spacing


def _dense_mean(value, o, d, t0, t1, chunk: int = 16) -> np.ndarray:
    """Mean of ``value(points)`` over ``[t0, t1]`` of each ray ``o + t d`` (NaN: empty)."""
    out = np.full(len(o), np.nan)
    s = (np.arange(SAMPLES) + 0.5) / SAMPLES
    rays = np.flatnonzero(t1 > t0)
    for a in range(0, len(rays), chunk):
        r = rays[a:a + chunk]
        t = t0[r, None] + s[None, :] * (t1[r] - t0[r])[:, None]
        points = o[r, None, :] + t[..., None] * d[r, None, :]
        out[r] = value(points).mean(axis=1)
    return out


@pytest.fixture(scope="module")
def lobb() -> sc.Volume:
    return sc.demo("marschner-lobb", size=12)


@pytest.mark.parametrize("model", ["trilinear", "bspline3"])
@pytest.mark.parametrize("ortho", [False, True])
def test_the_mean_along_each_ray_is_the_dense_mean(lobb, model, ortho):
    vol = lobb
    cam = sc.Camera.orbit(vol, azimuth=30, elevation=20, size=(24, 20), fit="box", zoom=0.8,
                          ortho=ortho)
    frame = sc.Scene(vol, model=model).render(cam, sc.Aip(window=(0.0, 1.0)))
    data = np.asarray(vol.data, np.float64)
    value = ((lambda p: trilinear(data, p)) if model == "trilinear"
             else (lambda p: bspline(data, 3, p)))
    o, d = _index_rays(vol, cam)
    t0, t1 = box_interval(o, d, np.zeros(3), np.asarray(vol.shape, float) - 1.0)
    want = _dense_mean(value, o, d, t0, t1).reshape(cam.height, cam.width)
    hit = np.isfinite(want)
    assert 50 < hit.sum() < hit.size  # rays through the volume and rays that miss it
    np.testing.assert_array_equal(np.isfinite(frame.value), hit)
    np.testing.assert_allclose(frame.value[hit], want[hit], rtol=0, atol=2e-7)
    # The depth is where the ray enters the volume; a miss has none.
    entry = np.where(hit, t0.reshape(want.shape), np.inf)
    np.testing.assert_allclose(frame.depth, entry, rtol=0, atol=1e-9)
    assert frame.stats["mode"] == "aip" and frame.stats["window"] == (0.0, 1.0)


@pytest.mark.parametrize("model", ["bspline1", "bspline2", "qss", "s31"])
def test_every_other_model_averages_its_own_reconstruction(model):
    """The models' 3D reconstructions evaluated directly (``tests/evaluators.py``: scipy's
    B-splines, the type-6 splines' Bernstein-Bezier rules written in the tests), densely
    sampled along each ray inside the model's box."""
    from evaluators import model_evaluator

    vol = sc.Volume(smooth_noise((11, 10, 12), seed=7, sigma=1.6).astype(np.float32),
                    spacing=(1.0, 1.2, 0.9), origin=(-3.0, 1.0, 0.5))
    cam = sc.Camera.orbit(vol, azimuth=37, elevation=23, size=(14, 11))
    scene = sc.Scene(vol, model=model)
    frame = scene.render(cam, sc.Aip(window=(-1.0, 1.0)))
    ev = model_evaluator(model, vol, scene)
    o, d = _index_rays(vol, cam)
    t0, t1 = box_interval(o, d, ev.lo, ev.hi)
    want = _dense_mean(ev.value, o, d, t0, t1).reshape(cam.height, cam.width)
    hit = np.isfinite(want)
    assert 30 < hit.sum()
    np.testing.assert_array_equal(np.isfinite(frame.value), hit)
    # The midpoint rule's error at 20000 samples: far below 1e-6 of these values (std 1).
    np.testing.assert_allclose(frame.value[hit], want[hit], rtol=0, atol=1e-6)


def _ramp() -> tuple[sc.Volume, np.ndarray]:
    i, j, k = np.meshgrid(*(np.arange(n, dtype=float) for n in (13, 11, 9)), indexing="ij")
    coeff = np.array([2.0, -3.0, 0.5])
    data = coeff[0] * i + coeff[1] * j + coeff[2] * k + 7.0
    return sc.Volume(data, spacing=(1.0, 0.8, 1.3), origin=(-4.0, 2.0, 0.5)), coeff


@pytest.mark.parametrize("crop", [None, (-1.0, 5.0, 3.0, 9.0, 1.0, 9.0)])
def test_a_linear_ramp_averages_to_its_value_at_the_middle_of_the_path(crop):
    vol, coeff = _ramp()
    cam = sc.Camera.orbit(vol, azimuth=-50, elevation=35, size=(22, 18), fit="box", zoom=0.8)
    frame = sc.Scene(vol).render(cam, "aip", crop=crop)
    o, d = _index_rays(vol, cam)
    lo, hi = np.zeros(3), np.asarray(vol.shape, float) - 1.0
    if crop is not None:  # the crop box in index space, intersected with the volume's
        spacing, origin = np.asarray(vol.spacing), np.asarray(vol.origin)
        box = np.asarray(crop).reshape(3, 2)
        lo = np.maximum(lo, (box[:, 0] - origin) / spacing)
        hi = np.minimum(hi, (box[:, 1] - origin) / spacing)
    t0, t1 = box_interval(o, d, lo, hi)
    hit = (t1 > t0).reshape(cam.height, cam.width)
    middle = o + (0.5 * (t0 + t1))[:, None] * d
    want = (middle @ coeff + 7.0).reshape(hit.shape)
    assert 30 < hit.sum() < hit.size
    np.testing.assert_array_equal(np.isfinite(frame.value), hit)
    np.testing.assert_allclose(frame.value[hit], want[hit], rtol=1e-12, atol=1e-11)


def test_the_window_and_colours_follow_the_projection(lobb):
    """The default window is the percentiles of the volume's mean projections (as MIP's is of
    its maximum projections); pixels map through it as MIP's do; misses show the background."""
    vol = lobb
    data = np.asarray(vol.data, np.float64)
    pixels = np.concatenate([data.mean(axis=a).ravel() for a in range(3)])
    want = tuple(np.percentile(pixels, sc.render.defaults.WINDOW_PERCENTILES))
    assert sc.Aip.default_window(vol) == pytest.approx(want, rel=1e-12)
    cam = sc.Camera.orbit(vol, size=(20, 16), fit="box", zoom=0.7)
    frame = sc.Scene(vol).render(cam, mode="aip")
    assert frame.stats["window"] == pytest.approx(want, rel=1e-12)
    lo, hi = want
    gray = np.clip((frame.value - lo) / (hi - lo), 0, 1)
    hit = np.isfinite(frame.value)
    np.testing.assert_allclose(frame.rgba[hit, 0], gray[hit], atol=2e-3)
    background = np.asarray(sc.Shading().background, np.float32)
    assert (~hit).any() and np.all(frame.rgba[~hit] == background)


def test_aip_options_are_checked_when_made():
    with pytest.raises(sc.ParameterError, match="window must be two finite numbers"):
        sc.Scene(sc.demo("sphere", size=8)).render(sc.Camera.orbit(sc.demo("sphere", size=8)),
                                                   sc.Aip(window=(1.0, 0.0)))
    with pytest.raises(sc.ParameterError, match="method must be one of"):
        sc.Scene(sc.demo("sphere", size=8)).render(
            sc.Camera.orbit(sc.demo("sphere", size=8)), mode="aip", method="sampled")


# ------------------------------------------------------------------------------- pyramids, Dask
B = 8


@pytest.fixture(scope="module")
def noise(tmp_path_factory):
    pytest.importorskip("zarr", reason="the multires extra (zarr) is not installed")
    vol = sc.Volume(smooth_noise((27, 23, 21), seed=3, sigma=2.0).astype(np.float32))
    path = tmp_path_factory.mktemp("aip") / "noise.zarr"
    sc.build_pyramid(vol, path, brick=B, shard=B, progress=False)
    return vol, path


def _noise_camera(size: tuple[int, int] = (26, 22)) -> sc.Camera:
    return sc.Camera((45.0, -24.0, 33.0), (13.0, 11.0, 10.0), size=size)


@pytest.mark.parametrize("model", ["trilinear", "s31"])
def test_a_pyramid_of_bricks_renders_the_in_memory_projection(noise, model):
    vol, path = noise
    cam = _noise_camera()
    options = {"mode": "aip", "window": (-1.0, 1.0)}
    whole = sc.Scene(vol, model=model).render(cam, **options)
    with sc.Scene(sc.read(path), model=model, budget="64MiB", lod=1e-6,
                  whole_level=False) as bricks:
        drawn = bricks.render(cam, complete=True, **options)
    st = drawn.stats
    assert st["complete"] and st["cut_levels"] == {0: st["cut_bricks"]} and st["cut_bricks"] > 8
    hit = np.isfinite(whole.value)
    assert 50 < hit.sum() < hit.size
    np.testing.assert_array_equal(np.isfinite(drawn.value), hit)
    # Each brick parametrizes its pieces from its own entry: equal to rounding.
    np.testing.assert_allclose(drawn.value[hit], whole.value[hit], rtol=0, atol=1e-12)
    np.testing.assert_allclose(drawn.depth[hit], whole.depth[hit], rtol=0, atol=1e-12)
    np.testing.assert_allclose(drawn.rgba, whole.rgba, rtol=0, atol=1e-6)
    if model == "trilinear":
        with sc.Scene(sc.read(path), budget="64MiB", lod=1e-6) as held:
            frame = held.render(cam, complete=True, **options)
        assert frame.stats["whole_level"]
        np.testing.assert_array_equal(frame.value, whole.value)


def test_a_cut_of_a_coarser_level_renders_that_levels_projection(noise):
    """A cut of level-1 bricks gives the in-memory projection of level 1's volume."""
    vol, path = noise
    cam = _noise_camera()
    with sc.Scene(sc.read(path), budget="64MiB", lod=4.0) as coarse:
        frame = coarse.render(cam, "aip", window=(-1.0, 1.0), complete=True)
    assert set(frame.stats["cut_levels"]) == {1}
    level = sc.read(path).level(1).to_volume()
    want = sc.Scene(level).render(cam, "aip", window=(-1.0, 1.0))
    hit = np.isfinite(want.value)
    assert 50 < hit.sum() < hit.size
    np.testing.assert_array_equal(np.isfinite(frame.value), hit)
    np.testing.assert_allclose(frame.value[hit], want.value[hit], rtol=0, atol=1e-12)


def test_sort_last_dask_equals_the_in_memory_projection(noise):
    distributed = pytest.importorskip("distributed", reason="needs the distributed extra")
    from splinecast.distributed import DistributedScene, SceneSource, VolumeInfo
    from splinecast.distributed.sort_last import (
        Share,
        combine_partials,
        finish_partial,
        render_share,
        split_bricks,
    )

    vol, path = noise
    level = sc.read(path).level(0).to_volume()
    cam = _noise_camera((24, 20))
    options = {"mode": "aip", "window": (-1.0, 1.0)}
    # Compile the workers' kernels here first (they then load them from the disk cache), by
    # running the sort-last tasks as plain functions on the two halves of the bricks.
    header = VolumeInfo.of(level)
    tree = split_bricks((4, 3, 3), 2)
    small = sc.Camera.orbit(level, size=(8, 8))
    low, high = (render_share(Share(SceneSource(path, "trilinear"), 0, B, leaf.part, leaf.lo,
                                    leaf.hi), small, options, header, "warm-up aip")
                 for leaf in tree.leaves())
    finish_partial(combine_partials(low, high, small, options, header, "warm-up aip"), small,
                   options, header, "warm-up aip")
    want = sc.Scene(level).render(cam, **options)
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                       dashboard_address=":0", silence_logs=40)
    with cluster, distributed.Client(cluster) as client:
        scene = DistributedScene(path, client, strategy="sort-last", level=0)
        got = scene.render(cam, **options)
        # The automatic window comes from the coarsest level (as every automatic choice of a
        # sort-last scene) and travels in the header to the workers.
        auto = scene.render(cam, mode="aip")
        header_window = scene.volume.metadata["default_window_aip"]
    assert got.stats["shares"] == 2
    hit = np.isfinite(want.value)
    assert 50 < hit.sum() < hit.size
    np.testing.assert_array_equal(np.isfinite(got.value), hit)
    np.testing.assert_allclose(got.value[hit], want.value[hit], rtol=0, atol=1e-12)
    np.testing.assert_allclose(got.depth[hit], want.depth[hit], rtol=0, atol=1e-12)
    np.testing.assert_allclose(got.rgba, want.rgba, rtol=0, atol=1e-6)
    coarsest = sc.read(path).level(-1).to_volume()
    assert auto.stats["window"] == pytest.approx(sc.Aip.default_window(coarsest), rel=1e-12)
    assert tuple(header_window) == auto.stats["window"]


# ------------------------------------------------------------------------------- command line
SRC = "demo:sphere?size=16"


def test_the_command_line_renders_aip_as_the_api(tmp_path, capsys):
    png = tmp_path / "aip.png"
    code = main(["render", SRC, "--mode", "aip", "--size", "20x16", "-o", str(png)])
    out, err = capsys.readouterr()
    assert code == 0 and out.strip().endswith("aip.png")
    vol = sc.demo("sphere", size=16)
    window = sc.Aip.default_window(vol)
    assert "window {:g}..{:g} (automatic".format(*window) in err  # printed, as MIP's
    cam = sc.Camera.orbit(vol, size=(20, 16), fit=sc.content_box(vol))  # --fit content
    frame = sc.Scene(vol).render(cam, mode="aip", window=window)
    np.testing.assert_array_equal(np.asarray(Image.open(png)), frame.to_uint8())


@pytest.mark.parametrize("extra, words", [
    (["--method", "sampled"], "--method does not apply to --mode aip"),
    (["--tolerance", "0.1"], "--tolerance does not apply to --mode aip"),
    (["--window", "2,1"], "window must be two finite numbers with lo < hi"),
])
def test_bad_aip_options_are_one_line(tmp_path, capsys, extra, words):
    code = main(["render", SRC, "--mode", "aip", "--size", "8x8", "--quiet",
                 "-o", str(tmp_path / "x.png"), *extra])
    _, err = capsys.readouterr()
    assert code == 2 and words in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "x.png").exists()


def test_the_help_offers_the_mode():
    parser_help = _help(["render", "--help"])
    assert "aip: average intensity projection" in parser_help
    assert "--mode mip/minip/aip" in parser_help  # --window, --colormap


def _help(argv: list[str]) -> str:
    import contextlib
    import io

    buffer = io.StringIO()
    with contextlib.redirect_stdout(buffer), pytest.raises(SystemExit):
        main(argv)
    return " ".join(buffer.getvalue().split())
