"""Rendering a multiresolution cut: every model in every mode, level boundaries, faults.

References, independent of the code under test:

- the in-memory :class:`splinecast.Scene` render of the finest level (a cut whose bricks are all
  on level 0 must give the same image: depths to 1e-9, MIP to 1e-12, DVR within 1e-6);
- the analytic sphere and torus (signed distance fields): with a small budget the cut mixes
  levels, and every ray whose line passes through the solid's core must hit the surface (no
  hole at a level boundary) within the coarsest drawn level's reconstruction error of it;
- the reconstructions themselves on the faces between levels (nested models: equal);
- a damaged copy of a store (a warning naming the chunk, a coarser level drawn, nothing
  written).
"""

from __future__ import annotations

import shutil
import threading
import warnings
from pathlib import Path

import numpy as np
import pytest
from reference import smooth_noise

pytest.importorskip("zarr", reason="the multires extra (zarr) is not installed")
pytest.importorskip("dask", reason="the multires extra (dask) is not installed")

import splinecast as sc  # noqa: E402
from splinecast.io.synthetic import sphere_sdf, torus_sdf  # noqa: E402
from splinecast.multires.scenes.multiscale import MultiscaleScene  # noqa: E402
from splinecast.multires.store.cache import BrickUnavailableWarning  # noqa: E402

MODELS = ["trilinear", "bspline1", "bspline2", "bspline3", "qss", "s31"]
MODES = ["iso", "multi", "mip", "minip", "dvr"]
B = 8


@pytest.fixture(scope="module")
def noise(tmp_path_factory) -> tuple[sc.Volume, Path]:
    """Smooth noise (float32 as most stores, sizes that are not powers of two) and its pyramid of
    8^3 bricks. (float32 like the other brick tests' stores: the suite then compiles one launch
    per model and mode, see ``tests/test_distributed_sort_last.py``.)"""
    vol = sc.Volume(smooth_noise((27, 23, 21), seed=3, sigma=2.0).astype(np.float32))
    path = tmp_path_factory.mktemp("noise") / "noise.zarr"
    sc.build_pyramid(vol, path, brick=B, shard=16, progress=False)
    return vol, path


def _cameras(vol: sc.Volume) -> list[sc.Camera]:
    """A perspective camera and an orthographic one whose rays lie in brick face planes."""
    persp = sc.Camera((45.0, -24.0, 33.0), (13.0, 11.0, 10.0), size=(26, 22))
    c = 8.0  # a brick face: rays along z at x = 8 and y = 8 lie in face planes
    ortho = sc.Camera((c, c, 60.0), (c, c, 0.0), up=(0.0, 1.0, 0.0), ortho=True,
                      ortho_height=22.0, size=(22, 22))
    return [persp, ortho]


def _options(mode: str, vol: sc.Volume) -> dict:
    if mode == "iso":
        return {"mode": "iso", "iso": 0.3}
    if mode == "multi":
        return {"mode": "iso", "iso": [-0.4, 0.3], "opacity": [0.4, 0.6]}
    if mode in ("mip", "minip"):
        return {"mode": mode, "window": vol.value_range}
    tf = sc.TransferFunction([(-0.8, 0.0), (-0.2, 0.4), (0.2, 0.0), (0.7, 0.6)],
                             domain=(-3.0, 3.0))
    return {"mode": "dvr", "tf": tf, "dvr": sc.DVRSettings(step=0.4)}


