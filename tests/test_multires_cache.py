"""Brick octree, level-of-detail cut, brick cache and loader thread, faults.

References are independent of the code under test: brick arrays against the level read whole and
padded by numpy, value ranges against the voxels, projected sizes recomputed from the camera,
budgets against the bytes the cache's arrays keep alive (``held_bytes``: its references walked at
every insertion), faults against damaged copies of a store.
"""

from __future__ import annotations

import math
import shutil
import threading
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
from held_bytes import held_bytes

pytest.importorskip("zarr", reason="the multires extra (zarr) is not installed")
pytest.importorskip("dask", reason="the multires extra (dask) is not installed")

import splinecast as sc  # noqa: E402
from splinecast.multires.cut.lod import select_cut  # noqa: E402
from splinecast.multires.cut.octree import GHOST, BrickOctree  # noqa: E402
from splinecast.multires.cut.relevance import ValueFilter  # noqa: E402
from splinecast.multires.cut.stream import BrickStream  # noqa: E402
from splinecast.multires.store.budget import parse_bytes  # noqa: E402
from splinecast.multires.store.cache import BrickCache, BrickUnavailableWarning  # noqa: E402
from splinecast.multires.store.pyramid import build_pyramid  # noqa: E402

B = 8
RADIUS = 17.0


@pytest.fixture(scope="module")
def sphere(tmp_path_factory) -> tuple[np.ndarray, Path]:
    """A 53 x 47 x 41 distance field (not powers of two) of a sphere, as a pyramid."""
    shape = (53, 47, 41)
    x, y, z = np.meshgrid(*(np.arange(n, dtype=np.float32) for n in shape), indexing="ij")
    data = np.sqrt((x - 26) ** 2 + (y - 23) ** 2 + (z - 20) ** 2).astype(np.float32)
    path = tmp_path_factory.mktemp("sphere") / "sphere.zarr"
    build_pyramid(sc.Volume(data, spacing=(1.0, 1.0, 1.0)), path, brick=B, shard=16,
                  progress=False)
    return data, path


def _boxes_volume(lo: np.ndarray, hi: np.ndarray) -> float:
    return float(np.prod(hi - lo, axis=1).sum())


def test_octree_bricks_nest_and_windows_have_ghosts(sphere):
    data, path = sphere
    octree = BrickOctree(sc.read(path))
    assert octree.levels == [0, 1, 2, 3] and octree.brick == B
    for level in octree.levels[1:]:
        for idx in np.indices(octree.counts[octree.position(level)]).reshape(3, -1).T:
            lo, hi = octree.box(level, idx[None])
            kids = octree.children(level, idx[None])
            finer = octree.levels[octree.position(level) - 1]
            klo, khi = octree.box(finer, kids)
            np.testing.assert_array_equal(klo.min(axis=0), lo[0])
            np.testing.assert_array_equal(khi.max(axis=0), hi[0])
            assert _boxes_volume(klo, khi) == pytest.approx(_boxes_volume(lo, hi))
    cut = select_cut(octree, _camera(sc.read(path)), lod=2.0)
    for n in range(len(cut)):  # the cut's per-level boxes are its level-0 boxes over 2^level
        np.testing.assert_allclose(cut.level_lo[n] * 2 ** cut.keys[n, 0], cut.box_lo[n])
        np.testing.assert_allclose(cut.level_hi[n] * 2 ** cut.keys[n, 0], cut.box_hi[n])
    first, stop = octree.window(1, np.array([[1, 1, 1]]))
    np.testing.assert_array_equal(first[0], [B - GHOST] * 3)
    np.testing.assert_array_equal(stop[0] - first[0], [B + 1 + 2 * GHOST] * 3)


