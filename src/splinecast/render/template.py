"""The render template: preparing, tracing and finishing a frame, written once for every scene.

Every kind of scene (an in-memory :class:`~splinecast.Scene`, a pyramid's cut, a wavelet
selection, a Dask worker's bricks, and the scenes that composite other scenes' frames: labels,
channels) derives from :class:`SceneTemplate`, which owns the public ``render`` signature::

    render(camera, mode, iso, ..., **frame_options)
      -> RenderOptions       the keywords common to every scene kind, as given
      -> prepare            (prepare_render) options validated, the automatic choices made from
                             the kind's ``defaults_volume``, the mode's host object built
      -> trace              (the kind's ``trace``) the camera's rays through the grids the kind
                             holds, the mode's state carried from grid to grid -> :class:`Traced`
      -> finish             (finish_frame) the host's buffers -> a Frame: colours, surface
                             effects, antialiasing, statistics

A scene kind supplies only the parts of the middle step (the :class:`SceneTemplate` protocol: a
``trace`` method, the volume its defaults come from, how it checks an isovalue, its own frame
options); a kind whose frames are made elsewhere (sort-first Dask: tiles made by the workers'
scenes with their own ``render_frame``; sort-last: finished on a Dask worker with the same
:func:`finish_frame`) or composited from other scenes' frames overrides
:meth:`SceneTemplate.render_frame` instead. Every kind has :meth:`SceneTemplate.close` (and
``with``): callers close any scene without asking which kind it is.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import inspect
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, ClassVar, Self

import numpy as np

from ..camera import Camera
from ..errors import ParameterError, limits
from ..transfer import TransferFunction
from .antialias import antialias, resolve_samples
from .clipping import make_planes
from .defaults import auto_iso
from .dvr import DVRSettings
from .effects import SurfaceEffects, apply_effects
from .frame import Frame
from .modes import ModeContext, RenderMode, build_mode, mode_name
from .outputs import OUTPUTS, check_outputs
from .shading import Shading, normals_code

__all__ = ["SceneTemplate", "RenderOptions", "RenderRequest", "Traced", "check_iso",
           "prepare_render", "finish_frame", "whole_frame_tracer"]


def check_iso(volume: Any, iso: Any) -> float:
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


@dataclass(frozen=True)
class RenderOptions:
    """The keywords of :meth:`SceneTemplate.render` that every scene kind takes, as given.

    The fields and their defaults are the render signature's (see :meth:`SceneTemplate.render`
    for their meaning); ``mode`` is already the scene kind's default when none was given.
    """

    mode: Any = "iso"
    iso: Any = None
    method: str = "exact"
    step: float = 0.25
    shading: Shading | None = None
    inside: str | None = None
    clip: Any = None
    crop: Any = None
    colors: Any = None
    opacity: Any = None
    effects: SurfaceEffects | None = None
    window: Any = None
    colormap: Any = None
    tolerance: float = 0.0
    tf: TransferFunction | None = None
    dvr: DVRSettings | None = None
    outputs: Any = None
    normals: str = "smooth"
    samples: int | None = None

    def as_dict(self) -> dict[str, Any]:
        """The options by name (the values themselves, not copies: a :class:`Shading` stays
        one), as keywords of ``render``."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}

    def given(self) -> dict[str, Any]:
        """The options whose value is not the signature's default (``mode`` left out)."""
        out = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name != "mode" and not (value is f.default or _equal(value, f.default)):
                out[f.name] = value
        return out


def _equal(a: Any, b: Any) -> bool:
    try:
        return bool(a == b)
    except (TypeError, ValueError):  # arrays and other values without one truth value
        return False


@dataclass
class Traced:
    """What a scene kind's :meth:`SceneTemplate.trace` hands to :func:`finish_frame`.

    Attributes
    ----------
    out : tuple
        The mode host's output buffers of the image (:meth:`frame` of the host reads them).
    counters : tuple of ndarray
        Per-ray cells visited, cells tested, blocks skipped.
    start : float
        ``time.perf_counter()`` when tracing started (``stats["trace_ms"]`` counts from it).
    trace : callable, optional
        ``trace(camera, mask, mode)``: the pixels of ``mask`` traced again with ``mode``, for
        antialiasing (None: the frame is not antialiased).
    """

    out: tuple
    counters: tuple
    start: float
    trace: Callable[..., tuple] | None = None


