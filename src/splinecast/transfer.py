"""Transfer functions and colormaps: how data values become colour and opacity.

A :class:`TransferFunction` maps a data value (in data units, never normalized behind the user's
back) to an RGB colour and an opacity:

* the **opacity** is piecewise linear between control points ``(value, alpha)`` and constant beyond
  the first and last point. ``alpha`` is the opacity of a slab **one voxel thick** (index units)
  of material with that value; the renderers turn it into the extinction coefficient
  ``tau = -ln(1 - alpha)`` per voxel length, so images do not change when the sampling step does;
* the **colour** comes from a named colormap (``viridis``, ``gray``, ``bone``, ``hot``,
  ``coolwarm``) stretched over the transfer function's ``domain``, or from explicit control points
  ``(position in [0, 1], r, g, b)``.

The colormaps are a handful of control points interpolated linearly in RGB (written for
splinecast; they follow the look of the usual maps closely enough for visualization, not
bit-for-bit). Transfer functions round-trip through JSON (:meth:`TransferFunction.save`,
:meth:`TransferFunction.load`).

For empty-space skipping, :meth:`TransferFunction.visible_ranges` gives the value intervals with
non-zero opacity (exact, from the control points), and :meth:`TransferFunction.transparency_prefix`
the prefix-sum table of Carmona & Froehlich 2011 (section 1.5): with ``t(i) = 1`` when table bin
``i`` is not fully transparent and ``T(i) = T(i-1) + t(i)``, a cell whose values lie in bins
``a..b`` is fully transparent exactly when ``T(b + 1) == T(a)``.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np
from numba import prange

from ._jit import jit
from .errors import ParameterError, ReadError, limits

__all__ = ["COLORMAPS", "TransferFunction", "colormap_table", "apply_colormap"]

#: Colormaps as control points ``(position, r, g, b)``, interpolated linearly in RGB.
COLORMAPS: dict[str, tuple[tuple[float, float, float, float], ...]] = {
    "gray": ((0.0, 0.0, 0.0, 0.0), (1.0, 1.0, 1.0, 1.0)),
    "viridis": (
        (0.00, 0.267, 0.005, 0.329),
        (0.13, 0.283, 0.141, 0.458),
        (0.25, 0.229, 0.322, 0.546),
        (0.38, 0.172, 0.448, 0.558),
        (0.50, 0.128, 0.567, 0.551),
        (0.63, 0.153, 0.680, 0.504),
        (0.75, 0.369, 0.789, 0.383),
        (0.88, 0.678, 0.864, 0.190),
        (1.00, 0.993, 0.906, 0.144),
    ),
    "bone": (
        (0.000, 0.000, 0.000, 0.000),
        (0.375, 0.326, 0.326, 0.451),
        (0.750, 0.652, 0.777, 0.777),
        (1.000, 1.000, 1.000, 1.000),
    ),
    "hot": (
        (0.000, 0.040, 0.000, 0.000),
        (0.375, 1.000, 0.000, 0.000),
        (0.750, 1.000, 1.000, 0.000),
        (1.000, 1.000, 1.000, 1.000),
    ),
    "coolwarm": (
        (0.0, 0.230, 0.299, 0.754),
        (0.5, 0.865, 0.865, 0.865),
        (1.0, 0.706, 0.016, 0.150),
    ),
}

# Opacity is capped just below 1 so the extinction -ln(1 - alpha) stays finite.
_ALPHA_CAP = 1.0 - 1e-6


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
        if colormap not in COLORMAPS:
            raise ParameterError(
                f"colormap must be one of {', '.join(COLORMAPS)}, got {limits.shorten(colormap)}"
            )
        return np.asarray(COLORMAPS[colormap], dtype=np.float64)
    pts = _control_points(colormap, 4, "colormap")
    if np.any((pts < 0) | (pts > 1)):
        raise ParameterError("colormap points must be (position, r, g, b) numbers in [0, 1]")
    return pts


def colormap_table(colormap: Any = "gray", n: int = 256) -> np.ndarray:
    """The colormap sampled at ``n`` evenly spaced positions of ``[0, 1]``: shape (n, 3).

    ``colormap`` is a name of :data:`COLORMAPS` or control points ``(position, r, g, b)``.
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
    _colormap_pixels(values.reshape(-1), lo, span, table, np.asarray(background, np.float32),
                     rgba.reshape(-1, 4))
    return rgba


@jit(parallel=True)
def _colormap_pixels(values, lo, span, table, background, out):  # pragma: no cover - compiled
    """``out[i]``: the ``table`` colour nearest ``(values[i] - lo) / span`` (clamped to [0, 1])
    with alpha 1, or ``background`` where the value is NaN."""
    top = table.shape[0] - 1
    for i in prange(values.shape[0]):
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
        A name of :data:`COLORMAPS` or explicit colour control points over ``[0, 1]`` of the
        domain.

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
        pieces: list[tuple[float, float]] = []
        if p[0, 1] > 0:
            pieces.append((-math.inf, p[0, 0]))
        for (v0, a0), (v1, a1) in zip(p[:-1], p[1:], strict=True):
            if a0 > 0 or a1 > 0:
                pieces.append((float(v0), float(v1)))
        if p[-1, 1] > 0:
            pieces.append((p[-1, 0], math.inf))
        merged: list[tuple[float, float]] = []
        for a, b in pieces:
            if merged and a <= merged[-1][1]:
                merged[-1] = (merged[-1][0], max(merged[-1][1], b))
            else:
                merged.append((a, b))
        return merged

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
