"""Image tiles: cutting a camera's image into windows and assembling their frames into one.

Sort-first rendering splits the *image*: every tile is rendered independently through
:meth:`splinecast.Camera.tile`, whose rays are bit-identical to the same pixels of the full image,
so pasting the tiles' buffers together gives exactly the full render. Nothing here knows about
Dask: the same functions assemble tiles rendered by threads, processes or machines.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..camera import Camera
from ..errors import ParameterError
from ..render.frame import Frame

__all__ = ["Tile", "tile_grid", "auto_tile_size", "FrameCanvas", "merge_stats"]

#: Per-ray arrays of a :class:`Frame`, pasted tile by tile (``value`` only for MIP/minIP).
PIXEL_FIELDS = ("rgba", "depth", "position", "normal", "face", "cells_visited", "cells_tested",
                "blocks_skipped")


@dataclass(frozen=True)
class Tile:
    """A window of the full image: ``width x height`` pixels from column ``col0``, row ``row0``
    (row 0 at the top, as everywhere in splinecast)."""

    col0: int
    row0: int
    width: int
    height: int

    @property
    def rows(self) -> slice:
        """The tile's rows in the full image's arrays."""
        return slice(self.row0, self.row0 + self.height)

    @property
    def cols(self) -> slice:
        """The tile's columns in the full image's arrays."""
        return slice(self.col0, self.col0 + self.width)

    @property
    def pixels(self) -> int:
        """Number of rays in the tile."""
        return self.width * self.height

    def camera(self, camera: Camera) -> Camera:
        """The camera rendering exactly this window of ``camera``'s image."""
        return camera.tile(self.col0, self.row0, self.width, self.height)


def auto_tile_size(width: int, height: int, threads: int) -> int:
    """A square tile edge giving every worker thread about four tiles.

    Four tiles per thread keep the threads busy while the slowest tiles finish (tiles through
    the object cost far more than tiles of background); the edge stays between 64 pixels (below
    that the per-task overhead dominates) and 512 (above that a tile's buffers weigh ~20 MB).
    """
    tiles_wanted = 4 * max(1, int(threads))
    edge = math.sqrt(width * height / tiles_wanted)
    return int(min(512, max(64, 16 * math.floor(edge / 16))))


def tile_grid(camera: Camera, tile_size: int | tuple[int, int]) -> list[Tile]:
    """Cut ``camera``'s image into tiles of ``tile_size`` pixels (the last row and column of
    tiles are smaller when the size does not divide the image).

    Tiles are ordered from the image centre outwards, so a progressive display fills in the
    middle of the picture, where the subject usually is, first.

    Parameters
    ----------
    camera : Camera
        The full image's camera.
    tile_size : int or (int, int)
        Tile edge in pixels, or ``(width, height)``.

    Raises
    ------
    ParameterError
        If the tile size is not positive.
    """
    tw, th = (tile_size, tile_size) if np.isscalar(tile_size) else tile_size
    try:
        tw, th = int(tw), int(th)
    except (TypeError, ValueError):
        raise ParameterError(f"tile_size must be a positive integer, got {tile_size!r}") from None
    if tw < 1 or th < 1:
        raise ParameterError(f"tile_size must be positive, got {tile_size!r}")
    w, h = camera.width, camera.height
    tiles = [Tile(c, r, min(tw, w - c), min(th, h - r))
             for r in range(0, h, th) for c in range(0, w, tw)]

    def distance_from_centre(t: Tile) -> float:
        return math.hypot(t.col0 + t.width / 2 - w / 2, t.row0 + t.height / 2 - h / 2)

    return sorted(tiles, key=distance_from_centre)


