"""A scene for volumes larger than memory: a multiscale OME-Zarr image rendered cut by cut.

``sc.Scene(sc.read("big.zarr"), model=..., budget="2GiB")`` returns a :class:`MultiscaleScene`
(``splinecast/__init__.py`` registers it with :func:`splinecast.scene.register_scene_type`). Per
frame it

1. asks its :class:`~.cut.stream.BrickStream` for the cut of the camera (bricks that cannot
   contribute to the mode left out, at most ``load_budget`` bricks read while the frame waits; a
   brick not yet resident is drawn from its finest resident ancestor). The cut policy ``cut``:
   ``"lod"`` (default) refines while a voxel covers more than ``lod`` pixels; ``"error"`` keeps the
   cut of Carmona & Froehlich 2011 (transfer-function distortion times importance from the eye and
   an optional point of ``interest``, split-and-collapse under the brick budget and ``load_budget``,
   updated from the previous frame's cut; :mod:`.cut.policy`) in DVR and MIP/minIP, and the
   level-of-detail cut in the isosurface modes;
2. turns the cut into :class:`~.draw.cut_renderer.Drawable` s and fixes the seams between levels
   (:mod:`.draw.seams`);
3. traces the drawables front to back per ray (:class:`~.draw.cut_renderer.CutRenderer`) in the mode
   of :meth:`~splinecast.Scene.render`, with the same options and the same :class:`Frame`.

``frame.stats`` adds the stream's counts (``complete``, ``substituted``, ``resident``,
``loaded_this_frame``, ``cut_bricks``, ``cut_levels``, ...) and the renderer's (``drawables``,
``drawables_traced``, ``drawables_changed_at_seams``, ``seam_closure_hits``). Rendering the same
view again converges to the complete cut.

Memory: the brick cache holds at most ``budget`` bytes. Models whose kernels need another dtype
than the store's (the type-6 splines read float32 or float64) hold a converted copy of every
drawn brick; their cache gets the share of the budget that leaves room for the copies.

Not available for multiscale volumes: ``prefilter=True`` for the B-spline models (the
interpolating coefficients come from a recursive filter over the whole volume, which a brick
cannot reproduce). The type-6 Laplacian prefilter is local and works.
"""

from __future__ import annotations

import time
from contextlib import nullcontext
from typing import Any

import numpy as np

from ...camera import Camera
from ...errors import ParameterError, ReadError
from ...io.omezarr import MultiscaleVolume
from ...models import MODELS
from ...render.defaults import auto_iso
from ...render.template import SceneTemplate, Traced, check_iso, whole_frame_tracer
from ...volume import Volume
from ..cut.lod import Cut
from ..cut.octree import DEFAULT_BRICK, BrickOctree
from ..cut.policy import CUT_PRIORITIES, ErrorCut, check_cut
from ..cut.relevance import ValueFilter
from ..cut.stream import BrickStream, FrameBricks
from ..draw.cut_renderer import CutRenderer, Drawable
from ..draw.seams import Seams
from ..store.budget import parse_bytes
from .whole_level import WholeLevel

__all__ = ["MultiscaleScene", "drawables_of", "render_brick", "RENDER_BRICK"]

#: Most rounds of ``load_budget`` bricks a ``complete=True`` frame waits for (a cut that keeps
#: changing, in a store whose ranges are learnt while reading, ends there).
_MAX_ROUNDS = 10_000


#: Cells per brick a scene renders with when the pyramid's are fewer (see
#: :func:`render_brick`).
RENDER_BRICK = 64


def render_brick(volume: MultiscaleVolume) -> int:
    """The cells per brick a scene renders ``volume`` with by default: the pyramid's, doubled
    while below :data:`RENDER_BRICK` and level 0 keeps at least 8 bricks along every axis.

    A brick of the cut costs per ray that crosses it (entering its grid and hierarchy) and per
    frame (a grid, seams, a drawable of the launch); the pyramid's bricks are its storage chunks,
    kept small so that reads are fine-grained. Rendering bricks of several chunks makes a cut of
    a large volume several times smaller, so it completes sooner and draws faster. Small
    volumes keep their bricks: their cuts are small anyway.
    """
    brick = int(volume.brick or DEFAULT_BRICK)
    shortest = int(min(volume.levels[0].shape))
    while brick < RENDER_BRICK and shortest // (2 * brick) >= 8:
        brick *= 2
    return brick


