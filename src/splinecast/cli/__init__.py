"""The ``splinecast`` command line: a thin front end over the public API.

One module per subcommand; each has ``add_parser(subparsers)`` and ``run(args) -> int``, and is
listed once in :data:`COMMANDS`. User mistakes print one line (``splinecast: error: ...``) naming
the file or option and exit with status 2. Progress and timings go to stderr (``--quiet``
silences them); the path of a written file goes to stdout.

Warnings and log lines of the libraries the readers use (pydicom, nibabel, tifffile, numpy) are
captured while a command runs (:func:`splinecast.cli._common.captured_output`): they never come
before the one-line error. ``--verbose`` prints them after it (or after a successful run);
splinecast's own warnings (flipped axes, uneven slices) are printed after a successful run.
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import logging
import sys

import splinecast as sc
from splinecast._jit import collecting_only_new_objects
from splinecast.errors.limits import printable

from . import info, movie, pyramid, render, view, warmup
from ._common import Parser, apply_remote_options, captured_output

__all__ = ["main", "COMMANDS"]

#: Subcommand name -> module (with ``add_parser`` and ``run``), in the order of ``--help``.
COMMANDS = {
    "info": info,
    "render": render,
    "view": view,
    "movie": movie,
    "pyramid": pyramid,
    "warmup": warmup,
}


def _build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog="splinecast", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"splinecast {sc.__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)
    for module in COMMANDS.values():
        module.add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    parser = _build_parser()
    args = parser.parse_args(argv)
    args.stderr = sys.stderr  # progress goes here, past the capture of library output
    verbose = getattr(args, "verbose", False)
    ours = logging.getLogger("splinecast")
    level = ours.level
    code = 1  # until the command returns
    # What exists before the command is not its garbage: left out of the collection after a
    # failure below, which otherwise walks the caller's whole heap (seconds in a process that
    # has compiled many kernels, per failed call), and of the compiles' collections.
    collector = contextlib.ExitStack()
    collector.enter_context(collecting_only_new_objects())
    # The collector's scope is closed below inside the capture; ``with`` closes it too if the
    # capture could not start (closing twice does nothing).
    with collector, captured_output() as captured:
        args.captured = captured  # a long-running command releases it (the viewer's server)
        args.release_collector = collector.close  # and this (:func:`_common.uncaptured`)
        if verbose:  # splinecast's debug lines too (what zarr's event loop dropped, ...)
            ours.setLevel(logging.DEBUG)
        try:
            apply_remote_options(args)
            code = COMMANDS[args.command].run(args)
        except sc.SplinecastError as exc:
            code = 2
            # printable(): names from a hostile file must not break the line or drive a terminal
            print(f"splinecast: error: {printable(str(exc))}", file=args.stderr)
        except KeyboardInterrupt:
            return 130
        finally:
            if code != 0:
                # What the failure left behind (tasks of zarr's event loop that failed beside
                # the one reported) is collected now, inside the capture, not at exit.
                gc.collect()
            collector.close()
            ours.setLevel(level)
    lines = captured.ours() if code == 0 and not getattr(args, "quiet", False) else []
    if code == 0 and getattr(args, "quiet", False):
        lines = captured.incomplete()  # what was written is incomplete: said even when quiet
    if verbose:
        lines = captured.everything()
    for line in lines:
        print(printable(line), file=args.stderr)
    return code
