"""Sparse 2D histograms per brick: what a transfer-function edit needs to recompute D(b).

Eq. (1) of Carmona & Froehlich 2011 sums, over the source voxels ``f_i`` a brick approximates, the
CIELUV distance between the classified colours of ``f_i`` and of its approximation ``b_i``. The
distance depends on the pair of values only, so a brick's distortion under any transfer function is
``D(b) = sum over (u, v) of H_b(u, v) * D(u, v)`` where ``H_b`` counts the (quantized source value
``u``, quantized approximating value ``v``) pairs of the brick: the "summary tables" the paper
stores sparsely next to the pyramid. A transfer-function edit then costs one pass over the non-zero
entries, never a voxel read.

What "the brick's approximation" is
-----------------------------------
The value a renderer drawing brick ``b`` (level ``l``) shows at the centre of source voxel ``i``:
the **trilinear reconstruction of level ``l``** evaluated there. A source index ``i`` maps to the
continuous level-``l`` index ``u = a i + c`` per axis; for the 2x2x2 mean pyramid (a coarse voxel
is the mean of the 2x2x2 voxels below it, so its centre is their centroid) ``a = 2^-l`` and
``c = 2^-l / 2 - 1/2`` (:func:`mean_pyramid_map`); a store with other NGFF ``scale`` and
``translation`` passes its own map. Positions beyond the outermost coarse voxel centres are clamped
(edge extension), as the brick's ghost layers would do. Why this and not "the coarse voxel that
contains ``i``": the renderer reconstructs trilinearly, so this is the error a viewer sees, and it
needs no extra convention. Leaves (level 0) are the source itself: their histograms are empty and
their distortion is 0.

Quantization
------------
Values are quantized into ``bins`` bins (:class:`Quantizer`), bin ``k`` standing for the value
``lo + k (hi - lo) / (bins - 1)``, a value going to the nearest bin (``floor(x + 1/2)``); for
8-bit data ``lo, hi = 0, 255``, otherwise the data range. The default is **64 bins**
(:data:`DEFAULT_BINS`). The paper's transparency table uses 255 intervals and its reference [3]
256-entry summary tables; 256 bins are exact for 8-bit data, but the number of distinct (source,
approximation) pairs of a noisy brick grows with the square of the bins: on the MNI152 MRI with
16^3 bricks, 256 bins cost 52% of the source in histogram bytes (8% compressed), 64 bins 6.5%
(1.4% compressed), and the distortion summed over the tree moves by 0.2%. Pass ``bins=256`` for
exact 8-bit bins.

Storage (flat arrays, storage-neutral)
--------------------------------------
:class:`BrickHistograms` holds, for the K nodes of a :class:`~.cut.tree.BrickTree`, the
non-zero entries in CSR form: ``offsets`` (K + 1, int64); ``keys`` (uint16 when ``bins <= 256``:
``source_bin * bins + approx_bin``, ascending within a node); ``counts`` (uint32). That is 6 bytes
per non-zero pair; :meth:`BrickHistograms.to_arrays` gives the three arrays plus the quantizer as
a dict a store writes next to the bricks.
"""

from __future__ import annotations

from collections import namedtuple
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np

from ..._jit import jit, read_only
from ..._jit.work_queue import run_items, take
from ...errors import ParameterError
from .tree import BrickGrid, regular_brick_tree, segment_indices

__all__ = [
    "DEFAULT_BINS",
    "Quantizer",
    "BrickHistograms",
    "mean_pyramid_map",
    "approximate",
    "brick_histogram",
    "pyramid_histograms",
    "box_histograms",
    "stack_histograms",
    "coarsen_histograms",
    "leaf_value_ranges",
]

#: Histogram bins per value axis unless told otherwise (see "Quantization" above).
DEFAULT_BINS = 64

#: Upper bound on histogram entries one batch of bricks may produce (48 MiB of buffers).
_BATCH_ENTRIES = 1 << 23


