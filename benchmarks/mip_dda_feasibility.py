"""Feasibility test: is the renderer's generic cell walk what makes exact MIP slow?

A stand-alone exact trilinear MIP, written as lean as I could: an incremental DDA cell walk
(``tMax += tDelta``, no division per step), the same block leaps over the min/max hierarchy
(64-, 16- and 4-cell maxima against the running maximum and the lower bound), the same
coherent lower bound (the value where the row's previous ray found its maximum), and each
tested cell's cubic maximised in closed form. It leaves out what the renderer adds: the mode
hooks, clipping, the footprint, the first ray's seed, the hull prune, per-ray statistics and
outputs. Rays come precomputed in index space.

Both run the same camera on two threads, and their values are compared. The DDA's values differ
from the renderer's exact ones by up to about 1e-7 of the data range on the smooth volumes, both
ways (its derivative roots come from the plain quadratic formula, which loses digits when the
cubic term is nearly zero, and its plane crossings are accumulated; not investigated further,
the timing is what it is for).

Session 49: the lean walk was no faster (``results/mip_dda_feasibility.md``: 0.97-1.22x the
renderer's time; 0.94-1.20x in an earlier run), so the generic driver is not what separates
exact MIP from VTK's casters.

    python benchmarks/mip_dda_feasibility.py
"""

from __future__ import annotations

import math
import sys
from functools import partial
from pathlib import Path

import numpy as np
from numba import njit, prange

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))
from _machine import median_ms, write_results  # noqa: E402

import splinecast as sc  # noqa: E402
from benchmarks.compare.scenes import ml, mri, noise  # noqa: E402


@njit(inline="always")
def corner(v, i, j, k):
    return float(v[i, j, k])


@njit(inline="always")
def corners(v, i, j, k):
    """The eight values of cell (i, j, k), as c000, c001, c010, c011, c100, ..., c111."""
    return (corner(v, i, j, k), corner(v, i, j, k + 1), corner(v, i, j + 1, k),
            corner(v, i, j + 1, k + 1), corner(v, i + 1, j, k), corner(v, i + 1, j, k + 1),
            corner(v, i + 1, j + 1, k), corner(v, i + 1, j + 1, k + 1))


@njit(inline="always")
def cell_top(v, i, j, k):
    """The largest of the eight values of cell (i, j, k)."""
    return max(max(max(corner(v, i, j, k), corner(v, i, j, k + 1)),
                   max(corner(v, i, j + 1, k), corner(v, i, j + 1, k + 1))),
               max(max(corner(v, i + 1, j, k), corner(v, i + 1, j, k + 1)),
                   max(corner(v, i + 1, j + 1, k), corner(v, i + 1, j + 1, k + 1))))


@njit(inline="always")
def tri(v, x, y, z, nx, ny, nz):
    i = min(max(int(math.floor(x)), 0), nx - 1)
    j = min(max(int(math.floor(y)), 0), ny - 1)
    k = min(max(int(math.floor(z)), 0), nz - 1)
    fx, fy, fz = x - i, y - j, z - k
    c000, c001, c010, c011, c100, c101, c110, c111 = corners(v, i, j, k)
    c00 = c000 + fz * (c001 - c000)
    c01 = c010 + fz * (c011 - c010)
    c10 = c100 + fz * (c101 - c100)
    c11 = c110 + fz * (c111 - c110)
    c0 = c00 + fy * (c01 - c00)
    c1 = c10 + fy * (c11 - c10)
    return c0 + fx * (c1 - c0)


