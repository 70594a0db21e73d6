"""Analytic maximum / minimum intensity projection against dense sampling along the same rays.

The reference samples the trilinear interpolant (``reference.trilinear``, lerp form) every 0.002
voxels along each ray and refines the best sample with a bounded scalar minimizer, independently of
the package's cubic ray profiles.
"""

from __future__ import annotations

import numpy as np
import pytest
from reference import trilinear
from scipy.optimize import minimize_scalar

import splinecast as sc
from splinecast.render import mip as mip_module
from splinecast.render.defaults import sample_values


@pytest.fixture(scope="module")
def setup():
    vol = sc.demo("noise", size=20)
    scene = sc.Scene(vol)
    cam = sc.Camera.orbit(vol, azimuth=35, elevation=25, size=(20, 15))
    return vol, scene, cam


def _ray_profile(vol, o, u, t0, t1):
    spacing = np.asarray(vol.spacing)
    origin = np.asarray(vol.origin)

    def f(t):
        p = (o + np.multiply.outer(np.atleast_1d(t), u) - origin) / spacing
        return trilinear(vol.data, p)

    return f


def _box_interval(vol, o, u):
    lo, hi = vol.bounds
    with np.errstate(divide="ignore"):
        ta, tb = (lo - o) / u, (hi - o) / u
    t0 = max(0.0, np.max(np.minimum(ta, tb)))
    t1 = np.min(np.maximum(ta, tb))
    return t0, t1


@pytest.mark.parametrize("kind", ["mip", "minip"])
def test_exact_projection_bounds_dense_samples_and_matches_refined_extremum(setup, kind):
    vol, scene, cam = setup
    frame = scene.render(cam, mode=kind)
    origins, dirs = cam.rays()
    sign = 1.0 if kind == "mip" else -1.0
    checked = 0
    for row in range(0, cam.height, 2):
        for col in range(0, cam.width, 2):
            o, u = origins[row, col], dirs[row, col]
            t0, t1 = _box_interval(vol, o, u)
            if not t0 < t1:
                assert np.isnan(frame.value[row, col])
                continue
            f = _ray_profile(vol, o, u, t0, t1)
            step = 0.002 * min(vol.spacing)
            ts = np.append(np.arange(t0, t1, step), t1)  # the exit point too
            samples = sign * f(ts)
            best = int(np.argmax(samples))
            lo_t, hi_t = ts[max(best - 1, 0)], ts[min(best + 1, len(ts) - 1)]
            res = minimize_scalar(lambda t, f=f: -sign * f(t)[0], bounds=(lo_t, hi_t),
                                  method="bounded", options={"xatol": 1e-12})
            refined = max(samples[best], -res.fun)
            got = sign * frame.value[row, col]
            assert got >= samples.max() - 1e-12
            assert abs(got - refined) < 1e-6
            # The reported depth is where the value is taken.
            assert sign * f(frame.depth[row, col])[0] == pytest.approx(got, abs=1e-7)
            checked += 1
    assert checked > 20


def test_exact_mip_is_never_below_the_sampled_mip(setup):
    vol, scene, cam = setup
    exact = scene.render(cam, mode="mip")
    for step in (2.0, 1.0, 0.5, 0.1):
        sampled = scene.render(cam, mode="mip", method="sampled", step=step)
        both = np.isfinite(sampled.value)
        assert np.all(exact.value[both] >= sampled.value[both] - 1e-12)
    # Sampling converges to the exact maximum from below.
    gap_coarse = np.nanmax(exact.value - scene.render(cam, mode="mip", method="sampled",
                                                      step=1.0).value)
    gap_fine = np.nanmax(exact.value - scene.render(cam, mode="mip", method="sampled",
                                                    step=0.05).value)
    assert gap_fine < gap_coarse and gap_fine < 1e-2


def test_mip_image_window_and_miss_background(setup):
    vol, scene, cam = setup
    frame = scene.render(cam, mode="mip", window=(0.2, 0.8), colormap="gray")
    hit = np.isfinite(frame.value)
    assert (~hit).any() and hit.any()
    expect = np.clip((frame.value[hit] - 0.2) / 0.6, 0, 1)
    np.testing.assert_allclose(frame.rgba[hit][:, 0], expect, atol=2e-3)
    assert np.all(np.isinf(frame.depth[~hit]))
    with pytest.raises(sc.ParameterError, match="window"):
        scene.render(cam, mode="mip", window=(1, 0))


