"""One frame's bricks in one call: level of detail, loading within the frame's budget, substitution.

:class:`BrickStream` is what a renderer of a multiscale volume holds (one per scene): an octree, a
cache with its loader thread, and the per-frame sequence

1. the cut for the camera and the cut's share of the budget: :func:`.cut.lod.select_cut`
   (screen-space level of detail ``lod``), or the ``selector`` a caller passes (the error-metric
   cut of :mod:`.cut.policy`): every policy shares the cache, its loader and the substitution
   below;
2. :meth:`.store.cache.BrickCache.request_cut` (the loader starts reading, coarse levels first);
3. :meth:`.store.cache.BrickCache.wait` for at most ``loads_per_frame`` bricks;
4. :meth:`.store.cache.BrickCache.resolve`: every brick of the cut, or its finest resident ancestor.

The renderer then traces each :class:`~.store.cache.DrawItem`'s brick over the cut's box ``n``
(front to back per ray) and reports ``FrameBricks.stats`` in ``frame.stats``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from ...camera import Camera
from ...errors import ParameterError
from ...io.omezarr import MultiscaleVolume
from ..store.cache import BrickCache, DrawItem
from .lod import Cut, Key, centre_first, select_cut
from .octree import BrickOctree
from .relevance import ValueFilter

__all__ = ["BrickStream", "FrameBricks", "Selector"]

#: A cut policy: ``selector(budget_bytes, resident, prefetch) -> Cut`` (``resident(key)`` tells
#: what the cache holds, ``prefetch`` how many bricks the cut may list to read when idle).
Selector = Callable[[int, Callable[[Key], bool], int], Cut]


@dataclass
class FrameBricks:
    """The bricks of one frame: the cut, what to draw for each of its bricks, and counts."""

    cut: Cut
    items: list[DrawItem]
    stats: dict[str, Any] = field(default_factory=dict)

    @property
    def complete(self) -> bool:
        """Every brick of the cut is drawn from its own data (nothing substituted)."""
        return not any(item.substituted for item in self.items)


@dataclass
class _LastFrame:
    """The last level-of-detail frame: its view, the cache's versions when its cut was chosen
    and when it was resolved, its cut and items."""

    view: tuple
    selected: int
    resolved: int
    cut: Cut
    items: list[DrawItem]
    substituted: int
    unreadable: list[Key]


class BrickStream:
    """Octree + cache + loader for a multiscale volume, driven one frame at a time.

    Parameters
    ----------
    volume : MultiscaleVolume
    budget : int or str
        Byte budget of the cache (``"2GiB"``).
    lod : float
        Default level-of-detail threshold: refine while a voxel covers more than this many pixels.
    loads_per_frame : int
        Bricks a frame waits for at most (M).
    border : {"edge", "reflect"}
        Ghost filling at the volume's ends: the model's boundary rule.
    cut_fraction : float
        Share of the budget the cut may take; the rest holds the ancestors being replaced and
        prefetched bricks.
    prefetch : int
        Bricks to prefetch per frame when the loader is idle.
    brick : int, optional
        Cells per brick (default: the pyramid's, 32 for stores splinecast did not write).
    """

    def __init__(self, volume: MultiscaleVolume, budget: Any = "1GiB", *, lod: float = 1.0,
                 loads_per_frame: int = 64, border: str = "edge", cut_fraction: float = 0.8,
                 prefetch: int = 64, brick: int | None = None) -> None:
        if not 0 < cut_fraction <= 1:
            raise ParameterError(f"cut_fraction must be in (0, 1], got {cut_fraction!r}")
        self.volume = volume
        self.octree = BrickOctree(volume, brick=brick)
        self.cache = BrickCache(volume, budget, octree=self.octree, border=border,
                                loads_per_frame=loads_per_frame)
        self.lod = lod
        self.cut_fraction = cut_fraction
        self.prefetch = prefetch
        self._last: _LastFrame | None = None

    def frame(self, camera: Camera, value_filter: ValueFilter | None = None, *,
              lod: float | None = None, wait: bool = True,
              timeout: float | None = None, selector: Selector | None = None) -> FrameBricks:
        """Choose, load (within the frame's budget) and resolve the bricks for ``camera``.

        ``selector`` replaces the level-of-detail cut by another policy (see :data:`Selector`);
        ``lod`` and ``value_filter`` then do not choose the cut (the filter still decides which
        ancestors are worth reading for substitution, through the selector's own use of it).
        """
        t0 = time.perf_counter()
        budget = self.cut_budget()
        lod = self.lod if lod is None else lod
        # The level-of-detail cut is a function of the view, the filter, the budget and what
        # is resident: while none of them changes (a steady view, a viewer redrawing), the
        # last frame's cut and draw items are drawn again (selecting and resolving a cut of
        # ten thousand bricks costs a third of a second).
        view = None if selector is not None else (
            camera.pixel_basis().tobytes(), float(lod), budget,
            None if value_filter is None else value_filter.key())
        last = self._last
        selected = self.cache.version  # what the cut is chosen from
        reuse = (view is not None and last is not None and last.view == view
                 and last.selected == selected)
        if reuse:
            assert last is not None
            cut = last.cut
        elif selector is not None:
            cut = selector(budget, self.cache.is_resident, self.prefetch)
        else:
            cut = select_cut(self.octree, camera, lod, budget=budget, value_filter=value_filter,
                             resident=self.cache.is_resident, prefetch=self.prefetch)
        t1 = time.perf_counter()
        self.cache.begin_frame()
        if not reuse:  # the loader already has this cut's requests
            cut.requests = centre_first(cut.requests, self.octree, camera)
            self.cache.request_cut(cut)
        if wait:
            self.cache.wait(timeout=timeout)
        t2 = time.perf_counter()
        # What is still to read, taken before resolving: a brick that arrives between the two
        # is drawn from an ancestor in this frame yet would no longer count as requested, and
        # a caller rendering until nothing is requested (``complete=True``, the viewer's
        # refinement) would stop one brick short.
        requested = self.cache.stats()["requested"]
        version = self.cache.version
        if reuse and last is not None and last.resolved == version:
            items = last.items
            self.cache.note_substituted(last.substituted, last.unreadable)
        else:
            items = self.cache.resolve(cut)
        stats = self.cache.stats()
        stats["requested"] = requested
        stats.update(cut_bricks=len(cut), cut_levels=cut.levels(), cut_bytes=cut.nbytes,
                     cut_limited_by_budget=cut.limited, time_select=t1 - t0, time_load=t2 - t1,
                     cut_reused=reuse)
        # Kept for the next frame when nothing changed while resolving (a brick read in
        # between would be drawn from an ancestor under the newer version). The cut is reused
        # only while nothing changed since it was chosen: its requests and kept set depend on
        # what was resident then.
        self._last = (_LastFrame(view, selected, version, cut, items, stats["substituted"],
                                 [key for key, _ in self.cache.unreadable()])
                      if view is not None and self.cache.version == version else None)
        return FrameBricks(cut, items, stats)

    def cut_budget(self) -> int:
        """Bytes the cut's bricks may take: ``cut_fraction`` of what the cache may hold for
        bricks, at least the pinned coarsest level (the value ranges learnt from the bricks read
        so far taken in first)."""
        self.cache.update_ranges()
        return max(int(self.cache.brick_budget * self.cut_fraction), self.cache.pinned_bytes)

    def close(self) -> None:
        """Stop the loader thread."""
        self.cache.close()

    def __enter__(self) -> BrickStream:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
