"""``splinecast view FILE``: the interactive viewer in the browser.

Prints the page's URL (with its access token) as the first line of stdout, opens the default
browser unless ``--no-browser``, and serves until Ctrl-C (exit status 0).
"""

from __future__ import annotations

import argparse
import asyncio
import math
import signal
import time
import webbrowser
from pathlib import Path

import splinecast as sc
from splinecast.errors import did_you_mean
from splinecast.render.modes import MODE_NAMES

from ._common import (
    add_input_options,
    add_selection_options,
    finite,
    log,
    numbers,
    read_options,
    uncaptured,
)
from .labels import wants_labels
from .render import DEFAULT_MODE

__all__ = ["add_parser", "run"]


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    view = sub.add_parser("view", help="explore a volume interactively in the web browser")
    view.add_argument("file", help="volume file, DICOM folder, Zarr folder (OME-Zarr pyramid or "
                      "wavelet store) or demo:NAME?size=N")
    view.add_argument("--model",
                      help=f"initial reconstruction ({', '.join(sc.MODELS)}; default trilinear; "
                           "bspline<d> for a degree-d wavelet store, the only model it renders)")
    view.add_argument("--mode", default=DEFAULT_MODE, choices=MODE_NAMES,
                      help=f"initial render mode (default {DEFAULT_MODE})")
    view.add_argument("--iso", help="initial isovalue(s) in data units, comma-separated "
                      "(default: the volume's, else Otsu's threshold of the non-background "
                      "histogram, as render)")
    view.add_argument("--port", type=int, default=0,
                      help="port to listen on (default 0: any free port)")
    view.add_argument("--host", default="127.0.0.1",
                      help="address to listen on (default 127.0.0.1: this machine only; "
                           "another address lets other machines in, protected by the token only)")
    view.add_argument("--no-browser", action="store_true",
                      help="do not open a web browser; just print the URL")
    view.add_argument("--budget", help="multiscale (OME-Zarr) volumes: RAM for bricks, e.g. "
                      "512MiB or 2GiB (default 2GiB)")
    view.add_argument("--lod", type=finite, help="multiscale volumes: refine while a voxel "
                      "covers more than this many pixels (default 1); wavelet stores: the angle "
                      "ε in radians below which cells are not refined (0: full resolution; "
                      "default one pixel's angle)")
    view.add_argument("--labels", action=argparse.BooleanOptionalAction, default=None,
                      help="a label volume (segmentation): each label's boundary as its own "
                           "surface in its own colour, a label list, and the label under the "
                           "cursor (default: for OME-Zarr label images; --no-labels shows their "
                           "raw values)")
    view.add_argument("--label-colors", metavar="TABLE",
                      help="--labels: colour table, .json or .csv (as render; default: the "
                           "store's image-label colours, else a palette)")
    view.add_argument("--quiet", action="store_true", help="no progress on stderr")
    add_selection_options(view, several=True)
    add_input_options(view)


async def _serve(server: object, args: argparse.Namespace, read: str) -> None:
    url = await server.start()  # warns on stderr when the host is not this machine only
    print(url, flush=True)
    # Progress only once the server listens, so a mistake stays a single line.
    log(args, read)
    log(args, "serving; press Ctrl-C to stop")
    if not args.no_browser:
        webbrowser.open(url)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    try:
        await stop.wait()
    finally:
        await server.stop()


