"""Feasibility test: exact MIP on packets of 8 rays, written for the compiler to vectorize.

The scalar exact walk pays about 85 cycles per cell visited and 45-80 per block leapt
(``cycle_breakdown.py``), and neither a better order, a leaner walk nor a kinder memory layout
moves that (``mip_exact_limits.py``, ``mip_dda_feasibility.py``, ``mip_memory_limits.py``).
What remains is several rays per vector instruction. Numba has no vector types; it can only hand
LLVM loops that LLVM's vectorizer takes. This kernel gives it the most favourable loop it can:

* each thread keeps 8 lanes, each tracing one ray of its image row; a lane whose ray ends is
  refilled with the row's next pixel (scalar code, outside the hot loop);
* the hot loop (``step_lanes``) runs over the 8 lanes with no branch in its body: each lane
  either leaps the largest block of the 64-, 16- and 4-cell hierarchy that cannot beat its
  running maximum or its lower bound, or crosses one cell and maximises the cell's cubic along
  the ray in closed form (computed for every lane, kept only where it counts: selects, not
  branches);
* the lower bound is the model's value at the depth where the row's last finished ray found
  its maximum, as in the renderer.

It runs beside the lean scalar walk of ``mip_dda_feasibility.py`` on the same rays, and the
answers are compared. The machine code of ``step_lanes`` is then searched for packed
double-precision instructions and gathers: the signs that LLVM vectorized it.

Session 54: it did not. The hot loop's machine code holds no packed operation and no gather,
only scalar ones, and the packets run 2.5-4.8x slower than the scalar walk: without vectors,
the branch-free body makes every lane pay for a cell's cubic at every event, leaps included
(``results/mip_packet_feasibility.md``). SIMD over rays would need vector code written
explicitly (LLVM vector types through ``numba.extending.intrinsic``, or a compiled extension).

    python benchmarks/mip_packet_feasibility.py
"""

from __future__ import annotations

import math
import re
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from numba import njit, prange

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))
from _machine import write_results  # noqa: E402
from mip_dda_feasibility import cell_at, clip, dda_mip, tri, walk_inputs  # noqa: E402

from benchmarks.compare.scenes import ml, mri, noise  # noqa: E402
from splinecast.models.trilinear import cell_corners, corner_monomials, ray_cubic  # noqa: E402

#: Rays per packet (AVX-512 holds 8 doubles).
L = 8


@njit(inline="always")
def setup_lane(l, r, c, O, D, nx, ny, nz, v, t_last, ox, oy, oz, dx, dy, dz, ix, iy, iz,
               tt, t1a, best, lower, where, ci, cj, ck, act):
    """Start lane ``l`` on pixel ``(r, c)``; False if its ray misses the grid."""
    x0, y0, z0 = O[r, c, 0], O[r, c, 1], O[r, c, 2]
    ex, ey, ez = D[r, c, 0], D[r, c, 1], D[r, c, 2]
    t0, t1 = clip(x0, y0, z0, ex, ey, ez, nx, ny, nz)
    if not t0 <= t1:
        return False
    ox[l], oy[l], oz[l], dx[l], dy[l], dz[l] = x0, y0, z0, ex, ey, ez
    ix[l] = 1.0 / ex if ex != 0.0 else math.inf
    iy[l] = 1.0 / ey if ey != 0.0 else math.inf
    iz[l] = 1.0 / ez if ez != 0.0 else math.inf
    tt[l] = t0
    t1a[l] = t1
    best[l] = -math.inf
    where[l] = math.inf
    lo = -math.inf
    if t_last == t_last:
        ts = min(max(t_last, t0), t1)
        val = tri(v, x0 + ts * ex, y0 + ts * ey, z0 + ts * ez, nx, ny, nz)
        lo = val - 1e-9 * (abs(val) + 1.0)
    lower[l] = lo
    ci[l] = cell_at(x0 + t0 * ex, ex, nx)
    cj[l] = cell_at(y0 + t0 * ey, ey, ny)
    ck[l] = cell_at(z0 + t0 * ez, ez, nz)
    act[l] = 1.0
    return True


@njit(inline="always")
def axis_exit(c, size, o, inv, d):
    """The aligned block of ``size`` cells around cell ``c`` on one axis: its first cell, the
    plane the ray leaves it by, and the ray parameter there."""
    base = c & -size
    plane = base + size if d > 0.0 else base
    t = (plane - o) * inv if d != 0.0 else math.inf
    return base, plane, t


@njit(inline="always")
def advance(c, base, plane, size, t_axis, te, o, d):
    """The cell the ray enters on one axis after leaving the block at ``te``."""
    if t_axis == te:
        return plane if d > 0.0 else plane - 1
    return min(max(int(math.floor(o + te * d)), base), base + size - 1)


