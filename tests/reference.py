"""Independent reference implementations used by the splinecast tests.

Nothing here imports splinecast: every reference is written from the mathematical definition so
that the tests compare the package against an independent computation, never against itself.

* :func:`exact_walk` -- the cells a ray passes through, from exact rational arithmetic
  (``fractions.Fraction``) on the float inputs, which are exactly representable rationals.
* :func:`mp_cubic_first_root`, :func:`mp_quadratic_roots` -- polynomial roots with mpmath at high
  precision.
* :func:`trilinear` -- the trilinear interpolant in plain numpy (lerp form, not the monomial form
  the package uses), and :class:`RefIsoCaster`, a brute-force first-hit isosurface ray caster built
  on it (see its docstring for why it cannot miss a crossing).
* :func:`box_interval`, :func:`planes_interval`, :func:`all_crossings` -- ray intervals in a box
  and behind clip planes, and every crossing of several isovalues along rays by dense sampling
  and bisection of any value function.
* :func:`bspline` -- tensor-product B-splines evaluated by scipy (``map_coordinates``).
* :func:`dense_dvr` -- the emission-absorption integral along rays, by dense sampling of the
  trilinear interpolant, with the transfer function evaluated from its control points.
* Analytic test volumes: :func:`marschner_lobb`, :func:`sphere_distance`, :func:`smooth_noise`.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np

__all__ = [
    "exact_walk",
    "mp_cubic_real_roots",
    "mp_cubic_first_root",
    "mp_quadratic_roots",
    "trilinear",
    "RefIsoCaster",
    "box_interval",
    "planes_interval",
    "all_crossings",
    "bspline",
    "dense_dvr",
    "marschner_lobb",
    "sphere_distance",
    "smooth_noise",
]


# =============================================================================== grid traversal
def exact_walk(origin, direction, n_cells) -> list[tuple[int, int, int]]:
    """Cells whose interior the ray ``o + t d`` (``t >= 0``) passes through, in order.

    Index space: cell ``(i, j, k)`` is ``[i, i+1] x [j, j+1] x [k, k+1]``, the grid is
    ``[0, n_a]`` per axis. Computed exactly with rationals: the ray is clipped to the grid box, all
    parameters where a coordinate crosses an integer plane are collected and sorted, and every
    piece between consecutive crossings (which has positive length) contributes the cell holding
    its midpoint. A cell only touched in a point, an edge or a corner therefore never appears.
    A ray lying in a plane ``x_a = c`` (``d_a == 0`` and ``c`` an integer) is assigned to the cell
    on the positive side, ``floor(c)``, except on the grid's upper face ``c == n_a`` where it
    belongs to the last cell ``n_a - 1``.
    """
    o = [Fraction(float(v)) for v in origin]
    d = [Fraction(float(v)) for v in direction]
    n = [int(v) for v in n_cells]
    if all(v == 0 for v in d):
        raise ValueError("direction must not be zero")
    t0: Fraction = Fraction(0)
    t1: Fraction | None = None  # None stands for +infinity
    for a in range(3):
        if d[a] == 0:
            if o[a] < 0 or o[a] > n[a]:
                return []
            continue
        ta = (0 - o[a]) / d[a]
        tb = (n[a] - o[a]) / d[a]
        if ta > tb:
            ta, tb = tb, ta
        t0 = max(t0, ta)
        t1 = tb if t1 is None else min(t1, tb)
    assert t1 is not None
    if not t0 < t1:
        return []
    params = {t0, t1}
    for a in range(3):
        if d[a] == 0:
            continue
        x0, x1 = sorted((o[a] + t0 * d[a], o[a] + t1 * d[a]))
        # integers strictly between x0 and x1
        for plane in range(math.floor(x0) + 1, math.ceil(x1)):
            params.add((plane - o[a]) / d[a])
    ts = sorted(params)
    cells = []
    for ta, tb in zip(ts[:-1], ts[1:], strict=True):
        tm = (ta + tb) / 2
        cell = []
        for a in range(3):
            x = o[a] + tm * d[a]
            c = math.floor(x)
            if d[a] == 0:
                c = min(c, n[a] - 1)  # lying in the grid's upper face: the last cell
            assert 0 <= c < n[a], (a, x)
            cell.append(c)
        cells.append(tuple(cell))
    return cells


# =============================================================================== polynomials
def mp_cubic_real_roots(c3, c2, c1, c0, dps: int = 60, imag_tol: float = 1e-25) -> list:
    """Real roots (mpmath ``mpf``, sorted, with multiplicity) of the float-coefficient cubic.

    The coefficients are taken exactly (a float is a rational); leading zero coefficients lower
    the degree. Returns ``None`` for the zero polynomial.
    """
    import mpmath

    with mpmath.workdps(dps):
        coeffs = [mpmath.mpf(float(c)) for c in (c3, c2, c1, c0)]
        while coeffs and coeffs[0] == 0:
            coeffs.pop(0)
        if not coeffs:
            return None  # identically zero
        if len(coeffs) == 1:
            return []
        roots = mpmath.polyroots(coeffs, maxsteps=400, extraprec=4 * dps)  # highest degree first
        real = []
        for r in roots:
            r = mpmath.mpc(r)
            if abs(r.imag) <= imag_tol * max(1, abs(r)):
                real.append(+r.real)
        return sorted(real)


def mp_cubic_first_root(c3, c2, c1, c0, lo, hi, dps: int = 60):
    """Smallest real root in ``[lo, hi]`` as an ``mpf`` (``lo`` for the zero polynomial),
    or ``None`` when there is none."""
    roots = mp_cubic_real_roots(c3, c2, c1, c0, dps=dps)
    if roots is None:
        return lo
    inside = [r for r in roots if lo <= r <= hi]
    return min(inside) if inside else None


def mp_quadratic_roots(a, b, c, dps: int = 60) -> list:
    """Distinct real roots (sorted ``mpf``) of ``a s^2 + b s + c`` (exact float coefficients)."""
    import mpmath

    with mpmath.workdps(dps):
        a, b, c = (mpmath.mpf(float(v)) for v in (a, b, c))
        if a == 0:
            if b == 0:
                return []
            return [-c / b]
        disc = b * b - 4 * a * c  # exact at this precision (products of 53-bit numbers)
        if disc < 0:
            return []
        if disc == 0:
            return [-b / (2 * a)]
        sq = mpmath.sqrt(disc)
        return sorted([(-b - sq) / (2 * a), (-b + sq) / (2 * a)])


# =============================================================================== trilinear
def trilinear(data: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Trilinear interpolant of ``data`` at index-space points ``p`` (shape (..., 3)).

    Written as nested linear interpolations between the eight corner voxels (not in the monomial
    form the package uses). Points are clamped into the grid box ``[0, n - 1]``.
    """
    data = np.asarray(data, dtype=np.float64)
    p = np.asarray(p, dtype=np.float64)
    hi = np.asarray(data.shape, dtype=np.float64) - 1.0
    p = np.clip(p, 0.0, hi)
    cell = np.minimum(np.floor(p), hi - 1.0).astype(np.intp)
    f = p - cell
    i, j, k = cell[..., 0], cell[..., 1], cell[..., 2]
    x, y, z = f[..., 0], f[..., 1], f[..., 2]

    def lerp(u, v, s):
        return u + s * (v - u)

    c00 = lerp(data[i, j, k], data[i + 1, j, k], x)
    c10 = lerp(data[i, j + 1, k], data[i + 1, j + 1, k], x)
    c01 = lerp(data[i, j, k + 1], data[i + 1, j, k + 1], x)
    c11 = lerp(data[i, j + 1, k + 1], data[i + 1, j + 1, k + 1], x)
    return lerp(lerp(c00, c10, y), lerp(c01, c11, y), z)


