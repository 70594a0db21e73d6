"""``splinecast movie FILE --frames N -o OUT``: a turntable or a sweep as MP4, GIF or PNG frames;
``--timepoints A:B[:STEP]``: a movie over the time points of a time series.

Without ``--workers`` or ``--scheduler`` the movie renders in this process, one frame after
another, each on all cores (Numba threads); no Dask is needed. ``--workers N`` starts a local Dask
cluster of N single-threaded worker processes, ``--scheduler ADDRESS`` uses a running cluster
whose workers can open FILE; there each frame is one task. Frames are written in order as they
complete, and the movie appears under its name only when the last one is written.

A movie over time renders in this process: frame i is time point i of the range, read and
prepared when its turn comes (one in memory at a time), with the camera fixed unless swept. The
isovalue, window, colormap and transfer function are chosen once, from the first time point of
the range, and kept for every frame: per-frame choices would make the brightness flicker, and
choosing from all of them would read every time point twice (give ``--iso``/``--window`` to fix
them otherwise).
"""

from __future__ import annotations

import argparse
import contextlib
import math
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

import splinecast as sc
from splinecast.distributed import (
    MovieWriter,
    SceneSource,
    Shot,
    orbit_path,
    ramp,
    render_locally,
)
from splinecast.io.omezarr import MultiscaleVolume, is_zarr
from splinecast.render.modes import modes_reading

from ._common import (
    add_input_options,
    add_missing_option,
    add_selection_options,
    derived_output,
    finite,
    log,
    numbers,
    read_options,
)
from ._compiling import CompileNotice
from ._progress import Progress
from .render import (
    add_render_options,
    check_render_args,
    mode_kwargs,
    model_options,
    orbit_options,
    output_stem,
    reads,
    warn_incomplete,
)

__all__ = ["add_parser", "run"]

#: Start of the default turntable, the same view as ``splinecast render``'s default.
DEFAULT_AZIMUTH = 30.0
DEFAULT_ELEVATION = 20.0


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    movie = sub.add_parser(
        "movie", help="render a turntable or an isovalue sweep to MP4, GIF or PNG frames",
        description="Render a turntable (by default one full turn) or a sweep of the camera "
                    "angles or the isovalue, locally or on a Dask cluster.")
    movie.add_argument("file", help="volume file, DICOM folder or demo:NAME?size=N")
    movie.add_argument("-o", "--output",
                       help="OUT.mp4, OUT.gif, or a folder (OUT/) for frame_0000.png, ... "
                            "(default: NAME.mp4, or NAME-MODE.mp4 for another mode than iso, "
                            "in the current folder, NAME from the input; printed)")
    movie.add_argument("--frames", type=int,
                       help="number of frames (required, except with --timepoints: one per "
                            "time point)")
    movie.add_argument("--timepoints", metavar="A:B[:STEP]",
                       help="a movie over time: time points A to B-1 (every STEP-th), Python "
                            "slice syntax ('0:20', '::2', ':' for all); camera fixed unless "
                            "--azimuth/--elevation sweep; iso, window and colours from time "
                            "point A for every frame")
    movie.add_argument("--azimuth", metavar="A0[:A1]",
                       help="degrees around z, fixed or from A0 to A1 (default: a full turn "
                            "30:390 when nothing else is swept, else 30)")
    movie.add_argument("--elevation", metavar="E0[:E1]",
                       help="degrees above xy, fixed or from E0 to E1 (default 20)")
    movie.add_argument("--iso", metavar="V0[:V1]",
                       help="isovalue in data units, fixed, a V0:V1 sweep, or comma-separated "
                            "for several translucent surfaces (default: the volume's, else "
                            "Otsu's threshold of the non-background histogram, as render)")
    movie.add_argument("--fps", type=finite, default=24.0, help="frames per second (default 24)")
    movie.add_argument("--quality", type=finite, default=8.0,
                       help="MP4 quality from 1 to 10 (default 8)")
    where = movie.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, metavar="N",
                       help="render on a local Dask cluster of N single-threaded processes")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="render on the Dask cluster at ADDRESS (tcp://host:8786); its "
                            "workers must be able to open FILE")
    add_render_options(movie)
    movie.add_argument("--lod", type=finite,
                       help="spline-wavelet stores: the angle ε in radians below which cells are "
                            "not refined (0: full resolution; default one pixel's angle); the "
                            "coarse bricks are reused from frame to frame")
    movie.add_argument("--quiet", action="store_true", help="no progress on stderr")
    add_missing_option(movie)
    add_selection_options(movie)
    add_input_options(movie)


