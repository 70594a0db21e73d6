"""Every option of ``splinecast render`` changes the output exactly as the equivalent Python call.

For each option the command line is run in-process and its PNG (and depth ``.npy``) is compared
bit for bit with ``Scene(...).render(...)`` called with the settings the option's ``--help``
documents. A second API render *without* the option must differ from it, so an option that the
command line dropped or mapped to something else could not pass. The API side is written out here
from the documented defaults (azimuth 30, elevation 20, fov 30, model trilinear, step 0.25
voxels, 2D pre-integration, colormap gray, ...), not taken from the CLI's code. That the help
texts state those defaults is checked in ``test_cli_help.py``.
"""

from __future__ import annotations

import importlib.metadata
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest
from PIL import Image

import splinecast as sc
from splinecast.cli import main

SIZE = (20, 16)
ML = "demo:marschner-lobb?size=16"  # values in [0, 1], default isovalue 0.5, inside "high"
SPHERE = "demo:sphere?size=16"  # |p| - 0.6, default isovalue 0, inside "low"
NOISE = "demo:noise?size=16"  # smooth seeded noise, values in [0, 1]

# Transfer functions given to --tf (written to JSON by the test).
TF_A = sc.TransferFunction([(0.3, 0.0), (0.5, 0.4), (0.8, 0.9)], domain=(0.0, 1.0),
                           colormap="viridis")
TF_B = sc.TransferFunction([(0.1, 0.0), (0.4, 0.2), (0.6, 0.0)], domain=(0.0, 1.0),
                           colormap="hot")


def dvr(**kw: Any) -> sc.DVRSettings:
    """The CLI's documented DVR values of the options not given when another DVR option is:
    --step 0.25, --preintegration 2d (with no DVR option at all, the library's default)."""
    return sc.DVRSettings(**{"step": 0.25, "preintegration": "2d", **kw})


@dataclass
class Case:
    """One option: the CLI arguments, the equivalent API call, and the API call without it."""

    id: str
    cli: list[str]
    api: dict[str, Any]
    baseline: dict[str, Any]
    src: str = ML


def api_frame(src: str, *, smooth: int | None = None, model: str = "trilinear",
              model_options: dict | None = None, camera: dict | None = None,
              **render: Any) -> sc.Frame:
    """The Python call a ``splinecast render`` command line stands for."""
    vol = sc.read(src)
    if smooth:
        vol = sc.smooth(vol, smooth)
    cam_kw = {"azimuth": 30.0, "elevation": 20.0, "size": SIZE, "fov": 30.0, **(camera or {})}
    if cam_kw.get("fit") == "content":  # what the visible content spans (sc.content_box)
        cam_kw["fit"] = sc.content_box(vol, iso=render.get("iso"))
    cam = sc.Camera.orbit(vol, **cam_kw)
    return sc.Scene(vol, model=model, **(model_options or {})).render(cam, **render)


