"""The lists of implemented (model, mode) pairs in ``pairs.py`` are exact: every listed pair
renders, every other pair is refused with a ParameterError (when the kernel rewrite makes one
render, this test asks for it to be listed, so the per-pair tests start covering it)."""

from __future__ import annotations

import pytest
from pairs import ALL_MODELS, missing_pairs, pairs

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


@pytest.mark.parametrize("model, mode", missing_pairs())
def test_unlisted_pairs_are_refused(model, mode):
    with pytest.raises(sc.ParameterError, match=model):
        _render(model, mode)
