"""Geometry of the type-6 tetrahedral partition and the derivation of its coefficient tables.

The trivariate splines of Kalbe et al. 2009 and Koch 2009 (:mod:`~splinecast.models.s31`,
:mod:`~splinecast.models.qss`) live on the *dual* grid: the data value of voxel ``(i, j, k)`` sits
at the centre of cube ``(i, j, k)``, which spans ``[i - 1/2, i + 1/2] x ...`` in index space. Each
cube is cut by the six planes ``x = +-y``, ``x = +-z``, ``y = +-z`` through its centre into 24
congruent tetrahedra ``[cube centre, face centre, the two ends of one edge of that face]``.

Everything here is in *local* index coordinates ``q`` of one cube (origin at the cube centre, the
cube is ``[-1/2, 1/2]^3``), so anisotropic spacing only enters where a gradient is converted to
world units.

Tetrahedra
----------
The reference tetrahedron ``T0 = [v0, v1, v2, v3]`` has ``v0 = (0, 0, 0)``, ``v1 = (0, 1/2, 0)``
(the ``+y`` face centre), ``v2 = (-1/2, 1/2, 1/2)``, ``v3 = (1/2, 1/2, 1/2)`` (the ``+z`` edge of
that face); it is the set ``y >= z >= |x|``. Tetrahedron ``T`` is the image ``M_T T0`` under a
signed permutation matrix that sends ``+y`` to the face axis/sign and ``+z`` to the edge
axis/sign. Its number is ``8 a + 4 [sa < 0] + 2 e + [sb < 0]`` where ``a`` is the face axis,
``sa`` its sign, ``e`` says which of the two remaining axes (0: the smaller, 1: the larger) the edge
lies on, and ``sb`` is the edge's sign. :func:`tet_of_point` finds it from ``q`` in a few compares.

Coefficients
------------
A coefficient rule gives, for one domain point of ``T0``, fixed weights on the 27 data values
around the cube. Because the schemes are symmetric, every other domain point of the cube is the
image of a rule point under one of the 48 symmetries of the cube, and its weights are the rule's
weights with the data offsets mapped by the same symmetry. :func:`derive_tables` performs that
expansion in exact rational arithmetic, checks that two symmetries reaching the same point agree,
and numbers the distinct points of the cube (175 for cubic, 65 for quadratic).
"""

from __future__ import annotations

import itertools
from fractions import Fraction

import numpy as np

from .._jit import jit

__all__ = [
    "SYMMETRIES",
    "TET_MATRICES",
    "REFERENCE_VERTICES",
    "OFFSETS",
    "multi_indices",
    "tet_vertices",
    "barycentric_matrices",
    "decasteljau_tables",
    "parse_rules",
    "derive_tables",
    "Type6Tables",
    "tet_of_point",
    "point",
    "Type6Program",
    "derive_program",
]

F = Fraction

#: The 27 data offsets around a cube, offset ``(ox, oy, oz)`` has number ``9(ox+1)+3(oy+1)+oz+1``.
OFFSETS = np.array(list(itertools.product((-1, 0, 1), repeat=3)), dtype=np.int64)

#: Vertices of the reference tetrahedron T0 (local cube coordinates, exact).
REFERENCE_VERTICES = (
    (F(0), F(0), F(0)),
    (F(0), F(1, 2), F(0)),
    (F(-1, 2), F(1, 2), F(1, 2)),
    (F(1, 2), F(1, 2), F(1, 2)),
)


def _signed_permutations() -> list[np.ndarray]:
    mats = []
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1, -1), repeat=3):
            m = np.zeros((3, 3), dtype=np.int64)
            for col, (row, s) in enumerate(zip(perm, signs, strict=True)):
                m[row, col] = s
            mats.append(m)
    return mats


#: The 48 symmetries of the cube as signed permutation matrices (acting on column vectors).
SYMMETRIES: tuple[np.ndarray, ...] = tuple(_signed_permutations())


