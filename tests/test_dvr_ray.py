"""DVR sampled at a fixed step along the ray (``DVRSettings(sampling="ray")``, the loop of
``splinecast.render.sampler``) and the model's ``value_at`` it reads.

References, independent of the code under test:

- the dense emission-absorption integral of ``test_dvr.py`` (``reference.dense_dvr``), same
  cases and metric (largest error over the visible pixels, premultiplied RGB over black);
- the fixed-grid sampling (``sampling="grid"``, the cell walk the other DVR tests check) at a
  fine step: a second code path converging to the same integral;
- the same sampler with its empty-space leaping switched off (every block flagged visible);
- the whole-volume render for bricks traced chained and combined (``test_bricks.py``);
- the model's ``value_gradient_at`` (monomial form, checked against finite differences and the
  reference interpolant elsewhere) for ``value_at`` (lerp form).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_bricks import _cameras, _render_bricks
from test_dvr import BLACK, GREY, TARGET, _ml_ramp, _noise_ramp
from test_dvr import Case as _Case

import splinecast as sc
from splinecast._jit import jit
from splinecast.models.pieces import value_at, value_gradient_at, value_on_plane
from splinecast.render.dvr import Dvr
from splinecast.render.segment import render_grid


@pytest.fixture(scope="module")
def cases():
    return {"ml-ramp": _ml_ramp(), "noise-ramp": _noise_ramp()}


@pytest.fixture(scope="module")
def scenes(cases):
    return {name: sc.Scene(case.volume) for name, case in cases.items()}


@pytest.mark.parametrize("name", ["ml-ramp", "noise-ramp"])
def test_ray_sampling_meets_1_255_where_the_grid_does(cases, scenes, name):
    """The docs' accuracy statement (step 0.25 within 1/255) holds for the ray sampling."""
    case = cases[name]
    err = case.error(case.render(scenes[name], step=0.25, sampling="ray"))
    assert err <= TARGET - case.ref_err, f"{name}: {err * 255:.3f}/255"


def test_ray_sampling_converges_second_order_to_the_grid_sampling(cases, scenes):
    case, scene = cases["noise-ramp"], scenes["noise-ramp"]
    errs = [case.error(case.render(scene, step=h, table_size=1024, sampling="ray"))
            for h in (1.0, 0.5, 0.25)]
    # Halving the step divides the error by about 4 (3 allows for the transfer function's kinks).
    assert errs[0] / errs[1] > 3 and errs[1] / errs[2] > 3, errs
    fine_grid = case.render(scene, step=0.0625, table_size=1024)
    fine_ray = case.render(scene, step=0.0625, table_size=1024, sampling="ray")
    diff = np.abs(fine_grid.rgba - fine_ray.rgba).max()
    assert diff < 0.1 * TARGET, diff * 255


@pytest.mark.parametrize("model", ["bspline3", "s31"])
def test_every_model_is_sampled_through_its_own_value(model):
    """Models without a ``value_at`` of their own (the value of ``value_gradient_at``): the
    ray sampling at a fine step equals the grid sampling (the cell walk with the model's
    polynomial pieces) at the same step."""
    case = _noise_ramp()
    scene = sc.Scene(case.volume, model=model)
    grid = case.render(scene, step=0.125, table_size=1024)
    ray = case.render(scene, step=0.125, table_size=1024, sampling="ray")
    assert grid.rgba[..., 3].max() > 0.5
    assert np.abs(grid.rgba - ray.rgba).max() < 0.2 * TARGET


def _visible_everywhere(setup: Dvr) -> Dvr:
    """The same DVR with every block flagged visible: the sampler leaps over nothing."""
    flagged = setup.blocks

    def blocks(hierarchy, flags=None):
        return tuple(np.ones_like(a) for a in flagged(hierarchy, flags))

    setup.blocks = blocks
    return setup