@njit(inline="always")
def cubic_max(v, i, j, k, ax, ay, az, ex, ey, ez):
    """Largest value of the cell's trilinear on p(s) = a + s e, s in [0, 1]; and its s."""
    c000, c001, c010, c011, c100, c101, c110, c111 = corners(v, i, j, k)
    # f = b0 + bx x + by y + bz z + bxy xy + bxz xz + byz yz + bxyz xyz
    b0 = c000
    bx = c100 - c000
    by = c010 - c000
    bz = c001 - c000
    bxy = c110 - c100 - c010 + c000
    bxz = c101 - c100 - c001 + c000
    byz = c011 - c010 - c001 + c000
    bxyz = c111 - c110 - c101 - c011 + c100 + c010 + c001 - c000
    # x = ax + s ex etc.: f(s) = q0 + q1 s + q2 s^2 + q3 s^3
    q0 = (b0 + bx * ax + by * ay + bz * az + bxy * ax * ay + bxz * ax * az + byz * ay * az
          + bxyz * ax * ay * az)
    q1 = (bx * ex + by * ey + bz * ez + bxy * (ax * ey + ex * ay) + bxz * (ax * ez + ex * az)
          + byz * (ay * ez + ey * az)
          + bxyz * (ex * ay * az + ax * ey * az + ax * ay * ez))
    q2 = (bxy * ex * ey + bxz * ex * ez + byz * ey * ez
          + bxyz * (ex * ey * az + ex * ay * ez + ax * ey * ez))
    q3 = bxyz * ex * ey * ez
    best = q0
    bs = 0.0
    f1 = q0 + q1 + q2 + q3
    if f1 > best:
        best, bs = f1, 1.0
    # f'(s) = q1 + 2 q2 s + 3 q3 s^2
    A, B, C = 3.0 * q3, 2.0 * q2, q1
    if A != 0.0:
        disc = B * B - 4.0 * A * C
        if disc >= 0.0:
            r = math.sqrt(disc)
            for s in ((-B - r) / (2.0 * A), (-B + r) / (2.0 * A)):
                if 0.0 < s < 1.0:
                    f = q0 + s * (q1 + s * (q2 + s * q3))
                    if f > best:
                        best, bs = f, s
    elif B != 0.0:
        s = -C / B
        if 0.0 < s < 1.0:
            f = q0 + s * (q1 + s * q2)
            if f > best:
                best, bs = f, s
    return best, bs


@njit(inline="always")
def clip(ox, oy, oz, dx, dy, dz, nx, ny, nz):
    t0 = 0.0
    t1 = 1e300
    for o, d, n in ((ox, dx, nx), (oy, dy, ny), (oz, dz, nz)):
        if d != 0.0:
            a = (0.0 - o) / d
            b = (n - o) / d
            if a > b:
                a, b = b, a
            t0 = max(t0, a)
            t1 = min(t1, b)
        elif o < 0.0 or o > n:
            return 1.0, 0.0
    return t0, t1


@njit(inline="always")
def cell_at(p, d, n):
    c = int(math.floor(p))
    if d < 0.0 and c == p:  # on a plane moving down: the cell below
        c -= 1
    return min(max(c, 0), n - 1)