@dataclass(frozen=True)
class Quantizer:
    """``bins`` bins over ``[lo, hi]``; bin ``k`` stands for ``lo + k (hi - lo) / (bins - 1)``."""

    lo: float
    hi: float
    bins: int = DEFAULT_BINS

    def __post_init__(self) -> None:
        if not (self.hi > self.lo) or self.bins < 2 or self.bins > 65536:
            raise ParameterError(f"a quantizer needs lo < hi and 2..65536 bins, got {self}")

    @classmethod
    def for_data(cls, dtype: Any, value_range: tuple[float, float],
                 bins: int = DEFAULT_BINS) -> Quantizer:
        """8-bit integers span their whole range (with 256 bins, the bins are the values);
        other dtypes span ``value_range``."""
        dtype = np.dtype(dtype)
        if dtype.kind in "ui" and dtype.itemsize == 1:
            info = np.iinfo(dtype)
            return cls(float(info.min), float(info.max), bins)
        lo, hi = float(value_range[0]), float(value_range[1])
        return cls(lo, hi if hi > lo else lo + 1.0, bins)

    @property
    def scale(self) -> float:
        """Bins per data unit."""
        return (self.bins - 1) / (self.hi - self.lo)

    @property
    def values(self) -> np.ndarray:
        """The value each bin stands for, shape ``(bins,)``."""
        return self.lo + np.arange(self.bins) / self.scale

    def bin_of(self, values: Any) -> np.ndarray:
        """The nearest bin of each value (clamped to the range), as int64."""
        x = (np.asarray(values, np.float64) - self.lo) * self.scale
        return np.clip(np.floor(x + 0.5), 0, self.bins - 1).astype(np.int64)