def test_leaping_changes_nothing_but_the_work():
    """A transfer function transparent over most of the data: the leaping sampler takes far
    fewer samples and gives the image of the sampler that evaluates every one."""
    vol = sc.demo("marschner-lobb", size=40)
    scene = sc.Scene(vol)
    tf = sc.TransferFunction([(0.0, 0.0), (0.8, 0.0), (0.85, 0.5), (1.0, 0.9)],
                             domain=vol.value_range)
    cam = sc.Camera.orbit(vol, azimuth=30, elevation=20, size=(48, 36))
    settings = sc.DVRSettings(step=0.7, sampling="ray")
    (rgba, *_), leapt = render_grid(scene.grid, Dvr(tf, settings), cam)
    (rgba_all, *_), every = render_grid(scene.grid, _visible_everywhere(Dvr(tf, settings)), cam)
    assert rgba[..., 3].max() > 0.3
    assert leapt[2].sum() > 0 and every[2].sum() == 0
    assert leapt[0].sum() < 0.6 * every[0].sum()  # samples evaluated
    # Segments inside a transparent block read the table at values its visible part is at
    # most one table cell away from: the difference is that cell's interpolation, no more.
    np.testing.assert_allclose(rgba, rgba_all, atol=0.05 * TARGET)


def test_rays_through_transparent_blocks_take_no_value():
    """A sphere seen through empty space: a ray that only crosses blocks the transfer function
    makes transparent goes from block to block without taking a single value, and every ray's
    colour is that of the sampler that evaluates every sample."""
    vol = sc.demo("sphere", size=40)
    scene = sc.Scene(vol)
    lo, hi = vol.value_range
    tf = sc.TransferFunction([(lo, 0.4), (-0.05 * (hi - lo), 0.4), (0.0, 0.0), (hi, 0.0)],
                             domain=(lo, hi))
    cam = sc.Camera.orbit(vol, azimuth=30, elevation=20, size=(40, 30), zoom=1.8)
    settings = sc.DVRSettings(step=1.0, sampling="ray")
    (rgba, *_), (evaluated, _, leapt) = render_grid(scene.grid, Dvr(tf, settings), cam)
    (rgba_all, *_), (every, _, _) = render_grid(scene.grid,
                                                _visible_everywhere(Dvr(tf, settings)), cam)
    crossing = every > 0  # rays that cross the volume's box
    empty = crossing & (evaluated == 0)
    assert crossing.sum() > 0.8 * crossing.size and rgba[..., 3].max() > 0.9
    assert empty.sum() > 0.3 * crossing.sum(), (empty.sum(), crossing.sum())
    # Block to block: most of those rays leave several blocks (a ray leaving the volume from
    # its first block takes one leap).
    assert (leapt[empty] >= 2).mean() > 0.5, np.bincount(leapt[empty])
    np.testing.assert_allclose(rgba, rgba_all, atol=0.05 * TARGET)


def test_samples_are_taken_every_step_from_the_entry():
    """A constant, visible volume seen along an axis: each ray takes ``n / step`` segments
    (the last one cut at the exit) and the colour is the closed-form slab integral."""
    n = 12
    vol = sc.Volume(np.full((n + 1, n + 1, n + 1), 0.5, np.float32))
    scene = sc.Scene(vol)
    tf = sc.TransferFunction([(0.0, 0.2), (1.0, 0.2)], domain=(0.0, 1.0),
                             colormap=[(0.0, 1.0, 1.0, 1.0), (1.0, 1.0, 1.0, 1.0)])
    c = n / 2
    cam = sc.Camera((c, c, 60.0), (c, c, 0.0), up=(0.0, 1.0, 0.0), ortho=True,
                    ortho_height=n - 2.0, size=(6, 6))
    frame = scene.render(cam, mode="dvr", tf=tf, shading=BLACK,
                         dvr=sc.DVRSettings(step=0.7, sampling="ray"))
    assert frame.stats["sampling"] == "ray"
    np.testing.assert_array_equal(frame.cells_tested, int(np.ceil(n / 0.7)))
    # Opacity 0.2 per voxel over n voxels, white emission over black: the premultiplied colour
    # is the ray's opacity, 1 - 0.8^n.
    np.testing.assert_allclose(frame.rgba[..., :3], 1.0 - 0.8**n, atol=1e-4)


