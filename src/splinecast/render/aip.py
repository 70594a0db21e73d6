"""Average intensity projection (AIP): the mean of the reconstruction along each ray, exactly.

A pixel shows the average value of the model along the part of its ray inside the volume (and
inside the clip planes): the integral of the reconstruction along that path divided by the
path's length. Along a ray piece the reconstruction is a polynomial of degree at most 9 in the
piece parameter ``s`` (trilinear: a cubic; B-spline degree d: 3d; the type-6 splines: 2 or 3),
so Gauss-Legendre quadrature with :data:`GAUSS_NODES` nodes, exact for every polynomial of
degree up to ``2 * GAUSS_NODES - 1``, gives each piece's integral without a step size; the
ray's integral is the sum over its pieces, and its length the sum of theirs. A ray that misses
the volume has no value (NaN), its depth is infinite.

Every piece counts, so no block is leapt over and no footprint narrows the rays (a block of
background still lengthens the path and lowers the mean). The per-ray state is the integral so
far, the length so far and the ray parameter where the ray entered the volume (the pixel's
depth and position: what is in front of the projection). Two partial states of one ray combine
by adding integrals and lengths and keeping the nearer entry, in any order, which is what a
pyramid's bricks and Dask's sort-last compositing do.

The window defaults to percentiles of the volume's axis-aligned mean projections
(:meth:`Aip.default_window`), as MIP's defaults to those of its maximum projections; pixels
whose rays meet only the background show the background colour, so the volume's box is not
drawn. This module is the whole mode: the kernels, the host object the scene kinds ask, and
the user's :class:`Aip`, added to the registry :data:`splinecast.render.modes.MODES`.
"""

from __future__ import annotations

import math
from collections import namedtuple
from collections.abc import Hashable
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numba import prange

from .._jit import jit
from ..roots.pieces import poly_value
from ..transfer import TransferFunction, colormap_table
from .defaults import (
    WINDOW_PERCENTILES,
    _cached,
    _sample,
    auto_colormap,
    background_value,
    is_signed,
)
from .frame import Frame
from .mip import check_window, projection_buffers, projection_frame
from .mode_api import (
    never,
    no_scratch,
    register,
    unchanged_begin,
    unchanged_end,
    unchanged_skip,
)
from .mode_host import ModeHost
from .modes import ModeContext, RenderMode, register_mode
from .outputs import ALL_OUTPUTS

__all__ = ["Aip", "AipHost", "AipMode", "combine_aip", "aip_window", "GAUSS_NODES"]

#: Gauss-Legendre nodes per piece: exact for polynomials of degree up to 9, the highest a
#: model yields (the cubic B-spline along a ray).
GAUSS_NODES = 5
_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(GAUSS_NODES)
#: The nodes and weights on ``[0, 1]`` (the weights sum to 1: the mean of a piece).
_S = 0.5 * (_NODES + 1.0)
_W = 0.5 * _WEIGHTS

#: Kernel parameters: the number of quadrature nodes (the one method, :data:`GAUSS_NODES`).
AipMode = namedtuple("AipMode", ["nodes"])


@jit()
def _state_new(mode):
    return 0.0, 0.0, math.inf  # integral, length, entry


@jit()
def _state_load(mode, state, row, col):
    integral, length, entry = state
    return integral[row, col], length[row, col], entry[row, col]


@jit()
def _state_store(mode, state, row, col, st):
    integral, length, entry = state
    integral[row, col] = st[0]
    length[row, col] = st[1]
    entry[row, col] = st[2]


@jit()
def _skip_size(mode, blocks, i, j, k, st):
    return 0  # every cell lengthens the path


@jit()
def _wants(mode, st, lo, hi):
    return True


@jit()
def _consume(mode, mscratch, grid, scratch, piece, ray, st):
    """Add the piece's exact integral ``(t1 - t0) * mean(poly on [0, 1])`` and its length."""
    mean = 0.0
    for n in range(_S.shape[0]):
        mean += _W[n] * poly_value(piece.poly, _S[n])
    length = piece.t1 - piece.t0
    return st[0] + mean * length, st[1] + length, min(st[2], piece.t0)


@jit()
def _done(mode, st):
    return False


@jit()
def _finish(mode, out, row, col, st, ray):
    value, depth, position = out
    t = st[2]
    missed = st[1] <= 0.0
    if value.shape[0] != 0:
        value[row, col] = math.nan if missed else st[0] / st[1]
    if depth.shape[0] != 0:
        depth[row, col] = math.inf if missed else t
    if position.shape[0] != 0:
        position[row, col, 0] = math.nan if missed else ray.world_x + t * ray.world_dx
        position[row, col, 1] = math.nan if missed else ray.world_y + t * ray.world_dy
        position[row, col, 2] = math.nan if missed else ray.world_z + t * ray.world_dz


register(AipMode, state_new=_state_new, state_load=_state_load, state_store=_state_store,
         mode_scratch=no_scratch, ray_begin=unchanged_begin, skip_size=_skip_size,
         wants=_wants, on_skip=unchanged_skip, consume=_consume, done=_done,
         ray_end=unchanged_end, finish=_finish, watches_skips=never)


@jit(parallel=True)
def combine_aip(front: tuple, back: tuple, out: tuple) -> None:
    """``out`` = two partial states of the same rays: integrals and lengths added, the nearer
    entry kept."""
    fi, fl, fe = front
    bi, bl, be = back
    oi, ol, oe = out
    height, width = fi.shape
    for row in prange(height):
        for col in range(width):
            oi[row, col] = fi[row, col] + bi[row, col]
            ol[row, col] = fl[row, col] + bl[row, col]
            oe[row, col] = min(fe[row, col], be[row, col])


