"""The :class:`Scene`: a volume with a prepared reconstruction, rendered through cameras.

A scene is prepared once per volume and model (the model's arrays and the min/max block ranges).
Changing the isovalue only re-classifies the blocks (milliseconds); rendering then traces every
pixel in compiled, multi-threaded code.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from .accel.active_cells import ActiveCells
from .accel.minmax import BLOCK_SHIFTS
from .camera import Camera
from .errors import ParameterError
from .models import MODELS
from .render.defaults import content_box
from .render.footprint import NO_FOOTPRINT
from .render.modes import MODE_NAMES
from .render.segment import (
    make_grid,
    pixel_ranges,
    render_grid,
    screen_footprint,
    trace_pixels,
)
from .render.template import (
    RenderRequest,
    SceneTemplate,
    Traced,
    check_iso,
    finish_frame,
    prepare_render,
    whole_frame_tracer,
)
from .transfer import TransferFunction
from .volume import Volume

# The render template's parts are re-exported here, where they were defined before the template
# had a module of its own.
__all__ = ["Scene", "MODES", "check_iso", "RenderRequest", "prepare_render", "finish_frame",
           "register_scene_type", "whole_frame_tracer", "SceneTemplate", "Traced"]

#: Names of the render modes accepted by :meth:`Scene.render` (the registry
#: :data:`splinecast.render.modes.MODES` holds their classes).
MODES = MODE_NAMES


#: Scene types for volumes other than :class:`Volume`: qualified class name of the volume ->
#: factory (see :func:`register_scene_type`).
_SCENE_TYPES: dict[str, Callable[..., Any]] = {}


#: The key of :func:`register_scene_type` under which the scene of label volumes
#: (``Scene(volume, labels=True)``, any kind of volume) is registered.
LABELS = "labels"


def register_scene_type(volume_class: str, factory: Callable[..., Any]) -> None:
    """Make ``Scene(volume, ...)`` return ``factory(volume, ...)`` for another kind of volume.

    ``volume_class`` is the qualified name of the volume's class (or of a base class), for
    example ``"splinecast.io.omezarr.MultiscaleVolume"``, or :data:`LABELS` for the scene of
    ``Scene(volume, labels=True)``: the layers above this module register
    their scenes here (``splinecast/__init__.py`` registers
    :class:`splinecast.multires.scenes.multiscale.MultiscaleScene`), so this module never imports
    them.
    """
    _SCENE_TYPES[volume_class] = factory


def _scene_factory(volume: Any) -> Callable[..., Any] | None:
    for klass in type(volume).__mro__:
        factory = _SCENE_TYPES.get(f"{klass.__module__}.{klass.__qualname__}")
        if factory is not None:
            return factory
    return None


class Scene(SceneTemplate):
    """A volume, its reconstruction model, and the acceleration structure for rendering.

    Parameters
    ----------
    volume : Volume
        The data to render. A lazy OME-Zarr volume gives a
        :class:`~splinecast.MultiscaleScene`; a list of volumes on one grid, or the
        :class:`~splinecast.MultichannelVolume` of ``read(path, channel=[0, 2])``, a
        :class:`~splinecast.ChannelScene` rendering the channels together.
    model : str
        Reconstruction: ``"trilinear"``, ``"bspline1"``, ``"bspline2"``, ``"bspline3"``,
        ``"qss"`` or ``"s31"`` (see :data:`splinecast.models.MODELS`); every model renders in
        every mode.
    labels : bool
        ``True``: ``volume`` is a label volume (a segmentation: 0 is the background, every
        other integer a region); each label's boundary is drawn as its own surface in its own
        colour, and ``Scene`` returns a :class:`~splinecast.multires.scenes.labels.LabelScene`
        (options ``colors``, ``show``, ``opacity``). Never guessed from the voxel type.
    **options
        Model options (for example ``prefilter=True`` for spline models), passed to the model.

    Examples
    --------
    >>> import splinecast as sc
    >>> vol = sc.demo("sphere", size=32)
    >>> scene = sc.Scene(vol)
    >>> frame = scene.render(sc.Camera.orbit(vol, size=(64, 48)), iso=0.0)
    >>> frame.depth.shape
    (48, 64)
    """

    def __new__(cls, volume: Any = None, *args: Any, **kwargs: Any) -> Any:
        # Label volumes (labels=True) of any kind get the label scene registered under
        # LABELS; a volume of another kind (a lazy multiscale OME-Zarr image) gets the scene
        # registered for it (register_scene_type); a Volume gets this class.
        if cls is Scene and kwargs.get("labels"):
            factory = _SCENE_TYPES.get(LABELS)
            if factory is not None:
                return factory(volume, *args, **kwargs)
        kwargs.pop("labels", None)
        if cls is Scene and not isinstance(volume, Volume):
            factory = _scene_factory(volume)
            if factory is not None:
                return factory(volume, *args, **kwargs)
        return super().__new__(cls)

    def __init__(self, volume: Volume, model: str = "trilinear", *, labels: bool = False,
                 **options: Any) -> None:
        if labels:
            raise ParameterError("labels=True needs the label scene, registered by importing "
                                 "splinecast")
        if not isinstance(volume, Volume):
            raise ParameterError(f"volume must be a splinecast.Volume, got {type(volume).__name__}")
        if model not in MODELS:
            raise ParameterError(f"model must be one of {', '.join(MODELS)}, got {model!r}")
        start = time.perf_counter()
        self.volume = volume
        self.model = MODELS[model](volume, **options)
        #: The whole volume as one grid of the model (kernel arrays, block hierarchy, placement).
        self.grid = make_grid(self.model)
        self.hierarchy = self.grid.hierarchy
        #: Per-isovalue work lists of models that classify their cells (s31, qss).
        classifier = self.model.active_cell_classifier()
        self.active_cells = ActiveCells(classifier) if classifier is not None else None
        self.prepare_ms = (time.perf_counter() - start) * 1e3
        self.classify_ms = math.nan
        #: Counts and timings of the model's own isovalue change (models with work lists).
        self.iso_stats: dict[str, Any] = {}
        self._iso: float | None = None

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """World-space corners of the volume (so a camera can frame a Scene)."""
        return self.volume.bounds

    @property
    def tile_shape(self) -> tuple[int, int]:
        """Columns and rows of the tiles the renderer traces as units, on the image's own grid.

        A window of an image (:meth:`Camera.tile`) whose first column and first row are
        multiples of these renders exactly the whole image's pixels, in every mode (MIP with
        a ``tolerance`` lets each ray start from what the previous ray of its tile found).
        Columns 0: a tile spans whole rows.
        """
        return (max(0, int(self.grid.tile)), max(1, int(self.grid.band_rows)))

    def content_box(self, iso: Any = None, tf: TransferFunction | None = None,
                    ) -> tuple[np.ndarray, np.ndarray]:
        """World box of what an isovalue or a transfer function shows (see
        :func:`splinecast.content_box`): ``tf`` if given, else ``iso``, else the isovalue last
        rendered, else the automatic one. ``Camera.orbit(scene, fit="content")`` frames it."""
        if tf is None and iso is None:
            iso = self._iso
        return content_box(self.volume, iso=iso, tf=tf)

    @property
    def iso(self) -> float | None:
        """The isovalue the block flags are classified for (None before the first)."""
        return self._iso

    def _iso_flags(self) -> tuple[np.ndarray, ...]:
        """Block flags of the current isovalue (the model's own work lists when it has them)."""
        if self.active_cells is not None:
            a = self.active_cells
            return a.act0, a.act1, a.act2, a.pairs, a.packed
        return self.hierarchy.active

    def _active_box(self, flags: tuple[np.ndarray, ...]) -> tuple[np.ndarray, np.ndarray] | None:
        """The box, in voxel index space, around the blocks that can hold the current isovalue
        (``None`` if none can).

        The box is padded outwards by a millionth of a voxel so rounding can never cut a hit.
        Rays are clipped to it as to the volume's box (:meth:`Grid.with_domain`), which the slab
        test does anyway; six clip planes per ray would add their tests to every ray.
        """
        act = flags[0].view(bool)
        if not act.any():
            return None
        block = 1 << BLOCK_SHIFTS[0]
        lo_cells, hi_cells = np.empty(3), np.empty(3)
        for axis in range(3):
            used = np.flatnonzero(act.any(axis=tuple(a for a in range(3) if a != axis)))
            lo_cells[axis] = used[0] * block
            hi_cells[axis] = min((used[-1] + 1) * block, self.grid.n_cells[axis])
        # Cell c spans [c, c + 1] in voxel index + shift.
        shift = self.model.shift
        return lo_cells - shift - 1e-6, hi_cells - shift + 1e-6

    def set_iso(self, iso: float) -> float:
        """Classify the blocks for a new isovalue; returns the time it took in ms."""
        value = self.check_iso(iso)
        start = time.perf_counter()
        self.hierarchy.classify(value)
        if self.active_cells is not None:
            self.iso_stats = self.active_cells.update(value)
        self.classify_ms = (time.perf_counter() - start) * 1e3
        self._iso = value
        return self.classify_ms

    def trace(self, request: RenderRequest, camera: Camera, **frame_options: Any) -> Traced:
        """Trace a validated request (:func:`prepare_render`) through this scene's grid: the
        step of the render template (:class:`~splinecast.render.template.SceneTemplate`) an
        in-memory scene supplies."""
        grid, flags, planes, stats = self.grid, None, request.planes, request.stats
        if request.iso is not None:
            classify_ms = 0.0
            if request.iso != self._iso:
                classify_ms = self.set_iso(request.iso)
            flags = self._iso_flags()
            if self.active_cells is not None:
                grid = grid.with_kernel(self.model.kernel_grid(active=self.active_cells))
            box = self._active_box(flags)
            if box is not None:
                grid = grid.with_domain(*box)
            stats["classify_ms"] = classify_ms
            stats.update(self.iso_stats)
        start = time.perf_counter()
        setup = request.setup
        tiles = screen_footprint(grid, setup, camera, setup.blocks(grid.hierarchy, flags))
        out, counters = render_grid(grid, setup, camera, planes, flags,
                                    count="stats" in request.outputs, footprint=tiles)
        return Traced(out, counters, start, _pixel_tracer(grid, camera, planes, flags, tiles))


def _pixel_tracer(grid: Any, camera: Camera, planes: np.ndarray, flags: Any,
                  tiles: np.ndarray) -> Callable[..., tuple]:
    """:func:`finish_frame`'s ``trace`` for a frame of one grid: the pixels of a mask traced
    with :func:`~splinecast.render.segment.trace_pixels`, with the frame's screen footprint
    ``tiles`` for cameras of the frame's window (shifted inside the pixels or not)."""
    last: list[Any] = [None, None]  # the mask and its ranges: the same for every pass

    def trace(cam: Camera, mask: np.ndarray, mode: Any) -> tuple:
        if last[0] is not mask:
            last[0], last[1] = mask, pixel_ranges(mask)
        same = cam.region == camera.region and cam.size == camera.size
        return trace_pixels(grid, mode, cam, last[1], planes, flags,
                            tiles if same else NO_FOOTPRINT)

    return trace


