"""The finest level held whole: a multiscale volume within its budget drawn as a Scene.

When the level-of-detail cut of a view is level 0 everywhere it draws (every brick that can show
something refined down to the finest level, within the cut's share of the budget) and level 0
fits in the budget, the cut's picture is the finest level's: the brick renderer then only adds
per-brick costs (a grid and a block hierarchy per brick, the launch over the drawables, whose
first-class function arguments Numba cannot cache on disk) to what an in-memory
:class:`~splinecast.scene.Scene` of that level does in one grid. :class:`WholeLevel` reads level
0 once, through the level's bounded chunk reader (:meth:`~splinecast.io.omezarr.Level.read`),
and draws such views with the in-memory scene. The picture is the same level of detail; the two
renderers agree to rounding (a ray entering a brick mid-cell parametrizes the cell from another
point), as ``tests/test_multires_render.py`` checks for every model and mode.

A view whose cut has coarser bricks (zoomed out, a budget the cut does not fit) is drawn from
bricks again, and the level held whole is let go first, so that the bricks and it never hold
more than the budget together.
"""

from __future__ import annotations

import time
from typing import Any

from ...camera import Camera
from ...errors import ReadError
from ...io.omezarr import MultiscaleVolume
from ...scene import Scene
from ...volume import Volume
from ..cut.lod import Cut, select_cut
from ..cut.relevance import ValueFilter
from ..cut.stream import BrickStream

__all__ = ["WholeLevel"]


class WholeLevel:
    """Level 0 of ``volume`` in memory as a :class:`~splinecast.scene.Scene`, for the views
    whose cut is level 0 everywhere.

    Parameters
    ----------
    volume : MultiscaleVolume
    stream : BrickStream
        The scene's stream: its octree, its cache (emptied while the level is held) and the
        cut's share of the budget.
    nbytes : int
        What holding level 0 costs (its voxels, and a model's converted copy of them).
    limit : int
        Bytes level 0 may take (the scene's budget less the pinned coarsest level).
    model : str
    options : dict
        Model options, as the scene's own model got them.
    """

    def __init__(self, volume: MultiscaleVolume, stream: BrickStream, nbytes: int, limit: int,
                 model: str, options: dict[str, Any]) -> None:
        self.volume = volume
        self.stream = stream
        self.fits = 0 < nbytes <= limit
        self.model = model
        self.options = dict(options)
        self.scene: Scene | None = None
        #: Why level 0 could not be read whole (the bricks are drawn instead; they name it).
        self.failed: str | None = None
        self.read_ms = 0.0
        self._view: tuple | None = None
        self._cut: Cut | None = None

    def cut(self, camera: Camera, value_filter: ValueFilter | None, lod: float) -> Cut | None:
        """The view's level-of-detail cut when every brick of it is on level 0 (and it has
        some), else None. Kept while the view, the filter and the cut's share of the budget
        stay the same (a steady view pays a comparison)."""
        if not self.fits or self.failed is not None:
            return None
        budget = self.stream.cut_budget()
        view = (camera.pixel_basis().tobytes(), float(lod), budget,
                None if value_filter is None else value_filter.key())
        if view != self._view:
            self._cut = select_cut(self.stream.octree, camera, lod, budget=budget,
                                   value_filter=value_filter, prefetch=0)
            self._view = view
        cut = self._cut
        if cut is None or not len(cut) or set(cut.levels()) != {0}:
            return None
        return cut

    def get(self, load: bool) -> Scene | None:
        """The in-memory scene of level 0: read now when ``load`` (the brick cache emptied
        first), else only if already held. None when level 0 cannot be read (see
        :attr:`failed`)."""
        if self.scene is not None or not load or self.failed is not None:
            return self.scene
        self.stream.cache.clear()
        start = time.perf_counter()
        level = self.volume.level(0)
        try:
            data = level.read((0, 0, 0), level.shape)
        except ReadError as exc:
            # A damaged or missing chunk: the bricks then substitute or name it, as asked.
            self.failed = str(exc)
            return None
        whole = Volume(data, spacing=level.spacing, origin=level.origin,
                       metadata=dict(self.volume.metadata))
        # Isovalues are checked against the store's range, as the preview checks them.
        whole._value_range = self.volume.value_range
        self.scene = Scene(whole, model=self.model, **self.options)
        self.read_ms = (time.perf_counter() - start) * 1e3
        return self.scene

    def release(self) -> None:
        """Let level 0 go (a view that needs bricks: they get the budget)."""
        self.scene = None

    @property
    def nbytes(self) -> int:
        """Bytes of level 0 held (0 when not held)."""
        return 0 if self.scene is None else int(self.scene.volume.data.nbytes)
