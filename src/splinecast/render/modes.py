"""Host side of the render modes beyond the single isosurface: MIP/minIP, DVR, multi-isosurface.

Each function validates its mode's parameters, allocates the Frame buffers, runs the compiled
kernel of :mod:`.mip`, :mod:`.dvr` or :mod:`.multi_iso` and packs the result into a
:class:`~splinecast.render.frame.Frame`. :class:`splinecast.Scene` calls them; they take the
prepared model, its min/max hierarchy and the camera, never a Scene (the render layer does not
import it). These modes are implemented for the trilinear model.
"""

from __future__ import annotations

import json
import math
import time
from typing import Any

import numpy as np

from ..errors import ParameterError
from ..preintegration import PreintegrationTable, preintegrate
from ..transfer import COLORMAPS, TransferFunction, apply_colormap, colormap_table
from .dvr import DVRSettings, trace_dvr
from .effects import NO_EFFECTS, SurfaceEffects
from .frame import Frame
from .mip import trace_mip
from .multi_iso import trace_multi_iso
from .shading import Shading

__all__ = ["render_mip", "render_dvr", "render_multi_iso", "visible_flags"]

_MIP_METHODS = {"exact": 0, "sampled": 1}


def _require_trilinear(model: Any, mode: str) -> None:
    if model.name != "trilinear":
        raise ParameterError(f"mode {mode!r} is implemented for model='trilinear' only, "
                             f"not {model.name!r}")


def visible_flags(hierarchy: Any, ranges: list[tuple[float, float]]) -> tuple[np.ndarray, ...]:
    """Block flags (uint8 per level) for blocks meeting any closed value interval in ``ranges``.

    The same test as :meth:`MinMaxHierarchy.classify_any`, without changing the hierarchy's own
    (isovalue) flags, so an iso render after a DVR render needs no re-classification.
    """
    flags = []
    for lo, hi in zip(hierarchy.lows, hierarchy.highs, strict=True):
        act = np.zeros(lo.shape, dtype=bool)
        for a, b in ranges:
            act |= (lo <= b) & (hi >= a)
        flags.append(act.view(np.uint8))
    return tuple(flags)


def _buffers(camera: Any) -> dict[str, np.ndarray]:
    h, w = camera.height, camera.width
    return {
        "rgba": np.empty((h, w, 4), np.float32),
        "depth": np.empty((h, w), np.float64),
        "position": np.empty((h, w, 3), np.float64),
        "normal": np.full((h, w, 3), np.nan, np.float32),
        "face": np.zeros((h, w), np.int8),
        "visited": np.zeros((h, w), np.int32),
        "tested": np.zeros((h, w), np.int32),
        "skipped": np.zeros((h, w), np.int32),
    }


def _frame(buf: dict[str, np.ndarray], stats: dict[str, Any], value: Any = None) -> Frame:
    stats.update({
        "hits": int(np.count_nonzero(np.isfinite(buf["depth"]))),
        "mean_cells_visited": float(buf["visited"].mean()),
        "mean_cells_tested": float(buf["tested"].mean()),
        "mean_blocks_skipped": float(buf["skipped"].mean()),
    })
    return Frame(buf["rgba"], buf["depth"], buf["position"], buf["normal"], buf["face"],
                 buf["visited"], buf["tested"], buf["skipped"], stats, value)


