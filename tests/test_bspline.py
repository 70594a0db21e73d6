"""B-spline isosurfaces against an independent brute-force reference.

The reference evaluates the tensor-product spline directly with
``scipy.ndimage.map_coordinates(coeffs, x, order=d, mode="mirror", prefilter=False)`` — the
convention documented in :mod:`splinecast.models.bspline` — on the unpadded coefficient array
(the voxels, or scipy's ``spline_filter`` of them for ``prefilter=True``), samples every ray
densely inside the box of voxel centres and refines the first sign change by bisection. It never
touches the per-cell transforms, the composition or the root finders under test.
"""

from __future__ import annotations

import numpy as np
import pytest
from reference import bspline as spline
from scipy import ndimage

import splinecast as sc
from splinecast.accel.minmax import MinMaxHierarchy
from splinecast.models.bspline_ray import _fill_cell, segment_polynomial
from splinecast.roots.bernstein import bernstein_eval, power_eval

ISO = 0.5
SAMPLE_STEP = 0.02  # voxels
DEPTH_TOL = 1e-7  # voxels


@pytest.fixture(scope="module")
def volume():
    return sc.demo("marschner-lobb", size=18)


@pytest.fixture(scope="module")
def camera(volume):
    return sc.Camera.orbit(volume, azimuth=35, elevation=25, size=(36, 28), zoom=1.3)


def coefficient_array(volume, degree, prefilter):
    """The coefficients the model documents: the voxels, or scipy's interpolating filter of
    them computed in float64 and stored at the voxels' precision (float32 for float32)."""
    data = volume.data.astype(np.float64)
    if prefilter:
        stored = np.float32 if volume.dtype == np.float32 else np.float64
        data = ndimage.spline_filter(data, order=degree, mode="mirror").astype(stored)
        data = data.astype(np.float64)
    return data


def reference_depths(volume, camera, coeffs, degree, iso=ISO):
    """First crossing per pixel by dense sampling + bisection (world depth, inf on a miss)."""
    origins, dirs = camera.rays()
    spacing = np.asarray(volume.spacing)
    o = (origins - np.asarray(volume.origin)) / spacing
    d = dirs / spacing
    hi = np.asarray(volume.shape, float) - 1
    with np.errstate(divide="ignore", invalid="ignore"):
        ta = (0 - o) / d
        tb = (hi - o) / d
    t0 = np.maximum(np.nanmax(np.minimum(ta, tb), axis=-1), 0.0)
    t1 = np.nanmin(np.maximum(ta, tb), axis=-1)
    inside = t0 < t1
    speed = np.linalg.norm(d, axis=-1)  # voxels per world unit
    n = int(np.ceil(np.max(np.where(inside, (t1 - t0) * speed, 0)) / SAMPLE_STEP)) + 1
    frac = np.linspace(0.0, 1.0, n)
    ts = t0[..., None] + frac * (t1 - t0)[..., None]
    pts = o[..., None, :] + ts[..., None] * d[..., None, :]
    g = spline(coeffs, degree, pts) - iso
    first_sign = g[..., :1]
    change = (np.sign(g) != np.sign(first_sign)) | (g == 0)
    change[..., 0] = g[..., 0] == 0
    has = change.any(axis=-1) & inside
    idx = np.argmax(change, axis=-1)
    depth = np.full(ts.shape[:-1], np.inf)
    rows, cols = np.nonzero(has)
    k = idx[rows, cols]
    lo = ts[rows, cols, np.maximum(k - 1, 0)]
    hi_t = ts[rows, cols, k]
    glo = g[rows, cols, np.maximum(k - 1, 0)]
    for _ in range(60):
        mid = 0.5 * (lo + hi_t)
        gm = spline(coeffs, degree, o[rows, cols] + mid[:, None] * d[rows, cols]) - iso
        same = (np.sign(gm) == np.sign(glo)) & (gm != 0)
        lo = np.where(same, mid, lo)
        glo = np.where(same, gm, glo)
        hi_t = np.where(same, hi_t, mid)
    depth[rows, cols] = np.where(k == 0, lo, hi_t)
    return depth, speed


CONFIGS = [(1, False), (2, False), (3, False), (2, True), (3, True)]


@pytest.fixture(scope="module")
def renders(volume, camera):
    out = {}
    for degree, prefilter in CONFIGS:
        scene = sc.Scene(volume, model=f"bspline{degree}", prefilter=prefilter)
        # The model's own normals: what the finite differences of the spline check.
        out[degree, prefilter] = scene.render(camera, iso=ISO, normals="exact")
    return out


