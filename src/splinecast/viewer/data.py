"""What a viewer shows: an in-memory volume, a prepared scene, or a multiresolution volume.

:class:`Shown` gives the rest of the viewer one interface whatever was passed in:

* ``volume`` - an in-memory :class:`~splinecast.Volume` for everything that looks at values
  (automatic isovalue, window and transfer function, isovalue checks, the histogram behind the
  sliders). For a multiresolution scene it is the scene's ``preview``: the coarsest level, which
  stays resident, with the whole volume's value range. The finest level is never read for it.
* ``geometry`` - what cameras frame (:meth:`Camera.orbit`) and what ``hello`` describes: the
  volume itself, or the lazy multiscale / wavelet volume (level 0's placement).
* ``models`` and ``modes`` - exactly what the page may choose (a wavelet store renders only its
  ``bspline<degree>``; a scene passed in by the caller only its own model).
* ``kind`` - what the viewer does differently for this kind of data (:mod:`.kinds`: stripes or
  whole frames, how long a pass waits for bricks, scenes kept, picking, ...).
* :meth:`Shown.make_scene` - the scene of another model, when that is offered.
* :func:`bricks_header` - the brick counts of a frame for the frame header and the status line.
* ``timepoints`` and :meth:`Shown.read_timepoint` - a time series read from a file (a 4D NIfTI,
  an OME-Zarr image with a ``t`` axis, a TIFF with T): how many time points it holds, and
  another one read from the same file (same channel).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from ..errors import ParameterError
from ..io.multichannel import MultichannelVolume
from ..models import MODELS
from ..multires.scenes.channels import ChannelScene
from ..multires.scenes.labels import LabelScene
from ..render.modes import MODE_NAMES as MODES
from ..scene import Scene
from ..volume import Volume
from .kinds import ChannelPyramids, Channels, DataKind, InMemory, Labels, Multiscale, Wavelet

__all__ = ["Shown", "shown", "DEFAULT_BUDGET", "DEFAULT_LOD"]

#: Brick cache of a pyramid the viewer opens itself (the default of ``splinecast render``).
DEFAULT_BUDGET = "2GiB"
#: Level of detail of a pyramid the viewer opens itself (pixels per voxel; as ``render``).
DEFAULT_LOD = 1.0


@dataclass
class Shown:
    """The data on display and what may be done with it (see the module docstring).

    Attributes
    ----------
    kind : DataKind
        What the viewer does differently for this kind of data (:mod:`.kinds`).
    volume : Volume
        In memory: values, defaults and histogram (a multiresolution scene's coarsest level).
    geometry : object
        World placement (``bounds``, ``shape``, ``spacing``, ``origin``, ``name``, ``dtype``,
        ``value_range``) of the full-resolution data.
    models, modes : tuple of str
        What the page may choose.
    pinned : scene, optional
        A scene given by the caller (kept; never closed by the viewer).
    initial : scene, optional
        A scene the viewer opened already (a pyramid's first model; the viewer closes it when
        another model replaces it).
    scene_options : dict
        Keyword arguments of scenes the viewer makes itself.
    default_model : str
        The model shown first.
    timepoints : int
        Time points of the file the data was read from (1: not a time series, or data not
        read from a file the viewer can read again).
    timepoint : int
        The time point ``volume`` and ``geometry`` are (the one shown first).
    reader : callable, optional
        ``reader(t)`` reads time point ``t`` of the file (a Volume, or a lazy multiscale volume).
    """

    kind: DataKind
    volume: Volume
    geometry: Any
    models: tuple[str, ...]
    modes: tuple[str, ...] = MODES
    pinned: Any = None
    initial: Any = None
    scene_options: dict[str, Any] = field(default_factory=dict)
    default_model: str = "trilinear"
    timepoints: int = 1
    timepoint: int = 0
    reader: Callable[[int], Any] | None = None
    #: Several channels: each one's label, colour (``#rrggbb``), window and visibility as its
    #: scene starts (the state's ``channels``).
    channels: list[dict[str, Any]] | None = None
    #: A label volume: each label's value, name and colour (``#rrggbb``), as ``hello.labels``
    #: lists them.
    labels: list[dict[str, Any]] | None = None

    @property
    def data(self) -> Any:
        """What the viewer's own scenes of the first time point are made of: the full-resolution
        data (for a volume in memory, the volume itself)."""
        return self.geometry

    def make_scene(self, model: str, data: Any = None) -> Any:
        """A new scene of ``model`` (one the page may choose) of ``data`` (a time point read by
        :meth:`read_timepoint`; default: the first one shown)."""
        if model not in self.models:
            raise ParameterError(f"model must be one of {', '.join(self.models)}, got {model!r}")
        return self.kind.make_scene(self.data if data is None else data, model,
                                    self.scene_options)

    def read_timepoint(self, timepoint: int) -> Any:
        """Time point ``timepoint`` of the file, read again from it (same channel)."""
        if timepoint == self.timepoint:
            return self.data
        if self.reader is None or not 0 <= timepoint < self.timepoints:
            raise ParameterError(f"timepoint must be 0 for {self.geometry.name} (it holds one "
                                 f"time point), got {timepoint!r}")
        return self.reader(timepoint)

    def close_scene(self, scene: Any) -> None:
        """Release a scene the viewer made (a pyramid's loader thread); pinned ones are kept,
        and ``None`` (no scene made yet) is left alone."""
        if scene is not None and scene is not self.pinned:
            scene.close()

    def description(self) -> dict[str, Any] | None:
        """The ``hello`` message's ``multires`` entry (None for data that is not
        multiresolution): :meth:`.kinds.DataKind.description`."""
        scene = self.pinned if self.pinned is not None else self.initial
        return self.kind.description(self.geometry, self.volume, scene, self.scene_options)


def bricks_header(stats: dict[str, Any]) -> dict[str, Any] | None:
    """The frame header's ``bricks`` object from a multiscale frame's statistics (None when the
    frame has no bricks).

    ``cut`` bricks make this view; ``cut_resident`` of them are drawn from their own data (the
    others from a coarser ancestor); ``loading`` are still to be read; ``resident`` bricks (of
    any view, ancestors included) hold ``resident_bytes`` of ``budget``; ``progress`` is
    ``cut_resident / cut``; ``complete`` says nothing more will arrive for this view;
    ``unreadable`` bricks of the view are drawn from a coarser level because their chunks
    cannot be read (the status line says so).
    """
    if "cut_bricks" not in stats or "substituted" not in stats:
        return None
    cut = int(stats["cut_bricks"])
    resident_in_cut = cut - int(stats["substituted"])
    loading = int(stats.get("requested", 0))
    complete = bool(stats.get("complete", False)) and stats.get("cut_final", True) is not False
    return {
        "cut": cut,
        "cut_resident": resident_in_cut,
        "loading": loading,
        "resident": int(stats.get("resident", 0)),
        "resident_bytes": int(stats.get("resident_bytes", 0)),
        "budget": int(stats.get("budget", 0)),
        "unavailable": int(stats.get("unavailable", 0)),
        "unreadable": int(stats.get("unreadable", 0)),
        "loaded": int(stats.get("loaded", 0)),
        "progress": resident_in_cut / cut if cut else 1.0,
        "complete": complete,
    }


def shown(data: Any, model: str | None = None, budget: Any = None,
          lod: float | None = None, allow_external: bool | None = None, *,
          labels: bool = False, colors: Any = None) -> Shown:
    """Classify what ``sc.view`` / ``splinecast view`` was given.

    Parameters
    ----------
    data : Volume, Scene, MultiscaleVolume, MultiscaleScene, WaveletVolume or WaveletScene
    model : str, optional
        The model shown first (default: a scene's own, a wavelet store's ``bspline<degree>``,
        else ``"trilinear"``).
    budget : int or str, optional
        Brick cache of a pyramid the viewer opens (default :data:`DEFAULT_BUDGET`).
    lod : float, optional
        Level of detail of a pyramid (pixels per voxel, default :data:`DEFAULT_LOD`) or a wavelet
        store (ε in radians, default one pixel's angle, as ``splinecast render``).
    allow_external : bool, optional
        Passed to :func:`splinecast.read` when another time point of the file is read (as the
        first one was read).
    labels : bool
        Show ``data`` (a Volume or a multiscale volume of integer labels) as a label volume:
        each label its own surface (:class:`~splinecast.multires.scenes.labels.LabelScene`). A
        ``LabelScene`` given as ``data`` is one already.
    colors : path, mapping or list, optional
        With ``labels``: the labels' colour table (as ``Scene(vol, labels=True, colors=...)``).

    Raises
    ------
    ParameterError
        Anything else, a model the data cannot be rendered with, or ``budget`` / ``lod`` given
        with data they do not apply to.
    """
    if labels or isinstance(data, LabelScene):
        return _labels(data, model, budget, lod, colors)
    if colors is not None:
        raise ParameterError("colors applies to label volumes (labels=True) only")
    out = _classify(data, model, budget, lod)
    if out.kind.time_series:
        _time_series(out, allow_external)
    return out


def _time_series(out: Shown, allow_external: bool | None) -> None:
    """Fill in ``timepoints``, ``timepoint`` and ``reader`` from the metadata of a volume read
    from a file that holds several time points (``metadata["source"]`` is read again)."""
    meta = getattr(out.geometry, "metadata", None) or {}
    count, source = meta.get("timepoints", 1), meta.get("source")
    if not isinstance(count, int) or count <= 1 or not isinstance(source, str):
        return
    channel = int(meta.get("channel", 0))

    def reader(timepoint: int) -> Any:
        from ..io import read  # imported here: the viewer of an in-memory volume needs no reader

        return read(source, timepoint=timepoint, channel=channel,
                    allow_external=allow_external)

    out.timepoints = int(count)
    out.timepoint = int(meta.get("timepoint", 0))
    out.reader = reader


def _classify(data: Any, model: str | None, budget: Any, lod: float | None) -> Shown:
    if model is not None and model not in MODELS:
        raise ParameterError(f"model must be one of {', '.join(MODELS)}, got {model!r}")
    if isinstance(data, Scene | Volume):
        if budget is not None or lod is not None:
            raise ParameterError("budget and lod apply to multiresolution (OME-Zarr or wavelet) "
                                 "data only")
        if isinstance(data, Scene):
            # A scene given by the caller offers the modes its kind declares (all by default).
            return Shown(InMemory(), data.volume, data.volume, tuple(MODELS),
                         modes=data.modes or MODES, pinned=data,
                         default_model=model or data.model_name)
        return Shown(InMemory(), data, data, tuple(MODELS), default_model=model or "trilinear")
    # Imported here: the viewer of an in-memory volume never loads zarr.
    from ..io.omezarr import MultiscaleVolume
    from ..multires.scenes.multiscale import MultiscaleScene
    from ..multires.scenes.wavelet import WaveletScene
    from ..multires.wavelet.store import WaveletVolume

    if isinstance(data, MultiscaleScene | WaveletScene):
        if budget is not None or lod is not None:
            raise ParameterError("budget and lod are the scene's own: pass a volume to set them")
        _only_model(model, data.model_name, data.volume.name)
        kind = Multiscale() if isinstance(data, MultiscaleScene) else Wavelet()
        return Shown(kind, data.preview, data.volume, (data.model_name,),
                     modes=data.modes or MODES, pinned=data, default_model=data.model_name)
    if isinstance(data, WaveletVolume):
        if budget is not None:
            raise ParameterError(f"budget does not apply to the wavelet store {data.name}")
        scene = WaveletScene(data, model=model, lod=lod)  # reads the coarsest level only
        return Shown(Wavelet(), scene.preview, data, (scene.model_name,), pinned=scene,
                     default_model=scene.model_name)
    if isinstance(data, MultiscaleVolume):
        # Bricks always (whole_level=False): reading a whole level inside a frame would stop the
        # frames until it is read, where bricks let the page refine while they arrive.
        options = {"budget": DEFAULT_BUDGET if budget is None else budget,
                   "lod": DEFAULT_LOD if lod is None else lod, "whole_level": False}
        scene = MultiscaleScene(data, model=model or "trilinear", **options)  # coarsest level
        return Shown(Multiscale(), scene.preview, data, tuple(MODELS), initial=scene,
                     scene_options=options, default_model=scene.model_name)
    if isinstance(data, list | tuple):
        data = MultichannelVolume(data)
    if isinstance(data, MultichannelVolume | ChannelScene):
        return _channels(data, model, budget, lod)
    raise ParameterError(f"the viewer shows a splinecast Volume or Scene (or a multiresolution "
                         f"volume or scene), got {type(data).__name__}")


def _channels(data: Any, model: str | None, budget: Any, lod: float | None) -> Shown:
    """Several channels on one grid: a :class:`~splinecast.ChannelScene` made now (so its
    channels' defaults are known for the ``hello`` message)."""
    volumes = data.volume if isinstance(data, ChannelScene) else data
    pyramids = any(not isinstance(v, Volume) for v in volumes)
    if (budget is not None or lod is not None) and not pyramids:
        raise ParameterError("budget and lod apply to multiresolution (OME-Zarr) data only")
    options: dict[str, Any] = {}
    if pyramids:
        options = {"budget": DEFAULT_BUDGET if budget is None else budget,
                   "lod": DEFAULT_LOD if lod is None else lod, "whole_level": False}
    if isinstance(data, ChannelScene):
        scene, pinned = data, data
        _only_model(model, data.model_name, volumes.name)
        models: tuple[str, ...] = (data.model_name,)
    else:
        scene, pinned = ChannelScene(volumes, model=model or "trilinear", **options), None
        models = tuple(MODELS)
    first = scene.scenes[0]
    volume = first.defaults_volume  # a pyramid's coarsest level, else the volume
    described = [{"label": c.label, "color": _hex(c.color),
                  "window": None if c.window is None else list(c.window),
                  "iso": c.iso, "visible": c.visible} for c in scene.channels]
    return Shown(ChannelPyramids() if pyramids else Channels(), volume, volumes, models,
                 pinned=pinned, initial=None if pinned is not None else scene,
                 scene_options=options, default_model=scene.model_name, channels=described)


def _labels(data: Any, model: str | None, budget: Any, lod: float | None,
            colors: Any) -> Shown:
    """A label volume: its :class:`LabelScene` made now (the labels present, their names and
    colours go into the ``hello`` message). One mode (the labels' surfaces, ``iso``); any model
    reconstructs each label's indicator."""
    if lod is not None:
        raise ParameterError("lod does not apply to label volumes (a multiscale label image's "
                             "finest level within budget is read whole)")
    if isinstance(data, LabelScene):
        if budget is not None or colors is not None:
            raise ParameterError("budget and colors are the label scene's own: pass a volume "
                                 "to set them")
        _only_model(model, data.model_name, str(data.volume.metadata.get("name", "labels")))
        scene, pinned, models, options = data, data, (data.model_name,), {}
    else:
        options: dict[str, Any] = {} if budget is None else {"budget": budget}
        scene = LabelScene(data, model=model or "trilinear", **options)
        if colors is not None:
            scene.set_colors(colors)
            options["colors"] = colors
        pinned, models = None, tuple(MODELS)
    described = [{"value": int(v), "name": scene.style(v).name, "color": _hex(
        scene.style(v).rgba[:3])} for v in scene.labels]
    volume = scene.volume
    return Shown(Labels(), volume, volume, models, modes=LabelScene.modes or MODES,
                 pinned=pinned, initial=None if pinned is not None else scene,
                 scene_options=options,
                 default_model=scene.model_name, labels=described)


def _hex(color: Any) -> str:
    return "#" + "".join(f"{round(255 * float(c)):02x}" for c in color)


def _only_model(model: str | None, own: str, name: str) -> None:
    if model is not None and model != own:
        raise ParameterError(f"model must be {own} for the scene of {name} given to the viewer "
                             f"(it renders that model only), got {model!r}")
