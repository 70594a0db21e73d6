"""Label volumes (segmentations): every label's boundary as its own surface, in its own colour.

``Scene(vol, labels=True)`` returns a :class:`LabelScene`. Label ``k``'s surface is the 0.5
isosurface of its indicator (1 where the voxel holds ``k``, 0 elsewhere) reconstructed by the
scene's model: trilinear gives the faceted boundary of the voxels, the smooth models (B-splines,
s31) smooth organ surfaces. Each label is rendered from a sub-volume: its voxel box plus
:data:`MARGIN` voxels on every side (clamped to the volume), with the origin shifted so it sits
where it belongs, and traced only in the window of the image that box projects to
(:meth:`splinecast.Camera.box_window`). The indicator is float32, so every label reuses the
kernels of float32 volumes (no compile per label), and the boxes of all labels together hold
about as many voxels as the volume.

The labels' frames are rendered on a transparent background and composited per pixel
(:mod:`splinecast.render.compose`): front to back in depth order with the "over" operator (so
translucent labels show the labels behind them, and antialiased silhouettes blend with the
surface behind), then once over the scene's background. ``Frame.label`` holds, per pixel, the
value of the label hit first (0 on a miss): what a viewer shows under the cursor.

Every kind of volume goes through this one path: an in-memory :class:`~splinecast.Volume`, a
multiscale (OME-Zarr) label image, whose finest level that fits the memory ``budget`` is read
(label pyramids are downsampled by the most frequent label, :mod:`.store.label_downsample`, so every
level is a label volume of its own), and the workers of a sort-first
:class:`~splinecast.distributed.DistributedScene` (``labels=True``), which render image tiles of
it (a tile camera's frame is that window of the whole frame, ``label`` included).
"""

from __future__ import annotations

import time
from collections import OrderedDict
from collections.abc import Iterable, Mapping
from dataclasses import replace
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np

from ...accel.label_boxes import integer_labels, label_boxes
from ...camera import Camera
from ...errors import ParameterError, limits
from ...io.label_colors import (
    LabelStyle,
    describe,
    image_label_table,
    palette_color,
    parse_color_table,
    read_color_table,
)
from ...models.smoothing import smooth as smooth_volume
from ...render.compose import gather, nearest_hit, on_background, over_by_depth
from ...render.frame import Frame
from ...render.modes import mode_name
from ...render.outputs import check_outputs
from ...render.shading import Shading
from ...render.template import RenderOptions, SceneTemplate
from ...scene import Scene
from ...volume import Volume

__all__ = ["LabelScene", "MARGIN", "DEFAULT_BUDGET", "label_volume"]

#: Voxels of background kept around each label's box: at least the widest support of a model's
#: reconstruction (the cubic B-spline reaches 2 voxels), so the indicator's surface closes
#: inside the sub-volume as it does in the whole volume.
MARGIN = 4
#: Memory a multiscale label image's level may take when read (``budget`` of :class:`LabelScene`).
DEFAULT_BUDGET = "2GiB"
#: How much darker than the front the back faces of a label are (where a clip plane or the
#: volume's box cuts it open).
_BACK_SHADE = 0.6


def label_volume(volume: Any, budget: Any = DEFAULT_BUDGET) -> Volume:
    """``volume`` as an in-memory :class:`Volume` of labels.

    A :class:`Volume` is returned as it is; a lazy multiscale volume (``levels``) gives its
    finest level whose voxels fit in ``budget`` bytes (an int or ``"512MiB"``), read whole.

    Raises
    ------
    ParameterError
        If no level fits the budget, or ``volume`` is neither.
    """
    if isinstance(volume, Volume):
        return volume
    levels = getattr(volume, "levels", None)
    if not levels:
        raise ParameterError(f"labels need a splinecast.Volume or a multiscale (OME-Zarr) "
                             f"volume, got {type(volume).__name__}")
    limit = limits.parse_bytes(budget, "budget")
    for level in levels:
        nbytes = int(np.prod(level.shape)) * np.dtype(level.dtype).itemsize
        if nbytes <= limit:
            loaded = level.to_volume(max_bytes=limit)
            loaded.metadata.update(getattr(volume, "metadata", {}))
            loaded.metadata["name"] = f"{volume.name} level {level.index}"
            loaded.metadata["level"] = level.index
            return loaded
    smallest = min(int(np.prod(lv.shape)) * np.dtype(lv.dtype).itemsize for lv in levels)
    raise ParameterError(f"{volume.name}: even the coarsest level ({smallest / 2**20:.0f} MiB) "
                         f"exceeds the labels' budget={limit / 2**20:.0f} MiB")


