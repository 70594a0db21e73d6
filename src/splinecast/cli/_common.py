"""What every subcommand of the command line shares: the parser class, option parsing helpers,
progress output and output-path checks."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import NoReturn

import splinecast as sc

__all__ = ["Parser", "numbers", "log", "check_output"]


class Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line and exit status 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"splinecast: error: {message} (see --help)\n")


def numbers(text: str | None, option: str, count: int | None = None) -> list[float] | None:
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


def log(args: argparse.Namespace, message: str) -> None:
    """Progress line on stderr unless ``--quiet``."""
    if not getattr(args, "quiet", False):
        print(message, file=sys.stderr, flush=True)


def check_output(path: str, suffix: str, option: str) -> None:
    """Refuse an output path with the wrong suffix, a missing folder, or that is a folder."""
    p = Path(path)
    if p.suffix.lower() != suffix:
        raise sc.ParameterError(f"{option} {path}: must end in {suffix}")
    if not p.parent.exists():
        raise sc.ParameterError(f"{option} {path}: the folder {p.parent} does not exist")
    if p.is_dir():
        raise sc.ParameterError(f"{option} {path}: is a folder")