@pytest.mark.parametrize("model", MODELS)
def test_scene_of_a_multiscale_volume_is_the_multires_scene(noise, model):
    vol, path = noise
    with sc.Scene(sc.read(path), model=model, budget="64MiB") as scene:
        assert isinstance(scene, MultiscaleScene)
        assert scene.model.name == model
        # The preview (the coarsest level in memory) checks isovalues against the range of the
        # whole volume, also after the model scanned it for non-finite values.
        assert scene.preview.nonfinite_counts() == (0, 0, 0)
        assert scene.preview.value_range == (float(vol.data.min()), float(vol.data.max()))
        coarse = sc.read(path).level(-1).to_volume()
        assert coarse.value_range != scene.preview.value_range  # the levels' ranges differ


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("mode", MODES)
def test_whole_finest_level_in_budget_equals_the_in_memory_render(noise, model, mode):
    """lod so fine that every brick is refined to level 0, a budget that holds them all."""
    vol, path = noise
    reference = sc.Scene(vol, model=model)
    options = _options(mode, vol)
    with sc.Scene(sc.read(path), model=model, budget="64MiB", lod=1e-6,
                  whole_level=False) as scene:
        for cam in _cameras(vol):
            # Antialiasing is off by default for a multiscale scene, on for an in-memory one.
            whole = reference.render(cam, samples=1, **options)
            frame = scene.render(cam, **options)
            what = f"{model} {mode} {'ortho' if cam.ortho else 'perspective'}"
            assert frame.stats["complete"], what
            assert frame.stats["cut_levels"] == {0: frame.stats["cut_bricks"]}, what
            _assert_same(mode, whole, frame, what)


def _assert_same(mode: str, whole: sc.Frame, frame: sc.Frame, what: str) -> None:
    if mode in ("mip", "minip"):
        np.testing.assert_array_equal(np.isnan(whole.value), np.isnan(frame.value), err_msg=what)
        # Exact up to rounding: a ray entering a brick mid-cell parametrizes the cell's
        # polynomial from another point (as tests/test_bricks.py allows).
        np.testing.assert_allclose(frame.value, whole.value, rtol=1e-12, atol=1e-12,
                                   err_msg=what)
        return
    if mode == "dvr":
        np.testing.assert_allclose(frame.rgba, whole.rgba, atol=1e-6, err_msg=what)
        return
    hit = np.isfinite(whole.depth)
    np.testing.assert_array_equal(hit, np.isfinite(frame.depth), err_msg=what)
    assert hit.sum() > 20, what
    np.testing.assert_allclose(frame.depth[hit], whole.depth[hit], rtol=0, atol=1e-9,
                               err_msg=what)
    np.testing.assert_allclose(frame.rgba, whole.rgba, atol=1e-6, err_msg=what)


# --------------------------------------------------------------------------- level boundaries
SHAPES = {"sphere": (sphere_sdf, 0.15), "torus": (torus_sdf, 0.08)}  # sdf, core depth (world)


@pytest.fixture(scope="module")
def shapes(tmp_path_factory) -> dict[str, tuple[sc.Volume, Path]]:
    """The demo sphere and torus distance fields (48^3, float32) as pyramids of 8^3 bricks."""
    out = {}
    for name in SHAPES:
        demo = sc.demo(name, size=48)
        vol = sc.Volume(demo.data.astype(np.float32), spacing=demo.spacing, origin=demo.origin,
                        metadata=demo.metadata)
        path = tmp_path_factory.mktemp(name) / f"{name}.zarr"
        sc.build_pyramid(vol, path, brick=B, shard=16, progress=False)
        out[name] = (vol, path)
    return out


def _brick_maker(mv, model: str, tree):
    """``drawable(level, index)``: the :class:`Drawable` of one brick of levels 0-2, its array cut
    from the level read whole and padded by numpy with the model's border rule (independent of
    the cache)."""
    from splinecast.multires.cut.octree import GHOST
    from splinecast.multires.draw.cut_renderer import Drawable

    padded = {}
    for level in (0, 1, 2):
        lv = mv.level(level)
        padded[level] = np.pad(lv.read((0, 0, 0), lv.shape), GHOST,
                               mode=sc.MODELS[model].border_rule)

    def drawable(level, index):
        first, stop = (a[0] for a in tree.window(level, np.array([index])))
        lo, hi = (a[0] for a in tree.box(level, np.array([index])))
        window = tuple(slice(int(f) + GHOST, int(s) + GHOST) for f, s in zip(first, stop,
                                                                               strict=True))
        key = (level, *map(int, index))
        return Drawable(key, key, level, np.ascontiguousarray(padded[level][window]),
                     tuple(int(v) for v in first), lo, hi)

    return drawable


