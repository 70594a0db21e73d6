"""Bricks changed at a level seam drawn as shells around their unchanged core
(:mod:`splinecast.multires.draw.seam_parts`).

References: the split is checked by brute force (sampled points of every part against the
changed elements; rays from the eye sampled densely for the order of the parts they cross), and
the rendered image against the other code path, one float64 copy of each changed brick's whole
array (``CutRenderer.split_seams = False``); the budget against the bytes the cache and the seam
state keep alive (their references walked).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from held_bytes import held_buffers

from splinecast.multires.draw.seam_parts import crop_range, part_order, split_box


def _random_case(rng: np.random.Generator, radius: float):
    lo = rng.integers(-3, 3, size=3).astype(float)
    hi = lo + rng.integers(20, 40, size=3)
    elements = []
    for _ in range(rng.integers(1, 3)):  # coarser neighbours across faces or edges
        axes = rng.choice(3, size=rng.integers(1, 3), replace=False)
        for _ in range(40):
            e = rng.uniform(lo, hi)
            for a in axes:  # within ``radius`` of that face, inside or in the ghost layers
                side = rng.integers(2)
                e[a] = (lo[a] + rng.uniform(-radius, radius) if side == 0
                        else hi[a] + rng.uniform(-radius, radius))
            elements.append(np.round(e))
    return lo, hi, np.array(elements)


@pytest.mark.parametrize("radius", [1.0, 1.5, 2.0])
def test_the_core_is_beyond_the_radius_of_every_changed_element_and_the_parts_tile_the_box(
        radius):
    rng = np.random.default_rng(int(radius * 10))
    split_seen = 0
    for _ in range(60):
        lo, hi, elements = _random_case(rng, radius)
        parts = split_box(lo, hi, elements, radius)
        if parts is None:
            continue
        split_seen += 1
        boxes = parts.boxes
        volumes = np.prod(boxes[:, 1] - boxes[:, 0], axis=1)
        assert np.all(volumes > 0)
        assert np.isclose(volumes.sum(), np.prod(hi - lo))  # no gap ...
        points = rng.uniform(lo, hi, size=(4000, 3))
        assert np.all(_inside(boxes, points).sum(axis=1) == 1)  # ... and no overlap
        core_lo, core_hi = boxes[-1]
        # Max-norm distance from each element to the core box.
        gap = np.maximum(np.maximum(core_lo - elements, elements - core_hi), 0.0).max(axis=1)
        assert np.all(gap > radius)
        # Every part is on whole voxels from the box's faces (cells end there too).
        assert np.all(np.mod(boxes - lo, 1.0) == 0.0)
    assert split_seen > 20


def _inside(boxes: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(points, boxes) mask: the point lies strictly inside the box."""
    return np.all((points[:, None] > boxes[None, :, 0]) & (points[:, None] < boxes[None, :, 1]),
                  axis=2)


def test_nothing_to_split_or_no_core_left_gives_none():
    lo, hi = np.zeros(3), np.full(3, 10.0)
    assert split_box(lo, hi, np.zeros((0, 3)), 1.0) is None
    # Shells of 6 from both x faces leave nothing of 10.
    assert split_box(lo, hi, np.array([[4.0, 5, 5], [6, 5, 5]]), 1.0) is None


def _crossed(boxes: np.ndarray, start: np.ndarray, direction: np.ndarray) -> list[int]:
    """The parts a ray crosses, in the order it meets them (sampled every 0.05 voxel; parts
    are at least one voxel thick)."""
    s = np.arange(0.0, 400.0, 0.05)
    inside = _inside(boxes, start + s[:, None] * direction)
    hit = inside.any(axis=1)
    seq = np.argmax(inside[hit], axis=1)
    return [int(p) for k, p in enumerate(seq) if k == 0 or p != seq[k - 1]]


