"""Rendering spline-wavelet stores: ``Scene(store, lod=ε)``.

References: the in-memory ``bspline<d>`` model render of the source voxels (a second code path:
one grid, no wavelets, no bricks) and an analytic sphere (which pixels must hit, where detail may
be needed).
"""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

import splinecast as sc
from splinecast.cli import main

pytest.importorskip("zarr")

N = 32
CENTRE = np.array([15.3, 16.1, 14.7])
RADIUS = 9.0
SIZE = (64, 48)


def _sphere(dtype, n=N, centre=CENTRE, radius=RADIUS):
    """Signed distance to a sphere, in voxels (negative inside)."""
    grid = np.stack(np.meshgrid(*[np.arange(n, dtype=np.float64)] * 3, indexing="ij"), -1)
    return (np.linalg.norm(grid - centre, axis=-1) - radius).astype(dtype)


@pytest.fixture(scope="module", params=(1, 2, 3))
def case(request, tmp_path_factory):
    degree = request.param
    dtype = np.float64 if degree != 2 else np.float32
    vol = sc.Volume(_sphere(dtype), metadata={"inside": "low"})
    path = tmp_path_factory.mktemp("w") / f"s{degree}.zarr"
    sc.build_pyramid(vol, path, kind="wavelet", degree=degree, chunk=4, progress=False)
    return degree, vol, sc.read(path)


def _camera(vol):
    return sc.Camera.orbit(vol, azimuth=35, elevation=25, size=SIZE, fit="box", zoom=2.5)


def test_epsilon_zero_renders_the_in_memory_bspline_model_in_every_mode(case):
    degree, vol, store = case
    camera = _camera(vol)
    ref = sc.Scene(vol, model=f"bspline{degree}")
    scene = sc.Scene(store, lod=0.0)
    assert scene.model.name == f"bspline{degree}"
    exact = vol.dtype == np.float64  # float32 stores hold rounded coefficients
    depth_tol = 1e-9 if exact else 1e-4
    # A wavelet scene does not antialias by default; the in-memory scene does. The model's own
    # normals: the reconstruction's gradient is what must be the same.
    a = ref.render(camera, iso=0.0, samples=1, normals="exact")
    b = scene.render(camera, iso=0.0, normals="exact")
    hit = np.isfinite(a.depth)
    assert hit.sum() > 300
    np.testing.assert_array_equal(hit, np.isfinite(b.depth))
    assert np.abs(a.depth[hit] - b.depth[hit]).max() < depth_tol  # spacing 1: voxels
    np.testing.assert_allclose(a.normal[hit], b.normal[hit], atol=1e-6 if exact else 1e-3)
    isos = [-3.0, 1.5]
    a = ref.render(camera, iso=isos, opacity=[0.5, 0.7], samples=1, normals="exact")
    b = scene.render(camera, iso=isos, opacity=[0.5, 0.7], normals="exact")
    np.testing.assert_allclose(a.rgba, b.rgba, atol=1e-6 if exact else 2e-3)
    lo, hi = vol.value_range
    for mode in ("mip", "minip"):
        a = ref.render(camera, mode=mode, window=(lo, hi))
        b = scene.render(camera, mode=mode, window=(lo, hi))
        np.testing.assert_allclose(a.value, b.value, atol=1e-9 if exact else 1e-4)
        assert b.stats["chunk_share"] == 1.0  # no isovalue: ε = 0 refines everything
    tf = sc.TransferFunction([(-4.0, 0.0), (-1.0, 0.6), (2.0, 0.0)], domain=(lo, hi))
    # Segments cut per ray piece meet the same pieces brick by brick as through the whole
    # volume; the default fixed step cuts a segment in two at each brick face (second order).
    pieces = sc.DVRSettings(sampling="pieces", step=1.0, termination=1.0 - 2.0**-10)
    a = ref.render(camera, mode="dvr", tf=tf, dvr=pieces)
    b = scene.render(camera, mode="dvr", tf=tf, dvr=pieces)
    np.testing.assert_allclose(a.rgba, b.rgba, atol=1e-4 if exact else 3e-3)
    a = ref.render(camera, mode="dvr", tf=tf)
    b = scene.render(camera, mode="dvr", tf=tf)
    np.testing.assert_allclose(a.rgba, b.rgba, atol=2 / 255 if exact else 3e-3 + 2 / 255)


