"""``cubic_first_root`` and ``quadratic_roots`` against mpmath at high precision.

The reference roots are those of the polynomial with exactly the float coefficients passed to the
solver (``mpmath.polyroots`` at 60 digits), not those the coefficients were generated from.

Accuracy. A double-precision root finder can only be asked for the root of the polynomial it can
evaluate: evaluating ``g`` in floating point has an error of at most about
``gamma * sum_i |c_i| |s|^i`` (Horner), which moves a simple root by that amount divided by
``|g'(s)|``. For well-separated roots this is far below 1e-12, and 1e-12 is what we require. For
clustered roots (``|g'|`` tiny) no double-precision method can do better than that bound, so the
tolerance there is ``1e-12 + 16 u sum_i |c_i| |s|^i / |g'(s)|``, and we additionally require the
error to be a small fraction of the cluster width (the right member of the cluster is found).

Tangency policy (module docstring of ``splinecast.roots.cubic``): a root without a sign change
(a double root) is reported only when the cubic evaluates to exactly 0 at the extremum, so the
double-root cases below use exactly representable roots where that evaluation is exact, or a
perturbation that makes the answer unambiguous.
"""

from __future__ import annotations

import math

import mpmath
import numba
import numpy as np
import pytest
from reference import mp_cubic_first_root, mp_cubic_real_roots, mp_quadratic_roots

from splinecast.roots.cubic import cubic_first_root, quadratic_roots
from splinecast.roots.pieces import PowerCubic, poly_first_root

U = 2.0**-53


def cond_tol(c, s):
    """Rounding-level forward error bound of a root ``s`` (see module docstring)."""
    c3, c2, c1, c0 = c
    s = float(s)
    mag = abs(c3) * abs(s) ** 3 + abs(c2) * s * s + abs(c1) * abs(s) + abs(c0)
    slope = abs(3 * c3 * s * s + 2 * c2 * s + c1)
    return 16 * U * mag / slope if slope > 0 else math.inf


def expand(roots, scale=1.0):
    """Float coefficients (c3, c2, c1, c0) of ``scale * prod(s - r)`` for three roots."""
    c = np.poly(np.asarray(roots, dtype=np.complex128)).real * scale
    return tuple(float(v) for v in c)


def solve(c, lo, hi):
    return float(cubic_first_root(c[0], c[1], c[2], c[3], float(lo), float(hi)))


def assert_first_root(c, lo, hi, abs_tol=1e-12, cond=False):
    ref = mp_cubic_first_root(*c, lo, hi)
    got = solve(c, lo, hi)
    if ref is None:
        assert math.isnan(got), f"{c} on [{lo}, {hi}]: no root, got {got!r}"
        return None
    assert not math.isnan(got), f"{c} on [{lo}, {hi}]: missed the root {ref}"
    assert lo <= got <= hi
    tol = abs_tol + (cond_tol(c, ref) if cond else 0.0)
    err = abs(mpmath.mpf(got) - ref)
    assert err <= tol, f"{c} on [{lo}, {hi}]: got {got!r}, reference {ref}, error {err}"
    return ref


def random_separated_roots(rng, sep, lo=-0.5, hi=1.5):
    while True:
        r = np.sort(rng.uniform(lo, hi, 3))
        if np.min(np.diff(r)) >= sep:
            return r


@pytest.mark.parametrize("seed", range(4))
def test_random_cubics_three_real_roots(seed):
    rng = np.random.default_rng(seed)
    n_roots = 0
    for _ in range(400):
        roots = random_separated_roots(rng, sep=0.2)
        scale = 10.0 ** rng.uniform(-8, 8) * rng.choice([-1.0, 1.0])
        c = expand(roots, scale)
        if rng.random() < 0.5:
            lo, hi = 0.0, 1.0
        else:
            lo, hi = np.sort(rng.uniform(-0.6, 1.6, 2))
        # keep the interval ends clear of the roots (roots at the ends are tested separately)
        if np.min(np.abs(np.subtract.outer(roots, [lo, hi]))) < 1e-6:
            continue
        ref = assert_first_root(c, lo, hi)
        n_roots += ref is not None
    assert n_roots > 200


