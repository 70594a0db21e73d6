"""TIFF stacks (multi-page or volumetric), via tifffile.

tifffile returns the stack as ``(z, y, x)``; it is transposed (a view) to ``(x, y, z)``. Spacing is
taken from ImageJ metadata when present (``spacing`` for z, the XResolution/YResolution tags, in
pixels per unit, for x and y); plain TIFF resolution tags are ignored because most writers fill
them with a meaningless 72 dpi, so other files get spacing 1. Uncompressed contiguous files are
memory-mapped.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ReadError
from ..volume import Volume
from ._common import finish_volume, fmt_shape, one_line, require

__all__ = ["read_tiff"]


def read_tiff(path: Path) -> Volume:
    """Read the first image series of a TIFF file as a 3D volume."""
    tifffile = require("tifffile", path)
    label = str(path)
    try:
        with tifffile.TiffFile(path) as tif:
            series = tif.series[0]
            axes = str(series.axes)
            shape = tuple(int(n) for n in series.shape)
            imagej = tif.imagej_metadata or {}
            page = tif.pages[0]
            xres = _resolution(page, "XResolution")
            yres = _resolution(page, "YResolution")
            data = _memmap(tifffile, path)
            if data is None or data.shape != shape:
                data = series.asarray()
    except FileNotFoundError:
        raise ReadError(f"{label}: no such file") from None
    except Exception as exc:  # tifffile raises TiffFileError, ValueError, struct.error, ...
        raise ReadError(f"{label}: not a readable TIFF ({one_line(exc)})") from None

    for channel_axis in ("S", "C"):
        if channel_axis in axes and shape[axes.index(channel_axis)] > 1:
            raise ReadError(f"{label}: colour/multi-channel TIFF (axes {axes}) is not supported")
    keep = [a for a, n in enumerate(shape) if n > 1 or axes[a] in "YX"]
    if len(keep) < 3:
        raise ReadError(f"{label}: a single 2D image ({fmt_shape(shape)}), expected a stack")
    if len(keep) > 3 or axes[keep[-2]] != "Y" or axes[keep[-1]] != "X":
        raise ReadError(f"{label}: a {len(keep)}D image (axes {axes}), expected a (z, y, x) stack")
    index = tuple(slice(None) if a in keep else 0 for a in range(len(shape)))
    data = data[index].transpose(2, 1, 0)

    spacing = [1.0, 1.0, 1.0]
    metadata: dict[str, Any] = {"format": "tiff", "axes": axes}
    if imagej:
        spacing = [xres or 1.0, yres or 1.0, float(imagej.get("spacing", 1.0) or 1.0)]
        if imagej.get("unit"):
            metadata["units"] = str(imagej["unit"])
    return finish_volume(data, spacing, 0.0, path, metadata=metadata)


def _resolution(page: Any, tag_name: str) -> float | None:
    """Pixel size from a resolution tag (a rational: pixels per unit)."""
    tag = page.tags.get(tag_name)
    if tag is None:
        return None
    value = tag.value
    num, den = (value if isinstance(value, tuple) else (value, 1))[:2]
    if not num or not den:
        return None
    return float(den) / float(num)


def _memmap(tifffile: Any, path: Path) -> np.ndarray | None:
    try:
        return tifffile.memmap(path, mode="r")
    except (ValueError, OSError):
        return None  # compressed, tiled or scattered pages: read into memory instead
