"""The viewer's render state: the JSON a page (or any other client) sends, validated into a
:class:`~splinecast.Camera` and the keyword arguments of :meth:`splinecast.Scene.render`.

Every field of a state is optional: an omitted field takes its value from
:func:`default_state` (which the server sends to the page in its ``hello`` message), so a client
may send ``{"mode": "mip"}`` and nothing else. Unknown fields are refused, so a misspelt field
never silently does nothing. JSON can carry any type where a number is expected, so this module
checks *types*; *ranges* are checked by the library's own constructors (:meth:`Camera.orbit`,
:func:`~splinecast.camera.parse_size`, :func:`~splinecast.check_iso`,
:class:`~splinecast.TransferFunction`, :class:`~splinecast.DVRSettings`,
:class:`~splinecast.Shading`, :func:`~splinecast.render.clipping.make_planes`) and by
:meth:`Scene.render` itself, so the viewer accepts exactly what the Python API accepts. Every
mistake raises :class:`~splinecast.errors.ParameterError` with a message naming the field.

The fields (see ``docs/viewer-protocol.md`` for the full table)::

    model, mode                    names from splinecast.MODELS and splinecast.scene.MODES
    camera {azimuth, elevation, zoom, pan: [x, y], fov, ortho}
    size [width, height]           full-resolution image size in pixels
    iso                            a number, or a list of numbers (several translucent surfaces)
    opacity                        one opacity per isovalue of a list (optional)
    window [lo, hi] | null, colormap          MIP / minIP display
    tolerance                      MIP / minIP: largest shortfall, a fraction of the window
    tf {domain, opacity, colormap}            DVR transfer function (TransferFunction.to_dict)
    dvr {step, shade, preintegration, termination, sampling}
    lighting {ambient, diffuse, specular, shininess}
    clip [[nx, ny, nz, d], ...], crop [x0, x1, y0, y1, z0, z1] | null    world coordinates
    timepoint                      which time point of a time series (0 .. hello.timepoints - 1)
    channels [{visible, color, window, iso}, ...]   several channels shown together (only
                                   when hello.channels lists them): each channel's settings;
                                   iso, window, colormap, opacity and tf then go unused
    labels {show: [v, ...] | null, opacity: a | {"v": a, ...}}   a label volume (only when
                                   hello.labels lists its labels): the labels drawn (null:
                                   all) and their opacity; iso and opacity then go unused
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..camera import Camera, parse_size
from ..errors import ParameterError
from ..errors.limits import shorten as limits_shorten
from ..models import MODELS
from ..render.clipping import make_planes
from ..render.defaults import auto_colormap, auto_iso, auto_transfer_function
from ..render.dvr import DEFAULT_SETTINGS, DVRSettings
from ..render.mip import check_tolerance
from ..render.modes import MODE_NAMES as MODES
from ..render.modes import MODES as MODE_CLASSES
from ..render.shading import NORMALS, Shading
from ..scene import check_iso
from ..transfer import TransferFunction, check_colormap
from ..volume import Volume

__all__ = [
    "RenderRequest",
    "default_state",
    "default_iso",
    "parse_state",
    "orbit_camera",
    "resized_camera",
    "MAX_PIXELS",
]

#: Largest image (pixels) a client may ask for unless the server is configured otherwise.
MAX_PIXELS = 4096 * 4096
#: Most isovalues of a multi-isosurface state, clip planes, and transfer-function points.
MAX_ISOS = 16
MAX_CLIP_PLANES = 6
MAX_TF_POINTS = 256
#: Bounds that keep a camera's numbers far from overflow (the library checks the rest).
_ZOOM_RANGE = (1e-3, 1e3)
_PAN_LIMIT = 100.0

_TOP_FIELDS = ("model", "mode", "camera", "size", "iso", "opacity", "window", "colormap",
               "tolerance", "tf", "dvr", "lighting", "clip", "crop", "normals",
               "timepoint", "channels", "labels")
#: The fields of the state's ``labels``.
_LABEL_FIELDS = ("show", "opacity")
#: The fields of one entry of the state's ``channels``.
_CHANNEL_FIELDS = ("visible", "color", "window", "iso")
_CAMERA_FIELDS = ("azimuth", "elevation", "zoom", "pan", "fov", "ortho")
_LIGHTING_FIELDS = ("ambient", "diffuse", "specular", "shininess")
_DVR_FIELDS = ("step", "shade", "preintegration", "termination", "sampling")


@dataclass(frozen=True)
class RenderRequest:
    """A validated state: what to render and how.

    Attributes
    ----------
    model, mode : str
        Reconstruction and render mode.
    camera : Camera
        The full-resolution camera.
    options : dict
        Keyword arguments of :meth:`splinecast.Scene.render` besides the camera.
    state : dict
        The complete state (defaults filled in).
    timepoint : int
        The time point of a time series to render (0 for data that is not one).
    """

    model: str
    mode: str
    camera: Camera
    options: dict[str, Any]
    state: dict[str, Any]
    timepoint: int = 0


def default_iso(volume: Volume) -> float:
    """The isovalue ``splinecast render`` shows when none is given (:func:`auto_iso`)."""
    return float(auto_iso(volume))


def _default_tf(volume: Volume) -> dict[str, Any]:
    """The transfer function ``splinecast render --mode dvr`` uses when none is given
    (:func:`auto_transfer_function`; a volume may bring its own as ``metadata["default_tf"]``)."""
    return auto_transfer_function(volume).to_dict()


def default_state(volume: Volume, model: str = "trilinear", mode: str = "iso",
                  iso: Any = None, *, geometry: Any = None, timepoint: int = 0,
                  channels: list[dict[str, Any]] | None = None,
                  labels: list[dict[str, Any]] | None = None) -> dict[str, Any]:
    """The complete state a viewer starts from (and that omitted fields take).

    Parameters
    ----------
    volume : Volume
        The data on display: the isovalue, window and transfer function are placed in its range.
    model, mode : str
        Initial reconstruction and render mode.
    iso : float or list of float, optional
        Initial isovalue(s); by default :func:`default_iso`.
    geometry : object, optional
        The full-resolution data when ``volume`` is a multiresolution volume's coarsest level:
        isovalues are checked against its ``value_range``.
    timepoint : int
        The time point of a time series shown first (``volume`` is that time point: the
        automatic choices come from it and stay for the others).
    channels : list of dict, optional
        Several channels shown together: each one's ``visible``, ``color``, ``window`` and
        ``iso`` as it starts (:attr:`splinecast.viewer.data.Shown.channels`); the state then
        has a ``channels`` field.
    labels : list of dict, optional
        A label volume's labels (:attr:`splinecast.viewer.data.Shown.labels`); the state then
        has a ``labels`` field: every label drawn, opaque.

    Raises
    ------
    ParameterError
        An unknown model or mode, or an isovalue outside the data range.
    """
    _check_choice(model, MODELS, "model")
    _check_choice(mode, MODES, "mode")
    if iso is None:
        iso = default_iso(volume)
    values = volume if geometry is None else geometry
    isos = [check_iso(values, v) for v in (iso if isinstance(iso, list | tuple) else [iso])]
    shading = Shading()
    state = {
        "model": model,
        "mode": mode,
        "camera": {"azimuth": 30.0, "elevation": 20.0, "zoom": 1.0, "pan": [0.0, 0.0],
                   "fov": 30.0, "ortho": False},
        "size": [1024, 768],
        "iso": isos[0] if len(isos) == 1 else isos,
        "opacity": None,
        # null: the automatic window of the projection shown (MIP's or minIP's, as
        # Scene.render; the hello message carries both); the colormap is gray, diverging for
        # signed data, as Scene.render.
        "window": None,
        "colormap": auto_colormap(volume),
        # The exact projection, as Scene.render gives it without tolerance=.
        "tolerance": 0.0,
        "tf": _default_tf(volume),
        # What Scene.render(mode="dvr") uses without dvr= (DEFAULT_SETTINGS): segments per ray
        # piece at most a voxel long, rays stopped once what they can still add is below 2^-10
        # per channel. A client that changes one field keeps the others.
        "dvr": {"step": DEFAULT_SETTINGS.step, "shade": DEFAULT_SETTINGS.shade,
                "preintegration": DEFAULT_SETTINGS.preintegration,
                "termination": DEFAULT_SETTINGS.termination,
                "sampling": DEFAULT_SETTINGS.sampling},
        "lighting": {name: getattr(shading, name) for name in _LIGHTING_FIELDS},
        "clip": [],
        "crop": None,
        # Isosurfaces shaded with a smooth field's normals (Scene.render's default).
        "normals": "smooth",
        "timepoint": int(timepoint),
    }
    if channels is not None:
        state["channels"] = [{k: copy.deepcopy(c.get(k)) for k in _CHANNEL_FIELDS}
                             for c in channels]
    if labels is not None:
        state["labels"] = {"show": None, "opacity": 1.0}
    return state


# ------------------------------------------------------------------------------ type checks
def _check_choice(value: Any, choices: Any, name: str) -> str:
    if not isinstance(value, str) or value not in choices:
        raise ParameterError(f"{name} must be one of {', '.join(choices)}, got {value!r}")
    return value


def _colormap_name(value: Any, name: str) -> str:
    """A colormap name the library knows (any matplotlib or cmap catalog name, as
    :meth:`Scene.render` accepts; the page's menu lists :data:`splinecast.transfer.MENU`)."""
    if not isinstance(value, str):
        raise ParameterError(f"{name} must be a colormap name, got {value!r}")
    return check_colormap(value, name)


def _check_fields(value: Any, fields: tuple[str, ...], name: str) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise ParameterError(f"{name} must be an object, got {type(value).__name__}")
    unknown = sorted(str(k) for k in value if k not in fields)
    if unknown:
        raise ParameterError(f"{name} has no field {unknown[0]!r} (valid: {', '.join(fields)})")
    return value


def _number(value: Any, name: str) -> float:
    """A finite JSON number (``bool`` is not one)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ParameterError(f"{name} must be a number, got {value!r}")
    out = float(value)
    if not math.isfinite(out):
        raise ParameterError(f"{name} must be a finite number, got {value!r}")
    return out


def _numbers(value: Any, name: str, count: int | None = None,
             max_count: int | None = None) -> list[float]:
    if not isinstance(value, list):
        raise ParameterError(f"{name} must be a list of numbers, got {value!r}")
    if count is not None and len(value) != count:
        raise ParameterError(f"{name} must hold {count} numbers, got {len(value)}")
    if max_count is not None and len(value) > max_count:
        raise ParameterError(f"{name} holds at most {max_count} numbers, got {len(value)}")
    return [_number(v, f"{name}[{i}]") for i, v in enumerate(value)]


def _boolean(value: Any, name: str) -> bool:
    if not isinstance(value, bool):
        raise ParameterError(f"{name} must be true or false, got {value!r}")
    return value


def _merged(base: dict[str, Any], given: Any, fields: tuple[str, ...], name: str) -> dict:
    out = dict(base)
    out.update(_check_fields(given, fields, name))
    return out


# ---------------------------------------------------------------------------------- cameras
def orbit_camera(volume: Volume, camera: dict[str, Any], size: tuple[int, int]) -> Camera:
    """The camera of a state's ``camera`` fields (already complete and type-checked).

    :meth:`Camera.orbit` around the volume's centre, then moved sideways by ``pan`` (in units of
    the view's height at the centre: ``pan = [0.5, 0]`` moves the centre half a view height to
    the left of the image centre, as dragging the data to the left does).
    """
    cam = Camera.orbit(volume, azimuth=camera["azimuth"], elevation=camera["elevation"],
                       size=size, fov=camera["fov"], ortho=camera["ortho"], zoom=camera["zoom"])
    px, py = camera["pan"]
    if px == 0.0 and py == 0.0:
        return cam
    if cam.ortho:
        view_height = cam.ortho_height
    else:
        distance = float(np.linalg.norm(cam.look_at - cam.position))
        view_height = 2.0 * distance * math.tan(math.radians(cam.fov) / 2.0)
    shift = (px * cam.right + py * cam.up) * view_height
    return Camera(cam.position + shift, cam.look_at + shift, up=cam.up, fov=cam.fov,
                  size=size, ortho=cam.ortho, ortho_height=cam.ortho_height)


def resized_camera(camera: Camera, width: int, height: int) -> Camera:
    """The same view at another image size (for reduced-resolution frames).

    The vertical field of view (or orthographic window height) is kept; the horizontal one
    follows the new aspect ratio, which differs from the original by rounding only.
    """
    return Camera(camera.position, camera.look_at, up=camera.up, fov=camera.fov,
                  size=(width, height), ortho=camera.ortho, ortho_height=camera.ortho_height)


# ---------------------------------------------------------------------------------- parsing
def _complete(state: Any, defaults: dict[str, Any]) -> dict[str, Any]:
    """The state with every omitted field taken from ``defaults`` (nested objects field-wise)."""
    given = _check_fields(state, _TOP_FIELDS, "state")
    full = copy.deepcopy(defaults)
    for key, value in given.items():
        if key == "camera":
            full[key] = _merged(defaults[key], value, _CAMERA_FIELDS, "camera")
        elif key == "lighting":
            full[key] = _merged(defaults[key], value, _LIGHTING_FIELDS, "lighting")
        elif key == "dvr":
            full[key] = _merged(defaults[key], value, _DVR_FIELDS, "dvr")
        elif key == "labels" and isinstance(defaults.get(key), dict):
            full[key] = _merged(defaults[key], value, _LABEL_FIELDS, "labels")
        else:
            full[key] = value
    return full


def _camera_fields(camera: dict[str, Any]) -> dict[str, Any]:
    out = {
        "azimuth": _number(camera["azimuth"], "camera.azimuth"),
        "elevation": _number(camera["elevation"], "camera.elevation"),
        "zoom": _number(camera["zoom"], "camera.zoom"),
        "pan": _numbers(camera["pan"], "camera.pan", 2),
        "fov": _number(camera["fov"], "camera.fov"),
        "ortho": _boolean(camera["ortho"], "camera.ortho"),
    }
    if not _ZOOM_RANGE[0] <= out["zoom"] <= _ZOOM_RANGE[1]:
        raise ParameterError(f"camera.zoom must be in [{_ZOOM_RANGE[0]:g}, {_ZOOM_RANGE[1]:g}], "
                             f"got {out['zoom']:g}")
    if not 0.0 < out["fov"] < 180.0:  # checked before Camera.orbit derives a distance from it
        raise ParameterError(f"camera.fov must be between 0 and 180 degrees, got {out['fov']:g}")
    if max(abs(p) for p in out["pan"]) > _PAN_LIMIT:
        raise ParameterError(f"camera.pan must be within +-{_PAN_LIMIT:g} view heights")
    return out


def _size(value: Any, max_pixels: int) -> tuple[int, int]:
    if not (isinstance(value, list) and len(value) == 2
            and all(isinstance(v, int) and not isinstance(v, bool) for v in value)):
        raise ParameterError(f"size must be two integers [width, height], got {value!r}")
    width, height = parse_size(value)
    if width * height > max_pixels:
        raise ParameterError(f"size {width}x{height} is larger than this server's limit of "
                             f"{max_pixels} pixels")
    return width, height


def _iso_options(state: dict[str, Any], volume: Any) -> dict[str, Any]:
    iso = state["iso"]
    if not isinstance(iso, list):
        return {"iso": check_iso(volume, _number(iso, "iso"))}
    if not 1 <= len(iso) <= MAX_ISOS:
        raise ParameterError(f"iso must hold 1 to {MAX_ISOS} isovalues, got {len(iso)}")
    options: dict[str, Any] = {"iso": [check_iso(volume, v) for v in _numbers(iso, "iso")]}
    if state["opacity"] is not None:
        options["opacity"] = _numbers(state["opacity"], "opacity", len(iso))
    return options


def _transfer_function(tf: Any) -> TransferFunction:
    tf = _check_fields(tf, ("domain", "opacity", "colormap"), "tf")
    if "domain" not in tf or "opacity" not in tf:
        raise ParameterError("tf needs 'domain' and 'opacity'")
    domain = _numbers(tf["domain"], "tf.domain", 2)
    points = tf["opacity"]
    if not isinstance(points, list) or not 1 <= len(points) <= MAX_TF_POINTS:
        raise ParameterError(f"tf.opacity must be a list of 1 to {MAX_TF_POINTS} [value, alpha]")
    opacity = [_numbers(p, f"tf.opacity[{i}]", 2) for i, p in enumerate(points)]
    colormap = _colormap_name(tf.get("colormap", "viridis"), "tf.colormap")
    return TransferFunction(opacity, domain, colormap)


def _dvr_settings(dvr: dict[str, Any], lighting: dict[str, float]) -> DVRSettings:
    termination = dvr["termination"]
    if termination is not None:
        termination = _number(termination, "dvr.termination")
    names = {}
    for field in ("preintegration", "sampling"):
        if not isinstance(dvr[field], str):
            raise ParameterError(f"dvr.{field} must be a name, got {dvr[field]!r}")
        names[field] = dvr[field]
    return DVRSettings(step=_number(dvr["step"], "dvr.step"), termination=termination,
                       shade=_boolean(dvr["shade"], "dvr.shade"), ambient=lighting["ambient"],
                       diffuse=lighting["diffuse"], **names)


def _mode_options(state: dict[str, Any], volume: Any, shown: Volume,
                  channels: bool = False) -> dict[str, Any]:
    """``Scene.render`` keywords of the state's mode fields. ``channels``: several channels
    shown together, each with its own isovalue, window and colours, so the single volume's
    ``iso``, ``opacity``, ``window``, ``colormap`` and ``tf`` are left out (of the first
    channel's range, they would be wrong for the others)."""
    mode = state["mode"]
    lighting = {k: _number(state["lighting"][k], f"lighting.{k}") for k in _LIGHTING_FIELDS}
    shading = Shading(**lighting)
    options: dict[str, Any] = {"mode": mode, "shading": shading}
    clip = state["clip"]
    if not isinstance(clip, list) or len(clip) > MAX_CLIP_PLANES:
        raise ParameterError(f"clip must be a list of at most {MAX_CLIP_PLANES} planes")
    clip = [_numbers(p, f"clip[{i}]", 4) for i, p in enumerate(clip)]
    crop = state["crop"]
    if crop is not None:
        crop = _numbers(crop, "crop", 6)
    make_planes(clip, crop)  # refuses zero normals and empty boxes with the library's message
    if clip:
        options["clip"] = clip
    if crop is not None:
        options["crop"] = crop
    # The state's fields that the mode reads (the registry says which), as its options.
    reads = MODE_CLASSES[mode].keywords
    if channels:
        reads = tuple(k for k in reads if k not in ("iso", "opacity", "window", "colormap",
                                                    "tf"))
    if "iso" in reads:
        options.update(_iso_options(state, volume))
    if "normals" in reads:
        options["normals"] = _check_choice(state["normals"], NORMALS, "normals")
    if "window" in reads:
        window = state["window"]
        # Without a window the projection's own automatic one, from the data on display (a
        # pyramid's coarsest level: the same for every cut, so frames agree while bricks load).
        window = (MODE_CLASSES[mode].default_window(shown) if window is None
                  else _numbers(window, "window", 2))
        options["window"] = window
    if "colormap" in reads:
        options["colormap"] = _colormap_name(state["colormap"], "colormap")
    if "tolerance" in reads:
        options["tolerance"] = check_tolerance(_number(state["tolerance"], "tolerance"), "exact")
    if "tf" in reads:
        options["tf"] = _transfer_function(state["tf"])
    if "dvr" in reads:
        options["dvr"] = _dvr_settings(state["dvr"], lighting)
    return options


def _channel_settings(value: Any, count: int) -> list[dict[str, Any]]:
    """The state's ``channels``: one object per channel, each field type-checked here and its
    value by :class:`splinecast.Channel` (colours, windows) when the scene applies it."""
    if not count:
        raise ParameterError("channels: the data on display has one channel")
    if not isinstance(value, list) or len(value) != count:
        raise ParameterError(f"channels must be a list of {count} objects (one per channel), "
                             f"got {limits_shorten(value)}")
    out = []
    for i, entry in enumerate(value):
        entry = _check_fields(entry, _CHANNEL_FIELDS, f"channels[{i}]")
        settings: dict[str, Any] = {}
        if entry.get("visible") is not None:
            settings["visible"] = _boolean(entry["visible"], f"channels[{i}].visible")
        if entry.get("color") is not None:
            color = entry["color"]
            if isinstance(color, list):
                color = _numbers(color, f"channels[{i}].color", 3)
            elif not isinstance(color, str) or len(color) > 32:
                raise ParameterError(f"channels[{i}].color must be '#rrggbb' or [r, g, b], got "
                                     f"{limits_shorten(color)}")
            settings["color"] = color
        if "window" in entry:  # null: the channel's automatic window
            window = entry["window"]
            settings["window"] = (None if window is None
                                  else _numbers(window, f"channels[{i}].window", 2))
        if "iso" in entry:  # null: the channel's automatic isovalue
            iso = entry["iso"]
            settings["iso"] = None if iso is None else _number(iso, f"channels[{i}].iso")
        out.append(settings)
    return out


def _label_settings(value: Any, present: list[int] | None) -> dict[str, Any]:
    """The state's ``labels`` as :meth:`LabelScene.render` keywords (``show``, ``opacity``).

    Checked here, so a label the volume does not hold or an opacity outside [0, 1] is one
    error naming the field (the scene would name its keyword instead)."""
    if present is None:
        raise ParameterError("labels: the data on display is not a label volume")
    value = _check_fields(value, _LABEL_FIELDS, "labels")
    known = set(present)

    def label(v: Any, name: str) -> int:
        if isinstance(v, str):  # JSON object keys are strings
            try:
                v = int(v)
            except ValueError:
                raise ParameterError(f"{name} must be a label value (an integer), got "
                                     f"{limits_shorten(v)}") from None
        if isinstance(v, bool) or not isinstance(v, int):
            raise ParameterError(f"{name} must be a label value (an integer), got "
                                 f"{limits_shorten(v)}")
        if v not in known:
            raise ParameterError(f"{name}: label {v} does not occur in the volume (its labels: "
                                 f"{limits_shorten(sorted(known))})")
        return int(v)

    def alpha(v: Any, name: str) -> float:
        number = _number(v, name)
        if not 0.0 <= number <= 1.0:
            raise ParameterError(f"{name} must be in [0, 1], got {number:g}")
        return number

    out: dict[str, Any] = {}
    show = value.get("show")
    if show is not None:
        if not isinstance(show, list):
            raise ParameterError(f"labels.show must be a list of label values or null, got "
                                 f"{limits_shorten(show)}")
        out["show"] = [label(v, f"labels.show[{i}]") for i, v in enumerate(show)]
    opacity = value.get("opacity", 1.0)
    if isinstance(opacity, dict):
        out["opacity"] = {label(k, f"labels.opacity key {k!r}"):
                          alpha(v, f"labels.opacity[{k!r}]") for k, v in opacity.items()}
    else:
        out["opacity"] = alpha(opacity, "labels.opacity")
    return out


def _timepoint(value: Any, timepoints: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ParameterError(f"timepoint must be an integer, got {value!r}")
    if not 0 <= value < timepoints:
        valid = "0" if timepoints == 1 else f"0 to {timepoints - 1}"
        raise ParameterError(f"timepoint {value} is out of range (the data holds {timepoints} "
                             f"time point{'s' if timepoints > 1 else ''}: {valid})")
    return int(value)


def parse_state(state: Any, volume: Volume, defaults: dict[str, Any],
                max_pixels: int = MAX_PIXELS, *, geometry: Any = None,
                models: Any = None, modes: Any = None, timepoints: int = 1,
                channels: int = 0, labels: list[int] | None = None) -> RenderRequest:
    """Validate a client's state into a :class:`RenderRequest`.

    Parameters
    ----------
    state : dict
        The state as decoded from JSON; omitted fields come from ``defaults``.
    volume : Volume
        The data on display (isovalues are checked against its range).
    defaults : dict
        A complete state, as made by :func:`default_state`.
    max_pixels : int
        The largest image size allowed.
    geometry : object, optional
        What the camera orbits and isovalues are checked against (world ``bounds``,
        ``value_range``; default ``volume``): the full-resolution data when ``volume`` is a
        multiresolution volume's coarsest level.
    models, modes : sequence of str, optional
        The choices offered (default: every model and mode).
    timepoints : int
        Time points of the data on display (``timepoint`` must be below it).
    channels : int
        Channels shown together (0: one volume). With channels, the request's options hold
        the state's ``channels`` (:meth:`splinecast.ChannelScene.render`) instead of the
        single volume's isovalue, window, colormap, opacity and transfer function, which each
        channel has of its own.
    labels : list of int, optional
        The values of a label volume's labels (None: not a label volume). The request's
        options then hold ``show`` and ``opacity`` (:meth:`LabelScene.render`) from the
        state's ``labels`` instead of the isovalue and its opacity.

    Raises
    ------
    ParameterError
        One line naming the first field that is wrong.
    """
    full = _complete(state, defaults)
    model = _check_choice(full["model"], MODELS if models is None else models, "model")
    mode = _check_choice(full["mode"], MODES if modes is None else modes, "mode")
    camera_fields = _camera_fields(full["camera"])
    size = _size(full["size"], max_pixels)
    geometry = volume if geometry is None else geometry
    camera = orbit_camera(geometry, camera_fields, size)
    timepoint = _timepoint(full.get("timepoint", 0), timepoints)
    several = bool(channels) or "channels" in full
    if labels is not None or "labels" in full:
        # A label scene draws its labels' own surfaces: no isovalue, window or colormap.
        options = _mode_options(full, geometry, volume, channels=True)
        options.update(_label_settings(full.get("labels"), labels))
        return RenderRequest(model, mode, camera, options, full, timepoint)
    options = _mode_options(full, geometry, volume, several)
    if several:
        options["channels"] = _channel_settings(full.get("channels"), channels)
    return RenderRequest(model, mode, camera, options, full, timepoint)
