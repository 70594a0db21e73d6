"""Which bricks can show anything: a brick's value range against the isovalues or the transfer
function. Bricks that cannot contribute are left out of the cut and never read."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np

from ...transfer import TransferFunction

__all__ = ["ValueFilter"]


class ValueFilter:
    """The value intervals that are visible; a brick contributes if its range meets one.

    Parameters
    ----------
    intervals : iterable of (lo, hi), optional
        Closed visible intervals in data units (infinite ends allowed); ``None`` means every
        brick contributes (MIP, minIP).
    widen : float
        Widen each brick's range by this fraction of its width before testing, for models whose
        reconstruction can leave the range of its voxels (the type-6 splines' coefficients are
        affine combinations with weights up to 9/8 in absolute sum: pass ``1/16``).

    Bricks whose range is unknown (NaN: not read yet, in stores without tables) contribute;
    bricks without a finite voxel (``lo > hi``) do not.
    """

    def __init__(self, intervals: Iterable[tuple[float, float]] | None = None,
                 widen: float = 0.0) -> None:
        self.intervals = None if intervals is None else [(float(a), float(b))
                                                         for a, b in intervals]
        self.widen = float(widen)

    def key(self) -> tuple:
        """What decides the filter's answers (equal keys, equal filters)."""
        return (None if self.intervals is None else tuple(self.intervals), self.widen)

    @classmethod
    def iso(cls, values: Any, widen: float = 0.0) -> ValueFilter:
        """Bricks that an isosurface (or several) crosses."""
        return cls([(v, v) for v in np.atleast_1d(np.asarray(values, dtype=np.float64))], widen)

    @classmethod
    def transfer(cls, tf: TransferFunction, widen: float = 0.0) -> ValueFilter:
        """Bricks that are not transparent under ``tf`` (its :meth:`visible_ranges`)."""
        return cls(tf.visible_ranges(), widen)

    def contributes(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """Boolean mask: which ranges ``[lo, hi]`` (arrays of equal shape) can show something."""
        lo = np.asarray(lo, dtype=np.float64)
        hi = np.asarray(hi, dtype=np.float64)
        unknown = np.isnan(lo) | np.isnan(hi)
        empty = ~unknown & (lo > hi)
        if self.intervals is None:
            return ~empty
        pad = self.widen * np.where(empty | unknown, 0.0, hi - lo)
        a, b = lo - pad, hi + pad
        hit = np.zeros(lo.shape, dtype=bool)
        for v0, v1 in self.intervals:
            hit |= (a <= v1) & (b >= v0)
        return unknown | (hit & ~empty)

    def __repr__(self) -> str:
        return f"ValueFilter({self.intervals}, widen={self.widen})"