@pytest.mark.parametrize("perspective", [True, False])
def test_every_ray_crosses_the_parts_in_the_given_order(perspective):
    rng = np.random.default_rng(3 + perspective)
    checked = 0
    for _ in range(30):
        lo, hi, elements = _random_case(rng, 1.0)
        parts = split_box(lo, hi, elements, 1.0)
        if parts is None:
            continue
        centre = 0.5 * (lo + hi)
        if perspective:  # eyes outside the box, near it, and inside it
            eye = centre + rng.normal(size=3) * rng.choice([10.0, 40.0, 3.0])
            order = part_order(parts, eye, perspective=True)
        else:
            direction = rng.normal(size=3)
            order = part_order(parts, direction, perspective=False)
        assert sorted(order) == list(range(len(parts.boxes)))
        rank = {p: k for k, p in enumerate(order)}
        for _ in range(20):
            target = rng.uniform(lo, hi)
            if perspective:
                d = target - eye
                seq = _crossed(parts.boxes, eye, d / np.linalg.norm(d))
            else:
                d = direction / np.linalg.norm(direction)
                seq = _crossed(parts.boxes, target - 200.0 * d, d)
            assert [rank[p] for p in seq] == sorted(rank[p] for p in seq), (seq, order)
            checked += 1
    assert checked > 200


def test_the_crop_holds_every_element_a_point_of_the_box_reads():
    first = np.array([-2, -2, -2])
    start, stop = crop_range(np.array([0.0, 0, 29]), np.array([3.0, 32, 32]), first,
                             np.array([37, 37, 37]), 1.0)
    # Points in [0, 3] read elements -1 .. 4 (trilinear, a rounding error outside included).
    assert start[0] + first[0] == -1 and stop[0] - 1 + first[0] == 4
    assert start[1] + first[1] == -1 and stop[1] - 1 + first[1] == 33
    assert start[2] + first[2] == 28 and stop[2] - 1 + first[2] == 33


# ---------------------------------------------------------------------------- rendering
zarr = pytest.importorskip("zarr", reason="the multires extra (zarr) is not installed")
pytest.importorskip("dask", reason="the multires extra (dask) is not installed")

from frame_replay import replay  # noqa: E402

import splinecast as sc  # noqa: E402


@pytest.fixture(scope="module")
def torus(tmp_path_factory) -> tuple[sc.Volume, Path]:
    """The demo torus distance field (192^3, float32) as a pyramid of 64^3 bricks (the render
    brick of large pyramids): big enough that bricks at a seam split."""
    demo = sc.demo("torus", size=192)
    vol = sc.Volume(demo.data.astype(np.float32), spacing=demo.spacing, origin=demo.origin)
    path = tmp_path_factory.mktemp("torus") / "torus.zarr"
    sc.build_pyramid(vol, path, brick=64, shard=128, progress=False)
    return vol, path


def _split_and_whole(scene, cam: sc.Camera, **options):
    """The same frame's pieces drawn with parts and from whole copies (the stream's frame is
    recorded once and handed to both renders)."""
    with replay(scene) as frames:
        split = scene.render(cam, complete=True, **options)
        split_stats = dict(scene.renderer.stats)
        frames.hold()
        scene.renderer.split_seams = False
        scene.renderer._last = None  # else the launch of the same pieces is reused
        whole = scene.render(cam, complete=True, **options)
        whole_stats = dict(scene.renderer.stats)
    scene.renderer.split_seams = True
    return split, whole, split_stats, whole_stats


CASES = [("trilinear", "iso"), ("trilinear", "multi"), ("trilinear", "dvr"),
         ("bspline3", "iso"), ("bspline2", "dvr"), ("s31", "iso")]