def _tet_matrices() -> np.ndarray:
    mats = np.zeros((24, 3, 3), dtype=np.int64)
    for a in range(3):
        others = [b for b in range(3) if b != a]
        for sa_neg in (0, 1):
            for e in (0, 1):
                b = others[e]
                c = others[1 - e]
                for sb_neg in (0, 1):
                    m = np.zeros((3, 3), dtype=np.int64)
                    m[a, 1] = -1 if sa_neg else 1  # +y (face normal of T0) -> face axis
                    m[b, 2] = -1 if sb_neg else 1  # +z (edge side of T0) -> edge axis
                    m[c, 0] = 1  # x (along the edge) -> the remaining axis
                    mats[8 * a + 4 * sa_neg + 2 * e + sb_neg] = m
    return mats


#: ``M_T`` for the 24 tetrahedra: tetrahedron ``T`` is ``M_T`` applied to T0's vertices.
TET_MATRICES: np.ndarray = _tet_matrices()


def multi_indices(degree: int) -> list[tuple[int, int, int, int]]:
    """Barycentric multi-indices ``(i, j, k, l)`` with sum ``degree``, in the package's order.

    The order (lexicographic, decreasing ``i`` first) is the layout of the per-tetrahedron
    coefficient vectors everywhere in splinecast.
    """
    out = []
    for i in range(degree, -1, -1):
        for j in range(degree - i, -1, -1):
            for k in range(degree - i - j, -1, -1):
                out.append((i, j, k, degree - i - j - k))
    return out


def _apply(m: np.ndarray, p: tuple) -> tuple:
    return tuple(sum((int(m[r, c]) * p[c] for c in range(3)), F(0)) for r in range(3))


def tet_vertices(tet: int) -> tuple[tuple[Fraction, ...], ...]:
    """Exact local coordinates of the four vertices of tetrahedron ``tet``."""
    return tuple(_apply(TET_MATRICES[tet], v) for v in REFERENCE_VERTICES)


def barycentric_matrices() -> np.ndarray:
    """Affine maps from local cube coordinates to barycentric coordinates, shape (24, 4, 4).

    ``lambda_m = A[T, m, 0] qx + A[T, m, 1] qy + A[T, m, 2] qz + A[T, m, 3]``; the first three
    columns are also the (constant) gradients of the barycentric coordinates. All entries are
    small integers, so the float64 table is exact.
    """
    out = np.zeros((24, 4, 4))
    for tet in range(24):
        verts = np.array([[float(c) for c in v] for v in tet_vertices(tet)])
        # Solve [v0..v3; 1 1 1 1] lambda = [q; 1] once per tetrahedron: A is its inverse.
        system = np.vstack([verts.T, np.ones(4)])
        out[tet] = np.linalg.inv(system)
        out[tet] = np.round(out[tet] * 2.0) / 2.0  # entries are multiples of 1/2; drop rounding
    return out


def decasteljau_tables(degree: int) -> np.ndarray:
    """Index tables for de Casteljau steps from degree ``degree`` down to 0.

    Returns an int64 array ``steps`` of shape ``(degree, n_max, 4)``: a step from degree ``e`` to
    ``e - 1`` (``steps[e - 1]``) computes output ``n`` (in :func:`multi_indices` order of degree
    ``e - 1``) as ``sum_m lambda_m c[steps[e - 1, n, m]]`` over the degree-``e`` coefficients.
    Unused rows are -1.
    """
    n_max = len(multi_indices(degree - 1)) if degree >= 1 else 1
    steps = -np.ones((degree, max(n_max, 1), 4), dtype=np.int64)
    for e in range(1, degree + 1):
        upper = {mi: n for n, mi in enumerate(multi_indices(e))}
        for n, beta in enumerate(multi_indices(e - 1)):
            for m in range(4):
                up = list(beta)
                up[m] += 1
                steps[e - 1, n, m] = upper[tuple(up)]
    return steps