class RefIsoCaster:
    """Brute-force reference for first-hit isosurface ray casting on the trilinear interpolant.

    For a world ray ``W + t U`` (``U`` a unit vector) the index-space ray is ``o + t d`` with
    ``o = (W - origin) / spacing``, ``d = U / spacing``; it is clipped to the reconstruction box
    ``[0, n - 1]^3`` and ``g(t) = f(o + t d) - iso`` is searched for its first sign change.

    Why it cannot miss a crossing: dense sampling at any fixed step can step over a crossing pair
    that is thinner than the step. Instead of a fixed step this reference uses two bounds that
    hold for the trilinear interpolant everywhere:

    * ``|g'(t)| <= L = sum_a |d_a| G_a`` where ``G_a`` is the largest voxel difference along axis
      ``a`` (inside a cell ``df/dx_a`` is a bilinear blend of the four edge differences along
      ``a``); so an interval ``[a, b]`` whose end values have the same sign and satisfy
      ``|g(a)| + |g(b)| > L (b - a)`` contains no zero;
    * inside one cell ``|g''(t)| <= M = 2 sum_{a<b} |d_a d_b| H_ab`` where ``H_ab`` is the largest
      mixed second difference in the ``ab`` planes (``f`` is linear along each axis, so only
      mixed derivatives appear); so an interval that crosses no grid plane and has
      ``min(|g(a)|, |g(b)|) > M (b - a)^2 / 8`` contains no zero.

    The search is a branch and bound over the whole clipped segment, vectorised over rays: every
    interval that cannot be proven zero-free is halved, intervals to the right of the leftmost
    interval with a sign change are dropped, and the process stops when the intervals are
    narrower than ``tol`` voxels (1e-12). This is exactly "sample densely, take the first sign
    change and bisect", with the sampling made as dense as needed wherever a crossing could hide
    and skipped only where the bounds prove that none can. The result is the first sign change of
    ``g`` to within ``tol`` (a tangential touch without sign change is not a hit).
    """

    def __init__(self, data, spacing=(1.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0), tol: float = 1e-12):
        self.data = np.ascontiguousarray(np.asarray(data, dtype=np.float64))
        self.shape = np.asarray(self.data.shape)
        self.spacing = np.broadcast_to(np.asarray(spacing, dtype=np.float64), (3,)).copy()
        self.origin = np.broadcast_to(np.asarray(origin, dtype=np.float64), (3,)).copy()
        self.tol = tol
        d = self.data
        self.G = np.array([np.abs(np.diff(d, axis=a)).max() for a in range(3)])
        mixed = {}
        for a, b in ((0, 1), (0, 2), (1, 2)):
            mixed[a, b] = np.abs(np.diff(np.diff(d, axis=a), axis=b)).max()
        self.H = mixed
        self.lo = float(d.min())
        self.hi = float(d.max())
        self.range = self.hi - self.lo
        # absolute rounding slack of a value of g (values are O(max |data|))
        self.slack = 1e-13 * max(1.0, float(np.abs(d).max()))

    @classmethod
    def of(cls, volume, **kw) -> RefIsoCaster:
        """Build from anything with ``data``, ``spacing``, ``origin`` attributes (a Volume)."""
        return cls(volume.data, volume.spacing, volume.origin, **kw)

    # ------------------------------------------------------------------ basic evaluation
    def to_index(self, W, U):
        """Index-space ray ``(o, d)`` of world rays ``(W, U)``."""
        W = np.asarray(W, dtype=np.float64)
        U = np.asarray(U, dtype=np.float64)
        return (W - self.origin) / self.spacing, U / self.spacing

    def value_world(self, P) -> np.ndarray:
        """Interpolant at world positions ``P`` (..., 3)."""
        return trilinear(self.data, (np.asarray(P, np.float64) - self.origin) / self.spacing)

    def g(self, o, d, t, iso):
        """``f(o + t d) - iso`` for rays (R, 3) and parameters t (R,)."""
        return trilinear(self.data, o + t[:, None] * d) - iso

    def clip(self, o, d):
        """Parameter interval ``[t0, t1]`` (``t >= 0``) inside the box ``[0, n - 1]^3``."""
        R = o.shape[0]
        t0 = np.zeros(R)
        t1 = np.full(R, np.inf)
        with np.errstate(divide="ignore", invalid="ignore"):
            for a in range(3):
                hi = float(self.shape[a] - 1)
                par = d[:, a] == 0.0
                inside = (o[:, a] >= 0.0) & (o[:, a] <= hi)
                ta = (0.0 - o[:, a]) / d[:, a]
                tb = (hi - o[:, a]) / d[:, a]
                lo_, hi_ = np.minimum(ta, tb), np.maximum(ta, tb)
                t0 = np.where(par, np.where(inside, t0, np.inf), np.maximum(t0, lo_))
                t1 = np.where(par, np.where(inside, t1, -np.inf), np.minimum(t1, hi_))
        return t0, t1

    def lipschitz(self, d):
        """Per-ray bounds ``L >= |g'|`` and ``M >= |g''|`` (inside a cell), per unit t."""
        ad = np.abs(d)
        L = (ad * self.G).sum(axis=1)
        M = 2.0 * sum(ad[:, a] * ad[:, b] * self.H[a, b] for (a, b) in self.H)
        return L * (1.0 + 1e-9), M * (1.0 + 1e-9)

    # ------------------------------------------------------------------ first sign change
    def first_root(self, o, d, t0, t1, sgn, iso, max_live: int = 20000):
        """First zero of ``g`` on ``[t0, t1]`` for rays with ``sgn * g(t0) >= 0``.

        Returns ``(root, unresolved)``: the first sign change (``inf`` when there is none) and a
        flag for rays abandoned because too many intervals stayed undecided (should not happen).
        """
        R = o.shape[0]
        root = np.full(R, np.inf)
        unresolved = np.zeros(R, dtype=bool)
        L, M = self.lipschitz(d)
        dnorm = np.linalg.norm(d, axis=1)
        tol_t = np.maximum(self.tol / dnorm, 4 * np.spacing(np.maximum(np.abs(t1), 1.0)))
        valid = t0 <= t1
        rid = np.nonzero(valid)[0]
        if rid.size == 0:
            return root, unresolved
        w_start = sgn[rid] * self.g(o[rid], d[rid], t0[rid], iso)
        at_start = w_start <= 0.0
        root[rid[at_start]] = t0[rid[at_start]]
        rid = rid[~at_start]
        a = t0[rid]
        b = t1[rid]
        wa = w_start[~at_start]
        wb = sgn[rid] * self.g(o[rid], d[rid], b, iso)
        slack = self.slack
        while rid.size:
            width = b - a
            sc = wb <= 0.0
            # cannot contain a zero: Lipschitz bound, or curvature bound inside one cell
            xa = o[rid] + a[:, None] * d[rid]
            xb = o[rid] + b[:, None] * d[rid]
            one_cell = np.all((np.floor(xa) == np.floor(xb)) | (d[rid] == 0.0), axis=1)
            free = ~sc & (
                (wa + wb > L[rid] * width + 2 * slack)
                | (one_cell & (np.minimum(wa, wb) > M[rid] * width * width / 8 + slack))
            )
            keep = ~free & (wa > 0.0)
            rid, a, b, wa, wb, sc, width = (v[keep] for v in (rid, a, b, wa, wb, sc, width))
            if rid.size == 0:
                break
            # drop everything right of each ray's leftmost interval with a sign change
            first_sc = np.full(R, np.inf)
            if sc.any():
                np.minimum.at(first_sc, rid[sc], a[sc])
            keep = a <= first_sc[rid]
            rid, a, b, wa, wb, sc, width = (v[keep] for v in (rid, a, b, wa, wb, sc, width))
            counts = np.bincount(rid, minlength=R)
            if counts.max() > max_live:
                bad = counts > max_live
                unresolved |= bad
                keep = ~bad[rid]
                rid, a, b, wa, wb, sc, width = (v[keep] for v in (rid, a, b, wa, wb, sc, width))
            done = width <= tol_t[rid]
            if done.all():
                break
            # halve the intervals that are not yet narrow enough
            s = ~done
            m = 0.5 * (a[s] + b[s])
            wm = sgn[rid[s]] * self.g(o[rid[s]], d[rid[s]], m, iso)
            rid = np.concatenate([rid[done], rid[s], rid[s]])
            a, b, wa, wb = (
                np.concatenate([a[done], a[s], m]),
                np.concatenate([b[done], m, b[s]]),
                np.concatenate([wa[done], wa[s], wm]),
                np.concatenate([wb[done], wm, wb[s]]),
            )
        # the leftmost interval with a sign change holds the first root
        if rid.size:
            sc = wb <= 0.0
            est = np.where(wb == 0.0, b, 0.5 * (a + b))
            np.minimum.at(root, rid[sc], est[sc])
        return root, unresolved

    def first_hits(self, W, U, iso, chunk: int = 1024):
        """First-hit depths (world distance along the unit ray; ``inf`` on a miss).

        ``W``, ``U``: world origins and unit directions, shape (..., 3). Returns ``(depth,
        unresolved)`` with the leading shape of ``W``.
        """
        W, U = np.broadcast_arrays(np.asarray(W, np.float64), np.asarray(U, np.float64))
        shape = W.shape[:-1]
        W = W.reshape(-1, 3)
        U = U.reshape(-1, 3)
        depth = np.full(W.shape[0], np.inf)
        unresolved = np.zeros(W.shape[0], dtype=bool)
        for s in range(0, W.shape[0], chunk):
            o, d = self.to_index(W[s:s + chunk], U[s:s + chunk])
            t0, t1 = self.clip(o, d)
            ok = t0 <= t1
            g0 = np.where(ok, 0.0, 1.0)
            g0[ok] = self.g(o[ok], d[ok], t0[ok], iso)
            sgn = np.where(g0 < 0.0, -1.0, 1.0)
            depth[s:s + chunk], unresolved[s:s + chunk] = self.first_root(o, d, t0, t1, sgn, iso)
        return depth.reshape(shape), unresolved.reshape(shape)

    def excursion_width(self, W, U, iso, t_root, window: float = 1e-2):
        """Width (in t) of the excursion beyond ``iso`` that starts at the crossing ``t_root``.

        The ray's side before the crossing is taken from a point just before ``t_root``; the
        return crossing is searched within ``window`` voxels. ``inf`` if it does not return.
        """
        W = np.atleast_2d(np.asarray(W, np.float64))
        U = np.atleast_2d(np.asarray(U, np.float64))
        t_root = np.atleast_1d(np.asarray(t_root, np.float64))
        o, d = self.to_index(W, U)
        dn = np.linalg.norm(d, axis=1)
        t0c, t1c = self.clip(o, d)
        eps = np.maximum(4 * self.tol / dn, 8 * np.spacing(np.abs(t_root) + 1.0))
        before = self.g(o, d, np.maximum(t_root - eps, t0c), iso)
        sgn_before = np.where(before < 0.0, -1.0, 1.0)
        start = t_root + eps
        end = np.minimum(t1c, t_root + window / dn)
        back, _ = self.first_root(o, d, start, end, -sgn_before, iso)
        return back - t_root


