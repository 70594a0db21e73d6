"""The error cut's split priority (naive P = E vs improved P = ER) and its frustum culling.

References, independent of the code under test:

- the greedy cut from scratch (:func:`.cut_select.greedy_cut`; ``test_cut_select.py`` checks
  it against the refinement replayed from its definition and measures its distance to the
  brute-force optimum) on a metric built apart from the scene's with ``improved=False``;
- which bricks are surely out of view, by projecting the corners of each box (grown by the
  culling margin) through the camera's pinhole (its ``forward``/``right``/``up`` axes and field of
  view): a box all of whose corners project beyond the same edge of the image, or lie behind the
  eye, is out of view;
- the in-memory :class:`splinecast.Scene` render of the finest level.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from reference import smooth_noise

pytest.importorskip("zarr", reason="the multires extra (zarr) is not installed")
pytest.importorskip("dask", reason="the multires extra (dask) is not installed")

import splinecast as sc  # noqa: E402
from splinecast.errors import ParameterError  # noqa: E402
from splinecast.multires.cut.histograms import Quantizer  # noqa: E402
from splinecast.multires.cut.metric import CutMetric  # noqa: E402
from splinecast.multires.cut.policy import octree_histograms, octree_tree  # noqa: E402
from splinecast.multires.cut.relevance import ValueFilter  # noqa: E402
from splinecast.multires.cut.select import greedy_cut  # noqa: E402

B = 8
TF = sc.TransferFunction([(-0.8, 0.0), (-0.2, 0.4), (0.2, 0.0), (0.7, 0.6)], domain=(-3.0, 3.0))
DVR = {"mode": "dvr", "tf": TF, "dvr": sc.DVRSettings(step=0.4)}


@pytest.fixture(scope="module")
def cube(tmp_path_factory) -> tuple[sc.Volume, Path]:
    """Smooth noise 48^3 (6^3 finest bricks of 8^3, four levels), histograms stored."""
    vol = sc.Volume(smooth_noise((48, 48, 48), seed=11, sigma=2.0))
    path = tmp_path_factory.mktemp("cube") / "cube.zarr"
    sc.build_pyramid(vol, path, brick=B, shard=16, progress=False, histograms=True)
    return vol, path


@pytest.fixture(scope="module")
def mixed(tmp_path_factory) -> tuple[sc.Volume, Path]:
    """Smooth noise with a rough half (x >= 24), 4^3 bricks (five levels): splitting a coarse
    brick of the rough half reduces the error little, so P = E and P = ER pick other cuts."""
    data = smooth_noise((48, 48, 48), seed=11, sigma=2.0)
    rough = smooth_noise((48, 48, 48), seed=12, sigma=0.6)
    x = np.arange(48)[:, None, None]
    vol = sc.Volume(np.where(x >= 24, 0.5 * data + 1.5 * rough, data))
    path = tmp_path_factory.mktemp("mixed") / "mixed.zarr"
    sc.build_pyramid(vol, path, brick=4, shard=16, progress=False, histograms=True)
    return vol, path


def _corners(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    return np.array([[(lo, hi)[i][0], (lo, hi)[j][1], (lo, hi)[k][2]]
                     for i in (0, 1) for j in (0, 1) for k in (0, 1)])


def _surely_out_of_view(cam: sc.Camera, lo: np.ndarray, hi: np.ndarray, grow: float) -> bool:
    """All corners of the grown box behind the eye or beyond one edge of the image."""
    q = _corners(lo - grow, hi + grow) - cam.position
    depth = q @ cam.forward
    if np.all(depth <= 0):
        return True
    if np.any(depth <= 0):
        return False  # straddles the eye plane: not surely out
    half_h = math.tan(math.radians(cam.fov) / 2)
    half_w = half_h * cam.width / cam.height
    sx, sy = (q @ cam.right) / depth, (q @ cam.up) / depth
    return bool(np.all(sx < -half_w) or np.all(sx > half_w) or np.all(sy < -half_h)
                or np.all(sy > half_h))


def _converge(scene, cam, limit: int = 50):
    """Render until the cut is final (M bricks per frame) and complete."""
    for _ in range(limit):
        frame = scene.render(cam, complete=True, **DVR)
        if frame.stats["cut_final"]:
            return frame
    raise AssertionError("the cut did not converge")


def test_frustum_culling_leaves_bricks_out_of_view_coarse(cube):
    vol, path = cube
    cam = sc.Camera((-20.0, -18.0, 27.0), (4.0, 5.0, 3.0), size=(20, 20), fov=20.0)
    whole = sc.Scene(vol).render(cam, **DVR)
    with sc.Scene(sc.read(path), budget="256MiB", cut="error") as scene:
        frame = _converge(scene, cam)
        ec = scene.error_cut
        tree, cut = ec.tree, np.fromiter(ec.updater.cut, np.int64)
        margin = ec.frustum_margin
    # Covered once: the cut's finest descendants are every leaf, each once.
    covered = np.zeros(tree.size, int)
    for node in cut.tolist():
        stack = [node]
        while stack:
            b = stack.pop()
            covered[b] += 1
            stack.extend(tree.children_of(b).tolist())
    assert np.all(covered[tree.is_leaf] == 1)
    # No brick surely out of view was split: every cut brick's parent may be in view.
    out = np.array([_surely_out_of_view(cam, tree.box_min[n], tree.box_max[n], margin)
                    for n in range(tree.size)])
    assert out.sum() > 0 and out[cut].sum() > 0  # the corner view leaves bricks out
    parents = tree.parent[cut]
    assert not out[parents[parents >= 0]].any()
    assert set(frame.stats["cut_levels"]) != {0}  # culling kept some bricks coarse
    assert frame.stats["cut_levels"].get(0, 0) > 0  # and refined what is seen
    # Every pixel's ray only crosses bricks in view: the image is the finest level's.
    assert frame.stats["complete"]
    np.testing.assert_allclose(frame.rgba, whole.rgba, atol=1e-6)


def test_without_culling_the_full_budget_cut_is_the_finest_level(cube):
    _, path = cube
    cam = sc.Camera((-20.0, -18.0, 27.0), (4.0, 5.0, 3.0), size=(20, 20), fov=20.0)
    with sc.Scene(sc.read(path), budget="256MiB", cut="error") as scene:
        scene.error_cut.frustum = False
        frame = _converge(scene, cam)
    assert frame.stats["cut_levels"] == {0: frame.stats["cut_bricks"]}


def test_naive_priority_cut_is_the_greedy_cut_with_p_equal_e(mixed):
    vol, path = mixed
    cam = sc.Camera.orbit(vol, azimuth=30, elevation=20, size=(16, 16))
    mv = sc.read(path)
    with sc.Scene(mv, budget="256MiB", cut="error", cut_priority="naive") as scene:
        ec = scene.error_cut
        assert not ec.improved
        tree = ec.tree
        # The whole volume is in view: frustum culling plays no part in this comparison.
        assert not any(_surely_out_of_view(cam, tree.box_min[n], tree.box_max[n], 0.0)
                       for n in range(tree.size))
        brick_bytes = ec.brick_bytes
        octree = scene.stream.octree
    ref_tree, _, _ = octree_tree(octree)
    hist = octree_histograms(octree, Quantizer.for_data(mv.dtype, mv.value_range))
    visible = ValueFilter.transfer(TF).contributes(ref_tree.value_min, ref_tree.value_max)
    naive = CutMetric(ref_tree, hist, TF, eye=cam.position, improved=False)
    improved = CutMetric(ref_tree, hist, TF, eye=cam.position, improved=True)
    naive.visible[:] = improved.visible[:] = visible
    # A budget at which the two priorities pick different cuts (else the test could not tell
    # them apart).
    n_bricks = next(n for n in range(12, 200, 7)
                    if not np.array_equal(greedy_cut(naive, n, fill=True),
                                          greedy_cut(improved, n, fill=True)))
    budget = int((n_bricks + 0.5) * brick_bytes / 0.8)
    with sc.Scene(mv, budget=budget, cut="error", cut_priority="naive", load_budget=64) as scene:
        frame = _converge(scene, cam)
        assert frame.stats["cut_budget_bricks"] == n_bricks
        cut = np.sort(np.fromiter(scene.error_cut.updater.cut, np.int64))
    np.testing.assert_array_equal(cut, greedy_cut(naive, n_bricks, fill=True))
    with sc.Scene(mv, budget=budget, cut="error", load_budget=64) as scene:
        _converge(scene, cam)
        cut = np.sort(np.fromiter(scene.error_cut.updater.cut, np.int64))
    np.testing.assert_array_equal(cut, greedy_cut(improved, n_bricks, fill=True))


def test_bad_cut_priority_is_refused_with_one_line(cube):
    _, path = cube
    with pytest.raises(ParameterError, match="cut_priority"):
        sc.Scene(sc.read(path), cut="error", cut_priority="best")
