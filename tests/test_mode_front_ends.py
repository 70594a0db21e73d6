"""The command line and the viewer ask the mode registry and the scene template, never a name.

A mode that a test registers (a class of its own, declaring the ``Scene.render`` keywords it
reads, what its projection keeps, how its channels composite) is offered at once by ``splinecast
render``, ``movie`` and ``view`` with exactly the options its keywords name; every scene kind
answers the viewer's questions (its model's name, its tile grid, the bricks it read, its modes)
through :class:`splinecast.render.template.SceneTemplate`'s documented attributes.

References: each option's documented keyword (the table below, written from ``--help``), frames
of ``Scene.render`` with the built-in mode the toy mode's kernels are, and values set on the
mode class by the test itself.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import inspect
from collections.abc import Iterator
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest
from PIL import Image

import splinecast as sc
from splinecast.cli import _build_parser, main
from splinecast.cli.render import check_render_args, model_options
from splinecast.render.antialias import DEFAULT_SAMPLES, resolve_samples
from splinecast.render.compose import ADDITIVE, NEAREST_HIT
from splinecast.render.modes import MODES, RenderMode, register_mode
from splinecast.render.template import SceneTemplate
from splinecast.viewer.client import ViewerClient
from splinecast.viewer.data import shown
from splinecast.viewer.server import ViewerServer

ML = "demo:marschner-lobb?size=16"  # values in [0, 1]
SIZE = (20, 16)

#: Every option only some modes read, a valid value of it, and the ``Scene.render`` keyword
#: its help says it sets (``--color`` a surface's colour, the DVR options ``DVRSettings``).
OPTIONS = {
    "--iso": (["--iso", "0.5"], "iso"),
    "--opacity": (["--opacity", "0.5"], "opacity"),
    "--inside": (["--inside", "low"], "inside"),
    "--color": (["--color", "red"], "colors"),
    "--texture": (["--texture", "noise"], "effects"),
    "--shading": (["--shading", "cel"], "effects"),
    "--normals": (["--normals", "exact"], "normals"),
    "--method": (["--method", "sampled"], "method"),
    "--colormap": (["--colormap", "hot"], "colormap"),
    "--window": (["--window", "0,1"], "window"),
    "--tolerance": (["--tolerance", "0.01"], "tolerance"),
    "--tf": (["--tf", "tf.json"], "tf"),
    "--preintegration": (["--preintegration", "none"], "dvr"),
    "--adaptive": (["--adaptive"], "dvr"),
    "--termination": (["--termination", "0.9"], "dvr"),
}


@contextlib.contextmanager
def registered(mode: type[RenderMode]) -> Iterator[type[RenderMode]]:
    """``mode`` in the registry for the ``with`` block only."""
    register_mode(mode)
    try:
        yield mode
    finally:
        del MODES[mode.name]


def toy(keywords: tuple[str, ...]) -> type[RenderMode]:
    """A mode class named ``toy`` reading ``keywords`` (never rendered)."""
    return dataclasses.dataclass(frozen=True)(type("Toy", (RenderMode,), {
        "name": "toy", "summary": "a toy", "keywords": keywords}))


@dataclasses.dataclass(frozen=True)
class ToyAip(sc.Aip):
    """The average intensity projection under another name: a mode the front ends never saw,
    whose frames are ``"aip"``'s."""

    name: ClassVar[str] = "toyaip"
    summary: ClassVar[str] = "a second average intensity projection"


def _accepted(argv: list[str]) -> bool:
    """Whether ``splinecast render`` takes ``argv``'s options (checked as before rendering)."""
    args = _build_parser().parse_args(["render", ML, *argv])
    try:
        check_render_args(args)
    except sc.ParameterError:
        return False
    return True


# ------------------------------------------------------------------------- command line
KEYWORD_SETS = [(), ("window", "colormap"), ("tf", "dvr"), ("window", "colormap", "method",
                "step", "tolerance"), ("iso", "inside", "opacity", "colors", "normals",
                "effects", "method", "step")]


@pytest.mark.parametrize("keywords", KEYWORD_SETS, ids=lambda k: "+".join(k) or "none")
def test_the_cli_takes_exactly_the_options_a_registered_mode_reads(keywords):
    with registered(toy(keywords)):
        for flag, (argv, keyword) in OPTIONS.items():
            assert _accepted(["--mode", "toy", *argv]) == (keyword in keywords), flag
    assert "toy" not in MODES


@pytest.mark.parametrize("name", list(MODES))
def test_the_cli_takes_exactly_the_options_each_built_in_mode_reads(name):
    keywords = MODES[name].keywords
    for flag, (argv, keyword) in OPTIONS.items():
        if flag == "--method" and "sampled" not in MODES[name].methods:
            continue  # refused by the mode object itself
        assert _accepted(["--mode", name, *argv]) == (keyword in keywords), (name, flag)