@pytest.mark.parametrize("seed", range(3))
def test_random_cubics_one_real_root(seed):
    rng = np.random.default_rng(100 + seed)
    for _ in range(300):
        real = rng.uniform(-0.5, 1.5)
        pair = complex(rng.uniform(-0.5, 1.5), rng.uniform(0.05, 1.0))
        scale = 10.0 ** rng.uniform(-8, 8) * rng.choice([-1.0, 1.0])
        c = expand([real, pair, pair.conjugate()], scale)
        if abs(real) < 1e-6 or abs(real - 1) < 1e-6:
            continue
        assert_first_root(c, 0.0, 1.0)


def pair_is_resolvable(c, r_a, r_b):
    """Whether double precision can see the sign change of the root pair ``r_a < r_b``.

    Between the two roots ``g`` reaches an extremum of size ``depth``; a float evaluation of ``g``
    there is off by up to ``bound`` (Horner). When ``depth`` is below the bound the pair is
    numerically a double root, and the tangency policy applies: it may be reported or skipped.
    """
    with mpmath.workdps(60):
        c3, c2, c1, c0 = (mpmath.mpf(v) for v in c)
        e = mpmath.findroot(lambda s: (3 * c3 * s + 2 * c2) * s + c1, (r_a + r_b) / 2)
        depth = abs(((c3 * e + c2) * e + c1) * e + c0)
        ef = abs(float(e))
        bound = 8 * U * (abs(c[0]) * ef**3 + abs(c[1]) * ef**2 + abs(c[2]) * ef + abs(c[3]))
        return depth > 4 * bound


@pytest.mark.parametrize("seed", range(2))
def test_random_cubics_close_roots(seed):
    # pairs of roots 1e-3 .. 1e-9 apart: ill-conditioned, see the module docstring
    rng = np.random.default_rng(200 + seed)
    resolvable = separated = 0
    for _ in range(200):
        r0 = rng.uniform(0.05, 0.9)
        gap = 10.0 ** rng.uniform(-9, -3)
        r2 = rng.choice([rng.uniform(-0.5, -0.05), rng.uniform(1.05, 1.5)])
        c = expand([r0, r0 + gap, r2], 10.0 ** rng.uniform(-3, 3))
        ref_roots = mp_cubic_real_roots(*c)
        if len(ref_roots) != 3:
            continue  # the rounded coefficients turned the pair complex: nothing to find
        pair = [r for r in ref_roots if 0.0 < r < 1.0]
        assert len(pair) == 2
        got = solve(c, 0.0, 1.0)
        if not pair_is_resolvable(c, *pair):
            # Numerically a double root: either a numerical root near the pair (an exact root of
            # the cubic with coefficients perturbed by a few ulps: small backward error) or the
            # next root, if any.
            after = [r for r in ref_roots if pair[1] < r <= 1.0]
            with mpmath.workdps(60):
                c3, c2, c1, c0 = (mpmath.mpf(v) for v in c)
                gs = mpmath.mpf(got)
                residual = abs(((c3 * gs + c2) * gs + c1) * gs + c0) if got == got else math.inf
            scale = sum(abs(ci) * abs(got) ** (3 - i) for i, ci in enumerate(c))
            width = pair[1] - pair[0]
            near_pair = residual <= 32 * U * scale and abs(got - pair[0]) <= 1e-6 + 10 * width
            next_root = (not after and math.isnan(got)) or (
                after and abs(got - after[0]) <= 1e-12 + cond_tol(c, after[0])
            )
            assert near_pair or next_root, f"{c}: got {got}, roots {ref_roots}"
            continue
        resolvable += 1
        ref = assert_first_root(c, 0.0, 1.0, cond=True)
        # Where the rounding-level error bound is small against the gap, the first member must
        # be returned, not the second one or the extremum.
        if cond_tol(c, ref) <= 0.05 * (pair[1] - pair[0]):
            separated += 1
            assert abs(got - ref) <= 0.25 * (pair[1] - pair[0])
    assert resolvable >= 100 and separated >= 50


