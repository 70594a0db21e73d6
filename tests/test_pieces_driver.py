"""The one-launch renderer of a cut (:mod:`splinecast.render.pieces_driver`) against the
per-piece one (one segment-entry-point call per piece, :meth:`CutRenderer._trace_each`).

The per-piece path is the independent reference: its images equal the in-memory renderer's
(``tests/test_multires_render.py``, ``tests/test_bricks.py``). Tracing a ray through the same
grids in the same order with the same intervals must give bit-identical states, so the two paths
are compared exactly, on cuts that mix levels (seam-changed float64 grids next to the store's
float32 ones: two grid types in one launch), for every mode, with clip planes, on a camera tile
(a sort-last worker's share) and with the isosurface's seam closure at work.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("zarr", reason="the multires extra (zarr) is not installed")
pytest.importorskip("dask", reason="the multires extra (dask) is not installed")

from frame_replay import replay  # noqa: E402

import splinecast as sc  # noqa: E402
from splinecast.multires.draw.cut_renderer import screen_rect, screen_rects  # noqa: E402

MODES = ["iso", "multi", "mip", "minip", "dvr"]


@pytest.fixture(scope="module")
def torus(tmp_path_factory) -> tuple[sc.Volume, Path]:
    """The demo torus distance field (40^3, float32) as a pyramid of 8^3 bricks."""
    demo = sc.demo("torus", size=40)
    vol = sc.Volume(demo.data.astype(np.float32), spacing=demo.spacing, origin=demo.origin)
    path = tmp_path_factory.mktemp("torus") / "torus.zarr"
    sc.build_pyramid(vol, path, brick=8, shard=16, progress=False)
    return vol, path


def _options(mode: str) -> dict:
    if mode == "iso":
        return {"mode": "iso", "iso": 0.0, "inside": "low"}
    if mode == "multi":
        return {"mode": "iso", "iso": [-0.1, 0.05], "opacity": [0.5, 0.5], "inside": "low"}
    if mode in ("mip", "minip"):
        return {"mode": mode, "window": (-0.5, 0.5)}
    tf = sc.TransferFunction([(-0.3, 0.5), (0.0, 0.2), (0.2, 0.0)], domain=(-1.0, 1.0))
    return {"mode": "dvr", "tf": tf, "dvr": sc.DVRSettings(step=0.5)}


def _both(scene, cam: sc.Camera, **options) -> tuple[sc.Frame, sc.Frame, dict, dict]:
    """The same cut rendered per piece and in one launch: the launch is handed the very bricks
    the per-piece render drew (the loader thread goes on prefetching and evicting between the
    two renders; what is compared here is the tracing, not the stream)."""
    with replay(scene) as frames:
        scene.renderer.batched = False
        each = scene.render(cam, complete=True, **options)
        each_stats = dict(scene.renderer.stats)
        assert each.stats["complete"]  # the whole cut drawn from its own bricks
        frames.hold()
        scene.renderer.batched = True
        batched = scene.render(cam, complete=True, **options)
    return each, batched, each_stats, dict(scene.renderer.stats)


def _assert_identical(a: sc.Frame, b: sc.Frame, what: str) -> None:
    # MIP's work on a ray depends on the ray its thread traced before (its lower bound starts
    # where that ray found its maximum), and the two paths trace the rays in other groups.
    work = () if a.value is not None else ("cells_visited", "cells_tested", "blocks_skipped")
    for name in ("rgba", "depth", *work):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=f"{what} {name}")
    for name in ("value", "normal", "position"):
        if getattr(a, name, None) is not None:
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name),
                                          err_msg=f"{what} {name}")


@pytest.mark.parametrize("mode", MODES)
def test_one_launch_equals_one_call_per_piece_in_every_mode(torus, mode):
    vol, path = torus
    cams = [sc.Camera.orbit(vol, azimuth=a, elevation=e, size=(44, 36), zoom=1.6)
            for a, e in ((25, 20), (200, -35))]
    with sc.Scene(sc.read(path), model="trilinear", budget="512KiB", lod=1.0) as scene:
        for cam in cams:
            each, batched, _, stats = _both(scene, cam, **_options(mode))
            what = f"{mode} {cam.position.round(2)}"
            assert len(batched.stats["cut_levels"]) >= 2, what  # levels meet in this cut
            assert stats["pieces_changed_at_seams"] > 0, what  # two grid types in the launch
            if mode == "iso":
                assert np.isfinite(batched.depth).sum() > 100, what
            _assert_identical(each, batched, what)


@pytest.mark.parametrize("model", ["bspline2", "s31"])
def test_seam_closure_inside_the_launch_equals_the_per_piece_closure(torus, model):
    """Models whose levels do not nest: the closure ends rays on level faces, the same rays
    with the same depths and normals in both paths."""
    vol, path = torus
    hits = 0
    with sc.Scene(sc.read(path), model=model, budget="512KiB", lod=1.0) as scene:
        for azimuth in (25, 110, 200, 290):
            cam = sc.Camera.orbit(vol, azimuth=azimuth, elevation=30, size=(48, 40), zoom=1.6)
            each, batched, each_stats, stats = _both(scene, cam, **_options("iso"))
            assert stats["seam_closure_hits"] == each_stats["seam_closure_hits"]
            hits += stats["seam_closure_hits"]
            _assert_identical(each, batched, f"{model} azimuth {azimuth}")
    assert hits > 0  # the closure did end rays (else this test checks nothing of it)


def test_clip_planes_and_a_camera_tile(torus):
    """Clipped rays, and a tile of the image traced into its own state (a sort-last worker)."""
    from splinecast.multires.scenes.multiscale import pieces_of
    from splinecast.render.iso import Iso
    from splinecast.render.segment import counters, new_state

    vol, path = torus
    cam = sc.Camera.orbit(vol, azimuth=60, elevation=25, size=(48, 40), zoom=1.6)
    options = {**_options("iso"), "clip": [(0.3, -1.0, 0.2, 0.1)]}
    with sc.Scene(sc.read(path), model="trilinear", budget="512KiB", lod=1.0) as scene:
        each, batched, _, _ = _both(scene, cam, **options)
        _assert_identical(each, batched, "clipped")
        plain = scene.render(cam, **_options("iso"))
        assert not np.array_equal(np.isfinite(plain.depth), np.isfinite(batched.depth))
        # A tile: the pieces of the last frame traced into a tile's state, both ways.
        tile = cam.tile(7, 5, 30, 21)
        setup = Iso(0.0, inside="low")
        pieces = pieces_of(scene.stream.frame(cam, None, wait=True))
        assert len({p.level for p in pieces}) >= 2
        results = []
        for batched_flag in (False, True):
            scene.renderer.batched = batched_flag
            state = new_state(setup, tile)
            stats = counters(tile.height, tile.width)
            scene.renderer.trace(pieces, setup, tile, state, stats)
            results.append((state, stats))
        for a, b in zip(results[0][0] + results[0][1], results[1][0] + results[1][1],
                        strict=True):
            np.testing.assert_array_equal(a, b)
        assert np.isfinite(results[1][0][0]).sum() > 50


def _pixels_whose_rays_meet(cam: sc.Camera, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Brute force: which pixels' rays (``Camera.rays``, a slab test per axis) meet the box.
    Perspective rays start at the eye; orthographic ones are whole lines."""
    origins, directions = cam.rays()
    directions = np.where(directions == 0.0, 1e-300, directions)
    with np.errstate(over="ignore"):
        t0, t1 = (lo - origins) / directions, (hi - origins) / directions
    near = np.minimum(t0, t1).max(axis=-1)
    far = np.maximum(t0, t1).min(axis=-1)
    return far >= (near if cam.ortho else np.maximum(near, 0.0))


