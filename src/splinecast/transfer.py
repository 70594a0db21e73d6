"""Transfer functions and colormaps: how data values become colour and opacity.

A :class:`TransferFunction` maps a data value (in data units, never normalized behind the user's
back) to an RGB colour and an opacity:

* the **opacity** is piecewise linear between control points ``(value, alpha)`` and constant beyond
  the first and last point. ``alpha`` is the opacity of a slab **one voxel thick** (index units)
  of material with that value; the renderers turn it into the extinction coefficient
  ``tau = -ln(1 - alpha)`` per voxel length, so images do not change when the sampling step does;
* the **colour** comes from a named colormap stretched over the transfer function's ``domain``,
  or from explicit control points ``(position in [0, 1], r, g, b)``.

Colormap names are those of the `cmap <https://cmap-docs.readthedocs.io>`_ catalog (the colormap
library napari uses; pure Python, its only dependency is numpy): every matplotlib colormap by its
matplotlib name, with the same colours, and the maps of colorcet, cmocean, Crameri, CET and
others. :data:`MENU` lists the ones offered in menus; :data:`DIVERGING` is the default of signed
data. A named map is read as 256 control points, interpolated linearly in RGB. Transfer
functions round-trip through JSON (:meth:`TransferFunction.save`,
:meth:`TransferFunction.load`).

For empty-space skipping, :meth:`TransferFunction.visible_ranges` gives the value intervals with
non-zero opacity (exact, from the control points), and :meth:`TransferFunction.transparency_prefix`
the prefix-sum table of Carmona & Froehlich 2011 (section 1.5): with ``t(i) = 1`` when table bin
``i`` is not fully transparent and ``T(i) = T(i-1) + t(i)``, a cell whose values lie in bins
``a..b`` is fully transparent exactly when ``T(b + 1) == T(a)``;
:meth:`TransferFunction.clear_ends` the values at or beyond which the opacity is zero, so that a
range touching a visible interval only at such an end (a background of zeros under a ramp that
starts at 0) counts as transparent.
"""

from __future__ import annotations

import functools
import json
import logging
import math
import os
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ._jit import jit
from ._jit.work_queue import run_items, take
from .errors import ParameterError, ReadError, did_you_mean, limits

__all__ = ["COLORMAPS", "MENU", "DIVERGING", "TransferFunction", "colormap_table", "apply_colormap",
           "check_colormap", "colormap_names", "parse_color"]

#: The colormaps offered by name in menus (the viewer's list, ``--help``), in that order. Any
#: other name of the `cmap <https://cmap-docs.readthedocs.io>`_ catalog works too: every
#: matplotlib colormap by its matplotlib name (``"RdBu_r"``, ``"jet"``, ...; ``_r`` reverses a
#: map), and the maps of colorcet, cmocean, Crameri, CET, ... (``"cmocean:thermal"``).
MENU = ("gray", "bone", "hot", "viridis", "magma", "inferno", "cividis", "turbo", "coolwarm",
        "RdBu_r", "berlin")
#: The colormap of signed data (values on both sides of a background of 0): Crameri's
#: ``berlin``, diverging through a dark centre, so that values near 0 fade into the dark
#: background and both signs stand out (blue below 0, red above).
DIVERGING = "berlin"

#: Names the catalog lacks or spells differently: the British spelling of ``gray`` (cmap's
#: ``grey`` is a single-colour map).
_ALIASES = {"grey": "gray", "grey_r": "gray_r"}
#: Colormap samples: a map is stored as this many control points (exact for the catalog's
#: 256-entry tables).
_SAMPLES = 256


def colormap_names() -> list[str]:
    """Every colormap name :func:`colormap_table` accepts (the short names of the cmap catalog;
    namespaced names ``"namespace:name"`` and ``_r`` reversals are accepted as well)."""
    import cmap

    short = {n for n in cmap.Colormap.catalog() if ":" not in n}
    return sorted(short | set(MENU) | set(_ALIASES))