@pytest.mark.parametrize("border", ["edge", "reflect"])
def test_brick_arrays_are_the_level_padded_by_the_border_rule(sphere, border):
    data, path = sphere
    mv = sc.read(path)
    cache = BrickCache(mv, "64MiB", border=border, start=False)
    for level in mv.levels:
        whole = level.read((0, 0, 0), level.shape)
        margin = B + GHOST + 2
        padded = np.pad(whole, margin, mode=border)
        counts = cache.octree.counts[cache.octree.position(level.index)]
        keys = [(level.index, *map(int, idx)) for idx in np.indices(counts).reshape(3, -1).T]
        for brick in cache._read(keys):
            f = np.array(brick.first) + margin
            n = np.array(brick.data.shape)
            np.testing.assert_array_equal(brick.data, padded[f[0]:f[0] + n[0], f[1]:f[1] + n[1],
                                                              f[2]:f[2] + n[2]])
            assert brick.data.flags.c_contiguous
            # Both placements agree: origin + u spacing = world of volume index offset + u scale.
            u = np.array([[0, 0, 0], n - 1])
            np.testing.assert_allclose(
                np.asarray(brick.origin) + u * np.asarray(brick.spacing),
                mv.index_to_world(np.asarray(brick.offset) + u * np.asarray(brick.scale)))
    cache.close()


def test_subtree_ranges_bound_the_children(sphere):
    data, path = sphere
    octree = BrickOctree(sc.read(path))
    for p in range(1, octree.n_levels):
        level = octree.levels[p]
        for idx in np.indices(octree.counts[p]).reshape(3, -1).T:
            sub = octree.subtree[p][tuple(idx)]
            kids = octree.children(level, idx[None])
            ks = octree.subtree[p - 1][kids[:, 0], kids[:, 1], kids[:, 2]]
            assert sub[0] <= ks[:, 0].min() and sub[1] >= ks[:, 1].max()
            own = octree.ranges[p][tuple(idx)]
            assert sub[0] <= own[0] and sub[1] >= own[1]


def _camera(mv, zoom=1.0, azimuth=30.0, size=(160, 120)):
    return sc.Camera.orbit(mv, azimuth=azimuth, elevation=20, size=size, zoom=zoom)


def test_fine_lod_cut_is_every_contributing_finest_brick(sphere):
    data, path = sphere
    mv = sc.read(path)
    octree = BrickOctree(mv)
    cut = select_cut(octree, _camera(mv), lod=1e-9)
    assert set(cut.levels()) == {0}
    assert len(cut) == int(np.prod(octree.counts[0]))
    total = np.prod(np.array(mv.shape) - 1)
    assert _boxes_volume(cut.box_lo, cut.box_hi) == pytest.approx(total)
    # With an isovalue, exactly the level-0 bricks whose ghosted window straddles it remain.
    cut = select_cut(octree, _camera(mv), lod=1e-9, value_filter=ValueFilter.iso(RADIUS))
    expected = set()
    for idx in np.indices(octree.counts[0]).reshape(3, -1).T:
        lo = np.maximum(idx * B - GHOST, 0)
        hi = np.minimum((idx + 1) * B + GHOST + 1, mv.shape)
        window = data[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]]
        if window.min() <= RADIUS <= window.max():
            expected.add((0, *map(int, idx)))
    assert {cut.key(n) for n in range(len(cut))} == expected
    assert set(cut.requests) >= expected
    assert all(k in expected or k[0] > 0 for k in cut.requests)


def test_lod_refines_exactly_while_voxels_cover_more_than_lod_pixels(sphere):
    data, path = sphere
    mv = sc.read(path)
    octree = BrickOctree(mv)
    for zoom, lod in [(1.0, 0.5), (3.0, 2.0), (0.5, 1.0)]:
        cam = _camera(mv, zoom=zoom)
        cut = select_cut(octree, cam, lod=lod)
        pixel = 2 * math.tan(math.radians(cam.fov) / 2) / cam.height

        def pixels(level, lo, hi, cam=cam, pixel=pixel):
            wlo, whi = mv.index_to_world(lo), mv.index_to_world(hi)
            d = float(np.linalg.norm(np.clip(cam.position, wlo, whi) - cam.position))
            return 2**level / (d * pixel) if d > 0 else math.inf

        for n in range(len(cut)):
            level = int(cut.keys[n, 0])
            assert cut.priority[n] == pytest.approx(pixels(level, cut.box_lo[n], cut.box_hi[n]))
            if level > 0:
                assert cut.priority[n] <= lod  # not refined: small enough
            parent = octree.parent(cut.key(n))
            if parent is not None:  # refined parent: too big on screen
                plo, phi = octree.box(parent[0], np.array([parent[1:]]))
                assert pixels(parent[0], plo[0], phi[0]) > lod
        assert _boxes_volume(cut.box_lo, cut.box_hi) <= np.prod(np.array(mv.shape) - 1) + 1e-6