def _checkerboard_cut(mv, model: str):
    """A cut that puts levels 0, 1 and 2 side by side in every direction: level-2 bricks with an
    odd index sum stay whole, the others split into level-1 bricks, of which those with an even
    index sum split into level-0 bricks (arrays from :func:`_brick_maker`)."""
    from splinecast.multires.cut.octree import BrickOctree
    from splinecast.multires.draw.cut_renderer import CutRenderer

    tree = BrickOctree(mv)
    drawable = _brick_maker(mv, model, tree)
    drawables = []
    for i2 in np.indices(tree.counts[2]).reshape(3, -1).T:
        if i2.sum() % 2:
            drawables.append(drawable(2, i2))
            continue
        for i1 in tree.children(2, i2[None]):
            if i1.sum() % 2:
                drawables.append(drawable(1, i1))
                continue
            drawables.extend(drawable(0, i0) for i0 in tree.children(1, i1[None]))
    coarse = mv.level(-1)
    prepared = sc.MODELS[model](sc.Volume(coarse.read((0, 0, 0), coarse.shape)))
    return drawables, tree, prepared, CutRenderer


def _level_errors(mv, model: str, sdf, spacing: float) -> dict[int, float]:
    """Largest |reconstruction - exact distance| of each level on a shell around the surface
    (world units), from the tests' evaluators (``evaluators.py``, not the ray kernels)."""
    from evaluators import model_evaluator

    rng = np.random.default_rng(0)
    world = rng.uniform(-0.95, 0.95, (60000, 3))
    world = world[np.abs(sdf(*world.T)) < 3 * spacing]
    errors = {}
    for level in (0, 1, 2):
        lv = mv.level(level)
        vol = sc.Volume(lv.read((0, 0, 0), lv.shape), spacing=lv.spacing, origin=lv.origin)
        ev = model_evaluator(model, vol, sc.Scene(vol, model=model))
        index = (world - np.asarray(lv.origin)) / np.asarray(lv.spacing)
        errors[level] = float(np.abs(ev.value(index) - sdf(*world.T)).max())
    return errors


def _core_rays(cam: sc.Camera, sdf, depth: float) -> tuple[np.ndarray, np.ndarray]:
    """Rays whose line passes at least ``depth`` inside the solid, and where along each ray the
    solid is deepest (dense sampling of the exact distance)."""
    origins, directions = cam.rays()
    reach = np.linalg.norm(cam.position)
    ts = np.linspace(reach - 1.8, reach + 1.8, 1200)
    points = origins[..., None, :] + directions[..., None, :] * ts[:, None]
    values = sdf(points[..., 0], points[..., 1], points[..., 2])
    return values.min(axis=-1) < -depth, ts[values.argmin(axis=-1)]


def _holes(renderer, drawables, cam, sdf, depth) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Core rays that miss the surface or hit it behind the solid's core (through a hole), the
    exact distance at every hit, and the core mask."""
    from splinecast.render.iso import Iso

    out, _ = renderer.render(drawables, Iso(0.0, inside="low"), cam)
    t_hit, position = out[1], out[2]
    core, t_core = _core_rays(cam, sdf, depth)
    hit = np.isfinite(t_hit)
    bad = core & (~hit | (t_hit > t_core))
    return bad, np.abs(sdf(*position[hit].T)), core


def _orbit(vol, count: int = 4) -> list[sc.Camera]:
    views = [(20, -30), (110, 15), (215, 50), (290, -10)][:count]
    return [sc.Camera.orbit(vol, azimuth=a, elevation=e, size=(56, 56), zoom=2.0)
            for a, e in views]


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("shape", SHAPES)
def test_no_holes_where_levels_meet(shapes, model, shape):
    """Levels 0, 1, 2 side by side (faces, edges, corners): every ray through the solid's core
    hits the surface in front of the core, within the drawn levels' reconstruction error."""
    from splinecast.multires.draw.seams import Seams

    vol, path = shapes[shape]
    sdf, depth = SHAPES[shape]
    mv = sc.read(path)
    drawables, tree, prepared, CutRenderer = _checkerboard_cut(mv, model)
    assert {p.level for p in drawables} == {0, 1, 2}
    renderer = CutRenderer(prepared, tree, Seams(prepared))
    tolerance = max(_level_errors(mv, model, sdf, vol.spacing[0]).values()) * 1.05 + 1e-9
    for cam in _orbit(vol):
        bad, error, core = _holes(renderer, drawables, cam, sdf, depth)
        what = f"{model} {shape} azimuth {cam.position.round(2)}"
        assert core.sum() > 300, what
        assert bad.sum() == 0, f"{what}: {bad.sum()} rays through the core miss the surface"
        assert error.max() <= tolerance, f"{what}: hit {error.max():.4g} > {tolerance:.4g} off"
        assert renderer.stats["drawables_changed_at_seams"] > 0
        if sc.MODELS[model].nested_degree is not None:  # the restriction alone closes the seams
            assert renderer.stats["seam_closure_hits"] == 0, what