def drawables_of(frame: FrameBricks, octree: BrickOctree | None = None) -> list[Drawable]:
    """The drawables of a frame of a :class:`~.cut.stream.BrickStream`: each brick of the cut with
    the array drawn for it (its own or its finest resident ancestor's).

    With the ``octree``, bricks of the cut drawn from one ancestor are drawn as one drawable per
    octree node under that ancestor whose bricks in the cut are all drawn from it: the ancestor
    over the node's whole box (bricks left out of the cut there, which cannot contribute at
    their own level, are then drawn from the ancestor as well: its level as it is). Every drawable
    costs per ray that crosses it, and the first frames of a view draw thousands of bricks from
    a few coarse ones.
    """
    cut = frame.cut
    items = frame.items
    nodes: dict[int, tuple[int, int, int, int]] = {}
    if octree is not None and any(item.substituted for item in items):
        nodes = _merged_nodes(cut.keys, items, octree)
    out = []
    done: set[tuple] = set()
    for item in items:
        brick = item.brick
        node = nodes.get(item.n)
        if node is not None and node != cut.key(item.n):
            if node in done:
                continue
            done.add(node)
            lo, hi = octree.box(node[0], np.array([node[1:]]))  # type: ignore[union-attr]
            out.append(Drawable(node, brick.key, int(brick.key[0]), brick.data,
                             tuple(int(v) for v in brick.first),  # type: ignore[arg-type]
                             lo[0], hi[0], True))
            continue
        out.append(Drawable(cut.key(item.n), brick.key, int(brick.key[0]), brick.data,
                         tuple(int(v) for v in brick.first),  # type: ignore[arg-type]
                         cut.box_lo[item.n], cut.box_hi[item.n], item.substituted))
    return out


def _merged_nodes(keys: np.ndarray, items: list,
                  octree: BrickOctree) -> dict[int, tuple[int, int, int, int]]:
    """For each substituted brick ``n`` of the cut: the coarsest node between it and the
    ancestor it is drawn from (that ancestor included) whose bricks in the cut are all drawn
    from that ancestor."""
    keys = np.asarray(keys, dtype=np.int64).reshape(-1, 4)
    position = np.array([octree.position(int(level)) for level in keys[:, 0]], dtype=np.int64)
    drawn = np.full(len(keys), -1, dtype=np.int64)  # an id per drawing ancestor, -1: itself
    ancestors: dict[tuple, int] = {}
    for item in items:
        if item.substituted:
            drawn[item.n] = ancestors.setdefault(tuple(int(v) for v in item.brick.key),
                                                 len(ancestors))
    top = np.full(len(ancestors), 0, dtype=np.int64)
    for key, a in ancestors.items():
        top[a] = octree.position(key[0])
    out: dict[int, tuple[int, int, int, int]] = {}
    left = drawn >= 0
    for q in range(int(top.max()), -1, -1):  # coarse to fine: the coarsest node wins
        under = position <= q
        if not np.any(left & under):
            continue
        # Every cut brick's node on level position q; a node is whole when all the cut's
        # bricks in it are drawn from one ancestor that lies at or above q.
        rows = np.flatnonzero(under)
        node = keys[rows, 1:] * octree.factors[position[rows]] // octree.factors[q]
        found, inverse, count = np.unique(node, axis=0, return_inverse=True, return_counts=True)
        inverse = inverse.reshape(-1)
        # One member's drawing ancestor per node; the node is whole if all members share it.
        one = np.empty(len(found), dtype=np.int64)
        one[inverse] = drawn[rows]
        same = np.bincount(inverse, weights=drawn[rows] == one[inverse], minlength=len(found))
        whole = (same == count) & (one >= 0)
        whole &= top[np.maximum(one, 0)] >= q
        level = int(octree.levels[q])
        for m in np.flatnonzero(left[rows] & whole[inverse]):
            n = int(rows[m])
            idx = found[inverse[m]]
            out[n] = (level, int(idx[0]), int(idx[1]), int(idx[2]))
            left[n] = False
    return out


