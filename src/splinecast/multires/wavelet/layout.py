"""Geometry of a spline-wavelet pyramid: level windows, boundary rules, chunks and bricks.

Everything here is integer bookkeeping shared by the transform, the per-chunk ranges, the
view-dependent selection and the chunk reconstruction; see :mod:`.wavelet.filters` for the filters.

Levels and node positions
    Level 0 is the finest. Level ``j`` is a B-spline coefficient sequence per axis whose node ``m``
    sits at voxel position ``o_j + 2^j m``, so its spline is ``Σ_m c_j[m] B_d((x - o_j) / 2^j - m)``
    per axis (``x`` in voxel units, :mod:`splinecast.volume`). For odd degree ``o_j = 0``: coarse
    nodes are every other fine node. For even degree the knots lie between nodes and the coarse
    knots must be fine knots, which forces ``o_j = 2^(j-1) - 3/2`` (``o_0 = -1``, ``o_1 = -1/2``,
    ``o_2 = 1/2``, ...): the knot ``-3/2`` is common to every level.

Windows and boundary rule (why the volume is padded)
    The level-0 sequence is the model's own: ``BSplineModel`` mirrors the voxels about the first
    and last voxel (``a[-m] = a[m]``). A symmetric extension is kept at every level when the
    coarse sequence is again symmetric about the same points [Brislawn, "Classification of
    nonexpansive symmetric extension transforms", 1996]. With odd-length (odd-degree) filters that
    holds for whole-sample symmetry (WS) about nodes ``0`` and ``N_j - 1`` as long as ``N_j`` is
    odd; with even-length (even-degree) filters for half-sample symmetry (HS) about ``-1/2`` and
    ``N_j - 1/2`` as long as ``N_j`` is even. So the level-0 *window* is

    * odd degree: voxels ``0 .. N_0 - 1`` with ``N_0 = 2^J ceil((n - 1) / 2^J) + 1``, WS ends;
    * even degree: voxels ``-1 .. N_0 - 2`` with ``N_0 = 2^J ceil((n + 2) / 2^J)``, HS ends (the
      window starts at the model's first ghost ``a[-1] = a[1]``, the last coefficient that
      reaches the volume; HS about voxel ``-3/2`` does not alter it),

    filled from the voxels by the model's mirror. The spline over the voxel box ``[0, n - 1]`` is
    then exactly the ``bspline`` model's, every level ``j`` has ``N_j`` nodes
    (``(N_0 - 1) / 2^j + 1`` or ``N_0 / 2^j``), the transform is non-expansive on the window and
    perfectly reconstructing, and a coefficient outside a window is the mirror image of one
    inside (details: HS for odd degree; antisymmetric HS for even degree, whose wavelets are
    antisymmetric).
    The padding costs at most ``2^J - 1`` voxels per axis (none for ``n = 2^J q + 1``, one for
    ``n = 2^J q`` at odd degree); chunks that lie entirely in it are never selected.

Chunks (Steinberger 2010, §4.4)
    A chunk ``(j, idx)`` is ``k`` nodes per axis of level ``j``: nodes ``k idx .. k idx + k - 1``.
    Its *region* is the ``k`` cells those nodes own, voxels
    ``[b + 2^j k idx, b + 2^j k (idx + 1)]`` with ``b = 0`` (odd) or ``-3/2`` (even degree): chunk
    regions form an octree (parent ``idx // 2``). Only chunks whose region meets the voxel box
    exist. A chunk *owns* the level-``j + 1`` details whose nodes fall in it
    (``k/2 idx .. k/2 (idx + 1) - 1`` per axis; details beyond the last chunk belong to it);
    refining the chunk adds them.

Bricks (what the renderer draws)
    The reconstructed coefficients of chunk ``(j, idx)`` are an array ``A`` of ``(k + d)^3``
    nodes ``k idx - pad .. k idx - pad + k + d - 1`` per axis, ``pad = d // 2``: exactly a
    ``BSplineModel`` padded coefficient array (``cell c`` depends on ``A[c .. c + d]``) whose
    local voxel ``v`` is level-``j`` node ``k idx + v``, i.e. world voxel ``o_j + 2^j (k idx + v)``:
    index offset ``o_j + 2^j k idx`` and scale ``2^j`` voxels per node. The chunk's region is local
    cells ``0 .. k - 1``: local voxels ``[0, k]`` (odd degree) or ``[-1/2, k - 1/2]`` (even).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..._jit import jit
from ...errors import ParameterError

__all__ = [
    "WS",
    "HS",
    "HA",
    "WaveletLayout",
    "reflect_index",
    "reflect_indices",
    "BANDS",
    "DETAIL_BANDS",
]

#: Boundary rules of a sequence of length L: whole-sample symmetric about 0 and L - 1,
#: half-sample symmetric about -1/2 and L - 1/2, half-sample antisymmetric (HS with sign -1).
WS, HS, HA = 0, 1, 2

#: Subband names: one letter per axis (x, y, z), L = low-pass (scaling), H = high-pass (wavelet).
BANDS = tuple(a + b + c for a in "LH" for b in "LH" for c in "LH")
DETAIL_BANDS = BANDS[1:]


@jit(inline="always")
def reflect_index(i: int, length: int, rule: int) -> tuple[int, float]:
    """Index in ``[0, length)`` and sign of entry ``i`` of a sequence extended by ``rule``."""
    if length <= 0:
        return 0, 0.0
    if rule == WS:
        if length == 1:
            return 0, 1.0
        period = 2 * (length - 1)
        r = i % period
        if r >= length:
            r = period - r
        return r, 1.0
    period = 2 * length
    r = i % period
    if r >= length:
        return period - 1 - r, (-1.0 if rule == HA else 1.0)
    return r, 1.0


@jit()
def _reflect_many(idx: np.ndarray, length: int, rule: int, out: np.ndarray,
                  sign: np.ndarray) -> None:
    for t in range(idx.shape[0]):
        out[t], sign[t] = reflect_index(idx[t], length, rule)


def reflect_indices(idx: np.ndarray, length: int, rule: int) -> tuple[np.ndarray, np.ndarray]:
    """Vectorised :func:`reflect_index`: ``(indices, signs)`` for an integer array."""
    idx = np.ascontiguousarray(idx, dtype=np.int64)
    out = np.empty_like(idx)
    sign = np.empty(idx.shape, dtype=np.float64)
    _reflect_many(idx, int(length), int(rule), out, sign)
    return out, sign


def default_levels(shape: tuple[int, ...], chunk: int) -> int:
    """Fewest levels whose coarsest chunk spans the volume: ``2^J k >= n - 1`` on every axis.

    The same for every degree (5 levels of 8^3 chunks for 128^3, as in the thesis). For even
    degree, whose chunk regions start half a cell early, the coarsest level may then hold two
    root chunks per axis rather than one (a level more would pad the window by 2^J voxels).
    """
    levels = 1
    while any(chunk * 2**levels < n - 1 for n in shape):
        levels += 1
    return levels


def _region_start(degree: int) -> float:
    return 0.0 if degree % 2 else -1.5


def _chunk_count(n: int, degree: int, chunk: int, level: int) -> int:
    """Chunks of a level whose region meets the open voxel box (0, n - 1)."""
    width = chunk * 2**level
    return max(1, int(np.ceil((n - 1 - _region_start(degree)) / width)))


@dataclass(frozen=True)
class WaveletLayout:
    """Geometry of a spline-wavelet pyramid of a ``shape`` volume (see the module docstring).

    Parameters
    ----------
    shape : tuple of 3 ints
        Voxels per axis (at least 2).
    degree : int
        B-spline degree 1, 2 or 3.
    levels : int
        Decomposition steps J (level J is the coarsest).
    chunk : int
        Nodes per chunk edge k (even, at least 4; the thesis uses 8).
    """

    shape: tuple[int, int, int]
    degree: int
    levels: int
    chunk: int = 8

    def __post_init__(self) -> None:
        if self.degree not in (1, 2, 3):
            raise ParameterError(f"degree must be 1, 2 or 3, got {self.degree!r}")
        if len(self.shape) != 3 or min(self.shape) < 2:
            raise ParameterError(f"shape must be 3 sizes of at least 2, got {self.shape!r}")
        if self.levels < 1:
            raise ParameterError(f"levels must be at least 1, got {self.levels!r}")
        if self.chunk < 4 or self.chunk % 2:
            raise ParameterError(f"chunk must be even and at least 4, got {self.chunk!r}")

    @classmethod
    def for_volume(cls, shape: tuple[int, ...], degree: int, levels: int | None = None,
                   chunk: int = 8) -> WaveletLayout:
        """Layout with ``levels`` steps (default: :func:`default_levels`)."""
        shape3 = tuple(int(s) for s in shape)
        if levels is None:
            levels = default_levels(shape3, chunk)
        return cls(shape3, int(degree), int(levels), int(chunk))

    # ---------------------------------------------------------------- per-level sequences
    @property
    def odd(self) -> bool:
        """Odd degree: WS coarse sequences, nodes on every other fine node."""
        return self.degree % 2 == 1

    @property
    def pad(self) -> int:
        """Ghost nodes before a brick's first node (the model's ``pad_width``)."""
        return self.degree // 2

    @property
    def brick_size(self) -> int:
        """Nodes per brick edge, ``k + d``."""
        return self.chunk + self.degree

    @cached_property
    def window(self) -> tuple[int, int, int]:
        """``N_0``: level-0 nodes per axis (the padded window)."""
        step = 2**self.levels
        if self.odd:
            return tuple(step * -(-(n - 1) // step) + 1 for n in self.shape)
        return tuple(step * -(-(n + 2) // step) for n in self.shape)

    def length(self, level: int) -> tuple[int, int, int]:
        """Coarse nodes per axis on ``level``."""
        if self.odd:
            return tuple((n - 1) // 2**level + 1 for n in self.window)
        return tuple(n // 2**level for n in self.window)

    def detail_length(self, level: int) -> tuple[int, int, int]:
        """Detail nodes per axis of the step that makes ``level`` (1..J) from ``level - 1``."""
        if not 1 <= level <= self.levels:
            raise ParameterError(f"detail level must be in 1..{self.levels}, got {level}")
        coarse = self.length(level)
        return tuple(c - 1 for c in coarse) if self.odd else coarse

    def band_shape(self, level: int, band: str) -> tuple[int, int, int]:
        """Shape of subband ``band`` (e.g. ``"LHL"``) of ``level``."""
        coarse = self.length(level)
        detail = self.detail_length(level)
        return tuple(c if b == "L" else h for b, c, h in zip(band, coarse, detail, strict=True))

    @property
    def coarse_rule(self) -> int:
        """Boundary rule of every coarse sequence."""
        return WS if self.odd else HS

    @property
    def detail_rule(self) -> int:
        """Boundary rule of every detail sequence."""
        return HS if self.odd else HA

    def band_rules(self, band: str) -> tuple[int, int, int]:
        """Boundary rule per axis of a subband."""
        return tuple(self.coarse_rule if b == "L" else self.detail_rule for b in band)

    def node_origin(self, level: int) -> float:
        """``o_j``: voxel position of node 0 of ``level``."""
        if self.odd:
            return 0.0
        return 2.0 ** (level - 1) - 1.5

    @property
    def region_start(self) -> float:
        """``b``: voxel position where chunk 0's region starts on every level."""
        return _region_start(self.degree)

    # ---------------------------------------------------------------- chunks
    def chunks(self, level: int) -> tuple[int, int, int]:
        """Chunks per axis on ``level`` (those whose region meets the voxel box)."""
        return tuple(_chunk_count(n, self.degree, self.chunk, level) for n in self.shape)

    def chunk_total(self) -> int:
        """Chunks summed over all levels 0..J (the thesis' "4681 chunks" for 128^3)."""
        return int(sum(np.prod(self.chunks(j)) for j in range(self.levels + 1)))

    def region(self, level: int, axis: int, idx: np.ndarray | int) -> tuple[np.ndarray, np.ndarray]:
        """Voxel interval ``[lo, hi]`` of chunk regions along ``axis``, clipped to the box."""
        width = self.chunk * 2**level
        idx = np.asarray(idx)
        lo = self.region_start + width * idx
        hi = lo + width
        top = self.shape[axis] - 1
        return np.clip(lo, 0.0, top), np.clip(hi, 0.0, top)

    def owner(self, level: int, axis: int, node: np.ndarray | int) -> np.ndarray:
        """Chunk of ``level`` that owns detail node(s) ``node`` of ``level + 1`` along ``axis``.

        ``node`` must already be reflected into the detail window.
        """
        return np.minimum(np.asarray(node) // (self.chunk // 2), self.chunks(level)[axis] - 1)

    # ---------------------------------------------------------------- bricks
    def brick_first_node(self, idx: np.ndarray | int) -> np.ndarray:
        """First node (per axis) of the brick of chunk ``idx``: ``k idx - pad``."""
        return self.chunk * np.asarray(idx) - self.pad

    def brick_origin(self, level: int, idx: np.ndarray | int) -> np.ndarray:
        """World-voxel position of a brick's local voxel 0 (its array index ``pad``)."""
        return self.node_origin(level) + 2.0**level * self.chunk * np.asarray(idx, dtype=float)

    def cell_nodes(self) -> tuple[int, int]:
        """Nodes before / after cell ``g``'s own index that its spline piece depends on.

        Cell ``g`` of a level depends on nodes ``g - before .. g + after``.
        """
        d = self.degree
        return ((d - 1) // 2, (d + 1) // 2) if self.odd else (d // 2, d // 2)

    def domain_cells(self, level: int, axis: int) -> tuple[int, int]:
        """First and last cell of ``level`` along ``axis`` that meet the open voxel box."""
        width = 2**level
        top = self.shape[axis] - 1
        first = int(np.floor((0 - self.region_start) / width))
        if self.region_start + width * (first + 1) <= 0:
            first += 1
        last = int(np.ceil((top - self.region_start) / width)) - 1
        return first, last
