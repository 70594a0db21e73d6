"""``splinecast render FILE [-o OUT.png]``: one image of any model in any mode."""

from __future__ import annotations

import argparse
import contextlib
import math
import time
import warnings
from pathlib import Path

import numpy as np

import splinecast as sc
from splinecast.errors import did_you_mean, limits
from splinecast.render.defaults import WINDOW_PERCENTILES
from splinecast.render.modes import (
    MODE_NAMES,
    all_methods,
    mode_class,
    modes_reading,
    modes_with_method,
)
from splinecast.render.modes import MODES as MODE_CLASSES
from splinecast.transfer import DIVERGING, MENU

from ._common import (
    IMAGE_SUFFIXES,
    IncompleteWarning,
    add_input_options,
    add_missing_option,
    add_selection_options,
    check_output,
    derived_output,
    finite,
    log,
    numbers,
    read_options,
)
from ._compiling import CompileNotice
from .channels import (
    CHANNEL_OPTIONS,
    add_channel_options,
    channel_settings,
    read_channels,
    several_channels,
)
from .labels import add_label_options, check_label_args, run_labels, wants_labels

__all__ = ["add_parser", "run", "add_render_options", "check_render_args", "model_options",
           "mode_kwargs", "orbit_options", "sampled_step", "dvr_settings", "SAMPLED_STEP",
           "DVR_FALLBACK", "sample_count", "DEFAULT_MODE", "output_stem", "reads"]

#: The mode of ``--mode`` when it is not given: the scenes' own default.
DEFAULT_MODE = sc.Scene.default_mode

#: Options only some modes read: flag -> (attribute, the ``Scene.render`` keyword it becomes).
#: Given with a mode that does not read that keyword
#: (:attr:`~splinecast.render.modes.RenderMode.keywords`) they would be ignored without a word, so
#: :func:`_refuse_ignored_options` refuses them instead. The keyword ``dvr`` is the
#: :class:`~splinecast.DVRSettings` the DVR options make (:func:`dvr_settings`).
_MODE_ONLY = {
    "--iso": ("iso", "iso"),
    "--opacity": ("opacity", "opacity"),
    "--inside": ("inside", "inside"),
    "--color": ("color", "colors"),
    "--texture": ("texture", "effects"),
    "--texture-scale": ("texture_scale", "effects"),
    "--shading": ("shading", "effects"),
    "--method": ("method", "method"),
    "--colormap": ("colormap", "colormap"),
    "--window": ("window", "window"),
    "--tolerance": ("tolerance", "tolerance"),
    "--tf": ("tf", "tf"),
    "--preintegration": ("preintegration", "dvr"),
    "--table-layout": ("table_layout", "dvr"),
    "--adaptive": ("adaptive", "dvr"),
    "--termination": ("termination", "dvr"),
    "--normals": ("normals", "normals"),
}

#: The render subcommand's option defaults (attribute -> default), filled by :func:`add_parser`.
_DEFAULTS: dict[str, object] = {}

#: The sampling step (voxels) of ``--method sampled`` when ``--step`` is not given.
SAMPLED_STEP = 0.25
#: Multiscale volumes: the brick budget, level of detail (pixels per voxel) and cut policy
#: when ``--budget``, ``--lod`` and ``--cut`` are not given.
DEFAULT_BUDGET = "2GiB"
DEFAULT_LOD = 1.0
DEFAULT_CUT = "lod"

#: The DVR options. With none of them given, ``--mode dvr`` renders as ``Scene.render`` without
#: ``dvr=`` does (the library's fast default, :data:`splinecast.render.dvr.DEFAULT_SETTINGS`);
#: with any of them, ``DVRSettings`` of the given ones and, for the others, these values (the
#: meaning the options always had). Their parser defaults are None so that an option given
#: with its documented value (``--step 0.25``) still counts as given.
DVR_FALLBACK: dict[str, object] = {"step": SAMPLED_STEP, "preintegration": "2d",
                                   "table_layout": "uniform", "adaptive": False,
                                   "termination": None}