class FrameCanvas:
    """The full image's buffers, filled tile by tile as tiles arrive (in any order).

    Only the buffers the tiles carry are assembled: tiles rendered with ``outputs=`` leave the
    others ``None`` in the assembled :class:`Frame`, as a local render does.

    Parameters
    ----------
    camera : Camera
        The full image's camera (its size decides the buffers' shapes).

    Examples
    --------
    >>> import splinecast as sc
    >>> vol = sc.demo("sphere", size=16)
    >>> scene, cam = sc.Scene(vol), sc.Camera.orbit(vol, size=(40, 30))
    >>> canvas = FrameCanvas(cam)
    >>> for tile in tile_grid(cam, 16):
    ...     canvas.paste(tile, scene.render(tile.camera(cam), iso=0.0))
    >>> bool((canvas.frame().depth == scene.render(cam, iso=0.0).depth).all())
    True
    """

    def __init__(self, camera: Camera) -> None:
        self.width, self.height = camera.width, camera.height
        self._arrays: dict[str, np.ndarray] = {}
        self._tile_stats: list[tuple[Tile, dict[str, Any]]] = []
        self._covered = 0

    @property
    def complete(self) -> bool:
        """Whether every pixel has been pasted (tiles must not overlap)."""
        return self._covered == self.width * self.height

    def paste(self, tile: Tile, frame: Frame) -> None:
        """Copy ``frame`` (the render of ``tile``) into its window of the full image."""
        if frame.size != (tile.width, tile.height):
            raise ValueError(f"a {frame.size} frame cannot fill tile {tile}")
        for name in PIXEL_FIELDS + ("value", "label"):
            part = getattr(frame, name)
            if part is None:  # not requested (``outputs=``) or not a MIP value
                continue
            full = self._arrays.get(name)
            if full is None:
                full = np.empty((self.height, self.width) + part.shape[2:], part.dtype)
                self._arrays[name] = full
            full[tile.rows, tile.cols] = part
        self._tile_stats.append((tile, frame.stats))
        self._covered += tile.pixels

    def frame(self, **extra_stats: Any) -> Frame:
        """The assembled :class:`Frame`, its statistics merged by :func:`merge_stats`.

        Raises
        ------
        ValueError
            If some tiles are still missing.
        """
        if not self.complete:
            raise ValueError(f"{self._covered} of {self.width * self.height} pixels rendered")
        a = self._arrays
        stats = merge_stats(self._tile_stats, a, self.width, self.height)
        stats.update(extra_stats)
        return Frame(*(a.get(name) for name in PIXEL_FIELDS), stats, a.get("value"),
                     a.get("label"))


#: Statistics recomputed from the assembled per-ray arrays (exactly the local render's numbers).
_FROM_ARRAYS = {"mean_cells_visited": "cells_visited", "mean_cells_tested": "cells_tested",
                "mean_blocks_skipped": "blocks_skipped"}
#: Counts of pixels that add up over the tiles (each tile counts its own pixels).
_SUMMED = ("antialiased",)


def merge_stats(tile_stats: list[tuple[Tile, dict[str, Any]]], arrays: dict[str, np.ndarray],
                width: int, height: int) -> dict[str, Any]:
    """One statistics dict for a frame assembled from tiles.

    * ``width``, ``height``, ``rays``: the full image's; ``tiles``: how many were merged;
    * ``hits``: counted on the assembled depth buffer; ``mean_cells_visited``,
      ``mean_cells_tested``, ``mean_blocks_skipped``: means of the assembled per-ray arrays
      (so all of these equal a local render's);
    * other ``mean_*`` numbers (per-ray counts the frame does not keep, e.g. DVR's
      ``mean_samples``): means weighted by each tile's ray count;
    * numbers under keys ending in ``_ms``: summed over tiles, i.e. the total work time spent
      in the tasks (not the wall time, which the caller adds as ``wall_ms``);
    * ``antialiased`` (pixels traced again for antialiasing): summed over tiles;
    * everything else (mode, model, isovalue, window, counts of the prepared model, ...) is the
      same for every tile and taken from the first.
    """
    if not tile_stats:
        raise ValueError("no tiles to merge")
    rays = width * height
    merged: dict[str, Any] = {}
    for key, first in tile_stats[0][1].items():
        values = [(t.pixels, s.get(key)) for t, s in tile_stats]
        numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) for _, v in values)
        if key.endswith("_ms") and numeric:
            merged[key] = float(sum(v for _, v in values))
        elif key in _SUMMED and numeric:
            merged[key] = int(sum(v for _, v in values))
        elif key.startswith("mean_") and numeric and key not in _FROM_ARRAYS:
            merged[key] = float(sum(n * v for n, v in values) / rays)
        else:
            merged[key] = first
    merged.update(width=width, height=height, rays=rays, tiles=len(tile_stats))
    if "hits" in merged and "depth" in arrays:
        merged["hits"] = int(np.count_nonzero(np.isfinite(arrays["depth"])))
    for key, name in _FROM_ARRAYS.items():
        if key in merged and name in arrays:
            merged[key] = float(arrays[name].mean())
    return merged