@dataclass(frozen=True, eq=False)
class BrickHistograms:
    """Sparse (source bin, approximating bin) counts for every node of a brick tree.

    Attributes
    ----------
    offsets : numpy.ndarray
        (K + 1,) int64; node ``b``'s entries are ``[offsets[b], offsets[b + 1])``.
    keys : numpy.ndarray
        ``source_bin * bins + approx_bin``, ascending within a node (uint16 for 256 bins).
    counts : numpy.ndarray
        Number of source voxels with that pair (uint32).
    quantizer : Quantizer
        The bins.
    """

    offsets: np.ndarray
    keys: np.ndarray
    counts: np.ndarray
    quantizer: Quantizer

    @property
    def nbytes(self) -> int:
        """Bytes a store spends on the three arrays."""
        return int(self.offsets.nbytes + self.keys.nbytes + self.counts.nbytes)

    def node(self, b: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(source_bins, approx_bins, counts)`` of node ``b``."""
        s = slice(self.offsets[b], self.offsets[b + 1])
        keys = self.keys[s].astype(np.int64)
        return keys // self.quantizer.bins, keys % self.quantizer.bins, self.counts[s]

    def to_arrays(self) -> dict[str, Any]:
        """Plain arrays and numbers to store next to the bricks (see :meth:`from_arrays`)."""
        q = self.quantizer
        return {"hist_offsets": self.offsets, "hist_keys": self.keys, "hist_counts": self.counts,
                "hist_lo": q.lo, "hist_hi": q.hi, "hist_bins": q.bins}

    @classmethod
    def from_arrays(cls, arrays: dict[str, Any]) -> BrickHistograms:
        """Inverse of :meth:`to_arrays`."""
        q = Quantizer(float(arrays["hist_lo"]), float(arrays["hist_hi"]),
                      int(arrays["hist_bins"]))
        return cls(np.asarray(arrays["hist_offsets"], np.int64), np.asarray(arrays["hist_keys"]),
                   np.asarray(arrays["hist_counts"]), q)


def _key_dtype(bins: int) -> type:
    return np.uint16 if bins <= 256 else np.uint32


# ------------------------------------------------------------------------------ approximation
def mean_pyramid_map(level: int) -> tuple[np.ndarray, np.ndarray]:
    """Source index ``i`` to level-``level`` continuous index ``u = a i + c`` of a mean pyramid.

    A level-``l`` voxel averages ``2^l`` source voxels per axis, so its centre lies at source
    index ``2^l (I + 1/2) - 1/2``; inverting gives ``a = 2^-l``, ``c = 2^-l / 2 - 1/2``.
    """
    f = float(2 ** int(level))
    return np.full(3, 1.0 / f), np.full(3, 0.5 / f - 0.5)


def _axis_taps(n_coarse: int, lo: int, hi: int, a: float,
               c: float) -> tuple[np.ndarray, np.ndarray]:
    """Lower coarse index and weight of the linear interpolation for source indices lo..hi-1."""
    u = np.clip(a * np.arange(lo, hi, dtype=np.float64) + c, 0.0, n_coarse - 1.0)
    i0 = np.minimum(np.floor(u).astype(np.int64), max(n_coarse - 2, 0))
    return i0, u - i0


def approximate(coarse: np.ndarray, lo: Any, hi: Any, a: Any, c: Any) -> np.ndarray:
    """Level values (trilinear, edge-clamped) at source voxels ``[lo, hi)`` per axis: float64.

    ``coarse`` is the whole level array; ``u = a i + c`` maps source index to level index.
    Separable: one linear interpolation per axis. For small blocks (tests, one brick).
    """
    out = np.asarray(coarse, np.float64)
    for axis in range(3):
        n = out.shape[axis]
        i0, w = _axis_taps(n, int(lo[axis]), int(hi[axis]), float(a[axis]), float(c[axis]))
        i1 = np.minimum(i0 + 1, n - 1)
        shape = [1, 1, 1]
        shape[axis] = -1
        w = w.reshape(shape)
        out = np.take(out, i0, axis=axis) * (1.0 - w) + np.take(out, i1, axis=axis) * w
    return out


def brick_histogram(source: np.ndarray, approx: np.ndarray,
                    quantizer: Quantizer) -> tuple[np.ndarray, np.ndarray]:
    """Sparse histogram of one brick from its source values and their approximations.

    Parameters
    ----------
    source, approx : numpy.ndarray
        Same shape: the source voxels the brick covers and the brick's approximation of each
        (for example from :func:`approximate`).
    quantizer : Quantizer

    Returns
    -------
    keys, counts : numpy.ndarray
        Ascending ``source_bin * bins + approx_bin`` and their counts.
    """
    if np.shape(source) != np.shape(approx):
        raise ParameterError("source and approx must have the same shape")
    keys = quantizer.bin_of(source).ravel() * quantizer.bins + quantizer.bin_of(approx).ravel()
    uniq, counts = np.unique(keys, return_counts=True)
    return uniq.astype(_key_dtype(quantizer.bins)), counts.astype(np.uint32)


# ------------------------------------------------------------------- compiled histogram kernels
@jit(inline="always")
def _quantize(x, lo, scale, top):
    k = np.floor((x - lo) * scale + 0.5)
    if k < 0.0:
        return 0
    if k > top:
        return int(top)
    return int(k)


@jit(nogil=True)
def _taps(n, lo, m, a, c):
    """Lower coarse index and weight per source index lo..lo+m-1 (as :func:`_axis_taps`)."""
    i0 = np.empty(m, np.int64)
    w = np.empty(m, np.float64)
    for t in range(m):
        u = min(max(a * (lo + t) + c, 0.0), n - 1.0)
        f = min(int(np.floor(u)), max(n - 2, 0))
        i0[t] = f
        w[t] = u - f
    return i0, w


#: The quantizer of the histograms' values (its ``lo`` and ``scale``) and bins per axis.
_Quant = namedtuple("_Quant", ("lo", "scale", "bins"))

#: The output arrays of the sparse histograms: keys and counts.
_Out = namedtuple("_Out", ("keys", "counts"))


@jit(nogil=True)
def _one_brick(source, coarse, lo, hi, ax, cx, quant, dense, touched, out, out_at):
    """Count the pairs of one brick into ``dense`` and write them, sorted, at ``out_at`` of
    ``out`` (:class:`_Out`); ``quant`` is the :class:`_Quant` of the values."""
    qlo, qscale, bins = quant
    out_keys, out_counts = out
    top = float(bins - 1)
    n0, n1, n2 = coarse.shape
    # Per-axis taps of the trilinear interpolation that gives eq. (1)'s b_i.
    xi, xw = _taps(n0, lo[0], hi[0] - lo[0], ax[0], cx[0])
    yi, yw = _taps(n1, lo[1], hi[1] - lo[1], ax[1], cx[1])
    zi, zw = _taps(n2, lo[2], hi[2] - lo[2], ax[2], cx[2])
    mz = hi[2] - lo[2]
    z_first = zi[0]
    z_last = min(zi[mz - 1] + 1, n2 - 1)
    row = np.empty(z_last - z_first + 1, np.float64)
    ntouched = 0
    for p in range(hi[0] - lo[0]):
        x0 = xi[p]
        x1 = min(x0 + 1, n0 - 1)
        wx = xw[p]
        for q in range(hi[1] - lo[1]):
            y0 = yi[q]
            y1 = min(y0 + 1, n1 - 1)
            wy = yw[q]
            # The bilinear (x, y) interpolation once per coarse z, then one lerp per voxel: a
            # level-l brick has 2^l source voxels per coarse voxel along z.
            for z in range(z_first, z_last + 1):
                c0 = coarse[x0, y0, z] * (1.0 - wy) + coarse[x0, y1, z] * wy
                c1 = coarse[x1, y0, z] * (1.0 - wy) + coarse[x1, y1, z] * wy
                row[z - z_first] = c0 * (1.0 - wx) + c1 * wx
            for r in range(mz):
                z0 = zi[r] - z_first
                z1 = min(zi[r] + 1, n2 - 1) - z_first
                value = row[z0] * (1.0 - zw[r]) + row[z1] * zw[r]
                f = _quantize(float(source[lo[0] + p, lo[1] + q, lo[2] + r]), qlo, qscale, top)
                key = f * bins + _quantize(value, qlo, qscale, top)
                if dense[key] == 0:
                    touched[ntouched] = key
                    ntouched += 1
                dense[key] += 1
    keys = np.sort(touched[:ntouched])
    for t in range(ntouched):
        out_keys[out_at + t] = keys[t]
        out_counts[out_at + t] = dense[keys[t]]
        dense[keys[t]] = 0
    return ntouched


def _brick_batch(source, coarse, lo, hi, ax, cx, quant, out_at, out, nnz, nchunks):
    """Histograms of bricks ``lo[b]..hi[b]`` (source ranges), one thread per chunk of bricks
    (``quant``: a :class:`_Quant`, ``out``: an :class:`_Out`; chunk ``i`` takes every
    ``nchunks``-th brick from ``i``)."""
    run_items(_brick_batch_chunks, nchunks, source, coarse, lo, hi, ax, cx, quant, out_at, out,
              nnz, nchunks)


@jit
def _brick_batch_chunks(source, coarse, lo, hi, ax, cx, quant, out_at, out, nnz, nchunks,
                        counter):
    """One thread's share of :func:`_brick_batch`: the chunks of bricks it takes."""
    bins = quant.bins
    nb = lo.shape[0]
    while True:
        chunk = take(counter)
        if chunk >= nchunks:
            break
        dense = np.zeros(bins * bins, np.int64)
        touched = np.empty(bins * bins, np.int64)
        for b in range(chunk, nb, nchunks):
            nnz[b] = _one_brick(source, coarse, lo[b], hi[b], ax, cx, quant, dense, touched,
                                out, out_at[b])


def _sum_rows(offsets, keys, counts, group_start, members, nkeys, out_at, out_keys, out_counts,
              nnz, nchunks):
    """Sparse sum of the histograms ``members[group_start[g]:group_start[g + 1]]`` per group
    (chunk ``i`` of ``nchunks``, one per thread, takes every ``nchunks``-th group from ``i``)."""
    run_items(_sum_row_chunks, nchunks, offsets, keys, counts, group_start, members, nkeys, out_at,
              out_keys, out_counts, nnz, nchunks)


@jit
def _sum_row_chunks(offsets, keys, counts, group_start, members, nkeys, out_at, out_keys,
                    out_counts, nnz, nchunks, counter):
    """One thread's share of :func:`_sum_rows`: the chunks of groups it takes."""
    ng = group_start.shape[0] - 1
    while True:
        chunk = take(counter)
        if chunk >= nchunks:
            break
        dense = np.zeros(nkeys, np.int64)
        touched = np.empty(nkeys, np.int64)
        for g in range(chunk, ng, nchunks):
            ntouched = 0
            for m in range(group_start[g], group_start[g + 1]):
                node = members[m]
                for e in range(offsets[node], offsets[node + 1]):
                    key = keys[e]
                    if dense[key] == 0:
                        touched[ntouched] = key
                        ntouched += 1
                    dense[key] += counts[e]
            sorted_keys = np.sort(touched[:ntouched])
            for t in range(ntouched):
                out_keys[out_at[g] + t] = sorted_keys[t]
                out_counts[out_at[g] + t] = dense[sorted_keys[t]]
                dense[sorted_keys[t]] = 0
            nnz[g] = ntouched


@jit
def _leaf_range_items(source, brick, ghost, nb0, nb1, nb2, vmin, vmax, counter):
    """One thread's share of :func:`leaf_value_ranges`: the bricks it takes."""
    n0, n1, n2 = source.shape
    while True:
        b = take(counter)
        if b >= nb0 * nb1 * nb2:
            break
        a = b // (nb1 * nb2)
        bb = (b // nb2) % nb1
        cc = b % nb2
        lo = source[min(a * brick, n0 - 1), min(bb * brick, n1 - 1), min(cc * brick, n2 - 1)]
        hi = lo
        for i in range(max(a * brick - ghost, 0), min((a + 1) * brick + ghost, n0)):
            for j in range(max(bb * brick - ghost, 0), min((bb + 1) * brick + ghost, n1)):
                for k in range(max(cc * brick - ghost, 0), min((cc + 1) * brick + ghost, n2)):
                    v = source[i, j, k]
                    if v < lo:
                        lo = v
                    if v > hi:
                        hi = v
        vmin[b] = lo
        vmax[b] = hi


def _batches(sizes: np.ndarray, limit: int) -> list[tuple[int, int]]:
    """Consecutive index ranges whose ``sizes`` add up to at most ``limit`` (at least one item)."""
    out, start, total = [], 0, 0
    for i, s in enumerate(sizes.tolist()):
        if i > start and total + s > limit:
            out.append((start, i))
            start, total = i, 0
        total += s
    if start < len(sizes):
        out.append((start, len(sizes)))
    return out


def _compact(parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]], key_dtype: type,
             count_dtype: type) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Concatenate per-batch (nnz, keys, counts) into CSR (row lengths, keys, counts)."""
    nnz = np.concatenate([p[0] for p in parts]) if parts else np.zeros(0, np.int64)
    keys = np.concatenate([p[1] for p in parts]).astype(key_dtype, copy=False)
    counts = np.concatenate([p[2] for p in parts]).astype(count_dtype, copy=False)
    return nnz, keys, counts


def _run_batched(sizes: np.ndarray, run) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Call ``run(start, stop, out_at, keys, counts, nnz)`` per batch; keep the filled entries."""
    parts = []
    for start, stop in _batches(sizes, _BATCH_ENTRIES):
        cap = sizes[start:stop]
        out_at = np.concatenate([[0], np.cumsum(cap)[:-1]]).astype(np.int64)
        keys = np.empty(int(cap.sum()), np.int64)
        counts = np.empty(int(cap.sum()), np.int64)
        nnz = np.zeros(stop - start, np.int64)
        run(start, stop, out_at, keys, counts, nnz)
        keep = segment_indices(out_at, nnz)
        parts.append((nnz, keys[keep], counts[keep]))
    return parts