def test_without_seam_treatment_the_same_cut_has_holes(shapes):
    """The check above can fail: drawn as they are, the bricks leave holes."""
    from splinecast.multires.draw.seams import Seams

    vol, path = shapes["torus"]
    sdf, depth = SHAPES["torus"]
    drawables, tree, prepared, CutRenderer = _checkerboard_cut(sc.read(path), "trilinear")
    plain = CutRenderer(prepared, tree, None)
    fixed = CutRenderer(prepared, tree, Seams(prepared))
    holes = sum(_holes(plain, drawables, cam, sdf, depth)[0].sum() for cam in _orbit(vol))
    assert holes > 10
    assert sum(_holes(fixed, drawables, cam, sdf, depth)[0].sum() for cam in _orbit(vol)) == 0


def _shared_boundary_points(a, b, rng, count: int = 40) -> np.ndarray | None:
    """Random level-0 points on the common boundary of two touching boxes (or None)."""
    lo = np.maximum(a.box_lo, b.box_lo)
    hi = np.minimum(a.box_hi, b.box_hi)
    if np.any(lo > hi):
        return None
    return lo + rng.random((count, 3)) * (hi - lo)


@pytest.mark.parametrize("model", MODELS)
def test_reconstructions_agree_on_faces_between_levels(shapes, model):
    """Nested models (trilinear, bspline1, bspline3): after the restriction the finer and the
    coarser brick reconstruct the same values on every face, edge and corner they share. The
    others: the gap shrinks well below the untreated one."""
    from splinecast.multires.draw.seams import Seams

    vol, path = shapes["torus"]
    drawables, tree, prepared, CutRenderer = _checkerboard_cut(sc.read(path), model)
    renderer = CutRenderer(prepared, tree)
    changes = Seams(prepared).plan(drawables, renderer)
    rng = np.random.default_rng(1)
    gap_before, gap_after, pairs = 0.0, 0.0, 0
    for a in drawables:
        for b in drawables:
            if b.level <= a.level:
                continue
            points = _shared_boundary_points(a, b, rng)
            if points is None:
                continue
            pairs += 1
            coarse = renderer.evaluate(b, points, changes)
            gap_after = max(gap_after, np.abs(renderer.evaluate(a, points, changes) - coarse).max())
            gap_before = max(gap_before, np.abs(renderer.evaluate(a, points) -
                                                renderer.evaluate(b, points)).max())
    assert pairs > 50
    assert gap_before > 1e-3
    if sc.MODELS[model].nested_degree is not None:
        assert gap_after < 1e-12, f"{model}: {gap_after:.3g}"
    else:
        assert gap_after < gap_before / 3, f"{model}: {gap_after:.3g} vs {gap_before:.3g}"


# --------------------------------------------------------------------------- the brick stream
def _torus_camera(vol) -> sc.Camera:
    return sc.Camera.orbit(vol, azimuth=35, elevation=40, size=(56, 48), zoom=2.0)


class _OneReadAtATime:
    """Stands in for ``Level.read`` while ``gating``: each read waits for a permit given by the
    test (:meth:`allow_one`), which then waits for that read to finish. Frames drawn in between
    see every state of the cache on the way, on any machine and under any load."""

    def __init__(self, original) -> None:
        self.original = original
        self.gating = False
        self.permits = threading.Semaphore(0)
        self.done = 0
        self.finished = threading.Condition()

    def read(self, level, lo, hi):
        if self.gating:
            self.permits.acquire()
        try:
            return self.original(level, lo, hi)
        finally:
            with self.finished:
                self.done += 1
                self.finished.notify_all()

    def allow_one(self, timeout: float = 120.0) -> None:
        with self.finished:
            before = self.done
            self.permits.release()
            assert self.finished.wait_for(lambda: self.done > before, timeout), "no read came"

    def open(self) -> None:
        self.gating = False
        for _ in range(64):  # more than loader threads: none is left waiting
            self.permits.release()


