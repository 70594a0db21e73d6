"""The options of a multichannel render: which channels, their colours, windows and isovalues,
and further files on the same grid as further channels."""

from __future__ import annotations

import argparse
from typing import Any

import splinecast as sc
from splinecast.errors import limits
from splinecast.multires.scenes.channels import channel_color
from splinecast.render.modes import modes_by_compositing, modes_reading

from ._common import numbers, read_options

__all__ = ["add_channel_options", "channel_settings", "read_channels", "several_channels",
           "CHANNEL_OPTIONS"]

#: The per-channel options (flag -> attribute); they need several channels.
CHANNEL_OPTIONS = {"--channel-colors": "channel_colors", "--channel-window": "channel_window",
                   "--channel-iso": "channel_iso", "--channel-file": "channel_file"}


def add_channel_options(parser: argparse.ArgumentParser) -> None:
    """``--channel-colors``, ``--channel-window``, ``--channel-iso`` and ``--channel-file``."""
    # What each mode shows of several channels and which take a window or an isovalue per
    # channel: the registry's answers, so a mode added to it is described too.
    shows = "; ".join(f"{', '.join(names)}: {rule.summary}"
                      for rule, names in modes_by_compositing().items())
    windowed, isos = "/".join(modes_reading("window")), "/".join(modes_reading("iso"))
    group = parser.add_argument_group(
        f"channels (with --channel 0,2 or all, or --channel-file: rendered together; {shows})")
    group.add_argument("--channel-colors", metavar="C1,C2,...",
                       help="one colour per channel, comma-separated: names (red, lime, "
                            "magenta, ...) or hex RRGGBB / #RRGGBB; 'auto' or no option: the "
                            "file's OME-Zarr omero colour, else magenta, green for two "
                            "channels, else cyan, yellow, magenta, red, green, blue in turn")
    group.add_argument("--channel-window", metavar="LO:HI,...",
                       help=f"one window per channel for --mode {windowed}, comma-separated "
                            "LO:HI pairs; "
                            "'auto' or no option: the file's omero window, else the "
                            "automatic window of the channel")
    group.add_argument("--channel-iso", metavar="V1,V2,...",
                       help=f"one isovalue per channel for --mode {isos}, comma-separated; "
                            "'auto' "
                            "or no option: --iso if given, else the automatic isovalue of the "
                            "channel")
    group.add_argument("--channel-file", action="append", metavar="FILE",
                       help="another volume on the same grid (shape, spacing, origin), "
                            "rendered as a further channel (repeatable)")


def several_channels(args: argparse.Namespace) -> bool:
    """Whether the command renders several channels together."""
    channel = getattr(args, "channel", None)
    return isinstance(channel, list) or channel == "all" or bool(
        getattr(args, "channel_file", None))


def _entries(text: str | None, option: str, count: int) -> list[str | None]:
    """``text`` split at commas into ``count`` entries (``auto``: None)."""
    if text is None:
        return [None] * count
    parts = [p.strip() for p in text.split(",")]
    if len(parts) != count:
        plural = "s" if len(parts) != 1 else ""
        raise sc.ParameterError(f"{option}: {len(parts)} value{plural} for {count} channels "
                                f"({limits.shorten(text)})")
    return [None if p.lower() == "auto" else p for p in parts]


def channel_settings(args: argparse.Namespace, count: int) -> dict[str, list[Any]]:
    """The :class:`splinecast.ChannelScene` keywords (``colors``, ``windows``, ``isos``) of
    the per-channel options, checked against the number of channels."""
    colors = [None if c is None else channel_color(c, "--channel-colors")
              for c in _entries(args.channel_colors, "--channel-colors", count)]
    windows: list[Any] = []
    for entry in _entries(args.channel_window, "--channel-window", count):
        if entry is None:
            windows.append(None)
            continue
        pair = numbers(entry.replace(":", ","), "--channel-window", 2)
        assert pair is not None
        if not pair[0] < pair[1]:
            raise sc.ParameterError(f"--channel-window: {entry} must be LO:HI with LO < HI")
        windows.append(tuple(pair))
    isos = [None if v is None else numbers(v, "--channel-iso", 1)[0]  # type: ignore[index]
            for v in _entries(args.channel_iso, "--channel-iso", count)]
    return {"colors": colors, "windows": windows, "isos": isos}


def read_channels(args: argparse.Namespace, first: Any) -> sc.MultichannelVolume:
    """The channels to render: those of ``first`` (what ``--channel`` read from the file)
    then one per ``--channel-file``, all on one grid (a file on another grid is refused,
    naming it and ``--channel-file``)."""
    volumes = list(first) if isinstance(first, sc.MultichannelVolume) else [first]
    extra = []
    options = {**read_options(args), "channel": None, "timepoint": None, "volume": None}
    for path in args.channel_file or []:
        extra.append(sc.read(path, **options))
    if isinstance(first, sc.MultichannelVolume) and not extra:
        return first
    names = [str(getattr(v, "name", "")) for v in volumes]
    names += [str(p) for p in args.channel_file or []]
    sc.io.multichannel.check_same_grid(volumes + extra, "--channel-file", names)
    return sc.MultichannelVolume(volumes + extra, option="--channel-file",
                                 hide_inactive=getattr(args, "channel", None) == "all")