def test_screen_rects_hold_every_ray_that_meets_the_box():
    """Every pixel whose ray meets a box lies in the box's rectangle (what the one-launch
    renderer relies on: it traces only there), a box no ray meets may be left out, and a box in
    front of the eye, inside the image and not thin gets a rectangle at most a few pixels wider
    than its rays' (the corners' projection plus the one-pixel margin). Boxes in front of,
    around and behind the eye; perspective, a tile of one, and orthographic cameras;
    ``screen_rect`` for single boxes."""
    rng = np.random.default_rng(5)
    lo = rng.uniform(-3.0, 3.0, (150, 3))
    hi = lo + rng.uniform(0.01, 2.0, (150, 3))
    tight = False
    for cam in (sc.Camera((0.0, 0.0, 4.0), (0.0, 0.0, 0.0), size=(64, 48)),
                sc.Camera((1.0, 2.0, 5.0), (0.0, 0.0, 0.0), size=(50, 40)).tile(10, 5, 30, 20),
                sc.Camera((0.0, 0.0, 4.0), (0.0, 0.0, 0.0), ortho=True, ortho_height=4.0,
                          size=(40, 40))):
        rects, seen = screen_rects(cam, lo, hi)
        kinds = set()
        for n in range(len(lo)):
            hits = _pixels_whose_rays_meet(cam, lo[n], hi[n])
            one = screen_rect(cam, lo[n], hi[n])
            assert seen[n] == (one is not None), n
            if not hits.any():
                kinds.add("none" if not seen[n] else "empty")
                continue
            assert seen[n], n
            c0, r0, c1, r1 = rects[n]
            assert one == (c0, r0, c1 - c0, r1 - r0), n
            rows, cols = np.nonzero(hits)
            assert c0 <= cols.min() and cols.max() < c1 and r0 <= rows.min() and rows.max() < r1, n
            corners = np.array([[(lo[n], hi[n])[(b >> a) & 1][a] for a in range(3)]
                                for b in range(8)])
            in_front = cam.ortho or np.all((corners - cam.position) @ cam.forward > 0.1)
            # (A rectangle cut by the image's edges may span rows the box reaches only outside
            # the image's columns, and the other way round.)
            # And a sliver of a box can fall between pixel centres over more than the margin.
            inside = c0 > 0 and r0 > 0 and c1 < cam.width and r1 < cam.height
            thick = np.all(hi[n] - lo[n] >= 0.5)  # several pixels on every camera here
            if in_front and inside and thick:
                kinds.add("tight")
                assert c1 - c0 <= cols.max() - cols.min() + 1 + 4, n
                assert r1 - r0 <= rows.max() - rows.min() + 1 + 4, n
            kinds.add("whole" if (c1 - c0, r1 - r0) == (cam.width, cam.height) else "part")
        assert "part" in kinds and ("none" in kinds or cam.ortho), kinds
        tight |= "tight" in kinds
    assert tight  # the tightness bound was checked at all


