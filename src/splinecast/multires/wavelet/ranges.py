"""Conservative per-chunk value ranges of a spline-wavelet pyramid (Steinberger 2010, §3.3.3, §4.4).

Two tables, both computed from coefficients, never by sampling:

``hull[j]`` (per chunk of level ``j``)
    ``[min, max]`` of the level-``j`` coefficients that act on the chunk's region inside the
    voxel box. By the B-spline convex-hull property (the basis is non-negative and sums to one)
    the pure level-``j`` spline lies in this interval everywhere on the region. Computed during
    the decomposition, block by block (:func:`block_hulls`).

``selection range`` (per chunk, :func:`selection_ranges`)
    The interval the view-dependent selection tests the isovalue against before it adds a
    chunk's details. It must cover every surface the details could reveal or remove, so it is the
    union, over the chunk's 3x3x3 neighbourhood (a chunk's wavelets reach at most 4 cells into its
    neighbours, see :mod:`.wavelet.lod`), of the hulls of every pure level ``0 .. j + 1`` —
    the full-resolution spline (level 0), the level the chunk reconstructs (``j``) and the level
    shown when it is not refined (``j + 1``, through the parent's hull). If the isovalue lies
    outside it, no single-level approximation at these levels, in particular not the full
    resolution, has a surface there.

    A *mixed* selection's spline (some neighbours refined, some not) is not bounded by these
    pure-level hulls in general; the renderer bounds each reconstructed brick by the convex hull
    of its own coefficients, which is exact for what it draws.
"""

from __future__ import annotations

import numpy as np

from .layout import WaveletLayout

__all__ = ["block_hulls", "selection_ranges", "EMPTY_RANGE"]

#: Range of a chunk whose region holds no cell of the level (never contains an isovalue).
EMPTY_RANGE = (np.inf, -np.inf)


def _axis_windows(layout: WaveletLayout, level: int, axis: int, chunks: range,
                  first_node: int) -> list[tuple[int, int]]:
    """Per chunk, the node slice (relative to ``first_node``) acting on its in-box cells."""
    before, after = layout.cell_nodes()
    k = layout.chunk
    first_cell, last_cell = layout.domain_cells(level, axis)
    out = []
    for c in chunks:
        lo = max(k * c, first_cell)
        hi = min(k * c + k - 1, last_cell)
        if lo > hi:
            out.append((0, 0))
        else:
            out.append((lo - before - first_node, hi + after - first_node + 1))
    return out


def block_hulls(layout: WaveletLayout, level: int, block: np.ndarray, first: tuple[int, ...],
                chunk_lo: tuple[int, ...], chunk_hi: tuple[int, ...],
                lo_out: np.ndarray, hi_out: np.ndarray) -> None:
    """Fill ``hull[level]`` for chunks ``chunk_lo .. chunk_hi - 1`` (per axis) from a block.

    ``block`` holds the level's (extended) coefficients of nodes ``first .. first + shape - 1``
    and must include every node acting on those chunks' cells; ``lo_out`` / ``hi_out`` are the
    level's hull tables, written in place. The minimum over a box is separable, so it is taken
    one axis at a time.
    """
    windows = [
        _axis_windows(layout, level, a, range(chunk_lo[a], chunk_hi[a]), first[a])
        for a in range(3)
    ]
    box = tuple(slice(chunk_lo[a], chunk_hi[a]) for a in range(3))
    lo_out[box] = _box_reduce(block, windows, np.min, np.inf)
    hi_out[box] = _box_reduce(block, windows, np.max, -np.inf)


def _box_reduce(block: np.ndarray, windows: list[list[tuple[int, int]]], reduce,
                empty: float) -> np.ndarray:
    cur = block
    for a in range(3):
        parts = []
        for s, e in windows[a]:
            if e <= s:
                shape = list(cur.shape)
                shape[a] = 1
                parts.append(np.full(shape, empty))
            else:
                sl = [slice(None)] * 3
                sl[a] = slice(s, e)
                parts.append(reduce(cur[tuple(sl)], axis=a, keepdims=True))
        cur = np.concatenate(parts, axis=a)
    return cur


def _grow(table: np.ndarray, reduce) -> np.ndarray:
    """Min or max over each entry's 3x3x3 neighbourhood (edges see fewer neighbours)."""
    out = table.copy()
    for a in range(3):
        n = out.shape[a]
        if n == 1:
            continue
        lo = [slice(None)] * 3
        hi = [slice(None)] * 3
        lo[a], hi[a] = slice(0, n - 1), slice(1, n)
        shifted = out.copy()
        shifted[tuple(lo)] = reduce(shifted[tuple(lo)], out[tuple(hi)])
        shifted[tuple(hi)] = reduce(shifted[tuple(hi)], out[tuple(lo)])
        out = shifted
    return out


def _coarsen(table: np.ndarray, shape: tuple[int, ...], reduce) -> np.ndarray:
    """Children table -> parent table (reduce over each parent's up to 8 children)."""
    out = np.full(shape, np.inf if reduce is np.minimum else -np.inf)
    for ox in (0, 1):
        for oy in (0, 1):
            for oz in (0, 1):
                part = table[ox::2, oy::2, oz::2]
                sx, sy, sz = part.shape
                out[:sx, :sy, :sz] = reduce(out[:sx, :sy, :sz], part)
    return out


def _refine(table: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """Parent table -> children table (each child gets its parent's entry)."""
    idx = [np.arange(n) // 2 for n in shape]
    return table[np.ix_(*idx)]


def selection_ranges(layout: WaveletLayout, hull_lo: list[np.ndarray],
                     hull_hi: list[np.ndarray]) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Selection ranges of every chunk of levels 0..J-1 (see the module docstring).

    Parameters
    ----------
    layout : WaveletLayout
    hull_lo, hull_hi : list of arrays
        ``hull[j]`` tables for j = 0..J, shapes ``layout.chunks(j)``.

    Returns
    -------
    lo, hi : list of arrays
        Per level 0..J-1 (the levels whose chunks own details), shapes ``layout.chunks(j)``.
    """
    lo_out, hi_out = [], []
    tree_lo, tree_hi = hull_lo[0], hull_hi[0]
    for j in range(layout.levels):
        shape = layout.chunks(j)
        if j > 0:
            tree_lo = np.minimum(_coarsen(tree_lo, shape, np.minimum), hull_lo[j])
            tree_hi = np.maximum(_coarsen(tree_hi, shape, np.maximum), hull_hi[j])
        lo = np.minimum(tree_lo, _refine(hull_lo[j + 1], shape))
        hi = np.maximum(tree_hi, _refine(hull_hi[j + 1], shape))
        lo_out.append(_grow(lo, np.minimum))
        hi_out.append(_grow(hi, np.maximum))
    return lo_out, hi_out