ISO = {"iso": 0.5}
MULTI = {"iso": [0.3, 0.6]}
CASES = [
    # --- camera -------------------------------------------------------------------------
    Case("size", ["--iso", "0.5", "--size", "13x9"], {**ISO, "camera": {"size": (13, 9)}},
         {**ISO}),
    Case("azimuth", ["--iso", "0.5", "--azimuth", "-70"],
         {**ISO, "camera": {"azimuth": -70.0}}, ISO),
    Case("elevation", ["--iso", "0.5", "--elevation", "55"],
         {**ISO, "camera": {"elevation": 55.0}}, ISO),
    Case("distance", ["--iso", "0.5", "--distance", "2.5"],
         {**ISO, "camera": {"distance": 2.5}}, ISO),
    Case("fov", ["--iso", "0.5", "--fov", "50"], {**ISO, "camera": {"fov": 50.0}}, ISO),
    Case("zoom", ["--iso", "0.5", "--zoom", "1.7"], {**ISO, "camera": {"zoom": 1.7}}, ISO),
    Case("ortho", ["--iso", "0.5", "--ortho"], {**ISO, "camera": {"ortho": True}}, ISO),
    Case("fit", ["--iso", "0.5", "--fit", "content"], {**ISO, "camera": {"fit": "content"}},
         ISO),
    # --- isosurface ---------------------------------------------------------------------
    Case("iso", ["--iso", "0.62"], {"iso": 0.62}, ISO),
    Case("iso-default", [], {"iso": None}, {"iso": 0.62}),  # the demo's default_iso (0.5)
    Case("method-sampled", ["--iso", "0.5", "--method", "sampled", "--step", "2"],
         {**ISO, "method": "sampled", "step": 2.0}, ISO),
    Case("inside", ["--iso", "0", "--inside", "high"], {"iso": 0.0, "inside": "high"},
         {"iso": 0.0}, src=SPHERE),
    # Negative isovalues in every form argparse could take for an option (issue: "--iso -3,3"
    # was "expected one argument").
    Case("iso-negative", ["--iso", "-0.2"], {"iso": -0.2}, {"iso": 0.0}, src=SPHERE),
    # (The outer surface, 0, translucent: the inner one shows through it.)
    Case("iso-negative-list", ["--iso", "-0.3,0", "--opacity", "1,0.5"],
         {"iso": [-0.3, 0.0], "opacity": [1.0, 0.5]},
         {"iso": [-0.2, 0.0], "opacity": [1.0, 0.5]}, src=SPHERE),
    Case("iso-negative-equals", ["--iso=-0.3,0", "--opacity=1,0.5"],
         {"iso": [-0.3, 0.0], "opacity": [1.0, 0.5]},
         {"iso": [-0.2, 0.0], "opacity": [1.0, 0.5]}, src=SPHERE),
    Case("color", ["--iso", "0.5", "--color", "0.2,0.5,0.9"],
         {**ISO, "shading": sc.Shading(front_color=(0.2, 0.5, 0.9))}, ISO),
    Case("color-per-surface", ["--iso", "0.3,0.6", "--color", "red", "--color", "#0000ff"],
         {**MULTI, "colors": [(1.0, 0.0, 0.0), (0.0, 0.0, 1.0)]}, MULTI),
    Case("background", ["--iso", "0.5", "--background", "white"],
         {**ISO, "shading": sc.Shading(background=(1.0, 1.0, 1.0, 1.0))}, ISO),
    Case("background-transparent", ["--iso", "0.5", "--background", "transparent"],
         {**ISO, "shading": sc.Shading(background=(0.0, 0.0, 0.0, 0.0))}, ISO),
    Case("opacity", ["--iso", "0.3,0.6", "--opacity", "0.3,0.9"],
         {**MULTI, "opacity": [0.3, 0.9]}, MULTI),
    Case("clip", ["--iso", "0.5", "--clip", "1,0.2,0,0.1"],
         {**ISO, "clip": [(1.0, 0.2, 0.0, 0.1)]}, ISO),
    Case("clip-twice", ["--iso", "0.5", "--clip", "1,0,0,0.3", "--clip", "0,0,1,0.1"],
         {**ISO, "clip": [(1.0, 0.0, 0.0, 0.3), (0.0, 0.0, 1.0, 0.1)]},
         {**ISO, "clip": [(1.0, 0.0, 0.0, 0.3)]}),
    Case("crop", ["--iso", "0.5", "--crop=-0.8,0.5,-1,0.6,-0.9,1"],
         {**ISO, "crop": (-0.8, 0.5, -1.0, 0.6, -0.9, 1.0)}, ISO),
    Case("texture-checker", ["--iso", "0.5", "--texture", "checker"],
         {**ISO, "effects": sc.SurfaceEffects(texture="checker", scale=0.1)}, ISO),
    Case("texture-noise", ["--iso", "0.5", "--texture", "noise"],
         {**ISO, "effects": sc.SurfaceEffects(texture="noise", scale=0.1)}, ISO),
    Case("texture-scale", ["--iso", "0.5", "--texture", "checker", "--texture-scale", "0.37"],
         {**ISO, "effects": sc.SurfaceEffects(texture="checker", scale=0.37)},
         {**ISO, "effects": sc.SurfaceEffects(texture="checker", scale=0.1)}),
    Case("shading-cel", ["--iso", "0.5", "--shading", "cel"],
         {**ISO, "effects": sc.SurfaceEffects(cel_bands=4)}, ISO),
    Case("multi-iso-texture", ["--iso", "0.3,0.6", "--texture", "checker", "--shading", "cel"],
         {**MULTI, "effects": sc.SurfaceEffects(texture="checker", cel_bands=4)}, MULTI),
    Case("smooth", ["--iso", "0.5", "--smooth", "5"], {**ISO, "smooth": 5}, ISO),
    Case("normals-exact", ["--iso", "0.5", "--normals", "exact"], {**ISO, "normals": "exact"},
         ISO),
    Case("samples", ["--iso", "0.5", "--samples", "1"], {**ISO, "samples": 1}, ISO),
    Case("samples-mip", ["--mode", "mip", "--samples", "4"], {"mode": "mip", "samples": 4},
         {"mode": "mip"}),
    # --- models and their options -------------------------------------------------------
    Case("model-bspline2", ["--iso", "0.5", "--model", "bspline2"],
         {**ISO, "model": "bspline2"}, ISO),
    Case("model-s31", ["--iso", "0.5", "--model", "s31"], {**ISO, "model": "s31"}, ISO),
    Case("model-qss", ["--iso", "0.5", "--model", "qss"], {**ISO, "model": "qss"},
         {**ISO, "model": "s31"}),
    Case("prefilter-bspline3", ["--iso", "0.5", "--model", "bspline3", "--prefilter"],
         {**ISO, "model": "bspline3", "model_options": {"prefilter": True}},
         {**ISO, "model": "bspline3"}),
    Case("prefilter-s31", ["--iso", "0.5", "--model", "s31", "--prefilter"],
         {**ISO, "model": "s31", "model_options": {"prefilter": True}},
         {**ISO, "model": "s31"}),
    # An iteration budget of 2 stops the Newton finder before it converges: depths move.
    Case("root-finder-iterations",
         ["--iso", "0.5", "--model", "bspline3", "--root-finder", "newton", "--iterations", "2"],
         {**ISO, "model": "bspline3", "model_options": {"root_finder": "newton",
                                                         "iterations": 2}},
         {**ISO, "model": "bspline3", "model_options": {"root_finder": "newton"}}),
    # --- MIP / minIP --------------------------------------------------------------------
    Case("mode-mip", ["--mode", "mip"], {"mode": "mip"}, ISO),
    Case("mode-minip", ["--mode", "minip"], {"mode": "minip"}, {"mode": "mip"}),
    Case("colormap", ["--mode", "mip", "--colormap", "hot"], {"mode": "mip", "colormap": "hot"},
         {"mode": "mip"}),
    # Any matplotlib / cmap name, not only the menu's.
    Case("colormap-catalog", ["--mode", "mip", "--colormap", "RdBu_r"],
         {"mode": "mip", "colormap": "RdBu_r"}, {"mode": "mip"}),
    Case("mip-background", ["--mode", "mip", "--background", "#336699"],
         {"mode": "mip", "shading": sc.Shading(background=(0.2, 0.4, 0.6, 1.0))},
         {"mode": "mip"}),
    Case("window", ["--mode", "mip", "--window", "0.4,0.7"],
         {"mode": "mip", "window": (0.4, 0.7)}, {"mode": "mip"}),
    Case("mip-tolerance", ["--mode", "mip", "--tolerance", "0.1"],
         {"mode": "mip", "tolerance": 0.1}, {"mode": "mip"}),
    Case("mip-sampled", ["--mode", "mip", "--method", "sampled", "--step", "1.5"],
         {"mode": "mip", "method": "sampled", "step": 1.5}, {"mode": "mip"}),
    Case("mip-slices", ["--mode", "mip", "--method", "slices", "--step", "2"],
         {"mode": "mip", "method": "slices", "step": 2.0},
         {"mode": "mip", "method": "sampled", "step": 2.0}),
    Case("mip-clip", ["--mode", "minip", "--clip", "0,1,0,0"],
         {"mode": "minip", "clip": [(0.0, 1.0, 0.0, 0.0)]}, {"mode": "minip"}),
    # --- DVR ----------------------------------------------------------------------------
    # No DVR option: what Scene.render(mode="dvr") gives without dvr= (DEFAULT_SETTINGS).
    Case("tf", ["--mode", "dvr", "--tf", "{tf_b}"], {"mode": "dvr", "tf": TF_B},
         {"mode": "dvr", "tf": TF_A}, src=NOISE),
    # An option given with its documented value still counts: DVRSettings(step=0.25).
    Case("dvr-step-documented", ["--mode", "dvr", "--tf", "{tf_a}", "--step", "0.25"],
         {"mode": "dvr", "tf": TF_A, "dvr": sc.DVRSettings(step=0.25)},
         {"mode": "dvr", "tf": TF_A}, src=NOISE),
    Case("preintegration-2d", ["--mode", "dvr", "--tf", "{tf_a}", "--preintegration", "2d"],
         {"mode": "dvr", "tf": TF_A, "dvr": dvr()},
         {"mode": "dvr", "tf": TF_A}, src=NOISE),
    Case("dvr-step", ["--mode", "dvr", "--tf", "{tf_a}", "--step", "1"],
         {"mode": "dvr", "tf": TF_A, "dvr": dvr(step=1.0)},
         {"mode": "dvr", "tf": TF_A, "dvr": dvr()}, src=NOISE),
    Case("preintegration-none", ["--mode", "dvr", "--tf", "{tf_a}", "--preintegration", "none"],
         {"mode": "dvr", "tf": TF_A, "dvr": dvr(preintegration="none")},
         {"mode": "dvr", "tf": TF_A, "dvr": dvr()}, src=NOISE),
    Case("preintegration-3d",
         ["--mode", "dvr", "--tf", "{tf_a}", "--preintegration", "3d", "--step", "1"],
         {"mode": "dvr", "tf": TF_A, "dvr": dvr(preintegration="3d", step=1.0)},
         {"mode": "dvr", "tf": TF_A, "dvr": dvr(preintegration="none", step=1.0)}, src=NOISE),
    # --adaptive: "opacity-adaptive step up to 8 x --step; uses a 3D table".
    Case("adaptive", ["--mode", "dvr", "--tf", "{tf_a}", "--adaptive"],
         {"mode": "dvr", "tf": TF_A,
          "dvr": dvr(preintegration="3d", adaptive=True, h_max=8 * 0.25)},
         {"mode": "dvr", "tf": TF_A, "dvr": dvr()}, src=NOISE),
    Case("table-layout",
         ["--mode", "dvr", "--tf", "{tf_a}", "--adaptive", "--table-layout", "exponential"],
         {"mode": "dvr", "tf": TF_A,
          "dvr": dvr(preintegration="3d", adaptive=True, h_max=2.0,
                     table_layout="exponential")},
         {"mode": "dvr", "tf": TF_A,
          "dvr": dvr(preintegration="3d", adaptive=True, h_max=2.0)}, src=NOISE),
    Case("termination", ["--mode", "dvr", "--tf", "{tf_a}", "--termination", "0.5"],
         {"mode": "dvr", "tf": TF_A, "dvr": dvr(termination=0.5)},
         {"mode": "dvr", "tf": TF_A, "dvr": dvr()}, src=NOISE),
    Case("dvr-crop", ["--mode", "dvr", "--tf", "{tf_a}", "--crop=-1,0.2,-1,1,-1,1"],
         {"mode": "dvr", "tf": TF_A, "crop": (-1.0, 0.2, -1.0, 1.0, -1.0, 1.0)},
         {"mode": "dvr", "tf": TF_A}, src=NOISE),
]