@njit(fastmath=False, error_model="numpy")
def step_lanes(v, h0, h1, h2, nx, ny, nz, ox, oy, oz, dx, dy, dz, ix, iy, iz, tt, t1a, best,
               lower, where, ci, cj, ck, act):
    """One event (a leap or a cell) for each of the L lanes, branch-free."""
    for l in range(L):
        i = min(max(ci[l], 0), nx - 1)
        j = min(max(cj[l], 0), ny - 1)
        k = min(max(ck[l], 0), nz - 1)
        ui, uj, uk = np.uint64(i), np.uint64(j), np.uint64(k)
        b = best[l]
        lo = lower[l]
        m2 = h2[ui >> np.uint64(6), uj >> np.uint64(6), uk >> np.uint64(6)]
        m1 = h1[ui >> np.uint64(4), uj >> np.uint64(4), uk >> np.uint64(4)]
        m0 = h0[ui >> np.uint64(2), uj >> np.uint64(2), uk >> np.uint64(2)]
        size = 1
        size = 4 if (m0 <= b or m0 < lo) else size
        size = 16 if (m1 <= b or m1 < lo) else size
        size = 64 if (m2 <= b or m2 < lo) else size
        bx, px, tx = axis_exit(i, size, ox[l], ix[l], dx[l])
        by, py, ty = axis_exit(j, size, oy[l], iy[l], dy[l])
        bz, pz, tz = axis_exit(k, size, oz[l], iz[l], dz[l])
        te = min(tx, min(ty, tz))
        t0 = tt[l]
        t1 = t1a[l]
        tend = min(te, t1)
        # The cell's cubic along the ray on [t0, tend], as the renderer's trilinear model
        # forms it.
        k0, k1, k2, k3, k4, k5, k6, k7 = corner_monomials(cell_corners(v, i, j, k))
        ax = ox[l] + t0 * dx[l] - i
        ay = oy[l] + t0 * dy[l] - j
        az = oz[l] + t0 * dz[l] - k
        ex = ox[l] + tend * dx[l] - i - ax
        ey = oy[l] + tend * dy[l] - j - ay
        ez = oz[l] + tend * dz[l] - k - az
        q3, q2, q1, q0 = ray_cubic(k0, k1, k2, k3, k4, k5, k6, k7, ax, ay, az, ex, ey, ez)
        f1 = q0 + q1 + q2 + q3
        cb = q0
        cs = 0.0
        cs = 1.0 if f1 > cb else cs
        cb = max(cb, f1)
        A = 3.0 * q3
        B = 2.0 * q2
        C = q1
        disc = B * B - 4.0 * A * C
        rd = math.sqrt(max(disc, 0.0))
        quad = A != 0.0 and disc >= 0.0
        s1 = (-B - rd) / (2.0 * A) if quad else (-C / B)
        s2 = (-B + rd) / (2.0 * A) if quad else -1.0
        fs1 = q0 + s1 * (q1 + s1 * (q2 + s1 * q3))
        fs2 = q0 + s2 * (q1 + s2 * (q2 + s2 * q3))
        ok1 = s1 > 0.0 and s1 < 1.0 and (quad or (A == 0.0 and B != 0.0))
        ok2 = s2 > 0.0 and s2 < 1.0 and quad
        take1 = ok1 and fs1 > cb
        cs = s1 if take1 else cs
        cb = fs1 if take1 else cb
        take2 = ok2 and fs2 > cb
        cs = s2 if take2 else cs
        cb = fs2 if take2 else cb
        live = act[l] > 0.0
        use = live and size == 1 and tend > t0 and cb > b
        best[l] = cb if use else b
        where[l] = (t0 + cs * (tend - t0)) if use else where[l]
        ni = advance(i, bx, px, size, tx, te, ox[l], dx[l])
        nj = advance(j, by, py, size, ty, te, oy[l], dy[l])
        nk = advance(k, bz, pz, size, tz, te, oz[l], dz[l])
        outside = ni < 0 or ni >= nx or nj < 0 or nj >= ny or nk < 0 or nk >= nz
        finished = te >= t1 or outside
        act[l] = 0.0 if (finished or not live) else 1.0
        ci[l] = ni
        cj[l] = nj
        ck[l] = nk
        tt[l] = max(t0, te)