@functools.lru_cache(maxsize=64)
def _catalog_points(name: str) -> np.ndarray:
    """Control points ``(position, r, g, b)`` of a catalog colormap (read-only, cached)."""
    import cmap

    key = _ALIASES.get(name.lower(), name)
    # cmap logs a warning when a short name exists in several namespaces; like matplotlib it
    # takes the matplotlib (bids, matlab, ...) map first, which is what a user of that name
    # expects, so the warning is noise here.
    logger = logging.getLogger("cmap")
    level = logger.level
    logger.setLevel(logging.ERROR)
    try:
        cm = cmap.Colormap(key)
    except (ValueError, KeyError, TypeError):
        raise _unknown_colormap(name) from None
    finally:
        logger.setLevel(level)
    x = np.linspace(0.0, 1.0, _SAMPLES)
    rgb = np.asarray(cm(x), dtype=np.float64)[:, :3]
    points = np.column_stack([x, np.clip(rgb, 0.0, 1.0)])
    points.setflags(write=False)
    return points


def _unknown_colormap(name: str) -> ParameterError:
    shown = limits.shorten(name)
    hint = did_you_mean(name, [*MENU, *colormap_names()])
    return ParameterError(
        f"colormap {shown} is not a known colormap{hint} (accepted: {', '.join(MENU)}, or any "
        "matplotlib or cmap catalog name)")


class _Colormaps(Mapping):
    """The :data:`MENU` colormaps by name -> control points ``(position, r, g, b)``."""

    def __getitem__(self, name: str) -> np.ndarray:
        if name not in MENU:
            raise KeyError(name)
        return _catalog_points(name)

    def __iter__(self) -> Iterator[str]:
        return iter(MENU)

    def __len__(self) -> int:
        return len(MENU)


#: The :data:`MENU` colormaps as control points ``(position, r, g, b)``, 256 each (read from
#: the cmap catalog on first use).
COLORMAPS: Mapping[str, np.ndarray] = _Colormaps()


def check_colormap(colormap: Any, name: str = "colormap") -> Any:
    """``colormap`` if it is a known colormap name or valid control points, else a
    :class:`~splinecast.errors.ParameterError` naming ``name``, the accepted values and the
    closest names."""
    try:
        _colormap_points(colormap)
    except ParameterError as exc:
        message = str(exc)
        if message.startswith("colormap") and name != "colormap":
            message = name + message[len("colormap"):]
        raise ParameterError(message) from None
    return colormap


# Opacity is capped just below 1 so the extinction -ln(1 - alpha) stays finite.
_ALPHA_CAP = 1.0 - 1e-6


def parse_color(value: Any, name: str = "color", alpha: bool = False) -> tuple[float, ...]:
    """A colour as RGB (``alpha=True``: RGBA) floats in [0, 1].

    ``value`` is a CSS colour name (``"white"``, ``"steelblue"``), a hex code (``"#1a1a1a"``,
    ``"#1a1a1a80"`` with alpha), ``"R,G,B"`` or ``"R,G,B,A"`` numbers in [0, 1], a sequence of
    3 (or 4) such numbers, or ``"transparent"`` (``"none"``), which needs ``alpha=True``.
    Without an alpha of its own a colour is opaque.

    Raises
    ------
    ParameterError
        One line naming ``name``, what was given, the accepted forms and the closest colour
        names.
    """
    from PIL import ImageColor

    width = 4 if alpha else 3
    accepted = ("a colour name (white, black, steelblue, ...), #RRGGBB"
                + (", #RRGGBBAA, transparent" if alpha else "")
                + (" or R,G,B[,A] numbers in [0, 1]" if alpha else " or R,G,B numbers in [0, 1]"))
    rgba: list[float] | None = None
    if isinstance(value, str):
        text = value.strip().lower()
        if alpha and text in ("transparent", "none"):
            return (0.0, 0.0, 0.0, 0.0)
        if "," in text and not text.startswith(("rgb", "hsl", "hsv")):
            try:
                rgba = [float(v) for v in text.split(",")]
            except ValueError:
                rgba = None
        else:
            try:
                rgb8 = ImageColor.getrgb(text)
                rgba = [c / 255.0 for c in rgb8]
            except ValueError:
                rgba = None
    elif not isinstance(value, bool):
        try:
            rgba = [float(v) for v in value]
        except (TypeError, ValueError):
            rgba = None
    if (rgba is None or not 3 <= len(rgba) <= width
            or not all(math.isfinite(v) and 0.0 <= v <= 1.0 for v in rgba)):
        hint = ""
        if isinstance(value, str) and not any(c.isdigit() for c in value):
            hint = did_you_mean(value.strip(), ImageColor.colormap)
        raise ParameterError(f"{name} {limits.shorten(value)} is not a colour{hint} "
                             f"(accepted: {accepted})")
    if alpha and len(rgba) == 3:
        rgba.append(1.0)
    return tuple(float(v) for v in rgba)