def pyramid_histograms(levels: list[np.ndarray], brick: int, quantizer: Quantizer,
                       maps: list[tuple[np.ndarray, np.ndarray]] | None = None
                       ) -> BrickHistograms:
    """Histograms of every node of ``regular_brick_tree(levels[0].shape, brick)``.

    Parameters
    ----------
    levels : list of numpy.ndarray
        The pyramid, finest first; ``levels[0]`` is the source and may be a ``numpy.memmap``
        (it is read brick by brick; the coarser levels are read whole, they are 1/7 of it).
        Level ``l`` must have the shape :func:`~.cut.tree.regular_brick_tree` gives it.
    brick : int
        Voxels per brick edge.
    quantizer : Quantizer
    maps : list of (a, c), optional
        Source index to level index per level (default :func:`mean_pyramid_map`).

    Returns
    -------
    BrickHistograms
        In the node order of the regular tree; leaves are empty.

    Notes
    -----
    Every level is one pass over the source; memory is bounded by one batch of output buffers
    (48 MiB) and a 65536-entry counting table per thread, whatever the volume size.
    """
    source = levels[0]
    tree_grid = regular_brick_tree(source.shape, brick).grid
    _check_levels(levels, tree_grid)
    bins = quantizer.bins
    nthreads = numba.get_num_threads()
    parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = [
        (np.zeros(tree_grid.level_offsets[1], np.int64), np.zeros(0, np.int64),
         np.zeros(0, np.int64))]
    for lv in range(1, tree_grid.levels):
        a, c = (mean_pyramid_map(lv) if maps is None else (maps[lv][0], maps[lv][1]))
        idx = np.indices(tree_grid.level_bricks[lv]).reshape(3, -1).T
        lo, hi = tree_grid.footprint(lv, idx)
        sizes = np.minimum(np.prod(hi - lo, axis=1), bins * bins)
        lo, hi, a, c, coarse = _batch_arrays(lo, hi, a, c, levels[lv])

        def run(start, stop, out_at, keys, counts, nnz, lo=lo, hi=hi, a=a, c=c, coarse=coarse):
            _brick_batch(read_only(source), coarse, lo[start:stop], hi[start:stop], a, c,
                         _Quant(quantizer.lo, quantizer.scale, bins), out_at,
                         _Out(keys, counts), nnz, nthreads)

        parts.extend(_run_batched(sizes, run))
    nnz, keys, counts = _compact(parts, _key_dtype(bins), _count_dtype(source.size))
    offsets = np.concatenate([[0], np.cumsum(nnz)]).astype(np.int64)
    return BrickHistograms(offsets, keys, counts, quantizer)