@pytest.fixture(scope="module")
def tf_files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("tf")
    paths = {"tf_a": folder / "a.json", "tf_b": folder / "b.json"}
    TF_A.save(paths["tf_a"])
    TF_B.save(paths["tf_b"])
    return {k: str(v) for k, v in paths.items()}


def run_cli(argv: list[str], capsys) -> tuple[int, str]:
    code = main(argv)
    _, err = capsys.readouterr()
    return code, err


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_option_gives_the_api_render(case, tmp_path, capsys, tf_files):
    png, depth = tmp_path / "out.png", tmp_path / "depth.npy"
    args = [a.format(**tf_files) for a in case.cli]
    size = [] if case.id == "size" else ["--size", "x".join(map(str, SIZE))]
    # "--fit box": the whole grid's framing, the API's default; the "fit" case sets content.
    code, err = run_cli(["render", case.src, *size, "--quiet", "-o", str(png),
                         "--depth", str(depth), "--fit", "box", *args], capsys)
    assert code == 0, err
    got = np.asarray(Image.open(png))
    expected = api_frame(case.src, **case.api)
    np.testing.assert_array_equal(got, expected.to_uint8())
    np.testing.assert_array_equal(np.load(depth), expected.depth)
    # The option matters: the render without it is a different image (or depth buffer), so an
    # option the command line ignored would have failed the comparison above.
    base = api_frame(case.src, **case.baseline)
    same_image = base.rgba.shape == expected.rgba.shape and np.array_equal(
        base.to_uint8(), expected.to_uint8())
    same_depth = base.depth.shape == expected.depth.shape and np.array_equal(
        base.depth, expected.depth)
    assert not (same_image and same_depth), f"{case.id}: the baseline equals the option's render"