#: What an unset DVR option holds after parsing.
_DVR_UNSET: dict[str, object] = {"step": None, "preintegration": None, "table_layout": None,
                                 "adaptive": False, "termination": None}


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    render = sub.add_parser("render", help="render an isosurface, a MIP or a DVR image to a "
                            "PNG, JPEG, TIFF or WebP file")
    render.add_argument("file", help="volume file, DICOM folder or demo:NAME?size=N")
    render.add_argument("-o", "--output",
                        help="output image: .png, .jpg/.jpeg (composited on the background), "
                             ".tif/.tiff or .webp (default: NAME.png, or NAME-MODE.png for "
                             "another mode than iso, in the current folder, NAME from the "
                             "input; printed)")
    render.add_argument("--array", help="data array of a VTK file holding several")
    render.add_argument("--iso", help="isovalue(s) in data units, comma-separated for several "
                        "translucent surfaces; negative values as --iso -3 or --iso -3,3 "
                        "(default: the volume's, else Otsu's threshold of the non-background "
                        "histogram, of the absolute values for signed data; printed)")
    render.add_argument("--azimuth", type=finite, default=30.0,
                        help="degrees around z (default 30)")
    render.add_argument("--elevation", type=finite, default=20.0,
                        help="degrees above xy (default 20)")
    render.add_argument("--fit", default="content", choices=("content", "box"),
                        help="content: frame what the isovalue or transfer function shows; box: "
                             "the whole grid (default content)")
    add_render_options(render)
    render.add_argument("--budget", help="multiscale (OME-Zarr) volumes and wavelet stores: RAM "
                        "for bricks (and wavelet details), e.g. 512MiB or 2GiB (default 2GiB)")
    render.add_argument("--lod", type=finite, help="multiscale volumes: refine while a voxel "
                        "covers more than this many pixels (default 1); wavelet stores: the "
                        "angle ε in radians below which cells are not refined (0: full "
                        "resolution; default one pixel's angle)")
    render.add_argument("--cut", help="multiscale volumes: which bricks to draw, lod (screen-"
                        "space level of detail) or error (transfer-function distortion times "
                        "importance under the budget; dvr and mip) (default lod)")
    render.add_argument("--depth", help="also save the depth buffer to this .npy file")
    render.add_argument("--quiet", action="store_true", help="no progress or timing on stderr")
    add_label_options(render)
    add_missing_option(render)
    add_selection_options(render, several=True)
    add_channel_options(render)
    add_input_options(render)
    _DEFAULTS.update({a.dest: a.default for a in render._actions if a.option_strings})


def add_render_options(render: argparse.ArgumentParser) -> None:
    """The options every rendering subcommand shares: model, camera (but the angles), method
    and modes. ``--iso``, ``--azimuth`` and ``--elevation`` are the caller's (a movie sweeps
    them)."""
    render.add_argument("--model", help="reconstruction (default trilinear; bspline<d> for a "
                        "degree-d wavelet store, the only model it renders)")
    render.add_argument("--root-finder", choices=("bernstein", "rfbs", "sturm", "newton"),
                        help="first-root solver of spline models (default: the model's)")
    render.add_argument("--iterations", type=int,
                        help="iteration budget of the root finder (default: the finder's)")
    render.add_argument("--prefilter", action="store_true",
                        help="B-spline models: interpolate the voxels instead of smoothing them")
    render.add_argument("--size", default="512x512", help="image WIDTHxHEIGHT (default 512x512)")
    render.add_argument("--distance", type=finite, help="camera distance from the volume centre")
    render.add_argument("--fov", type=finite, default=30.0,
                        help="vertical field of view, degrees (default 30)")
    render.add_argument("--zoom", type=finite, default=1.0, help="magnification (default 1)")
    render.add_argument("--ortho", action="store_true", help="orthographic projection")
    render.add_argument("--method", default="exact", choices=all_methods(),
                        help="exact: analytic roots; sampled: fixed-step sampling (--mode "
                             f"{_modes('sampled')}); slices: samples on every STEP-th plane "
                             f"of voxels across the ray, the fastest (--mode {_modes('slices')})"
                             " (default exact)")
    render.add_argument("--step", type=finite,
                        help="sampling step in voxels for --method sampled/slices (default "
                             f"0.25) and --mode {_reading('dvr')} (default 0.25 when another "
                             "DVR option is given)")
    render.add_argument("--inside", choices=("high", "low"),
                        help="which side of the isovalue is the object (default: the volume's, "
                             "else low for isovalues below the background value, e.g. negative "
                             "ones of a signed map, else high)")
    render.add_argument("--background", metavar="COLOR",
                        help="background colour: a name (white, black, ...), #RRGGBB[AA], "
                             "R,G,B[,A] in [0, 1] or transparent (default 0.07,0.07,0.09, a "
                             "dark grey)")
    render.add_argument("--color", action="append", metavar="COLOR",
                        help="surface colour (default 0.92,0.84,0.7, a light beige, for one "
                             "surface; the bone colormap for several): a name, #RRGGBB or "
                             "R,G,B in [0, 1]; repeat it once per --iso value, in the same "
                             "order, for several surfaces")
    _add_mode_options(render)


def _reading(keyword: str) -> str:
    """The modes that read ``keyword``, as the help says them (``mip/minip``)."""
    return "/".join(modes_reading(keyword))


def _modes(method: str) -> str:
    """The modes that accept ``method``, as the help says them."""
    return "/".join(modes_with_method(method))


