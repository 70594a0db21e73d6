"""Multichannel rendering: the channels of one grid drawn together, each in its own colour.

A :class:`ChannelScene` holds one scene per channel (:class:`splinecast.Scene` of each
channel's volume: in memory or a lazy OME-Zarr pyramid) and a :class:`Channel` of display
settings per channel: colour, MIP window, isovalue, DVR transfer function, visibility. A frame
renders every visible channel alone, on a transparent background, and composites them by the
rule the mode declares (:attr:`splinecast.render.modes.RenderMode.compositing`, a
:class:`~splinecast.render.compose.Compositing`); the background is put under the composite once.
The built-in modes' rules:

- ``mip`` / ``minip``: each channel's projected value through its window onto a black-to-colour
  ramp, the channels **added** and clipped (napari's additive blending, Fiji's "Composite"): a
  pixel shows the sum of the channels' colours, whatever their order.
- ``dvr``: each channel's volume rendering (its transfer function coloured with the channel's
  colour) **added** likewise. Each channel is integrated alone, so a channel in front does not
  absorb the light of one behind it (both show through), as with napari's additive volume
  layers; a joint integration of every channel along each ray would need a kernel that reads
  several fields at once.
- ``iso``: each channel's isosurface in its colour, each pixel showing the **nearest hit** of
  any channel (a depth test): surfaces hide one another as opaque objects do.

The scene asks the mode, never its name: a mode's channel settings are the :class:`Channel`
fields among the keywords it reads (``window``, ``iso``, ``tf``); a mode that reads ``window``
is coloured from its projected values (``Frame.value``) through the channel's window; one that
reads ``tf`` gets the channel's colour in its automatic transfer function; surfaces take it as
their shading's front colour.

``Scene(volumes)`` with a list of volumes, or with the
:class:`~splinecast.io.multichannel.MultichannelVolume` that ``read(path, channel=[0, 2])``
gives, returns a :class:`ChannelScene`. The file's display metadata (OME-Zarr ``omero``:
colour, window, label, active) gives the defaults; a channel the file marks inactive is hidden.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np

from ...camera import Camera
from ...errors import ParameterError, limits
from ...io.multichannel import MultichannelVolume
from ...render.compose import Composite, on_background, window_ramp
from ...render.defaults import auto_transfer_function, background_value, content_box
from ...render.frame import Frame
from ...render.modes import RenderMode, mode_class, option_value, with_option
from ...render.shading import Shading
from ...render.template import RenderOptions, SceneTemplate
from ...scene import Scene
from ...transfer import TransferFunction, parse_color

__all__ = ["Channel", "ChannelScene", "channel_color", "default_colors", "compositing"]


#: The :class:`Channel` fields that are render keywords: a channel's own value of those its
#: mode reads (``RenderMode.keywords``) is passed to the channel's render.
_SETTINGS = ("window", "iso", "tf")


def _projects(mode: type[RenderMode]) -> bool:
    """Whether ``mode`` projects a value per ray through a window (mip, minip, aip): asked of
    the mode's keywords, so a new projection is coloured as these are."""
    return "window" in mode.keywords


def compositing(mode: str | RenderMode) -> str:
    """The name of the rule by which ``mode`` (a name or a mode object) composites its
    channels (:attr:`splinecast.render.modes.RenderMode.compositing`): ``"nearest hit"`` for
    surfaces, ``"additive"`` for projections and volume rendering."""
    return mode_class(mode).compositing.name


#: Colours of channels without one of their own, as napari gives them: one channel white
#: (the plain grey ramp), two magenta and green (told apart with any colour vision), more the
#: cycle cyan, yellow, magenta, red, green, blue.
_TWO = ((1.0, 0.0, 1.0), (0.0, 1.0, 0.0))
_CYCLE = ((0.0, 1.0, 1.0), (1.0, 1.0, 0.0), (1.0, 0.0, 1.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0),
          (0.0, 0.0, 1.0))


def default_colors(count: int) -> list[tuple[float, float, float]]:
    """The colours of ``count`` channels that have none of their own (napari's choice)."""
    if count == 1:
        return [(1.0, 1.0, 1.0)]
    if count == 2:
        return list(_TWO)
    return [_CYCLE[i % len(_CYCLE)] for i in range(count)]


