"""View-dependent selection of wavelet chunks (Steinberger 2010, §4.2 and §4.4, Algorithm 1).

Per chunk ``(j, idx)`` of ``k^3`` level-``j`` nodes (:mod:`.wavelet.layout`), three conditions
decide whether its details (the level-``j + 1`` details it owns) are added — the chunk is
*active* and level ``j`` is shown on its region:

* c0: the parent chunk ``(j + 1, idx // 2)`` is active (the roots, level J, always are);
* c1: ``s / c >= ε``: ``s`` is the world diameter of one level-``j + 1`` cell (the resolution
  the details would refine, ``2^(j+1) |spacing|``) and ``c`` the distance from the eye to the
  nearest point of the chunk's region (0 inside it). So ε is an angle in radians: cells that
  look smaller than ε are not refined. ε = 0 refines everywhere; a value near the angle of one
  pixel (``fov / image height``) keeps cells about a pixel wide;
* c2: the isovalue (any of several) lies in the chunk's selection range
  (:func:`.wavelet.ranges.selection_ranges`); skipped when no isovalue is given (DVR, MIP).

Neighbours (the thesis' Fig. 4.8, derived here)
    A chunk's wavelets reach beyond its region — measured in level-``j`` cells, at most
    ``-g_start + before`` cells to the left and ``g_stop + after - 1`` to the right (2/2, 2/2 and
    4/4 cells for degree 1, 2, 3), always less than one chunk since ``k >= 4``. Every neighbour
    of an active chunk (26-neighbourhood) is therefore *reconstructed* at level ``j`` as well,
    with its own details zero, so the spline it shows includes the active chunk's wavelets. A
    reconstructed chunk needs only its parent's brick (:mod:`.wavelet.reconstruct`), and that
    parent is active or a neighbour of an active chunk itself, so the set is closed upwards.

Rendering
    A reconstructed chunk of level ``j > 0`` draws those octants (its children's regions) whose
    child chunk is not reconstructed; a reconstructed level-0 chunk draws its whole region. The
    regions drawn tile the voxel box, and on each the brick's spline equals the selection's global
    spline (nothing finer acts there), so faces between levels are as continuous as the spline.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ...accel.minmax import neighbourhood
from ...errors import ParameterError
from .layout import WaveletLayout

__all__ = ["Selection", "select", "WHOLE_CHUNK"]

#: Octant mask meaning "the whole region" (level-0 chunks have no children).
WHOLE_CHUNK = 0xFF


@dataclass
class Selection:
    """Which chunks one frame uses.

    Attributes
    ----------
    layout : WaveletLayout
    active : list of bool arrays
        Levels 0..J-1: the chunk's details are included.
    reconstructed : list of bool arrays
        Levels 0..J: the chunk's brick is needed (level J: every root).
    octants : list of uint8 arrays
        Levels 0..J: bit ``4 ox + 2 oy + oz`` set where the brick draws that octant of its
        region (:data:`WHOLE_CHUNK` on level 0).
    """

    layout: WaveletLayout
    active: list[np.ndarray]
    reconstructed: list[np.ndarray]
    octants: list[np.ndarray]

    @classmethod
    def from_active(cls, layout: WaveletLayout, active: Sequence[np.ndarray]) -> Selection:
        """The selection with these active chunks (levels 0..J-1): neighbours, octants added.

        Any policy may choose ``active`` (view-dependent, budgeted, magnitude-based) as long as
        an active chunk's parent is active too.
        """
        top = layout.levels
        active = [np.asarray(a, dtype=bool) for a in active]
        if len(active) != top or any(a.shape != layout.chunks(j) for j, a in enumerate(active)):
            raise ParameterError("active must hold one table of layout.chunks(j) per level 0..J-1")
        for j in range(top - 1):
            if np.any(active[j] & ~_parents(active[j + 1], layout.chunks(j))):
                raise ParameterError(f"an active chunk of level {j} has an inactive parent")
        reconstructed = [active[j] | _dilate(active[j]) for j in range(top)]
        reconstructed.append(np.ones(layout.chunks(top), dtype=bool))
        octants = [np.where(reconstructed[0], WHOLE_CHUNK, 0).astype(np.uint8)]
        for j in range(1, top + 1):
            shape = layout.chunks(j)
            child = reconstructed[j - 1]
            mask = np.zeros(shape, dtype=np.uint8)
            for octant in range(8):
                offset = ((octant >> 2) & 1, (octant >> 1) & 1, octant & 1)
                kids = [2 * np.arange(n) + o for n, o in zip(shape, offset, strict=True)]
                exists = np.ones(shape, dtype=bool)
                for a in range(3):
                    exists &= (kids[a] < child.shape[a]).reshape([-1 if b == a else 1
                                                                 for b in range(3)])
                clipped = [np.minimum(c, m - 1) for c, m in zip(kids, child.shape, strict=True)]
                free = exists & ~child[np.ix_(*clipped)]
                mask |= np.where(free, np.uint8(1 << octant), np.uint8(0))
            octants.append(np.where(reconstructed[j], mask, 0).astype(np.uint8))
        return cls(layout, active, reconstructed, octants)

    @property
    def chunk_count(self) -> int:
        """Reconstructed chunks on all levels (roots included)."""
        return int(sum(r.sum() for r in self.reconstructed))

    @property
    def share(self) -> float:
        """Reconstructed chunks over all chunks of all levels (the thesis' "chunks %")."""
        return self.chunk_count / self.layout.chunk_total()

    def drawn(self) -> list[tuple[int, tuple[int, int, int], int]]:
        """``(level, chunk index, octant mask)`` of every brick that draws something."""
        out = []
        for j, table in enumerate(self.octants):
            for idx in zip(*np.nonzero(table), strict=True):
                out.append((j, tuple(int(i) for i in idx), int(table[idx])))
        return out


def _region_distance(layout: WaveletLayout, level: int, eye_voxel: np.ndarray,
                     spacing: np.ndarray) -> np.ndarray:
    """World distance from the eye to each chunk region of ``level`` (0 inside)."""
    parts = []
    for a in range(3):
        lo, hi = layout.region(level, a, np.arange(layout.chunks(level)[a]))
        gap = np.maximum(np.maximum(lo - eye_voxel[a], eye_voxel[a] - hi), 0.0)
        parts.append(gap * abs(spacing[a]))
    return np.sqrt(parts[0][:, None, None] ** 2 + parts[1][None, :, None] ** 2
                   + parts[2][None, None, :] ** 2)


def _parents(table: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    return table[np.ix_(*[np.arange(n) // 2 for n in shape])]


def _dilate(table: np.ndarray) -> np.ndarray:
    """True where the entry or one of its 26 neighbours is True."""
    return neighbourhood(table, np.logical_or)


def select(
    layout: WaveletLayout,
    ranges: tuple[Sequence[np.ndarray], Sequence[np.ndarray]],
    eye: Sequence[float],
    epsilon: float,
    iso: float | Sequence[float] | None = None,
    spacing: Sequence[float] = (1.0, 1.0, 1.0),
    origin: Sequence[float] = (0.0, 0.0, 0.0),
) -> Selection:
    """Choose the chunks for one frame (see the module docstring).

    Parameters
    ----------
    layout : WaveletLayout
    ranges : (lo, hi)
        Selection ranges per level 0..J-1 (:attr:`.WaveletPyramid.ranges`).
    eye : 3 floats
        Eye position in world coordinates (``splinecast.Camera.position``).
    epsilon : float
        Refinement threshold ε >= 0 (radians; see c1).
    iso : float or sequence of floats, optional
        Isovalue(s); None selects regardless of values.
    spacing, origin : 3 floats
        The volume's voxel spacing and origin (world position of voxel 0).

    Returns
    -------
    Selection
    """
    if not (np.isfinite(epsilon) and epsilon >= 0):
        raise ParameterError(f"epsilon must be a finite number >= 0, got {epsilon!r}")
    spacing = np.asarray(spacing, dtype=np.float64)
    eye_voxel = (np.asarray(eye, dtype=np.float64) - np.asarray(origin, dtype=np.float64)) / spacing
    isos = None if iso is None else np.atleast_1d(np.asarray(iso, dtype=np.float64))
    top = layout.levels
    active: list[np.ndarray] = [np.zeros(0, bool)] * top
    parent = np.ones(layout.chunks(top), dtype=bool)
    for j in range(top - 1, -1, -1):
        shape = layout.chunks(j)
        cell = 2.0 ** (j + 1) * float(np.linalg.norm(spacing))
        c1 = cell >= epsilon * _region_distance(layout, j, eye_voxel, spacing)
        on = _parents(parent, shape) & c1
        if isos is not None:
            lo, hi = ranges[0][j], ranges[1][j]
            on &= np.any((lo[..., None] <= isos) & (isos <= hi[..., None]), axis=-1)
        active[j] = on
        parent = on
    return Selection.from_active(layout, active)