def _add_mode_options(render: argparse.ArgumentParser) -> None:
    """Options of the render modes beyond the single isosurface."""
    render.add_argument("--mode", default=DEFAULT_MODE, choices=MODE_NAMES,
                        help="; ".join(f"{name}: {cls.summary}"
                                       for name, cls in MODE_CLASSES.items())
                        + f" (default {DEFAULT_MODE})")
    render.add_argument("--opacity", help="one opacity per --iso value, comma-separated")
    render.add_argument("--tf", help=f"transfer function JSON file (--mode {_reading('tf')})")
    render.add_argument("--colormap",
                        help=f"colormap of --mode {_reading('colormap')}, any matplotlib or "
                             "cmap name "
                             f"({', '.join(MENU)}, ...; default gray, {DIVERGING} for signed "
                             "data)")
    render.add_argument("--window", help=f"LO,HI value window of --mode {_reading('window')} "
                        "(default: the {:g}th-{:g}th percentiles of the volume's projections "
                        "along its axes, symmetric about 0 for signed data; printed)".format(
                            *WINDOW_PERCENTILES))
    render.add_argument("--tolerance", type=finite, default=0.0,
                        help=f"--mode {_reading('tolerance')}, exact method: how far short "
                             "of the exact "
                             "projection a pixel may fall, as a fraction of the window "
                             "(e.g. 0.004 for one 8-bit level; default 0, exact), for faster "
                             "frames")
    render.add_argument("--clip", action="append", default=[], metavar="NX,NY,NZ,D",
                        help="clip plane keeping nx*x+ny*y+nz*z+d >= 0 (repeatable)")
    render.add_argument("--crop", metavar="X0,X1,Y0,Y1,Z0,Z1", help="world-space box to keep")
    render.add_argument("--texture", choices=("noise", "checker"), help="solid texture")
    render.add_argument("--texture-scale", type=finite, default=0.1,
                        help="checker cube / noise feature size in world units (default 0.1)")
    render.add_argument("--shading", default="phong", choices=("phong", "cel"),
                        help="phong: smooth Blinn-Phong; cel: 4-band cel shading (default phong)")
    render.add_argument("--smooth", type=int, choices=(3, 5),
                        help="Gaussian pre-smoothing kernel size (with --labels: of each "
                             "label's indicator, for smooth surfaces; the labels are never "
                             "averaged)")
    render.add_argument("--preintegration", choices=("none", "2d", "3d"),
                        help="DVR classification (default 2d pre-integration). With none of "
                             "--step, --preintegration, --table-layout, --adaptive and "
                             "--termination, --mode dvr renders with the library's fast default "
                             "(splinecast.render.dvr.DEFAULT_SETTINGS, as Scene.render without "
                             "dvr=)")
    render.add_argument("--table-layout", choices=("uniform", "exponential"),
                        help="DVR 3D pre-integration table lengths: uniform, k x step, or "
                             "exponential, 2^j x step (default uniform)")
    render.add_argument("--adaptive", action="store_true",
                        help="DVR opacity-adaptive step (up to 8 x --step; uses a 3D table)")
    render.add_argument("--termination", type=finite,
                        help="DVR early ray termination opacity, e.g. 0.99")
    render.add_argument("--normals", default="smooth", choices=("smooth", "exact"),
                        help="isosurface shading: smooth, the gradient of a smooth field at "
                             "the exact hit (the cubic B-spline of the voxels for trilinear and "
                             "bspline1), or exact, the model's own gradient (default smooth)")
    surfaces = "/".join(name for name, cls in MODE_CLASSES.items() if cls.surfaces)
    render.add_argument("--samples", type=sample_count,
                        help="antialiasing: rays per pixel on the edges of the image, the "
                             f"centre one included, 1 to {sc.render.antialias.MAX_SAMPLES} "
                             f"(default {sc.render.antialias.DEFAULT_SAMPLES} for --mode "
                             f"{surfaces}, 1 = off for the other modes and for multiscale "
                             "volumes)")


def reads(args: argparse.Namespace) -> tuple[str, ...]:
    """The ``Scene.render`` keywords ``--mode`` reads
    (:attr:`~splinecast.render.modes.RenderMode.keywords`): the one question the options ask
    of the mode, so a mode the registry adds is offered its options without a change here."""
    return mode_class(args.mode).keywords


def output_stem(mode: str) -> str:
    """The mode's part of an output name derived from the input's: none for
    :data:`DEFAULT_MODE` (``NAME.png``), else the mode's name (``NAME-mip.png``)."""
    return "" if mode == DEFAULT_MODE else mode


def _several_isos(args: argparse.Namespace) -> bool:
    """Whether the options ask for several isosurfaces (a list of isovalues, or opacities)."""
    return "iso" in reads(args) and bool(args.opacity or (args.iso and "," in args.iso))


def _steps(args: argparse.Namespace) -> bool:
    """Whether the render samples with ``--step``: a sampled ``--method`` of a mode reading
    ``step`` (not several isosurfaces, always exact), or a mode reading the DVR settings,
    whose step ``--step`` is."""
    keywords = reads(args)
    return "dvr" in keywords or (
        "step" in keywords and args.method != "exact" and not _several_isos(args))


def _refuse_ignored_options(args: argparse.Namespace) -> None:
    """Refuse an option set away from its default that the chosen settings would not read."""

    def given(attribute: str) -> bool:
        return getattr(args, attribute) != _DEFAULTS.get(attribute)

    for flag, (attribute, keyword) in _MODE_ONLY.items():
        modes = modes_reading(keyword)
        if given(attribute) and args.mode not in modes:
            raise sc.ParameterError(f"{flag} does not apply to --mode {args.mode} "
                                    f"(only to --mode {'/'.join(modes)})")
    several = _several_isos(args)
    slices = modes_with_method("slices")
    if args.method == "slices" and args.mode not in slices:
        raise sc.ParameterError(f"--method slices applies to --mode {'/'.join(slices)} only, "
                                f"not --mode {args.mode}")
    if several and args.method != "exact":
        raise sc.ParameterError("--method sampled takes a single --iso value "
                                "(several isosurfaces are always exact)")
    if given("step") and not _steps(args):
        raise sc.ParameterError("--step applies to --method sampled/slices and --mode "
                                f"{_reading('dvr')} only")
    if given("texture_scale") and not args.texture:
        raise sc.ParameterError("--texture-scale needs --texture")
    if given("table_layout") and not args.adaptive:
        raise sc.ParameterError("--table-layout needs --adaptive (it lays out the adaptive "
                                "step's table lengths)")