@pytest.mark.parametrize("model", ["trilinear", "bspline3"])
def test_ray_sampling_through_bricks_equals_the_whole_volume(model):
    """Bricks traced chained or combined: the same samples (anchored at the ray's entry into the
    volume); a segment crossing a brick face is cut in two there, which changes it by the
    curvature of the field along it only: second order in the step, like the sampling error
    itself (this transfer function's peaks are steep: 1/255 needs a step of about 0.25)."""
    from reference import smooth_noise

    volume = sc.Volume(smooth_noise((20, 19, 21), seed=3, sigma=2.0).astype(np.float32))
    scene = sc.Scene(volume, model=model)
    tf = sc.TransferFunction([(-0.8, 0.0), (-0.2, 0.4), (0.2, 0.0), (0.7, 0.6)],
                             domain=(-3.0, 3.0))
    for step in (0.4, 1.0):
        setup = Dvr(tf, sc.DVRSettings(step=step, sampling="ray"))
        for cam in _cameras(scene.model.shift):
            whole, _ = render_grid(scene.grid, setup, cam)
            assert whole[0][..., 3].max() > 0.5
            for chained in (True, False):
                bricks = _render_bricks(scene, setup, cam, 8, chained)
                what = f"{model} step {step} {'chained' if chained else 'combined'}"
                np.testing.assert_allclose(bricks[0], whole[0], atol=3 * TARGET * step**2,
                                           err_msg=what)


def test_adaptive_step_needs_another_sampling():
    with pytest.raises(sc.ParameterError, match="adaptive"):
        sc.DVRSettings(sampling="ray", adaptive=True)


@jit()
def _values(grid, points):
    out = np.empty((points.shape[0], 2))
    scratch = np.empty(0)
    for n in range(points.shape[0]):
        x, y, z = points[n, 0], points[n, 1], points[n, 2]
        out[n, 0] = value_at(grid, scratch, x, y, z)
        out[n, 1] = value_gradient_at(grid, scratch, x, y, z)[0]
    return out


@pytest.mark.parametrize("dtype", [np.uint8, np.int16, np.float32, np.float64])
def test_trilinear_value_at_equals_value_gradient_at(dtype):
    """Every dtype a reader hands the model, points inside, on the faces and outside (clamped)."""
    rng = np.random.default_rng(7)
    data = rng.integers(0, 250, size=(9, 8, 10)).astype(dtype)
    scene = sc.Scene(sc.Volume(data))
    points = rng.uniform(-1.5, 10.5, size=(400, 3))
    points[:40] = np.round(points[:40])  # on grid planes, and corners
    values = _values(scene.grid.kernel, points)
    assert np.ptp(values[:, 1]) > 100  # the points see the data's range
    np.testing.assert_allclose(values[:, 0], values[:, 1], rtol=1e-12, atol=1e-9)


@jit()
def _plane_values(grid, axis, planes, points):
    out = np.empty((points.shape[0], 2))
    scratch = np.empty(0)
    for n in range(points.shape[0]):
        p, a, b = planes[n], points[n, 0], points[n, 1]
        x, y, z = (p, a, b) if axis == 0 else ((a, p, b) if axis == 1 else (a, b, p))
        out[n, 0] = value_on_plane(grid, scratch, axis, p, a, b)
        out[n, 1] = value_at(grid, scratch, x, y, z)
    return out