def test_double_root_exactly_representable():
    # (s - 1/4)^2 (s - 3/4): the derivative's root 1/4 is computed exactly and g(1/4) == 0.
    c = (1.0, -1.25, 0.4375, -0.046875)
    assert c == expand([0.25, 0.25, 0.75])
    assert solve(c, 0.0, 1.0) == 0.25
    assert_first_root(c, 0.0, 1.0)
    assert solve(c, 0.5, 1.0) == 0.75
    # (s - 3/4)^2 (s - 1/4): simple root first, then the touching double root
    c = expand([0.75, 0.75, 0.25])
    assert_first_root(c, 0.0, 1.0)  # the simple root 1/4 (to 1e-12; Newton may stop an ulp off)
    assert abs(solve(c, 0.0, 1.0) - 0.25) <= 1e-15
    assert solve(c, 0.5, 1.0) == 0.75  # the touching root, exactly (extremum evaluates to 0)
    # a touching double root that is the only root in the interval, both orientations
    c = expand([0.5, 0.5, 2.0])
    assert solve(c, 0.0, 1.0) == 0.5
    assert solve(tuple(-v for v in c), 0.0, 1.0) == 0.5


@pytest.mark.parametrize("delta", [1e-6, 1e-10, 1e-14])
def test_double_root_split_by_perturbation(delta):
    # g = (s - 1/4)^2 (s - 3/4) has a local maximum 0 at 1/4. Lifting it by delta > 0 creates two
    # simple roots 1/4 -+ sqrt(2 delta) (sign changes that must be found); lowering it leaves
    # only the root near 3/4.
    base = expand([0.25, 0.25, 0.75])
    up = (base[0], base[1], base[2], base[3] + delta)
    ref = assert_first_root(up, 0.0, 1.0, cond=True)
    # (sanity of the case: c0 + delta is rounded, so compare loosely with 1/4 - sqrt(2 delta))
    assert abs(float(ref) - (0.25 - math.sqrt(2 * delta))) < 1e-2 * math.sqrt(2 * delta)
    down = (base[0], base[1], base[2], base[3] - delta)
    ref = assert_first_root(down, 0.0, 1.0, cond=True)
    assert abs(float(ref) - 0.75) < 1e-3


def test_clustered_roots_1e7_apart():
    for r0 in (0.3, 0.123456, 0.75):
        for third in (-0.4, 0.9, 1.7):
            c = expand([r0, r0 + 1e-7, third])
            ref = assert_first_root(c, 0.0, 1.0, cond=True)
            got = solve(c, 0.0, 1.0)
            assert abs(got - float(ref)) < 0.1 * 1e-7  # the first member of the cluster
            assert abs(got - r0) < 0.1 * 1e-7
    # three roots within 2e-7
    c = expand([0.4, 0.4 + 1e-7, 0.4 + 2e-7])
    got = solve(c, 0.0, 1.0)
    ref_roots = mp_cubic_real_roots(*c)
    if len(ref_roots) == 3:
        assert abs(got - float(ref_roots[0])) < 0.5e-7
    # a triple cluster is within rounding of a triple root; at least it must be found nearby
    assert abs(got - 0.4) < 2e-5


@pytest.mark.parametrize("side", ["lo", "hi"])
@pytest.mark.parametrize("offset", [1e-9, -1e-9, 1e-12, -1e-12])
def test_roots_near_interval_ends(side, offset):
    lo, hi = 0.2, 0.8
    end = lo if side == "lo" else hi
    for other in ((-0.3, 1.4), (0.5, 1.4), (-0.3, 0.5)):
        roots = [end + offset, *other]
        for scale in (1.0, -3e5):
            c = expand(roots, scale)
            assert_first_root(c, lo, hi)