def _batch_arrays(lo: Any, hi: Any, a: Any, c: Any, coarse: np.ndarray) -> tuple:
    """The read arguments of :func:`_brick_batch` in one form whatever the caller's arrays are
    (C order, read-only views; a pyramid map's cached or broadcast arrays are read-only, a
    footprint may be in Fortran order): each form would compile the function once more."""
    lo = np.ascontiguousarray(lo, np.int64).reshape(-1, 3)
    hi = np.ascontiguousarray(hi, np.int64).reshape(-1, 3)
    a = np.ascontiguousarray(np.broadcast_to(np.asarray(a, np.float64), (3,)))
    c = np.ascontiguousarray(np.broadcast_to(np.asarray(c, np.float64), (3,)))
    return (read_only(lo), read_only(hi), read_only(a), read_only(c),
            read_only(np.ascontiguousarray(coarse)))


def box_histograms(source: np.ndarray, coarse: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                   a: Any, c: Any, quantizer: Quantizer) -> BrickHistograms:
    """Histograms of bricks given by their source boxes, all approximated by one level.

    Parameters
    ----------
    source : numpy.ndarray
        The source (level 0), indexed by ``lo``/``hi``.
    coarse : numpy.ndarray
        The whole approximating level.
    lo, hi : numpy.ndarray
        (n, 3) source voxel ranges ``[lo, hi)`` of the bricks (any tiling: a pyramid store's
        bricks, which need not be :func:`~.cut.tree.regular_brick_tree`'s).
    a, c : 3 floats
        Source index to level index, ``u = a i + c`` (edge-clamped trilinear reconstruction).
    quantizer : Quantizer

    Returns
    -------
    BrickHistograms
        One entry range per brick, in the order of ``lo``.
    """
    lo, hi, a, c, coarse = _batch_arrays(lo, hi, a, c, coarse)
    bins = quantizer.bins
    sizes = np.minimum(np.prod(np.maximum(hi - lo, 0), axis=1), bins * bins)
    nthreads = numba.get_num_threads()

    def run(start, stop, out_at, keys, counts, nnz):
        _brick_batch(read_only(source), coarse, lo[start:stop], hi[start:stop], a, c,
                     _Quant(quantizer.lo, quantizer.scale, bins), out_at, _Out(keys, counts), nnz,
                     nthreads)

    parts = _run_batched(sizes, run) if len(lo) else []
    nnz, keys, counts = (_compact(parts, _key_dtype(bins), _count_dtype(source.size)) if parts
                         else (np.zeros(0, np.int64), np.zeros(0, _key_dtype(bins)),
                               np.zeros(0, _count_dtype(source.size))))
    offsets = np.concatenate([[0], np.cumsum(nnz)]).astype(np.int64)
    return BrickHistograms(offsets, keys, counts, quantizer)


