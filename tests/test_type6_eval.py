"""Type-6 splines: direct evaluation and gradient (continuity, precision, approximation order).

References: analytic functions (linear, quadratic, smooth), finite differences, and the value of
the neighbouring patch across each shared face.
"""

from __future__ import annotations

import numpy as np
import pytest

import splinecast as sc
from splinecast.models.qss import QSSModel
from splinecast.models.s31 import S31Model
from splinecast.models.type6 import evaluate_in_tets, locate

RNG = np.random.default_rng(1234)


def _model(kind, data, **kw):
    vol = sc.Volume(np.asarray(data, dtype=np.float64))
    if kind == "s31":
        return S31Model(vol, **kw)
    return QSSModel(vol, variant=kind, **kw)


def _eval(model, cubes, tets, q):
    return evaluate_in_tets(model.pad, *model.tables_arrays, model.degree,
                            np.ascontiguousarray(cubes, np.int64),
                            np.ascontiguousarray(tets, np.int64), np.ascontiguousarray(q))


def _face_points(model, n_per_face=6):
    """Random points on the four faces of every tetrahedron of cube (2, 2, 2), with both sides.

    Returns cube/tet/local point of side A and side B for each sample and whether the face is a
    cube face.
    """
    from splinecast.models.type6_geometry import tet_vertices

    ca, ta, qa, cb, tb, qb, outer = [], [], [], [], [], [], []
    for tet in range(24):
        verts = np.array([[float(c) for c in v] for v in tet_vertices(tet)])
        for drop in range(4):
            for _ in range(n_per_face):
                lam = RNG.dirichlet(np.ones(3)) * 0.9 + 0.1 / 3  # away from the face's edges
                face = np.delete(verts, drop, axis=0)
                p = lam @ face
                # Step a little across the face, away from the opposite vertex, to find side B.
                out = p + 1e-6 * (p - verts[drop])
                cube_b, tet_b, _ = locate((out + 2.0)[None, :], np.array(model.n_cells))
                qb_loc = p + 2.0 - cube_b[0]
                ca.append((2, 2, 2))
                ta.append(tet)
                qa.append(p)
                cb.append(cube_b[0])
                tb.append(tet_b[0])
                qb.append(qb_loc)
                outer.append(drop == 0)
    return (np.array(ca), np.array(ta), np.array(qa), np.array(cb), np.array(tb), np.array(qb),
            np.array(outer))


@pytest.mark.parametrize("kind", ["s31", "qss-b", "qss-a"])
def test_continuity_on_shared_faces(kind):
    model = _model(kind, RNG.normal(size=(5, 5, 5)))
    ca, ta, qa, cb, tb, qb, outer = _face_points(model)
    # Side B really is another tetrahedron (inner faces) or another cube (outer faces).
    assert np.all((ta != tb) | np.any(ca != cb, axis=1))
    assert np.all(np.any(ca != cb, axis=1) == outer)
    va, ga = _eval(model, ca, ta, qa)
    vb, gb = _eval(model, cb, tb, qb)
    assert np.max(np.abs(va - vb)) < 1e-10
    if kind == "s31":
        assert np.max(np.abs(ga - gb)) < 1e-10
    else:
        # QSS: C1 across cube faces; only C0 across (some) faces inside the cube.
        assert np.max(np.abs(ga[outer] - gb[outer])) < 1e-10
        assert np.max(np.abs(ga[~outer] - gb[~outer])) > 1e-3


@pytest.mark.parametrize("kind", ["s31", "qss-b", "qss-a"])
def test_reproduces_linear_functions(kind):
    n = 6
    i, j, k = np.meshgrid(*(np.arange(n),) * 3, indexing="ij")
    a = RNG.normal(size=4)
    data = a[0] + a[1] * i + a[2] * j + a[3] * k
    model = _model(kind, data)
    # Cubes whose 27-neighbourhood is inside the data: 1..n-2, i.e. points in [0.5, n-2.5].
    p = RNG.uniform(0.5, n - 2.5, size=(500, 3))
    exact = a[0] + p @ a[1:]
    assert np.max(np.abs(model.evaluate(p) - exact)) < 1e-12
    assert np.max(np.abs(model.gradient(p) - a[1:])) < 1e-11


def test_s31_quadratics_give_q_plus_laplacian_over_8_and_prefilter_is_exact():
    n = 8
    i, j, k = np.meshgrid(*(np.arange(n, dtype=float),) * 3, indexing="ij")
    c = RNG.normal(size=10)

    def q(x, y, z):
        return (c[0] + c[1] * x + c[2] * y + c[3] * z + c[4] * x * x + c[5] * y * y
                + c[6] * z * z + c[7] * x * y + c[8] * x * z + c[9] * y * z)

    lap = 2 * (c[4] + c[5] + c[6])
    p = RNG.uniform(1.5, n - 3.5, size=(500, 3))  # prefilter needs one more voxel of margin
    exact = q(p[:, 0], p[:, 1], p[:, 2])
    plain = _model("s31", q(i, j, k))
    assert np.max(np.abs(plain.evaluate(p) - (exact + lap / 8))) < 1e-10
    pre = _model("s31", q(i, j, k), prefilter=True)
    assert np.max(np.abs(pre.evaluate(p) - exact)) < 1e-10


