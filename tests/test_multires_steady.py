"""A view that stays the same: the loader goes quiet, and the cut, its drawables and the launch are
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
from splinecast.multires.cut.relevance import ValueFilter  # noqa: E402
from splinecast.multires.cut.stream import BrickStream  # noqa: E402

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
    with sc.Scene(mv, budget="8MiB", lod=0.5,
                  whole_level=False) as scene:
        first = scene.render(cam, complete=True, **options)
        scene.stream.cache.settle(timeout=10)
        again = [scene.render(cam, **options) for _ in range(3)]
        assert again[-1].stats["cut_reused"] and again[-1].stats["launch_reused"]
        for frame in again:
            np.testing.assert_array_equal(frame.depth, first.depth)
            np.testing.assert_array_equal(frame.rgba, first.rgba)
        # Another isovalue (another filter and block selection), another view and back, MIP
        # then minIP (the same cut and drawables, another block selection): each is what a fresh
        # scene draws.
        mip = {"mode": "mip", "window": (0.0, 30.0)}
        minip = dict(mip, mode="minip")
        changes = [(cam, dict(options, iso=RADIUS - 4.0)), (other, options), (cam, options),
                   (cam, mip), (cam, minip), (cam, mip)]
        for camera, opts in changes:
            scene.render(camera, complete=True, **opts)
            frame = scene.render(camera, **opts)
            with sc.Scene(mv, budget="8MiB", lod=0.5, whole_level=False) as fresh:
                reference = fresh.render(camera, complete=True, **opts)
            assert frame.stats["complete"] and reference.stats["complete"]
            np.testing.assert_array_equal(frame.depth, reference.depth)
            np.testing.assert_array_equal(frame.rgba, reference.rgba)
        assert not scene.render(other, **options).stats["cut_reused"]


def test_the_render_brick_grows_to_64_only_where_level_0_keeps_8_bricks_per_axis():
    from types import SimpleNamespace

    from splinecast.multires.scenes.multiscale import render_brick

    def volume(brick, shape):
        return SimpleNamespace(brick=brick, levels=[SimpleNamespace(shape=shape)])

    assert render_brick(volume(32, (2048, 2048, 2048))) == 64
    assert render_brick(volume(16, (2048, 1024, 1024))) == 64
    assert render_brick(volume(32, (2048, 2048, 511))) == 32  # 511 // 64 < 8
    assert render_brick(volume(8, (53, 47, 41))) == 8
    assert render_brick(volume(128, (4096,) * 3)) == 128  # never smaller than the pyramid's
    assert render_brick(volume(None, (4096,) * 3)) == 64


@pytest.mark.parametrize("model", ["trilinear", "bspline3"])
def test_bricks_drawn_from_one_ancestor_are_one_piece_that_draws_the_coarse_level(
        tmp_path, model):
    """Before any brick is read, the whole cut is drawn from the coarsest level. Its bricks
    become one drawable per coarsest brick over that brick's box, so the frame is the in-memory
    render of the coarsest level (reference: :class:`splinecast.Scene` of that level's voxels;
    a 33^3 volume, whose coarse levels cover level 0's domain exactly)."""
    n = 33
    x, y, z = np.meshgrid(*(np.arange(n, dtype=np.float64),) * 3, indexing="ij")
    data = np.sqrt((x - 15.3) ** 2 + (y - 16.2) ** 2 + (z - 17.1) ** 2).astype(np.float32)
    path = tmp_path / "ball.zarr"
    sc.build_pyramid(sc.Volume(data, spacing=(0.5, 0.5, 0.5)), path, brick=8, shard=16,
                     progress=False)
    mv = sc.read(path)
    cam = sc.Camera.orbit(mv, azimuth=35, elevation=25, size=(64, 48), zoom=1.4)
    with sc.Scene(mv, model=model, budget="8MiB", lod=0.3, whole_level=False) as scene:
        scene.stream.cache.close()  # nothing but the pinned coarsest level, ever
        frame = scene.render(cam, iso=11.0, inside="low", wait=False)
        tree = scene.stream.octree
        roots = len(tree.roots())
    coarse = mv.level(tree.coarsest)
    assert frame.stats["substituted"] == frame.stats["cut_bricks"] > roots
    assert frame.stats["drawables"] <= roots
    reference = sc.Scene(coarse.to_volume(max_bytes=2**30), model=model).render(
        cam, iso=11.0, inside="low")
    hit = np.isfinite(reference.depth)
    assert hit.sum() > 200
    np.testing.assert_array_equal(np.isfinite(frame.depth), hit)
    np.testing.assert_allclose(frame.depth[hit], reference.depth[hit], rtol=0, atol=1e-9)


def test_merged_nodes_are_the_coarsest_whose_cut_bricks_share_the_drawn_ancestor(sphere):
    """Random residency over a cut of mixed levels: each substituted brick's node is an
    ancestor-or-self at or below the brick drawn, every brick of the cut inside the node is
    drawn from that brick, and the node's parent (where still at or below it) has one that is
    not (brute force over the cut's boxes)."""
    from types import SimpleNamespace

    from splinecast.multires.cut.lod import select_cut
    from splinecast.multires.cut.octree import BrickOctree
    from splinecast.multires.scenes.multiscale import _merged_nodes

    mv = sc.read(sphere)
    tree = BrickOctree(mv)
    cut = select_cut(tree, _camera(mv), lod=0.3, budget=150_000,
                     value_filter=ValueFilter.iso(RADIUS))
    keys = [tuple(int(v) for v in cut.keys[n]) for n in range(len(cut))]
    assert len({k[0] for k in keys}) > 1
    rng = np.random.default_rng(3)
    kinds = set()
    for trial in range(6):
        resident = {tuple(k) for k in keys if rng.random() < 0.3 * (trial % 3)}
        for key in keys:
            for up in tree.ancestors(key):
                if rng.random() < 0.3 or up[0] == tree.coarsest:
                    resident.add(up)
        items = []
        for n, key in enumerate(keys):
            drawn = key if key in resident else next(a for a in tree.ancestors(key)
                                                     if a in resident)
            items.append(SimpleNamespace(n=n, brick=SimpleNamespace(key=drawn),
                                         substituted=drawn != key))
        nodes = _merged_nodes(cut.keys, items, tree)
        assert set(nodes) == {it.n for it in items if it.substituted}

        def inside(node, key):
            lo, hi = tree.box(node[0], np.array([node[1:]]))
            klo, khi = tree.box(key[0], np.array([key[1:]]))
            return bool(np.all(klo[0] >= lo[0]) and np.all(khi[0] <= hi[0])
                        and tree.position(key[0]) <= tree.position(node[0]))

        def all_drawn_from(node, drawn, items=items):
            return all(items[m].brick.key == drawn for m, k in enumerate(keys)
                       if inside(node, k))

        for n, node in nodes.items():
            drawn = items[n].brick.key
            chain = [keys[n], *tree.ancestors(keys[n])]
            assert node in chain and chain.index(node) <= chain.index(drawn)
            assert all_drawn_from(node, drawn)
            if node != drawn:
                assert not all_drawn_from(tree.parent(node), drawn)
            kinds.add("alone" if node == keys[n] else "whole" if node == drawn else "between")
    assert kinds == {"alone", "whole", "between"}  # the cases the test means to cover
