"""Sort-last rendering on Dask: the bricks of one level of an OME-Zarr pyramid spread over the
workers, their partial images composited in visibility order on the workers.

Shares of bricks
    The level's bricks (:class:`~splinecast.multires.cut.octree.BrickOctree`, ``B`` cells each) are
    cut into ``P`` boxes of bricks by a k-d split (:func:`split_bricks`): the longest side of a
    box (in bricks) is cut in proportion to the number of parts on each side, recursively, until
    every part is one box. ``P`` is the number of workers (at most the number of bricks); part
    ``p`` is a :class:`Share`, pinned to worker ``p``. A worker opens the store itself, reads the
    bricks of its share once (:func:`splinecast.multires.store.cache.read_bricks`: the chunks of its
    bricks, and of the neighbouring chunks the two ghost layers reach into, which every model's
    support needs) and keeps them between renders, like the sort-first workers keep their scene.

Partial images
    Each worker traces its bricks front to back per ray through the segment entry point
    (:class:`~splinecast.multires.draw.cut_renderer.CutRenderer`, the multiresolution renderer of a
    cut whose
    bricks all come from this level) into the mode's per-pixel state, without finishing it: iso
    keeps the nearest hit and its gradient, MIP the extreme value and where, DVR the
    premultiplied colour and opacity, the depth where the opacity passed 1/2 and the segment
    count. Only the screen rectangle the share's box projects to is traced and shipped.

Visibility order
    The k-d split is a BSP tree whose split planes are brick faces. A ray crosses a plane at most
    once, from the eye's side to the other (orthographic: from the side the rays come from), so
    at every node the child on the eye's side is in front along every ray of the camera that
    meets both. The partial images are therefore merged pairwise up that tree with the mode's
    ``combine`` (:func:`splinecast.render.segment.combine_states`: nearest hit, larger value,
    front over back): one Dask task per node, which the scheduler runs where one of its inputs
    already lives, and a last task that turns the root's state into the :class:`Frame`. The
    client receives that frame only (``log2 P`` levels of combining; ``P - 1`` partial images
    move between workers at most).

Equality
    Iso and MIP merges pick one of two states, so the frame is bit for bit the single-process
    render of the same bricks, front to back (``MultiscaleScene``'s cut renderer) and equals the
    in-memory ``Scene.render`` of the level as closely as that renderer does (rays restricted to
    bricks: depths to about 1e-12). DVR's "over" regroups the sums: colours within rounding
    (1e-12) with a fixed step. Early ray termination (``DVRSettings(termination=...)``) and the
    opacity-adaptive step depend on the opacity in front of a segment, which a share does not
    know: they act per share, and the image differs from the single-process one by up to what
    they leave out.

DVR depth
    A DVR frame's depth is where the ray's opacity first reaches 1/2. A share that starts from
    zero opacity places that point where *its own* opacity reaches 1/2, which is right only where
    nothing lies in front of it. So a DVR render adds a second, small round of tasks: the
    opacity in front of every share (top down through the k-d tree: a front child sees its
    parent's, a back child that over the front child's partial image, :func:`opacity_behind`),
    then each share traces again only the pixels where the opacity passes 1/2 inside it, starting
    from the opacity in front (:func:`refine_dvr_depth`), and the final task puts those depths
    in. The depth is then the single-process render's wherever the colours are (a fixed step, no
    early termination); the extra tracing is limited to the pixels whose crossing lies behind
    another share.

Defaults: the automatic isovalue, MIP window and transfer function come from the pyramid's
coarsest level, read by the client (as
:class:`~splinecast.multires.scenes.multiscale.MultiscaleScene` does);
the isovalue is checked against the level's value range (the union of the bricks' ranges the
workers report). Pass them explicitly to reproduce a render of another scene.
"""

from __future__ import annotations

import dataclasses
import os
import threading
import time
from collections import OrderedDict
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..camera import Camera
from ..errors import ParameterError, SplinecastError
from ..io import read
from ..io.omezarr import MultiscaleVolume, is_zarr
from ..io.remote import is_url
from ..models import MODELS
from ..multires.cut.octree import DEFAULT_BRICK, BrickOctree
from ..multires.draw.cut_renderer import CutRenderer, Drawable, screen_rect
from ..multires.store.cache import read_bricks
from ..render.frame import Frame
from ..render.segment import combine_states, counters, finish_state, new_state
from ..render.template import (
    RenderOptions,
    SceneTemplate,
    check_iso,
    finish_frame,
    prepare_render,
)
from ..volume import Volume
from . import worker
from .source import SceneSource, VolumeInfo