def test_frames_converge_without_holes_while_bricks_arrive(shapes, monkeypatch):
    """A small load budget: the first frames draw ancestors for missing bricks (levels mixed by
    substitution), have no holes, and the view converges to the complete cut. The loader reads
    one batch of bricks between two frames (:class:`_OneReadAtATime`)."""
    from splinecast.io.omezarr import Level

    vol, path = shapes["torus"]
    sdf, depth = SHAPES["torus"]
    cam = _torus_camera(vol)
    core, t_core = _core_rays(cam, sdf, depth)
    reads = _OneReadAtATime(Level.read)
    monkeypatch.setattr(Level, "read", lambda level, lo, hi: reads.read(level, lo, hi))
    scene = sc.Scene(sc.read(path), budget="64MiB", lod=1.5, load_budget=4, whole_level=False)
    reads.gating = True  # the coarsest level is resident; every later read waits for a permit
    try:
        with scene:
            first = scene.render(cam, iso=0.0, wait=False)
            assert not first.stats["complete"] and first.stats["substituted"] > 0
            frames = [first]
            for _ in range(1000):
                reads.allow_one()
                # The bricks of that read are in the cache before the next frame looks.
                scene.stream.cache.wait(max_loads=1, timeout=120)
                frames.append(scene.render(cam, iso=0.0, wait=False))
                if frames[-1].stats["complete"]:
                    break
            assert frames[-1].stats["complete"]
            # Some frame met ancestors beside finer bricks.
            assert any(f.stats["drawables_changed_at_seams"] > 0 for f in frames)
            # Every frame from the first read on (the first frame, drawn from the pinned
            # coarsest level alone before any read, is too coarse for the thin torus: a frame
            # the renderer only draws with ``wait=False``).
            for frame in frames[1:]:
                hit = np.isfinite(frame.depth)
                bad = core & (~hit | (frame.depth > t_core))
                assert bad.sum() == 0, frame.stats
            reads.open()
            final = scene.render(cam, iso=0.0)
            np.testing.assert_array_equal(final.depth, frames[-1].depth)  # converged: it stays
    finally:
        reads.open()


