"""Rendering on a Dask cluster, and batches of frames (movies) locally or on a cluster.

Sort-first scale-out: the image is split, the volume is not. Every worker opens the same
:class:`SceneSource` (a path or a ``demo:`` spec) once and keeps the prepared scene; a frame is
cut into tiles (:mod:`.tiles`) rendered as tasks, and a batch of frames (:mod:`.shots`) is one task
per frame. Movies (:mod:`.movie`) write such batches to MP4, GIF or a folder of PNGs.

- :mod:`.source`: what a worker opens (:class:`SceneSource`) and the header it reports
  (:class:`VolumeInfo`);
- :mod:`.worker`: the per-process scene cache and the task functions;
- :mod:`.tiles`: tiles of an image and the assembly of their frames;
- :mod:`.shots`: one frame's camera and options (:class:`Shot`), camera paths, local batches;
- :mod:`.scene`: :class:`DistributedScene`;
- :mod:`.movie`: movie files written frame by frame, all or nothing.

Sort-last rendering (bricks of an OME-Zarr pyramid spread over the workers, partial images
composited in visibility order) will live beside them in ``sort_last.py``.

Importing this package does not import Dask; creating a :class:`DistributedScene` does.
"""

from .movie import MovieWriter
from .scene import DistributedScene
from .shots import Shot, as_shots, orbit_path, ramp, render_locally
from .source import SceneSource, VolumeInfo
from .tiles import FrameCanvas, Tile, auto_tile_size, merge_stats, tile_grid

__all__ = [
    "DistributedScene",
    "FrameCanvas",
    "MovieWriter",
    "SceneSource",
    "Shot",
    "Tile",
    "VolumeInfo",
    "as_shots",
    "auto_tile_size",
    "merge_stats",
    "orbit_path",
    "ramp",
    "render_locally",
    "tile_grid",
]