# Largest distance (voxels) from a hit point to the analytic sphere (over the rays passing at
# least 0.03 inside its silhouette), measured per degree at
# ε = 0.005, 0.02, 0.05, 0.1, 0.3, 1.0 (ε is an angle: it picks coarser levels, whose splines
# smooth the distance field more; at ε <= 0.05 the error is the B-spline's own smoothing).
SPHERE_ERROR = {1: (0.0278, 0.0278, 0.0278, 0.0499, 0.2558, 1.1588),
                2: (0.0282, 0.0282, 0.0282, 0.0298, 0.0764, 0.5532),
                3: (0.0372, 0.0372, 0.0372, 0.0376, 0.2219, 0.8530)}
EPSILONS = (0.005, 0.02, 0.05, 0.1, 0.3, 1.0)


def _first_sphere_root(origins, directions, radius):
    """Ray parameter of the first crossing of the analytic sphere (inf for a miss)."""
    oc = origins - CENTRE
    b = np.einsum("...i,...i", oc, directions)
    disc = b * b - (np.einsum("...i,...i", oc, oc) - radius**2)
    return np.where(disc >= 0, -b - np.sqrt(np.maximum(disc, 0.0)), np.inf)


def test_isosurface_of_a_closed_distance_field_has_no_holes_at_any_epsilon(case):
    """Against the analytic sphere, at every ε: with ``tol`` 1.2x the measured largest distance
    of a hit point to the sphere (``SPHERE_ERROR``), every ray passing more than ``tol`` inside
    the sphere's silhouette hits a front face, at a point within ``tol`` of the sphere, and no
    later than the sphere of radius ``R - tol`` and no earlier than that of ``R + tol`` (a hole
    that shows the far side, or a surface missing in front, fails)."""
    degree, vol, store = case
    camera = _camera(vol)
    scene = sc.Scene(store)
    origins, directions = camera.rays()
    oc = origins - CENTRE
    along = np.einsum("...i,...i", oc, directions)
    passing = np.sqrt(np.maximum(np.einsum("...i,...i", oc, oc) - along**2, 0.0))
    shares = []
    for eps, measured in zip(EPSILONS, SPHERE_ERROR[degree], strict=True):
        tol = 1.2 * measured
        inner = passing < RADIUS - tol
        assert inner.sum() > 600
        frame = scene.render(camera, iso=0.0, lod=eps)
        where = f"degree {degree}, ε={eps}"
        assert np.all(np.isfinite(frame.depth[inner])), f"holes at {where}"
        assert np.all(frame.face[inner] == 1), f"back faces at {where}"
        radial = np.abs(np.linalg.norm(frame.position[inner] - CENTRE, axis=-1) - RADIUS)
        assert radial.max() <= tol, (where, radial.max())
        earliest = _first_sphere_root(origins, directions, RADIUS + tol)[inner]
        latest = _first_sphere_root(origins, directions, RADIUS - tol)[inner]
        depth = frame.depth[inner]
        assert np.all((depth >= earliest - 1e-9) & (depth <= latest + 1e-9)), where
        shares.append(frame.stats["chunk_share"])
    assert shares == sorted(shares, reverse=True) and shares[-1] < shares[0]


def test_detail_outside_the_isovalue_range_is_never_reconstructed(case, tmp_path):
    degree, vol, _ = case
    # A small sphere in a larger box, so that many chunks lie far from the surface.
    n, centre, radius = 40, np.array([19.3, 20.1, 18.7]), 6.0
    small = sc.Volume(_sphere(vol.dtype, n, centre, radius))
    sc.build_pyramid(small, tmp_path / "s.zarr", kind="wavelet", degree=degree, chunk=4,
                     progress=False)
    store = sc.read(tmp_path / "s.zarr")
    scene = sc.Scene(store, lod=0.0)
    camera = sc.Camera.orbit(small, azimuth=35, elevation=25, size=(32, 24), fit="box")
    frame = scene.render(camera, iso=0.0)
    lay = store.layout
    assert sum(scene.reconstructor.update(scene.selection).computed) == 0  # all reused
    level0 = lay.chunks(0)
    assert 0 < frame.stats["detail_owners"] < sum(int(np.prod(lay.chunks(j)))
                                                  for j in range(lay.levels))
    # Which level-0 chunks may own details that entered a brick: only those whose 3x3x3
    # neighbourhood or its parents' regions (two chunks beyond the chunk), widened by the
    # level-1 support (4 voxels) and 6 voxels of slack, come near the surface (analytic).
    owners0 = scene.reconstructor.update(_fresh_selection(scene)).detail_owners[0]
    reach = 2 * lay.chunk + 10
    excluded = 0
    for idx in np.ndindex(*level0):
        lo = np.array([lay.region(0, a, idx[a])[0] for a in range(3)])
        hi = np.array([lay.region(0, a, idx[a])[1] for a in range(3)])
        d_min = np.linalg.norm(np.clip(centre, lo, hi) - centre)
        corners = np.array([[(lo, hi)[(b >> a) & 1][a] for a in range(3)] for b in range(8)])
        d_max = np.linalg.norm(corners - centre, axis=1).max()
        if not d_min - reach <= radius <= d_max + reach:
            excluded += 1
            assert not owners0[idx], idx
    assert excluded > 30  # the check is not empty
    assert owners0.sum() < np.prod(level0) - excluded