def render_mip(model: Any, hierarchy: Any, volume: Any, camera: Any, planes: np.ndarray,
               row_order: np.ndarray, kind: str = "mip", method: str = "exact",
               step: float = 0.25, window: Any = None, colormap: Any = "gray",
               background: Any = (0.0, 0.0, 0.0, 1.0)) -> Frame:
    """Maximum (``kind="mip"``) or minimum (``"minip"``) intensity projection.

    ``window=(lo, hi)`` maps values to the colormap (default: the volume's value range);
    ``Frame.value`` holds the projected values and ``Frame.depth`` the distance to them.
    """
    _require_trilinear(model, kind)
    if method not in _MIP_METHODS:
        raise ParameterError(f"method must be one of {', '.join(_MIP_METHODS)}, got {method!r}")
    if method == "sampled" and not (math.isfinite(step) and step > 0):
        raise ParameterError(f"step must be a positive number of voxels, got {step}")
    window = _check_window(window, volume)
    colormap_table(colormap, 2)  # validates the name before any work
    sign = 1.0 if kind == "mip" else -1.0
    if sign > 0:
        h0, h1, h2 = hierarchy.highs
        g1 = hierarchy.lows[1]
    else:
        h0, h1, h2 = (-a for a in hierarchy.lows)
        g1 = -hierarchy.highs[1]
    buf = _buffers(camera)
    value = np.empty(buf["depth"].shape, np.float64)
    start = time.perf_counter()
    trace_mip(model.data, h0, h1, h2, g1, sign, camera.pixel_basis(), np.asarray(volume.origin),
              np.asarray(volume.spacing), planes, row_order, _MIP_METHODS[method],
              float(step), value, buf["depth"], buf["position"], buf["visited"], buf["tested"],
              buf["skipped"])
    trace_ms = (time.perf_counter() - start) * 1e3
    buf["rgba"] = apply_colormap(value, window, colormap, background)
    stats = {"mode": kind, "model": model.name, "method": method, "window": window,
             "width": camera.width, "height": camera.height, "rays": camera.width * camera.height,
             "trace_ms": trace_ms}
    if method == "sampled":
        stats["step"] = float(step)
    return _frame(buf, stats, value)


