"""``splinecast render FILE -o OUT.png``: one image of any model in any mode."""

from __future__ import annotations

import argparse
import inspect
import time
from pathlib import Path

import splinecast as sc
from splinecast import limits

from ._common import add_input_options, check_output, finite, log, numbers

__all__ = ["add_parser", "run"]


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    render = sub.add_parser("render", help="render an isosurface, a MIP or a DVR image to a PNG")
    render.add_argument("file", help="volume file, DICOM folder or demo:NAME?size=N")
    render.add_argument("-o", "--output", required=True, help="output PNG path")
    render.add_argument("--iso", help="isovalue(s) in data units, comma-separated for several "
                        "translucent surfaces (default: the demo's)")
    render.add_argument("--model", default="trilinear", help="reconstruction (default trilinear)")
    render.add_argument("--root-finder", choices=("bernstein", "rfbs", "sturm", "newton"),
                        help="first-root solver of spline models (default: the model's)")
    render.add_argument("--iterations", type=int,
                        help="iteration budget of the root finder (default: the finder's)")
    render.add_argument("--prefilter", action="store_true",
                        help="B-spline models: interpolate the voxels instead of smoothing them")
    render.add_argument("--size", default="512x512", help="image WIDTHxHEIGHT (default 512x512)")
    render.add_argument("--azimuth", type=finite, default=30.0,
                        help="degrees around z (default 30)")
    render.add_argument("--elevation", type=finite, default=20.0,
                        help="degrees above xy (default 20)")
    render.add_argument("--distance", type=finite, help="camera distance from the volume centre")
    render.add_argument("--fov", type=finite, default=30.0, help="vertical field of view, degrees")
    render.add_argument("--zoom", type=finite, default=1.0, help="magnification (default 1)")
    render.add_argument("--ortho", action="store_true", help="orthographic projection")
    render.add_argument("--method", default="exact", choices=("exact", "sampled"),
                        help="exact analytic roots (default) or fixed-step sampling")
    render.add_argument("--step", type=finite, default=0.25,
                        help="sampling step in voxels for --method sampled (default 0.25)")
    render.add_argument("--inside", choices=("high", "low"),
                        help="which side of the isovalue is the object (default from the data)")
    render.add_argument("--depth", help="also save the depth buffer to this .npy file")
    _add_mode_options(render)
    render.add_argument("--quiet", action="store_true", help="no progress or timing on stderr")
    add_input_options(render)


def _add_mode_options(render: argparse.ArgumentParser) -> None:
    """Options of the render modes beyond the single isosurface (issue 5)."""
    render.add_argument("--mode", default="iso", choices=("iso", "mip", "minip", "dvr"),
                        help="isosurface (default), max/min intensity projection, or DVR")
    render.add_argument("--opacity", help="one opacity per --iso value, comma-separated")
    render.add_argument("--tf", help="transfer function JSON file (--mode dvr)")
    render.add_argument("--colormap", default="gray",
                        help="colormap of --mode mip/minip (default gray)")
    render.add_argument("--window", help="LO,HI value window of --mode mip/minip")
    render.add_argument("--clip", action="append", default=[], metavar="NX,NY,NZ,D",
                        help="clip plane keeping nx*x+ny*y+nz*z+d >= 0 (repeatable)")
    render.add_argument("--crop", metavar="X0,X1,Y0,Y1,Z0,Z1", help="world-space box to keep")
    render.add_argument("--texture", choices=("noise", "checker"), help="solid texture")
    render.add_argument("--texture-scale", type=finite, default=0.1,
                        help="checker cube / noise feature size in world units (default 0.1)")
    render.add_argument("--shading", default="phong", choices=("phong", "cel"),
                        help="smooth Blinn-Phong (default) or 4-band cel shading")
    render.add_argument("--smooth", type=int, choices=(3, 5),
                        help="Gaussian pre-smoothing kernel size")
    render.add_argument("--preintegration", default="2d", choices=("none", "2d", "3d"),
                        help="DVR classification (default 2d pre-integration)")
    render.add_argument("--table-layout", default="uniform", choices=("uniform", "exponential"),
                        help="DVR 3D pre-integration table lengths: k x step (default) or "
                             "2^j x step")
    render.add_argument("--adaptive", action="store_true",
                        help="DVR opacity-adaptive step (up to 8 x --step; uses a 3D table)")
    render.add_argument("--termination", type=finite,
                        help="DVR early ray termination opacity, e.g. 0.99")


