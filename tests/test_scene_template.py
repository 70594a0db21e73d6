"""The render template: a scene kind that supplies only its pieces renders every mode.

The kinds below are written here, as a newcomer would write one: a :class:`SceneTemplate`
subclass with a ``trace`` method. The reference is :class:`splinecast.Scene` on the same volume,
a second code path (its own grid, block flags, active box and per-pixel tracer).
"""

from __future__ import annotations

import inspect
import time
from typing import Any

import numpy as np
import pytest

import splinecast as sc
from splinecast.render.modes import MODE_NAMES
from splinecast.render.segment import (
    brick_grid,
    counters,
    finish_state,
    make_grid,
    new_state,
    render_grid,
    trace_segment,
)
from splinecast.render.template import SceneTemplate, Traced


class OneGridScene(SceneTemplate):
    """The whole volume as one grid, every block traced (no flags, no active box)."""

    def __init__(self, volume: sc.Volume, model: str = "trilinear") -> None:
        self.volume = volume
        self.model = sc.MODELS[model](volume)

    def trace(self, request: Any, camera: sc.Camera) -> Traced:
        grid = make_grid(self.model)
        if request.iso is not None:
            grid.hierarchy.classify(request.iso)
        start = time.perf_counter()
        out, counts = render_grid(grid, request.setup, camera, request.planes)
        return Traced(out, counts, start)


class HalvesScene(SceneTemplate):
    """The volume as two bricks (cells split across the first axis), traced front to back with
    the mode's state carried from one to the other; ``split`` is a frame option."""

    def __init__(self, volume: sc.Volume, model: str = "trilinear") -> None:
        self.volume = volume
        self.model = sc.MODELS[model](volume)

    def trace(self, request: Any, camera: sc.Camera, *, split: float = 0.5) -> Traced:
        cells = make_grid(self.model).n_cells
        cut = max(1, min(int(cells[0]) - 1, round(split * int(cells[0]))))
        low = brick_grid(self.model, (0, 0, 0), (cut, cells[1], cells[2]))
        high = brick_grid(self.model, (cut, 0, 0), tuple(int(c) for c in cells))
        plane = self.volume.index_to_world(np.array([cut - self.model.shift, 0.0, 0.0]))[0]
        front_low = (camera.forward[0] >= 0.0 if camera.ortho
                     else camera.position[0] <= plane)
        start = time.perf_counter()
        setup = request.setup
        state = new_state(setup, camera)
        counts = counters(camera.height, camera.width)
        for grid in (low, high) if front_low else (high, low):
            if request.iso is not None:
                grid.hierarchy.classify(request.iso)
            trace_segment(grid, setup, camera, state, counts, request.planes)
        return Traced(finish_state(setup, state, camera), counts, start)


@pytest.fixture(scope="module")
def volume() -> sc.Volume:
    return sc.demo("sphere", size=20)


def _options(name: str, bricks: bool = False) -> dict[str, Any]:
    if name == "iso":
        return {"iso": 0.0}
    if name == "dvr" and bricks:
        # Samples at fixed steps along the ray (not from each brick's entry), as the sort-last
        # tests compare brick-by-brick DVR.
        return {"dvr": sc.DVRSettings(step=0.5)}
    return {}


@pytest.mark.parametrize("name", list(MODE_NAMES))
def test_a_kind_supplying_one_grid_equals_scene(volume, name):
    cam = sc.Camera.orbit(volume, azimuth=30, elevation=20, size=(40, 32))
    ref = sc.Scene(volume).render(cam, name, samples=1, **_options(name))
    got = OneGridScene(volume).render(cam, name, samples=1, **_options(name))
    assert got.stats["mode"] == ref.stats["mode"] == name
    for buffer in ("rgba", "depth", "value", "position", "normal", "face"):
        a, b = getattr(got, buffer), getattr(ref, buffer)
        assert (a is None) == (b is None), buffer
        if a is not None:
            np.testing.assert_array_equal(a, b, err_msg=buffer)
    if name != "aip":  # a projection of background only shows the background colour
        assert np.any(ref.rgba[..., :3] != ref.rgba[0, 0, :3])


@pytest.mark.parametrize("name", list(MODE_NAMES))
def test_a_kind_supplying_two_bricks_matches_scene(volume, name):
    cam = sc.Camera.orbit(volume, azimuth=-40, elevation=25, size=(40, 32))
    ref = sc.Scene(volume).render(cam, name, samples=1, **_options(name, bricks=True))
    scene = HalvesScene(volume)
    got = scene.render(cam, name, samples=1, split=0.4, **_options(name, bricks=True))
    np.testing.assert_allclose(got.rgba, ref.rgba, atol=1e-6)
    hit = np.isfinite(ref.depth)
    np.testing.assert_array_equal(np.isfinite(got.depth), hit)
    np.testing.assert_allclose(got.depth[hit], ref.depth[hit], rtol=1e-9, atol=1e-9)
    if ref.value is not None:
        np.testing.assert_allclose(got.value, ref.value, rtol=1e-9, atol=1e-9)


def test_the_template_gives_each_kind_its_signature(volume):
    params = inspect.signature(HalvesScene.render).parameters
    assert params["split"].default == 0.5 and params["mode"].default == "iso"
    assert list(inspect.signature(sc.Scene.render).parameters)[:3] == ["self", "camera", "mode"]
    assert "split" not in inspect.signature(OneGridScene.render).parameters
    cam = sc.Camera.orbit(volume, size=(8, 8))
    with pytest.raises(TypeError, match="unexpected keyword argument 'spilt'"):
        HalvesScene(volume).render(cam, spilt=0.5)
    with pytest.raises(sc.ParameterError, match="outside the data range"):
        OneGridScene(volume).render(cam, iso=1e9)
    with pytest.raises(sc.ParameterError, match="camera"):
        OneGridScene(volume).render("camera")


def test_every_kind_closes_through_the_template(volume):
    """``close()`` and ``with`` come with the template (nothing to release by default), so the
    command line and the viewer close any scene without asking which kind it is."""
    cam = sc.Camera.orbit(volume, size=(8, 8))
    with OneGridScene(volume) as scene:
        assert scene.render(cam, iso=0.0).hit.any()
    scene.close()  # again: closing holds nothing, so it may be repeated
    kinds = [sc.Scene(volume), sc.Scene([volume, volume]),
             sc.Scene(sc.Volume((volume.data > 0).astype(np.uint8)), labels=True)]
    for kind in kinds:
        assert isinstance(kind, SceneTemplate)
        with kind as entered:
            assert entered is kind
    assert "close" not in vars(sc.Scene) and "close" in vars(SceneTemplate)