def test_every_render_option_has_a_case():
    """A new option of ``splinecast render`` needs a case above (or a reason here)."""
    from splinecast.cli import _build_parser

    parser = _build_parser()
    render = parser._subparsers._group_actions[0].choices["render"]
    options = {s for a in render._actions for s in a.option_strings if s.startswith("--")}
    # Output options and --help are checked by the other tests of this module and test_cli.py;
    # --array picks a point-data array of VTK files (tests/test_vtkimage.py); --budget and --lod
    # of multiscale volumes are tested in tests/test_multires_render.py, --cut in
    # tests/test_cut_render.py; --allow-external-data and --verbose (input handling, not
    # rendering) in tests/test_hostile_input.py, --allow-missing (unreadable bricks of a
    # pyramid) in tests/test_zarr_bounded.py; --timepoint, --volume and --channel (which
    # volume of a series is read) in tests/test_timepoints.py; --anon (S3 without
    # credentials) in tests/test_remote_s3.py, --cache-dir and --cache-size (the local cache of
    # fetched chunks) in tests/test_remote_http.py; --labels, --no-labels, --show,
    # --label-colors and --label-opacity (label volumes, against the API's LabelScene) in
    # tests/test_labels.py; the options of several channels rendered together
    # (--channel-colors, --channel-window, --channel-iso, --channel-file) in
    # tests/test_channels.py.
    covered = {"--output", "--depth", "--quiet", "--help", "--mode", "--array", "--budget",
               "--lod", "--cut", "--allow-external-data", "--verbose", "--allow-missing",
               "--timepoint", "--volume", "--channel", "--anon", "--cache-dir", "--cache-size",
               "--labels", "--no-labels", "--show", "--label-colors", "--label-opacity",
               "--channel-colors", "--channel-window", "--channel-iso", "--channel-file"}
    used = {a.split("=")[0] for c in CASES for a in c.cli if a.startswith("--")}
    assert options - covered - used == set()


