"""The one exception family of splinecast.

User mistakes (a missing file, a bad header, an isovalue outside the data range, an impossible
image size) raise a subclass of :class:`SplinecastError` whose message is one line that names the
file or parameter and says what is wrong. The command-line interface prints that line and exits
with status 2. Programming errors (bugs) are not wrapped and raise normally.
"""

from __future__ import annotations

__all__ = ["SplinecastError", "ReadError", "ParameterError", "DataError"]


class SplinecastError(Exception):
    """Base class of every user-facing error raised by splinecast."""


class ReadError(SplinecastError):
    """A file or folder cannot be read: missing, truncated, bad header, unsupported content."""


class ParameterError(SplinecastError, ValueError):
    """A parameter has an impossible value (size, isovalue, step, option name)."""


class DataError(SplinecastError, ValueError):
    """The voxel data cannot be reconstructed as given (for example it contains NaN)."""