class LabelScene(SceneTemplate):
    """A label volume: each label's surface rendered in its own colour.

    Usually made by ``Scene(volume, labels=True, ...)``; see the module's text for the method.

    Parameters
    ----------
    volume : Volume or MultiscaleVolume
        Integer labels (0: background); floating-point voxels must be whole numbers.
    model : str
        Reconstruction of each label's indicator (:data:`splinecast.models.MODELS`).
    colors : path, mapping or list, optional
        Colours and names of labels (:mod:`splinecast.io.label_colors`): a ``.json``/``.csv``
        colour table file, or its content. Overrides the volume's ``image-label`` colours,
        which override the default palette.
    show : iterable of int, optional
        The labels drawn (default: every label of the volume).
    opacity : float or mapping, optional
        Opacity of every label, or label -> opacity (others 1); multiplies the colour's alpha.
    budget : int or str
        Multiscale volumes: memory for the level read (:func:`label_volume`); every volume:
        memory for the labels' indicators kept prepared between frames (beyond it the least
        recently drawn are dropped and prepared again when needed).
    smooth : {3, 5}, optional
        Filter each label's indicator with the ``smooth^3`` Gaussian
        (:func:`splinecast.smooth`) before the model reconstructs it: the voxels' staircase,
        which every model's 0.5 isosurface of a binary indicator still shows as ripples, melts
        into a smooth organ surface (about a voxel's detail is lost). Default: none.
    labels : bool
        ``True``, as ``Scene(volume, labels=True)`` passes it.
    **options
        Model options (``prefilter=True``, ...), passed to every label's scene.

    Attributes
    ----------
    volume : Volume
        The labels in memory.
    labels : ndarray of int64
        The label values present, 0 left out, increasing.
    styles : dict
        Label -> :class:`~splinecast.io.label_colors.LabelStyle` (colour and name).

    Raises
    ------
    ParameterError
        An unknown model, a label in ``show`` or ``colors`` that the volume does not hold (the
        message names the file or option), a bad colour table or opacity.
    DataError
        Voxels that are not whole numbers.
    """

    def __init__(self, volume: Any, model: str = "trilinear", *, colors: Any = None,
                 show: Iterable[int] | None = None, opacity: Any = 1.0,
                 budget: Any = DEFAULT_BUDGET, smooth: int | None = None, labels: bool = True,
                 **options: Any) -> None:
        from ...models import MODELS

        if not labels:
            raise ParameterError("a LabelScene renders labels: labels must be True")

        if model not in MODELS:
            raise ParameterError(f"model must be one of {', '.join(MODELS)}, got {model!r}")
        start = time.perf_counter()
        self.source = volume
        self.volume = label_volume(volume, budget)
        name = str(self.volume.metadata.get("name", "the volume"))
        self.data = integer_labels(self.volume.data, name)
        self.labels, self._lo, self._hi = label_boxes(self.data)
        self._model_name = model
        self.options = options
        if smooth is not None and smooth not in (3, 5):
            raise ParameterError(f"smooth must be 3 or 5 (the Gaussian's size), got {smooth!r}")
        self.smooth = smooth
        self.styles = self._styles(colors, name)
        self._show = self._check_show(show, "show")
        self._opacity = self._check_opacity(opacity)
        # Prepared label scenes, least recently used first; their indicators' bytes are kept
        # within the budget (a scene dropped is prepared again when its label is drawn).
        self._scenes: OrderedDict[int, Scene] = OrderedDict()
        self._budget = limits.parse_bytes(budget, "budget")
        self.prepare_ms = (time.perf_counter() - start) * 1e3

    # ------------------------------------------------------------------ set-up
    def _styles(self, colors: Any, name: str) -> dict[int, LabelStyle]:
        styles = {int(v): LabelStyle(palette_color(int(v))) for v in self.labels}
        meta = self.volume.metadata.get("image_label")
        for value, style in image_label_table(meta, name).items():
            if value in styles:  # a store's table may name labels of other levels or times
                styles[value] = style
        self.styles = styles
        if colors is not None:
            self.set_colors(colors)
        return self.styles

    def set_colors(self, colors: Any, option: str = "colors") -> None:
        """Colour (and name) the labels a colour table names; the others keep theirs.

        Parameters
        ----------
        colors : path, mapping or list
            A ``.json``/``.csv`` file or its content (:mod:`splinecast.io.label_colors`).
        option : str
            What gave it, for messages (``"--label-colors"``).

        Raises
        ------
        ParameterError
            A bad table, or one naming a label the volume does not hold (the message names
            the file and ``option``).
        """
        if isinstance(colors, (Mapping, list)):
            table, where = parse_color_table(colors, option), option
        else:
            table, where = read_color_table(colors, option), f"{colors} ({option})"
        self._check_present(table, where)
        self.styles.update(table)

    @property
    def shown(self) -> tuple[int, ...]:
        """The labels drawn by default (``show``)."""
        return self._show

    def _check_present(self, values: Iterable[int], where: str) -> None:
        present = set(int(v) for v in self.labels)
        missing = sorted(int(v) for v in values if int(v) not in present)
        if missing:
            name = self.volume.metadata.get("name", "the volume")
            raise ParameterError(
                f"{where}: label{'s' if len(missing) > 1 else ''} {describe(missing)} "
                f"{'do' if len(missing) > 1 else 'does'} not occur in {name} "
                f"(its labels: {describe(self.labels) or 'none'})")

    def _check_show(self, show: Iterable[int] | None, where: str) -> tuple[int, ...]:
        if show is None:
            return tuple(int(v) for v in self.labels)
        try:
            values = [int(v) for v in show]
        except (TypeError, ValueError):
            raise ParameterError(f"{where} must be label values (integers), got {show!r}") \
                from None
        self._check_present(values, where)
        return tuple(sorted(set(values)))

    def _check_opacity(self, opacity: Any) -> dict[int, float]:
        def one(value: Any, what: str) -> float:
            try:
                number = float(value)
            except (TypeError, ValueError):
                raise ParameterError(f"{what} must be a number in [0, 1], got {value!r}") \
                    from None
            if not 0.0 <= number <= 1.0:
                raise ParameterError(f"{what} must be in [0, 1], got {number:g}")
            return number

        if isinstance(opacity, Mapping):
            self._check_present(opacity, "opacity")
            table = {int(v): 1.0 for v in self.labels}
            table.update({int(k): one(v, f"opacity of label {k}") for k, v in opacity.items()})
            return table
        value = one(opacity, "opacity")
        return {int(v): value for v in self.labels}

    def _scene(self, value: int) -> Scene:
        """The scene of label ``value``'s indicator over its box plus the margin (made on first
        use, then kept)."""
        scene = self._scenes.get(value)
        if scene is not None:
            self._scenes.move_to_end(value)
        else:
            index = int(np.searchsorted(self.labels, value))
            shape = np.array(self.data.shape)
            lo = np.maximum(self._lo[index] - MARGIN, 0)
            hi = np.minimum(self._hi[index] + MARGIN + 1, shape)
            box = tuple(slice(int(a), int(b)) for a, b in zip(lo, hi, strict=True))
            name = self.volume.metadata.get("name", "the volume")
            limits.check_memory(4 * int(np.prod(hi - lo)), f"the indicator of label {value}",
                                str(name))
            indicator = (self.data[box] == value).astype(np.float32)
            spacing = np.asarray(self.volume.spacing)
            origin = np.asarray(self.volume.origin) + lo * spacing
            sub = Volume(indicator, spacing=tuple(spacing), origin=tuple(origin),
                         metadata={"name": f"label {value} of "
                                           f"{self.volume.metadata.get('name', 'the volume')}",
                                   "inside": "high"})
            if self.smooth:
                sub = smooth_volume(sub, self.smooth)
                sub.metadata["inside"] = "high"
            scene = Scene(sub, model=self.model_name, **self.options)
            self._scenes[value] = scene
            held = sum(s.volume.data.nbytes for s in self._scenes.values())
            while held > self._budget and len(self._scenes) > 1:
                _, dropped = self._scenes.popitem(last=False)
                held -= dropped.volume.data.nbytes
        return scene

    # ------------------------------------------------------------------ what a camera frames
    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """World-space corners of the volume (so a camera can frame the scene)."""
        return self.volume.bounds

    def content_box(self, show: Iterable[int] | None = None, **_: Any,
                    ) -> tuple[np.ndarray, np.ndarray]:
        """World box around the labels drawn (all, or ``show``); the volume's box if none."""
        values = self._check_show(show, "show") if show is not None else self._show
        if not values:
            return self.volume.bounds
        index = np.searchsorted(self.labels, values)
        spacing, origin = np.asarray(self.volume.spacing), np.asarray(self.volume.origin)
        lo = self._lo[index].min(axis=0) * spacing + origin
        hi = self._hi[index].max(axis=0) * spacing + origin
        return lo, hi

    def style(self, value: int) -> LabelStyle:
        """Colour and name of label ``value``."""
        if int(value) not in self.styles:
            self._check_present([value], "label")
        return self.styles[int(value)]

    # ------------------------------------------------------------------ rendering
    #: The options of ``render`` a label scene reads; the others must keep their defaults.
    _READS = frozenset(("mode", "opacity", "shading", "clip", "crop", "normals", "samples",
                        "outputs", "inside"))
    frame_options = MappingProxyType({"show": None})
    #: The labels' surfaces are the one mode of a label scene (the template refuses others).
    modes: ClassVar[tuple[str, ...] | None] = ("iso",)
    modes_reason: ClassVar[str | None] = "label volumes render their labels' surfaces"

    @property
    def model_name(self) -> str:
        """The model reconstructing each label's indicator (the scene holds no model itself:
        each label's scene has its own)."""
        return self._model_name

    def render_frame(self, camera: Camera, options: RenderOptions,
                     frame_options: Mapping[str, Any]) -> Frame:
        """Render the labels' surfaces: the render template's step for a scene that composites
        one in-memory scene's frame per label (``render`` is :meth:`splinecast.Scene.render`,
        with the frame option ``show``).

        ``render`` options a label scene reads:

        mode : str
            ``"iso"`` (the labels' surfaces), the only mode of label scenes (:attr:`modes`:
            ``render`` refuses another one), by name.
        show : iterable of int, optional
            Labels to draw this frame (default: the scene's ``show``).
        opacity : float or mapping, optional
            Opacity of every label or per label (default: the scene's).
        shading : Shading, optional
            Lighting and background; the colours are the labels'.
        clip, crop, normals, samples
            As :meth:`splinecast.Scene.render`.
        outputs : list of str, optional
            Buffers of the frame (as :meth:`Scene.render`); ``"label"`` (the label hit per
            pixel) and ``"depth"`` are always filled.

        The others (``iso``, ``window``, ``tf``, ...) are refused unless left at their defaults.

        Returns
        -------
        Frame
            ``rgba`` composited, ``depth`` (and ``position``, ``normal``, ``face``) of the first
            label hit, ``label`` its value (0 on a miss), ``stats["labels"]`` the labels drawn.
        """
        mode, inside = options.mode, options.inside
        if not isinstance(mode, str):  # a mode object's options are not the labels'
            raise ParameterError(f"label volumes take mode {mode_name(mode)!r} by name, not "
                                 f"as a mode object ({type(mode).__name__})")
        if inside is not None and inside != "high":
            raise ParameterError("inside does not apply to label volumes (a label is inside "
                                 "where the voxels hold it)")
        for key in options.given():
            if key not in self._READS:
                raise ParameterError(f"{key} does not apply to label volumes")
        if not isinstance(camera, Camera):
            raise ParameterError(f"camera must be a splinecast.Camera, got "
                                 f"{type(camera).__name__}")
        show, opacity, shading = frame_options["show"], options.opacity, options.shading
        clip, crop, normals, samples = (options.clip, options.crop, options.normals,
                                        options.samples)
        outputs = options.outputs
        values = self._check_show(show, "show") if show is not None else self._show
        alphas = self._check_opacity(opacity) if opacity is not None else self._opacity
        shading = shading or Shading()
        wanted = check_outputs(outputs)
        need = sorted((wanted - {"stats"}) | {"rgba", "depth"})
        if "stats" in wanted:
            need.append("stats")
        start = time.perf_counter()
        frames, drawn, offsets = [], [], []
        prepare_ms = 0.0
        for value in values:
            alpha = self.styles[value].rgba[3] * alphas[value]
            if alpha <= 0.0:
                continue
            t0 = time.perf_counter()
            scene = self._scene(value)
            prepare_ms += (time.perf_counter() - t0) * 1e3
            # Only the window of the image the label's box projects to is traced: a label
            # costs its share of the picture, not a whole frame.
            window = camera.box_window(*scene.volume.bounds)
            if window is None:
                continue
            rgb = self.styles[value].rgba[:3]
            look = replace(shading, front_color=rgb,
                           back_color=tuple(c * _BACK_SHADE for c in rgb),
                           background=(0.0, 0.0, 0.0, 0.0))
            frame = scene.render(camera.tile(*window), iso=0.5, inside="high", shading=look,
                                 clip=clip, crop=crop, normals=normals, samples=samples,
                                 outputs=need)
            if alpha < 1.0:  # premultiplied: colour and alpha scale together
                frame.rgba *= np.float32(alpha)
            frames.append(frame)
            drawn.append(value)
            offsets.append((window[1], window[0]))
        return self._compose(frames, drawn, offsets, camera, shading, wanted, start,
                             prepare_ms)

    def _compose(self, frames: list[Frame], drawn: list[int], offsets: list[tuple[int, int]],
                 camera: Camera, shading: Shading, wanted: frozenset[str], start: float,
                 prepare_ms: float) -> Frame:
        size = height, width = camera.height, camera.width
        stats: dict[str, Any] = {"mode": "labels", "model": self.model_name,
                                 "labels": len(drawn), "width": width, "height": height,
                                 "rays": width * height}
        depth, source = nearest_hit(frames, offsets, size)
        rgba = on_background(over_by_depth(frames, offsets, size), shading.background)
        values = np.asarray([0, *drawn], np.int64)

        def nearest(name: str) -> np.ndarray | None:
            return gather(frames, source, name, offsets) if name in wanted else None

        frame = Frame(rgba=rgba if "rgba" in wanted else None,
                      depth=depth if "depth" in wanted else None,
                      position=nearest("position"), normal=nearest("normal"),
                      face=nearest("face"), cells_visited=None, cells_tested=None,
                      blocks_skipped=None, stats=stats, label=values[source + 1])
        if "stats" in wanted:
            for name in ("cells_visited", "cells_tested", "blocks_skipped"):
                total = np.zeros(size, np.int32)
                for f, (r0, c0) in zip(frames, offsets, strict=True):
                    counts = getattr(f, name)  # work per pixel over all the labels' rays
                    total[r0:r0 + counts.shape[0], c0:c0 + counts.shape[1]] += counts
                setattr(frame, name, total)
            stats["mean_cells_visited"] = float(frame.cells_visited.mean())
        stats["hits"] = int(np.count_nonzero(np.isfinite(depth)))
        stats["prepare_ms"] = prepare_ms
        stats["trace_ms"] = (time.perf_counter() - start) * 1e3 - prepare_ms
        stats["traced_pixels"] = int(sum(f.rgba.shape[0] * f.rgba.shape[1] for f in frames))
        stats["samples"] = max((f.stats.get("samples", 1) for f in frames), default=1)
        return frame

    def __repr__(self) -> str:
        return (f"LabelScene({self.volume.metadata.get('name', 'volume')!r}, "
                f"model={self.model_name!r}, labels={len(self.labels)}, "
                f"shown={len(self._show)})")
