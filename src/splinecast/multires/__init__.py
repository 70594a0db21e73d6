"""Multiresolution: OME-Zarr brick pyramids, the brick octree, level of detail, the brick cache
and its loader thread, cut selection, spline wavelets (see ``docs/architecture.rst``).

Nothing here is imported by ``import splinecast``; the names below load their module (and
zarr/dask) on first use::

    from splinecast.multires import build_pyramid, BrickStream
"""

from __future__ import annotations

import importlib
from typing import Any

#: Public name -> module that defines it.
_EXPORTS = {
    "build_pyramid": "store.pyramid",
    "BrickOctree": "cut.octree",
    "GHOST": "cut.octree",
    "BrickCache": "store.cache",
    "Brick": "store.cache",
    "BrickUnavailableWarning": "store.cache",
    "select_cut": "cut.lod",
    "Cut": "cut.lod",
    "ValueFilter": "cut.relevance",
    "BrickStream": "cut.stream",
    "write_table": "store.tables",
    "parse_bytes": "store.budget",
    "MultiscaleScene": "scenes.multiscale",
    "CutRenderer": "draw.cut_renderer",
    "Drawable": "draw.cut_renderer",
    "Seams": "draw.seams",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        return getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
