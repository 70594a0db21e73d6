"""What every subcommand of the command line shares: the parser class, option parsing helpers,
the capture of library output, progress output and output-path checks."""

from __future__ import annotations

import argparse
import contextlib
import io
import logging
import math
import os
import re
import sys
import warnings
from collections.abc import Callable, Iterator, Sequence
from contextlib import AbstractContextManager, contextmanager, nullcontext
from pathlib import Path
from typing import NoReturn, TextIO

import splinecast as sc
from splinecast.errors import did_you_mean, limits

__all__ = [
    "Captured",
    "IncompleteWarning",
    "add_missing_option",
    "Parser",
    "add_input_options",
    "add_selection_options",
    "captured_output",
    "channel_argument",
    "check_output",
    "derived_output",
    "IMAGE_SUFFIXES",
    "finite",
    "log",
    "numbers",
    "read_options",
    "uncaptured",
]

_PACKAGE_DIR = str(Path(sc.__file__).resolve().parent)


#: What argparse takes for a value rather than an option although it starts with ``-``:
#: negative numbers, also comma- or colon-separated lists of them (``--iso -3,3``,
#: ``--window -5,5``, ``--iso -1:1``), where argparse's own rule knows single numbers only.
_NEGATIVE_NUMBERS = re.compile(r"^-\.?\d[\d.,:eE+-]*$")
_INVALID_CHOICE = re.compile(r"invalid choice: '(?P<value>.*)' \(choose from (?P<choices>.*)\)$")


class Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line and exit status 2, with "did you mean"
    suggestions for misspelt options and choices, and negative numbers (also lists such as
    ``-3,3``) taken as values."""

    def __init__(self, *args: object, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = _NEGATIVE_NUMBERS

    def parse_args(self, args: Sequence[str] | None = None,  # type: ignore[override]
                   namespace: argparse.Namespace | None = None) -> argparse.Namespace:
        parsed, extras = self.parse_known_args(args, namespace)
        if extras:
            options = self._option_strings(parsed)
            first = next((e for e in extras if e.startswith("-")), extras[0])
            hint = did_you_mean(first.split("=", 1)[0], options) if first.startswith("-") else ""
            self.error(f"unrecognized arguments: {' '.join(extras)}{hint}")
        return parsed

    def _option_strings(self, parsed: argparse.Namespace) -> list[str]:
        """The long options of this parser and of the subcommand ``parsed`` chose."""
        parsers = [self]
        for action in self._actions:
            if isinstance(action, argparse._SubParsersAction):
                chosen = action.choices.get(getattr(parsed, action.dest or "", None) or "")
                if chosen is not None:
                    parsers.append(chosen)
        return [o for p in parsers for a in p._actions for o in a.option_strings
                if o.startswith("--")]

    def error(self, message: str) -> NoReturn:
        match = _INVALID_CHOICE.search(message)
        if match:
            choices = re.findall(r"'([^']*)'", match["choices"])
            message += did_you_mean(match["value"], choices)
        self.exit(2, f"splinecast: error: {message} (see --help)\n")


def finite(text: str) -> float:
    """argparse type of every numeric option: a finite number (no nan, inf or 1e999)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number, got {limits.shorten(text)}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {limits.shorten(text)}")
    return value


def add_input_options(parser: argparse.ArgumentParser) -> None:
    """Options every subcommand that reads a volume shares."""
    parser.add_argument("--allow-external-data", action="store_true",
                        help="let a header name data files outside its own folder "
                             f"(default: refused; or set {limits.ENV_ALLOW_EXTERNAL}=1)")
    parser.add_argument("--verbose", action="store_true",
                        help="also print the warnings and log lines of the file-format "
                             "libraries (captured otherwise)")
    remote = parser.add_argument_group("remote data (http(s)://, s3://, gs:// URLs)")
    remote.add_argument("--anon", action="store_true",
                        help="anonymous access even when credentials are configured (default: "
                             "anonymous unless the environment or ~/.aws, gcloud give some)")
    remote.add_argument("--cache-dir", metavar="DIR",
                        help="keep fetched chunks in this folder, reused by later runs "
                             "(default: no disk cache)")
    remote.add_argument("--cache-size", metavar="BYTES", default=None,
                        help="most bytes the --cache-dir folder holds, least recently used "
                             "out first (default 2GiB)")