def test_budget_limits_the_cut_and_frustum_culls(sphere):
    data, path = sphere
    mv = sc.read(path)
    octree = BrickOctree(mv)
    cam = _camera(mv)
    full = select_cut(octree, cam, lod=1e-9)
    budget = full.nbytes // 5
    cut = select_cut(octree, cam, lod=1e-9, budget=budget)
    assert cut.limited and cut.nbytes <= budget and len(cut) < len(full)
    total = np.prod(np.array(mv.shape) - 1)
    assert _boxes_volume(cut.box_lo, cut.box_hi) == pytest.approx(total)  # still all covered
    # Zoomed in on the centre: bricks outside the view are left out.
    zoomed = select_cut(octree, _camera(mv, zoom=6.0), lod=1e-9)
    assert len(zoomed) < len(full)
    # No ray of the image passes through a brick that was left out (exact slab test).
    kept = {zoomed.key(n) for n in range(len(zoomed))}
    dropped = [n for n in range(len(full)) if full.key(n) not in kept]
    origins, directions = _camera(mv, zoom=6.0).rays()
    o, d = origins.reshape(-1, 1, 3), directions.reshape(-1, 1, 3)
    with np.errstate(divide="ignore", invalid="ignore"):
        t0 = (full.world_lo[dropped][None] - o) / d
        t1 = (full.world_hi[dropped][None] - o) / d
    near = np.nanmax(np.minimum(t0, t1), axis=2)
    far = np.nanmin(np.maximum(t0, t1), axis=2)
    assert not np.any((near <= far) & (far >= 0))


def test_transparent_bricks_are_left_out(sphere):
    data, path = sphere
    mv = sc.read(path)
    tf = sc.TransferFunction([(0, 0), (5, 0), (6, 1), (8, 1), (9, 0), (60, 0)], (0, 60))
    cut = select_cut(BrickOctree(mv), _camera(mv), lod=1e-9, value_filter=ValueFilter.transfer(tf))
    # Only bricks within distance ~9 of the centre can hold values in (5, 9).
    assert 0 < len(cut)
    for n in range(len(cut)):
        lo, hi = cut.box_lo[n] - GHOST, cut.box_hi[n] + GHOST
        nearest = np.clip([26, 23, 20], lo, hi)
        assert np.linalg.norm(nearest - [26, 23, 20]) < 9


def test_cache_never_exceeds_its_budget_and_converges(sphere):
    data, path = sphere
    mv = sc.read(path)
    budget = 260_000
    stream = BrickStream(mv, budget, lod=0.25, loads_per_frame=4)
    cache = stream.cache
    seen = []
    insert = cache._insert
    # Outside the budget by design: the store, the octree's tables and the decoded chunks kept
    # for the neighbours' ghost layers (its own, documented cap).
    outside = (cache.volume, cache.octree, cache.chunks)

    def instrumented(brick):
        ok = insert(brick)
        # The memory the cache's arrays keep alive, found by walking its references (a brick
        # that is a view of a larger read block costs the block).
        seen.append(held_bytes(cache, skip=outside))
        return ok

    cache._insert = instrumented
    with stream:
        for azimuth in (0, 90, 200):
            cam = _camera(mv, zoom=2.5, azimuth=azimuth)
            for _ in range(60):
                fb = stream.frame(cam, ValueFilter.iso(RADIUS), timeout=5)
                if fb.complete:
                    break
            assert fb.complete, fb.stats
            assert fb.stats["substituted"] == 0 and fb.stats["complete"]
    assert seen and max(seen) <= budget
    assert max(seen) > budget // 2  # the views filled the cache
    assert held_bytes(cache, skip=outside) <= budget
    assert cache.stats()["evicted"] > 0  # the views did not all fit: eviction happened


