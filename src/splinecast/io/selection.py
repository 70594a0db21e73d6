"""Choosing one 3D volume of a file that holds several: a time point or a channel.

A 4D NIfTI, an OME-Zarr image with ``t`` or ``c`` axes, a multichannel TIFF and a ``.vti`` array
with several components each hold more than the one scalar field a scene renders. The readers ask
:func:`choose` which entry to read: the one the caller named (``timepoint=``, its alias
``volume=``, or ``channel=``), checked against the axis' length, or, when none was named, the
first, with a :class:`SeveralVolumesWarning` saying so (napari and Neuroglancer also open such
data at its first time point and channel, so nobody is stopped by an error without a way out).

The readers record the counts and the choice in the volume's metadata under
:data:`TIMEPOINTS`, :data:`TIMEPOINT`, :data:`CHANNELS` and :data:`CHANNEL`.
"""

from __future__ import annotations

import operator
import warnings
from typing import Any

from ..errors import ParameterError, limits

__all__ = [
    "CHANNEL",
    "CHANNELS",
    "TIMEPOINT",
    "TIMEPOINTS",
    "SeveralVolumesWarning",
    "Selection",
    "choose",
    "index_argument",
]

#: Metadata keys: the number of time points and channels of the file, and the ones read.
TIMEPOINTS, TIMEPOINT, CHANNELS, CHANNEL = "timepoints", "timepoint", "channels", "channel"


class SeveralVolumesWarning(UserWarning):
    """The file holds several time points or channels and none was chosen: the first is read."""


def index_argument(value: Any, option: str) -> int | None:
    """``value`` of the keyword ``option`` as an index (``None`` stays ``None``).

    Raises
    ------
    ParameterError
        Not an integer (a bool, a float, a string).
    """
    if value is None:
        return None
    if isinstance(value, bool):
        raise ParameterError(f"{option} must be an integer index, got {value!r}")
    try:
        return operator.index(value)
    except TypeError:
        raise ParameterError(f"{option} must be an integer index, got "
                             f"{limits.shorten(value)}") from None


class Selection:
    """Which time point and channel a reader is asked for.

    Parameters
    ----------
    timepoint : int, optional
        The time point (``None``: not chosen).
    channel : int, optional
        The channel or component (``None``: not chosen).
    time_option : str
        The keyword the time point was given with (``"timepoint"`` or ``"volume"``), named in
        messages.
    """

    def __init__(self, timepoint: int | None = None, channel: int | None = None,
                 time_option: str = "timepoint") -> None:
        self.timepoint = index_argument(timepoint, time_option)
        self.channel = index_argument(channel, "channel")
        self.time_option = time_option

    def time(self, label: str, count: int) -> int:
        """The time point to read of ``count`` (see :func:`choose`)."""
        return choose(label, "time point", count, self.timepoint, self.time_option)

    def chan(self, label: str, count: int, what: str = "channel") -> int:
        """The channel to read of ``count`` (``what``: ``"component"`` for VTK arrays)."""
        return choose(label, what, count, self.channel, "channel")

    def metadata(self, timepoints: int, timepoint: int, channels: int,
                 channel: int) -> dict[str, int]:
        """The metadata entries recording the counts and the choice."""
        return {TIMEPOINTS: int(timepoints), TIMEPOINT: int(timepoint),
                CHANNELS: int(channels), CHANNEL: int(channel)}

    def single(self, label: str) -> dict[str, int]:
        """For a file holding one 3D volume: refuse a time point or channel other than 0, and
        return its metadata entries."""
        return self.metadata(1, self.time(label, 1), 1, self.chan(label, 1))


def choose(label: str, what: str, count: int, wanted: int | None, option: str) -> int:
    """The entry to read of an axis of ``count`` entries.

    Parameters
    ----------
    label : str
        The file, named in messages.
    what : str
        What the entries are (``"time point"``, ``"channel"``, ``"component"``).
    count : int
        How many the file holds (1 when it has no such axis).
    wanted : int or None
        The entry asked for; ``None``: the first, with a :class:`SeveralVolumesWarning` when
        there are several.
    option : str
        The keyword (and command-line option) that chooses, named in messages.

    Returns
    -------
    int
        An index in ``[0, count)``.

    Raises
    ------
    ParameterError
        ``wanted`` outside ``[0, count)``: the message names the file, the option and the
        valid range.
    """
    if wanted is None:
        if count > 1:
            warnings.warn(f"{label}: holds {count} {what}s; reading the first (choose one with "
                          f"{option}=N, on the command line --{option} N)",
                          SeveralVolumesWarning, stacklevel=3)
        return 0
    if not 0 <= wanted < count:
        valid = "0" if count == 1 else f"0 to {count - 1}"
        plural = "" if count == 1 else "s"
        raise ParameterError(f"{label}: {option} {wanted} is out of range (it holds {count} "
                             f"{what}{plural}: {valid})")
    return int(wanted)
