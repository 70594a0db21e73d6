"""What runs inside a worker process: the per-process scene cache and the render tasks.

The task functions take a :class:`SceneSource` (a few hundred bytes), never a volume. The first
task on a worker opens the source and prepares the model; later tasks, frames and renders reuse
the prepared :class:`~splinecast.Scene`. A worker that restarts (after a crash) starts with an
empty cache and simply opens the source again on its first task.

Renders within one process run one at a time, each on as many Numba threads as the Dask worker
has threads: a render already keeps all of them busy, and one render at a time keeps a scene's
per-isovalue state (its block classification) consistent.
"""

from __future__ import annotations

import dataclasses
import threading
from collections import OrderedDict

import numpy as np

from ..camera import Camera
from ..errors import SplinecastError
from ..render.frame import Frame
from ..render.template import RenderOptions
from ..scene import Scene
from .source import SceneSource, VolumeInfo
from .tiles import Tile

__all__ = ["prepare", "render_tile", "render_shot", "forget", "MAX_SCENES"]

#: Prepared scenes a worker process keeps (least recently used dropped first).
MAX_SCENES = 2

_scenes: OrderedDict[SceneSource, Scene] = OrderedDict()
_lock = threading.RLock()  # guards the cache and serializes renders in this process


def _scene(source: SceneSource) -> Scene:
    """The prepared scene of ``source`` in this process, opening it on first use."""
    scene = _scenes.get(source)
    if scene is not None:
        _scenes.move_to_end(source)
        return scene
    try:
        scene = source.open()
    except SplinecastError as exc:
        # The message names the file; add the worker, since on a cluster the file may be
        # missing on only some machines.
        where = _where()
        if not where:
            raise
        raise type(exc)(f"{where}{exc}") from None
    _scenes[source] = scene
    while len(_scenes) > MAX_SCENES:
        _scenes.popitem(last=False)
    return scene


def _where() -> str:
    """``"worker ADDRESS: "`` inside a Dask worker, empty elsewhere."""
    try:
        from distributed import get_worker

        return f"worker {get_worker().address}: "
    except (ImportError, ValueError):
        return ""


def _use_worker_threads() -> None:
    """Give this task's Numba kernels as many threads as the Dask worker has.

    Without it every single-threaded worker would start one Numba thread per core and the
    workers of a machine would fight over its cores.
    """
    try:
        from distributed import get_worker

        threads = get_worker().state.nthreads
    except (ImportError, ValueError, AttributeError):
        return
    import numba

    numba.set_num_threads(max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS)))


def prepare(source: SceneSource) -> VolumeInfo | SplinecastError:
    """Open and prepare ``source`` in this process (if not yet) and return its header.

    A user error (missing file, bad header, bad model option) is *returned*, not raised: the
    client reports it as one line naming the path, and the worker logs no traceback for it.
    """
    with _lock:
        try:
            return VolumeInfo.of(_scene(source).volume)
        except SplinecastError as exc:
            return exc


def forget(source: SceneSource) -> bool:
    """Drop this process's prepared scene of ``source``; whether there was one."""
    with _lock:
        return _scenes.pop(source, None) is not None


def render_tile(source: SceneSource, camera: Camera, tile: Tile, options: RenderOptions,
                image_only: bool = False) -> tuple[Tile, Frame | np.ndarray]:
    """Render the ``tile`` window of ``camera``'s image with the scene's render template."""
    return tile, render_shot(source, tile.camera(camera), options, image_only)


def render_shot(source: SceneSource, camera: Camera, options: RenderOptions,
                image_only: bool = False) -> Frame | np.ndarray:
    """Render one image: the prepared scene's ``render_frame`` (the render template's step for
    a frame, as its ``render`` calls it) of ``options``; with ``image_only`` return just its
    8-bit RGBA colours, which is all a movie or a display needs and 1/18 of the frame's
    buffers."""
    if image_only and options.outputs is None:
        # Colour is all that is kept: the other buffers are not even filled.
        options = dataclasses.replace(options, outputs=("rgba",))
    with _lock:
        _use_worker_threads()
        scene = _scene(source)
        frame = scene.render_frame(camera, options, scene.check_frame_options({}))
    return frame.to_uint8() if image_only else frame