@pytest.mark.parametrize("degree,prefilter", CONFIGS)
def test_depths_match_brute_force(volume, camera, renders, degree, prefilter):
    frame = renders[degree, prefilter]
    coeffs = coefficient_array(volume, degree, prefilter)
    ref, speed = reference_depths(volume, camera, coeffs, degree)
    got = frame.depth
    assert np.isfinite(ref).sum() > 100  # the surface covers a good part of the image
    origins, dirs = camera.rays()
    # Every reported hit is a true root of the directly evaluated spline, inside the box ...
    hits = np.isfinite(got)
    idx = (origins[hits] + got[hits, None] * dirs[hits] - volume.origin) / volume.spacing
    assert np.all(idx >= -1e-9) and np.all(idx <= np.array(volume.shape) - 1 + 1e-9)
    residual = np.abs(spline(coeffs, degree, idx) - ISO)
    assert residual.max() < 1e-9
    # ... never past the first crossing the reference found ...
    both = hits & np.isfinite(ref)
    assert np.all((got[both] - ref[both]) * speed[both] <= DEPTH_TOL)
    # ... and equal to it except where the renderer found an earlier (true) root that a thin
    # crossing pair hid from the sampling, or a grazing hit the sampling missed entirely.
    with np.errstate(invalid="ignore"):  # inf - inf on common misses
        agree = both & (np.abs(got - ref) * speed <= DEPTH_TOL)
    assert np.count_nonzero(np.isfinite(ref) & ~hits) == 0, "missed a surface the reference hit"
    assert np.count_nonzero(hits & ~agree) <= 0.01 * hits.sum()


def test_normals_match_finite_differences(volume, camera, renders):
    origins, dirs = camera.rays()
    for (degree, prefilter), frame in renders.items():
        coeffs = coefficient_array(volume, degree, prefilter)
        hits = frame.hit
        idx = (frame.position[hits] - volume.origin) / volume.spacing
        h = 1e-5
        grad = np.stack([
            (spline(coeffs, degree, idx + h * e) - spline(coeffs, degree, idx - h * e)) / (2 * h)
            for e in np.eye(3)], axis=-1) / np.asarray(volume.spacing)
        norm = np.linalg.norm(grad, axis=-1)
        ok = (norm > 1e-3) & np.all((idx > 2 * h) & (idx < np.array(volume.shape) - 1 - 2 * h),
                                    axis=-1)
        expected = -grad[ok] / norm[ok, None]  # outward normal, inside = high values
        got = frame.normal[hits][ok].astype(np.float64)
        cos = np.sum(expected * got, axis=-1)
        assert cos.min() > 1 - 1e-6, (degree, prefilter)


def test_bspline1_reproduces_trilinear(volume, camera, renders):
    tri = sc.Scene(volume).render(camera, iso=ISO, normals="exact")
    lin = renders[1, False]
    np.testing.assert_array_equal(tri.hit, lin.hit)
    speed = np.linalg.norm(camera.rays()[1] / np.asarray(volume.spacing), axis=-1)
    both = tri.hit
    # The two renderers solve the same cubic by different routes (monomial expansion + Newton
    # vs Bernstein composition + subdivision): equal within a millionth of a voxel.
    assert np.max(np.abs(tri.depth[both] - lin.depth[both]) * speed[both]) < 1e-5


def test_prefilter_interpolates(volume):
    """The prefiltered spline passes through the voxels, to the voxels' precision: float64
    coefficients for float64 voxels, float32 ones (half the memory, the float32 kernels) for
    float32 voxels."""
    precise = sc.Volume(volume.data.astype(np.float64))
    for vol, atol, dtype in ((precise, 1e-12, np.float64), (volume, 2e-6, np.float32)):
        for degree in (2, 3):
            model = sc.Scene(vol, model=f"bspline{degree}", prefilter=True).model
            assert model.coeffs.dtype == dtype
            ijk = np.argwhere(np.ones(vol.shape, bool))[::7].astype(float)
            np.testing.assert_allclose(model.evaluate(ijk), vol.data[tuple(ijk.astype(int).T)],
                                       atol=atol)


@pytest.mark.parametrize("degree", [1, 2, 3])
def test_composition_equals_direct_evaluation(volume, degree):
    coeffs = coefficient_array(volume, degree, False)
    model = sc.Scene(volume, model=f"bspline{degree}").model
    h = 0.5 if degree % 2 == 0 else 0.0
    rng = np.random.default_rng(degree)
    s = np.linspace(0, 1, 11)
    scale = np.abs(coeffs).max()
    for _ in range(40):
        cell = rng.integers(1, np.array(model.n_cells) - 1)
        a, b = rng.random(3), rng.random(3)
        ref = spline(coeffs, degree, cell + a + s[:, None] * (b - a) - h)
        bern = segment_polynomial(model.coefficients, degree, cell, a, b, "bernstein")
        power = segment_polynomial(model.coefficients, degree, cell, a, b, "power")
        naive = segment_polynomial(model.coefficients, degree, cell, a, b, "naive")
        n = 3 * degree
        for x, r in zip(s, ref, strict=True):
            assert abs(bernstein_eval(bern, n, x) - r) <= 1e-12 * scale
            assert abs(power_eval(power, n, x) - r) <= 1e-12 * scale
            assert abs(power_eval(naive, n, x) - r) <= 1e-12 * scale


