"""Type-6 splines: coefficient rules, their symmetric expansion and exact smoothness conditions.

References are independent of the package: the tetrahedra are rebuilt here from their definition
(centre, face centre, two ends of a face edge), the note's rules are re-typed as offset vectors
at the note's point coordinates, and smoothness is checked with the Bernstein–Bézier C0/C1
conditions in exact rational arithmetic (weights as functions of the 27 data values).
"""

from __future__ import annotations

import itertools
from fractions import Fraction as F

import pytest

from splinecast.models.qss import qss_tables
from splinecast.models.s31 import s31_tables

H = F(1, 2)


# ----------------------------------------------------------------------------- independent geometry
def ref_tets():
    """The 24 tetrahedra [centre, face centre, edge end, edge end] built from the definition."""
    tets = []
    for axis in range(3):
        for s in (1, -1):
            fc = [F(0)] * 3
            fc[axis] = s * H
            for other in range(3):
                if other == axis:
                    continue
                for s2 in (1, -1):
                    ends = []
                    last = 3 - axis - other
                    for s3 in (1, -1):
                        p = [F(0)] * 3
                        p[axis], p[other], p[last] = s * H, s2 * H, s3 * H
                        ends.append(tuple(p))
                    tets.append(((F(0),) * 3, tuple(fc), ends[0], ends[1]))
    return tets


def domain_point(verts, mi, d):
    return tuple(sum((mi[m] * verts[m][a] for m in range(4)), F(0)) / d for a in range(3))


def multi(d):
    return [mi for mi in itertools.product(range(d + 1), repeat=4) if sum(mi) == d]


def solve_bary(verts, p):
    """Barycentric coordinates of p in the tetrahedron (exact Gaussian elimination)."""
    rows = [[verts[m][a] for m in range(4)] + [p[a]] for a in range(3)]
    rows.append([F(1)] * 4 + [F(1)])
    for col in range(4):
        piv = next(r for r in range(col, 4) if rows[r][col] != 0)
        rows[col], rows[piv] = rows[piv], rows[col]
        for r in range(4):
            if r != col and rows[r][col] != 0:
                f = rows[r][col] / rows[col][col]
                rows[r] = [x - f * y for x, y in zip(rows[r], rows[col], strict=True)]
    return [rows[m][4] / rows[m][m] for m in range(4)]


def coef(tables, p, shift=(0, 0, 0)):
    """Weights (offset -> Fraction) of the coefficient at local point p of the cube at shift."""
    lookup = {pt: n for n, pt in enumerate(tables.points)}
    w = tables.weights[lookup[p]]
    return {tuple(o[a] + shift[a] for a in range(3)): v for o, v in w.items()}


def combo(terms):
    out: dict = {}
    for factor, w in terms:
        for o, v in w.items():
            out[o] = out.get(o, F(0)) + factor * v
    return {o: v for o, v in out.items() if v != 0}


def clean(w):
    return {o: v for o, v in w.items() if v != 0}


# ----------------------------------------------------------------------------- counts and rules
def test_point_counts_and_tet_tables():
    for tables, d, n_pts in ((s31_tables(), 3, 175), (qss_tables("qss-b"), 2, 65),
                             (qss_tables("qss-a"), 2, 65)):
        assert tables.n_points == n_pts
        assert tables.tet_points.shape == (24, len(multi(d)))
        for row in tables.tet_points:
            assert len(set(row.tolist())) == len(row)
        # Every point of every independently built tetrahedron has a coefficient.
        pts = set(tables.points)
        for verts in ref_tets():
            for mi in multi(d):
                assert domain_point(verts, mi, d) in pts


def _rule(terms):
    out = {}
    for w, names in terms:
        for name in names.split():
            o = [0, 0, 0]
            for ch in name:
                o = [a + b for a, b in zip(o, {"i": (0, 0, 0), "r": (1, 0, 0), "l": (-1, 0, 0),
                                               "f": (0, 1, 0), "b": (0, -1, 0), "t": (0, 0, 1),
                                               "d": (0, 0, -1)}[ch], strict=True)]
            out[tuple(o)] = F(w)
    return out


