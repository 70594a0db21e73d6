"""The one exception family of splinecast.

User mistakes (a missing file, a bad header, an isovalue outside the data range, an impossible
image size) raise a subclass of :class:`SplinecastError` whose message is one line that names the
file or parameter and says what is wrong. The command-line interface prints that line and exits
with status 2. Programming errors (bugs) are not wrapped and raise normally.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable

__all__ = ["SplinecastError", "ReadError", "ParameterError", "DataError", "did_you_mean"]


def did_you_mean(value: object, choices: Iterable[str], n: int = 2) -> str:
    """``"; did you mean X?"`` (or ``"X or Y"``) for the choices closest to a misspelt
    ``value`` (:func:`difflib.get_close_matches`, case-insensitive), else ``""``: the tail of
    a one-line error message."""
    if not isinstance(value, str) or not value:
        return ""
    by_lower: dict[str, str] = {}
    for choice in choices:
        by_lower.setdefault(str(choice).lower(), str(choice))
    close = difflib.get_close_matches(value.lower(), list(by_lower), n=n, cutoff=0.6)
    return f"; did you mean {' or '.join(by_lower[c] for c in close)}?" if close else ""


class SplinecastError(Exception):
    """Base class of every user-facing error raised by splinecast."""


class ReadError(SplinecastError):
    """A file or folder cannot be read: missing, truncated, bad header, unsupported content."""


class ParameterError(SplinecastError, ValueError):
    """A parameter has an impossible value (size, isovalue, step, option name)."""


class DataError(SplinecastError, ValueError):
    """The voxel data cannot be reconstructed as given (for example it contains NaN)."""
