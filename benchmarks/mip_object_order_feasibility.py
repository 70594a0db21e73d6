"""Feasibility test: would an object-order exact MIP beat the renderer's ray walk?

The exact MIP walks each ray cell by cell and pays about 70-80 cycles per cell visited or
block leapt (``results/cycles_mip_*.md``), while only a third of the cells it visits can hold
its answer (``results/mip_exact_limits.md``). An object-order projection visits no cell in
vain along a ray: it takes the 4-cell blocks in decreasing order of their maxima, projects each
block and then each of its cells to the screen, and tests a pixel's ray against a cell only
when the cell's maximum beats the pixel's running maximum; a cell's cubic along the ray is then
maximised as the renderer does. Each pixel starts from the value at its ray's entry (a value
the ray meets), so pixels become finished early, and a thread stops when the next block's
maximum does not beat the smallest running maximum of its rows. This is a stand-alone trilinear
kernel for perspective cameras (threads own horizontal strips with as many covered pixels), not
part of the renderer; its values are checked against the renderer's exact ones.

Session 53: 1.66x the walk's speed on Marschner-Lobb 128^3, 1.17x on the MRI, 1.07x on
Marschner-Lobb 256^3 and 0.89x on noise 256^3 (``results/mip_object_order_feasibility.md``).
It forms about as many cubics per ray (3.4-11.4) as the walk tests cells (3.6-10.9), and the
projection of the blocks and cells it enters costs about what the walk's steps cost. That is
short of the 1.6-2.6x over the walk the MIP targets need on every scene, and an image-order
kernel serves bricks, clipping, every model and every camera, so the renderer keeps its walk.

    python benchmarks/mip_object_order_feasibility.py
"""

from __future__ import annotations

import math
import statistics
import sys
import time
from pathlib import Path

import numba
import numpy as np
from numba import njit, prange

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))
from _machine import write_results  # noqa: E402

import splinecast as sc  # noqa: E402
from benchmarks.compare.scenes import ml, mri, noise  # noqa: E402
from splinecast.models.trilinear import cell_corners, corner_monomials, ray_cubic  # noqa: E402
from splinecast.roots.cubic import cubic_max  # noqa: E402

#: Edge of the blocks taken in decreasing order of their maxima, in cells.
BLOCK = 4
#: Edge of the screen tiles whose smallest running maximum decides whether a block is entered.
TILE = 8
ROUNDS = 3
AZIMUTHS = (40.0, 50.0, 60.0, 70.0)
SIZE = (1024, 768)