# Rules of the note, keyed by the note's point coordinates (re-typed independently here).
NOTE_S31 = {
    (-H, H, H): [("1/8", "i f l t fl lt ft flt")],
    (F(-1, 6), H, H): [("5/24", "i f t ft"), ("1/24", "l fl lt flt")],
    (F(0), H, F(1, 3)): [("13/48", "i f"), ("7/48", "t ft"), ("1/32", "l r fl fr"),
                         ("1/96", "lt rt flt frt")],
    (F(-1, 3), H, F(1, 3)): [("5/24", "i f"), ("1/8", "l t fl ft"), ("1/24", "lt flt")],
    (F(-1, 6), H, F(1, 6)): [("13/48", "i f"), ("17/192", "l t fl ft"), ("1/64", "r d fr fd"),
                             ("1/96", "lt flt"), ("1/192", "rt ld frt fld")],
    (F(0), H, F(0)): [("13/48", "i f"), ("5/96", "l r t d fl fr ft fd"),
                      ("1/192", "lt rt ld rd flt frt fld frd")],
    (F(-1, 3), F(1, 3), F(1, 3)): [("1/4", "i"), ("1/6", "f l t"), ("1/12", "fl ft lt")],
    (F(0), F(1, 3), F(1, 3)): [("1/3", "i"), ("5/24", "f t"), ("1/12", "ft"), ("1/24", "l r"),
                               ("1/48", "fl fr lt rt")],
    (F(-1, 6), F(1, 3), F(1, 6)): [("1/3", "i"), ("5/24", "f"), ("1/8", "l t"),
                                   ("5/96", "fl ft"), ("1/48", "r d lt"),
                                   ("1/96", "fr fd rt ld")],
    (F(0), F(1, 3), F(0)): [("1/3", "i"), ("5/24", "f"), ("7/96", "l r t d"),
                            ("1/32", "fl fr ft fd"), ("1/96", "lt rt ld rd")],
    (F(-1, 6), F(1, 6), F(1, 6)): [("3/8", "i"), ("7/48", "f l t"),
                                   ("1/48", "fl ft lt b r d"), ("1/96", "bl bt fr fd rt ld")],
    (F(0), F(1, 6), F(0)): [("3/8", "i"), ("7/48", "f"), ("1/12", "l r t d"), ("1/48", "b"),
                            ("1/64", "fl fr ft fd"), ("1/96", "lt rt ld rd"),
                            ("1/192", "bl br bt bd")],
    (F(0), F(0), F(0)): [("3/8", "i"), ("1/12", "f b l r t d"),
                         ("1/96", "fl fr ft fd bl br bt bd lt rt ld rd")],
}
NOTE_QSS_COMMON = {
    (-H, H, H): [("1/8", "i f l t fl lt ft flt")],
    (F(0), H, H): [("1/4", "i f t ft")],
    (F(-1, 4), H, F(1, 4)): [("1/4", "i f"), ("1/8", "l t fl ft")],
    (F(0), H, F(0)): [("1/4", "i f"), ("1/16", "l r t d fl fr ft fd")],
}
NOTE_QSS_B = {
    (F(-1, 4), F(1, 4), F(1, 4)): [("5/16", "i"), ("3/16", "f l t"), ("1/16", "fl ft lt"),
                                   ("-1/16", "flt")],
    (F(0), F(1, 4), F(0)): [("5/16", "i"), ("3/16", "f"), ("3/32", "l r t d"),
                            ("1/32", "fl fr ft fd"), ("1/64", "lt rt ld rd"),
                            ("-1/64", "flt frt fld frd")],
    (F(0), F(0), F(0)): [("5/16", "i"), ("3/32", "f b l r t d"),
                         ("1/64", "fl fr ft fd bl br bt bd lt rt ld rd"),
                         ("-1/128", "flt frt fld frd blt brt bld brd")],
}
NOTE_QSS_A = {
    (F(-1, 4), F(1, 4), F(1, 4)): [("1/4", "i f l t")],
    (F(0), F(1, 4), F(0)): [("1/4", "i f"), ("1/8", "l r t d")],
    (F(0), F(0), F(0)): [("1/4", "i"), ("1/8", "f b l r t d")],
}


