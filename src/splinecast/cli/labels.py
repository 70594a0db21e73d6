"""``splinecast render FILE --labels``: every label of a segmentation as its own surface.

The options (``--labels``, ``--show``, ``--label-colors``, ``--label-opacity``) and the render of
a label volume through :class:`splinecast.multires.scenes.labels.LabelScene`. A store that says it
is an OME-Zarr label image (``image-label`` metadata) renders as labels without ``--labels``
(``--no-labels`` renders its raw values), as napari and Neuroglancer show such data as
segmentations; any other volume renders as labels only when asked, whatever its voxel type.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np

import splinecast as sc
from splinecast.errors import limits

from ._common import log, numbers

__all__ = ["add_label_options", "wants_labels", "check_label_args", "run_labels"]

#: Options that mean nothing for label volumes (flag -> attribute, default).
_NOT_FOR_LABELS = {
    "--iso": ("iso", None), "--color": ("color", None), "--opacity": ("opacity", None),
    "--method": ("method", "exact"), "--tf": ("tf", None), "--colormap": ("colormap", None),
    "--window": ("window", None), "--texture": ("texture", None), "--lod": ("lod", None),
    "--cut": ("cut", None), "--step": ("step", None),
    "--preintegration": ("preintegration", None), "--adaptive": ("adaptive", False),
    "--termination": ("termination", None), "--allow-missing": ("allow_missing", False),
    "--inside": ("inside", None), "--shading": ("shading", "phong"),
    "--texture-scale": ("texture_scale", 0.1), "--tolerance": ("tolerance", 0.0),
    "--table-layout": ("table_layout", None),
}


def add_label_options(parser: argparse.ArgumentParser) -> None:
    """Register the label options on the render subcommand."""
    parser.add_argument("--labels", action=argparse.BooleanOptionalAction, default=None,
                        help="a label volume (segmentation): each label's boundary as its own "
                             "surface in its own colour (default: for OME-Zarr label images; "
                             "--no-labels renders their raw values)")
    parser.add_argument("--show", metavar="L1,L2,...",
                        help="--labels: the labels to draw, comma-separated (default all)")
    parser.add_argument("--label-colors", metavar="TABLE",
                        help="--labels: colour table, .json ({\"3\": {\"rgba\": [255, 0, 0, "
                             "255], \"name\": \"liver\"}}) or .csv (value,r,g,b,a,name) "
                             "(default: the store's image-label colours, else a palette)")
    parser.add_argument("--label-opacity", type=float, metavar="ALPHA",
                        help="--labels: opacity of every label, in [0, 1] (default 1)")


def wants_labels(args: argparse.Namespace, vol: Any) -> bool:
    """Whether to render ``vol`` as labels: ``--labels``/``--no-labels``, else whether it is an
    OME-Zarr label image (said on stderr)."""
    label_image = isinstance(getattr(vol, "metadata", {}).get("image_label"), dict)
    if args.labels is None and label_image:
        log(args, f"{args.file} is an OME-Zarr label image: rendering its labels "
                  "(--no-labels for the raw values)")
        return True
    return bool(args.labels)


def check_label_args(args: argparse.Namespace, labels: bool, multiscale: bool = False) -> None:
    """Refuse label options without labels, and options labels do not read (``--budget`` is
    the memory of the level read, for multiscale volumes only)."""
    if not labels:
        for flag, value in (("--show", args.show), ("--label-colors", args.label_colors),
                            ("--label-opacity", args.label_opacity)):
            if value is not None:
                raise sc.ParameterError(f"{flag} applies to --labels only")
        return
    if args.mode not in (sc.LabelScene.modes or ()):
        raise sc.ParameterError(f"--mode {args.mode} does not apply to --labels (labels render "
                                "as surfaces)")
    for flag, (attribute, default) in _NOT_FOR_LABELS.items():
        if getattr(args, attribute, default) not in (default, [], None):
            raise sc.ParameterError(f"{flag} does not apply to --labels")
    if args.label_opacity is not None:
        limits.check_finite_number(args.label_opacity, "--label-opacity", lo=0, hi=1)
    if args.budget is not None:
        if not multiscale:
            raise sc.ParameterError(f"--budget applies to multiscale (OME-Zarr) volumes only; "
                                    f"{args.file} is read into memory whole")
        limits.parse_bytes(args.budget, "--budget")


def _show(text: str | None) -> list[int] | None:
    if text is None:
        return None
    values = []
    for part in text.split(","):
        try:
            values.append(int(part.strip()))
        except ValueError:
            raise sc.ParameterError(f"--show must be label values like 3,5,12, got "
                                    f"{limits.shorten(text)}") from None
    return values


def _scene(args: argparse.Namespace, vol: Any, options: dict) -> Any:
    """The label scene, with the messages naming the options instead of the keywords."""
    kwargs: dict[str, Any] = {"show": _show(args.show)}
    if args.label_opacity is not None:
        kwargs["opacity"] = args.label_opacity
    if args.budget is not None:
        kwargs["budget"] = args.budget
    if args.smooth:
        kwargs["smooth"] = args.smooth  # each label's indicator, never the labels
    scene = sc.Scene(vol, model=args.model, labels=True, **kwargs, **options)
    if args.label_colors is not None:
        scene.set_colors(Path(args.label_colors), "--label-colors")
    return scene


def run_labels(args: argparse.Namespace, vol: Any, read_s: float, options: dict,
               shading: sc.Shading | None, orbit: dict) -> int:
    """Render the labels of ``vol`` to ``args.output`` (``options``: the model's; ``orbit``:
    ``Camera.orbit``'s but the angles and the fit)."""
    start = time.perf_counter()
    try:
        scene = _scene(args, vol, options)
    except sc.ParameterError as exc:  # the keywords' names -> the options'
        text = str(exc)
        for keyword, flag in (("show:", "--show:"), ("opacity", "--label-opacity"),
                              ("budget", "--budget")):
            if text.startswith(keyword):
                text = flag + text[len(keyword):]
        raise sc.ParameterError(text) from None
    level = scene.volume.metadata.get("level")
    where = f" (level {level} read)" if level is not None else ""
    log(args, f"read {vol.name}: {vol.shape} {vol.dtype}{where} in "
              f"{read_s + (time.perf_counter() - start):.2f} s, {len(scene.labels)} labels")
    shown = scene.shown
    camera = sc.Camera.orbit(vol, azimuth=args.azimuth, elevation=args.elevation,
                             fit=scene.content_box() if args.fit == "content" else "box",
                             **orbit)
    start = time.perf_counter()
    extra: dict[str, Any] = {}
    if shading is not None:
        extra["shading"] = shading
    frame = scene.render(camera, clip=_planes(args.clip), crop=_crop(args.crop),
                         normals=args.normals, samples=args.samples,
                         outputs=("rgba", "depth"), **extra)
    st = frame.stats
    seen = np.unique(frame.label)
    log(args, f"rendered {camera.width}x{camera.height}, {len(shown)} labels "
              f"({np.count_nonzero(seen)} in view) in {time.perf_counter() - start:.2f} s "
              f"({st['hits']} hits)")
    background = (shading or sc.Shading()).background
    frame.save(args.output, background=background)
    if args.depth:
        frame.save_depth(args.depth)
        log(args, f"wrote depth {args.depth}")
    print(Path(args.output).resolve())
    return 0


def _planes(clip: list[str]) -> Any:
    return [numbers(c, "--clip", 4) for c in clip] or None


def _crop(crop: str | None) -> Any:
    return numbers(crop, "--crop", 6) if crop else None