def test_roots_exactly_at_the_interval_ends():
    c = expand([0.25, 0.5, 0.75])  # exact dyadic coefficients
    assert c == (1.0, -1.5, 0.6875, -0.09375)
    assert solve(c, 0.25, 0.4) == 0.25
    assert solve(c, 0.6, 0.75) == 0.75
    assert solve(c, 0.3, 0.5) == 0.5
    assert solve(c, 0.25, 0.25) == 0.25  # degenerate interval holding a root
    assert math.isnan(solve(c, 0.3, 0.3))
    assert math.isnan(solve(c, 0.3, 0.45))


def test_nearly_quadratic_and_nearly_linear():
    # c3 = 1e-18: the third root is near -c2/c3 ~ 1e18, far outside; the other two are those of
    # the quadratic part.
    for (r0, r1) in ((0.3, 0.7), (0.05, 0.06), (-0.2, 0.55)):
        q = np.poly([r0, r1])
        for c3 in (1e-18, -1e-18, 1e-30):
            c = (c3, float(q[0]), float(q[1]), float(q[2]))
            assert_first_root(c, 0.0, 1.0)
    # nearly linear: tiny c3 and c2
    for c3, c2 in ((1e-18, 1e-17), (-1e-18, 3e-17), (1e-25, -1e-20)):
        c = (c3, c2, 1.0, -0.3)
        ref = assert_first_root(c, 0.0, 1.0)
        assert abs(float(ref) - 0.3) < 1e-15
        c = (c3, c2, -2.5, 1.75)
        assert_first_root(c, 0.0, 1.0)
    # exact lower degrees
    assert_first_root((0.0, 1.0, -1.0, 0.21), 0.0, 1.0)  # quadratic, roots 0.3, 0.7
    assert_first_root((0.0, 0.0, 2.0, -0.5), 0.0, 1.0)  # linear, root 0.25
    assert solve((0.0, 0.0, 2.0, -0.5), 0.0, 1.0) == 0.25
    assert math.isnan(solve((0.0, 0.0, 0.0, 1.0), 0.0, 1.0))  # non-zero constant


def test_zero_polynomial_and_no_root():
    assert solve((0.0, 0.0, 0.0, 0.0), 0.2, 0.9) == 0.2
    assert math.isnan(solve((0.0, 1.0, 0.0, 1.0), 0.0, 1.0))  # s^2 + 1
    assert math.isnan(solve((1.0, 0.0, 0.0, 1.0), 0.0, 1.0))  # s^3 + 1 (root at -1)
    c = expand([-0.5, 1.5, 2.0])  # all roots outside
    assert math.isnan(solve(c, 0.0, 1.0))
    assert mp_cubic_first_root(*c, 0.0, 1.0) is None


# ----------------------------------------------------------------------------- quadratic_roots
def check_quadratic(a, b, c):
    count, r0, r1 = quadratic_roots(a, b, c)
    ref = mp_quadratic_roots(a, b, c)
    got = [r for r in (r0, r1)[:count]]
    assert count == len(ref), f"{a, b, c}: count {count}, reference {ref}"
    assert all(math.isnan(r) for r in (r0, r1)[count:])
    # Relative accuracy of both roots: a few ulps, plus the rounding of the discriminant
    # propagated into q = -(b + sign(b) sqrt(disc)) / 2 (large only when the roots are close,
    # i.e. b^2 - 4ac small against b^2 + 4|ac|; for b^2 >> 4ac both roots stay at a few ulps).
    rel = 4 * U
    if a != 0 and count == 2:
        with mpmath.workdps(60):
            sq = mpmath.sqrt(mpmath.mpf(b) ** 2 - 4 * mpmath.mpf(a) * mpmath.mpf(c))
            rel += float(4 * U * (b * b + 4 * abs(a * c)) / (2 * sq * (abs(b) + sq)))
    for g, r in zip(got, ref, strict=True):
        assert abs(mpmath.mpf(g) - r) <= rel * abs(r), f"{a, b, c}: got {got}, reference {ref}"
    return got