def run(args: argparse.Namespace) -> int:
    """Serve ``args.file`` until interrupted."""
    # Imported here: the other subcommands never pay for the server library.
    from splinecast.viewer.handle import require_aiohttp

    require_aiohttp()
    from splinecast.viewer.server import ViewerServer

    if args.model is not None and args.model not in sc.MODELS:
        raise sc.ParameterError(f"--model must be one of {', '.join(sc.MODELS)}, "
                                f"got {args.model!r}{did_you_mean(args.model, sc.MODELS)}")
    isos = numbers(args.iso, "--iso")
    start = time.perf_counter()
    vol = sc.read(args.file, **read_options(args))
    several = isinstance(vol, sc.MultichannelVolume)
    _check_multires_options(args, vol[0] if several else vol)
    iso = None if isos is None else (isos[0] if len(isos) == 1 else isos)
    if several and args.labels:
        raise sc.ParameterError(f"--labels needs one volume of labels; {args.file} was read as "
                                f"{len(vol)} channels")
    labels = not several and wants_labels(args, vol)
    _check_label_options(args, labels, isos)
    server = ViewerServer(vol, model=args.model, mode=args.mode, iso=iso, host=args.host,
                          port=args.port, budget=args.budget, lod=args.lod,
                          allow_external=read_options(args)["allow_external"], labels=labels,
                          colors=None if args.label_colors is None
                          else Path(args.label_colors))
    seconds = time.perf_counter() - start
    if labels:
        count = len(server.shown.labels or ())
        read = (f"read {vol.name}: {count} label{'s' if count != 1 else ''}, {vol.shape} "
                f"{vol.dtype} in {seconds:.2f} s")
    elif several:
        read = (f"read {vol.name}: {len(vol)} channels ({', '.join(vol.labels)}), {vol.shape} "
                f"{vol.dtype} in {seconds:.2f} s")
    elif isinstance(vol, sc.Volume):
        read = f"read {vol.name}: {vol.shape} {vol.dtype} in {seconds:.2f} s"
    elif isinstance(vol, sc.WaveletVolume):
        read = (f"opened {vol.name}: degree-{vol.degree} wavelet store, {vol.layout.levels} "
                f"levels, {vol.shape} in {seconds:.2f} s (coarsest level read)")
    else:
        read = (f"opened {vol.name}: {len(vol.levels)} levels, {vol.shape} {vol.dtype} in "
                f"{seconds:.2f} s (coarsest level read; bricks load while you look)")
    with uncaptured(args):  # serving: warnings and log lines as they come, not at the end
        asyncio.run(_serve(server, args, read))
    log(args, "stopped")
    return 0


def _check_label_options(args: argparse.Namespace, labels: bool, isos: object) -> None:
    """Label options only with labels; options label volumes do not read, refused."""
    if not labels:
        if args.label_colors is not None:
            raise sc.ParameterError("--label-colors applies to --labels only")
        return
    if args.mode not in (sc.LabelScene.modes or ()):
        raise sc.ParameterError(f"--mode {args.mode} does not apply to --labels (labels show "
                                "as surfaces)")
    for flag, value in (("--iso", isos), ("--lod", args.lod)):
        if value is not None:
            raise sc.ParameterError(f"{flag} does not apply to --labels")


def _check_multires_options(args: argparse.Namespace, vol: object) -> None:
    """``--budget`` and ``--lod`` only for the data they apply to, checked as ``render`` does."""
    if isinstance(vol, sc.Volume):
        for flag, value in (("--budget", args.budget), ("--lod", args.lod)):
            if value is not None:
                raise sc.ParameterError(f"{flag} applies to multiscale (OME-Zarr) volumes and "
                                        f"wavelet stores only; {args.file} is a plain volume")
    elif isinstance(vol, sc.WaveletVolume):
        if args.budget is not None:
            raise sc.ParameterError(f"--budget does not apply to the wavelet store {args.file}")
        if args.lod is not None and not (math.isfinite(args.lod) and args.lod >= 0):
            raise sc.ParameterError(f"--lod must be an angle >= 0 in radians, got {args.lod}")
    else:
        if args.budget is not None:
            from splinecast.errors import limits

            limits.parse_bytes(args.budget, "--budget")
        if args.lod is not None and not (math.isfinite(args.lod) and args.lod > 0):
            raise sc.ParameterError(f"--lod must be a positive number of pixels, got {args.lod}")