@pytest.mark.parametrize("model", ["trilinear", "bspline3"])
@pytest.mark.parametrize("axis", [0, 1, 2])
def test_value_on_a_voxel_plane_is_the_value_at_that_point(model, axis):
    """The slices method's plane reads (the trilinear's bilinear of one slice, 4 voxels; the
    default for other models) give the model's value at the point to the last bit on every
    plane but the last (to rounding there), with in-plane points inside, on cell faces and
    outside (clamped)."""
    rng = np.random.default_rng(3)
    data = rng.integers(0, 250, size=(9, 8, 10)).astype(np.uint8)
    scene = sc.Scene(sc.Volume(data), model=model)
    n = data.shape[axis] - 1
    planes = rng.integers(0, n + 1, size=300).astype(np.float64)
    planes[:2] = (0.0, n)
    points = rng.uniform(-1.5, 10.5, size=(300, 2))
    points[:30] = np.round(points[:30])
    values = _plane_values(scene.grid.kernel, axis, planes, points)
    assert np.ptp(values[:, 1]) > 100
    inner = planes < n
    np.testing.assert_array_equal(values[inner, 0], values[inner, 1])
    # On the last plane value_at interpolates toward it from the cell before (weight 1),
    # which rounds; the plane read is that slice's own bilinear.
    np.testing.assert_allclose(values[~inner, 0], values[~inner, 1], rtol=1e-14)


def _twin_without(hook: str, name: str) -> tuple:
    """A Marschner-Lobb 40^3 grid of the trilinear model and the same grid as a twin grid
    class registered with every trilinear hook but ``hook`` (the model's default then)."""
    from collections import namedtuple

    from splinecast.models import pieces
    from splinecast.models.trilinear import TrilinearGrid

    plain_class = namedtuple(name, TrilinearGrid._fields)
    hooks = {k: v for k, v in pieces.hooks_of(TrilinearGrid).items() if k != hook}
    assert len(hooks) < len(pieces.hooks_of(TrilinearGrid))
    pieces.register(plain_class, **hooks)
    vol = sc.demo("marschner-lobb", size=40)
    grid = sc.Scene(vol).grid
    return vol, grid, grid.with_kernel(plain_class(*grid.kernel))


def _both_twins(vol: sc.Volume, grid, plain, tf: sc.TransferFunction):
    """Renders of ``grid`` and its twin ``plain`` for two cameras and three (step,
    termination) settings: a step that divides the volume and two that do not, no termination
    and an early one. Yields ``((rgba, depth, ...), counts)`` of each."""
    cams = [sc.Camera.orbit(vol, azimuth=30, elevation=20, size=(48, 36)),
            sc.Camera.orbit(vol, azimuth=-70, elevation=50, size=(40, 30), zoom=1.6)]
    for step, termination in ((1.0, 1.0 - 2.0**-10), (0.7, None), (2.5, 0.9)):
        setup = Dvr(tf, sc.DVRSettings(step=step, sampling="ray", termination=termination))
        for cam in cams:
            yield render_grid(grid, setup, cam), render_grid(plain, setup, cam)


def test_taking_values_one_sample_early_changes_nothing():
    """The trilinear model's values are taken one sample early (``look_ahead``): the same
    hooks registered for a twin grid class without it run the plain loop, and the two give
    bit-identical colours and depths, with leaps, early termination and a step that does not
    divide the volume (a ray's last segment cut at its exit)."""
    vol, grid, plain = _twin_without("look_ahead", "TrilinearGridNoLookAhead")
    lo, hi = vol.value_range
    tf = sc.TransferFunction([(lo, 0.0), (lo + 0.45 * (hi - lo), 0.0),
                              (lo + 0.55 * (hi - lo), 0.3), (hi, 0.9)], domain=(lo, hi))
    for ((rgba, depth, *_), counts), ((rgba_p, depth_p, *_), counts_p) in _both_twins(
            vol, grid, plain, tf):
        assert rgba[..., 3].max() > 0.5
        np.testing.assert_array_equal(rgba, rgba_p)
        np.testing.assert_array_equal(depth, depth_p)
        # The early values: more evaluated (a ray that stops leaves one unused), never
        # fewer, and the same segments.
        np.testing.assert_array_equal(counts[1], counts_p[1])
        assert (counts[0] >= counts_p[0]).all() and counts[0].sum() > counts_p[0].sum()


