"""The lists of (model, mode) pairs in ``pairs.py`` that the per-pair tests follow name every
model and every mode, and every pair renders."""

from __future__ import annotations

import pytest
from pairs import ALL_MODELS, ALL_MODES, pairs

import splinecast as sc


def _render(model: str, mode: str) -> sc.Frame:
    vol = sc.demo("sphere", size=8)
    cam = sc.Camera.orbit(vol, size=(4, 3))
    scene = sc.Scene(vol, model=model)
    if mode == "multi-iso":
        return scene.render(cam, iso=[-0.2, 0.0])
    if mode == "dvr":
        tf = sc.TransferFunction([(-0.3, 0.0), (0.0, 0.5)], domain=(-0.6, 1.0))
        return scene.render(cam, mode="dvr", tf=tf)
    return scene.render(cam, mode=mode, iso=0.0)


def test_the_lists_name_known_models():
    assert set(ALL_MODELS) == set(sc.MODELS)


@pytest.mark.parametrize("model, mode", pairs())
def test_listed_pairs_render(model, mode):
    assert _render(model, mode).rgba.shape == (3, 4, 4)


def test_every_pair_is_listed():
    assert set(pairs()) == {(model, mode) for model in ALL_MODELS for mode in ALL_MODES}