@pytest.mark.parametrize("args, needle", [
    (["--samples", "0"], "--samples: must be an integer from 1 (no antialiasing) to 64"),
    (["--samples", "65"], "--samples: must be an integer from 1 (no antialiasing) to 64"),
    (["--samples", "2.5"], "--samples: must be an integer from 1 (no antialiasing) to 64"),
    (["--normals", "flat"], "--normals: invalid choice: 'flat' (choose from 'smooth', 'exact')"),
])
def test_bad_shading_and_sample_options_are_one_line(args, needle, tmp_path, capsys):
    """A bad sample count or normals choice: one line naming the option and what it accepts,
    status 2, no file."""
    png = tmp_path / "out.png"
    with pytest.raises(SystemExit) as exit_info:
        main(["render", ML, "--size", "8x8", "--quiet", "-o", str(png), *args])
    err = capsys.readouterr().err
    assert exit_info.value.code == 2
    assert err.startswith("splinecast: error:") and err.count("\n") == 1 and needle in err
    assert not png.exists()


def test_version_prints_the_package_version(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["--version"])
    assert exit_info.value.code == 0
    out = capsys.readouterr().out.strip()
    assert out == f"splinecast {sc.__version__}"
    assert sc.__version__ == importlib.metadata.version("splinecast")


