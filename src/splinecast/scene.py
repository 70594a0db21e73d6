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

from . import limits
from .accel.minmax import MinMaxHierarchy
from .camera import Camera
from .errors import ParameterError
from .models import MODELS
from .render.clipping import make_planes
from .render.dvr import DVRSettings
from .render.effects import SurfaceEffects, apply_effects
from .render.frame import Frame
from .render.iso import METHODS
from .render.kernels import ISO_KERNELS
from .render.modes import render_dvr, render_mip, render_multi_iso
from .render.shading import Shading
from .transfer import TransferFunction
from .volume import Volume

__all__ = ["Scene", "MODES", "check_iso"]

#: Render modes accepted by :meth:`Scene.render`.
MODES = ("iso", "mip", "minip", "dvr")


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
        if hasattr(self.model, "block_hierarchy"):  # models with their own bounds (s31, qss)
            self.hierarchy = self.model.block_hierarchy()
        else:
            self.hierarchy = MinMaxHierarchy(
                self.model.coefficients, self.model.n_cells, self.model.support
            )
        self.prepare_ms = (time.perf_counter() - start) * 1e3
        self.classify_ms = math.nan
        #: Counts and timings of the model's own isovalue change (models with ``classify``).
        self.iso_stats: dict[str, Any] = {}
        self._iso: float | None = None
        self._table_cache: dict = {}  # the last pre-integration table (mode="dvr")

    @property
    def iso(self) -> float | None:
        """The isovalue the block flags are classified for (None before the first)."""
        return self._iso

    def _check_iso(self, iso: Any) -> float:
        return check_iso(self.volume, iso)

    def _active_box_planes(self) -> np.ndarray:
        """Six clip planes around the blocks that can hold the current isovalue (world space).

        Only for models that state where their cells lie (``cell_offset``); others get none. The
        box is padded outwards by a millionth of a voxel so rounding can never cut a hit.
        """
        offset = getattr(self.model, "cell_offset", None)
        bounds = self.hierarchy.active_cell_bounds() if offset is not None else None
        if bounds is None:
            return np.zeros((0, 4))
        origin, spacing = np.asarray(self.volume.origin), np.asarray(self.volume.spacing)
        lo = origin + (bounds[0] + offset - 1e-6) * spacing
        hi = origin + (bounds[1] + offset + 1e-6) * spacing
        rows = []
        for axis in range(3):
            normal = np.zeros(3)
            normal[axis] = 1.0
            rows.append([*normal, -lo[axis]])  # keeps x_axis >= lo
            rows.append([*(-normal), hi[axis]])  # keeps x_axis <= hi
        return np.asarray(rows)

    def set_iso(self, iso: float) -> float:
        """Classify the blocks for a new isovalue; returns the time it took in ms."""
        value = self._check_iso(iso)
        start = time.perf_counter()
        self.hierarchy.classify(value)
        if hasattr(self.model, "classify"):  # models with per-isovalue work lists (s31, qss)
            self.iso_stats = self.model.classify(value)
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
        *,
        clip: Any = None,
        crop: Any = None,
        colors: Any = None,
        opacity: Any = None,
        effects: SurfaceEffects | None = None,
        window: Any = None,
        colormap: Any = "gray",
        tf: TransferFunction | None = None,
        dvr: DVRSettings | None = None,
    ) -> Frame:
        """Render one image.

        Parameters
        ----------
        camera : Camera
            Viewpoint and image size.
        mode : str
            ``"iso"``: first-hit isosurface (or several translucent ones, see ``iso``);
            ``"mip"`` / ``"minip"``: maximum / minimum intensity projection (``Frame.value``);
            ``"dvr"``: direct volume rendering through ``tf``.
        iso : float or list of float, optional
            Isovalue in data units; defaults to the volume's ``metadata["default_iso"]``. A list
            renders every crossing of every isovalue, composited front to back with ``colors``
            and ``opacity`` (trilinear model).
        method : str
            ``"exact"`` (analytic first root per cell, the default) or ``"sampled"`` (fixed step
            plus bisection, the reference common viewers use). For MIP: analytic extrema per
            cell, or samples every ``step`` voxels.
        step : float
            Sampling step of the sampled method, in voxels (index units).
        shading : Shading, optional
            Colours and lighting.
        inside : str, optional
            ``"high"`` or ``"low"``: which side of the isovalue is the object's inside (decides
            front and back faces and the normals' orientation). Defaults to
            ``volume.metadata["inside"]`` or ``"high"``.
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
            MIP/minIP display: value window ``(lo, hi)`` (default: the data range) and colormap.
        tf : TransferFunction
            Transfer function of ``mode="dvr"``.
        dvr : DVRSettings, optional
            Step, pre-integration, adaptive step, early termination, shading of ``mode="dvr"``.

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
        # A model may implement only some iso methods (B-splines: "exact").
        model_methods = getattr(self.model, "methods", tuple(METHODS))
        if mode == "iso" and method not in model_methods:
            raise ParameterError(
                f"method={method!r} is not available for model {self.model.name!r} "
                f"(use {', '.join(model_methods)})"
            )
        if method == "sampled" and not (math.isfinite(step) and step > 0):
            raise ParameterError(f"step must be a positive number of voxels, got {step}")
        limits.check_render(self.volume, camera, mode=mode, method=method, step=step, dvr=dvr)
        inside = inside or self.volume.metadata.get("inside", "high")
        if inside not in ("high", "low"):
            raise ParameterError(f"inside must be 'high' or 'low', got {inside!r}")
        shading = shading or Shading()
        if effects is not None and not isinstance(effects, SurfaceEffects):
            raise ParameterError(f"effects must be a SurfaceEffects, got {type(effects).__name__}")
        planes = make_planes(clip, crop)
        if mode in ("mip", "minip"):
            return render_mip(self.model, self.hierarchy, self.volume, camera, planes,
                              _row_order(camera.height), mode, method, step, window, colormap,
                              shading.background)
        if mode == "dvr":
            return render_dvr(self.model, self.hierarchy, self.volume, camera, planes,
                              _row_order(camera.height), tf, dvr, shading.background,
                              self._table_cache)
        if isinstance(iso, (list, tuple, np.ndarray)):
            if len(iso) == 0:
                raise ParameterError("iso must hold at least one isovalue")
            isos = [self._check_iso(v) for v in iso]
            return render_multi_iso(self.model, self.hierarchy, self.volume, camera, planes,
                                    _row_order(camera.height), isos, colors, opacity,
                                    inside == "high", shading, effects)
        value = self._check_iso(iso)
        classify_ms = 0.0
        if value != self._iso:
            classify_ms = self.set_iso(value)
        user_planes = len(planes)
        planes = np.vstack([planes, self._active_box_planes()])

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
            np.asarray(self.volume.origin), np.asarray(self.volume.spacing), planes,
            _row_order(h),
            METHODS[method], float(step), inside == "high", shading.as_array(),
            rgba, depth, position, normal, face, visited, tested, skipped,
        )
        if effects is not None and effects.active:
            apply_effects(camera.pixel_basis(), shading.as_array(), effects.as_array(), position,
                          normal, face, rgba)
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
        stats.update(self.iso_stats)
        if user_planes:
            stats["planes"] = user_planes
        return Frame(rgba, depth, position, normal, face, visited, tested, skipped, stats)
