"""Per-brick tables stored with a pyramid: value ranges (the sparse 2D histograms of the error cut
have a layout of their own, :mod:`.store.hist_store`).

A table holds one entry per brick of one level, as a Zarr array ``splinecast/<name>/<level>`` in
the pyramid's group, indexed ``[bi, bj, bk, ...]`` with the brick index along x, y, z first
(splinecast order; tables are not images, so NGFF's axis order does not apply) and whatever the
table needs per brick after it. The root attribute ``splinecast["tables"][name]`` describes it.
:func:`write_table` is the one way to add a table; :meth:`MultiscaleVolume.table
<splinecast.io.omezarr.MultiscaleVolume.table>` reads one back.

The table every pyramid has, ``minmax`` (float64, ``[..., 0]`` = min, ``[..., 1]`` = max), is the
range of the voxels a brick's renderer may read: its ``B + 1`` voxels per axis plus
:data:`~splinecast.multires.cut.octree.GHOST` ghost voxels on each side, clipped to the level.
Border
padding repeats voxels of the window, so the range also bounds the padded brick. A brick without
a finite voxel has ``(+inf, -inf)``, an empty range.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from ...errors import ParameterError
from ...io._common import require
from ...io.omezarr import ATTRIBUTE, TABLES_GROUP

__all__ = ["write_table", "window_minmax", "MINMAX"]

#: Name of the value-range table every splinecast pyramid carries.
MINMAX = "minmax"


def write_table(
    store: Any,
    name: str,
    level: int,
    values: np.ndarray,
    description: str,
    chunks: tuple[int, ...] | None = None,
) -> None:
    """Store per-brick table ``name`` of ``level`` in a pyramid's group.

    Parameters
    ----------
    store : path or zarr.Group
        The pyramid's folder (opened for writing) or its open root group.
    name : str
        Table name (a valid Zarr node name, e.g. ``"minmax"``, ``"hist2d"``).
    level : int
        Pyramid level the table describes.
    values : ndarray
        Shape ``(nbx, nby, nbz, ...)``: one entry per brick of the level.
    description : str
        One line for the root attribute: what an entry holds.
    chunks : tuple of int, optional
        Chunk shape of the table array (default: the whole table in chunks of about 8 MiB).
    """
    zarr = require("zarr", str(store), action="writing tables to")
    if not name.replace("_", "").isalnum():
        raise ParameterError(f"table name {name!r} must be letters, digits and underscores")
    values = np.asarray(values)
    if values.ndim < 3:
        raise ParameterError(f"table {name}: values need a brick index along x, y, z first, "
                             f"got shape {values.shape}")
    root = store if isinstance(store, zarr.Group) else zarr.open_group(os.fspath(store), mode="r+")
    if chunks is None:
        per_brick = max(1, values[0, 0, 0].nbytes if values.ndim > 3 else values.itemsize)
        side = max(1, int(round((8 * 2**20 / per_brick) ** (1 / 3))))
        chunks = tuple(min(side, n) or 1 for n in values.shape[:3]) + values.shape[3:]
    array = root.create_array(
        f"{TABLES_GROUP}/{name}/{level}", shape=values.shape, dtype=values.dtype,
        chunks=chunks, overwrite=True,
    )
    array[...] = values
    attrs = dict(root.attrs.get(ATTRIBUTE, {}))
    tables = dict(attrs.get("tables", {}))
    entry = dict(tables.get(name, {}))
    entry["description"] = description
    entry["levels"] = sorted(set(entry.get("levels", [])) | {int(level)})
    tables[name] = entry
    attrs["tables"] = tables
    root.attrs[ATTRIBUTE] = attrs


def window_minmax(
    block: np.ndarray, block_lo: Any, bricks_lo: Any, bricks_hi: Any, brick: int, ghost: int,
    level_shape: Any,
) -> np.ndarray:
    """Value range of each brick window ``[b B - ghost, (b + 1) B + ghost]`` within ``block``.

    Parameters
    ----------
    block : ndarray, (x, y, z)
        Voxels of one level starting at level index ``block_lo``; it must contain the windows of
        bricks ``bricks_lo .. bricks_hi - 1`` (clipped to the level).
    block_lo, bricks_lo, bricks_hi, level_shape : 3 ints each
    brick, ghost : int

    Returns
    -------
    ndarray, shape (nbx, nby, nbz, 2), float64
        ``[..., 0]`` min and ``[..., 1]`` max of the finite voxels, ``(+inf, -inf)`` if none.
    """
    data = block
    if data.dtype.kind == "f":
        finite = np.isfinite(data)
        lo_data = np.where(finite, data, np.inf)
        hi_data = np.where(finite, data, -np.inf)
    else:
        lo_data = hi_data = data
    block_lo = np.asarray(block_lo, dtype=np.int64)
    bricks_lo = np.asarray(bricks_lo, dtype=np.int64)
    bricks_hi = np.asarray(bricks_hi, dtype=np.int64)
    shape = np.asarray(level_shape, dtype=np.int64)
    if np.any(bricks_hi <= bricks_lo):  # a region holding only the last voxel of a level
        return np.zeros((*np.maximum(bricks_hi - bricks_lo, 0), 2))
    # Separable: reduce each axis over every brick's window in turn (windows overlap by 2 ghost
    # layers, so a plain reshape does not do).
    mins, maxs = lo_data, hi_data
    for axis in range(3):
        parts_min, parts_max = [], []
        for b in range(bricks_lo[axis], bricks_hi[axis]):
            w0 = max(b * brick - ghost, 0) - block_lo[axis]
            w1 = min((b + 1) * brick + ghost + 1, shape[axis]) - block_lo[axis]
            take = [slice(None)] * 3
            take[axis] = slice(w0, w1)
            parts_min.append(np.min(mins[tuple(take)], axis=axis, keepdims=True))
            parts_max.append(np.max(maxs[tuple(take)], axis=axis, keepdims=True))
        mins = np.concatenate(parts_min, axis=axis)
        maxs = np.concatenate(parts_max, axis=axis)
    return np.stack([mins.astype(np.float64), maxs.astype(np.float64)], axis=-1)
