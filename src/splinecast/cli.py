"""The ``splinecast`` command line: a thin front end over the public API.

User mistakes print one line (``splinecast: error: ...``) naming the file or option and exit with
status 2. Progress and timings go to stderr (``--quiet`` silences them); the path of a written image
goes to stdout.
"""

from __future__ import annotations

import argparse
import inspect
import sys
import time
from pathlib import Path
from typing import NoReturn

import numpy as np

import splinecast as sc

__all__ = ["main"]

_PERCENTILES = (0.5, 1, 5, 25, 50, 75, 95, 99, 99.5)
_EXACT_STATS_LIMIT = 64_000_000  # voxels; above this, percentiles come from a strided subsample


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line and exit status 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"splinecast: error: {message} (see --help)\n")


def _build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="splinecast", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"splinecast {sc.__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    info = sub.add_parser("info", help="describe a volume file: shape, dtype, spacing, values")
    info.add_argument("file", help="volume file, DICOM folder or demo:NAME?size=N")

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
    render.add_argument("--azimuth", type=float, default=30.0,
                        help="degrees around z (default 30)")
    render.add_argument("--elevation", type=float, default=20.0,
                        help="degrees above xy (default 20)")
    render.add_argument("--distance", type=float, help="camera distance from the volume centre")
    render.add_argument("--fov", type=float, default=30.0, help="vertical field of view, degrees")
    render.add_argument("--zoom", type=float, default=1.0, help="magnification (default 1)")
    render.add_argument("--ortho", action="store_true", help="orthographic projection")
    render.add_argument("--method", default="exact", choices=("exact", "sampled"),
                        help="exact analytic roots (default) or fixed-step sampling")
    render.add_argument("--step", type=float, default=0.25,
                        help="sampling step in voxels for --method sampled (default 0.25)")
    render.add_argument("--inside", choices=("high", "low"),
                        help="which side of the isovalue is the object (default from the data)")
    render.add_argument("--depth", help="also save the depth buffer to this .npy file")
    _add_mode_options(render)
    render.add_argument("--quiet", action="store_true", help="no progress or timing on stderr")
    return parser


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
    render.add_argument("--texture-scale", type=float, default=0.1,
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
    render.add_argument("--termination", type=float,
                        help="DVR early ray termination opacity, e.g. 0.99")


def _numbers(text: str | None, option: str, count: int | None = None) -> list[float] | None:
    """Comma-separated numbers of ``option`` (``count`` of them when given)."""
    if text is None:
        return None
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise sc.ParameterError(f"{option} must be comma-separated numbers, got {text!r}") from None
    if count is not None and len(values) != count:
        raise sc.ParameterError(f"{option} needs {count} numbers, got {text!r}")
    return values


def _mode_kwargs(args: argparse.Namespace, vol: sc.Volume) -> dict:
    """Scene.render keyword arguments of the mode options, validated before any rendering."""
    kwargs: dict = {"mode": args.mode}
    clip = [_numbers(c, "--clip", 4) for c in args.clip]
    if clip:
        kwargs["clip"] = clip
    if args.crop:
        kwargs["crop"] = _numbers(args.crop, "--crop", 6)
    if args.mode in ("mip", "minip"):
        kwargs["colormap"] = args.colormap
        sc.transfer.colormap_table(args.colormap, 2)  # a bad name fails before any work
        if args.window:
            kwargs["window"] = _numbers(args.window, "--window", 2)
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
    isos = _numbers(args.iso, "--iso")
    if isos is not None and (len(isos) > 1 or args.opacity):
        kwargs["iso"] = [sc.check_iso(vol, v) for v in isos]
        if args.opacity:
            kwargs["opacity"] = _numbers(args.opacity, "--opacity", len(isos))
    else:
        kwargs["iso"] = sc.check_iso(vol, isos[0] if isos else None)
        kwargs["method"] = args.method
        kwargs["step"] = args.step
    if args.texture or args.shading == "cel":
        kwargs["effects"] = sc.SurfaceEffects(texture=args.texture, scale=args.texture_scale,
                                              cel_bands=4 if args.shading == "cel" else 0)
    return kwargs


def _log(args: argparse.Namespace, message: str) -> None:
    if not getattr(args, "quiet", False):
        print(message, file=sys.stderr, flush=True)


def _check_output(path: str, suffix: str, option: str) -> None:
    p = Path(path)
    if p.suffix.lower() != suffix:
        raise sc.ParameterError(f"{option} {path}: must end in {suffix}")
    if not p.parent.exists():
        raise sc.ParameterError(f"{option} {path}: the folder {p.parent} does not exist")
    if p.is_dir():
        raise sc.ParameterError(f"{option} {path}: is a folder")


def _cmd_info(args: argparse.Namespace) -> int:
    vol = sc.read(args.file)
    data = vol.data
    sample = data
    note = ""
    if data.size > _EXACT_STATS_LIMIT:
        stride = int(np.ceil((data.size / _EXACT_STATS_LIMIT) ** (1 / 3)))
        sample = data[::stride, ::stride, ::stride]
        note = f" (percentiles from every {stride}th voxel per axis)"
    lo, hi = vol.value_range
    finite = sample[np.isfinite(sample)] if sample.dtype.kind == "f" else sample.reshape(-1)
    pct = np.percentile(finite, _PERCENTILES)
    print(f"file:      {vol.metadata.get('source', vol.name)}")
    print(f"shape:     {' x '.join(str(n) for n in vol.shape)} (x, y, z)")
    print(f"dtype:     {vol.dtype}")
    print(f"spacing:   {', '.join(f'{s:g}' for s in vol.spacing)}")
    print(f"origin:    {', '.join(f'{s:g}' for s in vol.origin)}")
    print(f"extent:    {', '.join(f'{s:g}' for s in vol.extent)}")
    print(f"range:     {lo:g} .. {hi:g}")
    print(f"NaN:       {vol.count_nan()}")
    print("percentiles" + note + ":")
    for p, v in zip(_PERCENTILES, pct, strict=True):
        print(f"  {p:>5g}%  {v:g}")
    if "default_iso" in vol.metadata:
        print(f"default iso: {vol.metadata['default_iso']:g}")
    return 0


def _cmd_render(args: argparse.Namespace) -> int:
    # Validate every option and output path before any work, so a mistake writes nothing.
    _check_output(args.output, ".png", "-o")
    if args.depth:
        _check_output(args.depth, ".npy", "--depth")
    if args.method == "sampled" and not args.step > 0:
        raise sc.ParameterError(f"--step must be positive, got {args.step}")
    width, height = sc.camera.parse_size(args.size)

    start = time.perf_counter()
    vol = sc.read(args.file)
    read_s = time.perf_counter() - start
    if args.model not in sc.MODELS:
        valid = ", ".join(sc.MODELS)
        raise sc.ParameterError(f"--model must be one of {valid}, got {args.model!r}")
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
    _log(args, f"read {vol.name}: {vol.shape} {vol.dtype} in {read_s:.2f} s")
    if args.smooth:
        vol = sc.smooth(vol, args.smooth)
        _log(args, f"smoothed with a {args.smooth}^3 Gaussian")
    start = time.perf_counter()
    scene = sc.Scene(vol, model=args.model, **options)
    _log(args, f"prepared {args.model} model in {time.perf_counter() - start:.2f} s")
    start = time.perf_counter()
    frame = scene.render(camera, inside=args.inside, **kwargs)
    st = frame.stats
    what = f"at iso {st['iso']}" if "iso" in st else st["mode"]
    _log(args, f"rendered {width}x{height} {what} in "
               f"{time.perf_counter() - start:.2f} s (trace {st['trace_ms']:.0f} ms, "
               f"{st['hits']} hits, {st['mean_cells_visited']:.1f} cells/ray; "
               "the first run includes compilation)")
    frame.save(args.output)
    if args.depth:
        frame.save_depth(args.depth)
        _log(args, f"wrote depth {args.depth}")
    print(Path(args.output).resolve())
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    parser = _build_parser()
    args = parser.parse_args(argv)
    try:
        if args.command == "info":
            return _cmd_info(args)
        return _cmd_render(args)
    except sc.SplinecastError as exc:
        print(f"splinecast: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
