"""Mode objects and their registry; models' declared capabilities.

A mode object (``sc.Iso``, ``sc.MultiIso``, ``sc.Mip``, ``sc.MinIp``, ``sc.Dvr``) renders the
same frame as its name with the same options; the registry is the one list of modes the front
ends read; every model answers the capability questions itself.
"""

import dataclasses
import inspect
from typing import ClassVar

import numpy as np
import pytest

import splinecast as sc
from splinecast.models.base import ReconstructionModel
from splinecast.render.modes import (
    MODE_NAMES,
    MODES,
    RENDER_DEFAULTS,
    RenderMode,
    build_mode,
    register_mode,
)


@pytest.fixture(scope="module")
def sphere():
    vol = sc.demo("sphere", size=16)
    return sc.Scene(vol), sc.Camera.orbit(vol, azimuth=30, elevation=20, size=(24, 16))


def test_the_registry_names_the_modes_scene_render_takes():
    # The built-in modes come first; a mode module adds its own (register_mode), and the names
    # every front end reads follow the registry, also when taken before the module registered.
    assert tuple(MODE_NAMES)[:4] == ("iso", "mip", "minip", "dvr")
    assert MODE_NAMES == tuple(MODES) == tuple(sc.scene.MODES)
    assert all(issubclass(cls, RenderMode) and cls.name == name for name, cls in MODES.items())
    assert all(cls.summary for cls in MODES.values())


def test_a_registered_mode_joins_every_list():
    @dataclasses.dataclass(frozen=True)
    class Toy(RenderMode):
        name: ClassVar[str] = "toy"
        summary: ClassVar[str] = "a toy"

    try:
        register_mode(Toy)
        assert MODE_NAMES[-1] == "toy" and "toy" in sc.scene.MODES
        assert len(MODE_NAMES) == len(MODES)
    finally:
        del MODES["toy"]
    assert "toy" not in MODE_NAMES
    with pytest.raises(TypeError, match="taken by Mip"):
        register_mode(type("Other", (sc.Mip,), {"name": "mip"}))


def test_render_defaults_are_scene_render_defaults():
    params = inspect.signature(sc.Scene.render).parameters
    assert {k: params[k].default for k in RENDER_DEFAULTS} == RENDER_DEFAULTS


@pytest.mark.parametrize("obj, name, options", [
    (sc.Iso(0.1), "iso", {"iso": 0.1}),
    (sc.Iso(0.1, method="sampled", step=0.5), "iso", {"iso": 0.1, "method": "sampled",
                                                      "step": 0.5}),
    (sc.MultiIso([-0.2, 0.2], opacity=[0.5, 1.0]), "iso", {"iso": [-0.2, 0.2],
                                                          "opacity": [0.5, 1.0]}),
    (sc.Mip(window=(-1.0, 1.0)), "mip", {"window": (-1.0, 1.0)}),
    (sc.MinIp(window=(-1.0, 1.0), method="slices"), "minip", {"window": (-1.0, 1.0),
                                                              "method": "slices"}),
    (sc.Dvr(sc.TransferFunction([[-1, 0], [1, 0.5]], (-1, 1))), "dvr",
     {"tf": sc.TransferFunction([[-1, 0], [1, 0.5]], (-1, 1))}),
])
def test_a_mode_object_renders_as_its_name_with_its_options(sphere, obj, name, options):
    scene, cam = sphere
    by_object = scene.render(cam, obj, outputs=("rgba", "depth"))
    by_name = scene.render(cam, mode=name, outputs=("rgba", "depth"), **options)
    np.testing.assert_array_equal(by_object.rgba, by_name.rgba)
    assert by_object.stats["mode"] == name


def test_a_name_with_options_builds_the_mode_object():
    assert build_mode("mip", dict(RENDER_DEFAULTS, window=(0, 1))) == sc.Mip(window=(0, 1))
    assert isinstance(build_mode("iso", dict(RENDER_DEFAULTS, iso=[0.1, 0.2])), sc.MultiIso)


def test_an_option_set_twice_is_refused(sphere):
    scene, cam = sphere
    with pytest.raises(sc.ParameterError, match="iso is an option of the mode object Iso"):
        scene.render(cam, sc.Iso(0.1), iso=0.2)
    with pytest.raises(sc.ParameterError, match="tolerance is for mode='mip' and 'minip'"):
        scene.render(cam, sc.Iso(0.1), tolerance=0.1)


def test_mode_objects_check_their_options_when_made():
    with pytest.raises(sc.ParameterError, match="slices is for mip and minip, not iso"):
        sc.Iso(0.5, method="slices")
    with pytest.raises(sc.ParameterError, match="inside must be 'high' or 'low'"):
        sc.Iso(0.5, inside="up")
    with pytest.raises(sc.ParameterError, match="at least one isovalue"):
        sc.MultiIso([])
    with pytest.raises(sc.ParameterError, match="or slices for mip and minip, got 'fast'"):
        sc.Mip(method="fast")


def test_unknown_modes_are_refused_with_the_registry_list(sphere):
    scene, cam = sphere
    with pytest.raises(sc.ParameterError, match="mode must be one of " + ", ".join(MODES)):
        scene.render(cam, mode="xray")


@pytest.mark.parametrize("name", list(sc.MODELS))
def test_every_model_declares_its_capabilities(name):
    cls = sc.MODELS[name]
    assert issubclass(cls, ReconstructionModel)
    assert cls.border_rule in ("edge", "reflect")
    assert cls.nested_degree in (None, 1, 2, 3)
    assert cls.typical_compile_s > 0
    model = cls(sc.demo("sphere", size=8))
    assert model.value_overshoot >= 0.0
    data = np.zeros((4, 4, 4), np.float32)
    first = np.zeros(3, np.int64)
    out, where = model.prefilter_brick(data, first, (8, 8, 8))
    assert out is data and where is first  # no model prefilters with default options
    classifier = model.active_cell_classifier()
    assert (classifier is not None) == (name in ("s31", "qss"))


def test_brick_refusals_come_from_the_model():
    assert sc.MODELS["bspline3"].brick_refusal({"prefilter": True}).option == "prefilter=True"
    assert sc.MODELS["s31"].brick_refusal({"prefilter": True}) is None
    assert sc.MODELS["trilinear"].brick_refusal({}) is None