def _shading(args: argparse.Namespace, isos: list[float] | None) -> tuple[dict, list]:
    """``shading`` (and ``colors`` for several surfaces) of ``--background`` and ``--color``."""
    kwargs: dict = {}
    shading: dict = {}
    if args.background is not None:
        shading["background"] = sc.transfer.parse_color(args.background, "--background",
                                                         alpha=True)
    colors = [sc.transfer.parse_color(c, "--color") for c in args.color or []]
    if colors:
        count = len(isos) if isos else 1
        if len(colors) != count:
            raise sc.ParameterError(
                f"--color given {len(colors)} times for {count} isovalue"
                f"{'s' if count > 1 else ''}: give one --color per --iso value")
        if count > 1:
            kwargs["colors"] = colors
        else:
            shading["front_color"] = colors[0]
    if shading:
        kwargs["shading"] = sc.Shading(**shading)
    return kwargs, colors


def mode_kwargs(args: argparse.Namespace, vol: sc.Volume) -> tuple[dict, list[str]]:
    """Scene.render keyword arguments of the mode options, validated before any rendering, and
    what was chosen automatically (printed once everything is known to be valid).

    ``vol`` is only asked for its value range, metadata and the automatic choices of
    :mod:`splinecast.render.defaults` (a distributed scene's ``VolumeInfo`` carries those).
    """
    kwargs: dict = {"mode": args.mode}
    keywords = reads(args)  # every question below is the mode's, never its name
    if args.samples is not None:
        kwargs["samples"] = args.samples
    if "normals" in keywords:
        kwargs["normals"] = args.normals
    notes: list[str] = []
    clip = [numbers(c, "--clip", 4) for c in args.clip]
    if clip:
        kwargs["clip"] = clip
    if args.crop:
        kwargs["crop"] = numbers(args.crop, "--crop", 6)
    isos = numbers(args.iso, "--iso") if "iso" in keywords else None
    shading, _ = _shading(args, isos)
    kwargs.update(shading)
    if "method" in keywords and not _several_isos(args):  # several isosurfaces: always exact
        kwargs["method"] = args.method
        kwargs["step"] = sampled_step(args)
    if "window" in keywords:  # the projections
        if args.colormap is not None:
            kwargs["colormap"] = sc.transfer.check_colormap(args.colormap, "--colormap")
        else:
            kwargs["colormap"] = sc.auto_colormap(vol)
            if sc.is_signed(vol):
                notes.append(f"colormap {kwargs['colormap']} (automatic: signed data, a "
                             "background of 0 with values of both signs; set --colormap)")
        if args.tolerance:
            kwargs["tolerance"] = args.tolerance
        if args.window:
            kwargs["window"] = numbers(args.window, "--window", 2)
        else:
            kwargs["window"] = MODE_CLASSES[args.mode].default_window(vol)
            how = ("symmetric about 0, signed data" if sc.is_signed(vol) else
                   "percentiles of the volume's axis-aligned projections")
            notes.append("window {:g}..{:g} (automatic: {}; set --window LO,HI)".format(
                *kwargs["window"], how))
    if "tf" in keywords:
        if args.tf:
            kwargs["tf"] = sc.TransferFunction.load(args.tf)
        else:
            kwargs["tf"] = tf = sc.auto_transfer_function(vol)
            (v0, _), (v1, a1) = tf.opacity_points[0], tf.opacity_points[-1]
            notes.append(f"transfer function: opacity 0 at {v0:g} rising to {a1:g} per voxel at "
                      f"{v1:g}, {tf.colormap} colours (automatic, from the histogram; set "
                      "--tf FILE.json)")
    if "dvr" in keywords:
        settings = dvr_settings(args)
        if settings is not None:  # else Scene.render's own default (dvr= not passed)
            kwargs["dvr"] = settings
    if "iso" in keywords:
        notes += _iso_kwargs(args, vol, isos, kwargs)
    if "effects" in keywords and (args.texture or args.shading == "cel"):
        kwargs["effects"] = sc.SurfaceEffects(texture=args.texture, scale=args.texture_scale,
                                              cel_bands=4 if args.shading == "cel" else 0)
    return kwargs, notes


def _iso_kwargs(args: argparse.Namespace, vol: sc.Volume, isos: list[float] | None,
                kwargs: dict) -> list[str]:
    """Add the isovalue(s) (and opacities) of a mode that reads ``iso`` to ``kwargs``;
    returns what was chosen automatically."""
    notes: list[str] = []
    if isos is not None and (len(isos) > 1 or args.opacity):
        kwargs["iso"] = [sc.check_iso(vol, v) for v in isos]
        if args.opacity:
            kwargs["opacity"] = numbers(args.opacity, "--opacity", len(isos))
    else:
        kwargs["iso"] = sc.check_iso(vol, isos[0] if isos else None)
        if not isos:
            how = ("the volume's default" if vol.metadata.get("default_iso") is not None
                   else "automatic: Otsu's threshold of the non-background histogram")
            if sc.is_signed(vol) and vol.metadata.get("default_iso") is None:
                t = kwargs["iso"]
                how = (f"automatic: Otsu's threshold of the absolute values of signed data; "
                       f"--iso=-{t:g},{t:g} shows both signs")
            notes.append(f"iso {kwargs['iso']:g} ({how}; set --iso)")
    if args.inside is None and vol.metadata.get("inside") is None:
        inside = sc.auto_inside(vol, kwargs["iso"])
        if inside == "low":
            notes.append(f"inside low (automatic: the isovalues lie below the background value "
                         f"{sc.background_value(vol):g}, so the object is the values below "
                         "them; set --inside)")
    return notes