@pytest.mark.parametrize("model", ["trilinear", "bspline3", "qss"])
def test_the_incremental_seam_plan_equals_a_plan_from_scratch(shapes, model):
    """Bricks arriving change the cut every frame; the seam plan reuses the change of every
    array whose coarser neighbours (their boxes and their own changes) are as before. A
    sequence of cuts, from most bricks drawn by their parents to none, each planned by one
    :class:`Seams` in turn, must give the plans of a new :class:`Seams` per cut, and reuse."""
    from dataclasses import replace

    from splinecast.multires.draw.seams import Seams
    from splinecast.render.iso import Iso

    mv = sc.read(shapes["torus"][1])
    drawables, tree, prepared, CutRenderer = _checkerboard_cut(mv, model)
    brick = _brick_maker(mv, model, tree)

    def parent(drawable):  # drawn from its level-2 ancestor, or its parent (level 0, even index)
        level, *index = drawable.key
        up = 1 if level == 0 and sum(index) % 2 == 0 else 2
        up = brick(up, np.array(index) // 2 ** (up - level))
        return replace(drawable, key=up.key, level=up.level, data=up.data, first=up.first,
                       substituted=True)

    rng = np.random.default_rng(7)
    fine = np.array([n for n, p in enumerate(drawables) if p.level < 2])
    renderer = CutRenderer(prepared, tree, Seams(prepared))
    camera = sc.Camera.orbit(mv, azimuth=20, elevation=-30, size=(48, 48), zoom=0.8)
    reused = 0
    # Most bricks missing at first, then fewer; a few evicted again on the way (a change of a
    # coarser array must reach the finer arrays next to it even where their own neighbours
    # stay the same).
    missing = set(fine.tolist())
    for share in (0.7, 0.5, 0.5, 0.3, 0.3, 0.1, 0.0):
        arrived = rng.choice(sorted(missing), size=len(missing) - int(share * len(fine)),
                             replace=False) if len(missing) > share * len(fine) else []
        missing -= set(np.asarray(arrived).tolist())
        missing |= set(rng.choice(fine, size=int(0.05 * len(fine) * share)).tolist())
        cut = [parent(p) if n in missing else p for n, p in enumerate(drawables)]
        changes = renderer.seams.plan(cut, renderer)
        reused += len(changes) - renderer.seams.recomputed
        fresh = Seams(prepared)._plan(cut, renderer)
        assert len(fresh) > 0 and set(fresh) == set(changes)
        for key, change in fresh.items():
            np.testing.assert_array_equal(changes[key].index, change.index)
            np.testing.assert_array_equal(changes[key].values, change.values)
        # Drawing the cut keeps changed values (float64 copies of whole arrays, or of the
        # shells of those drawn in parts) only of arrays changed now, and of each of them (an
        # array drawn for several boxes, an ancestor standing in, may have both).
        renderer.render(cut, Iso(0.0), camera)
        split = {key[0] for key, entry in renderer._split.items() if entry[1] is not None}
        assert set(renderer._changed) <= set(changes) and split <= set(changes)
        assert set(renderer._changed) | split == {p.key for p in cut} & set(changes)
    assert reused > 0


def _snapshot(root: Path) -> dict[str, tuple[int, int]]:
    return {str(p.relative_to(root)): (p.stat().st_size, p.stat().st_mtime_ns)
            for p in root.rglob("*") if p.is_file()}


def test_corrupt_chunk_while_rendering_draws_a_coarser_level_and_names_the_chunk(shapes,
                                                                                 tmp_path):
    vol, path = shapes["sphere"]
    sdf, depth = SHAPES["sphere"]
    copy = tmp_path / "damaged.zarr"
    shutil.copytree(path, copy)
    # Level 0, the shard of voxels x 0..15, y and z 16..31: the sphere's side facing -x.
    shard = copy / "0" / "c" / "1" / "1" / "0"
    raw = bytearray(shard.read_bytes())
    raw[100:400] = bytes(300)
    shard.write_bytes(bytes(raw))
    before = _snapshot(copy)
    cam = sc.Camera((-2.6, 0.35, 0.3), (0.0, 0.0, 0.0), size=(48, 48), fov=30)
    core, t_core = _core_rays(cam, sdf, depth)
    with sc.Scene(sc.read(copy), budget="64MiB", lod=0.5, whole_level=False) as scene:
        with pytest.warns(BrickUnavailableWarning, match=r"0/c/1/1/0"):
            frame = scene.render(cam, iso=0.0, complete=True, timeout=10)
        stats = frame.stats
        assert stats["unavailable"] > 0 and not stats["complete"] and stats["substituted"] > 0
        assert stats["cut_levels"] == {0: stats["cut_bricks"]}  # the cut wants level 0 ...
        hit = np.isfinite(frame.depth)
        assert not (core & (~hit | (frame.depth > t_core))).any()  # ... and has no hole
        again = scene.render(cam, iso=0.0)  # a known fault is not read again
        np.testing.assert_array_equal(again.depth, frame.depth)
    assert _snapshot(copy) == before  # nothing was written into the store


def test_store_deleted_while_rendering(shapes, tmp_path, monkeypatch):
    """The store disappears after the first frame and before any finer brick is read: the
    later reads fail, are reported, and the frame is drawn from what is resident. The reads
    are held at a gate (:class:`_OneReadAtATime`) until the store is gone, so that no loader
    can finish them first on a fast machine."""
    from splinecast.io.omezarr import Level

    vol, path = shapes["sphere"]
    copy = tmp_path / "gone.zarr"
    shutil.copytree(path, copy)
    cam = sc.Camera((-2.6, 0.35, 0.3), (0.0, 0.0, 0.0), size=(40, 40), fov=30)
    reads = _OneReadAtATime(Level.read)
    monkeypatch.setattr(Level, "read", lambda level, lo, hi: reads.read(level, lo, hi))
    with sc.Scene(sc.read(copy), budget="64MiB", lod=0.5, whole_level=False) as scene:
        reads.gating = True  # the coarsest level is resident; finer reads wait at the gate
        scene.render(cam, iso=0.0, wait=False)  # the coarsest level only
        shutil.rmtree(copy)
        reads.open()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            frame = scene.render(cam, iso=0.0, complete=True, timeout=10)
        assert any(issubclass(w.category, BrickUnavailableWarning) and "gone" in str(w.message)
                   for w in caught)
        assert np.isfinite(frame.depth).sum() > 100  # drawn from what is resident


def test_bad_options_are_refused_with_one_line(noise):
    vol, path = noise
    mv = sc.read(path)
    with pytest.raises(sc.ParameterError, match="prefilter=True is not available"):
        sc.Scene(mv, model="bspline3", prefilter=True)
    with pytest.raises(sc.ParameterError, match="budget"):
        sc.Scene(mv, budget="a lot")
    with sc.Scene(mv, budget="64MiB") as scene:
        with pytest.raises(sc.ParameterError, match="iso=9 is outside the data range"):
            scene.render(_cameras(vol)[0], iso=9.0)
        with pytest.raises(sc.ParameterError, match="lod"):
            scene.render(_cameras(vol)[0], iso=0.3, lod=-1)


def test_type6_prefilter_in_bricks_equals_the_whole_volume(noise):
    """The Laplacian prefilter is local: per brick, with the level's border re-clamped, it gives
    the in-memory s31 render exactly."""
    vol, path = noise
    reference = sc.Scene(vol, model="s31", prefilter=True)
    with sc.Scene(sc.read(path), model="s31", prefilter=True, budget="64MiB", lod=1e-6,
                  whole_level=False) as scene:
        for cam in _cameras(vol):
            _assert_same("iso", reference.render(cam, iso=0.3, samples=1),
                         scene.render(cam, iso=0.3, complete=True), "s31 prefilter")


def test_cli_renders_a_pyramid(shapes, tmp_path, capsys):
    from splinecast.cli import main

    vol, path = shapes["sphere"]
    out = tmp_path / "sphere.png"
    assert main([ "render", str(path), "--budget", "64MiB", "--lod", "2", "--size", "48x40",
                 "-o", str(out)]) == 0
    assert out.is_file()
    assert "complete" in capsys.readouterr().err
    for argv, message in (
        (["--budget", "lots"], "--budget must be a size"),
        (["--lod", "0"], "--lod must be a positive number"),
        (["--smooth", "3"], "--smooth does not apply"),
    ):
        assert main(["render", str(path), *argv, "-o", str(tmp_path / "x.png")]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1
    assert not (tmp_path / "x.png").exists()
    assert main(["render", "demo:sphere?size=16", "--lod", "2", "-o", str(out)]) == 2
    assert "--lod applies to multiscale" in capsys.readouterr().err


def test_a_mip_tolerance_holds_over_the_bricks_of_the_cut(noise):
    """``tolerance=`` on a multiresolution scene (the cut's bricks traced one after another):
    every pixel within the tolerance below the in-memory exact projection, never above it."""
    vol, path = noise
    reference = sc.Scene(vol)
    options = _options("mip", vol)
    tolerance = 0.05
    width = vol.value_range[1] - vol.value_range[0]
    largest = 0.0
    with sc.Scene(sc.read(path), budget="64MiB", lod=1e-6, whole_level=False) as scene:
        for cam in _cameras(vol):
            exact = reference.render(cam, **options)
            frame = scene.render(cam, **options, tolerance=tolerance)
            hit = np.isfinite(exact.value)
            np.testing.assert_array_equal(np.isfinite(frame.value), hit)
            short = (exact.value - frame.value)[hit] / width
            assert short.min() >= -1e-9 and short.max() <= tolerance * (1 + 1e-9)
            largest = max(largest, float(short.max()))
    assert largest > 0.0  # the tolerance was used