def stack_histograms(parts: list[BrickHistograms]) -> BrickHistograms:
    """The nodes of several :class:`BrickHistograms` (same quantizer) one after the other."""
    if not parts:
        raise ParameterError("stack_histograms needs at least one part")
    q = parts[0].quantizer
    if any(p.quantizer != q for p in parts):
        raise ParameterError("stack_histograms needs one quantizer for all parts")
    keys = np.concatenate([p.keys for p in parts])
    counts = np.concatenate([p.counts for p in parts])
    rows = np.concatenate([np.diff(p.offsets) for p in parts])
    offsets = np.concatenate([[0], np.cumsum(rows)]).astype(np.int64)
    return BrickHistograms(offsets, keys, counts, q)


def _count_dtype(voxels: int) -> type:
    return np.uint32 if voxels < 2**32 else np.uint64


def _check_levels(levels: list[np.ndarray], grid: BrickGrid) -> None:
    if len(levels) < grid.levels:
        raise ParameterError(f"the pyramid needs {grid.levels} levels for bricks of "
                             f"{grid.brick}, got {len(levels)}")
    for lv in range(grid.levels):
        if tuple(levels[lv].shape) != grid.level_shapes[lv]:
            raise ParameterError(f"level {lv} has shape {levels[lv].shape}, expected "
                                 f"{grid.level_shapes[lv]}")