def apply_remote_options(args: argparse.Namespace) -> None:
    """Hand ``--anon``, ``--cache-dir`` and ``--cache-size`` to the remote reader through its
    environment variables, so that worker processes started by this command see them too."""
    from splinecast.io import remote

    if getattr(args, "anon", False):
        os.environ[remote.ENV_ANON] = "1"
    if getattr(args, "cache_size", None) is not None:
        limits.parse_bytes(args.cache_size, "--cache-size")  # a bad size is said here
        os.environ[remote.ENV_CACHE_SIZE] = str(args.cache_size)
    if getattr(args, "cache_dir", None):
        os.environ[remote.ENV_CACHE_DIR] = os.path.abspath(args.cache_dir)


def channel_argument(text: str) -> int | list[int] | str:
    """argparse type of ``--channel`` where several channels may be chosen: an index, a
    comma-separated list of indices, or ``all``."""
    value = text.strip().lower()
    if value == "all":
        return "all"
    try:
        indices = [int(v) for v in value.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an index, a comma-separated list of indices "
                                         f"or all, got {limits.shorten(text)}") from None
    return indices[0] if len(indices) == 1 and "," not in value else indices


def _one_channel(text: str) -> int:
    """argparse type of ``--channel`` where one channel is read (``info``, ``view``,
    ``movie``)."""
    try:
        return int(text)
    except ValueError:
        several = "," in text or text.strip().lower() == "all"
        hint = " (several channels render together with 'splinecast render')" if several else ""
        raise argparse.ArgumentTypeError(f"takes one channel index here, got "
                                         f"{limits.shorten(text)}{hint}") from None


def add_selection_options(parser: argparse.ArgumentParser, several: bool = False) -> None:
    """``--timepoint`` (or ``--volume``) and ``--channel``: which volume of a file holding
    several to read (``several``: ``--channel`` may name several channels, rendered
    together)."""
    when = parser.add_mutually_exclusive_group()
    when.add_argument("--timepoint", type=int, metavar="N",
                      help="time point of a time series to read: a 4D NIfTI's volume, an "
                           "OME-Zarr 't' axis, a TIFF hyperstack's T (default: the first, with "
                           "a note; 'splinecast info' gives the count)")
    when.add_argument("--volume", type=int, metavar="N",
                      help="another name for --timepoint (the volumes of a 4D NIfTI)")
    if several:
        parser.add_argument("--channel", type=channel_argument, metavar="N[,M...]|all",
                            help="channel(s) to read: an OME-Zarr 'c' axis, a TIFF's channels "
                                 "or colour samples, a VTK array's components; several "
                                 "(0,2 or all) are rendered together, each in its colour "
                                 "(default: the first, with a note)")
        return
    parser.add_argument("--channel", type=_one_channel, metavar="N",
                        help="channel to read: an OME-Zarr 'c' axis, a TIFF's channels or "
                             "colour samples, a VTK array's components (default: the first, "
                             "with a note)")


def read_options(args: argparse.Namespace) -> dict[str, object]:
    """The keywords of :func:`splinecast.read` the input options give."""
    return {"allow_external": getattr(args, "allow_external_data", False) or None,
            "timepoint": getattr(args, "timepoint", None),
            "volume": getattr(args, "volume", None),
            "channel": getattr(args, "channel", None)}


def numbers(text: str | None, option: str, count: int | None = None) -> list[float] | None:
    """Comma-separated finite numbers of ``option`` (``count`` of them when given)."""
    if text is None:
        return None
    shown = limits.shorten(text)
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise sc.ParameterError(f"{option} must be comma-separated numbers, got {shown}") from None
    if not all(math.isfinite(v) for v in values):
        raise sc.ParameterError(f"{option} must be finite numbers, got {shown}")
    if count is not None and len(values) != count:
        raise sc.ParameterError(f"{option} needs {count} numbers, got {shown}")
    return values


def log(args: argparse.Namespace, message: str) -> None:
    """Progress line on stderr unless ``--quiet`` (the real stderr, past any capture)."""
    if not getattr(args, "quiet", False):
        print(message, file=getattr(args, "stderr", sys.stderr), flush=True)


#: Bricks that could not be read named one per line after a command; the others counted.
_BRICK_LINES = 3