def _control_points(points: Any, width: int, name: str) -> np.ndarray:
    try:
        arr = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise ParameterError(f"{name} must be a list of {width}-number points") from None
    if arr.ndim != 2 or arr.shape[1] != width or arr.shape[0] < 1:
        raise ParameterError(
            f"{name} must be a list of {width}-number points, got {limits.shorten(points)}"
        )
    if not np.all(np.isfinite(arr)):
        raise ParameterError(f"{name} must hold finite numbers")
    if np.any(np.diff(arr[:, 0]) < 0):
        raise ParameterError(f"{name}: the positions must be in increasing order")
    return arr


def _colormap_points(colormap: Any) -> np.ndarray:
    if isinstance(colormap, str):
        return _catalog_points(colormap)
    pts = _control_points(colormap, 4, "colormap")
    if np.any((pts < 0) | (pts > 1)):
        raise ParameterError("colormap points must be (position, r, g, b) numbers in [0, 1]")
    return pts


def colormap_table(colormap: Any = "gray", n: int = 256) -> np.ndarray:
    """The colormap sampled at ``n`` evenly spaced positions of ``[0, 1]``: shape (n, 3).

    ``colormap`` is a colormap name (:data:`MENU`, any matplotlib or cmap catalog name) or
    control points ``(position, r, g, b)``.
    """
    pts = _colormap_points(colormap)
    x = np.linspace(0.0, 1.0, n)
    return np.stack([np.interp(x, pts[:, 0], pts[:, c]) for c in (1, 2, 3)], axis=-1)


