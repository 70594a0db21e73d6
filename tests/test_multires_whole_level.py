"""A multiscale scene holding level 0 whole (:mod:`splinecast.multires.scenes.whole_level`).

References:

- the in-memory :class:`splinecast.Scene` of the same volume with the same options: the frame of
  a view whose cut is level 0 everywhere is that scene's, bit for bit;
- the same store drawn from bricks (``whole_level=False``): equal within the tolerances that
  hold between bricks and a whole volume (depths 1e-9 voxels, colours 1e-6, MIP 1e-12;
  ``tests/test_multires_render.py`` checks those against the in-memory render for every model);
- views it must not take: a cut with coarser bricks, a level 0 larger than the budget, a damaged
  chunk (the bricks then substitute and name it, as without it).
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from reference import smooth_noise

pytest.importorskip("zarr", reason="the multires extra (zarr) is not installed")

import splinecast as sc  # noqa: E402
from splinecast.multires.scenes.multiscale import MultiscaleScene  # noqa: E402
from splinecast.multires.store.cache import BrickUnavailableWarning  # noqa: E402

B = 8


@pytest.fixture(scope="module")
def noise(tmp_path_factory) -> tuple[sc.Volume, Path]:
    """Smooth noise (float32, sides that are not powers of two) and its pyramid of 8^3 bricks."""
    vol = sc.Volume(smooth_noise((27, 23, 21), seed=3, sigma=2.0).astype(np.float32))
    path = tmp_path_factory.mktemp("noise") / "noise.zarr"
    sc.build_pyramid(vol, path, brick=B, shard=16, progress=False)
    return vol, path


def _camera(size: tuple[int, int] = (26, 22)) -> sc.Camera:
    return sc.Camera((45.0, -24.0, 33.0), (13.0, 11.0, 10.0), size=size)


def _options(mode: str, vol: sc.Volume) -> dict:
    if mode == "iso":
        return {"mode": "iso", "iso": 0.3, "inside": "high"}
    if mode == "mip":
        return {"mode": "mip", "window": vol.value_range, "colormap": "gray"}
    tf = sc.TransferFunction([(-0.8, 0.0), (-0.2, 0.4), (0.2, 0.0), (0.7, 0.6)],
                             domain=(-3.0, 3.0))
    return {"mode": "dvr", "tf": tf, "dvr": sc.DVRSettings(step=0.4)}


@pytest.mark.parametrize("mode", ["iso", "mip", "dvr"])
def test_a_cut_of_level_0_in_budget_is_drawn_from_level_0_held_whole(noise, mode):
    vol, path = noise
    cam = _camera()
    options = _options(mode, vol)
    whole = sc.Scene(vol).render(cam, samples=1, **options)
    with sc.Scene(sc.read(path), budget="64MiB", lod=1e-6) as scene:
        frame = scene.render(cam, complete=True, **options)
        st = frame.stats
        assert st["whole_level"] and st["complete"] and st["cut_levels"] == {0: st["cut_bricks"]}
        assert st["resident_bytes"] >= vol.data.nbytes and st["requested"] == 0
        # The same volume, the same options, the same code: the same image, bit for bit.
        for name in ("rgba", "depth", "value"):
            a, b = getattr(frame, name), getattr(whole, name)
            if b is not None:
                np.testing.assert_array_equal(a, b, err_msg=name)
        again = scene.render(cam, **options)  # a steady view: held, nothing read
        assert again.stats["whole_level"] and again.stats["loaded"] == st["loaded"]
        np.testing.assert_array_equal(again.rgba, frame.rgba)
        at_once = scene.render(cam, wait=False, **options)  # held: drawn at once too
        assert at_once.stats["whole_level"]
    with sc.Scene(sc.read(path), budget="64MiB", lod=1e-6, whole_level=False) as bricks:
        drawn = bricks.render(cam, complete=True, **options)
        assert not drawn.stats["whole_level"] and drawn.stats["complete"]
    if mode == "mip":
        np.testing.assert_allclose(frame.value, drawn.value, rtol=1e-12, atol=1e-12)
    elif mode == "iso":
        hit = np.isfinite(drawn.depth)
        np.testing.assert_array_equal(np.isfinite(frame.depth), hit)
        assert hit.sum() > 20
        np.testing.assert_allclose(frame.depth[hit], drawn.depth[hit], rtol=0, atol=1e-9)
    np.testing.assert_allclose(frame.rgba, drawn.rgba, atol=1e-6)


def test_the_automatic_choices_stay_those_of_the_store(noise):
    """No isovalue given: the store's automatic one (from its coarsest level, as the bricks
    use), not the one level 0 alone would give."""
    vol, path = noise
    cam = _camera()
    with sc.Scene(sc.read(path), budget="64MiB", lod=1e-6) as scene, \
            sc.Scene(sc.read(path), budget="64MiB", lod=1e-6, whole_level=False) as bricks:
        frame = scene.render(cam, complete=True)
        drawn = bricks.render(cam, complete=True)
    assert frame.stats["whole_level"] and not drawn.stats["whole_level"]
    assert frame.stats["iso"] == drawn.stats["iso"]
    hit = np.isfinite(drawn.depth)
    np.testing.assert_array_equal(np.isfinite(frame.depth), hit)
    np.testing.assert_allclose(frame.depth[hit], drawn.depth[hit], rtol=0, atol=1e-9)


def test_views_it_must_not_take_are_drawn_from_bricks(noise):
    vol, path = noise
    cam = _camera()
    options = _options("iso", vol)
    mv = sc.read(path)
    with MultiscaleScene(mv, budget="64MiB", lod=1e-6) as scene:
        assert scene.render(cam, complete=True, **options).stats["whole_level"]
        assert scene.whole is not None and scene.whole.nbytes == vol.data.nbytes
        # A coarse level of detail: the cut has coarser bricks, so level 0 is let go.
        frame = scene.render(cam, lod=50.0, complete=True, **options)
        assert not frame.stats["whole_level"] and set(frame.stats["cut_levels"]) != {0}
        assert scene.whole.nbytes == 0
    # Level 0 (about 52 KB) larger than the budget.
    with MultiscaleScene(mv, budget="40KB", lod=1e-6) as scene:
        assert not scene.render(cam, complete=True, **options).stats["whole_level"]
        assert scene.whole is not None and not scene.whole.fits
    # Not waiting for anything: the first frame does not read level 0.
    with MultiscaleScene(mv, budget="64MiB", lod=1e-6) as scene:
        assert not scene.render(cam, wait=False, **options).stats["whole_level"]


def test_a_damaged_chunk_falls_back_to_the_bricks_that_name_it(noise, tmp_path):
    vol, path = noise
    copy = tmp_path / "damaged.zarr"
    shutil.copytree(path, copy)
    shard = copy / "0" / "c" / "0" / "0" / "0"
    raw = bytearray(shard.read_bytes())
    raw[100:400] = bytes(300)
    shard.write_bytes(bytes(raw))
    with sc.Scene(sc.read(copy), budget="64MiB", lod=1e-6) as scene:
        with pytest.warns(BrickUnavailableWarning, match=r"0/c/0/0/0"):
            frame = scene.render(_camera(), complete=True, timeout=10, **_options("iso", vol))
        st = frame.stats
        assert not st["whole_level"] and st["unavailable"] > 0 and st["substituted"] > 0
        assert scene.whole is not None and "0/c/0/0/0" in scene.whole.failed
        with pytest.raises(sc.ReadError, match=r"0/c/0/0/0"):
            scene.render(_camera(), complete=True, missing="error", **_options("iso", vol))