@njit(parallel=True, fastmath=False)
def dda_mip(v, h0, h1, h2, O, D, out, visits, cellmax, loads, sink):
    """Exact trilinear MIP of rays ``O + t D`` (index space) into ``out``; cells visited per
    ray into ``visits``.

    ``loads`` = -1 is the plain walk (``cellmax`` and ``sink`` are not read). ``loads`` >= 0 is
    the memory experiment of ``mip_memory_limits.py``: each visited cell's range test reads
    ``cellmax`` (the cell's largest corner) instead of the eight corners, so the walk is the
    same whatever the corners cost, and the eight corners are read anyway into ``sink`` (0: not
    at all; 1: the cell's own, from ``v``; 2: the same instructions at indices masked to the
    grid's first 16^3 cells, which stay in the L1 cache)."""
    h, w = out.shape
    nx, ny, nz = v.shape[0] - 1, v.shape[1] - 1, v.shape[2] - 1  # cells
    for r in prange(h):
        t_prev = math.nan
        for c in range(w):
            ox, oy, oz = O[r, c, 0], O[r, c, 1], O[r, c, 2]
            dx, dy, dz = D[r, c, 0], D[r, c, 1], D[r, c, 2]
            t0, t1 = clip(ox, oy, oz, dx, dy, dz, nx, ny, nz)
            if not t0 <= t1:
                out[r, c] = math.nan
                continue
            best = -math.inf
            lower = -math.inf
            if t_prev == t_prev:
                ts = min(max(t_prev, t0), t1)
                val = tri(v, ox + ts * dx, oy + ts * dy, oz + ts * dz, nx, ny, nz)
                lower = val - 1e-9 * (abs(val) + 1.0)
            # DDA set-up
            sx = 1 if dx > 0.0 else -1
            sy = 1 if dy > 0.0 else -1
            sz = 1 if dz > 0.0 else -1
            idx = 1.0 / dx if dx != 0.0 else math.inf
            idy = 1.0 / dy if dy != 0.0 else math.inf
            idz = 1.0 / dz if dz != 0.0 else math.inf
            tdx, tdy, tdz = abs(idx), abs(idy), abs(idz)
            t = t0
            i = cell_at(ox + t * dx, dx, nx)
            j = cell_at(oy + t * dy, dy, ny)
            k = cell_at(oz + t * dz, dz, nz)
            tmx = ((i + (sx > 0)) - ox) * idx if dx != 0.0 else math.inf
            tmy = ((j + (sy > 0)) - oy) * idy if dy != 0.0 else math.inf
            tmz = ((k + (sz > 0)) - oz) * idz if dz != 0.0 else math.inf
            ob = -1  # open 4-block key
            where = math.inf
            nv = 0
            spent = 0.0
            while True:
                key = ((i >> 2) * 4096 + (j >> 2)) * 4096 + (k >> 2)
                if key != ob:
                    # largest skippable block
                    size = 0
                    if h2[i >> 6, j >> 6, k >> 6] <= best or h2[i >> 6, j >> 6, k >> 6] < lower:
                        size = 64
                    elif h1[i >> 4, j >> 4, k >> 4] <= best or h1[i >> 4, j >> 4, k >> 4] < lower:
                        size = 16
                    elif h0[i >> 2, j >> 2, k >> 2] <= best or h0[i >> 2, j >> 2, k >> 2] < lower:
                        size = 4
                    if size > 0:
                        # leave the block: exit planes
                        bx0 = i & -size
                        by0 = j & -size
                        bz0 = k & -size
                        px = bx0 + size if sx > 0 else bx0
                        py = by0 + size if sy > 0 else by0
                        pz = bz0 + size if sz > 0 else bz0
                        ex = (px - ox) * idx if dx != 0.0 else math.inf
                        ey = (py - oy) * idy if dy != 0.0 else math.inf
                        ez = (pz - oz) * idz if dz != 0.0 else math.inf
                        te = min(ex, ey, ez)
                        if te >= t1:
                            break
                        t = te
                        # new cell: step across the exit plane, floor on the others
                        if te == ex:
                            i = px if sx > 0 else px - 1
                        else:
                            i = min(max(int(math.floor(ox + te * dx)), bx0), bx0 + size - 1)
                        if te == ey:
                            j = py if sy > 0 else py - 1
                        else:
                            j = min(max(int(math.floor(oy + te * dy)), by0), by0 + size - 1)
                        if te == ez:
                            k = pz if sz > 0 else pz - 1
                        else:
                            k = min(max(int(math.floor(oz + te * dz)), bz0), bz0 + size - 1)
                        if i < 0 or i >= nx or j < 0 or j >= ny or k < 0 or k >= nz:
                            break
                        tmx = ((i + (sx > 0)) - ox) * idx if dx != 0.0 else math.inf
                        tmy = ((j + (sy > 0)) - oy) * idy if dy != 0.0 else math.inf
                        tmz = ((k + (sz > 0)) - oz) * idz if dz != 0.0 else math.inf
                        continue
                    ob = key
                # the cell [t, t_out]
                t_out = min(tmx, tmy, tmz, t1)
                nv += 1
                if loads < 0:
                    cmax = cell_top(v, i, j, k)
                else:
                    cmax = float(cellmax[i, j, k])
                    if loads == 1:
                        spent += cell_top(v, i, j, k)
                    elif loads == 2:
                        spent += cell_top(v, i & 15, j & 15, k & 15)
                if cmax > best and cmax >= lower and t_out > t:
                    ax = ox + t * dx - i
                    ay = oy + t * dy - j
                    az = oz + t * dz - k
                    ex = ox + t_out * dx - i - ax
                    ey = oy + t_out * dy - j - ay
                    ez = oz + t_out * dz - k - az
                    val, s = cubic_max(v, i, j, k, ax, ay, az, ex, ey, ez)
                    if val > best:
                        best = val
                        where = t + s * (t_out - t)
                if t_out >= t1:
                    break
                t = t_out
                if tmx <= tmy and tmx <= tmz:
                    i += sx
                    tmx += tdx
                    if i < 0 or i >= nx:
                        break
                elif tmy <= tmz:
                    j += sy
                    tmy += tdy
                    if j < 0 or j >= ny:
                        break
                else:
                    k += sz
                    tmz += tdz
                    if k < 0 or k >= nz:
                        break
            out[r, c] = best
            visits[r, c] = nv
            if loads > 0:
                sink[r, c] = spent
            if where < math.inf:
                t_prev = where