# =============================================================================== ray intervals
def box_interval(o, d, lo, hi):
    """``(t0, t1)`` of rays ``o + t d`` (t >= 0, shape (R, 3)) inside the box ``[lo, hi]``;
    ``t0 > t1`` for a ray that misses it."""
    o, d = np.asarray(o, np.float64), np.asarray(d, np.float64)
    lo, hi = np.broadcast_to(lo, (3,)), np.broadcast_to(hi, (3,))
    t0 = np.zeros(len(o))
    t1 = np.full(len(o), np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for a in range(3):
            ta, tb = (lo[a] - o[:, a]) / d[:, a], (hi[a] - o[:, a]) / d[:, a]
            par = d[:, a] == 0.0
            inside = (o[:, a] >= lo[a]) & (o[:, a] <= hi[a])
            t0 = np.where(par, np.where(inside, t0, np.inf), np.maximum(t0, np.minimum(ta, tb)))
            t1 = np.where(par, np.where(inside, t1, -np.inf), np.minimum(t1, np.maximum(ta, tb)))
    return t0, t1


def planes_interval(W, U, planes):
    """``(t_min, t_max)`` of world rays ``W + t U`` (t >= 0) in the half-spaces
    ``n . x + d >= 0`` of ``planes`` (rows ``(nx, ny, nz, d)``); ``t_min > t_max`` when none."""
    W, U = np.asarray(W, np.float64), np.asarray(U, np.float64)
    t_min = np.zeros(len(W))
    t_max = np.full(len(W), np.inf)
    for plane in np.asarray(planes, np.float64).reshape(-1, 4):
        at_origin = W @ plane[:3] + plane[3]
        rate = U @ plane[:3]
        with np.errstate(divide="ignore", invalid="ignore"):
            cross = -at_origin / rate
        t_min = np.where(rate > 0, np.maximum(t_min, cross), t_min)
        t_max = np.where(rate < 0, np.minimum(t_max, cross), t_max)
        outside = (rate == 0) & (at_origin < 0)
        t_min = np.where(outside, np.inf, t_min)
        t_max = np.where(outside, -np.inf, t_max)
    return t_min, t_max


def all_crossings(value, o, d, t0, t1, isos, step: float = 1e-3, tangent: float = 1e-4,
                  bisections: int = 60):
    """Every crossing of every isovalue along index-space rays ``o + t d``, ``t in [t0, t1]``.

    ``value`` maps index points (..., 3) to field values. Each ray is sampled at equal steps of at
    most ``step`` voxels (index-space arc length); every sign change of ``value - iso`` between
    neighbouring samples is refined by ``bisections`` halvings. Returns ``(crossings,
    ambiguous)``: per ray a sorted array of ``(t, iso index)`` rows and a flag set when the
    sampling cannot decide the crossings: a sample within ``tangent`` of an isovalue at a local
    minimum of ``|value - iso|`` without a sign change (a tangency, or two crossings closer than
    the step), or a sample exactly on an isovalue. All rays are evaluated together (a few calls
    of ``value`` on many points), so a slow-to-call evaluator stays cheap.
    """
    o, d = np.asarray(o, np.float64), np.asarray(d, np.float64)
    t0, t1 = np.asarray(t0, np.float64), np.asarray(t1, np.float64)
    isos = np.asarray(isos, np.float64)
    R = len(o)
    live = t0 < t1
    length = np.where(live, (t1 - t0) * np.linalg.norm(d, axis=1), 0.0)
    count = np.where(live, np.ceil(length / step).astype(np.int64) + 1, 0)
    ray = np.repeat(np.arange(R), count)  # ray of each sample, rays one after the other
    first = np.concatenate([[0], np.cumsum(count)[:-1]])
    frac = (np.arange(len(ray)) - first[ray]) / np.maximum(count[ray] - 1, 1)
    ts = t0[ray] + frac * (t1[ray] - t0[ray])
    v = value(o[ray] + ts[:, None] * d[ray]) if len(ray) else np.zeros(0)
    same_ray = ray[1:] == ray[:-1]  # neighbouring samples on one ray
    ambiguous = np.zeros(R, bool)
    found_t, found_k, found_r = [], [], []
    for k, iso in enumerate(isos):
        g = v - iso
        np.logical_or.at(ambiguous, ray[g == 0.0], True)
        change = same_ray & (np.sign(g[:-1]) != np.sign(g[1:]))
        a, b, ga = ts[:-1][change], ts[1:][change], g[:-1][change]
        rid = ray[:-1][change]
        for _ in range(bisections):
            m = 0.5 * (a + b)
            gm = value(o[rid] + m[:, None] * d[rid]) - iso if len(m) else m
            left = np.sign(gm) == np.sign(ga)
            a, ga = np.where(left, m, a), np.where(left, gm, ga)
            b = np.where(left, b, m)
        found_t.append(0.5 * (a + b))
        found_k.append(np.full(len(a), k))
        found_r.append(rid)
        absg = np.abs(g)
        mid = same_ray[:-1] & same_ray[1:]  # sample i+1 has neighbours on its own ray
        dip = (mid & (absg[1:-1] <= absg[:-2]) & (absg[1:-1] <= absg[2:]) & ~change[:-1]
               & ~change[1:] & (absg[1:-1] < tangent))
        np.logical_or.at(ambiguous, ray[1:-1][dip], True)
    t_all, k_all, r_all = (np.concatenate(x) for x in (found_t, found_k, found_r))
    order = np.lexsort((t_all, r_all))
    t_all, k_all, r_all = t_all[order], k_all[order], r_all[order]
    bounds = np.searchsorted(r_all, np.arange(R + 1))
    crossings = [np.stack([t_all[bounds[r]:bounds[r + 1]], k_all[bounds[r]:bounds[r + 1]]],
                          axis=1).astype(np.float64) for r in range(R)]
    return crossings, ambiguous


# =============================================================================== B-splines
def bspline(coeffs: np.ndarray, degree: int, points: np.ndarray) -> np.ndarray:
    """Tensor-product B-spline of ``degree`` with coefficients ``coeffs`` at index-space
    ``points`` (shape (..., 3)), coefficient ``m`` centred at ``x = m``, coefficients mirrored
    about the first and last voxel: ``scipy.ndimage.map_coordinates(coeffs, order=degree,
    mode="mirror", prefilter=False)``, independent of splinecast's per-cell transforms."""
    from scipy import ndimage

    points = np.asarray(points, np.float64)
    flat = ndimage.map_coordinates(np.asarray(coeffs, np.float64), points.reshape(-1, 3).T,
                                   order=degree, mode="mirror", prefilter=False)
    return flat.reshape(points.shape[:-1])


# =============================================================================== volume rendering
def dense_dvr(data, spacing, origin, origins, directions, opacity_points, color_points, domain,
              ds: float = 0.01, chunk: int = 256, planes=None, value=None, box=None):
    """Emission-absorption integral along world rays through the trilinear interpolant (or the
    field ``value`` of index points (..., 3) over the index-space ``box = (lo, hi)``, e.g. an
    ``evaluators.Evaluator``'s, for other models).

    The transfer function is given by its control points and evaluated with ``np.interp`` (linear
    between points, constant beyond them): ``opacity_points`` are ``(value, alpha)`` with
    ``alpha`` the opacity of a slab one voxel (index unit) thick, so the extinction per voxel
    length is ``tau = -ln(1 - alpha)``; ``color_points`` are ``(position, r, g, b)`` over
    ``[0, 1]`` of ``domain`` (values outside the domain take the end colours).

    Along each ray the index-space arc length ``s`` (voxels) runs over the box of voxel centres;
    the field is sampled at equal steps no longer than ``ds`` voxels and both
    ``Tau(s) = int tau ds`` and ``C = int c(v) tau(v) exp(-Tau) ds`` are integrated with the
    trapezoid rule (second order; kinks of the integrand at cell faces and control points cost
    O(ds^2) each). ``planes`` (rows ``(nx, ny, nz, d)``, world) limit each ray further to the
    half-spaces ``n . x + d >= 0``. Returns premultiplied ``rgb`` (..., 3) and opacity ``alpha``
    (...) over a transparent background, with the leading shape of ``origins``.
    """
    data = np.asarray(data, np.float64)
    spacing = np.broadcast_to(np.asarray(spacing, np.float64), (3,))
    origin = np.broadcast_to(np.asarray(origin, np.float64), (3,))
    W = np.asarray(origins, np.float64)
    U = np.asarray(directions, np.float64)
    W, U = np.broadcast_arrays(W, U)
    shape = W.shape[:-1]
    W, U = W.reshape(-1, 3), U.reshape(-1, 3)
    op = np.asarray(opacity_points, np.float64)
    cp = np.asarray(color_points, np.float64)
    lo, hi = float(domain[0]), float(domain[1])
    if np.any(op[:, 1] >= 1.0):
        raise ValueError("opacity 1 has infinite extinction; use alpha < 1")
    if value is None:
        value = lambda p: trilinear(data, p)  # noqa: E731
        box = (np.zeros(3), np.asarray(data.shape, np.float64) - 1.0)
    rgb = np.zeros((W.shape[0], 3))
    alpha = np.zeros(W.shape[0])
    for start in range(0, W.shape[0], chunk):
        o = (W[start:start + chunk] - origin) / spacing
        d = U[start:start + chunk] / spacing
        t0, t1 = box_interval(o, d, box[0], box[1])
        if planes is not None:
            p0, p1 = planes_interval(W[start:start + chunk], U[start:start + chunk], planes)
            t0, t1 = np.maximum(t0, p0), np.minimum(t1, p1)
        speed = np.linalg.norm(d, axis=1)  # voxels per world unit
        length = np.where(t1 > t0, (t1 - t0) * speed, 0.0)  # voxels
        n = int(np.ceil(length.max() / ds)) + 1 if length.max() > 0 else 2
        frac = np.linspace(0.0, 1.0, n)
        s = length[:, None] * frac  # voxels from the entry point
        t = np.where(length > 0, t0, 0.0)[:, None] + s / speed[:, None]
        v = value(o[:, None, :] + t[..., None] * d[:, None, :])
        tau = -np.log1p(-np.interp(v, op[:, 0], op[:, 1]))
        u = np.clip((v - lo) / (hi - lo), 0.0, 1.0)
        color = np.stack([np.interp(u, cp[:, 0], cp[:, k]) for k in (1, 2, 3)], axis=-1)
        h = (length / (n - 1))[:, None]  # the step of each ray
        optical = np.concatenate(
            [np.zeros((len(h), 1)), np.cumsum(0.5 * h * (tau[:, 1:] + tau[:, :-1]), axis=1)],
            axis=1)
        f = color * (tau * np.exp(-optical))[..., None]
        rgb[start:start + chunk] = np.sum(0.5 * h[..., None] * (f[:, 1:] + f[:, :-1]), axis=1)
        alpha[start:start + chunk] = -np.expm1(-optical[:, -1])
    return rgb.reshape(*shape, 3), alpha.reshape(shape)


# =============================================================================== test volumes
def marschner_lobb(n: int, f_m: float = 6.0, alpha: float = 0.25):
    """The Marschner-Lobb test signal on ``[-1, 1]^3`` sampled on ``n`` points per axis.

    ``rho(x, y, z) = (1 - sin(pi z / 2) + alpha (1 + rho_r(sqrt(x^2 + y^2)))) / (2 (1 + alpha))``
    with ``rho_r(r) = cos(2 pi f_M cos(pi r / 2))``; values lie in ``[0, 1]``, the usual isovalue
    is 0.5. Returns ``(data, spacing, origin)``.
    """
    x = np.linspace(-1.0, 1.0, n)
    X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
    r = np.sqrt(X * X + Y * Y)
    rho_r = np.cos(2.0 * np.pi * f_m * np.cos(np.pi * r / 2.0))
    data = (1.0 - np.sin(np.pi * Z / 2.0) + alpha * (1.0 + rho_r)) / (2.0 * (1.0 + alpha))
    spacing = 2.0 / (n - 1)
    return data, (spacing, spacing, spacing), (-1.0, -1.0, -1.0)


def sphere_distance(shape, center_world, radius, spacing=(1.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0)):
    """Signed distance ``|x - c| - r`` sampled at the voxel centres (world units)."""
    spacing = np.broadcast_to(np.asarray(spacing, np.float64), (3,))
    origin = np.broadcast_to(np.asarray(origin, np.float64), (3,))
    axes = [origin[a] + np.arange(shape[a]) * spacing[a] for a in range(3)]
    X, Y, Z = np.meshgrid(*axes, indexing="ij")
    c = center_world
    return np.sqrt((X - c[0]) ** 2 + (Y - c[1]) ** 2 + (Z - c[2]) ** 2) - radius


def smooth_noise(shape, seed: int, sigma: float = 2.0) -> np.ndarray:
    """Gaussian-filtered white noise, normalised to zero mean and unit standard deviation."""
    from scipy.ndimage import gaussian_filter

    rng = np.random.default_rng(seed)
    data = gaussian_filter(rng.standard_normal(shape), sigma=sigma, mode="reflect")
    return (data - data.mean()) / data.std()