@pytest.mark.parametrize("degree", [1, 2, 3])
def test_cell_cache_ranges_bound_the_spline_and_are_tighter(volume, degree):
    """The range the kernels test a cell's segments against (its Bernstein control points,
    :func:`splinecast.models.bspline_ray._fill_cell`) holds every value of the spline in the
    cell, as scipy evaluates it, and lies inside the influence coefficients' range."""
    coeffs = coefficient_array(volume, degree, False)
    model = sc.Scene(volume, model=f"bspline{degree}").model
    grid = model.kernel_grid()
    h = 0.5 if degree % 2 == 0 else 0.0
    rng = np.random.default_rng(10 + degree)
    u = np.stack(np.meshgrid(*[np.linspace(0, 1, 9)] * 3, indexing="ij"), -1).reshape(-1, 3)
    tensor, tmp, bounds = np.empty((4, 4, 4)), np.empty((4, 4, 4)), np.empty(2)
    tighter = 0
    for _ in range(60):
        cell = rng.integers(1, np.array(model.n_cells) - 1)
        _fill_cell(grid.coeffs, degree, grid.power, *(int(c) for c in cell), tensor, tmp, bounds)
        values = spline(coeffs, degree, cell + u - h)
        assert bounds[0] <= values.min() and values.max() <= bounds[1]
        i, j, k = cell
        influence = grid.coeffs[i:i + degree + 1, j:j + degree + 1, k:k + degree + 1]
        assert influence.min() <= bounds[0] and bounds[1] <= influence.max()
        tighter += bounds[1] - bounds[0] < influence.max() - influence.min()
        if degree == 1:  # trilinear: the control points are the corners
            np.testing.assert_allclose(bounds, [influence.min(), influence.max()], rtol=1e-9)
    if degree > 1:
        assert tighter > 30  # the point of the range: most cells get a narrower one


@pytest.mark.parametrize("degree", [2, 3])
def test_block_bounds_are_conservative(volume, degree):
    model = sc.Scene(volume, model=f"bspline{degree}").model
    hier = MinMaxHierarchy(model.coefficients, model.n_cells, model.support)
    coeffs = coefficient_array(volume, degree, False)
    rng = np.random.default_rng(5)
    pts = rng.uniform(0, np.array(volume.shape) - 1, (4000, 3))
    values = spline(coeffs, degree, pts)
    h = 0.5 if degree % 2 == 0 else 0.0
    cells = np.minimum(np.floor(pts + h).astype(int), np.array(model.n_cells) - 1)
    blocks = tuple((cells >> 2).T)
    assert np.all(hier.lows[0][blocks] <= values + 1e-12)
    assert np.all(hier.highs[0][blocks] >= values - 1e-12)


def test_root_finders_and_iso_change(volume, camera, renders):
    coeffs = coefficient_array(volume, 3, False)
    ref, speed = reference_depths(volume, camera, coeffs, 3, iso=0.3)
    scene = sc.Scene(volume, model="bspline3", root_finder="rfbs")
    scene.render(camera, iso=ISO)
    for name in ("rfbs", "sturm"):
        if name != "rfbs":
            scene = sc.Scene(volume, model="bspline3", root_finder=name)
        frame = scene.render(camera, iso=0.3)  # a new isovalue re-classifies the blocks
        both = frame.hit & np.isfinite(ref)
        assert np.count_nonzero(np.isfinite(ref) & ~frame.hit) == 0, name
        close = np.abs(frame.depth[both] - ref[both]) * speed[both] <= DEPTH_TOL
        assert np.count_nonzero(~close) <= 0.01 * both.sum(), name
    # Newton is the baseline without a first-root guarantee: its hits are true roots.
    frame = sc.Scene(volume, model="bspline3", root_finder="newton").render(camera, iso=0.3)
    origins, dirs = camera.rays()
    idx = (origins[frame.hit] + frame.depth[frame.hit, None] * dirs[frame.hit]
           - volume.origin) / volume.spacing
    assert np.abs(spline(coeffs, 3, idx) - 0.3).max() < 1e-9


def test_errors(volume, camera):
    with pytest.raises(sc.ParameterError, match="root_finder"):
        sc.Scene(volume, model="bspline3", root_finder="magic")
    with pytest.raises(sc.ParameterError, match="iterations"):
        sc.Scene(volume, model="bspline2", iterations=0)
    with pytest.raises(sc.ParameterError, match="method"):
        sc.Scene(volume, model="bspline2").render(camera, iso=ISO, method="magic")


def test_cli_render(tmp_path):
    from splinecast.cli import main

    out = tmp_path / "b.png"
    status = main(["render", "demo:sphere?size=12", "--model", "bspline3", "--prefilter",
                   "--root-finder", "rfbs", "--iterations", "30", "--size", "24x16", "--quiet",
                   "-o", str(out)])
    assert status == 0 and out.exists()
    assert main(["render", "demo:sphere?size=12", "--prefilter", "--quiet",
                 "-o", str(tmp_path / "c.png")]) == 2
