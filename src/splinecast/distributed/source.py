"""What a worker opens: a :class:`SceneSource` names the data and the model, never holds them.

A distributed render ships this small description to the workers instead of the volume; each
worker process opens it once, prepares the model and keeps the :class:`~splinecast.Scene`
(:mod:`.worker`). :class:`VolumeInfo` is the small summary of the opened volume that travels
back, enough for the client to aim cameras and check isovalues without reading the data itself.
"""

from __future__ import annotations

import inspect
import json
import os
from dataclasses import dataclass, field
from typing import Any

from ..errors import ParameterError
from ..io import read
from ..io.selection import index_argument
from ..models import MODELS
from ..models.smoothing import smooth as smooth_volume
from ..render.defaults import (
    auto_colormap,
    auto_iso,
    auto_transfer_function,
    background_value,
    is_signed,
)
from ..render.modes import MODES, modes_reading
from ..scene import Scene
from ..volume import GridGeometry, Volume

__all__ = ["SceneSource", "VolumeInfo"]


@dataclass(frozen=True)
class SceneSource:
    """A volume every worker can open, the reconstruction model and its options.

    Parameters
    ----------
    location : str or os.PathLike
        A file or folder path (anything :func:`splinecast.read` reads) or a ``"demo:NAME?..."``
        spec. A relative path is made absolute against the client's working directory, so
        workers started elsewhere on a shared file system find the same file.
    model : str
        Reconstruction model name (see :data:`splinecast.MODELS`).
    options : dict, optional
        Model options (``prefilter=True``, ``root_finder="newton"``, ...); values must be
        hashable since the source is the key of the workers' scene cache.
    smooth : int, optional
        Gaussian pre-smoothing kernel size (3 or 5), applied on the workers after reading.
    allow_external : bool, optional
        Let the file's header name data files outside its folder (see :func:`splinecast.read`);
        travels to the workers with the source.
    timepoint, channel : int, optional
        Which time point and channel of a file holding several to read (see
        :func:`splinecast.read`; default: the first).
    labels : dict, optional
        A label volume: the options of the label scene the workers open (``Scene(volume,
        labels=True, **labels)``: ``colors`` as a path or JSON text, ``show``, ``opacity``,
        ``smooth``, ``budget``); hashable values. ``None``: an ordinary scene.
    """

    location: str
    model: str = "trilinear"
    options: tuple[tuple[str, Any], ...] = field(default=())
    smooth: int | None = None
    allow_external: bool | None = None
    timepoint: int | None = None
    channel: int | None = None
    labels: tuple[tuple[str, Any], ...] | None = None

    def __init__(self, location: str | os.PathLike, model: str = "trilinear",
                 options: dict[str, Any] | None = None, smooth: int | None = None,
                 allow_external: bool | None = None, timepoint: int | None = None,
                 channel: int | None = None, labels: dict[str, Any] | None = None) -> None:
        text = os.fspath(location)
        if not isinstance(text, str) or not text:
            raise ParameterError(f"source must be a path or a demo: spec, got {location!r}")
        if not text.startswith("demo:") and "://" not in text:
            text = os.path.abspath(text)
        if model not in MODELS:
            raise ParameterError(f"model must be one of {', '.join(MODELS)}, got {model!r}")
        accepted = inspect.signature(MODELS[model]).parameters
        for name in options or {}:
            if name == "volume" or name not in accepted:
                raise ParameterError(f"model option {name!r} does not apply to model {model}")
        items = tuple(sorted((options or {}).items()))
        try:
            hash(items)
        except TypeError:
            raise ParameterError(f"model options must be hashable values, got {dict(items)}"
                                 ) from None
        object.__setattr__(self, "location", text)
        object.__setattr__(self, "model", model)
        object.__setattr__(self, "options", items)
        object.__setattr__(self, "smooth", None if smooth is None else int(smooth))
        object.__setattr__(self, "allow_external",
                           None if allow_external is None else bool(allow_external))
        object.__setattr__(self, "timepoint", index_argument(timepoint, "timepoint"))
        object.__setattr__(self, "channel", index_argument(channel, "channel"))
        label_items = None if labels is None else tuple(sorted(labels.items()))
        try:
            hash(label_items)
        except TypeError:
            raise ParameterError(f"label options must be hashable values, got {labels}"
                                 ) from None
        object.__setattr__(self, "labels", label_items)

    def read(self) -> Volume:
        """Read (and pre-smooth) the volume; raises :class:`~splinecast.ReadError` naming the
        location when it cannot."""
        volume = read(self.location, allow_external=self.allow_external,
                      timepoint=self.timepoint, channel=self.channel)
        return smooth_volume(volume, self.smooth) if self.smooth else volume

    def open(self) -> Scene:
        """Read the volume and prepare the model: the expensive step workers do once."""
        if self.labels is not None:
            labels = dict(self.labels)
            if isinstance(labels.get("colors"), str) and labels["colors"].lstrip()[:1] in "[{":
                labels["colors"] = json.loads(labels["colors"])  # a table sent as JSON text
            if isinstance(labels.get("opacity"), tuple):  # per label, as pairs
                labels["opacity"] = dict(labels["opacity"])
            return Scene(self.read(), model=self.model, labels=True, **labels,
                         **dict(self.options))
        return Scene(self.read(), model=self.model, **dict(self.options))

    def __str__(self) -> str:
        return self.location


@dataclass(frozen=True)
class VolumeInfo(GridGeometry):
    """The header of a volume opened on the workers: geometry, value range and metadata.

    It stands in for the :class:`~splinecast.Volume` where only these are needed, e.g.
    ``Camera.orbit(info, ...)`` and ``check_iso(info, iso)``.
    """

    name: str
    shape: tuple[int, int, int]
    dtype: str
    spacing: tuple[float, float, float]
    origin: tuple[float, float, float]
    value_range: tuple[float, float]
    metadata: dict[str, Any]

    @classmethod
    def of(cls, volume: Volume) -> VolumeInfo:
        """The header of ``volume``, with the automatic choices of :mod:`splinecast.render.defaults`
        (computed from the data, which the header does not hold) in its metadata."""
        metadata = dict(volume.metadata)
        metadata["default_iso"] = auto_iso(volume)
        metadata.setdefault("background", background_value(volume))
        metadata.setdefault("signed", is_signed(volume))
        metadata.setdefault("default_colormap", auto_colormap(volume))
        # Every projection's automatic window (RenderMode.default_window reads it back).
        for name in modes_reading("window"):
            if metadata.get(f"default_window_{name}") is None:
                metadata[f"default_window_{name}"] = MODES[name].default_window(volume)
        metadata.setdefault("default_tf", auto_transfer_function(volume).to_dict())
        return cls(volume.name, volume.shape, str(volume.dtype), volume.spacing, volume.origin,
                   volume.value_range, metadata)
