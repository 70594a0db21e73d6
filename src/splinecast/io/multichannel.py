"""Several channels of one grid: the volumes a multichannel render draws together.

A microscope image has channels (fluorophores) sampled on one grid: the ``c`` axis of an
OME-Zarr image, the ``C`` axis of a TIFF hyperstack, the components of a VTK array, or separate
files of the same acquisition. :func:`splinecast.read` with ``channel=[0, 2]`` (or ``"all"``)
gives a :class:`MultichannelVolume` holding one volume per channel, each read as
``channel=i`` reads it (lazily for OME-Zarr), with the file's display defaults per channel
(OME-Zarr ``omero`` metadata: label, colour, window, active). ``MultichannelVolume([a, b])``
makes one of volumes read separately. Either way the channels must share one grid (shape,
spacing and origin): a channel on another grid is refused with a message naming it.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from typing import Any

import numpy as np

from ..errors import ParameterError, limits
from ..volume import GridGeometry
from .selection import index_argument

__all__ = ["MultichannelVolume", "channel_indices", "is_all", "read_channels", "check_same_grid"]

#: Relative tolerance of the spacing and origin comparison of two channels' grids (headers
#: round their numbers differently; a real mismatch is far larger).
GRID_RTOL = 1e-6


def _describe(volume: Any) -> str:
    """The volume's name, for messages."""
    return str(getattr(volume, "name", None) or type(volume).__name__)


def _fmt(values: Sequence[float]) -> str:
    return "(" + ", ".join(f"{float(v):g}" for v in values) + ")"


def check_same_grid(volumes: Sequence[Any], option: str, names: Sequence[str] | None = None
                    ) -> None:
    """Refuse volumes that do not share the first one's grid.

    Parameters
    ----------
    volumes : sequence of Volume or MultiscaleVolume
    option : str
        The keyword or command-line option the volumes came with, named in the message.
    names : sequence of str, optional
        What to call each volume in the message (default: its name).

    Raises
    ------
    ParameterError
        One line naming the volume, the option, and the first property that differs (shape,
        spacing or origin) with both values.
    """
    names = list(names) if names is not None else [_describe(v) for v in volumes]
    first = volumes[0]
    for volume, name in zip(volumes[1:], names[1:], strict=True):
        for what in ("shape", "spacing", "origin"):
            mine, theirs = getattr(volume, what), getattr(first, what)
            if what == "shape":
                same = tuple(int(v) for v in mine) == tuple(int(v) for v in theirs)
            else:
                scale = max(float(np.max(np.abs(first.spacing))), 1e-300)
                same = bool(np.allclose(mine, theirs, rtol=GRID_RTOL, atol=GRID_RTOL * scale))
            if not same:
                raise ParameterError(
                    f"{name}: {option}: {what} {_fmt(mine)} differs from {names[0]}'s "
                    f"{_fmt(theirs)} (the channels must share one grid)")


