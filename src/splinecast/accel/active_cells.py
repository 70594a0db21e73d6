"""Isovalue change for the type-6 splines: classify and compact active cubes and tetrahedra.

References 003/004 (section 4.1) prepare every frame's work list once per isovalue: cubes whose
patches may contain the isovalue, then, inside them, the tetrahedra whose patch may. Here:

1. **Cube classification** (vectorised bounds, compiled scan): a cube is a candidate when the
   isovalue lies in its conservative value range (the model's ``cube_lo``/``cube_hi``: the range
   of the 27 data values, widened for schemes with negative weights). The candidates are compacted
   into a list of linear cube indices in the same pass.
2. **Tetrahedron classification** (compiled, parallel over candidates): the coefficients of the
   candidate cube are computed from its 27 values and each tetrahedron is active when the
   isovalue lies in the range of its own Bernstein–Bézier coefficients (convex hull property:
   the patch lies in that range, so this is conservative and much tighter than stage 1). A cube
   is active when one of its tetrahedra is; since neighbouring tetrahedra share coefficients,
   this is the same as the isovalue lying in the range of the cube's coefficients.
3. **Compaction**: active cubes (with a 24-bit tetrahedron mask each), the list of active
   tetrahedra (``slot * 24 + tet``), the cube -> slot lookup grid the kernels use and the block
   flags for empty-space leaps.
4. Optionally (``precompute=True``), the coefficients of every active cube are stored (the
   thesis' "high frame rate" variant) so the kernels read instead of recomputing them.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from numba import prange

from .._jit import jit
from ..models.type6 import gather27
from .minmax import BLOCK_SHIFTS

__all__ = ["ActiveCells", "candidate_cubes", "classify_tets", "tet_list"]

_CHUNK = 512  # candidates per work item: per-thread scratch buffers are reused within a chunk


@jit(parallel=True)
def candidate_cubes(lo: np.ndarray, hi: np.ndarray, iso: float) -> np.ndarray:
    """Linear indices (C order) of the cubes with ``lo <= iso <= hi``, compacted in two passes."""
    nx, ny, nz = lo.shape
    counts = np.zeros(nx, np.int64)
    for i in prange(nx):
        c = 0
        for j in range(ny):
            for k in range(nz):
                if lo[i, j, k] <= iso and hi[i, j, k] >= iso:
                    c += 1
        counts[i] = c
    starts = np.zeros(nx + 1, np.int64)
    for i in range(nx):
        starts[i + 1] = starts[i] + counts[i]
    out = np.empty(starts[nx], np.int64)
    for i in prange(nx):
        n = starts[i]
        for j in range(ny):
            for k in range(nz):
                if lo[i, j, k] <= iso and hi[i, j, k] >= iso:
                    out[n] = (i * ny + j) * nz + k
                    n += 1
    return out


@jit(inline="always")
def _cube_coefficients(v27, indptr, cols, vals, out):
    for p in range(indptr.shape[0] - 1):
        s = 0.0
        for q in range(indptr[p], indptr[p + 1]):
            s += vals[q] * v27[cols[q]]
        out[p] = s


@jit(parallel=True)
def classify_tets(
    pad: np.ndarray, cubes: np.ndarray, shape: np.ndarray, tet_points: np.ndarray,
    indptr: np.ndarray, cols: np.ndarray, vals: np.ndarray, iso: float,
) -> np.ndarray:
    """24-bit masks of the tetrahedra whose coefficient range contains ``iso``, per cube."""
    n = cubes.shape[0]
    masks = np.zeros(n, np.uint32)
    n_chunks = (n + _CHUNK - 1) // _CHUNK
    ny, nz = shape[1], shape[2]
    n_pts = indptr.shape[0] - 1
    for chunk in prange(n_chunks):
        v27 = np.empty(27)
        c = np.empty(n_pts)
        for m in range(chunk * _CHUNK, min(n, (chunk + 1) * _CHUNK)):
            lin = cubes[m]
            k = lin % nz
            j = (lin // nz) % ny
            i = lin // (ny * nz)
            gather27(pad, i, j, k, v27)
            _cube_coefficients(v27, indptr, cols, vals, c)
            mask = 0
            for t in range(24):
                cmin = np.inf
                cmax = -np.inf
                for q in range(tet_points.shape[1]):
                    v = c[tet_points[t, q]]
                    cmin = min(cmin, v)
                    cmax = max(cmax, v)
                if cmin <= iso <= cmax:
                    mask |= 1 << t
            masks[m] = mask
    return masks


@jit(parallel=True)
def store_coefficients(
    pad: np.ndarray, cubes: np.ndarray, shape: np.ndarray, indptr: np.ndarray,
    cols: np.ndarray, vals: np.ndarray,
) -> np.ndarray:
    """All coefficients of the given cubes, shape (n, n_points) float64."""
    n = cubes.shape[0]
    n_pts = indptr.shape[0] - 1
    out = np.empty((n, n_pts))
    n_chunks = (n + _CHUNK - 1) // _CHUNK
    ny, nz = shape[1], shape[2]
    for chunk in prange(n_chunks):
        v27 = np.empty(27)
        for m in range(chunk * _CHUNK, min(n, (chunk + 1) * _CHUNK)):
            lin = cubes[m]
            gather27(pad, lin // (ny * nz), (lin // nz) % ny, lin % nz, v27)
            _cube_coefficients(v27, indptr, cols, vals, out[m])
    return out


@jit()
def tet_list(masks: np.ndarray) -> np.ndarray:
    """Compact list ``slot * 24 + tet`` of the active tetrahedra of the active cubes."""
    total = 0
    for m in range(masks.shape[0]):
        x = masks[m]
        while x:
            x &= x - 1
            total += 1
    out = np.empty(total, np.int32)
    n = 0
    for m in range(masks.shape[0]):
        for t in range(24):
            if (masks[m] >> t) & 1:
                out[n] = m * 24 + t
                n += 1
    return out


@jit()
def _update_lookup(
    slot: np.ndarray, old: np.ndarray, new: np.ndarray, act0: np.ndarray, act1: np.ndarray,
    act2: np.ndarray,
) -> None:
    """Reset the old active cubes' slots to -1, then enter the new ones and their block flags."""
    ny, nz = slot.shape[1], slot.shape[2]
    flat = slot.reshape(-1)
    for m in range(old.shape[0]):
        flat[old[m]] = -1
    act0[:] = 0
    act1[:] = 0
    act2[:] = 0
    for m in range(new.shape[0]):
        lin = new[m]
        flat[lin] = m
        k = lin % nz
        j = (lin // nz) % ny
        i = lin // (ny * nz)
        act0[i >> 2, j >> 2, k >> 2] = 1
        act1[i >> 4, j >> 4, k >> 4] = 1
        act2[i >> 6, j >> 6, k >> 6] = 1


def _block_shape(shape: tuple[int, int, int], shift: int) -> tuple[int, int, int]:
    return tuple(-(-n // (1 << shift)) for n in shape)  # type: ignore[return-value]


class ActiveCells:
    """Per-isovalue work lists of a type-6 model (see the module docstring).

    Attributes
    ----------
    iso : float or None
        Isovalue of the current lists.
    cubes : ndarray of int64
        Linear (C-order) indices of the active cubes; a cube's position here is its *slot*.
    tet_mask : ndarray of uint32
        Per active cube, bit ``t`` set when tetrahedron ``t`` is active.
    tets : ndarray of int32
        Compact list of active tetrahedra, ``slot * 24 + tet``.
    slot : ndarray of int32, shape = volume shape
        Slot of each cube, -1 for inactive cubes (the kernels' lookup).
    coeffs : ndarray of float64, shape (n_active, n_points) or (0, n_points)
        Stored coefficients of the active cubes when the model precomputes them.
    act0, act1, act2 : ndarray of uint8
        Block flags (blocks of 4, 16, 64 cubes) for :func:`~.minmax.inactive_block_size`.
    """

    def __init__(self, model: Any) -> None:
        self.model = model
        self.iso: float | None = None
        shape = model.n_cells
        self.slot = np.full(shape, -1, dtype=np.int32)
        self.cubes = np.zeros(0, np.int64)
        self.tet_mask = np.zeros(0, np.uint32)
        self.tets = np.zeros(0, np.int32)
        self.coeffs = np.zeros((0, model.n_points))
        self.act0, self.act1, self.act2 = (
            np.zeros(_block_shape(shape, s), np.uint8) for s in BLOCK_SHIFTS
        )
        self.stats: dict[str, Any] = {}

    def update(self, iso: float) -> dict[str, Any]:
        """Classify and compact for ``iso``; returns counts, timings (ms) and memory (bytes)."""
        m = self.model
        tet_points, indptr, cols, vals = m.tables_arrays[:4]
        shape = np.asarray(m.n_cells, np.int64)
        t0 = time.perf_counter()
        candidates = candidate_cubes(m.cube_lo, m.cube_hi, iso)
        t1 = time.perf_counter()
        masks = classify_tets(m.pad, candidates, shape, tet_points, indptr, cols, vals, iso)
        t2 = time.perf_counter()
        keep = masks != 0
        new = candidates[keep]
        self.tet_mask = masks[keep]
        self.tets = tet_list(self.tet_mask)
        _update_lookup(self.slot, self.cubes, new, self.act0, self.act1, self.act2)
        self.cubes = new
        t3 = time.perf_counter()
        if m.precompute:
            self.coeffs = store_coefficients(m.pad, new, shape, indptr, cols, vals)
        else:
            self.coeffs = np.zeros((0, m.n_points))
        t4 = time.perf_counter()
        self.iso = iso
        n_cubes = int(new.shape[0])
        n_tets = int(self.tets.shape[0])
        lookup_bytes = int(self.slot.nbytes + self.act0.nbytes + self.act1.nbytes
                           + self.act2.nbytes)
        lists_bytes = int(self.cubes.nbytes + self.tet_mask.nbytes + self.tets.nbytes)
        coeff_bytes_precomputed = n_cubes * m.n_points * 8
        self.stats = {
            "cube_classify_ms": (t1 - t0) * 1e3,
            "tet_classify_ms": (t2 - t1) * 1e3,
            "compact_ms": (t3 - t2) * 1e3,
            "precompute_ms": (t4 - t3) * 1e3,
            "iso_change_ms": (t4 - t0) * 1e3,
            "cubes_candidate": int(candidates.shape[0]),
            "cubes_active": n_cubes,
            "tets_active": n_tets,
            "tets_per_active_cube": n_tets / n_cubes if n_cubes else 0.0,
            "precompute": bool(m.precompute),
            # Memory per variant: on the fly needs the padded data, the cube bounds, the lookup
            # and the lists; precomputed adds n_active x n_points float64 coefficients.
            "memory_on_the_fly_bytes": int(m._static_nbytes + lookup_bytes + lists_bytes),
            "memory_precomputed_bytes": int(m._static_nbytes + lookup_bytes + lists_bytes
                                            + coeff_bytes_precomputed),
        }
        return dict(self.stats)

    @property
    def nbytes(self) -> int:
        """Memory held by the per-isovalue arrays."""
        return int(sum(a.nbytes for a in (self.slot, self.cubes, self.tet_mask, self.tets,
                                           self.coeffs, self.act0, self.act1, self.act2)))
