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
- :mod:`.movie`: movie files written frame by frame, all or nothing;
- :mod:`.cluster`: :func:`local_cluster`, a ``LocalCluster`` whose background polling does not
  take the renders' cores.

Sort-last scale-out: the data is split, the image is not. ``DistributedScene(store, client,
model, strategy="sort-last", level=k)`` (:mod:`.sort_last`, :class:`SortLastScene`) assigns the
bricks of level ``k`` of an OME-Zarr pyramid to the workers by a k-d split (each worker reads
only its own bricks' chunks and keeps them); each worker traces its bricks into a partial image
(the mode's unfinished per-pixel state), and the partial images are merged pairwise up the k-d
tree in visibility order by tasks on the workers, so the client receives only the final frame.

- :mod:`.sort_last`: :class:`SortLastScene`, the k-d split (:func:`split_bricks`), the shares
  (:class:`Share`) and the worker tasks that trace, combine and finish partial images.

Importing this package does not import Dask; creating a :class:`DistributedScene` does.
"""

from .cluster import QUIET_CONFIG, local_cluster
from .movie import MovieWriter
from .scene import STRATEGIES, DistributedScene
from .shots import Shot, as_shots, orbit_path, ramp, render_locally
from .sort_last import KdNode, Partial, Share, SortLastScene, split_bricks
from .source import SceneSource, VolumeInfo
from .tiles import FrameCanvas, Tile, auto_tile_size, merge_stats, tile_grid

__all__ = [
    "DistributedScene",
    "FrameCanvas",
    "KdNode",
    "MovieWriter",
    "QUIET_CONFIG",
    "Partial",
    "STRATEGIES",
    "SceneSource",
    "Share",
    "Shot",
    "SortLastScene",
    "Tile",
    "VolumeInfo",
    "as_shots",
    "local_cluster",
    "auto_tile_size",
    "merge_stats",
    "orbit_path",
    "ramp",
    "render_locally",
    "split_bricks",
    "tile_grid",
]