@pytest.mark.parametrize("kind", ["s31", "qss-b"])
def test_approximation_order_two(kind):
    """Max error on f = sin x cos y cos z falls by ~4 per halving of h (values and gradients)."""
    rng = np.random.default_rng(7)
    errs, gerrs = [], []
    for n in (11, 21, 41):
        h = 1.0 / (n - 1)
        x = np.arange(n) * h
        X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
        model = _model(kind, np.sin(X) * np.cos(Y) * np.cos(Z))
        w = rng.uniform(0.25, 0.75, size=(2000, 3))  # world points away from the border
        p = w / h
        f = np.sin(w[:, 0]) * np.cos(w[:, 1]) * np.cos(w[:, 2])
        g = np.stack([np.cos(w[:, 0]) * np.cos(w[:, 1]) * np.cos(w[:, 2]),
                      -np.sin(w[:, 0]) * np.sin(w[:, 1]) * np.cos(w[:, 2]),
                      -np.sin(w[:, 0]) * np.cos(w[:, 1]) * np.sin(w[:, 2])], axis=1)
        errs.append(np.max(np.abs(model.evaluate(p) - f)))
        gerrs.append(np.max(np.abs(model.gradient(p) / h - g)))
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all(orders > 1.8), (errs, orders)
    gorders = np.log2(np.array(gerrs[:-1]) / np.array(gerrs[1:]))
    assert np.all(gorders > 0.9), (gerrs, gorders)


@pytest.mark.parametrize("kind", ["s31", "qss-b"])
def test_gradient_matches_finite_differences(kind):
    model = _model(kind, RNG.normal(size=(6, 6, 6)))
    p = RNG.uniform(0.0, 5.0, size=(200, 3))
    h = 1e-6
    fd = np.stack([(model.evaluate(p + h * e) - model.evaluate(p - h * e)) / (2 * h)
                   for e in np.eye(3)], axis=1)
    g = model.gradient(p)
    # Points within h of a tetrahedron face can see a kink (QSS); compare the robust majority.
    close = np.all(np.abs(fd - g) < 1e-5, axis=1)
    assert close.mean() > 0.97


def test_border_values_stay_in_data_range_and_options_are_checked():
    data = RNG.uniform(3.0, 4.0, size=(4, 5, 6))
    model = _model("s31", data)
    p = np.stack([RNG.uniform(-0.5, s - 0.5, 2000) for s in data.shape], axis=1)
    v = model.evaluate(p)
    assert v.min() >= 3.0 - 1e-12 and v.max() <= 4.0 + 1e-12
    vol = sc.Volume(data)
    with pytest.raises(sc.ParameterError):
        sc.Scene(vol, model="qss", prefilter=True)
    with pytest.raises(sc.ParameterError):
        sc.Scene(vol, model="s31", root_finder="sturm")
    with pytest.raises(sc.ParameterError):
        sc.Scene(vol, model="qss", variant="qss-c")


@pytest.mark.parametrize("kind", ["s31", "qss-b", "qss-a"])
def test_averaging_chain_gives_the_rules_and_cube_bounds_are_exact_ranges(kind):
    """The compiled chain (used by classification, precompute and the renderer's cube cache)
    against the weight matrix of the rules (checked against the note in
    test_type6_coefficients); the per-cube bounds and the scene's block ranges against the
    range of those reference coefficients."""
    from splinecast.models.type6 import store_coefficients

    data = RNG.normal(size=(6, 5, 7)) * 10.0 + 3.0
    model = _model(kind, data)
    shape = np.asarray(data.shape, np.int64)
    cubes = np.arange(data.size, dtype=np.int64)[::-1].copy()  # any order
    prog = model.program
    assert prog.n_terms < model.tables.sparse()[1].size  # cheaper than the direct rules
    got = store_coefficients(model.pad, cubes, shape, *prog.arrays, prog.n_slots, model.n_points)
    w = model.tables.weight_matrix()
    ijk = np.stack(np.unravel_index(cubes, data.shape), axis=1)
    ref = np.array([w @ model.pad[i:i + 3, j:j + 3, k:k + 3].reshape(27) for i, j, k in ijk])
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12)
    lo = model.cube_lo.reshape(-1)[cubes]
    hi = model.cube_hi.reshape(-1)[cubes]
    assert np.all(lo <= ref.min(axis=1)) and np.all(hi >= ref.max(axis=1))
    assert np.allclose(lo, ref.min(axis=1), atol=1e-5) and np.allclose(hi, ref.max(axis=1),
                                                                        atol=1e-5)
    hier = sc.Scene(sc.Volume(data), model="s31" if kind == "s31" else "qss",
                    **({} if kind == "s31" else {"variant": kind})).hierarchy
    assert hier.lows[0].min() <= ref.min() and hier.highs[0].max() >= ref.max()
    for level, shift in enumerate((2, 4, 6)):
        for (i, j, k), a, b in zip(ijk, ref.min(axis=1), ref.max(axis=1), strict=True):
            assert hier.lows[level][i >> shift, j >> shift, k >> shift] <= a
            assert hier.highs[level][i >> shift, j >> shift, k >> shift] >= b


