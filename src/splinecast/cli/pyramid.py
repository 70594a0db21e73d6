"""``splinecast pyramid SOURCE -o OUT.zarr``: an OME-Zarr brick pyramid."""

from __future__ import annotations

import argparse
import contextlib
import sys
import time

from ._common import add_input_options, log

__all__ = ["add_parser", "run"]


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    cmd = sub.add_parser(
        "pyramid", help="write a volume as an OME-Zarr 0.5 multiresolution brick pyramid",
        description="Build an OME-Zarr 0.5 pyramid (Zarr v3, sharded, zstd) chunk by chunk in "
                    "bounded memory; the store appears under its name only when complete.")
    cmd.add_argument("source", help="volume file (raw data stays memory-mapped), Zarr folder "
                     "or demo:NAME?size=N")
    cmd.add_argument("-o", "--output", required=True, help="output store (a folder, NAME.zarr)")
    cmd.add_argument("--brick", type=int, default=32,
                     help="cells per brick and chunk along each axis (default 32)")
    cmd.add_argument("--levels", type=int, help="at most this many levels (default: until the "
                     "coarsest fits in one brick)")
    cmd.add_argument("--unit", help="length unit of the spacing (default: from the header)")
    cmd.add_argument("--workers", type=int, help="threads (default: up to 4)")
    cmd.add_argument("--wavelet", type=int, metavar="DEGREE",
                     help="write a spline-wavelet pyramid for B-spline degree 1, 2 or 3 instead "
                          "(rendered with model bspline<DEGREE>; --brick does not apply)")
    cmd.add_argument("--histograms", action="store_true",
                     help="also store the brick histograms of the error cut (--cut error): "
                          "opening it then reads no level, a transfer-function edit no voxel")
    cmd.add_argument("--labels", action=argparse.BooleanOptionalAction, default=None,
                     help="a label volume (segmentation): coarser levels take the most "
                          "frequent label, never an average, and the store is marked as an "
                          "OME-Zarr label image (default: when the source is one)")
    cmd.add_argument("--overwrite", action="store_true", help="replace an existing store")
    cmd.add_argument("--quiet", action="store_true", help="no progress on stderr")
    add_input_options(cmd)


def run(args: argparse.Namespace) -> int:
    """Build the pyramid; print the store's path on stdout."""
    from pathlib import Path

    import splinecast as sc
    from splinecast.multires.store.pyramid import build_pyramid

    out = Path(args.output)
    if out.suffix.lower() != ".zarr":
        raise sc.ParameterError(f"-o {args.output}: must end in .zarr")
    if out.exists() and not args.overwrite:
        raise sc.ParameterError(f"-o {args.output}: already exists (use --overwrite)")
    start = time.perf_counter()
    # The per-level progress goes to the real stderr, past the capture of library output
    # (splinecast.cli.main); warnings and log records stay captured.
    if args.wavelet is not None:
        if args.labels:
            raise sc.ParameterError("--labels does not apply to --wavelet pyramids (a wavelet "
                                    "pyramid averages)")
        if args.wavelet not in (1, 2, 3):
            raise sc.ParameterError(f"--wavelet must be a B-spline degree 1, 2 or 3, got "
                                    f"{args.wavelet}")
        with contextlib.redirect_stderr(getattr(args, "stderr", sys.stderr)):
            wv = build_pyramid(args.source, out, levels=args.levels, overwrite=args.overwrite,
                               progress=not args.quiet, kind="wavelet", degree=args.wavelet)
        log(args, f"wrote a degree-{wv.degree} wavelet pyramid of {wv.layout.levels} levels in "
                  f"{time.perf_counter() - start:.1f} s")
        print(out)
        return 0
    with contextlib.redirect_stderr(getattr(args, "stderr", sys.stderr)):
        mv = build_pyramid(args.source, out, brick=args.brick, levels=args.levels,
                           overwrite=args.overwrite, unit=args.unit, workers=args.workers,
                           progress=not args.quiet, histograms=args.histograms,
                           allow_external=args.allow_external_data or None,
                           labels=args.labels)
    kind = " of labels (most frequent label per block)" if mv.attributes.get("labels") else ""
    log(args, f"wrote {len(mv.levels)} levels{kind} in {time.perf_counter() - start:.1f} s")
    print(out)
    return 0