def test_a_brick_read_while_a_frame_resolves_still_counts_as_requested(sphere):
    """The loader may finish a brick between the frame's look at the cache and its stats: the
    frame drew the brick's ancestor, so the brick must still count as requested, or a caller
    rendering until nothing is requested (``complete=True``) stops with a substituted brick."""
    data, path = sphere
    mv = sc.read(path)
    stream = BrickStream(mv, "64MiB", lod=0.25, loads_per_frame=1)
    cache = stream.cache
    resolve = cache.resolve

    def late(cut):
        items = resolve(cut)
        cache.wait(max_loads=10**6, timeout=10)  # the loader finishes right after resolving
        return items

    cache.resolve = late
    with stream:
        cam = _camera(mv, zoom=2.5)
        fb = stream.frame(cam, ValueFilter.iso(RADIUS), timeout=5)
        assert not fb.complete and fb.stats["substituted"] > 0
        assert cache.stats()["requested"] == 0  # everything arrived since ...
        assert fb.stats["requested"] > 0  # ... but not in time for this frame
        fb = stream.frame(cam, ValueFilter.iso(RADIUS), timeout=5)
        assert fb.complete and fb.stats["requested"] == 0


def test_missing_bricks_are_drawn_from_the_finest_resident_ancestor(sphere):
    data, path = sphere
    mv = sc.read(path)
    cache = BrickCache(mv, "8MiB", start=False)  # no loader: only the coarsest level is there
    cut = select_cut(cache.octree, _camera(mv), lod=1e-9)
    items = cache.resolve(cut)
    assert all(item.substituted for item in items)
    assert cache.stats()["substituted"] == len(cut) and not cache.stats()["complete"]
    for item in items:
        assert item.brick.key[0] == cache.octree.coarsest
        key = cut.key(item.n)
        assert item.brick.key in cache.octree.ancestors(key)
    # Load one level-1 brick by hand: its descendants now come from it.
    key1 = (1, 1, 1, 1)
    cache._insert(cache._read([key1])[0])
    for item in cache.resolve(cut):
        if key1 in cache.octree.ancestors(cut.key(item.n)):
            assert item.brick.key == key1
    cache.close()


def test_loader_thread_stops_cleanly(sphere):
    data, path = sphere
    mv = sc.read(path)
    cache = BrickCache(mv, "64MiB")
    assert cache.running
    cut = select_cut(cache.octree, _camera(mv), lod=1e-9)
    cache.request_cut(cut)
    cache.close(timeout=10)
    assert not cache.running
    assert not [t for t in threading.enumerate() if t.name == "splinecast-brick-loader"]


def _snapshot(root: Path) -> dict[str, tuple[int, int]]:
    return {str(p.relative_to(root)): (p.stat().st_size, p.stat().st_mtime_ns)
            for p in root.rglob("*") if p.is_file()}


def _damaged_copy(path: Path, tmp_path: Path, shard: str, start: int, stop: int) -> Path:
    """A copy of the store with bytes ``start:stop`` of one shard file zeroed."""
    copy = tmp_path / "damaged.zarr"
    shutil.copytree(path, copy)
    target = copy / shard
    raw = bytearray(target.read_bytes())
    raw[start:stop] = bytes(stop - start)
    target.write_bytes(bytes(raw))
    return copy


def test_corrupt_chunk_gives_a_warning_and_a_coarser_level(sphere, tmp_path):
    data, path = sphere
    # Level 0, the shard holding the centre.
    copy = _damaged_copy(path, tmp_path, "0/c/1/1/1", 100, 400)
    before = _snapshot(copy)
    mv = sc.read(copy)
    with BrickStream(mv, "64MiB", lod=1e-9, loads_per_frame=1000) as stream:
        cam = _camera(mv, zoom=3)
        with pytest.warns(BrickUnavailableWarning, match=r"0/c/1/1/1"):
            for _ in range(30):
                fb = stream.frame(cam, timeout=5)
                if fb.stats["requested"] == 0:
                    break
        bad = [item for item in fb.items if item.substituted]
        assert bad and all(item.brick.key[0] >= 1 for item in bad)
        assert fb.stats["unavailable"] > 0 and not fb.stats["complete"]
        good = [item for item in fb.items if not item.substituted]
        assert good  # bricks of the other shards render from their own data
    assert _snapshot(copy) == before  # nothing was written into the store