@pytest.mark.parametrize("keywords, method, takes_step", [
    (("tf", "dvr"), "exact", True),  # the DVR settings' step
    (("window", "method", "step"), "sampled", True),
    (("window", "method", "step"), "exact", False),
    (("window", "colormap"), "exact", False),
])
def test_step_follows_the_mode_s_keywords(keywords, method, takes_step):
    with registered(toy(keywords)):
        extra = ["--method", method] if method != "exact" else []
        assert _accepted(["--mode", "toy", "--step", "0.5", *extra]) == takes_step


def test_a_registered_projection_renders_from_the_cli_with_its_own_name(tmp_path, capsys,
                                                                        monkeypatch):
    """``--mode toyaip`` is offered, takes ``--window``, names the output after itself, and
    renders the frame of the built-in ``aip`` it shares its kernels with."""
    monkeypatch.chdir(tmp_path)
    with registered(ToyAip):
        render = _build_parser()._subparsers._group_actions[0].choices["render"]
        assert "toyaip: a second average intensity projection" in render.format_help()
        code = main(["render", ML, "--mode", "toyaip", "--window", "0.2,0.8", "--fit", "box",
                     "--size", "x".join(map(str, SIZE))])
        out, err = capsys.readouterr()
        assert code == 0, err
        assert "--step" not in err
        code = main(["render", ML, "--mode", "toyaip", "--step", "0.5", "-o", "no.png"])
        refused = capsys.readouterr().err
    assert code == 2 and "--step applies to" in refused and not Path("no.png").exists()
    png = Path(out.strip())
    assert png == tmp_path / "marschner-lobb-toyaip.png"
    vol = sc.read(ML)
    camera = sc.Camera.orbit(vol, azimuth=30, elevation=20, size=SIZE, fit="box")
    expected = sc.Scene(vol).render(camera, "aip", window=(0.2, 0.8), samples=1)
    np.testing.assert_array_equal(np.asarray(Image.open(png)), expected.to_uint8())


@pytest.mark.parametrize("declared", [(), ("prefilter",), ("root_finder", "iterations")])
def test_the_cli_takes_the_model_options_a_model_declares(declared, monkeypatch):
    class Toy(sc.MODELS["trilinear"]):
        option_names: ClassVar[tuple[str, ...]] = declared

    monkeypatch.setitem(sc.MODELS, "toy", Toy)
    for argv, name in ((["--prefilter"], "prefilter"), (["--root-finder", "sturm"], "root_finder"),
                       (["--iterations", "5"], "iterations")):
        args = _build_parser().parse_args(["render", ML, "--model", "toy", *argv])
        try:
            options = model_options(args)
        except sc.ParameterError as exc:
            assert name not in declared and "does not apply to model toy" in str(exc)
        else:
            assert name in declared and name in options


def test_every_model_declares_the_options_it_is_made_with():
    vol = sc.demo("sphere", size=8)
    for cls in sc.MODELS.values():
        for option in cls.option_names:  # each one a keyword the model is made with
            default = inspect.signature(cls).parameters[option].default
            cls(vol, **{option: default})
    assert {"prefilter", "root_finder", "iterations"} <= set(sc.MODELS["bspline3"].option_names)
    assert sc.MODELS["trilinear"].option_names == ()


def test_antialiasing_by_default_follows_the_modes_that_draw_surfaces(monkeypatch):
    assert resolve_samples(None, "iso") == resolve_samples(None, sc.MultiIso) == DEFAULT_SAMPLES
    assert resolve_samples(None, sc.Aip()) == resolve_samples(None, "mip") == 1
    monkeypatch.setattr(sc.Aip, "surfaces", True)
    assert resolve_samples(None, "aip") == DEFAULT_SAMPLES
    render = _build_parser()._subparsers._group_actions[0].choices["render"]
    assert f"(default {DEFAULT_SAMPLES} for --mode iso/aip," in " ".join(
        render.format_help().split())


@pytest.fixture(scope="module")
def empty_minimum(tmp_path_factory) -> Path:
    """A bright ball inside a border of background (0): every ray enters through the
    background, so its minimum is the background value and minIP draws nothing."""
    z, y, x = np.mgrid[:14, :14, :14]
    data = np.where((x - 6.5) ** 2 + (y - 6.5) ** 2 + (z - 6.5) ** 2 < 16, 1.0, 0.0)
    path = tmp_path_factory.mktemp("empty") / "ball.npy"
    np.save(path, data.astype(np.float32))
    return path


@pytest.mark.parametrize("projection", ["minimum", "least value", None])
def test_nothing_drawn_names_what_the_mode_says_its_projection_keeps(projection, empty_minimum,
                                                                    tmp_path, capsys,
                                                                    monkeypatch):
    monkeypatch.setattr(sc.MinIp, "projection", projection)
    code = main(["render", str(empty_minimum), "--mode", "minip", "--size", "16x12",
                 "-o", str(tmp_path / "out.png")])
    err = capsys.readouterr().err
    assert code == 0, err
    said = f"nothing drawn: every ray's {projection} is the background value 0 "
    if projection is None:
        assert "nothing drawn" not in err
    else:
        assert said in err, err