def aip_window(volume: Any) -> tuple[float, float]:
    """The AIP window shown when none is given: ``(lo, hi)``, ``lo < hi``.

    ``volume.metadata["default_window_aip"]`` when present, else the
    :data:`~splinecast.render.defaults.WINDOW_PERCENTILES` of the volume's mean projections
    along its three axes, leaving out the pixels whose ray meets only background (symmetric
    about 0 for signed data); the data range when those coincide.
    """
    stored = volume.metadata.get("default_window_aip")
    if stored is not None:
        lo, hi = (float(v) for v in stored)
        return lo, hi

    def compute() -> tuple[float, float]:
        lo_data, hi_data = (float(v) for v in volume.value_range)
        data = _sample(volume)
        background = background_value(volume)
        empty = data == background
        pixels = np.concatenate([data.mean(axis=a)[~empty.all(axis=a)].ravel()
                                 for a in range(3)])
        pixels = pixels[np.isfinite(pixels)]
        if pixels.size and is_signed(volume):
            m = float(np.percentile(np.abs(pixels), WINDOW_PERCENTILES[1]))
            if m > 0:
                return -m, m
        elif pixels.size:
            lo, hi = (float(v) for v in np.percentile(pixels, WINDOW_PERCENTILES))
            if hi - lo > 1e-3 * (hi_data - lo_data):
                return lo, hi
        return (lo_data, hi_data if hi_data > lo_data else lo_data + 1.0)

    return _cached(volume, "window-aip", compute)


class AipHost(ModeHost):
    """Host side of the average intensity projection: parameters, buffers, the Frame.

    Parameters
    ----------
    window : (lo, hi)
        Values mapped to the ends of the colormap.
    colormap : str or control points
        Colormap of :mod:`splinecast.transfer`.
    background : 4 floats
        Colour of rays that miss the volume.
    value_range : (lo, hi)
        The data range (scales the test for background-only pixels).
    outputs : set of str, optional
        The Frame's buffers to fill (:mod:`.outputs`; default all).
    empty : float, optional
        The background value: pixels whose mean is this value (their ray meets only
        background) get ``background``, as rays that miss the volume do.
    """

    name = "aip"

    def __init__(self, window: tuple[float, float], colormap: Any,
                 background: Any = (0.0, 0.0, 0.0, 1.0),
                 value_range: tuple[float, float] = (0.0, 1.0),
                 outputs: frozenset[str] = ALL_OUTPUTS, empty: float | None = None) -> None:
        self.window = check_window(window, value_range)
        colormap_table(colormap, 2)  # validates the name before any work
        self.colormap = colormap
        self.background = background
        self.value_range = value_range
        self.outputs = outputs
        self.empty = empty
        self.params = AipMode(float(GAUSS_NODES))

    def blocks_key(self) -> Hashable:
        """The blocks are the grid's alone."""
        return ("aip",)

    def cut_transfer(self) -> TransferFunction:
        """The classification of the image: the window's colormap at full opacity."""
        lo, hi = (float(v) for v in self.window)
        return TransferFunction([(lo, 1.0), (hi, 1.0)], domain=(lo, hi), colormap=self.colormap)

    @staticmethod
    def blocks(hierarchy: Any, flags: tuple | None = None) -> tuple:
        """The finest block maxima (never read: no block is leapt over)."""
        return (hierarchy.highs[0],)

    @staticmethod
    def state(height: int, width: int) -> tuple:
        """Per-pixel state arrays: integral, length and entry of the path so far."""
        return np.empty((height, width)), np.empty((height, width)), np.empty((height, width))

    def output(self, height: int, width: int) -> tuple:
        """Output buffers: value, depth, position (zero rows: not requested)."""
        return projection_buffers(self.outputs, height, width)

    def frame(self, out: tuple, counters: tuple, stats: dict) -> Frame:
        """The Frame: colormapped means; ``Frame.value`` holds them."""
        return projection_frame(self, out, counters, stats)

    combine = staticmethod(combine_aip)


@register_mode
@dataclass(frozen=True)
class Aip(RenderMode):
    """The average intensity projection: the exact mean of the reconstruction along each ray
    inside the volume (``Frame.value``), colormapped through a window.

    Parameters
    ----------
    window : (lo, hi), optional
        The value window shown (default :meth:`default_window`).
    colormap : str, optional
        The colormap (default :func:`~splinecast.auto_colormap`).

    Examples
    --------
    >>> import splinecast as sc
    >>> vol = sc.demo("sphere", size=16)
    >>> frame = sc.Scene(vol).render(sc.Camera.orbit(vol, size=(32, 24)), sc.Aip())
    >>> frame.value.shape
    (24, 32)
    """

    name: ClassVar[str] = "aip"
    keywords: ClassVar[tuple[str, ...]] = ("window", "colormap")
    summary: ClassVar[str] = "average intensity projection"
    projection: ClassVar[str | None] = "mean"

    window: Any = None
    colormap: Any = None

    @classmethod
    def default_window(cls, volume: Any) -> tuple[float, float]:
        """:func:`aip_window`: percentiles of the volume's axis-aligned mean projections."""
        return aip_window(volume)

    def setup(self, context: ModeContext) -> tuple[Any, dict[str, Any], float | None]:
        """The :class:`AipHost` with the automatic window and colormap."""
        volume = context.volume
        window = self.default_window(volume) if self.window is None else self.window
        colormap = auto_colormap(volume) if self.colormap is None else self.colormap
        host = AipHost(window, colormap, context.shading.background, volume.value_range,
                       outputs=context.outputs, empty=background_value(volume))
        return host, {"method": "exact"}, None