def test_missing_chunk_file_and_deleted_store(sphere, tmp_path):
    data, path = sphere
    copy = tmp_path / "holes.zarr"
    shutil.copytree(path, copy)
    (copy / "0" / "c" / "0" / "0" / "0").unlink()
    mv = sc.read(copy)
    with BrickStream(mv, "64MiB", lod=1e-9, loads_per_frame=1000) as stream:
        with pytest.warns(BrickUnavailableWarning, match=r"chunk file .*0/c/0/0/0 is missing"):
            for _ in range(30):
                fb = stream.frame(_camera(mv, zoom=4, azimuth=225), timeout=5)
                if fb.stats["requested"] == 0:
                    break
        shutil.rmtree(copy)  # the store disappears while rendering
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            for _ in range(5):
                fb = stream.frame(_camera(mv, zoom=4, azimuth=45), timeout=5)
        assert fb.items  # still a frame: from what is resident, at worst the coarsest level
        assert any(issubclass(w.category, BrickUnavailableWarning) and "gone" in str(w.message)
                   for w in caught)


def test_parse_bytes():
    assert parse_bytes("2GiB") == 2 * 2**30
    assert parse_bytes("512 MiB") == 512 * 2**20
    assert parse_bytes("1.5GB") == 1_500_000_000
    assert parse_bytes(4096) == 4096
    for bad in ("lots", "-1GiB", 0, "2 parsecs"):
        with pytest.raises(sc.ParameterError, match="budget"):
            parse_bytes(bad)


def test_budget_below_the_coarsest_level_is_refused(sphere):
    data, path = sphere
    with pytest.raises(sc.ParameterError, match="smaller than the coarsest level"):
        BrickCache(sc.read(path), 1000)