def _check_window(window: Any, volume: Any) -> tuple[float, float]:
    if window is None:
        lo, hi = volume.value_range
        return (float(lo), float(hi) if hi > lo else float(lo) + 1.0)
    try:
        lo, hi = (float(v) for v in window)
    except (TypeError, ValueError):
        raise ParameterError(f"window must be two numbers (lo, hi), got {window!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
        raise ParameterError(f"window must be two finite numbers with lo < hi, got {window!r}")
    return lo, hi


def _table(tf: TransferFunction, settings: DVRSettings, cache: dict) -> PreintegrationTable:
    """The pre-integration table for ``tf`` and ``settings``, built once and cached."""
    key = (json.dumps(tf.to_dict()), settings.table_size, settings.step, settings.table_steps,
           settings.table_layout)
    table = cache.get(key)
    if table is None:
        cache.clear()  # one table at a time: they can be large
        table = preintegrate(tf, n=settings.table_size, h0=settings.step,
                             steps=settings.table_steps, layout=settings.table_layout)
        cache[key] = table
    return table


def render_dvr(model: Any, hierarchy: Any, volume: Any, camera: Any, planes: np.ndarray,
               row_order: np.ndarray, tf: TransferFunction, settings: DVRSettings | None = None,
               background: Any = (0.0, 0.0, 0.0, 1.0), cache: dict | None = None) -> Frame:
    """Direct volume rendering of the trilinear field through ``tf`` (see :mod:`.dvr`)."""
    _require_trilinear(model, "dvr")
    if not isinstance(tf, TransferFunction):
        raise ParameterError("mode 'dvr' needs tf=TransferFunction(...)")
    settings = settings or DVRSettings()
    if not isinstance(settings, DVRSettings):
        raise ParameterError(f"dvr must be a DVRSettings, got {type(settings).__name__}")
    cache = {} if cache is None else cache
    start = time.perf_counter()
    pi_mode = settings.pi_mode
    if pi_mode:
        pit = _table(tf, settings, cache)
        table = pit.table
    else:
        table = np.zeros((1, 2, 2, 4), np.float32)
    table_ms = (time.perf_counter() - start) * 1e3
    _, lut_rgb, lut_tau = tf.sample(4096)
    prefix = tf.transparency_prefix(1024)
    act0, act1, act2 = visible_flags(hierarchy, tf.visible_ranges())
    term = 2.0 if settings.termination is None else float(settings.termination)
    bg = np.asarray(background, np.float64).reshape(4)
    buf = _buffers(camera)
    samples = np.empty(buf["depth"].shape, np.int32)
    domain = np.asarray(tf.domain, np.float64)
    start = time.perf_counter()
    trace_dvr(model.data, act0, act1, act2, prefix, domain, pi_mode, table, domain,
              float(settings.step), lut_rgb, lut_tau, bool(settings.adaptive),
              float(settings.h_max), float(settings.exponent), term, bool(settings.shade),
              float(settings.ambient), float(settings.diffuse), bool(settings.leap), bg,
              camera.pixel_basis(),
              np.asarray(volume.origin), np.asarray(volume.spacing), planes, row_order,
              buf["rgba"], buf["depth"], buf["position"], samples, buf["visited"],
              buf["skipped"])
    trace_ms = (time.perf_counter() - start) * 1e3
    stats = {"mode": "dvr", "model": model.name, "step": settings.step,
             "preintegration": settings.preintegration, "adaptive": settings.adaptive,
             "table_layout": settings.table_layout, "leap": settings.leap,
             "termination": settings.termination, "width": camera.width,
             "height": camera.height, "rays": camera.width * camera.height,
             "trace_ms": trace_ms, "table_ms": table_ms,
             "mean_samples": float(samples.mean())}
    return _frame(buf, stats)


def _per_surface(values: Any, count: int, width: int, name: str) -> np.ndarray:
    arr = np.asarray(values, dtype=np.float64)
    if width > 1 and arr.ndim == 1 and arr.size == width:
        arr = arr.reshape(1, width)  # one colour for all surfaces
    try:
        arr = np.broadcast_to(arr.reshape(-1, width) if width > 1 else arr.reshape(-1),
                              (count, width) if width > 1 else (count,))
    except ValueError:
        raise ParameterError(f"{name} must give one value per isovalue ({count})") from None
    if not np.all((arr >= 0) & (arr <= 1)):
        raise ParameterError(f"{name} must be in [0, 1]")
    return np.ascontiguousarray(arr, dtype=np.float64)


def render_multi_iso(model: Any, hierarchy: Any, volume: Any, camera: Any, planes: np.ndarray,
                     row_order: np.ndarray, isos: list[float], colors: Any = None,
                     opacity: Any = None, inside_high: bool = True,
                     shading: Shading | None = None,
                     effects: SurfaceEffects | None = None) -> Frame:
    """Several isosurfaces composited front to back (see :mod:`.multi_iso`).

    ``colors``: one RGB per isovalue (default: evenly spaced on the ``bone`` colormap, in
    increasing isovalue order). ``opacity``: one per isovalue (default 0.5, and 1 for the last).
    """
    _require_trilinear(model, "iso")
    count = len(isos)
    if colors is None:
        order = np.argsort(np.argsort(isos))
        palette = colormap_table(COLORMAPS["bone"], 256)
        colors = palette[(64 + order * 191 // max(count - 1, 1)).clip(0, 255)]
    if opacity is None:
        opacity = [0.5] * (count - 1) + [1.0]
    colors_arr = _per_surface(colors, count, 3, "colors")
    opacity_arr = _per_surface(opacity, count, 1, "opacity")
    shading = shading or Shading()
    effects = effects or SurfaceEffects()
    act0, act1, act2 = visible_flags(hierarchy, [(v, v) for v in isos])
    buf = _buffers(camera)
    layers = np.empty(buf["depth"].shape, np.int32)
    start = time.perf_counter()
    trace_multi_iso(model.data, act0, act1, act2, np.asarray(isos, np.float64), colors_arr,
                    opacity_arr, camera.pixel_basis(), np.asarray(volume.origin),
                    np.asarray(volume.spacing), planes, row_order, bool(inside_high),
                    shading.as_array(), effects.as_array() if effects else NO_EFFECTS,
                    buf["rgba"], buf["depth"], buf["position"], buf["normal"], buf["face"],
                    layers, buf["visited"], buf["tested"], buf["skipped"])
    trace_ms = (time.perf_counter() - start) * 1e3
    stats = {"mode": "iso", "model": model.name, "method": "exact", "iso": list(isos),
             "width": camera.width, "height": camera.height, "rays": camera.width * camera.height,
             "trace_ms": trace_ms, "mean_layers": float(layers.mean())}
    return _frame(buf, stats)
