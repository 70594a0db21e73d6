"""The :class:`Scene`: a volume with a prepared reconstruction, rendered through cameras.

A scene is prepared once per volume and model (the model's arrays and the min/max block ranges).
Changing the isovalue only re-classifies the blocks (milliseconds); rendering then traces every
pixel in compiled, multi-threaded code.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from .accel.minmax import MinMaxHierarchy
from .camera import Camera
from .errors import ParameterError
from .models import MODELS
from .render.clipping import NO_PLANES
from .render.frame import Frame
from .render.iso import METHODS
from .render.kernels import ISO_KERNELS
from .render.shading import Shading
from .volume import Volume

__all__ = ["Scene", "MODES", "check_iso"]

#: Render modes accepted by :meth:`Scene.render`.
MODES = ("iso",)


def _row_order(height: int) -> np.ndarray:
    """A permutation of rows in which every contiguous run is spread over the whole image.

    Numba hands each thread a contiguous range of the parallel loop; ordering rows by the
    fractional part of ``row * golden ratio`` gives every thread a similar mix of busy and empty
    rows.
    """
    key = (np.arange(height) * 0.6180339887498949) % 1.0
    return np.argsort(key, kind="stable").astype(np.int64)


def check_iso(volume: Volume, iso: Any) -> float:
    """Validate an isovalue for ``volume`` (``None`` means its ``metadata["default_iso"]``).

    Raises
    ------
    ParameterError
        If there is no isovalue, it is not a number, or it lies outside the data range.
    """
    if iso is None:
        iso = volume.metadata.get("default_iso")
        if iso is None:
            raise ParameterError("iso is required (no default isovalue for this volume)")
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


class Scene:
    """A volume, its reconstruction model, and the acceleration structure for rendering.

    Parameters
    ----------
    volume : Volume
        The data to render.
    model : str
        Reconstruction: ``"trilinear"`` (more models plug in by name, see
        :data:`splinecast.models.MODELS`).
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

    def __init__(self, volume: Volume, model: str = "trilinear", **options: Any) -> None:
        if not isinstance(volume, Volume):
            raise ParameterError(f"volume must be a splinecast.Volume, got {type(volume).__name__}")
        if model not in MODELS:
            raise ParameterError(f"model must be one of {', '.join(MODELS)}, got {model!r}")
        start = time.perf_counter()
        self.volume = volume
        self.model = MODELS[model](volume, **options)
        self.hierarchy = MinMaxHierarchy(
            self.model.coefficients, self.model.n_cells, self.model.support
        )
        self.prepare_ms = (time.perf_counter() - start) * 1e3
        self.classify_ms = math.nan
        self._iso: float | None = None

    @property
    def iso(self) -> float | None:
        """The isovalue the block flags are classified for (None before the first)."""
        return self._iso

    def _check_iso(self, iso: Any) -> float:
        return check_iso(self.volume, iso)

    def set_iso(self, iso: float) -> float:
        """Classify the blocks for a new isovalue; returns the time it took in ms."""
        value = self._check_iso(iso)
        start = time.perf_counter()
        self.hierarchy.classify(value)
        self.classify_ms = (time.perf_counter() - start) * 1e3
        self._iso = value
        return self.classify_ms

    def render(
        self,
        camera: Camera,
        mode: str = "iso",
        iso: float | None = None,
        method: str = "exact",
        step: float = 0.25,
        shading: Shading | None = None,
        inside: str | None = None,
    ) -> Frame:
        """Render one image.

        Parameters
        ----------
        camera : Camera
            Viewpoint and image size.
        mode : str
            ``"iso"``: first-hit isosurface.
        iso : float, optional
            Isovalue in data units; defaults to the volume's ``metadata["default_iso"]``.
        method : str
            ``"exact"`` (analytic first root per cell, the default) or ``"sampled"`` (fixed step
            plus bisection, the reference common viewers use).
        step : float
            Sampling step of the sampled method, in voxels (index units).
        shading : Shading, optional
            Colours and lighting.
        inside : str, optional
            ``"high"`` or ``"low"``: which side of the isovalue is the object's inside (decides
            front and back faces and the normals' orientation). Defaults to
            ``volume.metadata["inside"]`` or ``"high"``.

        Returns
        -------
        Frame
        """
        if not isinstance(camera, Camera):
            raise ParameterError(f"camera must be a splinecast.Camera, got {type(camera).__name__}")
        if mode not in MODES:
            raise ParameterError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
        if method not in METHODS:
            raise ParameterError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
        if method == "sampled" and not (math.isfinite(step) and step > 0):
            raise ParameterError(f"step must be a positive number of voxels, got {step}")
        inside = inside or self.volume.metadata.get("inside", "high")
        if inside not in ("high", "low"):
            raise ParameterError(f"inside must be 'high' or 'low', got {inside!r}")
        shading = shading or Shading()
        value = self._check_iso(iso)
        classify_ms = 0.0
        if value != self._iso:
            classify_ms = self.set_iso(value)

        h, w = camera.height, camera.width
        rgba = np.empty((h, w, 4), np.float32)
        depth = np.empty((h, w), np.float64)
        position = np.empty((h, w, 3), np.float64)
        normal = np.empty((h, w, 3), np.float32)
        face = np.empty((h, w), np.int8)
        visited = np.empty((h, w), np.int32)
        tested = np.empty((h, w), np.int32)
        skipped = np.empty((h, w), np.int32)
        act0, act1, act2 = self.hierarchy.active
        start = time.perf_counter()
        ISO_KERNELS[self.model.name](
            self.model.arrays, self.model.params, act0, act1, act2, value, camera.pixel_basis(),
            np.asarray(self.volume.origin), np.asarray(self.volume.spacing), NO_PLANES,
            _row_order(h),
            METHODS[method], float(step), inside == "high", shading.as_array(),
            rgba, depth, position, normal, face, visited, tested, skipped,
        )
        trace_ms = (time.perf_counter() - start) * 1e3
        hits = int(np.count_nonzero(np.isfinite(depth)))
        stats = {
            "mode": mode,
            "model": self.model.name,
            "method": method,
            "iso": value,
            "width": w,
            "height": h,
            "rays": w * h,
            "hits": hits,
            "trace_ms": trace_ms,
            "classify_ms": classify_ms,
            "mean_cells_visited": float(visited.mean()),
            "mean_cells_tested": float(tested.mean()),
            "mean_blocks_skipped": float(skipped.mean()),
        }
        if method == "sampled":
            stats["step"] = float(step)
        return Frame(rgba, depth, position, normal, face, visited, tested, skipped, stats)