def test_prefetching_voxels_changes_nothing():
    """The trilinear model prefetches the voxels of a sample ahead (``prefetch_at``): the same
    hooks registered for a twin grid class without it (the default, nothing) give
    bit-identical colours, depths and counts, with leaps, early termination and steps that do
    and do not divide the volume (prefetches near and beyond the grid's far faces)."""
    vol, grid, plain = _twin_without("prefetch_at", "TrilinearGridNoPrefetch")
    lo, hi = vol.value_range
    tf = sc.TransferFunction([(lo, 0.0), (lo + 0.2 * (hi - lo), 0.02), (hi, 0.2)],
                             domain=(lo, hi))
    for ((rgba, depth, *_), counts), ((rgba_p, depth_p, *_), counts_p) in _both_twins(
            vol, grid, plain, tf):
        assert rgba[..., 3].max() > 0.5
        np.testing.assert_array_equal(rgba, rgba_p)
        np.testing.assert_array_equal(depth, depth_p)
        for c, c_p in zip(counts, counts_p, strict=True):
            np.testing.assert_array_equal(c, c_p)


def test_clear_ends_are_where_the_opacity_is_zero_to_the_end():
    """Against the opacity sampled densely: zero at every value up to ``below`` and from
    ``above`` on, and not zero just inside each (so neither end could be wider)."""
    for points in ([(0.0, 0.0), (255.0, 0.1)], [(30.0, 0.0), (60.0, 0.02), (255.0, 0.9)],
                   [(0.0, 0.2), (10.0, 0.0), (20.0, 0.0), (30.0, 0.1), (40.0, 0.0)],
                   [(10.0, 0.0), (20.0, 0.0), (30.0, 0.5), (40.0, 0.0), (50.0, 0.0)]):
        tf = sc.TransferFunction(points, (0.0, 255.0))
        below, above = tf.clear_ends()
        values = np.linspace(-100.0, 400.0, 50001)
        alpha = tf.opacity(values)
        if np.isfinite(below):
            assert np.all(alpha[values <= below] == 0.0)
            assert alpha[values > below][0] > 0.0
        else:
            assert alpha[0] > 0.0
        if np.isfinite(above):
            assert np.all(alpha[values >= above] == 0.0)
            assert alpha[values < above][-1] > 0.0
        else:
            assert alpha[-1] > 0.0


def test_a_background_at_the_transparent_end_is_leapt_and_the_image_keeps_its_bound():
    """A ramp starting at 0 over a volume whose background is 0: the background's blocks touch
    the ramp's transparent end only, so the loop leaps them (they were taken sample by sample),
    and the image stays within 1/255 of the dense reference (at the step of the docs'
    accuracy statement, and at the default step)."""
    data = np.zeros((28, 28, 28), np.float32)
    idx = np.indices(data.shape).astype(np.float64)
    r = np.sqrt(((idx - 13.5) ** 2).sum(axis=0))
    inside = r < 9.0
    data[inside] = (2.0 * (1.0 - (r[inside] / 9.0) ** 2) ** 2).astype(np.float32)  # a blob
    vol = sc.Volume(data)
    cam = sc.Camera.orbit(vol, azimuth=30, elevation=20, size=(24, 18))
    case = _Case(vol, cam, [(0.0, 0.0), (2.0, 0.3)], GREY, (0.0, 2.0), ds=0.01)
    scene = sc.Scene(vol)
    frame = case.render(scene, step=0.25, sampling="ray")
    assert frame.blocks_skipped.sum() > 0
    assert case.error(frame) <= TARGET - case.ref_err
    default = scene.render(cam, mode="dvr", tf=case.tf, shading=BLACK)
    assert default.blocks_skipped.sum() > 0
    mean = np.abs(default.rgba[..., :3] - case.ref).mean()
    assert mean <= TARGET, mean * 255


def _ends_transparent_tf(lo: float, hi: float) -> sc.TransferFunction:
    """Transparent below 40% and above 85% of ``[lo, hi]``, visible in between."""
    return sc.TransferFunction([(lo, 0.0), (lo + 0.4 * (hi - lo), 0.0),
                                (lo + 0.6 * (hi - lo), 0.3), (lo + 0.8 * (hi - lo), 0.1),
                                (lo + 0.85 * (hi - lo), 0.0), (hi, 0.0)], domain=(lo, hi))