@njit(parallel=True, cache=True)
def cell_and_block_maxima(data):
    """Each cell's corner maximum (the trilinear interpolant's maximum in the cell) and each
    block's."""
    nx, ny, nz = data.shape[0] - 1, data.shape[1] - 1, data.shape[2] - 1
    cell_max = np.empty((nx, ny, nz))
    for i in prange(nx):
        for j in range(ny):
            for k in range(nz):
                cell_max[i, j, k] = cell_corners(data, i, j, k)[1]
    bx, by, bz = -(-nx // BLOCK), -(-ny // BLOCK), -(-nz // BLOCK)
    block_max = np.full((bx, by, bz), -np.inf)
    for i in prange(bx):
        for j in range(by):
            for k in range(bz):
                m = -np.inf
                for a in range(i * BLOCK, min(nx, i * BLOCK + BLOCK)):
                    for b in range(j * BLOCK, min(ny, j * BLOCK + BLOCK)):
                        for c in range(k * BLOCK, min(nz, k * BLOCK + BLOCK)):
                            m = max(m, cell_max[a, b, c])
                block_max[i, j, k] = m
    return cell_max, block_max


@njit(inline="always")
def _project(basis, origin, spacing, x, y, z, width, height):
    """Depth along the view axis, row and column (pixel centres at integers) of index point
    ``(x, y, z)`` under the perspective camera ``basis``."""
    wx = origin[0] + spacing[0] * x - basis[0]
    wy = origin[1] + spacing[1] * y - basis[1]
    wz = origin[2] + spacing[2] * z - basis[2]
    depth = wx * basis[3] + wy * basis[4] + wz * basis[5]
    sx = (wx * basis[6] + wy * basis[7] + wz * basis[8]) / depth
    sy = (wx * basis[9] + wy * basis[10] + wz * basis[11]) / depth
    return (depth, (1.0 - sy / basis[13]) * 0.5 * height - 0.5,
            (sx / basis[12] + 1.0) * 0.5 * width - 0.5)


@njit(inline="always")
def _pixel_span(lo, hi, last):
    """The pixel centres in ``[lo, hi]`` (a rounding margin wide), clamped to ``[0, last]``."""
    return max(0, int(math.ceil(lo - 1e-6))), min(last, int(math.floor(hi + 1e-6)))


@njit(parallel=True, cache=True)
def setup_rays(basis, origin, spacing, data, rays, best, where):
    """Each pixel's index-space direction, its reciprocal, its interval in the grid's box, and
    the value at its entry (``best = inf``: the ray misses)."""
    height, width = best.shape
    nx, ny, nz = data.shape[0] - 1, data.shape[1] - 1, data.shape[2] - 1
    ox = (basis[0] - origin[0]) / spacing[0]
    oy = (basis[1] - origin[1]) / spacing[1]
    oz = (basis[2] - origin[2]) / spacing[2]
    for row in prange(height):
        for col in range(width):
            sx = ((col + 0.5) / width * 2.0 - 1.0) * basis[12]
            sy = (1.0 - (row + 0.5) / height * 2.0) * basis[13]
            dx = basis[3] + sx * basis[6] + sy * basis[9]
            dy = basis[4] + sx * basis[7] + sy * basis[10]
            dz = basis[5] + sx * basis[8] + sy * basis[11]
            inv = 1.0 / math.sqrt(dx * dx + dy * dy + dz * dz)
            v = (dx * inv / spacing[0], dy * inv / spacing[1], dz * inv / spacing[2])
            t0, t1 = 0.0, math.inf
            for o, d, n in ((ox, v[0], nx), (oy, v[1], ny), (oz, v[2], nz)):
                if d == 0.0:
                    if o < 0.0 or o > n:
                        t0, t1 = math.inf, -math.inf
                else:
                    ta, tb = (0.0 - o) / d, (n - o) / d
                    t0, t1 = max(t0, min(ta, tb)), min(t1, max(ta, tb))
            for a in range(3):
                rays[row, col, a] = v[a]
                rays[row, col, 3 + a] = 1.0 / v[a] if v[a] != 0.0 else math.inf
            rays[row, col, 6] = t0
            rays[row, col, 7] = t1
            best[row, col] = math.inf
            where[row, col] = math.inf
            if t0 <= t1:
                x = min(max(ox + t0 * v[0], 0.0), float(nx))
                y = min(max(oy + t0 * v[1], 0.0), float(ny))
                z = min(max(oz + t0 * v[2], 0.0), float(nz))
                i, j, k = min(int(x), nx - 1), min(int(y), ny - 1), min(int(z), nz - 1)
                k0, k1, k2, k3, k4, k5, k6, k7 = corner_monomials(cell_corners(data, i, j, k))
                u, w, s = x - i, y - j, z - k
                best[row, col] = (k0 + k1 * u + k2 * w + k3 * s + k4 * u * w + k5 * u * s
                                  + k6 * w * s + k7 * u * w * s)
                where[row, col] = t0


@njit(inline="always")
def _tile_min(best, ty, tx):
    height, width = best.shape
    m = math.inf
    for r in range(ty * TILE, min(height, ty * TILE + TILE)):
        for c in range(tx * TILE, min(width, tx * TILE + TILE)):
            m = min(m, best[r, c])
    return m


@njit(inline="always")
def _tiles_min(tile_min, r0, r1, c0, c1):
    m = math.inf
    for ty in range(r0 // TILE, r1 // TILE + 1):
        for tx in range(c0 // TILE, c1 // TILE + 1):
            m = min(m, tile_min[ty, tx])
    return m


@njit(parallel=True, cache=True)
def project_mip(basis, origin, spacing, data, cell_max, block_max, order, rays, best, where,
                tile_min, strips, lattice, counts):
    """Raise each pixel's ``best`` / ``where`` to its ray's maximum and its first position,
    taking blocks in the order ``order``; thread ``s`` owns rows ``[strips[s], strips[s+1])``.
    ``counts[s]``: blocks entered, cells projected, (pixel, cell) pairs whose ray crosses the
    cell and whose cubic was formed."""
    height, width = best.shape
    ox = (basis[0] - origin[0]) / spacing[0]
    oy = (basis[1] - origin[1]) / spacing[1]
    oz = (basis[2] - origin[2]) / spacing[2]
    for ty in prange(tile_min.shape[0]):
        for tx in range(tile_min.shape[1]):
            tile_min[ty, tx] = _tile_min(best, ty, tx)
    by, bz = block_max.shape[1], block_max.shape[2]
    nx, ny, nz = cell_max.shape
    flat_max = block_max.ravel()
    for s in prange(strips.shape[0] - 1):
        ra, rb = strips[s], strips[s + 1] - 1
        lat = lattice[s]
        strip_min = _tiles_min(tile_min, ra, rb, 0, width - 1)
        entered = projected = formed = 0
        for q in range(order.shape[0]):
            b = order[q]
            top = flat_max[b]
            if top <= strip_min:
                break  # no later block beats any pixel of the strip
            if (q & 1023) == 1023:  # the strip's minimum only grows: refresh it now and then
                strip_min = _tiles_min(tile_min, ra, rb, 0, width - 1)
            bi, bj, bk = b // (by * bz), (b // bz) % by, b % bz
            behind = False
            rmin = cmin = math.inf
            rmax = cmax = -math.inf
            for a in range(0, BLOCK + 1, BLOCK):
                for e in range(0, BLOCK + 1, BLOCK):
                    for c in range(0, BLOCK + 1, BLOCK):
                        depth, rr, cc = _project(basis, origin, spacing, bi * BLOCK + a,
                                                 bj * BLOCK + e, bk * BLOCK + c, width, height)
                        behind |= depth <= 1e-9
                        rmin, rmax = min(rmin, rr), max(rmax, rr)
                        cmin, cmax = min(cmin, cc), max(cmax, cc)
            if behind:
                continue  # (the feasibility cameras never put the volume behind the eye)
            r0, r1 = _pixel_span(rmin, rmax, height - 1)
            c0, c1 = _pixel_span(cmin, cmax, width - 1)
            r0, r1 = max(r0, ra), min(r1, rb)
            if r0 > r1 or c0 > c1:
                continue
            floor = _tiles_min(tile_min, r0, r1, c0, c1)
            if not top > floor:
                continue
            # The block's lattice points projected once; its cells' boxes come from them.
            for a in range(BLOCK + 1):
                for e in range(BLOCK + 1):
                    for c in range(BLOCK + 1):
                        _, rr, cc = _project(basis, origin, spacing, bi * BLOCK + a,
                                             bj * BLOCK + e, bk * BLOCK + c, width, height)
                        lat[a, e, c, 0], lat[a, e, c, 1] = rr, cc
            entered += 1
            for i in range(bi * BLOCK, min(nx, bi * BLOCK + BLOCK)):
                for j in range(bj * BLOCK, min(ny, bj * BLOCK + BLOCK)):
                    for k in range(bk * BLOCK, min(nz, bk * BLOCK + BLOCK)):
                        cm = cell_max[i, j, k]
                        if not cm > floor:
                            continue
                        li, lj, lk = i - bi * BLOCK, j - bj * BLOCK, k - bk * BLOCK
                        prmin = pcmin = math.inf
                        prmax = pcmax = -math.inf
                        for a in range(2):
                            for e in range(2):
                                for c in range(2):
                                    rr = lat[li + a, lj + e, lk + c, 0]
                                    cc = lat[li + a, lj + e, lk + c, 1]
                                    prmin, prmax = min(prmin, rr), max(prmax, rr)
                                    pcmin, pcmax = min(pcmin, cc), max(pcmax, cc)
                        p0, p1 = _pixel_span(prmin, prmax, height - 1)
                        q0, q1 = _pixel_span(pcmin, pcmax, width - 1)
                        p0, p1, q0, q1 = max(p0, r0), min(p1, r1), max(q0, c0), min(q1, c1)
                        if p0 > p1 or q0 > q1:
                            continue
                        projected += 1
                        loaded = False
                        k0 = k1 = k2 = k3 = k4 = k5 = k6 = k7 = 0.0
                        for row in range(p0, p1 + 1):
                            for col in range(q0, q1 + 1):
                                if not cm > best[row, col]:
                                    continue
                                t0, t1 = rays[row, col, 6], rays[row, col, 7]
                                for o, lo, inv in ((ox, i, rays[row, col, 3]),
                                                   (oy, j, rays[row, col, 4]),
                                                   (oz, k, rays[row, col, 5])):
                                    ta, tb = (lo - o) * inv, (lo + 1 - o) * inv
                                    t0, t1 = max(t0, min(ta, tb)), min(t1, max(ta, tb))
                                if not t0 < t1:
                                    continue
                                formed += 1
                                if not loaded:
                                    k0, k1, k2, k3, k4, k5, k6, k7 = corner_monomials(
                                        cell_corners(data, i, j, k))
                                    loaded = True
                                vx, vy, vz = rays[row, col, 0], rays[row, col, 1], rays[row, col, 2]
                                c3, c2, c1_, c0_ = ray_cubic(
                                    k0, k1, k2, k3, k4, k5, k6, k7, ox + t0 * vx - i,
                                    oy + t0 * vy - j, oz + t0 * vz - k, (t1 - t0) * vx,
                                    (t1 - t0) * vy, (t1 - t0) * vz)
                                # The convex hull of the Bernstein coefficients bounds the cubic.
                                h1 = c0_ + c1_ / 3.0
                                h2 = c0_ + (2.0 * c1_ + c2) / 3.0
                                hull = max(max(c0_, h1), max(h2, c0_ + c1_ + c2 + c3))
                                if hull + 1e-11 * abs(hull) <= best[row, col]:
                                    continue
                                v, sp = cubic_max(c3, c2, c1_, c0_)
                                t = t0 + sp * (t1 - t0)
                                if v > best[row, col] or (v == best[row, col]
                                                          and t < where[row, col]):
                                    best[row, col] = v
                                    where[row, col] = t
            for ty in range(r0 // TILE, r1 // TILE + 1):
                for tx in range(c0 // TILE, c1 // TILE + 1):
                    tile_min[ty, tx] = _tile_min(best, ty, tx)
        counts[s, 0], counts[s, 1], counts[s, 2] = entered, projected, formed


def measure(spec) -> dict:
    vol = spec.make()
    scene = sc.Scene(vol)
    data = np.ascontiguousarray(scene.grid.kernel.data)
    cell_and_block_maxima(data)  # compilation for this data type
    start = time.perf_counter()
    cell_max, block_max = cell_and_block_maxima(data)
    order = np.argsort(-block_max.ravel(), kind="stable").astype(np.int64)
    prepare_ms = 1e3 * (time.perf_counter() - start)
    origin = np.asarray(vol.origin, float)
    spacing = np.asarray(vol.spacing, float)
    width, height = SIZE
    threads = numba.get_num_threads()
    rays = np.empty((height, width, 8))
    best = np.empty((height, width))
    where = np.empty((height, width))
    tile_min = np.empty((-(-height // TILE), -(-width // TILE)))
    lattice = np.empty((threads, BLOCK + 1, BLOCK + 1, BLOCK + 1, 2))
    counts = np.zeros((threads, 3), np.int64)
    lo, hi = vol.value_range
    row = {"scene": spec.label, "prepare_ms": prepare_ms, "threads": threads}
    times, walk, largest, formed, covered = [], [], 0.0, [], []
    for r in range(ROUNDS + 1):
        for az in AZIMUTHS:
            cam = sc.Camera.orbit(vol, azimuth=az, elevation=20.0, size=SIZE)
            basis = cam.pixel_basis()
            t = time.perf_counter()
            setup_rays(basis, origin, spacing, data, rays, best, where)
            # Strips of whole tile rows with as many covered pixels each.
            per_tile_row = np.cumsum(np.add.reduceat((best < np.inf).sum(axis=1),
                                                     np.arange(0, height, TILE)))
            cuts = [TILE * int(np.searchsorted(per_tile_row, per_tile_row[-1] * q / threads))
                    for q in range(1, threads)]
            strips = np.asarray([0, *cuts, height], np.int64)
            project_mip(basis, origin, spacing, data, cell_max, block_max, order, rays, best,
                        where, tile_min, strips, lattice, counts)
            t_object = time.perf_counter() - t
            t = time.perf_counter()
            ref = scene.render(cam, mode="mip", outputs=("value",)).value
            t_walk = time.perf_counter() - t
            if r == 0:  # warm-up round: the answers and the counts
                got = np.where(best < np.inf, best, np.nan)
                seen = np.isfinite(ref)
                assert np.array_equal(seen, np.isfinite(got)), "the rays that hit differ"
                largest = max(largest, float(np.abs(got[seen] - ref[seen]).max() / (hi - lo)))
                formed.append(int(counts[:, 2].sum()))
                covered.append(int(seen.sum()))
            else:
                times.append(t_object)
                walk.append(t_walk)
    row["object_order_ms"] = 1e3 * statistics.median(times)
    row["walk_ms"] = 1e3 * statistics.median(walk)
    row["largest_difference"] = largest
    row["cubics_per_ray"] = float(np.sum(formed) / np.sum(covered))
    print(row, flush=True)
    return row


def main() -> None:
    rows = [measure(spec) for spec in (ml(128), ml(256), mri(), noise(256)) if spec is not None]
    write_results(
        HERE / "results" / "mip_object_order_feasibility",
        "Exact MIP: an object-order projection against the renderer's ray walk",
        f"Command: `python benchmarks/mip_object_order_feasibility.py`. {SIZE[0]}x{SIZE[1]}, "
        f"four orbit views (azimuth 40-70, elevation 20), medians of {ROUNDS} rounds after a "
        "warm-up, run side by side in the same rounds. *Object order*: the stand-alone "
        "trilinear kernel of the script (ray set-up included, the sort of the blocks by "
        "maximum, done once per volume, not); *walk*: `scene.render(mode=\"mip\")`, outputs "
        "value only. *Difference*: the largest between the two answers, of the data range. "
        "*Cubics per ray*: (pixel, cell) pairs whose cubic the object order formed, per ray "
        "that hits (the walk tests 9.3-10.9 cells per ray, `mip_exact_limits.md`).",
        ["scene", "walk ms", "object order ms", "speed-up", "difference", "cubics per ray",
         "sort once ms"],
        rows, lambda r: [r["scene"], f"{r['walk_ms']:.1f}", f"{r['object_order_ms']:.1f}",
                         f"{r['walk_ms'] / r['object_order_ms']:.2f}x",
                         f"{r['largest_difference']:.1e}", f"{r['cubics_per_ray']:.1f}",
                         f"{r['prepare_ms']:.0f}"])

if __name__ == "__main__":
    main()