def coarsen_histograms(hist: BrickHistograms, fine: BrickGrid, coarse: BrickGrid
                       ) -> BrickHistograms:
    """Histograms for bricks of twice the edge, summed from those of ``fine`` bricks.

    A brick of edge ``2B`` on level ``l`` covers the source of the (up to) 2x2x2 bricks of edge
    ``B`` on the same level, and both approximate it by the same level, so its histogram is
    their sum: one pyramid pass serves 16^3 and 32^3 bricks.
    """
    if coarse.brick != 2 * fine.brick or coarse.shape != fine.shape:
        raise ParameterError("coarsen_histograms needs bricks of twice the edge on one grid")
    group_start = [0]
    members: list[np.ndarray] = []
    for lv in range(coarse.levels):
        idx = np.indices(coarse.level_bricks[lv]).reshape(3, -1).T
        for b in idx:
            if lv == 0:
                group_start.append(group_start[-1])  # leaves stay empty
                continue
            sub = (b * 2 + np.indices((2, 2, 2)).reshape(3, -1).T)
            sub = sub[np.all(sub < np.asarray(fine.level_bricks[lv]), axis=1)]
            ids = fine.node_id(lv, sub)
            members.append(ids)
            group_start.append(group_start[-1] + len(ids))
    members_arr = np.concatenate(members).astype(np.int64)
    starts = np.asarray(group_start, np.int64)
    nkeys = hist.quantizer.bins ** 2
    row = hist.offsets[1:] - hist.offsets[:-1]
    sizes = np.minimum(np.add.reduceat(np.append(row[members_arr], 0), starts[:-1])
                       * (starts[1:] > starts[:-1]), nkeys)
    nthreads = numba.get_num_threads()

    def run(start, stop, out_at, keys, counts, nnz):
        local = starts[start:stop + 1]
        _sum_rows(hist.offsets, hist.keys, hist.counts, local - local[0],
                  members_arr[local[0]:local[-1]], nkeys, out_at, keys, counts, nnz, nthreads)

    nnz, keys, counts = _compact(_run_batched(sizes, run), hist.keys.dtype.type,
                                 hist.counts.dtype.type)
    offsets = np.concatenate([[0], np.cumsum(nnz)]).astype(np.int64)
    return BrickHistograms(offsets, keys, counts, hist.quantizer)


def leaf_value_ranges(source: np.ndarray, brick: int,
                      ghost: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Value range of every finest brick, ``ghost`` voxels beyond its faces included.

    The trilinear reconstruction inside a brick reads the neighbouring voxel across each face,
    hence ``ghost = 1``. Returns float64 arrays shaped like the level-0 brick grid, ready for
    :func:`~.cut.tree.regular_brick_tree` (which makes them hierarchical).
    """
    nb = tuple(-(-n // brick) for n in source.shape)
    vmin = np.empty(int(np.prod(nb)), np.float64)
    vmax = np.empty(int(np.prod(nb)), np.float64)
    run_items(_leaf_range_items, vmin.shape[0], source, int(brick), int(ghost), nb[0], nb[1],
              nb[2], vmin, vmax)
    return vmin.reshape(nb), vmax.reshape(nb)
