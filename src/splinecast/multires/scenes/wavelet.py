"""A scene of a spline-wavelet store: view-dependent chunks rendered exactly (Steinberger 2010, §4).

``sc.Scene(sc.read("x.zarr"), lod=ε)`` of a store written with ``kind="wavelet"`` returns a
:class:`WaveletScene` (registered in ``splinecast/__init__.py``). Per frame it

1. selects the chunks for the camera (:func:`.wavelet.lod.select`: refine while a level's cell
   looks larger than ``ε`` radians from the eye and the isovalue lies in the chunk's range);
2. reconstructs the selected chunks' B-spline coefficient bricks
   (:class:`.wavelet.reconstruct.ChunkReconstructor`, reusing unchanged bricks across frames; the
   details of a chunk are read from the store the first time it is refined);
3. draws every region the selection shows from its brick with the ``bspline<degree>`` model
   through the cut renderer (:class:`.draw.cut_renderer.CutRenderer`, the segment entry point,
   front to back
   per ray), in any mode of :meth:`splinecast.Scene.render`.

Coefficients, not samples
    A brick *is* a padded B-spline coefficient array (:mod:`.wavelet.layout`), exactly what the
    model's prepared array is for its default smoothing reconstruction (voxels as coefficients),
    so it goes to the kernels as is: nothing is prefiltered, and ``prefilter=True`` is refused.
    Hence the model must be the store's ``bspline<degree>``. With ``ε = 0`` every chunk is
    refined and the image is the in-memory ``bspline<degree>`` render of the source voxels.

Seams
    None need fixing: where levels meet, both bricks evaluate the selection's one global spline
    (:mod:`.wavelet.lod`), continuous (C^(d-1)) by construction.

``frame.stats`` adds ``lod`` (ε), ``chunks`` (reconstructed), ``chunk_share`` (over all chunks
of all levels), ``active_chunks`` (refined), ``select_ms``, ``reconstruct_ms``,
``bricks_computed``, ``bricks_reused``, ``detail_owners`` (chunks whose details entered a brick
this frame), ``details_read`` (detail blocks read this frame), ``resident_bytes`` (bricks and
details cached after the frame, under ``budget``) and the renderer's ``drawables``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...camera import Camera
from ...errors import ParameterError
from ...models import MODELS
from ...render.defaults import auto_iso
from ...render.template import SceneTemplate, Traced, check_iso, whole_frame_tracer
from ...volume import Volume
from ..draw.cut_renderer import CutRenderer, Drawable, gc_paused
from ..store.budget import parse_bytes
from ..wavelet.layout import WaveletLayout
from ..wavelet.lod import Selection, select
from ..wavelet.reconstruct import ChunkReconstructor
from ..wavelet.store import WaveletVolume

__all__ = ["WaveletScene", "WaveletTree", "wavelet_drawables"]


@dataclass(frozen=True)
class _LevelPlacement:
    shape: tuple[int, int, int]
    origin: tuple[float, float, float]
    spacing: tuple[float, float, float]


class _Placement:
    """Level-0 geometry for the front-to-back order (origin at the chunk grid's corner, the
    layout's ``region_start``) and each level's placement for the renderer."""

    def __init__(self, volume: WaveletVolume) -> None:
        lay = volume.layout
        self.spacing = np.asarray(volume.spacing, dtype=np.float64)
        base = np.asarray(volume.origin, dtype=np.float64)
        self.origin = base + lay.region_start * self.spacing
        self._levels = [
            _LevelPlacement(lay.length(j), tuple(base + lay.node_origin(j) * self.spacing),
                            tuple(2.0**j * self.spacing))
            for j in range(lay.levels + 1)
        ]

    def level(self, index: int) -> _LevelPlacement:
        return self._levels[index]


class WaveletTree:
    """The chunk octree of a wavelet layout, in the shape :class:`.draw.cut_renderer.CutRenderer`
    and
    :func:`.draw.order.front_to_back` read (``levels``, ``brick``, ``factors``, ``counts``, ``n0``,
    ``volume``, ``level_map``)."""

    def __init__(self, volume: WaveletVolume) -> None:
        lay = volume.layout
        self.layout = lay
        self.levels = list(range(lay.levels + 1))
        self.brick = lay.chunk
        self.factors = np.array([[2**j] * 3 for j in self.levels], dtype=np.int64)
        self.counts = np.array([lay.chunks(j) for j in self.levels], dtype=np.int64)
        self.n0 = np.asarray(lay.shape, dtype=np.int64)
        self.volume = _Placement(volume)

    def level_map(self, level: int) -> tuple[np.ndarray, np.ndarray]:
        """``level index = level-0 index * scale + offset`` (node ``m`` at voxel
        ``o_j + 2^j m``)."""
        scale = 2.0**-level
        return np.full(3, scale), np.full(3, -self.layout.node_origin(level) * scale)


# Entries of a scene's box cache before it starts over: several frames of the largest
# selections the benchmarks make (about 33 k drawables for a 512^3 store); each entry is a key and
# one to eight small boxes.
_BOXES_KEPT = 200_000


def _region(lay: WaveletLayout, level: int, idx: Sequence[int]) -> tuple[list[float], list[float]]:
    """A chunk's region clipped to the voxel box (level-0 voxel index space): the arithmetic of
    :meth:`.WaveletLayout.region` on Python floats (numpy per scalar cost most of a frame's
    drawable list)."""
    width = lay.chunk * 2.0**level
    start = lay.region_start
    lo, hi = [], []
    for a in range(3):
        top = float(lay.shape[a] - 1)
        first = start + width * int(idx[a])
        lo.append(min(max(first, 0.0), top))
        hi.append(min(max(first + width, 0.0), top))
    return lo, hi


def _boxes(lay: WaveletLayout, level: int, idx: tuple[int, int, int],
           mask: int) -> list[tuple[tuple[int, int, int, int], np.ndarray, np.ndarray]]:
    """``(cut key, lo, hi)`` of what a drawn brick draws: its region, or the octants of it
    whose finer chunk is not reconstructed; empty boxes left out."""
    boxes = []
    if level == 0:
        boxes.append(((0, *idx), _region(lay, 0, idx)))
    else:
        kids = [tuple(2 * idx[a] + ((o >> (2 - a)) & 1) for a in range(3)) for o in range(8)]
        below = lay.chunks(level - 1)
        exist = sum(1 << o for o, kid in enumerate(kids)
                    if all(kid[a] < below[a] for a in range(3)))
        if mask == exist:
            boxes.append(((level, *idx), _region(lay, level, idx)))
        else:
            boxes += [((level - 1, *kids[o]), _region(lay, level - 1, kids[o]))
                      for o in range(8) if mask >> o & 1]
    return [(cut_key, np.array(lo), np.array(hi)) for cut_key, (lo, hi) in boxes
            if hi[0] > lo[0] and hi[1] > lo[1] and hi[2] > lo[2]]


def wavelet_drawables(selection: Selection, reconstructor: ChunkReconstructor,
                      boxes: dict | None = None) -> list[Drawable]:
    """The drawables of a selection: each drawn brick over its region, or over the octants of it
    whose finer chunk is not reconstructed (one drawable per octant, named by that child chunk so
    the front-to-back order sees leaves of one octree). Call ``reconstructor.update`` first.

    ``boxes`` keeps each ``(level, chunk, octant mask)``'s boxes between calls (they depend on
    the layout only): a frame of tens of thousands of drawables otherwise spends most of its
    Python time recomputing them.
    """
    lay = selection.layout
    if boxes is None:
        boxes = {}
    out = []
    for level, idx, mask in selection.drawn():
        drawn = boxes.get((level, idx, mask))
        if drawn is None:
            drawn = boxes[level, idx, mask] = _boxes(lay, level, idx, mask)
        coeffs = reconstructor.coefficients(level, idx)
        key = ("wavelet", level, idx, reconstructor.signature(level, idx))
        first = (lay.chunk * idx[0] - lay.pad, lay.chunk * idx[1] - lay.pad,
                 lay.chunk * idx[2] - lay.pad)
        for cut_key, lo, hi in drawn:
            out.append(Drawable(cut_key, key, level, coeffs, first, lo, hi, placed=True))
    return out


class WaveletScene(SceneTemplate):
    """A spline-wavelet store, the matching B-spline model, a chunk reconstructor and the
    renderer of its selections.

    Parameters
    ----------
    volume : WaveletVolume
        From :func:`splinecast.read` of a store written with ``kind="wavelet"``.
    model : str, optional
        Must be ``"bspline<degree>"`` of the store (the default).
    lod : float, optional
        ε in radians: refine while a level's cell looks larger than ε from the eye (0: render
        the full resolution). Default: the angle of one pixel of each frame's camera.
    budget : int, str or None
        Bytes the reconstructed bricks and the details read from the store may hold together
        (``"512MiB"``; ``None``: unbounded). Least recently used ones not in the current
        selection are dropped to stay under it; a selection that needs more still renders.
    **options
        Model options (``root_finder``, ``iterations``); ``prefilter=True`` is refused (the
        bricks are coefficients already).

    Raises
    ------
    ParameterError
        Another model, a bad ``lod`` or bad options.

    Notes
    -----
    ``render`` is the render template's (:meth:`splinecast.Scene.render`), with this scene's
    frame option ``lod`` (see :meth:`trace`), and antialiasing off by default.
    """

    #: Each further antialiasing sample is traced over the whole image: off unless asked.
    default_samples = 1

    def __init__(self, volume: WaveletVolume, model: str | None = None, lod: float | None = None,
                 budget: Any = "2GiB", **options: Any) -> None:
        if not isinstance(volume, WaveletVolume):
            raise ParameterError(f"volume must be a WaveletVolume, got {type(volume).__name__}")
        expected = f"bspline{volume.degree}"
        if model is None:
            model = expected
        if model != expected:
            raise ParameterError(
                f"model must be {expected} for the degree-{volume.degree} wavelet store "
                f"{volume.name} (its bricks are that spline's coefficients), got {model!r}")
        if options.get("prefilter"):
            raise ParameterError(
                f"prefilter=True does not apply to the wavelet store {volume.name}: its bricks "
                "are B-spline coefficients already")
        options.pop("prefilter", None)
        self._check_lod(lod)
        self.budget = None if budget is None else parse_bytes(budget, "budget")
        start = time.perf_counter()
        self.volume = volume
        lay = volume.layout
        top = lay.levels
        place = WaveletTree(volume)
        coarse = place.volume.level(top)
        #: The coarsest level's coefficients as a volume: the automatic isovalue, window and
        #: transfer function come from it; isovalues are checked against the voxels' range.
        self.preview = Volume(np.ascontiguousarray(volume.pyramid.coarse[top]),
                              spacing=coarse.spacing, origin=coarse.origin,
                              metadata=dict(volume.metadata))
        self.preview._value_range = volume.value_range
        self.model = MODELS[model](self.preview, **options)
        self.lod = lod
        self.reconstructor = ChunkReconstructor(volume.pyramid, loader=volume.read_detail_block,
                                                budget=self.budget, label=str(volume.path))
        self.renderer = CutRenderer(self.model, place, None)
        self.selection: Selection | None = None
        self._boxes: dict = {}  # wavelet_drawables' boxes per (level, chunk, octant mask)
        # (reconstructor version, octant tables, drawables) of the last frame.
        self._last_drawables: tuple[int, list[np.ndarray], list[Drawable]] | None = None
        self.prepare_ms = (time.perf_counter() - start) * 1e3

    @staticmethod
    def _check_lod(lod: Any) -> None:
        if lod is None:
            return
        try:
            value = float(lod)
        except (TypeError, ValueError):
            raise ParameterError(f"lod must be a number of radians >= 0, got {lod!r}") from None
        if not (math.isfinite(value) and value >= 0):
            raise ParameterError(f"lod must be a number of radians >= 0, got {lod!r}")

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """World-space corners of the volume."""
        return self.volume.bounds

    def epsilon(self, camera: Camera, lod: float | None = None) -> float:
        """The ε of a frame: ``lod``, else the scene's, else the angle of one of ``camera``'s
        pixels (its vertical field of view over its height)."""
        for value in (lod, self.lod):
            if value is not None:
                self._check_lod(value)
                return float(value)
        return math.radians(camera.fov) / max(camera.height, 1)

    @property
    def defaults_volume(self) -> Volume:
        """The coarsest level's coefficients (:attr:`preview`): the automatic choices come
        from it."""
        return self.preview

    def check_iso(self, iso: Any) -> float:
        """An isovalue checked against the voxels' range (``None``: the automatic one of the
        coarsest level)."""
        return check_iso(self.volume, auto_iso(self.preview) if iso is None else iso)

    def trace(self, request: Any, camera: Camera, *, lod: float | None = None) -> Traced:
        """The selection of ``camera`` traced in the mode of ``request``: the step of the
        render template (:class:`~splinecast.render.template.SceneTemplate`) a wavelet scene
        supplies. Antialiasing (``samples``) is off by default: each further sample's rays are
        traced for the whole image through the selection.

        Parameters
        ----------
        lod : float, optional
            ε of this frame (a frame option: ``render(camera, ..., lod=ε)``; default: the
            scene's, else one pixel's angle).
        """
        eps = self.epsilon(camera, lod)
        setup = request.setup
        isos = setup.surface_values()
        start = time.perf_counter()
        vol = self.volume
        selection = select(vol.layout, vol.ranges, camera.position, eps, isos, vol.spacing,
                           vol.origin)
        select_ms = (time.perf_counter() - start) * 1e3
        rstats = self.reconstructor.update(selection)
        if len(self._boxes) > _BOXES_KEPT:
            self._boxes.clear()
        with gc_paused():
            last = self._last_drawables
            if (last is not None and last[0] == self.reconstructor.version
                    and all(np.array_equal(a, b)
                            for a, b in zip(last[1], selection.octants, strict=True))):
                # The same bricks drawn the same way, none rewritten: the same list, which
                # lets the renderer keep its draw order and launch arrays (a steady view).
                drawables, reused = last[2], True
            else:
                drawables = wavelet_drawables(selection, self.reconstructor, self._boxes)
                reused = False
                self._last_drawables = (self.reconstructor.version, selection.octants, drawables)
            self.selection = selection
            start = time.perf_counter()
            out, counters = self.renderer.render(drawables, setup, camera, request.planes)
            if not reused:
                self.renderer.forget(p.key for p in drawables)
        stats = request.stats
        stats.update(self.renderer.stats)
        stats.update({
            "lod": eps, "chunks": selection.chunk_count, "chunk_share": selection.share,
            "active_chunks": int(sum(a.sum() for a in selection.active)),
            "select_ms": select_ms, "reconstruct_ms": rstats.milliseconds,
            "bricks_computed": int(sum(rstats.computed)),
            "bricks_reused": int(sum(rstats.reused)),
            "detail_owners": int(sum(u.sum() for u in rstats.detail_owners)),
            "details_read": rstats.details_read, "resident_bytes": rstats.resident_bytes,
        })
        return Traced(out, counters, start,
                      whole_frame_tracer(self.renderer, drawables, request.planes))

    def __repr__(self) -> str:
        return (f"WaveletScene({self.volume.name!r}, model={self.model.name!r}, "
                f"lod={self.lod}, levels={self.volume.layout.levels})")