def _mode_kwargs(args: argparse.Namespace, vol: sc.Volume) -> dict:
    """Scene.render keyword arguments of the mode options, validated before any rendering."""
    kwargs: dict = {"mode": args.mode}
    clip = [numbers(c, "--clip", 4) for c in args.clip]
    if clip:
        kwargs["clip"] = clip
    if args.crop:
        kwargs["crop"] = numbers(args.crop, "--crop", 6)
    if args.mode in ("mip", "minip"):
        kwargs["colormap"] = args.colormap
        sc.transfer.colormap_table(args.colormap, 2)  # a bad name fails before any work
        if args.window:
            kwargs["window"] = numbers(args.window, "--window", 2)
        kwargs["method"] = args.method
        kwargs["step"] = args.step
        return kwargs
    if args.mode == "dvr":
        if not args.tf:
            raise sc.ParameterError("--mode dvr needs --tf FILE.json")
        kwargs["tf"] = sc.TransferFunction.load(args.tf)
        pre = "3d" if args.adaptive and args.preintegration == "2d" else args.preintegration
        kwargs["dvr"] = sc.DVRSettings(step=args.step, preintegration=pre,
                                       adaptive=args.adaptive, h_max=8 * args.step,
                                       termination=args.termination,
                                       table_layout=args.table_layout)
        return kwargs
    isos = numbers(args.iso, "--iso")
    if isos is not None and (len(isos) > 1 or args.opacity):
        kwargs["iso"] = [sc.check_iso(vol, v) for v in isos]
        if args.opacity:
            kwargs["opacity"] = numbers(args.opacity, "--opacity", len(isos))
    else:
        kwargs["iso"] = sc.check_iso(vol, isos[0] if isos else None)
        kwargs["method"] = args.method
        kwargs["step"] = args.step
    if args.texture or args.shading == "cel":
        kwargs["effects"] = sc.SurfaceEffects(texture=args.texture, scale=args.texture_scale,
                                              cel_bands=4 if args.shading == "cel" else 0)
    return kwargs


def _check_options(args: argparse.Namespace) -> tuple[int, int]:
    """Ranges of the numeric options (argparse has made them finite), before any reading;
    returns the image size."""
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
    if args.method == "sampled" or args.mode == "dvr":
        limits.check_finite_number(args.step, "--step (voxels)", lo=limits.MIN_STEP)
    if args.iterations is not None:
        limits.check_count(args.iterations, "--iterations", hi=limits.MAX_ROOT_ITERATIONS)
    limits.check_finite_number(args.texture_scale, "--texture-scale", lo=0, lo_open=True)
    if args.termination is not None:
        limits.check_finite_number(args.termination, "--termination", lo=0, hi=1, lo_open=True)
    return width, height


def run(args: argparse.Namespace) -> int:
    """Render ``args.file`` to ``args.output``."""
    # Validate every option and output path before any work, so a mistake writes nothing.
    check_output(args.output, ".png", "-o")
    if args.depth:
        check_output(args.depth, ".npy", "--depth")
    width, height = _check_options(args)

    start = time.perf_counter()
    vol = sc.read(args.file, allow_external=args.allow_external_data or None)
    read_s = time.perf_counter() - start
    if args.method == "sampled" or args.mode == "dvr":
        limits.check_step(args.step, "--step", vol.shape)
    if args.model not in sc.MODELS:
        valid = ", ".join(sc.MODELS)
        raise sc.ParameterError(
            f"--model must be one of {valid}, got {limits.shorten(args.model)}"
        )
    options = {}
    accepted = inspect.signature(sc.MODELS[args.model]).parameters
    for name, flag in (("root_finder", "--root-finder"), ("iterations", "--iterations"),
                       ("prefilter", "--prefilter")):
        value = getattr(args, name)
        if value is None or value is False:
            continue
        if name not in accepted:
            raise sc.ParameterError(f"{flag} does not apply to model {args.model}")
        options[name] = value
    kwargs = _mode_kwargs(args, vol)
    camera = sc.Camera.orbit(
        vol, azimuth=args.azimuth, elevation=args.elevation, distance=args.distance,
        size=(width, height), fov=args.fov, ortho=args.ortho, zoom=args.zoom,
    )
    # Progress starts only once every input is known to be valid, so a mistake is one line.
    log(args, f"read {vol.name}: {vol.shape} {vol.dtype} in {read_s:.2f} s")
    if args.smooth:
        limits.check_memory(limits.nbytes(vol.shape, 8) * 2, "smoothing the volume",
                            "--smooth")
        vol = sc.smooth(vol, args.smooth)
        log(args, f"smoothed with a {args.smooth}^3 Gaussian")
    start = time.perf_counter()
    scene = sc.Scene(vol, model=args.model, **options)
    log(args, f"prepared {args.model} model in {time.perf_counter() - start:.2f} s")
    start = time.perf_counter()
    frame = scene.render(camera, inside=args.inside, **kwargs)
    st = frame.stats
    what = f"at iso {st['iso']}" if "iso" in st else st["mode"]
    log(args, f"rendered {width}x{height} {what} in "
               f"{time.perf_counter() - start:.2f} s (trace {st['trace_ms']:.0f} ms, "
               f"{st['hits']} hits, {st['mean_cells_visited']:.1f} cells/ray; "
               "the first run includes compilation)")
    frame.save(args.output)
    if args.depth:
        frame.save_depth(args.depth)
        log(args, f"wrote depth {args.depth}")
    print(Path(args.output).resolve())
    return 0