@pytest.mark.parametrize("kind", ["s31", "qss-b", "qss-a"])
@pytest.mark.parametrize("dtype", [np.float64, np.float32, np.uint8])
def test_renderers_straight_line_coefficients_are_the_programs(kind, dtype):
    """The renderer's cube cache is filled by the scheme's program written out as code
    (``type6_ray.fill_cube``, picked by the grid's scheme number): the same numbers as the
    program's loop (same sums in the same order: bit for bit), and the rules' weight matrix
    applied to the 27 values (an independent reference, to rounding)."""
    from numba import njit

    from splinecast.models.type6 import store_coefficients
    from splinecast.models.type6_ray import fill_cube

    @njit
    def fill_all(grid, cubes, out):
        nz = grid.pad.shape[2] - 2
        ny = grid.pad.shape[1] - 2
        for m in range(cubes.shape[0]):
            lin = cubes[m]
            fill_cube(grid, lin // (ny * nz), (lin // nz) % ny, lin % nz, out[m])

    data = RNG.normal(size=(4, 5, 3)) * 40.0 + 100.0
    model = _model(kind, np.clip(data, 0, 255).astype(dtype) if dtype is np.uint8 else
                   data.astype(dtype))
    cubes = np.arange(data.size, dtype=np.int64)
    got = np.full((cubes.size, model.n_points), np.nan)
    fill_all(model.kernel_grid(), cubes, got)
    prog = model.program
    loop = store_coefficients(model.pad, cubes, np.asarray(data.shape, np.int64), *prog.arrays,
                              prog.n_slots, model.n_points)
    np.testing.assert_array_equal(got, loop)
    w = model.tables.weight_matrix()
    ijk = np.stack(np.unravel_index(cubes, data.shape), axis=1)
    ref = np.array([w @ model.pad[i:i + 3, j:j + 3, k:k + 3].astype(np.float64).reshape(27)
                    for i, j, k in ijk])
    np.testing.assert_allclose(got, ref, rtol=1e-13, atol=0)


@pytest.mark.parametrize("kind", ["s31", "qss-b"])
def test_ray_restriction_matches_the_patch_along_the_segment(kind):
    """The unrolled blossoms of the renderer against de Casteljau evaluation of the patch at
    points of the segment (the Bernstein polynomial of the restriction must agree)."""
    from math import comb

    from splinecast.models.type6 import barycentric, ray_bernstein2, ray_bernstein3
    from splinecast.models.type6_geometry import tet_vertices

    model = _model(kind, RNG.normal(size=(5, 5, 5)))
    tet_points, _, _, _, bary, _ = model.tables_arrays
    cube = np.array([2, 2, 2])
    coeffs = model.cube_coefficients(*cube)
    d = model.degree
    s = np.linspace(0.0, 1.0, 7)
    for tet in range(24):
        verts = np.array([[float(c) for c in v] for v in tet_vertices(tet)])
        lam = RNG.dirichlet(np.ones(4), size=2)
        a, b = lam @ verts  # two points inside the tetrahedron
        c = np.ascontiguousarray(coeffs[tet_points[tet]])
        ab = barycentric(bary, tet, *a) + barycentric(bary, tet, *b)
        u = ray_bernstein3(c, *ab) if d == 3 else ray_bernstein2(c, *ab)
        poly = sum(u[k] * comb(d, k) * s**k * (1 - s) ** (d - k) for k in range(d + 1))
        pts = a + s[:, None] * (b - a)
        ref, _ = _eval(model, np.tile(cube, (len(s), 1)), np.full(len(s), tet), pts)
        np.testing.assert_allclose(poly, ref, rtol=0, atol=1e-12)


def test_cube_segments_are_cut_at_every_tetrahedron_face_in_order():
    """``split_cube_segment`` (branch-free: a sorting network) against the crossings of the six
    planes computed and sorted here, on random segments and degenerate ones (parallel to a
    plane, inside a plane, through the centre, along an axis); and every piece lies in one
    tetrahedron (points inside a piece find the same one)."""
    from numba import njit

    from splinecast.models.type6_geometry import tet_of_point
    from splinecast.models.type6_ray import split_cube_segment

    @njit(error_model="numpy")  # as every kernel: a division by zero gives inf or NaN
    def split_all(a, e, cuts, counts):
        for m in range(a.shape[0]):
            counts[m] = split_cube_segment(a[m, 0], a[m, 1], a[m, 2], e[m, 0], e[m, 1],
                                           e[m, 2], cuts[m])

    rng = np.random.default_rng(5)
    n = 4000
    a = rng.uniform(-0.5, 0.5, (n, 3))
    b = rng.uniform(-0.5, 0.5, (n, 3))
    b[:400, 1:] = a[:400, 1:]  # along x
    b[400:800, 0] = b[400:800, 1] + (a[400:800, 0] - a[400:800, 1])  # parallel to x = y
    a[800:1200, 0] = a[800:1200, 1]  # inside x = y
    b[800:1200, 0] = b[800:1200, 1]
    b[1200:1600] = -a[1200:1600]  # through the centre
    a[1600:1700] = np.round(a[1600:1700] * 4) / 4  # on lattice points (exact ties)
    b[1600:1700] = np.round(b[1600:1700] * 4) / 4
    e = b - a
    cuts = np.full((n, 8), np.nan)
    counts = np.zeros(n, np.int64)
    split_all(a, e, cuts, counts)
    for m in range(n):
        want = []
        for u, v in ((0, 1), (0, 2), (1, 2)):
            for sign in (1.0, -1.0):
                with np.errstate(divide="ignore", invalid="ignore"):
                    s = -(a[m, u] - sign * a[m, v]) / (e[m, u] - sign * e[m, v])
                if 0.0 < s < 1.0:
                    want.append(s)
        want = [0.0, *sorted(want), 1.0]
        assert counts[m] == len(want) - 1
        np.testing.assert_array_equal(cuts[m, :len(want)], want)
        for p in range(counts[m]):
            s0, s1 = cuts[m, p], cuts[m, p + 1]
            if s1 - s0 < 1e-9 or 800 <= m < 1200:  # a tie, or a segment in a face
                continue
            tets = {tet_of_point(*(a[m] + s * e[m])) for s in np.linspace(s0, s1, 7)[1:-1]}
            assert len(tets) == 1, (m, p, tets)


@pytest.mark.parametrize("kind", ["s31", "qss"])
def test_value_at_is_the_value_of_value_gradient_at(kind):
    """The value-only hook of the fixed-step loop (coefficients read in place from the cube
    cache) against the value of ``value_gradient_at`` (a copy of the tetrahedron's
    coefficients and a de Casteljau evaluation with gradient) to the last bit, and against
    the sparse rules' evaluation (``evaluate_in_tets``), at random points in random order (so
    the thread's cube cache both misses and hits), on tetrahedron faces and outside the
    spline's box (clamped)."""
    from splinecast._jit import jit
    from splinecast.models.pieces import new_scratch, value_at, value_gradient_at

    @jit()
    def values(grid, points):
        scratch = new_scratch(grid)
        out = np.empty((points.shape[0], 2))
        for n in range(points.shape[0]):
            x, y, z = points[n, 0], points[n, 1], points[n, 2]
            out[n, 0] = value_at(grid, scratch, x, y, z)
            out[n, 1] = value_gradient_at(grid, scratch, x, y, z)[0]
        return out

    data = RNG.normal(size=(7, 6, 9))
    scene = sc.Scene(sc.Volume(data), model=kind)
    model, grid = scene.model, scene.grid.kernel
    shape = np.array(data.shape)
    # Traversal space (index + 1/2, the box [0, n]), a little beyond it on every side.
    points = RNG.uniform(-0.4, shape + 0.4, size=(3000, 3))
    # On the planes between tetrahedra (|qx| = |qy| and the like) and on cube faces.
    cubes = np.floor(points[:600]).astype(float)
    q = points[:600] - cubes - 0.5
    q[:200, 1] = np.copysign(q[:200, 0], q[:200, 1])
    q[200:400, 2] = -q[200:400, 0]
    q[400:500, 0] = 0.5
    points[:600] = cubes + 0.5 + q
    points[500:600] = np.round(points[500:600])
    got = values(grid, points)
    np.testing.assert_array_equal(got[:, 0], got[:, 1])
    # Inside the box, the sparse rules' value of the same cube and tetrahedron.
    inside = np.all((points >= 0) & (points <= shape), axis=1)
    cube, tet, loc = locate(points[inside] - 0.5, shape)
    ref, _ = _eval(model, cube, tet, loc)
    assert inside.sum() > 1000 and np.ptp(ref) > 1.0
    np.testing.assert_allclose(got[inside, 0], ref, rtol=0, atol=1e-12)