def channel_color(value: Any, name: str = "color") -> tuple[float, float, float]:
    """A channel colour as RGB in [0, 1]: what :func:`splinecast.transfer.parse_color` takes,
    and also bare hex ``"FF0000"`` as OME-Zarr's ``omero`` metadata writes it."""
    if isinstance(value, str):
        text = value.strip()
        if len(text) == 6 and all(c in "0123456789abcdefABCDEF" for c in text):
            value = "#" + text
    return parse_color(value, name)  # type: ignore[return-value]


def _window(value: Any, name: str) -> tuple[float, float] | None:
    if value is None:
        return None
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError, OverflowError):
        raise ParameterError(f"{name} must be (lo, hi), got {limits.shorten(value)}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise ParameterError(f"{name} must be two finite numbers with lo < hi, got "
                             f"{limits.shorten(value)}")
    return lo, hi


@dataclass
class Channel:
    """How one channel is shown.

    Parameters
    ----------
    color : colour, optional
        A name, ``#RRGGBB`` (or bare ``RRGGBB``) or RGB in [0, 1]: the top of the channel's
        black-to-colour ramp (MIP), its surface colour (iso), its emission colour (DVR).
    window : (lo, hi), optional
        MIP/minIP window in data units (default :func:`~splinecast.auto_window` of the
        channel).
    iso : float, optional
        Isovalue (default :func:`~splinecast.auto_iso` of the channel).
    tf : TransferFunction, optional
        DVR transfer function (default :func:`~splinecast.auto_transfer_function` of the
        channel, in the channel's colour).
    visible : bool
        Whether the channel is drawn.
    label : str
        Its name (OME-Zarr ``omero`` label, else ``"channel i"``).
    """

    color: Any = (1.0, 1.0, 1.0)
    window: Any = None
    iso: float | None = None
    tf: TransferFunction | None = None
    visible: bool = True
    label: str = ""

    def __setattr__(self, name: str, value: Any) -> None:
        # Checked on every assignment, not only on construction: settings are changed between
        # renders (``scene.channels[1].color = "#00ff00"``) and a bad one must be refused here,
        # not deep inside the next render.
        super().__setattr__(name, _checked(name, value))


def _checked(name: str, value: Any) -> Any:
    """A :class:`Channel` field's value, normalized (colour as RGB, window as two floats)."""
    if name == "color":
        return channel_color(value, "color")
    if name == "window":
        return _window(value, "window")
    if name == "iso" and value is not None:
        return limits.check_finite_number(value, "iso")
    if name == "tf" and value is not None and not isinstance(value, TransferFunction):
        raise ParameterError(f"tf must be a TransferFunction, got {type(value).__name__}")
    if name == "visible":
        if not isinstance(value, (bool, np.bool_)):
            raise ParameterError(f"visible must be True or False, got {value!r}")
        return bool(value)
    if name == "label":
        return str(value)
    return value


def _per_channel(values: Any, count: int, name: str) -> list[Any]:
    """``values``: None (every entry None) or one entry per channel."""
    if values is None:
        return [None] * count
    if isinstance(values, (str, bytes)) or not isinstance(values, Sequence):
        raise ParameterError(f"{name} must be a list with one entry per channel ({count}), got "
                             f"{limits.shorten(values)}")
    if len(values) != count:
        raise ParameterError(f"{name}: {len(values)} given for {count} channels")
    return list(values)


def _info(scene: SceneTemplate) -> Any:
    """What answers a channel's automatic choices (:attr:`SceneTemplate.defaults_volume`): a
    multiscale scene's coarse preview (its voxels in memory), else the scene's volume."""
    return scene.defaults_volume


