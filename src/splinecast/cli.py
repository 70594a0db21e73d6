"""The ``splinecast`` command line: a thin front end over the public API.

User mistakes print one line (``splinecast: error: ...``) naming the file or option and exit with
status 2. Progress and timings go to stderr (``--quiet`` silences them); the path of a written image
goes to stdout.
"""

from __future__ import annotations

import argparse
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

    render = sub.add_parser("render", help="render an isosurface to a PNG")
    render.add_argument("file", help="volume file, DICOM folder or demo:NAME?size=N")
    render.add_argument("-o", "--output", required=True, help="output PNG path")
    render.add_argument("--iso", type=float, help="isovalue in data units (default: the demo's)")
    render.add_argument("--model", default="trilinear", help="reconstruction (default trilinear)")
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
    render.add_argument("--quiet", action="store_true", help="no progress or timing on stderr")
    return parser


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
    iso = sc.check_iso(vol, args.iso)
    camera = sc.Camera.orbit(
        vol, azimuth=args.azimuth, elevation=args.elevation, distance=args.distance,
        size=(width, height), fov=args.fov, ortho=args.ortho, zoom=args.zoom,
    )
    # Progress starts only once every input is known to be valid, so a mistake is one line.
    _log(args, f"read {vol.name}: {vol.shape} {vol.dtype} in {read_s:.2f} s")
    start = time.perf_counter()
    scene = sc.Scene(vol, model=args.model)
    _log(args, f"prepared {args.model} model in {time.perf_counter() - start:.2f} s")
    start = time.perf_counter()
    frame = scene.render(camera, iso=iso, method=args.method, step=args.step,
                         inside=args.inside)
    st = frame.stats
    _log(args, f"rendered {width}x{height} at iso {st['iso']:g} in "
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