def test_a_maximum_far_behind_dim_structure_is_found_and_the_front_is_leapt():
    """A bright slab (value 1) at the back of dim noise (values in [0, 0.1]): the 16-cell block
    minima bound nothing there (the slab's block also holds noise), so before the walk the MIP
    takes values of the field inside the block with the largest maximum; the front's blocks
    then cannot beat that bound and are leapt. Reference: the field is 1 where x <= 7 (in
    voxels) and below 1 elsewhere, so the answer is 1, taken between the planes x = 7 and
    x = 0 (analytic)."""
    n = 64
    rng = np.random.default_rng(3)
    data = (0.1 * rng.random((n, n, n))).astype(np.float32)
    data[:8] = 1.0
    vol = sc.Volume(data)
    cam = sc.Camera.orbit(vol, azimuth=0.0, elevation=0.0, size=(32, 24), zoom=1.3)
    frame = sc.Scene(vol).render(cam, mode="mip")
    origins, dirs = cam.rays()
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (7.0 - origins[..., 0]) / dirs[..., 0]
    at = origins + t[..., None] * dirs
    inside = np.all((at[..., 1:] > 0.5) & (at[..., 1:] < n - 1.5), axis=-1) & (t > 0)
    assert inside.sum() > 150
    np.testing.assert_allclose(frame.value[inside], 1.0, rtol=0, atol=1e-12)
    # Taken inside the slab (rounding makes some of its values 1 - 1 ulp, so the first
    # position of the largest computed value may lie anywhere in it).
    with np.errstate(divide="ignore", invalid="ignore"):
        back = (0.0 - origins[..., 0]) / dirs[..., 0]
    assert np.all(frame.depth[inside] >= t[inside] - 1e-9)
    assert np.all(frame.depth[inside] <= back[inside] + 1e-9)
    # Without the bound every front cell whose block holds noise above the block minima is
    # tested (32 per ray on average, measured); with it, the slab's cells and few others (8).
    assert frame.cells_tested[inside].mean() < 16


def test_a_constant_field_keeps_its_first_position():
    """Every value equal: the bound taken before the walk equals the answer, which must still
    be found, at the entry point (the first position of the maximum)."""
    vol = sc.Volume(np.full((20, 20, 20), 5.0, dtype=np.float32))
    cam = sc.Camera.orbit(vol, azimuth=35, elevation=25, size=(20, 15))
    frame = sc.Scene(vol).render(cam, mode="mip")
    origins, dirs = cam.rays()
    hit = np.isfinite(frame.depth)
    assert hit.sum() > 100
    np.testing.assert_array_equal(frame.value[hit], 5.0)
    for row, col in zip(*np.nonzero(hit), strict=True):
        t0, _ = _box_interval(vol, origins[row, col], dirs[row, col])
        assert frame.depth[row, col] == pytest.approx(t0, abs=1e-9)



def _fast_and_slow(vol, model, kind, **slower):
    """Frames of the default exact method and of the same with the kernel parameters
    ``slower`` replaced (a slower path it must agree with), checked bit-identical in value,
    depth and position; returns both and the mask of rays with a value."""
    cam = sc.Camera.orbit(vol, azimuth=35, elevation=25, size=(48, 36))
    fast = sc.Scene(vol, model=model).render(cam, mode=kind)
    original = mip_module.Mip.__init__

    def init(self, *args, **kwargs):
        original(self, *args, **kwargs)
        self.params = self.params._replace(**slower)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(mip_module.Mip, "__init__", init)
        slow = sc.Scene(vol, model=model).render(cam, mode=kind)
    for name in ("value", "depth", "position"):
        np.testing.assert_array_equal(getattr(fast, name), getattr(slow, name), err_msg=name)
    hit = np.isfinite(fast.value)
    assert hit.sum() > 500
    return fast, slow, hit


@pytest.mark.parametrize(("model", "kind"), [("trilinear", "mip"), ("trilinear", "minip"),
                                              ("s31", "mip"), ("bspline3", "mip")])
