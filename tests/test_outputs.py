"""Optional per-pixel outputs (``Scene.render(..., outputs=...)``, issue 15).

The reference is the render with every output: a render that fills fewer buffers must give the
same values, bit for bit, in the buffers it fills, ``None`` for the others, and leave out the
summary numbers that need a missing buffer.
"""

from __future__ import annotations

import numpy as np
import pytest

import splinecast as sc
from splinecast.errors import ParameterError

BUFFERS = ("rgba", "depth", "position", "normal", "face", "cells_visited", "cells_tested",
           "blocks_skipped", "value")


@pytest.fixture(scope="module")
def scene() -> sc.Scene:
    return sc.Scene(sc.demo("sphere", size=24))


@pytest.fixture(scope="module")
def camera(scene: sc.Scene) -> sc.Camera:
    return sc.Camera.orbit(scene.volume, azimuth=30, elevation=20, size=(40, 30))


MODES = {
    "iso": {"iso": 0.0},
    "multi-iso": {"iso": [-0.2, 0.0]},
    "mip": {"mode": "mip"},
    "dvr": {"mode": "dvr"},
    "aip": {"mode": "aip"},
}


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and a.dtype == b.dtype and np.array_equal(a, b, equal_nan=True)


@pytest.mark.parametrize("mode", list(MODES))
@pytest.mark.parametrize("outputs", [("rgba",), ("rgba", "depth"), ("depth", "position"),
                                     ("normal", "face", "stats")])
def test_requested_buffers_equal_the_full_render(scene, camera, mode, outputs):
    full = scene.render(camera, **MODES[mode])
    part = scene.render(camera, **MODES[mode], outputs=outputs)
    kept = set(outputs) | ({"cells_visited", "cells_tested", "blocks_skipped"}
                           if "stats" in outputs else set())
    for name in BUFFERS:
        mine, ref = getattr(part, name), getattr(full, name)
        if name in kept and ref is not None:
            assert mine is not None and _same(mine, ref), name
        else:
            assert mine is None, name
    assert part.size == full.size == (40, 30)
    # "hits" counts the depth buffer: there when asked for, or when antialiasing needed it.
    assert ("hits" in part.stats) == ("depth" in outputs or "antialiased" in part.stats)
    if "depth" in outputs:
        assert part.stats["hits"] == full.stats["hits"] > 0
    stat_keys = {"mean_cells_visited", "mean_samples", "mean_layers"} & set(full.stats)
    for key in stat_keys:
        assert (key in part.stats) == ("stats" in outputs)
        if "stats" in outputs:
            assert part.stats[key] == full.stats[key]


def test_mip_value_alone(scene, camera):
    full = scene.render(camera, mode="mip")
    part = scene.render(camera, mode="mip", outputs=["value"])
    assert part.rgba is None and part.depth is None
    assert _same(part.value, full.value)


def test_surface_effects_with_colour_only(scene, camera):
    effects = sc.SurfaceEffects(texture="checker", scale=0.1)
    full = scene.render(camera, iso=0.0, effects=effects)
    part = scene.render(camera, iso=0.0, effects=effects, outputs=("rgba",))
    assert _same(part.rgba, full.rgba)
    assert part.position is None and part.normal is None and part.face is None


def test_missing_buffers_say_what_to_request(scene, camera, tmp_path):
    frame = scene.render(camera, iso=0.0, outputs="rgba")
    with pytest.raises(ParameterError, match="depth"):
        _ = frame.hit
    with pytest.raises(ParameterError, match="depth"):
        frame.save_depth(tmp_path / "d.npy")
    assert not (tmp_path / "d.npy").exists()
    depth_only = scene.render(camera, iso=0.0, outputs=("depth",))
    with pytest.raises(ParameterError, match="rgba"):
        depth_only.save(tmp_path / "c.png")
    assert not (tmp_path / "c.png").exists()
    assert depth_only._repr_png_() is None


@pytest.mark.parametrize("bad", [("rgba", "colour"), (), 3])
def test_bad_outputs_name_the_parameter(scene, camera, bad):
    with pytest.raises(ParameterError, match="outputs"):
        scene.render(camera, iso=0.0, outputs=bad)
