"""The :class:`DistributedScene`: a :class:`~splinecast.Scene` whose renders run on a Dask cluster.

Sort-first: a single frame is cut into image tiles, each rendered as a task and pasted into the
frame as it completes; a batch of frames (a camera path, a sweep) is one task per frame. The
volume is never shipped through the task graph: every worker opens the :class:`SceneSource`
itself, once, and keeps the prepared scene (:mod:`.worker`).

``render`` is the render template's (:class:`~splinecast.render.template.SceneTemplate`): its
arguments are gathered and checked on the client as every scene kind's are, and the frame is
made elsewhere, so the scene overrides the template's step for a frame
(:meth:`DistributedScene.render_frame`): every tile is the workers' scene's own
``render_frame`` of the same :class:`~splinecast.render.template.RenderOptions` for the tile's
camera, and the tiles are pasted together.

Sort-last: ``DistributedScene(store, client, model, strategy="sort-last", level=k)`` returns a
:class:`~.sort_last.SortLastScene` instead (bricks of one pyramid level per worker, partial images
composited on the workers), with the same ``render``.

Dask is imported only when a DistributedScene is created, so ``import splinecast`` (and the local
movie path) never needs it.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterable, Iterator, Mapping
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np

from ..camera import Camera
from ..errors import ParameterError, SplinecastError
from ..multires.scenes.labels import LabelScene
from ..render.frame import Frame
from ..render.template import RenderOptions, SceneTemplate
from . import worker
from .render_call import render_options
from .shots import Shot, as_shots
from .sort_last import SortLastScene
from .source import SceneSource, VolumeInfo
from .tiles import FrameCanvas, Tile, auto_tile_size, tile_grid

if TYPE_CHECKING:
    from distributed import Client, Future

__all__ = ["DistributedScene", "STRATEGIES"]

#: How a :class:`DistributedScene` divides the work: the image (tiles and frames) or the data
#: (bricks of one level of an OME-Zarr pyramid, :mod:`.sort_last`).
STRATEGIES = ("sort-first", "sort-last")

class DistributedScene(SceneTemplate):
    """A volume and model prepared on every worker of a Dask cluster, rendered like a Scene.

    Parameters
    ----------
    source : str, os.PathLike or SceneSource
        What every worker opens: a file or folder path (relative paths are resolved against the
        client's working directory; the workers must see the same file, e.g. on a shared file
        system) or a ``"demo:NAME?size=N"`` spec.
    client : distributed.Client, optional
        The cluster to use; by default the current client (``distributed.get_client()``).
    model : str
        Reconstruction model (see :data:`splinecast.MODELS`).
    strategy : {"sort-first", "sort-last"}
        ``"sort-first"`` (default): every worker opens the whole volume, the image is split.
        ``"sort-last"``: ``source`` is an OME-Zarr store, the bricks of one pyramid level
        (``level=k``, default 0) are split among the workers, each reading only its own, and
        their partial images are composited on the workers; returns a
        :class:`~splinecast.distributed.sort_last.SortLastScene` (its ``render`` takes the
        same arguments and returns the same :class:`Frame`; ``level``, ``parts`` and
        ``brick`` are its options).
    smooth : int, optional
        Gaussian pre-smoothing kernel size (3 or 5), applied on the workers (sort-first); with
        ``labels=True``, to each label's indicator (a label volume is never averaged).
    labels : bool
        A label volume (sort-first): every worker opens ``Scene(volume, labels=True, ...)``
        (:class:`~splinecast.multires.scenes.labels.LabelScene`) with the options ``colors`` (a
        path or a table), ``show``, ``opacity`` and ``budget``; the frame's ``label`` buffer is
        assembled with the others.
    **options
        Model options, as for :class:`~splinecast.Scene`.

    Attributes
    ----------
    volume : VolumeInfo
        The header of the volume as the workers read it (shape, spacing, origin, value range,
        metadata): pass it to ``Camera.orbit`` like a :class:`~splinecast.Volume`.

    Raises
    ------
    ReadError, DataError, ParameterError
        When a worker cannot open or prepare the source; the message names the worker and the
        path. Every worker present at construction opens the source right away (in parallel), so
        such a mistake shows here rather than in the middle of a render.

    Examples
    --------
    >>> from distributed import Client, LocalCluster            # doctest: +SKIP
    >>> client = Client(LocalCluster(n_workers=2, threads_per_worker=1))  # doctest: +SKIP
    >>> scene = DistributedScene("head.nii.gz", client, model="s31")  # doctest: +SKIP
    >>> cam = sc.Camera.orbit(scene.volume, size=(2048, 2048))  # doctest: +SKIP
    >>> frame = scene.render(cam, mode="iso", iso=80)            # doctest: +SKIP
    >>> cams = orbit_path(scene.volume, 120, size=(512, 512))    # doctest: +SKIP
    >>> for frame in scene.render_many(cams, iso=80): ...        # doctest: +SKIP
    """

    def __new__(cls, source: Any = None, client: Any = None, model: str = "trilinear", *,
                strategy: str = "sort-first", **kwargs: Any) -> Any:
        # strategy="sort-last" returns a SortLastScene (bricks per worker), as Scene returns a
        # MultiscaleScene for a multiscale volume.
        if strategy not in STRATEGIES:
            raise ParameterError(f"strategy must be one of {', '.join(STRATEGIES)}, "
                                 f"got {strategy!r}")
        if cls is DistributedScene and strategy == "sort-last":
            return SortLastScene(source, client, model, **kwargs)
        if "level" in kwargs:
            raise ParameterError("level applies to strategy='sort-last' only (sort-first "
                                 "renders the whole volume the source names)")
        return super().__new__(cls)

    def __init__(self, source: str | os.PathLike | SceneSource, client: Client | None = None,
                 model: str = "trilinear", *, strategy: str = "sort-first",
                 smooth: int | None = None, labels: bool = False, **options: Any) -> None:
        from distributed import Client, get_client

        if not isinstance(source, SceneSource):
            label_options = _label_options(options, smooth) if labels else None
            source = SceneSource(source, model, options, None if labels else smooth,
                                 labels=label_options)
        if client is None:
            try:
                client = get_client()
            except ValueError:
                raise ParameterError("DistributedScene needs a Dask client: pass client= or "
                                     "create a distributed.Client first") from None
        if not isinstance(client, Client):
            raise ParameterError(f"client must be a distributed.Client, got "
                                 f"{type(client).__name__}")
        self.source = source
        self.client = client
        self.volume: VolumeInfo = self._prepare_workers()

    # ------------------------------------------------------------------ workers
    def _prepare_workers(self) -> VolumeInfo:
        """Open the source on every current worker (one task each, in parallel) and return the
        volume's header; raise the first worker's error, naming the worker and the path."""
        addresses = sorted(self.client.nthreads())
        # Each task asks for its worker but may run elsewhere: a worker that dies meanwhile
        # must not leave a task waiting forever for it. An empty cluster (adaptive, still
        # starting) gets one unpinned task, run by the first worker that arrives.
        futures = [self.client.submit(worker.prepare, self.source, workers=[a],
                                      allow_other_workers=True, pure=False)
                   for a in addresses] or [self.client.submit(worker.prepare, self.source,
                                                              pure=False)]
        results = [result for _, result in self._as_completed(futures)]
        errors = [r for r in results if isinstance(r, SplinecastError)]
        if errors:
            n = len(errors) - 1
            others = f" (also on {n} other worker{'s' if n > 1 else ''})" if n else ""
            raise type(errors[0])(f"{errors[0]}{others}")
        return results[0]

    # The modes of the workers' scene kind (a label volume's: its labels' surfaces): ``render``
    # refuses another mode here, before any tile is sent to a worker.
    @property
    def modes(self) -> tuple[str, ...] | None:  # type: ignore[override]
        """The modes the workers' scenes render (a label volume's, or every mode)."""
        return LabelScene.modes if self.source.labels is not None else None

    @property
    def modes_reason(self) -> str | None:  # type: ignore[override]
        """Why only :attr:`modes` (a label volume's reason), for the message refusing another."""
        return LabelScene.modes_reason if self.source.labels is not None else None

    @property
    def threads(self) -> int:
        """Worker threads in the cluster now (they change with adaptive clusters)."""
        return max(1, sum(self.client.nthreads().values()))

    def close(self) -> None:
        """Let every worker drop its prepared scene (memory is freed; the scene can still
        render: workers would open the source again)."""
        self.client.run(worker.forget, self.source)

    def __repr__(self) -> str:
        return (f"DistributedScene({self.source.location!r}, model={self.source.model!r}, "
                f"workers={len(self.client.nthreads())})")

    # ------------------------------------------------------------------ one frame, by tiles
    #: The frame options of a sort-first render (see :meth:`render_frame`).
    frame_options = MappingProxyType({"tile_size": "auto", "image_only": False,
                                      "on_tile": None})

    def render_frame(self, camera: Camera, options: RenderOptions,
                     frame_options: Mapping[str, Any]) -> Frame | np.ndarray:
        """Render one image, cut into tiles rendered on the workers: the render template's step
        for a frame made elsewhere (``render`` is :meth:`splinecast.Scene.render`, with the
        frame options below).

        Every tile is the workers' scene's own ``render_frame`` of ``options`` for the tile's
        camera (:meth:`splinecast.Camera.tile`), so the assembled :class:`Frame` equals the
        local render array by array. Statistics are merged as
        :func:`~splinecast.distributed.tiles.merge_stats` says, plus ``wall_ms`` (client-side
        time of the whole render) and ``tiles``.

        Frame options:

        tile_size : int or "auto"
            Tile edge in pixels; ``"auto"`` gives every worker thread about four tiles
            (see :func:`~splinecast.distributed.tiles.auto_tile_size`, a multiple of 16).
            With a multiple of :attr:`splinecast.Scene.tile_shape` (8 pixels for every
            model) the image equals the local render pixel for pixel in every mode; with
            other sizes a MIP with a ``tolerance`` may report another value within the
            tolerance at some pixels.
        image_only : bool
            Return only the 8-bit RGBA image (``Frame.to_uint8()`` of the full render): the
            workers then send 4 bytes per pixel instead of the Frame's 73.
        on_tile : callable, optional
            Called as ``on_tile(tile, frame)`` with each tile as it arrives (its 8-bit image
            with ``image_only``), for progressive display; see also :meth:`render_tiles`.
        """
        if not isinstance(camera, Camera):  # checked here: the workers' template checks it late
            raise ParameterError(f"camera must be a splinecast.Camera, got "
                                 f"{type(camera).__name__}")
        start = time.perf_counter()
        image_only, on_tile = frame_options["image_only"], frame_options["on_tile"]
        tiles = self._tiles(camera, options, frame_options["tile_size"], image_only)
        if image_only:
            image = np.empty((camera.height, camera.width, 4), np.uint8)
        else:
            canvas = FrameCanvas(camera)
        for tile, part in tiles:
            if image_only:
                image[tile.rows, tile.cols] = part
            else:
                canvas.paste(tile, part)
            if on_tile is not None:
                on_tile(tile, part)
        if image_only:
            return image
        return canvas.frame(wall_ms=(time.perf_counter() - start) * 1e3)

    def render_tiles(self, camera: Camera, *args: Any, tile_size: int | str = "auto",
                     image_only: bool = False, **kwargs: Any
                     ) -> Iterator[tuple[Tile, Frame | np.ndarray]]:
        """Render one image by tiles and yield ``(tile, frame)`` pairs in the order they
        complete (a progressive display pastes ``frame.rgba``, or the 8-bit image with
        ``image_only``, at ``tile.rows, tile.cols``).

        Tiles are scheduled from the image centre outwards. Leaving the loop early cancels the
        tiles not yet rendered. Arguments as for :meth:`render`.
        """
        options = render_options(camera, args, kwargs, self.default_mode)
        return self._tiles(camera, options, tile_size, image_only)

    def _tiles(self, camera: Camera, options: RenderOptions, tile_size: int | str,
               image_only: bool) -> Iterator[tuple[Tile, Frame | np.ndarray]]:
        """The tasks of ``camera``'s tiles, yielded as they complete (see :meth:`render_tiles`)."""
        if tile_size == "auto":
            tile_size = auto_tile_size(camera.width, camera.height, self.threads)
        tiles = tile_grid(camera, tile_size)
        futures = [self.client.submit(worker.render_tile, self.source, camera, tile, options,
                                      image_only, pure=False, priority=len(tiles) - i)
                   for i, tile in enumerate(tiles)]
        try:
            for _, result in self._as_completed(futures):
                yield result
        finally:
            self._cancel(futures)

    # ------------------------------------------------------------------ many frames
    def render_many(self, cameras: Camera | Shot | Iterable[Camera | Shot], *,
                    image_only: bool = False, in_flight: int | None = None,
                    **kwargs: Any) -> Iterator[Frame | np.ndarray]:
        """Render a batch of frames, one task per frame, and yield them in order.

        Parameters
        ----------
        cameras : Camera, Shot or iterable of them
            The frames: cameras (a camera path) or :class:`Shot` objects carrying their own
            render options (an isovalue or transfer-function sweep).
        image_only : bool
            Yield each frame's 8-bit RGBA image (``Frame.to_uint8()``) instead of the whole
            :class:`Frame`: all a movie needs, and 4 of the Frame's 73 bytes per pixel.
        in_flight : int, optional
            Frames submitted ahead of the one the caller is waiting for (default: four per
            worker thread). Bounds the memory held by finished frames waiting for their turn.
        **kwargs
            :meth:`Scene.render` options shared by every frame (a shot's own options win).

        Yields
        ------
        Frame or ndarray
            In the order of ``cameras``, each as soon as it and every frame before it are done;
            earlier frames are scheduled first. Leaving the loop early cancels the rest.
        """
        from distributed import as_completed

        shots = as_shots(cameras, **kwargs)
        requests = [(s.camera, render_options(s.camera, (), dict(s.options), self.default_mode))
                    for s in shots]
        window = in_flight or 4 * self.threads
        running = as_completed()
        index: dict[str, int] = {}  # future key -> frame number, for the futures in flight
        futures: dict[str, Future] = {}
        finished: dict[int, Any] = {}  # results that arrived before their turn

        def submit(i: int) -> None:
            camera, options = requests[i]
            future = self.client.submit(worker.render_shot, self.source, camera, options,
                                        image_only, pure=False, priority=-i)
            index[future.key], futures[future.key] = i, future
            running.add(future)

        try:
            for i in range(min(window, len(requests))):
                submit(i)
            for turn in range(len(requests)):
                while turn not in finished:
                    future, result = self._next(running)
                    finished[index.pop(future.key)] = result
                    del futures[future.key]
                if turn + window < len(requests):
                    submit(turn + window)
                yield finished.pop(turn)
        finally:
            self._cancel(list(futures.values()))

    def _as_completed(self, futures: list[Future]) -> Iterator[tuple[Future, Any]]:
        """``(future, result)`` pairs as the futures finish."""
        from distributed import as_completed

        running = as_completed(futures)
        for _ in futures:
            yield self._next(running)

    @staticmethod
    def _next(running: Any) -> tuple[Future, Any]:
        """The next finished ``(future, result)`` of a Dask ``as_completed``.

        The wait for a task happens on a plain condition variable in this thread, so Ctrl-C
        interrupts it cleanly; only then is the (finished) result fetched, one at a time. A
        user error from a worker is raised without the worker's traceback, since its message
        already names the file or parameter.
        """
        future = next(running)
        try:
            return future, future.result()
        except SplinecastError as exc:
            raise exc.with_traceback(None) from None

    def _cancel(self, futures: list[Future]) -> None:
        """Cancel what a loop left early no longer needs (unless the client is already gone:
        a generator may be collected after its client closed)."""
        if futures and self.client.status == "running":
            self.client.cancel(futures)


def _label_options(options: dict[str, Any], smooth: int | None) -> dict[str, Any]:
    """The label scene's options taken out of ``options`` (the rest are the model's), made
    hashable: a colour table as a path or JSON text, ``show`` as a tuple."""
    import json

    labels: dict[str, Any] = {}
    for name in ("colors", "show", "opacity", "budget"):
        value = options.pop(name, None)
        if value is None:
            continue
        if name == "colors":
            value = (json.dumps(value) if isinstance(value, (dict, list))
                     else os.path.abspath(os.fspath(value)))
        elif name == "show":
            value = tuple(int(v) for v in value)
        elif name == "opacity" and isinstance(value, dict):
            value = tuple(sorted(value.items()))
        labels[name] = value
    if smooth is not None:
        labels["smooth"] = int(smooth)
    return labels