@pytest.mark.parametrize("smooth", [True, False], ids=["smooth", "noise"])
def test_the_previous_rays_bound_changes_no_value_or_position(model, kind, smooth):
    """The bound taken where the previous ray found its maximum only leaves out cells: values,
    depths and positions are bit-identical to the block-walk bound's (``coherent = 0``: the
    coarse block walk for every ray), on a smooth volume (the bound is then nearly the answer)
    and on noise (neighbouring maxima at unrelated depths)."""
    vol = sc.demo("marschner-lobb", size=40) if smooth else sc.demo("noise", size=24)
    fast, slow, hit = _fast_and_slow(vol, model, kind, coherent=0.0)
    if smooth and kind == "mip":
        # The bound is exercised: it leaves out cells the block walk's bound lets through
        # (the minimum of this volume is not as coherent: there both test as many).
        assert fast.cells_tested[hit].sum() < 0.95 * slow.cells_tested[hit].sum()  # 0.90


def _quantized_marschner_lobb(n):
    """Marschner-Lobb in 9 integer levels: plateaus of equal values, as in CT and MRI data,
    where a ray meets the largest value of a block inside it."""
    ml = sc.demo("marschner-lobb", size=n)
    return sc.Volume(np.round(np.asarray(ml.data, np.float64) * 8.0).astype(np.uint8))


@pytest.mark.parametrize(("model", "kind"), [("trilinear", "mip"), ("trilinear", "minip"),
                                              ("s31", "mip"), ("bspline2", "mip")])
@pytest.mark.parametrize("volume", ["smooth", "noise", "plateaus"])
def test_pruned_pieces_and_blocks_change_no_value_or_position(model, kind, volume):
    """Pieces whose control points cannot beat the running maximum are left out, and the rest
    of a block is leapt once the maximum reaches the block's: values, depths and positions are
    bit-identical to the exact method's without either (``prune = 0``: every tested piece's
    derivative roots, the hierarchy asked once per finest block)."""
    vol = {"smooth": lambda: sc.demo("marschner-lobb", size=40),
           "noise": lambda: sc.demo("noise", size=24),
           "plateaus": lambda: _quantized_marschner_lobb(40)}[volume]()
    fast, slow, hit = _fast_and_slow(vol, model, kind, prune=0.0)
    if volume == "plateaus" and model == "trilinear":
        # Asking again is exercised: rays leap the rest of blocks they would have walked.
        assert fast.cells_visited[hit].sum() < 0.98 * slow.cells_visited[hit].sum()  # 0.96


def test_tiles_of_an_image_have_the_whole_images_projection():
    """Rays of a tile follow other rays than the same pixels of the whole image do (their
    bounds start elsewhere); the projection is the same."""
    vol = sc.demo("marschner-lobb", size=40)
    cam = sc.Camera.orbit(vol, azimuth=200, elevation=-30, size=(64, 48), zoom=1.4)
    scene = sc.Scene(vol)
    whole = scene.render(cam, mode="mip")
    part = scene.render(cam.tile(13, 7, 31, 29), mode="mip")
    np.testing.assert_array_equal(part.value, whole.value[7:36, 13:44])
    np.testing.assert_array_equal(part.depth, whole.depth[7:36, 13:44])


@pytest.mark.parametrize("kind", ["mip", "minip"])
def test_a_tolerance_gives_the_whole_images_pixels_in_windows_on_the_tile_grid(kind):
    """With a tolerance, a ray starts from what the previous ray of its tile found, and that
    decides which value within the tolerance it reports. Windows whose edges lie on the scene's
    grid of tiles (the viewer's stripes, Dask's tiles) must still give exactly the whole
    image's pixels: stripes of whole rows, and windows that start inside a band of rows."""
    vol = sc.demo("marschner-lobb", size=40)
    scene = sc.Scene(vol)
    width, height = 100, 76
    cam = sc.Camera.orbit(vol, azimuth=35, elevation=25, size=(width, height))
    whole = scene.render(cam, mode=kind, tolerance=0.05)
    exact = scene.render(cam, mode=kind)
    hit = np.isfinite(exact.value)
    assert np.any(whole.value[hit] != exact.value[hit])  # the tolerance changes pixels
    cols, rows = scene.tile_shape
    assert cols > 0 and rows > 0
    for tw, th in ((width, 3 * rows), (3 * cols, 2 * rows), (cols, height)):
        for r0 in range(0, height, th):
            for c0 in range(0, width, tw):
                window = cam.tile(c0, r0, min(tw, width - c0), min(th, height - r0))
                part = scene.render(window, mode=kind, tolerance=0.05)
                where = (slice(r0, r0 + th), slice(c0, c0 + tw))
                np.testing.assert_array_equal(part.value, whole.value[where])
                np.testing.assert_array_equal(part.depth, whole.depth[where])