_LETTERS = {
    "i": (0, 0, 0), "r": (1, 0, 0), "l": (-1, 0, 0), "f": (0, 1, 0), "b": (0, -1, 0),
    "t": (0, 0, 1), "d": (0, 0, -1),
}


def _offset(name: str) -> tuple[int, int, int]:
    """Data offset of a name like ``"flt"`` = front + left + top = ``(-1, 1, 1)``."""
    o = [0, 0, 0]
    for ch in name:
        for a in range(3):
            o[a] += _LETTERS[ch][a]
    return tuple(o)  # type: ignore[return-value]


def parse_rules(
    rules: dict[tuple[int, int, int, int], list[tuple[Fraction, str]]],
) -> dict[tuple[int, int, int, int], dict[tuple[int, int, int], Fraction]]:
    """Turn rules written as ``{multi-index: [(weight, "i f fl"), ...]}`` into offset weights.

    Each ``(weight, names)`` term gives ``weight`` to every data value named in ``names``
    (space-separated letter codes: ``i`` centre, ``r``/``l`` = +x/-x, ``f``/``b`` =
    +y/-y, ``t``/``d`` = +z/-z). Every rule must sum to 1 (checked).
    """
    out = {}
    for mi, terms in rules.items():
        w: dict[tuple[int, int, int], Fraction] = {}
        for weight, names in terms:
            for name in names.split():
                o = _offset(name)
                if o in w:
                    raise ValueError(f"rule {mi}: data value {name} named twice")
                w[o] = F(weight)
        if sum(w.values()) != 1:
            raise ValueError(f"rule {mi}: weights sum to {sum(w.values())}, not 1")
        out[mi] = w
    return out