if TYPE_CHECKING:
    from distributed import Client, Future

__all__ = ["SortLastScene", "Share", "KdNode", "split_bricks", "Partial"]

#: Bricks read per store read while a worker loads its share (a box of up to 4^3 bricks: one
#: decode of each chunk of the box, ghost chunks shared with its neighbours).
_READ_GROUP = 4
#: Render requests (validated options and mode tables) a worker keeps.
_MAX_REQUESTS = 4


# --------------------------------------------------------------------------- the k-d split
@dataclass(frozen=True)
class KdNode:
    """A node of the k-d split of a level's bricks.

    A leaf holds ``part`` (the share's number) and its brick box ``[lo, hi)``; an inner node
    splits its box at brick index ``at`` along ``axis`` into ``low`` (``< at``) and ``high``.
    """

    lo: tuple[int, int, int]
    hi: tuple[int, int, int]
    part: int = -1
    axis: int = -1
    at: int = 0
    low: KdNode | None = None
    high: KdNode | None = None

    @property
    def leaf(self) -> bool:
        return self.low is None

    def leaves(self) -> list[KdNode]:
        """The leaves, in part order."""
        if self.leaf:
            return [self]
        return sorted(self.low.leaves() + self.high.leaves(), key=lambda n: n.part)  # type: ignore

    def depth(self) -> int:
        """Levels of combining below this node (0 for a leaf)."""
        return 0 if self.leaf else 1 + max(self.low.depth(), self.high.depth())  # type: ignore


