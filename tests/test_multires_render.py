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
import warnings
from pathlib import Path

import numpy as np
import pytest
from reference import smooth_noise

pytest.importorskip("zarr", reason="the multires extra (zarr) is not installed")
pytest.importorskip("dask", reason="the multires extra (dask) is not installed")

import splinecast as sc  # noqa: E402
from splinecast.io.synthetic import SPHERE_RADIUS, sphere_sdf, torus_sdf  # noqa: E402
from splinecast.multires.cache import BrickUnavailableWarning  # noqa: E402
from splinecast.multires.scene import MultiscaleScene  # noqa: E402

MODELS = ["trilinear", "bspline1", "bspline2", "bspline3", "qss", "s31"]
MODES = ["iso", "multi", "mip", "minip", "dvr"]
B = 8


@pytest.fixture(scope="module")
def noise(tmp_path_factory) -> tuple[sc.Volume, Path]:
    """Smooth noise (float64, sizes that are not powers of two) and its pyramid of 8^3 bricks."""
    vol = sc.Volume(smooth_noise((27, 23, 21), seed=3, sigma=2.0))
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


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("mode", MODES)
def test_whole_finest_level_in_budget_equals_the_in_memory_render(noise, model, mode):
    """lod so fine that every brick is refined to level 0, a budget that holds them all."""
    vol, path = noise
    reference = sc.Scene(vol, model=model)
    options = _options(mode, vol)
    with sc.Scene(sc.read(path), model=model, budget="64MiB", lod=1e-6) as scene:
        for cam in _cameras(vol):
            whole = reference.render(cam, **options)
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