class Type6Tables:
    """Exact coefficient tables of one scheme, derived by :func:`derive_tables`.

    Attributes
    ----------
    degree : int
        Polynomial degree per tetrahedron (3 cubic, 2 quadratic).
    points : list of tuple of Fraction
        Distinct domain points of the cube (local coordinates), in coefficient order.
    weights : list of dict
        Per point, the weight of each data offset (exact).
    tet_points : ndarray of int64, shape (24, n_local)
        Cube coefficient number of each local Bernstein–Bézier coefficient of each tetrahedron
        (local order: :func:`multi_indices`).
    """

    def __init__(self, degree, points, weights, tet_points) -> None:
        self.degree = degree
        self.points = points
        self.weights = weights
        self.tet_points = tet_points

    @property
    def n_points(self) -> int:
        """Number of distinct coefficients per cube."""
        return len(self.points)

    def weight_matrix(self) -> np.ndarray:
        """Dense float64 matrix ``W`` (n_points, 27): coefficients = ``W @ data27``."""
        w = np.zeros((self.n_points, 27))
        for p, row in enumerate(self.weights):
            for o, val in row.items():
                w[p, 9 * (o[0] + 1) + 3 * (o[1] + 1) + o[2] + 1] = float(val)
        return w

    def sparse(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """CSR form ``(indptr, offset_numbers, weights)`` of :meth:`weight_matrix`."""
        w = self.weight_matrix()
        indptr = [0]
        cols: list[int] = []
        vals: list[float] = []
        for row in w:
            nz = np.flatnonzero(row)
            cols.extend(nz.tolist())
            vals.extend(row[nz].tolist())
            indptr.append(len(cols))
        return (np.array(indptr, np.int64), np.array(cols, np.int64), np.array(vals))

    def negative_weight_sum(self) -> float:
        """Largest sum of the absolute negative weights of one coefficient (0 for convex rules)."""
        return float(max(-sum((v for v in row.values() if v < 0), F(0)) for row in self.weights))


def derive_tables(
    degree: int, rules: dict[tuple[int, int, int, int], dict[tuple[int, int, int], Fraction]]
) -> Type6Tables:
    """Expand rules given on T0 to every domain point of the cube by the cube's symmetries.

    Parameters
    ----------
    degree : int
        3 or 2.
    rules : dict
        Output of :func:`parse_rules`: weights on data offsets for domain points of T0, at least
        one per orbit of the symmetry group.

    Raises
    ------
    ValueError
        If two symmetries map rules to the same point with different weights (the scheme would
        not be symmetric) or some domain point of a tetrahedron gets no rule.
    """
    ref = REFERENCE_VERTICES
    by_point: dict[tuple, dict] = {}
    order: list[tuple] = []
    for mi, weights in rules.items():
        point = tuple(sum((mi[m] * ref[m][a] for m in range(4)), F(0)) / degree for a in range(3))
        for g in SYMMETRIES:
            gp = _apply(g, point)
            gw = {tuple(int(v) for v in g @ np.array(o)): w for o, w in weights.items()}
            if gp in by_point:
                if by_point[gp] != gw:
                    raise ValueError(f"rules are not symmetric at point {gp}")
            else:
                by_point[gp] = gw
                order.append(gp)
    # Number points by a canonical order (sorted coordinates) so tables do not depend on rules.
    order.sort()
    number = {p: n for n, p in enumerate(order)}
    local = multi_indices(degree)
    tet_points = np.zeros((24, len(local)), dtype=np.int64)
    for tet in range(24):
        verts = tet_vertices(tet)
        for n, mi in enumerate(local):
            p = tuple(sum((mi[m] * verts[m][a] for m in range(4)), F(0)) / degree
                      for a in range(3))
            if p not in number:
                raise ValueError(f"no rule reaches domain point {p} of tetrahedron {tet}")
            tet_points[tet, n] = number[p]
    return Type6Tables(degree, order, [by_point[p] for p in order], tet_points)


@jit(inline="always")
def tet_of_point(qx: float, qy: float, qz: float) -> int:
    """Number of the tetrahedron of the cube holding local point ``q`` (ties: lowest axis)."""
    ax, ay, az = abs(qx), abs(qy), abs(qz)
    if ax >= ay and ax >= az:
        a, qa, u, v = 0, qx, qy, qz
    elif ay >= az:
        a, qa, u, v = 1, qy, qx, qz
    else:
        a, qa, u, v = 2, qz, qx, qy
    # u, v are the two other axes in increasing axis order; the edge lies on the larger |.|.
    if abs(u) >= abs(v):
        e, qb = 0, u
    else:
        e, qb = 1, v
    return 8 * a + (4 if qa < 0.0 else 0) + 2 * e + (1 if qb < 0.0 else 0)


# ----------------------------------------------------------------------------- evaluation programs
def point(text: str) -> tuple[Fraction, Fraction, Fraction]:
    """Exact local point from ``"x y z"`` with rational entries, e.g. ``"-1/3 1/2 1/3"``."""
    x, y, z = (F(s) for s in text.split())
    return (x, y, z)


class Type6Program:
    """A verified straight-line program computing all coefficients of a cube from its 27 values.

    Rows are evaluated in order; row ``r`` writes ``buffer[targets[r]] = sum_q weights[q] *
    buffer[sources[q]]`` over ``q`` in ``ptr[r] .. ptr[r + 1]``. Buffer slots: ``0..26`` the data
    values (offset numbering of :data:`OFFSETS`), ``27 + p`` coefficient ``p`` of the tables,
    then auxiliary quantities. Built by :func:`derive_program`, which checks in exact arithmetic
    that every coefficient comes out with exactly the weights of the tables.
    """

    def __init__(self, targets, ptr, sources, weights, n_slots, n_points) -> None:
        self.targets = targets
        self.ptr = ptr
        self.sources = sources
        self.weights = weights
        self.n_slots = n_slots
        #: Coefficients per cube (slots ``27 .. 27 + n_points - 1``; auxiliaries follow).
        self.n_points = n_points

    @property
    def n_terms(self) -> int:
        """Multiply-adds per cube."""
        return int(self.sources.shape[0])

    @property
    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(targets, ptr, sources, weights)`` for the compiled evaluators."""
        return (self.targets, self.ptr, self.sources, self.weights)


def derive_program(
    tables: Type6Tables,
    chain: list[tuple[str, list[tuple[Fraction, str]]]] | None = None,
) -> Type6Program:
    """Expand a local averaging chain by the cube's symmetries into a :class:`Type6Program`.

    Parameters
    ----------
    tables : Type6Tables
        The scheme; defines the coefficient numbering and the exact weights to reproduce.
    chain : list, optional
        Rules on the reference tetrahedron's side of the cube, evaluated in order: ``(point,
        terms)`` with ``point`` a string for :func:`point` and each term ``(weight, ref)``, where
        ``ref`` is either data names as in :func:`parse_rules` (each gets ``weight``) or
        ``"@x y z"``, a point computed by an earlier rule (a coefficient, or an auxiliary
        quantity if the point is not a domain point of the scheme). Every image of a rule under
        the 48 symmetries is added unless its point already has a rule. Points left without a
        rule get the tables' direct data rule (``None``: the direct rules for every point).

    Raises
    ------
    ValueError
        If a rule refers to an undefined point, or the composed weights of some coefficient
        differ from the tables' (the chain is wrong).
    """
    number = {p: n for n, p in enumerate(tables.points)}
    slot: dict[tuple, int] = {}
    composed: dict[int, dict[tuple[int, int, int], Fraction]] = {}
    rows: list[tuple[int, list[tuple[int, Fraction]]]] = []
    n_aux = 0

    def data_slot(o) -> int:
        return 9 * (o[0] + 1) + 3 * (o[1] + 1) + o[2] + 1

    for text, terms in chain or []:
        p0 = point(text)
        for g in SYMMETRIES:
            gp = _apply(g, p0)
            if gp in slot:
                continue
            row: list[tuple[int, Fraction]] = []
            weights: dict[tuple[int, int, int], Fraction] = {}
            for w, ref in terms:
                w = F(w)
                if ref.startswith("@"):
                    q = _apply(g, point(ref[1:]))
                    if q not in slot:
                        raise ValueError(f"rule for {text}: point {ref[1:]} is not computed yet")
                    row.append((slot[q], w))
                    for o, v in composed[slot[q]].items():
                        weights[o] = weights.get(o, F(0)) + w * v
                else:
                    for name in ref.split():
                        o = tuple(int(v) for v in g @ np.array(_offset(name)))
                        row.append((data_slot(o), w))
                        weights[o] = weights.get(o, F(0)) + w
            if gp in number:
                s = 27 + number[gp]
            else:
                s = 27 + tables.n_points + n_aux
                n_aux += 1
            slot[gp] = s
            composed[s] = {o: v for o, v in weights.items() if v != 0}
            rows.append((s, row))
    for p, n in number.items():
        if p not in slot:
            s = 27 + n
            slot[p] = s
            composed[s] = dict(tables.weights[n])
            rows.append((s, [(data_slot(o), w) for o, w in tables.weights[n].items()]))
        elif composed[slot[p]] != {o: w for o, w in tables.weights[n].items() if w != 0}:
            raise ValueError(f"chain gives wrong weights at point {p}")
    targets = np.array([s for s, _ in rows], np.int64)
    ptr = np.cumsum([0] + [len(r) for _, r in rows]).astype(np.int64)
    sources = np.array([s for _, r in rows for s, _ in r], np.int64)
    weights_arr = np.array([float(w) for _, r in rows for _, w in r])
    return Type6Program(targets, ptr, sources, weights_arr, 27 + tables.n_points + n_aux,
                        tables.n_points)