def _fresh_selection(scene):
    """The last frame's selection, with every brick forgotten (so all are computed again)."""
    scene.reconstructor.clear()
    return scene.selection


def test_user_mistakes_name_the_parameter(case, tmp_path, capsys):
    degree, vol, store = case
    other = "trilinear" if degree != 1 else "bspline3"
    with pytest.raises(sc.ParameterError, match="model"):
        sc.Scene(store, model=other)
    with pytest.raises(sc.ParameterError, match="prefilter"):
        sc.Scene(store, prefilter=True)
    with pytest.raises(sc.ParameterError, match="lod"):
        sc.Scene(store, lod=-1.0)
    if degree != 3:
        return
    out = tmp_path / "w.png"
    argv = ["render", str(store.path), "--iso", "0", "--size", "32x24", "--quiet"]
    assert main([*argv, "--lod", "0.05", "-o", str(out)]) == 0 and out.is_file()
    assert main([*argv, "--model", "trilinear", "-o", str(out)]) == 2
    assert "model" in capsys.readouterr().err
    # A budget bounds the bricks and details kept between frames; the pixels stay the same.
    small = tmp_path / "small.png"
    assert main([*argv, "--lod", "0.05", "--budget", "64KiB", "-o", str(small)]) == 0
    np.testing.assert_array_equal(np.asarray(Image.open(small)), np.asarray(Image.open(out)))
    assert main([*argv, "--budget", "lots", "-o", str(out)]) == 2
    assert "--budget" in capsys.readouterr().err
    assert main([*argv, "--cut", "error", "-o", str(out)]) == 2
    assert "--cut" in capsys.readouterr().err


def test_every_kind_of_scene_works_in_a_with_block(case):
    """``with sc.Scene(...) as scene`` for an in-memory volume and a wavelet store too, as for a
    brick pyramid (whose scene has a loader thread to stop): the same frame either way."""
    degree, vol, store = case
    camera = _camera(vol)
    for source, options in ((vol, {"model": f"bspline{degree}"}), (store, {"lod": 0.0})):
        plain = sc.Scene(source, **options).render(camera, iso=0.0)
        with sc.Scene(source, **options) as scene:
            framed = scene.render(camera, iso=0.0)
        np.testing.assert_array_equal(plain.depth, framed.depth)


def test_frames_of_one_scene_equal_fresh_scenes_through_steady_moved_and_evicted_views(case):
    """One scene's frames reuse the last frame's pieces and launch when the same bricks are
    drawn and none was rewritten; every frame of a sequence (the same view again, a moved one,
    back, a new isovalue, each with and without a budget that evicts bricks between frames)
    equals a fresh scene's render of that view (reference: no state carried between frames)."""
    degree, vol, store = case
    near = _camera(vol)
    far = sc.Camera.orbit(vol, azimuth=110, elevation=-30, size=SIZE, fit="box", zoom=2.5)
    steps = [(near, 0.0), (near, 0.0), (far, 0.0), (near, 0.0), (near, 0.0), (near, 0.4),
             (near, 0.4)]
    fresh = {}
    computed = {}
    for budget in (None, "24KiB"):
        scene = sc.Scene(store, lod=0.08, budget=budget)
        reused, computed[budget] = [], []
        for camera, iso in steps:
            frame = scene.render(camera, iso=iso)
            key = (camera is near, iso)
            if key not in fresh:
                fresh[key] = sc.Scene(store, lod=0.08).render(camera, iso=iso)
            np.testing.assert_array_equal(frame.depth, fresh[key].depth)
            np.testing.assert_array_equal(frame.rgba, fresh[key].rgba)
            reused.append(frame.stats["launch_reused"])
            computed[budget].append(frame.stats["bricks_computed"])
        # The second frame of each repeated view is steady; every first view is not.
        assert reused[1] and reused[4] and reused[6]
        assert not (reused[0] or reused[2] or reused[3] or reused[5])
        # The new isovalue draws the same bricks but rewrites some (their active details
        # change): the list must not be reused then.
        assert computed[budget][5] > 0
    # The budget did evict: back at the first view, more bricks are computed again.
    assert computed["24KiB"][3] > computed[None][3]
