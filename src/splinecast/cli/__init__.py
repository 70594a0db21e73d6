"""The ``splinecast`` command line: a thin front end over the public API.

One module per subcommand; each has ``add_parser(subparsers)`` and ``run(args) -> int``, and is
listed once in :data:`COMMANDS`. User mistakes print one line (``splinecast: error: ...``) naming
the file or option and exit with status 2. Progress and timings go to stderr (``--quiet``
silences them); the path of a written file goes to stdout.
"""

from __future__ import annotations

import argparse
import sys

import splinecast as sc

from . import info, movie, pyramid, render, view
from ._common import Parser

__all__ = ["main", "COMMANDS"]

#: Subcommand name -> module (with ``add_parser`` and ``run``), in the order of ``--help``.
COMMANDS = {
    "info": info,
    "render": render,
    "view": view,
    "movie": movie,
    "pyramid": pyramid,
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
    try:
        return COMMANDS[args.command].run(args)
    except sc.SplinecastError as exc:
        print(f"splinecast: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