class MultichannelVolume(GridGeometry):
    """One volume per channel, all on the same grid, with their display defaults.

    Parameters
    ----------
    volumes : sequence of Volume or MultiscaleVolume
        The channels, in order (at least one).
    labels : sequence of str, optional
        A name per channel (default: ``metadata["channel_label"]``; else, for volumes of
        separate files, ``metadata["name"]``; else ``"channel i"`` with ``i`` the channel's
        index in its file).
    option : str
        The keyword or command-line option the volumes came with, named in messages (a grid
        that differs from the first channel's).
    hide_inactive : bool
        Whether a channel the file marks inactive (``metadata["channel_active"]``) is hidden
        by default. :func:`splinecast.read` hides them when asked for ``"all"`` channels, not
        when the channels were named one by one.

    Attributes
    ----------
    volumes : list
        The channels.
    indices : list of int
        Each channel's index in its file (``metadata["channel"]``, else its position).
    defaults : list of dict
        Per channel, what the file says about showing it: ``label``, ``color`` (RGB in [0, 1]
        or ``None``), ``window`` (``(lo, hi)`` or ``None``) and ``active`` (a channel the file
        marks inactive is hidden by default, as napari and OMERO do; see ``hide_inactive``).
    metadata : dict
        The first channel's metadata, its name the image's.

    Raises
    ------
    ParameterError
        No volume, or a volume whose grid differs from the first's (:func:`check_same_grid`).

    Examples
    --------
    >>> import splinecast as sc
    >>> a, b = sc.demo("sphere", size=24), sc.demo("torus", size=24)
    >>> mv = MultichannelVolume([a, b])
    >>> len(mv), mv.shape
    (2, (24, 24, 24))
    """

    def __init__(self, volumes: Sequence[Any], labels: Sequence[str] | None = None,
                 option: str = "volumes", hide_inactive: bool = True) -> None:
        volumes = list(volumes)
        if not volumes:
            raise ParameterError(f"{option}: a multichannel volume needs at least one channel")
        for position, volume in enumerate(volumes):
            if not (hasattr(volume, "shape") and hasattr(volume, "spacing")
                    and hasattr(volume, "metadata")):
                raise ParameterError(f"{option}[{position}] must be a splinecast volume, got "
                                     f"{type(volume).__name__}")
        check_same_grid(volumes, option)
        self.volumes = volumes
        self.option = option
        # Channels of one file keep their index in it; separate files are numbered in order.
        sources = {str(v.metadata.get("source", id(v))) for v in volumes}
        one_file = len(sources) == 1 and all("channel" in v.metadata for v in volumes)
        self.indices = [int(v.metadata["channel"]) if one_file else i
                        for i, v in enumerate(volumes)]
        if labels is not None and len(labels) != len(volumes):
            raise ParameterError(f"labels: {len(labels)} labels for {len(volumes)} channels")
        self.defaults = []
        for i, volume in enumerate(volumes):
            meta = volume.metadata
            label = labels[i] if labels is not None else meta.get("channel_label")
            if not label and not one_file:  # separate volumes: their own names
                label = meta.get("name")
            self.defaults.append({
                "label": str(label) if label else f"channel {self.indices[i]}",
                "color": meta.get("channel_color"),
                "window": meta.get("channel_window"),
                "active": bool(meta.get("channel_active", True)) or not hide_inactive,
            })
        self.metadata = dict(volumes[0].metadata)

    # GridGeometry: the shared grid (checked equal on construction).
    @property
    def shape(self) -> tuple[int, int, int]:  # type: ignore[override]
        return tuple(int(v) for v in self.volumes[0].shape)  # type: ignore[return-value]

    @property
    def spacing(self) -> tuple[float, float, float]:  # type: ignore[override]
        return tuple(float(v) for v in self.volumes[0].spacing)  # type: ignore[return-value]

    @property
    def origin(self) -> tuple[float, float, float]:  # type: ignore[override]
        return tuple(float(v) for v in self.volumes[0].origin)  # type: ignore[return-value]

    @property
    def dtype(self) -> np.dtype:
        return np.dtype(self.volumes[0].dtype)

    @property
    def name(self) -> str:
        return _describe(self.volumes[0])

    @property
    def value_range(self) -> tuple[float, float]:
        """The smallest and largest value of any channel."""
        ranges = [v.value_range for v in self.volumes]
        return (min(float(r[0]) for r in ranges), max(float(r[1]) for r in ranges))

    @property
    def labels(self) -> list[str]:
        """Each channel's label."""
        return [d["label"] for d in self.defaults]

    def __len__(self) -> int:
        return len(self.volumes)

    def __getitem__(self, index: int) -> Any:
        return self.volumes[index]

    def __iter__(self) -> Iterator[Any]:
        return iter(self.volumes)

    def __repr__(self) -> str:
        return (f"MultichannelVolume(name={self.name!r}, channels={self.labels}, "
                f"shape={self.shape}, dtype={self.dtype})")


def channel_indices(channel: Any, count: int | None = None, option: str = "channel"
                    ) -> list[int] | None:
    """The channels asked for by ``channel`` when it names several, else ``None``.

    ``channel`` is a list or tuple of indices, ``"all"`` (every channel: needs ``count``) or a
    comma-separated string of indices (``"0,2"``, as the command line gives it); a single index
    (or ``None``) is not a multichannel request and gives ``None``.

    Raises
    ------
    ParameterError
        An entry that is not an integer index, an empty list, or a channel named twice.
    """
    if channel is None or isinstance(channel, (int, np.integer)) and not isinstance(
            channel, bool):
        return None
    if isinstance(channel, str):
        text = channel.strip().lower()
        if text == "all":
            return None if count is None else list(range(count))
        parts = [p.strip() for p in text.split(",")]
        try:
            channel = [int(p) for p in parts]
        except ValueError:
            raise ParameterError(f"{option} must be an index, a comma-separated list of indices "
                                 f"or 'all', got {limits.shorten(channel)}") from None
    if not isinstance(channel, (list, tuple, np.ndarray)):
        index_argument(channel, option)  # raises with the usual message
        return None
    indices = [index_argument(c, option) for c in channel]
    if not indices:
        raise ParameterError(f"{option}: an empty list of channels")
    if len(set(indices)) != len(indices):
        raise ParameterError(f"{option}: channel listed twice in {limits.shorten(list(indices))}")
    return indices  # type: ignore[return-value]


def is_all(channel: Any) -> bool:
    """Whether ``channel`` asks for every channel (``"all"``)."""
    return isinstance(channel, str) and channel.strip().lower() == "all"


def read_channels(read_one: Callable[[int], Any], channel: Any, label: str,
                  option: str = "channel") -> MultichannelVolume:
    """Read several channels of one file through ``read_one(index)`` (a single-channel read).

    ``channel`` is what :func:`channel_indices` accepts. The first channel asked for is read
    first (for ``"all"``: channel 0), and its ``metadata["channels"]`` gives the count, so an
    index out of range is refused by the reader with the file's range before the others are
    read.
    """
    wanted = channel_indices(channel, None, option)
    first = read_one(0 if wanted is None else wanted[0])
    count = int(first.metadata.get("channels", 1))
    if wanted is None:  # "all"
        wanted = list(range(count))
    volumes = [first] + [read_one(i) for i in wanted[1:]]
    names = [f"{label} channel {i}" for i in wanted]
    check_same_grid(volumes, option, names)
    # A channel named explicitly is shown even if the file marks it inactive.
    return MultichannelVolume(volumes, option=option, hide_inactive=is_all(channel))