class IncompleteWarning(UserWarning):
    """What a command wrote is incomplete (bricks drawn from a coarser level because their
    chunks could not be read): printed last, even with ``--quiet``."""


def add_missing_option(parser: argparse.ArgumentParser) -> None:
    """``--allow-missing``: still images of a multiscale volume may draw unreadable bricks from
    a coarser level (an error otherwise)."""
    parser.add_argument("--allow-missing", action="store_true",
                        help="multiscale (OME-Zarr) volumes: draw a brick whose chunks are "
                             "missing or damaged from a coarser level and say the image is "
                             "incomplete (default: an error naming the chunk)")


class Captured:
    """Warnings and stderr output collected while a command ran."""

    def __init__(self) -> None:
        self.warnings: list[warnings.WarningMessage] = []
        self.stream = io.StringIO()
        self._undo: Callable[[], None] | None = None
        self._redo: Callable[[], None] | None = None

    @staticmethod
    def _line(w: warnings.WarningMessage) -> str:
        return f"splinecast: warning: {w.message}"

    def _is_ours(self, w: warnings.WarningMessage) -> bool:
        inside = str(Path(w.filename).resolve()).startswith(_PACKAGE_DIR)
        return inside and issubclass(w.category, UserWarning)

    def ours(self) -> list[str]:
        """splinecast's own warnings (about the data), one line each (the first few of the
        bricks that could not be read, then their count); those saying the output is
        incomplete last."""
        mine = [w for w in self.warnings if self._is_ours(w)]
        last = [w for w in mine if issubclass(w.category, IncompleteWarning)]
        bricks = [w for w in mine if w.category.__name__ == "BrickUnavailableWarning"]
        shown = [w for w in mine if w not in last and w not in bricks[_BRICK_LINES:]]
        lines = [self._line(w) for w in shown]
        if len(bricks) > _BRICK_LINES:
            lines.append(f"splinecast: warning: ... and {len(bricks) - _BRICK_LINES} more "
                         "bricks that could not be read")
        return lines + [self._line(w) for w in last]

    def incomplete(self) -> list[str]:
        """The warnings saying the output is incomplete (printed even with ``--quiet``)."""
        return [self._line(w) for w in self.warnings
                if self._is_ours(w) and issubclass(w.category, IncompleteWarning)]

    def everything(self) -> list[str]:
        """Every warning and every line the libraries printed or logged (``--verbose``)."""
        lines = [self._line(w) if self._is_ours(w)
                 else f"  {w.category.__name__} ({Path(w.filename).name}): {w.message}"
                 for w in self.warnings if not issubclass(w.category, IncompleteWarning)]
        lines += [f"  {line}" for line in self.stream.getvalue().splitlines() if line.strip()]
        return lines + self.incomplete()

    @contextmanager
    def released(self) -> Iterator[None]:
        """Stop capturing inside the block: a command that runs until interrupted (the viewer's
        server) shows its warnings and log lines as they come, once its input was read."""
        if self._undo is None or self._redo is None:
            yield
            return
        self._undo()
        try:
            with warnings.catch_warnings():
                warnings.showwarning = _show_warning
                yield
        finally:
            self._redo()


def _show_warning(message: Warning | str, category: type[Warning], filename: str, lineno: int,
                  file: TextIO | None = None, line: str | None = None) -> None:
    """Print a warning the default way, on the stderr of the moment (not a captured one)."""
    text = warnings.formatwarning(message, category, filename, lineno, line)
    (file or sys.stderr).write(text)