def _range(text: str | None, option: str) -> float | tuple[float, float] | None:
    """``"A"`` -> A, ``"A0:A1"`` -> (A0, A1), None -> None."""
    if text is None:
        return None
    parts = text.split(":")
    if len(parts) > 2:
        raise sc.ParameterError(f"{option} must be V or V0:V1, got {text!r}")
    values = [numbers(p, option, 1)[0] for p in parts]
    return values[0] if len(values) == 1 else (values[0], values[1])


def _shots(args: argparse.Namespace, volume: Any, kwargs: dict[str, Any],
           iso_sweep: tuple[float, float] | None) -> list[Shot]:
    """One Shot per frame: the turntable's cameras and, for a sweep, each frame's isovalue."""
    elevation = _range(args.elevation, "--elevation")
    azimuth = _range(args.azimuth, "--azimuth")
    if azimuth is None:
        swept = (isinstance(elevation, tuple) or iso_sweep is not None
                 or args.timepoints is not None)
        azimuth = DEFAULT_AZIMUTH if swept else (DEFAULT_AZIMUTH, DEFAULT_AZIMUTH + 360.0)
    cameras = orbit_path(volume, args.frames, azimuth=azimuth,
                         elevation=DEFAULT_ELEVATION if elevation is None else elevation,
                         **orbit_options(args))
    if iso_sweep is None:
        return [Shot(camera, kwargs) for camera in cameras]
    isos = ramp(iso_sweep, args.frames, "--iso")
    return [Shot(camera, {**kwargs, "iso": float(v)})
            for camera, v in zip(cameras, isos, strict=True)]


def _slice(text: str) -> slice:
    """``--timepoints`` ``A:B[:STEP]`` (each part optional, none negative) as a slice."""
    parts = text.split(":")
    if not 2 <= len(parts) <= 3:
        raise sc.ParameterError(f"--timepoints must be A:B or A:B:STEP, got {text!r}")
    values: list[int | None] = []
    for part in parts:
        part = part.strip()
        try:
            value = int(part) if part else None
        except ValueError:
            raise sc.ParameterError(f"--timepoints must be A:B or A:B:STEP of whole numbers, got "
                                    f"{text!r}") from None
        if value is not None and value < 0:
            raise sc.ParameterError(f"--timepoints counts from 0, got {text!r}")
        values.append(value)
    if len(values) == 3 and values[2] == 0:
        raise sc.ParameterError(f"--timepoints: STEP must be at least 1, got {text!r}")
    return slice(*values)


def _timepoints(args: argparse.Namespace, chosen: slice, count: int) -> list[int]:
    """The time points of ``chosen`` in a file of ``count``: a start or stop past the end is
    a mistake (a slice would clip it silently), an empty range too."""
    label = args.file
    if chosen.start is not None and chosen.start >= count:
        raise sc.ParameterError(f"{label}: --timepoints {args.timepoints} starts past the end "
                                f"(it holds {count} time point{'s' if count > 1 else ''}: "
                                f"{'0' if count == 1 else f'0 to {count - 1}'})")
    if chosen.stop is not None and chosen.stop > count:
        raise sc.ParameterError(f"{label}: --timepoints {args.timepoints} ends past the end "
                                f"(it holds {count} time point{'s' if count > 1 else ''}; "
                                f"the stop may be at most {count})")
    points = list(range(count))[chosen]
    if not points:
        raise sc.ParameterError(f"{label}: --timepoints {args.timepoints} is empty")
    return points


def _time_frames(args: argparse.Namespace, points: list[int], shots: list[Shot],
                 options: dict[str, Any], first: Any, image_only: bool) -> Iterator[Any]:
    """Frame i: time point ``points[i]`` read, prepared and rendered with ``shots[i]`` (as
    :func:`render_locally` renders it); one time point in memory at a time (``first``, the
    scene of ``points[0]``, is used for it)."""
    for point, shot in zip(points, shots, strict=True):
        if point == points[0]:
            scene = first
        else:
            volume = sc.read(args.file, **{**read_options(args), "timepoint": point})
            if args.smooth:
                volume = sc.smooth(volume, args.smooth)
            scene = sc.Scene(volume, model=args.model, **options)
        try:
            yield from render_locally(scene, [shot], image_only=image_only)
        finally:
            if scene is not first:
                scene.close()