class ChannelScene(SceneTemplate):
    """The channels of one grid, rendered together (see the module's description).

    Parameters
    ----------
    volumes : MultichannelVolume or sequence of volumes
        The channels: ``read(path, channel=[0, 2])`` or ``"all"``, or volumes on one grid
        (same shape, spacing and origin; refused otherwise, naming the volume).
    model : str
        The reconstruction of every channel (see :class:`splinecast.Scene`).
    colors, windows, isos, tfs, visible, labels : list, optional
        One entry per channel (``None`` entries: the default), overriding the file's display
        metadata. Colours default to the file's (OME-Zarr ``omero``), else napari's
        (:func:`default_colors`); windows to the file's, else the automatic window; visibility
        to the file's ``active``.
    **options
        Scene options (model options; ``budget``, ``lod``... for OME-Zarr pyramids), the same
        for every channel.

    Attributes
    ----------
    channels : list of Channel
        The display settings, one per channel; change them between renders.
    scenes : list of Scene
        One scene per channel.

    Examples
    --------
    >>> import splinecast as sc
    >>> a, b = sc.demo("sphere", size=24), sc.demo("torus", size=24)
    >>> scene = sc.Scene([a, b])
    >>> [c.color for c in scene.channels]
    [(1.0, 0.0, 1.0), (0.0, 1.0, 0.0)]
    >>> frame = scene.render(sc.Camera.orbit(a, size=(32, 24)), "mip")
    >>> frame.rgba.shape
    (24, 32, 4)
    """

    def __init__(self, volumes: Any, model: str = "trilinear", *, colors: Any = None,
                 windows: Any = None, isos: Any = None, tfs: Any = None, visible: Any = None,
                 labels: Any = None, **options: Any) -> None:
        if not isinstance(volumes, MultichannelVolume):
            if isinstance(volumes, (str, bytes)) or not isinstance(volumes, Sequence):
                raise ParameterError("volumes must be a MultichannelVolume or a list of volumes "
                                     f"on one grid, got {type(volumes).__name__}")
            volumes = MultichannelVolume(volumes, option="volumes")
        self.volume = volumes
        count = len(volumes)
        given = {name: _per_channel(v, count, name) for name, v in (
            ("colors", colors), ("windows", windows), ("isos", isos), ("tfs", tfs),
            ("visible", visible), ("labels", labels))}
        fallback = default_colors(count)
        self.channels: list[Channel] = []
        for i, defaults in enumerate(volumes.defaults):
            label = given["labels"][i] or defaults["label"]
            color = given["colors"][i]
            color = color if color is not None else defaults["color"] or fallback[i]
            window = given["windows"][i]
            shown = given["visible"][i]
            self.channels.append(Channel(
                color=color, window=window if window is not None else defaults["window"],
                iso=given["isos"][i], tf=given["tfs"][i],
                visible=bool(defaults["active"]) if shown is None else shown, label=str(label)))
        self.scenes = [Scene(v, model=model, **options) for v in volumes]

    # ------------------------------------------------------------------ what cameras ask
    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """World-space corners of the shared grid."""
        return self.volume.bounds

    def content_box(self, iso: Any = None, tf: TransferFunction | None = None,
                    ) -> tuple[np.ndarray, np.ndarray]:
        """The world box around what the visible channels show (each channel's isovalue or
        transfer function, else ``iso`` / ``tf``, else its automatic one); the grid's box
        when no channel is visible."""
        boxes = [content_box(_info(s), iso=c.iso if c.iso is not None else iso,
                             tf=c.tf if c.tf is not None else tf)
                 for c, s in zip(self.channels, self.scenes, strict=True) if c.visible]
        if not boxes:
            return self.bounds
        return (np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0))

    def close(self) -> None:
        """Close every channel's scene (a multiscale scene's loader thread)."""
        for scene in self.scenes:
            scene.close()

    def __len__(self) -> int:
        return len(self.channels)

    @property
    def model(self) -> Any:
        """The reconstruction model (every channel's is of the same kind: the first one's)."""
        return self.scenes[0].model

    @property
    def tile_shape(self) -> tuple[int, int]:
        """Tiles every channel's scene traces as units (see :attr:`splinecast.Scene.tile_shape`):
        a window of the image on their grid renders exactly the whole image's pixels."""
        shapes = [s.tile_shape for s in self.scenes]
        columns = math.lcm(*(max(1, int(c)) for c, _ in shapes)) if any(
            c for c, _ in shapes) else 0
        return columns, math.lcm(*(max(1, int(r)) for _, r in shapes))

    def with_settings(self, overrides: Sequence[Any]) -> list[Channel]:
        """The channels' settings with ``overrides`` applied (not kept): one entry per channel,
        ``None`` or a dict of :class:`Channel` fields (``visible``, ``color``, ``window``,
        ``iso``, ``tf``), checked as an assignment is."""
        if isinstance(overrides, (str, bytes)) or not isinstance(overrides, Sequence):
            raise ParameterError(f"channels must be a list with one entry per channel "
                                 f"({len(self.channels)}), got {limits.shorten(overrides)}")
        if len(overrides) != len(self.channels):
            raise ParameterError(f"channels: {len(overrides)} entries for "
                                 f"{len(self.channels)} channels")
        fields = {f.name for f in dataclasses.fields(Channel)}
        out = []
        for i, (channel, given) in enumerate(zip(self.channels, overrides, strict=True)):
            if given is None:
                out.append(channel)
                continue
            if not isinstance(given, dict):
                raise ParameterError(f"channels[{i}] must be an object of Channel fields, got "
                                     f"{limits.shorten(given)}")
            unknown = sorted(str(k) for k in given if k not in fields)
            if unknown:
                raise ParameterError(f"channels[{i}] has no field {unknown[0]!r} (valid: "
                                     f"{', '.join(sorted(fields))})")
            out.append(dataclasses.replace(channel, **given))
        return out

    # ------------------------------------------------------------------ rendering
    default_mode = "mip"
    frame_options = MappingProxyType({"channels": None})
    passes_options = True

    def check_frame_options(self, given: Mapping[str, Any]) -> dict[str, Any]:
        """``channels`` and the frame options of the channels' scenes (a multiscale channel's
        ``complete``, ``lod``, ...), which are passed on to the scenes that take them.

        Raises
        ------
        TypeError
            A name neither this scene nor any channel's scene takes.
        """
        known = set(self.frame_options).union(*(s.frame_options for s in self.scenes))
        for name in given:
            if name not in known:
                raise TypeError(f"{type(self).__name__}.render() got an unexpected keyword "
                                f"argument {name!r}")
        return {**self.frame_options, **given}

    def render_frame(self, camera: Camera, options: RenderOptions,
                     frame_options: Mapping[str, Any]) -> Frame:
        """Render every visible channel and composite them: the render template's step for a
        scene of scenes (``render`` is :meth:`splinecast.Scene.render`, with the frame option
        ``channels`` and ``"mip"`` by default).

        ``render`` options a channel scene reads:

        mode : str or mode object
            ``"mip"``, ``"minip"``, ``"dvr"`` or ``"iso"`` (see the module's description of
            how each composites), or a mode object (:class:`splinecast.Mip`, ...) whose
            options every channel shares, but for the channel's own window, isovalue or
            transfer function.
        shading : Shading, optional
            Lighting and background; each channel's surface colour is its own.
        outputs : list of str, optional
            ``"rgba"``, ``"depth"`` (the nearest channel's), ``"position"``, ``"normal"``,
            ``"face"`` (iso: the nearest channel's) and ``"stats"``; default all.
        channels : list, optional
            Settings of this render only, one entry per channel: ``None`` (the channel's own)
            or a dict of :class:`Channel` fields (:meth:`with_settings`), as the viewer sends
            them.
        others
            The other :meth:`splinecast.Scene.render` keywords (``method``, ``step``,
            ``clip``, ``crop``, ``dvr``, ``samples``, ...) and the channels' scenes' frame
            options, the same for every channel. ``window``, ``iso`` and ``tf`` apply to the
            channels that have none of their own; ``colormap`` and ``colors`` are refused: a
            channel's colour is its :attr:`Channel.color`.

        Returns
        -------
        Frame
            ``stats["channels"]`` holds each rendered channel's statistics (with its
            ``label`` and ``index``), ``stats["compositing"]`` the compositing.
        """
        mode, shading, outputs = options.mode, options.shading, options.outputs
        channels = frame_options["channels"]
        kwargs = {k: v for k, v in options.as_dict().items()
                  if k not in ("mode", "shading", "outputs")}
        kwargs.update((k, v) for k, v in frame_options.items() if k != "channels")
        if not isinstance(camera, Camera):
            raise ParameterError(f"camera must be a splinecast.Camera, got "
                                 f"{type(camera).__name__}")
        kind = mode_class(mode)
        for key in ("colormap", "colors"):
            if kwargs.get(key) is not None:
                raise ParameterError(f"{key} does not apply to a multichannel render: each "
                                     "channel's colour is its Channel.color")
        shading = shading or Shading()
        if not isinstance(shading, Shading):
            raise ParameterError(f"shading must be a Shading, got {type(shading).__name__}")
        wanted = frozenset(("rgba", "depth", "position", "normal", "face", "stats")
                           if outputs is None else outputs)
        unknown = wanted - {"rgba", "depth", "position", "normal", "face", "stats", "value"}
        if unknown:
            raise ParameterError(f"outputs: unknown buffer(s) {sorted(unknown)}")
        settings = self.channels if channels is None else self.with_settings(channels)
        start = time.perf_counter()
        shown = [i for i, c in enumerate(settings) if c.visible]
        frames, stats = [], []
        for i in shown:
            frame = self._render_channel(settings[i], i, camera, mode, kind, shading, wanted,
                                         kwargs)
            frames.append(frame)
            stats.append({"index": self.volume.indices[i], "label": settings[i].label,
                          **frame.stats})
        return self._composite(kind, shown, settings, frames, stats, camera, shading, wanted,
                               start)

    def _render_channel(self, channel: Channel, i: int, camera: Camera, mode: Any,
                        kind: type[RenderMode], shading: Shading, wanted: frozenset[str],
                        kwargs: dict[str, Any]) -> Frame:
        """Channel ``i`` alone (with the settings ``channel``), on a transparent background,
        in its colour, with the buffers compositing needs."""
        scene = self.scenes[i]
        # The channel's colour on surfaces (the other modes do not read the shading's colours).
        clear = dataclasses.replace(shading, background=(0.0, 0.0, 0.0, 0.0),
                                    front_color=channel.color,
                                    back_color=tuple(0.6 * c for c in channel.color))
        own = dict(kwargs)
        for key in _SETTINGS:
            if key not in kind.keywords:
                continue
            value = getattr(channel, key)
            if key == "tf" and value is None and option_value(mode, kwargs, "tf") is None:
                value = _coloured(auto_transfer_function(_info(scene)), channel.color)
            if value is not None:
                mode, own = with_option(mode, own, key, value)
        keep = ({"stats"} & wanted) | {"depth"} | kind.compositing.reads(wanted)
        keep |= {"value"} if _projects(kind) else {"rgba"}
        return scene.render(camera, mode, shading=clear, outputs=tuple(sorted(keep)),
                            **_accepted(scene, own))

    def _layer(self, kind: type[RenderMode], i: int, channel: Channel, frame: Frame
               ) -> np.ndarray:
        """Channel ``i``'s frame as a premultiplied RGBA layer in its colour: a projection's
        values through its window (pixels of background only left transparent), else the
        colours as rendered."""
        if not _projects(kind):
            return frame.rgba
        info = _info(self.scenes[i])
        lo, hi = (float(v) for v in info.value_range)
        empty = np.abs(frame.value - background_value(info)) <= 1e-9 * max(hi - lo, 1e-300)
        return window_ramp(frame.value, frame.stats["window"], channel.color, empty)

    def _composite(self, kind: type[RenderMode], shown: list[int], settings: list[Channel],
                   frames: list[Frame], stats: list[dict], camera: Camera, shading: Shading,
                   wanted: frozenset[str], start: float) -> Frame:
        """The channels' frames combined by the mode's rule, over the background."""
        height, width = camera.height, camera.width
        rule = kind.compositing
        if frames:
            layers = [self._layer(kind, i, settings[i], frame)
                      for i, frame in zip(shown, frames, strict=True)]
            composite = rule.combine(layers, frames, wanted)
        else:
            composite = Composite(np.zeros((height, width, 4)), np.full((height, width), np.inf))
        depth = composite.depth
        position, normal, face = (getattr(composite, n) if n in wanted else None
                                  for n in ("position", "normal", "face"))
        layer = composite.rgba
        rgba = on_background(layer, shading.background) if "rgba" in wanted else None
        frame_stats: dict[str, Any] = {
            "mode": kind.name, "compositing": rule.name, "channels": stats,
            "width": width, "height": height, "rays": width * height * len(frames),
            "trace_ms": (time.perf_counter() - start) * 1e3,
            "hits": int(np.count_nonzero(np.isfinite(depth))),
        }
        return Frame(rgba, depth if "depth" in wanted else None, position, normal, face,
                     None, None, None, frame_stats)


def _accepted(scene: Any, kwargs: dict[str, Any]) -> dict[str, Any]:
    """``kwargs`` without the frame options that ``scene`` does not take (a multiscale
    channel's ``complete`` or ``wait`` for an in-memory channel), so pyramids and in-memory
    volumes can be channels of one scene."""
    options = frozenset(RenderOptions.__dataclass_fields__) | frozenset(scene.frame_options)
    return {k: v for k, v in kwargs.items() if k in options}


def _coloured(tf: TransferFunction, color: Sequence[float]) -> TransferFunction:
    """``tf``'s opacity with one colour over its whole domain (a channel's emission)."""
    points = [(0.0, *color), (1.0, *color)]
    return TransferFunction(tf.opacity_points.tolist(), tf.domain, colormap=points)
