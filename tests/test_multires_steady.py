"""A view that stays the same: the loader goes quiet, and the cut, its pieces and the launch are
reused without changing the image.

References: the loader's own counters (a read-ahead that evicted itself kept reading the same
bricks every frame), and images of a fresh scene that selects, resolves and plans everything
again (a stale reused cut or launch, say after the isovalue changed, would differ from it).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("zarr", reason="the multires extra (zarr) is not installed")
pytest.importorskip("dask", reason="the multires extra (dask) is not installed")

import splinecast as sc  # noqa: E402
from splinecast.multires.relevance import ValueFilter  # noqa: E402
from splinecast.multires.stream import BrickStream  # noqa: E402

RADIUS = 17.0


@pytest.fixture(scope="module")
def sphere(tmp_path_factory) -> Path:
    """A 53 x 47 x 41 distance field of a sphere as a pyramid of 8^3 bricks."""
    shape = (53, 47, 41)
    x, y, z = np.meshgrid(*(np.arange(n, dtype=np.float32) for n in shape), indexing="ij")
    data = np.sqrt((x - 26) ** 2 + (y - 23) ** 2 + (z - 20) ** 2).astype(np.float32)
    path = tmp_path_factory.mktemp("steady") / "sphere.zarr"
    sc.build_pyramid(sc.Volume(data), path, brick=8, shard=16, progress=False)
    return path


def _camera(mv, azimuth: float = 30.0) -> sc.Camera:
    return sc.Camera.orbit(mv, azimuth=azimuth, elevation=20, size=(96, 72), zoom=2.5)


@pytest.mark.parametrize("budget", ["96KiB", "160KiB", "512KiB"])
def test_a_steady_view_completes_and_stops_reading_once_its_read_ahead_is_resident(sphere,
                                                                                  budget):
    """Budgets where the cut leaves room for only part of the read-ahead, and where the cut
    with every ancestor of it did not fit: the view's cut becomes complete, and after a few
    frames of the same view frames read and evict nothing (the loader idle between them)."""
    mv = sc.read(sphere)
    with BrickStream(mv, budget, lod=0.3, loads_per_frame=1000) as stream:
        cache = stream.cache
        cam = _camera(mv)
        counts = []
        for _ in range(12):
            fb = stream.frame(cam, ValueFilter.iso(RADIUS), timeout=10)
            assert cache.settle(timeout=10)
            stats = cache.stats()
            counts.append((stats["loaded"], stats["evicted"]))
        assert fb.complete
        assert fb.cut.prefetch, "the test needs a read-ahead list"
        assert counts[-1] == counts[-5], counts  # nothing read or evicted any more
        assert cache.nbytes <= cache.budget


def test_a_steady_view_reuses_its_cut_and_launch_and_draws_the_same_image(sphere):
    mv = sc.read(sphere)
    cam = _camera(mv)
    other = _camera(mv, azimuth=75.0)
    options = {"mode": "iso", "iso": RADIUS, "inside": "low"}
    with sc.Scene(mv, budget="8MiB", lod=0.5) as scene:
        first = scene.render(cam, complete=True, **options)
        scene.stream.cache.settle(timeout=10)
        again = [scene.render(cam, **options) for _ in range(3)]
        assert again[-1].stats["cut_reused"] and again[-1].stats["launch_reused"]
        for frame in again:
            np.testing.assert_array_equal(frame.depth, first.depth)
            np.testing.assert_array_equal(frame.rgba, first.rgba)
        # Another isovalue (another filter and block selection), another view and back, MIP
        # then minIP (the same cut and pieces, another block selection): each is what a fresh
        # scene draws.
        mip = {"mode": "mip", "window": (0.0, 30.0)}
        minip = dict(mip, mode="minip")
        changes = [(cam, dict(options, iso=RADIUS - 4.0)), (other, options), (cam, options),
                   (cam, mip), (cam, minip), (cam, mip)]
        for camera, opts in changes:
            scene.render(camera, complete=True, **opts)
            frame = scene.render(camera, **opts)
            with sc.Scene(mv, budget="8MiB", lod=0.5) as fresh:
                reference = fresh.render(camera, complete=True, **opts)
            assert frame.stats["complete"] and reference.stats["complete"]
            np.testing.assert_array_equal(frame.depth, reference.depth)
            np.testing.assert_array_equal(frame.rgba, reference.rgba)
        assert not scene.render(other, **options).stats["cut_reused"]


def test_the_render_brick_grows_to_64_only_where_level_0_keeps_8_bricks_per_axis():
    from types import SimpleNamespace

    from splinecast.multires.scene import render_brick

    def volume(brick, shape):
        return SimpleNamespace(brick=brick, levels=[SimpleNamespace(shape=shape)])

    assert render_brick(volume(32, (2048, 2048, 2048))) == 64
    assert render_brick(volume(16, (2048, 1024, 1024))) == 64
    assert render_brick(volume(32, (2048, 2048, 511))) == 32  # 511 // 64 < 8
    assert render_brick(volume(8, (53, 47, 41))) == 8
    assert render_brick(volume(128, (4096,) * 3)) == 128  # never smaller than the pyramid's
    assert render_brick(volume(None, (4096,) * 3)) == 64