def test_quadratic_random():
    rng = np.random.default_rng(7)
    for _ in range(2000):
        a, b, c = rng.normal(size=3) * 10.0 ** rng.uniform(-6, 6, 3)
        check_quadratic(float(a), float(b), float(c))


@pytest.mark.parametrize("ratio", [1e4, 1e8, 1e12, 1e16, 1e20])
def test_quadratic_cancellation(ratio):
    # b^2 >> 4ac: the textbook formula loses the small root completely
    for a, b, c in ((1.0, ratio, 1.0), (1.0, -ratio, 1.0), (3.0, ratio, -2.0), (-1e-3, ratio, 7.0)):
        got = check_quadratic(a, b, c)  # each root to a few ulps *relative* to itself
        small = min(got, key=abs)
        assert abs(small) < 1e-3 * max(abs(r) for r in got)


def test_quadratic_degenerate():
    assert quadratic_roots(1.0, -1.0, 0.25)[:2] == (1, 0.5)  # exact double root
    check_quadratic(1.0, -1.0, 0.25)
    assert quadratic_roots(0.0, 2.0, -1.0)[:2] == (1, 0.5)  # linear
    assert quadratic_roots(0.0, 0.0, 1.0)[0] == 0
    assert quadratic_roots(1.0, 0.0, 1.0)[0] == 0  # complex
    check_quadratic(1.0, 0.0, -4.0)
    check_quadratic(2.0, 0.0, 0.0)  # double root at 0
    check_quadratic(1.0, 3.0, 0.0)  # roots 0 and -3


# Not cached on disk: numba would not see a change of the overload in another file.
@numba.njit
def _first_roots_of_pieces(coeffs, values):  # pragma: no cover - compiled
    out = np.empty(coeffs.shape[0])
    for n in range(coeffs.shape[0]):
        c = coeffs[n]
        out[n] = poly_first_root(PowerCubic(c[0], c[1], c[2], c[3]), values[n])
    return out


def _hull_decides(coeffs, values):
    """Cases the convex hull of the Bernstein coefficients settles (no root), in exact-enough
    numpy arithmetic: the shortcut of ``poly_first_root`` answers those without the solver."""
    c0 = coeffs[:, 0] - values
    b = np.stack([c0, c0 + coeffs[:, 1] / 3, c0 + (2 * coeffs[:, 1] + coeffs[:, 2]) / 3,
                  c0 + coeffs[:, 1:].sum(axis=1)], axis=1)
    return np.all(b > 1e-9, axis=1) | np.all(b < -1e-9, axis=1)


def test_the_power_cubic_first_root_is_the_solvers_answer():
    """``poly_first_root`` of a :class:`PowerCubic` tries the convex hull of its Bernstein
    coefficients before the solver; its answer must be the solver's, bit for bit: on random
    cubics, on trilinear ray cubics (the trilinear model's pieces) and on cubics that touch or
    nearly touch the value (where a shortcut taken too eagerly would lose a root)."""
    rng = np.random.default_rng(7)
    cases = [rng.normal(size=(4000, 4)) * rng.choice([1e-6, 1.0, 1e6], size=(4000, 1))]
    # Trilinear: corner values and rays through a cell, coefficients as the model forms them.
    corners = rng.uniform(-1.0, 1.0, size=(4000, 8))
    a = rng.uniform(0.0, 1.0, size=(4000, 3))
    d = rng.uniform(0.0, 1.0, size=(4000, 3)) - a
    s = np.linspace(0.0, 1.0, 4)
    p = a[:, None, :] + s[None, :, None] * d[:, None, :]
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    v = sum(corners[:, [4 * i + 2 * j + k]] * (x if i else 1 - x) * (y if j else 1 - y)
            * (z if k else 1 - z) for i in (0, 1) for j in (0, 1) for k in (0, 1))
    cases.append(np.linalg.solve(np.vander(s, 4, increasing=True), v.T).T)
    # Touching: (s - r)^2 (s - q) shifted by tiny offsets around the value.
    r = rng.uniform(-0.2, 1.2, size=4000)
    q = rng.uniform(-3.0, 3.0, size=4000)
    eps = rng.choice([0.0, 1e-16, -1e-16, 1e-13, -1e-13, 1e-10, -1e-10], size=4000)
    cases.append(np.stack([-r * r * q + eps, r * r + 2 * r * q, -(2 * r + q),
                           np.ones(4000)], axis=1))
    for coeffs in cases:
        values = rng.choice([0.0, 0.3, -0.3], size=len(coeffs))
        got = _first_roots_of_pieces(coeffs, values)
        want = np.array([cubic_first_root(c[3], c[2], c[1], c[0] - val, 0.0, 1.0)
                         for c, val in zip(coeffs, values, strict=True)])
        np.testing.assert_array_equal(got, want)
        assert _hull_decides(coeffs, values).mean() > 0.05  # the shortcut is exercised