@pytest.mark.parametrize("name", ["s31", "qss-b", "qss-a"])
def test_every_class_matches_the_note_exactly(name):
    if name == "s31":
        tables, note = s31_tables(), NOTE_S31
    else:
        tables = qss_tables(name)
        note = {**NOTE_QSS_COMMON, **(NOTE_QSS_B if name == "qss-b" else NOTE_QSS_A)}
    for point, terms in note.items():
        assert clean(coef(tables, point)) == _rule(terms), point


@pytest.mark.parametrize("name", ["s31", "qss-b", "qss-a"])
def test_linear_precision_exact(name):
    """Every coefficient of a linear function is its value at the domain point (exactly)."""
    tables = s31_tables() if name == "s31" else qss_tables(name)
    for p, w in zip(tables.points, tables.weights, strict=True):
        assert sum(w.values()) == 1
        for a in range(3):
            assert sum((v * o[a] for o, v in w.items()), F(0)) == p[a]


def test_weight_signs():
    assert all(v >= 0 for w in s31_tables().weights for v in w.values())
    assert all(v >= 0 for w in qss_tables("qss-a").weights for v in w.values())
    assert any(v < 0 for w in qss_tables("qss-b").weights for v in w.values())


# ----------------------------------------------------------------------------- exact C0/C1
def _shared_pairs():
    """(T, T', shift of T''s cube) for every face shared inside a cube or across the +x face."""
    tets = ref_tets()
    pairs = []
    for a, b in itertools.combinations(range(24), 2):
        if len(set(tets[a]) & set(tets[b])) == 3:
            pairs.append((tets[a], tets[b], (0, 0, 0)))
    for ta in tets:
        for tb in tets:
            tb_global = [tuple(v[k] + (1 if k == 0 else 0) for k in range(3)) for v in tb]
            if len(set(ta) & set(tb_global)) == 3:
                pairs.append((ta, tb, (1, 0, 0)))
    return pairs


def _check_pair(tables, d, ta, tb, shift, order):
    """C0 (order 0) or C0 and C1 (order 1) between ta (cube 0) and tb (cube at shift)."""
    tb_g = [tuple(v[k] + shift[k] for k in range(3)) for v in tb]
    shared = [v for v in tb_g if v in ta]
    w_out = next(v for v in tb_g if v not in ta)
    beta = solve_bary(ta, w_out)

    def c_a(p):
        return coef(tables, p)

    def c_b(p_global):
        local = tuple(p_global[k] - shift[k] for k in range(3))
        return coef(tables, local, shift)

    for gamma in multi(d):  # C0 on the shared face
        if gamma[3] != 0:
            continue
        p = tuple(sum((gamma[m] * shared[m][k] for m in range(3)), F(0)) / d for k in range(3))
        if clean(c_a(p)) != clean(c_b(p)):
            return False
    if order == 0:
        return True
    for gamma in multi(d - 1):  # C1: one layer off the face in tb
        if gamma[3] != 0:
            continue
        base = [sum((gamma[m] * shared[m][k] for m in range(3)), F(0)) for k in range(3)]
        p_out = tuple((base[k] + w_out[k]) / d for k in range(3))
        rhs = combo([(beta[m], c_a(tuple((base[k] + ta[m][k]) / d for k in range(3))))
                     for m in range(4)])
        if clean(c_b(p_out)) != rhs:
            return False
    return True


def test_s31_is_c1_exactly_on_every_shared_face():
    tables = s31_tables()
    pairs = _shared_pairs()
    assert sum(1 for p in pairs if p[2] == (0, 0, 0)) == 36  # interior faces of a cube
    assert sum(1 for p in pairs if p[2] != (0, 0, 0)) == 4  # the +x face: 4 triangles
    for ta, tb, shift in pairs:
        assert _check_pair(tables, 3, ta, tb, shift, 1)


@pytest.mark.parametrize("variant", ["qss-b", "qss-a"])
def test_qss_c0_everywhere_c1_across_cube_faces(variant):
    tables = qss_tables(variant)
    pairs = _shared_pairs()
    for ta, tb, shift in pairs:
        assert _check_pair(tables, 2, ta, tb, shift, 0)
        if shift != (0, 0, 0):
            assert _check_pair(tables, 2, ta, tb, shift, 1)
    # Not C1 everywhere (no C1 quadratic scheme with this stencil exists).
    assert not all(_check_pair(tables, 2, ta, tb, s, 1) for ta, tb, s in pairs)
