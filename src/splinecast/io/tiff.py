"""TIFF stacks (multi-page or volumetric), via tifffile.

tifffile returns the stack as ``(z, y, x)`` (once one time point and channel of a hyperstack are
chosen, see :mod:`splinecast.io.selection`); it is transposed (a view) to ``(x, y, z)``. Spacing is
taken from ImageJ metadata when present (``spacing`` for z, the XResolution/YResolution tags, in
pixels per unit, for x and y); plain TIFF resolution tags are ignored because most writers fill them
with a meaningless 72 dpi, so other files get spacing 1. Uncompressed contiguous files are
memory-mapped.

A multi-file OME-TIFF names its other files in its OME-XML (``UUID FileName``); tifffile would
open them wherever they are, so the names are checked first like any header's data file (in the
file's folder or below, unless external files are allowed).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ReadError, limits
from ..volume import Volume
from ._common import check_dtype, check_in_memory, finish_volume, fmt_shape, require, third_party
from .selection import Selection

__all__ = ["read_tiff"]


def read_tiff(path: Path, *, allow_external: bool | None = None,
              selection: Selection | None = None) -> Volume:
    """Read one 3D volume of the first image series of a TIFF file.

    A time axis (``T``) and a channel axis (``C``, or the samples ``S`` of colour pages) give a
    series of volumes: ``selection`` says which to read (default: the first, with a
    :class:`~splinecast.io.selection.SeveralVolumesWarning` when there are several). The
    series' shape and type are checked against the limits and the memory available before any
    pixel is decoded; a compressed series is decoded in full, then sliced.
    """
    selection = selection or Selection()
    counts: list[tuple[int, int]] = []
    tifffile = require("tifffile", path)
    label = str(path)
    with third_party(label, "not a readable TIFF"):
        with tifffile.TiffFile(path, _multifile=False) as tif:
            multifile = _other_files_allowed(tif.ome_metadata, path, allow_external)
    with third_party(label, "not a readable TIFF"), \
            tifffile.TiffFile(path, _multifile=multifile) as tif:
        series = tif.series[0]
        axes = str(series.axes)
        shape = tuple(int(n) for n in series.shape)
        dtype = series.dtype
        imagej = tif.imagej_metadata or {}
        page = tif.pages[0]
        xres = _resolution(page, "XResolution")
        yres = _resolution(page, "YResolution")
        # Time (T) and channel (C, or S: the samples of an RGB page) axes longer than 1: one
        # entry of each is read; every other axis but z, y, x must be 1 long.
        picked: dict[int, int] = {}
        for letters, choose in (("T", selection.time), ("CS", selection.chan)):
            found = [a for a, name in enumerate(axes) if name in letters and shape[a] > 1]
            if len(found) > 1:
                raise ReadError(f"{label}: both channel (C) and sample (S) axes (axes {axes}); "
                                "only one can be chosen from")
            count = shape[found[0]] if found else 1
            index = choose(label, count)
            if found:
                picked[found[0]] = index
            counts.append((count, index))
        keep = [a for a, n in enumerate(shape)
                if a not in picked and (n > 1 or axes[a] in "YX")]
        if len(keep) < 3:
            raise ReadError(f"{label}: a single 2D image ({fmt_shape(shape)}), expected a stack")
        if len(keep) > 3 or axes[keep[-2]] != "Y" or axes[keep[-1]] != "X":
            raise ReadError(f"{label}: a {len(keep)}D image (axes {axes}), expected a (z, y, x) "
                            "stack")
        limits.check_shape([shape[a] for a in keep], f"{label}: the image size", error=ReadError)
        if dtype is None:
            raise ReadError(f"{label}: the pages differ in pixel type")
        dtype = check_dtype(dtype, label)
        data = _memmap(tifffile, path)
        if data is None or data.shape != shape:
            check_in_memory(shape, dtype, label)
            data = series.asarray()
    if data.shape != shape:
        raise ReadError(f"{label}: decoded {fmt_shape(data.shape)} pixels, the tags give "
                        f"{fmt_shape(shape)}")

    index = tuple(slice(None) if a in keep else picked.get(a, 0) for a in range(len(shape)))
    data = data[index].transpose(2, 1, 0)

    spacing = [1.0, 1.0, 1.0]
    metadata: dict[str, Any] = {"format": "tiff", "axes": axes,
                                **selection.metadata(*counts[0], *counts[1])}
    if imagej:
        z = imagej.get("spacing", 1.0) or 1.0
        z = limits.check_finite_number(z, f"{label}: ImageJ spacing", lo=0, lo_open=True,
                                       error=ReadError)
        spacing = [xres or 1.0, yres or 1.0, z]
        if imagej.get("unit"):
            metadata["units"] = str(imagej["unit"])[:200]
    return finish_volume(data, spacing, 0.0, path, metadata=metadata)


def _other_files_allowed(ome: str | None, path: Path, allow_external: bool | None) -> bool:
    """Whether tifffile may open the other files of a multi-file OME-TIFF (raises a ReadError
    naming the first one outside the folder)."""
    if not ome:
        return False
    names = re.findall(r"""FileName\s*=\s*["']([^"']*)["']""", ome)
    for name in names:
        limits.check_data_file(path, name, "OME-XML FileName", allow_external=allow_external)
    return bool(names)


def _resolution(page: Any, tag_name: str) -> float | None:
    """Pixel size from a resolution tag (a rational: pixels per unit)."""
    tag = page.tags.get(tag_name)
    if tag is None:
        return None
    value = tag.value
    try:
        num, den = (value if isinstance(value, tuple) else (value, 1))[:2]
        if not num or not den:
            return None
        return float(den) / float(num)
    except (TypeError, ValueError, OverflowError, ZeroDivisionError):
        return None  # a malformed tag: ignored like a missing one


def _memmap(tifffile: Any, path: Path) -> np.ndarray | None:
    try:
        return tifffile.memmap(path, mode="r")
    except Exception:  # compressed, tiled, scattered or damaged pages: decode instead
        return None