def sample_count(text: str) -> int:
    """argparse type of ``--samples``: an integer from 1 to
    :data:`splinecast.render.antialias.MAX_SAMPLES`."""
    top = sc.render.antialias.MAX_SAMPLES
    try:
        value = int(text)
    except ValueError:
        value = 0
    if not 1 <= value <= top:
        raise argparse.ArgumentTypeError(
            f"must be an integer from 1 (no antialiasing) to {top}, got {limits.shorten(text)}")
    return value


def sampled_step(args: argparse.Namespace) -> float:
    """``--step``, or :data:`SAMPLED_STEP` when it is not given."""
    return SAMPLED_STEP if args.step is None else args.step


def dvr_settings(args: argparse.Namespace) -> sc.DVRSettings | None:
    """The ``DVRSettings`` the DVR options stand for, or None when none of them is given (the
    library's default then applies, see :data:`DVR_FALLBACK`)."""
    given = {name: getattr(args, name) for name, unset in _DVR_UNSET.items()
             if getattr(args, name) != unset}
    if not given:
        return None
    o = {**DVR_FALLBACK, **given}
    pre = "3d" if o["adaptive"] and o["preintegration"] == "2d" else o["preintegration"]
    return sc.DVRSettings(step=o["step"], preintegration=pre, adaptive=o["adaptive"],
                          h_max=8 * o["step"], termination=o["termination"],
                          table_layout=o["table_layout"])


def _fit(args: argparse.Namespace, vol: sc.Volume, kwargs: dict) -> object:
    """``Camera.orbit``'s ``fit``: the box of what the mode shows, or ``"box"``."""
    if args.fit == "box":
        return "box"
    if kwargs.get("tf") is not None:  # a mode reading a transfer function frames what it shows
        return sc.content_box(vol, tf=kwargs["tf"])
    # The projections frame the object the automatic isovalue finds.
    return sc.content_box(vol, iso=kwargs.get("iso"), inside=args.inside)


def check_render_args(args: argparse.Namespace) -> tuple[int, int]:
    """Validate the options :func:`add_render_options` added that need no volume (ranges of the
    numeric options, which argparse has made finite, against :mod:`splinecast.errors.limits`;
    options the mode would ignore); returns the image ``(width, height)``."""
    if len(args.size) > 32:
        shown = limits.shorten(args.size)
        raise sc.ParameterError(f"--size must look like WIDTHxHEIGHT, got {shown}")
    width, height = sc.camera.parse_size(args.size)
    limits.check_image(width, height, "--size")
    if not 0 < args.fov < 180:
        raise sc.ParameterError(f"--fov must be between 0 and 180 degrees, got {args.fov:g}")
    limits.check_finite_number(args.zoom, "--zoom", lo=1e-6, hi=1e6)
    if args.distance is not None:
        limits.check_finite_number(args.distance, "--distance", lo=0, lo_open=True)
    if args.step is not None and (args.method != "exact" or "dvr" in reads(args)):
        limits.check_finite_number(args.step, "--step (voxels)", lo=limits.MIN_STEP)
    if args.iterations is not None:
        limits.check_count(args.iterations, "--iterations", hi=limits.MAX_ROOT_ITERATIONS)
    limits.check_finite_number(args.texture_scale, "--texture-scale", lo=0, lo_open=True)
    if args.termination is not None:
        limits.check_finite_number(args.termination, "--termination", lo=0, hi=1, lo_open=True)
    _refuse_ignored_options(args)
    return width, height


def model_options(args: argparse.Namespace) -> dict:
    """The model's keyword arguments from ``--root-finder``, ``--iterations``, ``--prefilter``,
    refusing those the model does not take (no ``--model``: trilinear)."""
    if args.model is None:
        args.model = "trilinear"
    if args.model not in sc.MODELS:
        valid = ", ".join(sc.MODELS)
        raise sc.ParameterError(
            f"--model must be one of {valid}, got {limits.shorten(args.model)}"
            f"{did_you_mean(args.model, sc.MODELS)}"
        )
    options = {}
    accepted = sc.MODELS[args.model].option_names
    for name, flag in (("root_finder", "--root-finder"), ("iterations", "--iterations"),
                       ("prefilter", "--prefilter")):
        value = getattr(args, name)
        if value is None or value is False:
            continue
        if name not in accepted:
            raise sc.ParameterError(f"{flag} does not apply to model {args.model}")
        options[name] = value
    return options