@contextmanager
def captured_output() -> Iterator[Captured]:
    """Collect warnings, log records and whatever is written to ``sys.stderr`` in the block.

    Libraries print warnings, log lines (nibabel's own stderr handler, pydicom's loggers) and
    sometimes plain text; none of it may come before splinecast's one-line error. Handlers
    created inside the block bind to the captured stream; a handler on the root logger catches
    the records of loggers without their own.
    """
    captured = Captured()
    handler = logging.StreamHandler(captured.stream)
    handler.setFormatter(logging.Formatter("%(name)s %(levelname)s: %(message)s"))
    root = logging.getLogger()
    saved_stderr = sys.stderr
    # Handlers made before the block (a library imported earlier) hold the old stream: redirect
    # them too, and put them back afterwards.
    redirected = [
        h for logger in [root, *logging.Logger.manager.loggerDict.values()]
        if isinstance(logger, logging.Logger)
        for h in logger.handlers
        if type(h) is logging.StreamHandler and h.stream in (saved_stderr, sys.__stderr__)
    ]
    old_streams = [h.setStream(captured.stream) for h in redirected]
    sys.stderr = captured.stream
    root.addHandler(handler)

    def undo() -> None:
        root.removeHandler(handler)
        for h, stream in zip(redirected, old_streams, strict=True):
            h.setStream(stream)
        sys.stderr = saved_stderr

    def redo() -> None:
        for h in redirected:
            h.setStream(captured.stream)
        sys.stderr = captured.stream
        root.addHandler(handler)

    captured._undo, captured._redo = undo, redo
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("default")
            try:
                yield captured
            finally:
                captured.warnings = list(caught)
    finally:
        captured._undo = captured._redo = None
        undo()


def uncaptured(args: argparse.Namespace) -> AbstractContextManager[None]:
    """The block runs outside the capture of :func:`main <splinecast.cli.main>` (a no-op when
    the command was not started by it): see :meth:`Captured.released`. A command that serves
    for long (the viewer) also ends :func:`main`'s scope of the garbage collector here: what it
    froze stays frozen while the scope is open, which for a server would be its whole life."""
    release_collector = getattr(args, "release_collector", None)
    if release_collector is not None:
        release_collector()
    captured = getattr(args, "captured", None)
    return captured.released() if captured is not None else nullcontext()


#: Image files ``render -o`` writes (through Pillow; see :meth:`splinecast.Frame.save`).
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".webp")


def check_output(path: str, suffix: str | tuple[str, ...], option: str) -> None:
    """Refuse an output path with the wrong suffix (one of ``suffix`` when a tuple), a missing
    folder, or that is a folder."""
    p = limits.check_path_text(path, option)
    if path.endswith(("/", "\\")):  # pathlib would drop the slash and write a file anyway
        raise sc.ParameterError(f"{option} {limits.shorten(path)}: names a folder, not a file")
    suffixes = (suffix,) if isinstance(suffix, str) else suffix
    if p.suffix.lower() not in suffixes:
        accepted = suffixes[0] if len(suffixes) == 1 else (
            ", ".join(suffixes[:-1]) + " or " + suffixes[-1])
        raise sc.ParameterError(f"{option} {limits.shorten(path)}: must end in {accepted}")
    if not p.parent.exists():
        raise sc.ParameterError(f"{option} {path}: the folder {p.parent} does not exist")
    if p.is_dir():
        raise sc.ParameterError(f"{option} {path}: is a folder")


#: Suffixes of compressed files, left out of a derived name with the suffix before them
#: (``head.nii.gz`` -> ``head``).
_COMPRESSED = (".gz", ".bz2", ".xz", ".zst")


def derived_output(source: str, tag: str, suffix: str) -> Path:
    """The output path when ``-o`` is not given: the input's name without its suffix, then
    ``-TAG`` when ``tag`` is not empty, then ``suffix``, in the current folder
    (``/data/head.nii.gz`` -> ``./head-mip.png``; ``demo:torus?size=64`` -> ``./torus.png``).
    Never the input itself: a clash adds ``-render``."""
    text = source.rstrip("/\\")
    if text.startswith("demo:"):
        name = text[len("demo:"):].split("?", 1)[0] or "demo"
    else:
        name = re.split(r"[/\\]", text.split("?", 1)[0])[-1] or "volume"
        for compressed in _COMPRESSED:
            if name.lower().endswith(compressed):
                name = name[: -len(compressed)]
        stem = Path(name).stem
        name = stem if stem and not stem.startswith(".") else name
        if name.lower().endswith(".ome"):  # OME-Zarr and OME-TIFF: image.ome.zarr
            name = name[: -len(".ome")] or name
    name = re.sub(r"[^\w.+-]", "_", name)
    out = Path.cwd() / f"{name}{'-' + tag if tag else ''}{suffix}"
    with contextlib.suppress(OSError):
        if out.exists() and out.resolve() == Path(source).resolve():
            out = out.with_name(f"{out.stem}-render{suffix}")
    return out