def split_bricks(counts: Any, parts: int) -> KdNode:
    """Cut a grid of ``counts`` bricks (per axis) into ``parts`` boxes by a k-d split.

    The longest side of a box (ties: x before y before z) is cut in proportion to the parts on
    each side (``parts // 2`` below the cut), so the boxes have about the same number of bricks.

    Raises
    ------
    ParameterError
        If ``parts`` is not between 1 and the number of bricks.
    """
    counts = tuple(int(c) for c in counts)
    total = int(np.prod(counts))
    if not isinstance(parts, (int, np.integer)) or not 1 <= parts <= total:
        raise ParameterError(f"parts must be an integer from 1 to the {total} bricks of the "
                             f"level, got {parts!r}")
    next_part = iter(range(parts))

    def build(lo: tuple[int, ...], hi: tuple[int, ...], n: int) -> KdNode:
        if n == 1:
            return KdNode(lo, hi, part=next(next_part))  # type: ignore[arg-type]
        size = [h - low for low, h in zip(lo, hi, strict=True)]
        axis = int(np.argmax(size))
        n_low = n // 2
        at = lo[axis] + max(1, min(size[axis] - 1, round(size[axis] * n_low / n)))
        # Enough bricks on each side for its parts (boxes of a box with >= n bricks).
        side = int(np.prod(size)) // size[axis]
        at = min(max(at, lo[axis] + -(-n_low // side)), hi[axis] - -(-(n - n_low) // side))
        hi_low = tuple(at if a == axis else h for a, h in enumerate(hi))
        lo_high = tuple(at if a == axis else low for a, low in enumerate(lo))
        low = build(lo, hi_low, n_low)
        high = build(lo_high, hi, n - n_low)
        return KdNode(lo, hi, axis=axis, at=at, low=low, high=high)  # type: ignore[arg-type]

    return build((0, 0, 0), counts, int(parts))


# --------------------------------------------------------------------------- shares
@dataclass(frozen=True)
class Share:
    """What one worker renders: the bricks ``[lo, hi)`` (brick indices) of a level of a store.

    Attributes
    ----------
    source : SceneSource
        The store's path, the model and its options.
    level : int
        Store level (0 finest).
    brick : int
        Cells per brick.
    part : int
        The share's number in the k-d split.
    lo, hi : 3 ints
        Brick index box of the share.
    """

    source: SceneSource
    level: int
    brick: int
    part: int
    lo: tuple[int, int, int]
    hi: tuple[int, int, int]

    @property
    def n_bricks(self) -> int:
        return int(np.prod(np.subtract(self.hi, self.lo)))


@dataclass
class Partial:
    """A partial image: the mode's per-pixel state over the screen rectangle ``rect``
    (``(col0, row0, width, height)``; ``None``: the share is not seen) and the per-ray
    counters, plus what the tasks measured."""

    rect: tuple[int, int, int, int] | None
    state: tuple = ()
    counts: tuple = ()
    stats: dict[str, Any] = field(default_factory=dict)

    @property
    def nbytes(self) -> int:
        return int(sum(a.nbytes for a in (*self.state, *self.counts)))

    def __sizeof__(self) -> int:
        # What Dask's sizeof sees: its memory accounting and its choice of the worker that
        # merges two partial images (where the larger input already is) depend on it.
        return self.nbytes + 256


def level_view(volume: MultiscaleVolume, level: int) -> MultiscaleVolume:
    """A one-level multiscale volume holding only ``level`` of ``volume``: its bricks are then
    the bricks of a volume of the level's own shape, spacing and origin (rendered exactly like
    the level's in-memory :class:`~splinecast.Volume`)."""
    lv = volume.level(level)
    return MultiscaleVolume(path=volume.path, levels=[lv], metadata=dict(volume.metadata),
                            attributes={"brick": volume.brick} if volume.brick else {})


class _Loaded:
    """A share opened in a worker process: its bricks as drawables and the renderer of a cut."""

    def __init__(self, share: Share) -> None:
        start = time.perf_counter()
        source = share.source
        volume = read(source.location)
        if not isinstance(volume, MultiscaleVolume):  # checked on the client too
            raise ParameterError(f"{source.location} is not an OME-Zarr image")
        view = level_view(volume, share.level)
        self.octree = BrickOctree(view, brick=share.brick)
        index = np.indices(np.subtract(share.hi, share.lo)).reshape(3, -1).T + share.lo
        border = MODELS[source.model].border_rule
        bricks = []
        group = index // _READ_GROUP
        for g in np.unique(group, axis=0):
            keys = [(0, *map(int, idx)) for idx in index[np.all(group == g, axis=1)]]
            bricks += read_bricks(view, self.octree, keys, border)
        lv = view.level(0)
        small = Volume(bricks[0].data, spacing=lv.spacing, origin=lv.origin)
        self.model = MODELS[source.model](small, **dict(source.options))
        self.renderer = CutRenderer(self.model, self.octree, None)
        lo, hi = self.octree.box(0, index)
        self.drawables = [Drawable((0, *b.key[1:]), b.key, 0, b.data, b.first, lo[n], hi[n])
                       for n, b in enumerate(bricks)]
        boxes = [self.renderer.box(p)[:2] for p in self.drawables]
        #: The share's box as drawn, in the level's index space.
        self.box_lo = np.min([b[0] for b in boxes], axis=0)
        self.box_hi = np.max([b[1] for b in boxes], axis=0)
        origin, spacing = np.asarray(lv.origin), np.asarray(lv.spacing)
        corners = [origin + self.box_lo * spacing, origin + self.box_hi * spacing]
        #: World box of the share's bricks (as drawn), for the screen rectangle.
        self.world_lo, self.world_hi = np.minimum(*corners), np.maximum(*corners)
        values = [b.data[np.isfinite(b.data)] if b.data.dtype.kind == "f" else b.data
                  for b in bricks]
        self.value_range = (float(min(v.min() for v in values if v.size)),
                            float(max(v.max() for v in values if v.size)))
        self.bytes_read = int(sum(b.data.nbytes for b in bricks))
        self.load_ms = (time.perf_counter() - start) * 1e3


_loaded: OrderedDict[Share, _Loaded] = OrderedDict()
_requests: OrderedDict[str, Any] = OrderedDict()
_cache_lock = threading.RLock()


def _share(share: Share) -> _Loaded:
    loaded = _loaded.get(share)
    if loaded is not None:
        _loaded.move_to_end(share)
        return loaded
    try:
        loaded = _Loaded(share)
    except SplinecastError as exc:
        where = worker._where()
        if not where:
            raise
        raise type(exc)(f"{where}{exc}") from None
    _loaded[share] = loaded
    while len(_loaded) > 4 * worker.MAX_SCENES:
        _loaded.popitem(last=False)
    return loaded


def _request(token: str, header: VolumeInfo, camera: Camera, options: dict[str, Any]) -> Any:
    """The validated render request (mode, tables, clip planes) of ``options``, kept per
    ``token`` so that the combine tasks on this worker do not build the mode again."""
    request = _requests.get(token)
    if request is None:
        request = prepare_request(header, camera, options)
        _requests[token] = request
        while len(_requests) > _MAX_REQUESTS:
            _requests.popitem(last=False)
    return request


def prepare_request(header: VolumeInfo, camera: Camera, options: dict[str, Any]) -> Any:
    """:func:`splinecast.render.template.prepare_render` of ``Scene.render`` options (the
    fields of :class:`~splinecast.render.template.RenderOptions`, by name) for a level: on the
    client to check them, on the workers to build the mode."""
    opts = RenderOptions(**options)
    # The partial images of the shares hold no pixel's neighbours: no antialiasing.
    if opts.samples not in (None, 1):
        raise ParameterError("samples: sort-last frames are not antialiased (sort-first "
                             "frames are), pass samples=1 or leave it out")
    return prepare_render(
        header, camera, opts.mode, opts.iso, opts.method, opts.step, opts.shading, opts.inside,
        clip=opts.clip, crop=opts.crop, colors=opts.colors, opacity=opts.opacity,
        effects=opts.effects, window=opts.window, colormap=opts.colormap, tf=opts.tf,
        dvr=opts.dvr, table_cache={}, check_iso=lambda v: check_iso(header, v),
        model=header.metadata.get("model", ""), outputs=opts.outputs, tolerance=opts.tolerance,
        normals=opts.normals, samples=1)


def prepare_share(share: Share) -> dict[str, Any] | SplinecastError:
    """Worker task: read the share's bricks (once per process) and report their value range,
    bytes and load time; a user error is returned, not raised (as :func:`.worker.prepare`)."""
    with worker._lock, _cache_lock:
        try:
            loaded = _share(share)
        except SplinecastError as exc:
            return exc
        return {"value_range": loaded.value_range, "bytes_read": loaded.bytes_read,
                "box_lo": loaded.box_lo.tolist(), "box_hi": loaded.box_hi.tolist(),
                "load_ms": loaded.load_ms, "bricks": len(loaded.drawables)}


def render_share(share: Share, camera: Camera, options: dict[str, Any], header: VolumeInfo,
                 token: str) -> Partial:
    """Worker task: the partial image of a share (its bricks front to back, state unfinished)
    over the screen rectangle its box projects to."""
    with worker._lock, _cache_lock:
        worker._use_worker_threads()
        start = time.perf_counter()
        loaded = _share(share)
        request = _request(token, header, camera, options)
        rect = screen_rect(camera, loaded.world_lo, loaded.world_hi)
        if rect is None:
            return Partial(None, stats={"trace_ms": [0.0], "combine_ms": 0.0, "moved": 0})
        full = rect == (0, 0, camera.width, camera.height)
        tile = camera if full else camera.tile(*rect)
        state = new_state(request.setup, tile)
        counts = counters(tile.height, tile.width)
        loaded.renderer.trace(loaded.drawables, request.setup, tile, state, counts, request.planes)
        part = Partial(rect, state, counts)
        part.stats = {"trace_ms": [(time.perf_counter() - start) * 1e3], "combine_ms": 0.0,
                      "moved": 0, "drawables_traced": loaded.renderer.stats["drawables_traced"]}
        return part


def forget_shares(shares: list[Share]) -> int:
    """Drop this process's bricks of ``shares``; how many shares it held."""
    with _cache_lock:
        gone = [s for s in shares if _loaded.pop(s, None) is not None]
        return len(gone)


def _union(a: tuple[int, int, int, int], b: tuple[int, int, int, int]) -> tuple[int, ...]:
    c0, r0 = min(a[0], b[0]), min(a[1], b[1])
    c1, r1 = max(a[0] + a[2], b[0] + b[2]), max(a[1] + a[3], b[1] + b[3])
    return c0, r0, c1 - c0, r1 - r0


def _widen(part: Partial, rect: tuple[int, ...], setup: Any, camera: Camera) -> tuple:
    """``part``'s state and counters over the larger rectangle ``rect`` (fresh states, which
    every mode's combine leaves unchanged, elsewhere)."""
    if part.rect == rect:
        return part.state, part.counts
    c0, r0, w, h = rect
    state = new_state(setup, camera.tile(c0, r0, w, h))
    counts = counters(h, w)
    pc, pr, pw, ph = part.rect  # type: ignore[misc]
    window = (slice(pr - r0, pr - r0 + ph), slice(pc - c0, pc - c0 + pw))
    for full, window_values in zip((*state, *counts), (*part.state, *part.counts), strict=True):
        full[window] = window_values
    return state, counts


def combine_partials(front: Partial, back: Partial, camera: Camera, options: dict[str, Any],
                     header: VolumeInfo, token: str) -> Partial:
    """Worker task: ``front`` over ``back`` (the mode's combine of the same rays' states)."""
    with worker._lock, _cache_lock:
        worker._use_worker_threads()
        start = time.perf_counter()
        stats = {"trace_ms": front.stats["trace_ms"] + back.stats["trace_ms"],
                 "combine_ms": front.stats["combine_ms"] + back.stats["combine_ms"],
                 "moved": front.stats["moved"] + back.stats["moved"] + front.nbytes
                 + back.nbytes,
                 "drawables_traced": (front.stats.get("drawables_traced", 0)
                                   + back.stats.get("drawables_traced", 0))}
        if front.rect is None or back.rect is None:
            out = back if front.rect is None else front
            return Partial(out.rect, out.state, out.counts, stats)
        setup = _request(token, header, camera, options).setup
        rect = _union(front.rect, back.rect)
        f_state, f_counts = _widen(front, rect, setup, camera)
        b_state, b_counts = _widen(back, rect, setup, camera)
        state = combine_states(setup, f_state, b_state)
        counts = tuple(a + b for a, b in zip(f_counts, b_counts, strict=True))
        stats["combine_ms"] += (time.perf_counter() - start) * 1e3
        return Partial(rect, state, counts, stats)  # type: ignore[arg-type]


def opacity_behind(prefix: np.ndarray | None, front: Partial,
                   camera: Camera) -> np.ndarray | None:
    """Worker task (DVR): the opacity per pixel in front of a back child, ``prefix`` (the
    opacity in front of the parent; ``None``: nothing) over the front child's opacity, with the
    formula of the DVR combine."""
    if front.rect is None:
        return prefix
    alpha = np.zeros((camera.height, camera.width)) if prefix is None else prefix.copy()
    c0, r0, w, h = front.rect
    window = alpha[r0:r0 + h, c0:c0 + w]
    window += (1.0 - window) * front.state[0][..., 3]
    return alpha


#: What a DVR pixel's opacity is set to so that the trace leaves it alone: every threshold of
#: early termination is at most 2 (``DVRSettings(termination=None)`` uses 2).
_SKIP_OPACITY = 2.0


def refine_dvr_depth(share: Share, camera: Camera, options: dict[str, Any], header: VolumeInfo,
                     token: str, prefix: np.ndarray | None,
                     own: Partial) -> tuple[tuple[int, int, int, int], np.ndarray, float] | None:
    """Worker task (DVR): the half-opacity depth of the pixels whose opacity passes 1/2 inside
    this share but had some opacity in front of it.

    Those pixels are traced again through the share's bricks, starting from the opacity in
    front (``prefix``), so the sample where the running opacity reaches 1/2 is found as the
    single-process ray finds it. Returns the bounding rectangle of those pixels, their depths
    (``inf`` elsewhere in it) and the time the second trace took (ms), or ``None`` when the share
    has none.
    """
    if prefix is None or own.rect is None:
        return None  # nothing in front of this share: its own depth is the ray's
    c0, r0, w, h = own.rect
    front = prefix[r0:r0 + h, c0:c0 + w]
    alpha = own.state[0][..., 3]
    cross = (front > 0.0) & (front < 0.5) & (front + (1.0 - front) * alpha >= 0.5)
    if not cross.any():
        return None
    rows, cols = np.nonzero(cross)
    a0, a1, b0, b1 = rows.min(), rows.max() + 1, cols.min(), cols.max() + 1
    rect = (int(c0 + b0), int(r0 + a0), int(b1 - b0), int(a1 - a0))
    cross = cross[a0:a1, b0:b1]
    with worker._lock, _cache_lock:
        worker._use_worker_threads()
        start = time.perf_counter()
        loaded = _share(share)
        request = _request(token, header, camera, options)
        tile = camera.tile(*rect)
        state = new_state(request.setup, tile)
        state[0][..., 3] = np.where(cross, front[a0:a1, b0:b1], _SKIP_OPACITY)
        counts = counters(tile.height, tile.width)
        loaded.renderer.trace(loaded.drawables, request.setup, tile, state, counts, request.planes)
        ms = (time.perf_counter() - start) * 1e3
    return rect, np.where(cross, state[1], np.inf), ms


def finish_partial(part: Partial, camera: Camera, options: dict[str, Any], header: VolumeInfo,
                   token: str, *depths: tuple[tuple[int, int, int, int], np.ndarray, float] | None
                   ) -> Frame:
    """Worker task: the :class:`Frame` of the root's partial image (shading, colours), with the
    DVR depths of :func:`refine_dvr_depth` put in."""
    with worker._lock, _cache_lock:
        worker._use_worker_threads()
        start = time.perf_counter()
        request = _request(token, header, camera, options)
        setup = request.setup
        if part.rect is None:
            part = Partial((0, 0, camera.width, camera.height),
                           new_state(setup, camera), counters(camera.height, camera.width),
                           part.stats)
        state, counts = _widen(part, (0, 0, camera.width, camera.height), setup, camera)
        refined, refine_ms = 0, 0.0
        for item in depths:
            if item is None:
                continue
            (c0, r0, w, h), depth, ms = item
            refine_ms += ms
            window = state[1][r0:r0 + h, c0:c0 + w]
            found = np.isfinite(depth)
            # A crossing the second trace missed by rounding keeps the share's own depth.
            window[found] = depth[found]
            refined += int(found.sum())
        out = finish_state(setup, state, camera)
        # Fresh stats: the cached request is shared by renders of the same options.
        request = dataclasses.replace(request, stats=dict(request.stats))
        frame = finish_frame(request, out, counts, camera, start)
        trace = part.stats["trace_ms"]
        frame.stats.update({
            "strategy": "sort-last",
            "share_trace_ms_max": float(max(trace)),
            "share_trace_ms_sum": float(sum(trace)),
            "composite_ms": float(part.stats["combine_ms"]),
            "partial_bytes": int(part.stats["moved"] + part.nbytes),
            "drawables_traced": int(part.stats.get("drawables_traced", 0)),
        })
        if setup.refines_depth_after_compositing:
            frame.stats["depth_refined_pixels"] = refined
            frame.stats["depth_refine_ms"] = refine_ms
        frame.stats["finish_ms"] = (time.perf_counter() - start) * 1e3
        return frame


# --------------------------------------------------------------------------- the client
class SortLastScene(SceneTemplate):
    """One level of an OME-Zarr pyramid spread over the workers of a Dask cluster, rendered
    sort-last (bricks per worker, partial images composited in visibility order on the workers).

    Usually made by ``DistributedScene(store, client, model, strategy="sort-last", level=k)``;
    ``render`` is the render template's (:meth:`splinecast.Scene.render`: the same arguments)
    and returns the same :class:`Frame` as
    ``Scene(sc.read(store).level(k).to_volume(), model).render(...)`` (see
    :meth:`render_frame`).

    Parameters
    ----------
    source : str or os.PathLike
        Path of an OME-Zarr image (a pyramid of :func:`splinecast.build_pyramid`, or any
        OME-Zarr image :func:`splinecast.read` opens) that every worker can open.
    client : distributed.Client, optional
        The cluster (default: the current client).
    model : str
        Reconstruction model (:data:`splinecast.MODELS`).
    level : int
        The pyramid level to render (0: finest).
    parts : int, optional
        Shares of bricks (default: one per worker present now, at most one per brick).
    brick : int, optional
        Cells per brick (default: the pyramid's, else 32).
    **options
        Model options (not ``prefilter=True`` for the B-spline models: their interpolating
        coefficients need the whole volume).

    Attributes
    ----------
    volume : VolumeInfo
        The level's header (shape, spacing, origin, value range of its bricks): aim cameras
        at it (``Camera.orbit(scene.volume, ...)``).
    tree : KdNode
        The k-d split of the level's bricks; ``shares`` its leaves, ``workers[p]`` the worker
        share ``p`` is pinned to.
    load_stats : list of dict
        Per share: bricks, bytes read, load time (ms).

    Raises
    ------
    ParameterError
        A source that is not an OME-Zarr store, a level it does not have, a bad model, option,
        brick size or ``parts``.
    ReadError
        A worker cannot read its bricks (the message names the worker and the chunk).

    Examples
    --------
    >>> from distributed import Client, LocalCluster                       # doctest: +SKIP
    >>> client = Client(LocalCluster(n_workers=2, threads_per_worker=1))   # doctest: +SKIP
    >>> scene = DistributedScene("big.zarr", client, model="trilinear",
    ...                          strategy="sort-last", level=1)            # doctest: +SKIP
    >>> cam = sc.Camera.orbit(scene.volume, size=(1024, 1024))             # doctest: +SKIP
    >>> frame = scene.render(cam, mode="mip")                              # doctest: +SKIP
    """

    def __init__(self, source: str | os.PathLike, client: Client | None = None,
                 model: str = "trilinear", *, level: int = 0, parts: int | None = None,
                 brick: int | None = None, **options: Any) -> None:
        from distributed import Client, get_client

        if isinstance(source, SceneSource):
            source = source.location
        if not isinstance(source, (str, os.PathLike)) or str(source).startswith("demo:"):
            raise ParameterError(f"source must be the path of an OME-Zarr store for "
                                 f"strategy='sort-last', got {source!r}")
        location = SceneSource(source, model, options).location
        if not is_url(location) and not is_zarr(Path(location)):
            raise ParameterError(f"source must be an OME-Zarr store for strategy='sort-last' "
                                 f"(bricks are read per worker), got {location}")
        refusal = MODELS[model].brick_refusal(options) if model in MODELS else None
        if refusal is not None:
            raise ParameterError(f"{refusal.option} is not available for model {model} with "
                                 f"strategy='sort-last': {refusal.reason}")
        volume = read(location)
        if not isinstance(volume, MultiscaleVolume):
            raise ParameterError(f"source must be an OME-Zarr image for strategy='sort-last', "
                                 f"got {location}")
        n_levels = len(volume.levels)
        if isinstance(level, bool) or not isinstance(level, (int, np.integer)) or not (
                0 <= level < n_levels):
            raise ParameterError(f"level must be an integer from 0 to {n_levels - 1} (the levels "
                                 f"of {location}), got {level!r}")
        brick = int(brick or volume.brick or DEFAULT_BRICK)
        if brick < 2:
            raise ParameterError(f"brick must be at least 2, got {brick}")
        if client is None:
            try:
                client = get_client()
            except ValueError:
                raise ParameterError("a sort-last scene needs a Dask client: pass client= or "
                                     "create a distributed.Client first") from None
        if not isinstance(client, Client):
            raise ParameterError(f"client must be a distributed.Client, got "
                                 f"{type(client).__name__}")
        self.client = client
        self.source = SceneSource(location, model, options)
        self.level = int(level)
        self.brick = brick
        lv = volume.level(self.level)
        octree = BrickOctree(level_view(volume, self.level), brick=brick)
        self.counts = tuple(int(c) for c in octree.counts[0])
        addresses = sorted(client.nthreads())
        total = int(np.prod(self.counts))
        parts = min(max(1, len(addresses)), total) if parts is None else parts
        self.tree = split_bricks(self.counts, parts)
        self.shares = [Share(self.source, self.level, brick, leaf.part, leaf.lo, leaf.hi)
                       for leaf in self.tree.leaves()]
        self.workers = [addresses[p % len(addresses)] if addresses else None
                        for p in range(len(self.shares))]
        self.load_stats = self._load()
        lo = min(s["value_range"][0] for s in self.load_stats)
        hi = max(s["value_range"][1] for s in self.load_stats)
        self.volume = self._header(volume, lv, (lo, hi))

    def _submit(self, fn: Any, *args: Any, part: int | None = None, **kw: Any) -> Future:
        where = {} if part is None or self.workers[part] is None else {
            "workers": [self.workers[part]], "allow_other_workers": True}
        return self.client.submit(fn, *args, pure=False, **where, **kw)

    def _load(self) -> list[dict[str, Any]]:
        """Every share read on its worker (in parallel); the first user error is raised."""
        futures = [self._submit(prepare_share, s, part=s.part) for s in self.shares]
        results = self.client.gather(futures)
        errors = [r for r in results if isinstance(r, SplinecastError)]
        if errors:
            n = len(errors) - 1
            others = f" (also on {n} other worker{'s' if n > 1 else ''})" if n else ""
            raise type(errors[0])(f"{errors[0]}{others}")
        return results

    def _header(self, volume: MultiscaleVolume, lv: Any, value_range: tuple) -> VolumeInfo:
        """The level's geometry and value range, with the automatic choices of the coarsest
        level (read here, on the client)."""
        coarse = volume.level(-1)
        preview = Volume(coarse.read((0, 0, 0), coarse.shape), spacing=coarse.spacing,
                         origin=coarse.origin, metadata=dict(volume.metadata))
        preview._value_range = value_range
        info = VolumeInfo.of(preview)
        metadata = dict(info.metadata, model=self.source.model, level=self.level)
        return VolumeInfo(f"{volume.name} level {self.level}", lv.shape, str(lv.dtype),
                          lv.spacing, lv.origin, value_range, metadata)

    def prepare(self, camera: Camera, options: RenderOptions) -> Any:
        """The request of ``options``, checked on the client as the workers build it."""
        return prepare_request(self.volume, camera, options.as_dict())

    def render_frame(self, camera: Camera, options: RenderOptions,
                     frame_options: Mapping[str, Any]) -> Frame:
        """Render one image sort-last (the render template's step for a frame made on the
        workers: each share traced where it lives, the frame finished by the last task with
        :func:`~splinecast.render.template.finish_frame`).

        One task per share renders its partial image; ``P - 1`` tasks merge them up the k-d
        tree in visibility order for ``camera``; a last task makes the :class:`Frame`, the only
        thing sent to the client. ``frame.stats`` adds ``strategy``, ``shares``,
        ``composite_levels``, ``share_trace_ms_max`` / ``_sum`` (time in the shares' traces),
        ``composite_ms`` (time in the merges), ``partial_bytes`` (bytes of the partial images
        the merges and the final task consumed: what moves between workers at most),
        ``frame_bytes`` (what the client received) and ``wall_ms``.
        """
        from dask.base import tokenize

        start = time.perf_counter()
        # A user error fails here, on the client.
        request = self.prepare(camera, options)
        shipped = options.as_dict()  # what the workers build their request from
        token = tokenize(camera.pixel_basis().tolist(), camera.width, camera.height, shipped)
        leaves = {s.part: self._submit(render_share, s, camera, shipped, self.volume, token,
                                       part=s.part) for s in self.shares}
        nodes: dict[int, Future] = {}
        root = self._reduce(self.tree, leaves, camera, shipped, token, nodes)
        depths: list[Future] = []
        if request.setup.refines_depth_after_compositing:
            prefixes: dict[int, Any] = {}
            self._opacity_in_front(self.tree, None, nodes, camera, prefixes)
            depths = [self._submit(refine_dvr_depth, s, camera, shipped, self.volume, token,
                                   prefixes[s.part], leaves[s.part], part=s.part)
                      for s in self.shares if prefixes[s.part] is not None]
        future = self._submit(finish_partial, root, camera, shipped, self.volume, token,
                              *depths)
        try:
            frame = future.result()
        except SplinecastError as exc:
            self.client.cancel([future, root, *leaves.values(), *nodes.values(), *depths])
            raise exc.with_traceback(None) from None
        frame.stats.update(shares=len(self.shares), composite_levels=self.tree.depth(),
                           frame_bytes=int(sum(getattr(frame, n).nbytes for n in _FIELDS
                                               if getattr(frame, n, None) is not None)),
                           wall_ms=(time.perf_counter() - start) * 1e3)
        return frame

    def _reduce(self, node: KdNode, leaves: dict[int, Future], camera: Camera,
                options: dict[str, Any], token: str, nodes: dict[int, Future]) -> Future:
        """The merge tasks below ``node``; ``nodes`` gets every node's partial image (by id)."""
        if node.leaf:
            nodes[id(node)] = leaves[node.part]
            return nodes[id(node)]
        low = self._reduce(node.low, leaves, camera, options, token, nodes)  # type: ignore[arg-type]
        high = self._reduce(node.high, leaves, camera, options, token, nodes)  # type: ignore[arg-type]
        front, back = (low, high) if self._low_in_front(node, camera) else (high, low)
        nodes[id(node)] = self._submit(combine_partials, front, back, camera, options,
                                       self.volume, token)
        return nodes[id(node)]

    def _opacity_in_front(self, node: KdNode, prefix: Future | None, nodes: dict[int, Future],
                          camera: Camera, out: dict[int, Any]) -> None:
        """Tasks of the opacity in front of every share (DVR depth), top down: ``out[part]``
        is a future of a full-image opacity, or ``None`` for the share nothing is in front of."""
        if node.leaf:
            out[node.part] = prefix
            return
        low_first = self._low_in_front(node, camera)
        front, back = (node.low, node.high) if low_first else (node.high, node.low)
        self._opacity_in_front(front, prefix, nodes, camera, out)  # type: ignore[arg-type]
        behind = self._submit(opacity_behind, prefix, nodes[id(front)], camera)
        self._opacity_in_front(back, behind, nodes, camera, out)  # type: ignore[arg-type]

    def _low_in_front(self, node: KdNode, camera: Camera) -> bool:
        """Whether the bricks below ``node``'s split plane come first along the camera's rays."""
        axis = node.axis
        origin = float(self.volume.origin[axis])
        spacing = float(self.volume.spacing[axis])
        if camera.ortho:
            return float(camera.forward[axis]) / spacing >= 0.0
        # The plane between the two boxes as the shares draw them (level index space).
        plane = min(self.load_stats[leaf.part]["box_lo"][axis]
                    for leaf in node.high.leaves())  # type: ignore[union-attr]
        return (float(camera.position[axis]) - origin) / spacing <= plane

    def close(self) -> None:
        """Let every worker drop its shares (memory is freed; rendering reads them again)."""
        self.client.run(forget_shares, list(self.shares))

    def __repr__(self) -> str:
        return (f"SortLastScene({self.source.location!r}, model={self.source.model!r}, "
                f"level={self.level}, bricks={'x'.join(map(str, self.counts))}, "
                f"shares={len(self.shares)})")


#: Frame buffers counted in ``frame_bytes``.
_FIELDS = ("rgba", "depth", "position", "normal", "value", "face")