@pytest.mark.parametrize("model", ["s31", "qss"])
def test_the_smooth_models_leap_a_constant_background_once_they_have_met_its_value(model):
    """The type-6 models' cube ranges are widened for rounding by the magnitude of the cube's
    own data points, so a cube of zeros has the exact range [0, 0]: a MIP ray through a zero
    background leaps it after its first cells, as over the trilinear model (with a widening
    from the whole volume's largest value, every background cube was tested). Reference: the
    projection is 0 there (every coefficient of a zero cube is 0)."""
    n = 40
    data = np.zeros((n, n, n), np.float32)
    data[16:24, 16:24, 16:24] = 100.0
    vol = sc.Volume(data)
    scene = sc.Scene(vol, model=model)
    kernel = scene.grid.kernel
    assert kernel.cube_lo[2, 2, 2] == 0.0 and kernel.cube_hi[2, 2, 2] == 0.0
    assert kernel.cube_hi[19, 19, 19] >= 100.0
    cam = sc.Camera.orbit(vol, azimuth=35, elevation=25, size=(48, 36))
    frame = scene.render(cam, mode="mip")
    background = np.isfinite(frame.value) & (frame.value == 0.0)
    assert background.sum() > 300
    assert frame.cells_tested[background].mean() < 4  # about 40 per ray before


def _rays_through_the_box(vol, cam, frame):
    """``(row, col, o, u, t0, t1)`` of every pixel whose ray crosses the volume's box (world
    origin, direction and interval); the others must have no value."""
    origins, dirs = cam.rays()
    for row in range(cam.height):
        for col in range(cam.width):
            o, u = origins[row, col], dirs[row, col]
            t0, t1 = _box_interval(vol, o, u)
            if not t0 < t1:
                assert np.isnan(frame.value[row, col])
                continue
            yield row, col, o, u, t0, t1


def _plane_samples(vol, o, u, t0, t1, step):
    """Where the ray ``o + t u`` (world) crosses the voxel planes ``m * step`` across its
    dominant index axis inside ``[t0, t1]``, with the two ends: the slices method's samples."""
    spacing, origin = np.asarray(vol.spacing), np.asarray(vol.origin)
    d = u / spacing
    a = int(np.argmax(np.abs(d)))
    pa = [(o[a] + t * u[a] - origin[a]) / spacing[a] for t in (t0, t1)]
    planes = step * np.arange(np.ceil(min(pa) / step), np.floor(max(pa) / step) + 1)
    ts = (planes * spacing[a] + origin[a] - o[a]) / u[a]
    return np.concatenate([[t0], np.sort(ts[(ts > t0) & (ts < t1)]), [t1]])


@pytest.mark.parametrize("kind", ["mip", "minip"])
@pytest.mark.parametrize("step", [1.0, 2.0, 1.5])
@pytest.mark.parametrize("view", [(30.0, 15.0), (100.0, 20.0), (20.0, 75.0)])
def test_slices_projection_is_the_extremum_of_the_samples_on_voxel_planes(kind, step, view):
    """``method="slices"`` takes the model's values where the ray crosses every ``step``-th
    plane of voxels across its dominant axis, and at its entry and exit. Reference: the numpy
    trilinear at those points, computed from the world ray (planes from the volume's origin
    and anisotropic spacing), its extremum per ray. The three views make x, y and z the
    dominant axis (the first has rays of both x and y, as perspective turns them); step 1.5
    puts every other plane between voxels (the model's full value there)."""
    n = 24
    rng = np.random.default_rng(5)
    data = rng.random((n, n + 4, n - 3)).astype(np.float32)
    vol = sc.Volume(data, spacing=(0.5, 0.4, 0.6), origin=(1.0, -2.0, 0.5))
    azimuth, elevation = view
    cam = sc.Camera.orbit(vol, azimuth=azimuth, elevation=elevation, size=(30, 24))
    frame = sc.Scene(vol).render(cam, mode=kind, method="slices", step=step)
    sign = 1.0 if kind == "mip" else -1.0
    checked = 0
    for row, col, o, u, t0, t1 in _rays_through_the_box(vol, cam, frame):
        ts = _plane_samples(vol, o, u, t0, t1, step)
        values = sign * _ray_profile(vol, o, u, t0, t1)(ts)
        got = sign * frame.value[row, col]
        assert got == pytest.approx(values.max(), abs=1e-6), (row, col)
        checked += 1
    assert checked > 200
    # Sampled along the ray at the same step, the samples differ: so do the values somewhere.
    other = sc.Scene(vol).render(cam, mode=kind, method="sampled", step=step)
    seen = np.isfinite(frame.value)
    assert np.abs(other.value[seen] - frame.value[seen]).max() > 1e-3