def _mp_bernstein_first_root(b):
    """First root in [0, 1] of the cubic with exactly the float Bernstein coefficients ``b``
    (converted to the power form in exact arithmetic; ``None``: no root)."""
    with mpmath.workdps(60):
        b0, b1, b2, b3 = (mpmath.mpf(float(v)) for v in b)
        c = (b3 - 3 * b2 + 3 * b1 - b0, 3 * (b2 - 2 * b1 + b0), 3 * (b1 - b0), b0)
        roots = mpmath.polyroots(c, maxsteps=200, extraprec=200)
        real = sorted(mpmath.re(r) for r in roots if abs(mpmath.im(r)) < mpmath.mpf(10) ** -40)
        inside = [r for r in real if 0 <= r <= 1]
        return (min(inside), c) if inside else (None, c)


@pytest.mark.parametrize("seed", range(3))
def test_bernstein_cubic_first_root_against_mpmath(seed):
    """The type-6 (s31) pieces' solver, ``bernstein_cubic_first_root``: isolation by
    subdivision and refinement, on cubics with three separated real roots, one real root, and
    short nearly linear ray pieces with one crossing (the common case of a hit), at scales from
    1e-6 to 1e6; the reference is the exact polynomial of the float coefficients."""
    from splinecast.roots.bernstein_cubic import bernstein_cubic_first_root

    rng = np.random.default_rng(300 + seed)
    found = 0
    for case in range(600):
        scale = 10.0 ** rng.uniform(-6, 6) * rng.choice([-1.0, 1.0])
        kind = case % 3
        if kind == 0:
            roots = random_separated_roots(rng, sep=0.05)
        elif kind == 1:
            pair = complex(rng.uniform(-0.5, 1.5), rng.uniform(0.05, 1.0))
            roots = [rng.uniform(-0.5, 1.5), pair, pair.conjugate()]
        if kind < 2:
            c3, c2, c1, c0 = expand(roots, scale)
            b = (c0, c0 + c1 / 3, c0 + (2 * c1 + c2) / 3, c0 + c1 + c2 + c3)
        else:
            start, slope = rng.uniform(-1.0, 1.0), rng.uniform(0.2, 2.0) * rng.choice([-1, 1])
            bend = rng.normal(size=2) * 0.1
            b = tuple(scale * v for v in (start, start + slope / 3 + bend[0],
                                          start + 2 * slope / 3 + bend[1], start + slope))
        ref, c = _mp_bernstein_first_root(b)
        got = float(bernstein_cubic_first_root(*b))
        if ref is None:
            assert math.isnan(got), f"{b}: no root, got {got!r}"
            continue
        assert not math.isnan(got), f"{b}: missed the root {ref}"
        # Roots closer than 1e-9 to an end are the ends' own tests' business.
        if min(abs(ref), abs(ref - 1)) < 1e-9:
            continue
        tol = 1e-12 + cond_tol(tuple(float(v) for v in c), ref)
        err = abs(mpmath.mpf(got) - ref)
        assert err <= tol, f"{b}: got {got!r}, reference {ref}, error {err}"
        found += 1
    assert found > 250