def orbit_options(args: argparse.Namespace) -> dict:
    """``Camera.orbit`` keyword arguments of the camera options (all but the angles)."""
    return {"distance": args.distance, "size": sc.camera.parse_size(args.size), "fov": args.fov,
            "ortho": args.ortho, "zoom": args.zoom}


def _refuse_multiscale_options(args: argparse.Namespace, multiscale: bool,
                               wavelet: bool = False) -> None:
    """``--budget``/``--lod``/``--cut`` only for multiscale volumes (``--cut`` not for wavelet
    stores, whose ``--lod`` is an angle >= 0); ``--smooth`` only for the others."""
    if getattr(args, "allow_missing", False) and (wavelet or not multiscale):
        what = (f"the wavelet store {args.file} (a damaged chunk is always an error)" if wavelet
                else f"{args.file}, which is read into memory whole")
        raise sc.ParameterError(f"--allow-missing applies to multiscale (OME-Zarr) volumes "
                                f"only, not {what}")
    if wavelet:
        for flag, value in (("--smooth", args.smooth), ("--cut", args.cut)):
            if value:
                raise sc.ParameterError(f"{flag} does not apply to the wavelet store {args.file}")
        if args.budget is not None:
            limits.parse_bytes(args.budget, "--budget")
        if args.lod is not None and not (math.isfinite(args.lod) and args.lod >= 0):
            raise sc.ParameterError(f"--lod must be an angle >= 0 in radians, got {args.lod}")
        return
    if multiscale:
        if args.smooth:
            raise sc.ParameterError(f"--smooth does not apply to the multiscale volume "
                                    f"{args.file} (it would read every voxel)")
        if args.budget is not None:
            limits.parse_bytes(args.budget, "--budget")
        if args.lod is not None and not (math.isfinite(args.lod) and args.lod > 0):
            raise sc.ParameterError(f"--lod must be a positive number of pixels, got {args.lod}")
        if args.cut is not None and args.cut not in ("lod", "error"):
            raise sc.ParameterError(f"--cut must be lod or error, got {args.cut!r}")
        return
    for flag, value in (("--budget", args.budget), ("--lod", args.lod), ("--cut", args.cut)):
        if value is not None:
            raise sc.ParameterError(f"{flag} applies to multiscale (OME-Zarr) volumes only; "
                                    f"{args.file} is read into memory whole")