@njit(parallel=True, fastmath=False, error_model="numpy")
def packet_mip(v, h0, h1, h2, O, D, out):
    """Exact trilinear MIP of rays ``O + t D`` (index space) into ``out``, 8 lanes a thread."""
    H, W = out.shape
    nx, ny, nz = v.shape[0] - 1, v.shape[1] - 1, v.shape[2] - 1
    for r in prange(H):
        # The lanes' rays (origin, direction, reciprocal direction), the walk's state (entry
        # and exit parameters, cell, whether the lane is tracing) and the running answer.
        ox, oy, oz = np.empty(L), np.empty(L), np.empty(L)
        dx, dy, dz = np.empty(L), np.empty(L), np.empty(L)
        ix, iy, iz = np.empty(L), np.empty(L), np.empty(L)
        tt, t1a, act = np.zeros(L), np.zeros(L), np.zeros(L)
        best, lower, where = np.full(L, -math.inf), np.full(L, -math.inf), np.full(L, math.inf)
        ci, cj, ck = np.zeros(L, np.int64), np.zeros(L, np.int64), np.zeros(L, np.int64)
        pix = np.full(L, -1, np.int64)
        nxt = 0
        t_last = math.nan
        busy = 0
        while True:
            # refill idle lanes (scalar)
            for l in range(L):
                if act[l] == 0.0:
                    if pix[l] >= 0:
                        out[r, pix[l]] = best[l] if best[l] > -math.inf else math.nan
                        if where[l] < math.inf:
                            t_last = where[l]
                        pix[l] = -1
                        busy -= 1
                    while nxt < W:
                        c = nxt
                        nxt += 1
                        if setup_lane(l, r, c, O, D, nx, ny, nz, v, t_last, ox, oy, oz, dx, dy,
                                      dz, ix, iy, iz, tt, t1a, best, lower, where, ci, cj, ck,
                                      act):
                            pix[l] = c
                            busy += 1
                            break
                        out[r, c] = math.nan
            if busy == 0:
                break
            step_lanes(v, h0, h1, h2, nx, ny, nz, ox, oy, oz, dx, dy, dz, ix, iy, iz, tt, t1a,
                       best, lower, where, ci, cj, ck, act)


ROUNDS = 5
SIZE = (1024, 768)


def vector_signs() -> dict[str, int]:
    """Counts, in ``step_lanes``' machine code, of packed double-precision arithmetic and of
    gathers (what a vectorized loop over the lanes would be made of), and of scalar ones."""
    asm = "\n".join(step_lanes.inspect_asm().values())
    return {
        "packed_double_ops": len(re.findall(r"\bv(?:add|sub|mul|div|min|max|sqrt|fmadd\w*)pd\b",
                                            asm)),
        "gathers": len(re.findall(r"\bvgather\w+", asm)),
        "scalar_double_ops": len(re.findall(r"\bv(?:add|sub|mul|div|min|max|sqrt|fmadd\w*)sd\b",
                                            asm)),
    }


def measure(spec) -> dict:
    """Packet and scalar walks on one scene, interleaved; their answers compared."""
    vol, _, _, data, (h0, h1, h2), o_index, d_index = walk_inputs(spec, SIZE)
    packet = np.empty(SIZE[::-1])
    scalar = np.empty(SIZE[::-1])
    visits = np.zeros(SIZE[::-1], np.int64)
    unused = np.zeros((1, 1, 1), data.dtype)
    runs = {
        "packet": lambda: packet_mip(data, h0, h1, h2, o_index,
                                     d_index, packet),
        "scalar": lambda: dda_mip(data, h0, h1, h2, o_index, d_index,
                                  scalar, visits, unused, -1, scalar),
    }
    times: dict[str, list[float]] = {name: [] for name in runs}
    for round_ in range(ROUNDS + 1):  # round 0 compiles and warms up
        for name, run in runs.items():
            start = time.perf_counter()
            run()
            if round_ > 0:
                times[name].append((time.perf_counter() - start) * 1e3)
    both = np.isfinite(packet) & np.isfinite(scalar)
    lo, hi = vol.value_range
    row = {"scene": spec.label,
           "packet_ms": statistics.median(times["packet"]),
           "scalar_ms": statistics.median(times["scalar"]),
           "largest_difference": float(np.abs(packet[both] - scalar[both]).max() / (hi - lo)),
           "same_misses": bool(np.array_equal(np.isfinite(packet), np.isfinite(scalar)))}
    print(row, flush=True)
    return row


def main() -> None:
    rows = [measure(spec) for spec in (ml(128), ml(256), mri(), noise(256)) if spec is not None]
    signs = vector_signs()
    print(signs)
    for row in rows:
        row.update(signs)
    write_results(
        HERE / "results" / "mip_packet_feasibility",
        "Exact MIP: packets of 8 rays written for LLVM's vectorizer, against the scalar walk",
        f"Command: `python benchmarks/mip_packet_feasibility.py`. {SIZE[0]}x{SIZE[1]}, the "
        "comparison's orbit camera at azimuth 40, numba's default threads, medians of "
        f"{ROUNDS} rounds after a warm-up, the two kernels interleaved. *Scalar*: the lean walk "
        "of `mip_dda_feasibility.py`. *Difference*: the largest between the two answers, of "
        "the data range. Machine code of the packet's hot loop (`step_lanes`): "
        f"{signs['packed_double_ops']} packed double-precision operations, {signs['gathers']} "
        f"gathers, {signs['scalar_double_ops']} scalar double-precision operations.",
        ["scene", "packet ms", "scalar ms", "packet time / scalar time", "difference",
         "same rays miss"],
        rows, lambda r: [r["scene"], f"{r['packet_ms']:.1f}", f"{r['scalar_ms']:.1f}",
                         f"{r['packet_ms'] / r['scalar_ms']:.2f}x",
                         f"{r['largest_difference']:.1e}", "yes" if r["same_misses"] else "NO"])


if __name__ == "__main__":
    main()