def apply_colormap(values: np.ndarray, window: tuple[float, float], colormap: Any = "gray",
                   background: Any = (0.0, 0.0, 0.0, 1.0)) -> np.ndarray:
    """RGBA float32 image of ``values`` through a window/level and a colormap.

    Values at or below ``window[0]`` get the colormap's first colour, at or above ``window[1]`` its
    last (the nearest of 1024 entries sampled over the window); NaN (rays that miss the volume)
    gets ``background``.
    """
    lo, hi = float(window[0]), float(window[1])
    table = colormap_table(colormap, 1024)
    span = hi - lo if hi > lo else 1.0
    values = np.asarray(values)
    rgba = np.empty((*values.shape, 4), np.float32)
    # One pass over the pixels on every thread: the whole-array numpy form took 57 ms of a
    # 1024x768 MIP frame on one core (six temporaries the image's size).
    flat = values.reshape(-1)
    run_items(_colormap_pixels, -(-flat.shape[0] // _PIXEL_CHUNK), flat, float(lo), float(span),
              table, np.asarray(background, np.float32), rgba.reshape(-1, 4))
    return rgba


#: Pixels per item of :func:`_colormap_pixels` on threads.
_PIXEL_CHUNK = 16384


@jit
def _colormap_pixels(values, lo, span, table, background, out, counter):  # pragma: no cover
    """``out[i]``: the ``table`` colour nearest ``(values[i] - lo) / span`` (clamped to [0, 1])
    with alpha 1, or ``background`` where the value is NaN; for the chunks of pixels this thread
    takes from ``counter`` (:func:`~splinecast._jit.work_queue.run_items`)."""
    top = table.shape[0] - 1
    n = values.shape[0]
    while True:
        start = take(counter) * _PIXEL_CHUNK
        if start >= n:
            break
        for i in range(start, min(start + _PIXEL_CHUNK, n)):
            v = np.float64(values[i])
            if math.isnan(v):
                for c in range(4):
                    out[i, c] = background[c]
                continue
            u = min(max((v - lo) / span, 0.0), 1.0)
            # rint: round half to even, like numpy's.
            entry = int(np.rint(u * top))
            for c in range(3):
                out[i, c] = table[entry, c]
            out[i, 3] = 1.0


class TransferFunction:
    """A 1D transfer function: piecewise linear opacity and a colormap over a value domain.

    Parameters
    ----------
    opacity : list of (value, alpha)
        Control points in data units, increasing values, ``alpha`` in [0, 1]: the opacity of a
        one-voxel-thick slab. Constant extrapolation beyond the first and last point.
    domain : (lo, hi)
        The value interval the colormap spans and the pre-integration tables cover (data units).
    colormap : str or list of (position, r, g, b)
        A colormap name (:data:`MENU`, any matplotlib or cmap catalog name) or explicit colour
        control points over ``[0, 1]`` of the domain.

    Examples
    --------
    >>> tf = TransferFunction([(0.4, 0.0), (0.5, 0.8), (0.6, 0.0)], domain=(0, 1))
    >>> float(tf.opacity(0.5)), float(tf.opacity(0.45))
    (0.8, 0.4)
    """

    def __init__(self, opacity: Any, domain: tuple[float, float], colormap: Any = "viridis"):
        pts = _control_points(opacity, 2, "opacity")
        if np.any((pts[:, 1] < 0) | (pts[:, 1] > 1)):
            raise ParameterError("opacity values must be in [0, 1]")
        try:
            lo, hi = (float(v) for v in domain)
        except (TypeError, ValueError, OverflowError):
            raise ParameterError(
                f"domain must be two numbers (lo, hi), got {limits.shorten(domain)}"
            ) from None
        if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
            raise ParameterError(f"domain must be two finite numbers with lo < hi, got {domain}")
        self.opacity_points = pts
        self.domain = (lo, hi)
        self.colormap = colormap if isinstance(colormap, str) else _colormap_points(colormap)
        self._color_points = _colormap_points(colormap)

    # ----------------------------------------------------------------------------- evaluation
    def opacity(self, values: Any) -> np.ndarray:
        """Opacity of a one-voxel slab at ``values``."""
        p = self.opacity_points
        return np.interp(np.asarray(values, np.float64), p[:, 0], p[:, 1])

    def extinction(self, values: Any) -> np.ndarray:
        """Extinction coefficient ``tau = -ln(1 - alpha)`` per voxel length at ``values``."""
        return -np.log1p(-np.minimum(self.opacity(values), _ALPHA_CAP))

    def color(self, values: Any) -> np.ndarray:
        """RGB colour at ``values``, shape ``(..., 3)``."""
        lo, hi = self.domain
        u = np.clip((np.asarray(values, np.float64) - lo) / (hi - lo), 0.0, 1.0)
        c = self._color_points
        return np.stack([np.interp(u, c[:, 0], c[:, k]) for k in (1, 2, 3)], axis=-1)

    def sample(self, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(values, rgb, tau)`` at ``n`` evenly spaced values spanning the domain."""
        values = np.linspace(self.domain[0], self.domain[1], int(n))
        return values, self.color(values), self.extinction(values)

    # ------------------------------------------------------------------ empty-space skipping
    def visible_ranges(self) -> list[tuple[float, float]]:
        """Closed value intervals where the opacity is not zero (exact, from the control points).

        Infinite ends stand for the constant extrapolation beyond the first or last point.
        """
        p = self.opacity_points
        visible: list[tuple[float, float]] = []
        if p[0, 1] > 0:
            visible.append((-math.inf, p[0, 0]))
        for (v0, a0), (v1, a1) in zip(p[:-1], p[1:], strict=True):
            if a0 > 0 or a1 > 0:
                visible.append((float(v0), float(v1)))
        if p[-1, 1] > 0:
            visible.append((p[-1, 0], math.inf))
        merged: list[tuple[float, float]] = []
        for a, b in visible:
            if merged and a <= merged[-1][1]:
                merged[-1] = (merged[-1][0], max(merged[-1][1], b))
            else:
                merged.append((a, b))
        return merged

    def clear_ends(self) -> tuple[float, float]:
        """Values ``(below, above)`` such that the opacity is zero at every value ``<= below``
        and at every value ``>= above`` (exact, from the control points; ``-inf`` / ``inf``
        when the opacity beyond the first / last point is not zero).

        :meth:`visible_ranges` are closed, so a range that only touches one of these ends, such
        as a background of zeros under a ramp starting at 0, meets them; these two values let
        a renderer tell that range transparent.
        """
        p = self.opacity_points
        zero = p[:, 1] <= 0
        if zero.all():
            return math.inf, -math.inf
        first = int(np.argmin(zero))  # the first point with a non-zero opacity
        last = len(zero) - 1 - int(np.argmin(zero[::-1]))
        below = -math.inf if first == 0 else float(p[first - 1, 0])
        above = math.inf if last == len(zero) - 1 else float(p[last + 1, 0])
        return below, above

    def transparency_prefix(self, n: int = 1024) -> np.ndarray:
        """Prefix-sum table ``T`` (int64, length ``n + 1``) over ``n`` equal bins of the domain.

        Bin ``i`` covers ``[lo + i w, lo + (i + 1) w]`` (``w = (hi - lo) / n``); values below or
        above the domain fall into the first or last bin. ``T[0] = 0`` and ``T[i + 1] = T[i] +
        t(i)`` with ``t(i) = 1`` when the opacity is not zero somewhere in bin ``i`` (the first and
        last bins also stand for the extrapolation beyond the domain). Values in bins ``a..b`` are
        all transparent exactly when ``T[b + 1] == T[a]``.
        """
        lo, hi = self.domain
        edges = np.linspace(lo, hi, n + 1)
        opaque = np.zeros(n, dtype=np.int64)
        for a, b in self.visible_ranges():
            first = 0 if a <= lo else int(np.searchsorted(edges, a, side="right")) - 1
            last = n - 1 if b >= hi else int(np.searchsorted(edges, b, side="left")) - 1
            first = min(max(first, 0), n - 1)
            last = min(max(last, first), n - 1)
            opaque[first:last + 1] = 1
        return np.concatenate([[0], np.cumsum(opaque)]).astype(np.int64)

    # --------------------------------------------------------------------------- persistence
    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready description (see :meth:`from_dict`)."""
        cmap = self.colormap if isinstance(self.colormap, str) else self.colormap.tolist()
        return {
            "domain": list(self.domain),
            "opacity": self.opacity_points.tolist(),
            "colormap": cmap,
        }

    @classmethod
    def from_dict(cls, spec: dict[str, Any]) -> TransferFunction:
        """Build from ``{"domain": [lo, hi], "opacity": [[v, a], ...], "colormap": ...}``."""
        if not isinstance(spec, dict) or "opacity" not in spec or "domain" not in spec:
            raise ParameterError("a transfer function needs 'domain' and 'opacity' entries")
        return cls(spec["opacity"], spec["domain"], spec.get("colormap", "viridis"))

    def save(self, path: str | os.PathLike) -> None:
        """Write the transfer function as JSON."""
        Path(path).write_text(json.dumps(self.to_dict(), indent=2) + "\n")

    @classmethod
    def load(cls, path: str | os.PathLike) -> TransferFunction:
        """Read a transfer function written by :meth:`save` (or by hand in the same format).

        The file is read with the bounds of :func:`splinecast.errors.limits.load_json` (size,
        nesting, finite numbers), so any file, even ``/dev/zero``, gives at worst a one-line
        ReadError.
        """
        label = str(limits.check_path_text(path, "transfer function", ReadError))
        spec = limits.load_json(Path(label), label)
        try:
            return cls.from_dict(spec)
        except ParameterError as exc:
            raise ReadError(f"{label}: {exc}") from None

    def __repr__(self) -> str:
        cmap = self.colormap if isinstance(self.colormap, str) else "custom"
        return (f"TransferFunction(domain={self.domain}, "
                f"{len(self.opacity_points)} opacity points, colormap={cmap!r})")