def walk_inputs(spec, size: tuple[int, int]) -> tuple:
    """What the stand-alone walks take for one comparison scene: ``(volume, scene, camera,
    data, (h0, h1, h2), origins, directions)``. The camera is the orbit view at azimuth 40,
    elevation 20; origins and directions are its rays in index space; ``h0..h2`` are the 4-,
    16- and 64-cell block maxima."""
    vol = spec.make()
    scene = sc.Scene(vol)
    h = scene.grid.hierarchy
    data = np.asarray(scene.grid.kernel.data)
    cam = sc.Camera.orbit(vol, azimuth=40.0, elevation=20.0, size=size)
    origins, dirs = cam.rays()
    origin, spacing = np.asarray(vol.origin), np.asarray(vol.spacing)
    o_index = np.ascontiguousarray((origins - origin) / spacing)
    d_index = np.ascontiguousarray(dirs / spacing)
    return vol, scene, cam, data, (h.highs[0], h.highs[1], h.highs[2]), o_index, d_index


def _median_ms(fn, repeats: int = 9) -> float:
    fn()  # compilation and warm-up
    return median_ms(fn, repeats)


def main() -> None:
    size = (1024, 768)
    rows = []
    for spec in (mri(), ml(128), noise(256)):
        if spec is None:
            continue
        vol, scene, cam, data, (h0, h1, h2), o_index, d_index = walk_inputs(spec, size)
        out = np.empty(size[::-1])
        visits = np.zeros(size[::-1], np.int64)
        unused = np.zeros((1, 1, 1), data.dtype)
        dda_ms = _median_ms(partial(dda_mip, data, h0, h1, h2, o_index,
                                    d_index, out, visits, unused, -1, out))
        render_ms = _median_ms(partial(scene.render, cam, mode="mip", outputs=("value",)))
        ref = scene.render(cam, mode="mip", outputs=("value",)).value
        both = np.isfinite(ref) & np.isfinite(out)
        lo, hi = vol.value_range
        diff = (out[both] - ref[both]) / (hi - lo)
        row = {"scene": spec.label, "dda_ms": dda_ms, "renderer_ms": render_ms,
               "largest_shortfall": float(max(-diff.min(), 0.0)),
               "largest_excess": float(max(diff.max(), 0.0)),
               "cells_per_traced_ray": float(visits[both].mean())}
        rows.append(row)
        print(row, flush=True)
    write_results(
        HERE / "results" / "mip_dda_feasibility",
        "Exact MIP: a lean stand-alone DDA walk against the renderer",
        "Command: `python benchmarks/mip_dda_feasibility.py`. 1024x768, the comparison's orbit "
        "camera at azimuth 40, numba's default threads, median of 9 frames after a warm-up; the "
        "renderer fills `value` only.",
        ["scene", "lean DDA ms", "renderer ms", "DDA / renderer",
         "DDA's largest shortfall / excess (of the data range)",
         "cells visited per traced ray (DDA)"],
        rows, lambda r: [r["scene"], f"{r['dda_ms']:.1f}", f"{r['renderer_ms']:.1f}",
                         f"{r['dda_ms'] / r['renderer_ms']:.2f}",
                         f"{r['largest_shortfall']:.1e} / {r['largest_excess']:.1e}",
                         f"{r['cells_per_traced_ray']:.2f}"])

if __name__ == "__main__":
    main()