@pytest.mark.parametrize("model", ["s31"])
def test_slices_projection_of_the_smooth_models_lies_below_the_exact_one(model):
    """On the models without a plane read of their own, the slices method takes their
    ``value_at`` at the plane crossings: every value one the ray meets, so never above the
    exact projection (to rounding), and close below it at a step of one voxel. (s31 only: each
    model's sampled MIP kernel takes half a minute to compile; the default plane read is
    checked for bspline3 too in ``test_dvr_ray.py``.)"""
    vol = sc.demo("marschner-lobb", size=24)
    scene = sc.Scene(vol, model=model)
    cam = sc.Camera.orbit(vol, azimuth=35.0, elevation=25.0, size=(32, 24))
    exact = scene.render(cam, mode="mip").value
    slices = scene.render(cam, mode="mip", method="slices", step=1.0).value
    seen = np.isfinite(exact)
    np.testing.assert_array_equal(np.isfinite(slices), seen)
    lo, hi = vol.value_range
    gap = (exact[seen] - slices[seen]) / (hi - lo)
    assert gap.min() >= -1e-9
    assert 0.0 < gap.mean() < 0.02


@pytest.mark.parametrize("options", [{"iso": 0.5}, {"mode": "dvr"}])
def test_slices_is_refused_outside_mip_with_a_clear_message(options):
    vol = sc.Volume(np.zeros((8, 8, 8), np.float32))
    cam = sc.Camera.orbit(vol, size=(8, 8))
    with pytest.raises(sc.ParameterError, match="slices is for mip and minip, not"):
        sc.Scene(vol).render(cam, method="slices", **options)


def test_slices_views_have_each_axis_dominant():
    """The three views of the slices test above make x, y and z the dominant axis in turn."""
    vol = sc.Volume(np.zeros((24, 28, 21), np.float32), spacing=(0.5, 0.4, 0.6))
    seen = []
    for azimuth, elevation in [(30.0, 15.0), (100.0, 20.0), (20.0, 75.0)]:
        cam = sc.Camera.orbit(vol, azimuth=azimuth, elevation=elevation, size=(30, 24))
        _, dirs = cam.rays()
        seen.append(int(np.argmax(np.abs(dirs[12, 15] / np.asarray(vol.spacing)))))
    assert sorted(seen) == [0, 1, 2]


