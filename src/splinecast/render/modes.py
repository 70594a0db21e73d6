"""The render modes as objects, and the one registry of them that every front end reads.

A mode object holds the options of one mode (``Iso(0.5)``, ``Mip(window=(0, 1))``,
``Dvr(tf)``), checked when it is made, and knows how to become the compiled kernels' host object
for a volume (:meth:`RenderMode.setup`: the automatic window, isovalue or transfer function
filled in). :meth:`splinecast.Scene.render` takes a mode object or a mode's name with its options
as keywords (``render(cam, "mip", window=(0, 1))``); either way the name's class in
:data:`MODES` builds the object, so the command line, the viewer and the checks of a render ask
this registry which modes exist and which options each one reads, instead of keeping lists of
their own.

The kernel side of a mode (its parameter tuple and compiled hooks) lives in its own module,
:mod:`.iso`, :mod:`.multi_iso`, :mod:`.mip`, :mod:`.dvr` (see :mod:`.mode_api`); the classes here
are what a user writes.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ..errors import ParameterError, limits
from ..transfer import TransferFunction
from .compose import ADDITIVE, NEAREST_HIT, Compositing
from .defaults import (
    auto_colormap,
    auto_inside,
    auto_transfer_function,
    auto_window,
    background_value,
)
from .dvr import Dvr as DvrKernel
from .dvr import DVRSettings
from .effects import SurfaceEffects
from .iso import METHODS
from .iso import Iso as IsoKernel
from .mip import Mip as MipKernel
from .multi_iso import MultiIso as MultiIsoKernel
from .shading import Shading

__all__ = ["RenderMode", "ModeContext", "Iso", "MultiIso", "Mip", "MinIp", "Dvr", "MODES",
           "MODE_NAMES", "RENDER_DEFAULTS", "build_mode", "modes_reading", "modes_with_method",
           "register_mode", "all_methods", "mode_name", "mode_class", "with_option",
           "option_value", "modes_by_compositing"]

#: :meth:`splinecast.Scene.render`'s defaults of the keywords a mode reads: a keyword left at
#: its default does not clash with a mode object that sets it.
RENDER_DEFAULTS: dict[str, Any] = {
    "iso": None, "method": "exact", "step": 0.25, "inside": None, "colors": None,
    "opacity": None, "window": None, "colormap": None, "tolerance": 0.0, "tf": None,
    "dvr": None,
}


@dataclass
class ModeContext:
    """What a mode needs of the scene and the frame to build its kernels' host object.

    Attributes
    ----------
    volume : Volume, MultiscaleVolume or VolumeInfo
        Supplies the automatic choices (:mod:`.defaults`), the metadata and the value range.
    check_iso : callable
        ``check_iso(value)`` validates an isovalue (``None``: the automatic one).
    shading : Shading
    effects : SurfaceEffects or None
    outputs : frozenset of str
        The buffers the kernels fill.
    table_cache : dict
        The scene's cache of pre-integration tables.
    normals : str
        The isosurfaces' normals (:mod:`.shading`).
    planes : int
        How many clip planes the frame has (reported by the isosurface).
    """

    volume: Any
    check_iso: Callable[[Any], float]
    shading: Shading
    effects: SurfaceEffects | None
    outputs: frozenset[str]
    table_cache: dict
    normals: str = "smooth"
    planes: int = 0


class RenderMode:
    """Base of the mode objects: what every layer above the kernels asks a mode.

    A subclass is a frozen dataclass of its options, registered by name in :data:`MODES`.
    """

    #: The name :meth:`splinecast.Scene.render` takes (``mode="iso"``).
    name: ClassVar[str] = ""
    #: The values of ``method`` the mode accepts (the first is the default).
    methods: ClassVar[tuple[str, ...]] = ("exact",)
    #: The keywords of :meth:`splinecast.Scene.render` the mode reads; the others are the
    #: frame's (camera, clipping, outputs, ...) or another mode's.
    keywords: ClassVar[tuple[str, ...]] = ()
    #: What the mode shows, in a few words (the command line's and the viewer's menus).
    summary: ClassVar[str] = ""
    #: How the frames it renders per channel (each alone, in the channel's colour) combine into
    #: a multichannel image (:class:`~splinecast.render.compose.Compositing`): by default
    #: :data:`~splinecast.render.compose.ADDITIVE`, napari's additive blending, whatever the
    #: channels' order; surfaces declare :data:`~splinecast.render.compose.NEAREST_HIT`.
    compositing: ClassVar[Compositing] = ADDITIVE
    #: What a projection keeps of the values along each ray, in a word (``"maximum"``,
    #: ``"minimum"``, ``"mean"``), None for a mode that is not a projection of the values. The
    #: command line names it when every ray kept the background value (nothing drawn).
    projection: ClassVar[str | None] = None
    #: Whether the mode draws surfaces (first hits with a depth, a normal and a face): a frame
    #: is then antialiased by default (:func:`~splinecast.render.antialias.resolve_samples`),
    #: its edges found from the geometry as well as the colours; other modes take one ray per
    #: pixel unless ``samples`` is given.
    surfaces: ClassVar[bool] = False

    @classmethod
    def default_window(cls, volume: Any) -> tuple[float, float] | None:
        """The value window shown when a mode that reads ``window`` is given none (the command
        line prints it, the viewer puts it on its slider); None for a mode without one.

        ``volume`` is a :class:`~splinecast.Volume`, a pyramid's preview or a distributed
        scene's :class:`~splinecast.distributed.source.VolumeInfo`, whose metadata carries
        ``default_window_<name>`` for every such mode (the workers' data is not at hand)."""
        return None

    @classmethod
    def from_options(cls, **options: Any) -> RenderMode:
        """The mode built from :meth:`splinecast.Scene.render` keywords (any of
        :attr:`keywords`; the others are not passed)."""
        names = {f.name for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
        return cls(**{k: v for k, v in options.items() if k in names})

    def options(self) -> dict[str, Any]:
        """The mode's options as :meth:`splinecast.Scene.render` keywords."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}  # type: ignore

    def check_limits(self, volume: Any) -> None:
        """Refuse options the volume's size makes impossible (a sampling step out of the
        bounds of :func:`splinecast.errors.limits.check_step`); by default none."""

    def setup(self, context: ModeContext) -> tuple[Any, dict[str, Any], float | None]:
        """The kernels' host object of the mode for a frame.

        Returns
        -------
        (setup, stats, iso)
            The host object (:mod:`.iso`, :mod:`.multi_iso`, :mod:`.mip`, :mod:`.dvr`), what
            the frame's statistics report of the mode, and the single isovalue of a first-hit
            isosurface (None for the other modes).
        """
        raise NotImplementedError


def _check_method(mode: type[RenderMode], method: str) -> None:
    if method in mode.methods:
        return
    others = modes_with_method(method)
    if others:
        extra = f"; {method} is for {' and '.join(others)}, not {mode.name}"
    else:
        wider = [m for m in dict.fromkeys(m for cls in MODES.values() for m in cls.methods)
                 if m not in METHODS]
        extra = "".join(f", or {m} for {' and '.join(modes_with_method(m))}" for m in wider)
    raise ParameterError(f"method must be one of {', '.join(METHODS)}{extra}, got {method!r}")


def _check_inside(inside: Any) -> None:
    if inside is not None and inside not in ("high", "low"):
        raise ParameterError(f"inside must be 'high' or 'low', got {inside!r}")


@dataclass(frozen=True)
class Iso(RenderMode):
    """The first-hit isosurface.

    Parameters
    ----------
    iso : float, optional
        Isovalue in data units (default :func:`~splinecast.auto_iso`).
    method : {"exact", "sampled"}
        Analytic first root per cell, or fixed steps plus bisection.
    step : float
        Sampling step of ``method="sampled"``, in voxels.
    inside : {"high", "low"}, optional
        Which side of the isovalue is the inside (default :func:`~splinecast.auto_inside`).
    """

    name: ClassVar[str] = "iso"
    methods: ClassVar[tuple[str, ...]] = ("exact", "sampled")
    keywords: ClassVar[tuple[str, ...]] = ("iso", "method", "step", "inside", "colors",
                                           "opacity", "normals", "effects")
    summary: ClassVar[str] = "isosurface(s)"
    compositing: ClassVar[Compositing] = NEAREST_HIT
    surfaces: ClassVar[bool] = True

    iso: float | None = None
    method: str = "exact"
    step: float = 0.25
    inside: str | None = None

    def __post_init__(self) -> None:
        _check_method(type(self), self.method)
        _check_inside(self.inside)

    @classmethod
    def from_options(cls, **options: Any) -> RenderMode:
        """An :class:`Iso`, or a :class:`MultiIso` when ``iso`` is a list of values."""
        iso = options.get("iso")
        if isinstance(iso, (list, tuple, np.ndarray)):
            _check_method(cls, options.get("method", "exact"))
            return MultiIso(iso, options.get("colors"), options.get("opacity"),
                            options.get("inside"))
        return cls(iso, options.get("method", "exact"), options.get("step", 0.25),
                   options.get("inside"))

    def check_limits(self, volume: Any) -> None:
        """A sampled isosurface's step."""
        if self.method == "sampled":
            limits.check_step(self.step, "step", volume.shape)

    def setup(self, context: ModeContext) -> tuple[Any, dict[str, Any], float | None]:
        """The :class:`splinecast.render.iso.Iso` of the (checked) isovalue."""
        value = context.check_iso(self.iso)
        inside = self.inside or auto_inside(context.volume, value)
        kernel = IsoKernel(value, self.method, self.step, inside, context.shading,
                           outputs=context.outputs, normals=context.normals)
        stats: dict[str, Any] = {}
        if context.planes:
            stats["planes"] = context.planes
        stats.update(method=self.method, iso=value)
        if self.method == "sampled":
            stats["step"] = float(self.step)
        return kernel, stats, value


@dataclass(frozen=True)
class MultiIso(RenderMode):
    """Every crossing of several isosurfaces, composited front to back (``mode="iso"`` with a
    list of isovalues).

    Parameters
    ----------
    iso : sequence of float
        The isovalues in data units.
    colors, opacity : optional
        One RGB and one opacity per isovalue.
    inside : {"high", "low"}, optional
        Which side of the isovalues is the inside.
    """

    name: ClassVar[str] = "iso"
    methods: ClassVar[tuple[str, ...]] = Iso.methods
    keywords: ClassVar[tuple[str, ...]] = Iso.keywords
    compositing: ClassVar[Compositing] = NEAREST_HIT
    surfaces: ClassVar[bool] = True

    iso: Sequence[float] = ()
    colors: Any = None
    opacity: Any = None
    inside: str | None = None

    def __post_init__(self) -> None:
        if len(self.iso) == 0:
            raise ParameterError("iso must hold at least one isovalue")
        _check_inside(self.inside)

    def setup(self, context: ModeContext) -> tuple[Any, dict[str, Any], float | None]:
        """The :class:`splinecast.render.multi_iso.MultiIso` of the (checked) isovalues."""
        isos = [context.check_iso(v) for v in self.iso]
        inside = self.inside or auto_inside(context.volume, isos)
        kernel = MultiIsoKernel(isos, self.colors, self.opacity, inside, context.shading,
                                context.effects, outputs=context.outputs,
                                normals=context.normals)
        return kernel, {"method": "exact"}, None


@dataclass(frozen=True)
class Mip(RenderMode):
    """The maximum intensity projection (``Frame.value``), exact per piece or sampled.

    Parameters
    ----------
    window : (lo, hi), optional
        The value window shown (default :func:`~splinecast.auto_window`).
    colormap : str, optional
        The colormap (default :func:`~splinecast.auto_colormap`).
    method : {"exact", "sampled", "slices"}
        Analytic extrema per cell, samples every ``step`` voxels, or samples on every
        ``step``-th plane of voxels.
    step : float
        Sampling step of the sampled methods, in voxels.
    tolerance : float
        How far a pixel may fall short of the exact projection, as a fraction of the window.
    """

    name: ClassVar[str] = "mip"
    methods: ClassVar[tuple[str, ...]] = ("exact", "sampled", "slices")
    keywords: ClassVar[tuple[str, ...]] = ("window", "colormap", "method", "step", "tolerance")
    summary: ClassVar[str] = "maximum intensity projection"
    projection: ClassVar[str | None] = "maximum"

    window: Any = None
    colormap: Any = None
    method: str = "exact"
    step: float = 0.25
    tolerance: float = 0.0

    def __post_init__(self) -> None:
        _check_method(type(self), self.method)

    @classmethod
    def default_window(cls, volume: Any) -> tuple[float, float]:
        """:func:`~splinecast.auto_window` of the projection."""
        return auto_window(volume, cls.name)

    def check_limits(self, volume: Any) -> None:
        """The sampled methods' step."""
        if self.method != "exact":
            limits.check_step(self.step, "step", volume.shape)

    def setup(self, context: ModeContext) -> tuple[Any, dict[str, Any], float | None]:
        """The :class:`splinecast.render.mip.Mip` with the automatic window and colormap."""
        volume = context.volume
        window = auto_window(volume, self.name) if self.window is None else self.window
        colormap = auto_colormap(volume) if self.colormap is None else self.colormap
        kernel = MipKernel(self.name, self.method, self.step, window, colormap,
                           context.shading.background, volume.value_range,
                           outputs=context.outputs, tolerance=self.tolerance,
                           empty=background_value(volume))
        return kernel, {"method": self.method}, None


@dataclass(frozen=True)
class MinIp(Mip):
    """The minimum intensity projection; options as :class:`Mip`."""

    name: ClassVar[str] = "minip"
    summary: ClassVar[str] = "minimum intensity projection"
    projection: ClassVar[str | None] = "minimum"


@dataclass(frozen=True)
class Dvr(RenderMode):
    """Direct volume rendering: the emission-absorption integral through a transfer function.

    Parameters
    ----------
    tf : TransferFunction, optional
        Default :func:`~splinecast.auto_transfer_function`.
    dvr : DVRSettings, optional
        Step, pre-integration, adaptive step, early termination, shading
        (default :data:`splinecast.render.dvr.DEFAULT_SETTINGS`).
    """

    name: ClassVar[str] = "dvr"
    methods: ClassVar[tuple[str, ...]] = ("exact", "sampled")
    keywords: ClassVar[tuple[str, ...]] = ("tf", "dvr")
    summary: ClassVar[str] = "direct volume rendering"

    tf: TransferFunction | None = None
    dvr: DVRSettings | None = None

    @classmethod
    def from_options(cls, **options: Any) -> RenderMode:
        """A :class:`Dvr`; ``method`` is checked, though the integral has no other."""
        _check_method(cls, options.get("method", "exact"))
        return cls(options.get("tf"), options.get("dvr"))

    def check_limits(self, volume: Any) -> None:
        """The settings' step."""
        if self.dvr is not None and hasattr(self.dvr, "step"):
            limits.check_step(self.dvr.step, "DVRSettings.step", volume.shape)

    def setup(self, context: ModeContext) -> tuple[Any, dict[str, Any], float | None]:
        """The :class:`splinecast.render.dvr.Dvr` of the (automatic) transfer function."""
        tf = auto_transfer_function(context.volume) if self.tf is None else self.tf
        kernel = DvrKernel(tf, self.dvr, context.shading.background, context.table_cache,
                           outputs=context.outputs)
        return kernel, {}, None


#: Render modes by the name :meth:`splinecast.Scene.render` takes, the one list the command
#: line, the viewer and the checks read (a list of isovalues makes ``"iso"`` a
#: :class:`MultiIso`). A mode's module adds its class with :func:`register_mode`.
MODES: dict[str, type[RenderMode]] = {"iso": Iso, "mip": Mip, "minip": MinIp, "dvr": Dvr}


class _ModeNames(Sequence[str]):
    """The names of :data:`MODES`, in order, as they are when read: a mode registered after
    this module was imported (:func:`register_mode`) is among them, so a front end that took
    the list at import time still offers it."""

    def __getitem__(self, index: Any) -> Any:
        return tuple(MODES)[index]

    def __len__(self) -> int:
        return len(MODES)

    def __iter__(self) -> Iterator[str]:
        return iter(tuple(MODES))

    def __contains__(self, name: object) -> bool:
        return name in MODES

    def __eq__(self, other: object) -> bool:
        return tuple(MODES) == (tuple(other) if isinstance(other, Sequence) else other)

    def __hash__(self) -> int:
        return hash(tuple(MODES))

    def __repr__(self) -> str:
        return repr(tuple(MODES))


#: The names of :data:`MODES`, in order (a live view: modes registered later are included).
MODE_NAMES: Sequence[str] = _ModeNames()


def register_mode(mode: type[RenderMode]) -> type[RenderMode]:
    """Add a mode class to :data:`MODES` under its :attr:`~RenderMode.name` (usable as a class
    decorator); the command line, the viewer, pyramids and Dask then offer it.

    Raises
    ------
    TypeError
        Not a :class:`RenderMode` subclass with a name, or the name is taken by another class.
    """
    if not (isinstance(mode, type) and issubclass(mode, RenderMode) and mode.name):
        raise TypeError(f"a mode is a RenderMode subclass with a name, got {mode!r}")
    if MODES.get(mode.name, mode) is not mode:
        raise TypeError(f"mode name {mode.name!r} is taken by {MODES[mode.name].__name__}")
    MODES[mode.name] = mode
    return mode


def all_methods() -> tuple[str, ...]:
    """Every value of ``method`` some registered mode accepts, ``"exact"`` first."""
    return tuple(dict.fromkeys(m for cls in MODES.values() for m in cls.methods))


def modes_with_method(method: str) -> tuple[str, ...]:
    """Names of the modes that accept ``method``."""
    return tuple(name for name, cls in MODES.items() if method in cls.methods)


def modes_reading(keyword: str) -> tuple[str, ...]:
    """Names of the modes that read :meth:`splinecast.Scene.render`'s ``keyword``."""
    return tuple(name for name, cls in MODES.items() if keyword in cls.keywords)


def modes_by_compositing() -> dict[Compositing, tuple[str, ...]]:
    """The names of the registered modes by the rule that composites their channels
    (:attr:`RenderMode.compositing`), rules and names in the registry's order: what the
    command line's help says of several channels."""
    out: dict[Compositing, tuple[str, ...]] = {}
    for name, cls in MODES.items():
        out[cls.compositing] = (*out.get(cls.compositing, ()), name)
    return out


def _same(value: Any, default: Any) -> bool:
    return value is default or (isinstance(value, (str, int, float)) and value == default)


def build_mode(mode: str | RenderMode, given: dict[str, Any]) -> RenderMode:
    """The mode object of a render call: ``mode`` itself, or built from its name and the
    keywords ``given`` (the call's values of :data:`RENDER_DEFAULTS`' keys).

    Raises
    ------
    ParameterError
        An unknown mode name, a keyword another mode reads that cannot be ignored
        (``tolerance``), or a keyword that a mode object sets too.
    """
    if isinstance(mode, RenderMode):
        for key in mode.options():
            if key in given and not _same(given[key], RENDER_DEFAULTS[key]):
                raise ParameterError(f"{key} is an option of the mode object "
                                     f"{type(mode).__name__}: set it there, not as a keyword "
                                     "as well")
        cls: type[RenderMode] = type(mode)
        name = mode.name
    elif not isinstance(mode, str) or mode not in MODES:
        raise ParameterError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
    else:
        cls, name = MODES[mode], mode
        _check_method(cls, given.get("method", "exact"))
    tolerance = given.get("tolerance", 0.0)
    if "tolerance" not in cls.keywords and not _same(tolerance, 0.0):
        raise ParameterError("tolerance is for mode=" + " and ".join(
            repr(m) for m in modes_reading("tolerance")) + f", not {name!r}")
    if isinstance(mode, RenderMode):
        return mode
    return cls.from_options(**{k: v for k, v in given.items() if k in cls.keywords})


def mode_name(mode: Any) -> Any:
    """The registry name of ``mode``, given as a name or as a mode object (anything else is
    returned as it is, for the caller's check to name it): the layers above ask this instead of
    testing what ``mode`` is."""
    return mode.name if isinstance(mode, RenderMode) else mode


def mode_class(mode: Any) -> type[RenderMode]:
    """The class of ``mode``, given as a registry name or as a mode object (whose class need
    not be registered): what the layers above ask a mode's capabilities of
    (:attr:`RenderMode.keywords`, :attr:`RenderMode.compositing`, ...).

    Raises
    ------
    ParameterError
        Neither a mode object nor a name of :data:`MODES`.
    """
    if isinstance(mode, RenderMode):
        return type(mode)
    if isinstance(mode, str) and mode in MODES:
        return MODES[mode]
    raise ParameterError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")


def with_option(mode: Any, keywords: dict[str, Any], key: str,
                value: Any) -> tuple[Any, dict[str, Any]]:
    """``mode`` and the render keywords that go with it, with the option ``key`` set to
    ``value``: a mode object's field replaced (its options are not passed as keywords too),
    else the keyword set (a copy of ``keywords``)."""
    if isinstance(mode, RenderMode):
        return dataclasses.replace(mode, **{key: value}), keywords
    return mode, {**keywords, key: value}


def option_value(mode: Any, keywords: dict[str, Any], key: str) -> Any:
    """The value of the option ``key`` that a render of ``mode`` with the render keywords
    ``keywords`` uses: a mode object's field, else the keyword (None: not given)."""
    if isinstance(mode, RenderMode):
        return mode.options().get(key)
    return keywords.get(key)