class SceneTemplate:
    """Base class of every scene kind: ``render`` written once (see the module's description).

    A scene kind supplies the parts of a frame it alone knows:

    ``trace(request, camera, **frame_options) -> Traced``
        The camera's rays through the grids the kind holds, in the mode of ``request`` (a
        :class:`RenderRequest`); may add to ``request.stats``.
    ``defaults_volume``
        The volume (or header) the automatic isovalue, window and transfer function come from,
        and whose size the limits check (a pyramid's coarsest level in memory).
    ``check_iso(iso)``
        An isovalue checked (``None``: the automatic one); default :func:`check_iso` of
        ``defaults_volume``.
    ``model``
        The reconstruction model (``stats["model"]`` reports its name).
    ``close()``
        What the kind releases when closed (a loader thread); default nothing.
    :attr:`frame_options`, :attr:`default_mode`, :attr:`default_samples`
        The kind's own keywords of a frame with their defaults (by default ``trace``'s
        keyword-only parameters), the mode of ``render(camera)`` and the antialiasing samples
        when ``samples`` is not given.

    What the front ends (the command line, the viewer) ask of any scene, answered here with
    the defaults of a kind holding its data in memory, so they never test which kind they hold:

    :attr:`modes`
        The modes the kind renders (None: every mode of the registry); ``render`` refuses
        another one (:meth:`check_mode`).
    :attr:`model_name`
        The name of the reconstruction model.
    :attr:`tile_shape`
        The grid of pixel tiles the kind traces as units (a window of the image on it renders
        the whole image's pixels).
    :meth:`bricks_loaded`
        How many bricks the kind has read from storage (None: it reads none).

    Each subclass gets a ``render`` whose signature (``inspect.signature``, ``help``) shows its
    default mode and its own frame options; the code behind it is this class's.
    """

    #: The mode of ``render(camera)`` without one.
    default_mode: ClassVar[str] = "iso"
    #: The kind's own keywords of ``render`` (per frame) and their defaults.
    frame_options: ClassVar[Mapping[str, Any]] = MappingProxyType({})
    #: Antialiasing samples when ``samples`` is not given (None: the mode's default; scenes
    #: that trace every further sample over the whole image default to 1).
    default_samples: ClassVar[int | None] = None
    #: Whether ``render`` passes other keywords on (a scene of scenes, whose parts take them).
    passes_options: ClassVar[bool] = False
    #: The names of the modes the kind renders, :attr:`default_mode` among them (None: every
    #: mode of the registry :data:`~splinecast.render.modes.MODES`); the command line and the
    #: viewer offer these, and ``render`` refuses any other (:meth:`check_mode`).
    modes: ClassVar[tuple[str, ...] | None] = None
    #: What the kind renders, in words: the start of the message refusing a mode not in
    #: :attr:`modes` (None: "<class name> renders its own modes").
    modes_reason: ClassVar[str | None] = None

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if "frame_options" not in cls.__dict__ and "trace" in cls.__dict__:
            # A kind's frame options are its trace's keyword-only parameters: written once.
            cls.frame_options = MappingProxyType({
                p.name: p.default for p in inspect.signature(cls.trace).parameters.values()
                if p.kind is inspect.Parameter.KEYWORD_ONLY})
        if "render" not in cls.__dict__:
            cls.render = _render_of(cls)  # type: ignore[method-assign]

    # ------------------------------------------------------------------- the parts (defaults)
    @property
    def defaults_volume(self) -> Any:
        """The volume the automatic choices come from (default: ``self.volume``)."""
        return self.volume  # type: ignore[attr-defined]

    def check_iso(self, iso: Any) -> float:
        """An isovalue checked against the data range (``None``: the automatic one)."""
        return check_iso(self.defaults_volume, iso)

    def check_mode(self, mode: Any) -> Any:
        """``mode`` (a name or a mode object), refused unless the kind renders it.

        Raises
        ------
        ParameterError
            The kind declares :attr:`modes` and ``mode`` is not one of them.
        """
        allowed = self.modes
        if allowed is not None and mode_name(mode) not in allowed:
            reason = self.modes_reason or f"{type(self).__name__} renders its own modes"
            raise ParameterError(f"{reason} (mode {' or '.join(map(repr, allowed))}), "
                                 f"not mode {mode_name(mode)!r}")
        return mode

    @property
    def model_name(self) -> str:
        """The name of the reconstruction model (:data:`splinecast.models.MODELS`' key; default
        the name of ``self.model``)."""
        return self.model.name  # type: ignore[attr-defined]

    @property
    def tile_shape(self) -> tuple[int, int]:
        """Columns and rows of the tiles the kind traces as units, on the image's own grid: a
        window of the image (:meth:`Camera.tile`) whose first column and row are multiples of
        these renders exactly the whole image's pixels. Columns 0: a tile spans whole rows.
        Default ``(0, 1)``: every ray is its own (a kind that shares work between the rays of a
        tile says so, :attr:`splinecast.Scene.tile_shape`)."""
        return (0, 1)

    def bricks_loaded(self) -> int | None:
        """How many bricks the scene has read from storage so far (a pyramid's scene reads them
        as frames need them), safe to ask from any thread; None (the default) for a kind that
        reads none while it renders."""
        return None

    @property
    def table_cache(self) -> dict:
        """The last pre-integration table (``mode="dvr"``), kept between frames."""
        cache = self.__dict__.get("_table_cache")
        if cache is None:
            cache = self.__dict__["_table_cache"] = {}
        return cache

    def trace(self, request: RenderRequest, camera: Camera, **frame_options: Any) -> Traced:
        """Trace ``camera``'s rays in the mode of ``request`` through the kind's grids."""
        raise NotImplementedError(f"{type(self).__name__} does not trace frames itself")

    # ------------------------------------------------------------------ lifetime
    def close(self) -> None:
        """Release what the scene holds (a pyramid's loader thread, the workers' memory of a
        Dask scene); by default nothing. Every kind has it, so a caller closes any scene, or
        uses it in ``with``, without asking which kind it holds."""

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ the template
    def render(
        self,
        camera: Camera,
        mode: str | RenderMode | None = None,
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
        **frame_options: Any,
    ) -> Frame:
        """Render one image.

        Parameters
        ----------
        camera : Camera
            Viewpoint and image size.
        mode : str or mode object, optional
            Default: the scene kind's :attr:`default_mode` (``"iso"``; ``"mip"`` for a
            :class:`~splinecast.ChannelScene`). ``"iso"``: first-hit isosurface (or several
            translucent ones, see ``iso``);
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
        **frame_options
            The scene kind's own options of a frame (its :attr:`frame_options`, described with
            its class: a multiscale scene's ``lod``, ``wait``, ``complete``, ...). A name the
            kind does not take raises ``TypeError``, as an unknown keyword does.

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
        # The mode is checked here, before the kind's own step: every kind refuses a mode it
        # does not declare, whatever frame it makes.
        options = RenderOptions(
            self.check_mode(self.default_mode if mode is None else mode), iso, method, step,
            shading, inside, clip, crop, colors, opacity, effects, window, colormap, tolerance,
            tf, dvr, outputs, normals, samples)
        return self.render_frame(camera, options, self.check_frame_options(frame_options))

    def check_frame_options(self, given: Mapping[str, Any]) -> dict[str, Any]:
        """The kind's frame options: ``given`` over :attr:`frame_options`' defaults.

        Raises
        ------
        TypeError
            A name the kind does not take (as Python raises it for an unknown keyword).
        """
        for name in given:
            if name not in self.frame_options:
                raise TypeError(f"{type(self).__name__}.render() got an unexpected keyword "
                                f"argument {name!r}")
        return {**self.frame_options, **given}

    def render_frame(self, camera: Camera, options: RenderOptions,
                     frame_options: Mapping[str, Any]) -> Frame:
        """Prepare, trace and finish one frame (what :meth:`render` does after gathering its
        arguments); kinds whose frames are made elsewhere or composited override it."""
        return self.draw(self.prepare(camera, options), camera, **frame_options)

    def prepare(self, camera: Camera, options: RenderOptions) -> RenderRequest:
        """:func:`prepare_render` of ``options`` with this scene's automatic choices."""
        samples = options.samples
        if samples is None:
            samples = self.default_samples
        model = self.model  # type: ignore[attr-defined]
        return prepare_render(
            self.defaults_volume, camera, options.mode, options.iso, options.method,
            options.step, options.shading, options.inside, clip=options.clip, crop=options.crop,
            colors=options.colors, opacity=options.opacity, effects=options.effects,
            window=options.window, colormap=options.colormap, tf=options.tf, dvr=options.dvr,
            table_cache=self.table_cache, check_iso=self.check_iso, model=model.name,
            outputs=options.outputs, tolerance=options.tolerance, normals=options.normals,
            samples=samples)

    def draw(self, request: RenderRequest, camera: Camera, **frame_options: Any) -> Frame:
        """Trace a validated request (:meth:`prepare`) and finish its frame.

        A scene of another kind that holds this one (a multiscale scene drawing its finest level
        from memory) prepares the request with its own automatic choices and draws it here.
        """
        traced = self.trace(request, camera, **frame_options)
        return finish_frame(request, traced.out, traced.counters, camera, traced.start,
                            traced.trace)