def test_store_without_tables_learns_ranges_and_covers_shifted_levels(sphere, tmp_path):
    """An ome-zarr-py-style store (no tables, coarse voxels half a fine voxel off): unknown
    ranges are read, learnt, and then prune; every brick's window covers its box plus ghosts."""
    import zarr

    data, _ = sphere
    group = zarr.open_group(str(tmp_path / "foreign.zarr"), mode="w")
    zyx = data.transpose(2, 1, 0)
    datasets = []
    for n, level in enumerate([zyx, zyx[::2, ::2, ::2][: zyx.shape[0] // 2, : zyx.shape[1] // 2,
                                                        : zyx.shape[2] // 2]]):
        array = group.create_array(f"s{n}", shape=level.shape, dtype=level.dtype,
                                   chunks=(16, 16, 16))
        array[...] = level
        scale = [zyx.shape[a] / level.shape[a] for a in range(3)]
        datasets.append({"path": f"s{n}", "coordinateTransformations": [
            {"type": "scale", "scale": scale},
            {"type": "translation", "translation": [s / 2 - 0.5 for s in scale]}]})
    group.attrs["ome"] = {"version": "0.5", "multiscales": [{
        "axes": [{"name": a, "type": "space"} for a in "zyx"], "datasets": datasets}]}
    mv = sc.read(tmp_path / "foreign.zarr")
    with BrickStream(mv, "64MiB", lod=1e-9, loads_per_frame=1000, brick=B) as stream:
        assert np.isnan(stream.octree.ranges[0]).all()
        cam = _camera(mv)
        for _ in range(40):
            fb = stream.frame(cam, ValueFilter.iso(RADIUS), timeout=5)
            if fb.complete and fb.stats["requested"] == 0:
                break
        fb = stream.frame(cam, ValueFilter.iso(RADIUS), timeout=5)
        assert fb.complete and not np.isnan(stream.octree.ranges[0]).any()
        assert fb.stats["cut_bricks"] < np.prod(stream.octree.counts[0])  # empty ones pruned
        for item in fb.items:
            brick, n = item.brick, item.n
            assert brick.data.min() <= RADIUS <= brick.data.max()
            first = np.array(brick.first)
            last = first + np.array(brick.data.shape) - 1
            assert np.all(first <= np.floor(fb.cut.level_lo[n] + 1e-9) - GHOST)
            assert np.all(last >= np.ceil(fb.cut.level_hi[n] - 1e-9) + GHOST)


def test_chunk_cache_reads_equal_the_store_and_reuse_decoded_chunks(sphere):
    """Windows read through the chunk cache equal the level's own reads (a second code path:
    zarr's selection), neighbours' windows reuse decoded chunks, and the cache stays within
    its bytes."""
    from splinecast.multires.store.chunk_cache import ChunkCache

    data, path = sphere
    mv = sc.read(path)
    level = mv.level(0)
    chunk_bytes = int(np.prod(level.chunks)) * level.dtype.itemsize
    chunks = ChunkCache(6 * chunk_bytes)
    rng = np.random.default_rng(3)
    shape = np.array(level.shape)
    for _ in range(40):
        lo = rng.integers(0, shape - 1)
        hi = np.minimum(lo + rng.integers(1, 20, 3), shape)
        np.testing.assert_array_equal(chunks.read(0, level, lo, hi), level.read(lo, hi))
        np.testing.assert_array_equal(chunks.read(0, level, lo, hi), data[lo[0]:hi[0],
                                      lo[1]:hi[1], lo[2]:hi[2]])
        assert chunks.nbytes <= 6 * chunk_bytes
    assert chunks.hits > 0 and chunks.misses > 0
    # Two neighbouring windows sharing chunks: the second decodes only what it adds.
    fresh = ChunkCache(64 * chunk_bytes)
    fresh.read(0, level, np.array([0, 0, 0]), np.array([10, 10, 10]))
    before = fresh.misses
    fresh.read(0, level, np.array([6, 0, 0]), np.array([16, 10, 10]))
    assert fresh.hits > 0 and fresh.misses - before < before


def test_chunk_cache_keeps_nothing_of_a_failed_read(sphere, tmp_path):
    from splinecast.errors import ReadError
    from splinecast.multires.store.chunk_cache import ChunkCache

    data, path = sphere
    level = sc.read(_damaged_copy(path, tmp_path, "0/c/0/0/0", 50, 300)).level(0)
    chunks = ChunkCache(2**24)
    for _ in range(2):  # the second time too: nothing of the failed read was kept
        with pytest.raises(ReadError):
            chunks.read(0, level, np.array([0, 0, 0]), np.array([12, 12, 12]))
    assert chunks.nbytes == 0


def test_resolve_draws_each_brick_from_its_finest_resident_ancestor(sphere):
    """Against a walk up each brick's ancestors in the set of resident keys (``resolve``
    remembers what it found for shared parents)."""
    data, path = sphere
    mv = sc.read(path)
    cache = BrickCache(mv, "64MiB", start=False)
    octree = cache.octree
    rng = np.random.default_rng(5)
    for level in octree.levels[:-1]:
        keys = [(level, *map(int, idx))
                for idx in np.indices(octree.counts[octree.position(level)]).reshape(3, -1).T]
        for n in rng.choice(len(keys), size=max(1, len(keys) // 4), replace=False):
            cache._insert(cache._read([keys[n]])[0])
    resident = set(cache.resident_keys())
    assert {key[0] for key in resident} == set(octree.levels)
    cut = select_cut(octree, _camera(mv), lod=1e-9)
    items = cache.resolve(cut)
    substituted = 0
    for item in items:
        key = cut.key(item.n)
        expected = key if key in resident else next(
            a for a in octree.ancestors(key) if a in resident)
        assert item.brick.key == expected and item.substituted == (expected != key)
        substituted += expected != key
    assert 0 < substituted < len(cut) and cache.stats()["substituted"] == substituted
    cache.close()


def test_no_read_starts_while_a_frame_is_drawn(sphere):
    data, path = sphere
    mv = sc.read(path)
    cache = BrickCache(mv, "64MiB")
    cut = select_cut(cache.octree, _camera(mv), lod=1e-9)
    try:
        with cache.drawing():
            cache.request_cut(cut)
            time.sleep(0.5)
            assert cache.stats()["loaded"] == 0
        assert cache.settle(timeout=30)
        assert cache.stats()["loaded"] > 0  # the reads ran once the frame was drawn
        with pytest.raises(RuntimeError), cache.drawing():  # a failed frame lets reads go on
            raise RuntimeError("trace failed")
        assert cache._drawing == 0
        cache.pause_while_drawing = False
        with cache.drawing():
            assert cache._drawing == 0
    finally:
        cache.close()


def test_the_loader_starts_no_read_beside_the_trace_of_a_frame_drawn_at_once(sphere):
    """A frame drawn at once (``wait=False``) has none of the reads it asks for start before its
    trace ends."""
    data, path = sphere
    mv = sc.read(path)
    with sc.Scene(mv, budget="64MiB", lod=0.25, load_budget=2) as scene:
        cache = scene.stream.cache
        render, read = scene.renderer.render, cache._read
        traces, starts = [], []

        def slow_trace(*args, **kwargs):
            t0 = time.perf_counter()
            time.sleep(0.4)  # time enough for reads to start
            traces.append((t0, time.perf_counter()))
            return render(*args, **kwargs)

        def timed_read(keys):
            starts.append(time.perf_counter())
            return read(keys)

        scene.renderer.render, cache._read = slow_trace, timed_read
        frame = scene.render(_camera(mv, zoom=2.5), mode="iso", iso=RADIUS, wait=False)
        assert not frame.stats["complete"] and frame.stats["requested"] > 0
        assert cache.settle(timeout=30) and starts
        (t0, t1), = traces
        assert min(starts) > t1


@pytest.mark.parametrize("ortho", [False, True])
def test_requests_go_coarse_first_then_nearest_the_centre_of_the_screen(sphere, ortho):
    """The camera looks at the centre of one off-centre level-0 brick: after the coarser
    levels, that brick is read first, and the level-0 requests follow in the order of the
    angle (perspective) or the distance (orthographic) of their centres from the view axis."""
    data, path = sphere
    mv = sc.read(path)
    octree = BrickOctree(mv)
    level0 = mv.levels[0]
    target = np.array([1, 4, 3])  # brick index on level 0 (bricks of B voxels)
    look = np.asarray(level0.origin) + (target * B + B / 2) * np.asarray(level0.spacing)
    eye = look + np.array([-3.0, 40.0, 25.0])
    cam = sc.Camera(eye, look, size=(120, 90), fov=20, ortho=ortho)
    with BrickStream(mv, budget="64MiB", lod=1e-9) as stream:
        asked = []
        request_cut = stream.cache.request_cut
        stream.cache.request_cut = lambda cut: (asked.append(list(cut.requests)),
                                                request_cut(cut))
        stream.frame(cam, wait=False)
    requests = asked[0]
    levels = [k[0] for k in requests]
    assert levels == sorted(levels, reverse=True) and levels[-1] == 0
    finest = [k for k in requests if k[0] == 0]
    assert finest[0] == (0, *target)

    def away(key):
        lo, hi = octree.world_box(0, np.array([key[1:]]))  # the geometry the tests above check
        v = 0.5 * (lo[0] + hi[0]) - cam.position
        along = v @ cam.forward
        aside = np.linalg.norm(v - along * cam.forward)
        return aside if ortho else math.atan2(aside, along)

    distances = [away(k) for k in finest]
    assert len(finest) > 20
    assert all(b >= a - 1e-12 for a, b in zip(distances, distances[1:], strict=False))


@pytest.mark.parametrize("waiting, cancelled", [(0, []), (1, [1]), (2, [1, 0]), (5, [1, 0])])
def test_reads_ahead_give_their_places_to_the_view_only_as_needed(sphere, waiting, cancelled):
    """Two reads ahead under way (``reads=2``, started in order 0, 1) and a new request whose
    view needs ``waiting`` bricks no read has started: the reads ahead started last are stopped
    until as many places are free as such bricks (at most every place), never more; a read of
    bricks the request no longer wants at all is always stopped, one of a brick the view needs
    never. (The rule the test states, on the cache's bookkeeping: no loader thread runs.)"""
    from splinecast.io.cancel import CancelToken
    from splinecast.multires.store.cache import _Read

    _, path = sphere
    cache = BrickCache(sc.read(path), "64MiB", start=False, reads=2)
    level0 = [(0, int(i), int(j), int(k)) for i, j, k in np.indices((2, 2, 2)).reshape(3, -1).T]
    ahead = [level0[0:1], level0[1:2]]
    reads = [_Read(keys, CancelToken(), 0) for keys in ahead]
    cache._reads = list(reads)
    cache._inflight = {k for keys in ahead for k in keys}
    cache.request(level0[2:2 + waiting], prefetch=level0[0:2])
    assert [n for n in (1, 0) if reads[n].token.cancelled] == cancelled
    # A read no longer wanted at all is stopped; one of a brick the view needs is kept.
    reads = [_Read(keys, CancelToken(), 0) for keys in ahead]
    cache._reads = list(reads)
    cache.request([level0[0]], prefetch=[])
    assert not reads[0].token.cancelled and reads[1].token.cancelled