def _iso_sweep(args: argparse.Namespace) -> tuple[float, float] | None:
    """The ``--iso V0:V1`` sweep, if any; leaves ``args.iso`` at V0 for the option checks."""
    if args.iso is None or ":" not in args.iso:
        return None
    sweep = _range(args.iso, "--iso")
    if "iso" not in reads(args) or "," in args.iso:
        raise sc.ParameterError("--iso V0:V1 sweeps one isosurface: use it with --mode "
                                + "/".join(modes_reading("iso")))
    args.iso = repr(sweep[0])
    return sweep


@contextlib.contextmanager
def _dask_client(args: argparse.Namespace) -> Iterator[Any]:
    """A client of the cluster ``--scheduler`` names, or of a local one of ``--workers``
    single-threaded processes (shut down afterwards)."""
    try:
        from distributed import Client

        from splinecast.distributed.cluster import local_cluster
    except ImportError:
        raise sc.ParameterError("--workers/--scheduler need Dask: "
                                "pip install 'splinecast[distributed]'") from None
    if args.scheduler:
        try:
            client = Client(args.scheduler, timeout="10s")
        except OSError as exc:
            raise sc.ParameterError(f"--scheduler {args.scheduler}: cannot connect ({exc})"
                                    ) from None
        with client:
            yield client
        return
    # Single-threaded worker processes with Dask's background polling turned down (it would
    # take its share of the cores from the renders); worker logs quiet below errors, any free
    # port for the dashboard (see splinecast.distributed.cluster).
    with local_cluster(args.workers) as cluster, Client(cluster) as client:
        yield client


def _wavelet_store(args: argparse.Namespace) -> Any:
    """The spline-wavelet store ``args.file`` names (opened lazily: metadata only), else
    ``None``; ``--lod`` applies to such stores only, which render in this process with their
    own model (``bspline<degree>``) and no ``--smooth``."""
    path = Path(args.file)
    if not args.file.startswith("demo:") and path.is_dir() and is_zarr(path):
        volume = sc.read(path, allow_external=args.allow_external_data or None)
        if isinstance(volume, sc.WaveletVolume):
            for flag, value in (("--smooth", args.smooth), ("--workers", args.workers),
                                ("--scheduler", args.scheduler)):
                if value:
                    raise sc.ParameterError(f"{flag} does not apply to the wavelet store "
                                            f"{args.file}")
            if args.model is None:
                args.model = f"bspline{volume.degree}"
            return volume
    if args.lod is not None:
        raise sc.ParameterError(f"--lod applies to spline-wavelet stores only, not {args.file}")
    return None