@pytest.mark.parametrize("args, needle", [
    (["--mode", "mip", "--iso", "0.3"], "--iso does not apply to --mode mip"),
    (["--mode", "dvr", "--tf", "{tf_a}", "--opacity", "0.5"], "--opacity"),
    (["--mode", "minip", "--inside", "low"], "--inside"),
    (["--mode", "dvr", "--tf", "{tf_a}", "--texture", "checker"], "--texture"),
    (["--mode", "mip", "--shading", "cel"], "--shading"),
    (["--mode", "dvr", "--tf", "{tf_a}", "--method", "sampled"], "--method"),
    (["--mode", "dvr", "--tf", "{tf_a}", "--colormap", "hot"], "--colormap"),
    (["--iso", "0.5", "--window", "0,1"], "--window"),
    (["--iso", "0.5", "--tolerance", "0.01"], "--tolerance"),
    (["--mode", "mip", "--method", "slices", "--step", "2", "--tolerance", "0.01"],
     "tolerance bounds the exact method"),
    (["--iso", "0.5", "--tf", "{tf_a}"], "--tf"),
    (["--mode", "mip", "--preintegration", "none"], "--preintegration"),
    (["--iso", "0.5", "--adaptive"], "--adaptive"),
    (["--iso", "0.5", "--termination", "0.9"], "--termination"),
    (["--iso", "0.3,0.6", "--method", "sampled"], "--method sampled"),
    (["--iso", "0.5", "--opacity", "0.5", "--method", "sampled"], "--method sampled"),
    (["--iso", "0.5", "--method", "slices"], "--method slices applies to --mode mip/minip"),
    (["--iso", "0.5", "--step", "0.1"], "--step"),
    (["--mode", "mip", "--step", "0.1"], "--step"),
    (["--iso", "0.5", "--texture-scale", "0.3"], "--texture-scale"),
    (["--mode", "dvr", "--tf", "{tf_a}", "--table-layout", "exponential"], "--table-layout"),
    (["--mode", "mip", "--normals", "exact"], "--normals"),
])
def test_options_the_settings_would_ignore_are_refused(args, needle, tmp_path, capsys, tf_files):
    """An option that would not change the output is a mistake: one line, status 2, no file."""
    png = tmp_path / "out.png"
    code, err = run_cli(["render", ML, "--size", "8x8", "--quiet", "-o", str(png),
                         *[a.format(**tf_files) for a in args]], capsys)
    assert code == 2
    assert err.startswith("splinecast: error:") and err.count("\n") == 1 and needle in err
    assert not png.exists()