def run(args: argparse.Namespace) -> int:
    """Render ``args.file`` to ``args.output``."""
    # Validate every option and output path before any work, so a mistake writes nothing.
    derived = args.output is None
    if derived:
        args.output = str(derived_output(args.file, output_stem(args.mode), ".png"))
    check_output(args.output, IMAGE_SUFFIXES, "-o")
    if args.depth:
        check_output(args.depth, ".npy", "--depth")
    width, height = check_render_args(args)
    several = several_channels(args)
    if several:
        _refuse_channel_conflicts(args)
    else:
        for flag, attribute in CHANNEL_OPTIONS.items():
            if getattr(args, attribute) is not None:
                raise sc.ParameterError(f"{flag} needs several channels (--channel 0,2 or all, "
                                        "or --channel-file)")

    start = time.perf_counter()
    vol = sc.read(args.file, array=args.array, **read_options(args))
    if several:
        return _run_channels(args, read_channels(args, vol), time.perf_counter() - start,
                             derived)
    read_s = time.perf_counter() - start
    multiscale = not isinstance(vol, sc.Volume)
    wavelet = multiscale and isinstance(vol, sc.WaveletVolume)
    labels = wants_labels(args, vol)
    check_label_args(args, labels, multiscale and not wavelet)
    if labels:
        options = model_options(args)
        shading = _shading(args, None)[0].get("shading")
        with CompileNotice(f"{args.model} / labels", args.model,
                           enabled=not getattr(args, "quiet", False),
                           stream=getattr(args, "stderr", None)):
            return run_labels(args, vol, read_s, options, shading, orbit_options(args))
    if args.model is None and wavelet:
        args.model = f"bspline{vol.degree}"
    _refuse_multiscale_options(args, multiscale, wavelet)
    if args.method != "exact" or ("dvr" in reads(args) and args.step is not None):
        limits.check_step(sampled_step(args), "--step", vol.shape)
    with contextlib.ExitStack() as stack:
        options = model_options(args)
        scene = None
        if wavelet:  # nothing but the coarsest level is read here
            scene = sc.Scene(vol, model=args.model, lod=args.lod,
                             budget=args.budget or DEFAULT_BUDGET, **options)
        elif multiscale:  # nothing but the coarsest level is read here; the loader stops at the end
            scene = stack.enter_context(sc.Scene(
                vol, model=args.model, budget=args.budget or DEFAULT_BUDGET,
                lod=DEFAULT_LOD if args.lod is None else args.lod, cut=args.cut or DEFAULT_CUT,
                **options))
        info = scene.preview if multiscale else vol
        kwargs, notes = mode_kwargs(args, info)
        camera = sc.Camera.orbit(vol, azimuth=args.azimuth, elevation=args.elevation,
                                 fit=_fit(args, info, kwargs), **orbit_options(args))
        # Progress starts only once every input is known to be valid, so a mistake is one line.
        if wavelet:
            log(args, f"opened {vol.name}: degree-{vol.degree} wavelet store, "
                      f"{vol.layout.levels} levels, {vol.shape} in {read_s:.2f} s")
        elif multiscale:
            log(args, f"opened {vol.name}: {len(vol.levels)} levels, {vol.shape} {vol.dtype} in "
                      f"{read_s:.2f} s (coarsest level read)")
        else:
            log(args, f"read {vol.name}: {vol.shape} {vol.dtype} in {read_s:.2f} s")
        for note in notes:
            log(args, note)
        if args.smooth:
            limits.check_memory(limits.nbytes(vol.shape, 8) * 2, "smoothing the volume",
                                "--smooth")
            vol = sc.smooth(vol, args.smooth)
            log(args, f"smoothed with a {args.smooth}^3 Gaussian")
        # Said only when kernels really compile (first use of a model, mode and voxel type).
        model = args.model or "trilinear"
        stack.enter_context(CompileNotice(
            f"{model} / {args.mode}, {np.dtype(info.dtype).name} data", model,
            enabled=not getattr(args, "quiet", False),
            stream=getattr(args, "stderr", None)))
        start = time.perf_counter()
        if scene is None:
            scene = sc.Scene(vol, model=args.model, **options)
            log(args, f"prepared {args.model} model in {time.perf_counter() - start:.2f} s")
        start = time.perf_counter()
        # A still image: the whole cut, read; an unreadable brick is an error unless allowed.
        extra = ({"complete": True, "missing": "substitute" if args.allow_missing else "error"}
                 if multiscale and not wavelet else {})
        # The PNG needs colour, --depth and the "hits" count the depth, the log line the per-ray
        # counters; world position, normal and face are never written, so not kept.
        frame = scene.render(camera, inside=args.inside, outputs=("rgba", "depth", "stats"),
                             **extra, **kwargs)
        st = frame.stats
        what = f"at iso {st['iso']}" if "iso" in st else st["mode"]
        log(args, f"rendered {width}x{height} {what} in "
                   f"{time.perf_counter() - start:.2f} s (trace {st['trace_ms']:.0f} ms, "
                   f"{st['hits']} hits, {st['mean_cells_visited']:.1f} cells/ray)")
        if wavelet:
            log(args, f"chunks: {st['chunks']} ({100 * st['chunk_share']:.1f}% of all, "
                      f"ε = {st['lod']:.3g} rad), reconstructed in {st['reconstruct_ms']:.0f} ms")
        elif multiscale:
            levels = ", ".join(f"{n} of level {lv}" for lv, n in sorted(st["cut_levels"].items()))
            state = "complete" if st["complete"] else "incomplete"
            policy = st.get("cut_policy", "lod")
            if "cut_error" in st:
                policy += f", E(cut) {st['cut_error']:.4g}"
            if st.get("whole_level"):
                read = f"level 0 read whole in {st['whole_level_read_ms'] / 1e3:.2f} s"
            else:
                read = f"{st['loaded']} read, {st['unavailable']} unreadable"
            log(args, f"cut ({policy}): {st['cut_bricks']} bricks ({levels}), {read}, {state}")
        background = kwargs.get("shading", sc.Shading()).background
        what = mode_class(args.mode).projection
        if what is not None and np.all(frame.rgba == np.float32(background)):
            log(args, f"nothing drawn: every ray's {what} is the background value "
                      f"{sc.background_value(info):g} (a ray enters through the background; "
                      "--crop or --clip can leave it out)")
        frame.save(args.output, background=background)
        if derived:
            log(args, f"wrote {args.output} (named after the input; set -o)")
        if args.depth:
            frame.save_depth(args.depth)
            log(args, f"wrote depth {args.depth}")
        print(Path(args.output).resolve())
        warn_incomplete(args.output, [st])
    return 0


def _refuse_channel_conflicts(args: argparse.Namespace) -> None:
    """Options a multichannel render cannot honour: one colour or colormap for every channel
    (each has its own), several isovalues, pre-smoothing."""
    for flag, value, instead in (("--colormap", args.colormap, "--channel-colors"),
                                 ("--color", args.color, "--channel-colors"),
                                 ("--opacity", args.opacity, "one --iso per channel"),
                                 ("--smooth", args.smooth, "a smoothed file")):
        if value:
            raise sc.ParameterError(f"{flag} does not apply to several channels (use {instead})")
    if args.iso and "," in args.iso:
        raise sc.ParameterError("--iso takes one value for several channels (--channel-iso "
                                "gives one per channel)")
    # The channel scene gives each channel its own value of the settings the mode reads.
    for flag, value, keyword in (("--channel-iso", args.channel_iso, "iso"),
                                 ("--channel-window", args.channel_window, "window")):
        if value is not None and keyword not in reads(args):
            raise sc.ParameterError(f"{flag} does not apply to --mode {args.mode} "
                                    f"(only to --mode {_reading(keyword)})")


