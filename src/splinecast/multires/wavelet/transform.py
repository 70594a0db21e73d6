"""Non-standard separable 3D spline-wavelet transform (Steinberger 2010, §4.1; Stollnitz et al.
1996, §4.3).

One step filters the level-``j`` coefficients along x, y and z with the analysis low- and
high-pass of :mod:`.wavelet.filters` and keeps every other output: one scaling subband ``LLL``
(level ``j + 1``) and seven detail subbands (``LLH`` .. ``HHH``, letters per axis x, y, z). The
step is repeated on ``LLL`` only. Geometry, windows and boundary rules: :mod:`.wavelet.layout`.

Bounded memory
    :func:`decompose` works block by block: an output block of ``B^3`` level-``j + 1`` nodes
    needs a ``(2B + h)^3`` block of level ``j`` (``h`` = filter length), read from any array that
    supports numpy slicing (``numpy.memmap``, a Zarr array) with the boundary rule applied to
    out-of-window indices, and its subbands are written to a *sink* (:class:`MemorySink`,
    :class:`MemmapSink`, or the pyramid store's adapter). Peak memory is a few such blocks,
    independent of the volume. Each level is read back from the sink for the next step.

Output
    A :class:`WaveletPyramid`: every coarse level ``1..J`` (the pure B-spline approximations; the
    non-redundant set is level ``J`` plus all details, the same node count as the window), the
    detail subbands of every level, and the per-chunk hulls of :mod:`.wavelet.ranges`.
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from ...errors import ParameterError
from .filters import Filter, SplineWavelet, spline_wavelet
from .layout import BANDS, DETAIL_BANDS, WS, WaveletLayout, reflect_indices
from .ranges import block_hulls, selection_ranges

__all__ = [
    "Sink",
    "MemorySink",
    "MemmapSink",
    "WaveletPyramid",
    "decompose",
    "reconstruct",
    "level0_window",
    "analyze_axis",
    "synthesize_axis",
]


class Sink(Protocol):
    """Where a decomposition writes its arrays (a pyramid store's adapter implements this)."""

    def create(self, name: str, shape: tuple[int, ...], dtype: np.dtype) -> Any:
        """A writable array-like of ``shape`` (slice assignment and slice reads)."""


class MemorySink:
    """Keeps every array in memory (numpy)."""

    def create(self, name: str, shape: tuple[int, ...], dtype: np.dtype) -> np.ndarray:
        return np.zeros(shape, dtype=dtype)


class MemmapSink:
    """Writes every array to ``directory/<name>.npy`` as a memory map (bounded RAM)."""

    def __init__(self, directory: str | os.PathLike) -> None:
        self.directory = Path(directory)

    def create(self, name: str, shape: tuple[int, ...], dtype: np.dtype) -> np.memmap:
        path = self.directory / (name.replace("/", "_") + ".npy")
        path.parent.mkdir(parents=True, exist_ok=True)
        return np.lib.format.open_memmap(path, mode="w+", dtype=dtype, shape=shape)


@dataclass
class WaveletPyramid:
    """Result of :func:`decompose`.

    Attributes
    ----------
    layout : WaveletLayout
    coarse : dict
        ``coarse[j]``, j = 1..J: level-``j`` B-spline coefficients (window ``layout.length(j)``).
    details : dict
        ``details[j][band]``, j = 1..J: the seven detail subbands that, with ``coarse[j]``,
        reconstruct level ``j - 1`` (shapes ``layout.band_shape(j, band)``).
    hull_lo, hull_hi : list of arrays
        Per level 0..J, per chunk: convex-hull bound of the pure level's spline on the chunk's
        region (:mod:`.wavelet.ranges`).
    """

    layout: WaveletLayout
    coarse: dict[int, Any]
    details: dict[int, dict[str, Any]]
    hull_lo: list[np.ndarray]
    hull_hi: list[np.ndarray]
    dtype: np.dtype = field(default=np.dtype(np.float64))

    @property
    def wavelet(self) -> SplineWavelet:
        """The filters."""
        return spline_wavelet(self.layout.degree)

    @cached_property
    def ranges(self) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Selection ranges per chunk of levels 0..J-1 (:func:`.selection_ranges`)."""
        return selection_ranges(self.layout, self.hull_lo, self.hull_hi)


# ----------------------------------------------------------------------------------- reading
def _source_indices(layout: WaveletLayout, level: int, axis: int, idx: np.ndarray) -> np.ndarray:
    """Indices into the stored level array (level 0: into the voxels) for level indices ``idx``.

    Level indices outside the window follow the coarse boundary rule; level-0 window index ``i``
    is voxel ``o_0 + i``, and voxels outside the volume follow the model's mirror (WS).
    """
    inside, _ = reflect_indices(idx, layout.length(level)[axis], layout.coarse_rule)
    if level > 0:
        return inside
    voxel = inside + int(layout.node_origin(0))
    mirrored, _ = reflect_indices(voxel, layout.shape[axis], WS)
    return mirrored


def _read_box(array: Any, indices: Sequence[np.ndarray],
              signs: Sequence[np.ndarray] | None = None) -> np.ndarray:
    """``array[ix, iy, iz]`` (outer product of index lists) as float64, reading one bounding box."""
    lo = [int(ix.min()) for ix in indices]
    hi = [int(ix.max()) + 1 for ix in indices]
    box = np.asarray(array[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]], dtype=np.float64)
    out = box[np.ix_(*[ix - a for ix, a in zip(indices, lo, strict=True)])]
    if signs is not None:
        out = out * signs[0][:, None, None] * signs[1][None, :, None] * signs[2][None, None, :]
    return out


# ----------------------------------------------------------------------------------- 1D steps
def _along(axis: int, sl: slice) -> tuple[slice, ...]:
    out = [slice(None)] * 3
    out[axis] = sl
    return tuple(out)


def analyze_axis(x: np.ndarray, x_first: int, axis: int, filt: Filter, out_first: int,
                 count: int) -> np.ndarray:
    """``y[m] = Σ_k filt[k] x[2m + k]`` for ``m = out_first .. out_first + count - 1``.

    ``x[t]`` along ``axis`` holds sequence entry ``x_first + t`` and must cover every tap.
    """
    shape = list(x.shape)
    shape[axis] = max(count, 0)
    y = np.zeros(shape)
    if count <= 0:
        return y
    for t, w in enumerate(filt.taps):
        if w == 0.0:
            continue
        s = 2 * out_first + filt.start + t - x_first
        y += w * x[_along(axis, slice(s, s + 2 * (count - 1) + 1, 2))]
    return y


def synthesize_axis(low: np.ndarray, low_first: int, high: np.ndarray | None, high_first: int,
                    axis: int, p: Filter, g: Filter, out_first: int, count: int) -> np.ndarray:
    """``x[i] = Σ_m p[i - 2m] low[m] + Σ_m g[i - 2m] high[m]`` for ``i`` in the output range.

    ``low[t]`` holds coarse entry ``low_first + t`` (``high`` likewise, or None for zero details)
    and must cover every coarse node the output range needs.
    """
    shape = list(low.shape)
    shape[axis] = count
    x = np.zeros(shape)
    for seq, first, filt in ((low, low_first, p), (high, high_first, g)):
        if seq is None:
            continue
        for t, w in enumerate(filt.taps):
            if w == 0.0:
                continue
            k = filt.start + t
            i0 = out_first + ((out_first - k) % 2)  # first output with i - k even
            n = (out_first + count - i0 + 1) // 2
            if n <= 0:
                continue
            m0 = (i0 - k) // 2 - first
            x[_along(axis, slice(i0 - out_first, i0 - out_first + 2 * n - 1, 2))] += (
                w * seq[_along(axis, slice(m0, m0 + n))]
            )
    return x


def _coarse_span(filt: Filter, out_first: int, count: int) -> tuple[int, int]:
    """Coarse nodes ``[lo, hi]`` that synthesis filter ``filt`` needs for the output range."""
    return -(-(out_first - filt.stop) // 2), (out_first + count - 1 - filt.start) // 2


# ----------------------------------------------------------------------------------- decompose
def _block_starts(length: int, step: int) -> list[tuple[int, int]]:
    return [(s, min(s + step, length)) for s in range(0, length, step)]


def _analyze_block(x: np.ndarray, x_first: Sequence[int], wavelet: SplineWavelet,
                   out_lo: Sequence[int], coarse_count: Sequence[int],
                   detail_count: Sequence[int]) -> dict[str, np.ndarray]:
    """Filter an extended level block along x, y, z into the eight subbands."""
    bands = {"": x}
    for axis in range(3):
        nxt = {}
        for name, arr in bands.items():
            nxt[name + "L"] = analyze_axis(arr, x_first[axis], axis, wavelet.analysis_low,
                                           out_lo[axis], coarse_count[axis])
            nxt[name + "H"] = analyze_axis(arr, x_first[axis], axis, wavelet.analysis_high,
                                           out_lo[axis], detail_count[axis])
        bands = nxt
    return bands


def _hull_chunks(layout: WaveletLayout, level: int, lo: int, hi: int, axis: int) -> tuple[int, int]:
    k = layout.chunk
    count = layout.chunks(level)[axis]
    return min(lo // k, count), min(-(-hi // k), count)


def _hull_nodes(layout: WaveletLayout, c_lo: int, c_hi: int) -> tuple[int, int]:
    before, after = layout.cell_nodes()
    k = layout.chunk
    return k * c_lo - before, k * c_hi - 1 + after


def decompose(
    data: Any,
    degree: int,
    levels: int | None = None,
    chunk: int = 8,
    dtype: Any = np.float64,
    sink: Sink | None = None,
    block: int | None = None,
) -> WaveletPyramid:
    """Spline-wavelet decomposition of a 3D array (see the module docstring).

    Parameters
    ----------
    data : array_like, shape (nx, ny, nz)
        The voxels, used as B-spline coefficients (the ``bspline`` models' default). Anything that
        supports numpy slicing: ``numpy.ndarray``, ``numpy.memmap``, a Zarr array.
    degree : int
        B-spline degree 1, 2 or 3 (wavelets ψ2,2, ψ3,1, ψ4,2).
    levels : int, optional
        Decomposition steps J; default: the fewest whose coarsest chunk spans the volume.
    chunk : int
        Chunk edge k in nodes (even, at least 4).
    dtype : dtype
        Storage type of the coefficients (float64 or float32); arithmetic is float64.
    sink : Sink, optional
        Where the arrays go; default :class:`MemorySink`.
    block : int, optional
        Output block edge in coarse nodes (rounded up to a multiple of ``chunk / 2``); memory is
        about ``8 (2 block + 8)^3`` bytes per live block. Default: one block per level.

    Returns
    -------
    WaveletPyramid
    """
    shape = tuple(int(s) for s in np.shape(data))
    if len(shape) != 3:
        raise ParameterError(f"data must be 3D, got shape {shape}")
    layout = WaveletLayout.for_volume(shape, degree, levels, chunk)
    wavelet = spline_wavelet(layout.degree)
    sink = MemorySink() if sink is None else sink
    dtype = np.dtype(dtype)
    half = layout.chunk // 2
    if block is not None:
        block = max(half, -(-int(block) // half) * half)
    an_lo = min(wavelet.analysis_low.start, wavelet.analysis_high.start)
    an_hi = max(wavelet.analysis_low.stop, wavelet.analysis_high.stop)

    coarse: dict[int, Any] = {}
    details: dict[int, dict[str, Any]] = {}
    hull_lo = [np.full(layout.chunks(j), np.inf) for j in range(layout.levels + 1)]
    hull_hi = [np.full(layout.chunks(j), -np.inf) for j in range(layout.levels + 1)]
    source = data
    for j in range(layout.levels):
        n_out = layout.length(j + 1)
        n_det = layout.detail_length(j + 1)
        coarse[j + 1] = sink.create(f"coarse/{j + 1}", n_out, dtype)
        details[j + 1] = {
            b: sink.create(f"detail/{j + 1}/{b}", layout.band_shape(j + 1, b), dtype)
            for b in DETAIL_BANDS
        }
        ranges = [_block_starts(n, block or n) for n in n_out]
        for box in itertools.product(*ranges):
            m_lo = [b[0] for b in box]
            m_hi = [b[1] for b in box]
            chunks = [_hull_chunks(layout, j, 2 * m_lo[a], 2 * m_hi[a], a) for a in range(3)]
            first, last = [], []
            for a in range(3):
                c_lo, c_hi = chunks[a]
                if m_hi[a] == n_out[a]:
                    c_hi = layout.chunks(j)[a]
                    chunks[a] = (c_lo, c_hi)
                h_lo, h_hi = _hull_nodes(layout, c_lo, c_hi)
                first.append(min(2 * m_lo[a] + an_lo, h_lo))
                last.append(max(2 * (m_hi[a] - 1) + an_hi, h_hi))
            idx = [np.arange(first[a], last[a] + 1) for a in range(3)]
            x = _read_box(source, [_source_indices(layout, j, a, idx[a]) for a in range(3)])
            if all(c[0] < c[1] for c in chunks):
                block_hulls(layout, j, x, tuple(first), tuple(c[0] for c in chunks),
                            tuple(c[1] for c in chunks), hull_lo[j], hull_hi[j])
            counts_c = [m_hi[a] - m_lo[a] for a in range(3)]
            counts_d = [min(m_hi[a], n_det[a]) - m_lo[a] for a in range(3)]
            bands = _analyze_block(x, first, wavelet, m_lo, counts_c, counts_d)
            coarse[j + 1][m_lo[0]:m_hi[0], m_lo[1]:m_hi[1], m_lo[2]:m_hi[2]] = bands["LLL"]
            for b in DETAIL_BANDS:
                stop = [m_lo[a] + (counts_c if b[a] == "L" else counts_d)[a] for a in range(3)]
                if min(s - lo for s, lo in zip(stop, m_lo, strict=True)) > 0:
                    details[j + 1][b][m_lo[0]:stop[0], m_lo[1]:stop[1], m_lo[2]:stop[2]] = bands[b]
        source = coarse[j + 1]
    # Hulls of the coarsest level, from its (small) array.
    top = layout.levels
    c_hi = layout.chunks(top)
    first = [_hull_nodes(layout, 0, c_hi[a])[0] for a in range(3)]
    last = [_hull_nodes(layout, 0, c_hi[a])[1] for a in range(3)]
    idx = [np.arange(first[a], last[a] + 1) for a in range(3)]
    x = _read_box(source, [_source_indices(layout, top, a, idx[a]) for a in range(3)])
    block_hulls(layout, top, x, tuple(first), (0, 0, 0), c_hi, hull_lo[top], hull_hi[top])
    return WaveletPyramid(layout, coarse, details, hull_lo, hull_hi, dtype)


# ----------------------------------------------------------------------------------- reconstruct
def detail_mask(layout: WaveletLayout, level: int, band: str, active: np.ndarray) -> np.ndarray:
    """1.0 where a detail of subband ``band`` of ``level`` belongs to an active chunk, else 0.0.

    ``active`` is the bool table of chunks of ``level - 1`` whose details are included.
    """
    shape = layout.band_shape(level, band)
    owners = [layout.owner(level - 1, a, np.arange(shape[a])) for a in range(3)]
    return active[np.ix_(*owners)].astype(np.float64)


def synthesize_level(layout: WaveletLayout, level: int, coarse: Any,
                     details: dict[str, Any] | None,
                     active: np.ndarray | None = None) -> np.ndarray:
    """Level ``level - 1`` window from ``level``'s coarse coefficients and detail subbands.

    Filters along z, then y, then x (the thesis' order). ``details=None`` means all zero;
    ``active`` (bool per chunk of ``level - 1``) zeroes the details of inactive chunks.
    """
    wavelet = spline_wavelet(layout.degree)
    p, g = wavelet.synthesis_low, wavelet.synthesis_high
    n_out = layout.length(level - 1)
    spans = {"L": [_coarse_span(p, 0, n) for n in n_out],
             "H": [_coarse_span(g, 0, n) for n in n_out]}
    rules = {"L": layout.coarse_rule, "H": layout.detail_rule}
    lengths = {"L": layout.length(level), "H": layout.detail_length(level)}

    def read(band: str) -> np.ndarray | None:
        if band == "LLL":
            array = coarse
        elif details is None:
            return None
        else:
            array = details[band]
        idx, signs = [], []
        for a, letter in enumerate(band):
            lo, hi = spans[letter][a]
            ix, sg = reflect_indices(np.arange(lo, hi + 1), lengths[letter][a], rules[letter])
            idx.append(ix)
            signs.append(sg)
        values = _read_box(array, idx, signs)
        if active is not None and band != "LLL":
            values = values * detail_mask(layout, level, band, active)[np.ix_(*idx)]
        return values

    bands = {b: read(b) for b in BANDS}
    for axis in (2, 1, 0):  # merge each L/H pair along the axis into one sequence
        merged = {}
        for key, low in bands.items():
            if key[axis] != "L":
                continue
            high = bands[key[:axis] + "H" + key[axis + 1:]]
            if low is None:  # no details at all: every pair but the LLL one is zero
                merged[key] = None
                continue
            merged[key] = synthesize_axis(low, spans["L"][axis][0], high, spans["H"][axis][0],
                                          axis, p, g, 0, n_out[axis])
        bands = merged
    return bands["LLL"]


def reconstruct(pyramid: WaveletPyramid, level: int = 0,
                active: Sequence[np.ndarray] | None = None) -> np.ndarray:
    """Coefficients of ``level`` (its whole window, float64) from the coarsest level and details.

    Parameters
    ----------
    pyramid : WaveletPyramid
    level : int
        Target level (0 = finest).
    active : sequence of bool arrays, optional
        ``active[j]`` (shape ``layout.chunks(j)``) says which chunks of level ``j`` have their
        details included; default all. This is the global spline of a selection, computed
        without chunks (the reference the chunk reconstruction is tested against).
    """
    layout = pyramid.layout
    current: Any = pyramid.coarse[layout.levels]
    for j in range(layout.levels, level, -1):
        current = synthesize_level(layout, j, current, pyramid.details[j],
                                   None if active is None else active[j - 1])
    return np.asarray(current, dtype=np.float64)


def level0_window(data: Any, layout: WaveletLayout) -> np.ndarray:
    """The level-0 window (padded voxels, float64) that the decomposition transforms."""
    idx = [np.arange(n) for n in layout.window]
    return _read_box(data, [_source_indices(layout, 0, a, idx[a]) for a in range(3)])