@pytest.mark.parametrize("kind", ["mip", "minip"])
@pytest.mark.parametrize("step", [0.7, 2.0, 3.0])
def test_sampled_projection_is_the_extremum_of_the_trilinear_samples(kind, step):
    """The sampled method's values are those of the fixed-step loop's sample positions: the ray's
    entry into the volume's box, every ``step`` voxels from there, and its exit. Reference: the
    numpy trilinear interpolant at those positions, every sample taken (no leaping), its
    extremum per ray. The volume is dim noise with one bright (dark, for minIP) ball, so the
    loop leaps blocks that cannot beat the running value, and the answer must not change."""
    n = 40
    rng = np.random.default_rng(11)
    data = 0.2 * rng.random((n, n, n))
    x = np.arange(n) - 25.0
    ball = np.exp(-(x[:, None, None] ** 2 + (x[None, :, None] + 6.0) ** 2
                    + x[None, None, :] ** 2) / 20.0)
    data = (data + ball if kind == "mip" else 1.0 - data - ball).astype(np.float32)
    vol = sc.Volume(data, spacing=(0.5, 0.5, 0.5), origin=(1.0, -2.0, 0.5))
    cam = sc.Camera.orbit(vol, azimuth=30.0, elevation=15.0, size=(40, 30))
    frame = sc.Scene(vol).render(cam, mode=kind, method="sampled", step=step)
    sign = 1.0 if kind == "mip" else -1.0
    dt = step * 0.5  # voxels to world units along a unit direction (isotropic spacing)
    checked = 0
    for row, col, o, u, t0, t1 in _rays_through_the_box(vol, cam, frame):
        ts = np.concatenate([[t0], t0 + dt * np.arange(1, int((t1 - t0) / dt) + 2), [t1]])
        ts = np.append(ts[ts < t1], t1)
        values = sign * _ray_profile(vol, o, u, t0, t1)(ts)
        got = sign * frame.value[row, col]
        assert got == pytest.approx(values.max(), abs=1e-6)
        # The depth is where the value was taken.
        assert sign * _ray_profile(vol, o, u, t0, t1)(frame.depth[row, col])[0] == \
            pytest.approx(got, abs=1e-6)
        checked += 1
    assert checked > 400
    # Blocks that cannot beat the running value were leapt.
    assert frame.blocks_skipped.sum() > 0


def _shortfall(exact, frame, kind, window):
    """How far each pixel of ``frame`` lies below ``exact`` (above, for minIP), as a fraction
    of the window's width."""
    sign = 1.0 if kind == "mip" else -1.0
    return sign * (exact.value - frame.value) / (window[1] - window[0])


@pytest.mark.parametrize(("model", "kind"), [("trilinear", "mip"), ("trilinear", "minip"),
                                              ("s31", "mip"), ("bspline3", "minip")])
@pytest.mark.parametrize("volume", ["smooth", "noise", "plateaus"])
@pytest.mark.parametrize("tolerance", [1 / 255, 0.05])
def test_a_tolerance_keeps_every_pixel_within_it_of_the_exact_projection(model, kind, volume,
                                                                          tolerance):
    """``tolerance=e`` may leave a pixel at most ``e`` (of the window) below the exact
    projection, never above it, and misses stay misses; it must really leave cells out and
    change some pixel (``test_a_tolerance_twice_as_wide_breaks_the_bound`` shows that this
    check catches a rule that leaves out too much)."""
    vol = {"smooth": lambda: sc.demo("marschner-lobb", size=40),
           "noise": lambda: sc.demo("noise", size=24),
           "plateaus": lambda: _quantized_marschner_lobb(40)}[volume]()
    scene = sc.Scene(vol, model=model)
    cam = sc.Camera.orbit(vol, azimuth=35, elevation=25, size=(48, 36))
    # The window the tolerances here were chosen for: the voxels' 0.1st-99.9th percentiles (the
    # automatic window of the projections is narrower for minIP of these volumes, and 1/255 of
    # it leaves nothing out there).
    window = tuple(float(v) for v in np.percentile(sample_values(vol), (0.1, 99.9)))
    exact = scene.render(cam, mode=kind, window=window)
    fast = scene.render(cam, mode=kind, tolerance=tolerance, window=window)
    window = exact.stats["window"]
    assert fast.stats["tolerance"] == tolerance and fast.stats["window"] == window
    hit = np.isfinite(exact.value)
    np.testing.assert_array_equal(np.isfinite(fast.value), hit)
    assert hit.sum() > 500
    short = _shortfall(exact, fast, kind, window)[hit]
    assert short.min() >= -1e-9  # a value the ray meets: never beyond the exact one
    assert short.max() <= tolerance * (1 + 1e-9)
    assert short.max() > 0.0
    assert fast.cells_tested[hit].sum() < exact.cells_tested[hit].sum()