class MultiscaleScene(SceneTemplate):
    """A multiscale volume, a reconstruction model, a brick cache and the renderer of its cuts.

    Parameters
    ----------
    volume : MultiscaleVolume
        From :func:`splinecast.read` of an OME-Zarr image (nothing is read but its coarsest
        level, which stays resident).
    model : str
        Any of :data:`splinecast.models.MODELS`.
    budget : int or str
        Hard byte budget (``"2GiB"``) of the resident bricks and the copies of bricks changed
        at level seams (see :attr:`seams_in_budget`).
    lod : float
        Refine a brick while one of its voxels covers more than ``lod`` pixels.
    load_budget : int, optional
        Bricks a frame waits for at most (M); the loader thread goes on reading in the
        background, and later frames draw what it read. Default: 64 bricks of 32^3 cells'
        worth of voxels (8 bricks of 64^3), at most 64 bricks.
    cut : {"lod", "error"}
        Cut policy (see above). ``"error"`` reads the brick histograms of the distortion metric
        stored with the pyramid (``build_pyramid(..., histograms=True)``, ``splinecast pyramid
        --histograms``); a store without them has every level read once when the scene opens to
        build them (``prepare_ms`` includes it; a warning says so).
    cut_priority : {"improved", "naive"}
        Split priority of the ``"error"`` cut: ``"improved"`` (default) orders splits by the
        error reduction per child brick, ``P = ER`` (eq. 9 of Carmona & Froehlich 2011); ``"naive"``
        by the brick's error, ``P = E`` (the classic greedy rule the paper compares against).
    interest : 3 floats, optional
        Point of interest (world coordinates) of the ``"error"`` cut; without one its importance
        is the distance to the eye alone. :meth:`render` can move it per frame.
    seams : bool
        Make bricks of different levels meet without cracks (:mod:`.draw.seams`; default). ``False``
        draws every brick as it is (to see the cracks).
    brick : int, optional
        Cells per brick (default: :func:`render_brick`, the pyramid's or a multiple of it).
    whole_level : bool
        Draw a view whose level-of-detail cut is level 0 everywhere from level 0 read whole
        into memory, as an in-memory :class:`~splinecast.Scene` of it, when level 0 fits in
        the budget (default; :mod:`.whole_level`): the same picture (to rounding) without the
        per-brick costs. Frames that do not wait (``wait=False``) use it once it is read.
        ``False`` always draws bricks.
    **options
        Model options (``root_finder``, ``prefilter`` for the type-6 splines, ...).

    Attributes
    ----------
    seams_in_budget : bool
        The seam copies' bytes (``frame.stats["seam_copy_bytes"]``) are held back from the
        bricks' share of the budget, from the frame after they appear (default; a view that
        stays the same keeps what it held back, so its cut settles). ``False``
        leaves them beside the budget, so that the cut's brick count follows from the budget
        alone (the error cut's ``N`` of Carmona & Froehlich 2011, for comparing cut algorithms).

    Raises
    ------
    ParameterError
        Bad model, options or budget (a budget below the coarsest level), or ``prefilter=True``
        for a B-spline model.
    ReadError
        The coarsest level cannot be read.

    Notes
    -----
    ``render`` is the render template's (:meth:`splinecast.Scene.render`), with this scene's
    frame options ``lod``, ``interest``, ``wait``, ``timeout``, ``complete`` and ``missing``
    (see :meth:`trace`), and antialiasing off by default.
    """

    #: Each further antialiasing sample is traced over the whole image: off unless asked.
    default_samples = 1

    def __init__(self, volume: MultiscaleVolume, model: str = "trilinear", budget: Any = "2GiB",
                 lod: float = 1.0, load_budget: int | None = None, *, cut: str = "lod",
                 cut_priority: str = "improved", interest: Any = None, seams: bool = True,
                 brick: int | None = None, whole_level: bool = True,
                 **options: Any) -> None:
        if not isinstance(volume, MultiscaleVolume):
            raise ParameterError(f"volume must be a MultiscaleVolume, got {type(volume).__name__}")
        if model not in MODELS:
            raise ParameterError(f"model must be one of {', '.join(MODELS)}, got {model!r}")
        refusal = MODELS[model].brick_refusal(options)
        if refusal is not None:
            raise ParameterError(f"{refusal.option} is not available for model {model} on a "
                                 f"multiscale volume: {refusal.reason}")
        self.cut = check_cut(cut)
        if cut_priority not in CUT_PRIORITIES:
            raise ParameterError(f"cut_priority must be one of "
                                 f"{', '.join(map(repr, CUT_PRIORITIES))}, got {cut_priority!r}")
        self.cut_priority = cut_priority
        start = time.perf_counter()
        self.volume = volume
        coarse = volume.level(-1)
        #: The coarsest level in memory: the automatic isovalue, window and transfer function
        #: come from it; isovalues are checked against the whole volume's range.
        self.preview = Volume(coarse.read((0, 0, 0), coarse.shape), spacing=coarse.spacing,
                              origin=coarse.origin, metadata=dict(volume.metadata))
        self.preview._value_range = volume.value_range
        self.model = MODELS[model](self.preview, **options)
        self.budget = parse_bytes(budget, "budget")
        brick = brick or render_brick(volume)
        if load_budget is None:
            # The frame's wait is for bytes read: bricks of 64^3 are 8 of 32^3.
            load_budget = max(4, min(64, round(64 * (32 / brick) ** 3)))
        self.stream = BrickStream(volume, self._cache_budget(), lod=lod,
                                  loads_per_frame=load_budget, border=self.model.border_rule,
                                  brick=brick)
        #: The error-metric cut (``cut="error"``), None for the level-of-detail cut.
        self.error_cut = (ErrorCut(self.stream.octree, interest=interest,
                                   improved=cut_priority == "improved")
                          if self.cut == "error" else None)
        self.renderer = CutRenderer(self.model, self.stream.octree,
                                    Seams(self.model) if seams else None)
        #: Level 0 held whole for the views whose cut is level 0 everywhere (None: never).
        self.whole: WholeLevel | None = None
        if whole_level:
            finest = volume.level(0).nbytes
            self.whole = WholeLevel(
                volume, self.stream, finest,
                self._cache_budget() - self.stream.cache.pinned_bytes, model, options)
        self.prepare_ms = (time.perf_counter() - start) * 1e3
        self._last_drawables: tuple[list, list[Drawable]] | None = None
        #: The view (camera, level of detail, visible values) of the last reservation.
        self._reserved_view: tuple | None = None
        self.seams_in_budget = True

    def _cache_budget(self) -> int:
        """The cache's share of the budget: all of it, unless the model's grids copy the bricks
        into another dtype (type-6), which then takes its share."""
        copy_dtype = self.model.grid_copy_dtype
        copy = 0 if copy_dtype is None or copy_dtype == self.volume.dtype else copy_dtype.itemsize
        item = self.volume.dtype.itemsize
        return int(self.budget * item / (item + copy))

    @property
    def lod(self) -> float:
        """The default level-of-detail threshold (pixels per voxel)."""
        return self.stream.lod

    @property
    def defaults_volume(self) -> Volume:
        """The coarsest level in memory (:attr:`preview`): the automatic choices come from it."""
        return self.preview

    def check_iso(self, iso: Any) -> float:
        """An isovalue checked against the whole volume's range (``None``: the automatic one
        of the coarsest level)."""
        return check_iso(self.volume, auto_iso(self.preview) if iso is None else iso)

    def _filter(self, setup: Any) -> ValueFilter | None:
        """Which bricks can show something in this mode (None: all, for MIP/minIP)."""
        widen = self.model.value_overshoot
        isos = setup.surface_values()
        if isos is not None:
            return ValueFilter.iso(isos, widen)
        tf = setup.visible_transfer()
        if tf is not None:
            return ValueFilter.transfer(tf, widen)
        return None

    def trace(self, request: Any, camera: Camera, *, lod: float | None = None,
              interest: Any = None, wait: bool = True, timeout: float | None = None,
              complete: bool = False, missing: str = "substitute") -> Traced:
        """The cut of ``camera`` traced in the mode of ``request``: the step of the render
        template (:class:`~splinecast.render.template.SceneTemplate`) a multiscale scene
        supplies. Its keywords are the scene's frame options: ``render(camera, ..., lod=...,
        wait=False)`` passes them here. Antialiasing (``samples``) is off by default: the rays
        of each further sample are traced for the whole image through the cut (the default 5
        samples cost about one more frame), where an in-memory scene traces only the pixels on
        edges.

        Parameters
        ----------
        lod : float, optional
            Level of detail of this frame (default: the scene's; ``cut="lod"`` and the
            isosurface modes).
        interest : 3 floats, optional
            Point of interest of this frame (``cut="error"``; default: the scene's).
        wait : bool
            Wait for up to ``load_budget`` bricks of the cut (default); ``False`` draws what is
            resident at once.
        timeout : float, optional
            Longest wait in seconds (per ``load_budget`` bricks).
        complete : bool
            Wait until every brick of the cut is resident or known to be unreadable (a still
            image: the command line); default: draw after ``load_budget`` bricks.
        missing : {"substitute", "error"}
            A brick of the cut whose chunks cannot be read (missing in a store whose chunks
            were all written, or damaged): drawn from its finest readable ancestor (default:
            the frame says so in ``stats["unreadable"]`` and ``stats["unreadable_reason"]``),
            or a :class:`~splinecast.ReadError` naming the chunk (``"error"``: a still image
            that must show the data, the command line without ``--allow-missing``).

        Returns
        -------
        Traced
            The frame's ``stats["complete"]`` is ``False`` while bricks of the cut are drawn
            from coarser ancestors (``stats["unreadable"]`` of them because they cannot be
            read); render the same view again to refine.

        Raises
        ------
        ReadError
            With ``missing="error"``, the first unreadable brick's reason (naming the chunk and
            its file).
        """
        if missing not in ("substitute", "error"):
            raise ParameterError(f"missing must be 'substitute' or 'error', got {missing!r}")
        # A frame drawn at once (the viewer's interactive passes, the first image) has the
        # cores to itself: no read starts from its start to the end of its trace
        # (BrickCache.drawing). Frames that wait for bricks share them with the loader's
        # read-ahead: pausing it during their traces too made a 2048^3 view's cut take 146
        # frames and 172 s to complete instead of 16 frames and 79 s.
        at_once = not wait and not complete
        start = time.perf_counter()
        value_filter = self._filter(request.setup)
        selector = self._selector(request.setup, camera, value_filter, interest)
        if self.whole is not None:
            # The error cut (DVR, MIP) chooses under the budget from what is resident: bricks.
            cut = None if selector is not None else self.whole.cut(
                camera, value_filter, self.lod if lod is None else lod)
            if cut is None:
                self.whole.release()  # the bricks get the budget
            else:
                whole = self.whole.get(load=not at_once)
                if whole is not None:
                    request.stats["cut_ms"] = (time.perf_counter() - start) * 1e3
                    return self._trace_whole(whole, cut, request, camera, lod)
        with self.stream.cache.drawing() if at_once else nullcontext():
            bricks = self._frame(camera, value_filter, lod, wait, timeout, selector)
            rounds = 1
            while complete and rounds < _MAX_ROUNDS and (
                    bricks.stats["requested"] or not bricks.stats.get("cut_final", True)):
                bricks = self._frame(camera, value_filter, lod, True, timeout, selector)
                rounds += 1
            unreadable = self.stream.cache.unreadable()
            if unreadable and missing == "error":
                _key, reason = unreadable[0]
                more = f" ({len(unreadable)} bricks of the view cannot be read)" \
                    if len(unreadable) > 1 else ""
                raise ReadError(f"{reason}{more}")
            # The same draw items (a steady view): the same drawables, so that the renderer keeps
            # its seam plan and launch arrays.
            last = self._last_drawables
            if last is not None and last[0] is bricks.items:
                drawables = last[1]
            else:
                drawables = drawables_of(bricks, self.stream.octree)
                self._last_drawables = (bricks.items, drawables)
            request.stats["cut_ms"] = (time.perf_counter() - start) * 1e3
            start = time.perf_counter()
            out, counters = self.renderer.render(drawables, request.setup, camera, request.planes)
        self.renderer.forget(p.key for p in drawables)
        # The seam copies count against the budget: the bricks get what they leave. The same
        # view keeps what it reserved: its seams depend on its cut and its cut on the room the
        # reservation leaves, so lowering the reservation after a smaller cut (smaller seams) let
        # the larger cut, whose seams do not fit beside it, back in every other frame.
        seam_bytes = self.renderer.seam_copy_bytes()
        cache = self.stream.cache
        view = (camera.pixel_basis().tobytes(), self.lod if lod is None else lod,
                repr(value_filter))
        reserve = seam_bytes if self.seams_in_budget else 0
        if self.seams_in_budget and view == self._reserved_view:
            reserve = max(reserve, cache.reserved_bytes)
        self._reserved_view = view
        cache.reserve(reserve)
        stats = request.stats
        stats.update(self.renderer.stats)
        stats["seam_copy_bytes"] = seam_bytes
        stats.update(bricks.stats)
        stats["unreadable_reason"] = unreadable[0][1] if unreadable else ""
        stats["lod"] = self.lod if lod is None else lod
        stats["whole_level"] = False
        return Traced(out, counters, start,
                      whole_frame_tracer(self.renderer, drawables, request.planes))

    def _trace_whole(self, whole: Any, cut: Cut, request: Any, camera: Camera,
                     lod: float | None) -> Traced:
        """Trace a view whose cut is level 0 everywhere from level 0 held whole (the in-memory
        scene ``whole``), with the statistics a complete frame of that cut reports."""
        assert self.whole is not None
        traced = whole.trace(request, camera)
        cache = self.stream.cache
        stats = request.stats
        stats.update(cache.stats())
        stats.update(
            resident_bytes=cache.nbytes + self.whole.nbytes, requested=0, substituted=0,
            complete=True, unreadable=0, unreadable_reason="", cut_bricks=len(cut),
            cut_levels=cut.levels(), cut_bytes=cut.nbytes, cut_limited_by_budget=cut.limited,
            cut_policy="lod", lod=self.lod if lod is None else lod, drawables=1,
            drawables_traced=1, drawables_changed_at_seams=0, seam_copy_bytes=0, whole_level=True,
            whole_level_read_ms=self.whole.read_ms)
        return traced

    def _selector(self, setup: Any, camera: Camera, value_filter: ValueFilter | None,
                  interest: Any) -> Any:
        """The error cut's selector for DVR and MIP/minIP, else None (level of detail)."""
        if self.error_cut is None:
            return None
        tf = setup.cut_transfer()
        if tf is None:
            return None
        cache = self.stream.cache
        return self.error_cut.selector(camera, tf, value_filter, cache.loads_per_frame, interest,
                                       cache.resident_keys)

    def _frame(self, camera: Camera, value_filter: ValueFilter | None, lod: float | None,
               wait: bool, timeout: float | None, selector: Any) -> FrameBricks:
        bricks = self.stream.frame(camera, value_filter, lod=lod, wait=wait, timeout=timeout,
                                   selector=selector)
        if selector is not None:
            assert self.error_cut is not None
            bricks.stats.update(self.error_cut.stats())
        else:
            bricks.stats["cut_policy"] = "lod"
        return bricks

    def bricks_loaded(self) -> int:
        """Bricks read from the store so far (the cache counts them under its lock)."""
        return int(self.stream.cache.stats()["loaded"])

    def close(self) -> None:
        """Stop the loader thread (the scene cannot render afterwards)."""
        self.stream.close()

    def __repr__(self) -> str:
        levels = np.asarray(self.stream.octree.levels).tolist()
        return (f"MultiscaleScene({self.volume.name!r}, model={self.model.name!r}, "
                f"budget={self.budget}, cut={self.cut!r}, lod={self.lod}, levels={levels})")