def test_zero_corners_bound_lookups_of_transparent_entries_only():
    """The bounds below and above which the default DVR skips the table lookup: every
    ``(uf, ub)`` they let through has four corners of opacity 0 in the table the kernel reads
    (corners as the lookup takes them: ``int(u)`` and ``int(u) + 1``, ``int(u)`` at most
    ``n - 2``), checked exhaustively on a quarter-index grid; a transfer function that is
    nowhere transparent has no such bounds, and one transparent everywhere skips all."""
    from splinecast.render.dvr import _zero_corners

    setup = Dvr(_ends_transparent_tf(0.0, 1.0), None)
    table = setup.params.table[0, :, :, 3]
    below, above = setup.params.zero_below, setup.params.zero_above
    n = table.shape[0]
    assert 0.3 * n < below < 0.45 * n and 0.8 * n < above < 0.9 * n, (below, above)
    u = np.concatenate([np.arange(0.0, n - 1.0, 0.25), [n - 1.0]])
    uf, ub = (a.ravel() for a in np.meshgrid(u, u, indexing="ij"))
    skipped = ((uf < below) & (ub < below)) | ((uf >= above) & (ub >= above))
    i0 = np.minimum(uf.astype(np.int64), n - 2)[skipped]
    j0 = np.minimum(ub.astype(np.int64), n - 2)[skipped]
    corners = np.stack([table[i0 + di, j0 + dj] for di in (0, 1) for dj in (0, 1)])
    assert skipped.sum() > 0.1 * skipped.size
    assert (corners == 0.0).all()
    dense = Dvr(sc.TransferFunction([(0.0, 0.1), (1.0, 0.3)], domain=(0.0, 1.0)), None)
    assert dense.params.zero_below <= 0.0 and dense.params.zero_above == math.inf
    assert _zero_corners(np.zeros((8, 8))) == (math.inf, math.inf)


def test_skipping_transparent_lookups_changes_nothing():
    """The default DVR with a transfer function transparent at both ends: the image, depth
    and counts are bit-identical to those of the same settings with the skip switched off
    (bounds that let nothing through, so every segment reads the table), on the
    Marschner-Lobb volume and on integer voxels (a background of zeros)."""
    ml = sc.demo("marschner-lobb", size=40)
    rng = np.random.default_rng(7)
    blocky = (rng.random((36, 30, 33)) * 3).round() * 60
    blocky[:, :, :6] = 0.0
    volumes = [ml, sc.Volume(np.ascontiguousarray(blocky.astype(np.uint8)))]
    for vol in volumes:
        scene = sc.Scene(vol)
        lo, hi = vol.value_range
        tf = _ends_transparent_tf(lo, hi)
        cams = [sc.Camera.orbit(vol, azimuth=30, elevation=20, size=(48, 36)),
                sc.Camera.orbit(vol, azimuth=-70, elevation=50, size=(40, 30), zoom=1.6)]
        for termination in (1.0 - 2.0**-10, None):
            setup = Dvr(tf, sc.DVRSettings(step=1.0, sampling="ray", termination=termination))
            assert setup.params.zero_below > 0.0 and setup.params.zero_above < math.inf
            plain = Dvr(tf, sc.DVRSettings(step=1.0, sampling="ray", termination=termination))
            plain.params = plain.params._replace(zero_below=-math.inf, zero_above=math.inf)
            for cam in cams:
                (rgba, depth, *_), counts = render_grid(scene.grid, setup, cam)
                (rgba_p, depth_p, *_), counts_p = render_grid(scene.grid, plain, cam)
                assert rgba[..., 3].max() > 0.3
                np.testing.assert_array_equal(rgba, rgba_p)
                np.testing.assert_array_equal(depth, depth_p)
                for c, c_p in zip(counts, counts_p, strict=True):
                    np.testing.assert_array_equal(c, c_p)
