"""The :class:`Scene`: a volume with a prepared reconstruction, rendered through cameras.

A scene is prepared once per volume and model (the model's arrays and the min/max block ranges).
Changing the isovalue only re-classifies the blocks (milliseconds); rendering then traces every
pixel in compiled, multi-threaded code.
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .accel.active_cells import ActiveCells
from .accel.minmax import BLOCK_SHIFTS
from .camera import Camera
from .errors import ParameterError, limits
from .models import MODELS
from .render.antialias import antialias, resolve_samples
from .render.clipping import make_planes
from .render.defaults import (
    auto_iso,
    content_box,
)
from .render.dvr import DVRSettings
from .render.effects import SurfaceEffects, apply_effects
from .render.footprint import NO_FOOTPRINT
from .render.frame import Frame
from .render.modes import MODE_NAMES, ModeContext, RenderMode, build_mode
from .render.outputs import OUTPUTS, check_outputs
from .render.segment import (
    make_grid,
    pixel_ranges,
    render_grid,
    screen_footprint,
    trace_pixels,
)
from .render.shading import Shading, normals_code
from .transfer import TransferFunction
from .volume import Volume

__all__ = ["Scene", "MODES", "check_iso", "RenderRequest", "prepare_render", "finish_frame",
           "register_scene_type", "whole_frame_tracer"]

#: Names of the render modes accepted by :meth:`Scene.render` (the registry
#: :data:`splinecast.render.modes.MODES` holds their classes).
MODES = MODE_NAMES


def check_iso(volume: Volume, iso: Any) -> float:
    """Validate an isovalue for ``volume`` (``None`` means :func:`~splinecast.auto_iso`: its
    ``metadata["default_iso"]``, else Otsu's threshold of the non-background values).

    Raises
    ------
    ParameterError
        If the isovalue is not a number or lies outside the data range.
    """
    if iso is None:
        iso = auto_iso(volume)
    try:
        value = float(iso)
    except (TypeError, ValueError):
        raise ParameterError(f"iso must be a number, got {iso!r}") from None
    lo, hi = volume.value_range
    if not lo <= value <= hi:
        raise ParameterError(
            f"iso={value:g} is outside the data range [{lo:g}, {hi:g}] of {volume.name}"
        )
    return value


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
    :class:`splinecast.multires.scene.MultiscaleScene`), so this module never imports them.
    """
    _SCENE_TYPES[volume_class] = factory


def _scene_factory(volume: Any) -> Callable[..., Any] | None:
    for klass in type(volume).__mro__:
        factory = _SCENE_TYPES.get(f"{klass.__module__}.{klass.__qualname__}")
        if factory is not None:
            return factory
    return None


class Scene:
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
        colour, and ``Scene`` returns a :class:`~splinecast.multires.label_scene.LabelScene`
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
        self._table_cache: dict = {}  # the last pre-integration table (mode="dvr")

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

    def _check_iso(self, iso: Any) -> float:
        return check_iso(self.volume, iso)

    def _iso_flags(self) -> tuple[np.ndarray, ...]:
        """Block flags of the current isovalue (the model's own work lists when it has them)."""
        if self.active_cells is not None:
            a = self.active_cells
            return a.act0, a.act1, a.act2
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

    def close(self) -> None:
        """Nothing to release (no loader thread); here so that every scene ``sc.Scene`` returns
        is closed and used in ``with`` the same way."""

    def __enter__(self) -> Scene:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def set_iso(self, iso: float) -> float:
        """Classify the blocks for a new isovalue; returns the time it took in ms."""
        value = self._check_iso(iso)
        start = time.perf_counter()
        self.hierarchy.classify(value)
        if self.active_cells is not None:
            self.iso_stats = self.active_cells.update(value)
        self.classify_ms = (time.perf_counter() - start) * 1e3
        self._iso = value
        return self.classify_ms

    def render(
        self,
        camera: Camera,
        mode: str | RenderMode = "iso",
        iso: float | None = None,
        method: str = "exact",
        step: float = 0.25,
        shading: Shading | None = None,
        inside: str | None = None,
        *,
        clip: Any = None,
        crop: Any = None,
        colors: Any = None,
        opacity: Any = None,
        effects: SurfaceEffects | None = None,
        window: Any = None,
        colormap: Any = None,
        tolerance: float = 0.0,
        tf: TransferFunction | None = None,
        dvr: DVRSettings | None = None,
        outputs: Any = None,
        normals: str = "smooth",
        samples: int | None = None,
    ) -> Frame:
        """Render one image.

        Parameters
        ----------
        camera : Camera
            Viewpoint and image size.
        mode : str or mode object
            ``"iso"``: first-hit isosurface (or several translucent ones, see ``iso``);
            ``"mip"`` / ``"minip"``: maximum / minimum intensity projection (``Frame.value``);
            ``"dvr"``: direct volume rendering through ``tf``; any other name of the registry
            :data:`splinecast.render.modes.MODES` (``"aip"``: average intensity projection,
            :class:`~splinecast.Aip`). Or a mode object holding its options
            (:class:`~splinecast.Iso`, :class:`~splinecast.MultiIso`,
            :class:`~splinecast.Mip`, :class:`~splinecast.MinIp`, :class:`~splinecast.Dvr`,
            ...): its options are then not passed as keywords too.
        iso : float or list of float, optional
            Isovalue in data units; default :func:`~splinecast.auto_iso` (the volume's
            ``metadata["default_iso"]``, else Otsu's threshold of the histogram). A list
            renders every crossing of every isovalue, composited front to back with ``colors``
            and ``opacity``.
        method : str
            ``"exact"`` (analytic first root per cell, the default) or ``"sampled"`` (fixed step
            plus bisection, the reference common viewers use). For MIP: analytic extrema per
            cell, samples every ``step`` voxels, or ``"slices"``: samples where the ray crosses
            every ``step``-th plane of voxels across its dominant axis (the fastest; see
            :class:`splinecast.render.mip.Mip`).
        step : float
            Sampling step of the sampled method, in voxels (index units).
        shading : Shading, optional
            Colours and lighting.
        inside : str, optional
            ``"high"`` or ``"low"``: which side of the isovalue is the object's inside (decides
            front and back faces and the normals' orientation). Default
            :func:`~splinecast.auto_inside`: ``volume.metadata["inside"]``, else ``"low"`` for
            isovalues below the background value (a negative isovalue of a signed map), else
            ``"high"``.
        clip : list of (nx, ny, nz, d), optional
            Clip planes in world coordinates, each keeping ``nx*x + ny*y + nz*z + d >= 0``;
            applied analytically to every ray (all modes, all models).
        crop : (x0, x1, y0, y1, z0, z1), optional
            Axis-aligned world-space box to keep.
        colors, opacity : optional
            One RGB and one opacity per isovalue when ``iso`` is a list.
        effects : SurfaceEffects, optional
            Procedural texture and cel shading of isosurfaces.
        window, colormap : optional
            The projections' display (the modes that read them: MIP, minIP, AIP): value window
            ``(lo, hi)`` (default: the mode's ``default_window``, for MIP
            :func:`~splinecast.auto_window`: percentiles of the volume's axis-aligned
            projections, symmetric about 0 for signed data) and colormap (a name of
            :mod:`splinecast.transfer`: any matplotlib or cmap name; default
            :func:`~splinecast.auto_colormap`: ``"gray"``, a diverging map for signed data).
            Pixels whose projected value is the background value
            (:func:`~splinecast.background_value`) show the background colour.
        tolerance : float
            MIP/minIP with the exact method: how far a pixel may fall short of the exact
            projection (below it for MIP, above for minIP), as a fraction of the window's
            width (``1 / 255``: one level of an 8-bit image), for faster frames. Every pixel
            keeps that bound and a value its ray meets; 0 (the default) is exact. See
            :class:`splinecast.render.mip.Mip`.
        tf : TransferFunction, optional
            Transfer function of ``mode="dvr"`` (default
            :func:`~splinecast.auto_transfer_function`, a ramp from the histogram).
        dvr : DVRSettings, optional
            Step, pre-integration, adaptive step, early termination, shading of ``mode="dvr"``
            (default :data:`splinecast.render.dvr.DEFAULT_SETTINGS`: a sample every voxel from
            the ray's entry, pre-integrated segments between them, rays stopped at opacity
            1 - 2^-10).
        outputs : list of str, optional
            The Frame's buffers to fill, from ``"rgba"``, ``"depth"``, ``"position"``,
            ``"normal"``, ``"face"``, ``"value"`` (the projections) and ``"stats"`` (the per-ray
            counters); default all. The others are ``None`` in the Frame and cost nothing:
            ``outputs=("rgba",)`` is what an image viewer needs, ``("rgba", "depth")`` what
            compositing with other geometry needs. Summary numbers (``Frame.stats``) that
            need a buffer that was not requested (``hits``: depth; ``mean_cells_visited``:
            stats) are left out.
        normals : str
            Isosurfaces: ``"smooth"`` (default) shades every hit with the gradient of a smooth
            field at the exact hit: the models that are only continuous (``trilinear``,
            ``bspline1``), whose gradient jumps from cell to cell, with the cubic B-spline of
            the voxels, the others with their own gradient. ``"exact"`` shades with the
            model's own gradient (and ``Frame.normal`` holds it). Hits are the model's either
            way (:mod:`splinecast.render.shading`).
        samples : int, optional
            Antialiasing: rays per pixel on the edges of the image (silhouettes, creases,
            where front and back faces meet), the centre one included; the other pixels keep
            their one ray (:mod:`splinecast.render.antialias`). ``1`` turns it off. Default:
            :data:`~splinecast.render.antialias.DEFAULT_SAMPLES` for isosurfaces, 1 for MIP,
            minIP and DVR. Only the colours are averaged: depth, position, normal and face
            are the centre ray's. ``Frame.stats["antialiased"]`` counts the pixels traced
            again.

        Returns
        -------
        Frame

        Examples
        --------
        >>> import splinecast as sc
        >>> vol = sc.demo("sphere", size=32)
        >>> cam = sc.Camera.orbit(vol, size=(64, 48))
        >>> frame = sc.Scene(vol).render(cam, iso=0.0, outputs=("rgba", "depth"))
        >>> frame.rgba.shape, frame.position is None
        ((48, 64, 4), True)
        """
        request = prepare_render(
            self.volume, camera, mode, iso, method, step, shading, inside, clip=clip,
            crop=crop, colors=colors, opacity=opacity, effects=effects, window=window,
            colormap=colormap, tf=tf, dvr=dvr, table_cache=self._table_cache,
            check_iso=self._check_iso, model=self.model.name, outputs=outputs,
            tolerance=tolerance, normals=normals, samples=samples)
        return self.draw(request, camera)

    def draw(self, request: RenderRequest, camera: Camera) -> Frame:
        """Trace a validated request (:func:`prepare_render`) through this scene's grid.

        :meth:`render` is :func:`prepare_render` then this; a scene of another kind that holds
        this one (a multiscale scene drawing its finest level from memory) prepares the request
        with its own automatic choices and draws it here.
        """
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
        return finish_frame(request, out, counters, camera, start,
                            _pixel_tracer(grid, camera, planes, flags, tiles))


@dataclass
class RenderRequest:
    """A validated :meth:`Scene.render` call: the mode's host object and what the frame reports.

    Attributes
    ----------
    setup : Iso, MultiIso, Mip or Dvr
        The mode (:mod:`splinecast.render`), with its parameters and buffers.
    planes : ndarray (m, 4)
        Clip planes of ``clip`` and ``crop``.
    stats : dict
        The frame's statistics so far (mode, model, method, isovalue, ...).
    iso : float or None
        The isovalue of a single isosurface (``mode="iso"`` with one value), else ``None``.
    shading : Shading
    effects : SurfaceEffects or None
    outputs : frozenset of str
        The buffers the Frame keeps (:mod:`splinecast.render.outputs`); the mode may fill more
        (surface effects need position, normal and face, antialiasing depth).
    samples : int
        Rays per edge pixel (:mod:`splinecast.render.antialias`; 1: none).
    """

    setup: Any
    planes: np.ndarray
    stats: dict[str, Any]
    iso: float | None
    shading: Shading
    effects: SurfaceEffects | None
    outputs: frozenset[str] = frozenset(OUTPUTS)
    samples: int = 1


def prepare_render(
    volume: Any, camera: Camera, mode: str | RenderMode, iso: Any, method: str, step: float,
    shading: Shading | None, inside: str | None, *, clip: Any, crop: Any, colors: Any,
    opacity: Any, effects: SurfaceEffects | None, window: Any, colormap: Any,
    tf: TransferFunction | None, dvr: DVRSettings | None, table_cache: dict,
    check_iso: Any, model: str, outputs: Any = None, tolerance: float = 0.0,
    normals: str = "smooth", samples: Any = None,
) -> RenderRequest:
    """Validate the arguments of :meth:`Scene.render` and build the mode (shared by every scene
    type: in memory, multiresolution).

    ``volume`` supplies the automatic choices (:mod:`splinecast.render.defaults`), the metadata
    and the value range; ``check_iso(value)`` validates an isovalue (``None``: the automatic one).
    ``outputs`` names the Frame's buffers (``None``: all); ``tolerance`` is MIP's
    (:class:`~splinecast.render.mip.Mip`); ``normals`` the isosurfaces'
    (:mod:`splinecast.render.shading`); ``samples`` the antialiasing's (``None``: the mode's
    default, :func:`splinecast.render.antialias.resolve_samples`).
    """
    if not isinstance(camera, Camera):
        raise ParameterError(f"camera must be a splinecast.Camera, got {type(camera).__name__}")
    spec = build_mode(mode, {
        "iso": iso, "method": method, "step": step, "inside": inside, "colors": colors,
        "opacity": opacity, "window": window, "colormap": colormap, "tolerance": tolerance,
        "tf": tf, "dvr": dvr})
    limits.check_render(volume, camera)
    spec.check_limits(volume)
    normals_code(normals)  # checked for every mode: a typo is refused, not ignored
    samples = resolve_samples(samples, spec.name)
    if inside is not None and inside not in ("high", "low"):
        raise ParameterError(f"inside must be 'high' or 'low', got {inside!r}")
    shading = shading or Shading()
    if effects is not None and not isinstance(effects, SurfaceEffects):
        raise ParameterError(f"effects must be a SurfaceEffects, got {type(effects).__name__}")
    planes = make_planes(clip, crop)
    wanted = check_outputs(outputs)
    # Surface effects are applied on the host from the hit's position, normal and face.
    filled = wanted | {"position", "normal", "face"} if (
        effects is not None and effects.active) else wanted
    if "rgba" not in wanted:
        samples = 1  # nothing to antialias
    elif samples > 1 and spec.name == "iso":
        filled = filled | {"depth", "normal", "face"}  # the edges of the geometry
    stats: dict[str, Any] = {"mode": spec.name, "model": model}
    context = ModeContext(volume, check_iso, shading, effects, filled, table_cache,
                          normals=normals, planes=len(planes))
    setup, mode_stats, value = spec.setup(context)
    stats.update(mode_stats)
    return RenderRequest(setup, planes, stats, value, shading, effects, wanted, samples)


def finish_frame(request: RenderRequest, out: tuple, counters: tuple, camera: Camera,
                 start: float, trace: Callable[..., tuple] | None = None) -> Frame:
    """The :class:`Frame` of a traced image: surface effects applied, antialiased (with
    ``trace``), per-ray counts and the time since ``start`` (``time.perf_counter()``) in
    ``stats``.

    ``trace(camera, mask, mode)`` traces the pixels of ``camera``'s image where ``mask`` is
    true with ``mode`` (a copy of the request's with fewer outputs) and returns its outputs
    (:func:`splinecast.render.segment.trace_pixels`); without it the frame is not antialiased.
    """
    setup, stats, effects = request.setup, request.stats, request.effects
    frame = setup.frame(out, counters, stats)
    shaded = setup.effects_after_tracing and effects is not None and effects.active
    if shaded:
        apply_effects(camera.pixel_basis(), request.shading.as_array(), effects.as_array(),
                      frame.position, frame.normal, frame.face, frame.rgba)
    if trace is not None and request.samples > 1 and frame.rgba is not None:
        stats["samples"] = request.samples
        stats["antialiased"] = antialias(frame, camera, request.samples,
                                         _sample_tracer(request, trace, shaded),
                                         geometry=setup.name == "iso")
    trace_ms = (time.perf_counter() - start) * 1e3
    stats.update({
        "width": camera.width,
        "height": camera.height,
        "rays": camera.width * camera.height,
        "trace_ms": trace_ms,
    })
    wanted = request.outputs
    if frame.depth is not None:
        stats["hits"] = int(np.count_nonzero(np.isfinite(frame.depth)))
    if "stats" in wanted:
        visited, tested, skipped = counters
        stats.update({
            "mean_cells_visited": float(visited.mean()),
            "mean_cells_tested": float(tested.mean()),
            "mean_blocks_skipped": float(skipped.mean()),
        })
    else:
        frame.cells_visited = frame.cells_tested = frame.blocks_skipped = None
    # Buffers filled for the mode's own use (surface effects, antialiasing) but not requested.
    for name in ("depth", "position", "normal", "face"):
        if name not in wanted:
            setattr(frame, name, None)
    return frame


def _sample_tracer(request: RenderRequest, trace: Callable[..., tuple],
                   shaded: bool) -> Callable[[Camera, np.ndarray], Frame]:
    """``trace`` as :func:`splinecast.render.antialias.antialias` calls it: a Frame of the
    traced pixels (surface effects applied), from a copy of the request's mode that fills only
    what antialiasing reads."""
    sub = copy.copy(request.setup)
    need = {"rgba", "depth", "normal", "face"} | ({"position"} if shaded else set())
    sub.outputs = frozenset(need)
    effects = request.effects

    def samples(cam: Camera, mask: np.ndarray) -> Frame:
        unused = np.empty(mask.shape, np.int32)  # per-ray counters: not gathered
        frame = sub.frame(trace(cam, mask, sub), (unused, unused, unused), {})
        if shaded:
            apply_effects(cam.pixel_basis(), request.shading.as_array(), effects.as_array(),
                          frame.position, frame.normal, frame.face, frame.rgba)
        return frame

    return samples


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


def whole_frame_tracer(renderer: Any, pieces: Any, planes: np.ndarray) -> Callable[..., tuple]:
    """:func:`finish_frame`'s ``trace`` for a scene drawn by a cut renderer
    (:class:`splinecast.multires.draw.CutRenderer`) from ``pieces``: every pixel of the image
    traced, whatever the mask (the launch has no per-pixel mask)."""

    def trace(cam: Camera, mask: np.ndarray, mode: Any) -> tuple:
        return renderer.render(pieces, mode, cam, planes)[0]

    return trace