def test_tile_lists_name_every_overlapping_piece_in_order():
    """Each tile's list is exactly the pieces whose rectangle meets it, ascending (a brute-force
    overlap test of every tile and rectangle): rectangles at the image's edges, one pixel
    wide, covering the image, and empty ones."""
    from splinecast.render.pieces_driver import TILE, tile_lists

    rng = np.random.default_rng(7)
    height, width = 3 * TILE + 5, 5 * TILE + 11
    c0 = rng.integers(0, width, 300)
    r0 = rng.integers(0, height, 300)
    c1 = np.minimum(c0 + rng.integers(0, 3 * TILE, 300), width)
    r1 = np.minimum(r0 + rng.integers(0, 3 * TILE, 300), height)
    rects = np.stack([c0, r0, c1, r1], axis=1)
    rects[:3] = [(0, 0, width, height), (width - 1, height - 1, width, height), (4, 4, 4, 9)]
    start, pieces = tile_lists(rects, height, width)
    ncol = -(-width // TILE)
    nrow = -(-height // TILE)
    assert len(start) == nrow * ncol + 1
    for tr in range(nrow):
        for tc in range(ncol):
            y0, x0 = tr * TILE, tc * TILE
            y1, x1 = min(y0 + TILE, height), min(x0 + TILE, width)
            expect = [p for p, (a, b, c, d) in enumerate(rects)
                      if max(a, x0) < min(c, x1) and max(b, y0) < min(d, y1)]
            t = tr * ncol + tc
            assert pieces[start[t]:start[t + 1]].tolist() == expect
