"""The error-metric cut (reference 002) as the cut policy of the multiresolution renderer.

References, independent of the code under test:

- the in-memory :class:`splinecast.Scene` render of the finest level (a budget that holds every
  brick: the converged error cut is all of level 0, and the image must be the same);
- D(b) summed voxel by voxel with scipy's interpolation (:func:`cut_reference.voxel_distortion`)
  over each brick's source voxels, from the definition of the store's bricks and levels;
- the error metric computed here from the voxels (:func:`_voxel_metric`: the brick tree from the
  store's documented geometry, D(b) voxel by voxel, the fix-up, eqs. 5-7, visibility from the
  transfer function's opacity over each brick's values), and the greedy refinement replayed on
  it from its definition (:func:`cut_reference.reference_greedy`): the scene's frame-to-frame
  updates must converge to that cut, carry the same errors, and respect the budgets;
  ``test_cut_select.py`` measures the greedy cut's distance to the brute-force optimum.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from cut_reference import reference_greedy, srgb_luv, voxel_distortion
from reference import smooth_noise

pytest.importorskip("zarr", reason="the multires extra (zarr) is not installed")
pytest.importorskip("dask", reason="the multires extra (dask) is not installed")

import splinecast as sc  # noqa: E402
from splinecast.multires.cut.colour import classified_luv, distortion_table  # noqa: E402
from splinecast.multires.cut.histograms import Quantizer  # noqa: E402
from splinecast.multires.cut.metric import histogram_distortion  # noqa: E402
from splinecast.multires.cut.policy import octree_histograms, octree_tree  # noqa: E402
from splinecast.multires.cut.select import optimal_cut  # noqa: E402
from splinecast.multires.cut.tree import BrickTree  # noqa: E402
from splinecast.multires.scenes.multiscale import MultiscaleScene  # noqa: E402

B = 8
TF = sc.TransferFunction([(-0.8, 0.0), (-0.2, 0.4), (0.2, 0.0), (0.7, 0.6)], domain=(-3.0, 3.0))
DVR = {"mode": "dvr", "tf": TF, "dvr": sc.DVRSettings(step=0.4)}


@pytest.fixture(scope="module")
def noise(tmp_path_factory) -> tuple[sc.Volume, Path]:
    """Smooth noise (float32, sizes that are not powers of two) and its pyramid of 8^3 bricks.
    (float32 as in the other multiresolution tests: a float64 store costs the suite its own
    compiled kernels for every model and mode.)"""
    vol = sc.Volume(smooth_noise((27, 23, 21), seed=3, sigma=2.0).astype(np.float32))
    path = tmp_path_factory.mktemp("noise") / "noise.zarr"
    sc.build_pyramid(vol, path, brick=B, shard=16, progress=False)
    return vol, path


@pytest.fixture(scope="module")
def wide(tmp_path_factory) -> tuple[sc.Volume, Path]:
    """A pyramid whose coarsest level keeps several bricks (``levels=2``): a virtual root."""
    vol = sc.Volume(smooth_noise((30, 20, 18), seed=5, sigma=2.0).astype(np.float32))
    path = tmp_path_factory.mktemp("wide") / "wide.zarr"
    sc.build_pyramid(vol, path, brick=B, shard=16, levels=2, progress=False)
    return vol, path


def _camera(vol: sc.Volume) -> sc.Camera:
    return sc.Camera((45.0, -24.0, 33.0), (13.0, 11.0, 10.0), size=(26, 22))


def _budget(bricks: int, scene_brick_bytes: int, fraction: float = 0.8) -> int:
    """A byte budget whose cut share holds ``bricks`` full bricks."""
    return int((bricks + 0.5) * scene_brick_bytes / fraction)


# ------------------------------------------------------------------------------- full budget
@pytest.mark.parametrize("model", ["trilinear", "s31"])
@pytest.mark.parametrize("mode", ["dvr", "mip"])
def test_error_cut_at_full_budget_equals_the_in_memory_render(noise, model, mode):
    vol, path = noise
    options = DVR if mode == "dvr" else {"mode": "mip", "window": vol.value_range}
    cam = _camera(vol)
    whole = sc.Scene(vol, model=model).render(cam, **options)
    with sc.Scene(sc.read(path), model=model, budget="64MiB", cut="error") as scene:
        assert isinstance(scene, MultiscaleScene) and scene.cut == "error"
        frame = scene.render(cam, complete=True, **options)
    stats = frame.stats
    assert stats["cut_policy"] == "error" and stats["complete"] and stats["cut_final"]
    assert stats["cut_levels"] == {0: stats["cut_bricks"]}
    assert stats["cut_error"] == 0.0
    if mode == "dvr":
        np.testing.assert_allclose(frame.rgba, whole.rgba, atol=1e-6)
    else:
        np.testing.assert_allclose(frame.value, whole.value, rtol=1e-12, atol=1e-12)


def test_isosurfaces_keep_the_level_of_detail_cut(noise):
    vol, path = noise
    with sc.Scene(sc.read(path), budget="64MiB", cut="error", lod=1e-6) as scene:
        frame = scene.render(_camera(vol), iso=0.3, complete=True)
    assert frame.stats["cut_policy"] == "lod"
    assert frame.stats["cut_levels"] == {0: frame.stats["cut_bricks"]}


# --------------------------------------------------------------------------- the metric's input
def test_histograms_of_the_store_bricks_match_their_voxels(noise):
    """D(b) of every brick of the store's octree from its histogram equals the voxel sum over the
    source voxels it owns, approximated by its level (vertex-centred: level index = i / f)."""
    vol, path = noise
    mv = sc.read(path)
    with sc.Scene(mv, budget="64MiB", cut="error") as scene:
        octree = scene.stream.octree
        q = Quantizer.for_data(mv.dtype, mv.value_range)
        tree, keys, virtual = octree_tree(octree)
        hist = octree_histograms(octree, q)
    assert virtual == -1 and tree.size == len(keys)
    levels = [mv.level(i).read((0, 0, 0), mv.level(i).shape) for i in range(len(mv.levels))]
    got = histogram_distortion(hist, distortion_table(TF, q.values))
    luv = classified_luv(TF, q.values)
    n0 = np.asarray(vol.shape)
    for node in range(tree.size):
        level, index = int(keys[node, 0]), keys[node, 1:]
        f = 2 ** level
        edge = B * f
        last = -(-(n0 - 1) // edge) - 1
        lo = index * edge
        hi = np.where(index == last, n0, (index + 1) * edge)
        assert tree.voxels[node] == np.prod(hi - lo)
        if level == 0:
            assert got[node] == 0.0
            continue
        ref = voxel_distortion(vol.data, levels[level], level, lo, hi, q.bin_of, luv,
                               index_map=(1.0 / f, 0.0))
        assert got[node] == pytest.approx(ref, rel=1e-9, abs=1e-9), keys[node]
    # The children own their parent's voxels, exactly.
    for node in np.flatnonzero(~tree.is_leaf):
        assert tree.voxels[tree.children_of(node)].sum() == tree.voxels[node]


# ------------------------------------------------------------------------------ small budgets
def _voxel_metric(vol: sc.Volume, levels: list[np.ndarray], tf, eye, interest=None,
                  bins: int = 64, ghost: int = 2):
    """The error metric of the store's brick tree, from the voxels (independent of the package).

    Tree: level ``p`` (factor ``2^p``) has ``ceil((n - 1) / (B 2^p))`` bricks per axis (at least
    one); node ids level by level, finest first, C order within a level; a brick's parent is the
    brick ``index // 2`` of the next level. Brick ``index`` owns the source voxels
    ``[index B 2^p, (index + 1) B 2^p)`` (the last one up to the end) and its box is the cell box
    of those voxel centres, clamped to the volume. D(b): :func:`voxel_distortion` with 64 bins
    over the data range, colours from :func:`srgb_luv`; D*(b) = max(D(b), sum of the visible
    children's D); I(b) of eqs. 5-6 (t = 1/4); E = D* I. Visible: the transfer function's
    opacity is positive somewhere in the values of the brick's window (its voxels and ``ghost``
    level voxels around) or of its descendants'.

    Returns ``(parent, keys, error, visible)``, keys as ``(level, i, j, k)``.
    """
    n0 = np.asarray(vol.shape)
    data = np.asarray(vol.data)
    lo_v, hi_v = float(data.min()), float(data.max())
    scale = (bins - 1) / (hi_v - lo_v)
    bin_values = lo_v + np.arange(bins) / scale

    def bin_of(x):
        return np.clip(np.floor((np.asarray(x, np.float64) - lo_v) * scale + 0.5), 0,
                       bins - 1).astype(np.int64)

    colours = srgb_luv(tf.color(bin_values) * tf.opacity(bin_values)[:, None])
    keys: list[tuple[int, ...]] = []
    for p in range(len(levels)):
        keys += [(p, *idx) for idx in np.ndindex(*np.maximum(1, -(-(n0 - 1) // (B * 2**p))))]
    node_of = {key: n for n, key in enumerate(keys)}
    parent = [node_of.get((key[0] + 1, *(np.asarray(key[1:]) // 2).tolist()), -1)
              for key in keys]
    size = len(keys)
    raw, imp = np.zeros(size), np.zeros(size)
    vmin, vmax = np.full(size, np.inf), np.full(size, -np.inf)

    def reach(box_lo, box_hi, diag, point):
        d = np.linalg.norm(np.maximum(np.maximum(box_lo - point, point - box_hi), 0.0))
        return diag / (diag + d)

    for node, (p, *index) in enumerate(keys):
        idx, f = np.asarray(index), 2**p
        edge = B * f
        last = np.maximum(1, -(-(n0 - 1) // edge)) - 1
        lo, hi = idx * edge, np.where(idx == last, n0, (idx + 1) * edge)
        if p > 0:
            raw[node] = voxel_distortion(data, levels[p], p, lo, hi, bin_of, colours,
                                         index_map=(1.0 / f, 0.0))
        box_lo = np.minimum(lo, n0 - 1).astype(float)
        box_hi = np.minimum((idx + 1) * edge, n0 - 1).astype(float)
        diag = float(np.linalg.norm(box_hi - box_lo))
        eye_term = reach(box_lo, box_hi, diag, np.asarray(eye, float))
        imp[node] = eye_term if interest is None else (
            0.75 * reach(box_lo, box_hi, diag, np.asarray(interest, float)) + 0.25 * eye_term)
        level = levels[p]
        first = np.clip(np.floor(box_lo / f + 1e-9).astype(int) - ghost, 0, level.shape)
        stop = np.clip(np.ceil(box_hi / f - 1e-9).astype(int) + ghost + 1, 0, level.shape)
        window = level[first[0]:stop[0], first[1]:stop[1], first[2]:stop[2]]
        vmin[node], vmax[node] = float(window.min()), float(window.max())
    for node in range(size):  # children (finer levels) come before their parents
        if parent[node] >= 0:
            vmin[parent[node]] = min(vmin[parent[node]], vmin[node])
            vmax[parent[node]] = max(vmax[parent[node]], vmax[node])
    visible = np.array([bool(np.any(tf.opacity(np.linspace(a, b, 4001)) > 0))
                        for a, b in zip(vmin, vmax, strict=True)])
    kids: list[list[int]] = [[] for _ in keys]
    for node, up in enumerate(parent):
        if up >= 0:
            kids[up].append(node)
    fixed = np.array([max(raw[b], sum(raw[k] for k in kids[b] if visible[k]))
                      for b in range(size)])
    return parent, keys, fixed * imp, visible


def _reference(scene: MultiscaleScene, vol: sc.Volume, tf, cam, interest=None):
    """:func:`_voxel_metric` of the scene's store; checks that the scene's metric holds the
    same tree (as keys), visibility and errors. Returns ``(parent, keys, error, visible)``."""
    mv = scene.volume
    levels = [mv.level(i).read((0, 0, 0), mv.level(i).shape) for i in range(len(mv.levels))]
    parent, keys, error, visible = _voxel_metric(vol, levels, tf, cam.position, interest)
    ec = scene.error_cut
    scene_keys = [tuple(int(v) for v in key) for key in ec.keys]
    assert sorted(scene_keys) == sorted(keys)
    order = [scene_keys.index(key) for key in keys]
    np.testing.assert_array_equal(ec.metric.visible[order], visible)
    np.testing.assert_allclose(ec.metric.all_errors()[order], error, rtol=1e-9, atol=1e-9)
    return parent, keys, error, visible


def _scene_cut(scene: MultiscaleScene) -> list[tuple[int, ...]]:
    keys = scene.error_cut.keys
    return sorted(tuple(int(v) for v in keys[n]) for n in scene.error_cut.updater.cut)


def _converge(scene, cam, options, limit=300, **extra):
    frames = [scene.render(cam, **options, **extra)]
    while not (frames[-1].stats["complete"] and frames[-1].stats["cut_final"]):
        frames.append(scene.render(cam, **options, **extra))
        assert len(frames) < limit
    return frames


def test_small_budget_cut_is_the_greedy_cut_within_budget_and_above_the_optimum(noise):
    vol, path = noise
    cam = _camera(vol)
    interest = (5.0, 6.0, 4.0)
    mv = sc.read(path)
    probe = MultiscaleScene(mv, budget="64MiB", cut="error")
    brick_bytes = probe.error_cut.brick_bytes
    probe.close()
    n_bricks = 20
    budget = _budget(n_bricks, brick_bytes)
    with sc.Scene(mv, budget=budget, cut="error", interest=interest, load_budget=3) as scene:
        scene.seams_in_budget = False  # N follows from the budget alone
        frames = _converge(scene, cam, DVR)
        last = frames[-1].stats
        # M = 3 (8, a whole split, in effect) bricks per frame: the cut refines over frames.
        assert len(frames) >= 2 and frames[0].stats["cut_stop"] == "load budget"
        assert last["cut_budget_bricks"] == n_bricks
        assert last["cut_bricks"] <= n_bricks
        assert last["cut_bytes"] <= 0.8 * budget
        assert last["peak_bytes"] <= budget
        assert set(last["cut_levels"]) != {0}  # the budget forces coarser bricks
        errors = [f.stats["cut_error"] for f in frames]
        assert errors[-1] < errors[0]
        # The reference: the metric from the voxels, the greedy cut replayed on it (fill: the
        # scene sets aside a split that does not fit).
        parent, keys, error, visible = _reference(scene, vol, TF, cam, interest)
        greedy = reference_greedy(parent, error, visible, n_bricks, fill=True)
        assert _scene_cut(scene) == sorted(keys[n] for n in greedy)
        paper = reference_greedy(parent, error, visible, n_bricks)  # stops at the first misfit
        assert len(greedy) >= len(paper)
        # E(cut), eq. 8: per source voxel of the visible region (every brick is visible here).
        assert visible.all()
        assert last["cut_error"] == pytest.approx(error[greedy].sum() / vol.data.size, rel=1e-9)
        best, total = optimal_cut(BrickTree.from_parents(parent), error, visible, n_bricks)
        assert len(best) <= n_bricks
        assert total <= error[greedy].sum() * (1 + 1e-12)
        again = scene.render(cam, **DVR)  # converged: it stays
        np.testing.assert_array_equal(again.rgba, frames[-1].rgba)


@pytest.fixture(scope="module")
def ramp(tmp_path_factory) -> tuple[sc.Volume, Path]:
    """Values rising along x (-2 to 2) with smooth noise: regions a transfer function can hide."""
    x = np.linspace(-2.0, 2.0, 27)[:, None, None]
    vol = sc.Volume((x + 0.3 * smooth_noise((27, 23, 21), seed=4, sigma=2.0)).astype(np.float32))
    path = tmp_path_factory.mktemp("ramp") / "ramp.zarr"
    sc.build_pyramid(vol, path, brick=B, shard=16, progress=False)
    return vol, path


def test_a_transfer_function_edit_coarsens_what_became_transparent(ramp):
    """Make the values above a threshold transparent: the bricks holding only such values leave
    the cut or are covered by coarser ancestors, none of the cut's bricks is transparent, the bricks
    freed go to the region still visible (finer there), and the repaired, refined cut is the
    greedy cut of the new transfer function."""
    vol, path = ramp
    cam = _camera(vol)
    mv = sc.read(path)
    probe = MultiscaleScene(mv, budget="64MiB", cut="error")
    budget = _budget(20, probe.error_cut.brick_bytes)
    probe.close()
    with sc.Scene(mv, budget=budget, cut="error", load_budget=64) as scene:
        scene.seams_in_budget = False  # the same N before and after the edit
        # The edit hides everything above the smallest value of some level-1 brick.
        tree = scene.error_cut.tree
        cut_at = float(tree.value_min[tree.level == 1].max()) - 1e-9
        first = sc.TransferFunction([(-2.5, 0.3), (cut_at - 0.5, 0.5), (2.5, 0.3)],
                                    domain=(-3.0, 3.0))
        edited = sc.TransferFunction([(-2.5, 0.3), (cut_at - 0.5, 0.5), (cut_at, 0.0)],
                                     domain=(-3.0, 3.0))
        before = _converge(scene, cam, {**DVR, "tf": first})[-1]
        ec = scene.error_cut
        cut_before = np.fromiter(ec.updater.cut, np.int64)
        after = _converge(scene, cam, {**DVR, "tf": edited})[-1]
        assert after.stats["cut_policy"] == "error"
        cut_after = np.fromiter(ec.updater.cut, np.int64)
        gone = tree.value_min > cut_at  # every value of the brick (and below) is transparent
        assert not gone[cut_after].any()
        assert gone[cut_before].any()  # the edit matters for this cut

        def covering_depth(cut):
            depth = np.full(tree.size, -1)
            for node in cut.tolist():
                stack = [node]
                while stack:
                    b = stack.pop()
                    depth[b] = tree.depth[node]
                    stack.extend(tree.children_of(b).tolist())
            return depth

        leaves = np.flatnonzero(tree.is_leaf & gone)
        d0, d1 = covering_depth(cut_before)[leaves], covering_depth(cut_after)[leaves]
        assert np.all(d1 <= d0) and np.any(d1 < d0)
        kept = np.flatnonzero(tree.is_leaf & ~gone)
        k0, k1 = covering_depth(cut_before)[kept], covering_depth(cut_after)[kept]
        assert k1.sum() > k0.sum()
        parent, keys, error, visible = _reference(scene, vol, edited, cam)
        assert not visible.all()
        greedy = reference_greedy(parent, error, visible, 20, fill=True)
        assert _scene_cut(scene) == sorted(keys[n] for n in greedy)
        assert not np.array_equal(after.rgba, before.rgba)


def test_several_coarsest_bricks_hang_below_a_virtual_root(wide):
    vol, path = wide
    cam = sc.Camera((50.0, -20.0, 30.0), (15.0, 10.0, 9.0), size=(24, 20))
    whole = sc.Scene(vol).render(cam, **DVR)
    with sc.Scene(sc.read(path), budget="64MiB", cut="error") as scene:
        ec = scene.error_cut
        assert ec.virtual >= 0 and len(ec.roots) > 1
        frame = scene.render(cam, complete=True, **DVR)
        assert ec.virtual not in ec.updater.cut
    assert frame.stats["cut_levels"] == {0: frame.stats["cut_bricks"]}
    np.testing.assert_allclose(frame.rgba, whole.rgba, atol=1e-6)


def test_bad_cut_values_are_refused_with_one_line(noise):
    vol, path = noise
    mv = sc.read(path)
    for bad in ("errors", None, 3):
        with pytest.raises(sc.ParameterError, match="cut must be one of 'lod', 'error'") as info:
            sc.Scene(mv, budget="64MiB", cut=bad)
        assert "\n" not in str(info.value)
    with sc.Scene(mv, budget="64MiB", cut="error") as scene:
        with pytest.raises(sc.ParameterError, match="interest"):
            scene.render(_camera(vol), interest=(1, 2), **DVR)


def test_cli_renders_a_pyramid_with_the_error_cut(noise, tmp_path, capsys):
    from splinecast.cli import main

    vol, path = noise
    out = tmp_path / "noise.png"
    assert main(["render", str(path), "--mode", "dvr", "--cut", "error", "--budget", "64MiB",
                 "--size", "32x24", "-o", str(out)]) == 0
    assert out.is_file()
    assert "cut (error, E(cut) " in capsys.readouterr().err
    for argv, message in ((["--cut", "errors"], "--cut must be lod or error, got 'errors'"),):
        assert main(["render", str(path), *argv, "-o", str(tmp_path / "x.png")]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1
    assert main(["render", "demo:sphere?size=16", "--cut", "error", "-o", str(out)]) == 2
    assert "--cut applies to multiscale" in capsys.readouterr().err