def run(args: argparse.Namespace) -> int:
    """Render the movie ``args.output``."""
    # Validate every option and the output before any work, so a mistake writes nothing.
    if args.output is None:
        args.output = str(derived_output(args.file, output_stem(args.mode), ".mp4"))
    width, height = check_render_args(args)
    over_time = _slice(args.timepoints) if args.timepoints is not None else None
    if over_time is not None:
        for flag, value in (("--timepoint", args.timepoint), ("--volume", args.volume),
                            ("--workers", args.workers), ("--scheduler", args.scheduler),
                            ("--lod", args.lod)):
            if value is not None:
                raise sc.ParameterError(f"--timepoints makes a movie over time in this process: "
                                        f"{flag} does not apply")
    elif args.frames is None:
        raise sc.ParameterError("--frames N is required (or --timepoints A:B for a movie over "
                                "time)")
    if args.frames is not None and args.frames < 1:
        raise sc.ParameterError(f"--frames must be at least 1, got {args.frames}")
    if args.workers is not None and args.workers < 1:
        raise sc.ParameterError(f"--workers must be at least 1, got {args.workers}")
    iso_sweep = _iso_sweep(args)
    _range(args.azimuth, "--azimuth")
    _range(args.elevation, "--elevation")
    if args.lod is not None and not (math.isfinite(args.lod) and args.lod >= 0):
        raise sc.ParameterError(f"--lod must be an angle >= 0 in radians, got {args.lod}")
    points: list[int] | None = None
    if over_time is not None:
        # The first time point of the range: read now, it gives the count and the defaults.
        first_point = over_time.start or 0
        try:
            first = sc.read(args.file, **{**read_options(args), "timepoint": first_point})
        except sc.ParameterError:
            if not first_point:
                raise
            # Past the end (or a bad channel): the message should name --timepoints.
            count = sc.read(args.file, **read_options(args)).metadata.get("timepoints", 1)
            _timepoints(args, over_time, int(count))
            raise
        if isinstance(first, sc.WaveletVolume):
            raise sc.ParameterError(f"--timepoints: the wavelet store {args.file} holds one "
                                    "volume")
        points = _timepoints(args, over_time, int(first.metadata.get("timepoints", 1)))
        if args.frames is not None and args.frames != len(points):
            raise sc.ParameterError(f"--frames {args.frames} and --timepoints "
                                    f"{args.timepoints} ({len(points)} time points) disagree: "
                                    "leave out --frames")
        args.frames = len(points)
    writer = MovieWriter(args.output, (width, height), args.frames, fps=args.fps,
                         quality=args.quality)
    wavelet = _wavelet_store(args) if points is None else None
    options = model_options(args)
    source = SceneSource(args.file, args.model, options, args.smooth,
                         allow_external=args.allow_external_data or None,
                         timepoint=args.volume if args.timepoint is None else args.timepoint,
                         channel=args.channel)

    start = time.perf_counter()
    local = args.workers is None and args.scheduler is None
    with contextlib.ExitStack() as stack:
        if wavelet is not None:
            scene = sc.Scene(wavelet, model=args.model, lod=args.lod, **options)
            volume = wavelet
            where = "in this process"
        elif local:
            # Read here (not by the source) so that a message names --volume when given.
            read = first if points is not None else sc.read(args.file, **read_options(args))
            if args.smooth:
                read = sc.smooth(read, args.smooth)
            scene = sc.Scene(read, model=args.model, **options)
            stack.callback(scene.close)  # a pyramid's loader thread stops at the end
            volume = scene.volume
            where = "in this process"
        else:
            from splinecast.distributed import DistributedScene

            client = stack.enter_context(_dask_client(args))
            dscene = DistributedScene(source, client)
            volume = dscene.volume
            where = f"on {len(client.nthreads())} Dask workers"
        multiscale = wavelet is None and local and isinstance(volume, MultiscaleVolume)
        if args.allow_missing and not multiscale:
            raise sc.ParameterError(f"--allow-missing applies to multiscale (OME-Zarr) volumes "
                                    f"rendered in this process only, not {args.file}")
        info = scene.preview if wavelet is not None or multiscale else volume
        kwargs, notes = mode_kwargs(args, info)
        for note in notes:
            log(args, note)
        kwargs["inside"] = args.inside
        if multiscale:  # every frame a still image: its whole cut read
            kwargs.update(complete=True, missing="substitute" if args.allow_missing else "error")
        if iso_sweep is not None:
            for v in iso_sweep:
                sc.check_iso(volume, v)
        shots = _shots(args, volume, kwargs, iso_sweep)
        log(args, f"{volume.name}: {volume.shape} prepared ({args.model}) in "
                  f"{time.perf_counter() - start:.2f} s {where}")
        if points is not None:
            log(args, f"time points {points[0]} to {points[-1]} ({len(points)} frames); iso, "
                      f"window and colours from time point {points[0]}")
        if wavelet is not None or local:
            # Said only when kernels really compile here (the first frame's, on first use).
            model = args.model or "trilinear"
            stack.enter_context(CompileNotice(
                f"{model} / {args.mode}, {np.dtype(info.dtype).name} data", model,
                enabled=not args.quiet, stream=getattr(args, "stderr", None)))
        stats: list[dict] = []
        if points is not None:
            frames = _time_frames(args, points, shots, options, scene, image_only=not multiscale)
            images = _images(frames, stats) if multiscale else frames
        elif multiscale:  # the frames' stats are kept: does any draw an unreadable brick?
            images = _images(render_locally(scene, shots), stats)
        elif wavelet is not None or local:
            images = render_locally(scene, shots, image_only=True)
        else:
            images = dscene.render_many(shots, image_only=True)
        # An interrupted loop cancels the frames in flight while the client is still open.
        stack.callback(images.close)
        # On the real stderr, past the capture of library output (splinecast.cli.main).
        progress = Progress(args.frames, "frames", enabled=not args.quiet,
                            stream=getattr(args, "stderr", None))
        with writer:
            for image in images:
                writer.write(image)
                progress.update()
    print(Path(args.output).resolve())
    warn_incomplete(args.output, stats)
    return 0


def _images(frames: Iterator[Any], stats: list[dict]) -> Iterator[Any]:
    """The 8-bit images of ``frames``, their stats appended to ``stats``."""
    for frame in frames:
        stats.append({k: frame.stats.get(k) for k in ("unreadable", "unreadable_reason")})
        yield frame.to_uint8()