# ------------------------------------------------------------------------------ viewer
def test_the_viewer_offers_a_registered_mode_and_renders_it():
    vol = sc.demo("marschner-lobb", size=16)
    camera = {"azimuth": 40.0, "elevation": 25.0}

    async def check() -> None:
        async with ViewerServer(vol) as server, ViewerClient(server.url) as client:
            hello = client.hello
            assert hello["modes"] == list(MODES) and hello["modes"][-1] == "toyaip"
            assert hello["mode_keywords"]["toyaip"] == ["window", "colormap"]
            assert hello["mode_compositing"]["toyaip"] == ADDITIVE.summary
            assert hello["mode_compositing"]["iso"] == NEAREST_HIT.summary
            assert hello["auto_window"]["toyaip"] == hello["auto_window"]["aip"]
            ident = await client.render({"mode": "toyaip", "window": [0.2, 0.8],
                                         "camera": camera, "size": list(SIZE)})
            frame = await client.frame(ident)
            expected = sc.Scene(vol).render(sc.Camera.orbit(vol, size=SIZE, **camera), "aip",
                                            window=(0.2, 0.8)).to_uint8()
            np.testing.assert_array_equal(frame.image, expected)

    with registered(ToyAip):
        asyncio.run(check())


# ------------------------------------------------------------------------ scene template
def test_every_scene_kind_answers_the_front_ends_questions():
    vol = sc.demo("sphere", size=12)
    scene = sc.Scene(vol, model="bspline2")
    assert scene.model_name == "bspline2" and scene.modes is None
    assert scene.bricks_loaded() is None
    columns, rows = scene.tile_shape
    assert columns >= 0 and rows >= 1

    labels = sc.Scene(sc.Volume((vol.data < 0).astype(np.uint8)), model="bspline1", labels=True)
    assert labels.model_name == "bspline1"
    assert labels.modes == ("iso",) and labels.default_mode in labels.modes
    assert labels.tile_shape == (0, 1) and labels.bricks_loaded() is None
    with pytest.raises(sc.ParameterError, match=r"\(mode 'iso'\), not mode 'mip'"):
        labels.render(sc.Camera.orbit(vol, size=(8, 8)), "mip")

    channels = sc.Scene([vol, vol], model="bspline2")
    assert channels.model_name == "bspline2" and channels.modes is None
    # Two scenes of one model on one grid trace the same tiles: the channels' are theirs.
    assert channels.tile_shape == scene.tile_shape

    class Bare(SceneTemplate):
        """A kind that declares nothing but its model: the template's defaults."""

        model = sc.MODELS["trilinear"](vol)

    bare = Bare()
    assert (bare.model_name, bare.tile_shape, bare.bricks_loaded(), bare.modes) == (
        "trilinear", (0, 1), None, None)


def test_the_template_refuses_a_mode_the_scene_kind_does_not_declare():
    """A kind declaring ``modes`` renders those, by name or as mode objects, and the template
    refuses any other before tracing, naming the mode and the ones allowed; what it accepts is
    the frame of a kind declaring nothing."""

    class IsoOnly(sc.Scene):
        """An in-memory scene that declares one mode and nothing else of its own."""

        modes: ClassVar[tuple[str, ...] | None] = ("iso",)

    vol = sc.demo("sphere", size=12)
    camera = sc.Camera.orbit(vol, size=(16, 12))
    scene = IsoOnly(vol)
    for mode in ("mip", sc.Mip(), "dvr"):
        with pytest.raises(sc.ParameterError) as refused:
            scene.render(camera, mode)
        name = mode if isinstance(mode, str) else mode.name
        assert str(refused.value) == (f"IsoOnly renders its own modes (mode 'iso'), "
                                      f"not mode {name!r}")
    expected = sc.Scene(vol).render(camera, "iso", iso=0.0)
    accepted = [scene.render(camera, "iso", iso=0.0), scene.render(camera, sc.Iso(iso=0.0)),
                scene.render(camera, iso=0.0)]  # the last: the default mode, declared
    for frame in accepted:
        np.testing.assert_array_equal(frame.rgba, expected.rgba)
        np.testing.assert_array_equal(frame.depth, expected.depth)

    class Reasoned(IsoOnly):
        modes_reason: ClassVar[str | None] = "this kind draws surfaces"

    with pytest.raises(sc.ParameterError, match=r"^this kind draws surfaces \(mode 'iso'\), "
                                                r"not mode 'mip'$"):
        Reasoned(vol).render(camera, "mip")
    # The viewer offers a scene given to it only the modes its kind declares.
    assert shown(scene).modes == ("iso",)
    assert shown(sc.Scene(vol)).modes == tuple(MODES)