def _channel_kwargs(args: argparse.Namespace) -> dict:
    """``ChannelScene.render`` keywords of the options every channel shares."""
    kwargs: dict = {"mode": args.mode}
    if args.samples is not None:
        kwargs["samples"] = args.samples
    clip = [numbers(c, "--clip", 4) for c in args.clip]
    if clip:
        kwargs["clip"] = clip
    if args.crop:
        kwargs["crop"] = numbers(args.crop, "--crop", 6)
    if args.background is not None:
        kwargs["shading"] = sc.Shading(background=sc.transfer.parse_color(
            args.background, "--background", alpha=True))
    if args.inside is not None:
        kwargs["inside"] = args.inside
    keywords = reads(args)
    if "method" in keywords:
        kwargs.update(method=args.method, step=sampled_step(args))
    if "normals" in keywords:
        kwargs["normals"] = args.normals
    if "tolerance" in keywords and args.tolerance:
        kwargs["tolerance"] = args.tolerance
    if "window" in keywords and args.window:
        kwargs["window"] = numbers(args.window, "--window", 2)
    if "tf" in keywords and args.tf:
        kwargs["tf"] = sc.TransferFunction.load(args.tf)
    if "dvr" in keywords:
        settings = dvr_settings(args)
        if settings is not None:
            kwargs["dvr"] = settings
    if "iso" in keywords and args.iso:
        kwargs["iso"] = numbers(args.iso, "--iso", 1)[0]  # type: ignore[index]
    return kwargs


def _run_channels(args: argparse.Namespace, volumes: sc.MultichannelVolume, read_s: float,
                  derived: bool) -> int:
    """Render several channels together (:class:`splinecast.ChannelScene`) to ``args.output``."""
    multiscale = any(not isinstance(v, sc.Volume) for v in volumes)
    if any(isinstance(v, sc.WaveletVolume) for v in volumes):
        raise sc.ParameterError(f"{args.file}: a wavelet store holds one channel")
    _refuse_multiscale_options(args, multiscale)
    if args.method != "exact" or ("dvr" in reads(args) and args.step is not None):
        limits.check_step(sampled_step(args), "--step", volumes.shape)
    settings = channel_settings(args, len(volumes))
    kwargs = _channel_kwargs(args)
    options = model_options(args)
    if multiscale:
        options.update(budget=args.budget or DEFAULT_BUDGET, cut=args.cut or DEFAULT_CUT,
                       lod=DEFAULT_LOD if args.lod is None else args.lod)
    with contextlib.ExitStack() as stack:
        start = time.perf_counter()
        scene = stack.enter_context(sc.ChannelScene(volumes, model=args.model, **settings,
                                                    **options))
        what = "opened" if multiscale else "read"
        log(args, f"{what} {volumes.name}: {len(volumes)} channels, {volumes.shape} "
                  f"{volumes.dtype} in {read_s:.2f} s; prepared {args.model} models in "
                  f"{time.perf_counter() - start:.2f} s")
        for index, channel in zip(volumes.indices, scene.channels, strict=True):
            colour = "#" + "".join(f"{round(255 * c):02x}" for c in channel.color)
            state = "" if channel.visible else " (hidden: inactive in the file's metadata)"
            window = (f", window {channel.window[0]:g}..{channel.window[1]:g}"
                      if channel.window and "window" in reads(args) else "")
            log(args, f"channel {index} {channel.label!r}: {colour}{window}{state}")
        mode = kwargs.pop("mode")
        fit: object = "box"
        if args.fit == "content":
            fit = scene.content_box(iso=kwargs.get("iso"), tf=kwargs.get("tf"))
        camera = sc.Camera.orbit(scene, azimuth=args.azimuth, elevation=args.elevation,
                                 fit=fit, **orbit_options(args))
        stack.enter_context(CompileNotice(
            f"{args.model} / {mode}, {volumes.dtype.name} data", args.model,
            enabled=not getattr(args, "quiet", False), stream=getattr(args, "stderr", None)))
        extra = ({"complete": True, "missing": "substitute" if args.allow_missing else "error"}
                 if multiscale else {})
        start = time.perf_counter()
        frame = scene.render(camera, mode, outputs=("rgba", "depth", "stats"), **extra,
                             **kwargs)
        st = frame.stats
        drawn = len(st["channels"])
        log(args, f"rendered {camera.width}x{camera.height} {mode}, {drawn} channel"
                  f"{'s' if drawn != 1 else ''} composited ({st['compositing']}) in "
                  f"{time.perf_counter() - start:.2f} s ({st['hits']} hits)")
        frame.save(args.output, background=kwargs.get("shading", sc.Shading()).background)
        if derived:
            log(args, f"wrote {args.output} (named after the input; set -o)")
        if args.depth:
            frame.save_depth(args.depth)
            log(args, f"wrote depth {args.depth}")
        print(Path(args.output).resolve())
        warn_incomplete(args.output, st["channels"])
    return 0


def warn_incomplete(output: str, stats: list[dict]) -> None:
    """Say (last, even with ``--quiet``) that ``output`` is incomplete when frames drew
    unreadable bricks from a coarser level (``--allow-missing``)."""
    bad = [st for st in stats if st.get("unreadable")]
    if not bad:
        return
    bricks = sum(int(st["unreadable"]) for st in bad)
    frames = f" in {len(bad)} of {len(stats)} frames" if len(stats) > 1 else ""
    warnings.warn(f"{output} is incomplete: {bricks} brick{'s' if bricks > 1 else ''}{frames} "
                  f"could not be read and were drawn from a coarser level (first: "
                  f"{bad[0]['unreadable_reason']})", IncompleteWarning, stacklevel=2)