def _render_of(cls: type[SceneTemplate]) -> Callable[..., Frame]:
    """:meth:`SceneTemplate.render` for ``cls``, with a signature that shows the kind's default
    mode and its own frame options (the code is the template's)."""
    template = SceneTemplate.render

    @functools.wraps(template)
    def render(self: Any, camera: Camera, *args: Any, **kwargs: Any) -> Frame:
        return template(self, camera, *args, **kwargs)

    render.__qualname__ = f"{cls.__qualname__}.render"
    # The signature below is the one to show; without this, tools that read the source of the
    # wrapped function (Sphinx's preserved defaults) pair the template's defaults with it.
    del render.__wrapped__
    signature = inspect.signature(template)
    params = []
    for p in signature.parameters.values():
        if p.kind is inspect.Parameter.VAR_KEYWORD:
            continue
        params.append(p.replace(default=cls.default_mode) if p.name == "mode" else p)
    params += [inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=default)
               for name, default in cls.frame_options.items()]
    if cls.passes_options:
        params.append(inspect.Parameter("options", inspect.Parameter.VAR_KEYWORD))
    render.__signature__ = signature.replace(parameters=params)  # type: ignore[attr-defined]
    return render


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
    surfaces : bool
        Whether the mode draws surfaces (:attr:`RenderMode.surfaces`): antialiasing finds
        their edges from the geometry too.
    """

    setup: Any
    planes: np.ndarray
    stats: dict[str, Any]
    iso: float | None
    shading: Shading
    effects: SurfaceEffects | None
    outputs: frozenset[str] = frozenset(OUTPUTS)
    samples: int = 1
    surfaces: bool = False


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
    samples = resolve_samples(samples, spec)
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
    elif samples > 1 and spec.surfaces:
        filled = filled | {"depth", "normal", "face"}  # the edges of the geometry
    stats: dict[str, Any] = {"mode": spec.name, "model": model}
    context = ModeContext(volume, check_iso, shading, effects, filled, table_cache,
                          normals=normals, planes=len(planes))
    setup, mode_stats, value = spec.setup(context)
    stats.update(mode_stats)
    return RenderRequest(setup, planes, stats, value, shading, effects, wanted, samples,
                         spec.surfaces)


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
                                         geometry=request.surfaces)
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


def whole_frame_tracer(renderer: Any, drawables: Any, planes: np.ndarray) -> Callable[..., tuple]:
    """:func:`finish_frame`'s ``trace`` for a scene drawn by a cut renderer
    (:class:`splinecast.multires.draw.cut_renderer.CutRenderer`) from ``drawables``: every pixel of
    the image
    traced, whatever the mask (the launch has no per-pixel mask)."""

    def trace(cam: Camera, mask: np.ndarray, mode: Any) -> tuple:
        return renderer.render(drawables, mode, cam, planes)[0]

    return trace