def test_a_tolerance_twice_as_wide_breaks_the_bound():
    """The bound is used to its edge (pixels fall nearly the whole tolerance short), so a rule
    that left out cells by twice the tolerance would break it: the check above can fail."""
    vol = sc.demo("marschner-lobb", size=40)
    cam = sc.Camera.orbit(vol, azimuth=35, elevation=25, size=(48, 36))
    tolerance = 0.05
    exact = sc.Scene(vol).render(cam, mode="mip")
    window = exact.stats["window"]
    fast = sc.Scene(vol).render(cam, mode="mip", tolerance=tolerance)
    hit = np.isfinite(exact.value)
    assert _shortfall(exact, fast, "mip", window)[hit].max() > 0.8 * tolerance
    original = mip_module.Mip.__init__

    def init(self, *args, **kwargs):
        original(self, *args, **kwargs)
        self.params = self.params._replace(tolerance=2.0 * self.params.tolerance)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(mip_module.Mip, "__init__", init)
        wide = sc.Scene(vol).render(cam, mode="mip", tolerance=tolerance)
    assert _shortfall(exact, wide, "mip", window)[hit].max() > tolerance * (1 + 1e-9)


@pytest.mark.parametrize("kind", ["mip", "minip"])
def test_a_tolerant_projection_is_the_fields_value_at_its_depth(setup, kind):
    """The value reported with a tolerance is the trilinear field's (the independent reference's)
    at the depth reported: the value of a point the ray meets, not a bound."""
    vol, scene, cam = setup
    frame = scene.render(cam, mode=kind, tolerance=0.05)
    exact = scene.render(cam, mode=kind)
    origins, dirs = cam.rays()
    hit = np.isfinite(frame.value)
    assert hit.sum() > 100
    rows, cols = np.nonzero(hit)
    for row, col in zip(rows, cols, strict=True):
        f = _ray_profile(vol, origins[row, col], dirs[row, col], 0.0, 0.0)
        assert f(frame.depth[row, col])[0] == pytest.approx(frame.value[row, col], abs=1e-9)
    assert np.any(frame.value[hit] != exact.value[hit])


def test_a_tolerance_holds_brick_by_brick():
    """Bricks traced into fresh states and merged (the distributed renderer's compositing) keep
    the bound: each brick's part is within the tolerance of its own exact part."""
    from splinecast.render.segment import (
        brick_grid,
        combine_states,
        counters,
        finish_state,
        new_state,
        trace_segment,
    )

    vol = sc.demo("marschner-lobb", size=33)
    scene = sc.Scene(vol)
    cam = sc.Camera.orbit(vol, azimuth=35, elevation=25, size=(40, 30))
    tolerance = 0.05
    setup_ = mip_module.Mip("mip", value_range=vol.value_range, tolerance=tolerance)
    state = None
    for lo in ((0, 0, 0), (16, 0, 0), (0, 16, 0), (16, 16, 0), (0, 0, 16), (16, 0, 16),
               (0, 16, 16), (16, 16, 16)):
        hi = tuple(min(a + 16, n) for a, n in zip(lo, scene.grid.n_cells, strict=True))
        part = new_state(setup_, cam)
        trace_segment(brick_grid(scene.model, lo, hi), setup_, cam, part,
                      counters(cam.height, cam.width))
        state = part if state is None else combine_states(setup_, state, part)
    value = finish_state(setup_, state, cam)[0]
    exact = scene.render(cam, mode="mip", window=vol.value_range)
    hit = np.isfinite(exact.value)
    short = (exact.value - value)[hit] / (vol.value_range[1] - vol.value_range[0])
    assert short.min() >= -1e-9 and short.max() <= tolerance * (1 + 1e-9)
    assert short.max() > 0.1 * tolerance


@pytest.mark.parametrize(("options", "needle"), [
    ({"mode": "mip", "tolerance": -0.1}, "tolerance must be a fraction"),
    ({"mode": "mip", "tolerance": float("nan")}, "tolerance must be a fraction"),
    ({"mode": "mip", "tolerance": 2.0}, "tolerance must be a fraction"),
    ({"mode": "mip", "tolerance": "a"}, "tolerance must be a number"),
    ({"mode": "mip", "method": "slices", "step": 2.0, "tolerance": 0.01}, "no bound"),
    ({"mode": "minip", "method": "sampled", "step": 1.0, "tolerance": 0.01}, "no bound"),
    ({"iso": 0.5, "tolerance": 0.01}, "tolerance is for mode='mip'"),
    ({"mode": "dvr", "tolerance": 0.01}, "tolerance is for mode='mip'"),
])
def test_a_bad_tolerance_is_refused_with_a_clear_message(setup, options, needle):
    vol, scene, cam = setup
    with pytest.raises(sc.ParameterError, match=needle):
        scene.render(cam, **options)