@pytest.mark.parametrize(("model", "mode"), CASES)
def test_parts_draw_what_the_whole_changed_copy_draws(torus, model, mode):
    vol, path = torus
    tf = sc.TransferFunction([(-0.3, 0.5), (0.0, 0.2), (0.2, 0.0)], domain=(-1.0, 1.0))
    options = {"iso": {"mode": "iso", "iso": 0.0, "inside": "low"},
               "multi": {"mode": "iso", "iso": [-0.1, 0.05], "opacity": [0.5, 0.5],
                         "inside": "low"},
               "dvr": {"mode": "dvr", "tf": tf, "dvr": sc.DVRSettings(step=0.5)}}[mode]
    cam = sc.Camera.orbit(vol, azimuth=35, elevation=25, size=(96, 72), zoom=2.5)
    with sc.Scene(sc.read(path), model=model, budget="12MiB", lod=0.5) as scene:
        split, whole, split_stats, whole_stats = _split_and_whole(scene, cam, **options)
    assert len(split.stats["cut_levels"]) >= 2
    assert split_stats["seam_parts"] > 0 and whole_stats["seam_parts"] == 0
    # Shells are float64 grids like whole copies: still two grid types, one launch.
    assert split_stats["one_launch"] and whole_stats["one_launch"]
    # Held for the seams: the shells' copies against (after the second render) the shells
    # plus every whole copy.
    shells = split_stats["seam_copy_bytes"]
    assert 0 < shells < whole_stats["seam_copy_bytes"] - shells
    if mode == "dvr":
        # Segments restart at the parts' faces (cell boundaries): the same integral, summed
        # in other places.
        np.testing.assert_allclose(split.rgba, whole.rgba, rtol=0, atol=1e-4)
        return
    assert np.isfinite(split.depth).sum() > 500
    np.testing.assert_array_equal(split.depth, whole.depth)
    np.testing.assert_array_equal(split.rgba, whole.rgba)
    if split.normal is not None:
        np.testing.assert_array_equal(split.normal, whole.normal)


def test_the_seam_copies_count_against_the_budget_and_the_view_settles(torus):
    """The cache holds back the seam copies' bytes (in steps of 1/32 of the budget, at most
    half of it): once a
    view is complete, its resident bricks and its seam copies together fit the budget, and
    the view keeps its cut (the reservation does not move the cut every frame)."""
    vol, path = torus
    cam = sc.Camera.orbit(vol, azimuth=35, elevation=25, size=(96, 72), zoom=2.5)
    options = {"mode": "iso", "iso": 0.0, "inside": "low"}
    with sc.Scene(sc.read(path), model="trilinear", budget="12MiB", lod=0.5) as scene:
        cache = scene.stream.cache
        frames = []
        for _ in range(8):
            frames.append(scene.render(cam, complete=True, **options))
            cache.settle(30.0)
        last = frames[-1]
        seams = last.stats["seam_copy_bytes"]
        assert seams > 0 and last.stats["seam_parts"] > 0
        assert cache.reserved_bytes >= seams
        # What is actually held, found by walking the references: the cache's bricks and the
        # renderer's seam state (the split pieces' shells and changes, whole changed copies,
        # the launch's type exemplars), each buffer once. Outside the budget by design: the
        # store, the octree's tables and the decoded-chunk cache.
        renderer = scene.renderer
        outside = (cache.volume, cache.octree, cache.chunks)
        bricks = held_buffers(cache, skip=outside)
        seam_state = held_buffers(renderer._split, renderer._changed, renderer._seam_pairs,
                                  skip=outside)
        assert sum(seam_state.values()) > seams // 2
        assert sum(bricks.values()) + sum(v for k, v in seam_state.items()
                                          if k not in bricks) <= cache.budget
        assert last.stats["complete"] and last.stats["cut_reused"]
        # Steps: a little less keeps the reservation, a step less lowers it, more raises it.
        step = cache.budget // 32
        held = cache.reserved_bytes
        assert not cache.reserve(held - step // 2) and cache.reserved_bytes == held
        assert cache.reserve(held - 2 * step) and cache.reserved_bytes == held - 2 * step
        assert cache.reserve(held + 1) and cache.reserved_bytes == held + step
        assert cache.nbytes <= cache.budget - cache.reserved_bytes
        # At most half the budget is held back (more would starve the cut it was measured on).
        assert cache.reserve(cache.budget) and cache.reserved_bytes == cache.budget // 2
        # The bricks the view keeps stay until the next frame chooses its cut for the room left.
        scene.render(cam, complete=True, **options)
        cache.settle(30.0)
        assert cache.nbytes <= cache.budget - cache.reserved_bytes
